"""Quadrature rules for the integral kernels, with the order adapted to the segment length.

A segment of length ``L`` in length-scale units (the GPOMIK paper's warping:
the segment is divided by the length scales first) is integrated with the
lowest order of the rule whose *reach* covers ``L``. The reach of each order is
calibrated once per kernel profile and tolerance: it is the longest piece on
which the order integrates the kernel's profile to ``tol`` times the profile's
half mass ``int_0^inf f(t**2) dt``, for the worst of a family of offsets (the
peak anywhere along the piece for the smooth squared exponential; the closest
point at or before the start, at perpendicular distances 0 to 1, for the
kernels whose pieces are split there). Pieces longer than the reach of the
highest order are split into equal panels of that order.
"""

from __future__ import annotations

import functools
import numbers
import warnings

import numpy as np
from numpy.typing import NDArray
from scipy import integrate

from .._docfill import fill_doc
from .._params import ParamsMixin

__all__ = ["ClenshawCurtis", "Simpson", "clenshaw_curtis", "simpson"]

#: The rules' first parameter (see :func:`occgp._docs.fill_doc`).
_TOL = """\
Parameters
----------
tol : float, default=1e-10
    Error allowed on one piece, relative to the profile's half mass."""

#: Most nodes of :func:`clenshaw_curtis` (its weights take O(n**2) work) and the highest
#: `max_order` of the adaptive rules.
MAX_CC_NODES = 16385
#: Most nodes of :func:`simpson`.
MAX_SIMPSON_NODES = 2 ** 20 + 1


