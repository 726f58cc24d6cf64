"""Navigation on a map's cells: 2D maps, ROS map files, frontiers, distance fields.

:class:`OccupancyGrid2D` is a height band of a 3D map projected to a 2D grid
(written and read as ROS ``map_server`` files), :class:`Frontiers` the free
cells next to unknown ones, :class:`DistanceField` the distance from each cell
to the nearest occupied one in a box, and :class:`DistanceMap` a distance field
kept up to date scan by scan. The maps' own methods (``project_2d``,
``frontiers``, ``distance_field``, ``distance_map``, ``plan_2d`` ...) call them.
"""

from ._distance import DistanceField
from ._distance_map import DistanceMap
from ._frontiers import Frontiers
from ._map2d import OccupancyGrid2D

__all__ = ["OccupancyGrid2D", "Frontiers", "DistanceField", "DistanceMap"]

# the public path in reprs, error messages and pickles (the classes' files are private)
for _cls in (OccupancyGrid2D, Frontiers, DistanceField, DistanceMap):
    _cls.__module__ = __name__
del _cls
