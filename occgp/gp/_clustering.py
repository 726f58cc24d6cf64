"""Clustering of laser hits for the mixture of GP experts (Kim & Kim 2022, §3.1).

Every clusterer follows one protocol: ``fit_predict(hits, origins)`` labels the
hits ``0..k-1`` (``origins`` is the sensor position of each hit; consecutive
hits with the same origin form one scan), ``partial_fit(hits, origins)`` labels
new hits without changing the labels of earlier ones, ``labels_`` holds the
label of every hit seen so far and ``n_clusters_`` their number.

* :class:`DirichletProcessClustering`: a Dirichlet-process Gaussian mixture
  (scikit-learn's variational ``BayesianGaussianMixture``), any dimension;
* :class:`LineTracking`: the paper's Algorithm 1 on 2D scans, lines merged
  across scans;
* :class:`PlaneClustering`: planes grown over the k-NN graph of 3D hits, with
  the Dirichlet process for what is not planar.
"""

from __future__ import annotations

import numbers
import warnings
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree
from sklearn.base import BaseEstimator
from sklearn.exceptions import ConvergenceWarning
from threadpoolctl import threadpool_limits

from .. import _linetrack
from .._validation import (as_numeric, as_points, check_choice, check_int, check_n_jobs,
                           check_real, n_threads)

__all__ = ["DirichletProcessClustering", "LineTracking", "PlaneClustering", "Lines", "Planes"]

#: Largest accepted coordinate of a hit or origin (metres): float64 still resolves
#: 2e-6 m there, far below any threshold of the clusterers.
MAX_COORDINATE = 1e10
#: Percentile of the fitted hits' log densities below which a new hit opens a new
#: Dirichlet-process cluster (:meth:`DirichletProcessClustering.partial_fit`).
_DENSITY_PERCENTILE = 1.0


# ----------------------------------------------------------------- input checks
def _check_hits(hits, origins, dims, what="", dim=None):
    """Validated (hits, origins), float64 (n, D) with D in `dims` (or equal to `dim`)."""
    arr = as_numeric(hits, "hits")
    if dim is None:
        if arr.ndim != 2 or arr.shape[1] not in dims:
            want = f"(n_hits, {dims[0]})" if len(dims) == 1 else \
                f"(n_hits, D) with D in {dims[0]}..{dims[-1]}"
            raise ValueError(f"hits must have shape {want}{what}, got {arr.shape}")
        dim = arr.shape[1]
    elif arr.ndim != 2 or arr.shape[1] != dim:
        raise ValueError(f"hits must have shape (n_hits, {dim}) (the dimension of the first "
                         f"fit), got {arr.shape}")
    hits = as_points(arr, "hits", dim)
    if not len(hits):
        raise ValueError("hits must hold at least one hit, got 0 rows")
    origins = as_points(origins, "origins", dim)
    if origins.shape != hits.shape:
        raise ValueError(f"origins must have one row per hit, of shape {hits.shape}, got "
                         f"{origins.shape}")
    for name, x in (("hits", hits), ("origins", origins)):
        worst = float(np.abs(x).max())
        if worst > MAX_COORDINATE:
            raise ValueError(f"{name} must lie within {MAX_COORDINATE:g} m of the origin, got a "
                             f"coordinate of {worst:.6g}; shift the data towards the origin")
    return hits, origins


def _scan_ids(origins):
    """Scan index of each hit: a new scan starts wherever the origin changes."""
    change = np.any(origins[1:] != origins[:-1], axis=1)
    return np.concatenate([[0], np.cumsum(change)])


def _check_random_state(random_state):
    """`random_state` in the form scikit-learn takes (None, an int or a RandomState)."""
    if random_state is None or isinstance(random_state, np.random.RandomState):
        return random_state
    if isinstance(random_state, np.random.Generator):
        return int(random_state.integers(2 ** 31 - 1))
    if isinstance(random_state, (bool, np.bool_)) or not isinstance(
            random_state, (numbers.Integral, np.integer)):
        raise TypeError("random_state must be None, an int, a numpy Generator or a "
                        f"RandomState, got {type(random_state).__name__}")
    if not 0 <= int(random_state) < 2 ** 32:
        raise ValueError(f"random_state must lie in [0, 2**32 - 1], got {random_state!r}")
    return int(random_state)


def _check_at_least(value, name, low, high=None):
    """An int in [low, high] (check_int's type check, a message that says the bounds)."""
    v = check_int(value, name)
    if v < low or (high is not None and v > high):
        want = f">= {low}" if high is None else f"in [{low}, {high}]"
        raise ValueError(f"{name} must be an int {want}, got {v}")
    return v


def _check_angle(value, name):
    return check_real(value, name, low=0.0, high=90.0, low_open=False, high_open=False)


def _first_appearance(labels, k):
    """Map labels 0..k-1 to their rank of first appearance in `labels` (-1: absent)."""
    present, first = np.unique(labels, return_index=True)
    out = np.full(k, -1, dtype=np.int64)
    out[present[np.argsort(first, kind="stable")]] = np.arange(len(present))
    return out


def _components(n, i, j):
    """Connected components of the graph on `n` nodes with edges (i, j)."""
    if not len(i):
        return np.arange(n, dtype=np.int64)
    graph = coo_matrix((np.ones(len(i), dtype=np.int8), (i, j)), shape=(n, n))
    _, comp = connected_components(graph, directed=False)
    return comp.astype(np.int64)


def _best_per_row(i, j, score):
    """For each distinct `i`, the `j` of lowest `score` (ties: lowest `j`).

    Returns (rows, picks, scores), rows ascending.
    """
    if not len(i):
        return i, j, score
    order = np.lexsort((j, score, i))
    i, j, score = i[order], j[order], score[order]
    first = np.r_[True, i[1:] != i[:-1]]
    return i[first], j[first], score[first]


def _group_starts(labels):
    """(order, starts): `labels` sorted stably and where each group starts."""
    order = np.argsort(labels, kind="stable")
    sorted_labels = labels[order]
    starts = np.flatnonzero(np.r_[True, sorted_labels[1:] != sorted_labels[:-1]])
    return order, starts


