"""Merging occupancy octrees (several robots or sessions).

:func:`merge` is a method of :class:`occgp.OccupancyOctree`, which binds it in its
class body (``merge = _merge.merge``), so its first argument is the map, named
``self``."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..io._export import leaf_cells
from .._octree import _OcTree
from .._validation import as_numeric, check_choice, check_int

__all__ = ["merge", "MERGE_RULES", "MAX_MERGE_CELLS", "check_rigid_transform"]

#: How :func:`merge` combines two cells' log-odds.
MERGE_RULES = ("add", "max")
#: The most finest cells :func:`merge` expands `other` into by default
#: (about 40 bytes each while merging).
MAX_MERGE_CELLS = 2**24
_HALF = 32768
# the 27 key offsets of a cell and its neighbours
_NEIGHBOURS = np.stack(np.meshgrid(*[np.arange(-1, 2)] * 3, indexing="ij"),
                       axis=-1).reshape(-1, 3)
_CHUNK = 1 << 17


def check_rigid_transform(transform: ArrayLike, name: str = "transform") -> NDArray[np.float64]:
    """`transform` as a 4 x 4 rigid transform (rotation and translation), checked."""
    t = as_numeric(transform, name).astype(np.float64)
    if t.shape != (4, 4):
        raise ValueError(f"{name} must be a 4 x 4 homogeneous matrix, got shape {t.shape}")
    if not np.isfinite(t).all():
        raise ValueError(f"{name} must be finite")
    if not np.array_equal(t[3], [0.0, 0.0, 0.0, 1.0]):
        raise ValueError(f"{name}'s last row must be [0, 0, 0, 1], got {t[3].tolist()}")
    r = t[:3, :3]
    if (np.abs(r @ r.T - np.eye(3)).max() > 1e-6 or np.linalg.det(r) < 0):
        raise ValueError(f"{name}'s upper-left 3 x 3 block must be a rotation "
                         f"(orthonormal, determinant +1)")
    return t


def merge(self, other: Any, transform: ArrayLike | None = None, *, rule: str = "add",
          max_cells: int | None = None):
    """Add another map's evidence to this map, cell by cell.

    Every finest cell `other` knows (pruned leaves count for each of
    their cells) is combined with this map's cell at the same place:

    * ``rule="add"``: its log-odds are added, as
      :meth:`update_cells` adds them (a cell this map did not know starts
      from 0), clamped to this map's ``[clamping_min, clamping_max]``. For
      maps made from independent scans this is the Bayesian fusion of
      their evidence.
    * ``rule="max"``: the cell takes the larger of the two log-odds (the
      other's alone where this map knew nothing), as :meth:`set_cells`
      sets it (clamped): a conservative merge for maps that saw the same
      scans.

    With `transform`, `other` is first moved by that rigid transform (its
    frame into this map's): each cell of this map within reach takes the
    value of the cell of `other` holding the preimage of its center
    (nearest-cell resampling, so no cell is left out or counted twice).
    Transforms by whole cells (and quarter turns about the axes through
    cell corners) map cells onto cells exactly.

    Empty maps are valid on either side: an empty `other` (with or
    without `transform`) leaves this map unchanged, and merging into an
    empty map gives it `other`'s cells (clamped to this map's limits).

    Parameters
    ----------
    other : OccupancyOctree or map with ``to_octree()``
        The map to merge in, of the same resolution (a
        :class:`~occgp.GridMap` goes through its ``to_octree()``).
    transform : array-like of shape (4, 4), default=None
        Homogeneous rigid transform from `other`'s frame to this map's.
    rule : {"add", "max"}, default="add"
    max_cells : int, default=None
        The most finest cells `other` may expand into (None:
        :data:`MAX_MERGE_CELLS`); past it a ValueError is raised before
        anything changes.

    Returns
    -------
    self : OccupancyOctree

    Raises
    ------
    TypeError
        If `other` is not a map.
    ValueError
        If the resolutions differ, `transform` is not a 4 x 4 rigid
        transform, `rule` is unknown, `other` expands into more than
        `max_cells` cells, or a cell moved by `transform` falls outside the
        key range. The map is then unchanged.

    Examples
    --------
    >>> from occgp import OccupancyOctree
    >>> a = OccupancyOctree(0.1).update_cells([[0.05, 0.05, 0.05]], 1.0)
    >>> b = OccupancyOctree(0.1).update_cells([[0.05, 0.05, 0.05], [0.15, 0.05, 0.05]],
    ...                                       [1.5, -0.5])
    >>> a.merge(b).log_odds([[0.05, 0.05, 0.05], [0.15, 0.05, 0.05]]).tolist()
    [2.5, -0.5]
    """
    other = _as_octree(other)
    if other.resolution != self.resolution:
        raise ValueError(f"other must have this map's resolution {self.resolution!r}, "
                         f"got {other.resolution!r}")
    t = None if transform is None else check_rigid_transform(transform)
    rule = check_choice(rule, "rule", MERGE_RULES)
    cap = MAX_MERGE_CELLS if max_cells is None else check_int(max_cells, "max_cells", low=1)
    keys, values = _finest_cells(other, cap)
    if len(keys) and t is not None and not np.array_equal(t, np.eye(4)):
        keys, values = _resampled(other, keys, t, self.resolution)
    if len(keys) == 0:
        return self
    packed = (keys[:, 0].astype(np.uint64) | (keys[:, 1].astype(np.uint64) << np.uint64(16))
              | (keys[:, 2].astype(np.uint64) << np.uint64(32)))
    if rule == "add":
        self._apply_cells(np.ascontiguousarray(packed), np.ascontiguousarray(values))
        return self
    mine = self.log_odds((keys - _HALF + 0.5) * self.resolution)
    take = np.isnan(mine) | (values > mine)
    if take.any():
        self._set_values(np.ascontiguousarray(keys[take], dtype=np.uint16),
                         np.ascontiguousarray(values[take]))
    return self


def _as_octree(other: Any) -> Any:
    # _OcTree: the compiled tree under OccupancyOctree, and under no other class, so
    # that this part of OccupancyOctree need not import it
    if isinstance(other, _OcTree):
        return other
    to_octree = getattr(other, "to_octree", None)
    if to_octree is None:
        raise TypeError(f"other must be an OccupancyOctree or a map with to_octree(), "
                        f"got {type(other).__name__}")
    out = to_octree()
    if not isinstance(out, _OcTree):
        raise TypeError(f"other.to_octree() must give an OccupancyOctree, got "
                        f"{type(out).__name__}")
    return out


def _finest_cells(tree: Any, cap: int) -> tuple[NDArray[np.int64], NDArray[np.float32]]:
    """The keys (int64, (n, 3)) and log-odds of every finest cell `tree` knows."""
    leaves = tree.leaves()
    total = int(np.sum(np.rint(leaves.sizes / tree.resolution) ** 3))
    if total > cap:
        raise ValueError(f"other holds {total} finest cells, more than max_cells={cap}")
    index, owner = leaf_cells(leaves.centers, leaves.sizes, tree.resolution)
    return index + _HALF, leaves.log_odds[owner]


def _resampled(other: Any, keys: NDArray[np.int64], t: NDArray[np.float64],
               res: float) -> tuple[NDArray[np.int64], NDArray[np.float32]]:
    """The cells (keys, log-odds) of `other` moved by `t`, resampled on this grid."""
    r, shift = t[:3, :3], t[:3, 3]
    found: list[NDArray[np.int64]] = []
    for start in range(0, len(keys), _CHUNK):   # bounded memory: 27 candidates a cell
        centers = (keys[start:start + _CHUNK] - _HALF + 0.5) * res
        moved_f = np.floor((centers @ r.T + shift) / res)
        if (np.abs(moved_f) > _HALF + 1).any():
            raise ValueError("transform moves cells of other outside this map's key range")
        moved = moved_f.astype(np.int64) + _HALF
        cand = (moved[:, None, :] + _NEIGHBOURS[None]).reshape(-1, 3)
        found.append(np.unique(cand, axis=0))
    cand = np.unique(np.concatenate(found), axis=0)
    centers = (cand - _HALF + 0.5) * res
    values = other.log_odds((centers - shift) @ r)    # r is orthonormal: r^-1 = r^T
    known = ~np.isnan(values)
    cand, values = cand[known], values[known]
    if ((cand < 0) | (cand > 2 * _HALF - 1)).any():
        raise ValueError("transform moves cells of other outside this map's key range")
    return cand, values.astype(np.float32)
