"""Maps out: PLY, PCD and Open3D exports of a log-odds map, and a distance field.

The functions take the map (an :class:`occgp.OccupancyOctree` or an
:class:`occgp.GridMap`) as their first argument; the maps' methods of the same
names call them. PLY files are written by occgp itself (no third-party PLY
library); PCD files through :func:`occgp.datasets.write_pcd`.
"""

from __future__ import annotations

import importlib
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._logodds_map import LogOddsMap
from ._validation import as_numeric, as_path, check_bool, check_choice, check_int, check_real

__all__ = ["save_ply", "save_pcd", "to_open3d", "distance_field", "DistanceField",
           "MAX_VOXELS", "MAX_DISTANCE_CELLS", "pack_rgb", "unpack_rgb"]

#: Default cap on the finest voxels :func:`to_open3d` builds (about 56 bytes each
#: while the voxel grid is built: centres, colours and Open3D's own copy).
MAX_VOXELS = 2**22
#: Default cap on the cells of a :func:`distance_field` grid (about 30 bytes each
#: at peak: the distances, the obstacle mask and scipy's feature transform).
MAX_DISTANCE_CELLS = 2**23
#: The most cubes one PLY mesh holds: 8 vertices each, indexed by int32.
_MAX_CUBES = (2**31 - 1) // 8
#: Rows formatted at a time in ASCII files (bounds the memory of the text).
_ASCII_CHUNK = 65536
#: viridis at 0, 1/4, 1/2, 3/4 and 1 (matplotlib's colour map, CC0).
_VIRIDIS = np.array([[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98],
                     [253, 231, 37]], dtype=np.float64)
_VIRIDIS_AT = np.linspace(0.0, 1.0, len(_VIRIDIS))
# The 12 triangles of a cube, counter-clockwise seen from outside (outward normals),
# over corners numbered bx + 2 * by + 4 * bz (b = 0: low side, 1: high side).
_CUBE_CORNERS = np.array([[(c >> a) & 1 for a in range(3)] for c in range(8)], dtype=np.float64)
_CUBE_QUADS = np.array([[0, 4, 6, 2], [1, 3, 7, 5], [0, 1, 5, 4],
                        [2, 6, 7, 3], [0, 2, 3, 1], [4, 5, 7, 6]])
_CUBE_TRIANGLES = np.concatenate([_CUBE_QUADS[:, [0, 1, 2]], _CUBE_QUADS[:, [0, 2, 3]]])
_KINDS = ("voxels", "points")
_UNKNOWN = ("occupied", "free")


class DistanceField(NamedTuple):
    """A Euclidean distance field on a regular grid (see :func:`distance_field`)."""

    #: Distance (metres) from each cell's centre to the nearest obstacle cell's
    #: centre, shape (nx, ny, nz), indexed [i, j, k] along x, y, z; 0 in obstacle
    #: cells, inf everywhere when the grid holds no obstacle.
    distances: NDArray[np.float64]
    #: The grid's minimum corner, shape (3,): cell [i, j, k] spans
    #: ``origin + [i, j, k] * resolution`` to ``origin + [i + 1, j + 1, k + 1] * resolution``.
    origin: NDArray[np.float64]
    #: Edge of the grid's cells, in metres.
    resolution: float

    def centers(self) -> NDArray[np.float64]:
        """Centres of every cell of the grid.

        Returns
        -------
        centers : ndarray of shape (nx, ny, nz, 3)
            In metres, indexed as `distances`.
        """
        axes = [self.origin[a] + (np.arange(n) + 0.5) * self.resolution
                for a, n in enumerate(self.distances.shape)]
        return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)


# --------------------------------------------------------------------------- #
# helpers
# --------------------------------------------------------------------------- #
def _check_map(tree: object) -> LogOddsMap:
    if not isinstance(tree, LogOddsMap):
        raise TypeError(f"tree must be an OccupancyOctree or a GridMap, got "
                        f"{type(tree).__name__}")
    return tree


