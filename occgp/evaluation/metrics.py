"""Scores of occupancy predictions against labelled test points.

Every function takes `y_true`, the true labels of test points (``True`` or
``1`` = occupied, ``False`` or ``0`` = free), and `y_prob`, the occupancy
probabilities a map predicts for them. A map answers NaN where a point lies in
no known cell; **every function here scores NaN as p = 0.5**, as the
evaluation protocol of occgp prescribes (see DESIGN "Evaluation"): an unknown
point is then uninformative for ROC and TPR–FDR curves, costs 0.25 in the MSE
and is wrong for both accuracies.

The ROC curve and its area wrap :func:`sklearn.metrics.roc_curve` and
:func:`sklearn.metrics.roc_auc_score` (exact and tie-aware). The TPR–FDR curve
of Miao et al. is computed here with the same conventions.
"""

from __future__ import annotations

import textwrap

import numpy as np
from numpy.typing import ArrayLike, NDArray
from sklearn import metrics as _skm

from .._docfill import fill_doc
from .._validation import as_numeric, check_bool, check_real
from ._tpr_fdr import tpr_fdr_auc_unchecked, tpr_fdr_points

__all__ = [
    "roc_curve",
    "roc_auc",
    "mse",
    "accuracy",
    "tpr_fdr_curve",
    "tpr_fdr_auc",
    "score_all",
]

#: The docstring sections every score shares (see :func:`occgp._docfill.fill_doc`).
_SECTIONS = {
    "y_params": """Parameters
----------
y_true : array-like of shape (n_points,)
    True labels: ``True``/``1`` occupied, ``False``/``0`` free.
y_prob : array-like of shape (n_points,)
    Predicted occupancy probabilities in [0, 1]; NaN = unknown.""",
    "type_error": """TypeError
    If an array is not numeric or boolean.""",
}


def _invalid_input(more):
    """The Raises section of a score that checks its input as :func:`mse` does, and `more`."""
    text = textwrap.fill(f"If the input is invalid (see :func:`mse`){more}.", 76)
    return "\n".join(["Raises", "------", "ValueError", textwrap.indent(text, "    "),
                      _SECTIONS["type_error"]])


def _check_labels_probs(y_true, y_prob):
    """Validate and coerce a pair of label and probability arrays.

    Returns
    -------
    labels : ndarray of bool, shape (n,)
    probs : ndarray of float64, shape (n,)
        `y_prob` with NaN replaced by 0.5.
    unknown : ndarray of bool, shape (n,)
        Where `y_prob` was NaN.
    """
    y_true = as_numeric(y_true, "y_true", kinds="biuf")
    y_prob = as_numeric(y_prob, "y_prob", kinds="biuf")
    for name, arr in (("y_true", y_true), ("y_prob", y_prob)):
        if arr.ndim != 1:
            raise ValueError(f"{name} must have shape (n_points,), got {arr.shape}")
    if y_true.shape[0] != y_prob.shape[0]:
        raise ValueError(
            "y_true and y_prob must have the same length, got "
            f"{y_true.shape[0]} and {y_prob.shape[0]}"
        )
    if y_true.shape[0] == 0:
        raise ValueError("y_true and y_prob must not be empty, got 0 test points")
    if y_true.dtype.kind == "b":
        labels = y_true
    else:
        bad = (y_true != 0) & (y_true != 1)
        if bad.any():
            raise ValueError(
                "y_true must hold only 0/1 or booleans, got "
                f"{np.unique(y_true[bad])[:5].tolist()}"
            )
        labels = y_true == 1
    probs = y_prob.astype(np.float64)
    unknown = np.isnan(probs)
    if np.isinf(probs).any():
        raise ValueError("y_prob must be probabilities in [0, 1] or NaN, got inf")
    known = probs[~unknown]
    if known.size and (known.min() < 0.0 or known.max() > 1.0):
        raise ValueError(
            "y_prob must be probabilities in [0, 1] or NaN, got values in "
            f"[{known.min():g}, {known.max():g}]"
        )
    probs = np.where(unknown, 0.5, probs)
    return np.ascontiguousarray(labels, dtype=bool), probs, unknown


def _require_both_classes(labels, what):
    n_pos = int(labels.sum())
    if n_pos == 0 or n_pos == labels.shape[0]:
        present = "occupied" if n_pos else "free"
        raise ValueError(
            f"{what} needs both occupied and free test points in y_true, "
            f"got only {present} ones ({labels.shape[0]} points)"
        )


