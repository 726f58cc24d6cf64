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
import os
import re
import struct
import warnings

import numpy as np
from numpy.typing import ArrayLike

from .._atomic import write_bytes
from .._docfill import fill_doc
from ..io._fileio import READER_SECTIONS, as_path, read_bytes, read_text
from ..io._pcd import read_pcd
from ..io._scan import Scan, drop_non_finite, make_scan, check_origin

__all__ = [
    "BIN_LAYOUTS", "read_kitti_bin", "read_scan_graph", "write_scan_graph", "read_xyz", "read_scan_log",
    "load_scan_folder", "read_scans",
]

_TEXT_SUFFIXES = (".xyz", ".txt", ".dat", ".log")
#: The `fields` parameter and the Returns section of the folder and dispatch readers.
_FIELDS_TO_SCANS = """fields : int, str or numpy.dtype, optional
    Record layout of ``.bin`` files, passed to :func:`read_kitti_bin`
    (default: by file name).

Returns
-------
scans : list of Scan"""
_COMPRESSED = (".bz2", ".gz", ".xz")


def _quat_to_matrix(q):
    """Rotation matrix of the unit quaternion ``(w, x, y, z)`` (normalised first).

    `q` must be finite and non-zero; it is scaled by its largest component
    first, so that no square overflows.
    """
    q = np.asarray(q, dtype=np.float64)
    q = q / np.max(np.abs(q))
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
# KITTI / nuScenes .bin
# --------------------------------------------------------------------------- #
#: Named record layouts of :func:`read_kitti_bin`: name -> (float32 fields, description).
BIN_LAYOUTS = {
    "kitti": (4, "KITTI: float32 x y z reflectance"),
    "nuscenes": (5, "nuScenes: float32 x y z intensity ring_index"),
}
_MAX_BIN_FIELDS = 1024
#: Names of the fields after x y z in the named layouts (``return_fields=True``).
_BIN_NAMES = {"kitti": ["reflectance"], "nuscenes": ["intensity", "ring"]}


def _bin_record(fields, path):
    """Return (record dtype with fields x, y, z, description) for :func:`read_kitti_bin`."""
    if fields is None:
        fields = "nuscenes" if path.name.lower().endswith(".pcd.bin") else "kitti"
    if isinstance(fields, str):
        key = fields.lower()
        if key not in BIN_LAYOUTS:
            raise ValueError(
                f"fields must be a number of float32 fields, a numpy record dtype or one of "
                f"{sorted(BIN_LAYOUTS)}, got {fields!r}"
            )
        n, what = BIN_LAYOUTS[key]
        names = ["x", "y", "z"] + _BIN_NAMES[key]
        return np.dtype({"names": names, "formats": ["<f4"] * n}), what
    elif isinstance(fields, np.dtype):
        if fields.names is None or not {"x", "y", "z"} <= set(fields.names):
            raise ValueError(f"fields as a dtype must be a record dtype with fields x, y and z, "
                             f"got {fields}")
        for axis in "xyz":
            sub = fields.fields[axis][0]
            if sub.kind not in "fiu" or sub.shape != ():
                raise ValueError(
                    f"fields: the field {axis!r} must be a scalar number type, got {sub}"
                )
        if fields.itemsize == 0:
            raise ValueError(f"fields: the record dtype {fields} has size 0")
        return fields, f"records of dtype {fields}"
    elif isinstance(fields, (int, np.integer)) and not isinstance(fields, (bool, np.bool_)):
        fields = int(fields)
        if not 3 <= fields <= _MAX_BIN_FIELDS:
            raise ValueError(
                f"fields must be between 3 and {_MAX_BIN_FIELDS} float32 fields per record "
                f"(x y z first), got {fields}"
            )
        what = next((d for n, d in BIN_LAYOUTS.values() if n == fields),
                    f"{fields} float32 fields, x y z first")
    else:
        raise TypeError(
            "fields must be None, an int (float32 fields per record), a layout name "
            f"({', '.join(sorted(BIN_LAYOUTS))}) or a numpy record dtype, got "
            f"{type(fields).__name__}"
        )
    names = ["x", "y", "z"] + [f"f{k}" for k in range(3, fields)]
    return np.dtype({"names": names, "formats": ["<f4"] * fields}), what


