"""The real-log benchmark: hold out whole scans of a posed log, map the rest, score.

Real logs have no ground truth, but every held-out scan says where the space was
free (along its beams) and where it was not (at its hits). :func:`log_split`
holds out the scans ``i % every == offset``; :func:`log_test_set` turns them into
one balanced, seeded set of test points; :class:`RealLogBenchmark` builds each
map from the other scans and scores it there: ROC AUC, accuracy at the map's own
threshold, Brier score and NLL (calibration), the unknown fraction, build and
query time and peak memory.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray
from tqdm.auto import tqdm

from .._validation import as_point, as_points, check_real, check_seed
from ..io import LaserLog, LaserScan2D
from ._protocols import disable_bar, map_factory
from ._scene_sets import PeakRSS
from .metrics import roc_auc

__all__ = ["log_split", "LogTestSet", "log_test_set", "score_log", "LogResult",
           "RealLogBenchmark", "NLL_EPS"]

#: Probabilities are clipped to [NLL_EPS, 1 - NLL_EPS] in the negative log-likelihood.
NLL_EPS = 1e-6


def log_split(n_scans: int, *, every: int = 10, offset: int = 5):
    """Indices of the training and the held-out scans of a log.

    Scan ``i`` is held out when ``i % every == offset``: one scan in `every`,
    spread over the whole log, with the scans around it kept for mapping.

    Parameters
    ----------
    n_scans : int
        Scans in the log (at least 2).
    every : int, default=10
        One scan in `every` is held out (at least 2).
    offset : int, default=5
        Which one, in ``[0, every)``.

    Returns
    -------
    train, test : ndarray of int
        Scan indices in increasing order.

    Raises
    ------
    ValueError
        If an argument is out of range, or no scan is held out or none kept.
    TypeError
        If an argument is not an int.

    Examples
    --------
    >>> train, test = log_split(23)
    >>> test.tolist(), len(train)
    ([5, 15], 21)
    """
    for name, value in (("n_scans", n_scans), ("every", every), ("offset", offset)):
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
            raise TypeError(f"{name} must be an int, got {type(value).__name__}")
    if every < 2:
        raise ValueError(f"every must be at least 2, got {every}")
    if not 0 <= offset < every:
        raise ValueError(f"offset must lie in [0, every) = [0, {every}), got {offset}")
    idx = np.arange(n_scans)
    held = idx % every == offset
    if not held.any() or held.all():
        raise ValueError(f"a log of {n_scans} scans holds out no scan with every={every}, "
                         f"offset={offset} (it needs more than {offset} scans)")
    return idx[~held], idx[held]


class LogTestSet(NamedTuple):
    """The test points of held-out scans.

    Attributes
    ----------
    points : ndarray of shape (n_points, D)
        Test locations (D = 2 for a 2D log, 3 for a 3D one).
    labels : ndarray of bool, shape (n_points,)
        True for the held-out hits (occupied), False for the free samples.
    near_surface : ndarray of bool, shape (n_points,)
        Free samples drawn within `near` metres in front of their hit.
    scan : ndarray of int, shape (n_points,)
        The held-out scan (its index among the scans given) of each point.
    """

    points: NDArray[np.float64]
    labels: NDArray[np.bool_]
    near_surface: NDArray[np.bool_]
    scan: NDArray[np.int64]


LogTestSet.__test__ = False  # type: ignore[attr-defined]  # pytest: not a test class


def _hits_origin(scan, i):
    """(hits, origin) of a held-out scan: a LaserScan2D's returns, or a 3D scan."""
    if isinstance(scan, LaserScan2D):
        return scan.points, np.asarray(scan.origin, dtype=np.float64)
    try:
        points, origin = scan[0], scan[1]
    except (TypeError, IndexError, KeyError):
        raise TypeError(f"scans[{i}] must be a LaserScan2D or a (points, origin) pair, got "
                        f"{type(scan).__name__}") from None
    pts = np.asarray(points)
    dim = pts.shape[1] if pts.ndim == 2 and pts.shape[1] in (2, 3) else 3
    return as_points(points, f"scans[{i}].points", dim), as_point(origin, f"scans[{i}].origin",
                                                                 dim)


