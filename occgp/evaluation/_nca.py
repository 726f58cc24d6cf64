"""Neighbourhood component feature selection (NCA-FS): per-feature weights.

The diagonal, regularised neighbourhood component analysis of Yang, Wang and
Zuo (2012), as MATLAB's ``fsrnca`` (regression) and ``fscnca`` (classification)
implement it: :func:`nca_feature_weights` (its Notes give the objective).
scikit-learn's :class:`~sklearn.neighbors.NeighborhoodComponentsAnalysis` learns
a full linear map instead, which gives no per-feature weight.
"""

from __future__ import annotations

import contextlib
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import minimize

from .._validation import as_numeric, check_bool, check_choice, check_int, check_n_jobs, \
    check_real, n_threads

__all__ = ["NCAResult", "nca_feature_weights", "MAX_NCA_BYTES"]

#: The most memory (bytes) the pairwise feature differences may take:
#: ``n_samples**2 * n_features * 8`` (2 GiB: 4,050 samples x 16 features).
MAX_NCA_BYTES = 2 * 1024 ** 3
_SIGMA_RANGE = (1e-8, 1e8)
_LAM_MAX = 1e10


class NCAResult(NamedTuple):
    """The result of :func:`nca_feature_weights`.

    Attributes
    ----------
    weights : ndarray of shape (n_features,)
        The learned feature weights :math:`|w_l|` (MATLAB's ``FeatureWeights``);
        the distance uses their squares.
    normalized : ndarray of shape (n_features,)
        ``weights / weights.max()``: the largest weight is 1 (all zeros if every
        weight is 0). This is the "normalised weight" the NCA parameter
        reduction compares across data sets.
    objective : float
        The minimised objective :math:`f(w)` (on the standardised data when
        ``standardize=True``).
    n_iter : int
        L-BFGS-B iterations run.
    converged : bool
        Whether L-BFGS-B reported convergence within `max_iter` iterations.
    """

    weights: NDArray[np.float64]
    normalized: NDArray[np.float64]
    objective: float
    n_iter: int
    converged: bool


def _as_X(X: ArrayLike) -> NDArray[np.float64]:
    arr = as_numeric(X, "X", kinds="biuf")
    if arr.ndim != 2 or arr.shape[1] < 1:
        raise ValueError(f"X must have shape (n_samples, n_features), got {arr.shape}")
    if arr.shape[0] < 3:
        raise ValueError(f"X must hold at least 3 samples, got {arr.shape[0]}")
    arr = np.ascontiguousarray(arr, dtype=np.float64)
    if not np.isfinite(arr).all():
        raise ValueError("X must be finite (found NaN or inf)")
    return arr


def _standardize(X: NDArray[np.float64]) -> NDArray[np.float64]:
    """Columns to zero mean and unit variance (constant ones to 0), overflow-free."""
    scale = np.abs(X).max(axis=0)
    X = X / np.where(scale > 0, scale, 1.0)        # |X| <= 1: mean and std cannot overflow
    X = X - X.mean(axis=0)
    std = X.std(axis=0)
    return X / np.where(std > 0, std, 1.0)


def _loss_matrix(y: ArrayLike, n: int, task: str, loss: str,
                 standardize: bool) -> NDArray[np.float64]:
    """The (n, n) matrix of l(y_i, y_j), after checking `y`."""
    kinds = "iuf" if task == "regression" else "biufUS"
    arr = as_numeric(y, "y", kinds=kinds)
    if arr.ndim != 1 or arr.shape[0] != n:
        raise ValueError(f"y must have shape (n_samples,) = ({n},), got {arr.shape}")
    if arr.dtype.kind == "f" and not np.isfinite(arr).all():
        raise ValueError("y must be finite (found NaN or inf)")
    if task == "classification":
        _, codes = np.unique(arr, return_inverse=True)
        codes = codes.ravel()
        if codes.max() == 0:
            raise ValueError("y must hold at least 2 classes, got 1")
        return (codes[:, None] != codes[None, :]).astype(np.float64)
    yf = arr.astype(np.float64)
    with np.errstate(over="ignore", invalid="ignore"):
        span = float(np.ptp(yf))
    if span == 0.0:
        raise ValueError(f"y must not be constant, got all {yf[0]!r}")
    if standardize:
        yf = _standardize(yf[:, None])[:, 0]
    elif not np.isfinite(span) or (loss == "squared" and not np.isfinite(span * span)):
        raise ValueError(f"y spans {span!r}, too wide for the {loss} loss in float64; "
                         "use standardize=True")
    diff = yf[:, None] - yf[None, :]
    return diff * diff if loss == "squared" else np.abs(diff)


