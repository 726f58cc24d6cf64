"""The k-NN map: :class:`KNNMap`, public in :mod:`occgp.knn`.

The k-NN inverse sensor model on the octree (Miao, Hunter and Georgilas, 2022).

OctoMap gives every cell that holds a point the same ``prob_hit``. The k-NN
model scores each point of a scan by the mean distance ``s`` to its ``k``
nearest neighbours in the same scan and turns the score into an occupancy
probability through the CDF of ``s``: isolated points (stereo speckle, far
outliers) get a low probability, and can lower a cell's occupancy. With
``history=W`` (beyond the paper) the neighbours are those of the W previous
scans instead, which isolates errors that move with the viewpoint.

:class:`KNNMap` is the map; :class:`ScanReplay` holds what a data set's maps
share under every parameter value (the cells of each scan, the k-NN distances),
so that :func:`occgp.evaluation.grid_search` replays thousands of parameter
combinations as vectorised updates, each exactly the map :class:`KNNMap` or
:class:`~occgp.OccupancyOctree` would build.
"""

from __future__ import annotations

import math
import time
from numbers import Integral, Real
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._scores import (
    fixed_log_odds, history_knn_distances, logodds32, mean_knn_distances, point_log_odds,
)
from .._octree import _welford
from .._params import (DEFAULT_RESOLUTION, Check, Interval, Options, ParamsMixin,
                       check_renamed, deprecated_alias)
from .._status import Status
from ..octree._options import InsertOptions, resolve_options
from ..octree._superray_policy import adaptive_threshold
from .._validation import (
    check_choice, check_int, check_n_jobs, check_real, check_resolution, n_threads,
)
from ..maps import register
from ..octree._tree import OccupancyOctree
from .._scan_input import prefilter

__all__ = ["KNNMap", "check_knn_params", "check_score_stats", "mean_knn_distances",
           "history_knn_distances", "point_log_odds", "fixed_log_odds"]

#: The parameters of the k-NN model, as :class:`KNNMap` takes them (``cdf`` and
#: ``n_jobs`` aside).
KNN_PARAMS = ("k", "p_u", "p_l", "p_m", "p_m_out", "p_min", "p_max", "occupancy_threshold",
              "max_range")
#: The names the k-NN model's parameters had before (deprecated), with their new names.
RENAMED = {"p_t": "occupancy_threshold", "sensor_range": "max_range"}
CDFS = ("normal", "truncated")
#: Where the mean and standard deviation of the scores come from: Welford's running
#: statistics, or the whole data set's (fixed for the run).
STATS = ("online", "dataset")
MAX_K = 1000
#: The most previous scans a point may be scored against (``KNNMap(history=)``).
MAX_HISTORY = 64
MAX_RANGE = 1e15
# the underlying tree's own sensor model: used only to tell end cells (l_hit > 0)
# from crossed cells (l_miss < 0) in the traversal, never to update the map
_CLASS_HIT, _CLASS_MISS = 0.7, 0.4


def check_knn_params(params: dict[str, Any]) -> dict[str, Any]:
    """Validate the k-NN model's parameters (Miao et al., Eq. 12); return them typed.

    The rules, each raising ValueError naming the parameters:

    * ``k``: an int in [1, 1000];
    * ``p_u`` and ``p_l`` in (0, 1), ``p_u >= p_l`` (the CDF maps the
      smallest scores to ``p_u``, the largest to ``p_l``);
    * ``0 < p_min <= p_m <= p_m_out < 0.5``: a ray whose end point lies beyond
      the sensor range is less trustworthy, so its miss probability ``p_m_out``
      is nearer 0.5 than ``p_m``; both lie above the lower clamp;
    * ``p_min <= occupancy_threshold <= p_max < 1``;
    * ``max_range``: finite, in (0, 1e15] metres.

    The names ``p_t`` and ``sensor_range`` (before ``occupancy_threshold`` and
    ``max_range``) are deprecated: they still work for one release, with a
    DeprecationWarning.
    """
    params = check_renamed(RENAMED, params, owner="check_knn_params")
    out = dict(params)
    out["k"] = check_int(params["k"], "k", low=1, high=MAX_K)
    for name in ("p_u", "p_l", "p_m", "p_m_out", "p_min", "p_max", "occupancy_threshold"):
        out[name] = check_real(params[name], name, low=0.0, high=1.0)
    out["max_range"] = check_real(params["max_range"], "max_range", low=0.0,
                                  high=MAX_RANGE, high_open=False)
    rules = [
        ("p_u", "p_l", "p_u >= p_l"),
        ("p_m", "p_min", "p_m >= p_min"),
        ("p_m_out", "p_m", "p_m_out >= p_m"),
        ("occupancy_threshold", "p_min", "occupancy_threshold >= p_min"),
        ("p_max", "occupancy_threshold", "p_max >= occupancy_threshold"),
    ]
    for big, small, rule in rules:
        if out[big] < out[small]:
            raise ValueError(f"the k-NN parameters must satisfy {rule} (Miao et al., Eq. 12), "
                             f"got {big}={out[big]!r} and {small}={out[small]!r}")
    if out["p_m_out"] >= 0.5:
        raise ValueError(f"p_m_out must be below 0.5 (a miss lowers occupancy), "
                         f"got {out['p_m_out']!r}")
    return out