def _selected_leaves(tree: LogOddsMap, occupied: bool, with_colors: bool = False):
    """(centres, sizes, probabilities) of the occupied (or the free) leaves, and with
    `with_colors` their colours (uint8 (n, 3); None for a map without colours)."""
    occupied = check_bool(occupied, "occupied")
    table = (getattr(tree, "leaves", None) or getattr(tree, "cells"))()
    centres, sizes, values = table[:3]
    colors = getattr(table, "colors", None)
    if hasattr(tree, "_log_odds_thresholds"):
        threshold = np.float32(tree._log_odds_thresholds()[2])
    else:  # liboctomap's logodds(): float of log(p / (1 - p))
        p = tree.occupancy_threshold
        threshold = np.float32(np.log(p / (1.0 - p)))
    keep = (values >= threshold) == occupied
    centres, sizes, values = centres[keep], sizes[keep], values[keep]
    # liboctomap's probability(): 1 - 1 / (1 + exp(l))
    prob = 1.0 - 1.0 / (1.0 + np.exp(values.astype(np.float64)))
    out = np.ascontiguousarray(centres), np.ascontiguousarray(sizes), prob
    if with_colors:
        return (*out, None if colors is None else np.ascontiguousarray(colors[keep]))
    return out


def _height_colors(z: np.ndarray) -> NDArray[np.uint8]:
    """viridis colours (uint8, shape (n, 3)) of heights `z`, spread over their range."""
    if len(z) == 0:
        return np.empty((0, 3), dtype=np.uint8)
    lo, hi = float(z.min()), float(z.max())
    t = (z - lo) / (hi - lo) if hi > lo else np.full(len(z), 0.5)
    rgb = np.column_stack([np.interp(t, _VIRIDIS_AT, _VIRIDIS[:, c]) for c in range(3)])
    return np.rint(rgb).astype(np.uint8)


def _level_counts(sizes: np.ndarray, resolution: float):
    """Per leaf, its level k (edge = resolution * 2**k) and 2**k."""
    k = np.rint(np.log2(sizes / resolution)).astype(np.int64) if len(sizes) else \
        np.empty(0, dtype=np.int64)
    return k, np.left_shift(np.int64(1), k)


def _check_cap(sizes, resolution, max_cells, what, cap_name) -> int:
    """The number of finest cells the leaves of `sizes` cover, at most `max_cells`."""
    m = _level_counts(sizes, resolution)[1]
    total = int(np.sum(m**3)) if len(m) else 0  # disjoint leaves: at most 2**48
    if total > max_cells:
        raise ValueError(
            f"the {what} leaves expand to {total} finest cells of {resolution:g} m, more "
            f"than {cap_name}={max_cells}; raise {cap_name}, or export the leaf centres "
            f"(kind='points')")
    return total


def _expand_leaves(centres, sizes, resolution, max_cells, what, cap_name):
    """Finest-cell centres of leaves, and for each the index of its leaf.

    A leaf of edge ``resolution * 2**k`` yields ``8**k`` cells whose centres are
    computed as liboctomap's ``keyToCoord`` at depth 16 computes them:
    ``(index + 0.5) * resolution``.
    """
    k, _ = _level_counts(sizes, resolution)
    total = _check_cap(sizes, resolution, max_cells, what, cap_name)
    out = np.empty((total, 3))
    owner = np.empty(total, dtype=np.int64)
    pos = 0
    for level in np.unique(k):  # at most 17 levels; vectorised within each
        rows = np.flatnonzero(k == level)
        side = 1 << int(level)
        # integer index of each leaf's lowest finest cell (exact: |index| <= 2**15)
        low = np.rint(centres[rows] / resolution - side / 2.0)
        ar = np.arange(side, dtype=np.float64)
        offsets = np.stack(np.meshgrid(ar, ar, ar, indexing="ij"), axis=-1).reshape(-1, 3)
        block = ((low[:, None, :] + offsets[None]) + 0.5) * resolution
        n = block.shape[0] * block.shape[1]
        out[pos:pos + n] = block.reshape(-1, 3)
        owner[pos:pos + n] = np.repeat(rows, side**3)
        pos += n
    return out, owner


