"""GP regression over mixed point and segment observations: LML, its gradient, fitting.

Shared by :class:`~occgp.gp.GPOMIK` (points and segments) and
:class:`~occgp.gp.GPOM` (points only). The covariance of the targets is
``K + (noise + jitter) I``: ``K`` the integral-kernel matrix, ``noise`` the
global noise variance (a hyper-parameter) and ``jitter = 1e-10 * mean(diag K)``,
which keeps the factorisation defined when the fitted noise sits at its lower
bound.

Repeated observations (the same start, end and target, as many identical beams
give) are merged for the hyper-parameter optimisation: ``c`` copies of an
observation with noise ``nu`` have the likelihood of one copy with noise
``nu / c``, times ``(2 pi nu)**(-(c - 1) / 2) / sqrt(c)`` (their residuals are
all equal), so the merged log marginal likelihood and its gradient are the
same numbers at a fraction of the cost.
"""

from __future__ import annotations

import logging

import numpy as np
import scipy.linalg as sl
from scipy import optimize

from ._integral_kernel import covariance

__all__ = ["JITTER", "OBJECTIVES", "jitter_for", "log_marginal_likelihood",
           "loo_log_predictive", "optimize_hyperparameters", "factorise", "cholesky",
           "unique_observations"]

#: Objectives of the hyper-parameter fit: the log marginal likelihood, or the
#: leave-one-out log predictive probability (Rasmussen & Williams, §5.4.2).
OBJECTIVES = ("lml", "loo")

#: Jitter added to the diagonal, relative to the mean of diag(K).
JITTER = 1e-10

_LOG = logging.getLogger("occgp")


def jitter_for(K):
    """The jitter for kernel matrix `K`: ``JITTER * mean(diag K)``."""
    return JITTER * max(float(np.mean(np.diag(K))), 1e-300) if len(K) else 0.0


def with_noise(K, noise, jitter=None):
    K[np.diag_indices_from(K)] += noise + (jitter_for(K) if jitter is None else jitter)
    return K


def cholesky(K, kernel, noise, what="the observations"):
    """Lower Cholesky factor of `K`, or a LinAlgError (a ValueError) saying what to change."""
    try:
        L = sl.cholesky(K, lower=True, check_finite=False)
    except np.linalg.LinAlgError:
        L = None
    if L is None or not np.isfinite(np.diag(L)).all():
        finite = bool(np.isfinite(K).all())
        cause = ("it is not numerically positive definite (observations that nearly "
                 "coincide in length-scale units, or SparseKernel in 2D or 3D, which is only "
                 "nearly positive definite) and the noise does not make up for it"
                 if finite else "it holds NaN or inf")
        raise np.linalg.LinAlgError(
            f"the covariance matrix of {what} ({len(K)} x {len(K)}, kernel {kernel!r}, noise "
            f"{noise:.3g}) cannot be factorised: {cause}; raise noise (and the lower bound of "
            f"noise_bounds), or thin out nearly coinciding observations") from None
    return L


def factorise(kernel, quadrature, noise, starts, ends, y, n_threads=1, jitter=None,
              what="the observations"):
    """Lower Cholesky factor of the target covariance and ``alpha = K^-1 y``.

    `jitter` None means ``jitter_for(K)``. A matrix that cannot be factorised
    raises a LinAlgError naming `what`, the kernel and the noise.
    """
    K = with_noise(covariance(kernel, quadrature, starts, ends, n_threads=n_threads),
                    noise, jitter)
    L = cholesky(K, kernel, noise, what)
    return L, solve_lower(L, y)


def unique_observations(starts, ends, y):
    """First occurrences of repeated observations and their counts, or None without repeats.

    Two observations repeat each other when start, end and target are equal.
    Returns ``(index, counts)``: ``index`` increasing.
    """
    if len(y) < 2:
        return None
    rows = np.column_stack([starts, ends, y]) + 0.0   # -0.0 and 0.0 are the same
    _, first, counts = np.unique(rows, axis=0, return_index=True, return_counts=True)
    if len(first) == len(y):
        return None
    order = np.argsort(first)
    return first[order], counts[order]


