"""The OctoMap family: liboctomap's ``OcTree`` and ``ColorOcTree`` under a numpy API.

:class:`OccupancyOctree` is the log-odds octree (scan insertion with super rays
and the culling region, queries, OctoMap's ``.bt`` / ``.ot`` files, per-cell
stamps and decay, merging); :class:`ColorOctree` adds a colour per cell.
:class:`InsertOptions` holds the rarely changed options of a scan insertion.
:class:`Leaves`, :class:`Nodes`, :class:`Changes`, :class:`Stamps` and
:class:`ColorLeaves` are what their queries return.

Composition, not a chain of mixins: each map is :class:`LogOddsMap` in front of its
compiled core (``OccupancyOctree(LogOddsMap, _OcTree)``), and its methods are plain,
documented functions, one file per concern, bound in the class body
(``insert_scan = _insert.insert_scan``). Files: ``_tree.py`` (the class: what it binds
from where), ``_logodds.py`` (the log-odds base every cell map shares: parameters,
queries, scan checks), ``_outputs.py`` (PLY, PCD, Open3D, distance fields),
``_options.py`` (:class:`InsertOptions`), ``_insert.py`` (``insert_scan``),
``_edits.py`` (cell updates, deletion, pruning), ``_changes.py`` (change detection),
``_queries.py``, ``_files.py``, ``_stamps.py``, ``_merge.py``, ``_color_tree.py`` and
``_superray_policy.py`` (when a scan's rays are grouped into super rays).
"""

from ._logodds import Leaves, LogOddsMap
from ._options import InsertOptions
from ._queries import Nodes
from ._stamps import Stamps
from ._tree import Changes, OccupancyOctree
from ._color_tree import FUSIONS, ColorLeaves, ColorOctree

__all__ = ["OccupancyOctree", "ColorOctree", "LogOddsMap", "InsertOptions", "Leaves", "Nodes",
           "Changes", "Stamps", "ColorLeaves", "FUSIONS"]

# the public path in reprs, error messages and pickles (the classes' files are private)
for _cls in (OccupancyOctree, ColorOctree, LogOddsMap, InsertOptions, Leaves, Nodes, Changes,
             Stamps, ColorLeaves):
    _cls.__module__ = __name__
del _cls