def log_test_set(scans, *, max_range: float = 30.0, min_range: float = 0.3,
                 margin: float = 0.2, near: float = 1.0, near_fraction: float = 0.5,
                 max_points: int | None = None, seed=0) -> LogTestSet:
    """Occupied and free test points from held-out scans, as many of each.

    Every hit of a held-out scan at a range ``r`` with
    ``min_range + margin < r <= max_range`` is an occupied test point, and
    gives one free test point on its beam, at a range drawn uniformly in
    ``[max(min_range, r - margin - near), r - margin]`` (a *near-surface*
    sample, with probability `near_fraction`, where maps that smooth
    surfaces into free space fail) or else in ``[min_range, r - margin]``.
    Beams without a return are never scored: where they end nothing is
    known. The points are drawn from one generator over the scans in order,
    so the same scans and arguments give the same test set.

    Parameters
    ----------
    scans : sequence of LaserScan2D or of (points, origin)
        The held-out scans: 2D laser scans (their returns are the hits) or
        3D scans in the world frame (every point a hit).
    max_range : float, default=30.0
        Hits farther than this (metres) are not scored.
    min_range : float, default=0.3
        No free sample nearer to the sensor than this (metres, >= 0).
    margin : float, default=0.2
        Every free sample lies at least this far (metres, >= 0) before its hit.
    near : float, default=1.0
        Width (metres, > 0) of the near-surface band in front of the margin.
    near_fraction : float, default=0.5
        Fraction of the free samples drawn in that band, in [0, 1].
    max_points : int, default=None
        Keep at most this many hits (a seeded uniform subsample, each with
        its free sample); None keeps all.
    seed : int, numpy.random.Generator or None, default=0

    Returns
    -------
    test_set : LogTestSet
        The occupied points in scan order, then their free samples in the
        same order.

    Raises
    ------
    ValueError
        If an argument is out of range, a scan is malformed, or no hit lies
        in the scored range.
    TypeError
        If a scan is neither a LaserScan2D nor a pair, or an argument has a
        wrong type.

    Examples
    --------
    >>> wall = np.column_stack([np.full(50, 4.0), np.linspace(-1, 1, 50), np.zeros(50)])
    >>> test = log_test_set([(wall, np.zeros(3))])
    >>> int(test.labels.sum()), int((~test.labels).sum())
    (50, 50)
    >>> bool((test.points[~test.labels, 0] <= 3.8 + 1e-9).all())
    True
    """
    max_range = check_real(max_range, "max_range", low=0.0, high=1e6, high_open=False)
    min_range = check_real(min_range, "min_range", low=0.0, low_open=False)
    margin = check_real(margin, "margin", low=0.0, low_open=False)
    near = check_real(near, "near", low=0.0)
    near_fraction = check_real(near_fraction, "near_fraction", low=0.0, high=1.0,
                               low_open=False, high_open=False)
    if not min_range + margin < max_range:
        raise ValueError(f"min_range + margin must be less than max_range, got "
                         f"{min_range} + {margin} >= {max_range}")
    if max_points is not None and (isinstance(max_points, (bool, np.bool_))
                                   or not isinstance(max_points, (int, np.integer))):
        raise TypeError(f"max_points must be an int or None, got {type(max_points).__name__}")
    if max_points is not None and max_points < 1:
        raise ValueError(f"max_points must be at least 1, got {max_points}")
    rng = check_seed(seed)
    hits, origins, scan_of = [], [], []
    for i, scan in enumerate(scans):
        pts, origin = _hits_origin(scan, i)
        if hits and pts.shape[1] != hits[0].shape[1]:
            raise ValueError(f"scans[{i}] has {pts.shape[1]}-D points, the first scan "
                             f"{hits[0].shape[1]}-D")
        r = np.linalg.norm(pts - origin, axis=1)
        keep = (r > min_range + margin) & (r <= max_range)
        hits.append(pts[keep])
        origins.append(np.broadcast_to(origin, (int(keep.sum()), len(origin))))
        scan_of.append(np.full(int(keep.sum()), i, dtype=np.int64))
    if not hits or not sum(len(h) for h in hits):
        raise ValueError(f"no held-out hit lies between min_range + margin "
                         f"({min_range + margin:g} m) and max_range ({max_range:g} m)")
    occ, org, scan = np.vstack(hits), np.vstack(origins), np.concatenate(scan_of)
    if max_points is not None and len(occ) > max_points:
        pick = np.sort(rng.choice(len(occ), max_points, replace=False))
        occ, org, scan = occ[pick], org[pick], scan[pick]
    ray = occ - org
    r = np.linalg.norm(ray, axis=1)
    is_near = rng.uniform(size=len(r)) < near_fraction
    hi = r - margin
    lo = np.where(is_near, np.maximum(min_range, hi - near), min_range)
    s = lo + rng.uniform(size=len(r)) * (hi - lo)
    free = org + (s / r)[:, None] * ray
    n = len(occ)
    return LogTestSet(np.vstack([occ, free]),
                      np.r_[np.ones(n, dtype=bool), np.zeros(n, dtype=bool)],
                      np.r_[np.zeros(n, dtype=bool), is_near], np.r_[scan, scan])


