"""Probabilistic least-squares classification (Rasmussen & Williams, §6.5).

A GP regression on labels in {-1, +1} gives a latent mean ``mu`` and variance
``var`` at each point; PLSC squashes them into a probability

    p(y = +1 | x) = Phi((a * mu + b) / sqrt(1 + a**2 * var)),

with ``a`` and ``b`` fitted by maximising the leave-one-out log predictive
probability of the training labels (against Platt's regularised targets by
default). The leave-one-out means and variances
come in closed form from the factorised covariance (R&W Eq. 5.12).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import lapack
from numpy.typing import ArrayLike, NDArray
from scipy import optimize, special

from .._validation import as_numeric, check_bool, check_real

__all__ = ["loo_predictions", "fit_plsc", "plsc_proba", "PLSCProba"]


def _finite(x, name, ndim=None):
    arr = as_numeric(x, name).astype(np.float64)
    if ndim is not None and arr.ndim != ndim:
        raise ValueError(f"{name} must be {ndim}-D, got shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} must be finite (found NaN or inf)")
    return arr


def loo_predictions(L: ArrayLike, y: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Leave-one-out predictive means and variances of a GP regression.

    With ``K`` the covariance of the training targets (noise included) and
    ``L`` its lower Cholesky factor: ``mu_i = y_i - [K^-1 y]_i / [K^-1]_ii``
    and ``var_i = 1 / [K^-1]_ii`` (Rasmussen & Williams, Eq. 5.12), the
    predictive distribution of ``y_i`` given every other target.

    Parameters
    ----------
    L : array-like of shape (n, n)
        Lower Cholesky factor of ``K``.
    y : array-like of shape (n,)
        Training targets.

    Returns
    -------
    mu, var : ndarray of shape (n,)

    Raises
    ------
    ValueError
        If `L` is not a finite (n, n) matrix with a positive diagonal, or `y`
        not finite of shape (n,).
    TypeError
        If `L` or `y` does not hold real numbers.

    Examples
    --------
    >>> K = np.array([[2.0, 1.0], [1.0, 2.0]])
    >>> mu, var = loo_predictions(np.linalg.cholesky(K), np.array([1.0, -1.0]))
    >>> mu.tolist(), var.tolist()      # y_0 | y_1: mean 1/2 * (-1), variance 2 - 1/2
    ([-0.5, 0.5], [1.5, 1.5])
    """
    L = _finite(L, "L", 2)
    y = _finite(y, "y", 1)
    if L.shape != (len(y), len(y)):
        raise ValueError(f"L must have shape (n, n) with n = len(y) = {len(y)}, got {L.shape}")
    if not (np.diag(L) > 0).all():
        raise ValueError("L must be a lower Cholesky factor, with a positive diagonal")
    Linv, info = lapack.dtrtri(L, lower=1)   # L^-1: a third of a triangular solve's work
    if info != 0:
        raise ValueError(f"L must be a lower Cholesky factor, with a positive diagonal "
                         f"(dtrtri failed with info {info})")
    Linv = np.tril(Linv)
    alpha = Linv.T @ (Linv @ y)
    kinv_diag = np.einsum("ij,ij->j", Linv, Linv)
    return y - alpha / kinv_diag, 1.0 / kinv_diag


def _neg_log_prob(params, mu, var, targets):
    """Minus the cross-entropy of Phi(z) against `targets`, and its gradient."""
    a, b = params
    s = np.sqrt(1.0 + a * a * var)
    z = (a * mu + b) / s
    log_pos, log_neg = special.log_ndtr(z), special.log_ndtr(-z)
    log_phi = -0.5 * z * z - 0.5 * np.log(2.0 * np.pi)
    dz = targets * np.exp(log_phi - log_pos) - (1.0 - targets) * np.exp(log_phi - log_neg)
    dz_da = (mu * s * s - (a * mu + b) * a * var) / s ** 3
    dz_db = 1.0 / s
    value = targets @ log_pos + (1.0 - targets) @ log_neg
    return -value, -np.array([dz @ dz_da, dz @ dz_db])


