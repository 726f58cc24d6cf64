"""The log-odds occupancy octree: liboctomap's ``OcTree`` under a numpy API."""

from __future__ import annotations

import numbers
import os
import warnings
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import _octomap_format as fmt
from ._logodds_map import MODES, Leaves, OctreeFace
from .maps import register
from ._octree import (
    KEYRAY_CELLS, TREE_DEPTH, TREE_MAX_VAL, _check_binary_data, _check_full_data, _OcTree,
)
from ._validation import (
    as_numeric, as_path, as_points, check_bool, check_choice, check_int, check_n_jobs,
    check_real, check_resolution, n_threads,
)

__all__ = ["OccupancyOctree", "Leaves", "Changes", "Nodes"]


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


class Nodes(NamedTuple):
    """The nodes of an octree, inner ones included (see :meth:`OccupancyOctree.nodes`)."""

    #: Node centres, metres, shape (n_nodes, 3).
    centers: NDArray[np.float64]
    #: Edge lengths, shape (n_nodes,): ``resolution * 2**(16 - depths)``.
    sizes: NDArray[np.float64]
    #: Tree depth of each node, uint8: 0 is the root, 16 the finest cells.
    depths: NDArray[np.uint8]
    #: Log-odds, float32 as liboctomap stores them; an inner node holds the largest
    #: log-odds of its children.
    log_odds: NDArray[np.float32]
    #: True where the node is listed as a leaf: it has no children, or lies at the
    #: listing's ``max_depth``.
    is_leaf: NDArray[np.bool_]