class LogResult(NamedTuple):
    """One map's row of the real-log benchmark.

    Attributes
    ----------
    method : str
    auc : float
        ROC AUC (unknown points count as p = 0.5).
    accuracy : float
        Fraction of test points the map labels right at its own threshold
        (occupied when ``p >= occupancy_threshold``); an unknown point is
        wrong whatever its label.
    brier : float
        Mean squared error of the probability (unknown: 0.5).
    nll : float
        Mean negative log-likelihood of the labels, probabilities clipped to
        ``[NLL_EPS, 1 - NLL_EPS]`` (unknown: log 2).
    acc_occupied, acc_free, acc_near : float
        The accuracy on the occupied points, on the free ones, and on the
        near-surface free ones.
    unknown_fraction : float
        Test points in no known cell.
    build_seconds, query_seconds : float
        Time in ``fit`` / ``insert_scan`` calls, and in the ``occupancy``
        query of the test points.
    map_mb : float
        The built map's own ``memory_usage()``, MB (NaN for a map without it).
    peak_mb : float
        Peak resident memory of the process above its value at the start,
        over building and querying (MB, sampled every 5 ms). Memory that
        maps built before in the same process gave back to the allocator is
        reused without raising the resident size: run each map in a process
        of its own for a true peak (``bench/bench_real.py`` does).
    n_train_scans, n_test : int
    threshold : float
        The map's occupancy threshold.
    map : object
        The built map; not part of tables.
    """

    method: str
    auc: float
    accuracy: float
    brier: float
    nll: float
    acc_occupied: float
    acc_free: float
    acc_near: float
    unknown_fraction: float
    build_seconds: float
    query_seconds: float
    map_mb: float
    peak_mb: float
    n_train_scans: int
    n_test: int
    threshold: float
    map: Any = None


