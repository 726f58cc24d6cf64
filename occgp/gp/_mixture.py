"""A mixture of Gaussian-process experts for occupancy (Kim & Kim 2022).

The observations are clustered (hits by line tracking, a Dirichlet process
or plane growing; beams follow their hit, or the most similar returning beam
when they have none), one :class:`~occgp.gp.GPOMIK` expert is fitted per
cluster with its own hyper-parameters, and the experts' latent predictions
are merged by a committee rule (:mod:`occgp.gp._committee`) before PLSC maps
them to probabilities. This module holds the class, its fit, prediction and files;
its incremental updates are in ``_mixture_update.py``.
"""

from __future__ import annotations

import numpy as np
from joblib import Parallel, delayed
from numpy.typing import ArrayLike, NDArray
from sklearn.base import BaseEstimator, clone
from sklearn.utils.validation import check_is_fitted
from threadpoolctl import threadpool_limits

from .._docfill import fill_doc
from .._validation import (as_points, check_bool, check_choice, check_int, check_n_jobs,
                           check_probability, check_real)
from ..maps import register
from ._beams import (HIT_TOLERANCE, beam_sources, match_call, merge_small_clusters,
                     no_return_error)
from ._cells import spatial_groups
from ._clustering import DirichletProcessClustering
from ._committee import COMBINE_RULES, Committee
from ._experts import (QueryIndex, Reach, downdated, evaluate_expert, fit_expert,
                       global_template, hit_origins, hits_first, one_cell, order_positions,
                       shared_template, skip_tolerances)
from ._gpomik import GPOMIK
from ._io import gp_fitted, gp_params, read_gp, write_gp
from ._limits import generator
from ._lines import LineTracking
from ._map_protocol import MapProtocol
from ._mixture_update import GPMixtureUpdates
from ._observations import Observations, check_beam_hits, loo_sample, make_observations
from ._planes import PlaneClustering
from ._plsc import PLSCProba, fit_plsc
from ._thinning import thin_to_budget

__all__ = ["GPMixture"]

_CLUSTERINGS = ("line", "dp", "plane")
_UPDATES = ("cholesky", "refit")
_HYPERPARAMETERS = ("global", "shared", "own")
#: What the committee's PLSC is fitted on (see GPMixture's `calibration`).
_CALIBRATIONS = ("committee-loo", "subset-loo")
#: The objects a GPMixture's parameters may hold (besides the kernels and rules).
_CLASSES = {c.__name__: c for c in (GPOMIK, LineTracking, DirichletProcessClustering,
                                    PlaneClustering)}


@register("gp-mixture", dims=(2,), formats=(".npz",),
          description="Mixture of GPOMIK experts merged by a committee (2D)")