def _finest_cells(tree: LogOddsMap, occupied: bool = True,
                  max_cells: int = MAX_VOXELS) -> NDArray[np.float64]:
    """Centres of the finest cells (edge = resolution) that the selected leaves cover.

    Pruned leaves are expanded to their ``8**k`` finest cells, whose centres are
    liboctomap's ``keyToCoord`` at depth 16 (the centres of the map after
    :meth:`~occgp.OccupancyOctree.expand`).

    Raises
    ------
    ValueError
        If they are more than `max_cells` (checked before any allocation).
    """
    _check_map(tree)
    max_cells = check_int(max_cells, "max_cells", low=0)
    centres, sizes, _ = _selected_leaves(tree, occupied)[:3]
    what = "occupied" if occupied else "free"
    return _expand_leaves(centres, sizes, tree.resolution, max_cells, what, "max_cells")[0]


def _ascii_rows(fh, table: np.ndarray, fmts: list[str]) -> None:
    """Write the rows of a float64 `table` as text, one ``%`` format per column."""
    row = " ".join(fmts) + "\n"
    for start in range(0, len(table), _ASCII_CHUNK):
        chunk = table[start:start + _ASCII_CHUNK]
        fh.write(((row * len(chunk)) % tuple(chunk.ravel().tolist())).encode("ascii"))


