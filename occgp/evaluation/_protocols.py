"""The evaluation protocols: test sets, timed map building and comparisons.

:func:`held_out_split` and :func:`grid_test_set` make test sets;
:func:`evaluate_map` scores a built map on one; :func:`run_method`,
:func:`compare_methods` and :func:`equal_time_comparison` build maps from
scans (from factories or from registered map names, see :mod:`occgp.maps`),
time their updates and score them, one :class:`MapResult` per method.
"""

from __future__ import annotations

import functools
import logging
import math
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any, NamedTuple, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray
from tqdm.auto import tqdm

from .._docfill import fill_doc
from .._validation import as_point, as_points, check_real, check_seed
from ..maps import available_maps, make_map, map_type
from .metrics import score_all

__all__ = ["TestSet", "MapResult", "held_out_split", "grid_test_set", "evaluate_map",
           "run_method", "compare_methods", "equal_time_comparison"]

#: What a method may be given as: a factory of empty maps, a registered map name or
#: ``{"map": name, **params}``.
MethodSpec = Union[Callable[[], Any], str, Mapping[str, Any]]

_logger = logging.getLogger("occgp")
_clock = time.perf_counter  # the timer of `run_method` (tests replace it)
_MAX_GRID_POINTS = 50_000_000

#: Docstring sections of the comparisons of several methods (see :func:`occgp._docfill.fill_doc`).
_METHODS_SECTIONS = {
    "methods_params": """methods : mapping of str to (callable, str or dict), or sequence of str
    Method name (the rows' ``method``) to its map: a factory
    ``factory() -> map`` (see :func:`run_method`), a registered map name
    (:func:`occgp.maps.available_maps`), built with its default
    parameters, or a dict ``{"map": name, **params}``, built by
    :func:`occgp.maps.make_map` (an optional key ``"insert"`` holds
    options every ``insert_scan`` call gets, e.g. ``{"map": "octree",
    "resolution": 0.1, "insert": {"mode": "ray"}}``). A sequence of
    registered map names stands for ``{name: name, ...}``. Every entry is
    checked before any map is built.
scans : iterable of (points, origin)
    The scans to insert.
test_set : TestSet or (points, labels)
    Where to score the maps.""",
    "methods_type_error": """TypeError
    If `methods` is neither a mapping nor a sequence of str, or one of
    its values is neither callable, a str nor a dict.""",
}


class TestSet(NamedTuple):
    """Labelled test points.

    Attributes
    ----------
    points : ndarray of shape (n_points, 3)
        Test locations in the world frame, in metres.
    labels : ndarray of bool, shape (n_points,)
        ``True`` where the point is occupied.
    """

    points: NDArray[np.float64]
    labels: NDArray[np.bool_]


TestSet.__test__ = False  # type: ignore[attr-defined]  # pytest: not a test class


class MapResult(NamedTuple):
    """One row of a comparison: a method's scores and costs.

    Attributes
    ----------
    method : str
        Name of the method.
    auc, mse, acc_occupied, acc_free, tpr_fdr_auc, n_test, unknown_fraction
        Scores of :func:`occgp.metrics.score_all` on the test set.
    seconds : float
        Total time spent in ``insert_scan`` calls.
    n_scans, n_points : int
        Scans and points inserted.
    data_fraction : float
        Fraction of each scan's points used (1.0 unless reduced by
        :func:`equal_time_comparison`).
    map : object
        The built map; not part of tables or records.
    """

    method: str
    auc: float
    mse: float
    acc_occupied: float
    acc_free: float
    tpr_fdr_auc: float
    seconds: float
    n_scans: int
    n_points: int
    n_test: int
    unknown_fraction: float
    data_fraction: float = 1.0
    map: Any = None


# ----------------------------------------------------------------- validation
def _check_scans(scans):
    """Return ``[(points, origin, template), ...]``; template is a NamedTuple or None."""
    if isinstance(scans, (str, bytes, np.ndarray)) or not isinstance(scans, Iterable):
        raise TypeError(f"scans must be a sequence of (points, origin) pairs, "
                        f"got {type(scans).__name__}")
    out = []
    for i, scan in enumerate(scans):
        named = isinstance(scan, tuple) and hasattr(type(scan), "_fields")
        if isinstance(scan, (str, bytes)) or not isinstance(scan, Sequence):
            raise TypeError(f"scans[{i}] must be a (points, origin) pair, "
                            f"got {type(scan).__name__}")
        if len(scan) != 2 and not (named and len(scan) > 2):
            raise ValueError(f"scans[{i}] must be a (points, origin) pair, "
                             f"got a sequence of length {len(scan)}")
        points = as_points(scan[0], f"scans[{i}].points")
        if points.shape[0] == 0:
            raise ValueError(f"scans[{i}].points must hold at least one point, got 0")
        out.append((points, as_point(scan[1], f"scans[{i}].origin"), scan if named else None))
    if not out:
        raise ValueError("scans must hold at least one scan, got 0")
    return out


