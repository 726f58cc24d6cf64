"""The log-odds occupancy octree: liboctomap's ``OcTree`` under a numpy API.

:class:`OccupancyOctree` is :class:`~occgp.octree.LogOddsMap` in front of the compiled
tree; its methods are plain functions, each concern in its own file of this folder,
bound in the class body below (``insert_scan = _insert.insert_scan``), so that the
class chain stays ``OccupancyOctree -> LogOddsMap -> _OcTree`` and every method keeps
its signature and docstring.
"""

from __future__ import annotations

import math

from .._docfill import fill_doc
from .._octree import TREE_DEPTH, _OcTree
from ..maps import register
from . import _changes, _edits, _files, _insert, _merge, _queries, _stamps
from ._changes import Changes
from ._logodds import OCTREE_ATTRIBUTES, SENSOR_MODEL, Leaves, LogOddsMap
from ._queries import Nodes, pack_keys, unpack_keys  # noqa: F401 (imported from here)
from ._stamps import Stamps

__all__ = ["OccupancyOctree", "Leaves", "Changes", "Nodes", "Stamps"]


@register("octree", formats=(".bt", ".ot"), description="OctoMap's log-odds octree",
          resolution=0.1)
@fill_doc(sensor_model=SENSOR_MODEL, octree_attributes=OCTREE_ATTRIBUTES)
class OccupancyOctree(LogOddsMap, _OcTree):
    """Probabilistic 3D occupancy map on an octree (OctoMap).

    Each cell holds the log-odds of being occupied. A range scan marks the cells
    its rays cross as free (``prob_miss``) and the cells they end in as occupied
    (``prob_hit``); log-odds are clamped to ``[clamping_min, clamping_max]`` so
    that the map stays updatable, and eight identical children are pruned into
    their parent. The tree is liboctomap's own ``OcTree``, so maps are
    interchangeable with every OctoMap tool (``.bt`` and ``.ot`` files).

    Coordinates are converted to single precision, as liboctomap's ``point3d``
    stores them. Keys are 16 bits per axis: the map covers
    ``[-32768, 32768) * resolution`` metres on each axis.

    The class is :class:`~occgp.octree.LogOddsMap` (parameters, queries, exports)
    in front of the compiled tree (``occgp._octree._OcTree``); its other methods
    are plain functions, one file of ``occgp/octree/`` per concern, bound in the
    class body: scan insertion (``_insert.py``), cell edits (``_edits.py``),
    change detection (``_changes.py``), queries (``_queries.py``), OctoMap files
    (``_files.py``), stamps and decay (``_stamps.py``) and merging
    (``_merge.py``).

    Parameters
    ----------
    resolution : float
        Edge length of the smallest cells, in metres. Must lie in ``[1e-15, 1e14]``:
        the range where liboctomap's single-precision ray traversal is sound
        (see the user guide's notes on single precision).
    {sensor_model}
    n_jobs : int or None, default=None
        Threads that walk each scan's rays in :meth:`insert_scan` (None: 1, -1:
        every core; at most the cores, and about one per 64 rays). The threads'
        counts are merged (integer sums); the tree is then updated once, on the
        same threads for scans of at least 4096 cells (each owns whole subtrees;
        the few nodes above them are finished on one thread), so the tree, node
        for node, and :attr:`last_insert_`'s counts are the same for every
        `n_jobs`. liboctomap's own ``insertPointCloud`` (``method="plain"``,
        ``mode="scan"``), and any scan with :attr:`track_changes` on, update on
        one thread. The rays' cells are counted densely over the scan's key box:
        in scan mode in one array of flags that every thread shares (a byte per
        cell), in ray mode in 4 bytes per cell for each thread; within 2^24
        cells for all threads together (larger boxes run on fewer threads, or
        count in hash tables). A run-time setting: :meth:`set_params` may change
        it; pickles keep it, ``.bt`` / ``.ot`` files do not (pass it to
        :meth:`load`).

    Attributes
    ----------
    {octree_attributes}
    n_jobs : int or None
        The constructor's `n_jobs`.
    last_insert_ : dict
        Statistics of the last :meth:`insert_scan`: ``rays`` traversed (super
        rays count once), and, for the methods occgp implements itself,
        ``updated_cells``, ``traversed_cells`` (cell visits that counted a
        ray: those the culling region spares are not walked or not counted),
        ``spared_cells`` (the visits super rays spared: each walked ray's
        visits times the other rays of its class), ``culled_rays`` (rays
        whose cells all lie in the culling region, told from their end cells
        and not walked), ``region_spared_cells`` (the visits the culling region
        spared: with ``traversed_cells``, those of occgp's walk without the
        region, a hidden ray counted as reaching its end cell), ``region_cells``
        (-1 without culling), ``superrays``
        (whether rays were grouped) and the seconds spent on the end points, on super rays,
        on the culling region, on traversal and on the tree update:
        ``endpoint_seconds``, ``superray_seconds``, ``region_seconds``
        (``preprocessing_seconds`` is their sum), ``traversal_seconds``,
        ``update_seconds``.

    See Also
    --------
    occgp.datasets.structured_room : A synthetic scene to map.

    References
    ----------
    .. [1] A. Hornung, K. M. Wurm, M. Bennewitz, C. Stachniss and W. Burgard,
       "OctoMap: an efficient probabilistic 3D mapping framework based on
       octrees", Autonomous Robots 34(3), 2013.
    .. [2] Y. Kwon, "Real-time dense occupancy mapping using spatial
       correlation of point clouds", dissertation, KAIST School of Computing,
       2022, ch. 2 (super rays and the culling region; §2.3.5, Alg. 3).

    Examples
    --------
    >>> import numpy as np
    >>> from occgp import OccupancyOctree
    >>> m = OccupancyOctree(resolution=0.1)
    >>> m = m.insert_scan([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], origin=[0.0, 0.0, 0.0])
    >>> m.is_occupied([[1.0, 0.0, 0.0], [0.5, 0.0, 0.0]])
    array([ True, False])
    >>> float(np.round(m.occupancy([[1.0, 0.0, 0.0]])[0], 2))
    0.7
    >>> bool(np.isnan(m.occupancy([[5.0, 5.0, 5.0]])[0]))   # never observed
    True
    """

    _kind = "octree"
    #: The `now` of the last ``decay(half_life=...)`` call (NaN: none yet).
    _half_life_at = math.nan

    def __init__(
        self,
        resolution: float,
        *,
        prob_hit: float = 0.7,
        prob_miss: float = 0.4,
        clamping_min: float = 0.1192,
        clamping_max: float = 0.971,
        occupancy_threshold: float = 0.5,
        n_jobs: int | None = None,
    ) -> None:
        self._build_checked(dict(
            resolution=resolution, prob_hit=prob_hit, prob_miss=prob_miss,
            clamping_min=clamping_min, clamping_max=clamping_max,
            occupancy_threshold=occupancy_threshold, n_jobs=n_jobs))

    def __repr__(self) -> str:
        return _queries.tree_repr(self)

    # ------------------------------------------------------------------ updates
    insert_scan = _insert.insert_scan
    update_cells = _edits.update_cells
    set_cells = _edits.set_cells
    delete_cells = _edits.delete_cells
    to_max_likelihood = _edits.to_max_likelihood
    prune = _edits.prune
    expand = _edits.expand
    merge = _merge.merge
    _cell_values = _edits._cell_values

    # ------------------------------------------------------------------ changes
    track_changes = property(_changes.track_changes, _changes.set_track_changes)
    changed_cells = _changes.changed_cells
    reset_changes = _changes.reset_changes

    # ------------------------------------------------------------------ queries
    num_leaves = _queries.num_leaves
    num_nodes = _queries.num_nodes
    _num_cells = _queries._num_leaves
    coord_to_key = _queries.coord_to_key
    key_to_coord = _queries.key_to_coord
    extract_points = _queries.extract_points
    occupancy = _queries.occupancy
    log_odds = _queries.log_odds
    is_occupied = _queries.is_occupied
    is_at_threshold = _queries.is_at_threshold
    cast_rays = _queries.cast_rays
    ray_intersections = _queries.ray_intersections
    leaves = _queries.leaves
    nodes = _queries.nodes
    _check_bbox = _queries._check_bbox
    _check_depth = _queries._check_depth
    _depth_query = _queries._depth_query
    _distance_past_bounds = _queries._distance_past_bounds
    _leaves_key_box = _queries._leaves_key_box
    _rows_in_range = _queries._rows_in_range

    @property
    def tree_depth(self) -> int:
        """Depth of the tree (liboctomap's ``getTreeDepth``): always 16, the finest cells'."""
        return TREE_DEPTH

    # ------------------------------------------------------------------ stamps
    stamps = _stamps.stamps
    stamp_at = _stamps.stamp_at
    clear_stamps = _stamps.clear_stamps
    decay = _stamps.decay
    _stamped = _stamps.stamped

    # ------------------------------------------------------------------ files
    to_bytes = _files.to_bytes
    from_bytes = classmethod(_files.from_bytes)
    save = _files.save
    load = classmethod(_files.load)
    _from_data = classmethod(_files._from_data)
    # what follows OctoMap's data in the files: the stamps (liboctomap skips it)
    _trailer = _stamps.stamps_block
    _read_trailer = _stamps.read_stamps_block

    def to_octree(self) -> "OccupancyOctree":
        """The map as an :class:`OccupancyOctree`: the map itself (the map protocol's
        export to OctoMap's files).

        Returns
        -------
        self : OccupancyOctree
        """
        return self

    def __reduce__(self):
        return (_rebuild, (type(self), self.get_params(), self.to_bytes("ot")))

    def _sensor_params(self) -> dict:
        return {k: v for k, v in self._params.items() if k != "resolution"}


def _rebuild(cls, params: dict, data: bytes) -> OccupancyOctree:
    """Unpickle: the header stores the resolution with full precision (repr)."""
    return cls.from_bytes(data, **{k: v for k, v in params.items() if k != "resolution"})
