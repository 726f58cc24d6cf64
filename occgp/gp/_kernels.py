"""Stationary covariance functions with ARD length scales and log-space hyper-parameters.

Each kernel is ``k(x, x') = variance * f(s)`` with ``s`` the squared distance
scaled by the length scales, ``s = sum_d ((x_d - x'_d) / l_d) ** 2``. The
profile ``f`` is all the integral kernels (:mod:`occgp.gp._integral_kernel`) need;
the compiled core evaluates the same profiles.

Hyper-parameters live in log space, ``theta = log([variance, *length_scale])``
(one length scale, or one per input dimension for ARD), with box bounds in log
space; gradients of a kernel matrix are with respect to ``theta``.
"""

from __future__ import annotations

import numbers
from numbers import Real

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._docfill import fill_doc
from .._params import Check, Interval, ParamsMixin
from .._validation import as_numeric, check_bool, check_int
from ._limits import MAX_DENSE_BYTES

__all__ = ["SquaredExponential", "Matern32", "SparseKernel"]

#: The Parameters section of the kernels (see :func:`occgp._docs.fill_doc`).
_KERNEL_PARAMETERS = """\
Parameters
----------
variance : float, default=1.0
    Signal variance ``sigma_f ** 2``.
length_scale : float or array-like of shape (n_features,), default=1.0
    One length scale, or one per input dimension (ARD).
variance_bounds, length_scale_bounds : pair of float
    Bounds used when hyper-parameters are fitted (default ``(1e-3, 1e3)``
    and ``(1e-2, 1e2)``)."""

_SQRT3 = np.sqrt(3.0)
_TWO_PI = 2.0 * np.pi


def _as_samples(x, name):
    """`x` as a finite float64 array of shape (n_samples, n_features); 1-D is one sample."""
    arr = np.atleast_2d(as_numeric(x, name))
    if arr.ndim != 2:
        raise ValueError(f"{name} must have shape (n_samples, n_features), got {arr.shape}")
    arr = arr.astype(np.float64)
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} must be finite (found NaN or inf)")
    return arr


def check_bounds(bounds, name):
    try:
        lo, hi = (float(b) for b in bounds)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a pair (low, high) of positive numbers, got {bounds!r}")
    if not (0 < lo < hi < np.inf):
        raise ValueError(f"{name} must satisfy 0 < low < high < inf, got {bounds!r}")
    return lo, hi


def _check_length_scale(value, name: str = "length_scale"):
    ls = np.asarray(value)
    if ls.dtype.kind not in "iuf":
        raise TypeError(f"{name} must hold real numbers, got dtype {ls.dtype}")
    ls = np.atleast_1d(ls.astype(np.float64))
    if ls.ndim != 1 or not (np.isfinite(ls).all() and (ls > 0).all()):
        raise ValueError(
            f"{name} must be a positive number or a 1-D array of them, got {value!r}")
    return ls