def _objective(w: NDArray[np.float64], A: NDArray[np.float64], L: NDArray[np.float64],
               sigma: float, lam: float) -> tuple[float, NDArray[np.float64]]:
    """f(w) and its gradient; `A` is (d, n, n) with A[l, i, j] = |x_il - x_jl|."""
    d, n, _ = A.shape
    w2 = w * w
    D = (w2 @ A.reshape(d, n * n)).reshape(n, n)
    np.fill_diagonal(D, np.inf)
    D -= D.min(axis=1, keepdims=True)       # softmax shift: each row's nearest is 0
    P = np.exp(D / (-sigma))
    P /= P.sum(axis=1, keepdims=True)
    PL = P * L
    Lbar = PL.sum(axis=1)                   # expected loss of each sample
    # d f / d w_l = -2 w_l / (n sigma) * sum_ij p_ij (L_ij - Lbar_i) A_lij + 2 lam w_l
    M = PL - P * Lbar[:, None]
    G = A.reshape(d, n * n) @ M.ravel()
    f = float(Lbar.mean() + lam * w2.sum())
    grad = (-2.0 / (n * sigma)) * w * G + 2.0 * lam * w
    return f, grad


def nca_feature_weights(X: ArrayLike, y: ArrayLike, *, task: str = "regression",
                        sigma: float = 1.0, lam: float | None = None,
                        loss: str = "squared", standardize: bool = True,
                        max_iter: int = 1000, n_jobs: int | None = None) -> NCAResult:
    """Learn a weight per feature by neighbourhood component feature selection.

    Minimises the regularised NCA objective of Yang, Wang and Zuo (2012)
    (see Notes) over the weights :math:`w` with L-BFGS-B and the analytic
    gradient, starting from all weights 1 (MATLAB's default). Features
    irrelevant to `y` end with weight ~0; the normalised weights rank the
    features (e.g. the parameters of a mapping method by their effect on TPR or
    FDR over a parameter grid).

    Parameters
    ----------
    X : array-like of shape (n_samples, n_features)
        The samples (e.g. one row of parameter values per grid combination).
        Must be finite, with at least 3 samples.
    y : array-like of shape (n_samples,)
        The response (regression; real, finite, not constant) or the class
        labels (classification; ints, bools or strings, at least 2 classes).
    task : {"regression", "classification"}, default="regression"
        ``"regression"`` as MATLAB's ``fsrnca``; ``"classification"`` as
        ``fscnca`` (Yang et al.'s NCA-FS: maximise the expected leave-one-out
        accuracy).
    sigma : float, default=1.0
        Kernel width of the reference probabilities, in [1e-8, 1e8].
    lam : float or None, default=None
        Ridge penalty :math:`\\lambda \\ge 0` on :math:`\\sum_l w_l^2`, at most
        1e10. None: ``1 / n_samples`` (MATLAB's default).
    loss : {"squared", "absolute"}, default="squared"
        The regression loss :math:`\\ell(y_i, y_j)`: :math:`(y_i - y_j)^2` or
        :math:`|y_i - y_j|`. Ignored for classification.
    standardize : bool, default=True
        Standardise each feature to zero mean and unit variance (a constant
        feature becomes 0) and, for regression, `y` likewise, so the weights do
        not depend on the units of the features or of `y`. MATLAB's default is
        False (raw values).
    max_iter : int, default=1000
        Most L-BFGS-B iterations (>= 1).
    n_jobs : int or None, default=None
        Threads for the BLAS contractions (joblib's counting: -1 every core).
        None: leave the BLAS thread count as it is.

    Returns
    -------
    result : NCAResult
        ``weights`` (the :math:`|w_l|`), ``normalized`` (``weights / max``),
        ``objective``, ``n_iter`` and ``converged``.

    Raises
    ------
    TypeError
        If `X` or `y` does not hold numbers (or labels, for classification), or
        `sigma`, `lam`, `standardize` or `max_iter` is of the wrong type.
    ValueError
        If `X` is not of shape (n_samples, n_features) with n_samples >= 3, or
        holds NaN or inf; if `y` is not of shape (n_samples,), holds NaN or inf,
        is constant (regression) or holds one class (classification), or spans
        too wide a range for float64 (without standardisation); if `task` or
        `loss` is unknown, `sigma` or `lam` out of range, `max_iter` < 1 or
        `n_jobs` is 0; if the pairwise differences, ``n_samples**2 *
        n_features * 8`` bytes, would exceed :data:`MAX_NCA_BYTES` (2 GiB:
        subsample the rows); or if the features span too wide a range for
        float64 without standardisation.

    Notes
    -----
    Each feature gets a weight :math:`w_l`; samples are compared by the
    weighted city-block distance

    .. math:: D_w(x_i, x_j) = \\sum_l w_l^2 \\, |x_{il} - x_{jl}|,

    and each sample picks a reference point among the others with probability

    .. math:: p_{ij} = \\frac{\\exp(-D_w(x_i, x_j) / \\sigma)}
              {\\sum_{k \\ne i} \\exp(-D_w(x_i, x_k) / \\sigma)}, \\qquad p_{ii} = 0.

    The weights minimise the expected leave-one-out loss plus a ridge penalty,

    .. math:: f(w) = \\frac{1}{n} \\sum_i \\sum_{j \\ne i} p_{ij} \\, \\ell(y_i, y_j)
              + \\lambda \\sum_l w_l^2,

    with :math:`\\ell(y_i, y_j) = (y_i - y_j)^2` or :math:`|y_i - y_j|` for
    regression and :math:`\\ell = [y_i \\ne y_j]` for classification, where
    :math:`f(w) = 1 - \\frac{1}{n} \\sum_i p_i + \\lambda \\|w\\|^2` with
    :math:`p_i = \\sum_{j: y_j = y_i} p_{ij}`: Yang et al.'s objective
    (maximise :math:`\\sum_i p_i - \\lambda' \\|w\\|^2`,
    :math:`\\lambda' = n\\lambda`). Features that do not help predict `y` are
    driven to weight ~0 by the penalty.

    Memory and time per iteration are O(n_samples**2 * n_features): the
    pairwise differences are stored once. 4,050 samples with 9 features take
    1.2 GB of differences and about 2 GB at the peak.

    References
    ----------
    W. Yang, K. Wang and W. Zuo, "Neighborhood component feature selection for
    high-dimensional data", Journal of Computers 7(1): 161-168, 2012.

    Examples
    --------
    >>> import numpy as np
    >>> from occgp.evaluation import nca_feature_weights
    >>> rng = np.random.default_rng(0)
    >>> X = rng.uniform(-1, 1, size=(150, 4))
    >>> y = 2 * X[:, 0] - X[:, 1] + 0.05 * rng.normal(size=150)
    >>> res = nca_feature_weights(X, y)
    >>> res.normalized.round(1)
    array([1. , 0.8, 0. , 0. ])
    """
    X = _as_X(X)
    n, d = X.shape
    task = check_choice(task, "task", ("regression", "classification"))
    loss = check_choice(loss, "loss", ("squared", "absolute"))
    sigma = check_real(sigma, "sigma", low=_SIGMA_RANGE[0], high=_SIGMA_RANGE[1],
                       low_open=False, high_open=False)
    lam = 1.0 / n if lam is None else check_real(lam, "lam", low=0.0, high=_LAM_MAX,
                                                  low_open=False, high_open=False)
    standardize = check_bool(standardize, "standardize")
    max_iter = check_int(max_iter, "max_iter", low=1)
    n_jobs = check_n_jobs(n_jobs)
    need = n * n * d * 8
    if need > MAX_NCA_BYTES:
        raise ValueError(f"X of shape {X.shape} needs n_samples**2 * n_features * 8 = "
                         f"{need / 1024**3:.1f} GiB of pairwise differences, more than the "
                         f"limit of {MAX_NCA_BYTES / 1024**3:.0f} GiB; subsample the rows "
                         f"(at most {int((MAX_NCA_BYTES / (8 * d)) ** 0.5)} samples for "
                         f"{d} features)")
    L = _loss_matrix(y, n, task, loss, standardize)
    if standardize:
        X = _standardize(X)
    else:
        with np.errstate(over="ignore", invalid="ignore"):
            span = np.ptp(X, axis=0)
        if not np.isfinite(span).all() or not np.isfinite(span.sum()):
            raise ValueError("X's features span too wide a range for float64 distances; "
                             "use standardize=True")
    A = X.T[:, :, None] - X.T[:, None, :]                # (d, n, n)
    np.abs(A, out=A)
    limits = contextlib.nullcontext()
    if n_jobs is not None:
        from threadpoolctl import threadpool_limits
        limits = threadpool_limits(n_threads(n_jobs))
    with limits:
        res = minimize(_objective, np.ones(d), args=(A, L, sigma, lam), jac=True,
                       method="L-BFGS-B", options={"maxiter": max_iter, "gtol": 1e-6})
    weights = np.abs(res.x)
    top = weights.max()
    normalized = weights / top if top > 0 else np.zeros(d)
    return NCAResult(weights=weights, normalized=normalized, objective=float(res.fun),
                     n_iter=int(res.nit), converged=bool(res.success))
