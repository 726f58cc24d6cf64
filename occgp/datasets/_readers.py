"""Readers (and a few writers) for range-scan files.

KITTI Velodyne ``.bin``, OctoMap ScanGraph ``.graph``, plain-text point
lists (``.xyz`` / ``.txt`` / ``.dat``, optionally ``.bz2`` / ``.gz``
compressed), OctoMap plain-text scan logs (``NODE`` lines), folders of
scans, and :func:`read_scans`, which dispatches on the suffix. Every reader
raises :class:`OSError` for a missing or unreadable file and
:class:`ValueError`, naming the file and what is wrong, for malformed or
truncated content.
"""

import io
import re
import struct
import warnings

import numpy as np
from numpy.typing import ArrayLike

from ._fileio import as_path, read_bytes, read_maybe_compressed
from ._pcd import read_pcd
from ._scan import Scan, _make_scan

__all__ = [
    "read_kitti_bin", "read_scan_graph", "write_scan_graph", "read_xyz", "read_scan_log",
    "load_scan_folder", "read_scans",
]

_TEXT_SUFFIXES = (".xyz", ".txt", ".dat", ".log")
_COMPRESSED = (".bz2", ".gz", ".xz")


def _quat_to_matrix(q):
    """Rotation matrix of the unit quaternion ``(w, x, y, z)`` (normalised first)."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q)
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


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
# KITTI
# --------------------------------------------------------------------------- #
def read_kitti_bin(path, origin: ArrayLike = (0.0, 0.0, 0.0)) -> Scan:
    """Read a KITTI Velodyne scan: float32 records ``x y z reflectance``.

    Parameters
    ----------
    path : str or os.PathLike
    origin : array-like of shape (3,), default=(0, 0, 0)
        Sensor origin (KITTI points are in the sensor frame).

    Returns
    -------
    scan : Scan

    Raises
    ------
    OSError
        If the file is missing or unreadable.
    ValueError
        If its size is not a multiple of 16 bytes (truncated file).

    Examples
    --------
    >>> import tempfile, os
    >>> path = os.path.join(tempfile.mkdtemp(), "000000.bin")
    >>> np.array([[1, 2, 3, 0.5]], dtype=np.float32).tofile(path)
    >>> read_kitti_bin(path).points.tolist()
    [[1.0, 2.0, 3.0]]
    """
    path = as_path(path)
    raw = read_bytes(path)
    if len(raw) % 16:
        raise ValueError(
            f"{path}: KITTI .bin size {len(raw)} bytes is not a multiple of 16 "
            "(float32 x y z reflectance records); the file is truncated or not a KITTI scan"
        )
    data = np.frombuffer(raw, dtype="<f4").reshape(-1, 4)
    return _make_scan(data[:, :3].astype(np.float64), origin)


# --------------------------------------------------------------------------- #
# OctoMap ScanGraph (.graph)
# --------------------------------------------------------------------------- #
_POINT = np.dtype([("n", "<i4"), ("xyz", "<f8", (3,))])  # 28 bytes, packed
_POSE = np.dtype([("tn", "<i4"), ("t", "<f8", (3,)), ("qn", "<i4"), ("q", "<f8", (4,))])
_EDGE = np.dtype([("first", "<u4"), ("second", "<u4"), ("pose", _POSE), ("weight", "<f8")])


class _Cursor:
    """Bounds-checked reading of a byte buffer (truncation -> ValueError)."""

    def __init__(self, raw, path):
        self.raw, self.pos, self.path = raw, 0, path

    def take(self, dtype, count, what):
        need = np.dtype(dtype).itemsize * count
        have = len(self.raw) - self.pos
        if have < need:
            raise ValueError(
                f"{self.path}: truncated ScanGraph file: expected {need} bytes for {what} at "
                f"offset {self.pos}, found {have}"
            )
        out = np.frombuffer(self.raw, dtype=dtype, count=count, offset=self.pos)
        self.pos += need
        return out

    def uint32(self, what):
        return int(self.take("<u4", 1, what)[0])


def read_scan_graph(path) -> list:
    """Read an OctoMap ScanGraph binary file (``.graph``) as a list of scans.

    Layout (little-endian): uint32 node count; per node a Pointcloud (uint32
    n, then n Vector3 = int32 3 + 3 float64), a Pose6D (Vector3 translation,
    Quaternion = int32 4 + float64 w x y z) and a uint32 id; then uint32 edge
    count and the edges (uint32 ids, Pose6D, float64 weight). Node points
    are in the sensor frame; they are returned in the world frame,
    ``R(q) p + t``, with origin ``t``.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    scans : list of Scan

    Raises
    ------
    OSError
        If the file is missing or unreadable.
    ValueError
        If the file is truncated (the message gives the bytes expected and
        found), has trailing bytes, or its Vector3 / Quaternion tags are
        not 3 / 4.

    Examples
    --------
    >>> import tempfile, os
    >>> path = os.path.join(tempfile.mkdtemp(), "scans.graph")
    >>> write_scan_graph(path, [Scan(np.array([[1.0, 0, 0]]), np.array([0.0, 0, 1]))])
    >>> [s.points.tolist() for s in read_scan_graph(path)]
    [[[1.0, 0.0, 0.0]]]
    """
    path = as_path(path)
    cur = _Cursor(read_bytes(path), path)
    n_nodes = cur.uint32("the node count")
    scans = []
    for i in range(n_nodes):
        n_points = cur.uint32(f"the point count of node {i}")
        block = cur.take(_POINT, n_points, f"the {n_points} points of node {i}")
        pose = cur.take(_POSE, 1, f"the pose of node {i}")[0]
        cur.uint32(f"the id of node {i}")
        if n_points and np.any(block["n"] != 3):
            raise ValueError(f"{path}: malformed ScanGraph: a point of node {i} is not tagged 3")
        if pose["tn"] != 3 or pose["qn"] != 4:
            raise ValueError(f"{path}: malformed ScanGraph: bad pose tags in node {i}")
        q = pose["q"]
        if not np.all(np.isfinite(q)) or np.linalg.norm(q) == 0:
            raise ValueError(f"{path}: malformed ScanGraph: node {i} has quaternion {q.tolist()}")
        rotation = _quat_to_matrix(q)
        points = block["xyz"] @ rotation.T + pose["t"]
        scans.append(_make_scan(points, pose["t"].copy()))
    n_edges = cur.uint32("the edge count")
    edges = cur.take(_EDGE, n_edges, f"{n_edges} edges")
    if n_edges and (np.any(edges["pose"]["tn"] != 3) or np.any(edges["pose"]["qn"] != 4)):
        raise ValueError(f"{path}: malformed ScanGraph: bad pose tags in an edge")
    if cur.pos != len(cur.raw):
        raise ValueError(
            f"{path}: malformed ScanGraph: {len(cur.raw) - cur.pos} unexpected bytes after "
            f"the {n_edges} edges (expected {cur.pos} bytes in all)"
        )
    return scans


def write_scan_graph(path, scans) -> None:
    """Write scans as an OctoMap ScanGraph binary file readable by ``graph2tree``.

    Each scan becomes a node whose pose is its origin with identity
    rotation and whose points are stored relative to it (``points -
    origin``); no edges are written.

    Parameters
    ----------
    path : str or os.PathLike
    scans : sequence of Scan or (points, origin) pairs

    Raises
    ------
    ValueError
        If a scan has bad shapes.
    OSError
        If the file cannot be written.

    Examples
    --------
    >>> import tempfile, os
    >>> path = os.path.join(tempfile.mkdtemp(), "scans.graph")
    >>> write_scan_graph(path, [Scan(np.zeros((5, 3)), np.zeros(3))])
    >>> os.path.getsize(path)                 # 4 + 4 + 5 * 28 + 64 + 4 + 4
    220
    """
    path = as_path(path)
    chunks = [struct.pack("<I", len(scans))]
    for i, scan in enumerate(scans):
        points, origin = _make_scan(*scan, source=f"scans[{i}].points")
        block = np.zeros(len(points), dtype=_POINT)
        block["n"] = 3
        block["xyz"] = points - origin
        pose = np.zeros(1, dtype=_POSE)
        pose["tn"], pose["t"], pose["qn"], pose["q"] = 3, origin, 4, (1.0, 0.0, 0.0, 0.0)
        chunks += [struct.pack("<I", len(points)), block.tobytes(), pose.tobytes(),
                   struct.pack("<I", i)]
    chunks.append(struct.pack("<I", 0))
    with open(path, "wb") as fh:
        fh.write(b"".join(chunks))


# --------------------------------------------------------------------------- #
# plain text
# --------------------------------------------------------------------------- #
def _text_of(path):
    raw = read_maybe_compressed(path)
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not a text file (invalid UTF-8)") from None


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
    if not np.isfinite(table).all():
        row = int(np.argmax(~np.isfinite(table).all(axis=1)))
        raise ValueError(f"{path}: point {row} (counting from 0) is not finite (NaN or inf)")
    return table


def read_xyz(path, origin: ArrayLike = (0.0, 0.0, 0.0)) -> Scan:
    """Read a plain-text point list, one ``x y z`` per line.

    Extra columns are ignored, ``#`` comments and blank lines skipped;
    ``.bz2``, ``.gz`` and ``.xz`` files are decompressed transparently
    (by suffix).

    Parameters
    ----------
    path : str or os.PathLike
    origin : array-like of shape (3,), default=(0, 0, 0)
        Sensor origin.

    Returns
    -------
    scan : Scan

    Raises
    ------
    OSError
        If the file is missing or unreadable.
    ValueError
        For a malformed line (with its line number where numpy reports
        it), non-finite values, a corrupt compressed stream, or ``NODE``
        lines (an OctoMap scan log: use :func:`read_scan_log`).

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
    text = _text_of(path)
    if re.search(r"^\s*NODE\b", text, flags=re.MULTILINE):
        raise ValueError(
            f"{path}: contains NODE lines (an OctoMap scan log with poses); "
            "read it with read_scan_log"
        )
    return _make_scan(_parse_xyz(text, path), origin)