@fill_doc(**READER_SECTIONS)
def read_kitti_bin(path, origin: ArrayLike = (0.0, 0.0, 0.0), *, fields=None,
                   return_fields: bool = False):
    """Read a KITTI or nuScenes lidar scan: packed records whose first fields are x y z.

    KITTI Velodyne files (``*.bin``) hold float32 ``x y z reflectance``
    records (16 bytes); nuScenes files (``*.pcd.bin``, binary despite the
    name) hold float32 ``x y z intensity ring_index`` records (20 bytes). The
    layout is chosen by the file name unless `fields` says otherwise; a name
    cannot be told from the size alone (34,688 nuScenes points are 693,760
    bytes, a multiple of 16 too). Points with a NaN or inf coordinate are
    dropped, and their number logged on the ``"occgp"`` logger (PCL's
    habit).

    Parameters
    ----------
    path : str or os.PathLike
    origin : array-like of shape (3,), default=(0, 0, 0)
        Sensor origin (KITTI and nuScenes points are in the sensor frame).
        Must be finite.
    fields : int, str or numpy.dtype, optional
        The record layout. None (default) picks ``"nuscenes"`` for names
        ending in ``.pcd.bin`` and ``"kitti"`` otherwise. A name:
        ``"kitti"`` (4 float32) or ``"nuscenes"`` (5 float32). An int
        ``n`` (3 to 1024): records of ``n`` little-endian float32 values,
        x y z first (e.g. ``fields=3`` for bare ``x y z``). A numpy record
        dtype with fields ``x``, ``y`` and ``z`` for any other layout, e.g.
        ``np.dtype([("x", "<f8"), ("y", "<f8"), ("z", "<f8"), ("t", "<u4")])``.
    return_fields : bool, default=False
        Also return the fields after x y z, by name, for the points kept
        (same order as ``scan.points``).

    Returns
    -------
    scan : Scan
    extra : dict of str to ndarray of shape (n_points,)
        Only if `return_fields`. The named layouts name their fields:
        ``"kitti"`` gives ``{"reflectance": float32}``, ``"nuscenes"``
        ``{"intensity": float32, "ring": int64}`` (the laser index, 0 to 31
        on nuScenes' HDL-32E, counted from the bottom beam: pass it to
        ``occgp.iln.range_image_from_points(points, model, ring=...)``); an
        int layout names its extra fields ``"f3"``, ``"f4"``, ...; a record
        dtype gives its own field names (values in the dtype's native byte
        order).

    {raises_oserror}
    ValueError
        If the file size is not a whole number of records (the message
        gives the file, its size and the record size, and suggests
        ``fields=5`` when a KITTI-named file fits nuScenes' layout), if
        `fields` is not a known layout, or `origin` is not of shape (3,)
        or not finite; with `return_fields`, if a nuScenes ring index of a
        kept point is not a finite integer in [0, 2**31).
    TypeError
        If `path`, `origin`, `fields` or `return_fields` has a wrong type.

    Examples
    --------
    >>> import tempfile, os
    >>> folder = tempfile.mkdtemp()
    >>> path = os.path.join(folder, "000000.bin")
    >>> np.array([[1, 2, 3, 0.5]], dtype=np.float32).tofile(path)
    >>> read_kitti_bin(path).points.tolist()
    [[1.0, 2.0, 3.0]]
    >>> path = os.path.join(folder, "n008__LIDAR_TOP__1533151603547590.pcd.bin")
    >>> np.array([[1, 2, 3, 7, 31]], dtype=np.float32).tofile(path)
    >>> read_kitti_bin(path).points.tolist()
    [[1.0, 2.0, 3.0]]
    >>> scan, extra = read_kitti_bin(path, return_fields=True)
    >>> extra["ring"].tolist(), extra["intensity"].tolist()
    ([31], [7.0])
    """
    path = as_path(path)
    origin = check_origin(origin)
    if not isinstance(return_fields, (bool, np.bool_)):
        raise TypeError(f"return_fields must be a bool, got {type(return_fields).__name__}")
    record, what = _bin_record(fields, path)
    raw = read_bytes(path)
    if len(raw) % record.itemsize:
        hint = ""
        if fields is None and record.itemsize == 16 and len(raw) % 20 == 0:
            hint = ("; it is a whole number of nuScenes records: pass fields=5 (or 'nuscenes'), "
                    "or name the file *.pcd.bin")
        elif fields is None and record.itemsize == 20 and len(raw) % 16 == 0:
            hint = "; it is a whole number of KITTI records: pass fields=4 (or 'kitti')"
        raise ValueError(
            f"{path}: size {len(raw)} bytes is not a multiple of {record.itemsize}, the size of "
            f"a record ({what}); the file is truncated or has another layout{hint}"
        )
    data = np.frombuffer(raw, dtype=record)
    points = np.empty((len(data), 3))
    with np.errstate(over="ignore", invalid="ignore"):
        for k, axis in enumerate("xyz"):
            points[:, k] = data[axis]
    scan = Scan(drop_non_finite(points, path), origin)
    if not return_fields:
        return scan
    keep = np.isfinite(points).all(axis=1)
    extra = {}
    for name in record.names:
        if name in ("x", "y", "z"):
            continue
        values = data[name][keep]
        values = values.astype(values.dtype.newbyteorder("="))
        if name == "ring" and (fields is None or isinstance(fields, str)):  # nuScenes' layout
            values = _ring_index(values, path)
        extra[name] = values
    return scan, extra


