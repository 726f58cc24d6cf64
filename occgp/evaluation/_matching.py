"""The authors' true-positive rule: a predicted occupied cell matched one to one with an
occupied reference cell within ±1 cell (Miao, Hunter and Georgilas's map comparison).

occgp's strict protocol counts a predicted occupied cell as a true positive only when
the cell itself is occupied in the ground truth. The authors' comparison of a map
with a reference map is looser: a predicted occupied cell is a true positive when an
occupied reference cell lies in its 3x3x3 neighbourhood and has not been matched to
another predicted cell yet. :func:`matched_counts` counts by that rule;
:func:`neighbour_table` and :func:`greedy_matches` are its two vectorised steps, used
by :func:`occgp.evaluation.grid_search` to score every threshold of every combination
against one table.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..octree._tree import pack_keys, unpack_keys

__all__ = ["MatchedCounts", "matched_counts", "OFFSETS", "neighbour_table",
           "greedy_matches"]

#: The 27 key offsets (dx, dy, dz) a predicted cell tries, in order: the cell itself,
#: then the authors' order of the other 26 (dz = +1, 0, -1 outermost, then dx, then
#: dy, each +1, 0, -1).
OFFSETS = np.array([(0, 0, 0)] + [(dx, dy, dz) for dz in (1, 0, -1) for dx in (1, 0, -1)
                                  for dy in (1, 0, -1) if (dx, dy, dz) != (0, 0, 0)],
                   dtype=np.int64)
_KEY_MAX = 0xFFFF


class MatchedCounts(NamedTuple):
    """The confusion counts of :func:`matched_counts`.

    Attributes
    ----------
    tp : int
        Predicted occupied scored cells matched to an occupied reference cell.
    fp : int
        The other predicted occupied scored cells.
    fn : int
        Scored cells occupied in the reference and not predicted occupied.
    tn : int
        Scored cells neither predicted nor reference occupied.
    tpr : float
        ``tp / (tp + fn)`` (NaN when 0/0).
    fdr : float
        ``fp / (tp + fp)`` (NaN when nothing is predicted occupied).
    """

    tp: int
    fp: int
    fn: int
    tn: int
    tpr: float
    fdr: float


def _as_keys(keys: ArrayLike, name: str) -> NDArray[np.uint64]:
    """Packed keys (uint64, 1-D) of packed or (n, 3) integer keys, sorted and unique."""
    a = np.asarray(keys)
    if a.size == 0:
        return np.empty(0, np.uint64)
    if a.dtype.kind not in "iu":
        raise TypeError(f"{name} must hold integer keys, got dtype {a.dtype}")
    if a.ndim == 2 and a.shape[1] == 3:
        if a.min() < 0 or a.max() > _KEY_MAX:
            raise ValueError(f"{name} keys must lie in [0, 65535]")
        return np.unique(pack_keys(a.astype(np.uint16)))
    if a.ndim != 1:
        raise ValueError(f"{name} must be packed keys of shape (n,) or keys of shape (n, 3), "
                         f"got shape {a.shape}")
    if a.dtype.kind == "i" and a.min() < 0:
        raise ValueError(f"{name} packed keys must be non-negative")
    packed = a.astype(np.uint64)
    if (packed >> np.uint64(48)).any():
        raise ValueError(f"{name} packed keys must fit in 48 bits (16 bits per axis)")
    return np.unique(packed)


def neighbour_table(keys: NDArray[np.uint64],
                    reference: NDArray[np.uint64]) -> NDArray[np.int64]:
    """For each cell and each of the 27 :data:`OFFSETS`, the index of the occupied
    reference cell there.

    Parameters
    ----------
    keys : ndarray of uint64, shape (n,)
        Packed keys of the candidate cells.
    reference : ndarray of uint64, shape (n_ref,)
        Packed keys of the occupied reference cells, sorted and unique.

    Returns
    -------
    table : ndarray of int64, shape (n, 27)
        Index into `reference`, -1 where that neighbour is no occupied reference cell
        (or lies outside the key range).
    """
    k = unpack_keys(keys).astype(np.int64)
    table = np.full((len(keys), len(OFFSETS)), -1, dtype=np.int64)
    if len(reference) == 0:
        return table
    for j, off in enumerate(OFFSETS):
        nb = k + off
        inside = ((nb >= 0) & (nb <= _KEY_MAX)).all(axis=1)
        packed = pack_keys(np.where(inside[:, None], nb, 0).astype(np.uint16))
        pos = np.minimum(np.searchsorted(reference, packed), len(reference) - 1)
        hit = inside & (reference[pos] == packed)
        table[hit, j] = pos[hit]
    return table


def greedy_matches(table: NDArray[np.int64], active: NDArray[np.bool_],
                   n_reference: int) -> NDArray[np.bool_]:
    """Match the active rows of `table` one to one with reference cells, greedily.

    Offset by offset (the columns, in :data:`OFFSETS` order), every active row not
    matched yet takes its reference cell at that offset if that cell is not taken
    (at one offset distinct cells reach distinct reference cells).

    Parameters
    ----------
    table : ndarray of int64, shape (n, 27)
        From :func:`neighbour_table`.
    active : ndarray of bool, shape (n,)
        The rows predicted occupied (and scored).
    n_reference : int
        Number of reference cells.

    Returns
    -------
    matched : ndarray of bool, shape (n,)
    """
    matched = np.zeros(len(table), dtype=bool)
    taken = np.zeros(n_reference, dtype=bool)
    rows = np.flatnonzero(active)
    for j in range(table.shape[1]):
        cand = table[rows, j]
        ok = cand >= 0
        ok[ok] = ~taken[cand[ok]]
        if not ok.any():
            continue
        r, c = rows[ok], cand[ok]
        matched[r] = True
        taken[c] = True
        rows = rows[~matched[rows]]
    return matched


def counts_from_matches(n_pred: int, n_matched: int, fn: int, tn: int) -> MatchedCounts:
    """The :class:`MatchedCounts` of predicted and matched counts."""
    tp, fp = n_matched, n_pred - n_matched
    tpr = tp / (tp + fn) if tp + fn else float("nan")
    fdr = fp / n_pred if n_pred else float("nan")
    return MatchedCounts(int(tp), int(fp), int(fn), int(tn), tpr, fdr)


def matched_counts(predicted: ArrayLike, reference: ArrayLike,
                   scored: ArrayLike | None = None) -> MatchedCounts:
    """Confusion counts by the authors' ±1-cell, one-to-one true-positive rule.

    The map comparison of Miao, Hunter and Georgilas's code: only the `scored`
    cells count (theirs: the cells known in both the map and the reference
    map). A scored cell predicted occupied is a true positive when it can be
    matched to an occupied reference cell in its 3x3x3 neighbourhood (the cell
    itself or one of its 26 neighbours, scored or not) that no other predicted
    cell holds; a false positive otherwise. A scored cell not predicted
    occupied is a false negative when it is itself occupied in the reference,
    a true negative otherwise. TPR = TP / (TP + FN), FDR = FP / (TP + FP).

    The matching is greedy and deterministic. Offset by offset, first the cell
    itself, then the 26 neighbours in the authors' order (dz = +1, 0, -1
    outermost, then dx, then dy, each +1, 0, -1), every predicted cell not yet
    matched takes the reference cell at that offset if no predicted cell has
    taken it. At one offset no two predicted cells reach the same reference
    cell, so the result depends on the offset order only. The authors' code
    goes cell by cell instead (each predicted cell, in its sweep by z, x, y
    decreasing, takes the first free neighbour in their offset order, which
    starts at (+1, +1, +1)); the two greedy rules agree wherever no two
    predicted cells compete for one reference cell, and both are one to one.
    Trying the cell itself first makes a prediction equal to the reference
    score TP = every occupied cell.

    Parameters
    ----------
    predicted : array-like of int
        The cells predicted occupied: packed keys of shape (n,) (x in the low
        16 bits, as :meth:`occgp.OccupancyOctree.cells` packs them) or keys of
        shape (n, 3). Those outside `scored` are ignored.
    reference : array-like of int
        The occupied cells of the reference map, as `predicted`.
    scored : array-like of int or None, default=None
        The cells that count, as `predicted`; None: every cell of `predicted`
        and `reference`.

    Returns
    -------
    counts : MatchedCounts
        ``tp``, ``fp``, ``fn``, ``tn``, ``tpr`` and ``fdr``.

    Raises
    ------
    TypeError
        If a key array is not of integers.
    ValueError
        If a key array has the wrong shape or keys out of range.

    Examples
    --------
    >>> ref = [[10, 10, 10], [11, 10, 10]]
    >>> matched_counts([[10, 10, 10], [10, 11, 10], [10, 12, 10]], ref)[:4]
    (2, 1, 1, 0)
    """
    pred = _as_keys(predicted, "predicted")
    ref = _as_keys(reference, "reference")
    cells = np.union1d(pred, ref) if scored is None else _as_keys(scored, "scored")
    pred = pred[np.isin(pred, cells, assume_unique=True)]
    matched = greedy_matches(neighbour_table(pred, ref), np.ones(len(pred), bool), len(ref))
    ref_scored = np.isin(cells, ref, assume_unique=True)
    pred_scored = np.isin(cells, pred, assume_unique=True)
    fn = int(np.count_nonzero(ref_scored & ~pred_scored))
    tn = int(np.count_nonzero(~ref_scored & ~pred_scored))
    return counts_from_matches(len(pred), int(matched.sum()), fn, tn)