def solve_lower(L, y, z=None):
    """``alpha = K^-1 y`` from the lower factor ``L`` (``z = L^-1 y`` if known)."""
    if z is None:
        z = sl.solve_triangular(L, y, lower=True, check_finite=False)
    return sl.solve_triangular(L, z, lower=True, trans="T", check_finite=False)


def log_marginal_likelihood(theta, kernel, quadrature, starts, ends, y, n_threads=1,
                            counts=None):
    """Log marginal likelihood and its gradient at ``theta = [kernel.theta, log(noise)]``.

    With `counts`, observation ``i`` stands for ``counts[i]`` identical copies
    (see the module docstring): the value and gradient are those of the data
    with the copies.
    """
    k = kernel.with_theta(theta[:-1])
    noise = float(np.exp(theta[-1]))
    K, dK = covariance(k, quadrature, starts, ends, eval_gradient=True, n_threads=n_threads)
    if counts is None:
        with_noise(K, noise)
        share = 1.0
    else:
        counts = np.asarray(counts, dtype=np.float64)
        diag = np.diag(K)
        jitter = JITTER * max(float(counts @ diag / counts.sum()), 1e-300)
        share = 1.0 / counts
        K[np.diag_indices_from(K)] += (noise + jitter) * share
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
    grad[-1] = 0.5 * noise * (np.trace(W) if counts is None else np.diag(W) @ share)
    if counts is not None:  # the copies: (2 pi nu)^(-(c - 1) / 2) / sqrt(c) each
        nu = noise + jitter
        extra = float((counts - 1.0).sum())
        lml -= 0.5 * extra * np.log(2.0 * np.pi * nu) + 0.5 * np.log(counts).sum()
        grad[-1] -= 0.5 * extra * noise / nu
    return float(lml), grad


def loo_log_predictive(theta, kernel, quadrature, starts, ends, y, n_threads=1):
    """Leave-one-out log predictive probability and its gradient (R&W, Eq. 5.10–5.13).

    With ``C = K + (noise + jitter) I`` and ``alpha = C^-1 y``, observation
    ``i`` predicted from the others is ``N(y_i - alpha_i / [C^-1]_ii,
    1 / [C^-1]_ii)``; the objective is the sum of the log densities of the
    targets under those predictions. Its gradient with respect to each
    hyper-parameter ``t`` (``Z = C^-1 dC/dt``) is
    ``sum_i (alpha_i [Z alpha]_i - (1 + alpha_i^2 / [C^-1]_ii) [Z C^-1]_ii / 2)
    / [C^-1]_ii``. Unlike the log marginal likelihood it scores the
    predictions the map makes, not the data's probability under the model,
    and is more robust to a misspecified kernel (R&W, §5.4.2). Repeated
    observations are not merged: a copy left out is still predicted by the
    others.
    """
    k = kernel.with_theta(theta[:-1])
    noise = float(np.exp(theta[-1]))
    K, dK = covariance(k, quadrature, starts, ends, eval_gradient=True, n_threads=n_threads)
    with_noise(K, noise)
    try:
        L = sl.cholesky(K, lower=True, check_finite=False)
    except np.linalg.LinAlgError:
        return -np.inf, np.zeros_like(theta)
    n = len(y)
    Linv = sl.solve_triangular(L, np.eye(n), lower=True, check_finite=False)
    Cinv = Linv.T @ Linv
    alpha = Cinv @ y
    d = np.diag(Cinv).copy()
    if not np.all(d > 0):
        return -np.inf, np.zeros_like(theta)
    value = float(np.sum(-0.5 * np.log(2.0 * np.pi) + 0.5 * np.log(d) - 0.5 * alpha ** 2 / d))
    grad = np.empty_like(theta)
    factor = 0.5 * (1.0 + alpha ** 2 / d)
    for j in range(len(theta) - 1):
        Z = Cinv @ dK[j]
        ZC_diag = np.einsum("ij,ji->i", Z, Cinv)
        grad[j] = float(np.sum((alpha * (Z @ alpha) - factor * ZC_diag) / d))
    # noise: dC/dt = noise * I, so Z = noise * C^-1 (and C^-1 is symmetric)
    ZC_diag = noise * np.einsum("ij,ij->i", Cinv, Cinv)
    grad[-1] = float(np.sum((alpha * noise * (Cinv @ alpha) - factor * ZC_diag) / d))
    return value, grad


