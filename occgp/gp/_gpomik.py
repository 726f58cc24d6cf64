"""GPOMIK: Gaussian-process occupancy maps with integral kernels (O'Callaghan & Ramos)."""

from __future__ import annotations

import inspect
import numbers
import os

import numpy as np
import scipy.linalg as sl
from numpy.typing import ArrayLike, NDArray
from sklearn.base import BaseEstimator
from sklearn.utils.validation import check_is_fitted

from .. import _integral, _npz_io
from .._validation import as_points, check_bool, check_real
from ._gpr import _with_noise, cholesky, jitter_for, optimize_hyperparameters, solve_lower
from ._integral import _check_kernel, _check_quadrature, _covariance
from ._kernels import Matern32, SparseKernel, SquaredExponential
from ._limits import MAX_RESTARTS, check_coordinates, check_dense, check_segments, generator, threads
from ._observations import Observations, make_observations
from ._plsc import fit_plsc, loo_predictions, plsc_proba
from ._quadrature import ClenshawCurtis, Simpson, _Rule

__all__ = ["GPOMIK"]

#: Edge of the query tiles of predict, in length scales.
_TILE = 4.0
#: Most cross-covariance entries computed in one call of predict (64 MB).
_BLOCK_ENTRIES = 8_000_000


def _segment_distance(x, A, B):
    """Distance from point `x` to each segment A[i]-B[i] (points when A[i] == B[i])."""
    d = B - A
    dd = np.einsum("ij,ij->i", d, d)
    t = np.clip(np.einsum("ij,ij->i", x - A, d) / np.where(dd > 0, dd, 1.0), 0.0, 1.0)
    return np.linalg.norm(A + t[:, None] * d - x, axis=1)


class _Cell:
    """One local GP: its observations, Cholesky factor and ``alpha = K^-1 y``."""

    def __init__(self, obs: Observations, L, alpha):
        self.obs = obs
        self.L = L
        self.alpha = alpha
        self.kinv = None  # K^-1, computed by the first predict that needs it

    @property
    def size(self) -> int:
        return len(self.obs.y)

    def inverse(self):
        """``K^-1`` (noise included), computed once from the factor and kept."""
        if self.kinv is None:
            Linv = sl.solve_triangular(self.L, np.eye(self.size), lower=True, check_finite=False)
            self.kinv = Linv.T @ Linv
        return self.kinv

    def bounds(self, margin):
        pts = np.vstack([self.obs.starts, self.obs.ends])
        return pts.min(axis=0) - margin, pts.max(axis=0) + margin


def _kl_gain(var, mu, y, noise):
    """KL(after || before) of a latent N(mu, var) conditioned on target y with `noise`."""
    var_after = var * noise / (var + noise)
    shift = var / (var + noise) * (y - mu)
    return 0.5 * (np.log(var / var_after) + (var_after + shift ** 2) / var - 1.0)


def _check_int(value, name, low):
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be an int, got {type(value).__name__}")
    if value < low:
        raise ValueError(f"{name} must be >= {low}, got {value!r}")


def _spatial_groups(anchors, max_size):
    """Split indices into groups of at most `max_size` by median bisection of `anchors`."""
    todo, done = [np.arange(len(anchors))], []
    while todo:
        idx = todo.pop()
        if len(idx) <= max_size:
            done.append(idx)
            continue
        pts = anchors[idx]
        axis = int(np.argmax(np.ptp(pts, axis=0)))
        order = idx[np.argsort(pts[:, axis], kind="stable")]
        half = len(order) // 2
        todo += [order[half:], order[:half]]
    return done


# ------------------------------------------------------------------ files
#: Format of the GP models' files (see GPOMIK.save, GPOM.save).
_GP_FORMAT = "occgp.gp_model"
_GP_VERSIONS = (1,)
#: The objects a GP model's parameters may hold, rebuilt from their get_params().
_GP_CLASSES = {c.__name__: c for c in (SquaredExponential, Matern32, SparseKernel,
                                       ClenshawCurtis, Simpson)}


def _gp_params(model) -> dict:
    """JSON-ready constructor parameters of `model` (TypeError if one cannot be saved)."""
    try:
        return _npz_io.encode_value(model.get_params(deep=False), _GP_CLASSES)
    except TypeError as exc:
        raise TypeError(f"cannot save this {type(model).__name__}: a parameter holds an "
                        f"unsupported value: {exc}") from None


def _gp_fitted(value: dict) -> np.ndarray:
    return np.array(_npz_io.json_text(_npz_io.encode_value(value, _GP_CLASSES)))


def _read_gp(cls, path, spec):
    """(source, unfitted model of the saved parameters, arrays, fitted dict or None)."""
    source = os.fspath(_npz_io.as_path(path))
    spec = {"fitted": (np.str_, ()), **spec}
    _, _, raw, arrays = _npz_io.read_npz(source, _GP_FORMAT, _GP_VERSIONS, (cls.__name__,),
                                         spec, tuple(spec))
    name = cls.__name__
    params = _npz_io.decode_value(raw, source, _GP_CLASSES)
    expected = [p for p in inspect.signature(cls.__init__).parameters if p != "self"]
    if sorted(params) != sorted(expected):
        raise ValueError(f"{source}: the parameters of a {name} must be {sorted(expected)}, "
                         f"got {sorted(params)[:20]}")
    try:
        model = cls(**params)
        model._check_params()
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{source}: bad parameters of a {name}: {exc}") from None
    present = [k for k in spec if k in arrays]
    if present and len(present) != len(spec):
        raise ValueError(f"{source}: a fitted {name} needs all of {list(spec)}, got only "
                         f"{present}")
    fitted = None
    if present:
        text = str(arrays.pop("fitted")[()])
        fitted = _npz_io.decode_value(_npz_io.parse_json(text, "'fitted' entry", source),
                                      source, _GP_CLASSES, "'fitted' entry")
        if not isinstance(fitted, dict):
            raise ValueError(f"{source}: corrupt 'fitted' entry: expected a JSON object")
        _npz_io.check_finite(arrays, list(arrays), source)
    return source, model, arrays, fitted


