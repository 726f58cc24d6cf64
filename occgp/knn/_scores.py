"""The k-NN model's point scores and their log-odds (Miao et al., Eqs. 4-5), shared by
:class:`occgp.KNNMap` and :class:`occgp.knn.ScanReplay` (public there, in
:mod:`occgp.knn`)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree  # type: ignore[import-untyped]
from scipy.special import ndtr  # type: ignore[import-untyped]

__all__ = ["mean_knn_distances", "history_knn_distances", "point_log_odds", "fixed_log_odds",
           "logodds32"]


def logodds32(p: float) -> float:
    """liboctomap's ``logodds``: ``(float) log(p / (1 - p))`` (libm's log, float32)."""
    return float(np.float32(math.log(p / (1.0 - p))))


def mean_knn_distances(points: NDArray[np.float64], ks: Sequence[int],
                       workers: int = 1) -> NDArray[np.float64]:
    """Mean distance of each point to its k nearest other points, for each k in `ks`.

    Returns shape (n_points, len(ks)); inf where the scan holds at most k points.
    The means are running sums of the sorted distances, so every k gives the
    same value whatever the other ks are.
    """
    n = len(points)
    kmax = max(ks)
    out = np.full((n, len(ks)), np.inf)
    if n < 2:
        return out
    dist, _ = cKDTree(points).query(points, k=min(kmax, n - 1) + 1, workers=workers)
    # column 0 is the point itself (or a duplicate, at the same distance 0)
    csum = np.cumsum(dist[:, 1:], axis=1)
    for j, k in enumerate(ks):
        if k <= n - 1:
            out[:, j] = csum[:, k - 1] / k
    return out


def history_knn_distances(points: NDArray[np.float64],
                          history_clouds: Sequence[NDArray[np.float64]], ks: Sequence[int],
                          workers: int = 1) -> NDArray[np.float64]:
    """Mean distance of each point to its k nearest points of earlier scans, for each k.

    The k-NN score over scans: the neighbours are searched among the points of
    `history_clouds` (the near points of the previous scans, world frame), not
    among `points` themselves. While the history holds no point at all (the
    first scan), the points are scored against their own cloud instead, as
    :func:`mean_knn_distances` scores them.

    Parameters
    ----------
    points : ndarray of float64, shape (n_points, 3)
        The points to score.
    history_clouds : sequence of ndarray of float64, shape (n_i, 3)
        The previous scans' near points, oldest first (their order does not
        change the distances).
    ks : sequence of int
        The numbers of neighbours, each at least 1.
    workers : int, default=1
        Threads for the queries (``cKDTree.query(workers=)``).

    Returns
    -------
    s : ndarray of float64, shape (n_points, len(ks))
        inf where the history holds fewer than k points. As in
        :func:`mean_knn_distances`, the means are running sums of the sorted
        distances, so every k gives the same value whatever the other ks are.
    """
    clouds = [np.asarray(c, dtype=np.float64).reshape(-1, 3) for c in history_clouds]
    n_hist = sum(len(c) for c in clouds)
    if n_hist == 0:
        return mean_knn_distances(points, ks, workers)
    n = len(points)
    out = np.full((n, len(ks)), np.inf)
    if n == 0:
        return out
    kq = min(max(ks), n_hist)
    dist, _ = cKDTree(np.concatenate(clouds)).query(points, k=kq, workers=workers)
    csum = np.cumsum(np.reshape(dist, (n, kq)), axis=1)
    for j, k in enumerate(ks):
        if k <= n_hist:
            out[:, j] = csum[:, k - 1] / k
    return out


def point_log_odds(s: NDArray[np.float64], count: int, mean: float, m2: float, p_u: float,
                   p_l: float, cdf: str = "normal") -> NDArray[np.float64]:
    """logit(p(s)) with p(s) = p_u - (p_u - p_l) F(s), F the normal CDF of (mean, std).

    ``std = sqrt(m2 / count)`` (Welford's). With ``std == 0`` F is the step at
    `mean` (0.5 on it); a score of inf (too few neighbours) gets F = 1, p = p_l.
    ``cdf="truncated"`` truncates the normal at s = 0 (distances are >= 0).
    """
    std = math.sqrt(m2 / count) if count > 0 else 0.0
    return fixed_log_odds(s, mean, std, p_u, p_l, cdf)


def fixed_log_odds(s: NDArray[np.float64], mean: float, std: float, p_u: float, p_l: float,
                   cdf: str = "normal") -> NDArray[np.float64]:
    """:func:`point_log_odds` with the statistics given as a mean and a standard deviation.

    Parameters
    ----------
    s : ndarray of float64
        The scores (inf: too few neighbours).
    mean, std : float
        μ and σ of the CDF (σ = 0: the step at μ).
    p_u, p_l : float
        Probabilities of the best-supported and of the most isolated points.
    cdf : {"normal", "truncated"}, default="normal"

    Returns
    -------
    log_odds : ndarray of float64
        ``logit(p(s))``, as :func:`point_log_odds`.
    """
    with np.errstate(invalid="ignore", divide="ignore"):
        if std > 0:
            z = (s - mean) / std
            f = ndtr(z)
            if cdf == "truncated":
                f0 = ndtr(-mean / std)
                f = np.clip((f - f0) / (1.0 - f0), 0.0, 1.0) if f0 < 1.0 else np.ones_like(f)
        else:
            f = np.where(s > mean, 1.0, np.where(s < mean, 0.0, 0.5))
    f = np.where(np.isfinite(s), f, 1.0)
    p = p_u - (p_u - p_l) * f
    return np.log(p / (1.0 - p))
