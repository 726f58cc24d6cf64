"""Maps for planners: the 2D projection of a height band, and frontiers.

:func:`project_2d` and :func:`frontiers` are methods of the log-odds maps
(:class:`occgp.OccupancyOctree`, :class:`occgp.ColorOctree`,
:class:`occgp.GridMap`), which bind them in their class bodies (``project_2d =
_planning.project_2d``), so their first argument is the map, named ``self``;
they read the map's cells through ``leaves()`` (the octrees) or ``cells()`` (the
grid). Everything works on the map's integer cell
indices: finest cell ``i`` spans ``[i * resolution, (i + 1) * resolution)`` on
each axis, and a leaf of edge ``resolution * 2**k`` spans ``2**k`` of them.
Leaves are never expanded: the cells a set of boxes covers come from a
difference array over the output grid (one ``+1`` / ``-1`` per box corner,
then cumulative sums along each axis), so a pruned leaf costs as much as a
finest one.
"""

from __future__ import annotations

import inspect
import itertools

import numpy as np
from numpy.typing import ArrayLike

from ._frontiers import Frontiers, empty_frontiers, find_frontiers
from ._map2d import OccupancyGrid2D
from .._validation import as_numeric, check_int, check_real

__all__ = ["project_2d", "frontiers", "MAX_GRID_CELLS", "MAX_FRONTIER_CELLS", "box_counts",
           "grid_span", "as_box"]

#: Default cap on the cells of a :func:`project_2d` grid (about 10
#: bytes each at peak: two int32 coverage counts and the int8 states).
MAX_GRID_CELLS = 2**25
#: Default cap on the cells of the 3D state grid :func:`frontiers`
#: builds (about 14 bytes each at peak, with scipy's labels).
MAX_FRONTIER_CELLS = 2**24
#: Finest cell indices the maps can hold: keys 0 .. 65535 less 32768.
_KEY_LOW, _KEY_HIGH = -32768, 32767


def _snapped(q: np.ndarray) -> np.ndarray:
    """`q` with values within 1e-9 (relative) of an integer moved onto it: 0.3 / 0.1
    is 2.9999999999999996, and a corner at 0.3 m is on the cell boundary."""
    near = np.rint(q)
    return np.where(np.abs(q - near) <= 1e-9 * np.maximum(1.0, np.abs(near)), near, q)


def as_box(bbox: ArrayLike, dims: int, name: str = "bbox") -> np.ndarray:
    """`bbox` as a float64 array of shape (2, dims), finite, min < max on every axis."""
    box = as_numeric(bbox, name)
    if box.shape != (2, dims):
        raise ValueError(f"{name} must have shape (2, {dims}) (min and max corner), "
                         f"got {box.shape}")
    box = box.astype(np.float64)
    if not np.isfinite(box).all():
        raise ValueError(f"{name} must be finite, got {box.tolist()}")
    if not (box[0] < box[1]).all():
        raise ValueError(f"{name} must have min < max on every axis, got {box.tolist()}")
    return box


def grid_span(box: np.ndarray, cell: float, max_cells: int,
              name: str = "bbox") -> tuple[np.ndarray, tuple[int, ...]]:
    """The grid of cells of edge `cell`, aligned to its multiples, that covers `box`:
    (index of its first cell per axis, as floats; its shape). ValueError naming
    `name` when it would have more than `max_cells` cells."""
    with np.errstate(over="ignore", invalid="ignore"):
        q = _snapped(box / cell)
        first, stop = np.floor(q[0]), np.ceil(q[1])
        counts = np.maximum(stop - first, 1.0)
        total = float(np.prod(counts))
    if not (np.isfinite(total) and total <= max_cells and np.isfinite(first).all()):
        raise ValueError(
            f"{name} {box.tolist()} at resolution {cell:g} m needs "
            f"{' x '.join(f'{c:.3g}' for c in counts)} cells, more than "
            f"max_cells={max_cells}; use a smaller box, a coarser resolution or a "
            "larger max_cells")
    return first, tuple(int(c) for c in counts)


