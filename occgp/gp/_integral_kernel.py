"""Integral kernels: covariances between points and line segments.

An observation is a point or a segment; a point is a segment whose two ends
coincide. The covariance of a segment ``l`` and a point ``x`` is the kernel
integrated along the segment's arc length, ``k(l, x) = int_0^|l| k(l(s), x) ds``;
between two segments it is the double integral (O'Callaghan & Ramos, 2012,
Eq. 5–6). The compiled core (:mod:`occgp._integral`) evaluates every entry:
closed forms for the squared exponential, adaptive quadrature otherwise.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .. import _integral
from .._validation import as_numeric, as_points, check_bool
from ._kernels import Stationary
from ._limits import check_coordinates, check_dense, check_segments, threads
from ._quadrature import ClenshawCurtis, Simpson, Rule

__all__ = ["integral_kernel"]


def check_kernel(kernel):
    if not isinstance(kernel, Stationary):
        raise TypeError("kernel must be one of occgp.gp's kernels (SquaredExponential, "
                        f"Matern32, SparseKernel), got {type(kernel).__name__}")
    return kernel


def check_quadrature(quadrature):
    if quadrature is None or quadrature == "clenshaw-curtis":
        return ClenshawCurtis()
    if quadrature == "simpson":
        return Simpson()
    if isinstance(quadrature, Rule):
        quadrature._checked()
        return quadrature
    raise ValueError("quadrature must be 'clenshaw-curtis', 'simpson', a ClenshawCurtis or "
                     f"Simpson instance, or None, got {quadrature!r}")


def as_segments(starts, ends, name="segment", dim=None):
    """Validate paired start and end points; returns (starts, ends) float64 (n, D)."""
    starts_name, ends_name = f"{name}_starts", f"{name}_ends"
    if dim is None:
        starts = as_numeric(starts, starts_name)
        dim = starts.shape[1] if starts.ndim == 2 else -1
        if not 1 <= dim <= 3:
            raise ValueError(f"{starts_name} must have shape (n, D) with D in 1..3, "
                             f"got {np.shape(starts)}")
    starts = as_points(starts, starts_name, dim)
    ends = as_points(ends, ends_name, dim)
    if starts.shape != ends.shape:
        raise ValueError(f"{starts_name} and {ends_name} must have the same shape, got "
                         f"{starts.shape} and {ends.shape}")
    return starts, ends


class _Prepared:
    """Scaled start points, scaled directions and arc lengths of observations."""

    __slots__ = ("A", "V", "length")

    def __init__(self, starts, ends, inv_ls):
        self.A = np.ascontiguousarray(starts * inv_ls)
        self.V = np.ascontiguousarray((ends - starts) * inv_ls)
        self.length = np.ascontiguousarray(np.linalg.norm(ends - starts, axis=1))


def covariance(kernel, quadrature, starts1, ends1, starts2=None, ends2=None, *,
                eval_gradient=False, n_threads=1):
    """Kernel matrix (with the variance) and, optionally, its gradient (n_theta, n1, n2)."""
    variance = float(kernel.variance)
    dim = starts1.shape[1]
    inv_ls = kernel.inverse_length_scales(dim)
    one = _Prepared(starts1, ends1, inv_ls)
    same = starts2 is None
    two = one if same else _Prepared(starts2, ends2, inv_ls)
    n1, n2 = len(one.length), len(two.length)
    nodes, weights, offsets, reach = quadrature.table(kernel)
    K = np.empty((n1, n2))
    grad = np.empty((dim, n1, n2)) if eval_gradient else None
    _integral.observation_covariance(
        type(kernel).kind, float(type(kernel).cutoff2), one.A, one.V, one.length,
        two.A, two.V, two.length, same, nodes, weights, offsets, reach, K, grad, n_threads)
    K *= variance
    if not eval_gradient:
        return K
    grad *= variance
    if not kernel.anisotropic:
        grad = grad.sum(axis=0, keepdims=True)
    return K, np.concatenate([K[None], grad], axis=0)


def integral_kernel(kernel, starts: ArrayLike, ends: ArrayLike, starts2: ArrayLike | None = None,
                    ends2: ArrayLike | None = None, *, quadrature=None,
                    eval_gradient: bool = False, n_jobs: int | None = None):
    """Covariance matrix between observations that are points or line segments.

    Observation ``i`` is the segment from ``starts[i]`` to ``ends[i]``, or the
    point ``starts[i]`` when both coincide. Entries are the kernel integrated
    over the arc length of each segment: ``k(l, x) = int_0^|l| k(l(s), x) ds``
    between a segment and a point, the double integral between two segments.

    * squared exponential: segment–point in closed form (erf), segment–segment
      by quadrature of the closed form along the shorter segment;
    * Matérn 3/2 and the sparse kernel: quadrature split at the closest point
      (where the profile has a kink) and, for the sparse kernel, clipped to
      its support.

    The quadrature order adapts to each piece's length in length-scale units
    (see :class:`ClenshawCurtis`). Entries are symmetric by construction.

    Parameters
    ----------
    kernel : SquaredExponential, Matern32 or SparseKernel
    starts, ends : array-like of shape (n_obs, D)
        The observations; D is 1, 2 or 3.
    starts2, ends2 : array-like of shape (n_obs2, D), default=None
        A second set; None means the first one again (a symmetric matrix).
    quadrature : {"clenshaw-curtis", "simpson"}, ClenshawCurtis, Simpson or None
        The rule; None means ``ClenshawCurtis()`` (tol 1e-10).
    eval_gradient : bool, default=False
        Also return the gradient with respect to ``kernel.theta`` (only for
        one set).
    n_jobs : int, default=None
        Threads (None: 1; -1: every core). The result does not depend on it.

    Returns
    -------
    K : ndarray of shape (n_obs, n_obs2)
    K_gradient : ndarray of shape (n_obs, n_obs, n_theta)
        Only with `eval_gradient`.

    Raises
    ------
    ValueError
        On NaN or inf, bad shapes, observations beyond 1e10 length scales
        from the origin or segments longer than 1e4 length scales (see
        ``occgp.gp._limits``), or a result of more than 4 GiB.
    TypeError
        On non-numeric observations, a kernel or quadrature of another kind,
        or a non-bool `eval_gradient`.

    Examples
    --------
    A unit segment against a point on its line, one length scale beyond its end:

    >>> from occgp.gp import SquaredExponential
    >>> K = integral_kernel(SquaredExponential(), [[0.0, 0.0], [2.0, 0.0]],
    ...                     [[1.0, 0.0], [2.0, 0.0]])
    >>> from scipy.special import erf
    >>> exact = np.sqrt(np.pi / 2) * (erf(2 / np.sqrt(2)) - erf(1 / np.sqrt(2)))
    >>> bool(np.isclose(K[0, 1], exact, rtol=1e-14, atol=0))   # int_0^1 exp(-(2-s)^2/2) ds
    True
    >>> bool(np.allclose(K, K.T))
    True
    """
    kernel = check_kernel(kernel)
    quadrature = check_quadrature(quadrature)
    n_threads = threads(n_jobs)
    eval_gradient = check_bool(eval_gradient, "eval_gradient")
    starts, ends = as_segments(starts, ends, "observation")
    if (starts2 is None) != (ends2 is None):
        raise ValueError("starts2 and ends2 must be given together")
    if starts2 is not None:
        if eval_gradient:
            raise ValueError("eval_gradient is only supported for one set of observations")
        starts2, ends2 = as_segments(starts2, ends2, "observation2", dim=starts.shape[1])
    inv = kernel.inverse_length_scales(starts.shape[1])
    sets = [("observation", starts, ends)]
    if starts2 is not None:
        sets.append(("observation2", starts2, ends2))
    for name, a, b in sets:
        check_coordinates({f"{name}_starts": a, f"{name}_ends": b}, inv,
                          fix="shift the observations towards the origin")
        check_segments(a, b, inv, name)
    n2 = len(starts) if starts2 is None else len(starts2)
    check_dense(len(starts), n2, 1 + (kernel.n_theta + 1 if eval_gradient else 0),
                "the kernel matrix", "pass fewer observations at a time")
    out = covariance(kernel, quadrature, starts, ends, starts2, ends2,
                      eval_gradient=eval_gradient, n_threads=n_threads)
    if eval_gradient:
        return out[0], np.moveaxis(out[1], 0, -1)
    return out
