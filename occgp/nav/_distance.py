"""Distance fields of a log-odds map on a regular grid (dense), and the transforms
the blocked :class:`occgp.DistanceMap` shares with it.

Every distance here is computed the same way: scipy's exact Euclidean feature
transform (``scipy.ndimage.distance_transform_edt(..., return_indices=True)``)
gives, for each cell, the index of its nearest feature cell; the squared offset
to it is summed in integers and the distance is ``sqrt(offset²) * resolution``
in float64. Two computations that find the same nearest distance therefore give
bit-identical values, whatever window of cells they ran on.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._map_types import check_log_odds_map
from .._validation import as_numeric, check_bool, check_choice, check_int, check_real

if TYPE_CHECKING:  # annotations only: the maps import this module
    from ..octree._logodds import LogOddsMap

__all__ = ["DistanceField", "distance_field", "MAX_DISTANCE_CELLS", "UNKNOWN_CHOICES",
           "check_distance_map", "nearest_features", "squared_offsets", "cells_of", "grid_of_box",
           "signed_transform", "finish", "closest_and_gradient"]

#: Default cap on the cells of a :func:`distance_field` grid (about 30 bytes each at
#: peak for an unsigned field without extras: the distances, the obstacle mask and
#: scipy's feature transform; a signed field, `return_closest` and `return_gradient`
#: add up to 60 more).
MAX_DISTANCE_CELLS = 2**23
#: How cells the map knows nothing about count.
UNKNOWN_CHOICES = ("occupied", "free")


class DistanceField(NamedTuple):
    """A Euclidean distance field on a regular grid (see :func:`distance_field`)."""

    #: Distance (metres) from each cell's center to the nearest obstacle cell's
    #: center, shape (nx, ny, nz), indexed [i, j, k] along x, y, z; 0 in obstacle
    #: cells, inf everywhere when the grid holds no obstacle. In a signed field,
    #: obstacle cells hold minus the distance to the nearest non-obstacle cell's
    #: center instead (see :meth:`occgp.OccupancyOctree.distance_field`).
    distances: NDArray[np.float64]
    #: The grid's minimum corner, shape (3,): cell [i, j, k] spans
    #: ``origin + [i, j, k] * resolution`` to ``origin + [i + 1, j + 1, k + 1] * resolution``.
    origin: NDArray[np.float64]
    #: Edge of the grid's cells, in metres.
    resolution: float

    def centers(self) -> NDArray[np.float64]:
        """Centers of every cell of the grid.

        Returns
        -------
        centers : ndarray of shape (nx, ny, nz, 3)
            In metres, indexed as `distances`.
        """
        axes = [self.origin[a] + (np.arange(n) + 0.5) * self.resolution
                for a, n in enumerate(self.distances.shape)]
        return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)


# --------------------------------------------------------------------------- #
# shared helpers (also used by the blocked DistanceMap)
# --------------------------------------------------------------------------- #
def check_distance_map(tree: object, name: str = "tree") -> LogOddsMap:
    """`tree` if it is a log-odds map (an OccupancyOctree or a GridMap), else TypeError."""
    return check_log_odds_map(tree, name)


def cells_of(points: np.ndarray, resolution: float) -> NDArray[np.int64]:
    """Integer indices ``floor(x / resolution)`` of the cells holding `points`, from the
    single-precision coordinates as liboctomap's ``coordToKey`` computes them (the
    key minus 32768)."""
    scaled = points.astype(np.float32).astype(np.float64) * (1.0 / resolution)
    with np.errstate(invalid="ignore", over="ignore"):
        return np.floor(np.clip(scaled, -2.0**40, 2.0**40)).astype(np.int64)


def nearest_features(features: np.ndarray) -> NDArray[np.int32] | None:
    """The index of the nearest True cell of a boolean array, per cell (scipy's exact
    Euclidean feature transform), shape ``(ndim, *features.shape)``; None when no cell
    is True. A True cell is its own nearest; ties are broken by scipy, deterministically
    for a given array."""
    from scipy import ndimage  # type: ignore[import-untyped]

    if not features.any():
        return None
    return ndimage.distance_transform_edt(~features, return_distances=False,
                                          return_indices=True)


def squared_offsets(indices: np.ndarray, region: tuple[slice, ...]) -> NDArray[np.int64]:
    """Integer squared distance, in cells, from each cell of `region` (a tuple of slices
    of the transformed array) to its nearest feature (`indices`, from
    :func:`nearest_features`)."""
    out = np.zeros(tuple(sl.stop - sl.start for sl in region), dtype=np.int64)
    for a, sl in enumerate(region):
        here = np.arange(sl.start, sl.stop, dtype=np.int64)
        shape = [1] * len(region)
        shape[a] = len(here)
        diff = indices[a][region].astype(np.int64) - here.reshape(shape)
        out += diff * diff
    return out


# --------------------------------------------------------------------------- #
# the dense field
# --------------------------------------------------------------------------- #
def grid_of_box(bbox: ArrayLike, res: float, max_cells: float):
    """(shape, origin) of the grid of cells of edge `res` that covers `bbox`."""
    box = as_numeric(bbox, "bbox")
    if box.shape != (2, 3):
        raise ValueError(f"bbox must have shape (2, 3) (min and max corner), got {box.shape}")
    box = box.astype(np.float64)
    if not np.isfinite(box).all():
        raise ValueError(f"bbox must be finite, got {box.tolist()}")
    if not (box[0] < box[1]).all():
        raise ValueError(f"bbox must have min < max on every axis, got {box.tolist()}")
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
    return tuple(int(c) for c in counts), first


def _obstacles(tree: LogOddsMap, shape, origin, res, unknown: str) -> NDArray[np.bool_]:
    """The obstacle mask of the grid: the map's state at each cell's center."""
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
    return obstacle


def signed_transform(obstacle: np.ndarray, signed: bool, region: tuple[slice, ...]):
    """Squared distances (int64, cells) and nearest-cell indices (int32, shape
    (3, *region shape), -1 where none) over `region` of the obstacle mask.

    Outside obstacles: the nearest obstacle cell. In obstacle cells: the cell itself
    (squared distance 0), or with `signed` the nearest non-obstacle cell and the
    squared distance to it (negated by the caller). No such cell: squared distance
    -1 and index -1.
    """
    inside = obstacle[region]
    shape = inside.shape
    d2 = np.full(shape, -1, dtype=np.int64)
    near = np.full((3, *shape), -1, dtype=np.int32)
    # a transform runs only if the region has cells that need it
    if not inside.all():
        idx = nearest_features(obstacle)
        if idx is not None:
            d2[...] = squared_offsets(idx, region)
            near[...] = idx[(slice(None), *region)]
    if signed:
        d2[inside] = -1
        near[:, inside] = -1
        idx = nearest_features(~obstacle) if inside.any() else None
        if idx is not None:
            d2_in = squared_offsets(idx, region)
            d2[inside] = d2_in[inside]
            near[:, inside] = idx[(slice(None), *region)][:, inside]
    elif inside.any():          # an obstacle cell is its own nearest obstacle
        d2[inside] = 0
        here = np.meshgrid(*[np.arange(sl.start, sl.stop, dtype=np.int32) for sl in region],
                           indexing="ij")
        for a in range(3):
            near[a][inside] = here[a][inside]
    return d2, near


def finish(d2: np.ndarray, inside: np.ndarray, signed: bool, res: float,
           max_distance: float | None = None):
    """Distances (float64) from squared offsets; a mask of the cells with a nearest
    cell within reach. Missing nearest cells give ±inf (or ±max_distance)."""
    has = d2 >= 0
    dist = np.where(has, np.sqrt(np.maximum(d2, 0).astype(np.float64)) * res, np.inf)
    if max_distance is not None:
        has &= dist <= max_distance
        dist = np.minimum(dist, max_distance)
    if signed:
        dist = np.where(inside, -dist, dist)
    return dist, has


def closest_and_gradient(cells: np.ndarray, near: np.ndarray, has: np.ndarray,
                         dist: np.ndarray, origin: np.ndarray, res: float,
                         want_closest: bool, want_gradient: bool):
    """Centers of the nearest cells and the unit gradient, for cells of integer index
    `cells` (..., 3) whose nearest cell index is `near` (..., 3) (grid indices from
    `origin`). NaN where `has` is False; a zero gradient where the distance is 0."""
    out = []
    center = origin + (near + 0.5) * res
    center[~has] = np.nan
    if want_closest:
        out.append(center)
    if want_gradient:
        here = origin + (cells + 0.5) * res
        with np.errstate(invalid="ignore", divide="ignore"):
            grad = (here - center) / dist[..., None]
        grad[has & (dist == 0)] = 0.0
        out.append(grad)
    return out


def distance_field(tree: LogOddsMap, bbox: ArrayLike, resolution: float | None = None, *,
                   unknown: str = "occupied", max_cells: int = MAX_DISTANCE_CELLS,
                   signed: bool = False, return_closest: bool = False,
                   return_gradient: bool = False):
    """The distance field of `tree` over a box: :meth:`occgp.OccupancyOctree.distance_field`."""
    check_distance_map(tree)
    res = tree.resolution if resolution is None else check_real(resolution, "resolution",
                                                                 low=0.0)
    unknown = check_choice(unknown, "unknown", UNKNOWN_CHOICES)
    max_cells = check_int(max_cells, "max_cells", low=1)
    signed = check_bool(signed, "signed")
    return_closest = check_bool(return_closest, "return_closest")
    return_gradient = check_bool(return_gradient, "return_gradient")
    shape, first = grid_of_box(bbox, res, max_cells)
    origin = first * res
    obstacle = _obstacles(tree, shape, origin, res, unknown)
    region = tuple(slice(0, n) for n in shape)
    d2, near = signed_transform(obstacle, signed, region)
    dist, has = finish(d2, obstacle, signed, res)
    field = DistanceField(dist, origin, res)
    if not (return_closest or return_gradient):
        return field
    cells = np.stack(np.meshgrid(*[np.arange(n) for n in shape], indexing="ij"), axis=-1)
    extras = closest_and_gradient(cells, np.moveaxis(near, 0, -1), has, dist, origin, res,
                                  return_closest, return_gradient)
    return (field, *extras)