def box_counts(shape: tuple[int, ...], lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Which cells of a grid of `shape` the integer boxes ``lo[b] .. hi[b]`` (inclusive,
    inside the grid) cover: a boolean array of `shape`, without a loop over boxes."""
    d = len(shape)
    dtype = np.int32 if len(lo) < 2**31 - 1 else np.int64   # counts <= the number of boxes
    diff = np.zeros(tuple(n + 1 for n in shape), dtype=dtype)
    for corner in itertools.product((0, 1), repeat=d):
        index = tuple(hi[:, a] + 1 if c else lo[:, a] for a, c in enumerate(corner))
        np.add.at(diff, index, dtype(-1 if sum(corner) % 2 else 1))
    for axis in range(d):
        np.cumsum(diff, axis=axis, out=diff)
    return diff[tuple(slice(0, n) for n in shape)] > 0


def _leaf_boxes(tree, occupied_only: bool, key_lo: np.ndarray,
                key_hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lowest finest index (n, 3), edge in finest cells (n,)) of the map's leaves
    (or only the occupied ones) that may overlap the finest-index box
    ``key_lo .. key_hi``; the caller tests the overlap exactly."""
    res = tree.resolution
    lo = np.clip(key_lo, _KEY_LOW, _KEY_HIGH)
    hi = np.clip(key_hi, _KEY_LOW, _KEY_HIGH)
    if (lo > hi).any() or (key_hi < _KEY_LOW).any() or (key_lo > _KEY_HIGH).any():
        return np.empty((0, 3), dtype=np.int64), np.empty(0, dtype=np.int64)
    leaves = getattr(tree, "leaves", None)
    if callable(leaves) and "bbox" in inspect.signature(leaves).parameters:
        # liboctomap's begin_leafs_bbx, over the keys of these centers
        table = leaves(occupied_only=occupied_only,
                       bbox=np.stack([lo + 0.5, hi + 0.5]) * res)
    elif callable(leaves):  # ColorOctree
        table = leaves(occupied_only=occupied_only)
    else:
        table = tree.cells(occupied_only=occupied_only)
    centers, sizes = table[0], table[1]
    side = np.rint(sizes / res).astype(np.int64)
    low = np.rint(centers / res - side[:, None] / 2.0).astype(np.int64)
    return low, side


def _coverage(tree, shape: tuple[int, ...], first: np.ndarray, factor: int,
              z_keys: tuple[float, float] | None) -> np.ndarray:
    """The states (int8: 1 occupied, 0 free, -1 unknown) of a grid of `shape` whose
    cells are `factor` finest cells wide and whose first cell has index `first`;
    2D (with the finest z-layers `z_keys`, inclusive) or 3D."""
    d = len(shape)
    first_key = first * factor
    key_lo = np.full(3, np.nan)
    key_hi = np.full(3, np.nan)
    key_lo[:d] = first_key
    key_hi[:d] = (first + np.array(shape)) * factor - 1
    if z_keys is not None:
        key_lo[2], key_hi[2] = z_keys
    covered = []
    for occupied_only in (False, True):
        low, side = _leaf_boxes(tree, occupied_only, key_lo, key_hi)
        top = low + side[:, None] - 1
        keep = ((low <= key_hi) & (top >= key_lo)).all(axis=1)
        low, top = low[keep, :d], top[keep, :d]
        # output cell of each box's first and last finest cell, relative to the grid
        a = np.floor_divide(low, factor).astype(np.float64) - first
        b = np.floor_divide(top, factor).astype(np.float64) - first
        upper = np.array(shape, dtype=np.float64) - 1
        a = np.clip(a, 0, upper).astype(np.int64)
        b = np.clip(b, 0, upper).astype(np.int64)
        covered.append(box_counts(shape, a, b))
    states = np.full(shape, -1, dtype=np.int8)
    states[covered[0]] = 0
    states[covered[1]] = 1
    return states


def project_2d(self, z_min: float, z_max: float, *, resolution: float | None = None,
               bbox: ArrayLike | None = None,
               max_cells: int | None = None) -> OccupancyGrid2D:
    """Project a height band of the map onto a 2D grid, for navigation.

    Each column cell of the 2D grid is **occupied** if an occupied cell of
    the map in the band overlaps it, **free** if the band's known cells that
    overlap it are all free (at least one is known), and **unknown**
    otherwise. The band's cells are the finest z-layers holding a point of
    ``[z_min, z_max]``: layers ``floor(z_min / r)`` to ``floor(z_max / r)``
    (r the map's resolution, as octomap_server's keys of its height limits;
    a value within 1e-9 cell of a layer boundary counts as on it, so
    ``z_max=0.3`` at 0.1 m includes the layer from 0.3 to 0.4 m). Pruned
    leaves count for every cell they cover; they are not expanded.

    The grid's cells are aligned to multiples of `resolution` (cell ``i``
    spans ``[i * resolution, (i + 1) * resolution)``), so with a coarser
    resolution each grid cell covers whole map cells, and a grid cell is
    occupied when any of them is, in the band.

    Parameters
    ----------
    z_min, z_max : float
        The height band, metres, finite, ``z_min <= z_max``.
    resolution : float, default=None
        Edge of the grid's cells: the map's resolution (the default) or a
        whole multiple of it (within 1e-9 relative).
    bbox : array-like of shape (2, 2), default=None
        ``[[x_min, y_min], [x_max, y_max]]``: the area, extended outward to
        whole grid cells. Default: the map's ``bounds`` in x and y (a grid
        of shape (0, 0) when the map is empty). A box where the map knows
        no cell gives a grid of unknown cells.
    max_cells : int, default=None
        The most cells the grid may have (None: 2**25, about 10 bytes each
        at peak); past it a ValueError is raised before any allocation.

    Returns
    -------
    grid : OccupancyGrid2D
        `states` of shape (nx, ny) indexed along x, y: 1 occupied, 0 free,
        -1 unknown; `origin` the grid's minimum corner (x, y);
        `resolution`. :meth:`occgp.OccupancyGrid2D.save_ros_map` writes it for
        map_server / Nav2.

    Raises
    ------
    TypeError
        If `z_min`, `z_max` or `resolution` is not a real number, `bbox`
        does not hold numbers, or `max_cells` is not an int.
    ValueError
        If `z_min` or `z_max` is not finite or ``z_min > z_max``;
        `resolution` is not positive, finite and a whole multiple of the
        map's; `bbox` is not of shape (2, 2), finite, min < max; or the grid
        would have more than `max_cells` cells.

    Examples
    --------
    >>> from occgp import OccupancyOctree
    >>> m = OccupancyOctree(1.0).set_cells([[0.5, 0.5, 0.5], [1.5, 0.5, 0.5],
    ...                                     [1.5, 0.5, 3.5]], [2.0, -2.0, 2.0])
    >>> m.project_2d(0.0, 1.0).states.tolist()
    [[1], [0]]
    >>> m.project_2d(3.0, 3.0).states.tolist()
    [[-1], [1]]
    >>> m.project_2d(0.0, 1.0, resolution=2.0).states.tolist()
    [[1]]
    """
    z_min = check_real(z_min, "z_min")
    z_max = check_real(z_max, "z_max")
    if z_min > z_max:
        raise ValueError(f"z_min must be <= z_max, got z_min={z_min!r} > z_max={z_max!r}")
    cell, factor = _grid_resolution(self, resolution)
    max_cells = check_int(MAX_GRID_CELLS if max_cells is None else max_cells,
                          "max_cells", low=1)
    if bbox is None:
        lo, hi = self.bounds
        if not np.isfinite(lo).all():
            return OccupancyGrid2D(np.empty((0, 0), dtype=np.int8), [0.0, 0.0], cell)
        box = np.stack([lo[:2], hi[:2]])
    else:
        box = as_box(bbox, 2)
    first, shape = grid_span(box, cell, max_cells)
    res = self.resolution
    with np.errstate(over="ignore", invalid="ignore"):
        z_keys = np.floor(_snapped(np.array([z_min, z_max]) / res))
    z_keys = np.clip(z_keys, _KEY_LOW - 1, _KEY_HIGH + 1)
    states = _coverage(self, shape, first, factor, (float(z_keys[0]), float(z_keys[1])))
    return OccupancyGrid2D(states, first * cell, cell)

def _grid_resolution(tree, resolution: float | None) -> tuple[float, int]:
    """(cell edge, cells of the map per grid cell) of a checked `resolution`."""
    res = tree.resolution
    if resolution is None:
        return res, 1
    cell = check_real(resolution, "resolution", low=0.0)
    ratio = cell / res
    factor = round(ratio) if np.isfinite(ratio) else 0
    if factor < 1 or abs(ratio - factor) > 1e-9 * factor or factor > 2**17:
        raise ValueError(f"resolution must be a whole multiple (1 to 131072 times) of "
                         f"the map's resolution {res!r}, got {resolution!r}")
    return cell, int(factor)


def frontiers(self, *, bbox: ArrayLike | None = None, min_size: int = 1,
              max_cells: int | None = None) -> Frontiers:
    """Frontier cells: known-free cells next to unknown space, in clusters.

    A frontier cell is a free cell of the map (at its resolution; a pruned
    leaf counts for each cell it covers) with at least one unknown cell among
    its 6 face neighbours. Cells beyond the map's known space are unknown;
    the neighbours of the cells at the edge of `bbox` take the map's state,
    inside or outside the box. Frontier cells are grouped into clusters, the
    connected components with 26-connectivity (cells sharing a face, an
    edge or a corner: ``scipy.ndimage.label``), and clusters of fewer than
    `min_size` cells are dropped. The work is done on a dense grid of the
    box's cells.

    Parameters
    ----------
    bbox : array-like of shape (2, 3), default=None
        ``[min_corner, max_corner]``, metres, extended outward to whole
        cells. Default: the map's ``bounds`` (no frontier when the map
        is empty; nor in a box where it knows no cell).
    min_size : int, default=1
        The fewest cells a cluster keeps.
    max_cells : int, default=None
        The most cells the box may have (None: 2**24, about 14 bytes each at
        peak); past it a ValueError is raised before any allocation.

    Returns
    -------
    frontiers : Frontiers
        Named tuple ``(cells, labels, centroids, sizes)``: the frontier cells'
        centers (n_cells, 3), each one's cluster, and each cluster's centroid
        and size, largest first (:meth:`occgp.Frontiers.cluster` gives one
        cluster's cells).

    Raises
    ------
    TypeError
        If `bbox` does not hold numbers, or `min_size` or `max_cells` is not
        an int.
    ValueError
        If `bbox` is not of shape (2, 3), finite, min < max; `min_size` is
        below 1; or the box has more than `max_cells` cells.

    Examples
    --------
    >>> import numpy as np
    >>> from occgp import OccupancyOctree
    >>> free = np.array([[x + 0.5, 0.5, 0.5] for x in range(3)])
    >>> m = OccupancyOctree(1.0).set_cells(free, [-2.0] * 3)
    >>> f = m.frontiers(bbox=[[0, 0, 0], [3, 1, 1]])
    >>> f.sizes.tolist(), f.centroids.tolist()
    ([3], [[1.5, 0.5, 0.5]])
    """
    min_size = check_int(min_size, "min_size", low=1)
    max_cells = check_int(MAX_FRONTIER_CELLS if max_cells is None else max_cells,
                          "max_cells", low=1)
    res = self.resolution
    if bbox is None:
        lo, hi = self.bounds
        if not np.isfinite(lo).all():
            return empty_frontiers(3)
        box = np.stack([lo, hi])
    else:
        box = as_box(bbox, 3)
    first, shape = grid_span(box, res, max_cells)
    # one more cell on every side: the neighbours of the box's edge cells
    padded = tuple(n + 2 for n in shape)
    states = _coverage(self, padded, first - 1, 1, None)
    return find_frontiers(states, first * res, res, min_size, padded=True)