# --------------------------------------------------------------------------- #
# PLY
# --------------------------------------------------------------------------- #
def save_ply(tree: LogOddsMap, path, *, occupied: bool = True, binary: bool = True,
             cubes: bool = False, color: bool = True) -> None:
    """Write the occupied (or the free) cells of a map to a PLY file.

    With ``cubes=False`` the file is a point cloud: one vertex per leaf, at
    its centre. With ``cubes=True`` it is a triangle mesh: each leaf is a cube
    of 8 vertices and 12 triangles (counter-clockwise seen from outside), so
    that mesh viewers (MeshLab, CloudCompare, Open3D) show the voxels. Every
    vertex carries the properties

    * ``x y z`` (float): the centre (points) or a corner (cubes), in metres;
    * ``size`` (float): the leaf's edge (pruned leaves are larger than the
      resolution);
    * ``probability`` (float): the leaf's occupancy probability;
    * ``red green blue`` (uchar, with `color`): the leaf's own colour for
      a colour map (:class:`occgp.color.ColorOctree`; ``255 255 255`` where a
      leaf has none), otherwise a viridis colour of the leaf's height, spread
      from the lowest to the highest cell.

    A ``comment`` line records the map's resolution. Faces are
    ``property list uchar int vertex_indices``.

    Parameters
    ----------
    tree : OccupancyOctree, ColorOctree or GridMap
    path : str or os.PathLike
        Destination (overwritten).
    occupied : bool, default=True
        True: the leaves at or above the occupancy threshold; False: the
        known leaves below it.
    binary : bool, default=True
        ``binary_little_endian`` (True) or ``ascii`` (False) encoding.
    cubes : bool, default=False
        Write each leaf as a cube mesh instead of a point.
    color : bool, default=True
        Add the colours (the cells' own for a colour map, else by height).

    Raises
    ------
    TypeError
        If `tree` is not a map, `path` is not a str or os.PathLike, or a flag
        is not a bool.
    ValueError
        If ``cubes=True`` and the leaves are more than 268,435,455 (their
        vertex indices would overflow int32).
    OSError
        If the file cannot be written (missing folder, no permission); the
        message names the path.

    Notes
    -----
    Coordinates are stored in single precision, as liboctomap stores them:
    across the key range (``2**15`` cells each side) that resolves a cell to
    about 1/256 of its edge.

    Examples
    --------
    >>> import os, tempfile
    >>> from occgp import OccupancyOctree
    >>> m = OccupancyOctree(0.1).insert_scan([[1.0, 0.0, 0.0]], [0.0, 0.0, 0.0])
    >>> path = os.path.join(tempfile.mkdtemp(), "map.ply")
    >>> save_ply(m, path, binary=False)
    >>> print(open(path).read().splitlines()[-1])
    1.04999995 0.0500000007 0.0500000007 0.100000001 0.699999988 33 145 140
    """
    _check_map(tree)
    binary = check_bool(binary, "binary")
    cubes = check_bool(cubes, "cubes")
    color = check_bool(color, "color")
    centres, sizes, prob, own_colors = _selected_leaves(tree, occupied, with_colors=True)
    path = as_path(path)
    n = len(centres)
    if cubes and n > _MAX_CUBES:
        raise ValueError(f"save_ply(cubes=True) writes at most {_MAX_CUBES} cubes (int32 "
                         f"vertex indices), the map has {n} such leaves; use cubes=False")
    columns = [("x", "f4"), ("y", "f4"), ("z", "f4"), ("size", "f4"), ("probability", "f4")]
    if color:
        columns += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
    per_leaf = np.column_stack([centres, sizes, prob]) if n else np.empty((0, 5))
    if color:
        per_leaf = np.column_stack([per_leaf, _height_colors(centres[:, 2])
                                    if own_colors is None else own_colors])
    if cubes:
        vertices = np.repeat(per_leaf, 8, axis=0)
        corners = (centres[:, None, :]
                   + (_CUBE_CORNERS[None] - 0.5) * sizes[:, None, None]).reshape(-1, 3)
        vertices[:, :3] = corners
        faces = (np.arange(n, dtype=np.int64)[:, None, None] * 8
                 + _CUBE_TRIANGLES[None]).reshape(-1, 3)
    else:
        vertices, faces = per_leaf, None
    header = [
        "ply",
        f"format {'binary_little_endian' if binary else 'ascii'} 1.0",
        f"comment occgp {'occupied' if occupied else 'free'} cells, "
        f"resolution {tree.resolution!r}",
        f"element vertex {len(vertices)}",
    ]
    names = {"f4": "float", "u1": "uchar"}
    header += [f"property {names[t]} {name}" for name, t in columns]
    if cubes:
        header += [f"element face {len(faces)}", "property list uchar int vertex_indices"]
    header.append("end_header")
    with open(path, "wb") as fh:  # an OSError names the path
        fh.write(("\n".join(header) + "\n").encode("ascii"))
        if binary:
            record = np.dtype([(name, "<" + t) for name, t in columns])
            out = np.empty(len(vertices), dtype=record)
            for c, (name, _) in enumerate(columns):
                out[name] = vertices[:, c]
            fh.write(out.tobytes())
            if cubes:
                tri = np.empty(len(faces), dtype=[("n", "u1"), ("v", "<i4", (3,))])
                tri["n"] = 3
                tri["v"] = faces
                fh.write(tri.tobytes())
        else:
            # float32 values printed with 9 significant digits read back exactly
            vertices[:, :5] = vertices[:, :5].astype(np.float32)
            _ascii_rows(fh, vertices, ["%.9g"] * 5 + ["%d"] * (3 if color else 0))
            if cubes:
                _ascii_rows(fh, faces.astype(np.float64), ["3 %d", "%d", "%d"])