class Stationary(ParamsMixin):
    """Base of the stationary kernels: ``variance * f(s)``.

    Subclasses set ``kind`` (the compiled core's id), ``name`` and implement
    ``_profile(s)`` and ``_gradient_factor(s) = -2 f'(s)``. ``get_params`` /
    ``set_params`` (scikit-learn's estimator protocol) check the new values
    against ``_parameter_constraints`` before any changes.
    """

    _parameter_constraints = {
        "variance": [Interval(Real, 0, None, closed="neither")],
        "length_scale": [Check(_check_length_scale,
                               "a positive number or a 1-D array of them")],
        "variance_bounds": [Check(lambda v, name: check_bounds(v, name), "(low, high) bounds")],
        "length_scale_bounds": [Check(lambda v, name: check_bounds(v, name),
                                      "(low, high) bounds")],
    }

    kind = -1
    name = ""
    #: Squared scaled distance beyond which the kernel is treated as exactly 0
    #: (below 1e-18 of the variance; the compact sparse kernel vanishes at 1).
    cutoff2 = np.inf

    def __init__(self, variance: float = 1.0, length_scale: ArrayLike = 1.0, *,
                 variance_bounds=(1e-3, 1e3), length_scale_bounds=(1e-2, 1e2)):
        self.variance = variance
        self.length_scale = length_scale
        self.variance_bounds = variance_bounds
        self.length_scale_bounds = length_scale_bounds

    # -------------------------------------------------------------- parameters
    def _checked(self):
        if isinstance(self.variance, bool) or not isinstance(self.variance, numbers.Real):
            raise TypeError(f"variance must be a real number, got {type(self.variance).__name__}")
        variance = float(self.variance)
        if not (0 < variance < np.inf):
            raise ValueError(f"variance must be positive and finite, got {self.variance!r}")
        ls = _check_length_scale(self.length_scale)
        check_bounds(self.variance_bounds, "variance_bounds")
        check_bounds(self.length_scale_bounds, "length_scale_bounds")
        return variance, ls

    @property
    def anisotropic(self) -> bool:
        """Whether there is one length scale per input dimension (ARD)."""
        return np.ndim(self.length_scale) > 0 and np.size(self.length_scale) > 1

    @property
    def n_theta(self) -> int:
        """Number of hyper-parameters: the variance and the length scales."""
        return 1 + int(np.size(self.length_scale))

    @property
    def theta(self) -> NDArray[np.float64]:
        """``log([variance, *length_scale])``, shape (n_theta,)."""
        variance, ls = self._checked()
        return np.log(np.r_[variance, ls])

    @property
    def bounds(self) -> NDArray[np.float64]:
        """Log-space bounds of :attr:`theta`, shape (n_theta, 2)."""
        self._checked()
        rows = [check_bounds(self.variance_bounds, "variance_bounds")]
        rows += [check_bounds(self.length_scale_bounds, "length_scale_bounds")] * (self.n_theta - 1)
        return np.log(np.array(rows, dtype=np.float64))

    @property
    def hyperparameter_names(self) -> list[str]:
        """Names of the entries of :attr:`theta`."""
        if self.n_theta == 2:
            return ["log_variance", "log_length_scale"]
        return ["log_variance"] + [f"log_length_scale_{d}" for d in range(self.n_theta - 1)]

    def with_theta(self, theta: ArrayLike):
        """A copy of the kernel with hyper-parameters ``exp(theta)``.

        Parameters
        ----------
        theta : array-like of shape (n_theta,)
            ``log([variance, *length_scale])``, finite.

        Returns
        -------
        kernel : same type as self
            A new kernel with the same bounds; its length scale is a float
            unless this kernel is ARD (:attr:`anisotropic`).

        Raises
        ------
        TypeError
            If `theta` does not hold real numbers.
        ValueError
            If `theta` is not of shape (n_theta,) or holds NaN or inf.
        """
        theta = as_numeric(theta, "theta").astype(np.float64)
        if theta.shape != (self.n_theta,) or not np.isfinite(theta).all():
            raise ValueError(f"theta must be a finite array of shape ({self.n_theta},), got {theta!r}")
        ls = np.exp(theta[1:])
        return type(self)(float(np.exp(theta[0])), ls if self.anisotropic else float(ls[0]),
                          variance_bounds=self.variance_bounds,
                          length_scale_bounds=self.length_scale_bounds)

    def __repr__(self):
        ls = np.asarray(self.length_scale)
        ls_txt = f"{float(ls):.4g}" if ls.ndim == 0 else np.array2string(ls, precision=4)
        return f"{type(self).__name__}(variance={float(self.variance):.4g}, length_scale={ls_txt})"

    def __eq__(self, other):
        return (type(self) is type(other)
                and float(self.variance) == float(other.variance)
                and np.array_equal(np.atleast_1d(self.length_scale), np.atleast_1d(other.length_scale)))

    __hash__ = None  # mutable, like scikit-learn estimators

    # ----------------------------------------------------------------- values
    def inverse_length_scales(self, n_dims: int) -> NDArray[np.float64]:
        """``1 / length_scale`` broadcast to `n_dims` entries.

        Parameters
        ----------
        n_dims : int
            Number of input dimensions, 0 to 65536.

        Returns
        -------
        inv : ndarray of shape (n_dims,)

        Raises
        ------
        ValueError
            If `n_dims` is not in [0, 65536], the length scale has neither 1 nor
            `n_dims` entries, or the variance, length scale or bounds are
            invalid.
        TypeError
            If `n_dims` is not an int, or the variance or length scale is not
            real.
        """
        n_dims = check_int(n_dims, "n_dims", low=0, high=65536)
        _, ls = self._checked()
        if ls.size == 1:
            ls = np.full(n_dims, ls[0])
        elif ls.size != n_dims:
            raise ValueError(
                f"length_scale has {ls.size} entries but the inputs have {n_dims} dimensions")
        return 1.0 / ls

    def profile(self, s: ArrayLike) -> NDArray[np.float64]:
        """The kernel as a function of the squared scaled distance, divided by the variance.

        Parameters
        ----------
        s : array-like of any shape
            Squared scaled distances ``sum_d ((x_d - x'_d) / l_d) ** 2``, >= 0
            (not checked: negative values give NaN for the Matérn and sparse
            kernels).

        Returns
        -------
        f : ndarray of the shape of `s`
            ``f(s)``; 1 at ``s = 0``.

        Raises
        ------
        TypeError
            If `s` does not hold real numbers.
        """
        return self._profile(as_numeric(s, "s").astype(np.float64))

    def gradient_factor(self, s: ArrayLike) -> NDArray[np.float64]:
        """``-2 f'(s)``: ``dk/dlog(l_d) = variance * gradient_factor(s) * (dx_d / l_d) ** 2``.

        Parameters
        ----------
        s : array-like of any shape
            Squared scaled distances, >= 0 (not checked, as :meth:`profile`).

        Returns
        -------
        g : ndarray of the shape of `s`

        Raises
        ------
        TypeError
            If `s` does not hold real numbers.
        """
        return self._gradient_factor(as_numeric(s, "s").astype(np.float64))

    def __call__(self, X: ArrayLike, Y: ArrayLike | None = None, eval_gradient: bool = False):
        """Kernel matrix between the rows of `X` and `Y` (default `X`).

        Parameters
        ----------
        X : array-like of shape (n_samples_X, n_features)
        Y : array-like of shape (n_samples_Y, n_features), default=None
        eval_gradient : bool, default=False
            Also return the gradient with respect to :attr:`theta` (only when
            `Y` is None).

        Returns
        -------
        K : ndarray of shape (n_samples_X, n_samples_Y)
        K_gradient : ndarray of shape (n_samples_X, n_samples_X, n_theta)
            Only when `eval_gradient` is True.

        Raises
        ------
        ValueError
            If `X` or `Y` is not finite of shape (n, n_features), the column
            counts differ, or the result with its intermediate arrays would
            take more than 4 GiB.
        TypeError
            If `X` or `Y` does not hold real numbers, or `eval_gradient` is
            not a bool.
        """
        X = _as_samples(X, "X")
        if check_bool(eval_gradient, "eval_gradient") and Y is not None:
            raise ValueError("eval_gradient is only supported when Y is None")
        Y = X if Y is None else _as_samples(Y, "Y")
        if X.shape[1] != Y.shape[1]:
            raise ValueError(f"X and Y must be 2-D with the same number of columns, got "
                             f"{X.shape} and {Y.shape}")
        width = X.shape[1] * (3 if eval_gradient else 1) + 2
        size = 8.0 * X.shape[0] * Y.shape[0] * width
        if size > MAX_DENSE_BYTES:
            raise ValueError(f"the kernel matrix of {X.shape[0]} x {Y.shape[0]} samples needs "
                             f"{size / 2 ** 30:.3g} GiB with its intermediate arrays, more than "
                             f"the limit of {MAX_DENSE_BYTES / 2 ** 30:g} GiB; pass fewer "
                             f"samples at a time")
        variance, _ = self._checked()
        inv = self.inverse_length_scales(X.shape[1])
        diff = (X[:, None, :] - Y[None, :, :]) * inv
        s = np.einsum("ijd,ijd->ij", diff, diff)
        K = variance * self._profile(s)
        if not eval_gradient:
            return K
        g = variance * self._gradient_factor(s)
        per_dim = g[:, :, None] * diff ** 2
        if not self.anisotropic:
            per_dim = per_dim.sum(axis=2, keepdims=True)
        return K, np.concatenate([K[:, :, None], per_dim], axis=2)

    def diag(self, X: ArrayLike) -> NDArray[np.float64]:
        """``k(x, x)`` for each row of `X`: the variance.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_features)
            Finite inputs; a 1-D array is one sample.

        Returns
        -------
        d : ndarray of shape (n_samples,)

        Raises
        ------
        TypeError
            If `X` does not hold real numbers, or the variance is not real.
        ValueError
            If `X` has more than two dimensions or holds NaN or inf, or the
            variance, length scale or bounds are invalid.
        """
        variance, _ = self._checked()
        return np.full(_as_samples(X, "X").shape[0], variance)


