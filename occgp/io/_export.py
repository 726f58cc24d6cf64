"""Maps out: PLY, PCD and Open3D exports of a log-odds map.

The functions take the map (an :class:`occgp.OccupancyOctree` or an
:class:`occgp.GridMap`) as their first argument; the maps' methods of the same
names call them. PLY files are written by occgp itself (no third-party PLY
library); PCD files through :func:`occgp.io.write_pcd`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._atomic import atomic_open
from .._map_types import check_log_odds_map
from .._params import renamed_keywords
from .._validation import as_path, check_bool, check_choice, check_int
from ._pcd import write_pcd

if TYPE_CHECKING:  # annotations only: the maps import this module
    from ..octree._logodds import LogOddsMap

__all__ = ["save_ply", "save_pcd", "to_open3d", "MAX_VOXELS", "pack_rgb", "unpack_rgb"]

#: Default cap on the finest voxels :func:`to_open3d` builds (about 56 bytes each
#: while the voxel grid is built: centers, colours and Open3D's own copy).
MAX_VOXELS = 2**22
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


# --------------------------------------------------------------------------- #
# helpers
# --------------------------------------------------------------------------- #
def _check_map(tree: object) -> LogOddsMap:
    return check_log_odds_map(tree)


def _selected_leaves(tree: LogOddsMap, occupied: bool, with_colors: bool = False):
    """(centers, sizes, probabilities) of the occupied (or the free) leaves, and with
    `with_colors` their colours (uint8 (n, 3); None for a map without colours)."""
    occupied = check_bool(occupied, "occupied")
    table = (getattr(tree, "leaves", None) or getattr(tree, "cells"))()
    centers, sizes, values = table[:3]
    colors = getattr(table, "colors", None)
    if hasattr(tree, "_log_odds_thresholds"):
        threshold = np.float32(tree._log_odds_thresholds()[2])
    else:  # liboctomap's logodds(): float of log(p / (1 - p))
        p = tree.occupancy_threshold
        threshold = np.float32(np.log(p / (1.0 - p)))
    keep = (values >= threshold) == occupied
    centers, sizes, values = centers[keep], sizes[keep], values[keep]
    # liboctomap's probability(): 1 - 1 / (1 + exp(l))
    prob = 1.0 - 1.0 / (1.0 + np.exp(values.astype(np.float64)))
    out = np.ascontiguousarray(centers), np.ascontiguousarray(sizes), prob
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
            f"than {cap_name}={max_cells}; raise {cap_name}, or export the leaf centers "
            f"(kind='points')")
    return total


@renamed_keywords(centres="centers")
def leaf_cells(centers: np.ndarray, sizes: np.ndarray,
               resolution: float) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The finest cells that leaves cover: their integer indices (the cell of edge
    `resolution` whose center is ``(index + 0.5) * resolution``), shape (n, 3), and for
    each the row of its leaf. A leaf of edge ``resolution * 2**k`` covers ``8**k`` cells;
    callers check the total first (:func:`_check_cap`). The keyword ``centres``, the
    old name of `centers`, is deprecated."""
    k, _ = _level_counts(sizes, resolution)
    total = int(np.sum(np.left_shift(np.int64(1), 3 * k))) if len(k) else 0
    index = np.empty((total, 3), dtype=np.int64)
    owner = np.empty(total, dtype=np.int64)
    pos = 0
    for level in np.unique(k):  # at most 17 levels; vectorised within each
        rows = np.flatnonzero(k == level)
        side = 1 << int(level)
        # integer index of each leaf's lowest finest cell (exact: |index| <= 2**15)
        low = np.rint(centers[rows] / resolution - side / 2.0).astype(np.int64)
        ar = np.arange(side)
        offsets = np.stack(np.meshgrid(ar, ar, ar, indexing="ij"), axis=-1).reshape(-1, 3)
        n = len(rows) * len(offsets)
        index[pos:pos + n] = (low[:, None, :] + offsets[None]).reshape(-1, 3)
        owner[pos:pos + n] = np.repeat(rows, side**3)
        pos += n
    return index, owner


def _expand_leaves(centers, sizes, resolution, max_cells, what, cap_name):
    """Finest-cell centers of leaves, and for each the index of its leaf.

    The centers are computed as liboctomap's ``keyToCoord`` at depth 16 computes
    them: ``(index + 0.5) * resolution``.
    """
    _check_cap(sizes, resolution, max_cells, what, cap_name)
    index, owner = leaf_cells(centers, sizes, resolution)
    return (index + 0.5) * resolution, owner


