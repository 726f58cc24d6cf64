"""The log-odds occupancy octree: liboctomap's ``OcTree`` under a numpy API."""

from __future__ import annotations

import numbers
import os
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import _octomap_format as fmt
from ._logodds_map import MODES, Leaves, LogOddsMap
from ._octree import (
    KEYRAY_CELLS, TREE_DEPTH, TREE_MAX_VAL, _check_binary_data, _check_full_data, _OcTree,
)
from ._validation import (
    as_numeric, as_path, as_points, check_bool, check_choice, check_int, check_real,
    check_resolution,
)

__all__ = ["OccupancyOctree", "Leaves", "Changes"]


class Changes(NamedTuple):
    """The cells a map recorded as changed (see :attr:`OccupancyOctree.track_changes`)."""

    #: Keys of the finest cells, uint16, shape (n, 3), sorted.
    keys: NDArray[np.uint16]
    #: Their centres, metres, shape (n, 3).
    centres: NDArray[np.float64]
    #: True where the cell was new (unknown before), False where its state flipped.
    new: NDArray[np.bool_]



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

    Parameters
    ----------
    resolution : float
        Edge length of the smallest cells, in metres. Must lie in ``[1e-15, 1e14]``:
        the range where liboctomap's single-precision ray traversal is sound
        (see the user guide's notes on single precision).
    prob_hit : float, default=0.7
        Probability that a cell is occupied given a ray ends in it; in (0.5, 1).
    prob_miss : float, default=0.4
        Probability that a cell is occupied given a ray crosses it; in (0, 0.5).
    clamping_min : float, default=0.1192
        Lower clamping bound (probability); in (0, 0.5).
    clamping_max : float, default=0.971
        Upper clamping bound (probability); in (0.5, 1).
    occupancy_threshold : float, default=0.5
        Cells at or above this probability count as occupied; in (0, 1).

    Attributes
    ----------
    resolution : float
        Edge length of the smallest cells.
    num_leaves : int
        Number of leaves (known cells after pruning).
    num_nodes : int
        Number of nodes, inner ones included.
    bounds : tuple of ndarray of shape (3,)
        Minimum and maximum corner of the known space (NaN when empty).
    last_insert_ : dict
        Statistics of the last :meth:`insert_scan`: ``rays`` traversed (super
        rays count once), and, for the methods occgp implements itself,
        ``updated_cells``, ``traversed_cells`` (cell visits that counted a
        ray: those the culling region spares are not walked or not counted),
        ``region_cells`` (-1 without culling), ``superrays`` (whether rays
        were grouped) and the seconds spent on the end points, on super rays,
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

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(resolution={self.resolution!r}, "
                f"num_leaves={self.num_leaves})")

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
            bit. ``"auto"`` is ``"superray+culling"`` (``"plain"`` with
            `discretize`). ``"plain"`` traverses every ray in full (with
            ``mode="scan"`` it is liboctomap's ``insertPointCloud`` itself;
            otherwise occgp's traversal, which visits the cells
            ``computeRayKeys`` visits, and one-pass tree update). ``"superray"``
            groups the rays that end in a cell holding at least
            `superray_threshold` end points into *super rays* [1]_: rays whose
            crossings of the cell borders on the way (the mapping lines) give
            the same keys traverse the same cells, so one of them is traversed
            and counted for all. A ray joins a super ray only when its margins
            to every border exceed the error bound of liboctomap's
            single-precision traversal, which keeps the map identical; other
            rays are traversed on their own. ``"culling"``
            first grows the scan's *culling region* [1]_: the cells around the
            sensor that are fully free (at the lower clamp), hold no end point
            of the scan, and are reached from the sensor through such cells
            only. A ray's cells in the region form a prefix of its traversal
            and their updates would change nothing, so they are skipped: each
            ray is walked back from its end until it enters the region (when
            the walk can be certified to give liboctomap's cells; forward
            otherwise). It pays off once the map has saturated free space, e.g.
            along a trajectory. ``"superray+culling"`` does both, and adapts:
            after a scan whose grouping took longer than the traversal it saved
            (as measured in that scan), the next :attr:`SUPERRAY_BACKOFF` scans
            use the culling region alone, twice as many after each further such
            scan in a row (the map is the same either way). In
            every super-ray method, cells whose rays the mapping lines split
            into more classes than they have rays are not grouped.
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
            most the cores, and about one per 64 rays). Each thread counts its
            share of the rays on its own; the counts are merged (integer sums)
            before the one tree update, so the map and :attr:`last_insert_`'s
            counts are the same for every `n_jobs`. It applies to occgp's
            traversal (every `method` but ``"plain"`` with ``mode="scan"``, and
            that one too where it falls back to occgp's traversal: change
            tracking on, or rays too long for liboctomap's key buffer);
            liboctomap's own ``insertPointCloud`` runs on one thread. Each
            thread's dense counts take 4 bytes per cell of the scan's key box,
            within 2^24 cells for all threads together: a scan whose box holds
            more than 2^24 / n cells runs on fewer threads, and one whose box
            holds more than 2^24 cells counts in hash tables (on every thread).

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
            an int). The map is then unchanged.

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
        """
        from ._validation import check_n_jobs, n_threads
        threads = n_threads(check_n_jobs(n_jobs))
        discretize = check_bool(discretize, "discretize")
        mode = check_choice(mode, "mode", MODES)
        method, threshold = self._check_method(
            "plain" if discretize and isinstance(method, str) and method == "auto" else method,
            superray_threshold)
        if discretize and (mode != "scan" or method != "plain"):
            raise ValueError("discretize=True is only defined for mode='scan', method='plain'")
        liboctomap = mode == "scan" and method == "plain"
        box = None if bbox is None else self._check_bbox(bbox)
        scan = self._validated_scan(points, origin, max_range, mode, check_ends=liboctomap)
        if scan is None:
            return self
        pts, org, rng, cells = scan
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
                    and not self._is_tracking()):
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
            pts = np.ascontiguousarray(pts[self._bbx_rays(pts, org, rng, box)])
            key_box = self.coord_to_key(box)
            if len(pts) == 0:
                self.last_insert_ = {"rays": 0}
                return self
        threshold = self._adaptive_threshold(method, threshold)
        self._record_insert(self._insert_batch(
            pts, org, rng, mode == "ray", method.endswith("culling"), None, threshold,
            False, self._max_scan_cells(), key_box, threads), pts, org, rng, method,
            threshold)
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
            Named tuple ``(keys, centres, new)``: the finest cells' keys
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
        """Forget the recorded changes (tracking stays as it is); return self."""
        self._reset_changes()
        return self

    def _check_bbox(self, bbox: ArrayLike) -> np.ndarray:
        """`bbox` as a float32 (2, 3) array: finite, min <= max, corners in key range."""
        box = as_numeric(bbox, "bbox")
        if box.shape != (2, 3):
            raise ValueError(f"bbox must have shape (2, 3) (min and max corner), got {box.shape}")
        with np.errstate(over="ignore"):
            box32 = np.ascontiguousarray(box, dtype=np.float32)
        if not np.isfinite(box32).all():
            raise ValueError("bbox must be finite (in single precision)")
        if (box32[0] > box32[1]).any():
            raise ValueError(f"bbox must have min <= max on every axis, got {box.tolist()}")
        ok = self._in_range(box32)
        if not ok.all():
            self._raise_out_of_range("bbox corners", ok, "")
        return box32

    def update_cells(self, points: ArrayLike, log_odds: ArrayLike | None = None, *,
                     occupied: ArrayLike | None = None) -> "OccupancyOctree":
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
        if len(keys) == 0:
            return self
        packed = _pack(keys)
        order = np.argsort(packed, kind="stable")
        sorted_keys = packed[order]
        start = np.r_[True, sorted_keys[1:] != sorted_keys[:-1]]
        group_start = np.maximum.accumulate(np.where(start, np.arange(len(order)), 0))
        rank = np.arange(len(order)) - group_start      # the row's turn within its cell
        by_round = np.lexsort((sorted_keys, rank))
        bounds = np.searchsorted(rank[by_round], np.arange(rank.max() + 2))
        rows = order[by_round]
        for r in range(len(bounds) - 1):
            take = rows[bounds[r]:bounds[r + 1]]
            self._apply_cells(np.ascontiguousarray(packed[take]),
                              np.ascontiguousarray(values[take]))
        return self

    def set_cells(self, points: ArrayLike, log_odds: ArrayLike) -> "OccupancyOctree":
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
        if len(keys):
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

    def coord_to_key(self, points: ArrayLike) -> NDArray[np.uint16]:
        """The 16-bit keys of the finest cells holding `points` (liboctomap's ``coordToKey``).

        ``floor(coordinate / resolution) + 32768`` per axis, from the
        single-precision coordinate as liboctomap computes it.

        Parameters
        ----------
        points : array-like of shape (n_points, 3)

        Returns
        -------
        keys : ndarray of uint16, shape (n_points, 3)

        Raises
        ------
        ValueError
            If `points` is malformed, not finite, or outside the key range.

        Examples
        --------
        >>> OccupancyOctree(0.1).coord_to_key([[0.05, -0.05, 1.0]]).tolist()
        [[32768, 32767, 32778]]
        """
        pts = self._as_float32_points(points, "points")
        ok = self._in_range(pts)
        if not ok.all():
            self._raise_out_of_range("points", ok, "")
        keys = np.floor(pts.astype(np.float64) * (1.0 / self.resolution)) + TREE_MAX_VAL
        return np.ascontiguousarray(keys, dtype=np.uint16)

    def key_to_coord(self, keys: ArrayLike, depth: int = TREE_DEPTH) -> NDArray[np.float64]:
        """Centres of the cells of `keys` at `depth` (liboctomap's ``keyToCoord``).

        Parameters
        ----------
        keys : array-like of int, shape (n_keys, 3)
            Keys in [0, 65535].
        depth : int, default=16
            Tree depth of the cells: 16 is the finest (edge ``resolution``),
            ``d`` gives the node of edge ``resolution * 2**(16 - d)`` holding
            the key.

        Returns
        -------
        centres : ndarray of shape (n_keys, 3)

        Raises
        ------
        TypeError
            If `keys` does not hold integers.
        ValueError
            If `keys` is not of shape (n_keys, 3), a key lies outside
            [0, 65535], or `depth` outside [0, 16].

        Examples
        --------
        >>> m = OccupancyOctree(0.1)
        >>> m.key_to_coord(m.coord_to_key([[0.05, -0.05, 1.0]])).round(3).tolist()
        [[0.05, -0.05, 1.05]]
        """
        depth = check_int(depth, "depth", low=0, high=TREE_DEPTH)
        arr = as_numeric(keys, "keys", kinds="iu")
        if arr.ndim != 2 or arr.shape[1] != 3:
            raise ValueError(f"keys must have shape (n_keys, 3), got {arr.shape}")
        if arr.size and (arr.min() < 0 or arr.max() > 2 * TREE_MAX_VAL - 1):
            raise ValueError(f"keys must lie in [0, {2 * TREE_MAX_VAL - 1}], got "
                             f"[{arr.min()}, {arr.max()}]")
        return self._key_to_coord(np.ascontiguousarray(arr, dtype=np.uint16), depth)

    def extract_points(self, occupied: bool = True) -> tuple[NDArray[np.float64],
                                                            NDArray[np.float64]]:
        """Centres and sizes of the occupied (or the free) leaves.

        Parameters
        ----------
        occupied : bool, default=True
            True: the leaves at or above the occupancy threshold; False: the
            known leaves below it.

        Returns
        -------
        centres : ndarray of shape (n_leaves, 3)
        sizes : ndarray of shape (n_leaves,)
            Edge of each leaf (pruned leaves are larger than the resolution).

        Examples
        --------
        >>> m = OccupancyOctree(0.1).insert_scan([[0.55, 0.05, 0.05]], [0.05, 0.05, 0.05])
        >>> centres, sizes = m.extract_points()
        >>> centres.round(2).tolist(), len(m.extract_points(occupied=False)[0])
        ([[0.55, 0.05, 0.05]], 5)
        """
        occupied = check_bool(occupied, "occupied")
        centres, sizes, values = self._leaves(False)
        keep = (values >= np.float32(self._log_odds_thresholds()[2])) == occupied
        return centres[keep], sizes[keep]

    def to_max_likelihood(self) -> "OccupancyOctree":
        """Set every cell to its clamping bound by its state (liboctomap's
        ``toMaxLikelihood``): occupied cells to ``clamping_max``, free ones to
        ``clamping_min``; then prune. Returns self."""
        self._to_max_likelihood()
        return self

    # ------------------------------------------------------------------ queries
    def cast_rays(
        self,
        origins: ArrayLike,
        directions: ArrayLike,
        *,
        max_range: float | ArrayLike | None = None,
        ignore_unknown: bool = False,
    ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """Cast rays through the map and return where they stop (liboctomap's ``castRay``).

        A ray stops at the first occupied cell (a hit), at an unknown cell unless
        `ignore_unknown`, or after `max_range` metres.

        Parameters
        ----------
        origins : array-like of shape (n_rays, 3) or (3,)
            Ray origins; a single origin is shared by all rays.
        directions : array-like of shape (n_rays, 3)
            Ray directions; need not be unit length, must not be zero.
        max_range : float or array-like of shape (n_rays,), default=None
            Longest distance to travel. None: no limit (with `ignore_unknown`,
            rays then stop once they leave the map's bounding box).
        ignore_unknown : bool, default=False
            Treat unknown cells as free instead of stopping there.

        Returns
        -------
        ends : ndarray of shape (n_rays, 3)
            Centre of the cell where each ray stopped.
        hits : ndarray of bool, shape (n_rays,)
            True where the ray stopped at an occupied cell.

        Examples
        --------
        >>> m = OccupancyOctree(0.1).insert_scan([[1.02, 0.05, 0.05]], [0.05, 0.05, 0.05])
        >>> ends, hits = m.cast_rays([0.05, 0.05, 0.05], [[1.0, 0, 0]])
        >>> hits.tolist(), ends.round(2).tolist()
        ([True], [[1.05, 0.05, 0.05]])
        """
        dirs = _as_float32_directions(directions)
        n = len(dirs)
        ignore_unknown = check_bool(ignore_unknown, "ignore_unknown")
        org_arr = as_numeric(origins, "origins")
        if org_arr.ndim == 1:
            orgs = np.repeat(self._as_float32_origin(org_arr, "origins")[None], n, axis=0)
        else:
            orgs = self._as_float32_points(org_arr, "origins")
            if len(orgs) != n:
                raise ValueError(f"origins must have shape (3,) or ({n}, 3) to match "
                                 f"directions, got {orgs.shape}")
        ok = self._in_range(orgs)
        if not ok.all():
            self._raise_out_of_range("origins", ok, "")
        if max_range is None:
            ranges = np.full(n, -1.0)
            if ignore_unknown:
                ranges = self._distance_past_bounds(orgs)
        elif isinstance(max_range, (numbers.Real, np.floating, np.integer)):
            ranges = np.full(n, check_real(max_range, "max_range", low=0.0))
        else:
            try:
                ranges = np.asarray(max_range)
            except ValueError:  # ragged
                ranges = np.array(None)
            if ranges.dtype.kind not in "iuf" or ranges.ndim == 0:
                raise TypeError(f"max_range must be a real number or an array of them, "
                                f"got {type(max_range).__name__} of dtype {ranges.dtype}")
            if ranges.shape != (n,):
                raise ValueError(f"max_range must be a scalar or of shape ({n},), "
                                 f"got {ranges.shape}")
            ranges = ranges.astype(np.float64)
            if not (np.isfinite(ranges) & (ranges > 0)).all():
                raise ValueError("max_range must be positive and finite")
        # no ray travels farther than the key range's diagonal (castRay stops there)
        ranges = np.minimum(ranges, 2 * np.sqrt(3) * (self.key_range[1] - self.key_range[0]))
        return self._cast_rays(orgs, dirs, bool(ignore_unknown), np.ascontiguousarray(ranges))

    def _distance_past_bounds(self, origins: np.ndarray) -> np.ndarray:
        """Per origin, a range past which no known cell lies (for unlimited casts)."""
        lo, hi = self.bounds
        if not np.isfinite(lo).all():
            return np.full(len(origins), self.resolution)
        corners = np.array(np.meshgrid(*zip(lo, hi), indexing="ij")).reshape(3, -1).T
        far = np.linalg.norm(origins[:, None, :] - corners[None], axis=2).max(axis=1)
        return far + 2 * self.resolution

    def leaves(self, *, occupied_only: bool = False, bbox: ArrayLike | None = None) -> Leaves:
        """Return every leaf of the tree as arrays.

        Parameters
        ----------
        occupied_only : bool, default=False
            Keep only the occupied leaves.
        bbox : array-like of shape (2, 3), default=None
            ``[min_corner, max_corner]``: keep only the leaves overlapping this
            axis-aligned box.

        Returns
        -------
        leaves : Leaves
            Named tuple ``(centers, sizes, log_odds)``.

        Examples
        --------
        >>> m = OccupancyOctree(0.1).insert_scan([[0.55, 0.05, 0.05]], [0.05, 0.05, 0.05])
        >>> centers, sizes, log_odds = m.leaves(occupied_only=True)
        >>> centers.round(2).tolist(), sizes.round(2).tolist()
        ([[0.55, 0.05, 0.05]], [0.1])
        """
        occupied_only = check_bool(occupied_only, "occupied_only")
        if bbox is not None:
            box = as_numeric(bbox, "bbox")
            if box.shape != (2, 3):
                raise ValueError(f"bbox must have shape (2, 3) (min and max corner), "
                                 f"got {box.shape}")
            box = np.ascontiguousarray(box, dtype=np.float64)
            if np.isnan(box).any() or (box[0] > box[1]).any():
                raise ValueError(f"bbox must have min <= max on every axis, got {box.tolist()}")
            box = np.clip(box, *(np.array(self.key_range) * [1, 1 - 1e-12]))
            return Leaves(*self._leaves(occupied_only, box))
        return Leaves(*self._leaves(occupied_only))

    # ------------------------------------------------------------------ structure
    @property
    def num_leaves(self) -> int:
        """Number of leaves (known cells, after pruning)."""
        return self._num_leaves()

    @property
    def num_nodes(self) -> int:
        """Number of nodes in the tree, inner nodes included."""
        return self._num_nodes()

    @property
    def bounds(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(min corner, max corner) of the known space, in metres; NaN when empty."""
        if self.num_nodes == 0:
            return np.full(3, np.nan), np.full(3, np.nan)
        return self._bounds()

    def memory_usage(self) -> int:
        """Bytes used by the tree's nodes (liboctomap's estimate)."""
        return self._memory_usage()

    def prune(self) -> "OccupancyOctree":
        """Merge every set of eight identical leaves into their parent; return self."""
        self._prune()
        return self

    def expand(self) -> "OccupancyOctree":
        """Split every pruned leaf down to the finest resolution; return self."""
        self._expand()
        return self

    def clear(self) -> "OccupancyOctree":
        """Remove every cell; return self."""
        self._clear()
        return self

    # ------------------------------------------------------------------ I/O
    def to_bytes(self, format: str = "ot") -> bytes:
        """Serialise the map in an OctoMap file format.

        Parameters
        ----------
        format : {"ot", "bt"}, default="ot"
            ``"ot"`` keeps every log-odds value. ``"bt"`` is OctoMap's compact
            binary format: it keeps only whether each leaf is free or occupied
            (reading it back gives clamped values). The map itself is unchanged.

        Returns
        -------
        data : bytes
            The contents of a file that OctoMap's tools (octovis, ...) read.
        """
        binary = _check_format(format) == "bt"
        if binary:
            # liboctomap's .bt writer stores the max-likelihood tree: build it on a copy
            tree = type(self).from_bytes(self.to_bytes("ot"), **self._sensor_params())
            tree._to_max_likelihood()
            body = tree._write_data(True)
            size = tree.num_nodes
        else:
            body = self._write_data(False)
            size = self.num_nodes
        return fmt.write_header(binary, size, self.resolution) + body

    @classmethod
    def from_bytes(cls, data: bytes, **params) -> "OccupancyOctree":
        """Build a map from the contents of a ``.bt`` or ``.ot`` file.

        Parameters
        ----------
        data : bytes
            File contents; the format is read from the header.
        **params
            Sensor-model parameters (``prob_hit``, ``clamping_min``, ...); the
            files store only the resolution. The clamping bounds give the
            values of ``.bt`` leaves.

        Raises
        ------
        ValueError
            If the data is not an OcTree file, is truncated or corrupt.
        """
        if not isinstance(data, (bytes, bytearray, memoryview)):
            raise TypeError(f"data must be bytes, got {type(data).__name__}")
        return cls._from_data(bytes(data), "data", params)

    def save(self, path: str | os.PathLike, format: str | None = None) -> "OccupancyOctree":
        """Write the map to an OctoMap file (see :meth:`to_bytes`).

        Parameters
        ----------
        path : str or path-like
            Destination. Its suffix (``.bt`` or ``.ot``) gives the format unless
            `format` is set.
        format : {"ot", "bt"}, default=None

        Returns
        -------
        self : OccupancyOctree
        """
        path = os.fspath(as_path(path))
        if format is None:
            format = os.path.splitext(path)[1].lstrip(".").lower()
            if format not in fmt.FORMATS:
                raise ValueError(f"path must end in .bt or .ot (or pass format=), got {path!r}")
        data = self.to_bytes(format)
        with open(path, "wb") as f:
            f.write(data)
        return self

    @classmethod
    def load(cls, path: str | os.PathLike, **params) -> "OccupancyOctree":
        """Read a map from an OctoMap ``.bt`` or ``.ot`` file.

        Parameters
        ----------
        path : str or path-like
        **params
            Sensor-model parameters, as for :meth:`from_bytes`.

        Raises
        ------
        OSError
            If the file cannot be read.
        ValueError
            If it is not an OcTree file, or is truncated or corrupt.
        """
        path = os.fspath(as_path(path))
        with open(path, "rb") as f:
            data = f.read()
        return cls._from_data(data, path, params)

    @classmethod
    def _from_data(cls, data: bytes, source: str, params: dict) -> "OccupancyOctree":
        header = fmt.parse_header(data, source)
        if header.tree_type != "OcTree":
            raise ValueError(f"{source} holds a {header.tree_type!r} tree; only 'OcTree' "
                             "(occupancy) files can be read")
        try:
            check_resolution(header.resolution)
        except ValueError as exc:
            raise ValueError(f"{source}: the header's {exc}") from None
        tree = cls(header.resolution, **params)
        if header.size == 0:
            return tree
        check = _check_binary_data if header.binary else _check_full_data
        buf = np.frombuffer(data, dtype=np.uint8)
        try:
            nodes, end = check(buf, header.data_offset)
        except ValueError as exc:
            raise ValueError(f"{source}: {exc}") from None
        if nodes != header.size:
            raise ValueError(f"{source}: corrupt data: the header announces {header.size} "
                             f"nodes, the data holds {nodes}")
        tree._read_data(data[header.data_offset:end], header.binary, header.resolution)
        return tree

    def __reduce__(self):
        return (_rebuild, (type(self), self.get_params(), self.to_bytes("ot")))

    # ------------------------------------------------------------------ helpers
    def _sensor_params(self) -> dict:
        return {k: v for k, v in self._params.items() if k != "resolution"}

def _rebuild(cls, params: dict, data: bytes) -> OccupancyOctree:
    """Unpickle: the header stores the resolution with full precision (repr)."""
    return cls.from_bytes(data, **{k: v for k, v in params.items() if k != "resolution"})


def _as_float32_directions(directions: ArrayLike) -> np.ndarray:
    """Ray directions for liboctomap's ``castRay``, which normalises them in single
    precision: rows whose float squared length would overflow or underflow (e.g. 1e39,
    or 1e-30) are normalised in double precision first; the others are passed as given."""
    d64 = as_points(directions, "directions")
    zero = ~(d64 != 0).any(axis=1)
    if zero.any():
        raise ValueError(f"directions must be non-zero, got {int(zero.sum())} zero vectors "
                         f"(first: row {int(np.flatnonzero(zero)[0])})")
    with np.errstate(over="ignore", under="ignore"):
        d = d64.astype(np.float32)
        nsq = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2]
    bad = ~((nsq >= np.finfo(np.float32).tiny) & np.isfinite(nsq))
    if bad.any():
        u = d64[bad] / np.abs(d64[bad]).max(axis=1, keepdims=True)
        d[bad] = u / np.linalg.norm(u, axis=1, keepdims=True)
    return np.ascontiguousarray(d)


def _pack(keys: np.ndarray) -> np.ndarray:
    """Packed keys (x in the low 16 bits), as the compiled core hashes them."""
    k = keys.astype(np.uint64)
    return k[:, 0] | (k[:, 1] << np.uint64(16)) | (k[:, 2] << np.uint64(32))


def unpack_keys(packed: np.ndarray) -> NDArray[np.uint16]:
    """The (n, 3) uint16 keys of packed keys (the inverse of :func:`_pack`)."""
    return np.column_stack([(packed >> np.uint64(16 * a)) & np.uint64(0xFFFF)
                            for a in range(3)]).astype(np.uint16).reshape(-1, 3)


def _discretized(points: np.ndarray, resolution: float) -> np.ndarray:
    """liboctomap's ``discretize``: the centre of each distinct cell holding a point."""
    keys = np.floor(points.astype(np.float64) * (1.0 / resolution))
    keys = np.unique(keys, axis=0)
    return np.ascontiguousarray((keys + 0.5) * resolution, dtype=np.float32)


def _check_format(format: str) -> str:
    return check_choice(format, "format", fmt.FORMATS)