def _check_gp_fitted(fitted: dict, keys, n_dims: int, source: str, name: str) -> dict:
    """The fitted scalars shared by the GP models, checked; ValueError naming `source`."""
    if sorted(fitted) != sorted(keys):
        raise ValueError(f"{source}: the fitted state of a {name} must hold {sorted(keys)}, "
                         f"got {sorted(fitted)[:20]}")
    try:
        kernel = _check_kernel(fitted["kernel_"])
        kernel._checked()
        kernel.inverse_length_scales(n_dims)
        check_real(fitted["noise_"], "noise_", low=0.0)
        plsc = fitted["plsc_"]
        if not (isinstance(plsc, tuple) and len(plsc) == 2):
            raise ValueError(f"plsc_ must be a pair (a, b), got {plsc!r:.80}")
        for v in plsc:
            check_real(v, "plsc_")
        lml = fitted["log_marginal_likelihood_value_"]
        if lml is not None:
            check_real(lml, "log_marginal_likelihood_value_")
        dims = fitted["n_dims_"]
        if isinstance(dims, bool) or dims != n_dims:
            raise ValueError(f"n_dims_ must be {n_dims} (the arrays' width), got {dims!r:.40}")
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{source}: corrupt fitted state of a {name}: {exc}") from None
    fitted = dict(fitted)
    fitted["log_marginal_likelihood_value_"] = np.nan if lml is None else float(lml)
    return fitted