def score_log(test_set: LogTestSet, probabilities, threshold: float = 0.5) -> dict:
    """The scores of :class:`LogResult` for predicted probabilities (NaN: unknown).

    Parameters
    ----------
    test_set : LogTestSet
    probabilities : array-like of shape (n_points,)
        In [0, 1], NaN where the map knows nothing.
    threshold : float, default=0.5
        The map's occupancy threshold, in (0, 1).

    Returns
    -------
    scores : dict
        ``auc``, ``accuracy``, ``brier``, ``nll``, ``acc_occupied``,
        ``acc_free``, ``acc_near``, ``unknown_fraction``.

    Raises
    ------
    ValueError
        If the probabilities have the wrong shape or lie outside [0, 1].
    """
    p = np.asarray(probabilities, dtype=np.float64)
    labels = np.asarray(test_set.labels, dtype=bool)
    if p.shape != labels.shape:
        raise ValueError(f"probabilities must have shape {labels.shape}, got {p.shape}")
    unknown = np.isnan(p)
    if ((p[~unknown] < 0) | (p[~unknown] > 1)).any():
        raise ValueError("probabilities must lie in [0, 1] (NaN: unknown)")
    threshold = check_real(threshold, "threshold", low=0.0, high=1.0)
    q = np.where(unknown, 0.5, p)
    right = ~unknown & ((q >= threshold) == labels)
    clipped = np.clip(q, NLL_EPS, 1.0 - NLL_EPS)
    nll = -np.where(labels, np.log(clipped), np.log1p(-clipped))
    near = np.asarray(test_set.near_surface, dtype=bool)
    return {"auc": roc_auc(labels, p), "accuracy": float(right.mean()),
            "brier": float(np.mean((q - labels) ** 2)), "nll": float(nll.mean()),
            "acc_occupied": float(right[labels].mean()),
            "acc_free": float(right[~labels].mean()),
            "acc_near": float(right[near].mean()) if near.any() else math.nan,
            "unknown_fraction": float(unknown.mean())}


def _is_2d(scans) -> bool:
    return isinstance(scans, LaserLog) or (len(scans) > 0 and isinstance(scans[0], LaserScan2D))


def _threshold(map_) -> float:
    value = getattr(map_, "occupancy_threshold", None)
    return 0.5 if value is None else float(value)


