"""The log-odds occupancy octree: liboctomap's ``OcTree`` under a numpy API."""

from __future__ import annotations

import warnings
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._docfill import fill_doc
from ._logodds import MODES, OCTREE_ATTRIBUTES, SENSOR_MODEL, Leaves
from .._octree import KEYRAY_CELLS, _OcTree
from ._files import OctreeFiles
from ._queries import Nodes, OctreeQueries, pack_keys, unpack_keys
from ._merge import OctreeMerging
from ._stamps import OctreeStamps, Stamps
from ..maps import register
from .._scan_input import join_free, prefilter
from ._superray_policy import adaptive_threshold
from .._validation import as_numeric, check_bool, check_choice, check_n_jobs, n_threads

__all__ = ["OccupancyOctree", "Leaves", "Changes", "Nodes", "Stamps"]


class Changes(NamedTuple):
    """The cells a map recorded as changed (see :attr:`OccupancyOctree.track_changes`)."""

    #: Keys of the finest cells, uint16, shape (n, 3), sorted.
    keys: NDArray[np.uint16]
    #: Their centres, metres, shape (n, 3).
    centers: NDArray[np.float64]
    #: True where the cell was new (unknown before), False where its state flipped.
    new: NDArray[np.bool_]

    @property
    def centres(self) -> NDArray[np.float64]:
        """Deprecated name of :attr:`centers` (the spelling of :class:`Nodes` and
        :class:`Leaves`)."""
        warnings.warn("Changes.centres is deprecated; use Changes.centers",
                      DeprecationWarning, stacklevel=2)
        return self.centers


@register("octree", formats=(".bt", ".ot"), description="OctoMap's log-odds octree",
          resolution=0.1)