class _Clustering(BaseEstimator):
    """The clustering protocol: fit, fit_predict and partial_fit over scans of hits."""

    _dims: tuple = (1, 2, 3)
    _what = ""

    def _check(self, hits, origins, dim=None):
        return _check_hits(hits, origins, self._dims, self._what, dim)

    def fit(self, hits: ArrayLike, origins: ArrayLike):
        """Cluster `hits` from scratch.

        Parameters
        ----------
        hits : array-like of shape (n_hits, D)
            Laser returns, in scan order.
        origins : array-like of shape (n_hits, D)
            The sensor position of each hit (where its beam starts); a run of
            consecutive equal rows is one scan.

        Returns
        -------
        self

        Raises
        ------
        ValueError
            If `hits` is empty, of the wrong shape or dimension for the
            method, holds NaN or inf or coordinates beyond 1e10 m, if
            `origins` does not have the shape of `hits`, or on a bad
            parameter.
        TypeError
            On non-numeric input or a parameter of the wrong type.
        """
        params = self._check_params()
        hits, origins = self._check(hits, origins)
        state, labels = self._fit(hits, origins, params)
        self.__dict__.update(state)
        self.labels_ = labels
        self.n_clusters_ = int(labels.max()) + 1
        self.n_dims_ = hits.shape[1]
        return self

    def fit_predict(self, hits: ArrayLike, origins: ArrayLike) -> NDArray[np.int64]:
        """Cluster `hits` from scratch and return their labels (int64, 0..k-1).

        The same as ``fit(hits, origins).labels_`` (a copy); raises as :meth:`fit`.
        """
        return self.fit(hits, origins).labels_.copy()

    def partial_fit(self, hits: ArrayLike, origins: ArrayLike) -> NDArray[np.int64]:
        """Label new hits; earlier hits keep their labels.

        New hits join existing clusters or open new ones, labelled from the
        previous :attr:`n_clusters_` on; existing clusters are never merged
        with one another by an update. The first call acts as :meth:`fit`.
        A scan does not continue across calls.

        Parameters
        ----------
        hits, origins : array-like of shape (n_new, D)
            As in :meth:`fit`; D must be that of the first call.

        Returns
        -------
        labels : ndarray of shape (n_new,), dtype int64
            The labels of the new hits; :attr:`labels_` grows by them.

        Raises
        ------
        ValueError, TypeError
            As :meth:`fit`, and if D differs from the first call's. A rejected
            update leaves the clusterer unchanged.
        """
        if not hasattr(self, "labels_"):
            return self.fit_predict(hits, origins)
        params = self._check_params()
        hits, origins = self._check(hits, origins, dim=self.n_dims_)
        state, new = self._partial(hits, origins, params)
        self.__dict__.update(state)
        self.labels_ = np.concatenate([self.labels_, new])
        self.n_clusters_ = max(self.n_clusters_, int(new.max()) + 1)
        return new.copy()


# ============================================================ Dirichlet process
class _Mixture(NamedTuple):
    model: object        # a fitted BayesianGaussianMixture, or None for a single hit
    shift: NDArray[np.float64]
    scale: float
    threshold: float     # log density (in the scaled frame) a new hit needs to join
    label_of: NDArray[np.int64]  # cluster label of each component (-1: no hit)


class DirichletProcessClustering(_Clustering):
    """Dirichlet-process Gaussian mixture of hits (Kim & Kim's DP-clustering).

    The hits are fitted by scikit-learn's variational
    :class:`~sklearn.mixture.BayesianGaussianMixture` with a Dirichlet-process
    (stick-breaking) prior on the weights, truncated at
    ``min(max_clusters, n_hits)`` components; each hit takes the component of
    highest responsibility and the components that received a hit become the
    clusters (labelled in order of their first hit), so the number of clusters
    comes out of the data. Hits are shifted and scaled to unit spread first
    (one scale for all axes), which makes the result independent of units.
    `origins` is checked and otherwise unused.

    :meth:`partial_fit` gives a new hit to an existing component when its log
    density under a fitted mixture is at least the 1st percentile of the log
    densities of the hits that mixture was fitted on (the mixture scoring it
    highest wins); the other new hits get a new Dirichlet-process fit among
    themselves and new labels. A fit on a single hit is one cluster that no
    later hit joins. Existing clusters never change or merge.

    Each fit runs on one thread (``threadpoolctl.threadpool_limits(1)`` while
    it runs): the problems are small (D <= 3), and the k-means
    initialisation's OpenMP threads only cost time on a busy machine.

    Parameters
    ----------
    concentration : float, default=1.0
        The concentration α of the Dirichlet process (scikit-learn's
        ``weight_concentration_prior``); larger values give more clusters.
    max_clusters : int, default=50
        Truncation of the process: at most this many clusters per fit (at
        most 1000: the fit holds ``n_hits x max_clusters`` responsibilities).
    covariance_type : {"full", "tied", "diag", "spherical"}, default="full"
    max_iter : int, default=500
        Most variational iterations per fit (at most 100,000). A fit that stops before
        converging is kept (``converged_`` is False); scikit-learn's
        ConvergenceWarning is not raised.
    n_init : int, default=1
        Initialisations per fit (at most 100); the best lower bound wins.
    random_state : int, numpy Generator, RandomState or None, default=None
        Seeds the k-means initialisation; an int makes the result
        reproducible.
    covariance_prior : float or None, default=None
        Variance (m², the same on every axis) of the Wishart prior on the
        components' covariances; None: scikit-learn's default, the hits'
        own covariance, which favours few broad clusters. Smaller values
        give more, smaller clusters.

    Attributes
    ----------
    labels_ : ndarray of shape (n_hits,), dtype int64
        Cluster of every hit seen so far.
    n_clusters_ : int
    n_dims_ : int
    converged_ : bool
        Whether every variational fit so far converged.
    mixtures_ : list of BayesianGaussianMixture
        One per fit (:meth:`fit`, then each :meth:`partial_fit` with hits
        that joined no cluster), fitted on scaled hits.

    Notes
    -----
    On ``room_2d().scan()`` (351 hits) the defaults give 3–4 clusters
    depending on the seed (Kim & Kim report 8 on their room): the default
    prior makes components as broad as the data. ``covariance_prior=1.0``
    gives 11–12. A fit of 10,000 2D hits (``room_2d().scan(n_poses=750)``)
    takes about 2 s on 2 cores (18 clusters).

    References
    ----------
    S. Kim, J. Kim, "Efficient clustering for continuous occupancy mapping
    using a mixture of Gaussian processes", Sensors 22(18), 6832 (2022),
    §3.1.1; D. Blei, M. Jordan, "Variational inference for Dirichlet process
    mixtures", Bayesian Analysis 1(1), 2006.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> hits = np.vstack([rng.normal(c, 0.2, (50, 2)) for c in [(0, 0), (5, 0), (0, 5)]])
    >>> dp = DirichletProcessClustering(random_state=0).fit(hits, np.zeros_like(hits))
    >>> dp.n_clusters_
    3
    """

    def __init__(self, concentration=1.0, max_clusters=50, covariance_type="full",
                 max_iter=500, n_init=1, random_state=None, covariance_prior=None):
        self.concentration = concentration
        self.covariance_prior = covariance_prior
        self.max_clusters = max_clusters
        self.covariance_type = covariance_type
        self.max_iter = max_iter
        self.n_init = n_init
        self.random_state = random_state

    def _check_params(self):
        return dict(
            concentration=check_real(self.concentration, "concentration", low=0.0),
            max_clusters=check_int(self.max_clusters, "max_clusters", low=1, high=1000),
            covariance_type=check_choice(self.covariance_type, "covariance_type",
                                         ("full", "tied", "diag", "spherical")),
            max_iter=check_int(self.max_iter, "max_iter", low=1, high=100_000),
            n_init=check_int(self.n_init, "n_init", low=1, high=100),
            random_state=_check_random_state(self.random_state),
            covariance_prior=None if self.covariance_prior is None else
            check_real(self.covariance_prior, "covariance_prior", low=0.0))

    @staticmethod
    def _mixture(hits, params, first_label):
        """Fit one mixture on `hits`; returns (_Mixture, labels, converged)."""
        from sklearn.mixture import BayesianGaussianMixture

        shift = hits.mean(axis=0)
        scale = float(hits.std(axis=0).max())
        scale = scale if scale > 0 else 1.0
        X = (hits - shift) / scale
        if len(X) < 2:
            return (_Mixture(None, shift, scale, np.inf, np.zeros(0, dtype=np.int64)),
                    np.full(len(X), first_label, dtype=np.int64), True)
        prior = params["covariance_prior"]
        if prior is not None:
            dim, kind = X.shape[1], params["covariance_type"]
            prior = prior / scale ** 2
            prior = prior * np.eye(dim) if kind in ("full", "tied") else \
                np.full(dim, prior) if kind == "diag" else prior
        model = BayesianGaussianMixture(
            n_components=min(params["max_clusters"], len(X)),
            covariance_prior=prior,
            covariance_type=params["covariance_type"],
            weight_concentration_prior_type="dirichlet_process",
            weight_concentration_prior=params["concentration"],
            max_iter=params["max_iter"], n_init=params["n_init"],
            random_state=params["random_state"])
        # one thread: the matrices are D x D (D <= 3), and scikit-learn's k-means
        # initialisation on OpenMP threads slows down by orders of magnitude on a
        # busy machine
        with warnings.catch_warnings(), threadpool_limits(limits=1):
            warnings.simplefilter("ignore", ConvergenceWarning)
            model.fit(X)
        comp = model.predict(X)
        label_of = _first_appearance(comp, model.n_components)
        label_of[label_of >= 0] += first_label
        threshold = float(np.percentile(model.score_samples(X), _DENSITY_PERCENTILE))
        return (_Mixture(model, shift, scale, threshold, label_of), label_of[comp],
                bool(model.converged_))

    def _fit(self, hits, origins, params):
        mixture, labels, converged = self._mixture(hits, params, 0)
        return dict(_mixtures=[mixture], converged_=converged,
                    mixtures_=[mixture.model] if mixture.model is not None else []), labels

    def _partial(self, hits, origins, params):
        labels = np.full(len(hits), -1, dtype=np.int64)
        best = np.full(len(hits), -np.inf)
        for mix in self._mixtures:
            if mix.model is None:
                continue
            X = (hits - mix.shift) / mix.scale
            score = mix.model.score_samples(X)
            cand = mix.label_of[mix.model.predict(X)]
            take = (score >= mix.threshold) & (cand >= 0) & (score > best)
            labels[take], best[take] = cand[take], score[take]
        mixtures, models, converged = list(self._mixtures), list(self.mixtures_), \
            self.converged_
        rest = labels < 0
        if rest.any():
            mixture, labels[rest], ok = self._mixture(hits[rest], params, self.n_clusters_)
            mixtures.append(mixture)
            if mixture.model is not None:
                models.append(mixture.model)
            converged = converged and ok
        return dict(_mixtures=mixtures, mixtures_=models, converged_=converged), labels