def _ring_index(values, path):
    """nuScenes ring indices (stored as float32) as int64, checked."""
    with np.errstate(invalid="ignore"):
        bad = ~(np.isfinite(values) & (values >= 0) & (values < 2**31) & (values == np.round(values)))
    if bad.any():
        bad = values[bad][0]
        raise ValueError(f"{path}: the ring field must hold integer laser indices, "
                         f"found {float(bad)!r}")
    return values.astype(np.int64)


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


@fill_doc(**READER_SECTIONS)
def read_scan_graph(path) -> list:
    """Read an OctoMap ScanGraph binary file (``.graph``) as a list of scans.

    Layout (little-endian): uint32 node count; per node a Pointcloud (uint32
    n, then n Vector3 = int32 3 + 3 float64), a Pose6D (Vector3 translation,
    Quaternion = int32 4 + float64 w x y z) and a uint32 id; then uint32 edge
    count and the edges (uint32 ids, Pose6D, float64 weight). Node points
    are in the sensor frame; they are returned in the world frame,
    ``R(q) p + t``, with origin ``t``. Points with a NaN or inf coordinate
    (stored so, or overflowing in the transform) are dropped, and their
    number logged on the ``"occgp"`` logger (PCL's habit).

    {path_to_scans}

    {raises_oserror}
    ValueError
        If the file is truncated (the message gives the bytes expected and
        found), has trailing bytes, its Vector3 / Quaternion tags are not
        3 / 4, a quaternion is zero or not finite, or a node position is
        not finite.
    {path_type_error}

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
        q, t = pose["q"], pose["t"]
        if not np.all(np.isfinite(q)) or not np.any(q):
            raise ValueError(f"{path}: malformed ScanGraph: node {i} has quaternion {q.tolist()}")
        if not np.all(np.isfinite(t)):
            raise ValueError(
                f"{path}: malformed ScanGraph: node {i} has a non-finite position (origin) "
                f"{t.tolist()}"
            )
        rotation = _quat_to_matrix(q)
        with np.errstate(over="ignore", invalid="ignore"):
            points = block["xyz"] @ rotation.T + t
        scans.append(Scan(drop_non_finite(points, f"{path} node {i}"), t.copy()))
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


@fill_doc(**READER_SECTIONS)
def write_scan_graph(path, scans) -> None:
    """Write scans as an OctoMap ScanGraph binary file readable by ``graph2tree``.

    Each scan becomes a node whose pose is its origin with identity
    rotation and whose points are stored relative to it (``points -
    origin``); no edges are written.

    The file is written atomically: a temporary file beside `path` replaces
    it once complete, so the previous file stays intact if the write fails.

    Parameters
    ----------
    path : str or os.PathLike
    scans : sequence of Scan or (points, origin) pairs

    Raises
    ------
    ValueError
        If a scan has bad shapes or non-finite points or origin.
    TypeError
        If `path` is not a str or os.PathLike, or `scans` is not a sequence
        of Scan or (points, origin) pairs.
    {unwritable}

    Examples
    --------
    >>> import tempfile, os
    >>> path = os.path.join(tempfile.mkdtemp(), "scans.graph")
    >>> write_scan_graph(path, [Scan(np.zeros((5, 3)), np.zeros(3))])
    >>> os.path.getsize(path)                 # 4 + 4 + 5 * 28 + 64 + 4 + 4
    220
    """
    path = as_path(path)
    if isinstance(scans, (str, bytes, np.ndarray)) or not hasattr(scans, "__iter__"):
        raise TypeError(
            f"scans must be a sequence of Scan or (points, origin) pairs, got {type(scans).__name__}"
        )
    scans = list(scans)
    checked = []
    for i, scan in enumerate(scans):
        try:
            points, origin = scan
        except (TypeError, ValueError):
            raise TypeError(
                f"scans[{i}] must be a Scan or a (points, origin) pair, got {type(scan).__name__}"
            ) from None
        points, origin = make_scan(points, origin, source=f"scans[{i}].points",
                                    origin_name=f"scans[{i}].origin")
        if not np.isfinite(points).all():
            raise ValueError(f"scans[{i}].points must be finite (no NaN or inf)")
        if len(points) >= 2**32:
            raise ValueError(f"scans[{i}].points has {len(points)} points; a ScanGraph node "
                             "holds fewer than 2**32")
        checked.append((points, origin))
    chunks = [struct.pack("<I", len(checked))]
    for i, (points, origin) in enumerate(checked):
        block = np.zeros(len(points), dtype=_POINT)
        block["n"] = 3
        block["xyz"] = points - origin
        pose = np.zeros(1, dtype=_POSE)
        pose["tn"], pose["t"], pose["qn"], pose["q"] = 3, origin, 4, (1.0, 0.0, 0.0, 0.0)
        chunks += [struct.pack("<I", len(points)), block.tobytes(), pose.tobytes(),
                   struct.pack("<I", i)]
    chunks.append(struct.pack("<I", 0))
    write_bytes(path, b"".join(chunks))


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
    >>> from occgp.datasets import write_pcd
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
        _bin_record(fields, folder)  # check it before reading anything
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
        _bin_record(fields, path)  # check it whatever the file
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