@fill_doc(sensor_model=SENSOR_MODEL, octree_attributes=OCTREE_ATTRIBUTES)
class OccupancyOctree(OctreeStamps, OctreeMerging, OctreeFiles, OctreeQueries, _OcTree):
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

    Parameters
    ----------
    resolution : float
        Edge length of the smallest cells, in metres. Must lie in ``[1e-15, 1e14]``:
        the range where liboctomap's single-precision ray traversal is sound
        (see the user guide's notes on single precision).
    {sensor_model}

    Attributes
    ----------
    {octree_attributes}
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

    # ------------------------------------------------------------------ updates
    def insert_scan(
        self,
        points: ArrayLike,
        origin: ArrayLike,
        *,
        max_range: float | None = None,
        mode: str = "scan",
        method: str = "auto",
        superray_threshold: int = 20,
        discretize: bool = False,
        bbox: ArrayLike | None = None,
        n_jobs: int | None = None,
        min_range: float | None = None,
        free_points: ArrayLike | None = None,
        stamp: float | None = None,
    ) -> "OccupancyOctree":
        """Integrate one range scan into the map.

        Each ray from `origin` to a point in `points` marks the cells it crosses
        as free and its end cell as occupied.

        Parameters
        ----------
        points : array-like of shape (n_points, 3)
            Ray end points in the world frame, in metres. Must be finite. An
            empty scan (``n_points == 0``) changes nothing.
        origin : array-like of shape (3,)
            Sensor position in the world frame, in metres.
        max_range : float, default=None
            Rays longer than this are truncated: the cells up to `max_range`
            are marked free and the end cell is not marked occupied. None means
            no limit. Points may then lie beyond the key range, or beyond float
            range: their rays are cut at `max_range` all the same.
        mode : {"scan", "ray"}, default="scan"
            ``"scan"`` is liboctomap's ``insertPointCloud``: the scan's sets of
            free and occupied cells are computed first, a cell in both counts as
            occupied, and every cell gets at most one update. The tree is
            identical, leaf for leaf, to liboctomap's. ``"ray"`` counts rays:
            each cell gets ``n_free * l_miss + n_hit * l_hit`` (``n`` = how many
            rays pass through / end in it) and is clamped once, whatever the
            order of the rays.
        method : {"auto", "plain", "culling", "superray", "superray+culling"}, \
default="auto"
            How the rays are traversed; every method gives the same map, bit for
            bit (the user guide's "Update methods" tells how each works).
            ``"auto"`` is ``"superray+culling"`` (``"plain"`` with
            `discretize`). ``"plain"`` traverses every ray in full (with
            ``mode="scan"``, liboctomap's ``insertPointCloud`` itself).
            ``"superray"`` traverses once for all the rays of a *super ray* [1]_
            (rays ending in a cell with at least `superray_threshold` end
            points that provably cross the same cells). ``"culling"`` skips
            each ray's cells inside the scan's *culling region* [1]_ (fully
            free cells around the sensor, whose updates would change nothing).
            ``"superray+culling"`` does both, groups only the cells where
            grouping can pay, and pauses super rays for
            :attr:`SUPERRAY_BACKOFF` scans (doubling in a row) after a scan
            whose grouping cost more than it saved.
        superray_threshold : int, default=20
            With the super-ray methods, the fewest end points a cell must hold
            for its rays to be grouped; at least 1.
        discretize : bool, default=False
            Only with ``mode="scan"`` and ``method="plain"`` (or ``"auto"``):
            cast one ray per distinct end cell, to its centre (liboctomap's
            ``discretize``), which is faster for dense scans.
        bbox : array-like of shape (2, 3), default=None
            ``[min_corner, max_corner]``: update only inside this box, as
            liboctomap's ``useBBXLimit`` does. A ray counts only when its end
            point lies in the box (a closed box, compared in single precision)
            and within `max_range`; it marks its end cell occupied and its cells
            inside the box free (rays ending outside the box, or cut at
            `max_range`, change nothing). Every method gives liboctomap's map.
            Both corners must lie in the key range.
        n_jobs : int or None, default=None
            Threads that walk the scan's rays (None: 1, -1: every core; at
            most the cores, and about one per 64 rays). The threads' counts
            are merged (integer sums); the tree is then updated once, on the
            same threads for scans of at least 4096 cells (each owns whole
            subtrees; the few nodes above them are finished on one thread),
            so the tree, node for node, and :attr:`last_insert_`'s counts are
            the same for every `n_jobs`. liboctomap's own ``insertPointCloud``
            (``method="plain"``, ``mode="scan"``), and any scan with
            :attr:`track_changes` on, update on one thread. The rays' cells
            are counted densely over the scan's key box: in scan mode in one
            array of flags that every thread shares (a byte per cell), in ray
            mode in 4 bytes per cell for each thread; within 2^24 cells for all
            threads together (larger boxes run on fewer threads, or count in
            hash tables).
        min_range : float, default=None
            Points nearer to `origin` than this (and free points, below) are
            dropped before anything else: they cast no ray at all
            (octomap_server's ``sensor_model/min_range``). The distance is
            Euclidean, computed in double precision from the points and the
            origin as given, before their conversion to single precision; a
            point at exactly `min_range` is kept. The map is the one the
            pre-filtered scan gives, for every method and mode. None (or 0):
            no filter. Must be finite, >= 0 and less than `max_range`.
        free_points : array-like of shape (n_free, 3), default=None
            End points of rays that only clear (octomap_server inserts its
            ground points so): the cells such a ray crosses count as free,
            and its end cell gets nothing from it, as for a ray cut at
            `max_range` (which applies to these rays too). They join the same
            update as `points`: with ``mode="scan"`` a cell in both the free
            and the occupied sets is occupied and every cell is updated once;
            with ``mode="ray"`` each crossed cell counts one more miss. Free
            rays are never grouped into super rays, so every method gives
            the same map. With `bbox`, a free ray counts when its end lies in
            the box and within `max_range`, as a point's ray does, and clears
            its cells inside the box. Not with `discretize`. Each must be
            finite and in the key range (after truncation at `max_range`).
        stamp : float, default=None
            Stamp every cell the scan updates with this time (see
            :meth:`stamps` and :meth:`decay`). The culling region is then not
            used (its cells are observed too, and are stamped), and the
            traversal is occgp's (liboctomap's ``insertPointCloud`` records no
            cells); the map is the same.

        Returns
        -------
        self : OccupancyOctree
            The updated map, to allow chaining.

        Raises
        ------
        TypeError
            If `points` or `origin` does not hold real numbers.
        ValueError
            If `points` is not of shape (n_points, 3), `origin` not of shape
            (3,), either holds NaN or inf or lies outside the key range (after
            truncation at `max_range`), a ray is shorter than 1.1e-19 m yet
            crosses a cell border (too short for the single-precision
            traversal), the scan reaches more than :attr:`MAX_SCAN_CELLS`
            distinct cells (the same scans for every `n_jobs`), or
            `max_range`, `mode`, `discretize` or `n_jobs` is invalid (0, or not
            an int); `min_range` is negative, not finite or not less than
            `max_range`; `free_points` is not of shape (n_free, 3), holds NaN
            or inf, has an end (after truncation) outside the key range, or
            comes with `discretize`; or `stamp` is not finite. The map is then
            unchanged.

        References
        ----------
        .. [1] Y. Kwon, "Real-time dense occupancy mapping using spatial
           correlation of point clouds", dissertation, KAIST, 2022, ch. 2
           (super rays §2.3.1-2.3.4 and appendix; culling region §2.3.5).

        Examples
        --------
        >>> m = OccupancyOctree(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0], mode="ray")
        >>> m.is_occupied([[1.0, 0, 0]]).tolist()
        [True]

        A point nearer than `min_range` casts no ray; a free point's ray only
        clears:

        >>> m = OccupancyOctree(0.1).insert_scan(
        ...     [[0.05, 0.05, 1.05], [0.05, 0.05, 0.35]], [0.05, 0.05, 0.05],
        ...     min_range=0.5, free_points=[[1.05, 0.05, 0.05]])
        >>> m.is_occupied([[0.05, 0.05, 1.05], [0.05, 0.05, 0.35]], return_unknown=True)
        (array([ True, False]), array([False, False]))
        >>> m.is_occupied([[0.95, 0.05, 0.05], [1.05, 0.05, 0.05]], return_unknown=True)
        (array([False, False]), array([False,  True]))
        """
        points, free64, _ = prefilter(points, origin, min_range, max_range, free_points)
        threads = n_threads(check_n_jobs(n_jobs))
        stamping = self._stamped(stamp)
        discretize = check_bool(discretize, "discretize")
        mode = check_choice(mode, "mode", MODES)
        method, threshold = self._check_method(
            "plain" if discretize and isinstance(method, str) and method == "auto" else method,
            superray_threshold)
        if discretize and (mode != "scan" or method != "plain"):
            raise ValueError("discretize=True is only defined for mode='scan', method='plain'")
        if discretize and free64 is not None:
            raise ValueError("free_points do not combine with discretize=True")
        liboctomap = mode == "scan" and method == "plain" and free64 is None
        box = None if bbox is None else self._check_bbox(bbox)
        scan = join_free(
            self._validated_scan(points, origin, max_range, mode,
                                 check_ends=liboctomap or free64 is not None),
            None if free64 is None else self._validated_scan(free64, origin, max_range, mode,
                                                             name="free_points"))
        if scan is None:
            return self
        pts, org, rng, cells, free_only = scan
        if liboctomap:
            if discretize and not (inside := self._in_range(pts)).all():
                # liboctomap discretises before it truncates, with unchecked keys
                self._raise_out_of_range("points", inside,
                                         " (with discretize=True, before truncation)")
            # rays within liboctomap's key buffer, and a bound on the cells they reach
            # within MAX_SCAN_CELLS: otherwise occgp's traversal, which checks it
            reach = cells.sum() + len(cells)
            # (with change tracking, occgp's traversal, which gives the same map and
            # records the changes)
            if (cells.max() <= KEYRAY_CELLS and reach <= self._max_scan_cells()
                    and not self._is_tracking() and stamp is None):
                self._insert_point_cloud(pts, org, rng, bool(discretize), box)
                self.last_insert_: dict[str, float] = {"rays": len(pts)}
                return self
            # a ray too long for liboctomap's key buffer (KEYRAY_CELLS): occgp's
            # traversal visits the cells computeRayKeys visits, and gives the map
            # insertPointCloud would give with a buffer large enough
            if discretize:
                pts = _discretized(pts, self.resolution)
        key_box = None
        if box is not None:
            # liboctomap keeps the rays that end in the box within range, and of their
            # cells those in the box's keys
            kept = self._bbx_rays(pts, org, rng, box)
            pts = np.ascontiguousarray(pts[kept])
            free_only = None if free_only is None else np.ascontiguousarray(free_only[kept])
            key_box = self.coord_to_key(box)
            if len(pts) == 0:
                self.last_insert_ = {"rays": 0}
                return self
        threshold = adaptive_threshold(self, method, threshold)
        # the culling region's cells are observed, so a stamped scan walks them too
        culling = method.endswith("culling") and stamp is None
        with stamping:
            stats = self._insert_batch(pts, org, rng, mode == "ray", culling, None, threshold,
                                       False, self._max_scan_cells(), key_box, threads,
                                       free_only)
        self._record_insert(stats, pts, org, rng, method, threshold)
        return self

    # ------------------------------------------------------------------ changes
    @property
    def track_changes(self) -> bool:
        """Whether the map records which cells change (liboctomap's change detection).

        Set it to True to start recording: from then on, every update
        (:meth:`insert_scan` by any method, :meth:`update_cells`,
        :meth:`set_cells`) records, per finest cell, what liboctomap's
        ``enableChangeDetection`` records: a cell the map did not know is
        recorded as new; a known cell whose state (occupied or free) flips is
        recorded, and removed again when it flips back. Read them with
        :meth:`changed_cells`, clear them with :meth:`reset_changes`. The
        record is not saved in files or pickles.

        Examples
        --------
        >>> m = OccupancyOctree(0.1)
        >>> m.track_changes = True
        >>> m = m.insert_scan([[0.35, 0.05, 0.05]], [0.05, 0.05, 0.05])
        >>> changes = m.changed_cells()
        >>> len(changes.keys), bool(changes.new.all())     # 3 free cells, 1 occupied
        (4, True)
        """
        return bool(self._is_tracking())

    @track_changes.setter
    def track_changes(self, value: bool) -> None:
        self._set_tracking(check_bool(value, "track_changes"))

    def changed_cells(self) -> "Changes":
        """The cells recorded since tracking began or :meth:`reset_changes`.

        Returns
        -------
        changes : Changes
            Named tuple ``(keys, centers, new)``: the finest cells' keys
            (uint16, shape (n, 3), sorted), their centres and whether each
            was new (unknown before) rather than flipped. Empty when
            :attr:`track_changes` was never set.
        """
        packed, new = self._changed()
        order = np.argsort(packed, kind="stable")
        packed, new = packed[order], new[order]
        keys = unpack_keys(packed)
        centres = self.key_to_coord(keys) if len(keys) else np.empty((0, 3))
        return Changes(keys, centres, new)

    def reset_changes(self) -> "OccupancyOctree":
        """Forget the recorded changes (tracking stays as it is).

        Returns
        -------
        self
            The map.
        """
        self._reset_changes()
        return self


    def update_cells(self, points: ArrayLike, log_odds: ArrayLike | None = None, *,
                     occupied: ArrayLike | None = None,
                     stamp: float | None = None) -> "OccupancyOctree":
        """Add log-odds to the cells holding `points` (liboctomap's ``updateNode``).

        Row ``i`` adds ``log_odds[i]`` to the finest cell holding ``points[i]``
        and clamps it to ``[clamping_min, clamping_max]``, as
        ``updateNode(point, log_odds[i])`` called for each row in order would:
        a cell named twice gets its updates one after the other, clamped after
        each. Cells are created where the map knew nothing (from log-odds 0).
        The tree is walked once per round of distinct cells, not once per row.

        Parameters
        ----------
        points : array-like of shape (n_points, 3)
            Points in the cells to update, metres; inside the key range.
        log_odds : float or array-like of shape (n_points,), optional
            The log-odds to add (finite in single precision). Give it or
            `occupied`.
        occupied : bool or array-like of bool of shape (n_points,), optional
            ``updateNode(point, occupied)``: add the log-odds of ``prob_hit``
            where True, of ``prob_miss`` where False.
        stamp : float, default=None
            Stamp the cells with this time (see :meth:`decay`).

        Returns
        -------
        self : OccupancyOctree

        Raises
        ------
        TypeError
            If an array does not hold numbers (booleans for `occupied`).
        ValueError
            If `points` is not of shape (n_points, 3), holds NaN or inf or lies
            outside the key range, `log_odds` or `occupied` has the wrong shape
            or non-finite values, or neither or both are given. The map is then
            unchanged.

        Examples
        --------
        >>> m = OccupancyOctree(0.1).update_cells([[0.05, 0.05, 0.05]] * 2, [2.0, 2.0])
        >>> float(m.log_odds([[0.05, 0.05, 0.05]])[0])     # 4.0, clamped at logit(0.971)
        3.511
        """
        keys = self.coord_to_key(points)
        values = self._cell_values(len(keys), log_odds, occupied)
        stamping = self._stamped(stamp)
        if len(keys) == 0:
            return self
        packed = pack_keys(keys)
        order = np.argsort(packed, kind="stable")
        sorted_keys = packed[order]
        start = np.r_[True, sorted_keys[1:] != sorted_keys[:-1]]
        group_start = np.maximum.accumulate(np.where(start, np.arange(len(order)), 0))
        rank = np.arange(len(order)) - group_start      # the row's turn within its cell
        by_round = np.lexsort((sorted_keys, rank))
        bounds = np.searchsorted(rank[by_round], np.arange(rank.max() + 2))
        rows = order[by_round]
        with stamping:
            for r in range(len(bounds) - 1):
                take = rows[bounds[r]:bounds[r + 1]]
                self._apply_cells(np.ascontiguousarray(packed[take]),
                                  np.ascontiguousarray(values[take]))
        return self

    def set_cells(self, points: ArrayLike, log_odds: ArrayLike, *,
                  stamp: float | None = None) -> "OccupancyOctree":
        """Set the log-odds of the cells holding `points` (liboctomap's ``setNodeValue``).

        Each value is clamped to ``[clamping_min, clamping_max]`` as liboctomap
        clamps it; a cell named twice keeps the last value. The inner nodes are
        then re-evaluated and the tree pruned.

        Parameters
        ----------
        points : array-like of shape (n_points, 3)
            Points in the cells to set, metres; inside the key range.
        log_odds : float or array-like of shape (n_points,)
            The values (finite in single precision).
        stamp : float, default=None
            Stamp the cells with this time (see :meth:`decay`).

        Returns
        -------
        self : OccupancyOctree

        Raises
        ------
        TypeError, ValueError
            As :meth:`update_cells`; the map is then unchanged.

        Examples
        --------
        >>> m = OccupancyOctree(0.1).set_cells([[0.05, 0.05, 0.05]], 1.0)
        >>> float(m.log_odds([[0.05, 0.05, 0.05]])[0])
        1.0
        """
        keys = self.coord_to_key(points)
        values = self._cell_values(len(keys), log_odds, None)
        stamping = self._stamped(stamp)
        if len(keys):
            with stamping:
                self._set_values(keys, values)
        return self

    def _cell_values(self, n: int, log_odds, occupied) -> np.ndarray:
        """The float32 log-odds of :meth:`update_cells` / :meth:`set_cells`, checked."""
        if (log_odds is None) == (occupied is None):
            raise ValueError("give exactly one of log_odds and occupied")
        if occupied is not None:
            occ = np.asarray(occupied)
            if occ.dtype != np.bool_:
                raise TypeError(f"occupied must hold booleans, got dtype {occ.dtype}")
            occ = np.broadcast_to(occ, (n,)) if occ.ndim == 0 else occ
            if occ.shape != (n,):
                raise ValueError(f"occupied must be a bool or of shape ({n},), got {occ.shape}")
            hit, miss = self._log_odds_thresholds()[3:]
            return np.where(occ, np.float32(hit), np.float32(miss)).astype(np.float32)
        values = as_numeric(log_odds, "log_odds")
        if values.ndim == 0:
            values = np.full(n, values)
        if values.shape != (n,):
            raise ValueError(f"log_odds must be a number or of shape ({n},), "
                             f"got {values.shape}")
        with np.errstate(over="ignore"):
            out = np.ascontiguousarray(values, dtype=np.float32)
        if not np.isfinite(out).all():
            bad = int(np.flatnonzero(~np.isfinite(out))[0])
            raise ValueError(f"log_odds must be finite in single precision, got "
                             f"{values[bad]!r} at row {bad}")
        return out




    def to_max_likelihood(self) -> "OccupancyOctree":
        """Set every cell to its clamping bound by its state (liboctomap's ``toMaxLikelihood``).

        Occupied cells go to ``clamping_max``, free ones to ``clamping_min``;
        then the tree is pruned.

        Returns
        -------
        self
            The map.
        """
        self._to_max_likelihood()
        return self

    # ------------------------------------------------------------------ queries








    def delete_cells(self, points: ArrayLike, depth: int = 0) -> int:
        """Make the nodes holding `points` unknown again (liboctomap's ``deleteNode``).

        Row ``i`` deletes the node at `depth` that holds ``points[i]``, with its
        whole subtree. A pruned leaf coarser than `depth` on the way is first
        expanded, as liboctomap's ``deleteNodeRecurs`` does: its eight children
        take its value, and the deletion continues in the child holding the
        point, so the rest of the pruned cube stays known. An inner node left
        without children is deleted too, and every remaining ancestor takes
        the largest log-odds of its children again, so queries at any depth
        stay consistent; afterwards queries at the points give NaN (unknown).
        The tree is not pruned again: the siblings of a deleted cell stay as
        they are.

        occgp implements this itself: liboctomap 1.9's ``deleteNode`` aborts
        on inner nodes. Deletions are not recorded by :attr:`track_changes`
        (liboctomap's change detection does not record them either); a
        deleted cell that is observed again is recorded as new.

        Parameters
        ----------
        points : array-like of shape (n_points, 3)
            Points in the nodes to delete, metres; inside the key range.
        depth : int, default=0
            Tree depth of the deleted nodes, in [0, 16]: 16 (or 0, liboctomap's
            convention for "the tree's depth") deletes the finest cells, ``d``
            the node of edge ``resolution * 2**(16 - d)``.

        Returns
        -------
        n_deleted : int
            How many nodes were deleted (points in unknown space, or in a node
            an earlier row already deleted, delete nothing).

        Raises
        ------
        TypeError
            If `points` does not hold numbers or `depth` is not an int.
        ValueError
            If `points` is not of shape (n_points, 3), holds NaN or inf or lies
            outside the key range, or `depth` lies outside [0, 16]. The map is
            then unchanged.

        Examples
        --------
        >>> m = OccupancyOctree(0.1).insert_scan([[0.55, 0.05, 0.05]], [0.05, 0.05, 0.05])
        >>> m.delete_cells([[0.55, 0.05, 0.05], [0.56, 0.05, 0.05]])
        1
        >>> m.log_odds([[0.55, 0.05, 0.05], [0.45, 0.05, 0.05]]).round(3).tolist()
        [nan, -0.405]
        """
        depth = self._check_depth(depth)
        keys = self.coord_to_key(points)
        if len(keys) == 0:
            return 0
        return int(self._delete(keys, depth))







    # ------------------------------------------------------------------ structure
    def prune(self) -> "OccupancyOctree":
        """Merge every set of eight identical leaves into their parent (liboctomap's ``prune``).

        Returns
        -------
        self
            The map.
        """
        self._prune()
        return self

    def expand(self) -> "OccupancyOctree":
        """Split every pruned leaf down to the finest resolution (liboctomap's ``expand``).

        Returns
        -------
        self
            The map.
        """
        self._expand()
        return self

    # ------------------------------------------------------------------ I/O





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

    # ------------------------------------------------------------------ helpers
    def _sensor_params(self) -> dict:
        return {k: v for k, v in self._params.items() if k != "resolution"}

def _rebuild(cls, params: dict, data: bytes) -> OccupancyOctree:
    """Unpickle: the header stores the resolution with full precision (repr)."""
    return cls.from_bytes(data, **{k: v for k, v in params.items() if k != "resolution"})








def _discretized(points: np.ndarray, resolution: float) -> np.ndarray:
    """liboctomap's ``discretize``: the centre of each distinct cell holding a point."""
    keys = np.floor(points.astype(np.float64) * (1.0 / resolution))
    keys = np.unique(keys, axis=0)
    return np.ascontiguousarray((keys + 0.5) * resolution, dtype=np.float32)