# ================================================================ line tracking
class Lines(NamedTuple):
    """The fitted line of each cluster of :class:`LineTracking` (arrays over clusters)."""

    #: Mean of the cluster's hits, shape (n_clusters, 2).
    centroid: NDArray[np.float64]
    #: Unit direction of the total-least-squares line, shape (n_clusters, 2).
    direction: NDArray[np.float64]
    #: ``(t_min, t_max)``: the hits' extent along `direction` from `centroid`,
    #: shape (n_clusters, 2).
    extent: NDArray[np.float64]
    #: Hits in the cluster, shape (n_clusters,).
    n_points: NDArray[np.int64]


class _LineSet(NamedTuple):
    """Moments and fitted segments of groups of 2D points."""

    n: NDArray[np.float64]
    mean: NDArray[np.float64]      # (k, 2)
    scatter: NDArray[np.float64]   # (k, 3): sums of centred xx, xy, yy
    direction: NDArray[np.float64]
    tmin: NDArray[np.float64]
    tmax: NDArray[np.float64]

    @property
    def starts(self):
        return self.mean + self.tmin[:, None] * self.direction

    @property
    def ends(self):
        return self.mean + self.tmax[:, None] * self.direction

    def take(self, idx):
        return _LineSet(*(a[idx] for a in self))


def _direction(scatter):
    """Principal unit direction of each (xx, xy, yy) scatter (x-axis when it vanishes)."""
    theta = 0.5 * np.arctan2(2.0 * scatter[:, 1], scatter[:, 0] - scatter[:, 2])
    return np.column_stack([np.cos(theta), np.sin(theta)])


def _line_set(points, groups, k):
    """Exact moments, TLS directions and extents of the `k` groups of `points`."""
    n = np.bincount(groups, minlength=k).astype(np.float64)
    mean = np.column_stack([np.bincount(groups, points[:, d], k) for d in range(2)]) / n[:, None]
    q = points - mean[groups]
    scatter = np.column_stack([np.bincount(groups, q[:, 0] * q[:, 0], k),
                               np.bincount(groups, q[:, 0] * q[:, 1], k),
                               np.bincount(groups, q[:, 1] * q[:, 1], k)])
    direction = _direction(scatter)
    t = np.einsum("ij,ij->i", q, direction[groups])
    order, starts = _group_starts(groups)
    return _LineSet(n, mean, scatter, direction, np.minimum.reduceat(t[order], starts),
                    np.maximum.reduceat(t[order], starts))


def _segment_samples(starts, ends, spacing):
    """Points at most `spacing` apart along each segment, and the segment of each."""
    length = np.linalg.norm(ends - starts, axis=1)
    m = np.ceil(length / spacing).astype(np.int64) + 1
    owner = np.repeat(np.arange(len(starts)), m)
    first = np.cumsum(m) - m
    u = (np.arange(len(owner)) - first[owner]) / np.maximum(m[owner] - 1, 1)
    return starts[owner] + u[:, None] * (ends - starts)[owner], owner


def _near_pairs(a_starts, a_ends, b_starts=None, b_ends=None, *, reach):
    """Pairs (i, j) of segments of A (and B, or A again with i < j) possibly within `reach`.

    Every pair whose segment distance is at most `reach` is returned (and some
    more): points sampled `reach` apart along each segment come within
    ``2 * reach`` of each other.
    """
    pa, oa = _segment_samples(a_starts, a_ends, reach)
    tree_a = cKDTree(pa)
    if b_starts is None:
        pairs = tree_a.query_pairs(2.0 * reach, output_type="ndarray")
        i, j = oa[pairs[:, 0]], oa[pairs[:, 1]]
        i, j = np.minimum(i, j), np.maximum(i, j)
        keep = i != j
        n = len(a_starts)
    else:
        pb, ob = _segment_samples(b_starts, b_ends, reach)
        sdm = tree_a.sparse_distance_matrix(cKDTree(pb), 2.0 * reach, output_type="ndarray")
        i, j = oa[sdm["i"]], ob[sdm["j"]]
        keep = np.ones(len(i), dtype=bool)
        n = len(b_starts)
    key = np.unique(i[keep] * n + j[keep])
    return key // n, key % n


