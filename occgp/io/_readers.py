"""Readers of plain-text scans, scan logs and folders, and the dispatch by suffix.

Plain-text point lists (``.xyz`` / ``.txt`` / ``.dat``, optionally ``.bz2`` / ``.gz``
compressed), OctoMap plain-text scan logs (``NODE`` lines), folders of scans, and
:func:`read_scans`, which dispatches on the suffix (KITTI ``.bin`` in ``_kitti_bin.py``,
ScanGraph ``.graph`` in ``_scan_graph.py``, PCD in ``_pcd.py``). Every reader
raises :class:`OSError` for a missing or unreadable file and
:class:`ValueError`, naming the file and what is wrong, for malformed or
truncated content.
"""

import io
import os
import re
import warnings

import numpy as np
from numpy.typing import ArrayLike

from .._docfill import fill_doc
from ._fileio import READER_SECTIONS, as_path, read_text
from ._kitti_bin import bin_record, read_kitti_bin
from ._pcd import read_pcd
from ._scan_graph import read_scan_graph
from ._scan import Scan, check_origin, drop_non_finite

__all__ = ["read_xyz", "read_scan_log", "load_scan_folder", "read_scans"]

_TEXT_SUFFIXES = (".xyz", ".txt", ".dat", ".log")
#: The `fields` parameter and the Returns section of the folder and dispatch readers.
_FIELDS_TO_SCANS = """fields : int, str or numpy.dtype, optional
    Record layout of ``.bin`` files, passed to :func:`read_kitti_bin`
    (default: by file name).

Returns
-------
scans : list of Scan"""
_COMPRESSED = (".bz2", ".gz", ".xz")


def _euler_to_matrix(roll, pitch, yaw):
    """OctoMap's ``Quaternion(roll, pitch, yaw)``: ``Rz(yaw) Ry(pitch) Rx(roll)``."""
    cr, sr = np.cos(roll), np.sin(roll)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cy, sy = np.cos(yaw), np.sin(yaw)
    return np.array([
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ])


# --------------------------------------------------------------------------- #
# plain text
# --------------------------------------------------------------------------- #
def _bad_line(text, first_line):
    """Describe the first line that is not ``x y z [...]`` (error path only)."""
    for i, line in enumerate(text.splitlines()):
        tokens = line.split("#", 1)[0].split()
        if not tokens:
            continue
        try:
            if len(tokens) < 3:
                raise ValueError
            [float(v) for v in tokens[:3]]
        except ValueError:
            return f"line {i + first_line}: expected 'x y z' numbers, got {line.strip()[:80]!r}"
    return None


