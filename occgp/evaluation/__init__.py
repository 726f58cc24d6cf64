"""Evaluation harness: test sets, timed map building, comparison tables.

A *map* is any object with ``insert_scan(points, origin)`` and
``occupancy(points)`` (probabilities, NaN where unknown), e.g. any map of the
registry (:mod:`occgp.maps`). A *scan* is any ``(points, origin)`` pair, e.g.
:class:`occgp.datasets.Scan`. Test sets come from the ground truth of a
synthetic scene (:func:`grid_test_set` over a box; :func:`exact_test_set` over
the cells the scans could see, see :func:`cells_in_view`) or, for real scans,
from the held-out protocol (:func:`held_out_split`), which scores only where
the sensor looked and so rates every method near perfect on a synthetic scene.
Real logs with poses (a :class:`~occgp.io.LaserLog` or a
:class:`~occgp.io.ScanSequence`) are scored by
:class:`RealLogBenchmark`: whole scans held out (:func:`log_split`), their
hits and samples along their beams as test points (:func:`log_test_set`),
scores with calibration (:func:`score_log`: AUC, accuracy at the map's own
threshold, Brier score, NLL) and costs (:class:`LogResult`).
Every method is then built and scored the same way (:func:`run_method`,
:func:`compare_methods`, :func:`equal_time_comparison`; methods are given as
factories or as registered map names) and the rows print as a table
(:func:`format_table`).

The scores are those of :mod:`occgp.evaluation.metrics` (also importable as
:mod:`occgp.metrics`). The parameters of the log-odds maps are searched with
:func:`grid_search` against exact cell labels (:func:`cell_labels`), and
ranked with :func:`nca_feature_weights`.

The GP maps' defaults are chosen on a seeded family of 2D scenes
(:func:`occgp.datasets.scene_family_2d`): :func:`evaluate_scene_set` fits
every method on every seed and scores it on the exact grid,
:func:`summarize_scene_set` and :func:`format_scene_set` give the mean, spread
and worst case per method and kind.
"""

from ._ground_truth import cell_labels, cells_in_view, exact_labels, exact_test_set
from ._matching import MatchedCounts, matched_counts
from ._nca import MAX_NCA_BYTES, NCAResult, nca_feature_weights
from ._real_logs import (
    NLL_EPS, LogResult, LogTestSet, RealLogBenchmark, log_split, log_test_set, score_log,
)
from ._protocols import (
    MapResult, TestSet, compare_methods, equal_time_comparison, evaluate_map, grid_test_set,
    held_out_split, run_method,
)
from ._scene_sets import (
    PeakRSS, evaluate_scene_set, format_scene_set, fpr_at_tpr, summarize_scene_set,
)
from ._search import (
    KNN_GRID, KNN_WEIGHT_GRID, OCTOMAP_GRID, THRESHOLDS, GridSearchResult, grid_search,
)
from ._tables import format_table, rows_to_records

__all__ = ["TestSet", "MapResult", "held_out_split", "grid_test_set", "exact_test_set",
           "cells_in_view", "exact_labels", "evaluate_map",
           "run_method", "compare_methods", "equal_time_comparison", "format_table",
           "rows_to_records", "nca_feature_weights", "NCAResult", "MAX_NCA_BYTES",
           "grid_search", "GridSearchResult", "cell_labels", "KNN_GRID", "OCTOMAP_GRID",
           "KNN_WEIGHT_GRID", "THRESHOLDS", "matched_counts", "MatchedCounts",
           "evaluate_scene_set", "summarize_scene_set", "format_scene_set", "fpr_at_tpr",
           "PeakRSS", "log_split", "log_test_set", "LogTestSet", "score_log", "LogResult",
           "RealLogBenchmark", "NLL_EPS"]
