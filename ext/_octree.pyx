# cython: language_level=3
# distutils: language = c++
"""Compiled core of :class:`occgp.OccupancyOctree`: liboctomap's ``OcTree`` behind typed loops.

Nothing here validates user input: :mod:`occgp.octree` coerces and checks every
array (shape, dtype, finiteness, key range) before it reaches these methods.
Every loop and every liboctomap call that does real work runs without the GIL;
a per-tree lock serialises the operations on one tree.
"""

cimport cython
from cython.parallel cimport prange
from cython.operator cimport dereference as deref, preincrement as inc
from libc.math cimport floor, isfinite
from libc.stdint cimport int64_t, uint8_t, uint16_t, uint32_t, uint64_t
from libc.string cimport memcpy
from libcpp cimport bool
from libcpp.memory cimport unique_ptr
from libcpp.string cimport string
from libcpp.unordered_map cimport unordered_map
from libcpp.vector cimport vector

from _keys cimport (
    KEY_DEPTH as _DEPTH, KEY_MAX_VAL as _MAX_VAL, KEYRAY_SAFE_CELLS, effective_end,
    pack_key as _pack, unpack_key as _unpack,
)
from _scan cimport ScanCell, ScanStats, empty_stats, scan_updates, scan_updates_free_only
from _status cimport Status
from liboctomap cimport (
    OcTree, OcTreeKey, OcTreeNode, Pointcloud, key_type, ostringstream, point3d,
)

import numpy as np

include "_scan_result.pxi"

#: Half the number of keys per axis (liboctomap's ``tree_max_val``, 16-level tree).
TREE_MAX_VAL = _MAX_VAL
#: Depth of the tree: leaves at this depth have the size of the resolution.
TREE_DEPTH = _DEPTH
#: The most cells a ray may cross for liboctomap's insertPointCloud (its KeyRay buffer).
KEYRAY_CELLS = KEYRAY_SAFE_CELLS


cdef extern from "_octree_batch.h" namespace "occgp" nogil:
    cdef cppclass CellUpdate:
        uint64_t code
        float update
    uint64_t morton_code(unsigned x, unsigned y, unsigned z)
    uint64_t morton_of_packed(uint64_t packed)
    size_t keep_in_box(vector[CellUpdate]& cells, const int* lo, const int* hi)
    OcTreeKey morton_key(uint64_t code)
    void sort_by_code(vector[CellUpdate]& cells, vector[CellUpdate]& scratch) except +
    size_t apply_updates(OcTree& tree, vector[CellUpdate]& cells,
                         vector[CellUpdate]& scratch, int n_threads) except +


cdef extern from "_octree_io.h" namespace "occgp" nogil:
    Status check_binary_data(const uint8_t* data, Py_ssize_t n, Py_ssize_t offset,
                             Py_ssize_t* nodes, Py_ssize_t* end) except +
    Status check_full_data(const uint8_t* data, Py_ssize_t n, Py_ssize_t offset,
                           int node_bytes, Py_ssize_t* nodes, Py_ssize_t* end) except +


cdef extern from "_octree_edit.h" namespace "occgp" nogil:
    cdef cppclass NodeList:
        vector[double] centers
        vector[double] sizes
        vector[uint8_t] depths
        vector[float] values
        vector[uint8_t] is_leaf
    bint delete_node(OcTree& tree, const OcTreeKey& key, unsigned depth) except +
    void collect_nodes(const OcTree& tree, unsigned max_depth, bint leaves_only,
                       bint occupied_only, const OcTreeKey& kmin, const OcTreeKey& kmax,
                       NodeList& out) except +


ctypedef OcTree Tree
ctypedef OcTreeNode Node
cdef str _PUBLIC_CLASS = "OccupancyOctree"

include "_tree_core.pxi"