# --------------------------------------------------------------------------- #
# PCD
# --------------------------------------------------------------------------- #
def save_pcd(tree: LogOddsMap, path, *, occupied: bool = True, binary: bool = True) -> None:
    """Write the centres of the occupied (or the free) leaves to a PCD v0.7 file.

    Fields ``x y z intensity`` (float32), ``intensity`` being the leaf's
    occupancy probability (PCL's ``PointXYZI``); the viewpoint is the origin.
    A colour map (:class:`occgp.color.ColorOctree`) adds the field ``rgb``:
    the leaf's colour packed as ``r << 16 | g << 8 | b`` in a uint32
    (``TYPE U``; PCL's ``PointXYZRGB`` holds the same bits), ``0xFFFFFF`` for
    leaves without colour.
    Pruned leaves give one point at their centre (see
    :meth:`~occgp.OccupancyOctree.expand` for finest cells).

    Parameters
    ----------
    tree : OccupancyOctree, ColorOctree or GridMap
    path : str or os.PathLike
        Destination (overwritten).
    occupied : bool, default=True
        True: the leaves at or above the occupancy threshold; False: the
        known leaves below it.
    binary : bool, default=True
        ``DATA binary`` (True) or ``DATA ascii`` (False).

    Raises
    ------
    TypeError
        If `tree` is not a map, `path` is not a str or os.PathLike, or a flag
        is not a bool.
    OSError
        If the file cannot be written; the message names the path.

    See Also
    --------
    occgp.datasets.read_pcd : Reads the file back.

    Examples
    --------
    >>> import os, tempfile
    >>> from occgp import OccupancyOctree
    >>> from occgp.datasets import read_pcd
    >>> m = OccupancyOctree(0.1).insert_scan([[1.0, 0.0, 0.0]], [0.0, 0.0, 0.0])
    >>> path = os.path.join(tempfile.mkdtemp(), "map.pcd")
    >>> save_pcd(m, path)
    >>> scan, fields = read_pcd(path, return_fields=True)
    >>> scan.points.round(2).tolist(), fields["intensity"].round(2).tolist()
    ([[1.05, 0.05, 0.05]], [0.7])
    """
    # imported at run time: occgp.datasets is not part of the maps' import graph
    write_pcd = importlib.import_module("occgp.datasets._pcd").write_pcd
    _check_map(tree)
    binary = check_bool(binary, "binary")
    centres, _, prob, colors = _selected_leaves(tree, occupied, with_colors=True)
    path = as_path(path)
    fields = {"intensity": prob.astype(np.float32)}
    if colors is not None:
        fields["rgb"] = pack_rgb(colors)
    write_pcd(path, centres, data="binary" if binary else "ascii", fields=fields)


def pack_rgb(colors: np.ndarray) -> NDArray[np.uint32]:
    """uint8 colours (n, 3) packed as PCL packs them: ``r << 16 | g << 8 | b`` (uint32)."""
    c = np.asarray(colors, dtype=np.uint32).reshape(-1, 3)
    return (c[:, 0] << np.uint32(16)) | (c[:, 1] << np.uint32(8)) | c[:, 2]


def unpack_rgb(rgb: ArrayLike) -> NDArray[np.uint8]:
    """The uint8 colours (n, 3) of PCL-packed ``rgb`` values (uint32, or float32 bits)."""
    v = np.asarray(rgb)
    v = (v.view(np.uint32) if v.dtype == np.float32 else v.astype(np.uint32)).ravel()
    return np.column_stack([(v >> np.uint32(s)) & np.uint32(0xFF)
                            for s in (16, 8, 0)]).astype(np.uint8).reshape(-1, 3)


# --------------------------------------------------------------------------- #
# Open3D
# --------------------------------------------------------------------------- #
def _import_open3d():
    try:
        import open3d  # type: ignore[import-not-found]
    except ImportError as exc:
        raise ImportError(
            "to_open3d needs Open3D, which occgp installs with its extra `occgp[open3d]` "
            "(or: pip install open3d-cpu, or open3d)") from exc
    return open3d


