"""OctoMap ScanGraph files (``.graph``): a binary list of posed point clouds, read by
:func:`read_scan_graph` and written by :func:`write_scan_graph`."""

import struct

import numpy as np

from .._atomic import write_bytes
from .._docfill import fill_doc
from ._fileio import READER_SECTIONS, as_path, read_bytes
from ._scan import Scan, drop_non_finite, make_scan

__all__ = ["read_scan_graph", "write_scan_graph"]


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