@register("octree", formats=(".bt", ".ot"), description="OctoMap's log-odds octree")
class OccupancyOctree(OctreeFace, _OcTree):
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

    def coord_to_key(self, points: ArrayLike, depth: int = TREE_DEPTH) -> NDArray[np.uint16]:
        """The 16-bit keys of the cells holding `points` (liboctomap's ``coordToKey``).

        ``floor(coordinate / resolution) + 32768`` per axis, from the
        single-precision coordinate as liboctomap computes it. With `depth`
        below 16, the key of the depth-`depth` node holding the point, as
        liboctomap's ``coordToKey(coord, depth)`` and ``adjustKeyAtDepth``
        give it: the key at the node's centre, ``(key >> s << s) + (1 << (s -
        1))`` per axis with ``s = 16 - depth``; ``key_to_coord(keys, depth)``
        gives the node's centre.

        Parameters
        ----------
        points : array-like of shape (n_points, 3)
        depth : int, default=16
            Tree depth of the cells, in [1, 16] (16: the finest cells). Depth
            0, the root, has no key of its own (liboctomap's formula wraps
            around there).

        Returns
        -------
        keys : ndarray of uint16, shape (n_points, 3)

        Raises
        ------
        TypeError
            If `points` does not hold numbers or `depth` is not an int.
        ValueError
            If `points` is malformed, not finite, or outside the key range, or
            `depth` lies outside [1, 16].

        Examples
        --------
        >>> OccupancyOctree(0.1).coord_to_key([[0.05, -0.05, 1.0]]).tolist()
        [[32768, 32767, 32778]]
        >>> OccupancyOctree(0.1).coord_to_key([[0.05, -0.05, 1.0]], depth=14).tolist()
        [[32770, 32766, 32778]]
        """
        depth = check_int(depth, "depth", low=1, high=TREE_DEPTH)
        pts = self._as_float32_points(points, "points")
        ok = self._in_range(pts)
        if not ok.all():
            self._raise_out_of_range("points", ok, "")
        keys = np.floor(pts.astype(np.float64) * (1.0 / self.resolution)) + TREE_MAX_VAL
        shift = TREE_DEPTH - depth
        if shift:
            keys = np.floor(keys / (1 << shift)) * (1 << shift) + (1 << (shift - 1))
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
    def occupancy(self, points: ArrayLike, *, depth: int = 0) -> NDArray[np.float64]:
        """Probability of occupancy at each point, NaN where the map knows nothing.

        Parameters
        ----------
        points : array-like of shape (n_points, 3)
            Query points, in metres. Points outside the key range are unknown.
        depth : int, default=0
            Tree depth of the answering node, in [0, 16]; 0 means 16 (the leaf
            holding the point). ``d`` answers with the depth-``d`` node holding
            the point, as liboctomap's ``search(key, depth)``: an inner node's
            value is the largest log-odds of its children, so a coarse query
            is conservative (occupied if anything below is); a pruned leaf
            coarser than ``d`` answers for itself.

        Returns
        -------
        p : ndarray of shape (n_points,)
            Occupancy probability of the node holding each point, or NaN.

        Raises
        ------
        TypeError
            If `points` does not hold numbers or `depth` is not an int.
        ValueError
            If `points` is not of shape (n_points, 3) or holds NaN or inf, or
            `depth` lies outside [0, 16].

        Examples
        --------
        >>> m = OccupancyOctree(0.1).insert_scan([[0.55, 0.05, 0.05]], [0.05, 0.05, 0.05])
        >>> m.occupancy([[0.45, 0.05, 0.05]]).round(2).tolist()      # a free leaf
        [0.4]
        >>> m.occupancy([[0.45, 0.05, 0.05]], depth=13).round(2).tolist()  # its 0.8 m node
        [0.7]
        """
        return self._depth_query(points, depth, 0)

    def log_odds(self, points: ArrayLike, *, depth: int = 0) -> NDArray[np.float64]:
        """Log-odds of occupancy at each point, NaN where the map knows nothing.

        Parameters
        ----------
        points : array-like of shape (n_points, 3)
            Query points, in metres. Points outside the key range are unknown.
        depth : int, default=0
            Tree depth of the answering node, as for :meth:`occupancy`.

        Returns
        -------
        l : ndarray of shape (n_points,)
            The node's stored log-odds (float32 values), or NaN.

        Raises
        ------
        TypeError, ValueError
            As :meth:`occupancy`.
        """
        return self._depth_query(points, depth, 1)

    def is_occupied(self, points: ArrayLike, *, return_unknown: bool = False,
                    depth: int = 0):
        """Whether each point lies in an occupied cell.

        A cell is occupied when its probability is at least
        ``occupancy_threshold``. Unknown cells are reported as not occupied;
        ask for `return_unknown` to tell them apart from free ones.

        Parameters
        ----------
        points : array-like of shape (n_points, 3)
        return_unknown : bool, default=False
            Also return the mask of points in unknown cells.
        depth : int, default=0
            Tree depth of the answering node, as for :meth:`occupancy`: an
            inner node is occupied when one of its children is.

        Returns
        -------
        occupied : ndarray of bool, shape (n_points,)
        unknown : ndarray of bool, shape (n_points,)
            Only when `return_unknown` is True.

        Raises
        ------
        TypeError, ValueError
            As :meth:`occupancy`, and TypeError if `return_unknown` is not a
            bool.

        Examples
        --------
        >>> m = OccupancyOctree(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0])
        >>> occ, unk = m.is_occupied([[1.0, 0, 0], [0.5, 0, 0], [9, 9, 9]], return_unknown=True)
        >>> occ.tolist(), unk.tolist()
        ([True, False, False], [False, False, True])
        """
        return_unknown = check_bool(return_unknown, "return_unknown")
        state = self._depth_query(points, depth, 2)
        occupied = state == 1
        return (occupied, state < 0) if return_unknown else occupied

    def _depth_query(self, points: ArrayLike, depth: int, what: int):
        """The core's query `what` (see ``_query_depth``) at a checked depth."""
        d = self._check_depth(depth)
        pts = self._as_float32_points(points, "points")
        return self._query(pts, what) if d == TREE_DEPTH else self._query_depth(pts, what, d)

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

    def leaves(self, *, occupied_only: bool = False, bbox: ArrayLike | None = None,
               max_depth: int = 0) -> Leaves:
        """Return every leaf of the tree as arrays (liboctomap's ``begin_leafs``).

        The leaves come in liboctomap's iterator order (depth first, children
        in liboctomap's child order).

        Parameters
        ----------
        occupied_only : bool, default=False
            Keep only the occupied leaves.
        bbox : array-like of shape (2, 3), default=None
            ``[min_corner, max_corner]``: keep only the leaves overlapping this
            axis-aligned box (``begin_leafs_bbx``). A box larger than the key
            range means all of it.
        max_depth : int, default=0
            Deepest level listed, in [0, 16]; 0 means 16 (the leaves
            themselves). As ``begin_leafs(max_depth)``: inner nodes at
            `max_depth` are listed as leaves, with their own size and value
            (the largest log-odds below them), and `occupied_only` tests
            that value.

        Returns
        -------
        leaves : Leaves
            Named tuple ``(centers, sizes, log_odds)``.

        Raises
        ------
        TypeError
            If `occupied_only` is not a bool, `max_depth` not an int, or `bbox`
            does not hold numbers.
        ValueError
            If `max_depth` lies outside [0, 16], or `bbox` is not of shape
            (2, 3), holds NaN or has min > max on an axis.

        Examples
        --------
        >>> m = OccupancyOctree(0.1).insert_scan([[0.55, 0.05, 0.05]], [0.05, 0.05, 0.05])
        >>> centers, sizes, log_odds = m.leaves(occupied_only=True)
        >>> centers.round(2).tolist(), sizes.round(2).tolist()
        ([[0.55, 0.05, 0.05]], [0.1])
        >>> leaves = m.leaves(max_depth=13)     # one 0.8 m cube holds the scan's cells
        >>> leaves.sizes.round(2).tolist(), leaves.log_odds.round(3).tolist()
        ([0.8], [0.847])
        """
        occupied_only = check_bool(occupied_only, "occupied_only")
        depth = self._check_depth(max_depth, "max_depth")
        if depth < TREE_DEPTH:
            key_box = None if bbox is None else self._leaves_key_box(bbox)
            centers, sizes, _, values, _ = self._nodes(depth, True, occupied_only, key_box)
            return Leaves(centers, sizes, values)
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

    def nodes(self, *, max_depth: int = 0, bbox: ArrayLike | None = None) -> "Nodes":
        """Return every node of the tree, inner nodes included (liboctomap's ``begin_tree``).

        The nodes come in the order of liboctomap's tree iterator: depth first,
        each node before its children, children in liboctomap's child order
        (``x`` in bit 0, ``y`` in bit 1, ``z`` in bit 2 of the child index).
        The root (depth 0, centre at the origin, edge ``resolution * 2**16``)
        comes first when the map is not empty. An inner node's log-odds is the
        largest of its children's (liboctomap's ``updateInnerOccupancy``,
        which occgp keeps current after every update and deletion).

        Parameters
        ----------
        max_depth : int, default=0
            Deepest level listed, in [0, 16]; 0 means 16 (every node). Nodes
            at `max_depth` are listed as leaves (``is_leaf`` True) and their
            children are not listed, as ``begin_tree(max_depth)`` does.
        bbox : array-like of shape (2, 3), default=None
            ``[min_corner, max_corner]``: list only the nodes whose cube
            overlaps this box (and so, with each node, its ancestors). A box
            larger than the key range means all of it.

        Returns
        -------
        nodes : Nodes
            Named tuple ``(centers, sizes, depths, log_odds, is_leaf)``.

        Raises
        ------
        TypeError
            If `max_depth` is not an int or `bbox` does not hold numbers.
        ValueError
            If `max_depth` lies outside [0, 16], or `bbox` is not of shape
            (2, 3), holds NaN or has min > max on an axis.

        Examples
        --------
        >>> m = OccupancyOctree(0.1).insert_scan([[0.15, 0.05, 0.05]], [0.05, 0.05, 0.05])
        >>> nodes = m.nodes()
        >>> len(nodes.depths), int(nodes.depths[0]), int(nodes.is_leaf.sum())   # root first
        (18, 0, 2)
        """
        depth = self._check_depth(max_depth, "max_depth")
        key_box = None if bbox is None else self._leaves_key_box(bbox)
        return Nodes(*self._nodes(depth, False, False, key_box))

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

    def is_at_threshold(self, points: ArrayLike, *, depth: int = 0) -> NDArray[np.bool_]:
        """Whether each point's cell is at a clamping bound (liboctomap's ``isNodeAtThreshold``).

        True where the stored log-odds is at or beyond ``logit(clamping_max)``
        or ``logit(clamping_min)`` (as float32, liboctomap's comparison): such
        a cell does not change under further updates in the same direction.
        Unknown cells (and points outside the key range) give False.

        Parameters
        ----------
        points : array-like of shape (n_points, 3)
            Query points, in metres.
        depth : int, default=0
            Answer for the node at this depth, as :meth:`log_odds` does.

        Returns
        -------
        at_threshold : ndarray of bool, shape (n_points,)

        Raises
        ------
        TypeError, ValueError
            As :meth:`log_odds`.

        Examples
        --------
        >>> m = OccupancyOctree(0.1).insert_scan([[0.55, 0.05, 0.05]], [0.05, 0.05, 0.05])
        >>> pts = [[0.55, 0.05, 0.05], [5.0, 5.0, 5.0]]
        >>> m.is_at_threshold(pts).tolist(), m.to_max_likelihood().is_at_threshold(pts).tolist()
        ([False, False], [True, False])
        """
        depth = self._check_depth(depth)
        return self._query_depth(self._as_float32_points(points, "points"), 3, depth) == 1

    def ray_intersections(
        self,
        origins: ArrayLike,
        directions: ArrayLike,
        centres: ArrayLike,
        *,
        delta: float = 0.0,
    ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """Where each ray enters a cell (liboctomap's ``getRayIntersection``).

        For row ``i``, the line through ``origins[i]`` along ``directions[i]``
        is intersected with the six faces of the cube of edge ``resolution``
        centred at ``centres[i]`` (liboctomap's computation, in its mixed
        single and double precision, faces widened by 1e-6); of the faces it
        meets, the one nearest along the direction is kept (the smallest
        signed distance: behind the origin when the origin lies inside the
        cube), and the point ``origin + unit_direction * (distance + delta)``
        is returned. Typical use: the `ends` of :meth:`cast_rays` as
        `centres`, to get the surface point where each ray hit.

        Parameters
        ----------
        origins : array-like of shape (n_rays, 3) or (3,)
            Ray origins (one shared origin, or one per ray), in the key range.
        directions : array-like of shape (n_rays, 3)
            Ray directions; normalised (in single precision, as ``castRay``
            normalises them), must not be zero.
        centres : array-like of shape (n_rays, 3) or (3,)
            Centres of the cells, in the key range (used as given, not snapped
            to the cell grid).
        delta : float, default=0.0
            Metres to move the point along the ray (liboctomap's ``delta``):
            a small positive value puts it inside the cell; ``|delta|`` at
            most the key range's diagonal.

        Returns
        -------
        points : ndarray of shape (n_rays, 3)
            The entry points; NaN where the line misses the cube.
        found : ndarray of bool, shape (n_rays,)
            Whether the line meets the cube.

        Raises
        ------
        TypeError
            If an array does not hold real numbers or `delta` is not a real number.
        ValueError
            If a shape is wrong (or the rows of `origins` or `centres` do not
            match `directions`), an array holds NaN or inf, `origins` or
            `centres` lie outside the key range, a direction is zero, or
            `delta` is out of range.

        Examples
        --------
        >>> m = OccupancyOctree(0.1)
        >>> pts, found = m.ray_intersections([0.05, 0.05, 0.05], [[1.0, 0, 0]],
        ...                                  [[1.05, 0.05, 0.05]])
        >>> found.tolist(), pts.round(3).tolist()
        ([True], [[1.0, 0.05, 0.05]])
        """
        dirs = _as_float32_directions(directions)
        n = len(dirs)
        orgs = self._rows_in_range(origins, "origins", n)
        cens = self._rows_in_range(centres, "centres", n)
        reach = 2 * np.sqrt(3) * (self.key_range[1] - self.key_range[0])
        delta = check_real(delta, "delta", low=-reach, high=reach, low_open=False,
                           high_open=False)
        return self._ray_intersections(orgs, dirs, cens, delta)

    def _rows_in_range(self, x: ArrayLike, name: str, n: int) -> np.ndarray:
        """`x` as float32 rows, one per ray ((3,) is shared), all in the key range."""
        arr = as_numeric(x, name)
        if arr.ndim == 1:
            rows = np.repeat(self._as_float32_origin(arr, name)[None], n, axis=0)
        else:
            rows = self._as_float32_points(arr, name)
            if len(rows) != n:
                raise ValueError(f"{name} must have shape (3,) or ({n}, 3) to match "
                                 f"directions, got {rows.shape}")
            ok = self._in_range(rows)
            if not ok.all():
                self._raise_out_of_range(name, ok, "")
        return np.ascontiguousarray(rows)

    @property
    def tree_depth(self) -> int:
        """Depth of the tree (liboctomap's ``getTreeDepth``): always 16, the finest cells'."""
        return TREE_DEPTH

    def _check_depth(self, depth: int, name: str = "depth") -> int:
        """A node depth in [0, 16] as liboctomap's search takes it: 0 becomes 16."""
        d = check_int(depth, name, low=0, high=TREE_DEPTH)
        return d if d else TREE_DEPTH

    def _leaves_key_box(self, bbox: ArrayLike) -> np.ndarray:
        """The lowest and highest key of `bbox` (rows), clipped to the key range."""
        box = as_numeric(bbox, "bbox")
        if box.shape != (2, 3):
            raise ValueError(f"bbox must have shape (2, 3) (min and max corner), "
                             f"got {box.shape}")
        box = np.ascontiguousarray(box, dtype=np.float64)
        if np.isnan(box).any() or (box[0] > box[1]).any():
            raise ValueError(f"bbox must have min <= max on every axis, got {box.tolist()}")
        box = np.clip(box, *(np.array(self.key_range) * [1, 1 - 1e-12]))
        # as the compiled _leaves computes them
        keys = np.floor((1.0 / self.resolution) * box) + TREE_MAX_VAL
        return np.ascontiguousarray(np.clip(keys, 0, 2 * TREE_MAX_VAL - 1), dtype=np.uint16)

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

        Returns
        -------
        tree : OccupancyOctree
            A map of the class this is called on.

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

        Returns
        -------
        tree : OccupancyOctree
            A map of the class this is called on.

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
            hint = (" (read ColorOcTree files with occgp.ColorOctree.load)"
                    if header.tree_type == "ColorOcTree" else "")
            raise ValueError(f"{source} holds a {header.tree_type!r} tree; only 'OcTree' "
                             f"(occupancy) files can be read{hint}")
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