def fit_plsc(mu: ArrayLike, var: ArrayLike, labels: ArrayLike, *,
             platt_targets: bool = True) -> tuple[float, float]:
    """Fit PLSC's ``a`` and ``b`` on leave-one-out predictions.

    Maximises the leave-one-out log predictive probability
    ``sum_i log Phi(y_i (a mu_i + b) / sqrt(1 + a**2 var_i))`` over ``a > 0``
    and ``b`` (R&W Eq. 6.42) with L-BFGS-B and the analytic gradient. When the
    leave-one-out predictions separate the classes (as they do for laser
    data: a beam's neighbours all say free), this likelihood grows without
    bound as ``a`` does; with `platt_targets` the 0/1 targets are replaced by
    Platt's ``(N+ + 1) / (N+ + 2)`` and ``1 / (N- + 2)`` (Platt, 2000; the
    GPOMIK paper's reference for PLSC), a cross-entropy with a finite optimum.

    Parameters
    ----------
    mu, var : array-like of shape (n,)
        Leave-one-out means and variances (see :func:`loo_predictions`).
    labels : array-like of shape (n,)
        Classes, -1 (free) or +1 (occupied); both must occur.
    platt_targets : bool, default=True
        Use Platt's regularised targets instead of 0 and 1.

    Returns
    -------
    a, b : float

    Raises
    ------
    ValueError
        If the arrays differ in shape, hold NaN or inf or a negative
        variance, or the labels are not -1/+1 of both classes.
    TypeError
        If an array does not hold real numbers or `platt_targets` is not a
        bool.

    Examples
    --------
    >>> a, b = fit_plsc([1.0, 0.8, -0.9, -1.1], [0.1] * 4, [1, 1, -1, -1])
    >>> a > 0.5
    True
    """
    mu, var, labels = _finite(mu, "mu"), _finite(var, "var"), _finite(labels, "labels")
    platt_targets = check_bool(platt_targets, "platt_targets")
    if not (mu.shape == var.shape == labels.shape and mu.ndim == 1):
        raise ValueError(f"mu, var and labels must be 1-D of one length, got {mu.shape}, "
                         f"{var.shape} and {labels.shape}")
    if not np.isin(labels, (-1.0, 1.0)).all():
        raise ValueError("labels must be -1 or +1")
    if (var < 0).any():
        raise ValueError(f"var must be non-negative, got a minimum of {float(var.min())!r}")
    n_pos, n_neg = int((labels > 0).sum()), int((labels < 0).sum())
    if not (n_pos and n_neg):
        raise ValueError("PLSC needs both classes among the training labels")
    if platt_targets:
        targets = np.where(labels > 0, (n_pos + 1.0) / (n_pos + 2.0), 1.0 / (n_neg + 2.0))
    else:
        targets = (labels > 0).astype(np.float64)
    res = optimize.minimize(_neg_log_prob, np.array([1.0, 0.0]), args=(mu, var, targets),
                            jac=True, method="L-BFGS-B", bounds=[(1e-6, 1e6), (-1e6, 1e6)])
    return float(res.x[0]), float(res.x[1])


def plsc_proba(mu: ArrayLike, var: ArrayLike, a: float, b: float) -> NDArray[np.float64]:
    """``Phi((a mu + b) / sqrt(1 + a**2 var))``, the probability of class +1.

    Parameters
    ----------
    mu : array-like
        Latent means, finite.
    var : array-like
        Latent variances, finite and >= 0; broadcasts with `mu`.
    a, b : float
        The PLSC slope and offset (:func:`fit_plsc`), finite.

    Returns
    -------
    proba : ndarray of the broadcast shape of `mu` and `var`
        Probabilities in [0, 1].

    Raises
    ------
    ValueError
        On NaN or inf, a negative variance or shapes that do not broadcast.
    TypeError
        On non-numeric input.

    Examples
    --------
    >>> plsc_proba([0.0], [1.0], 1.0, 0.0).tolist()
    [0.5]
    """
    mu, var = _finite(mu, "mu"), _finite(var, "var")
    a, b = check_real(a, "a"), check_real(b, "b")
    if (var < 0).any():
        raise ValueError(f"var must be non-negative, got a minimum of {float(var.min())!r}")
    try:
        np.broadcast_shapes(mu.shape, var.shape)
    except ValueError:
        raise ValueError(f"mu and var must broadcast together, got shapes {mu.shape} and "
                         f"{var.shape}") from None
    return special.ndtr((a * mu + b) / np.sqrt(1.0 + a * a * var))


class PLSCProba:
    """Mix-in: ``predict_proba`` of a latent GP model, PLSC on its ``predict``.

    The class defines ``predict(X, return_var=True)`` and, once fitted,
    ``plsc_`` (PLSC's ``(a, b)``).
    """

    def predict_proba(self, X: ArrayLike) -> NDArray[np.float64]:
        """Probability of occupancy at points `X` (PLSC on the latent prediction).

        Parameters
        ----------
        X : array-like of shape (n_queries, D)
            Query points in the fitted model's dimension D. Must be finite.

        Returns
        -------
        proba : ndarray of shape (n_queries,)
            ``Phi((a mean + b) / sqrt(1 + a**2 var))`` with ``(a, b) = plsc_``
            and the mean and variance of :meth:`predict`.

        Raises
        ------
        NotFittedError, ValueError, TypeError
            As :meth:`predict`.

        Examples
        --------
        >>> from occgp.gp import GPOM
        >>> m = GPOM(optimizer=False).fit([[2.0]], [[0.0]], [[2.0]])
        >>> m.predict_proba([[2.0], [0.5]]).shape
        (2,)
        """
        mean, var = self.predict(X, return_var=True)
        a, b = self.plsc_
        return plsc_proba(mean, var, a, b)