class LineTracking(_Clustering):
    """Line tracking of planar laser scans (Kim & Kim's LT-clustering, Algorithm 1).

    1. **Tracking.** Within each scan (a run of hits with the same origin),
       hits are ordered by bearing about the origin, starting after the
       widest angular gap (so a scan across the -x axis is not split; ties
       keep the input order). A line starts with the first hit; the next hit
       joins it when it lies within `distance_threshold` of the line's total
       least-squares fit (the principal axis of its hits' scatter, kept as
       running sums; with one point so far, any hit) and within
       `gap_threshold` of the previous hit; otherwise that hit starts a new
       line. A lone hit is a line of one point. The loop is compiled
       (``occgp._linetrack``), O(1) per hit.
    2. **Merging.** Two lines of at least `min_points` hits (of any scans)
       are one cluster when their directions differ by at most
       `merge_angle`, both endpoints of the shorter one lie within
       `merge_distance` of the longer one's line, and their extents along
       the longer one's direction overlap or are at most `gap_threshold`
       apart. Merging is transitive; each cluster's line is refit on all its
       hits and the clusters are tested again until none merge (walls seen
       from many poses become one cluster each).
    3. **Short lines** (fewer than `min_points` hits, whose direction is
       unreliable) join the cluster whose line they match best by the test
       above without the angle (smallest distance of their endpoints to its
       line), but never bridge two clusters; those matching none are
       clusters of their own, merged with each other when within
       `gap_threshold`. Clusters of few hits are left to
       :func:`merge_small_clusters`.

    Labels are numbered in order of each cluster's first hit. In
    :meth:`partial_fit`, the new scans are tracked, each new line of at least
    `min_points` hits joins the existing cluster it matches best (which is
    refit; the extent of its earlier hits is carried by its old segment's
    endpoints), the others merge among themselves as in :meth:`fit` into new
    clusters, then the new short lines are placed as in step 3. Existing
    clusters never merge with one another.

    Parameters
    ----------
    distance_threshold : float, default=0.1
        Largest distance (m) of a hit from the line it joins.
    gap_threshold : float, default=2.0
        Largest distance (m) between consecutive hits of a line, and between
        the extents of lines that merge. The default suits a 17-beam,
        180-degree, 8 m laser (hits up to 1.6 m apart on a wall facing it).
    merge_angle : float, default=10.0
        Largest angle (degrees, in [0, 90]) between lines that merge.
    merge_distance : float, default=0.15
        Largest distance (m) of the shorter line's endpoints from the longer
        one's line (below the 0.2 m walls of :func:`occgp.datasets.room_2d`,
        whose two faces stay apart).
    min_points : int, default=3
        Lines with fewer hits (at least 2) do not define a direction for
        merging (step 3).

    Attributes
    ----------
    labels_ : ndarray of shape (n_hits,), dtype int64
    n_clusters_ : int
    n_dims_ : int
        Always 2.
    n_lines_ : int
        Lines tracked in all scans so far (before merging).
    lines_ : Lines
        The fitted line of each cluster: ``centroid``, ``direction``,
        ``extent`` (``t_min, t_max`` along the direction) and ``n_points``.

    Notes
    -----
    On ``room_2d().scan()`` (351 hits, 26 scans) the defaults give 26
    clusters (23 once :func:`merge_small_clusters` has folded those that
    cannot train a classifier); Kim & Kim report 18 on their room. A fit of
    10,000 hits (``room_2d().scan(n_poses=750)``, 3,313 lines, 38 clusters)
    takes about 0.2 s on 2 cores, of which the tracking is 1.4 ms (the
    compiled loop 0.13 ms, against 15–20 ms in pure Python) and the rest the
    vectorised merging; :meth:`partial_fit` scan by scan costs about 1 ms a
    scan. Updates cannot merge clusters, so a map built scan by scan has
    more of them than one fit at once (119 against 38 there; 53 against 26
    on the 26-pose scan).

    References
    ----------
    A. Siadat, A. Kaske, S. Klausmann, M. Dufaut, R. Husson, "An optimized
    segmentation method for a 2D laser-scanner applied to mobile robot
    navigation", IFAC ICICA 1997; S. Kim, J. Kim, "Efficient clustering for
    continuous occupancy mapping using a mixture of Gaussian processes",
    Sensors 22(18), 6832 (2022), §3.1.2, Algorithm 1.

    Examples
    --------
    Two walls at right angles seen from one pose (the corner hit goes with
    the wall tracked first, by bearing):

    >>> import numpy as np
    >>> t = np.linspace(0.0, 2.0, 9)
    >>> hits = np.vstack([np.column_stack([t, np.full(9, 2.0)]),
    ...                   np.column_stack([np.full(8, 2.0), t[:-1][::-1]])])
    >>> lt = LineTracking().fit(hits, np.zeros_like(hits))
    >>> lt.n_clusters_, np.bincount(lt.labels_).tolist()
    (2, [8, 9])
    """

    _dims = (2,)
    _what = " for line tracking"

    def __init__(self, distance_threshold=0.1, gap_threshold=2.0, merge_angle=10.0,
                 merge_distance=0.15, min_points=3):
        self.distance_threshold = distance_threshold
        self.gap_threshold = gap_threshold
        self.merge_angle = merge_angle
        self.merge_distance = merge_distance
        self.min_points = min_points

    def _check_params(self):
        return dict(
            distance=check_real(self.distance_threshold, "distance_threshold", low=0.0),
            gap=check_real(self.gap_threshold, "gap_threshold", low=0.0),
            cos_angle=np.cos(np.radians(_check_angle(self.merge_angle, "merge_angle"))),
            merge=check_real(self.merge_distance, "merge_distance", low=0.0),
            min_points=_check_at_least(self.min_points, "min_points", 2))

    # ------------------------------------------------------------- tracking
    @staticmethod
    def _track(hits, origins, params):
        """Line of every hit (in input order) and the number of lines."""
        scan = _scan_ids(origins)
        d = hits - origins
        angle = np.arctan2(d[:, 1], d[:, 0])
        order = np.lexsort((np.arange(len(hits)), angle, scan))
        a, s = angle[order], scan[order]
        first = np.flatnonzero(np.r_[True, s[1:] != s[:-1]])
        size = np.diff(np.r_[first, len(s)])
        gap = np.empty_like(a)
        gap[1:] = a[1:] - a[:-1]
        last = first + size - 1
        gap[first] = a[first] + 2.0 * np.pi - a[last]
        # per scan, start after the widest gap: rotate the scan's sorted positions
        pos = np.arange(len(a)) - first[s]
        widest = np.maximum.reduceat(gap, first)
        is_widest = gap == widest[s]
        start = np.minimum.reduceat(np.where(is_widest, pos, len(a)), first)
        rank = (pos - start[s]) % size[s]
        order = order[np.lexsort((rank, s))]
        ptr = np.r_[first, len(s)].astype(np.intp)
        line_sorted = np.empty(len(hits), dtype=np.intp)
        n_lines = _linetrack.track_lines(np.ascontiguousarray(hits[order]), ptr,
                                         params["distance"], params["gap"], line_sorted)
        line = np.empty(len(hits), dtype=np.int64)
        line[order] = line_sorted
        return line, int(n_lines)

    # ---------------------------------------------------------------- tests
    @staticmethod
    def _match(one, i, two, j, params, angle=True):
        """Whether lines ``one[i]`` and ``two[j]`` merge, and a score (lower is better)."""
        len_i, len_j = one.tmax[i] - one.tmin[i], two.tmax[j] - two.tmin[j]
        i_long = len_i >= len_j
        c_l = np.where(i_long[:, None], one.mean[i], two.mean[j])
        d_l = np.where(i_long[:, None], one.direction[i], two.direction[j])
        lo_l = np.where(i_long, one.tmin[i], two.tmin[j])
        hi_l = np.where(i_long, one.tmax[i], two.tmax[j])
        s0 = np.where(i_long[:, None], two.starts[j], one.starts[i])
        s1 = np.where(i_long[:, None], two.ends[j], one.ends[i])
        normal = np.column_stack([-d_l[:, 1], d_l[:, 0]])
        perp = np.maximum(np.abs(np.einsum("ij,ij->i", s0 - c_l, normal)),
                          np.abs(np.einsum("ij,ij->i", s1 - c_l, normal)))
        t0 = np.einsum("ij,ij->i", s0 - c_l, d_l)
        t1 = np.einsum("ij,ij->i", s1 - c_l, d_l)
        gap = np.maximum(np.minimum(t0, t1) - hi_l, lo_l - np.maximum(t0, t1))
        ok = (perp <= params["merge"]) & (gap <= params["gap"])
        if angle:
            cos = np.abs(np.einsum("ij,ij->i", one.direction[i], two.direction[j]))
            ok &= cos >= params["cos_angle"]
        return ok, perp

    def _reach(self, params):
        return params["gap"] + params["merge"]

    def _agglomerate(self, points, groups, k, params):
        """Merge the `k` groups of `points` (lines) transitively until no pair merges.

        Returns (cluster of each group, number of clusters).
        """
        cluster = np.arange(k, dtype=np.int64)
        n_clusters = k
        while n_clusters > 1:
            lines = _line_set(points, cluster[groups], n_clusters)
            i, j = _near_pairs(lines.starts, lines.ends, reach=self._reach(params))
            ok, _ = self._match(lines, i, lines, j, params)
            comp = _components(n_clusters, i[ok], j[ok])
            n_new = int(comp.max()) + 1
            if n_new == n_clusters:
                break
            cluster, n_clusters = comp[cluster], n_new
        return cluster, n_clusters

    def _short_clusters(self, points, groups, k, params):
        """Clusters of short lines: transitively merged when within `gap_threshold`."""
        lines = _line_set(points, groups, k)
        reach = params["gap"]
        i, j = _near_pairs(lines.starts, lines.ends, reach=reach)
        close = _segment_distance(lines.starts[i], lines.ends[i], lines.starts[j],
                                  lines.ends[j]) <= reach
        comp = _components(k, i[close], j[close])
        return comp, int(comp.max()) + 1 if k else 0

    def _attach(self, short, clusters, params):
        """Best cluster of each short line (-1: none matches)."""
        best = np.full(len(short.n), -1, dtype=np.int64)
        if not len(short.n) or not len(clusters.n):
            return best
        i, j = _near_pairs(short.starts, short.ends, clusters.starts, clusters.ends,
                           reach=self._reach(params))
        ok, score = self._match(short, i, clusters, j, params, angle=False)
        rows, picks, _ = _best_per_row(i[ok], j[ok], score[ok])
        best[rows] = picks
        return best

    # ------------------------------------------------------------- clusters
    def _cluster_new(self, hits, line, n_lines, params, existing=None):
        """Cluster of each new hit: existing clusters (0..m-1), then new ones (m..).

        `existing` is the _LineSet of the existing clusters (None in fit).
        Returns (cluster of each hit, number of new clusters, the short mask of lines).
        """
        m = 0 if existing is None else len(existing.n)
        lines = _line_set(hits, line, n_lines)
        short = (lines.n < params["min_points"]) | (lines.scatter[:, 0] + lines.scatter[:, 2] <= 0)
        long_idx, short_idx = np.flatnonzero(~short), np.flatnonzero(short)
        cluster_of_line = np.full(n_lines, -1, dtype=np.int64)
        # long lines: join an existing cluster, or merge among themselves
        if m and len(long_idx):
            cluster_of_line[long_idx] = self._attach_long(lines.take(long_idx), existing, params)
        free = long_idx[cluster_of_line[long_idx] < 0]
        n_new = 0
        if len(free):
            sel = np.isin(line, free)
            remap = np.full(n_lines, -1, dtype=np.int64)
            remap[free] = np.arange(len(free))
            comp, n_new = self._agglomerate(hits[sel], remap[line[sel]], len(free), params)
            cluster_of_line[free] = m + comp
        # short lines: join the best cluster (existing or new), or cluster among themselves
        if len(short_idx):
            long_hits = cluster_of_line[line] >= m          # hits of the new long clusters
            sets = []
            if m:
                sets.append(existing)
            if n_new:
                sets.append(_line_set(hits[long_hits], cluster_of_line[line[long_hits]] - m,
                                      n_new))
            clusters = _LineSet(*(np.concatenate(parts) for parts in zip(*sets))) \
                if sets else None
            best = self._attach(lines.take(short_idx), clusters, params) \
                if clusters is not None else np.full(len(short_idx), -1)
            # an attached short line keeps its cluster index (existing first, then new)
            cluster_of_line[short_idx] = best
            lone = short_idx[best < 0]
            if len(lone):
                sel = np.isin(line, lone)
                remap = np.full(n_lines, -1, dtype=np.int64)
                remap[lone] = np.arange(len(lone))
                comp, n_short = self._short_clusters(hits[sel], remap[line[sel]], len(lone),
                                                     params)
                cluster_of_line[lone] = m + n_new + comp
                n_new += n_short
        return cluster_of_line[line], n_new

    def _attach_long(self, lines, existing, params):
        best = np.full(len(lines.n), -1, dtype=np.int64)
        i, j = _near_pairs(lines.starts, lines.ends, existing.starts, existing.ends,
                           reach=self._reach(params))
        ok, score = self._match(lines, i, existing, j, params)
        rows, picks, _ = _best_per_row(i[ok], j[ok], score[ok])
        best[rows] = picks
        return best

    def _fit(self, hits, origins, params):
        line, n_lines = self._track(hits, origins, params)
        cluster, k = self._cluster_new(hits, line, n_lines, params)
        rank = _first_appearance(cluster, k)
        labels = rank[cluster]
        lines = _line_set(hits, labels, k)
        return dict(_lines=lines, lines_=_public_lines(lines), n_lines_=n_lines), labels

    def _partial(self, hits, origins, params):
        old = self._lines
        m = len(old.n)
        line, n_lines = self._track(hits, origins, params)
        cluster, n_new = self._cluster_new(hits, line, n_lines, params, existing=old)
        # new clusters numbered m.. in order of their first hit
        rank = np.arange(m + n_new, dtype=np.int64)
        is_new = cluster >= m
        if n_new:
            rank[m:] = m + _first_appearance(cluster[is_new] - m, n_new)
        labels = rank[cluster]
        # refit: existing clusters that received hits, and the new clusters
        joined = labels[~is_new]
        lines = old
        if len(joined):
            lines = _combine(old, hits[~is_new], joined)
        if n_new:
            fresh = _line_set(hits[is_new], labels[is_new] - m, n_new)
            lines = _LineSet(*(np.concatenate([a, b]) for a, b in zip(lines, fresh)))
        return dict(_lines=lines, lines_=_public_lines(lines),
                    n_lines_=self.n_lines_ + n_lines), labels