def _parse_xyz(text, path, first_line=1):
    """Parse 'x y z [...]' lines (comments '#' and blank lines skipped)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # "input contained no data"
        try:
            table = np.loadtxt(
                io.StringIO(text), dtype=np.float64, usecols=(0, 1, 2), ndmin=2, comments="#"
            )
        except ValueError as exc:
            raise ValueError(f"{path}: malformed point data: {_bad_line(text, first_line) or exc}")
    if table.size == 0:
        return np.empty((0, 3))
    return table


@fill_doc(**READER_SECTIONS)
def read_xyz(path, origin: ArrayLike = (0.0, 0.0, 0.0)) -> Scan:
    """Read a plain-text point list, one ``x y z`` per line.

    Extra columns are ignored, ``#`` comments and blank lines skipped;
    ``.bz2``, ``.gz`` and ``.xz`` files are decompressed transparently
    (by suffix). Points with a NaN or inf coordinate (``nan``, ``inf``,
    ``1e999``) are dropped, and their number logged on the ``"occgp"``
    logger (PCL's habit).

    Parameters
    ----------
    path : str or os.PathLike
    origin : array-like of shape (3,), default=(0, 0, 0)
        Sensor origin. Must be finite.

    Returns
    -------
    scan : Scan

    {raises_oserror}
    ValueError
        For a malformed line (with its line number where numpy reports
        it), a corrupt compressed stream, ``NODE`` lines (an OctoMap scan
        log: use :func:`read_scan_log`), or an `origin` not of shape (3,)
        or not finite.
    TypeError
        If `path` or `origin` has a wrong type.

    Examples
    --------
    >>> import tempfile, os
    >>> from pathlib import Path
    >>> path = os.path.join(tempfile.mkdtemp(), "scan.xyz")
    >>> _ = Path(path).write_text("# x y z\\n1 2 3\\n\\n4 5 6 0.9\\n")
    >>> read_xyz(path).points.tolist()
    [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]
    """
    path = as_path(path)
    origin = check_origin(origin)
    text = read_text(path)
    if re.search(r"^\s*NODE\b", text, flags=re.MULTILINE):
        raise ValueError(
            f"{path}: contains NODE lines (an OctoMap scan log with poses); "
            "read it with read_scan_log"
        )
    return Scan(drop_non_finite(_parse_xyz(text, path), path), origin)


@fill_doc(**READER_SECTIONS)
def read_scan_log(path) -> list:
    """Read an OctoMap plain-text scan log (the input of ``log2graph``).

    Each scan starts with ``NODE x y z roll pitch yaw`` (the sensor pose;
    angles in radians, rotation ``Rz(yaw) Ry(pitch) Rx(roll)``) followed by
    its points in the sensor frame, one ``x y z`` per line. Points are
    returned in the world frame. Compressed files are handled as in
    :func:`read_xyz`, and so are points with a NaN or inf coordinate
    (dropped, their number logged).

    {path_to_scans}

    {raises_oserror}
    ValueError
        If a point comes before the first NODE line, or a line is malformed
        (a NODE pose must be six finite numbers).
    {path_type_error}

    Examples
    --------
    >>> import tempfile, os
    >>> from pathlib import Path
    >>> path = os.path.join(tempfile.mkdtemp(), "scans.log")
    >>> _ = Path(path).write_text("NODE 1 0 0 0 0 1.5707963267948966\\n1 0 0\\n")
    >>> np.round(read_scan_log(path)[0].points, 12).tolist()
    [[1.0, 1.0, 0.0]]
    """
    path = as_path(path)
    return _scan_log_from_text(read_text(path), path)


def _scan_log_from_text(text, path):
    lines = text.splitlines()
    starts = [i for i, ln in enumerate(lines) if ln.lstrip().startswith("NODE")]
    if not starts:
        raise ValueError(f"{path}: no NODE line (not an OctoMap scan log; try read_xyz)")
    if any(ln.split("#", 1)[0].strip() for ln in lines[:starts[0]]):
        raise ValueError(f"{path}: points before the first NODE line")
    scans = []
    for k, start in enumerate(starts):
        tokens = lines[start].split()
        try:
            pose = [float(v) for v in tokens[1:7]]
        except ValueError:
            pose = []
        if len(tokens) < 7 or len(pose) != 6 or not np.isfinite(pose).all():
            raise ValueError(
                f"{path}: line {start + 1}: expected 'NODE x y z roll pitch yaw', got "
                f"{lines[start].strip()!r}"
            )
        stop = starts[k + 1] if k + 1 < len(starts) else len(lines)
        local = _parse_xyz("\n".join(lines[start + 1:stop]), path, first_line=start + 2)
        t = np.array(pose[:3])
        with np.errstate(over="ignore", invalid="ignore"):
            points = local @ _euler_to_matrix(*pose[3:]).T + t
        scans.append(Scan(drop_non_finite(points, f"{path} NODE on line {start + 1}"), t))
    return scans


# --------------------------------------------------------------------------- #
# folders and dispatch
# --------------------------------------------------------------------------- #
def natural_key(path):
    parts = re.split(r"(\d+)", path.name)
    return [(0, int(p), "") if p.isdigit() else (1, 0, p.lower()) for p in parts]


def scan_kind(path):
    """Reader kind from the suffix (compression suffixes looked through)."""
    suffixes = [s.lower() for s in path.suffixes]
    if suffixes and suffixes[-1] in _COMPRESSED:
        inner = suffixes[-2] if len(suffixes) > 1 else ""
        return "text" if inner in _TEXT_SUFFIXES or inner == "" else None
    last = suffixes[-1] if suffixes else ""
    if last == ".pcd":
        return "pcd"
    if last == ".bin":
        return "bin"
    if last == ".graph":
        return "graph"
    if last in _TEXT_SUFFIXES:
        return "text"
    return None


@fill_doc(fields_to_scans=_FIELDS_TO_SCANS)
def load_scan_folder(path, pattern: str | None = "*.pcd", *, fields=None) -> list:
    """Read a folder of scan files (la3dm style), in natural file-name order.

    Files are sorted by the numbers in their names (``scan_2`` before
    ``scan_10``), not lexicographically.

    Parameters
    ----------
    path : str or os.PathLike
        The folder.
    pattern : str or None, optional
        Glob pattern of the files to read (default ``"*.pcd"``), relative to
        the folder; None reads every file with a supported suffix (see
        :func:`read_scans`).
    {fields_to_scans}

    Raises
    ------
    OSError
        If the folder is missing or not a directory.
    ValueError
        If no file matches, `pattern` is empty or absolute, or a file is
        malformed.
    TypeError
        If `path` is not a str or os.PathLike, or `pattern` is not a str
        or None.

    Examples
    --------
    >>> import tempfile, os
    >>> from occgp.io import write_pcd
    >>> folder = tempfile.mkdtemp()
    >>> for i in (10, 2, 1):
    ...     write_pcd(os.path.join(folder, f"scan_{i}.pcd"), [[i, 0.0, 0.0]])
    >>> [s.points[0, 0] for s in load_scan_folder(folder)]
    [np.float64(1.0), np.float64(2.0), np.float64(10.0)]
    """
    folder = as_path(path)
    if pattern is not None and not isinstance(pattern, str):
        raise TypeError(f"pattern must be a str or None, got {type(pattern).__name__}")
    if pattern is not None and (not pattern or os.path.isabs(pattern) or "\0" in pattern):
        raise ValueError(f"pattern must be a non-empty glob relative to the folder, got {pattern!r}")
    if fields is not None:
        bin_record(fields, folder)  # check it before reading anything
    if not folder.exists():
        raise FileNotFoundError(2, "no such directory", str(folder))
    if not folder.is_dir():
        raise NotADirectoryError(20, "expected a directory", str(folder))
    if pattern is None:
        files = [p for p in folder.iterdir() if p.is_file() and scan_kind(p) is not None]
    else:
        try:
            files = [p for p in folder.glob(pattern) if p.is_file()]
        except (ValueError, NotImplementedError) as exc:
            raise ValueError(f"pattern {pattern!r} is not a valid glob ({exc})") from None
    if not files:
        what = "supported scan files" if pattern is None else f"files matching {pattern!r}"
        raise ValueError(f"{folder}: no {what} in the folder")
    scans = []
    for f in sorted(files, key=natural_key):
        scans.extend(read_scans(f, fields=fields))
    return scans


@fill_doc(fields_to_scans=_FIELDS_TO_SCANS)
def read_scans(path, *, fields=None) -> list:
    """Read scans from a file or folder, choosing the reader by suffix.

    ==============================================  ==========================
    suffix                                          reader
    ==============================================  ==========================
    ``.pcd``                                        :func:`read_pcd`
    ``.bin`` (KITTI), ``.pcd.bin`` (nuScenes)       :func:`read_kitti_bin`
    ``.graph``                                      :func:`read_scan_graph`
    ``.xyz .txt .dat .log`` (+ ``.bz2 .gz .xz``)    :func:`read_xyz`, or
                                                    :func:`read_scan_log` if
                                                    the file has NODE lines
    a directory                                     :func:`load_scan_folder`
                                                    (every supported file)
    ==============================================  ==========================

    nuScenes' ``*.pcd.bin`` files are binary records, not PCD: they go to
    :func:`read_kitti_bin` with its nuScenes layout.

    Parameters
    ----------
    path : str or os.PathLike
        A scan file or a folder of them.
    {fields_to_scans}

    Raises
    ------
    OSError
        If the path does not exist or cannot be read.
    ValueError
        For an unsupported suffix or malformed content.
    TypeError
        If `path` is not a str or os.PathLike, or `fields` has a wrong type.

    Examples
    --------
    >>> import tempfile, os
    >>> from pathlib import Path
    >>> path = os.path.join(tempfile.mkdtemp(), "scan.txt")
    >>> _ = Path(path).write_text("1 2 3\\n")
    >>> len(read_scans(path))
    1
    """
    path = as_path(path)
    if fields is not None:
        bin_record(fields, path)  # check it whatever the file
    if path.is_dir():
        return load_scan_folder(path, pattern=None, fields=fields)
    if not path.exists():
        raise FileNotFoundError(2, "no such file or directory", str(path))
    kind = scan_kind(path)
    if kind == "pcd":
        return [read_pcd(path)]
    if kind == "bin":
        return [read_kitti_bin(path, fields=fields)]
    if kind == "graph":
        return read_scan_graph(path)
    if kind == "text":
        text = read_text(path)
        if re.search(r"^\s*NODE\b", text, flags=re.MULTILINE):
            return _scan_log_from_text(text, path)
        return [Scan(drop_non_finite(_parse_xyz(text, path), path), np.zeros(3))]
    raise ValueError(
        f"{path}: unsupported scan file suffix {''.join(path.suffixes)!r}; expected .pcd, "
        ".bin, .graph, .xyz/.txt/.dat/.log (optionally .bz2/.gz/.xz) or a directory"
    )
