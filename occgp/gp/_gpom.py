"""The Gaussian-process occupancy map of O'Callaghan, Ramos & Durrant-Whyte (2009).

Each laser beam is discretised into free points (label -1) and each return is
an occupied point (label +1). A query point gets its own small GP regression,
trained on its nearest occupied and nearest free points; a probabilistic
least-squares classifier (PLSC) turns the latent mean and variance into a
probability of occupancy. This is the baseline that :class:`GPOMIK` (integral
kernels over whole beams, one global model) is compared against.
"""

from __future__ import annotations

import copy
import os

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree
from sklearn.base import BaseEstimator
from sklearn.utils import check_random_state
from sklearn.utils.validation import check_is_fitted

from .._docfill import fill_doc
from .._validation import (as_numeric, as_points, check_bool, check_choice, check_probability,
                           check_real)
from ..maps import register
from ._checks import check_at_least
from ._gpr import JITTER, OBJECTIVES, factorise, optimize_hyperparameters
from ._integral_kernel import as_segments, check_kernel
from ._io import check_gp_fitted, fitted_scalars, gp_fitted, read_gp, set_fitted_scalars, \
    write_gp
from ._kernels import SquaredExponential, check_bounds
from ._limits import MAX_DENSE_BYTES, MAX_RESTARTS, check_coordinates, check_dense, threads
from ._map_protocol import MapProtocol
from ._observations import check_beam_hits
from ._plsc import PLSCProba, fit_plsc, loo_predictions

__all__ = ["GPOM"]

#: Most free points the beams of one fit may be cut into.
MAX_FREE_POINTS = 10_000_000
#: Memory of the local matrices of one batch of queries (the batch is cut to fit).
_BATCH_BYTES = 2 ** 28
#: What PLSC is fitted on (see GPOM's `calibration`).
CALIBRATIONS = ("local-loo", "subset-loo")


class _PointsOnly:
    """Stand-in quadrature rule for observations that are all points.

    The compiled core evaluates point-point covariances as ``f(s)``, without
    quadrature; a real rule would calibrate its table first (seconds for
    :class:`Matern32`) for nothing.
    """

    _TABLE = (np.array([0.0, 0.5, 1.0]), np.array([1.0, 4.0, 1.0]) / 6.0,
              np.array([0, 3], dtype=np.intp), np.array([np.inf]))

    def table(self, kernel):
        return self._TABLE


def _free_point_count(starts, ends, step):
    """Number of free points :func:`_discretise` would make, as a float (no overflow)."""
    with np.errstate(over="ignore"):
        length = np.linalg.norm(ends - starts, axis=1)
    return float(np.maximum(np.ceil(length / step - 0.5), 1.0).sum())


def _discretise(starts, ends, step):
    """Free points along segments, at arc lengths ``step/2, 3 step/2, ...`` below each length.

    A segment no longer than ``step / 2`` gives its midpoint (a zero-length
    one, its start). Returns an array of shape (n_free, D).
    """
    delta = ends - starts
    length = np.linalg.norm(delta, axis=1)
    counts = np.maximum(np.ceil(length / step - 0.5), 0).astype(np.int64)
    short = counts == 0
    counts[short] = 1
    seg = np.repeat(np.arange(len(starts)), counts)
    first = np.cumsum(counts) - counts
    arc = (np.arange(counts.sum()) - first[seg] + 0.5) * step
    arc = np.where(short[seg], 0.5 * length[seg], arc)
    frac = np.divide(arc, length[seg], out=np.zeros_like(arc), where=length[seg] > 0)
    return starts[seg] + frac[:, None] * delta[seg]


def _without(neighbours, own):
    """Each row of `neighbours` (b, k + 1) less its own index `own` (b,; -1: none), or
    less its last entry when it does not hold it: shape (b, k)."""
    hit = neighbours == own[:, None]
    drop = np.where(hit.any(axis=1), hit.argmax(axis=1), neighbours.shape[1] - 1)
    keep = np.ones(neighbours.shape, dtype=bool)
    keep[np.arange(len(neighbours)), drop] = False
    return neighbours[keep].reshape(len(neighbours), -1)