def _public_lines(lines):
    return Lines(lines.mean.copy(), lines.direction.copy(),
                 np.column_stack([lines.tmin, lines.tmax]), lines.n.astype(np.int64))


def _combine(old, points, labels):
    """`old` with `points` added to the groups `labels` (Chan's pairwise moments).

    The extent of the old points along a refit direction is that of the old
    segment's endpoints.
    """
    k = len(old.n)
    n_b = np.bincount(labels, minlength=k).astype(np.float64)
    touched = n_b > 0
    safe = np.where(touched, n_b, 1.0)
    mean_b = np.column_stack([np.bincount(labels, points[:, d], k) for d in range(2)]) \
        / safe[:, None]
    q = points - mean_b[labels]
    scatter_b = np.column_stack([np.bincount(labels, q[:, 0] * q[:, 0], k),
                                 np.bincount(labels, q[:, 0] * q[:, 1], k),
                                 np.bincount(labels, q[:, 1] * q[:, 1], k)])
    n = old.n + n_b
    delta = mean_b - old.mean
    w = np.where(touched, old.n * n_b / n, 0.0)
    mean = np.where(touched[:, None], old.mean + delta * (n_b / n)[:, None], old.mean)
    scatter = old.scatter + scatter_b + w[:, None] * np.column_stack(
        [delta[:, 0] ** 2, delta[:, 0] * delta[:, 1], delta[:, 1] ** 2])
    direction = np.where(touched[:, None], _direction(scatter), old.direction)
    # extents: the old endpoints and the new points, projected on the new line
    t_old = np.stack([np.einsum("ij,ij->i", e - mean, direction)
                      for e in (old.starts, old.ends)])
    t_new = np.einsum("ij,ij->i", points - mean[labels], direction[labels])
    tmin, tmax = t_old.min(axis=0), t_old.max(axis=0)
    np.minimum.at(tmin, labels, t_new)
    np.maximum.at(tmax, labels, t_new)
    return _LineSet(n, mean, scatter, direction, tmin, tmax)