@fill_doc()
class GPMixture(GPMixtureUpdates, PLSCProba, MapProtocol, BaseEstimator):
    """Mixture of Gaussian-process experts merged by a committee (Kim & Kim).

    The observations (hits and beams, as for :class:`GPOMIK`) are split into
    clusters, one GPOMIK expert with its own hyper-parameters (maximum
    marginal likelihood) is fitted on each, and the experts' latent
    predictions are merged by a committee rule. The cost falls from
    ``O(n^3)`` for one GP to ``O(n^3 / k^2)`` for k equal clusters, and the
    experts fit and predict in parallel through joblib.

    1. **Clustering of the hits**: line tracking (``"line"``, 2D: walls as
       lines, merged across scans), a Dirichlet-process Gaussian mixture
       (``"dp"``, any dimension) or plane growing (``"plane"``, 3D, with the
       Dirichlet process for what is not planar).
    2. **Beams**: a beam with a return joins its hit's cluster; one without
       joins the cluster of the most similar returning beam under the
       line–line integral kernel (the paper's Eq. 11, with the expert
       kernel's starting hyper-parameters). A beam's return is the hit its
       end equals (occgp's convention, :func:`observations_from_scans`'s
       default), or the hit on its ray at most `hit_tolerance` beyond its end
       (the integral-kernel paper's: free segments stopping short of the
       return), or the one `beam_hits` names (see :meth:`fit`).
    3. **Tiny clusters**: a cluster with fewer than `min_hits` hits or
       `min_size` observations, or without any beam, is merged into the
       nearest other cluster (every expert needs both classes for its
       classifier, and tiny experts cost more than they add); clusters of
       more than `max_cluster_size` observations are split by median
       bisection, each beam with its hit: a beam with a return sits at its
       hit, one without at the hit of the most similar returning beam (the
       one it took its cluster from), so the parts are pieces of a wall
       with the beams that hit them. A cut falls between distinct places
       only, and only where both parts keep hits and beams (the allowed
       cut nearest the median, along the longest axis that has one).
    4. **Merging** (``combine``): ``"bcm"`` is the paper's Eq. 13,
       ``"tresp"`` the BCM with its prior correction, ``"rbcm"`` the robust
       BCM, ``"gpoe"`` the generalised product of experts and ``"minvar"``
       the most confident expert alone (see :func:`combine_predictions`). An expert is evaluated only at the
       queries where it may differ from its prior by more than
       ``prior_tol / m`` (in prior variances and standard deviations; a
       bound from the distance to its observations), ``m`` the number of
       experts whose reach overlaps its own; elsewhere it counts as its
       prior, exactly known. Merged means and variances then differ from
       evaluating every expert everywhere by about `prior_tol` at most.
    5. **PLSC** (``a``, ``b``, see `calibration`): fitted on the committee's
       leave-one-out predictions at a seeded sample of at most `max_optimize`
       training observations, as many hits as beams (the classes weigh the
       same whatever their numbers): at each hit, and at a uniformly drawn
       point of each beam, every expert predicts and the observation's own
       expert predicts without it (a rank-one downdate).

    Parameters
    ----------
    expert : GPOMIK, default=None
        Template of the experts (its kernel is the starting point of every
        expert's hyper-parameter fit); None means ``GPOMIK(n_restarts=0)``.
        Its `random_state`, `max_cell_size` and `calibration` are replaced
        per expert (``"subset-loo"``: an expert's own PLSC is unused).
    clustering : {"line", "dp", "plane"} or clustering object, default="line"
        How the hits are clustered: :class:`LineTracking`,
        :class:`DirichletProcessClustering` or :class:`PlaneClustering` with
        their defaults, or an instance of one of them (or any object with
        ``fit_predict(hits, origins)`` and ``partial_fit(hits, origins)``),
        which is cloned.
    combine : {"bcm", "tresp", "rbcm", "gpoe", "minvar"}, default="gpoe"
        The committee rule.
    hyperparameters : {"global", "shared", "own"}, default="global"
        ``"global"``: one set for every expert, fitted as :meth:`GPOMIK.fit`
        fits its own on a random subset of the template's `max_optimize`
        observations; ``"shared"``: one set for every expert, maximising the
        sum of the experts' log marginal likelihoods (Deisenroth & Ng 2015)
        on whole experts drawn at random until the template's `max_optimize`
        observations; ``"own"``: each expert maximises its own (the mixture
        paper), which over-fits small clusters (see the user guide).
    min_hits : int, default=5
        Fewest hits of a cluster with its own expert.
    min_size : int, default=1
        Fewest observations (hits and beams) of a cluster with its own
        expert.
    max_cluster_size : int, default=1000
        Most observations of one expert at :meth:`fit` (of a new one in
        :meth:`update`), except for a cluster that no cut splits keeping
        hits and beams on both sides (e.g. one hit with many beams), whose
        expert is then larger (one cell of that size); also the other
        experts' `max_cell_size` in :meth:`update`.
    prior_tol : float, default=1e-3
        Tolerance of skipping an expert at a query (see above); 0 skips only
        where the kernel's entries are exactly zero.
    update_experts : {"cholesky", "refit"}, default="cholesky"
        What :meth:`update` does to an expert whose cluster grew: a Cholesky
        update with its hyper-parameters as fitted, or a new fit on all of its
        observations.
    max_optimize : int, default=1000
        Most observations the committee's PLSC is fitted on (see 5. above).
    max_observations : int or None, default=100000
        Most observations (hits and beams) :meth:`fit` keeps, before it
        clusters them: past it, the places seen by the most beams keep a
        random few of them (:func:`~occgp.gp.thin_observations`, seeded by
        `random_state`); `labels_` then lists the observations kept. None
        keeps every one, within the model-size limit. :meth:`update` keeps
        what it is given.
    calibration : {"committee-loo", "subset-loo"}, default="committee-loo"
        What PLSC is fitted on: ``"committee-loo"``, see 5. above;
        ``"subset-loo"`` (with ``hyperparameters="global"`` only): the
        classifier of the GPOMIK fitted on the hyper-parameters' subset, on
        its leave-one-out predictions per unit length (the GPOMIK paper's,
        the earlier default; see the user guide).
    n_jobs : int, default=None
        Experts fitted and evaluated at once through joblib (threads unless
        the caller chose another backend, e.g.
        ``joblib.parallel_config(backend="dask")``); None means 1, -1 every
        core. The map does not depend on it.
    random_state : int, Generator or None, default=None
        Seeds the clustering, every expert (one seed per expert, from its
        index) and the PLSC sample.
    occupancy_threshold : float, default=0.5
        :meth:`is_occupied`'s threshold: a point is occupied when its
        probability is at least this; in (0, 1).
    hit_tolerance : float, default=0.1
        Farthest (metres, >= 0) a beam's hit may lie beyond the beam's end,
        on its ray, for beams that stop short of their returns (see
        :func:`occgp.gp._beams.match_beams`); 0 accepts only beams ending
        at their hits. Unused for the beams of a call given `beam_hits`.

    Attributes
    ----------
    experts_ : list of GPOMIK
        The fitted experts.
    n_experts_ : int
    labels_ : ndarray of shape (n_observations,)
        Expert of every observation so far: the hits, then the beams, of each
        :meth:`fit` / :meth:`update` call in turn.
    n_clusters_ : int
        Clusters the clustering found (before tiny clusters were merged and
        large ones split).
    clustering_ : object
        The fitted clustering.
    plsc_ : tuple of float
        PLSC's ``(a, b)`` on the committee's predictions.
    kernel_, noise_ : kernel and float, or None
        The shared hyper-parameters (None with ``hyperparameters="own"``;
        each expert has its own ``kernel_`` and ``noise_``).
    n_dims_ : int
    updated_experts_ : ndarray of int
        The experts the last :meth:`update` changed or created (all of them
        after :meth:`fit`).

    Notes
    -----
    **As a map** (:class:`occgp.maps.OccupancyMap`, registered as
    ``"gp-mixture"``): :meth:`insert_scan` turns a 2D scan into hits and
    beams; the first scan is :meth:`fit`, each later one :meth:`update`, so
    a sequence of scans gives the model of ``fit`` on the first and
    ``update`` with each next. **Unknown space**: :meth:`occupancy` is NaN
    where no expert is evaluated, i.e. where every expert is within
    ``prior_tol / m`` of its prior (see 4. above): there the
    committee merges priors only. :attr:`bounds` is the box of the experts'
    reach, :attr:`num_cells` the number of observations in the experts, and
    :meth:`to_octree` evaluates the model on 0.1 m cells by default.

    References
    ----------
    S. Kim, J. Kim, "Efficient clustering for continuous occupancy mapping
    using a mixture of Gaussian processes", Sensors 22 (2022) 6832.

    Examples
    --------
    >>> from occgp.datasets import room_2d
    >>> from occgp.gp import GPMixture, observations_from_scans
    >>> hits, starts, ends = observations_from_scans(room_2d().scan(n_poses=6))
    >>> model = GPMixture(random_state=0).fit(hits, starts, ends)
    >>> model.n_experts_ > 1, model.labels_.shape == (len(hits) + len(starts),)
    (True, True)
    """

    def __init__(self, expert=None, *, clustering="line", combine="gpoe",
                 hyperparameters="global", min_hits=5, min_size=1, max_cluster_size=1000,
                 prior_tol=1e-3, update_experts="cholesky", max_optimize=1000,
                 max_observations=100_000, calibration="committee-loo", n_jobs=None, random_state=None,
                 occupancy_threshold=0.5, hit_tolerance=HIT_TOLERANCE):
        self.expert = expert
        self.clustering = clustering
        self.combine = combine
        self.hyperparameters = hyperparameters
        self.min_hits = min_hits
        self.min_size = min_size
        self.max_cluster_size = max_cluster_size
        self.prior_tol = prior_tol
        self.update_experts = update_experts
        self.max_optimize = max_optimize
        self.max_observations = max_observations
        self.calibration = calibration
        self.n_jobs = n_jobs
        self.random_state = random_state
        self.occupancy_threshold = occupancy_threshold
        self.hit_tolerance = hit_tolerance

    # ------------------------------------------------------------ parameters
    def _check_params(self):
        if self.expert is None:
            template = GPOMIK(n_restarts=0)
        elif isinstance(self.expert, GPOMIK):
            template = self.expert
        else:
            raise TypeError(f"expert must be a GPOMIK or None, got {type(self.expert).__name__}")
        check_choice(self.combine, "combine", COMBINE_RULES)
        check_choice(self.update_experts, "update_experts", _UPDATES)
        check_choice(self.hyperparameters, "hyperparameters", _HYPERPARAMETERS)
        check_int(self.min_hits, "min_hits", low=1)
        check_int(self.min_size, "min_size", low=1)
        check_int(self.max_cluster_size, "max_cluster_size", low=2)
        check_int(self.max_optimize, "max_optimize", low=2)
        if self.max_observations is not None:
            check_int(self.max_observations, "max_observations", low=2)
        check_choice(self.calibration, "calibration", _CALIBRATIONS)
        if self.calibration == "subset-loo" and self.hyperparameters != "global":
            raise ValueError("calibration='subset-loo' needs hyperparameters='global', got "
                             f"{self.hyperparameters!r}")
        check_real(self.prior_tol, "prior_tol", low=0.0, high=1.0, low_open=False)
        check_n_jobs(self.n_jobs)
        check_probability(self.occupancy_threshold, "occupancy_threshold")
        check_real(self.hit_tolerance, "hit_tolerance", low=0.0, low_open=False)
        c = self.clustering
        if isinstance(c, str):
            check_choice(c, "clustering", _CLUSTERINGS)
        elif not (callable(getattr(c, "fit_predict", None))
                  and callable(getattr(c, "partial_fit", None))):
            raise TypeError("clustering must be 'line', 'dp', 'plane' or an object with "
                            f"fit_predict and partial_fit, got {type(c).__name__}")
        # the experts' own classifiers are not the committee's: the cheapest one
        template = clone(template).set_params(max_cell_size=self.max_cluster_size,
                                              calibration="subset-loo", max_observations=None)
        return template

    def _make_clustering(self, seed):
        c = self.clustering
        if c == "line":
            return LineTracking()
        if c == "dp":
            return DirichletProcessClustering(random_state=seed)
        if c == "plane":
            return PlaneClustering(random_state=seed)
        return clone(c)

    def _parallel(self):
        return Parallel(n_jobs=check_n_jobs(self.n_jobs), prefer="threads")

    def _expert_seed(self, e):
        return int(np.random.SeedSequence([self._seed, e]).generate_state(1)[0])

    # ------------------------------------------------------------- clusters
    def _cluster_labels(self, clustering, obs, n_hits, partial, matched):
        """Cluster labels (of `clustering`) of the hits and of the beams of `obs`, and
        where each observation sits for the split of its cluster into experts.

        `matched` is :meth:`_match`'s answer for the beams of `obs`. A hit sits
        at itself, a beam at the hit it takes its label from (its own, or that
        of the most similar returning beam), so that a split keeps beams with
        their hits.
        """
        hits = obs.starts[:n_hits]
        starts, ends = obs.starts[n_hits:], obs.ends[n_hits:]
        n_old = len(self._hit_clusters) if partial else 0
        origins = hit_origins(hits, starts, ends, np.where(matched >= n_old, matched - n_old, -1))
        fit = clustering.partial_fit if partial else clustering.fit_predict
        if partial and not len(hits):  # beams only: they join the clusters of earlier beams
            hit_labels = np.empty(0, dtype=np.int64)
        else:
            hit_labels = np.asarray(fit(hits, origins), dtype=np.int64)
        kernel = self._template.kernel
        quadrature = self._template.quadrature
        if partial:  # returning beams of earlier calls are candidates too
            old = self._observations
            old_hit = old.labels > 0
            all_hits = np.vstack([old.starts[old_hit], hits])
            all_labels = np.r_[self._hit_clusters, hit_labels]
            beam_labels, sources = beam_sources(
                all_labels, all_hits, np.vstack([old.starts[~old_hit], starts]),
                np.vstack([old.ends[~old_hit], ends]), kernel=kernel, quadrature=quadrature,
                n_jobs=self.n_jobs, beam_hits=np.r_[self._beam_hits, matched])
            n_old = int(np.count_nonzero(~old_hit))
            beam_labels, sources = beam_labels[n_old:], sources[n_old:]
        else:
            all_hits = hits
            beam_labels, sources = beam_sources(hit_labels, hits, starts, ends, kernel=kernel,
                                                quadrature=quadrature, n_jobs=self.n_jobs,
                                                beam_hits=matched)
        where = np.vstack([hits, all_hits[sources]])
        return hit_labels, beam_labels, where

    # ------------------------------------------------------------------- fit
    def fit(self, hits: ArrayLike | None, segment_starts: ArrayLike | None,
            segment_ends: ArrayLike | None, *,
            beam_hits: ArrayLike | None = None) -> "GPMixture":
        """Cluster the observations, fit one expert per cluster and the committee's PLSC.

        Parameters
        ----------
        hits : array-like of shape (n_hits, D) or None
            Laser returns (occupied), D in 1..3 (2 for line tracking, 3 for
            plane clustering), in scan order.
        segment_starts, segment_ends : array-like of shape (n_beams, D) or None
            Beams from the sensor to the maximum range (no return) or to the
            return, in either convention: ending at the hit (occgp's: a beam
            whose end equals a hit is that hit's beam) or stopping short of
            it (the integral-kernel paper's: the hit on the beam's ray at
            most `hit_tolerance` beyond its end is its hit). The hit's
            origin (the beam's start) also tells the clustering which scan
            it belongs to.
        beam_hits : array-like of int of shape (n_beams,), default=None
            Each beam's hit, as an index into `hits`, or -1 for a beam
            without a return (e.g. from ``observations_from_scans(...,
            return_beam_hits=True)``); replaces the matching above. Several
            beams may name one hit.

        Returns
        -------
        self : GPMixture

        Raises
        ------
        ValueError
            On NaN or inf, wrong shapes, no hits or no beams, invalid
            parameters, `beam_hits` of the wrong shape or with an entry
            outside ``-1..n_hits-1``, beams without a return when no beam
            has one, a clustering that does not fit the dimension, or an
            expert's fit failing (see :meth:`GPOMIK.fit`).
        TypeError
            On non-numeric input, `beam_hits` that are not integers, or
            parameters of the wrong type.
        """
        with threadpool_limits(1):  # one BLAS thread: the same values in every worker
            return self._fit(hits, segment_starts, segment_ends, beam_hits=beam_hits)

    def _fit(self, hits, segment_starts, segment_ends, seed=None, beam_hits=None, matched=None):
        """:meth:`fit`; `seed` (what `random_state` draws) and `matched` (the beams'
        hits) are given when a file is read."""
        template = self._check_params()
        if seed is None:
            seed = int(generator(self.random_state).integers(2 ** 32))
        obs = make_observations(hits, segment_starts, segment_ends)
        n_hits = int(np.count_nonzero(obs.labels > 0))
        if not (n_hits and n_hits < len(obs.y)):
            raise ValueError(f"GPMixture needs both hits and beams, got {n_hits} hits and "
                             f"{len(obs.y) - n_hits} beams")
        matched = match_call(obs, n_hits, beam_hits, matched, None, None, self.hit_tolerance)
        if not (matched >= 0).any():
            raise no_return_error(len(matched), self.hit_tolerance, beam_hits is not None)
        obs, matched = thin_to_budget(
            obs, self.max_observations, matched,
            np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(1,))),
            self.max_cluster_size, "max_cluster_size")
        n_hits = int(np.count_nonzero(obs.labels > 0))
        self._template, self._seed = template, seed
        self.kernel_, self.noise_ = None, None
        clustering = self._make_clustering(seed)
        hit_labels, beam_labels, where = self._cluster_labels(clustering, obs, n_hits,
                                                              partial=False, matched=matched)
        clusters = np.r_[hit_labels, beam_labels]
        merged = merge_small_clusters(clusters, obs.anchors, obs.labels > 0,
                                      min_hits=self.min_hits, min_size=self.min_size)
        groups, expert_of = [], np.empty(len(obs.y), dtype=np.int64)
        for g in np.unique(merged):
            idx = np.flatnonzero(merged == g)
            for part in sorted(spatial_groups(where[idx], self.max_cluster_size,
                                              obs.labels[idx] > 0),
                               key=lambda p: int(p.min())):
                expert_of[idx[part]] = len(groups)
                groups.append(np.sort(idx[part]))
        plsc = None
        if self.hyperparameters == "shared":
            template = shared_template(template, obs, groups, np.random.default_rng(seed))
        elif self.hyperparameters == "global":
            template, plsc = global_template(template, obs, seed)
        if self.hyperparameters != "own":
            self.kernel_, self.noise_ = template.kernel, template.noise
        self._expert_template = template  # what update() fits new experts with
        experts = self._parallel()(
            delayed(fit_expert)(one_cell(template, len(idx)), hits_first(obs.take(idx)),
                                self._expert_seed(e))
            for e, idx in enumerate(groups))
        self.experts_ = list(experts)
        self.clustering_ = clustering
        self.n_dims_ = obs.starts.shape[1]
        self.labels_ = expert_of
        self.n_clusters_ = int(len(np.unique(clusters)))
        self._observations = obs
        self._calls = [len(obs.y)]   # observations of each fit / update call, for save()
        self._hit_clusters = hit_labels
        self._beam_hits = matched    # the hit of every beam so far (all calls' hits), or -1
        # clustering label -> the experts that hold its observations
        self._cluster_experts = {}
        for c, e in zip(clusters.tolist(), expert_of.tolist()):
            self._cluster_experts.setdefault(c, set()).add(e)
        self._reach = [None] * len(self.experts_)
        self.updated_experts_ = np.arange(len(self.experts_))
        if self.calibration == "committee-loo":
            plsc = self._fit_plsc(obs, expert_of, groups, np.random.default_rng(seed))
        self.plsc_ = plsc
        return self

    @property
    def n_experts_(self) -> int:
        """Number of experts (``len(experts_)``)."""
        check_is_fitted(self, "experts_")
        return len(self.experts_)

    # ---------------------------------------------------------- map protocol
    def _fitted(self):
        return hasattr(self, "experts_")

    def _known(self, X):
        known = np.zeros(len(X), dtype=bool)
        index = QueryIndex(X)
        for reach, eps in zip(self._reaches(), self._tolerances()):
            known[reach.queries(index, eps)] = True
        return known

    def _known_bounds(self):
        boxes = [reach.box(eps) for reach, eps in zip(self._reaches(), self._tolerances())]
        return np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0)

    def _num_cells(self):
        return sum(gp._num_cells() for gp in self.experts_)

    def _nbytes(self):
        return sum(gp._nbytes() for gp in self.experts_) + self.labels_.nbytes + sum(
            a.nbytes for a in self._observations)

    # ----------------------------------------------------------------- files
    _SPEC = {"starts": (np.float64, ("n_obs", "n_dims")), "ends": (np.float64, ("n_obs", "n_dims")),
             "labels": (np.float64, ("n_obs",)), "call_sizes": (np.int64, ("n_calls",)),
             "beam_hits": (np.int64, ("n_beams",))}

    def save(self, path) -> "GPMixture":
        """Write the model (parameters and, once fitted, its evidence) to an ``.npz``.

        The format of :meth:`GPOMIK.save <occgp.gp.GPOMIK.save>`
        (``"occgp.gp_model"``, version 1, class ``"GPMixture"``, ``params``:
        the `expert` and `clustering` objects as ``{"__object__": ...}``),
        with, for a fitted model: ``fitted`` (0-d str, JSON: ``seed``, what
        `random_state` drew at :meth:`fit`), ``starts``, ``ends``, ``labels``
        (float64 (n_obs, D), (n_obs, D) and (n_obs,): the observations of
        every :meth:`fit` and :meth:`update` call in turn, each call's hits
        first) and ``call_sizes`` (int64 (n_calls,): the observations of each
        call), and ``beam_hits`` (int64 (n_beams,): the hit of each beam,
        indexing the hits of every call in turn, or -1; absent from files
        written before it existed, whose beams are matched again).
        :meth:`load` replays the calls with the seed, which gives the
        same model (the experts are fitted again: loading takes the time of
        those calls).

        {save_parameters}

        Returns
        -------
        self : GPMixture

        Raises
        ------
        TypeError
            If `path` is not a str or path-like, or a parameter holds a value
            that cannot be saved (e.g. a clustering object of another class
            than occgp.gp's).
        OSError
            If the file cannot be written.
        """
        params = self.get_params(deep=False)
        if isinstance(params["expert"], GPOMIK):
            params["expert"] = {"__object__": "GPOMIK", "params": gp_params(params["expert"])}
        params = gp_params(self, _CLASSES, params)
        arrays = {}
        if self._fitted():
            obs = self._observations
            arrays["fitted"] = gp_fitted({"seed": int(self._seed)})
            arrays.update(starts=obs.starts, ends=obs.ends, labels=obs.labels,
                          call_sizes=np.array(self._calls, dtype=np.int64),
                          beam_hits=self._beam_hits)
        return write_gp(self, path, arrays, params)

    @classmethod
    def load(cls, path) -> "GPMixture":
        """Read a model written by :meth:`save` (its calls are replayed).

        {load_parameters}

        Returns
        -------
        GPMixture
            Fitted when the saved model was.

        {load_raises}
            Also if its observations are not valid (labels other than +1 and
            -1, call sizes that do not add up), or replaying them fails.
        """
        source, model, arrays, fitted = read_gp(cls, path, cls._SPEC, _CLASSES,
                                                optional=("beam_hits",))
        if fitted is None:
            return model
        labels, sizes = arrays["labels"], arrays["call_sizes"]
        seed = fitted.get("seed")
        bad = ""
        if sorted(fitted) != ["seed"]:
            bad = f"'fitted' must hold ['seed'], got {sorted(fitted)[:20]}"
        elif isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2 ** 32:
            bad = f"seed must be an int in [0, 2**32), got {seed!r:.40}"
        elif not ((labels == 1) | (labels == -1)).all():
            bad = "'labels' must be +1 (hit) or -1 (beam)"
        elif len(sizes) == 0 or (sizes < 1).any() or int(sizes.sum()) != len(labels):
            bad = f"'call_sizes' must be positive and sum to {len(labels)}"
        elif "beam_hits" in arrays and len(arrays["beam_hits"]) != int((labels < 0).sum()):
            bad = f"'beam_hits' must have one entry per beam ({int((labels < 0).sum())})"
        if bad:
            raise ValueError(f"{source}: corrupt fitted state of a GPMixture: {bad}")
        ends = np.cumsum(sizes)
        saved = arrays.get("beam_hits")
        n_beams = np.cumsum([int((labels[lo:hi] < 0).sum())
                             for lo, hi in zip(ends - sizes, ends)])
        try:
            for i, (lo, hi) in enumerate(zip(ends - sizes, ends)):
                hit = labels[lo:hi] > 0
                starts, stops = arrays["starts"][lo:hi], arrays["ends"][lo:hi]
                data = (starts[hit], starts[~hit], stops[~hit])
                matched = None if saved is None else saved[n_beams[i] - len(data[1]):n_beams[i]]
                with threadpool_limits(1):
                    if i == 0:
                        model._fit(*data, seed=seed, matched=matched)
                    else:
                        model._update(*data, matched=matched)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{source}: cannot rebuild the GPMixture from its observations: "
                             f"{exc}") from None
        return model

    # -------------------------------------------------------------- predict
    def _reaches(self):
        for e, gp in enumerate(self.experts_):
            if self._reach[e] is None:
                self._reach[e] = Reach(gp)
        return self._reach

    def _tolerances(self):
        """How far from its prior each expert may be where it is skipped."""
        return skip_tolerances(self._reaches(), float(self.prior_tol))

    def _committee(self, X, skip=None):
        """The committee at `X` with every expert evaluated where it is within reach.

        `skip` (one expert per query, or -1) leaves that expert out at that
        query (the caller adds it).
        """
        priors = np.array([float(gp.kernel_.variance) for gp in self.experts_])
        committee = Committee(self.combine, priors, len(X))
        index = QueryIndex(X)
        reaches, tolerances = self._reaches(), self._tolerances()

        def tasks():  # made as the workers take them: a few queries' lists at a time
            for e in range(len(reaches)):
                idx = reaches[e].queries(index, tolerances[e])
                if skip is not None:
                    idx = idx[skip[idx] != e]
                if len(idx):
                    yield delayed(evaluate_expert)(e, self.experts_[e], idx, X[idx])

        # results merge as they arrive, in the experts' order (the same sums for any
        # backend), and are freed: memory stays a few experts' predictions
        parallel = Parallel(n_jobs=check_n_jobs(self.n_jobs), prefer="threads",
                            return_as="generator")
        for e, idx, mean, var in parallel(tasks()):
            committee.add(idx, mean, var, priors[e])
        return committee, priors

    def predict(self, X: ArrayLike, return_var: bool = False):
        """Merged latent mean (and variance) of the occupancy function at `X`.

        {predict_parameters}

        {predict_returns}

        {predict_raises}
        """
        check_is_fitted(self, "experts_")
        X = as_points(X, "X", self.n_dims_)
        return_var = check_bool(return_var, "return_var")
        with threadpool_limits(1):
            mean, var = self._committee(X)[0].result()
        return (mean, var) if return_var else mean

    # ----------------------------------------------------------------- PLSC
    def _fit_plsc(self, obs, expert_of, groups, rng):
        """PLSC on the committee's leave-one-out predictions (see the class docstring)."""
        take, X = loo_sample(obs, self.max_optimize, rng)
        owner = expert_of[take]
        committee, priors = self._committee(X, skip=owner)
        for e, gp in enumerate(self.experts_):
            sel = np.flatnonzero(owner == e)
            if not len(sel):
                continue
            # the observation's place in its expert (hits first, as _order put them)
            idx = groups[e]
            local = order_positions(obs.labels[idx] > 0)
            pos = local[np.searchsorted(idx, take[sel])]
            mean, var = downdated(gp, X[sel], pos)
            committee.add(sel, mean, var, priors[e])
        mean, var = committee.result()
        a, b = fit_plsc(mean, var, obs.labels[take])
        if not np.isfinite([a, b]).all():
            raise ValueError(f"the committee's classifier fit failed (PLSC a, b = {a}, {b}); "
                             "check the data")
        return a, b
