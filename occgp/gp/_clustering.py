"""Clustering of laser hits for the mixture of GP experts (Kim & Kim 2022, §3.1).

Every clusterer follows one protocol: ``fit_predict(hits, origins)`` labels the
hits ``0..k-1`` (``origins`` is the sensor position of each hit; consecutive
hits with the same origin form one scan), ``partial_fit(hits, origins)`` labels
new hits without changing the labels of earlier ones, ``labels_`` holds the
label of every hit seen so far and ``n_clusters_`` their number.

* :class:`DirichletProcessClustering`: a Dirichlet-process Gaussian mixture
  (scikit-learn's variational ``BayesianGaussianMixture``), any dimension;
* :class:`~occgp.gp.LineTracking` (``_lines.py``): the paper's Algorithm 1 on
  2D scans, lines merged across scans;
* :class:`~occgp.gp.PlaneClustering` (``_planes.py``): planes grown over the
  k-NN graph of 3D hits, with the Dirichlet process for what is not planar.

This module holds the protocol's base class, the checks the clusterers share
and the Dirichlet process.
"""

from __future__ import annotations

import numbers
import warnings
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from sklearn.base import BaseEstimator
from sklearn.exceptions import ConvergenceWarning
from threadpoolctl import threadpool_limits

from .._validation import as_numeric, as_points, check_choice, check_int, check_real

__all__ = ["DirichletProcessClustering"]

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


def scan_ids(origins):
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


def first_appearance(labels, k):
    """Map labels 0..k-1 to their rank of first appearance in `labels` (-1: absent)."""
    present, first = np.unique(labels, return_index=True)
    out = np.full(k, -1, dtype=np.int64)
    out[present[np.argsort(first, kind="stable")]] = np.arange(len(present))
    return out


def components(n, i, j):
    """Connected components of the graph on `n` nodes with edges (i, j)."""
    if not len(i):
        return np.arange(n, dtype=np.int64)
    graph = coo_matrix((np.ones(len(i), dtype=np.int8), (i, j)), shape=(n, n))
    _, comp = connected_components(graph, directed=False)
    return comp.astype(np.int64)


def best_per_row(i, j, score):
    """For each distinct `i`, the `j` of lowest `score` (ties: lowest `j`).

    Returns (rows, picks, scores), rows ascending.
    """
    if not len(i):
        return i, j, score
    order = np.lexsort((j, score, i))
    i, j, score = i[order], j[order], score[order]
    first = np.r_[True, i[1:] != i[:-1]]
    return i[first], j[first], score[first]


def group_starts(labels):
    """(order, starts): `labels` sorted stably and where each group starts."""
    order = np.argsort(labels, kind="stable")
    sorted_labels = labels[order]
    starts = np.flatnonzero(np.r_[True, sorted_labels[1:] != sorted_labels[:-1]])
    return order, starts


def segment_distance(p0, p1, q0, q1):
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


class Clustering(BaseEstimator):
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
        """Cluster `hits` from scratch and return their labels.

        The same as ``fit(hits, origins).labels_`` (a copy).

        Parameters
        ----------
        hits : array-like of shape (n_hits, D)
            Laser returns, in scan order.
        origins : array-like of shape (n_hits, D)
            The sensor position of each hit; a run of consecutive equal rows
            is one scan.

        Returns
        -------
        labels : ndarray of shape (n_hits,), dtype int64
            Cluster labels ``0..k-1``, ``k`` = :attr:`n_clusters_`.

        Raises
        ------
        ValueError, TypeError
            As :meth:`fit`.
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


class DirichletProcessClustering(Clustering):
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
        label_of = first_appearance(comp, model.n_components)
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