@cython.auto_pickle(False)
cdef class _OcTree(_TreeCore):
    """A liboctomap ``OcTree`` owned by Python. Use :class:`occgp.OccupancyOctree`."""

    # a scan's dense ray counts over its key box, kept between scans (zero between
    # scans unless _counts_dirty) to spare allocating and clearing megabytes per scan
    cdef vector[uint32_t] _counts
    cdef bool _counts_dirty
    # change detection (liboctomap's rule): packed key -> the cell was new
    cdef bint _tracking
    cdef unordered_map[uint64_t, bint] _changes
    # stamps (see occgp/_octree_stamps.py): packed key of a finest cell -> the stamp of
    # the last update that reached it while _stamping was on (_stamp_now)
    cdef unordered_map[uint64_t, double] _stamps
    cdef bint _stamping
    cdef double _stamp_now

    # ------------------------------------------------------------------ updates
    def _insert_point_cloud(self, const float[:, ::1] points, const float[::1] origin,
                            double max_range, bint discretize, const float[:, ::1] bbox=None):
        """liboctomap's ``insertPointCloud`` (free/occupied key sets, one update per cell),
        limited to `bbox` (rows: min and max corner, keys checked by the caller) with
        liboctomap's ``useBBXLimit`` when given."""
        cdef OcTree* tree = self._get()
        cdef Pointcloud cloud
        cdef Py_ssize_t i, n = points.shape[0]
        cdef point3d o = point3d(origin[0], origin[1], origin[2])
        cdef point3d lo, hi
        cdef bint limit = bbox is not None
        if limit:
            lo = point3d(bbox[0, 0], bbox[0, 1], bbox[0, 2])
            hi = point3d(bbox[1, 0], bbox[1, 1], bbox[1, 2])
        with self._lock:
            with nogil:
                cloud.reserve(n)
                for i in range(n):
                    cloud.push_back(points[i, 0], points[i, 1], points[i, 2])
                if limit:
                    tree.setBBXMin(lo)
                    tree.setBBXMax(hi)
                    tree.useBBXLimit(True)
                try:
                    tree.insertPointCloud(cloud, o, max_range, False, discretize)
                finally:
                    tree.useBBXLimit(False)

    def _bbx_rays(self, const float[:, ::1] points, const float[::1] origin,
                  double max_range, const float[:, ::1] bbox):
        """Which rays liboctomap's insertPointCloud keeps under ``useBBXLimit``: the end
        point lies in the box (its float comparison) and within `max_range` (< 0: none)."""
        cdef Py_ssize_t i, n = points.shape[0]
        cdef point3d o = point3d(origin[0], origin[1], origin[2])
        cdef point3d p, end
        keep = np.zeros(n, dtype=np.bool_)
        cdef uint8_t[::1] k = keep.view(np.uint8)
        with nogil:
            for i in range(n):
                p = point3d(points[i, 0], points[i, 1], points[i, 2])
                k[i] = (p.x() >= bbox[0, 0] and p.y() >= bbox[0, 1] and p.z() >= bbox[0, 2]
                        and p.x() <= bbox[1, 0] and p.y() <= bbox[1, 1]
                        and p.z() <= bbox[1, 2]
                        and not effective_end(o, p, max_range, &end))
        return keep

    def _insert_batch(self, const float[:, ::1] points, const float[::1] origin,
                      double max_range, bint ray_mode, bint culling,
                      const uint32_t[::1] weights=None, int superray_threshold=0,
                      bint diagnose=False, uint64_t max_cells=0,
                      const uint16_t[:, ::1] key_box=None, int n_threads=1,
                      const uint8_t[::1] free_only=None):
        """Insert a scan through occgp's own key table, optionally culled.

        Every ray is traversed by liboctomap's ``computeRayKeys``; the cells are
        collected with their counts (rays passing through, rays ending in) and
        each updated once: in scan mode with ``l_hit`` if any ray ends in it,
        else ``l_miss`` (liboctomap's ``insertPointCloud``); in ray mode with
        ``n_free*l_miss + n_hit*l_hit``. With `culling`, the cells of the
        scan's culling region (``build_region``) are skipped: a ray's visit changes
        nothing there (fully free cells without end points; in scan mode, end cells).
        With `weights` (ray mode), ray i counts ``weights[i]`` times. With
        `superray_threshold` != 0, the rays are first grouped into super rays (cells
        of at least its magnitude; < 0: where it can pay) and one ray a class walked.

        Returns (region_cells, updated_cells, traversed_rays, traversed_cells, seconds,
        unnecessary_traversals, spared_cells, culled_rays, region_spared_cells), seconds
        = (end points, super rays, culling region, traversal, tree update), the last
        three as in ``last_insert_``. With `key_box`
        (rows: lowest and highest key), cells outside it are left out. region_cells
        is -1 when culling was off or the scan's key box was too large to cull;
        unnecessary_traversals is -1 unless `diagnose` (slow) asks for it.
        Returns, changing nothing, ``Status.OUT_OF_RANGE`` when a ray's end (after
        truncation) lies outside the key range, ``Status.RAY_TOO_SHORT`` when a ray
        cannot be walked, and ``Status.TOO_MANY_CELLS`` when the scan reaches more
        than `max_cells` cells (> 0) (:mod:`occgp._status`).
        The rays are walked on up to `n_threads` threads (one with `diagnose`), without
        the GIL; the tree and the statistics are the same for every `n_threads`.
        Rays i with ``free_only[i]`` (None: none) only clear, as rays cut at
        `max_range` (their end cell gets nothing from them).
        """
        cdef OcTree* tree = self._get()
        cdef Py_ssize_t j
        cdef const uint32_t* w = scan_weights(weights, points.shape[0], superray_threshold)
        cdef const uint8_t* fo = scan_free_only(free_only, points.shape[0])
        cdef point3d o = point3d(origin[0], origin[1], origin[2])
        cdef vector[ScanCell] found
        cdef vector[CellUpdate] cells, scratch
        cdef ScanStats stats
        cdef timespec done
        cdef bint boxed = key_box is not None
        cdef int lo[3]
        cdef int hi[3]
        cdef int axis
        cdef size_t m = 0
        cdef Status status = Status.ok
        if boxed:
            for axis in range(3):
                lo[axis] = key_box[0, axis]
                hi[axis] = key_box[1, axis]
        with self._lock:
            with nogil:
                status = scan_updates_free_only(
                    tree[0], scan_points(points), points.shape[0], o, max_range, ray_mode,
                    culling, w, superray_threshold, _fully_free, tree, self._counts,
                    self._counts_dirty, found, &stats, diagnose, max_cells, n_threads, fo)
                if status == Status.ok:
                    m = found.size()   # each row its own: on the threads for large scans
                    cells.resize(m)
                    for j in prange(<Py_ssize_t>m, num_threads=max(n_threads, 1),
                                    schedule="static", use_threads_if=m >= 65536):
                        cells[j].code = morton_of_packed(found[j].key)
                        cells[j].update = found[j].update
                    if boxed:
                        m = keep_in_box(cells, lo, hi)
                    self._apply_tracked(tree, cells, scratch, n_threads)
                clock_gettime(CLOCK_MONOTONIC, &done)
        return scan_result(status, stats, m, done)

    def _knn_cells(self, const float[:, ::1] points, const float[::1] origin,
                   double sensor_range, bint culling, int superray_threshold=0,
                   uint64_t max_cells=0, int n_threads=1):
        """A scan's cells for the k-NN inverse sensor model, one class per cell.

        The rays to the points within `sensor_range` (the *near* points: not
        truncated by liboctomap's computeUpdate rule) and the rays to the other
        points, cut at `sensor_range`, are traversed as two scans of
        :func:`scan_updates` (scan mode). Each cell gets one class: 0 if a near
        point lies in it, else 1 if a ray to a near point crosses it, else 2
        (crossed by cut rays only). With `culling`, each traversal skips its
        culling region: fully free cells (l_in, l_out <= 0 change nothing) and
        cells holding a near point (class 0 whatever crosses them).

        Returns (near, keys, kinds, point_cell, stats): near (n_near, 3) float32,
        the near points in scan order; keys
        (m,) uint64 packed keys (x in the low 16 bits); kinds (m,) uint8;
        point_cell (n_near,) int64, the row of `keys` holding each near point;
        stats as :meth:`_insert_batch` returns them (the two traversals added).
        Returns the failure's Status as :meth:`_insert_batch` does (also
        TOO_MANY_CELLS past `max_cells` (> 0) in all). The rays are walked
        on up to `n_threads` threads; the cells, their classes and the statistics are
        the same for every `n_threads` (the order of the cells may differ).
        """
        cdef OcTree* tree = self._get()
        cdef Py_ssize_t i, j, n = points.shape[0], n_near = 0, n_far = 0
        cdef point3d o = point3d(origin[0], origin[1], origin[2])
        cdef point3d end
        near = np.zeros(n, dtype=np.bool_)
        cdef uint8_t[::1] near_v = near.view(np.uint8)   # which rows are near
        with nogil:
            for i in range(n):
                near_v[i] = not effective_end(
                    o, point3d(points[i, 0], points[i, 1], points[i, 2]), sensor_range, &end)
                n_near += near_v[i]
        n_far = n - n_near
        near_pts = np.empty((n_near, 3), dtype=np.float32)
        far_pts = np.empty((n_far, 3), dtype=np.float32)
        cdef float[:, ::1] a_v = near_pts
        cdef float[:, ::1] b_v = far_pts
        cdef vector[ScanCell] found_a, found_b
        cdef ScanStats sa, sb
        cdef timespec done
        cdef unordered_map[uint64_t, Py_ssize_t] row
        cdef unordered_map[uint64_t, Py_ssize_t].iterator it
        cdef Py_ssize_t m = 0, ia = 0, ib = 0
        cdef OcTreeKey key
        cdef Status status = Status.ok
        with self._lock:
            with nogil:
                for i in range(n):
                    if near_v[i]:
                        a_v[ia, 0] = points[i, 0]
                        a_v[ia, 1] = points[i, 1]
                        a_v[ia, 2] = points[i, 2]
                        ia += 1
                    else:
                        b_v[ib, 0] = points[i, 0]
                        b_v[ib, 1] = points[i, 1]
                        b_v[ib, 2] = points[i, 2]
                        ib += 1
                empty_stats(&sa)
                empty_stats(&sb)
                if n_near:
                    status = scan_updates(tree[0], scan_points(a_v), n_near, o, -1.0, False,
                                          culling, NULL, superray_threshold, _fully_free,
                                          tree, self._counts, self._counts_dirty, found_a,
                                          &sa, False, max_cells, n_threads)
                if n_far and status == Status.ok:
                    status = scan_updates(tree[0], scan_points(b_v), n_far, o, sensor_range,
                                          False, culling, NULL, superray_threshold,
                                          _fully_free, tree, self._counts,
                                          self._counts_dirty, found_b, &sb, False,
                                          max_cells, n_threads)
                clock_gettime(CLOCK_MONOTONIC, &done)
        if status == Status.ok and max_cells and found_a.size() + found_b.size() > max_cells:
            status = Status.too_many_cells
        if status != Status.ok:
            return _Status(<int>status)
        keys = np.empty(found_a.size() + found_b.size(), dtype=np.uint64)
        kinds = np.empty(found_a.size() + found_b.size(), dtype=np.uint8)
        point_cell = np.empty(n_near, dtype=np.int64)
        cdef uint64_t[::1] keys_v = keys
        cdef uint8_t[::1] kinds_v = kinds
        cdef int64_t[::1] pc_v = point_cell
        with nogil:
            row.reserve(found_a.size() + found_b.size())
            for j in range(<Py_ssize_t>found_a.size()):
                row[found_a[j].key] = m
                keys_v[m] = found_a[j].key
                # scan mode: l_hit (> 0) where a near point ends, l_miss (< 0) elsewhere
                kinds_v[m] = 0 if found_a[j].update > 0 else 1
                m += 1
            for j in range(<Py_ssize_t>found_b.size()):
                if row.count(found_b[j].key):
                    continue
                keys_v[m] = found_b[j].key
                kinds_v[m] = 2
                m += 1
            key[0] = key[1] = key[2] = 0
            for i in range(n_near):
                tree.coordToKeyChecked(point3d(a_v[i, 0], a_v[i, 1], a_v[i, 2]), key)
                it = row.find(_pack(key))
                pc_v[i] = deref(it).second if it != row.end() else -1
        stats = _sum_stats(scan_result(Status.ok, sa, found_a.size(), done),
                           scan_result(Status.ok, sb, found_b.size(), done))
        return near_pts, keys[:m], kinds[:m], point_cell, stats

    def _apply_cells(self, const uint64_t[::1] keys, const float[::1] updates, int n_threads=1):
        """Add ``updates[i]`` to the cell of packed key ``keys[i]`` (keys distinct), as
        updateNode does (clamped), in one pass over the tree on up to `n_threads`
        threads; returns the number of cells not aborted early."""
        cdef OcTree* tree = self._get()
        cdef Py_ssize_t j, n = keys.shape[0]
        cdef vector[CellUpdate] cells, scratch
        cdef OcTreeKey key
        cdef size_t applied = 0
        with self._lock:
            with nogil:
                cells.resize(n)
                for j in range(n):
                    key = _unpack(keys[j])
                    cells[j].code = morton_code(key[0], key[1], key[2])
                    cells[j].update = updates[j]
                applied = self._apply_tracked(tree, cells, scratch, n_threads)
        return applied

    def _key_to_coord(self, const uint16_t[:, ::1] keys, unsigned depth):
        """liboctomap's keyToCoord(key, depth) on each axis of each row: (n, 3) doubles."""
        cdef OcTree* tree = self._get()
        cdef Py_ssize_t i, n = keys.shape[0]
        cdef int axis
        out = np.empty((n, 3))
        cdef double[:, ::1] v = out
        with nogil:
            for i in range(n):
                for axis in range(3):
                    v[i, axis] = tree.keyToCoord(keys[i, axis], depth)
        return out

    cdef size_t _apply_tracked(self, OcTree* tree, vector[CellUpdate]& cells,
                               vector[CellUpdate]& scratch, int n_threads=1) except * nogil:
        """apply_updates (on up to `n_threads` threads), recording the changes of
        liboctomap's change detection when on (then on one thread)."""
        cdef size_t j, applied
        cdef vector[uint8_t] known, before
        cdef OcTreeKey key
        cdef OcTreeNode* node
        if self._stamping:
            for j in range(cells.size()):
                self._stamps[_pack(morton_key(cells[j].code))] = self._stamp_now
        if not self._tracking:
            return apply_updates(tree[0], cells, scratch, n_threads)
        # apply_updates sorts the cells: sort first, so the states line up
        sort_by_code(cells, scratch)
        known.resize(cells.size())
        before.resize(cells.size())
        for j in range(cells.size()):
            node = tree.search(morton_key(cells[j].code), 0)
            known[j] = node != NULL
            before[j] = node != NULL and tree.isNodeOccupied(node)
        applied = apply_updates(tree[0], cells, scratch, 1)
        for j in range(cells.size()):
            key = morton_key(cells[j].code)
            node = tree.search(key, 0)
            self._record(_pack(key), known[j], before[j], tree.isNodeOccupied(node))
        return applied

    cdef inline void _record(self, uint64_t key, bint known, bint before,
                             bint after) noexcept nogil:
        """liboctomap's rule: a new cell is recorded as new; a known cell whose state
        flips is recorded (as not new), and a second flip of such a cell removes it."""
        cdef unordered_map[uint64_t, bint].iterator it
        if not known:
            if self._changes.count(key) == 0:
                self._changes[key] = True
        elif before != after:
            it = self._changes.find(key)
            if it == self._changes.end():
                self._changes[key] = False
            elif not deref(it).second:
                self._changes.erase(it)

    cdef void _reset(self) noexcept:
        self._stamps.clear()

    def _set_stamping(self, bint enable, double now):
        """Stamp every cell the following updates reach with `now` (until disabled)."""
        with self._lock:
            self._stamping = enable
            self._stamp_now = now

    def _stamp_table(self):
        """(packed keys uint64 (n,), stamps float64 (n,)) of the stamped cells, unsorted."""
        cdef Py_ssize_t n, j = 0
        cdef unordered_map[uint64_t, double].iterator it
        with self._lock:
            n = self._stamps.size()
            keys = np.empty(n, dtype=np.uint64)
            stamps = np.empty(n, dtype=np.float64)
            it = self._stamps.begin()
            while it != self._stamps.end():
                keys[j] = deref(it).first
                stamps[j] = deref(it).second
                j += 1
                inc(it)
        return keys, stamps

    def _set_stamps(self, const uint64_t[::1] keys, const double[::1] stamps):
        """Set the stamps of packed keys (a NaN stamp removes the key's)."""
        cdef Py_ssize_t j
        with self._lock:
            with nogil:
                for j in range(keys.shape[0]):
                    if stamps[j] != stamps[j]:
                        self._stamps.erase(keys[j])
                    else:
                        self._stamps[keys[j]] = stamps[j]

    def _clear_stamps(self):
        with self._lock:
            self._stamps.clear()

    def _set_tracking(self, bint enable):
        with self._lock:
            self._tracking = enable

    def _is_tracking(self):
        return self._tracking

    def _changed(self):
        """(packed keys uint64 (n,), new bool (n,)) of the recorded changes."""
        cdef Py_ssize_t n, j = 0
        cdef unordered_map[uint64_t, bint].iterator it
        with self._lock:
            n = self._changes.size()
            keys = np.empty(n, dtype=np.uint64)
            new = np.empty(n, dtype=np.bool_)
            it = self._changes.begin()
            while it != self._changes.end():
                keys[j] = deref(it).first
                new[j] = deref(it).second
                j += 1
                inc(it)
        return keys, new

    def _reset_changes(self):
        with self._lock:
            self._changes.clear()

    def _set_values(self, const uint16_t[:, ::1] keys, const float[::1] log_odds):
        """Set each finest cell's log-odds (liboctomap's setNodeValue, which clamps to the
        tree's bounds), then re-evaluate the inner nodes and prune."""
        cdef OcTree* tree = self._get()
        cdef Py_ssize_t i
        cdef OcTreeKey key
        cdef OcTreeNode* node
        cdef bint known, before
        with self._lock:
            with nogil:
                for i in range(keys.shape[0]):
                    key = OcTreeKey(keys[i, 0], keys[i, 1], keys[i, 2])
                    if self._tracking:
                        node = tree.search(key, 0)
                        known = node != NULL
                        before = known and tree.isNodeOccupied(node)
                    node = tree.setNodeValue(key, log_odds[i], True)
                    if self._stamping:
                        self._stamps[_pack(key)] = self._stamp_now
                    if self._tracking:
                        self._record(_pack(key), known, before, tree.isNodeOccupied(node))
                tree.updateInnerOccupancy()
                tree.prune()

    # ------------------------------------------------------------------ queries
    def _query_depth(self, const float[:, ::1] points, int what, unsigned depth):
        """Per point, of the node liboctomap's ``search(key, depth)`` returns (the node at
        `depth` holding the point, or the coarser leaf holding it): 0 → occupancy,
        1 → log-odds (NaN where unknown), 2 → int8 state (-1 unknown, 0 free,
        1 occupied), 3 → int8 ``isNodeAtThreshold`` (-1 unknown)."""
        cdef OcTree* tree = self._get()
        cdef Py_ssize_t i, n = points.shape[0]
        cdef OcTreeKey key
        cdef OcTreeNode* node
        out = np.full(n, np.nan) if what < 2 else np.full(n, -1, dtype=np.int8)
        cdef double[::1] values
        cdef signed char[::1] states
        if what >= 2:
            states = out
        else:
            values = out
        with self._lock:
            with nogil:
                for i in range(n):
                    if not tree.coordToKeyChecked(
                            point3d(points[i, 0], points[i, 1], points[i, 2]), key):
                        continue
                    node = tree.search(key, depth)
                    if node == NULL:
                        continue
                    if what == 0:
                        values[i] = node.getOccupancy()
                    elif what == 1:
                        values[i] = node.getLogOdds()
                    elif what == 2:
                        states[i] = 1 if tree.isNodeOccupied(node) else 0
                    else:
                        states[i] = 1 if tree.isNodeAtThreshold(node) else 0
        return out

    def _delete(self, const uint16_t[:, ::1] keys, unsigned depth):
        """Delete the depth-`depth` (1..16) node holding each key, in order (see
        ``ext/_octree_edit.h``); returns how many nodes were deleted."""
        cdef OcTree* tree = self._get()
        cdef Py_ssize_t i
        cdef size_t deleted = 0
        with self._lock:
            with nogil:
                for i in range(keys.shape[0]):
                    deleted += delete_node(tree[0], OcTreeKey(keys[i, 0], keys[i, 1], keys[i, 2]),
                                           depth)
        return deleted

    def _nodes(self, unsigned max_depth, bint leaves_only, bint occupied_only,
               const uint16_t[:, ::1] key_box=None):
        """Centres (n, 3), sizes (n,), depths (n,) uint8, log-odds (n,) float32 and
        is-leaf flags (n,) of the nodes down to `max_depth` (1..16) in liboctomap's
        iterator order (leaves only: as begin_leafs(max_depth)), limited to the nodes
        meeting `key_box` (rows: lowest and highest key) when given."""
        cdef OcTree* tree = self._get()
        cdef NodeList nodes
        cdef OcTreeKey kmin = OcTreeKey(0, 0, 0)
        cdef OcTreeKey kmax = OcTreeKey(65535, 65535, 65535)
        cdef int axis
        if key_box is not None:
            for axis in range(3):
                kmin[axis] = key_box[0, axis]
                kmax[axis] = key_box[1, axis]
        with self._lock:
            with nogil:
                collect_nodes(tree[0], max_depth, leaves_only, occupied_only, kmin, kmax, nodes)
        cdef Py_ssize_t n = nodes.sizes.size()
        out_c = np.empty((n, 3))
        out_s = np.empty(n)
        out_d = np.empty(n, dtype=np.uint8)
        out_v = np.empty(n, dtype=np.float32)
        out_l = np.empty(n, dtype=np.bool_)
        cdef double[:, ::1] oc = out_c
        cdef double[::1] os_ = out_s
        cdef uint8_t[::1] od = out_d
        cdef float[::1] ov = out_v
        cdef uint8_t[::1] ol = out_l.view(np.uint8)
        if n:
            memcpy(&oc[0, 0], nodes.centers.data(), 3 * n * sizeof(double))
            memcpy(&os_[0], nodes.sizes.data(), n * sizeof(double))
            memcpy(&od[0], nodes.depths.data(), n * sizeof(uint8_t))
            memcpy(&ov[0], nodes.values.data(), n * sizeof(float))
            memcpy(&ol[0], nodes.is_leaf.data(), n * sizeof(uint8_t))
        return out_c, out_s, out_d, out_v, out_l

    def _ray_intersections(self, const float[:, ::1] origins, const float[:, ::1] directions,
                           const float[:, ::1] centres, double delta):
        """liboctomap's ``getRayIntersection(origin, direction.normalized(), centre,
        intersection, delta)`` per row: (points (n, 3) doubles, NaN where not found;
        found (n,) bool)."""
        cdef OcTree* tree = self._get()
        cdef Py_ssize_t i, n = origins.shape[0]
        points = np.full((n, 3), np.nan)
        found = np.zeros(n, dtype=np.bool_)
        cdef double[:, ::1] pv = points
        cdef uint8_t[::1] fv = found.view(np.uint8)
        cdef point3d hit
        with self._lock:
            with nogil:
                for i in range(n):
                    fv[i] = tree.getRayIntersection(
                        point3d(origins[i, 0], origins[i, 1], origins[i, 2]),
                        point3d(directions[i, 0], directions[i, 1],
                                directions[i, 2]).normalized(),
                        point3d(centres[i, 0], centres[i, 1], centres[i, 2]), hit, delta)
                    if fv[i]:
                        pv[i, 0] = hit.x()
                        pv[i, 1] = hit.y()
                        pv[i, 2] = hit.z()
        return points, found

    def _cast_rays(self, const float[:, ::1] origins, const float[:, ::1] directions,
                   bint ignore_unknown, const double[::1] max_range):
        """liboctomap's ``castRay`` for each (origin, direction) row."""
        cdef OcTree* tree = self._get()
        cdef Py_ssize_t i, n = origins.shape[0]
        ends = np.empty((n, 3))
        hits = np.empty(n, dtype=np.bool_)
        cdef double[:, ::1] ends_v = ends
        cdef uint8_t[::1] hits_v = hits.view(np.uint8)
        cdef point3d end
        with self._lock:
            with nogil:
                for i in range(n):
                    hits_v[i] = tree.castRay(
                        point3d(origins[i, 0], origins[i, 1], origins[i, 2]),
                        point3d(directions[i, 0], directions[i, 1], directions[i, 2]),
                        end, ignore_unknown, max_range[i])
                    ends_v[i, 0] = end.x()
                    ends_v[i, 1] = end.y()
                    ends_v[i, 2] = end.z()
        return ends, hits

    def _leaves(self, bint occupied_only, const double[:, ::1] bbox=None):
        """Centres (n, 3), sizes (n,), log-odds (n,) of the leaves, optionally in a box."""
        cdef OcTree* tree = self._get()
        cdef vector[double] centers, sizes
        cdef vector[float] values
        cdef OcTree.leaf_iterator it, end
        cdef OcTree.leaf_bbx_iterator bit, bend
        cdef OcTreeKey kmin, kmax
        cdef double rf = 1.0 / tree.getResolution()
        cdef int axis
        cdef double scaled
        if bbox is not None:
            for axis in range(3):
                # clip the box to the key range, as a box larger than the tree means "all"
                scaled = floor(rf * bbox[0, axis]) + _MAX_VAL
                kmin[axis] = <key_type>min(max(scaled, 0.0), 2.0 * _MAX_VAL - 1)
                scaled = floor(rf * bbox[1, axis]) + _MAX_VAL
                kmax[axis] = <key_type>min(max(scaled, 0.0), 2.0 * _MAX_VAL - 1)
        with self._lock:
            with nogil:
                if bbox is None:
                    it = tree.begin_leafs(0)
                    end = tree.end_leafs()
                    while it != end:
                        if not occupied_only or tree.isNodeOccupied(&deref(it)):
                            _push_leaf(tree, it.getKey(), it.getDepth(), it.getSize(),
                                       deref(it).getLogOdds(), centers, sizes, values)
                        inc(it)
                else:
                    bit = tree.begin_leafs_bbx(kmin, kmax, 0)
                    bend = tree.end_leafs_bbx()
                    while bit != bend:
                        # liboctomap's box iterator also yields coarse leaves that only
                        # touch the box: keep the leaves whose key range meets it
                        if (_meets(bit.getKey(), bit.getDepth(), kmin, kmax)
                                and (not occupied_only or tree.isNodeOccupied(&deref(bit)))):
                            _push_leaf(tree, bit.getKey(), bit.getDepth(), bit.getSize(),
                                       deref(bit).getLogOdds(), centers, sizes, values)
                        inc(bit)
        cdef Py_ssize_t n = sizes.size()
        out_c = np.empty((n, 3))
        out_s = np.empty(n)
        out_v = np.empty(n, dtype=np.float32)
        cdef double[:, ::1] oc = out_c
        cdef double[::1] os_ = out_s
        cdef float[::1] ov = out_v
        if n:
            memcpy(&oc[0, 0], centers.data(), 3 * n * sizeof(double))
            memcpy(&os_[0], sizes.data(), n * sizeof(double))
            memcpy(&ov[0], values.data(), n * sizeof(float))
        return out_c, out_s, out_v

    # ------------------------------------------------------------------ structure
    def _prune(self):
        cdef OcTree* tree = self._get()
        with self._lock:
            with nogil:
                tree.prune()

    def _expand(self):
        cdef OcTree* tree = self._get()
        with self._lock:
            with nogil:
                tree.expand()

    def _to_max_likelihood(self):
        cdef OcTree* tree = self._get()
        with self._lock:
            with nogil:
                tree.toMaxLikelihood()
                tree.prune()

    # ------------------------------------------------------------------ serialisation
    def _write_data(self, bint binary):
        """The tree's data block (no header) in the .bt (`binary`) or .ot encoding."""
        cdef OcTree* tree = self._get()
        cdef ostringstream stream
        cdef string data
        with self._lock:
            with nogil:
                if binary:
                    tree.writeBinaryData(stream)
                else:
                    tree.writeData(stream)
                data = stream.str()
        return <bytes>data

    def _read_data(self, bytes payload, bint binary, double resolution):
        """Replace the tree by the data block `payload` (validated by the caller)."""
        self._read(payload, binary, resolution)