def to_open3d(tree: LogOddsMap, *, kind: str = "voxels", occupied: bool = True,
              max_voxels: int = MAX_VOXELS):
    """The occupied (or the free) cells of a map as an Open3D geometry.

    Parameters
    ----------
    tree : OccupancyOctree or GridMap
    kind : {"voxels", "points"}, default="voxels"
        ``"voxels"``: an ``open3d.geometry.VoxelGrid`` of voxel size
        ``resolution``, aligned to the map's cells; pruned leaves are expanded
        to their finest cells. ``"points"``: an ``open3d.geometry.PointCloud``
        of the leaf centres (one point per leaf, pruned or not).
    occupied : bool, default=True
        True: the leaves at or above the occupancy threshold; False: the
        known leaves below it.
    max_voxels : int, default=4194304
        The most voxels ``kind="voxels"`` builds (about 56 bytes each); past
        it a ValueError is raised before any allocation (free space, which
        prunes into large leaves, reaches it first).

    Returns
    -------
    geometry : open3d.geometry.VoxelGrid or open3d.geometry.PointCloud
        Coloured by height (viridis, from the lowest to the highest cell), or
        with the cells' own colours for a colour map
        (:class:`occgp.color.ColorOctree`).

    Raises
    ------
    ImportError
        If Open3D is not installed (the extra ``occgp[open3d]``).
    TypeError
        If `tree` is not a map, `occupied` not a bool or `max_voxels` not an int.
    ValueError
        If `kind` is unknown, or the voxels would be more than `max_voxels`.
    """
    _check_map(tree)
    kind = check_choice(kind, "kind", _KINDS)
    max_voxels = check_int(max_voxels, "max_voxels", low=0)
    centres, sizes, _, own_colors = _selected_leaves(tree, occupied, with_colors=True)
    res = tree.resolution
    what = "occupied" if occupied else "free"
    if kind == "voxels":  # the cap first: a ValueError is the same with or without Open3D
        _check_cap(sizes, res, max_voxels, what, "max_voxels")
    o3d = _import_open3d()
    if kind == "voxels":
        centres, owner = _expand_leaves(centres, sizes, res, max_voxels, what, "max_voxels")
        if own_colors is not None:
            own_colors = own_colors[owner]
    cloud = o3d.geometry.PointCloud()
    cloud.points = o3d.utility.Vector3dVector(centres)
    rgb = _height_colors(centres[:, 2]) if own_colors is None else own_colors
    cloud.colors = o3d.utility.Vector3dVector(rgb / 255.0)
    if kind == "points":
        return cloud
    if len(centres) == 0:
        grid = o3d.geometry.VoxelGrid()
        grid.voxel_size = res
        return grid
    # voxel index floor((centre - low) / res): centres sit mid-voxel, far from a boundary
    low = centres.min(axis=0) - 0.5 * res
    high = centres.max(axis=0) + 0.5 * res
    return o3d.geometry.VoxelGrid.create_from_point_cloud_within_bounds(cloud, res, low, high)


