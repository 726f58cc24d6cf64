"""The k-NN inverse sensor model on the octree (Miao, Hunter and Georgilas, 2022).

:class:`KNNMap` is the map (``occgp/knn/_map.py``); :class:`ScanReplay`
(``occgp/knn/_replay.py``) holds what a data set's maps share under every parameter
value, so that :func:`occgp.evaluation.grid_search` replays thousands of parameter
combinations as vectorised updates. This module is their public face: the replay
builds KNNMap probes, so it sits above the map, and both are imported here.
"""

from . import _map as _knn_map
from ._map import (
    CDFS, KNN_PARAMS, MAX_HISTORY, MAX_K, MAX_RANGE, STATS, KNNMap, check_knn_params,
    check_score_stats, fixed_log_odds, history_knn_distances, mean_knn_distances,
    point_log_odds,
)
from ._replay import ScanReplay, check_octomap_params

__all__ = ["KNNMap", "ScanReplay", "check_knn_params", "check_octomap_params",
           "check_score_stats", "mean_knn_distances", "history_knn_distances",
           "point_log_odds", "fixed_log_odds"]

# maps pickled before the map moved to occgp/knn/_map.py name their rebuild function here
_rebuild_knn = _knn_map._rebuild_knn