def _segment_distance(p0, p1, q0, q1):
    """Distance between segments p0-p1 and q0-q1, row by row (points when ends coincide).

    The closest-points algorithm of Ericson, *Real-Time Collision Detection*
    (2005), §5.1.9, vectorised.
    """
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a = np.einsum("ij,ij->i", d1, d1)
    e = np.einsum("ij,ij->i", d2, d2)
    f = np.einsum("ij,ij->i", d2, r)
    c = np.einsum("ij,ij->i", d1, r)
    b = np.einsum("ij,ij->i", d1, d2)
    denom = a * e - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(denom > 1e-300, np.clip((b * f - c * e) / denom, 0.0, 1.0), 0.0)
        s = np.where(a > 0, s, 0.0)
        t = np.where(e > 0, (b * s + f) / e, 0.0)
        s_lo = np.where(a > 0, np.clip(-c / a, 0.0, 1.0), 0.0)
        s_hi = np.where(a > 0, np.clip((b - c) / a, 0.0, 1.0), 0.0)
    s = np.where(e > 0, np.where(t < 0, s_lo, np.where(t > 1, s_hi, s)), s_lo)
    t = np.clip(t, 0.0, 1.0)
    return np.linalg.norm(p0 + s[:, None] * d1 - q0 - t[:, None] * d2, axis=1)


# ============================================================== plane clustering
class Planes(NamedTuple):
    """The fitted plane of each cluster of :class:`PlaneClustering` (arrays over clusters)."""

    #: Mean of the cluster's hits, shape (n_clusters, 3).
    centroid: NDArray[np.float64]
    #: Unit normal of the plane, shape (n_clusters, 3) (for a cluster that is
    #: not a plane, the direction of least spread of its hits).
    normal: NDArray[np.float64]
    #: Corners of the hits' axis-aligned bounding box, shape (n_clusters, 3) each.
    lower: NDArray[np.float64]
    upper: NDArray[np.float64]
    #: Hits in the cluster, shape (n_clusters,).
    n_points: NDArray[np.int64]
    #: Whether the cluster is a grown plane (False: a Dirichlet-process cluster
    #: of the hits left over), shape (n_clusters,).
    is_plane: NDArray[np.bool_]


#: Most neighbours per hit (PlaneClustering's n_neighbors), and hits whose
#: neighbourhoods are analysed at once (bounds the memory of the PCA).
_MAX_NEIGHBORS = 100
_PCA_BLOCK = 20_000
#: Kinds of a hit's neighbourhood (its local principal spreads against distance_threshold).
_POINT, _LINE, _PLANE = 0, 1, 2


def _local_shape(points, neighbours, distance, tan):
    """Normal, main direction, kind and curvature of each point's neighbourhood (PCA)."""
    C = np.empty((len(neighbours), 3, 3))
    for lo in range(0, len(neighbours), _PCA_BLOCK):
        P = points[neighbours[lo:lo + _PCA_BLOCK]]
        Q = P - P.mean(axis=1, keepdims=True)
        C[lo:lo + _PCA_BLOCK] = np.einsum("nki,nkj->nij", Q, Q) / neighbours.shape[1]
    w, v = np.linalg.eigh(C)
    w = np.maximum(w, 0.0)
    spread = np.sqrt(w)
    thick = (spread[:, 0] > distance) | (spread[:, 0] > tan * spread[:, 1])
    kind = np.where(thick, _POINT,
                    np.where(spread[:, 1] >= distance, _PLANE,
                             np.where(spread[:, 2] >= distance, _LINE, _POINT)))
    total = w.sum(axis=1)
    curvature = np.where(total > 0, w[:, 0] / np.where(total > 0, total, 1.0), 0.0)
    return v[:, :, 0], v[:, :, 2], kind, curvature


def _plane_moments(points, groups, k):
    """Counts, means, scatters (k, 3, 3), bounding boxes of the `k` groups of `points`."""
    n = np.bincount(groups, minlength=k).astype(np.float64)
    mean = np.column_stack([np.bincount(groups, points[:, d], k) for d in range(3)]) / n[:, None]
    q = points - mean[groups]
    scatter = np.stack([np.stack([np.bincount(groups, q[:, a] * q[:, b], k) for b in range(3)],
                                 axis=1) for a in range(3)], axis=1)
    order, starts = _group_starts(groups)
    lower = np.minimum.reduceat(points[order], starts, axis=0)
    upper = np.maximum.reduceat(points[order], starts, axis=0)
    return n, mean, scatter, lower, upper


def _normals(scatter):
    """Direction of least spread of each (3, 3) scatter."""
    return np.linalg.eigh(scatter)[1][:, :, 0]


