"""GP regression over mixed point and segment observations: LML, its gradient, fitting.

Shared by :class:`~occgp.gp.GPOMIK` (points and segments) and
:class:`~occgp.gp.GPOM` (points only). The covariance of the targets is
``K + (noise + jitter) I``: ``K`` the integral-kernel matrix, ``noise`` the
global noise variance (a hyper-parameter) and ``jitter = 1e-10 * mean(diag K)``,
which keeps the factorisation defined when the fitted noise sits at its lower
bound.
"""

from __future__ import annotations

import logging

import numpy as np
import scipy.linalg as sl
from scipy import optimize

from ._integral import _covariance

__all__ = ["JITTER", "jitter_for", "log_marginal_likelihood", "optimize_hyperparameters",
           "factorise"]

#: Jitter added to the diagonal, relative to the mean of diag(K).
JITTER = 1e-10

_LOG = logging.getLogger("occgp")


def jitter_for(K):
    """The jitter for kernel matrix `K`: ``JITTER * mean(diag K)``."""
    return JITTER * max(float(np.mean(np.diag(K))), 1e-300) if len(K) else 0.0


def _with_noise(K, noise, jitter=None):
    K[np.diag_indices_from(K)] += noise + (jitter_for(K) if jitter is None else jitter)
    return K


def factorise(kernel, quadrature, noise, starts, ends, y, n_threads=1, jitter=None):
    """Lower Cholesky factor of the target covariance and ``alpha = K^-1 y``.

    `jitter` None means ``jitter_for(K)``.
    """
    K = _with_noise(_covariance(kernel, quadrature, starts, ends, n_threads=n_threads),
                    noise, jitter)
    L = sl.cholesky(K, lower=True, check_finite=False)
    return L, solve_lower(L, y)


def solve_lower(L, y, z=None):
    """``alpha = K^-1 y`` from the lower factor ``L`` (``z = L^-1 y`` if known)."""
    if z is None:
        z = sl.solve_triangular(L, y, lower=True, check_finite=False)
    return sl.solve_triangular(L, z, lower=True, trans="T", check_finite=False)


def log_marginal_likelihood(theta, kernel, quadrature, starts, ends, y, n_threads=1):
    """Log marginal likelihood and its gradient at ``theta = [kernel.theta, log(noise)]``."""
    k = kernel.with_theta(theta[:-1])
    noise = float(np.exp(theta[-1]))
    K, dK = _covariance(k, quadrature, starts, ends, eval_gradient=True, n_threads=n_threads)
    _with_noise(K, noise)
    try:
        L = sl.cholesky(K, lower=True, check_finite=False)
    except np.linalg.LinAlgError:
        return -np.inf, np.zeros_like(theta)
    alpha = solve_lower(L, y)
    n = len(y)
    lml = -0.5 * y @ alpha - np.log(np.diag(L)).sum() - 0.5 * n * np.log(2.0 * np.pi)
    Linv = sl.solve_triangular(L, np.eye(n), lower=True, check_finite=False)
    W = np.outer(alpha, alpha) - Linv.T @ Linv
    grad = np.empty_like(theta)
    grad[:-1] = 0.5 * np.einsum("ij,kij->k", W, dK)
    grad[-1] = 0.5 * noise * np.trace(W)
    return float(lml), grad


def optimize_hyperparameters(kernel, noise, noise_bounds, starts, ends, y, quadrature, *,
                             n_restarts=2, rng=None, n_threads=1):
    """Maximise the log marginal likelihood with L-BFGS-B in log space.

    The first start is the given hyper-parameters; `n_restarts` more are drawn
    log-uniformly within the bounds from `rng`. Returns the best
    ``(kernel, noise, lml)``.
    """
    bounds = np.vstack([kernel.bounds, np.log(np.asarray(noise_bounds, dtype=np.float64))])
    theta0 = np.r_[kernel.theta, np.log(noise)]
    theta0 = np.clip(theta0, bounds[:, 0], bounds[:, 1])
    starts_theta = [theta0]
    for _ in range(n_restarts):
        starts_theta.append(rng.uniform(bounds[:, 0], bounds[:, 1]))

    def objective(theta):
        lml, grad = log_marginal_likelihood(theta, kernel, quadrature, starts, ends, y, n_threads)
        if not np.isfinite(lml):
            return 1e25, np.zeros_like(theta)
        return -lml, -grad

    best = None
    for i, t0 in enumerate(starts_theta):
        res = optimize.minimize(objective, t0, jac=True, method="L-BFGS-B", bounds=bounds)
        _LOG.debug("hyper-parameter start %d: -lml %.6g after %d evaluations", i, res.fun, res.nfev)
        if best is None or res.fun < best.fun:
            best = res
    theta = best.x
    return kernel.with_theta(theta[:-1]), float(np.exp(theta[-1])), float(-best.fun)
