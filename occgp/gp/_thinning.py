"""Thinning a large set of laser observations to a budget, place by place.

A dense log sees the same walls from many poses (Freiburg 079: 4,312 scans
0.1 m apart, 1.5 million beams). A GP map's cost grows with its observations,
not with the area they cover, so past a budget the GP maps keep a subset:
:func:`thin_observations` keeps, in every cell of `cell_size` that holds hits,
at most ``k`` returning beams (each with its hit), drawn at random, with the
largest ``k`` that fits the budget; places seen by few beams keep them all.
Beams without a return are kept at the rate of the returning ones. A budget
that even one beam per cell exceeds doubles the cell until it fits.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._validation import as_points, check_real, check_seed
from ._beams import match_beams
from ._limits import check_model_size

__all__ = ["thin_observations", "thin_to_budget"]


def _cell_ids(cells):
    """One int64 per cell row (rows of integer cell coordinates)."""
    lo = cells.min(axis=0)
    span = cells.max(axis=0) - lo + 1
    if float(np.prod(span.astype(np.float64))) < 2.0 ** 62:
        return np.ravel_multi_index(tuple((cells - lo).T), tuple(span))
    return np.unique(cells, axis=0, return_inverse=True)[1].reshape(-1)


def _per_cell(cells, budget, rng):
    """Mask of the items kept: at most k per cell (random ranks), the largest k whose
    total is within `budget` (k >= 1); None when one per cell is over it."""
    _, inverse, counts = np.unique(_cell_ids(cells), return_inverse=True, return_counts=True)
    if len(counts) > budget:
        return None
    order = np.lexsort((rng.permutation(len(inverse)), inverse))
    first = np.cumsum(counts) - counts
    rank = np.empty(len(inverse), dtype=np.int64)
    rank[order] = np.arange(len(inverse)) - first[inverse[order]]
    sorted_counts = np.sort(counts)
    # total(k) = sum(min(counts, k)), non-decreasing in k: the largest k within budget
    lo, hi = 1, int(sorted_counts[-1])
    while lo < hi:
        k = (lo + hi + 1) // 2
        if np.minimum(sorted_counts, k).sum() <= budget:
            lo = k
        else:
            hi = k - 1
    return rank < lo


def thin_observations(hits: ArrayLike, segment_starts: ArrayLike, segment_ends: ArrayLike,
                      max_observations: int, *, cell_size: float = 0.1,
                      beam_hits: ArrayLike | None = None, random_state=0):
    """Keep at most `max_observations` hits and beams, at most ``k`` beams a place.

    Every returning beam and its hit are kept or dropped together; the beams
    are grouped by the cell of `cell_size` (doubled until the cells are
    fewer than the budget allows) that their hit falls in, and each cell
    keeps at most ``k`` of them, drawn at random, with ``k`` the largest that
    fits. Beams without a return keep the returning beams' rate (a seeded
    uniform draw). Nothing is dropped when the data fits.

    Parameters
    ----------
    hits : array-like of shape (n_hits, D)
    segment_starts, segment_ends : array-like of shape (n_beams, D)
        The observations, as the GP maps' ``fit`` takes them.
    max_observations : int
        The budget: hits plus beams kept (at least 2).
    cell_size : float, default=0.1
        The first cell edge, metres.
    beam_hits : array-like of int of shape (n_beams,), default=None
        Each beam's hit or -1 (see :func:`match_beams`); None finds them.
    random_state : int, numpy.random.Generator or None, default=0

    Returns
    -------
    keep_hits : ndarray of int
        Indices of the hits kept, increasing.
    keep_beams : ndarray of int
        Indices of the beams kept, increasing.

    Raises
    ------
    ValueError
        If the arrays are malformed or `max_observations` or `cell_size` is
        out of range.
    TypeError
        If an argument has a wrong type.

    Examples
    --------
    >>> y = np.r_[np.linspace(0.0, 0.05, 50), np.linspace(1.0, 1.05, 50)]   # two spots
    >>> hits = np.column_stack([np.full(100, 2.0), y])
    >>> starts = np.zeros_like(hits)
    >>> kh, kb = thin_observations(hits, starts, hits, 20)
    >>> len(kh), len(kb), sorted(set(hits[kh, 1].round().tolist()))   # 5 beams a spot
    (10, 10, [0.0, 1.0])
    """
    if isinstance(max_observations, (bool, np.bool_)) or not isinstance(
            max_observations, (int, np.integer)):
        raise TypeError(f"max_observations must be an int, got "
                        f"{type(max_observations).__name__}")
    if max_observations < 2:
        raise ValueError(f"max_observations must be at least 2, got {max_observations}")
    cell = check_real(cell_size, "cell_size", low=0.0, high=1e6, high_open=False)
    hits = np.asarray(hits, dtype=np.float64)
    dim = hits.shape[1] if hits.ndim == 2 else 2
    hits = as_points(hits, "hits", dim)
    starts = as_points(segment_starts, "segment_starts", dim)
    ends = as_points(segment_ends, "segment_ends", dim)
    if len(starts) != len(ends):
        raise ValueError(f"segment_starts and segment_ends must have the same length, got "
                         f"{len(starts)} and {len(ends)}")
    n_hits, n_beams = len(hits), len(starts)
    if n_hits + n_beams <= max_observations:
        return np.arange(n_hits), np.arange(n_beams)
    rng = check_seed(random_state, "random_state")
    source = match_beams(hits, starts, ends, beam_hits=beam_hits, hit_tolerance=0.0) \
        if beam_hits is not None else match_beams(hits, starts, ends)
    returning = np.flatnonzero(source >= 0)
    silent = np.flatnonzero(source < 0)
    has_beam = np.zeros(n_hits, dtype=bool)
    has_beam[source[returning]] = True
    orphan = np.flatnonzero(~has_beam)                               # hits without a beam
    if len(orphan) > max_observations // 2:
        orphan = np.sort(rng.choice(orphan, max_observations // 2, replace=False))
    # the returning beams (2 observations each: the beam and its hit) get the budget less
    # the orphan hits and the silent beams at the same rate
    budget = max_observations - len(orphan)
    keep_ret = np.zeros(len(returning), dtype=bool)
    if len(returning) and budget >= 2:
        rate = min(1.0, budget / (2 * len(returning) + len(silent)))
        pairs = max(1, int(rate * len(returning)))
        lo = np.floor(hits[source[returning]] / cell).astype(np.int64)
        while True:
            mask = _per_cell(lo, pairs, rng)
            if mask is not None:
                break
            cell *= 2.0
            lo = np.floor(hits[source[returning]] / cell).astype(np.int64)
        keep_ret = mask
    kept_beams = returning[keep_ret]
    n_silent = max(0, min(len(silent), max_observations - len(orphan) - 2 * len(kept_beams)))
    if len(returning):
        n_silent = min(n_silent, int(round(len(silent) * keep_ret.mean())))
    kept_silent = np.sort(rng.choice(silent, n_silent, replace=False)) if n_silent else \
        np.empty(0, dtype=np.int64)
    keep_beams = np.sort(np.r_[kept_beams, kept_silent]).astype(np.int64)
    keep_hits = np.unique(np.r_[source[kept_beams], orphan]).astype(np.int64)
    return keep_hits, keep_beams


def thin_to_budget(obs, budget, beam_hits, rng, model_size, what):
    """`obs` (:class:`~occgp.gp.Observations`, hits first) thinned to `budget` (None:
    kept whole) and the beams' hits kept (`beam_hits` renumbered, or None), after the
    size check of models of at most `model_size` observations (`what`: the name of
    the parameter that sets it)."""
    n_hits = int(np.count_nonzero(obs.labels > 0))
    if budget is not None and len(obs.y) > budget:
        keep_hits, keep_beams = thin_observations(
            obs.starts[:n_hits], obs.starts[n_hits:], obs.ends[n_hits:], budget,
            beam_hits=beam_hits, random_state=rng)
        if beam_hits is not None:
            new_index = np.full(n_hits, -1, dtype=np.int64)
            new_index[keep_hits] = np.arange(len(keep_hits))
            kept = np.asarray(beam_hits)[keep_beams]
            beam_hits = np.where(kept >= 0, new_index[np.maximum(kept, 0)], -1)
        obs = obs.take(np.r_[keep_hits, n_hits + keep_beams])
    check_model_size(len(obs.y), model_size, "set max_observations" if budget is None
                     else f"lower max_observations or {what}")
    return obs, beam_hits