def clenshaw_curtis(n: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Nodes and weights of the `n`-point Clenshaw–Curtis rule on [0, 1].

    Parameters
    ----------
    n : int
        Number of nodes, from 2 (the end points are nodes) to 16385.

    Returns
    -------
    nodes : ndarray of shape (n,)
        Increasing, from 0 to 1.
    weights : ndarray of shape (n,)
        Positive, summing to 1.

    Raises
    ------
    TypeError
        If `n` is not an int.
    ValueError
        If `n` is outside [2, 16385].

    Examples
    --------
    >>> x, w = clenshaw_curtis(5)
    >>> float(w @ x ** 4)       # exact for polynomials of degree < n
    0.2
    """
    n = _check_order(n, 2, "n", MAX_CC_NODES)
    N = n - 1
    theta = np.pi * np.arange(n) / N
    w = np.zeros(n)
    v = np.ones(n - 2)
    inner = theta[1:-1]
    if N % 2 == 0:
        w[0] = w[-1] = 1.0 / (N * N - 1)
        for k in range(1, N // 2):
            v -= 2.0 * np.cos(2 * k * inner) / (4 * k * k - 1)
        v -= np.cos(N * inner) / (N * N - 1)
    else:
        w[0] = w[-1] = 1.0 / (N * N)
        for k in range(1, (N - 1) // 2 + 1):
            v -= 2.0 * np.cos(2 * k * inner) / (4 * k * k - 1)
    w[1:-1] = 2.0 * v / N
    # x = cos(theta) runs from 1 to -1: t = (1 - x) / 2 runs from 0 to 1
    return (1.0 - np.cos(theta)) / 2.0, w / 2.0


def simpson(n: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Nodes and weights of the composite Simpson rule with `n` (odd) nodes on [0, 1].

    Parameters
    ----------
    n : int
        Number of nodes, odd, from 3 to 2**20 + 1.

    Returns
    -------
    nodes : ndarray of shape (n,)
        Equally spaced, from 0 to 1.
    weights : ndarray of shape (n,)
        ``(1, 4, 2, 4, ..., 2, 4, 1) / (3 (n - 1))``, summing to 1.

    Raises
    ------
    TypeError
        If `n` is not an int.
    ValueError
        If `n` is even or outside [3, 2**20 + 1].

    Examples
    --------
    >>> x, w = simpson(5)
    >>> (w * 12).tolist()
    [1.0, 4.0, 2.0, 4.0, 1.0]
    """
    n = _check_order(n, 3, "n", MAX_SIMPSON_NODES)
    if n % 2 == 0:
        raise ValueError(f"n must be odd for Simpson's rule, got {n}")
    w = np.ones(n)
    w[1:-1:2] = 4.0
    w[2:-1:2] = 2.0
    return np.linspace(0.0, 1.0, n), w / (3.0 * (n - 1))


def _check_order(n, low, name, high):
    if isinstance(n, bool) or not isinstance(n, numbers.Integral):
        raise TypeError(f"{name} must be an int, got {type(n).__name__}")
    if not low <= n <= high:
        raise ValueError(f"{name} must be at least {low} and at most {high}, got {n}")
    return int(n)


def _check_kernel_class(kernel):
    from ._kernels import Stationary
    if not isinstance(kernel, Stationary):
        raise TypeError("kernel must be one of occgp.gp's kernels (SquaredExponential, "
                        f"Matern32, SparseKernel), got {type(kernel).__name__}")
    return kernel


class Rule(ParamsMixin):
    """Orders 3, 5, 9, ... up to `max_order`, each with its calibrated reach."""

    _family = None
    _min_max_order = 3

    def __init__(self, tol: float = 1e-10, max_order: int = 257):
        self.tol = tol
        self.max_order = max_order

    def _check_params_together(self, params):
        type(self)(**params)._checked()
        return params

    def _checked(self):
        if isinstance(self.tol, bool) or not isinstance(self.tol, numbers.Real) \
                or not (1e-15 <= float(self.tol) < 1):
            raise ValueError(f"tol must be a number in [1e-15, 1), got {self.tol!r}")
        max_order = _check_order(self.max_order, self._min_max_order, "max_order", MAX_CC_NODES)
        return float(self.tol), max_order

    @property
    def orders(self) -> list[int]:
        """The tabulated orders: ``2**k + 1`` up to `max_order`."""
        _, max_order = self._checked()
        out, n = [], 3
        while n <= max_order:
            out.append(n)
            n = 2 * (n - 1) + 1
        return out

    def nodes(self, order: int):
        """Nodes and weights of one order on [0, 1].

        Parameters
        ----------
        order : int
            Number of nodes: 2 to 16385 for :class:`ClenshawCurtis`, odd from
            3 to 2**20 + 1 for :class:`Simpson` (any such order, not only the
            tabulated :attr:`orders`).

        Returns
        -------
        nodes, weights : ndarray of shape (order,)
            As :func:`clenshaw_curtis` / :func:`simpson`.

        Raises
        ------
        TypeError
            If `order` is not an int.
        ValueError
            If `order` is out of the rule's range (or even, for Simpson).
        """
        return type(self)._family(order)

    def table(self, kernel):
        """Concatenated nodes, weights, offsets and reaches for `kernel`'s profile.

        The table depends on the kernel's class only (its profile ``f``), not
        on its variance or length scales; it is computed once per rule class,
        kernel class, `tol` and `max_order` and cached.

        Parameters
        ----------
        kernel : SquaredExponential, Matern32 or SparseKernel

        Returns
        -------
        nodes, weights : ndarray of shape (n_nodes,)
            The nodes and weights of each of :attr:`orders` in turn, on [0, 1].
        offsets : ndarray of intp of shape (n_orders + 1,)
            Order ``k`` occupies ``nodes[offsets[k]:offsets[k + 1]]``.
        reach : ndarray of shape (n_orders,)
            As :meth:`reach`.

        Raises
        ------
        TypeError
            If `kernel` is not one of occgp.gp's kernels, or `max_order` is
            not an int.
        ValueError
            If `tol` is not in [1e-15, 1), `max_order` is outside [3, 16385],
            or no order up to `max_order` reaches `tol`.
        """
        tol, max_order = self._checked()
        return _table(type(self).__name__, type(_check_kernel_class(kernel)), tol, max_order)

    def reach(self, kernel) -> NDArray[np.float64]:
        """Longest piece (length-scale units) each order integrates to `tol`.

        Parameters
        ----------
        kernel : SquaredExponential, Matern32 or SparseKernel

        Returns
        -------
        reach : ndarray of shape (n_orders,)
            Non-decreasing over :attr:`orders`; -1 for the lowest orders that
            reach none of the calibrated lengths (0.02 to 64).

        Raises
        ------
        TypeError, ValueError
            As :meth:`table`.
        """
        return self.table(kernel)[3].copy()

    def order_for(self, kernel, length: float) -> tuple[int, int]:
        """The order and number of panels used for a piece of `length` length-scale units.

        Parameters
        ----------
        kernel : SquaredExponential, Matern32 or SparseKernel
        length : float
            Length of the piece in length-scale units, finite and >= 0.

        Returns
        -------
        order : int
            The lowest of :attr:`orders` whose reach covers `length`, else the
            highest.
        n_panels : int
            1, or the number of equal panels of the highest order when
            `length` is beyond its reach.

        Raises
        ------
        TypeError
            If `length` is not a real number, or as :meth:`table`.
        ValueError
            If `length` is negative or not finite, or as :meth:`table`.
        """
        from .._validation import check_real
        length = check_real(length, "length", low=0.0, low_open=False)
        reach = self.table(kernel)[3]
        orders = self.orders
        k = int(np.searchsorted(reach, length)) if reach[-1] >= length else len(orders) - 1
        panels = 1 if reach[k] >= length else int(np.ceil(length / reach[k]))
        return orders[k], panels

    def __repr__(self):
        return f"{type(self).__name__}(tol={self.tol!r}, max_order={self.max_order!r})"


@fill_doc(tol=_TOL)
class ClenshawCurtis(Rule):
    """Adaptive-order Clenshaw–Curtis quadrature (the GPOMIK paper's choice).

    {tol}
    max_order : int, default=257
        Highest order, at most 16385; longer pieces are split into panels of it.

    Examples
    --------
    >>> from occgp.gp import SquaredExponential
    >>> ClenshawCurtis().order_for(SquaredExponential(), 4.0)[0] <= 33
    True
    """

    _family = staticmethod(clenshaw_curtis)


@fill_doc(tol=_TOL)
class Simpson(Rule):
    """Composite Simpson quadrature with an adaptive number of nodes (Kim & Kim's choice).

    {tol}
    max_order : int, default=4097
        Most nodes on one panel, at most 16385; longer pieces are split into
        panels.

    Examples
    --------
    >>> from occgp.gp import SquaredExponential
    >>> Simpson(tol=1e-6).order_for(SquaredExponential(), 1.0)[0] <= 65
    True
    """

    _family = staticmethod(simpson)

    def __init__(self, tol: float = 1e-10, max_order: int = 4097):
        super().__init__(tol, max_order)


# ------------------------------------------------------------------ calibration
_LENGTHS = np.geomspace(0.02, 64.0, 72)


def _offsets(kernel_cls):
    """(c, d) pairs: integrand f((t - c)**2 + d**2) on a piece [0, L]."""
    if kernel_cls.kind == 0:  # smooth: the peak anywhere along and around the piece
        return None
    cs = np.array([0.0, -0.02, -0.1, -0.3, -0.7, -1.5])
    ds = np.array([0.0, 0.02, 0.1, 0.3, 0.7])
    return np.array([(c, d) for c in cs for d in ds])


def _piece_pairs(kernel_cls, L):
    offsets = _offsets(kernel_cls)
    if offsets is None:
        cs = np.linspace(-1.5, L + 1.5, 25)
        return np.column_stack([cs, np.zeros_like(cs)])
    if kernel_cls.kind == 2:  # compact support: pieces stay inside it
        keep = (L - offsets[:, 0]) ** 2 + offsets[:, 1] ** 2 <= 1.0
        return offsets[keep]
    return offsets


def _reference(kernel, L, c, d):
    f = kernel.profile
    if type(kernel).kind == 0:
        from scipy.special import erf
        return np.exp(-d * d / 2) * np.sqrt(np.pi / 2) * (
            erf((L - c) / np.sqrt(2)) - erf(-c / np.sqrt(2)))
    with warnings.catch_warnings():  # asked for more than double precision gives
        warnings.simplefilter("ignore", integrate.IntegrationWarning)
        val, _ = integrate.quad(lambda t: float(f((t - c) ** 2 + d * d)), 0.0, L,
                                epsabs=1e-16, epsrel=1e-14, limit=400)
    return val


@functools.lru_cache(maxsize=None)
def _table(rule_name, kernel_cls, tol, max_order):
    rule = {"ClenshawCurtis": ClenshawCurtis, "Simpson": Simpson}[rule_name](tol, max_order)
    kernel = kernel_cls()
    mass, _ = integrate.quad(lambda t: float(kernel.profile(t * t)), 0.0, np.inf
                             if kernel_cls.kind != 2 else 1.0, epsabs=1e-15, limit=400)
    cases = []
    for L in _LENGTHS:
        pairs = _piece_pairs(kernel_cls, L)
        ref = np.array([_reference(kernel, L, c, d) for c, d in pairs])
        cases.append((L, pairs, ref))
    nodes, weights, offsets, reach = [], [], [0], []
    for order in rule.orders:
        x, w = rule.nodes(order)
        best = 0.0
        for L, pairs, ref in cases:
            if len(pairs):
                t = L * x
                s = (t[None, :] - pairs[:, :1]) ** 2 + pairs[:, 1:] ** 2
                approx = L * (kernel.profile(s) @ w)
                if np.max(np.abs(approx - ref)) > tol * mass:
                    break
            best = L
        nodes.append(x)
        weights.append(w)
        offsets.append(offsets[-1] + len(x))
        reach.append(best)
    reach = np.maximum.accumulate(np.array(reach))
    if reach[-1] <= 0:
        raise ValueError(f"{rule!r} cannot reach tol={tol} with orders up to {max_order}; "
                         f"raise max_order or tol")
    # an order that reaches nothing is never picked before a higher one
    reach = np.where(reach > 0, reach, -1.0)
    return (np.concatenate(nodes), np.concatenate(weights),
            np.array(offsets, dtype=np.intp), reach)