def check_score_stats(value: Any, name: str = "score_stats") -> tuple[float, float] | None:
    """Check fixed score statistics: None, or a (mean, std) pair.

    Parameters
    ----------
    value : None or (float, float)
        The statistics to check: finite reals, ``std >= 0``.
    name : str, default="score_stats"
        The name the errors give.

    Returns
    -------
    stats : (float, float) or None

    Raises
    ------
    TypeError
        If `value` is not None nor a pair of reals.
    ValueError
        If a value is not finite or the std is negative.
    """
    if value is None:
        return None
    if isinstance(value, (str, bytes)) or not np.iterable(value):
        raise TypeError(f"{name} must be None or a (mean, std) pair, got "
                        f"{type(value).__name__}")
    value = tuple(value)
    if len(value) != 2:
        raise TypeError(f"{name} must be None or a (mean, std) pair, got {len(value)} values")
    mean = check_real(value[0], f"{name}[0] (the mean)")
    std = check_real(value[1], f"{name}[1] (the std)", low=0.0, low_open=False)
    return (mean, std)


def _check_all(params: dict[str, Any]) -> dict[str, Any]:
    """Every KNNMap constructor parameter checked, in the constructor's order."""
    model = check_knn_params({name: params[name] for name in KNN_PARAMS})
    return {"resolution": check_resolution(params["resolution"]), **model,
            "cdf": check_choice(params["cdf"], "cdf", CDFS),
            "score_stats": check_score_stats(params["score_stats"]),
            "history": check_int(params["history"], "history", low=0, high=MAX_HISTORY),
            "n_jobs": check_n_jobs(params["n_jobs"])}


@register("knn", formats=(".bt", ".ot"),
          description="The k-NN inverse sensor model on an octree (Miao et al.)")