def _make_scan(points, origin, template):
    """A scan of the caller's type: the NamedTuple given, else a tuple."""
    if template is None:
        return (points, origin)
    fields = type(template)._fields
    return template._replace(**{fields[0]: points, fields[1]: origin})


def _as_test_set(test_set):
    if isinstance(test_set, (str, bytes)) or not isinstance(test_set, Sequence):
        raise TypeError(f"test_set must be a TestSet or a (points, labels) pair, "
                        f"got {type(test_set).__name__}")
    if len(test_set) != 2:
        raise ValueError(f"test_set must be a TestSet or a (points, labels) pair, "
                         f"got a sequence of length {len(test_set)}")
    points = as_points(test_set[0], "test_set.points")
    labels = np.asarray(test_set[1])
    if labels.shape != (points.shape[0],):
        raise ValueError(f"test_set.labels must have shape ({points.shape[0]},) to match "
                         f"test_set.points, got {labels.shape}")
    return TestSet(points, labels)


def disable_bar(progress):
    return None if progress is None else not progress


# ------------------------------------------------------------------ test sets
def held_out_split(scans: Iterable[Sequence[Any]], *, fraction: float = 0.2,
                   free_margin: float = 0.3, seed: int | np.random.Generator | None = 0,
                   ) -> tuple[list[Any], TestSet]:
    """Split real scans into training scans and a held-out test set.

    The protocol of Kwon's dissertation (§2.4.2) for data without ground
    truth. For each scan in order, ``round(fraction * n_points)`` of its
    points (at most ``n_points - 1``) are held out at random; the training
    scan keeps the others, in order, with the same origin. Each held-out end
    point is an occupied test point, and gives one free test point drawn
    uniformly on its ray between the origin and `free_margin` metres before
    the end point; a ray not longer than `free_margin` gives none.

    Parameters
    ----------
    scans : iterable of (points, origin)
        Scans with `points` of shape (n_points, 3) and `origin` of shape
        (3,), e.g. :class:`occgp.datasets.Scan`.
    fraction : float, default=0.2
        Fraction of each scan's points held out, in (0, 1).
    free_margin : float, default=0.3
        Distance in metres kept between a free test point and its end point.
    seed : int, numpy.random.Generator or None, default=0
        Seed of the one generator drawn from over all scans in order.

    Returns
    -------
    train_scans : list
        Training scans of the type given (NamedTuples are rebuilt with
        ``_replace``, other pairs come back as tuples).
    test_set : TestSet
        All occupied test points in scan order, then the free ones in the
        same order.

    Raises
    ------
    ValueError
        If a scan is malformed or empty, `fraction` is not in (0, 1) or
        `free_margin` is negative.
    TypeError
        If `scans` or one of its items is not a sequence.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> scan = (rng.uniform(1, 5, size=(100, 3)), np.zeros(3))
    >>> train, test = held_out_split([scan], fraction=0.2, seed=0)
    >>> len(train[0][0]), int(test.labels.sum()), int((~test.labels).sum())
    (80, 20, 20)
    """
    fraction = check_real(fraction, "fraction", low=0.0, high=1.0)
    free_margin = check_real(free_margin, "free_margin", low=0.0, low_open=False)
    checked = _check_scans(scans)
    rng = check_seed(seed)
    train, occupied, free = [], [], []
    for points, origin, template in checked:
        n = points.shape[0]
        held = np.zeros(n, dtype=bool)
        held[rng.permutation(n)[:min(math.floor(fraction * n + 0.5), n - 1)]] = True
        rays = points[held] - origin
        length = np.linalg.norm(rays, axis=1)
        u = rng.uniform(size=length.shape[0])
        ok = length > free_margin
        scale = u[ok] * (length[ok] - free_margin) / length[ok]
        free.append(origin + scale[:, None] * rays[ok])
        occupied.append(points[held])
        train.append(_make_scan(points[~held], origin, template))
    occ, fre = np.concatenate(occupied), np.concatenate(free)
    _logger.info("held-out split: %d scans, %d occupied and %d free test points",
                 len(train), len(occ), len(fre))
    labels = np.r_[np.ones(len(occ), dtype=bool), np.zeros(len(fre), dtype=bool)]
    return train, TestSet(np.concatenate([occ, fre]), labels)