@fill_doc(**_SECTIONS)
def roc_curve(
    y_true: ArrayLike, y_prob: ArrayLike, *, drop_intermediate: bool = True
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Receiver operating characteristic of occupancy predictions.

    A point is predicted occupied when its probability is at least the
    threshold. Unknown points (NaN) count as p = 0.5.

    {y_params}
    drop_intermediate : bool, default=True
        Drop thresholds that lie on straight segments of the curve (as in
        scikit-learn); the area is unchanged.

    Returns
    -------
    fpr : ndarray of shape (n_thresholds,)
        False positive rates, increasing.
    tpr : ndarray of shape (n_thresholds,)
        True positive rates, increasing.
    thresholds : ndarray of shape (n_thresholds,)
        Decreasing thresholds; the first is ``inf`` (nothing predicted
        occupied).

    Raises
    ------
    ValueError
        If the arrays are not 1-D of equal non-zero length, if `y_true` holds
        other values than 0/1, if `y_prob` leaves [0, 1], or if `y_true` holds
        only one class.
    {type_error}

    See Also
    --------
    roc_auc : The area under this curve.

    Examples
    --------
    >>> fpr, tpr, thr = roc_curve([0, 0, 1, 1], [0.1, 0.6, 0.4, 0.9])
    >>> fpr.tolist(), tpr.tolist()
    ([0.0, 0.0, 0.5, 0.5, 1.0], [0.0, 0.5, 0.5, 1.0, 1.0])
    """
    labels, probs, _ = _check_labels_probs(y_true, y_prob)
    _require_both_classes(labels, "roc_curve")
    fpr, tpr, thresholds = _skm.roc_curve(
        labels, probs, drop_intermediate=drop_intermediate
    )
    return fpr, tpr, thresholds


@fill_doc(**_SECTIONS, raises=_invalid_input(" or `y_true` holds only one class"))
def roc_auc(y_true: ArrayLike, y_prob: ArrayLike) -> float:
    """Area under the ROC curve of occupancy predictions.

    The probability that a random occupied test point gets a higher
    probability than a random free one, ties counting one half (exact,
    tie-aware). Unknown points (NaN) count as p = 0.5.

    {y_params}

    Returns
    -------
    auc : float
        1 for a perfect ranking, 0.5 for a random one, 0 for an inverted one.

    {raises}

    See Also
    --------
    roc_curve : The curve itself.

    Examples
    --------
    >>> roc_auc([0, 0, 1, 1], [0.1, 0.6, 0.4, 0.9])
    0.75
    >>> roc_auc([0, 1], [np.nan, np.nan])   # unknown everywhere: no ranking
    0.5
    """
    labels, probs, _ = _check_labels_probs(y_true, y_prob)
    _require_both_classes(labels, "roc_auc")
    return float(_skm.roc_auc_score(labels, probs))


@fill_doc(**_SECTIONS)
def mse(y_true: ArrayLike, y_prob: ArrayLike) -> float:
    """Mean squared error of occupancy probabilities against 0/1 labels.

    Unknown points (NaN) count as p = 0.5, so each costs 0.25.

    {y_params}

    Returns
    -------
    mse : float
        ``mean((y_prob - y_true) ** 2)``, in [0, 1].

    Raises
    ------
    ValueError
        If the arrays are not 1-D of equal non-zero length, if `y_true` holds
        other values than 0/1, or if `y_prob` leaves [0, 1].
    {type_error}

    Examples
    --------
    >>> mse([1, 0], [0.8, np.nan])
    0.145
    """
    labels, probs, _ = _check_labels_probs(y_true, y_prob)
    return float(np.mean((probs - labels) ** 2))


@fill_doc(**_SECTIONS, raises=_invalid_input(" or `threshold` is not in [0, 1]"))
def accuracy(
    y_true: ArrayLike, y_prob: ArrayLike, threshold: float = 0.5
) -> tuple[float, float]:
    """Accuracies on occupied and on free test points.

    The comparisons are **strict**: an occupied point is right when
    ``p > threshold`` and a free point when ``p < threshold``, so a point
    predicted exactly at the threshold is wrong for both. With the default
    threshold 0.5 an unknown point (NaN, counted as p = 0.5) is therefore
    wrong whatever its label, as the evaluation protocol requires.

    {y_params}
    threshold : float, default=0.5
        Occupancy threshold in [0, 1].

    Returns
    -------
    acc_occupied : float
        Fraction of occupied points with ``p > threshold``; NaN if there are
        no occupied points.
    acc_free : float
        Fraction of free points with ``p < threshold``; NaN if there are no
        free points.

    {raises}

    Examples
    --------
    >>> accuracy([1, 1, 0, 0], [0.9, 0.5, 0.2, np.nan])
    (0.5, 0.5)
    """
    labels, probs, _ = _check_labels_probs(y_true, y_prob)
    threshold = _check_threshold(threshold)
    return _accuracy(labels, probs, threshold)


def _check_threshold(threshold):
    return check_real(threshold, "threshold", low=0.0, high=1.0, low_open=False,
                      high_open=False)


def _accuracy(labels, probs, threshold):
    n_occ = int(labels.sum())
    n_free = labels.shape[0] - n_occ
    hits_occ = int(np.count_nonzero(labels & (probs > threshold)))
    hits_free = int(np.count_nonzero(~labels & (probs < threshold)))
    acc_occ = hits_occ / n_occ if n_occ else float("nan")
    acc_free = hits_free / n_free if n_free else float("nan")
    return acc_occ, acc_free


@fill_doc(**_SECTIONS,
          raises=_invalid_input(" or `y_true` holds no occupied point (TPR undefined)"))
def tpr_fdr_curve(
    y_true: ArrayLike, y_prob: ArrayLike, *, anchored: bool = True
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """True positive rate against false discovery rate over thresholds.

    The ROC variant that Miao et al. use for unbalanced occupancy data (most
    test cells free): for each threshold t a point is predicted occupied when
    ``p >= t``; TPR = TP / (TP + FN) and FDR = FP / (TP + FP). Every distinct
    probability is a threshold, highest first, so ties move together (the
    curve is tie-aware). Unknown points (NaN) count as p = 0.5.

    {y_params}
    anchored : bool, default=True
        Whether the curve starts at (0, 0) (threshold ``inf``); False: the
        measured operating points only.

    Returns
    -------
    fdr : ndarray of shape (n_thresholds + 1,)
        False discovery rates (x axis, like ``fpr`` of :func:`roc_curve`);
        ``n_thresholds`` entries when not `anchored`.
    tpr : ndarray of shape (n_thresholds + 1,)
        True positive rates, non-decreasing.
    thresholds : ndarray of shape (n_thresholds + 1,)
        Decreasing thresholds, the first ``inf`` when `anchored`.

    {raises}

    See Also
    --------
    tpr_fdr_auc : The area under this curve.

    Notes
    -----
    The curve starts at (FDR, TPR) = (0, 0) with threshold ``inf``, where
    nothing is predicted occupied and FDR = 0/0 is taken as 0 (the convention
    of precision = 1 at recall 0 in precision–recall curves). It ends at the
    lowest probability, where everything is predicted occupied:
    TPR = 1 and FDR = the fraction of free test points. FDR need not be
    monotone in the threshold, so the curve may fold back.

    References
    ----------
    Y. Miao, A. Hunter, I. Georgilas, "An occupancy mapping method based on
    k-nearest neighbours", Sensors 22(1), 139, 2022.

    Examples
    --------
    >>> fdr, tpr, thr = tpr_fdr_curve([1, 0, 1, 0], [0.9, 0.7, 0.6, 0.1])
    >>> fdr.tolist()
    [0.0, 0.0, 0.5, 0.3333333333333333, 0.5]
    >>> tpr.tolist()
    [0.0, 0.5, 0.5, 1.0, 1.0]
    >>> tpr_fdr_curve([1, 0, 1, 0], [0.9, 0.7, 0.6, 0.1], anchored=False)[0].tolist()
    [0.0, 0.5, 0.3333333333333333, 0.5]
    """
    anchored = check_bool(anchored, "anchored")
    labels, probs, _ = _check_labels_probs(y_true, y_prob)
    _require_positive(labels)
    fdr, tpr, thresholds = tpr_fdr_points(labels, probs)
    if anchored:
        return fdr, tpr, thresholds
    return fdr[1:], tpr[1:], thresholds[1:]


def _require_positive(labels):
    if not labels.any():
        raise ValueError(
            "the TPR-FDR curve needs at least one occupied test point in y_true, "
            f"got only free ones ({labels.shape[0]} points)"
        )


@fill_doc(**_SECTIONS, raises=_invalid_input(" or `y_true` holds no occupied point"))
def tpr_fdr_auc(y_true: ArrayLike, y_prob: ArrayLike, *, anchored: bool = True) -> float:
    """Area under the TPR–FDR curve (higher is better).

    Miao et al. rank occupancy maps by the area under the TPR–FDR curve
    traced by varying the occupancy threshold. Anchored (occgp's area, the
    default), the curve of :func:`tpr_fdr_curve` runs from (0, 0) through
    every threshold in decreasing order to (fraction of free points, 1), and
    is closed with a flat segment to (1, 1): beyond the all-occupied
    prediction TPR stays 1. The area is the trapezoid rule along this path on
    FDR in [0, 1]. Unanchored (the authors' area), the path holds the
    measured operating points only, from the highest threshold's to the
    lowest's: the trapezoid rule ``sum((fdr[i+1] - fdr[i]) * (tpr[i+1] +
    tpr[i]) / 2)`` over them (0 for a single point); it leaves out the
    stretches before the first point and after the last, so curves whose
    points span different FDR ranges are measured over different ranges.

    {y_params}
    anchored : bool, default=True
        Anchor the path at (0, 0) and (1, 1) (True) or not (False).

    Returns
    -------
    auc : float
        1 for a perfect ranking; about the fraction of occupied points for a
        random one.

    {raises}

    See Also
    --------
    tpr_fdr_curve : The curve itself.

    Notes
    -----
    Where the curve folds back (FDR falling as the threshold falls) the
    trapezoids count with their sign, so the area is a line integral;
    integrating by parts, it equals the trapezoidal area under the
    precision–recall curve (TPR is recall and 1 − FDR is precision), and lies
    in [0, 1].

    Linear interpolation between operating points in precision–recall space
    is slightly optimistic (Davis & Goadrich, 2006); the plain trapezoid
    rule is kept because it is what an area over a threshold sweep, as
    Miao et al. use for parameter search, amounts to.

    Examples
    --------
    >>> tpr_fdr_auc([1, 1, 0, 0], [0.9, 0.8, 0.3, 0.1])   # perfect
    1.0
    >>> round(tpr_fdr_auc([1, 0, 1, 0], [0.9, 0.7, 0.6, 0.1]), 4)
    0.7917
    >>> round(tpr_fdr_auc([1, 0, 1, 0], [0.9, 0.7, 0.6, 0.1], anchored=False), 4)
    0.2917
    """
    anchored = check_bool(anchored, "anchored")
    labels, probs, _ = _check_labels_probs(y_true, y_prob)
    _require_positive(labels)
    return tpr_fdr_auc_unchecked(labels, probs, anchored)


@fill_doc(**_SECTIONS, raises=_invalid_input(
    ", `y_true` holds only one class, or `threshold` is not in [0, 1]"))
def score_all(
    y_true: ArrayLike, y_prob: ArrayLike, threshold: float = 0.5
) -> dict[str, float]:
    """All scores of the evaluation protocol at once.

    Validates the input once, counts NaN as p = 0.5, and returns ROC AUC,
    MSE, both accuracies at `threshold` and the TPR–FDR AUC.

    {y_params}
    threshold : float, default=0.5
        Occupancy threshold of the accuracies (strict, see :func:`accuracy`).

    Returns
    -------
    scores : dict
        Keys ``auc``, ``mse``, ``acc_occupied``, ``acc_free``,
        ``tpr_fdr_auc`` (floats), ``n_test`` (int, number of test points) and
        ``unknown_fraction`` (float, fraction of NaN predictions).

    {raises}

    Examples
    --------
    >>> s = score_all([1, 1, 0, 0], [0.9, np.nan, 0.2, 0.4])
    >>> s["auc"], s["acc_occupied"], s["unknown_fraction"]
    (1.0, 0.5, 0.25)
    """
    labels, probs, unknown = _check_labels_probs(y_true, y_prob)
    threshold = _check_threshold(threshold)
    _require_both_classes(labels, "score_all")
    acc_occ, acc_free = _accuracy(labels, probs, threshold)
    return {
        "auc": float(_skm.roc_auc_score(labels, probs)),
        "mse": float(np.mean((probs - labels) ** 2)),
        "acc_occupied": acc_occ,
        "acc_free": acc_free,
        "tpr_fdr_auc": tpr_fdr_auc_unchecked(labels, probs),
        "n_test": int(labels.shape[0]),
        "unknown_fraction": float(unknown.mean()),
    }
