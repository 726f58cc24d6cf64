"""Which objects the navigation and file-format helpers take as a log-odds map.

The helpers (``_distance``, ``_distance_map``, ``_export``) sit below the map classes in
the layers (docs/architecture.rst): the maps' methods call them. They check their
argument against the compiled trees every log-odds map derives from
(:class:`occgp.OccupancyOctree`, :class:`occgp.ColorOctree`, :class:`occgp.GridMap`),
so they need not import the maps.
"""

from __future__ import annotations

from typing import Any

from ._color import _ColorOcTree
from ._grid import _Grid
from ._octree import _OcTree

__all__ = ["LOG_ODDS_TREES", "check_log_odds_map"]

#: The compiled trees under every log-odds map.
LOG_ODDS_TREES = (_OcTree, _ColorOcTree, _Grid)


def check_log_odds_map(tree: Any, name: str = "tree") -> Any:
    """`tree` if it is a log-odds map (an OccupancyOctree, a ColorOctree or a GridMap),
    else TypeError."""
    if not isinstance(tree, LOG_ODDS_TREES):
        raise TypeError(f"{name} must be an OccupancyOctree or a GridMap, got "
                        f"{type(tree).__name__}")
    return tree
