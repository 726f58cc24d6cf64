"""Parameter search for the log-odds maps: every combination of a grid, replayed.

:func:`grid_search` scores each parameter combination of the k-NN model
(:class:`occgp.KNNMap`) or of OctoMap by the area under its TPR–FDR curve
against ground truth, as Miao, Hunter and Georgilas do: the map's cells are
classified at each occupancy threshold of a grid, giving one
operating point (FDR, TPR) per threshold. The maps are not built one by one:
a :class:`occgp.knn.ScanReplay` holds what they share and replays each
combination exactly (see there).
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Iterable, Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np
from joblib import Parallel, delayed

from .._params import DEFAULT_RESOLUTION, check_renamed
from .._validation import check_choice, check_int, check_n_jobs, check_real, n_threads
from ..knn import (
    CDFS, MAX_HISTORY, STATS, KNNMap, ScanReplay, check_knn_params, check_octomap_params,
)
from . import _matching
from ._ground_truth import cell_labels
from ._tpr_fdr import tpr_fdr_area, tpr_fdr_auc_unchecked

__all__ = ["grid_search", "GridSearchResult", "KNN_GRID", "OCTOMAP_GRID", "KNN_WEIGHT_GRID",
           "THRESHOLDS"]


def _threshold_log_odds(p: float) -> float:
    """liboctomap's ``logodds``, ``(float) log(p / (1 - p))``: the log-odds the maps'
    cells are compared with (libm's log, rounded to float32)."""
    return float(np.float32(math.log(p / (1.0 - p))))


def _steps(low: float, high: float, step: float) -> tuple[float, ...]:
    """The paper's parameter set {low + (i - 1) step} up to `high` (rounded to 1e-9)."""
    n = int(math.floor((high - low) / step + 1e-9)) + 1
    return tuple(round(low + i * step, 9) for i in range(n))


#: The occupancy thresholds (the paper's p_t) of Miao et al.'s Table 1: 0.02 to 0.98 by 0.12.
THRESHOLDS = _steps(0.02, 0.98, 0.12)
#: Miao et al.'s Table 1, optimisation (k and the clamping fixed): with the
#: constraints of Eq. 12 and the 9 thresholds, 4,050 combinations.
KNN_GRID = {"k": (1,), "p_u": _steps(0.02, 0.98, 0.12), "p_l": _steps(0.02, 0.98, 0.12),
            "p_m": _steps(0.02, 0.38, 0.12), "p_m_out": _steps(0.02, 0.38, 0.12),
            "p_min": (0.02,), "p_max": (0.98,)}
#: OctoMap's grid of the same table: with the 9 thresholds, 180 combinations.
OCTOMAP_GRID = {"prob_hit": _steps(0.5, 0.98, 0.12), "prob_miss": _steps(0.02, 0.38, 0.12), "clamping_min": (0.02,),
                "clamping_max": (0.98,)}
#: Table 1's grid for the parameter weights (k, p_max and p_min varied too).
KNN_WEIGHT_GRID = {"k": (1, 3, 5, 7), "p_u": _steps(0.02, 0.98, 0.12),
                   "p_l": _steps(0.02, 0.98, 0.12), "p_m": _steps(0.02, 0.38, 0.12),
                   "p_m_out": _steps(0.02, 0.38, 0.12), "p_min": _steps(0.02, 0.38, 0.12),
                   "p_max": _steps(0.5, 0.98, 0.12)}
_KNN_KEYS = ("k", "p_u", "p_l", "p_m", "p_m_out", "p_min", "p_max")
_SCORE_KEYS = ("auc", "auc_exact", "thresholds", "tpr", "fdr")
SCORINGS = ("exact", "authors")
_OCTOMAP_KEYS = ("prob_hit", "prob_miss", "clamping_min", "clamping_max")


class GridSearchResult(NamedTuple):
    """The result of :func:`grid_search`.

    Attributes
    ----------
    results : list of dict
        One row per parameter combination (constraints met), in grid order:
        its parameters, ``auc`` (area under the TPR–FDR curve, by the
        search's `scoring` and `mask`), and ``thresholds``, ``tpr``, ``fdr``
        (tuples, one entry per threshold with a defined FDR, decreasing
        thresholds). When the search scored otherwise than occgp's strict
        protocol (``scoring="authors"`` or a `mask`), also ``auc_exact``: the
        strict protocol's area (exact cells, every reached cell, anchored).
    best_params : dict
        The parameters of the row with the highest ``auc`` (the first on ties).
    best_score : float
        Its ``auc``.
    best_index : int
        Its row.
    n_rejected : int
        Combinations of the grid dropped by the constraints.
    seconds : float
        Wall time of the search (the replay's set-up included when the search
        made it).
    scoring : str
        ``"exact"`` (occgp's strict protocol) or ``"authors"`` (Miao et al.'s
        ±1-cell rule and unanchored area), as :func:`grid_search` scored.
    masked : bool
        Whether only the cells of a `mask` were scored.
    """

    results: list[dict[str, Any]]
    best_params: dict[str, Any]
    best_score: float
    best_index: int
    n_rejected: int
    seconds: float
    scoring: str = "exact"
    masked: bool = False

    def operating_points(self) -> list[dict[str, Any]]:
        """One row per (combination, threshold) of the search.

        Returns
        -------
        rows : list of dict
            The combination's parameters, ``occupancy_threshold``, ``tpr`` and
            ``fdr``: e.g. the
            samples of :func:`occgp.evaluation.nca_feature_weights`.
        """
        rows = []
        for row in self.results:
            params = {k: v for k, v in row.items() if k not in _SCORE_KEYS}
            for t, tpr, fdr in zip(row["thresholds"], row["tpr"], row["fdr"]):
                rows.append({**params, "occupancy_threshold": t, "tpr": tpr, "fdr": fdr})
        return rows


def _combinations(param_grid, keys, defaults):
    grids = [param_grid] if isinstance(param_grid, Mapping) else list(param_grid)
    if not grids:
        raise ValueError("param_grid must be a dict of parameter lists, or a list of them")
    combos = []
    for g, grid in enumerate(grids):
        if not isinstance(grid, Mapping):
            raise TypeError(f"param_grid must be a dict or a list of dicts, got "
                            f"{type(grid).__name__} at {g}")
        unknown = sorted(set(grid) - set(keys))
        if unknown:
            raise ValueError(f"param_grid holds unknown parameters {unknown}; this method "
                             f"takes {list(keys)}")
        values = []
        for key in keys:
            v = grid.get(key, (defaults[key],))
            if isinstance(v, (str, bytes)) or not np.iterable(v):
                v = (v,)
            v = list(v)
            if not v:
                raise ValueError(f"param_grid[{key!r}] is empty")
            values.append(v)
        combos.extend(dict(zip(keys, c)) for c in itertools.product(*values))
    return combos


def _curve(values, labels, thresholds):
    """TPR and FDR at each threshold (log-odds, float32), NaN FDR dropped."""
    pos = labels.sum()
    tpr, fdr, kept = [], [], []
    for t, lt in thresholds:
        occ = values >= lt
        tp = int(np.count_nonzero(occ & labels))
        n = int(np.count_nonzero(occ))
        if n == 0:
            continue
        tpr.append(tp / pos)
        fdr.append((n - tp) / n)
        kept.append(t)
    return kept, tpr, fdr


def _authors_curve(values, scorer, thresholds):
    """TPR and FDR at each threshold by the authors' ±1-cell one-to-one rule over the
    scored cells (NaN FDR dropped)."""
    rows, table, n_ref, ref_scored = (scorer["rows"], scorer["table"], scorer["n_ref"],
                                      scorer["ref_scored"])
    v = values[rows]
    tpr, fdr, kept = [], [], []
    for t, lt in thresholds:
        active = v >= lt
        n = int(np.count_nonzero(active))
        if n == 0:
            continue
        tp = int(np.count_nonzero(_matching.greedy_matches(table, active, n_ref)))
        fn = int(np.count_nonzero(ref_scored & ~active))
        tpr.append(tp / (tp + fn))
        fdr.append((n - tp) / n)
        kept.append(t)
    return kept, tpr, fdr


def _score_row(values, labels, scorer, ts):
    """The row's scores: ``auc``, the curve, and ``auc_exact`` when not strict."""
    if ts is None:
        prob = 1.0 - 1.0 / (1.0 + np.exp(values.astype(np.float64)))
        mask = scorer["mask"]
        if mask is None:
            return {"auc": tpr_fdr_auc_unchecked(labels, prob), "thresholds": (), "tpr": (),
                    "fdr": ()}
        return {"auc": tpr_fdr_auc_unchecked(labels[mask], prob[mask]),
                "auc_exact": tpr_fdr_auc_unchecked(labels, prob), "thresholds": (),
                "tpr": (), "fdr": ()}
    kept, tpr, fdr = _curve(values, labels, ts)
    exact = {"auc": tpr_fdr_area(fdr, tpr), "thresholds": tuple(kept), "tpr": tuple(tpr),
             "fdr": tuple(fdr)}
    if scorer["scoring"] == "exact" and scorer["mask"] is None:
        return exact
    if scorer["scoring"] == "exact":
        mask = scorer["mask"]
        kept, tpr, fdr = _curve(values[mask], labels[mask], ts)
        area = tpr_fdr_area(fdr, tpr)
    else:
        kept, tpr, fdr = _authors_curve(values, scorer, ts)
        area = tpr_fdr_area(fdr, tpr, anchored=False)
    return {"auc": area, "auc_exact": exact["auc"], "thresholds": tuple(kept),
            "tpr": tuple(tpr), "fdr": tuple(fdr)}


def _score_chunk(replay, labels, method, combos, thresholds, batch_size, scorer):
    rows = []
    for start in range(0, len(combos), batch_size):
        batch = combos[start:start + batch_size]
        if method == "knn":
            values = replay.knn_log_odds(batch)
            bounds = [(p["p_min"], p["p_max"]) for p in batch]
        else:
            values = replay.octomap_log_odds(batch)
            bounds = [(p["clamping_min"], p["clamping_max"]) for p in batch]
        for b, params in enumerate(batch):
            lo, hi = bounds[b]
            ts = None if thresholds is None else [
                (t, np.float32(_threshold_log_odds(t)))
                for t in sorted(thresholds, reverse=True) if lo - 1e-12 <= t <= hi + 1e-12]
            rows.append({**params, **_score_row(values[b], labels, scorer, ts)})
    return rows


def _make_scorer(replay, labels, mask, scoring, thresholds):
    """What scoring needs besides a map's values: the mask, and for the authors' rule
    the neighbour table of the scored cells (built once for the whole search)."""
    if mask is not None:
        mask = np.asarray(mask)
        if mask.dtype != bool:
            raise TypeError(f"mask must be booleans over the replay's cells, got dtype "
                            f"{mask.dtype}")
        if mask.shape != (replay.num_cells,):
            raise ValueError(f"mask must have shape ({replay.num_cells},) (the replay's "
                             f"cells), got {mask.shape}")
        if not (labels & mask).any():
            raise ValueError("mask holds no occupied cell of truth: the TPR is undefined")
    scorer: dict[str, Any] = {"mask": mask, "scoring": scoring}
    if scoring == "authors":
        if thresholds is None:
            raise ValueError("thresholds=None (every distinct value) is not available with "
                             "scoring='authors': give the thresholds")
        rows = np.flatnonzero(mask) if mask is not None else np.arange(replay.num_cells)
        reference = replay.keys[labels]
        scorer.update(rows=rows, n_ref=len(reference), ref_scored=labels[rows],
                      table=_matching.neighbour_table(replay.keys[rows], reference))
    return scorer


def grid_search(scans: ScanReplay | Iterable[Sequence[Any]], truth: Any,
                param_grid: Mapping[str, Sequence[Any]] | Sequence[Mapping[str, Sequence[Any]]],
                *, method: str = "knn", resolution: float = DEFAULT_RESOLUTION,
                max_range: float = 4.0,
                thresholds: Sequence[float] | None = THRESHOLDS, mask: Any = None,
                scoring: str = "exact", cdf: str | None = None, stats: str | None = None,
                history: int | None = None, batch_size: int = 32,
                n_jobs: int | None = None, **deprecated: Any) -> GridSearchResult:
    """Score every combination of a parameter grid by its map's TPR–FDR AUC.

    Miao et al.'s search: each combination's map (:class:`occgp.KNNMap` for
    ``method="knn"``, OctoMap's ``insertPointCloud`` with the same
    ``max_range`` for ``"octomap"``) is built from the scans, every cell it
    holds is classified at each occupancy threshold of `thresholds` within the
    clamping bounds (``p_min <= threshold <= p_max``), and the operating points
    (FDR, TPR) give the curve's area. The maps are replayed from a
    :class:`~occgp.knn.ScanReplay` (exactly the maps the classes build), so
    the scans are traversed and scored by k-NN once for the whole grid.

    Parameters
    ----------
    scans : ScanReplay or iterable of (points, origin)
        The data set; scans are made into a ``ScanReplay(scans, resolution,
        max_range=max_range, ks=<the grid's k values>)``. Pass a
        ScanReplay to share it between searches (its resolution and range
        then apply, and its ks must hold the grid's).
    truth : array-like of bool of shape (n_cells,), or a scene
        Ground truth of the replay's cells (:attr:`ScanReplay.keys` order), or
        an object with ``occupancy(points)`` labelled by :func:`cell_labels`.
        Must hold an occupied cell.
    param_grid : dict or list of dict
        Parameter name -> sequence of values, all combinations taken (a list
        of dicts: the union of their grids). ``"knn"`` takes ``k``, ``p_u``,
        ``p_l``, ``p_m``, ``p_m_out``, ``p_min``, ``p_max``; ``"octomap"``
        ``prob_hit``, ``prob_miss``, ``clamping_min``, ``clamping_max``. A
        parameter left out takes its default (:class:`occgp.KNNMap`,
        :class:`occgp.OccupancyOctree`). Combinations breaking the
        constraints (:func:`occgp.knn.check_knn_params`; OctoMap's parameter
        ranges) are dropped and counted. :data:`KNN_GRID` and
        :data:`OCTOMAP_GRID` are the paper's.
    method : {"knn", "octomap"}, default="knn"
    resolution : float, default=DEFAULT_RESOLUTION (0.1)
    max_range : float, default=4.0
        The sensor range, metres: longer rays are cut there (``KNNMap``'s and
        OctoMap's ``max_range``; the name ``sensor_range`` is deprecated).
    thresholds : sequence of float or None, default=THRESHOLDS
        The occupancy thresholds (probabilities) of each curve; None: every
        distinct value of the map (:func:`occgp.metrics.tpr_fdr_auc`; not with
        ``scoring="authors"``).
    mask : array-like of bool of shape (n_cells,) or None, default=None
        The cells to score (:attr:`ScanReplay.keys` order): a region, or the
        cells known in a reference map (the authors score only the cells known
        in both maps); None: every cell the scans reach. Must hold an occupied
        cell of `truth`.
    scoring : {"exact", "authors"}, default="exact"
        ``"exact"``, occgp's strict protocol: a cell predicted occupied is a
        true positive only if it is occupied itself, and the area is anchored
        at (0, 0) and (1, 1) (:func:`occgp.metrics.tpr_fdr_auc`).
        ``"authors"``, Miao et al.'s: true positives by the ±1-cell one-to-one
        rule of :func:`occgp.evaluation.matched_counts` (the reference's
        occupied cells: the replay's cells `truth` marks occupied), false
        negatives the exact occupied cells predicted free, and the area under
        the measured operating points only (``anchored=False``). Unless the
        search is strict (``"exact"`` without a `mask`), every row also holds
        ``auc_exact``, the strict protocol's area.
    cdf : {"normal", "truncated"} or None, default=None
        The score CDF of the k-NN maps (:class:`occgp.KNNMap`); None: the
        replay's (``"normal"`` when the search builds it). A ScanReplay given
        as `scans` must have been made with it.
    stats : {"online", "dataset"} or None, default=None
        The score statistics (:class:`occgp.knn.ScanReplay`): Welford's
        running ones or the whole data set's; None: the replay's
        (``"online"`` when the search builds it). As `cdf`.
    history : int or None, default=None
        The previous scans each point is scored against
        (:class:`occgp.KNNMap`'s ``history``; 0: its own scan, the paper's
        score); None: the replay's (0 when the search builds it). As `cdf`.
    batch_size : int, default=32
        Combinations replayed at once (memory: ``batch_size * n_cells * 8``
        bytes).
    n_jobs : int or None, default=None
        Workers through joblib (processes by default;
        ``joblib.parallel_config(backend="dask")`` spreads them over a dask
        cluster). The result does not depend on it.

    Returns
    -------
    result : GridSearchResult

    Raises
    ------
    ValueError
        For an unknown parameter, an empty grid or one with no combination
        left by the constraints, labels of the wrong shape or without an
        occupied cell, a `mask` of the wrong shape or without an occupied
        cell, a bad `method`, `thresholds`, `scoring`, `cdf`, `stats`,
        `history` or `batch_size`, or a `cdf`, `stats` or `history` that
        differs from the given ScanReplay's.
    TypeError
        If `truth` or `mask` is not of booleans, `thresholds` not a
        sequence, or `history` not an int.

    Examples
    --------
    >>> from occgp.datasets import StereoCamera, simulate_stereo, tetromino_scene
    >>> scene = tetromino_scene("O")
    >>> scans = simulate_stereo(scene, StereoCamera(48, 27), n_frames=3)
    >>> res = grid_search(scans, scene, {"p_u": [0.74, 0.98], "p_l": [0.26, 0.5]})
    >>> len(res.results), res.n_rejected, sorted(res.best_params)[:3]
    (4, 0, ['k', 'p_l', 'p_m'])
    """
    t0 = time.perf_counter()
    for name in deprecated:
        if name != "sensor_range":
            raise TypeError(f"grid_search() got an unexpected keyword argument {name!r}")
    if deprecated:
        max_range = check_renamed({"sensor_range": "max_range"},
                                  {"max_range": max_range, **deprecated}, {"max_range": 4.0},
                                  "grid_search")["max_range"]
    method = check_choice(method, "method", ("knn", "octomap"))
    scoring = check_choice(scoring, "scoring", SCORINGS)
    if cdf is not None:
        cdf = check_choice(cdf, "cdf", CDFS)
    if stats is not None:
        stats = check_choice(stats, "stats", STATS)
    if history is not None:
        history = check_int(history, "history", low=0, high=MAX_HISTORY)
    batch_size = check_int(batch_size, "batch_size", low=1, high=100_000)
    n_jobs = check_n_jobs(n_jobs)
    if thresholds is not None:
        if isinstance(thresholds, (str, bytes)) or not np.iterable(thresholds):
            raise TypeError("thresholds must be a sequence of probabilities or None")
        thresholds = tuple(check_real(t, f"thresholds[{i}]", low=0.0, high=1.0)
                           for i, t in enumerate(thresholds))
        if not thresholds:
            raise ValueError("thresholds must hold at least one threshold (or be None)")
    if method == "knn":
        d = KNNMap(resolution if not isinstance(scans, ScanReplay) else scans.resolution)
        defaults = {k: getattr(d, k) for k in ("k", "p_u", "p_l", "p_m", "p_m_out")}
        defaults.update(p_min=d.clamping_min, p_max=d.clamping_max)
        combos = _combinations(param_grid, _KNN_KEYS, defaults)
    else:
        defaults = dict(prob_hit=0.7, prob_miss=0.4, clamping_min=0.1192, clamping_max=0.971)
        combos = _combinations(param_grid, _OCTOMAP_KEYS, defaults)
    kept = []
    for c in combos:
        try:
            if method == "knn":
                q = check_knn_params({**c, "occupancy_threshold": c["p_min"],
                                      "max_range": max_range})
                kept.append({key: q[key] for key in _KNN_KEYS})
            else:
                kept.append(check_octomap_params(c))
        except ValueError:
            continue
    n_rejected = len(combos) - len(kept)
    if not kept:
        raise ValueError(f"no combination of param_grid meets the constraints "
                         f"({len(combos)} tried)")
    if isinstance(scans, ScanReplay):
        replay = scans
        for name, value in (("cdf", cdf), ("stats", stats), ("history", history)):
            if value is not None and value != getattr(replay, name):
                raise ValueError(f"{name}={value!r} differs from the ScanReplay's "
                                 f"({getattr(replay, name)!r}): make the replay with it")
    else:
        ks = sorted({c["k"] for c in kept}) if method == "knn" else [1]
        replay = ScanReplay(scans, resolution, max_range=max_range, ks=ks,
                            cdf=cdf or "normal", stats=stats or "online",
                            history=history or 0, n_jobs=n_jobs)
    if hasattr(truth, "occupancy"):
        labels = cell_labels(truth, replay.centers, replay.resolution)
    else:
        labels = np.asarray(truth)
        if labels.dtype.kind not in "biu":
            raise TypeError(f"truth must be booleans or a scene, got dtype {labels.dtype}")
        if labels.shape != (replay.num_cells,):
            raise ValueError(f"truth must have shape ({replay.num_cells},) (the replay's "
                             f"cells), got {labels.shape}")
        labels = labels.astype(bool)
    if not labels.any():
        raise ValueError(f"truth holds no occupied cell among the {replay.num_cells} cells "
                         "the scans reach: the TPR is undefined")
    scorer = _make_scorer(replay, labels, mask, scoring, thresholds)
    workers = n_threads(n_jobs)
    n_chunks = min(2 * workers, len(kept)) if workers > 1 else 1
    chunks = [kept[i::n_chunks] for i in range(n_chunks)]
    if n_chunks == 1:
        parts = [_score_chunk(replay, labels, method, kept, thresholds, batch_size, scorer)]
    else:
        parts = Parallel(n_jobs=n_jobs)(
            delayed(_score_chunk)(replay, labels, method, c, thresholds, batch_size, scorer)
            for c in chunks)
    # chunk i holds the combinations i, i + n_chunks, ...: back to grid order
    results: list[dict[str, Any]] = [{}] * len(kept)
    for i, rows in enumerate(parts):
        results[i::n_chunks] = rows
    aucs = np.array([r["auc"] for r in results])
    best = int(np.argmax(aucs))
    best_params = {k: v for k, v in results[best].items() if k not in _SCORE_KEYS}
    return GridSearchResult(results, best_params, float(aucs[best]), best, n_rejected,
                            time.perf_counter() - t0, scoring, mask is not None)
