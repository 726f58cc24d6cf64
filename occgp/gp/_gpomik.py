"""GPOMIK: Gaussian-process occupancy maps with integral kernels (O'Callaghan & Ramos).

The class, its fit, prediction and files; its incremental updates (KL gains, Cholesky
updates) are in ``_gpomik_update.py``.
"""

from __future__ import annotations

import os

import numpy as np
from numpy.typing import ArrayLike, NDArray
from sklearn.base import BaseEstimator
from sklearn.utils.validation import check_is_fitted

from .._docfill import fill_doc
from .._validation import as_points, check_bool, check_choice, check_probability, check_real
from ..maps import register
from ._cells import Cell, downdated_cell, predict_cell, spatial_groups
from ._checks import check_at_least
from ._gpomik_update import GPOMIKUpdates
from ._gpr import (OBJECTIVES, cholesky, jitter_for, optimize_hyperparameters, solve_lower,
                   with_noise)
from ._integral_kernel import check_kernel, check_quadrature, covariance
from ._io import check_gp_fitted, fitted_scalars, gp_fitted, gpomik_cells, read_gp, \
    set_fitted_scalars, write_gp
from ._kernels import SquaredExponential
from ._limits import MAX_RESTARTS, check_coordinates, check_dense, check_segments, generator, threads
from ._map_protocol import MapProtocol
from ._observations import (Observations, check_beam_hits, draw_subset, loo_sample,
                            make_observations)
from ._plsc import PLSCProba, fit_plsc, loo_predictions
from ._thinning import thin_to_budget

__all__ = ["GPOMIK"]

#: What PLSC is fitted on (see GPOMIK's `calibration`).
CALIBRATIONS = ("model-loo", "subset-loo")
#: Default `max_observations`: most observations one fit keeps (see thin_observations).
MAX_OBSERVATIONS = 50_000



@register("gpomik", dims=(2,), formats=(".npz",),
          description="Gaussian-process occupancy map with integral kernels (2D)")
@fill_doc()
class GPOMIK(GPOMIKUpdates, PLSCProba, MapProtocol, BaseEstimator):
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
    noise_bounds : pair of float, default=(0.01, 0.25)
        Bounds of the noise variance during optimisation.
        The cap keeps the fit out of a degenerate optimum where the hits
        are noise and a nearly constant latent function explains the
        beams (on an open hall of the scene family's tuning seeds, with a
        cap of 1.0: noise 1.0, length scale 54 m, AUC 0.75; with 0.25:
        noise 0.015, length scale 0.65 m, AUC 0.999). The floor keeps it
        from interpolating a real log's scatter: on the Intel log (held-out
        benchmark, 50,000 observations kept) a floor of 1e-4 let the fit
        reach noise 1e-4 to 9e-4 on two of three seeds, AUC 0.92 to 0.93;
        with 0.01, noise 0.01 to 0.03 and AUC 0.97 to 0.98 on all three.
    quadrature : {"clenshaw-curtis", "simpson"}, ClenshawCurtis or Simpson, \
