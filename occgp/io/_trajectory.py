"""Sensor trajectories: KITTI odometry poses, TUM trajectories, and posing scans.

:func:`read_kitti_poses` reads KITTI odometry ``poses.txt`` files (a 3 x 4
row-major ``[R | t]`` per line), :func:`read_tum_trajectory` the TUM RGB-D
format (``timestamp tx ty tz qx qy qz qw``), and :func:`apply_poses` moves
scans recorded in the sensor frame into the world frame.
"""

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._docfill import fill_doc
from .._validation import check_real
from ._fileio import READER_SECTIONS, read_text
from ._scan import Scan, make_scan

__all__ = ["read_kitti_poses", "read_tum_trajectory", "apply_poses"]

_ROT_TOL = 1e-3


def _lines(path):
    """(line number, tokens) of the non-blank, non-comment lines of a text file."""
    for i, line in enumerate(read_text(path).splitlines(), start=1):
        tokens = line.split("#", 1)[0].split()
        if tokens:
            yield i, tokens


def _parse_table(path, n_cols, what):
    """(line numbers, float table of shape (n, n_cols)); ValueError naming the line."""
    numbers, rows = [], []
    for i, tokens in _lines(path):
        if len(tokens) != n_cols:
            raise ValueError(f"{path}: line {i}: expected {n_cols} numbers ({what}), got "
                             f"{len(tokens)}")
        try:
            row = [float(v) for v in tokens]
        except ValueError:
            bad = next(v for v in tokens if not _is_float(v))
            raise ValueError(f"{path}: line {i}: expected {n_cols} numbers ({what}), got "
                             f"{bad[:40]!r}") from None
        numbers.append(i)
        rows.append(row)
    if not rows:
        raise ValueError(f"{path}: no poses in the file (expected lines of {n_cols} numbers: "
                         f"{what})")
    table = np.array(rows, dtype=np.float64)
    lines = np.array(numbers)
    bad = ~np.isfinite(table).all(axis=1)
    if bad.any():
        raise ValueError(f"{path}: line {lines[np.argmax(bad)]}: values must be finite (no NaN "
                         "or inf)")
    return lines, table


def _is_float(token):
    try:
        float(token)
    except ValueError:
        return False
    return True


def _bad_rotations(rot, tol):
    """(bad mask, max |R R^T - I|, det R) of rotations of shape (n, 3, 3)."""
    err = np.abs(rot @ np.swapaxes(rot, 1, 2) - np.eye(3)).max(axis=(1, 2))
    det = np.linalg.det(rot)
    return ~((err <= tol) & (det > 0)), err, det


def _check_tol(tol):
    return check_real(tol, "tol", low=0.0, high=1.0, low_open=False)


@fill_doc(**READER_SECTIONS)
def read_kitti_poses(path, *, tol: float = _ROT_TOL) -> NDArray[np.float64]:
    """Read a KITTI odometry pose file (``poses/XX.txt``).

    Each line holds 12 numbers, the first three rows of the 4 x 4 pose
    (sensor to world) in row-major order: ``r11 r12 r13 tx r21 ... tz``.
    Blank lines and ``#`` comments are skipped; ``.bz2`` / ``.gz`` /
    ``.xz`` files are decompressed by suffix.

    Parameters
    ----------
    path : str or os.PathLike
    tol : float, default=1e-3
        Largest accepted ``|R R^T - I|`` entry of each rotation (the files
        print about seven significant digits).

    Returns
    -------
    poses : ndarray of shape (n_poses, 4, 4)
        Homogeneous sensor-to-world transforms, one per line.

    {raises_oserror}
    ValueError
        For a line without exactly 12 numbers, a non-numeric or non-finite
        value, a rotation that is not orthonormal within `tol` or is a
        reflection (each with its line number), or a file without poses.
    {path_type_error}

    Examples
    --------
    >>> import tempfile, os
    >>> from pathlib import Path
    >>> path = os.path.join(tempfile.mkdtemp(), "poses.txt")
    >>> _ = Path(path).write_text("1 0 0 0.5 0 1 0 0 0 0 1 0\\n")
    >>> read_kitti_poses(path)[0, :3, 3].tolist()
    [0.5, 0.0, 0.0]
    """
    tol = _check_tol(tol)
    lines, table = _parse_table(path, 12, "a 3x4 row-major pose r11 r12 r13 tx ... tz")
    poses = np.zeros((table.shape[0], 4, 4))
    poses[:, :3, :] = table.reshape(-1, 3, 4)
    poses[:, 3, 3] = 1.0
    bad, err, det = _bad_rotations(poses[:, :3, :3], tol)
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f"{path}: line {lines[i]}: the rotation part is not orthonormal with "
                         f"det +1 (max |R R^T - I| = {err[i]:.3g}, det {det[i]:.3g}, "
                         f"tol={tol:g})")
    return poses