def _finest_cells(tree: LogOddsMap, occupied: bool = True,
                  max_cells: int = MAX_VOXELS) -> NDArray[np.float64]:
    """Centers of the finest cells (edge = resolution) that the selected leaves cover.

    Pruned leaves are expanded to their ``8**k`` finest cells, whose centers are
    liboctomap's ``keyToCoord`` at depth 16 (the centers of the map after
    :meth:`~occgp.OccupancyOctree.expand`).

    Raises
    ------
    ValueError
        If they are more than `max_cells` (checked before any allocation).
    """
    _check_map(tree)
    max_cells = check_int(max_cells, "max_cells", low=0)
    centers, sizes, _ = _selected_leaves(tree, occupied)[:3]
    what = "occupied" if occupied else "free"
    return _expand_leaves(centers, sizes, tree.resolution, max_cells, what, "max_cells")[0]


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
    """Write `tree`'s occupied (or free) cells to a PLY file: :meth:`occgp.OccupancyOctree.save_ply`."""
    _check_map(tree)
    binary = check_bool(binary, "binary")
    cubes = check_bool(cubes, "cubes")
    color = check_bool(color, "color")
    centers, sizes, prob, own_colors = _selected_leaves(tree, occupied, with_colors=True)
    path = as_path(path)
    n = len(centers)
    if cubes and n > _MAX_CUBES:
        raise ValueError(f"save_ply(cubes=True) writes at most {_MAX_CUBES} cubes (int32 "
                         f"vertex indices), the map has {n} such leaves; use cubes=False")
    columns = [("x", "f4"), ("y", "f4"), ("z", "f4"), ("size", "f4"), ("probability", "f4")]
    if color:
        columns += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
    per_leaf = np.column_stack([centers, sizes, prob]) if n else np.empty((0, 5))
    if color:
        per_leaf = np.column_stack([per_leaf, _height_colors(centers[:, 2])
                                    if own_colors is None else own_colors])
    if cubes:
        vertices = np.repeat(per_leaf, 8, axis=0)
        corners = (centers[:, None, :]
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
    with atomic_open(path) as fh:  # an OSError names the path
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
    """Write `tree`'s occupied (or free) leaf centers to a PCD file: :meth:`occgp.OccupancyOctree.save_pcd`."""
    _check_map(tree)
    binary = check_bool(binary, "binary")
    centers, _, prob, colors = _selected_leaves(tree, occupied, with_colors=True)
    path = as_path(path)
    fields = {"intensity": prob.astype(np.float32)}
    if colors is not None:
        fields["rgb"] = pack_rgb(colors)
    write_pcd(path, centers, data="binary" if binary else "ascii", fields=fields)


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
    """`tree`'s occupied (or free) cells as an Open3D geometry: :meth:`occgp.OccupancyOctree.to_open3d`."""
    _check_map(tree)
    kind = check_choice(kind, "kind", _KINDS)
    max_voxels = check_int(max_voxels, "max_voxels", low=0)
    centers, sizes, _, own_colors = _selected_leaves(tree, occupied, with_colors=True)
    res = tree.resolution
    what = "occupied" if occupied else "free"
    if kind == "voxels":  # the cap first: a ValueError is the same with or without Open3D
        _check_cap(sizes, res, max_voxels, what, "max_voxels")
    o3d = _import_open3d()
    if kind == "voxels":
        centers, owner = _expand_leaves(centers, sizes, res, max_voxels, what, "max_voxels")
        if own_colors is not None:
            own_colors = own_colors[owner]
    cloud = o3d.geometry.PointCloud()
    cloud.points = o3d.utility.Vector3dVector(centers)
    rgb = _height_colors(centers[:, 2]) if own_colors is None else own_colors
    cloud.colors = o3d.utility.Vector3dVector(rgb / 255.0)
    if kind == "points":
        return cloud
    if len(centers) == 0:
        grid = o3d.geometry.VoxelGrid()
        grid.voxel_size = res
        return grid
    # voxel index floor((center - low) / res): centers sit mid-voxel, far from a boundary
    low = centers.min(axis=0) - 0.5 * res
    high = centers.max(axis=0) + 0.5 * res
    return o3d.geometry.VoxelGrid.create_from_point_cloud_within_bounds(cloud, res, low, high)