def _sum_stats(a, b):
    """Two traversals' statistics (see :func:`scan_result`) as one scan's."""
    region = -1 if a[0] < 0 and b[0] < 0 else max(a[0], 0) + max(b[0], 0)
    return (region, *(x + y for x, y in zip(a[1:4], b[1:4])),
            tuple(x + y for x, y in zip(a[4], b[4])), -1, *(x + y for x, y in zip(a[6:], b[6:])))


def _welford(const double[::1] values, long count, double mean, double m2):
    """Welford's update of (count, mean, sum of squared deviations) by `values`, in
    order; non-finite values are skipped."""
    cdef Py_ssize_t i
    cdef double delta, s
    with nogil:
        for i in range(values.shape[0]):
            s = values[i]
            if not isfinite(s):
                continue
            count += 1
            delta = s - mean
            mean += delta / count
            m2 += delta * (s - mean)
    return count, mean, m2


cdef bool _fully_free(void* tree, const OcTreeKey& key) noexcept nogil:
    """FreeTest of an OcTree: the cell is known and at the lower clamping bound."""
    cdef OcTree* t = <OcTree*>tree
    cdef OcTreeNode* node = t.search(key, 0)
    return node != NULL and node.getLogOdds() <= t.getClampingThresMinLog()


cdef inline bint _meets(const OcTreeKey& key, unsigned depth, const OcTreeKey& kmin,
                        const OcTreeKey& kmax) noexcept nogil:
    """Whether the node at `key`, `depth` covers a key in the box [kmin, kmax]."""
    cdef unsigned mask = (1u << (_DEPTH - depth)) - 1
    cdef int axis
    for axis in range(3):
        if (key[axis] & ~mask) > kmax[axis] or (key[axis] | mask) < kmin[axis]:
            return False
    return True


