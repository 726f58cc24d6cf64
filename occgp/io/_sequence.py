"""A posed scan sequence read lazily: a folder of scan files plus a pose file.

:class:`ScanSequence` is what ``occgp map FOLDER --poses FILE`` reads: scan files
in natural name order (``2.pcd`` before ``10.pcd``), each moved from the sensor
(or body) frame into the world frame by its pose, read one at a time so that a
long sequence never sits in memory whole.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from .._validation import as_path, check_bool
from ._fileio import read_text
from ._readers import natural_key, read_scans, scan_kind
from ._scan import Scan
from ._trajectory import apply_poses, check_poses, read_kitti_poses, read_tum_trajectory

__all__ = ["POSE_FORMATS", "ScanSequence", "read_poses"]

#: The pose file formats :func:`read_poses` reads.
POSE_FORMATS = ("kitti", "tum")


def read_poses(path, poses_format: str | None = None):
    """Read a KITTI or TUM pose file; the format guessed from its columns when not given.

    Parameters
    ----------
    path : str or os.PathLike
        The file: KITTI odometry poses (12 numbers a line, the top 3 x 4 of a
        row-major sensor-to-world pose) or TUM (``t x y z qx qy qz qw``).
    poses_format : {"kitti", "tum"}, default=None
        The format; None guesses it from the first line's column count (12:
        kitti, 8: tum).

    Returns
    -------
    poses : ndarray of shape (n_poses, 4, 4)
        Sensor-to-world transforms, in file order (TUM time stamps dropped).

    Raises
    ------
    OSError
        If the file is missing or unreadable.
    ValueError
        If `poses_format` is not a choice, the format cannot be guessed, or the
        file is malformed (see :func:`read_kitti_poses`,
        :func:`read_tum_trajectory`).
    TypeError
        If `path` is not a str or os.PathLike.
    """
    path = as_path(path, "poses")
    if poses_format is not None and poses_format not in POSE_FORMATS:
        raise ValueError(f"poses_format must be one of {POSE_FORMATS} or None (guess from the "
                         f"columns), got {poses_format!r}")
    if poses_format is None:
        first = next(((i, line.split("#", 1)[0].split())
                      for i, line in enumerate(read_text(path).splitlines(), start=1)
                      if line.split("#", 1)[0].split()), None)
        if first is None:
            raise ValueError(f"poses file {str(path)!r} holds no poses")
        n = len(first[1])
        if n not in (12, 8):
            raise ValueError(f"cannot tell the format of poses file {str(path)!r}: line "
                             f"{first[0]} has {n} columns; expected 12 (kitti: a 3x4 row-major "
                             f"pose) or 8 (tum: t x y z qx qy qz qw); pass poses_format")
        poses_format = "kitti" if n == 12 else "tum"
    if poses_format == "kitti":
        return read_kitti_poses(path)
    return read_tum_trajectory(path)[1]


def _scan_files(paths):
    """The scan files of `paths` (files as given, folders expanded in natural order)."""
    files = []
    for path in paths:
        path = as_path(path, "scans")
        if path.is_dir():
            found = sorted((p for p in path.iterdir() if p.is_file() and scan_kind(p) is not None),
                           key=natural_key)
            if not found:
                raise ValueError(f"{path}: no supported scan files in the folder (.pcd, .bin, "
                                 f".graph, .xyz/.txt/.dat/.log)")
            files.extend(found)
        elif not path.exists():
            raise FileNotFoundError(2, "no such file or directory", str(path))
        else:
            files.append(path)
    return files


class ScanSequence:
    """A sequence of scan files moved into the world frame by a pose file, read lazily.

    Scan ``i`` (of the files in natural name order, folders expanded) is read
    when it is asked for, and its points ``p`` and origin ``o`` become
    ``R_i p + t_i`` and ``R_i o + t_i`` (:func:`apply_poses`): for scans in
    the sensor or body frame (origin 0, as PCD files without a viewpoint
    and KITTI ``.bin`` files have it), the ray origin is the pose's
    translation. Iterating shows a progress bar (tqdm) where asked.
    ``occgp map`` reads its scan files through this class.

    ``.pcd`` and ``.bin`` files hold one scan each and are read when asked
    for; files that hold several scans (OctoMap ``.graph`` files and scan
    logs) are read when the sequence is made, to count them.

    Parameters
    ----------
    scans : str, os.PathLike or sequence of them
        A folder of scan files, a scan file, or a list of files and folders
        (see :func:`read_scans` for the suffixes).
    poses : str, os.PathLike or array-like of shape (n_scans, 4, 4) or (n_scans, 3, 4), default=None
        Sensor-to-world poses, one per scan in order: a KITTI or TUM file
        (:func:`read_poses`) or an array. None: the scans are in the world
        frame already (their files' own origins).
    poses_format : {"kitti", "tum"}, default=None
        The format of a pose file; None guesses it from the columns.
    fields : int, str or numpy.dtype, default=None
        Record layout of ``.bin`` files (:func:`read_kitti_bin`).
    progress : bool, default=None
        Show a progress bar while iterating (None: only on a terminal).

    Attributes
    ----------
    files : list of pathlib.Path
        The scan file of each scan.
    poses : ndarray of shape (n_scans, 4, 4) or None
        The poses, checked (orthonormal rotations, one per scan).

    Raises
    ------
    OSError
        If a path or the pose file is missing or unreadable.
    ValueError
        If a folder holds no scan file, the pose file is malformed, or the
        poses are not one per scan (checked when the sequence is made); a
        scan file that is malformed raises when it is read, naming it.
    TypeError
        If a path is not a str or os.PathLike, or `poses` is not numeric.

    Examples
    --------
    >>> import os, tempfile
    >>> import numpy as np
    >>> from occgp.io import write_pcd
    >>> folder = tempfile.mkdtemp()
    >>> for i in range(3):
    ...     write_pcd(os.path.join(folder, f"{i}.pcd"), [[1.0, 0.0, 0.0]])
    >>> poses = np.tile(np.eye(4), (3, 1, 1)); poses[:, 0, 3] = [0.0, 1.0, 2.0]
    >>> seq = ScanSequence(folder, poses, progress=False)
    >>> len(seq), [scan.points[0, 0] for scan in seq]
    (3, [np.float64(1.0), np.float64(2.0), np.float64(3.0)])
    >>> seq[2].origin.tolist()
    [2.0, 0.0, 0.0]
    """

    def __init__(self, scans, poses=None, *, poses_format: str | None = None, fields=None,
                 progress: bool | None = None):
        if progress is not None:
            check_bool(progress, "progress")
        self.progress = progress
        self._fields = fields
        paths = [scans] if isinstance(scans, (str, bytes, Path)) or hasattr(
            scans, "__fspath__") else list(scans)
        if not paths:
            raise ValueError("scans must name at least one scan file or folder, got none")
        self._items: list[tuple[Path, Scan | None]] = []
        for f in _scan_files(paths):
            if scan_kind(f) in ("pcd", "bin"):
                self._items.append((f, None))
            else:
                self._items.extend((f, s) for s in read_scans(f, fields=fields))
        self.files = [f for f, _ in self._items]
        self.poses = None if poses is None else self._checked_poses(poses, poses_format)

    def _checked_poses(self, poses, poses_format):
        if isinstance(poses, (str, bytes, Path)) or hasattr(poses, "__fspath__"):
            array = read_poses(poses, poses_format)
            if len(array) != len(self._items):
                raise ValueError(f"poses file {str(poses)!r} holds {len(array)} poses for "
                                 f"{len(self._items)} scans; expected one pose per scan, in "
                                 f"input order")
            return check_poses(array, len(self._items), 1e-3)
        if poses_format is not None:
            raise ValueError("poses_format applies to a pose file, got an array of poses")
        return check_poses(poses, len(self._items), 1e-3)

    def __len__(self) -> int:
        return len(self._items)

    def __getitem__(self, index):
        if not isinstance(index, (int, np.integer)):
            raise TypeError(f"ScanSequence indices must be integers, got "
                            f"{type(index).__name__} (iterate, or index scan by scan)")
        n = len(self)
        if not -n <= index < n:
            raise IndexError(f"scan index {index} out of range for {n} scans")
        index = int(index) % n
        path, scan = self._items[index]
        if scan is None:
            [scan] = read_scans(path, fields=self._fields)
        if self.poses is None:
            return scan
        return apply_poses([scan], self.poses[index:index + 1])[0]

    def __iter__(self):
        from tqdm.auto import tqdm  # type: ignore[import-untyped]

        disable = None if self.progress is None else not self.progress
        with tqdm(total=len(self), unit="scan", disable=disable) as bar:
            for i in range(len(self)):
                yield self[i]
                bar.update()

    def __repr__(self) -> str:
        posed = "" if self.poses is None else ", posed"
        return f"ScanSequence({len(self)} scans{posed})"

    def with_poses(self, poses, *, poses_format: str | None = None) -> "ScanSequence":
        """The same scan files moved by other poses, as a new sequence.

        Parameters
        ----------
        poses : str, os.PathLike or array-like of shape (n_scans, 4, 4) or (n_scans, 3, 4)
            A pose file or an array, one pose per scan (see the class); None
            leaves the scans in their files' frame.
        poses_format : {"kitti", "tum"}, default=None
            The format of a pose file; None guesses it from the columns.

        Returns
        -------
        sequence : ScanSequence
        """
        out = self.subset(np.arange(len(self)))
        out.poses = None
        if poses is not None:
            out.poses = out._checked_poses(poses, poses_format)
        return out

    def subset(self, indices: ArrayLike) -> "ScanSequence":
        """The scans at some indices, in that order, as a new (lazy) sequence.

        Parameters
        ----------
        indices : array-like of int or bool
            Scan indices (or a mask of ``len(self)`` booleans).

        Returns
        -------
        sequence : ScanSequence
            With the files and poses of those scans.
        """
        idx = np.arange(len(self))[np.asarray(indices)]
        out = object.__new__(ScanSequence)
        out.progress, out._fields = self.progress, self._fields
        out._items = [self._items[i] for i in idx]
        out.files = [f for f, _ in out._items]
        out.poses = None if self.poses is None else self.poses[idx]
        return out