@fill_doc(**READER_SECTIONS)
def read_tum_trajectory(path, *, tol: float = _ROT_TOL):
    """Read a TUM RGB-D trajectory: ``timestamp tx ty tz qx qy qz qw`` per line.

    ``#`` comments and blank lines are skipped; compressed files are read
    as in :func:`read_kitti_poses`. Quaternions are normalised.

    Parameters
    ----------
    path : str or os.PathLike
    tol : float, default=1e-3
        Largest accepted ``| |q| - 1 |`` of each quaternion.

    Returns
    -------
    timestamps : ndarray of shape (n_poses,)
        Seconds, non-decreasing.
    poses : ndarray of shape (n_poses, 4, 4)
        Homogeneous sensor-to-world transforms.

    {raises_oserror}
    ValueError
        For a line without exactly 8 numbers, a non-numeric or non-finite
        value, a quaternion whose norm is not 1 within `tol`, a timestamp
        smaller than the previous one (each with its line number), or a
        file without poses.
    {path_type_error}

    Examples
    --------
    >>> import tempfile, os
    >>> from pathlib import Path
    >>> path = os.path.join(tempfile.mkdtemp(), "traj.txt")
    >>> _ = Path(path).write_text("# t x y z qx qy qz qw\\n0.5 1 2 3 0 0 0 1\\n")
    >>> t, poses = read_tum_trajectory(path)
    >>> t.tolist(), poses[0, :3, 3].tolist()
    ([0.5], [1.0, 2.0, 3.0])
    """
    from scipy.spatial.transform import Rotation  # type: ignore[import-untyped]

    tol = _check_tol(tol)
    lines, table = _parse_table(path, 8, "timestamp tx ty tz qx qy qz qw")
    q = table[:, 4:]
    scale = np.abs(q).max(axis=1, keepdims=True)  # no overflow in the norm
    norm = np.linalg.norm(q / np.where(scale > 0, scale, 1.0), axis=1) * scale[:, 0]
    bad = ~(np.abs(norm - 1.0) <= tol)
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f"{path}: line {lines[i]}: quaternion qx qy qz qw = "
                         f"{q[i].tolist()} has norm {norm[i]:.6g}; expected a unit quaternion "
                         f"(tol={tol:g})")
    back = np.diff(table[:, 0]) < 0
    if back.any():
        i = int(np.argmax(back)) + 1
        now, before = float(table[i, 0]), float(table[i - 1, 0])
        raise ValueError(f"{path}: line {lines[i]}: timestamp {now!r} is smaller than the "
                         f"previous one {before!r}")
    poses = np.zeros((table.shape[0], 4, 4))
    poses[:, :3, :3] = Rotation.from_quat(q).as_matrix()
    poses[:, :3, 3] = table[:, 1:4]
    poses[:, 3, 3] = 1.0
    return table[:, 0].copy(), poses