def grid_test_set(scene: Any, resolution: float, *,
                  bbox: tuple[ArrayLike, ArrayLike] | None = None,
                  observed: Callable[[NDArray[np.float64]], ArrayLike] | None = None,
                  ) -> TestSet:
    """Ground-truth test points on a regular grid of a synthetic scene.

    The points are the centers ``(k + 0.5) * resolution`` (k integer) of the
    lattice aligned with the world origin, i.e. the cell centers of an
    octree or grid map of that resolution, that lie in the closed box; an axis
    too thin to hold one gets the single coordinate of its middle. Labels
    are ``scene.occupancy(centers)``.

    Parameters
    ----------
    scene : object
        Ground truth with ``occupancy(points) -> bool ndarray`` and
        ``bounds -> (min (3,), max (3,))``.
    resolution : float
        Grid spacing in metres, > 0.
    bbox : (array-like of shape (3,), array-like of shape (3,)), optional
        Box ``(min, max)`` to cover instead of ``scene.bounds``.
    observed : callable, optional
        ``observed(points) -> bool array of shape (n_points,)`` keeping only
        the centers it marks ``True`` (e.g. cells within sensor range).
        Default: keep all.

    Returns
    -------
    test_set : TestSet
        Grid centers (z varying fastest, then y, then x) and their labels.

    Raises
    ------
    ValueError
        If `resolution` is not positive, the box is malformed or would hold
        more than 50 million points, or `scene.occupancy` or `observed`
        returns the wrong shape.

    Examples
    --------
    >>> class Slab:
    ...     bounds = (np.zeros(3), np.ones(3))
    ...     def occupancy(self, points):
    ...         return points[:, 2] < 0.5
    >>> test = grid_test_set(Slab(), 0.5)
    >>> test.points.shape, int(test.labels.sum())
    ((8, 3), 4)
    """
    resolution = check_real(resolution, "resolution", low=0.0)
    name = "scene.bounds" if bbox is None else "bbox"
    box = scene.bounds if bbox is None else bbox
    if len(box) != 2:
        raise ValueError(f"{name} must be a (min, max) pair, got length {len(box)}")
    lo, hi = as_point(box[0], f"{name}[0]"), as_point(box[1], f"{name}[1]")
    if (lo > hi).any():
        raise ValueError(f"{name} must have min <= max on every axis, got {lo} and {hi}")
    # the closed box, up to round-off: count the centers before making them
    first = [math.ceil(lo[a] / resolution - 0.5 - 1e-9) for a in range(3)]
    last = [math.floor(hi[a] / resolution - 0.5 + 1e-9) for a in range(3)]
    counts = [max(last[a] - first[a] + 1, 1) for a in range(3)]
    n = math.prod(counts)
    if n > _MAX_GRID_POINTS:
        raise ValueError(f"the grid would hold {' x '.join(map(str, counts))} points (more "
                         f"than {_MAX_GRID_POINTS}); increase resolution or give a smaller "
                         "bbox")
    axes = []
    for a in range(3):
        k = np.arange(first[a], last[a] + 1)
        axes.append((k + 0.5) * resolution if k.size else np.array([(lo[a] + hi[a]) / 2]))
    centers = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    if observed is not None:
        keep = np.asarray(observed(centers), dtype=bool)
        if keep.shape != (n,):
            raise ValueError(f"observed(points) must return shape ({n},), got {keep.shape}")
        centers = centers[keep]
    labels = np.asarray(scene.occupancy(centers), dtype=bool)
    if labels.shape != (len(centers),):
        raise ValueError(f"scene.occupancy(points) must return shape ({len(centers)},), "
                         f"got {labels.shape}")
    return TestSet(np.ascontiguousarray(centers), labels)


# ------------------------------------------------------------------- scoring
def _evaluate(map_, test_set):
    prob = np.asarray(map_.occupancy(test_set.points), dtype=np.float64)
    if prob.shape != (len(test_set.points),):
        raise ValueError(f"map.occupancy(points) must return shape "
                         f"({len(test_set.points)},), got {prob.shape}")
    return score_all(test_set.labels, prob)