class RealLogBenchmark:
    """Hold out every `every`-th scan of a posed log, map the others, score every map.

    The test set (:func:`log_test_set` of the held-out scans) is made once,
    when first needed, and every map is scored on the same points. A 2D log
    (a :class:`~occgp.io.LaserLog`) builds a map with one ``fit(hits,
    segment_starts, segment_ends)`` on every training beam (every 2D map of
    the registry has it); a 3D log (a list of scans or a
    :class:`~occgp.io.ScanSequence`) inserts the training scans one by
    one, with the ``insert`` options of the method.

    Parameters
    ----------
    scans : LaserLog, ScanSequence or sequence of (points, origin)
        The log, in order; 3D scans in the world frame.
    every, offset : int, default=10, 5
        The held-out scans, see :func:`log_split`.
    max_range, min_range, margin, near, near_fraction, max_points, seed
        The test points, see :func:`log_test_set`.
    progress : bool, default=None
        Progress bars while building 3D maps (None: on a terminal).

    Attributes
    ----------
    train_indices, test_indices : ndarray of int
        The scans mapped and the scans held out.

    Examples
    --------
    >>> from occgp.datasets import room_2d
    >>> from occgp.io import LaserLog
    >>> scans = room_2d().scan(n_poses=20)
    >>> bench = RealLogBenchmark(LaserLog(scans, np.arange(20.0)), every=5, offset=2,
    ...                          max_range=8.0)
    >>> row = bench.evaluate("grid", {"map": "gp-grid", "resolution": 0.2})
    >>> row.n_train_scans, 0.5 < row.auc <= 1.0
    (16, True)
    """

    def __init__(self, scans, *, every: int = 10, offset: int = 5, max_range: float = 30.0,
                 min_range: float = 0.3, margin: float = 0.2, near: float = 1.0,
                 near_fraction: float = 0.5, max_points: int | None = None, seed=0,
                 progress: bool | None = None):
        if not hasattr(scans, "__len__") or not hasattr(scans, "__getitem__"):
            raise TypeError(f"scans must be a LaserLog, a ScanSequence or a sequence of "
                            f"scans, got {type(scans).__name__}")
        self.scans = scans
        self.train_indices, self.test_indices = log_split(len(scans), every=every,
                                                          offset=offset)
        self.dims = 2 if _is_2d(scans) else 3
        self._test_args = dict(max_range=max_range, min_range=min_range, margin=margin,
                               near=near, near_fraction=near_fraction, max_points=max_points,
                               seed=seed)
        self.progress = progress
        self._test_set: LogTestSet | None = None
        self._observations = None

    @property
    def test_set(self) -> LogTestSet:
        """The test points of the held-out scans (made on first use, then kept)."""
        if self._test_set is None:
            self._test_set = log_test_set([self.scans[int(i)] for i in self.test_indices],
                                          **self._test_args)
        return self._test_set

    def training_observations(self):
        """The hits and beams of the training scans of a 2D log (made once, then kept).

        Returns
        -------
        hits : ndarray of shape (n_hits, 2)
        segment_starts, segment_ends : ndarray of shape (n_beams, 2)

        Raises
        ------
        ValueError
            If the log is 3D.
        """
        if self.dims != 2:
            raise ValueError("training_observations is for 2D logs (a LaserLog), this log "
                             "is 3D")
        if self._observations is None:
            self._observations = self.scans.observations(self.train_indices) \
                if isinstance(self.scans, LaserLog) \
                else LaserLog([self.scans[int(i)] for i in self.train_indices],
                              np.zeros(len(self.train_indices))).observations()
        return self._observations

    def _build(self, factory, options, name):
        map_ = factory()
        seconds = 0.0
        if self.dims == 2:
            observations = self.training_observations()
            t0 = time.perf_counter()
            map_.fit(*observations)
            return map_, time.perf_counter() - t0
        for i in tqdm(self.train_indices, desc=str(name), unit="scan",
                      disable=disable_bar(self.progress), leave=False):
            points, origin = self.scans[int(i)][:2]
            t0 = time.perf_counter()
            map_.insert_scan(points, origin, **options)
            seconds += time.perf_counter() - t0
        return map_, seconds

    def evaluate(self, name: str, method) -> LogResult:
        """Build one map from the training scans and score it on the test set.

        Parameters
        ----------
        name : str
            The row's name.
        method : callable, str or dict
            A factory of empty maps, a registered map name, or
            ``{"map": name, **params}`` with an optional ``"insert"`` dict of
            ``insert_scan`` options (3D), as in
            :func:`~occgp.evaluation.compare_methods`.

        Returns
        -------
        row : LogResult

        Raises
        ------
        ValueError
            If the method is unknown, does not take the log's dimension, or
            its parameters are rejected; or the map rejects the data.
        TypeError
            If `method` is none of the above.
        """
        if callable(method):
            factory, options = method, {}
        elif isinstance(method, (str, Mapping)):
            factory, options = map_factory(name, method, dim=self.dims)
        else:
            raise TypeError(f"method must be a factory, a registered map name or a "
                            f"{{'map': name, ...}} dict, got {type(method).__name__}")
        test = self.test_set
        with PeakRSS() as memory:
            map_, build = self._build(factory, options, name)
            t0 = time.perf_counter()
            p = np.asarray(map_.occupancy(test.points), dtype=np.float64)
            query = time.perf_counter() - t0
        threshold = _threshold(map_)
        s = score_log(test, p, threshold)
        usage = getattr(map_, "memory_usage", None)
        map_mb = usage() / 2**20 if callable(usage) else math.nan
        return LogResult(str(name), s["auc"], s["accuracy"], s["brier"], s["nll"],
                         s["acc_occupied"], s["acc_free"], s["acc_near"],
                         s["unknown_fraction"], build, query, map_mb, memory.peak,
                         len(self.train_indices), len(test.labels), threshold, map_)

    def compare(self, methods: Mapping[str, Any] | Sequence[str]) -> list[LogResult]:
        """:meth:`evaluate` for each method, in order.

        Parameters
        ----------
        methods : mapping of str to (callable, str or dict), or sequence of str
            Row name to method (see :meth:`evaluate`); a sequence of
            registered map names stands for ``{name: name, ...}``.

        Returns
        -------
        rows : list of LogResult
        """
        if isinstance(methods, Mapping):
            items = list(methods.items())
        elif isinstance(methods, Sequence) and not isinstance(methods, (str, bytes)):
            items = [(m, m) for m in methods]
        else:
            raise TypeError(f"methods must be a mapping or a sequence of map names, got "
                            f"{type(methods).__name__}")
        return [self.evaluate(name, spec) for name, spec in items]