cdef inline void _push_leaf(OcTree* tree, const OcTreeKey& key, unsigned depth, double size,
                            float log_odds, vector[double]& centers, vector[double]& sizes,
                            vector[float]& values) noexcept nogil:
    centers.push_back(tree.keyToCoord(key[0], depth))
    centers.push_back(tree.keyToCoord(key[1], depth))
    centers.push_back(tree.keyToCoord(key[2], depth))
    sizes.push_back(size)
    values.push_back(log_odds)


# ---------------------------------------------------------------------- file validation
def _check_binary_data(const uint8_t[::1] data, Py_ssize_t offset):
    """Walk a .bt data block without building anything (``ext/_octree_io.h``).

    Returns (number of nodes, end offset), or raises ValueError when the block is
    truncated or describes a node deeper than the 16 levels of an OcTree.
    liboctomap trusts its input; this walk makes sure it gets only valid input.
    """
    cdef Py_ssize_t n = data.shape[0], nodes = 0, end = 0
    cdef Status status
    with nogil:
        status = check_binary_data(&data[0] if n else NULL, n, offset, &nodes, &end)
    _check_status(<int>status, n_bytes=n - offset)
    return nodes, end


def _check_full_data(const uint8_t[::1] data, Py_ssize_t offset, int node_bytes=5):
    """Like :func:`_check_binary_data` for a .ot data block: per node a float log-odds,
    then ``node_bytes - 5`` bytes of payload (3 for a ColorOcTree's r, g, b), then the
    child mask."""
    cdef Py_ssize_t n = data.shape[0], nodes = 0, end = 0
    cdef Status status
    if node_bytes < 5:
        raise ValueError(f"node_bytes must be at least 5, got {node_bytes}")
    with nogil:
        status = check_full_data(&data[0] if n else NULL, n, offset, node_bytes, &nodes, &end)
    _check_status(<int>status, n_bytes=n - offset)
    return nodes, end