def evaluate_map(map: Any, test_set: TestSet | Sequence[Any]) -> dict[str, float]:
    """Score a built map on a test set.

    Calls ``map.occupancy(test_set.points)`` and scores the answer with
    :func:`occgp.metrics.score_all` (NaN, i.e. unknown, counts as p = 0.5).

    Parameters
    ----------
    map : object
        A map with ``occupancy(points) -> ndarray of shape (n_points,)``.
    test_set : TestSet or (points, labels)
        Test points of shape (n_points, 3) and their boolean labels.

    Returns
    -------
    scores : dict
        See :func:`occgp.metrics.score_all`.

    Raises
    ------
    ValueError
        If the test set is malformed or holds one class only, or the map
        answers with the wrong shape or values outside [0, 1].

    Examples
    --------
    >>> class HalfSpace:
    ...     def occupancy(self, points):
    ...         return np.where(points[:, 0] > 0, 0.9, 0.1)
    >>> test = TestSet(np.array([[1.0, 0, 0], [-1.0, 0, 0]]), np.array([True, False]))
    >>> evaluate_map(HalfSpace(), test)["auc"]
    1.0
    """
    return _evaluate(map, _as_test_set(test_set))


def _run(name, method, checked, test_set, progress, data_fraction=1.0):
    factory, options = method
    map_ = factory()
    seconds, n_points = 0.0, 0
    for points, origin, _ in tqdm(checked, desc=str(name), unit="scan",
                                  disable=disable_bar(progress), leave=False):
        t0 = _clock()
        map_.insert_scan(points, origin, **options)
        seconds += _clock() - t0
        n_points += len(points)
    sc = _evaluate(map_, test_set)
    _logger.info("%s (%.0f%% of the data): %d scans, %d points in %.3f s, AUC %.3f",
                 name, 100 * data_fraction, len(checked), n_points, seconds, sc["auc"])
    return MapResult(str(name), sc["auc"], sc["mse"], sc["acc_occupied"], sc["acc_free"],
                     sc["tpr_fdr_auc"], seconds, len(checked), n_points, sc["n_test"],
                     sc["unknown_fraction"], data_fraction, map_)


def map_factory(name, spec, dim=3):
    """(``make_map`` bound to a registered map name, or to ``{"map": name, "insert":
    options, **params}``, and the options of its ``insert_scan``); the name, the
    points' dimension and the parameter names checked now."""
    options: dict = {}
    if isinstance(spec, str):
        map_name, params = spec, {}
    else:
        params = dict(spec)
        if "map" not in params:
            raise ValueError(f"the dict of method {name!r} must hold the key 'map' (a "
                             f"registered map name), got keys {list(params)}")
        map_name = params.pop("map")
        options = params.pop("insert", {})
        if not isinstance(options, Mapping) or not all(isinstance(k, str) for k in options):
            raise TypeError(f"the 'insert' of method {name!r} must be a mapping of "
                            f"insert_scan options by name, got {type(options).__name__}")
        options = dict(options)
        if not isinstance(map_name, str):
            raise TypeError(f"the 'map' of method {name!r} must be a registered map name "
                            f"(str), got {type(map_name).__name__}")
    try:
        entry = map_type(map_name)
    except ValueError:
        raise ValueError(f"method {name!r}: unknown map type {map_name!r}; available: "
                         f"{', '.join(available_maps())}") from None
    if dim not in entry.dims:
        raise ValueError(f"method {name!r}: the {map_name!r} map takes points of "
                         f"{' or '.join(map(str, entry.dims))} dimensions, the scans here "
                         f"are {dim}D; {dim}D maps: {', '.join(available_maps(dims=dim))}")
    try:
        entry.check_params(params)
    except ValueError as exc:
        raise ValueError(f"method {name!r}: {exc}") from None
    return functools.partial(make_map, map_name, **params), options


