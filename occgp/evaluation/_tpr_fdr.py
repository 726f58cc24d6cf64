"""The TPR–FDR curve and its area on checked arrays (shared by the metrics and the
grid search).

The functions here take labels and probabilities already validated by
:mod:`occgp.evaluation.metrics` (bool and float64 arrays of one length, no NaN);
the public, checking versions are :func:`~occgp.evaluation.metrics.tpr_fdr_curve`
and :func:`~occgp.evaluation.metrics.tpr_fdr_auc`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._docfill import fill_doc

__all__ = ["tpr_fdr_points", "tpr_fdr_area", "tpr_fdr_auc_unchecked"]

#: The Parameters section of the functions on checked labels and probabilities.
_CHECKED_PARAMS = """Parameters
----------
labels : ndarray of bool, shape (n_points,)
    True labels, at least one occupied.
probs : ndarray of float64, shape (n_points,)
    Probabilities in [0, 1], no NaN."""


@fill_doc(checked_params=_CHECKED_PARAMS)
def tpr_fdr_points(labels: NDArray[np.bool_], probs: NDArray[np.float64],
                   ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Counts at every distinct threshold, highest first, after (0, 0).

    {checked_params}

    Returns
    -------
    fdr, tpr, thresholds : ndarray of shape (n_thresholds + 1,)
        The curve of :func:`~occgp.evaluation.metrics.tpr_fdr_curve`.
    """
    order = np.argsort(-probs, kind="mergesort")
    p_sorted = probs[order]
    y_sorted = labels[order]
    last = np.r_[np.flatnonzero(np.diff(p_sorted)), p_sorted.shape[0] - 1]
    tps = np.cumsum(y_sorted)[last].astype(np.float64)
    fps = (last + 1) - tps
    tpr = np.r_[0.0, tps / tps[-1]]
    fdr = np.r_[0.0, fps / (tps + fps)]
    thresholds = np.r_[np.inf, p_sorted[last]]
    return fdr, tpr, thresholds


def tpr_fdr_area(fdr: ArrayLike, tpr: ArrayLike, anchored: bool = True) -> float:
    """Trapezoid area along a TPR-FDR path of operating points (by decreasing threshold).

    Anchored: the path runs from (0, 0) through the points and is closed with a
    flat segment to (1, 1) (occgp's area). Unanchored: the path through the
    points only (the authors' area; 0 for fewer than two points).

    Parameters
    ----------
    fdr, tpr : array-like of shape (n_thresholds,)
        The operating points, by decreasing threshold, without (0, 0).
    anchored : bool, default=True
        Whether the path is anchored at (0, 0) and (1, 1).

    Returns
    -------
    area : float
    """
    if anchored:
        return float(np.trapezoid(np.r_[0.0, tpr, 1.0], np.r_[0.0, fdr, 1.0]))
    fdr, tpr = np.asarray(fdr, dtype=np.float64), np.asarray(tpr, dtype=np.float64)
    return float(np.trapezoid(tpr, fdr)) if len(fdr) > 1 else 0.0


@fill_doc(checked_params=_CHECKED_PARAMS)
def tpr_fdr_auc_unchecked(labels: NDArray[np.bool_], probs: NDArray[np.float64],
                          anchored: bool = True) -> float:
    """:func:`~occgp.evaluation.metrics.tpr_fdr_auc` of checked arrays.

    {checked_params}
    anchored : bool, default=True
        Whether the area is anchored at (0, 0) and (1, 1) (see :func:`tpr_fdr_area`).

    Returns
    -------
    auc : float
    """
    fdr, tpr, _ = tpr_fdr_points(labels, probs)
    return tpr_fdr_area(fdr[1:], tpr[1:], anchored)