@fill_doc(kernel_parameters=_KERNEL_PARAMETERS)
class SquaredExponential(Stationary):
    """Squared exponential kernel ``variance * exp(-s / 2)``, optionally ARD.

    ``s = sum_d ((x_d - x'_d) / l_d) ** 2``. Its line integral against a point
    has a closed form (erf), which the integral kernels use.

    {kernel_parameters}

    Examples
    --------
    >>> k = SquaredExponential(2.0, 0.5)
    >>> k([[0.0, 0.0], [0.5, 0.0]]).round(4).tolist()
    [[2.0, 1.2131], [1.2131, 2.0]]
    >>> k.theta.round(4).tolist()
    [0.6931, -0.6931]
    """

    kind = 0
    name = "squared_exponential"
    cutoff2 = 84.0  # exp(-42) < 1e-18

    def _profile(self, s):
        return np.exp(-0.5 * s)

    def _gradient_factor(self, s):
        return np.exp(-0.5 * s)


@fill_doc(kernel_parameters=_KERNEL_PARAMETERS)
class Matern32(Stationary):
    """Matérn kernel with smoothness 3/2: ``variance * (1 + sqrt(3) r) exp(-sqrt(3) r)``.

    ``r = sqrt(s)``, the scaled distance. Once differentiable: its integrals
    are computed by quadrature split at the closest point.

    {kernel_parameters}

    Examples
    --------
    >>> round(float(Matern32()([[0.0]], [[1.0]])[0, 0]), 6)
    0.483358
    """

    kind = 1
    name = "matern32"
    cutoff2 = 27.0 ** 2  # (1 + sqrt(3) 27) exp(-sqrt(3) 27) < 1e-18

    def _profile(self, s):
        e = _SQRT3 * np.sqrt(s)
        return (1.0 + e) * np.exp(-e)

    def _gradient_factor(self, s):
        return 3.0 * np.exp(-_SQRT3 * np.sqrt(s))