def optimize_hyperparameters(kernel, noise, noise_bounds, starts, ends, y, quadrature, *,
                             n_restarts=2, rng=None, n_threads=1, objective="lml"):
    """Maximise the log marginal likelihood with L-BFGS-B in log space.

    The first start is the given hyper-parameters; `n_restarts` more are drawn
    log-uniformly within the bounds from `rng`. Repeated observations are
    merged first (same value and gradient, see the module docstring). Returns
    the best ``(kernel, noise, lml)``.
    """
    return optimize_shared_hyperparameters(kernel, noise, noise_bounds, [(starts, ends, y)],
                                           quadrature, n_restarts=n_restarts, rng=rng,
                                           n_threads=n_threads, objective=objective)


def optimize_shared_hyperparameters(kernel, noise, noise_bounds, parts, quadrature, *,
                                    n_restarts=2, rng=None, n_threads=1, objective="lml"):
    """Maximise the sum of the log marginal likelihoods of independent `parts`.

    `parts` is a list of ``(starts, ends, y)``; each is one GP with the shared
    hyper-parameters (the experts of a mixture, Deisenroth & Ng 2015, §2.1).
    One part is :func:`optimize_hyperparameters`. `objective` ``"loo"``
    maximises the summed leave-one-out log predictive probabilities instead
    (:func:`loo_log_predictive`). Returns the best ``(kernel, noise,
    value)``, the value being the objective's.
    """
    bounds = np.vstack([kernel.bounds, np.log(np.asarray(noise_bounds, dtype=np.float64))])
    theta0 = np.r_[kernel.theta, np.log(noise)]
    theta0 = np.clip(theta0, bounds[:, 0], bounds[:, 1])
    starts_theta = [theta0]
    for _ in range(n_restarts):
        starts_theta.append(rng.uniform(bounds[:, 0], bounds[:, 1]))

    loo = objective == "loo"
    data = []
    for starts, ends, y in parts:
        counts = None
        repeats = None if loo else unique_observations(starts, ends, y)
        if repeats is not None:
            index, counts = repeats
            _LOG.debug("hyper-parameters: %d observations, %d distinct", len(y), len(index))
            starts, ends, y = starts[index], ends[index], y[index]
        data.append((starts, ends, y, counts))

    def objective(theta):
        total, total_grad = 0.0, np.zeros_like(theta)
        for starts, ends, y, counts in data:
            if loo:
                lml, grad = loo_log_predictive(theta, kernel, quadrature, starts, ends, y,
                                               n_threads)
            else:
                lml, grad = log_marginal_likelihood(theta, kernel, quadrature, starts, ends, y,
                                                    n_threads, counts)
            if not np.isfinite(lml):
                return 1e25, np.zeros_like(theta)
            total += lml
            total_grad += grad
        return -total, -total_grad

    best = None
    for i, t0 in enumerate(starts_theta):
        res = optimize.minimize(objective, t0, jac=True, method="L-BFGS-B", bounds=bounds)
        _LOG.debug("hyper-parameter start %d: -lml %.6g after %d evaluations", i, res.fun, res.nfev)
        if best is None or res.fun < best.fun:
            best = res
    theta = best.x
    return kernel.with_theta(theta[:-1]), float(np.exp(theta[-1])), float(-best.fun)