class GPOMIK(BaseEstimator):
    """Gaussian-process occupancy map with integral kernels (GPOMIK).

    Laser returns are point observations of the latent occupancy (target +1);
    each beam is one segment observation, the integral of the latent function
    along it (target ``-length``: free all along). One covariance matrix over
    all observations serves every query: it is factorised once, grown by
    Cholesky updates as observations arrive (:meth:`update`), and split into a
    new local model for a new spatial cell when it reaches `max_cell_size`.
    A probabilistic least-squares classifier (PLSC) maps the latent mean and
    variance to a probability of occupancy.

    Limits, checked before any work: observations must lie within 1e10
    length scales of the origin and beams be at most 1e4 length scales long
    (the kernel's length scales at :meth:`fit`, the fitted ones at
    :meth:`update`; see ``occgp.gp._limits``), and no step may build dense
    matrices of more than 4 GiB together (which bounds `max_optimize`,
    `max_cell_size` and the size of one update). Queries may lie anywhere:
    far from every observation they get the prior.

    Parameters
    ----------
    kernel : SquaredExponential, Matern32 or SparseKernel, default=None
        Covariance of the latent function; None means
        ``SquaredExponential(1.0, 1.0)``. Its hyper-parameters are the
        starting point of the optimiser; the kernel passed is not modified.
    noise : float, default=0.01
        Noise variance of every observation (starting point when optimised).
    noise_bounds : pair of float, default=(1e-4, 1.0)
        Bounds of the noise variance during optimisation.
    quadrature : {"clenshaw-curtis", "simpson"}, ClenshawCurtis or Simpson, \
default="clenshaw-curtis"
        Rule for the segment integrals without closed form.
    optimizer : bool, default=True
        Fit the hyper-parameters by maximising the log marginal likelihood
        (L-BFGS-B in log space).
    n_restarts : int, default=2
        Extra optimiser starts, drawn log-uniformly within the bounds; at
        most 1000.
    max_optimize : int, default=1000
        Hyper-parameters and PLSC are fitted on a random subset of at most
        this many observations.
    max_cell_size : int or None, default=2000
        Most observations in one local model. :meth:`fit` splits larger sets
        into spatial cells by median bisection; :meth:`update` starts a new
        cell once the newest one is full. None: one model, no limit.
    kl_threshold : float or None, default=None
        Active sampling in :meth:`update`: an observation whose KL divergence
        between the predictive distributions at its location after and before
        adding it is below this is rejected. None accepts every observation.
    random_state : int, Generator or None, default=None
        Seeds the optimiser restarts and the subset of `max_optimize`.
    n_jobs : int, default=None
        Threads for the kernel matrices (None: 1; -1: every core).

    Attributes
    ----------
    kernel_ : kernel
        The fitted kernel.
    noise_ : float
        The fitted noise variance.
    jitter_ : float
        Added to the diagonal with the noise: ``1e-10 * mean(diag K)`` of the
        fitted training set.
    log_marginal_likelihood_value_ : float
        At the fitted hyper-parameters, on the optimisation subset.
    plsc_ : tuple of float
        PLSC's ``(a, b)``.
    cells_ : list
        The local models; each has ``obs`` (its :class:`Observations`), ``L``
        and ``alpha``.
    n_dims_ : int
        Dimension of the inputs.
    n_accepted_, n_rejected_ : int
        Observations accepted into and rejected from the model (``fit``
        accepts all of its).

    References
    ----------
    S. O'Callaghan, F. Ramos, "Continuous occupancy mapping with integral
    kernels", AAAI 2011.

    Examples
    --------
    A wall at x = 2 seen by five beams from the origin:

    >>> import numpy as np
    >>> from occgp.gp import GPOMIK
    >>> y = np.linspace(-1, 1, 5)
    >>> hits = np.column_stack([np.full(5, 2.0), y])
    >>> m = GPOMIK(optimizer=False).fit(hits, np.zeros((5, 2)), hits)
    >>> p = m.predict_proba([[2.0, 0.0], [1.0, 0.0]])
    >>> bool(p[0] > 0.5 > p[1])
    True
    """

    def __init__(self, kernel=None, *, noise=0.01, noise_bounds=(1e-4, 1.0),
                 quadrature="clenshaw-curtis", optimizer=True, n_restarts=2, max_optimize=1000,
                 max_cell_size=2000, kl_threshold=None, random_state=None, n_jobs=None):
        self.kernel = kernel
        self.noise = noise
        self.noise_bounds = noise_bounds
        self.quadrature = quadrature
        self.optimizer = optimizer
        self.n_restarts = n_restarts
        self.max_optimize = max_optimize
        self.max_cell_size = max_cell_size
        self.kl_threshold = kl_threshold
        self.random_state = random_state
        self.n_jobs = n_jobs

    # ------------------------------------------------------------ parameters
    def _check_params(self):
        kernel = SquaredExponential() if self.kernel is None else _check_kernel(self.kernel)
        kernel = type(kernel)(**kernel.get_params())
        kernel._checked()
        noise = check_real(self.noise, "noise", low=0.0)
        if not isinstance(self.noise_bounds, (tuple, list, np.ndarray)):
            raise TypeError(f"noise_bounds must be a pair (low, high), got {self.noise_bounds!r}")
        if len(self.noise_bounds) != 2:
            raise ValueError(f"noise_bounds must be a pair (low, high), got {self.noise_bounds!r}")
        lo, hi = (check_real(b, "noise_bounds", low=0.0) for b in self.noise_bounds)
        if not lo < hi:
            raise ValueError(f"noise_bounds must satisfy low < high, got {self.noise_bounds!r}")
        _check_int(self.n_restarts, "n_restarts", 0)
        if self.n_restarts > MAX_RESTARTS:
            raise ValueError(f"n_restarts must be at most {MAX_RESTARTS}, got {self.n_restarts!r}")
        _check_int(self.max_optimize, "max_optimize", 2)
        if self.max_cell_size is not None:
            _check_int(self.max_cell_size, "max_cell_size", 1)
        if self.kl_threshold is not None:
            check_real(self.kl_threshold, "kl_threshold", low=0.0, low_open=False)
        check_bool(self.optimizer, "optimizer")
        return kernel, noise, (lo, hi)

    # ------------------------------------------------------------------- fit
    def fit(self, hits: ArrayLike | None, segment_starts: ArrayLike | None,
            segment_ends: ArrayLike | None) -> "GPOMIK":
        """Fit the hyper-parameters and PLSC, and factorise the model.

        Parameters
        ----------
        hits : array-like of shape (n_hits, D) or None
            Laser returns (occupied), D in 1..3.
        segment_starts, segment_ends : array-like of shape (n_beams, D) or None
            Beams, from the sensor to the return or to the maximum range
            (free). A zero-length beam counts as one free point.

        Returns
        -------
        self : GPOMIK

        Raises
        ------
        ValueError
            On NaN or inf, wrong shapes, inconsistent dimensions, missing
            class (PLSC needs hits and beams), invalid parameters, or data
            beyond the limits (coordinates past 1e10 length scales, beams
            longer than 1e4 length scales, dense matrices past 4 GiB).
        numpy.linalg.LinAlgError
            (a ValueError) If a covariance matrix cannot be factorised (the
            message says what to change, usually a larger noise).
        TypeError
            On non-numeric input or a kernel that is not one of occgp.gp's.
        """
        kernel, noise, noise_bounds = self._check_params()
        quadrature = _check_quadrature(self.quadrature)
        n_threads = threads(self.n_jobs)
        rng = generator(self.random_state)
        obs = make_observations(hits, segment_starts, segment_ends)
        if not ((obs.labels > 0).any() and (obs.labels < 0).any()):
            raise ValueError("GPOMIK needs both hits and beams to fit its classifier, got "
                             f"{int((obs.labels > 0).sum())} hits and "
                             f"{int((obs.labels < 0).sum())} beams")
        self._check_observations(obs, kernel)
        n_opt = min(len(obs.y), self.max_optimize)
        fix = "lower max_optimize"
        if self.optimizer:
            check_dense(n_opt, n_opt, kernel.n_theta + 4, "the hyper-parameter optimisation", fix)
        check_dense(n_opt, n_opt, 3, "the classifier's leave-one-out predictions", fix)
        self._check_cell_size(len(obs.y))
        subset = obs
        if len(obs.y) > self.max_optimize:
            subset = obs.take(np.sort(rng.choice(len(obs.y), self.max_optimize, replace=False)))
        lml = np.nan
        if self.optimizer:
            kernel, noise, lml = optimize_hyperparameters(
                kernel, noise, noise_bounds, subset.starts, subset.ends, subset.y, quadrature,
                n_restarts=self.n_restarts, rng=rng, n_threads=n_threads)
        K_sub = _covariance(kernel, quadrature, subset.starts, subset.ends, n_threads=n_threads)
        jitter = jitter_for(K_sub)
        L = cholesky(_with_noise(K_sub, noise, jitter), kernel, noise,
                     "the optimisation subset")
        mu, var = loo_predictions(L, subset.y)
        scale = np.where(subset.lengths > 0, subset.lengths, 1.0)    # per unit length
        plsc = fit_plsc(mu / scale, var / scale ** 2, subset.labels)
        if not np.isfinite(plsc).all():
            raise ValueError(f"the classifier's fit on the leave-one-out predictions failed "
                             f"(PLSC a, b = {plsc}); check the data and the noise")
        cells = self._make_cells(obs, kernel, noise, jitter, quadrature, n_threads)
        self.kernel_, self.noise_, self.jitter_ = kernel, noise, jitter
        self.plsc_ = plsc
        self.log_marginal_likelihood_value_ = lml
        self.n_dims_ = obs.starts.shape[1]
        self._quadrature, self._n_threads = quadrature, n_threads
        self.cells_ = cells
        self.n_accepted_, self.n_rejected_ = len(obs.y), 0
        return self

    @staticmethod
    def _check_observations(obs, kernel):
        """Coordinate and beam-length limits of `obs` (hits first, then beams) for `kernel`."""
        inv = kernel.inverse_length_scales(obs.starts.shape[1])
        n_hits = int(np.count_nonzero(obs.labels > 0))
        check_coordinates({"hits": obs.starts[:n_hits], "segment_starts": obs.starts[n_hits:],
                           "segment_ends": obs.ends[n_hits:]}, inv,
                          fix="shift the data towards the origin or use a longer length scale")
        check_segments(obs.starts[n_hits:], obs.ends[n_hits:], inv)

    def _check_cell_size(self, n_new, n_old=0):
        """Dense-size limit of a cell grown from `n_old` to up to `n_old + n_new` observations."""
        size = n_old + n_new
        if self.max_cell_size is not None:
            size = min(size, max(self.max_cell_size, n_old))
        check_dense(size, size, 4, f"a local model of {size} observations",
                    "lower max_cell_size" if self.max_cell_size is None or n_old == 0
                    else "update with fewer observations at a time")

    def _make_cells(self, obs, kernel, noise, jitter, quadrature, n_threads):
        """Factorised cells of `obs` split by `max_cell_size`; nothing is stored."""
        size = len(obs.y) if self.max_cell_size is None else self.max_cell_size
        cells = []
        for idx in _spatial_groups(obs.anchors, max(size, 1)):
            part = obs.take(idx)
            K = _covariance(kernel, quadrature, part.starts, part.ends, n_threads=n_threads)
            L = cholesky(_with_noise(K, noise, jitter), kernel, noise,
                         f"a local model of {len(idx)} observations")
            cells.append(_Cell(part, L, solve_lower(L, part.y)))
        return cells

    # ---------------------------------------------------------------- update
    def _cross(self, obs_a, obs_b):
        return _covariance(self.kernel_, self._quadrature, obs_a.starts, obs_a.ends,
                           obs_b.starts, obs_b.ends, n_threads=self._n_threads)

    def _extend(self, cell, new, K12=None, K22=None):
        """Cholesky update of Eq. 11–13: append `new` to `cell`.

        `K12` (cell x new) and `K22` (new x new, without noise) are computed
        unless given.
        """
        if K12 is None:
            K12 = self._cross(cell.obs, new)
        if K22 is None:
            K22 = _covariance(self.kernel_, self._quadrature, new.starts, new.ends,
                              n_threads=self._n_threads)
        m = len(K22)
        K22 = K22 + (self.noise_ + self.jitter_) * np.eye(m)
        S12 = sl.solve_triangular(cell.L, K12, lower=True, check_finite=False)
        S22 = cholesky(K22 - S12.T @ S12, self.kernel_, self.noise_,
                       f"the {m} new observations given the newest local model")
        n = cell.size
        L = np.zeros((n + m, n + m))
        L[:n, :n] = cell.L
        L[n:, :n] = S12.T
        L[n:, n:] = S22
        obs = Observations(*(np.concatenate([a, b]) for a, b in zip(cell.obs, new)))
        # forward solution L^-1 y grows by one block; one backward solve gives alpha
        z_old = sl.solve_triangular(cell.L, cell.obs.y, lower=True, check_finite=False)
        z_new = sl.solve_triangular(S22, new.y - S12.T @ z_old, lower=True, check_finite=False)
        alpha = solve_lower(L, obs.y, np.r_[z_old, z_new])
        return _Cell(obs, L, alpha)

    def kl_divergence(self, hits=None, segment_starts=None, segment_ends=None):
        """KL divergence that adding each observation would bring to the map.

        Observations are taken in order (hits first, then beams, each in
        input order). For observation ``j`` with latent prediction
        ``N(mu, var)`` given the map and the observations before it in this
        batch, and ``N(mu', var')`` after conditioning on its target with the
        noise variance: ``KL(after || before) = log(sqrt(var / var')) +
        (var' + (mu' - mu)**2) / (2 var) - 1/2``. For a beam, the latent is
        the integral along it. The newest cell conditions on the batch too
        (one Cholesky factor of the batch's predictive covariance gives every
        sequential prediction at once); an older cell whose box holds the
        observation gives its own divergence, and the smallest one counts.
        The model is not changed.

        Parameters
        ----------
        hits : array-like of shape (n_hits, D), default=None
            Laser returns, in the fitted model's dimension D.
        segment_starts, segment_ends : array-like of shape (n_beams, D), default=None
            Beams, given together. `hits` or the beams may be None, not both.

        Returns
        -------
        kl : ndarray of shape (n_hits + n_beams,)
            One divergence per observation, hits first.

        Raises
        ------
        NotFittedError
            If called before :meth:`fit`.
        ValueError, TypeError
            As :meth:`update`, also when the batch's covariance with the
            largest cell would take more than 4 GiB.
        numpy.linalg.LinAlgError
            (a ValueError) If the batch's predictive covariance cannot be
            factorised.
        """
        new = self._new_observations(hits, segment_starts, segment_ends, kl=True)
        return self._kl(new)[0]

    def _new_observations(self, hits, segment_starts, segment_ends, kl):
        """Validated observations for :meth:`update` and :meth:`kl_divergence`."""
        check_is_fitted(self, "cells_")
        new = make_observations(hits, segment_starts, segment_ends, dim=self.n_dims_)
        self._check_observations(new, self.kernel_)
        if kl:  # the batch's covariance and its blocks against a cell
            m, n = len(new.y), max(cell.size for cell in self.cells_)
            check_dense(m, 3 * m + 2 * n, 1, f"the divergences of {m} new observations",
                        "pass fewer observations at a time")
        return new

    def _kl(self, new):
        """KL gains of `new`, and the newest cell's blocks K12 and K22 (no noise)."""
        noise = self.noise_ + self.jitter_
        K22 = _covariance(self.kernel_, self._quadrature, new.starts, new.ends,
                          n_threads=self._n_threads)
        prior = np.diag(K22)
        margin = 3.0 / self.kernel_.inverse_length_scales(self.n_dims_)
        kl = np.full(len(new.y), np.inf)
        for i, cell in enumerate(self.cells_):
            newest = i == len(self.cells_) - 1
            if newest:
                take = np.arange(len(new.y))
            else:
                lo, hi = cell.bounds(margin)
                take = np.flatnonzero(np.all((new.anchors >= lo) & (new.anchors <= hi), axis=1))
                if not len(take):
                    continue
            sub = new.take(take)
            K12 = self._cross(cell.obs, sub)
            S12 = sl.solve_triangular(cell.L, K12, lower=True, check_finite=False)
            mu = K12.T @ cell.alpha
            if newest:  # y_j given the cell and y_<j: one factor of the batch's covariance
                K12_newest = K12
                C = K22 - S12.T @ S12
                C[np.diag_indices_from(C)] += noise
                Lc = cholesky(C, self.kernel_, self.noise_,
                              f"the {len(sub.y)} new observations given the newest local model")
                z = sl.solve_triangular(Lc, sub.y - mu, lower=True, check_finite=False)
                d = np.diag(Lc)
                mu, var = sub.y - d * z, d * d - noise
            else:
                var = prior[take] - np.einsum("ij,ij->j", S12, S12)
            kl[take] = np.minimum(kl[take], _kl_gain(np.maximum(var, 1e-300), mu, sub.y, noise))
        return kl, K12_newest, K22

    def update(self, hits: ArrayLike | None = None, segment_starts: ArrayLike | None = None,
               segment_ends: ArrayLike | None = None) -> "GPOMIK":
        """Add observations by Cholesky updates, with active sampling.

        With `kl_threshold` set, observations whose KL divergence (see
        :meth:`kl_divergence`: given the map and the earlier observations of
        this call) is below it are rejected. The accepted ones join the newest
        cell, its factor grown by Eq. 11–13 of the paper (``O(n^2)`` instead
        of ``O(n^3)``); past `max_cell_size` the rest start new cells (split
        spatially when more than one cell's worth). Hyper-parameters and PLSC
        stay as fitted.

        Parameters
        ----------
        hits : array-like of shape (n_hits, D), default=None
        segment_starts, segment_ends : array-like of shape (n_beams, D), default=None

        Returns
        -------
        self : GPOMIK

        Raises
        ------
        ValueError, TypeError
            As :meth:`fit`, also for observations beyond the limits of the
            fitted kernel (see the class docstring); the model is then
            unchanged (every fitted attribute).
        numpy.linalg.LinAlgError
            (a ValueError) If the grown covariance cannot be factorised; the
            model is then unchanged.
        """
        new = self._new_observations(hits, segment_starts, segment_ends,
                                     kl=self.kl_threshold is not None)
        keep = np.arange(len(new.y))
        K12 = K22 = None
        if self.kl_threshold is not None and len(new.y):
            kl, K12, K22 = self._kl(new)  # the blocks serve the Cholesky update below
            keep = np.flatnonzero(kl >= float(self.kl_threshold))
        n_rejected = len(new.y) - len(keep)
        cells = list(self.cells_)
        if len(keep):
            room = len(keep) if self.max_cell_size is None \
                else self.max_cell_size - self.cells_[-1].size
            self._check_cell_size(min(max(room, 0), len(keep)), self.cells_[-1].size)
            rest = keep[max(room, 0):]
            if len(rest):
                self._check_cell_size(len(rest))
            if room > 0:
                head = keep[:room]
                cells[-1] = self._extend(
                    self.cells_[-1], new.take(head), None if K12 is None else K12[:, head],
                    None if K22 is None else K22[np.ix_(head, head)])
            if len(rest):
                cells += self._make_cells(new.take(rest), self.kernel_, self.noise_,
                                          self.jitter_, self._quadrature, self._n_threads)
        # every step that can fail is done: now change the model
        self.cells_[:] = cells
        self.n_accepted_ += len(keep)
        self.n_rejected_ += n_rejected
        return self

    # ----------------------------------------------------------------- files
    _OBS_SPEC = {"cell_sizes": (np.int64, ("n_cells",)),
                 "L_fortran": (np.bool_, ("n_cells",)),
                 "starts": (np.float64, ("n_obs", "n_dims")),
                 "ends": (np.float64, ("n_obs", "n_dims")),
                 "y": (np.float64, ("n_obs",)), "labels": (np.float64, ("n_obs",)),
                 "lengths": (np.float64, ("n_obs",)), "alpha": (np.float64, ("n_obs",)),
                 "L": (np.float64, ("n_L",))}
    _FITTED = ("kernel_", "quadrature_", "noise_", "jitter_", "plsc_",
               "log_marginal_likelihood_value_", "n_dims_", "n_accepted_", "n_rejected_")

    def save(self, path: str | os.PathLike) -> "GPOMIK":
        """Write the model (parameters and, once fitted, every local model) to an ``.npz``.

        A NumPy ``.npz`` archive (``numpy.savez_compressed``) of plain arrays,
        no pickled objects, written at `path` exactly; :meth:`load` reads it
        back into a model that predicts, and goes on updating, exactly as this
        one. Its entries:

        ``format``, ``version``, ``class``
            0-d arrays: ``"occgp.gp_model"``, 1, ``"GPOMIK"``.
        ``params``
            0-d str, JSON: the constructor's parameters; a kernel or rule as
            ``{"__object__": class name, "params": {...}}``, a tuple as
            ``{"__tuple__": [...]}``, an array as ``{"__ndarray__": dtype,
            "shape": [...], "data": [...]}``, a Generator as
            ``{"__generator__": its bit generator's state}``.
        ``fitted`` (fitted models only, as all below)
            0-d str, JSON: ``kernel_``, ``quadrature_`` (the rule in use),
            ``noise_``, ``jitter_``, ``plsc_``,
            ``log_marginal_likelihood_value_`` (null for NaN), ``n_dims_``,
            ``n_accepted_``, ``n_rejected_``.
        ``cell_sizes``
            int64 (n_cells,): observations in each local model, in order.
        ``L_fortran``
            bool (n_cells,): whether each factor was held in Fortran order
            (as LAPACK returns it); the triangular solves of ``predict`` and
            ``update`` round differently in the two layouts.
        ``starts``, ``ends``, ``y``, ``labels``, ``lengths``
            float64 (n_obs, D) and (n_obs,): the fields of every local
            model's :class:`~occgp.gp.Observations`, cell after cell.
        ``alpha``
            float64 (n_obs,): each local model's ``K^-1 y``, cell after cell.
        ``L``
            float64 (sum n_i (n_i + 1) / 2,): the lower triangle of each local
            model's Cholesky factor, row by row (``numpy.tril_indices``).

        Parameters
        ----------
        path : str or path-like
            Destination file (overwritten).

        Returns
        -------
        self : GPOMIK

        Raises
        ------
        TypeError
            If `path` is not a str or path-like, or a parameter holds a value
            other than None, bool, int, float, str, tuple, list, numeric array,
            numpy Generator or RandomState, or one of occgp.gp's kernels and
            rules.
        OSError
            If the file cannot be written.
        """
        params = _gp_params(self)
        arrays = {}
        if hasattr(self, "cells_"):
            cells = self.cells_
            lml = float(self.log_marginal_likelihood_value_)
            arrays["fitted"] = _gp_fitted({
                "kernel_": self.kernel_, "quadrature_": self._quadrature,
                "noise_": float(self.noise_), "jitter_": float(self.jitter_),
                "plsc_": tuple(float(v) for v in self.plsc_),
                "log_marginal_likelihood_value_": lml if np.isfinite(lml) else None,
                "n_dims_": int(self.n_dims_), "n_accepted_": int(self.n_accepted_),
                "n_rejected_": int(self.n_rejected_)})
            arrays["cell_sizes"] = np.array([c.size for c in cells], dtype=np.int64)
            arrays["L_fortran"] = np.array(
                [c.L.flags.f_contiguous and not c.L.flags.c_contiguous for c in cells],
                dtype=np.bool_)
            for f in Observations._fields:
                arrays[f] = np.concatenate([getattr(c.obs, f) for c in cells])
            arrays["alpha"] = np.concatenate([c.alpha for c in cells])
            arrays["L"] = np.concatenate([c.L[np.tril_indices(c.size)] for c in cells])
        _npz_io.write_npz(path, _GP_FORMAT, _GP_VERSIONS[-1], type(self).__name__, params,
                          arrays)
        return self

    @classmethod
    def load(cls, path: str | os.PathLike) -> "GPOMIK":
        """Read a model written by :meth:`save` (the format is described there).

        Parameters
        ----------
        path : str or path-like

        Returns
        -------
        GPOMIK
            Fitted when the saved model was.

        Raises
        ------
        TypeError
            If `path` is not a str or path-like.
        OSError
            If the file does not exist, is not a regular file or cannot be read.
        ValueError
            If it is not an ``.npz`` archive, is truncated or corrupt, is of
            another format, version or class, lacks an entry or has an
            unexpected one, an entry has the wrong dtype or shape; if the
            parameters or the fitted state are not valid (NaN or inf, sizes
            that disagree, a factor with a diagonal entry <= 0, targets that
            do not match the labels and lengths).
        """
        source, model, arrays, fitted = _read_gp(cls, path, cls._OBS_SPEC)
        if fitted is None:
            return model
        n_obs, n_dims = arrays["starts"].shape
        fitted = _check_gp_fitted(fitted, cls._FITTED, n_dims, source, "GPOMIK")
        bad = ""
        sizes = arrays["cell_sizes"]
        try:
            quadrature = fitted["quadrature_"]
            if not isinstance(quadrature, _Rule):
                raise TypeError(f"quadrature_ must be a ClenshawCurtis or Simpson, got "
                                f"{quadrature!r:.80}")
            quadrature._checked()
            check_real(fitted["jitter_"], "jitter_", low=0.0, low_open=False)
            for key in ("n_accepted_", "n_rejected_"):
                _check_int(fitted[key], key, 0)
        except (TypeError, ValueError) as exc:
            bad = str(exc)
        labels, y, lengths = arrays["labels"], arrays["y"], arrays["lengths"]
        hit = labels == 1
        if bad:
            pass
        elif not 1 <= n_dims <= 3:
            bad = f"the observations must have 1 to 3 dimensions, got {n_dims}"
        elif len(sizes) == 0 or (sizes < 1).any() or int(sizes.sum()) != n_obs:
            bad = f"'cell_sizes' must be positive and sum to {n_obs}"
        elif fitted["n_accepted_"] != n_obs:
            bad = f"n_accepted_ must be {n_obs} (the observations), got {fitted['n_accepted_']}"
        elif sum(int(n) * (int(n) + 1) // 2 for n in sizes) != len(arrays["L"]):
            bad = "'L' must hold the lower triangles of the cells' factors"
        elif not (hit | (labels == -1)).all():
            bad = "'labels' must be +1 (hit) or -1 (beam)"
        elif not (np.array_equal(y[hit], np.ones(hit.sum())) and
                  np.array_equal(arrays["starts"][hit], arrays["ends"][hit]) and
                  not lengths[hit].any()):
            bad = "the hits must be points with target 1 and length 0"
        elif not (np.array_equal(y[~hit], np.where(lengths[~hit] > 0, -lengths[~hit], -1.0))
                  and (lengths >= 0).all()):
            bad = "the beams' targets must be minus their lengths (-1 for zero length)"
        if bad:
            raise ValueError(f"{source}: corrupt fitted state of a GPOMIK: {bad}")
        cells, start, pos = [], 0, 0
        for n, fortran in zip(sizes.tolist(), arrays["L_fortran"].tolist()):
            L = np.zeros((n, n), order="F" if fortran else "C")
            L[np.tril_indices(n)] = arrays["L"][pos:pos + n * (n + 1) // 2]
            if not (np.diag(L) > 0).all():
                raise ValueError(f"{source}: corrupt fitted state of a GPOMIK: the Cholesky "
                                 f"factor of local model {len(cells)} has a diagonal entry "
                                 f"<= 0")
            obs = Observations(*(arrays[f][start:start + n].copy()
                                 for f in Observations._fields))
            cells.append(_Cell(obs, L, arrays["alpha"][start:start + n].copy()))
            start, pos = start + n, pos + n * (n + 1) // 2
        model.kernel_, model.noise_ = fitted["kernel_"], float(fitted["noise_"])
        model.jitter_ = float(fitted["jitter_"])
        model.plsc_ = tuple(float(v) for v in fitted["plsc_"])
        model.log_marginal_likelihood_value_ = fitted["log_marginal_likelihood_value_"]
        model.n_dims_ = n_dims
        model._quadrature, model._n_threads = fitted["quadrature_"], threads(model.n_jobs)
        model.cells_ = cells
        model.n_accepted_ = int(fitted["n_accepted_"])
        model.n_rejected_ = int(fitted["n_rejected_"])
        return model

    # --------------------------------------------------------------- predict
    def _check_X(self, X):
        check_is_fitted(self, "cells_")
        return as_points(X, "X", self.n_dims_)

    def _predict_cell(self, cell, X, return_var):
        """Mean (and variance) of one cell at `X`, tile by tile.

        Queries beyond the kernel's reach (its cutoff) of the cell's box get
        the prior, as the tiles would give them. The others are grouped into
        square tiles of `_TILE` (4) length scales; a tile
        only meets the observations that come within the kernel's cutoff of
        it (the other entries of its cross-covariance are exactly 0), so each
        tile solves a small dense problem: ``mean = k_S . alpha_S`` and
        ``var = k(x, x) - k_S^T [K^-1]_SS k_S``. The blocks of many tiles are
        computed in one parallel call, then the products run tile by tile.
        """
        kernel = self.kernel_
        inv = kernel.inverse_length_scales(self.n_dims_)
        reach = np.sqrt(type(kernel).cutoff2)
        lo, hi = cell.bounds(reach / inv)
        inside = np.all((X >= lo) & (X <= hi), axis=1)
        if not inside.all():  # beyond the kernel's reach of every observation: the prior
            mean = np.zeros(len(X))
            var = np.full(len(X), float(kernel.variance)) if return_var else None
            if inside.any():
                m, v = self._predict_cell(cell, X[inside], return_var)
                mean[inside] = m
                if return_var:
                    var[inside] = v
            return mean, var
        mean = np.empty(len(X))
        var = np.empty(len(X)) if return_var else None
        if not len(X):
            return mean, var
        kinv = cell.inverse() if return_var else None
        Xs = np.ascontiguousarray(X * inv)
        A = np.ascontiguousarray(cell.obs.starts * inv)
        V = np.ascontiguousarray((cell.obs.ends - cell.obs.starts) * inv)
        lengths = np.ascontiguousarray(cell.obs.lengths)
        keys = np.floor(Xs / _TILE).astype(np.int64)
        _, tile_of, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
        rows = np.argsort(tile_of.ravel(), kind="stable").astype(np.intp)
        row_ptr = np.r_[0, np.cumsum(counts)].astype(np.intp)
        half_diag = 0.5 * _TILE * np.sqrt(self.n_dims_)
        near = [np.flatnonzero(_segment_distance((keys[rows[row_ptr[t]]] + 0.5) * _TILE, A, A + V)
                               <= reach + half_diag) for t in range(len(counts))]
        sizes = counts * np.array([len(n) for n in near])
        nodes, weights, offsets, q_reach = self._quadrature.table(kernel)
        prior, variance = float(kernel.variance), float(kernel.variance)
        t0 = 0
        while t0 < len(counts):  # chunks of tiles whose blocks fit in _BLOCK_ENTRIES
            t1 = t0 + max(1, int(np.searchsorted(np.cumsum(sizes[t0:]), _BLOCK_ENTRIES)))
            cols = np.concatenate(near[t0:t1]).astype(np.intp)
            col_ptr = np.r_[0, np.cumsum([len(n) for n in near[t0:t1]])].astype(np.intp)
            out_ptr = np.r_[0, np.cumsum(sizes[t0:t1])].astype(np.intp)
            out = np.empty(int(out_ptr[-1]))
            _integral.tile_covariance(
                type(kernel).kind, float(type(kernel).cutoff2), Xs, A, V, lengths,
                rows[row_ptr[t0]:row_ptr[t1]], row_ptr[t0:t1 + 1] - row_ptr[t0], cols, col_ptr,
                out_ptr, nodes, weights, offsets, q_reach, out, self._n_threads)
            for t in range(t0, t1):
                q = rows[row_ptr[t]:row_ptr[t + 1]]
                Ks = variance * out[out_ptr[t - t0]:out_ptr[t - t0 + 1]].reshape(len(q), -1)
                mean[q] = Ks @ cell.alpha[near[t]]
                if return_var:
                    quad = np.einsum("ij,ij->i", Ks @ kinv[np.ix_(near[t], near[t])], Ks)
                    var[q] = np.maximum(prior - quad, 0.0)
            t0 = t1
        return mean, var

    def predict(self, X: ArrayLike, return_var: bool = False):
        """Latent mean (and variance) of the occupancy function at points `X`.

        With several cells, each query is answered by the cell with the
        smallest variance among those whose box (its observations' extent
        plus three length scales) holds it; a query in no box gets the prior
        (mean 0, variance of the kernel).

        Parameters
        ----------
        X : array-like of shape (n_queries, D)
            Query points in the fitted model's dimension D. Must be finite.
        return_var : bool, default=False
            Also return the latent variance.

        Returns
        -------
        mean : ndarray of shape (n_queries,)
        var : ndarray of shape (n_queries,)
            Only with `return_var`.

        Raises
        ------
        NotFittedError
            If called before :meth:`fit`.
        ValueError
            If `X` is not of shape (n_queries, D) or holds NaN or inf.
        TypeError
            If `X` does not hold real numbers, or `return_var` is not a bool.
        """
        X = self._check_X(X)
        return_var = check_bool(return_var, "return_var")
        if len(self.cells_) == 1:
            mean, var = self._predict_cell(self.cells_[0], X, return_var)
            return (mean, var) if return_var else mean
        prior = float(self.kernel_.variance)
        mean, best = np.zeros(len(X)), np.full(len(X), prior)
        margin = 3.0 / self.kernel_.inverse_length_scales(self.n_dims_)
        for cell in self.cells_:
            lo, hi = cell.bounds(margin)
            inside = np.flatnonzero(np.all((X >= lo) & (X <= hi), axis=1))
            if not len(inside):
                continue
            m, v = self._predict_cell(cell, X[inside], True)
            better = v < best[inside]
            mean[inside[better]], best[inside[better]] = m[better], v[better]
        return (mean, best) if return_var else mean

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
        """
        mean, var = self.predict(X, return_var=True)
        a, b = self.plsc_
        return plsc_proba(mean, var, a, b)