default="clenshaw-curtis"
        Rule for the segment integrals without closed form.
    optimizer : bool, default=True
        Fit the hyper-parameters by maximising the log marginal likelihood
        (L-BFGS-B in log space).
    n_restarts : int, default=2
        Extra optimiser starts, drawn log-uniformly within the bounds; at
        most 1000.
    objective : {"lml", "loo"}, default="lml"
        What the hyper-parameter fit maximises: the log marginal likelihood,
        or the leave-one-out log predictive probability of the observations
        (Rasmussen & Williams, §5.4.2), which scores the predictions the
        map makes and is less sensitive to a misspecified kernel.
    max_optimize : int, default=1000
        Hyper-parameters are fitted on a random subset of at most this many
        observations (with at least one hit and one beam), and PLSC on a
        sample of at most this many (see `calibration`).
    max_cell_size : int or None, default=2000
        Most observations in one local model. :meth:`fit` splits larger sets
        into spatial cells by median bisection; :meth:`update` starts a new
        cell once the newest one is full. None: one model, no limit.
    max_observations : int or None, default=50000
        Most observations (hits and beams) :meth:`fit` keeps: past it, the
        places seen by the most beams keep a random few of them
        (:func:`~occgp.gp.thin_observations`, seeded by `random_state`;
        dropped ones count in ``n_rejected_``). None keeps every one, within
        the model-size limit. :meth:`update` keeps what it is given. The
        model's cost grows with it: on the Intel log (287,400 observations),
        50,000 fit and answer the benchmark's queries in 29 s with AUC
        0.977, 100,000 in 69 s with 0.968, all of them in 282 s with 0.966;
        a fit past the limit of the models' size (8 GiB of factors) is
        refused before any work.
    kl_threshold : float or None, default=None
        Active sampling in :meth:`update`: an observation whose KL divergence
        between the predictive distributions at its location after and before
        adding it is below this is rejected. None accepts every observation.
    calibration : {"model-loo", "subset-loo"}, default="model-loo"
        What PLSC is fitted on. ``"model-loo"``: the leave-one-out
        predictions of the fitted model (its cells, as :meth:`predict`
        answers) at a seeded sample of at most `max_optimize` training
        observations, as many hits as beams (fewer of one class when it has
        fewer): at each hit, and at a uniformly drawn point of each beam,
        the observation's cell predicts without it (a rank-one downdate).
        ``"subset-loo"``: the leave-one-out predictions of one GP over the
        hyper-parameter subset, a beam's integral per unit length (the
        classifier of the GPOMIK paper), which sees the data far sparser
        than the model does: on the Intel log it calls more free space
        occupied (accuracy at 0.5 of 0.890 against 0.940 for
        ``"model-loo"``, AUC 0.975 and 0.977; see "Which map when").
    random_state : int, Generator or None, default=None
        Seeds the optimiser restarts, the subset of `max_optimize` and the
        classifier's sample.
    n_jobs : int, default=None
        Threads for the kernel matrices (None: 1; -1: every core).
    occupancy_threshold : float, default=0.5
        :meth:`is_occupied`'s threshold: a point is occupied when its
        probability is at least this; in (0, 1).

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
        rejects only those its thinning drops, see `max_observations`;
        ``update`` those below `kl_threshold`).

    Notes
    -----
    **As a map** (:class:`occgp.maps.OccupancyMap`, registered as
    ``"gpomik"``): :meth:`insert_scan` turns a 2D scan into hits and beams;
    the first scan is :meth:`fit`, each later one :meth:`update` (Cholesky
    updates, hyper-parameters and PLSC as fitted), so a sequence of scans
    gives the model of ``fit`` on the first and ``update`` with each next.
    **Unknown space**: :meth:`occupancy` is NaN outside the box of every
    local model's observations widened by the kernel's reach (its cutoff,
    e.g. 9.2 length scales for the squared exponential) or, with several
    local models, by the three length scales by which :meth:`predict` routes
    queries when that is less: there :meth:`predict` gives the prior without
    looking at any observation. :attr:`bounds` is the box of that known
    space, :attr:`num_cells` the number of observations, and
    :meth:`to_octree` evaluates the model on 0.1 m cells by default.

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

    def __init__(self, kernel=None, *, noise=0.01, noise_bounds=(0.01, 0.25),
                 quadrature="clenshaw-curtis", optimizer=True, n_restarts=2, objective="lml",
                 max_optimize=1000, max_cell_size=2000, max_observations=MAX_OBSERVATIONS,
                 kl_threshold=None, calibration="model-loo", random_state=None, n_jobs=None,
                 occupancy_threshold=0.5):
        self.kernel = kernel
        self.noise = noise
        self.noise_bounds = noise_bounds
        self.quadrature = quadrature
        self.optimizer = optimizer
        self.n_restarts = n_restarts
        self.objective = objective
        self.max_optimize = max_optimize
        self.max_cell_size = max_cell_size
        self.max_observations = max_observations
        self.kl_threshold = kl_threshold
        self.calibration = calibration
        self.random_state = random_state
        self.n_jobs = n_jobs
        self.occupancy_threshold = occupancy_threshold

    # ------------------------------------------------------------ parameters
    def _check_params(self):
        kernel = SquaredExponential() if self.kernel is None else check_kernel(self.kernel)
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
        check_at_least(self.n_restarts, "n_restarts", 0)
        if self.n_restarts > MAX_RESTARTS:
            raise ValueError(f"n_restarts must be at most {MAX_RESTARTS}, got {self.n_restarts!r}")
        check_choice(self.objective, "objective", OBJECTIVES)
        check_choice(self.calibration, "calibration", CALIBRATIONS)
        check_at_least(self.max_optimize, "max_optimize", 2)
        if self.max_cell_size is not None:
            check_at_least(self.max_cell_size, "max_cell_size", 1)
        if self.max_observations is not None:
            check_at_least(self.max_observations, "max_observations", 2)
        if self.kl_threshold is not None:
            check_real(self.kl_threshold, "kl_threshold", low=0.0, low_open=False)
        check_bool(self.optimizer, "optimizer")
        check_probability(self.occupancy_threshold, "occupancy_threshold")
        return kernel, noise, (lo, hi)

    # ------------------------------------------------------------------- fit
    def fit(self, hits: ArrayLike | None, segment_starts: ArrayLike | None,
            segment_ends: ArrayLike | None, *, beam_hits: ArrayLike | None = None) -> "GPOMIK":
        """Fit the hyper-parameters and PLSC, and factorise the model.

        Parameters
        ----------
        hits : array-like of shape (n_hits, D) or None
            Laser returns (occupied), D in 1..3.
        segment_starts, segment_ends : array-like of shape (n_beams, D) or None
            Beams, from the sensor to the return or to the maximum range
            (free). A zero-length beam counts as one free point. Every beam
            is a free segment, so both conventions serve: beams ending at
            their hits (occgp's), or stopping short of them (the
            integral-kernel paper's, which leaves the hit's surroundings
            unobserved: the maps then differ slightly near the hits).
        beam_hits : array-like of int of shape (n_beams,), default=None
            Each beam's hit (an index into `hits`), or -1 for a beam without
            a return, as :meth:`GPMixture.fit <occgp.gp.GPMixture.fit>`
            takes it. Checked, otherwise unused: this map needs no link
            between a beam and its hit.

        Returns
        -------
        self : GPOMIK

        Raises
        ------
        ValueError
            On NaN or inf, wrong shapes, inconsistent dimensions, missing
            class (PLSC needs hits and beams), invalid parameters, or data
            beyond the limits (coordinates past 1e10 length scales, beams
            longer than 1e4 length scales, dense matrices past 4 GiB), or
            `beam_hits` of the wrong shape or with an entry outside
            ``-1..n_hits-1``.
        numpy.linalg.LinAlgError
            (a ValueError) If a covariance matrix cannot be factorised (the
            message says what to change, usually a larger noise).
        TypeError
            On non-numeric input or `beam_hits`, or a kernel that is not one
            of occgp.gp's.
        """
        kernel, noise, noise_bounds = self._check_params()
        quadrature = check_quadrature(self.quadrature)
        n_threads = threads(self.n_jobs)
        rng = generator(self.random_state)
        obs = make_observations(hits, segment_starts, segment_ends)
        if beam_hits is not None:
            n_hits = int(np.count_nonzero(obs.labels > 0))
            check_beam_hits(beam_hits, len(obs.y) - n_hits, n_hits)
        if not ((obs.labels > 0).any() and (obs.labels < 0).any()):
            raise ValueError("GPOMIK needs both hits and beams to fit its classifier, got "
                             f"{int((obs.labels > 0).sum())} hits and "
                             f"{int((obs.labels < 0).sum())} beams")
        self._check_observations(obs, kernel)
        n_given = len(obs.y)
        obs = thin_to_budget(obs, self.max_observations, beam_hits, rng, self.max_cell_size,
                             "max_cell_size")[0]
        n_opt = min(len(obs.y), self.max_optimize)
        fix = "lower max_optimize"
        if self.optimizer:
            check_dense(n_opt, n_opt, kernel.n_theta + 4, "the hyper-parameter optimisation", fix)
        check_dense(n_opt, n_opt, 3, "the classifier's leave-one-out predictions", fix)
        self._check_cell_size(len(obs.y))
        subset = obs
        if len(obs.y) > self.max_optimize:
            subset = obs.take(draw_subset(obs.labels, self.max_optimize, rng))
        lml = np.nan
        if self.optimizer:
            kernel, noise, lml = optimize_hyperparameters(
                kernel, noise, noise_bounds, subset.starts, subset.ends, subset.y, quadrature,
                n_restarts=self.n_restarts, rng=rng, n_threads=n_threads,
                objective=self.objective)
        K_sub = covariance(kernel, quadrature, subset.starts, subset.ends, n_threads=n_threads)
        jitter = jitter_for(K_sub)
        L = cholesky(with_noise(K_sub, noise, jitter), kernel, noise,
                     "the optimisation subset")
        if self.calibration == "subset-loo":
            mu, var = loo_predictions(L, subset.y)
            scale = np.where(subset.lengths > 0, subset.lengths, 1.0)    # per unit length
            plsc = fit_plsc(mu / scale, var / scale ** 2, subset.labels)
        if subset is obs and (self.max_cell_size is None or len(obs.y) <= self.max_cell_size):
            # one cell of every observation: the factor of the subset is its factor
            # (the same matrix _make_cells would build, in the same order)
            cells, groups = [Cell(obs, L, solve_lower(L, obs.y))], [np.arange(len(obs.y))]
        else:
            cells, groups = self._make_cells(obs, kernel, noise, jitter, quadrature, n_threads,
                                             return_groups=True)
        if self.calibration == "model-loo":
            take, X = loo_sample(obs, self.max_optimize, rng)
            mu, var = self._model_loo(cells, groups, kernel, quadrature, n_threads, take, X)
            plsc = fit_plsc(mu, var, obs.labels[take])
        if not np.isfinite(plsc).all():
            raise ValueError(f"the classifier's fit on the leave-one-out predictions failed "
                             f"(PLSC a, b = {plsc}); check the data and the noise")
        self.kernel_, self.noise_, self.jitter_ = kernel, noise, jitter
        self.plsc_ = plsc
        self.log_marginal_likelihood_value_ = lml
        self.n_dims_ = obs.starts.shape[1]
        self._quadrature, self._n_threads = quadrature, n_threads
        self.cells_ = cells
        self.n_accepted_, self.n_rejected_ = len(obs.y), n_given - len(obs.y)
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

    def _make_cells(self, obs, kernel, noise, jitter, quadrature, n_threads,
                    return_groups=False):
        """Factorised cells of `obs` split by `max_cell_size`; nothing is stored.
        With `return_groups`, also the indices into `obs` of each cell's observations."""
        size = len(obs.y) if self.max_cell_size is None else self.max_cell_size
        cells, groups = [], spatial_groups(obs.anchors, max(size, 1))
        for idx in groups:
            part = obs.take(idx)
            K = covariance(kernel, quadrature, part.starts, part.ends, n_threads=n_threads)
            L = cholesky(with_noise(K, noise, jitter), kernel, noise,
                         f"a local model of {len(idx)} observations")
            cells.append(Cell(part, L, solve_lower(L, part.y)))
        return (cells, groups) if return_groups else cells

    @staticmethod
    def _model_loo(cells, groups, kernel, quadrature, n_threads, take, X):
        """Leave-one-out latent means and variances of the model at `X`, X[j] on the
        observation take[j] (an index into the observations that `groups` splits into
        `cells`): as :meth:`predict` answers there, with that observation's cell
        predicting without it (a rank-one downdate)."""
        cell_of = np.empty(sum(len(g) for g in groups), dtype=np.intp)
        pos_of = np.empty_like(cell_of)
        for c, idx in enumerate(groups):
            cell_of[idx], pos_of[idx] = c, np.arange(len(idx))
        owner = cell_of[take]
        if len(cells) == 1:
            return downdated_cell(cells[0], kernel, quadrature, n_threads, X, pos_of[take])
        prior = float(kernel.variance)
        mean, best = np.zeros(len(X)), np.full(len(X), prior)
        margin = 3.0 / kernel.inverse_length_scales(X.shape[1])
        for c, cell in enumerate(cells):
            lo, hi = cell.bounds(margin)
            inside = np.all((X >= lo) & (X <= hi), axis=1)
            own = np.flatnonzero(owner == c)    # within the box: on its own observation
            other = np.flatnonzero(inside & (owner != c))
            m, v = np.empty(len(X)), np.empty(len(X))
            if len(own):
                m[own], v[own] = downdated_cell(cell, kernel, quadrature, n_threads, X[own],
                                                pos_of[take[own]])
            if len(other):
                m[other], v[other] = predict_cell(cell, X[other], kernel, quadrature,
                                                  n_threads, True)
            at = np.union1d(own, other)
            better = at[v[at] < best[at]]
            mean[better], best[better] = m[better], v[better]
        return mean, best

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

        {save_parameters}

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
        arrays = {}
        if hasattr(self, "cells_"):
            cells = self.cells_
            arrays["fitted"] = gp_fitted({
                **fitted_scalars(self), "quadrature_": self._quadrature,
                "jitter_": float(self.jitter_), "n_accepted_": int(self.n_accepted_),
                "n_rejected_": int(self.n_rejected_)})
            arrays["cell_sizes"] = np.array([c.size for c in cells], dtype=np.int64)
            arrays["L_fortran"] = np.array(
                [c.L.flags.f_contiguous and not c.L.flags.c_contiguous for c in cells],
                dtype=np.bool_)
            for f in Observations._fields:
                arrays[f] = np.concatenate([getattr(c.obs, f) for c in cells])
            arrays["alpha"] = np.concatenate([c.alpha for c in cells])
            arrays["L"] = np.concatenate([c.L[np.tril_indices(c.size)] for c in cells])
        return write_gp(self, path, arrays)

    @classmethod
    def load(cls, path: str | os.PathLike) -> "GPOMIK":
        """Read a model written by :meth:`save` (the format is described there).

        {load_parameters}

        Returns
        -------
        GPOMIK
            Fitted when the saved model was.

        {load_raises}
            Also if the parameters or the fitted state are not valid (NaN or
            inf, sizes that disagree, a factor with a diagonal entry <= 0,
            targets that do not match the labels and lengths).
        """
        source, model, arrays, fitted = read_gp(cls, path, cls._OBS_SPEC)
        if fitted is None:
            return model
        n_dims = arrays["starts"].shape[1]
        fitted = check_gp_fitted(fitted, cls._FITTED, n_dims, source, "GPOMIK")
        cells = gpomik_cells(arrays, fitted, source)
        set_fitted_scalars(model, fitted)
        model.jitter_ = float(fitted["jitter_"])
        model._quadrature, model._n_threads = fitted["quadrature_"], threads(model.n_jobs)
        model.cells_ = cells
        model.n_accepted_ = int(fitted["n_accepted_"])
        model.n_rejected_ = int(fitted["n_rejected_"])
        return model

    # ---------------------------------------------------------- map protocol
    def _fitted(self):
        return hasattr(self, "cells_")

    def _margin(self):
        """How far beyond its observations' box a local model may differ from the prior."""
        inv = self.kernel_.inverse_length_scales(self.n_dims_)
        reach = float(np.sqrt(type(self.kernel_).cutoff2))
        return (reach if len(self.cells_) == 1 else min(reach, 3.0)) / inv

    def _known(self, X):
        margin = self._margin()
        known = np.zeros(len(X), dtype=bool)
        for cell in self.cells_:
            lo, hi = cell.bounds(margin)
            known |= np.all((X >= lo) & (X <= hi), axis=1)
        return known

    def _known_bounds(self):
        boxes = [cell.bounds(self._margin()) for cell in self.cells_]
        return np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0)

    def _num_cells(self):
        return sum(cell.size for cell in self.cells_)

    def _nbytes(self):
        return sum(cell.nbytes for cell in self.cells_)

    # --------------------------------------------------------------- predict
    def _check_X(self, X):
        check_is_fitted(self, "cells_")
        return as_points(X, "X", self.n_dims_)

    def _predict_cell(self, cell, X, return_var):
        """Mean (and variance) of one cell at `X` (see :func:`occgp.gp._cells.predict_cell`)."""
        return predict_cell(cell, X, self.kernel_, self._quadrature, self._n_threads, return_var)


    def predict(self, X: ArrayLike, return_var: bool = False):
        """Latent mean (and variance) of the occupancy function at points `X`.

        With several cells, each query is answered by the cell with the
        smallest variance among those whose box (its observations' extent
        plus three length scales) holds it; a query in no box gets the prior
        (mean 0, variance of the kernel).

        {predict_parameters}

        {predict_returns}

        {predict_raises}
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