class PlaneClustering(_Clustering):
    """Planes grown over the k-nearest-neighbour graph of 3D hits, with a DP fallback.

    The 3D counterpart of line tracking (Kim & Kim's future work):

    1. **Local shape.** Each hit's `n_neighbors` nearest hits (and itself;
       :class:`scipy.spatial.cKDTree`) are analysed by PCA, with principal
       spreads (standard deviations) ``s0 <= s1 <= s2``. The neighbourhood
       is *planar*, and gives the hit a normal, when it is thin
       (``s0 <= distance_threshold`` and ``s0 <= tan(angle_threshold) * s1``,
       so that the normal is known to about the angle threshold) and wide
       (``s1 >= distance_threshold``); *linear*, giving a direction, when
       only ``s2`` reaches `distance_threshold` (one row of a sparse LiDAR);
       otherwise (a corner, an edge, a lone hit) *point-like*. The curvature
       is ``s0^2 / (s0^2 + s1^2 + s2^2)``.
    2. **Region growing.** Planar hits are seeds in order of increasing
       curvature. A region starts with the seed's plane and grows
       breadth-first over the k-NN graph: a neighbour joins when it lies
       within `distance_threshold` of the region's plane and its shape
       agrees with it within `angle_threshold` (a planar hit's normal with
       the plane's normal; a linear hit's direction with the plane). The
       plane is refit on the region's hits after each breadth-first level,
       once they spread by at least `distance_threshold` in two directions.
    3. **Merging.** Regions of at least `min_region_size` hits are planes;
       two planes whose normals agree within `angle_threshold`, each
       centroid within `distance_threshold` of the other's plane, and whose
       bounding boxes overlap once grown by a margin (the median distance of
       a hit to its `n_neighbors`-th neighbour) are merged (transitively)
       and refit: the same wall seen from several poses is one plane.
    4. **Fallback.** The hits of smaller regions and those in no region are
       clustered by :class:`DirichletProcessClustering` (`concentration`,
       `random_state`).

    Labels are numbered in order of each cluster's first hit. In
    :meth:`partial_fit` the new hits' shapes are computed with neighbours
    among all hits so far, and the existing planes grow into the new hits
    over that k-NN graph: a new hit that has a hit of a plane among its
    neighbours (so it lies within the plane's extent, grown by one
    neighbourhood) joins it when it lies within `distance_threshold` of the
    plane and agrees with it (as in step 2), the nearest plane winning, and
    so on breadth-first; the planes are then refit. The other new hits are
    clustered among themselves as in :meth:`fit` (steps 2–4, over their own
    k-NN graph) and get new labels. Existing clusters never merge, and
    Dirichlet-process clusters never grow. The hits are kept
    (``n_hits x 3`` floats) for the neighbourhoods of later updates, and
    each update rebuilds the k-d tree of all of them.

    Parameters
    ----------
    distance_threshold : float, default=0.05
        Largest distance (m) of a hit from the plane it joins; also the
        spread that makes a neighbourhood planar or linear.
    angle_threshold : float, default=10.0
        Largest angle (degrees, in [0, 90]) between normals that agree.
    n_neighbors : int, default=10
        Neighbours of each hit (itself excluded) for its local shape and
        the graph; 2 to 100.
    min_region_size : int, default=30
        Smallest region kept as a plane.
    concentration : float, default=1.0
        Concentration of the Dirichlet-process fallback.
    random_state : int, numpy Generator, RandomState or None, default=None
        Seeds the Dirichlet-process fallback.
    n_jobs : int, default=None
        Threads of the neighbour queries (None: 1; -1: every core).

    Attributes
    ----------
    labels_ : ndarray of shape (n_hits,), dtype int64
    n_clusters_ : int
    n_planes_ : int
        Clusters that are planes (the others come from the fallback).
    n_dims_ : int
        Always 3.
    planes_ : Planes
        ``centroid``, ``normal``, ``lower``, ``upper``, ``n_points`` and
        ``is_plane`` of each cluster.

    Notes
    -----
    On ``structured_room(0)`` scanned from 4 poses by a 64 x 4 LiDAR (862
    hits, as in ``bench/bench_gp.py``) the defaults give 19 clusters, 7 of
    them planes (the floor, the four walls, the partition and the table
    top); the furniture's other faces, with a few hits each, go to the
    fallback. 10,000 hits (the same poses, a 256 x 12 LiDAR) take about
    0.3 s on 2 cores (33 clusters, 19 planes).

    References
    ----------
    T. Rabbani, F. van den Heuvel, G. Vosselman, "Segmentation of point
    clouds using smoothness constraint", ISPRS Archives 36(5), 2006.

    Examples
    --------
    Three faces of a box corner, seen from one pose:

    >>> import numpy as np
    >>> u, v = np.meshgrid(np.linspace(0.1, 1, 8), np.linspace(0.1, 1, 8))
    >>> u, v, o = u.ravel(), v.ravel(), np.zeros(64)
    >>> hits = np.vstack([np.column_stack([u, v, o]), np.column_stack([u, o, v]),
    ...                   np.column_stack([o, u, v])])
    >>> pc = PlaneClustering(random_state=0).fit(hits, np.ones_like(hits))
    >>> pc.n_clusters_, pc.n_planes_
    (3, 3)
    """

    _dims = (3,)
    _what = " for plane clustering"

    def __init__(self, distance_threshold=0.05, angle_threshold=10.0, n_neighbors=10,
                 min_region_size=30, concentration=1.0, random_state=None, n_jobs=None):
        self.distance_threshold = distance_threshold
        self.angle_threshold = angle_threshold
        self.n_neighbors = n_neighbors
        self.min_region_size = min_region_size
        self.concentration = concentration
        self.random_state = random_state
        self.n_jobs = n_jobs

    def _check_params(self):
        angle = np.radians(_check_angle(self.angle_threshold, "angle_threshold"))
        params = dict(
            distance=check_real(self.distance_threshold, "distance_threshold", low=0.0),
            cos=np.cos(angle), sin=np.sin(angle), tan=np.tan(angle),
            k=_check_at_least(self.n_neighbors, "n_neighbors", 2, _MAX_NEIGHBORS),
            min_size=check_int(self.min_region_size, "min_region_size", low=1),
            n_jobs=check_n_jobs(self.n_jobs))
        params["dp"] = DirichletProcessClustering(concentration=self.concentration,
                                                  random_state=self.random_state)
        params["dp"]._check_params()
        return params

    # ----------------------------------------------------------- local shape
    @staticmethod
    def _neighbours(points, k, n_jobs, queries=None):
        tree = cKDTree(points)
        k = min(k + 1, len(points))
        dist, nb = tree.query(points if queries is None else queries, k=k,
                              workers=n_threads(n_jobs))
        return dist.reshape(len(nb), -1), nb.reshape(len(nb), -1)

    @staticmethod
    def _agrees(kind, normal, direction, plane_normal, params):
        """Whether each hit's local shape agrees with `plane_normal` (rows or one)."""
        cos_n = np.abs(np.sum(normal * plane_normal, axis=-1))
        cos_d = np.abs(np.sum(direction * plane_normal, axis=-1))
        return np.where(kind == _PLANE, cos_n >= params["cos"],
                        np.where(kind == _LINE, cos_d <= params["sin"], True))

    def _grow(self, points, nb, shape, params):
        """Region of each point (-1: none), grown from the planar seeds."""
        normal, direction, kind, curvature = shape
        n = len(points)
        region = np.full(n, -1, dtype=np.int64)
        seeds = np.flatnonzero(kind == _PLANE)
        seeds = seeds[np.argsort(curvature[seeds], kind="stable")]
        dt = params["distance"]
        r = 0
        for seed in seeds:
            if region[seed] >= 0:
                continue
            region[seed] = r
            ref = points[seed]
            plane_n, plane_c = normal[seed], ref
            cnt, s1, s2 = 1.0, np.zeros(3), np.zeros((3, 3))
            frontier = np.array([seed])
            while len(frontier):
                cand = np.unique(nb[frontier].ravel())
                cand = cand[region[cand] < 0]
                if not len(cand):
                    break
                dist = np.abs((points[cand] - plane_c) @ plane_n)
                ok = (dist <= dt) & self._agrees(kind[cand], normal[cand], direction[cand],
                                                 plane_n, params)
                frontier = cand[ok]
                region[frontier] = r
                q = points[frontier] - ref
                cnt, s1, s2 = cnt + len(q), s1 + q.sum(axis=0), s2 + q.T @ q
                mean = s1 / cnt
                w, v = np.linalg.eigh(s2 / cnt - np.outer(mean, mean))
                if w[1] >= dt * dt:
                    plane_n, plane_c = v[:, 0], ref + mean
            r += 1
        return region, r

    def _cluster(self, points, nb, shape, params, margin):
        """Labels (0..k-1, first appearance) and _planes state of `points`."""
        region, n_regions = self._grow(points, nb, shape, params)
        size = np.bincount(region[region >= 0], minlength=n_regions)
        big = np.flatnonzero(size >= params["min_size"])
        remap = np.full(n_regions + 1, -1, dtype=np.int64)
        remap[big] = np.arange(len(big))
        plane = remap[region]                     # region -1 maps to the last entry: -1
        n_planes = len(big)
        if n_planes > 1:
            n, mean, scatter, lower, upper = _plane_moments(points[plane >= 0],
                                                            plane[plane >= 0], n_planes)
            nrm = _normals(scatter)
            i, j = np.triu_indices(n_planes, 1)
            cos = np.abs(np.einsum("ij,ij->i", nrm[i], nrm[j]))
            off = np.maximum(np.abs(np.einsum("ij,ij->i", mean[j] - mean[i], nrm[i])),
                             np.abs(np.einsum("ij,ij->i", mean[i] - mean[j], nrm[j])))
            overlap = np.all((lower[i] - margin <= upper[j] + margin)
                             & (lower[j] - margin <= upper[i] + margin), axis=1)
            ok = (cos >= params["cos"]) & (off <= params["distance"]) & overlap
            comp = _components(n_planes, i[ok], j[ok])
            plane = np.where(plane >= 0, comp[np.maximum(plane, 0)], -1)
            n_planes = int(comp.max()) + 1
        cluster = plane.copy()
        rest = plane < 0
        if rest.any():
            dp = params["dp"]
            cluster[rest] = n_planes + dp.fit_predict(points[rest], np.zeros_like(points[rest]))
        k = int(cluster.max()) + 1
        rank = _first_appearance(cluster, k)
        labels = rank[cluster]
        is_plane = np.zeros(k, dtype=bool)
        is_plane[rank[:n_planes]] = True
        return labels, k, is_plane

    @staticmethod
    def _plane_state(points, labels, k, is_plane):
        n, mean, scatter, lower, upper = _plane_moments(points, labels, k)
        return dict(n=n, mean=mean, scatter=scatter, lower=lower, upper=upper,
                    normal=_normals(scatter), is_plane=is_plane)

    @staticmethod
    def _public(planes):
        return Planes(planes["mean"].copy(), planes["normal"].copy(), planes["lower"].copy(),
                      planes["upper"].copy(), planes["n"].astype(np.int64),
                      planes["is_plane"].copy())

    def _fit(self, hits, origins, params):
        dist, nb = self._neighbours(hits, params["k"], params["n_jobs"])
        shape = _local_shape(hits, nb, params["distance"], params["tan"])
        margin = float(np.median(dist[:, -1]))
        labels, k, is_plane = self._cluster(hits, nb, shape, params, margin)
        planes = self._plane_state(hits, labels, k, is_plane)
        return dict(_hits=hits, _planes=planes, _margin=margin, planes_=self._public(planes),
                    n_planes_=int(is_plane.sum())), labels

    def _partial(self, hits, origins, params):
        everything = np.vstack([self._hits, hits])
        _, nb = self._neighbours(everything, params["k"], params["n_jobs"], queries=hits)
        normal, direction, kind, curvature = _local_shape(everything, nb, params["distance"],
                                                         params["tan"])
        old = self._planes
        m = len(old["n"])
        margin = self._margin
        n_old = len(self._hits)
        # grow the existing planes over the k-NN graph into the new hits
        owner = np.concatenate([np.where(old["is_plane"][self.labels_], self.labels_, -1),
                                np.full(len(hits), -1, dtype=np.int64)])
        while True:
            free = np.flatnonzero(owner[n_old:] < 0)
            cand = owner[nb[free]]
            rows, cols = np.nonzero(cand >= 0)
            if not len(rows):
                break
            q, p = free[rows], cand[rows, cols]
            dist = np.abs(np.einsum("ij,ij->i", hits[q] - old["mean"][p], old["normal"][p]))
            ok = (dist <= params["distance"]) & self._agrees(
                kind[q], normal[q], direction[q], old["normal"][p], params)
            if not ok.any():
                break
            q, p, _ = _best_per_row(q[ok], p[ok], dist[ok])
            owner[n_old + q] = p
        labels = owner[n_old:].copy()
        joined = labels >= 0
        new = dict(old)
        if joined.any():
            new = _combine_planes(old, hits[joined], labels[joined])
        rest = np.flatnonzero(~joined)
        n_new_planes = 0
        if len(rest):
            pts = hits[rest]
            _, nb_rest = self._neighbours(pts, params["k"], params["n_jobs"])
            shape = (normal[rest], direction[rest], kind[rest], curvature[rest])
            sub, k, is_plane = self._cluster(pts, nb_rest, shape, params, margin)
            labels[rest] = m + sub
            fresh = self._plane_state(pts, sub, k, is_plane)
            new = {key: np.concatenate([new[key], fresh[key]]) for key in new}
            n_new_planes = int(is_plane.sum())
        return dict(_hits=everything, _planes=new, planes_=self._public(new),
                    n_planes_=self.n_planes_ + n_new_planes), labels