# --------------------------------------------------------------------------- #
# distance field
# --------------------------------------------------------------------------- #
def distance_field(tree: LogOddsMap, bbox: ArrayLike, resolution: float | None = None, *,
                   unknown: str = "occupied",
                   max_cells: int = MAX_DISTANCE_CELLS) -> DistanceField:
    """Euclidean distance from each cell of a regular grid to the nearest obstacle.

    The grid covers the box `bbox` with cubic cells of edge `resolution`,
    aligned to its multiples: its minimum corner is
    ``floor(bbox[0] / resolution) * resolution`` and it reaches at least
    ``bbox[1]`` (a corner within 1e-9 cell of a multiple of `resolution`
    counts as on it). Each cell takes the map's state at its centre (occupied,
    free or unknown); obstacle cells are the occupied ones, plus the unknown
    ones when ``unknown="occupied"``. The distance, in metres, is from each
    cell's centre to the nearest obstacle cell's centre
    (``scipy.ndimage.distance_transform_edt`` with the cell edge as sampling),
    so obstacle cells hold 0 and a cell next to one holds `resolution`.
    Obstacles outside the box are not seen.

    Parameters
    ----------
    tree : OccupancyOctree or GridMap
    bbox : array-like of shape (2, 3)
        ``[min_corner, max_corner]`` in metres, finite, min < max on every axis.
    resolution : float, default=None
        Cell edge in metres; default: the map's resolution (then the grid's
        cells are the map's finest cells).
    unknown : {"occupied", "free"}, default="occupied"
        How cells the map knows nothing about count: as obstacles (the safe
        choice for planning) or as free space. Points outside the map's key
        range are unknown.
    max_cells : int, default=8388608
        The most cells the grid may have (about 30 bytes each at peak); past
        it a ValueError is raised before any allocation.

    Returns
    -------
    field : DistanceField
        Named tuple ``(distances, origin, resolution)``: `distances` of shape
        (nx, ny, nz) indexed along x, y, z (inf everywhere when the grid holds
        no obstacle), `origin` the grid's minimum corner, `resolution` its
        cell edge.

    Raises
    ------
    TypeError
        If `tree` is not a map, `bbox` does not hold numbers, `resolution` is
        not a real number or `max_cells` not an int.
    ValueError
        If `bbox` is not of shape (2, 3), not finite or not min < max;
        `resolution` not positive and finite; `unknown` not one of the
        choices; or the grid would have more than `max_cells` cells.

    Examples
    --------
    >>> from occgp import OccupancyOctree
    >>> m = OccupancyOctree(1.0).set_cells([[0.5, 0.5, 0.5]], [2.0])
    >>> field = distance_field(m, [[0, 0, 0], [3, 1, 1]], unknown="free")
    >>> field.distances[:, 0, 0].tolist(), field.origin.tolist()
    ([0.0, 1.0, 2.0], [0.0, 0.0, 0.0])
    """
    from scipy import ndimage  # type: ignore[import-untyped]

    _check_map(tree)
    box = as_numeric(bbox, "bbox")
    if box.shape != (2, 3):
        raise ValueError(f"bbox must have shape (2, 3) (min and max corner), got {box.shape}")
    box = box.astype(np.float64)
    if not np.isfinite(box).all():
        raise ValueError(f"bbox must be finite, got {box.tolist()}")
    if not (box[0] < box[1]).all():
        raise ValueError(f"bbox must have min < max on every axis, got {box.tolist()}")
    res = tree.resolution if resolution is None else check_real(resolution, "resolution",
                                                                 low=0.0)
    unknown = check_choice(unknown, "unknown", _UNKNOWN)
    max_cells = check_int(max_cells, "max_cells", low=1)
    with np.errstate(over="ignore", invalid="ignore"):
        # corners within 1e-9 cell of a multiple of res snap to it (0.3 / 0.1 is 2.9999...)
        q = box / res
        near = np.rint(q)
        q = np.where(np.abs(q - near) <= 1e-9 * np.maximum(1.0, np.abs(near)), near, q)
        first = np.floor(q[0])
        stop = np.ceil(q[1])
        counts = np.maximum(stop - first, 1.0)
        total = float(np.prod(counts))
    if not (np.isfinite(total) and total <= max_cells
            and np.isfinite(first).all() and np.isfinite(stop).all()):
        raise ValueError(
            f"bbox {box.tolist()} at resolution {res:g} m needs "
            f"{' x '.join(f'{c:.3g}' for c in counts)} cells, more than max_cells={max_cells}; "
            "use a smaller box or a coarser resolution")
    shape = tuple(int(c) for c in counts)
    origin = first * res
    obstacle = np.empty(shape, dtype=bool)
    axes = [origin[a] + (np.arange(n) + 0.5) * res for a, n in enumerate(shape)]
    yz = np.stack(np.meshgrid(axes[1], axes[2], indexing="ij"), axis=-1).reshape(-1, 2)
    per_slab = max(1, 2**20 // len(yz))
    for start in range(0, shape[0], per_slab):  # bounded memory for the query points
        xs = axes[0][start:start + per_slab]
        pts = np.column_stack([np.repeat(xs, len(yz)), np.tile(yz, (len(xs), 1))])
        occ, unk = tree.is_occupied(pts, return_unknown=True)
        block = occ | unk if unknown == "occupied" else occ
        obstacle[start:start + len(xs)] = block.reshape(len(xs), shape[1], shape[2])
    if not obstacle.any():
        return DistanceField(np.full(shape, np.inf), origin, res)
    distances = ndimage.distance_transform_edt(~obstacle, sampling=(res, res, res))
    return DistanceField(distances, origin, res)