class KNNMap(ParamsMixin, OccupancyOctree):
    """Occupancy octree updated by the k-NN inverse sensor model (Miao et al.).

    Per scan (:meth:`insert_scan`), the points within `max_range` of the
    origin (the *near* points, by liboctomap's own range test) are scored by
    ``s``, the mean distance to their `k` nearest neighbours among the scan's
    near points (:class:`scipy.spatial.cKDTree`). The mean and standard
    deviation of ``s`` are updated by Welford's algorithm over every point the
    map has seen (they are part of the map's state: pickled, restored and
    continued), and each point gets

    .. math:: p(s) = p_u - (p_u - p_l)\\,\\Phi\\big((s - \\mu) / \\sigma\\big).

    Each cell of the scan gets one update, clamped to ``[p_min, p_max]`` as
    liboctomap clamps (the map is liboctomap's ``OcTree``, so every query,
    leaf iterator, ``.bt``/``.ot`` file and pickle of
    :class:`~occgp.OccupancyOctree` works):

    * a cell holding near points: :math:`\\sum_j \\operatorname{logit} p(s_j)`
      over its points (may be negative: noise lowers occupancy);
    * else a cell crossed by a ray to a near point: ``l_in = logit(p_m)``;
    * else a cell crossed only by rays to points beyond `max_range`, which
      are cut there (their end cells are not updated): ``l_out =
      logit(p_m_out)``.

    Cells are occupied at ``p >= occupancy_threshold``. Rays are traversed as liboctomap's
    ``computeRayKeys`` traverses them, by occgp's compiled scan pipeline: the
    culling region and super rays apply (free updates are <= 0, so the
    culling region's fully free cells are left as they are) and give the same
    map, cell for cell.

    Parameters
    ----------
    resolution : float, default=DEFAULT_RESOLUTION (0.1)
        Edge length of the smallest cells, metres (as for
        :class:`~occgp.OccupancyOctree`).
    k : int, default=1
        Number of nearest neighbours, in [1, 1000].
    p_u, p_l : float, default=0.86, 0.38
        Probability of the best-supported and of the most isolated points;
        ``1 > p_u >= p_l > 0``.
    p_m : float, default=0.26
        Miss probability of cells crossed by rays to near points (``l_in``).
    p_m_out : float, default=0.38
        Miss probability of cells crossed only by rays cut at the sensor range
        (``l_out``); ``0 < p_min <= p_m <= p_m_out < 0.5``.
    p_min, p_max : float, default=0.02, 0.98
        Clamping bounds (probabilities); ``p_min <= occupancy_threshold <=
        p_max < 1``.
    occupancy_threshold : float, default=0.5
        Cells are occupied at a probability of at least this (the paper's
        ``p_t``; the name ``p_t`` is deprecated).
    max_range : float, default=4.0
        The sensor range s_c, metres: rays longer than this are cut here,
        their end cells are not marked occupied and the points are nobody's
        neighbour (the meaning of :meth:`occgp.OccupancyOctree.insert_scan`'s
        `max_range`, whose crossed cells here get ``p_m_out``). Finite, in
        (0, 1e15] (None, no limit, is not allowed: the model needs s_c). The
        name ``sensor_range`` is deprecated.
    cdf : {"normal", "truncated"}, default="normal"
        F: the normal CDF of the paper, or the normal truncated at s = 0 (the
        scores are distances), as the authors' code does.
    score_stats : (float, float) or None, default=None
        None: μ and σ are Welford's running statistics (online). A pair
        ``(mean, std)``: μ and σ fixed for the whole run, as the authors' code
        takes them from the whole data set (e.g.
        :meth:`ScanReplay.score_stats`, or :attr:`score_mean_` and
        :attr:`score_std_` of a map built from every scan); finite, ``std >=
        0``. Welford's statistics are still kept (the attributes below).
    history : int, default=0
        0: the paper's score, over the point's own scan. ``W >= 1`` (at most
        64): the score over scans, an extension beyond the paper: ``s`` is the
        mean distance to the `k` nearest near points (world frame) of the `W`
        previous scans inserted into this map, not of the point's own scan
        (:func:`~occgp.knn.history_knn_distances`). A stereo matching error is
        dense within its scan but seen at another place from each viewpoint,
        while a surface is seen at the same place from many: over scans the
        error is isolated. While the history holds no point (the first scan),
        the points are scored against their own scan; fewer than `k` points
        in it give the score inf. The map keeps the last `W` near clouds
        (float64, ``24 * W * n_near`` bytes).
    n_jobs : int or None, default=None
        Threads for the k-NN queries (``cKDTree.query(workers=)``), for
        walking a scan's rays and for the tree update (as
        ``OccupancyOctree(n_jobs=)``: the map is the same for every
        `n_jobs`); None: 1, -1: every core.

    Attributes
    ----------
    n_scores_ : int
        Number of finite scores the statistics hold.
    score_mean_, score_std_ : float
        Welford's mean and standard deviation of the scores (NaN before any).
    last_insert_ : dict
        As :class:`~occgp.OccupancyOctree`'s, plus ``near_points`` and
        ``knn_seconds``.

    Notes
    -----
    The constraints on the probabilities are the paper's Eq. 12, read with its
    text: the rays whose end points lie beyond the range are the less reliable
    ones, so ``p_m_out >= p_m``. A scan whose near points are at most `k` gives
    its points the score inf (no k neighbours): they count as isolated
    (``p = p_l``) and do not enter the statistics. The statistics follow the
    scans in insertion order, with the current scan's scores included before
    its points are scored.

    With ``history >= 1`` the clouds of the previous scans are part of the
    map's state like the statistics: pickles and copies keep them, ``.bt`` /
    ``.ot`` files (:meth:`save`, :meth:`to_bytes`) keep only the tree, so a
    loaded map starts with an empty history; :meth:`clear` removes the cells
    and keeps both. :meth:`set_params` may change `history` on a map that has
    scans: the last ``history`` clouds are kept (none with 0), a larger value
    fills up with the next scans.

    References
    ----------
    .. [1] Y. Miao, A. Hunter and I. Georgilas, "An occupancy mapping method
       based on k-nearest neighbours", Sensors 22(1), 139, 2022.
    .. [2] B. P. Welford, "Note on a method for calculating corrected sums of
       squares and products", Technometrics 4(3), 1962.

    Examples
    --------
    >>> import numpy as np
    >>> from occgp import KNNMap
    >>> rng = np.random.default_rng(0)
    >>> wall = np.column_stack([np.full(200, 2.0), rng.uniform(-1, 1, (200, 2))])
    >>> speckle = rng.uniform([0.5, -1, -1], [1.5, 1, 1], (5, 3))
    >>> m = KNNMap(0.1).insert_scan(np.vstack([wall, speckle]), [0.0, 0.0, 0.0])
    >>> bool(m.is_occupied(wall).mean() > 0.9), int(m.is_occupied(speckle).sum())
    (True, 0)
    """

    _kind = "octree"
    #: The parameter that limits the range of the scans: farther points are not
    #: inserted and their rays are cut there (``occgp map`` reports them).
    RANGE_PARAM = "max_range"
    _parameter_constraints = {
        "resolution": [Check(check_resolution, "a resolution in metres")],
        "k": [Interval(Integral, 1, MAX_K)],
        **{name: [Interval(Real, 0, 1, closed="neither")]
           for name in ("p_u", "p_l", "p_m", "p_m_out", "p_min", "p_max",
                        "occupancy_threshold")},
        "max_range": [Interval(Real, 0, MAX_RANGE, closed="right")],
        "cdf": [Options(CDFS)],
        "score_stats": [Check(check_score_stats, "None or a (mean, std) pair")],
        "history": [Interval(Integral, 0, MAX_HISTORY)],
        "n_jobs": [Check(check_n_jobs, "None or a non-zero int")],
    }
    _deprecated_params = RENAMED
    p_t = deprecated_alias("occupancy_threshold", "p_t")
    sensor_range = deprecated_alias("max_range", "sensor_range")

    def __init__(self, resolution: float = DEFAULT_RESOLUTION, *, k: int = 1,
                 p_u: float = 0.86, p_l: float = 0.38, p_m: float = 0.26,
                 p_m_out: float = 0.38, p_min: float = 0.02, p_max: float = 0.98,
                 occupancy_threshold: float = 0.5, max_range: float = 4.0,
                 cdf: str = "normal", score_stats: tuple[float, float] | None = None,
                 history: int = 0, n_jobs: int | None = None, **deprecated: Any) -> None:
        if deprecated:
            new = self._renamed(deprecated, occupancy_threshold=occupancy_threshold,
                                max_range=max_range)
            occupancy_threshold, max_range = new["occupancy_threshold"], new["max_range"]
        params = _check_all({"resolution": resolution, "k": k, "p_u": p_u, "p_l": p_l,
                              "p_m": p_m, "p_m_out": p_m_out, "p_min": p_min, "p_max": p_max,
                              "occupancy_threshold": occupancy_threshold,
                              "max_range": max_range, "cdf": cdf,
                              "score_stats": score_stats, "history": history,
                              "n_jobs": n_jobs})
        self._build(params, _CLASS_HIT, _CLASS_MISS, params["p_min"], params["p_max"],
                    params["occupancy_threshold"])
        self._scores = (0, 0.0, 0.0)       # Welford: count, mean, sum of squared deviations
        self._history: list[NDArray[np.float64]] = []   # the last `history` near clouds

    def __repr__(self) -> str:
        return (f"KNNMap(resolution={self.resolution!r}, k={self.k}, "
                f"num_leaves={self.num_leaves})")

    # ------------------------------------------------------------------ parameters
    def set_params(self, **params) -> "KNNMap":
        """Change the model's parameters (scikit-learn's ``set_params``).

        Any constructor parameter but ``resolution`` (accepted only with the
        map's own value) may change; the values are checked together as the
        constructor checks them. The cells keep their log-odds: new values apply
        to later scans, and ``p_min``, ``p_max`` and ``occupancy_threshold`` also to later
        clamps and to the queries that compare with the threshold. The score
        statistics (Welford's) are kept, and so are the previous scans' clouds
        up to the new `history` (the latest ones; none with 0); a larger
        `history` fills up with the next scans.

        Parameters
        ----------
        **params
            The parameters to change, by name.

        Returns
        -------
        self : KNNMap

        Raises
        ------
        TypeError
            If a value has the wrong type.
        ValueError
            If a name is not a parameter of KNNMap, `resolution` differs from
            the map's, or the values break a rule of the constructor. The map
            is then unchanged.

        Examples
        --------
        >>> from occgp import KNNMap
        >>> m = KNNMap(0.1).set_params(k=3, occupancy_threshold=0.6)
        >>> m.k, m.occupancy_threshold
        (3, 0.6)
        """
        return super().set_params(**params)

    def _get_param(self, name: str) -> Any:
        return self._params[name]

    def _check_params_together(self, params: dict[str, Any]) -> dict[str, Any]:
        if params["resolution"] != self.resolution:
            raise ValueError(f"resolution is fixed at construction ({self.resolution!r}), "
                             f"got {params['resolution']!r}; build a new map instead")
        return _check_all(params)

    def _set_checked_params(self, params: dict[str, Any], checked: dict[str, Any]) -> None:
        self._set_sensor_model(_CLASS_HIT, _CLASS_MISS, checked["p_min"], checked["p_max"],
                               checked["occupancy_threshold"])
        self._params = checked
        if len(self._history) > checked["history"]:
            self._history = self._history[len(self._history) - checked["history"]:]

    @property
    def k(self) -> int:
        """Number of nearest neighbours."""
        return self._params["k"]

    @property
    def p_u(self) -> float:
        """Probability of the best-supported points."""
        return self._params["p_u"]

    @property
    def p_l(self) -> float:
        """Probability of the most isolated points."""
        return self._params["p_l"]

    @property
    def p_m(self) -> float:
        """Miss probability of cells crossed by rays to near points."""
        return self._params["p_m"]

    @property
    def p_m_out(self) -> float:
        """Miss probability of cells crossed only by rays cut at the sensor range."""
        return self._params["p_m_out"]

    @property
    def max_range(self) -> float:
        """The sensor range s_c, metres: longer rays are cut here."""
        return self._params["max_range"]

    @property
    def cdf(self) -> str:
        """The score CDF's kind."""
        return self._params["cdf"]

    @property
    def score_stats(self) -> tuple[float, float] | None:
        """The fixed (mean, std) of the scores, or None (Welford's, online)."""
        return self._params["score_stats"]

    @property
    def history(self) -> int:
        """How many previous scans the points are scored against (0: their own scan)."""
        return self._params["history"]

    @property
    def prob_hit(self) -> float:
        raise AttributeError("KNNMap has no prob_hit: a cell holding points gets the sum "
                             "of its points' logit(p(s)) (see p_u, p_l)")

    @property
    def prob_miss(self) -> float:
        raise AttributeError("KNNMap has no prob_miss: see p_m and p_m_out")

    @property
    def clamping_min(self) -> float:
        return self._params["p_min"]

    @property
    def clamping_max(self) -> float:
        return self._params["p_max"]

    @property
    def occupancy_threshold(self) -> float:
        """Cells are occupied at a probability of at least this."""
        return self._params["occupancy_threshold"]

    @property
    def n_scores_(self) -> int:
        return self._scores[0]

    @property
    def score_mean_(self) -> float:
        return self._scores[1] if self._scores[0] else math.nan

    @property
    def score_std_(self) -> float:
        n, _, m2 = self._scores
        return math.sqrt(m2 / n) if n else math.nan

    # ------------------------------------------------------------------ updates
    def insert_scan(self, points: ArrayLike, origin: ArrayLike, *,  # type: ignore[override]
                    stamp: float | None = None, options: InsertOptions | None = None,
                    **kwargs: Any) -> "KNNMap":
        """Integrate one point cloud with the k-NN inverse sensor model.

        Parameters
        ----------
        points : array-like of shape (n_points, 3)
            The cloud in the world frame, metres; finite. Points beyond
            `max_range` only cut rays. An empty scan changes nothing.
        origin : array-like of shape (3,)
            Sensor position, metres.
        stamp : float, default=None
            Stamp every cell the scan updates with this time, for
            :meth:`~occgp.OccupancyOctree.stamps` and
            :meth:`~occgp.OccupancyOctree.decay` (as for
            :meth:`occgp.OccupancyOctree.insert_scan`). The culling region is
            then not used (its cells are observed too, and are stamped); the
            map is the same.
        options : InsertOptions, default=None
            Of :class:`~occgp.octree.InsertOptions`, the k-NN map takes
            `method` (how rays are traversed, as for
            :meth:`occgp.OccupancyOctree.insert_scan`; every method gives the
            same map), `superray_threshold` and `min_range` (points nearer to
            `origin` are dropped first: they cast no ray and are nobody's
            neighbour, so the map, its score statistics and its history are
            those of the pre-filtered scan; less than `max_range`);
            `discretize` and `bbox` must keep their defaults. The threads are
            the constructor's `n_jobs`.
        **kwargs
            Those fields by name, as in earlier releases.

        Returns
        -------
        self : KNNMap

        Raises
        ------
        TypeError
            If `points` or `origin` does not hold real numbers.
        ValueError
            If `points` is not of shape (n_points, 3), `origin` not of shape
            (3,), either holds NaN or inf, a ray end (after the cut at
            `max_range`) lies outside the key range, the scan reaches more
            than :attr:`MAX_SCAN_CELLS` cells, `method` is invalid, or
            `min_range` is negative, not finite or not less than
            `max_range`, or `stamp` is not finite. The map and its
            statistics are then unchanged.
        """
        opts, _ = resolve_options(options, kwargs, f"{type(self).__name__}.insert_scan",
                                  ("method", "superray_threshold", "min_range"),
                                  threaded=False)
        points, _, _ = prefilter(points, origin, opts.min_range, self.max_range,
                                 range_name="max_range")
        method, threshold = self._check_method(opts.method, opts.superray_threshold)
        stamping = self._stamped(stamp)
        scan = self._validated_scan(points, origin, self.max_range, "scan",
                                    check_ends=False)
        if scan is None:
            return self
        pts, org, rng, _ = scan
        threshold = adaptive_threshold(self, method, threshold)
        # the culling region's cells are observed, so a stamped scan walks them too
        culling = method.endswith("culling") and stamp is None
        out = self._knn_cells(pts, org, rng, culling, threshold,
                              self._max_scan_cells(), n_threads(self._params["n_jobs"]))
        if isinstance(out, Status):
            self._record_insert(out, pts, org, rng, method, threshold)   # raises
            raise AssertionError("unreachable")
        near, keys, kinds, point_cell, stats = out
        t0 = time.perf_counter()
        cloud = near.astype(np.float64)
        workers = n_threads(self._params["n_jobs"])
        s = (history_knn_distances(cloud, self._history, [self.k], workers) if self.history
             else mean_knn_distances(cloud, [self.k], workers))[:, 0]
        scores = _welford(s, *self._scores)
        fixed = self._params["score_stats"]
        values = (point_log_odds(s, *scores, self.p_u, self.p_l, self.cdf) if fixed is None
                  else fixed_log_odds(s, fixed[0], fixed[1], self.p_u, self.p_l, self.cdf))
        updates = _cell_updates(kinds, point_cell, values, logodds32(self.p_m),
                                logodds32(self.p_m_out))
        seconds = time.perf_counter() - t0
        with stamping:
            self._apply_cells(keys, updates, workers)
        self._scores = scores
        if self.history:
            self._history = (self._history + [cloud])[-self.history:]
        self._record_insert(stats, pts, org, rng, method, threshold)
        self.last_insert_["updated_cells"] = len(keys)
        self.last_insert_["near_points"] = len(s)
        self.last_insert_["knn_seconds"] = seconds
        return self

    # ------------------------------------------------------------------ state
    def __reduce__(self):
        return (_rebuild_knn, (type(self), self.get_params(), self.to_bytes("ot"),
                               self._scores, tuple(self._history)))


def _cell_updates(kinds: NDArray[np.uint8], point_cell: NDArray[np.int64],
                 point_values: NDArray[np.float64], l_in: float,
                 l_out: float) -> NDArray[np.float32]:
    """One scan's update per cell: the float32 sum of the point values of the cells
    holding points (kind 0, summed in point order in double precision), else l_in
    (kind 1) or l_out (kind 2)."""
    updates = np.where(kinds == 1, np.float32(l_in), np.float32(l_out)).astype(np.float32)
    held = kinds == 0
    sums = np.bincount(point_cell, point_values, minlength=len(kinds))
    updates[held] = sums[held].astype(np.float32)
    return updates


def _rebuild_knn(cls, params: dict, data: bytes, scores: tuple,
                 history: tuple = ()) -> KNNMap:
    # a pickle of an earlier version names p_t and sensor_range: read them without a warning
    params = {RENAMED.get(k, k): v for k, v in params.items()}
    tree = cls.from_bytes(data, **{k: v for k, v in params.items() if k != "resolution"})
    tree._scores = tuple(scores)
    tree._history = [np.array(c, dtype=np.float64).reshape(-1, 3) for c in history]
    return tree