def _combine_planes(old, points, labels):
    """Plane state `old` with `points` added to the clusters `labels`."""
    k = len(old["n"])
    n_b = np.bincount(labels, minlength=k).astype(np.float64)
    touched = n_b > 0
    safe = np.where(touched, n_b, 1.0)
    mean_b = np.column_stack([np.bincount(labels, points[:, d], k) for d in range(3)]) \
        / safe[:, None]
    q = points - mean_b[labels]
    scatter_b = np.stack([np.stack([np.bincount(labels, q[:, a] * q[:, b], k) for b in range(3)],
                                   axis=1) for a in range(3)], axis=1)
    n = old["n"] + n_b
    delta = mean_b - old["mean"]
    w = np.where(touched, old["n"] * n_b / n, 0.0)
    mean = np.where(touched[:, None], old["mean"] + delta * (n_b / n)[:, None], old["mean"])
    scatter = old["scatter"] + scatter_b + w[:, None, None] * np.einsum("ki,kj->kij", delta, delta)
    lower, upper = old["lower"].copy(), old["upper"].copy()
    np.minimum.at(lower, labels, points)
    np.maximum.at(upper, labels, points)
    normal = np.where(touched[:, None], _normals(scatter), old["normal"])
    return dict(n=n, mean=mean, scatter=scatter, lower=lower, upper=upper, normal=normal,
                is_plane=old["is_plane"].copy())