@fill_doc(kernel_parameters=_KERNEL_PARAMETERS)
class SparseKernel(Stationary):
    """The compactly supported kernel of Melkumyan & Ramos (2009).

    ``variance * ((2 + cos(2 pi r)) / 3 * (1 - r) + sin(2 pi r) / (2 pi))``
    for ``r < 1`` and 0 beyond, ``r = sqrt(s)``: the length scale is the
    support radius. Positive definite in one dimension; this isotropic form
    in two and three dimensions is only nearly so (dense random points give
    eigenvalues down to about -5e-6 times the trace), which the noise
    variance on the diagonal covers.

    {kernel_parameters}

    References
    ----------
    A. Melkumyan, F. Ramos, "A sparse covariance function for exact Gaussian
    process inference in large datasets", IJCAI 2009.

    Examples
    --------
    >>> SparseKernel(length_scale=2.0)([[0.0]], [[0.0], [1.0], [2.0]]).round(4).tolist()
    [[1.0, 0.1667, 0.0]]
    """

    kind = 2
    name = "sparse"
    cutoff2 = 1.0

    def _profile(self, s):
        r = np.sqrt(s)
        inside = r < 1.0
        r = np.where(inside, r, 1.0)
        val = (2.0 + np.cos(_TWO_PI * r)) / 3.0 * (1.0 - r) + np.sin(_TWO_PI * r) / _TWO_PI
        return np.where(inside, val, 0.0)

    def _gradient_factor(self, s):
        r = np.sqrt(s)
        inside = r < 1.0
        small = r < 1e-4
        rr = np.where(inside & ~small, r, 0.5)
        val = ((_TWO_PI / 3.0) * np.sin(_TWO_PI * rr) * (1.0 - rr)
               - (2.0 / 3.0) * (np.cos(_TWO_PI * rr) - 1.0)) / rr
        return np.where(inside, np.where(small, 4.0 * np.pi ** 2 / 3.0, val), 0.0)