def _balanced(n_hits, n_free, size, rng):
    """Sorted indices into hits-then-free points: at most `size`, as many hits as free
    points where both classes have enough (the rest from the larger class)."""
    half = size // 2
    k_hit = min(n_hits, max(half, size - n_free))
    k_free = min(n_free, size - k_hit)
    return np.sort(np.r_[rng.choice(n_hits, k_hit, replace=False),
                         n_hits + rng.choice(n_free, k_free, replace=False)])


def _subsample(y, size, rng):
    """Sorted indices of at most `size` samples, drawn per class so both classes stay."""
    if len(y) <= size:
        return np.arange(len(y))
    pos, neg = np.flatnonzero(y > 0), np.flatnonzero(y < 0)
    n_pos = min(max(round(size * len(pos) / len(y)), 1), len(pos), size - 1)
    chosen = [rng.choice(pos, n_pos, replace=False), rng.choice(neg, size - n_pos, replace=False)]
    return np.sort(np.concatenate(chosen))


@register("gpom", dims=(2,), formats=(".npz",),
          description="Gaussian-process occupancy map with a local GP per query (2D)")
@fill_doc()
class GPOM(PLSCProba, MapProtocol, BaseEstimator):
    """Gaussian-process occupancy map with a local GP per query point.

    Laser beams (segments from the sensor origin to the beam end) are
    discretised into free points every `free_step` metres, labelled -1, and
    laser returns are occupied points, labelled +1. Hyper-parameters are
    fitted once, by maximising the log marginal likelihood on a random subset
    of the training points. At prediction, each query point's latent mean and
    variance come from a GP trained on its `n_hit_neighbors` nearest occupied
    points and `n_free_neighbors` nearest free points; PLSC (fitted on the
    leave-one-out predictions of the local GPs at training points, see
    `calibration`) turns them into a probability of occupancy.

    Limits, checked before any work: the data must lie within 1e10 length
    scales of the origin (the kernel's length scales at :meth:`fit`), the
    beams may give at most ``MAX_FREE_POINTS`` (1e7) free points, and the
    dense matrices of the optimisation at most 4 GiB (which bounds
    `max_optimize`). Queries may lie anywhere: beyond the kernel's reach of
    every training point (its cutoff, 9.2 length scales for the squared
    exponential) they get the prior, ``mean = 0`` and ``var = variance``.

    Parameters
    ----------
    kernel : SquaredExponential, Matern32 or SparseKernel, default=None
        Covariance function; None means ``SquaredExponential()``. It is
        copied, never modified.
    noise : float, default=0.01
        Noise variance of the labels (the initial value when `optimizer`).
    noise_bounds : pair of float, default=(1e-4, 0.25)
        Bounds of `noise` during the optimisation.
        The cap keeps the fit out of a degenerate optimum where the hits
        are noise and a nearly constant latent function explains the
        beams (on an open hall of the scene family's tuning seeds, with a
        cap of 1.0: noise 1.0, length scale 54 m, AUC 0.75; with 0.25:
        noise 0.015, length scale 0.65 m, AUC 0.999).
    free_step : float, default=0.5
        Spacing of the free points along each beam, in metres.
    n_hit_neighbors : int, default=10
        Occupied points in each query's local training set.
    n_free_neighbors : int, default=20
        Free points in each query's local training set.
    optimizer : bool, default=True
        Whether to fit the kernel hyper-parameters and the noise.
    n_restarts : int, default=2
        Extra optimiser starts, drawn log-uniformly within the bounds; at
        most 1000.
    objective : {"lml", "loo"}, default="lml"
        What the hyper-parameter fit maximises: the log marginal likelihood,
        or the leave-one-out log predictive probability of the observations
        (Rasmussen & Williams, §5.4.2), which scores the predictions the
        map makes and is less sensitive to a misspecified kernel.
    max_optimize : int, default=1000
        Most training points (a random subset) used to fit the
        hyper-parameters, and to fit PLSC.
    calibration : {"local-loo", "subset-loo"}, default="local-loo"
        What PLSC is fitted on. ``"local-loo"``: the leave-one-out
        predictions of the local GPs that :meth:`predict` uses, at a seeded
        sample of at most `max_optimize` training points, as many hits as
        free points (fewer of one class when it has fewer). The classes weigh
        the same, so the probabilities do not depend on how finely the beams
        are cut into free points (`free_step`), and they are those of the
        model that answers the queries. ``"subset-loo"``: the leave-one-out
        predictions of one GP over the hyper-parameter subset (the
        classifier of the GPOMIK paper; on the Intel log its probabilities
        at the walls fall below 0.2: see the user guide).
    random_state : int, RandomState instance or None, default=None
        Seeds the subset and the restarts.
    batch_size : int, default=4096
        Query points predicted at once; the result does not depend on it.
    n_jobs : int, default=None
        Threads for the covariance matrices and the neighbour searches
        (None: 1; -1: every core).
    occupancy_threshold : float, default=0.5
        :meth:`is_occupied`'s threshold: a point is occupied when its
        probability is at least this; in (0, 1).

    Attributes
    ----------
    X_train_ : ndarray of shape (n_samples, n_dims)
        The occupied points, then the free points.
    y_train_ : ndarray of shape (n_samples,)
        Their labels, +1 (occupied) or -1 (free).
    kernel_ : kernel
        The kernel with the fitted hyper-parameters.
    noise_ : float
        The fitted noise variance.
    log_marginal_likelihood_value_ : float
        Log marginal likelihood of the subset at `kernel_` and `noise_`.
    plsc_ : tuple of float
        PLSC's ``(a, b)``: ``p = Phi((a mu + b) / sqrt(1 + a**2 var))``.
    n_dims_ : int
        Dimension of the inputs (1, 2 or 3).

    Notes
    -----
    **As a map** (:class:`occgp.maps.OccupancyMap`, registered as
    ``"gpom"``): :meth:`insert_scan` turns a 2D scan into hits and beams;
    the first scan is :meth:`fit`, and as GPOM has no incremental update,
    each later one fits the model again on all the evidence so far (the
    free points of earlier beams are kept as they are): a sequence of scans
    gives the model of one :meth:`fit` on all their observations.
    **Unknown space**: :meth:`occupancy` is NaN outside the box of the
    training points widened by the kernel's reach (its cutoff), where
    :meth:`predict` gives the prior. :attr:`bounds` is that box,
    :attr:`num_cells` the number of training points, and :meth:`to_octree`
    evaluates the model on 0.1 m cells by default.

    References
    ----------
    S. O'Callaghan, F. Ramos, H. Durrant-Whyte, "Contextual occupancy maps
    using Gaussian processes", ICRA 2009.

    Examples
    --------
    A wall at x = 2 seen by nine beams from the origin:

    >>> hits = np.c_[np.full(9, 2.0), 2.0 * np.tan(np.linspace(-0.6, 0.6, 9))]
    >>> m = GPOM(optimizer=False).fit(hits, np.zeros_like(hits), hits)
    >>> m.X_train_.shape                # 9 hits and 38 free points
    (47, 2)
    >>> (m.predict_proba([[2.0, 0.0], [1.0, 0.0]]) > 0.5).tolist()   # wall, beam
    [True, False]
    """

    def __init__(self, kernel=None, *, noise=0.01, noise_bounds=(1e-4, 0.25), free_step=0.5,
                 n_hit_neighbors=10, n_free_neighbors=20, optimizer=True, n_restarts=2,
                 objective="lml", max_optimize=1000, calibration="local-loo",
                 random_state=None, batch_size=4096, n_jobs=None, occupancy_threshold=0.5):
        self.kernel = kernel
        self.noise = noise
        self.noise_bounds = noise_bounds
        self.free_step = free_step
        self.n_hit_neighbors = n_hit_neighbors
        self.n_free_neighbors = n_free_neighbors
        self.optimizer = optimizer
        self.n_restarts = n_restarts
        self.objective = objective
        self.max_optimize = max_optimize
        self.calibration = calibration
        self.random_state = random_state
        self.batch_size = batch_size
        self.n_jobs = n_jobs
        self.occupancy_threshold = occupancy_threshold

    def _check_params(self):
        kernel = SquaredExponential() if self.kernel is None else check_kernel(self.kernel)
        check_real(self.noise, "noise", low=0.0)
        check_bounds(self.noise_bounds, "noise_bounds")
        check_real(self.free_step, "free_step", low=0.0)
        for name, low in [("n_hit_neighbors", 1), ("n_free_neighbors", 1), ("n_restarts", 0),
                          ("max_optimize", 2), ("batch_size", 1)]:
            check_at_least(getattr(self, name), name, low)
        if self.n_restarts > MAX_RESTARTS:
            raise ValueError(f"n_restarts must be at most {MAX_RESTARTS}, got {self.n_restarts!r}")
        check_choice(self.objective, "objective", OBJECTIVES)
        check_choice(self.calibration, "calibration", CALIBRATIONS)
        check_bool(self.optimizer, "optimizer")
        check_probability(self.occupancy_threshold, "occupancy_threshold")
        threads(self.n_jobs)
        try:
            check_random_state(self.random_state)
        except ValueError:
            raise TypeError("random_state must be None, an int or a RandomState instance, got "
                            f"{self.random_state!r}") from None
        return copy.deepcopy(kernel)

    def fit(self, hits: ArrayLike, segment_starts: ArrayLike, segment_ends: ArrayLike, *,
            beam_hits: ArrayLike | None = None):
        """Fit the map to laser returns and beams.

        Parameters
        ----------
        hits : array-like of shape (n_hits, D)
            Laser returns (occupied points); D is 1, 2 or 3.
        segment_starts, segment_ends : array-like of shape (n_segments, D)
            Each beam's sensor origin and end; they are discretised into free
            points (see `free_step`). A returning beam may end at its hit
            (occgp's convention) or stop short of it (the integral-kernel
            paper's): the free points then stop short too, and the maps
            differ slightly near the hits.
        beam_hits : array-like of int of shape (n_segments,), default=None
            Each beam's hit (an index into `hits`), or -1 for a beam without
            a return, as :meth:`GPMixture.fit <occgp.gp.GPMixture.fit>`
            takes it. Checked, otherwise unused: this map needs no link
            between a beam and its hit.

        Returns
        -------
        self : GPOM
            The fitted map.

        Raises
        ------
        ValueError
            If a parameter or an input has a bad value or shape, if the inputs
            disagree in dimension, if there are no hits or no free points,
            if the data is beyond the limits (see the class docstring), or if
            `beam_hits` has the wrong shape or an entry outside
            ``-1..n_hits-1``.
        numpy.linalg.LinAlgError
            (a ValueError) If the covariance of the optimisation subset
            cannot be factorised (the message says what to change).
        TypeError
            If a parameter or an input has a bad type (`beam_hits` not
            integers).
        """
        kernel = self._check_params()
        hits = as_numeric(hits, "hits")
        dim = hits.shape[1] if hits.ndim == 2 else -1
        if not 1 <= dim <= 3:
            raise ValueError(f"hits must have shape (n_hits, D) with D in 1..3, got {hits.shape}")
        hits = as_points(hits, "hits", dim)
        starts, ends = as_segments(segment_starts, segment_ends, "segment", dim)
        if beam_hits is not None:
            check_beam_hits(beam_hits, len(starts), len(hits))
        inv_ls = kernel.inverse_length_scales(dim)  # ARD length scales must match D
        check_coordinates({"hits": hits, "segment_starts": starts, "segment_ends": ends}, inv_ls,
                          fix="shift the data towards the origin or use a longer length scale")
        n_free = _free_point_count(starts, ends, float(self.free_step))
        if n_free > MAX_FREE_POINTS:
            raise ValueError(
                f"the segments would give {n_free:.4g} free points at free_step="
                f"{self.free_step!r}, more than the limit of {MAX_FREE_POINTS}; raise free_step "
                f"or pass fewer or shorter segments")
        n_opt = min(len(hits) + int(n_free), self.max_optimize)
        if self.optimizer:
            check_dense(n_opt, n_opt, kernel.n_theta + 4, "the hyper-parameter optimisation",
                        "lower max_optimize")
        check_dense(n_opt, n_opt, 3, "the classifier's leave-one-out predictions",
                    "lower max_optimize")
        m = min(self.n_hit_neighbors, len(hits)) + min(self.n_free_neighbors, int(n_free))
        if 32 * m * m > MAX_DENSE_BYTES:
            raise ValueError(
                f"n_hit_neighbors + n_free_neighbors (at most the data) must give local models "
                f"of at most {int(np.sqrt(MAX_DENSE_BYTES / 32))} points, got {m}")
        free = _discretise(starts, ends, float(self.free_step))
        if len(hits) == 0 or len(free) == 0:
            raise ValueError(f"GPOM needs both occupied and free points, got {len(hits)} hits "
                             f"and {len(free)} free points (from {len(starts)} segments)")
        X_train = np.concatenate([hits, free])
        y_train = np.r_[np.ones(len(hits)), -np.ones(len(free))]

        n_threads = threads(self.n_jobs)
        rng = check_random_state(self.random_state)
        sub = _subsample(y_train, self.max_optimize, rng)
        Xs, ys = X_train[sub], y_train[sub]
        quadrature = _PointsOnly()
        noise = float(self.noise)
        if self.optimizer:
            kernel, noise, _ = optimize_hyperparameters(
                kernel, noise, self.noise_bounds, Xs, Xs, ys, quadrature,
                n_restarts=self.n_restarts, rng=rng, n_threads=n_threads,
                objective=self.objective)
        L, alpha = factorise(kernel, quadrature, noise, Xs, Xs, ys, n_threads,
                             what="the optimisation subset")
        self.n_dims_ = dim
        self.X_train_, self.y_train_ = X_train, y_train
        self._hit_tree, self._free_tree = cKDTree(hits), cKDTree(free)
        self.kernel_, self.noise_ = kernel, noise
        if self.calibration == "subset-loo":
            plsc = fit_plsc(*loo_predictions(L, ys), ys)
        else:
            cal = _balanced(len(hits), len(free), self.max_optimize, rng)
            plsc = fit_plsc(*self._local_loo(cal), y_train[cal])
        if not np.isfinite(plsc).all():
            raise ValueError(f"the classifier's fit on the leave-one-out predictions failed "
                             f"(PLSC a, b = {plsc}); check the data and the noise")
        self.log_marginal_likelihood_value_ = float(
            -0.5 * ys @ alpha - np.log(np.diag(L)).sum() - 0.5 * len(ys) * np.log(2.0 * np.pi))
        self.plsc_ = plsc
        return self

    # ----------------------------------------------------------------- files
    _TRAIN_SPEC = {"X_train": (np.float64, ("n_train", "n_dims")),
                   "y_train": (np.float64, ("n_train",))}
    _FITTED = ("kernel_", "noise_", "plsc_", "log_marginal_likelihood_value_", "n_dims_")

    def save(self, path: str | os.PathLike) -> "GPOM":
        """Write the model (parameters and, once fitted, its training set) to an ``.npz``.

        The format of :meth:`GPOMIK.save <occgp.gp.GPOMIK.save>` (``"occgp.gp_model"``,
        version 1, class ``"GPOM"``, ``params``), with, for a fitted model:

        ``fitted``
            0-d str, JSON: ``kernel_``, ``noise_``, ``plsc_``,
            ``log_marginal_likelihood_value_`` (null for NaN), ``n_dims_``.
        ``X_train``, ``y_train``
            float64 (n_train, D) and (n_train,): ``X_train_`` and
            ``y_train_`` (the hits, target +1, then the free points, -1);
            the neighbour trees of :meth:`predict` are rebuilt from them.

        :meth:`load` reads it back into a model that predicts exactly as this one.

        {save_parameters}

        Returns
        -------
        self : GPOM

        {gp_save_raises}
        """
        arrays = {}
        if hasattr(self, "plsc_"):
            arrays["fitted"] = gp_fitted(fitted_scalars(self))
            arrays["X_train"], arrays["y_train"] = self.X_train_, self.y_train_
        return write_gp(self, path, arrays)

    @classmethod
    def load(cls, path: str | os.PathLike) -> "GPOM":
        """Read a model written by :meth:`save`.

        {load_parameters}

        Returns
        -------
        GPOM
            Fitted when the saved model was.

        {load_raises}
            Also if the parameters or the fitted state are not valid (NaN or
            inf, targets other than hits (+1) then free points (-1), both
            present).
        """
        source, model, arrays, fitted = read_gp(cls, path, cls._TRAIN_SPEC)
        if fitted is None:
            return model
        X, y = arrays["X_train"], arrays["y_train"]
        n_hits = int(np.count_nonzero(y == 1))
        if not 1 <= X.shape[1] <= 3:
            raise ValueError(f"{source}: corrupt fitted state of a GPOM: the training points "
                             f"must have 1 to 3 dimensions, got {X.shape[1]}")
        fitted = check_gp_fitted(fitted, cls._FITTED, X.shape[1], source, "GPOM")
        if not (0 < n_hits < len(y) and (y[:n_hits] == 1).all() and (y[n_hits:] == -1).all()):
            raise ValueError(f"{source}: corrupt fitted state of a GPOM: 'y_train' must be "
                             f"+1 (hits) then -1 (free points), both present")
        set_fitted_scalars(model, fitted)
        model.X_train_, model.y_train_ = X, y
        model._hit_tree, model._free_tree = cKDTree(X[:n_hits]), cKDTree(X[n_hits:])
        return model

    # ---------------------------------------------------------- map protocol
    def _fitted(self):
        return hasattr(self, "plsc_")

    def _insert(self, hits, starts, ends):
        """Fit again on the training points so far (free points as zero-length beams) and
        the new observations: the same model as one fit on all the observations."""
        n_hits = int(np.count_nonzero(self.y_train_ > 0))
        old_hits, old_free = self.X_train_[:n_hits], self.X_train_[n_hits:]
        self.fit(np.vstack([old_hits, hits]), np.vstack([old_free, starts]),
                 np.vstack([old_free, ends]))

    def _known_bounds(self):
        reach = np.sqrt(type(self.kernel_).cutoff2) / self.kernel_.inverse_length_scales(
            self.n_dims_)
        return self.X_train_.min(axis=0) - reach, self.X_train_.max(axis=0) + reach

    def _known(self, X):
        lo, hi = self._known_bounds()
        return np.all((X >= lo) & (X <= hi), axis=1)

    def _num_cells(self):
        return len(self.X_train_)

    def _nbytes(self):
        trees = (self._hit_tree, self._free_tree)
        return self.X_train_.nbytes + self.y_train_.nbytes + sum(
            t.data.nbytes + t.indices.nbytes for t in trees)

    def _check_X(self, X):
        check_is_fitted(self, "plsc_")
        return as_points(X, "X", self.n_dims_)

    def _predict_batch(self, Q, n_hit, n_free, workers):
        """Latent mean and variance of the local GPs at the query points `Q` (b, D)."""
        _, i_hit = self._hit_tree.query(Q, k=np.arange(1, n_hit + 1), workers=workers)
        _, i_free = self._free_tree.query(Q, k=np.arange(1, n_free + 1), workers=workers)
        return self._local_gp(Q, i_hit, i_free)

    def _local_loo(self, index):
        """Leave-one-out latent means and variances of the local GPs at the training points
        `index` (into `X_train_`): each point's local model is built without it."""
        n_hits, n_frees = self._hit_tree.n, self._free_tree.n
        k_hit = min(self.n_hit_neighbors + 1, n_hits)     # one more, then drop the point
        k_free = min(self.n_free_neighbors + 1, n_frees)
        if k_hit + k_free < 3:
            raise ValueError(f"calibration='local-loo' needs at least 3 training points, got "
                             f"{n_hits} hits and {n_frees} free points; use "
                             f"calibration='subset-loo'")
        workers = threads(self.n_jobs)
        mean, var = np.empty(len(index)), np.empty(len(index))
        m = k_hit + k_free
        batch = max(1, min(int(self.batch_size), _BATCH_BYTES // (32 * m * m)))
        for start in range(0, len(index), batch):
            part = index[start:start + batch]
            Q = self.X_train_[part]
            _, i_hit = self._hit_tree.query(Q, k=np.arange(1, k_hit + 1), workers=workers)
            _, i_free = self._free_tree.query(Q, k=np.arange(1, k_free + 1), workers=workers)
            i_hit = _without(i_hit, np.where(part < n_hits, part, -1))
            i_free = _without(i_free, np.where(part >= n_hits, part - n_hits, -1))
            mean[start:start + len(part)], var[start:start + len(part)] = self._local_gp(
                Q, i_hit, i_free)
        return mean, var

    def _local_gp(self, Q, i_hit, i_free):
        """Latent mean and variance at `Q` (b, D) of the GPs on the hits `i_hit` (b, n_hit)
        and the free points `i_free` (b, n_free) of each query."""
        variance = float(self.kernel_.variance)
        inv_ls = self.kernel_.inverse_length_scales(self.n_dims_)
        n_hit, n_free = i_hit.shape[1], i_free.shape[1]
        local = np.concatenate([self._hit_tree.data[i_hit], self._free_tree.data[i_free]],
                               axis=1) * inv_ls                             # (b, m, D)
        Q = Q * inv_ls
        s_train = np.zeros(local.shape[:2] + local.shape[1:2])             # (b, m, m)
        for d in range(self.n_dims_):
            s_train += (local[:, :, None, d] - local[:, None, :, d]) ** 2
        K = variance * self.kernel_.profile(s_train)
        m = K.shape[1]
        K[:, np.arange(m), np.arange(m)] += self.noise_ + JITTER * variance
        k_star = variance * self.kernel_.profile(((local - Q[:, None, :]) ** 2).sum(axis=2))
        y = np.r_[np.ones(n_hit), -np.ones(n_free)]
        rhs = np.stack([k_star, np.broadcast_to(y, k_star.shape)], axis=2)  # (b, m, 2)
        L = np.linalg.cholesky(K)
        v = np.linalg.solve(L, rhs)                                       # L^-1 [k_*, y]
        mean = np.einsum("bm,bm->b", v[:, :, 0], v[:, :, 1])
        var = np.maximum(variance - np.einsum("bm,bm->b", v[:, :, 0], v[:, :, 0]), 0.0)
        return mean, var

    def predict(self, X: ArrayLike, return_var: bool = False):
        """Latent mean (and variance) of the local GP at each query point.

        {predict_parameters}

        Returns
        -------
        mean : ndarray of shape (n_queries,)
            ``k_*^T (K + (noise + jitter) I)^-1 y`` over the local training set.
        var : ndarray of shape (n_queries,)
            ``k(x, x) - k_*^T (K + (noise + jitter) I)^-1 k_*``, at least 0.
            Only when `return_var` is True. A query beyond the kernel's reach
            of every training point gets the prior (mean 0, the variance).

        {predict_raises}

        Examples
        --------
        >>> m = GPOM(optimizer=False).fit([[2.0]], [[0.0]], [[2.0]])
        >>> mean, var = m.predict([[2.0], [9.0]], return_var=True)
        >>> bool(mean[0] > 0 and var[1] > var[0])
        True
        """
        X = self._check_X(X)
        return_var = check_bool(return_var, "return_var")
        n_hit = min(self.n_hit_neighbors, self._hit_tree.n)
        n_free = min(self.n_free_neighbors, self._free_tree.n)
        workers = threads(self.n_jobs)
        mean = np.zeros(len(X))
        var = np.full(len(X), float(self.kernel_.variance))   # the prior, far from the data
        reach = np.sqrt(type(self.kernel_).cutoff2) / self.kernel_.inverse_length_scales(
            self.n_dims_)
        lo, hi = self.X_train_.min(axis=0) - reach, self.X_train_.max(axis=0) + reach
        near = np.flatnonzero(np.all((X >= lo) & (X <= hi), axis=1))
        m = n_hit + n_free
        batch = max(1, min(int(self.batch_size), _BATCH_BYTES // (32 * m * m)))
        for start in range(0, len(near), batch):
            part = near[start:start + batch]
            mean[part], var[part] = self._predict_batch(X[part], n_hit, n_free, workers)
        return (mean, var) if return_var else mean