def check_poses(poses, n_scans: int, tol: float) -> NDArray[np.float64]:
    if isinstance(poses, tuple) and len(poses) == 2 and np.ndim(poses[0]) == 1:
        raise TypeError("poses must be an array of shape (n_scans, 4, 4) or (n_scans, 3, 4), "
                        "got a pair (read_tum_trajectory returns (timestamps, poses): pass "
                        "its poses)")
    try:
        poses = np.array(poses, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"poses must be an array of numbers of shape (n_scans, 4, 4) or "
                        f"(n_scans, 3, 4) ({exc})") from None
    if poses.ndim != 3 or poses.shape[1:] not in ((4, 4), (3, 4)):
        raise ValueError(f"poses must have shape (n_scans, 4, 4) or (n_scans, 3, 4), got "
                         f"{poses.shape}")
    if poses.shape[0] != n_scans:
        raise ValueError(f"poses has {poses.shape[0]} poses for {n_scans} scans; expected one "
                         "pose per scan")
    if not np.isfinite(poses).all():
        raise ValueError("poses must be finite (no NaN or inf)")
    if poses.shape[1] == 4:
        last = np.abs(poses[:, 3] - [0.0, 0.0, 0.0, 1.0]).max(axis=1) > 1e-9
        if last.any():
            i = int(np.argmax(last))
            raise ValueError(f"poses[{i}] must have last row [0, 0, 0, 1], got "
                             f"{poses[i, 3].tolist()}")
    bad, err, det = _bad_rotations(poses[:, :3, :3], tol)
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f"poses[{i}]: the rotation part is not orthonormal with det +1 "
                         f"(max |R R^T - I| = {err[i]:.3g}, det {det[i]:.3g}, tol={tol:g})")
    return poses


def apply_poses(scans, poses: ArrayLike, *, tol: float = _ROT_TOL) -> list:
    """Move scans from the sensor frame into the world frame.

    Scan ``i``'s points ``p`` become ``R_i p + t_i`` and its origin
    ``R_i o + t_i`` (the pose translation ``t_i`` for the usual sensor
    origin ``o = 0`` of sensor-frame files, e.g. :func:`read_kitti_bin`).

    Parameters
    ----------
    scans : iterable of Scan or of (points, origin) pairs
        Points of shape (n_points, 3) in the sensor frame.
    poses : array-like of shape (n_scans, 4, 4) or (n_scans, 3, 4)
        Sensor-to-world transforms ``[R | t]``, one per scan, as returned
        by :func:`read_kitti_poses` (or the poses of
        :func:`read_tum_trajectory`).
    tol : float, default=1e-3
        Largest accepted ``|R R^T - I|`` entry of each rotation.

    Returns
    -------
    scans : list of Scan
        New scans in the world frame; the inputs are not modified.

    Raises
    ------
    ValueError
        If `poses` has a wrong shape, not one pose per scan, non-finite
        values, a 4 x 4 last row other than ``[0, 0, 0, 1]`` or a rotation
        that is not orthonormal with det +1 within `tol`; or a scan's
        points / origin have a wrong shape or a non-finite origin.
    TypeError
        If `poses` is not numeric (or is the ``(timestamps, poses)`` pair
        of :func:`read_tum_trajectory`), or a scan is not a pair.

    Examples
    --------
    >>> import numpy as np
    >>> pose = np.eye(4); pose[:3, 3] = [10.0, 0.0, 0.0]
    >>> [scan] = apply_poses([Scan(np.array([[1.0, 2.0, 3.0]]), np.zeros(3))], [pose])
    >>> scan.points.tolist(), scan.origin.tolist()
    ([[11.0, 2.0, 3.0]], [10.0, 0.0, 0.0])
    """
    tol = _check_tol(tol)
    if isinstance(scans, Scan):
        raise TypeError("scans must be an iterable of Scan, got a single Scan (wrap it in a "
                        "list)")
    try:
        items = list(scans)
    except TypeError:
        raise TypeError(f"scans must be an iterable of Scan, got {type(scans).__name__}") from None
    checked = []
    for i, item in enumerate(items):
        try:
            points, origin = item
        except (TypeError, ValueError):
            raise TypeError(f"scans[{i}] must be a Scan or a (points, origin) pair, got "
                            f"{type(item).__name__}") from None
        checked.append(make_scan(points, origin, f"scans[{i}].points", f"scans[{i}].origin"))
    poses = check_poses(poses, len(checked), tol)
    out = []
    for scan, pose in zip(checked, poses):
        rot, trans = pose[:3, :3], pose[:3, 3]
        out.append(Scan(np.ascontiguousarray(scan.points @ rot.T + trans),
                        rot @ scan.origin + trans))
    return out
