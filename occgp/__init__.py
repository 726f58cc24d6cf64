"""occgp: occupancy mapping from range sensors.

The OctoMap octree under a numpy API (:class:`OccupancyOctree`, and
:class:`ColorOctree` with a colour per cell), kernel
inference on cells (:class:`BGKMap`, :class:`AKIMap`), the k-NN inverse
sensor model (:class:`KNNMap`), synthetic
scenes and scan readers (:mod:`occgp.datasets`), and one evaluation harness
(:mod:`occgp.metrics`, :mod:`occgp.evaluation`) for every mapping method.
"""

import logging

from .octree import Changes, ColorLeaves, ColorOctree, Leaves, Nodes, OccupancyOctree, Stamps
from .grid import GridMap
from .kernel import AKIMap, BGKMap
from .knn import KNNMap
from .nav import DistanceField, DistanceMap, Frontiers, OccupancyGrid2D
from .maps import OccupancyMap, available_maps, make_map, register
from . import filters  # noqa: F401  (occgp.filters: the scan filters)

from ._version import __version__
__all__ = ["OccupancyOctree", "ColorOctree", "GridMap", "Leaves", "Nodes", "ColorLeaves",
           "Changes", "Stamps", "AKIMap", "BGKMap", "KNNMap", "DistanceField", "DistanceMap",
           "OccupancyGrid2D", "Frontiers", "OccupancyMap", "available_maps", "make_map",
           "register", "__version__"]

logging.getLogger("occgp").addHandler(logging.NullHandler())