def _check_methods(methods):
    """The methods as ``{name: factory}``, in order; every spec checked before any
    map is built."""
    if isinstance(methods, Mapping):
        items = list(methods.items())
    elif (isinstance(methods, Sequence) and not isinstance(methods, (str, bytes))
          and all(isinstance(m, str) for m in methods)):
        items = [(m, m) for m in methods]
        twice = sorted({m for m in methods if methods.count(m) > 1})
        if twice:
            raise ValueError(f"methods must name each map type once, got {twice} "
                             "more than once (give a mapping of name -> spec to compare "
                             "one type with several parameters)")
    else:
        held = ""
        if isinstance(methods, Sequence) and not isinstance(methods, (str, bytes)):
            held = next(f" holding {type(m).__name__}" for m in methods
                        if not isinstance(m, str))
        raise TypeError(f"methods must be a mapping of name -> factory, map name or "
                        f"{{'map': name, ...}} dict, or a sequence of registered map "
                        f"names, got {type(methods).__name__}{held}")
    if not items:
        raise ValueError("methods must hold at least one method, got none")
    factories = {}
    for name, spec in items:
        if callable(spec):
            factories[name] = (spec, {})
        elif isinstance(spec, (str, Mapping)):
            factories[name] = map_factory(name, spec)
        else:
            raise TypeError(f"the factory of method {name!r} must be callable, got "
                            f"{type(spec).__name__} (or give a registered map name or a "
                            "{'map': name, ...} dict)")
    return factories


def run_method(name: str, factory: MethodSpec, scans: Iterable[Sequence[Any]],
               test_set: TestSet | Sequence[Any], *, progress: bool | None = None,
               ) -> MapResult:
    """Build one map from the scans, timing its updates, and score it.

    ``factory()`` is called once for a fresh empty map (a registered map
    name, or a ``{"map": name, **params}`` dict, is built with
    :func:`occgp.maps.make_map`); every scan is inserted in order and only
    the ``insert_scan`` calls are timed (:func:`time.perf_counter`). Scans
    are validated and converted to float64 before the clock runs.

    Parameters
    ----------
    name : str
        Name of the method, for the row and the progress bar.
    factory : callable, str or dict
        ``factory() -> map``, a new empty map; or a registered map name
        (:func:`occgp.maps.available_maps`), built with its default
        parameters; or a dict ``{"map": name, **params}``, built by
        ``make_map(name, **params)``.
    scans : iterable of (points, origin)
        The scans to insert.
    test_set : TestSet or (points, labels)
        Where to score the final map.
    progress : bool or None, default=None
        Show a progress bar over scans; None shows it only on a terminal.

    Returns
    -------
    result : MapResult
        Scores, seconds, counts and the built map.

    Raises
    ------
    ValueError
        If a scan or the test set is malformed, or `factory` names a map type
        that is not registered (the message lists
        :func:`occgp.maps.available_maps`), does not take 3D points, or does
        not take a parameter given or needs one not given.
    TypeError
        If `factory` is neither callable, a str nor a dict, or a dict's
        ``"map"`` is not a str.

    Examples
    --------
    >>> class Constant:
    ...     def insert_scan(self, points, origin):
    ...         return self
    ...     def occupancy(self, points):
    ...         return np.full(len(points), 0.5)
    >>> scans = [(np.ones((10, 3)), np.zeros(3))]
    >>> test = TestSet(np.eye(3), np.array([True, False, False]))
    >>> row = run_method("constant", Constant, scans, test, progress=False)
    >>> row.method, row.auc, row.n_points
    ('constant', 0.5, 10)
    >>> row = run_method("knn", {"map": "knn", "resolution": 0.5}, scans, test,
    ...                  progress=False)
    >>> type(row.map).__name__, row.map.resolution
    ('KNNMap', 0.5)
    """
    factory = _check_methods({name: factory})[name]
    return _run(name, factory, _check_scans(scans), _as_test_set(test_set), progress)


@fill_doc(**_METHODS_SECTIONS)
def compare_methods(methods: Mapping[str, MethodSpec] | Sequence[str],
                    scans: Iterable[Sequence[Any]], test_set: TestSet | Sequence[Any],
                    *, progress: bool | None = None) -> list[MapResult]:
    """Build and score every method on the same scans and test set.

    Parameters
    ----------
    {methods_params}
    progress : bool or None, default=None
        Show progress bars; None shows them only on a terminal.

    Returns
    -------
    rows : list of MapResult
        One row per method, in the order of `methods`.

    Raises
    ------
    ValueError
        If `methods` is empty or names a map type twice, a map type is not
        registered (the message lists :func:`occgp.maps.available_maps`),
        does not take 3D points, or does not take a parameter given or needs
        one not given, or a scan or the test set is malformed.
    {methods_type_error}

    See Also
    --------
    equal_time_comparison : The same under one time budget.
    format_table : Print the rows.
    occgp.maps.make_map : Build a registered map.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> wall = np.column_stack([np.full(300, 2.0), rng.uniform(-1, 1, (300, 2))])
    >>> train, test = held_out_split([(wall, np.zeros(3))], seed=0)
    >>> rows = compare_methods(["bgk", "knn"], train, test, progress=False)
    >>> [r.method for r in rows]
    ['bgk', 'knn']
    >>> rows = compare_methods({"fine": {"map": "bgk", "resolution": 0.1},
    ...                         "coarse": {"map": "bgk", "resolution": 0.4}},
    ...                        train, test, progress=False)
    >>> [(r.method, r.map.resolution) for r in rows]
    [('fine', 0.1), ('coarse', 0.4)]
    """
    methods = _check_methods(methods)
    checked, test_set = _check_scans(scans), _as_test_set(test_set)
    return [_run(name, f, checked, test_set, progress) for name, f in methods.items()]


