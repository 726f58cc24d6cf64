"""Scoring GP occupancy maps on the seeded 2D scene family, seed by seed.

:func:`evaluate_scene_set` fits every method on the scans of every seed of
:func:`occgp.datasets.scene_family_2d` and scores its probabilities on the exact
0.1 m grid; :func:`summarize_scene_set` and :func:`format_scene_set` reduce the
records per method (and per kind). Defaults are chosen on
:data:`occgp.datasets.TUNING_SEEDS` and reported on :data:`occgp.datasets.TEST_SEEDS`.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from tqdm.auto import tqdm

from .._validation import check_bool, check_choice, check_real
from ..datasets import scene_family_2d
from ..gp import observations_from_scans
from ._tables import format_table
from .metrics import roc_auc, roc_curve

__all__ = ["PeakRSS", "fpr_at_tpr", "evaluate_scene_set", "summarize_scene_set",
           "format_scene_set"]

_RECORD_KEYS = ("method", "seed", "kind", "n_observations", "n_cells", "auc", "fpr",
                "fit_seconds", "predict_seconds", "seconds", "peak_memory_mb")


class PeakRSS:
    """Peak resident memory above its value at entry, sampled by a thread.

    A context manager: a daemon thread reads the resident set size from
    ``/proc/self/statm`` every `interval` seconds while the block runs; on
    exit, :attr:`peak` holds the largest rise over the value at entry, in MB
    (2^20 bytes). Where ``/proc/self/statm`` cannot be read (not Linux),
    :attr:`peak` is NaN.

    Parameters
    ----------
    interval : float, default=0.005
        Seconds between two samples; positive.

    Attributes
    ----------
    peak : float
        Largest resident memory above the value at entry, MB (0 or more).
    start : float
        Resident memory at entry, MB.

    Raises
    ------
    TypeError
        If `interval` is not a real number.
    ValueError
        If `interval` is not positive.

    Examples
    --------
    >>> with PeakRSS() as memory:
    ...     block = np.ones(10_000_000)
    >>> bool(memory.peak >= 0) or bool(np.isnan(memory.peak))
    True
    """

    def __init__(self, interval: float = 0.005):
        self.interval = check_real(interval, "interval", low=0.0)
        self.start = self.peak = float("nan")

    @staticmethod
    def _rss():
        try:
            with open("/proc/self/statm") as f:
                pages = int(f.read().split()[1])
        except (OSError, ValueError, IndexError):
            return float("nan")
        return pages * os.sysconf("SC_PAGE_SIZE") / 2**20

    def _sample(self):
        while not self._stop.wait(self.interval):
            self.peak = max(self.peak, self._rss() - self.start)

    def __enter__(self) -> "PeakRSS":
        self.start = self._rss()
        self.peak = 0.0 if np.isfinite(self.start) else float("nan")
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._sample, daemon=True)
        if np.isfinite(self.start):
            self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join()
        if np.isfinite(self.start):
            self.peak = max(self.peak, self._rss() - self.start)


def fpr_at_tpr(y_true: ArrayLike, y_prob: ArrayLike, tpr: float = 0.9) -> float:
    """False-positive rate at the first threshold that reaches a true-positive rate.

    Unknown points (NaN) count as p = 0.5, as in :mod:`occgp.metrics`.

    Parameters
    ----------
    y_true : array-like of shape (n_points,)
        0/1 (or bool) labels, both classes present.
    y_prob : array-like of shape (n_points,)
        Probabilities of occupancy in [0, 1], NaN where unknown.
    tpr : float, default=0.9
        The true-positive rate to reach, in (0, 1].

    Returns
    -------
    fpr : float
        The false-positive rate of the highest threshold whose true-positive
        rate is at least `tpr`.

    Raises
    ------
    TypeError
        If `tpr` is not a real number, or the arrays are not numeric.
    ValueError
        If `tpr` lies outside (0, 1], or the arrays are bad as for
        :func:`occgp.metrics.roc_curve`.

    Examples
    --------
    >>> fpr_at_tpr([0, 0, 1, 1], [0.1, 0.6, 0.4, 0.9], tpr=0.9)
    0.5
    """
    tpr = check_real(tpr, "tpr", low=0.0, high=1.0, high_open=False)
    fpr, rate, _ = roc_curve(y_true, y_prob, drop_intermediate=False)
    return float(fpr[min(int(np.searchsorted(rate, tpr - 1e-12)), len(fpr) - 1)])


def _check_methods(methods):
    if not isinstance(methods, Mapping) or not methods:
        raise TypeError(f"methods must be a non-empty mapping of name -> factory, got "
                        f"{type(methods).__name__}" + (" (empty)" if isinstance(
                            methods, Mapping) else ""))
    for name, factory in methods.items():
        if not callable(factory):
            raise TypeError(f"methods[{name!r}] must be a callable returning an unfitted "
                            f"estimator, got {type(factory).__name__}")
    return dict(methods)


def _check_seeds(seeds):
    if isinstance(seeds, (str, bytes)) or not isinstance(seeds, Iterable):
        raise TypeError(f"seeds must be a sequence of ints, got {type(seeds).__name__}")
    seeds = list(seeds)
    if not seeds:
        raise ValueError("seeds must hold at least one seed")
    return seeds


def _build(name, factory):
    model = factory()
    for attr in ("fit", "predict_proba"):
        if not callable(getattr(model, attr, None)):
            raise TypeError(f"methods[{name!r}]() must return an estimator with fit and "
                            f"predict_proba, got {type(model).__name__} (no {attr})")
    return model


def evaluate_scene_set(methods: Mapping[str, Callable[[], Any]], seeds: Iterable[int], *,
                       kind: str | None = None, size: tuple[float, float] | None = None,
                       resolution: float = 0.1, region: str = "view",
                       with_variance: bool = True, tpr: float = 0.9,
                       progress: bool | None = False) -> list[dict[str, Any]]:
    """Fit and score every method on every seed of the 2D scene family.

    For each seed, :func:`occgp.datasets.scene_family_2d` gives the scene,
    its scans (with the seed's noise) and the exact occupancy of the cells
    of a grid over its bounds (:meth:`~occgp.datasets.FamilyScene2D.grid`).
    Each method is built fresh by its factory, fitted with ``fit(hits,
    segment_starts, segment_ends)`` (:func:`occgp.gp.observations_from_scans`)
    and queried on the cell centers; its probabilities are scored against
    the truth with :func:`occgp.metrics.roc_auc` and :func:`fpr_at_tpr`
    (unknown cells, NaN, count as 0.5) on the cells of `region`: by default
    those the laser saw (:meth:`~occgp.datasets.FamilyScene2D.view`), since
    no method can know the interiors of solids or space no ray reached.
    Errors of a method propagate.

    Choose defaults on :data:`occgp.datasets.TUNING_SEEDS` only; report them
    on :data:`occgp.datasets.TEST_SEEDS`.

    Parameters
    ----------
    methods : mapping of str to callable
        Name -> factory returning an unfitted estimator with ``fit(hits,
        segment_starts, segment_ends)`` and ``predict_proba(X)`` (the
        :mod:`occgp.gp` maps, e.g. ``{"mixture": GPMixture}``).
    seeds : iterable of int
        Seeds of the family, e.g. ``TUNING_SEEDS``.
    kind : str, optional
        Passed to :func:`~occgp.datasets.scene_family_2d` (default: the
        seed's kind).
    size : (float, float), optional
        Passed to :func:`~occgp.datasets.scene_family_2d`.
    resolution : float, default=0.1
        Edge of the grid's cells, metres.
    region : {"view", "grid"}, default="view"
        The cells scored as ``auc`` and ``fpr``: those in the laser's view,
        or every cell of the grid. The records always hold the whole grid's
        scores too (``auc_grid``, ``fpr_grid``).
    with_variance : bool, default=True
        Time ``predict(X, return_var=True)`` as the prediction, where the
        estimator has ``predict`` (then ``predict_proba`` gives the scored
        probabilities, untimed); otherwise, or for estimators without
        ``predict``, time ``predict_proba``.
    tpr : float, default=0.9
        True-positive rate of the false-positive rate reported.
    progress : bool or None, default=False
        Show a progress bar over seeds and methods; None shows it only on a
        terminal.

    Returns
    -------
    records : list of dict
        One per seed and method, in that order, with keys ``method``,
        ``seed``, ``kind``, ``n_observations`` (hits + beams), ``n_cells``
        (scored), ``auc``, ``fpr`` (at `tpr`, on `region`), ``auc_grid``,
        ``fpr_grid`` (on the whole grid), ``fit_seconds``, ``predict_seconds``,
        ``seconds`` (their sum) and ``peak_memory_mb`` (resident memory
        above its value before the fit, during fit and prediction, sampled
        every 5 ms by :class:`PeakRSS`; NaN where it cannot be read).

    Raises
    ------
    TypeError
        If `methods` is not a non-empty mapping of callables, a factory does
        not return an estimator with ``fit`` and ``predict_proba``, `seeds`
        is not iterable, or another argument has the wrong type.
    ValueError
        If `seeds` is empty, or an argument is invalid as for
        :func:`~occgp.datasets.scene_family_2d` and
        :meth:`~occgp.datasets.FamilyScene2D.grid`.

    Examples
    --------
    >>> from occgp.gp import OccupancyGrid
    >>> records = evaluate_scene_set({"grid": lambda: OccupancyGrid(0.2)}, [2])
    >>> r = records[0]
    >>> r["method"], r["seed"], r["kind"], 0.5 < r["auc"] <= 1.0
    ('grid', 2, 'hall', True)
    """
    methods = _check_methods(methods)
    seeds = _check_seeds(seeds)
    region = check_choice(region, "region", ("view", "grid"))
    with_variance = check_bool(with_variance, "with_variance")
    tpr = check_real(tpr, "tpr", low=0.0, high=1.0, high_open=False)
    records = []
    bar = tqdm(total=len(seeds) * len(methods), desc="scene set", unit="fit",
               disable=None if progress is None else not progress, leave=False)
    try:
        for seed in seeds:
            case = scene_family_2d(seed, kind, size=size)
            points, truth, _ = case.grid(resolution)
            scored = case.view(resolution) if region == "view" else np.ones(len(truth), bool)
            hits, starts, ends = observations_from_scans(case.scans())
            n_obs = len(hits) + len(starts)
            for name, factory in methods.items():
                model = _build(name, factory)
                with PeakRSS() as memory:
                    t0 = time.perf_counter()
                    model.fit(hits, starts, ends)
                    t1 = time.perf_counter()
                    if with_variance and callable(getattr(model, "predict", None)):
                        model.predict(points, return_var=True)
                        t2 = time.perf_counter()
                        prob = model.predict_proba(points)
                    else:
                        prob = model.predict_proba(points)
                        t2 = time.perf_counter()
                prob = np.asarray(prob, dtype=np.float64)
                records.append({
                    "method": str(name), "seed": int(seed), "kind": case.kind,
                    "n_observations": n_obs, "n_cells": int(scored.sum()),
                    "auc": roc_auc(truth[scored], prob[scored]),
                    "fpr": fpr_at_tpr(truth[scored], prob[scored], tpr),
                    "auc_grid": roc_auc(truth, prob), "fpr_grid": fpr_at_tpr(truth, prob, tpr),
                    "fit_seconds": t1 - t0, "predict_seconds": t2 - t1,
                    "seconds": t2 - t0, "peak_memory_mb": float(memory.peak)})
                bar.update()
    finally:
        bar.close()
    return records


def _check_records(records):
    if isinstance(records, (str, bytes, Mapping)) or not isinstance(records, Iterable):
        raise TypeError(f"records must be a list of dicts from evaluate_scene_set, got "
                        f"{type(records).__name__}")
    records = list(records)
    for i, rec in enumerate(records):
        if not isinstance(rec, Mapping):
            raise TypeError(f"records[{i}] must be a dict, got {type(rec).__name__}")
        missing = [k for k in _RECORD_KEYS if k not in rec]
        if missing:
            raise ValueError(f"records[{i}] lacks {missing}; records come from "
                             "evaluate_scene_set")
    return records


def summarize_scene_set(records: Sequence[Mapping[str, Any]], *,
                        by_kind: bool = False) -> list[dict[str, Any]]:
    """Per method (and per kind): mean, spread and worst case of the scores.

    Parameters
    ----------
    records : sequence of dict
        From :func:`evaluate_scene_set`.
    by_kind : bool, default=False
        One row per method and kind (kinds in order of first appearance)
        instead of one per method.

    Returns
    -------
    summary : list of dict
        One per method (and kind), in order of first appearance, with keys
        ``method``, ``kind`` ("all" unless `by_kind`), ``n_scenes``,
        ``auc_mean``, ``auc_std`` (population), ``auc_worst`` (the lowest),
        ``worst_seed`` (its seed), ``fpr_mean``, ``fpr_worst`` (the highest),
        ``auc_grid_mean`` (on the whole grid), ``fit_seconds_mean``, ``predict_seconds_mean``, ``seconds_mean``,
        ``seconds_max`` and ``peak_memory_mb_max``.

    Raises
    ------
    TypeError
        If `records` is not a sequence of dicts or `by_kind` not a bool.
    ValueError
        If a record lacks a key of :func:`evaluate_scene_set`.

    Examples
    --------
    >>> rec = dict(method="m", seed=0, kind="hall", n_observations=10, n_cells=4,
    ...            auc=0.9, fpr=0.2, fit_seconds=1.0, predict_seconds=0.5,
    ...            seconds=1.5, peak_memory_mb=3.0)
    >>> s = summarize_scene_set([rec, dict(rec, seed=1, auc=0.8)])[0]
    >>> s["n_scenes"], round(s["auc_mean"], 3), s["auc_worst"], s["worst_seed"]
    (2, 0.85, 0.8, 1)
    """
    records = _check_records(records)
    by_kind = check_bool(by_kind, "by_kind")
    groups: dict[tuple[str, str], list] = {}
    for rec in records:
        groups.setdefault((rec["method"], rec["kind"] if by_kind else "all"), []).append(rec)
    rows = []
    for (method, kind), recs in groups.items():
        col = {k: np.array([r[k] for r in recs], dtype=np.float64)
               for k in ("auc", "fpr", "fit_seconds", "predict_seconds", "seconds",
                         "peak_memory_mb")}
        worst = int(np.argmin(col["auc"]))
        mem = col["peak_memory_mb"]
        rows.append({
            "method": method, "kind": kind, "n_scenes": len(recs),
            "auc_mean": float(col["auc"].mean()), "auc_std": float(col["auc"].std()),
            "auc_worst": float(col["auc"][worst]), "worst_seed": recs[worst]["seed"],
            "fpr_mean": float(col["fpr"].mean()), "fpr_worst": float(col["fpr"].max()),
            "auc_grid_mean": float(np.mean([r.get("auc_grid", np.nan) for r in recs])),
            "fit_seconds_mean": float(col["fit_seconds"].mean()),
            "predict_seconds_mean": float(col["predict_seconds"].mean()),
            "seconds_mean": float(col["seconds"].mean()),
            "seconds_max": float(col["seconds"].max()),
            "peak_memory_mb_max": float(np.nanmax(mem)) if np.isfinite(mem).any()
            else float("nan")})
    return rows


_SUMMARY_COLUMNS = ("method", "kind", "n_scenes", "auc_mean", "auc_std", "auc_worst",
                    "worst_seed", "fpr_mean", "fpr_worst", "auc_grid_mean",
                    "fit_seconds_mean", "predict_seconds_mean", "peak_memory_mb_max")


def format_scene_set(records: Sequence[Mapping[str, Any]], *, by_kind: bool = False,
                     columns: Sequence[str] | None = None, floatfmt: str = ".3f") -> str:
    """The summary of :func:`summarize_scene_set` as a plain-text table.

    Parameters
    ----------
    records : sequence of dict
        From :func:`evaluate_scene_set`.
    by_kind : bool, default=False
        One row per method and kind.
    columns : sequence of str, optional
        Keys of the summary to show; default: method, kind, n_scenes,
        auc_mean, auc_std, auc_worst, worst_seed, fpr_mean, fpr_worst,
        auc_grid_mean, fit_seconds_mean, predict_seconds_mean, peak_memory_mb_max.
    floatfmt : str, default=".3f"
        Format of the floats (:func:`format_table`).

    Returns
    -------
    table : str
        As :func:`format_table` prints it.

    Raises
    ------
    TypeError
        As :func:`summarize_scene_set`.
    ValueError
        As :func:`summarize_scene_set`, or if a column is not a key of the
        summary.

    Examples
    --------
    >>> rec = dict(method="m", seed=0, kind="hall", n_observations=10, n_cells=4,
    ...            auc=0.9, fpr=0.2, fit_seconds=1.0, predict_seconds=0.5,
    ...            seconds=1.5, peak_memory_mb=3.0)
    >>> print(format_scene_set([rec], columns=["method", "auc_mean", "auc_worst"]))
    method  auc_mean  auc_worst
    ------  --------  ---------
    m          0.900      0.900
    """
    summary = summarize_scene_set(records, by_kind=by_kind)
    return format_table(summary, columns=list(_SUMMARY_COLUMNS if columns is None
                                              else columns), floatfmt=floatfmt)
