"""Cell edits of the occupancy octree: updates and values by point (liboctomap's
``updateNode`` and ``setNodeValue``), deletions, the max-likelihood tree, pruning
and expansion.

The functions are methods of :class:`occgp.OccupancyOctree`, which binds them in its
class body (``update_cells = _edits.update_cells``), so their first argument is the
map, named ``self``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from ._queries import pack_keys
from .._validation import as_numeric

if TYPE_CHECKING:
    from ._tree import OccupancyOctree

__all__ = ["update_cells", "set_cells", "delete_cells", "to_max_likelihood", "prune",
           "expand"]


def update_cells(self: OccupancyOctree, points: ArrayLike,
                 log_odds: ArrayLike | None = None, *, occupied: ArrayLike | None = None,
                 stamp: float | None = None) -> "OccupancyOctree":
    """Add log-odds to the cells holding `points` (liboctomap's ``updateNode``).

    Row ``i`` adds ``log_odds[i]`` to the finest cell holding ``points[i]``
    and clamps it to ``[clamping_min, clamping_max]``, as
    ``updateNode(point, log_odds[i])`` called for each row in order would:
    a cell named twice gets its updates one after the other, clamped after
    each. Cells are created where the map knew nothing (from log-odds 0).
    The tree is walked once per round of distinct cells, not once per row.

    Parameters
    ----------
    points : array-like of shape (n_points, 3)
        Points in the cells to update, metres; inside the key range.
    log_odds : float or array-like of shape (n_points,), optional
        The log-odds to add (finite in single precision). Give it or
        `occupied`.
    occupied : bool or array-like of bool of shape (n_points,), optional
        ``updateNode(point, occupied)``: add the log-odds of ``prob_hit``
        where True, of ``prob_miss`` where False.
    stamp : float, default=None
        Stamp the cells with this time (see :meth:`decay`).

    Returns
    -------
    self : OccupancyOctree

    Raises
    ------
    TypeError
        If an array does not hold numbers (booleans for `occupied`).
    ValueError
        If `points` is not of shape (n_points, 3), holds NaN or inf or lies
        outside the key range, `log_odds` or `occupied` has the wrong shape
        or non-finite values, or neither or both are given. The map is then
        unchanged.

    Examples
    --------
    >>> from occgp import OccupancyOctree
    >>> m = OccupancyOctree(0.1).update_cells([[0.05, 0.05, 0.05]] * 2, [2.0, 2.0])
    >>> float(m.log_odds([[0.05, 0.05, 0.05]])[0])     # 4.0, clamped at logit(0.971)
    3.511
    """
    keys = self.coord_to_key(points)
    values = self._cell_values(len(keys), log_odds, occupied)
    stamping = self._stamped(stamp)
    if len(keys) == 0:
        return self
    packed = pack_keys(keys)
    order = np.argsort(packed, kind="stable")
    sorted_keys = packed[order]
    start = np.r_[True, sorted_keys[1:] != sorted_keys[:-1]]
    group_start = np.maximum.accumulate(np.where(start, np.arange(len(order)), 0))
    rank = np.arange(len(order)) - group_start      # the row's turn within its cell
    by_round = np.lexsort((sorted_keys, rank))
    bounds = np.searchsorted(rank[by_round], np.arange(rank.max() + 2))
    rows = order[by_round]
    with stamping:
        for r in range(len(bounds) - 1):
            take = rows[bounds[r]:bounds[r + 1]]
            self._apply_cells(np.ascontiguousarray(packed[take]),
                              np.ascontiguousarray(values[take]))
    return self


def set_cells(self: OccupancyOctree, points: ArrayLike, log_odds: ArrayLike, *,
              stamp: float | None = None) -> "OccupancyOctree":
    """Set the log-odds of the cells holding `points` (liboctomap's ``setNodeValue``).

    Each value is clamped to ``[clamping_min, clamping_max]`` as liboctomap
    clamps it; a cell named twice keeps the last value. The inner nodes are
    then re-evaluated and the tree pruned.

    Parameters
    ----------
    points : array-like of shape (n_points, 3)
        Points in the cells to set, metres; inside the key range.
    log_odds : float or array-like of shape (n_points,)
        The values (finite in single precision).
    stamp : float, default=None
        Stamp the cells with this time (see :meth:`decay`).

    Returns
    -------
    self : OccupancyOctree

    Raises
    ------
    TypeError, ValueError
        As :meth:`update_cells`; the map is then unchanged.

    Examples
    --------
    >>> from occgp import OccupancyOctree
    >>> m = OccupancyOctree(0.1).set_cells([[0.05, 0.05, 0.05]], 1.0)
    >>> float(m.log_odds([[0.05, 0.05, 0.05]])[0])
    1.0
    """
    keys = self.coord_to_key(points)
    values = self._cell_values(len(keys), log_odds, None)
    stamping = self._stamped(stamp)
    if len(keys):
        with stamping:
            self._set_values(keys, values)
    return self


def delete_cells(self: OccupancyOctree, points: ArrayLike, depth: int = 0) -> int:
    """Make the nodes holding `points` unknown again (liboctomap's ``deleteNode``).

    Row ``i`` deletes the node at `depth` that holds ``points[i]``, with its
    whole subtree. A pruned leaf coarser than `depth` on the way is first
    expanded, as liboctomap's ``deleteNodeRecurs`` does: its eight children
    take its value, and the deletion continues in the child holding the
    point, so the rest of the pruned cube stays known. An inner node left
    without children is deleted too, and every remaining ancestor takes
    the largest log-odds of its children again, so queries at any depth
    stay consistent; afterwards queries at the points give NaN (unknown).
    The tree is not pruned again: the siblings of a deleted cell stay as
    they are.

    occgp implements this itself: liboctomap 1.9's ``deleteNode`` aborts
    on inner nodes. Deletions are not recorded by :attr:`track_changes`
    (liboctomap's change detection does not record them either); a
    deleted cell that is observed again is recorded as new.

    Parameters
    ----------
    points : array-like of shape (n_points, 3)
        Points in the nodes to delete, metres; inside the key range.
    depth : int, default=0
        Tree depth of the deleted nodes, in [0, 16]: 16 (or 0, liboctomap's
        convention for "the tree's depth") deletes the finest cells, ``d``
        the node of edge ``resolution * 2**(16 - d)``.

    Returns
    -------
    n_deleted : int
        How many nodes were deleted (points in unknown space, or in a node
        an earlier row already deleted, delete nothing).

    Raises
    ------
    TypeError
        If `points` does not hold numbers or `depth` is not an int.
    ValueError
        If `points` is not of shape (n_points, 3), holds NaN or inf or lies
        outside the key range, or `depth` lies outside [0, 16]. The map is
        then unchanged.

    Examples
    --------
    >>> from occgp import OccupancyOctree
    >>> m = OccupancyOctree(0.1).insert_scan([[0.55, 0.05, 0.05]], [0.05, 0.05, 0.05])
    >>> m.delete_cells([[0.55, 0.05, 0.05], [0.56, 0.05, 0.05]])
    1
    >>> m.log_odds([[0.55, 0.05, 0.05], [0.45, 0.05, 0.05]]).round(3).tolist()
    [nan, -0.405]
    """
    depth = self._check_depth(depth)
    keys = self.coord_to_key(points)
    if len(keys) == 0:
        return 0
    return int(self._delete(keys, depth))


def to_max_likelihood(self: OccupancyOctree) -> "OccupancyOctree":
    """Set every cell to its clamping bound by its state (liboctomap's ``toMaxLikelihood``).

    Occupied cells go to ``clamping_max``, free ones to ``clamping_min``;
    then the tree is pruned.

    Returns
    -------
    self
        The map.
    """
    self._to_max_likelihood()
    return self


def prune(self: OccupancyOctree) -> "OccupancyOctree":
    """Merge every set of eight identical leaves into their parent (liboctomap's ``prune``).

    Returns
    -------
    self
        The map.
    """
    self._prune()
    return self


def expand(self: OccupancyOctree) -> "OccupancyOctree":
    """Split every pruned leaf down to the finest resolution (liboctomap's ``expand``).

    Returns
    -------
    self
        The map.
    """
    self._expand()
    return self


def _cell_values(self: OccupancyOctree, n: int, log_odds, occupied) -> np.ndarray:
    """The float32 log-odds of :meth:`update_cells` / :meth:`set_cells`, checked."""
    if (log_odds is None) == (occupied is None):
        raise ValueError("give exactly one of log_odds and occupied")
    if occupied is not None:
        occ = np.asarray(occupied)
        if occ.dtype != np.bool_:
            raise TypeError(f"occupied must hold booleans, got dtype {occ.dtype}")
        occ = np.broadcast_to(occ, (n,)) if occ.ndim == 0 else occ
        if occ.shape != (n,):
            raise ValueError(f"occupied must be a bool or of shape ({n},), got {occ.shape}")
        hit, miss = self._log_odds_thresholds()[3:]
        return np.where(occ, np.float32(hit), np.float32(miss)).astype(np.float32)
    values = as_numeric(log_odds, "log_odds")
    if values.ndim == 0:
        values = np.full(n, values)
    if values.shape != (n,):
        raise ValueError(f"log_odds must be a number or of shape ({n},), "
                         f"got {values.shape}")
    with np.errstate(over="ignore"):
        out = np.ascontiguousarray(values, dtype=np.float32)
    if not np.isfinite(out).all():
        bad = int(np.flatnonzero(~np.isfinite(out))[0])
        raise ValueError(f"log_odds must be finite in single precision, got "
                         f"{values[bad]!r} at row {bad}")
    return out