@fill_doc(**_METHODS_SECTIONS)
def equal_time_comparison(methods: Mapping[str, MethodSpec] | Sequence[str],
                          scans: Iterable[Sequence[Any]],
                          test_set: TestSet | Sequence[Any], *, step: float = 0.05,
                          seed: int | np.random.Generator | None = 0,
                          max_rounds: int | None = None,
                          full_rows: Sequence[MapResult] | None = None,
                          progress: bool | None = None) -> list[MapResult]:
    """Compare methods given the same update time (AKIMap §3.4.1).

    Every method is first timed on all the data; the fastest time is the
    budget. Each slower method is rebuilt on less data, dropping `step`
    (5%) of each scan's points per round, until its update time is at most
    the budget. The subsets are nested and the same for every method: one
    random permutation per scan is drawn from `seed`, and a fraction f keeps
    the first ``round(f * n_points)`` of it (at least one point), in the
    scan's order.

    Parameters
    ----------
    {methods_params}
    step : float, default=0.05
        Fraction of the data dropped per round, in (0, 1).
    seed : int, numpy.random.Generator or None, default=0
        Seed of the subsampling.
    max_rounds : int, optional
        At most this many rounds per method; by default until the fraction
        would reach zero. A method still over budget then keeps its last
        row, and a warning is logged.
    full_rows : sequence of MapResult, optional
        Rows of :func:`compare_methods` on the same data, reused as the
        all-data measurement instead of timing it again.
    progress : bool or None, default=None
        Show progress bars; None shows them only on a terminal.

    Returns
    -------
    rows : list of MapResult
        One row per method in the order of `methods`, with the fraction of
        the data used in ``data_fraction`` (1.0 for methods within budget).

    Raises
    ------
    ValueError
        If `step` is not in (0, 1), `max_rounds` is negative, `full_rows`
        misses a method, a map name or its parameters are rejected (see
        :func:`compare_methods`), or the input is malformed.
    {methods_type_error}

    Notes
    -----
    Each fraction is timed once, so with noisy clocks a method close to the
    budget may stop one step early or late.
    """
    methods = _check_methods(methods)
    step = check_real(step, "step", low=0.0, high=1.0)
    if max_rounds is not None and (isinstance(max_rounds, bool) or not isinstance(
            max_rounds, (int, np.integer)) or max_rounds < 0):
        raise ValueError(f"max_rounds must be a non-negative integer, got {max_rounds!r}")
    checked, test_set = _check_scans(scans), _as_test_set(test_set)
    if full_rows is None:
        full = {n: _run(n, f, checked, test_set, progress) for n, f in methods.items()}
    else:
        given = {r.method: r for r in full_rows}
        missing = [str(n) for n in methods if str(n) not in given]
        if missing:
            raise ValueError(f"full_rows must hold a row for every method, missing {missing}")
        full = {n: given[str(n)] for n in methods}
    budget = min(r.seconds for r in full.values())
    rng = check_seed(seed)
    perms = [rng.permutation(len(p)) for p, _, _ in checked]
    n_rounds = math.ceil(round(1.0 / step, 9)) - 1
    if max_rounds is not None:
        n_rounds = min(n_rounds, int(max_rounds))
    rows = []
    for name, factory in methods.items():
        row, k = full[name], 0
        while row.seconds > budget and k < n_rounds:
            k += 1
            frac = round(1.0 - k * step, 12)
            subset = [(p[np.sort(perm[:max(1, math.floor(frac * len(p) + 0.5))])], o, t)
                      for (p, o, t), perm in zip(checked, perms)]
            row = _run(name, factory, subset, test_set, progress, data_fraction=frac)
        if row.seconds > budget:
            _logger.warning("%s: %.3f s on %.0f%% of the data, still over the budget "
                            "of %.3f s", name, row.seconds, 100 * row.data_fraction, budget)
        rows.append(row)
    return rows