def read_scan_log(path) -> list:
    """Read an OctoMap plain-text scan log (the input of ``log2graph``).

    Each scan starts with ``NODE x y z roll pitch yaw`` (the sensor pose;
    angles in radians, rotation ``Rz(yaw) Ry(pitch) Rx(roll)``) followed by
    its points in the sensor frame, one ``x y z`` per line. Points are
    returned in the world frame. Compressed files are handled as in
    :func:`read_xyz`.

    Returns
    -------
    scans : list of Scan

    Raises
    ------
    OSError
        If the file is missing or unreadable.
    ValueError
        If a point comes before the first NODE line, or a line is malformed.

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
    return _scan_log_from_text(_text_of(path), path)


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
        points = local @ _euler_to_matrix(*pose[3:]).T + t
        scans.append(_make_scan(points, t))
    return scans


# --------------------------------------------------------------------------- #
# folders and dispatch
# --------------------------------------------------------------------------- #
def _natural_key(path):
    parts = re.split(r"(\d+)", path.name)
    return [(0, int(p), "") if p.isdigit() else (1, 0, p.lower()) for p in parts]


def _kind(path):
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


def load_scan_folder(path, pattern: str | None = "*.pcd") -> list:
    """Read a folder of scan files (la3dm style), in natural file-name order.

    Files are sorted by the numbers in their names (``scan_2`` before
    ``scan_10``), not lexicographically.

    Parameters
    ----------
    path : str or os.PathLike
        The folder.
    pattern : str or None, optional
        Glob pattern of the files to read (default ``"*.pcd"``); None reads every file with a
        supported suffix (see :func:`read_scans`).

    Returns
    -------
    scans : list of Scan

    Raises
    ------
    OSError
        If the folder is missing or not a directory.
    ValueError
        If no file matches, or a file is malformed.

    Examples
    --------
    >>> import tempfile, os
    >>> from occgp.datasets import write_pcd
    >>> folder = tempfile.mkdtemp()
    >>> for i in (10, 2, 1):
    ...     write_pcd(os.path.join(folder, f"scan_{i}.pcd"), [[i, 0.0, 0.0]])
    >>> [s.points[0, 0] for s in load_scan_folder(folder)]
    [np.float64(1.0), np.float64(2.0), np.float64(10.0)]
    """
    folder = as_path(path)
    if not folder.exists():
        raise FileNotFoundError(2, "no such directory", str(folder))
    if not folder.is_dir():
        raise NotADirectoryError(20, "expected a directory", str(folder))
    if pattern is None:
        files = [p for p in folder.iterdir() if p.is_file() and _kind(p) is not None]
    else:
        files = [p for p in folder.glob(pattern) if p.is_file()]
    if not files:
        what = "supported scan files" if pattern is None else f"files matching {pattern!r}"
        raise ValueError(f"{folder}: no {what} in the folder")
    scans = []
    for f in sorted(files, key=_natural_key):
        scans.extend(read_scans(f))
    return scans


def read_scans(path) -> list:
    """Read scans from a file or folder, choosing the reader by suffix.

    ==============================================  ==========================
    suffix                                          reader
    ==============================================  ==========================
    ``.pcd``                                        :func:`read_pcd`
    ``.bin``                                        :func:`read_kitti_bin`
    ``.graph``                                      :func:`read_scan_graph`
    ``.xyz .txt .dat .log`` (+ ``.bz2 .gz .xz``)    :func:`read_xyz`, or
                                                    :func:`read_scan_log` if
                                                    the file has NODE lines
    a directory                                     :func:`load_scan_folder`
                                                    (every supported file)
    ==============================================  ==========================

    Returns
    -------
    scans : list of Scan

    Raises
    ------
    OSError
        If the path does not exist or cannot be read.
    ValueError
        For an unsupported suffix or malformed content.

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
    if path.is_dir():
        return load_scan_folder(path, pattern=None)
    if not path.exists():
        raise FileNotFoundError(2, "no such file or directory", str(path))
    kind = _kind(path)
    if kind == "pcd":
        return [read_pcd(path)]
    if kind == "bin":
        return [read_kitti_bin(path)]
    if kind == "graph":
        return read_scan_graph(path)
    if kind == "text":
        text = _text_of(path)
        if re.search(r"^\s*NODE\b", text, flags=re.MULTILINE):
            return _scan_log_from_text(text, path)
        return [_make_scan(_parse_xyz(text, path), np.zeros(3))]
    raise ValueError(
        f"{path}: unsupported scan file suffix {''.join(path.suffixes)!r}; expected .pcd, "
        ".bin, .graph, .xyz/.txt/.dat/.log (optionally .bz2/.gz/.xz) or a directory"
    )
