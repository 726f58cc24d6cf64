# cython: language_level=3
# distutils: language = c++
"""Compiled core of :class:`occgp.OccupancyOctree`: liboctomap's ``OcTree`` behind typed loops.

Nothing here validates user input: :mod:`occgp.octree` coerces and checks every
array (shape, dtype, finiteness, key range) before it reaches these methods.
Every loop and every liboctomap call that does real work runs without the GIL;
a per-tree lock serialises the operations on one tree.
"""

cimport cython
from cython.operator cimport dereference as deref, preincrement as inc
from libc.math cimport fabs, floor, isfinite, ldexp, sqrt
from libc.stdint cimport uint8_t, uint16_t, uint32_t, uint64_t
from libc.string cimport memcpy
from libcpp cimport bool
from libcpp.memory cimport unique_ptr
from libcpp.algorithm cimport sort
from libcpp.string cimport string
from libcpp.utility cimport pair
from libcpp.vector cimport vector

from _keys cimport (
    KEY_DEPTH as _DEPTH, KEY_EMPTY, KEY_MAX_VAL as _MAX_VAL, CellBox, KeyCounts, KeyTable,
    RayWalker,
    effective_end as _effective_end, mark_ends_in_range, mark_in_range, pack_key as _pack,
    unpack_key as _unpack,
)
from liboctomap cimport (
    KeyRay, OcTree, OcTreeKey, OcTreeNode, Pointcloud, istringstream, key_type,
    ostringstream, point3d,
)

from posix.time cimport CLOCK_MONOTONIC, clock_gettime, timespec


import threading

import numpy as np

cdef extern from *:
    int _clz64 "__builtin_clzll"(unsigned long long x) nogil

cdef enum:
    _MAX_REGION_CELLS = 1 << 28   # larger scan key boxes are not culled (2 x 32 MB of bits)
    _MAX_DENSE_CELLS = 1 << 24    # up to this, a scan's free counts live in an array (64 MB)

#: Half the number of keys per axis (liboctomap's ``tree_max_val``, 16-level tree).
TREE_MAX_VAL = _MAX_VAL
#: Depth of the tree: leaves at this depth have the size of the resolution.
TREE_DEPTH = _DEPTH


cdef extern from "_octree_batch.h" namespace "occgp" nogil:
    cdef cppclass CellUpdate:
        uint64_t code
        float update
    uint64_t morton_code(unsigned x, unsigned y, unsigned z)
    size_t apply_updates(OcTree& tree, vector[CellUpdate]& cells,
                         vector[CellUpdate]& scratch) except +


@cython.auto_pickle(False)
cdef class _OcTree:
    """A liboctomap ``OcTree`` owned by Python. Use :class:`occgp.OccupancyOctree`."""

    cdef unique_ptr[OcTree] _tree
    cdef object _lock
    # a scan's dense ray counts over its key box, kept between scans (zero between
    # scans unless _counts_dirty) to spare allocating and clearing megabytes per scan
    cdef vector[uint32_t] _counts
    cdef bint _counts_dirty

    def __cinit__(self, *args, **kwargs):
        self._lock = threading.Lock()

    cdef OcTree* _get(self) except NULL:
        cdef OcTree* tree = self._tree.get()
        if tree == NULL:
            raise ValueError(f"{type(self).__name__} was not initialised "
                             "(create it with OccupancyOctree(resolution))")
        return tree

    def _setup(self, double resolution, double prob_hit, double prob_miss,
               double clamping_min, double clamping_max, double occupancy_threshold):
        """Create the C++ tree (parameters were validated by the caller)."""
        cdef OcTree* tree
        with self._lock:
            self._tree.reset(new OcTree(resolution))
            tree = self._tree.get()
            tree.setProbHit(prob_hit)
            tree.setProbMiss(prob_miss)
            tree.setClampingThresMin(clamping_min)
            tree.setClampingThresMax(clamping_max)
            tree.setOccupancyThres(occupancy_threshold)

    # ------------------------------------------------------------------ key range
    def _in_range(self, const float[:, ::1] points):
        """Boolean mask: which rows of `points` have a valid key on every axis."""
        cdef double rf = 1.0 / self._get().getResolution()
        out = np.empty(points.shape[0], dtype=np.bool_)
        cdef uint8_t[::1] ok = out.view(np.uint8)
        with nogil:
            mark_in_range(rf, points, ok)
        return out

    def _ends_in_range(self, const float[:, ::1] points, const float[::1] origin,
                       double max_range):
        """Like :meth:`_in_range` for the ray ends after truncation at `max_range` (< 0: none)."""
        cdef double rf = 1.0 / self._get().getResolution()
        cdef point3d o = point3d(origin[0], origin[1], origin[2])
        out = np.empty(points.shape[0], dtype=np.bool_)
        cdef uint8_t[::1] ok = out.view(np.uint8)
        with nogil:
            mark_ends_in_range(rf, points, o, max_range, ok)
        return out

    # ------------------------------------------------------------------ updates
    def _insert_point_cloud(self, const float[:, ::1] points, const float[::1] origin,
                            double max_range, bint discretize):
        """liboctomap's ``insertPointCloud`` (free/occupied key sets, one update per cell)."""
        cdef OcTree* tree = self._get()
        cdef Pointcloud cloud
        cdef Py_ssize_t i, n = points.shape[0]
        cdef point3d o = point3d(origin[0], origin[1], origin[2])
        with self._lock:
            with nogil:
                cloud.reserve(n)
                for i in range(n):
                    cloud.push_back(points[i, 0], points[i, 1], points[i, 2])
                tree.insertPointCloud(cloud, o, max_range, False, discretize)

    def _insert_batch(self, const float[:, ::1] points, const float[::1] origin,
                      double max_range, bint ray_mode, bint culling,
                      const uint32_t[::1] weights=None, int superray_threshold=0):
        """Insert a scan through occgp's own key table, optionally culled.

        Every ray is traversed by liboctomap's ``computeRayKeys``; the cells are
        collected with their counts (rays passing through, rays ending in) and
        each updated once: in scan mode with ``l_hit`` if any ray ends in it,
        else ``l_miss`` (liboctomap's ``insertPointCloud``); in ray mode with
        ``n_free*l_miss + n_hit*l_hit``. With `culling`, the cells of the
        scan's culling region (see :func:`_build_region`) are skipped: they are
        at the lower clamp and hold no end point, so their update is a no-op.
        With `weights` (ray mode), ray i counts ``weights[i]`` times. With
        `superray_threshold` > 0, the rays are first grouped into super rays
        (see :func:`_super_rays`) and one ray per class is traversed.

        Returns (region_cells, updated_cells, traversed_rays, traversed_cells,
        seconds), seconds = (end points, pre-processing (super rays and
        culling region), traversal, tree update); region_cells is -1 when
        culling was off or the scan's key box was too large to cull.
        """
        cdef OcTree* tree = self._get()
        cdef Py_ssize_t i, n = points.shape[0]
        cdef bint weighted = weights is not None
        if weighted and weights.shape[0] != n:
            raise ValueError(f"weights must have length {n}, got {weights.shape[0]}")
        if weighted and superray_threshold > 0:
            raise ValueError("weights and super rays do not combine")
        cdef vector[uint32_t] ray_ids, ray_weights     # the rays to traverse, super rays
        cdef Py_ssize_t r, n_trav = n
        cdef point3d o = point3d(origin[0], origin[1], origin[2])
        cdef vector[point3d] ends
        cdef vector[uint8_t] truncated
        cdef KeyTable table
        cdef CellBox region
        cdef OcTreeKey ko, key
        cdef KeyCounts* entry
        cdef int lo[3]
        cdef int hi[3]
        cdef int axis, max_level = 0, level
        cdef uint32_t w = 1
        cdef long region_cells = -1
        cdef size_t slot, j, updated = 0
        cdef float l_hit = tree.getProbHitLog(), l_miss = tree.getProbMissLog()
        cdef timespec t[5]
        cdef vector[uint64_t] touched         # box indices with a nonzero count
        cdef uint64_t dims[3]
        cdef uint64_t idx, box_cells = 1
        cdef bint dense
        cdef uint32_t n_free
        cdef vector[OcTreeKey] end_keys
        cdef vector[uint8_t] end_ok
        cdef RayWalker walker
        cdef vector[uint64_t] back
        cdef bint more
        cdef double res = tree.getResolution()
        cdef int x, y, z
        cdef long traversed = 0
        cdef vector[CellUpdate] cells, scratch
        cdef CellUpdate cell
        with self._lock:
            with nogil:
                clock_gettime(CLOCK_MONOTONIC, &t[0])
                tree.coordToKeyChecked(o, ko)
                for axis in range(3):
                    lo[axis] = hi[axis] = ko[axis]
                ends.resize(n)
                end_keys.resize(n)
                end_ok.resize(n)
                truncated.resize(n)
                table.reset(<size_t>n // 8)
                # end cells first: they bound the region and may never join it
                for i in range(n):
                    truncated[i] = _effective_end(
                        o, point3d(points[i, 0], points[i, 1], points[i, 2]), max_range,
                        &ends[i])
                    end_ok[i] = tree.coordToKeyChecked(ends[i], key)
                    end_keys[i] = key
                    level = 0
                    for axis in range(3):
                        lo[axis] = min(lo[axis], <int>key[axis])
                        hi[axis] = max(hi[axis], <int>key[axis])
                        level += abs(<int>key[axis] - <int>ko[axis])
                    max_level = max(max_level, level)
                    if not truncated[i]:
                        entry = table.get(_pack(key))
                        entry.n_hit += weights[i] if weighted else 1
                clock_gettime(CLOCK_MONOTONIC, &t[1])
                if superray_threshold > 0:
                    _super_rays(tree, o, ko, ends, end_keys, truncated, table, superray_threshold,
                                ray_ids, ray_weights)
                    n_trav = ray_ids.size()
                if culling:
                    region_cells = _build_region(tree, ko, lo, hi, max_level, table, region)
                clock_gettime(CLOCK_MONOTONIC, &t[2])
                for axis in range(3):
                    dims[axis] = <uint64_t>(hi[axis] - lo[axis] + 1)
                    box_cells *= dims[axis]
                dense = box_cells <= _MAX_DENSE_CELLS
                if dense and (self._counts_dirty or self._counts.size() < box_cells):
                    self._counts.assign(max(box_cells, self._counts.size()), 0)
                self._counts_dirty = True
                for r in range(n_trav):
                    if superray_threshold > 0:
                        i = ray_ids[r]
                        w = ray_weights[r]
                    else:
                        i = r
                        if weighted:
                            w = weights[i]
                    if not end_ok[i]:
                        continue        # computeRayKeys's out-of-range check
                    more = walker.start(res, o, ko, ends[i], end_keys[i])
                    if more and region_cells > 0:
                        back.clear()
                        if walker.walk_back(region, back):
                            for j in range(back.size()):
                                key = _unpack(back[j])
                                _count_free(key[0], key[1], key[2], w, dense, lo, dims,
                                            self._counts, touched, table)
                            traversed += back.size()
                            continue
                        # the region is closed under stepping toward the origin, so a
                        # ray's cells in it form a prefix of its traversal
                        while more and region.inside(walker.key(0), walker.key(1),
                                                     walker.key(2)) and region.test(
                                walker.key(0), walker.key(1), walker.key(2)):
                            more = walker.next()
                    while more:
                        _count_free(walker.key(0), walker.key(1), walker.key(2), w, dense, lo,
                                    dims, self._counts, touched, table)
                        traversed += 1
                        more = walker.next()
                clock_gettime(CLOCK_MONOTONIC, &t[3])
                # one update per cell: the traversed cells, then end cells no ray crossed
                cells.reserve(touched.size() + table.size())
                for j in range(touched.size()):
                    idx = touched[j]
                    key = _box_key(idx, lo, dims)
                    entry = table.find(_pack(key))
                    cell.code = morton_code(key[0], key[1], key[2])
                    cell.update = _update_value(self._counts[idx],
                                                entry.n_hit if entry != NULL else 0,
                                                ray_mode, l_hit, l_miss)
                    cells.push_back(cell)
                for slot in range(table.capacity()):
                    if table.slot(slot).key == KEY_EMPTY:
                        continue
                    key = _unpack(table.slot(slot).key)
                    n_free = table.slot(slot).n_free
                    if dense and _in_box(key, lo, dims):
                        if self._counts[_box_index(key, lo, dims)]:
                            continue        # collected above
                        n_free = 0
                    cell.code = morton_code(key[0], key[1], key[2])
                    cell.update = _update_value(n_free, table.slot(slot).n_hit, ray_mode,
                                                l_hit, l_miss)
                    cells.push_back(cell)
                for j in range(touched.size()):
                    self._counts[touched[j]] = 0
                self._counts_dirty = False
                updated = cells.size()
                apply_updates(tree[0], cells, scratch)
                clock_gettime(CLOCK_MONOTONIC, &t[4])
        seconds = tuple([(t[k + 1].tv_sec - t[k].tv_sec) + 1e-9 * (t[k + 1].tv_nsec - t[k].tv_nsec)
                         for k in range(4)])
        return region_cells, updated, n_trav, traversed, seconds

    # ------------------------------------------------------------------ queries
    def _query(self, const float[:, ::1] points, int what):
        """Per point: 0 → occupancy probability, 1 → log-odds (NaN where unknown),
        2 → int8 state (-1 unknown, 0 free, 1 occupied)."""
        cdef OcTree* tree = self._get()
        cdef Py_ssize_t i, n = points.shape[0]
        cdef OcTreeKey key
        cdef OcTreeNode* node
        out = np.full(n, np.nan) if what != 2 else np.full(n, -1, dtype=np.int8)
        cdef double[::1] values
        cdef signed char[::1] states
        if what == 2:
            states = out
        else:
            values = out
        with self._lock:
            with nogil:
                for i in range(n):
                    if not tree.coordToKeyChecked(
                            point3d(points[i, 0], points[i, 1], points[i, 2]), key):
                        continue
                    node = tree.search(key, 0)
                    if node == NULL:
                        continue
                    if what == 0:
                        values[i] = node.getOccupancy()
                    elif what == 1:
                        values[i] = node.getLogOdds()
                    else:
                        states[i] = 1 if tree.isNodeOccupied(node) else 0
        return out

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
    def _num_leaves(self):
        cdef OcTree* tree = self._get()
        with self._lock:
            with nogil:
                n = tree.getNumLeafNodes()
        return n

    def _num_nodes(self):
        return self._get().size()

    def _memory_usage(self):
        return self._get().memoryUsage()

    def _bounds(self):
        cdef OcTree* tree = self._get()
        cdef double x0 = 0, y0 = 0, z0 = 0, x1 = 0, y1 = 0, z1 = 0
        with self._lock:
            tree.getMetricMin(x0, y0, z0)
            tree.getMetricMax(x1, y1, z1)
        return np.array([x0, y0, z0]), np.array([x1, y1, z1])

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

    def _clear(self):
        cdef OcTree* tree = self._get()
        with self._lock:
            tree.clear()

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
        cdef OcTree* tree = self._get()
        cdef string data = payload
        cdef unique_ptr[istringstream] stream
        with self._lock:
            with nogil:
                tree.clear()
                tree.setResolution(resolution)
                stream.reset(new istringstream(data))
                if binary:
                    tree.readBinaryData(deref(stream))
                else:
                    tree.readData(deref(stream))
            failed = deref(stream).fail()
        if failed:
            with self._lock:
                tree.clear()
            raise ValueError("liboctomap could not read the tree data")


cdef inline bint _in_box(const OcTreeKey& key, const int* lo,
                         const uint64_t* dims) noexcept nogil:
    return (<uint64_t>(<int>key[0] - lo[0]) < dims[0]
            and <uint64_t>(<int>key[1] - lo[1]) < dims[1]
            and <uint64_t>(<int>key[2] - lo[2]) < dims[2])


cdef inline uint64_t _box_index(const OcTreeKey& key, const int* lo,
                                const uint64_t* dims) noexcept nogil:
    return ((<uint64_t>(key[2] - lo[2]) * dims[1] + <uint64_t>(key[1] - lo[1])) * dims[0]
            + <uint64_t>(key[0] - lo[0]))


cdef inline OcTreeKey _box_key(uint64_t idx, const int* lo, const uint64_t* dims) noexcept nogil:
    cdef OcTreeKey key
    key[0] = <key_type>(lo[0] + idx % dims[0])
    idx //= dims[0]
    key[1] = <key_type>(lo[1] + idx % dims[1])
    key[2] = <key_type>(lo[2] + idx // dims[1])
    return key


cdef inline int _count_free(int kx, int ky, int kz, uint32_t w, bint dense, const int* lo,
                            const uint64_t* dims, vector[uint32_t]& free_counts,
                            vector[uint64_t]& touched, KeyTable& table) except -1 nogil:
    """Count `w` rays through the cell (kx, ky, kz): in the scan's dense box, or the table."""
    cdef uint64_t x = <uint64_t>(kx - lo[0]), y = <uint64_t>(ky - lo[1]), z = <uint64_t>(kz - lo[2])
    cdef uint64_t idx
    cdef OcTreeKey key
    # liboctomap's traversal may step past the end cell before its length test stops
    # it: such cells lie outside the box and go to the table
    if dense and x < dims[0] and y < dims[1] and z < dims[2]:
        idx = (z * dims[1] + y) * dims[0] + x
        if free_counts[idx] == 0:
            touched.push_back(idx)
        free_counts[idx] += w
    else:
        key[0] = <key_type>kx
        key[1] = <key_type>ky
        key[2] = <key_type>kz
        table.get(_pack(key)).n_free += w
    return 0


cdef inline float _update_value(uint32_t n_free, uint32_t n_hit, bint ray_mode, float l_hit,
                               float l_miss) noexcept nogil:
    """One cell's update of a scan: liboctomap's insertPointCloud rule, or ray counting."""
    if ray_mode:
        return <float>(n_free * <double>l_miss + n_hit * <double>l_hit)
    return l_hit if n_hit else l_miss


cdef inline double _dmin(double a, double b) noexcept nogil:
    return a if a < b else b


cdef inline double _dmax(double a, double b) noexcept nogil:
    return a if a > b else b


cdef struct Crossing:
    int axis          # the axis whose border the rays of a group cross
    int other         # the coordinate read at that border
    double border     # the border's position on `axis`, in metres
    int key_lo        # lowest key `other` may have there
    int n_keys        # how many keys `other` may have there


cdef int _super_rays(OcTree* tree, const point3d& o, const OcTreeKey& ko,
                     vector[point3d]& ends, const vector[OcTreeKey]& end_keys,
                     const vector[uint8_t]& truncated,
                     KeyTable& table, int threshold, vector[uint32_t]& rays,
                     vector[uint32_t]& weights) except -1 nogil:
    """Group the rays of a scan into super rays (Kwon, dissertation §2.3.1-2.3.4).

    Fills `rays` (indices of the rays to traverse) and `weights` (how many rays
    each stands for). Rays ending in a cell that holds at least `threshold` end
    points are classified by their *signature*: at every border a ray crosses
    between the origin's cell and its end cell, the keys of the other
    coordinates there; only the crossings where the rays into that end cell can
    differ ("critical", the mapping lines) are evaluated. Equal signatures mean
    the same traversed cells, so one ray of each class is traversed with the
    class size as weight.

    Exactness against liboctomap's float traversal: a ray joins a class only
    when it is *certified* -- at every crossing (critical or not) the other
    coordinate, and its end point in its cell, clear the nearest cell border by
    more than a margin several times the error of liboctomap's
    single-precision ray arithmetic: 2^-19 (length + resolution) for its float
    direction, plus 2^-21 resolution times the slope |d_b / d_a| for the
    single-precision half-cell offset of its borders. Its float traversal then
    equals the exact one. Every other ray is traversed on its own. (A border
    through the origin is crossed first, at t = 0, by every ray heading that
    way; the margins of that crossing certify it like any other.)
    """
    cdef double res = tree.getResolution(), rf = 1.0 / res
    cdef double oc[3]
    cdef double lo[3]
    cdef double hi[3]
    cdef double pc[3]
    cdef Py_ssize_t n = ends.size(), i, j, g, m, first
    cdef uint32_t n_groups = 0, idx
    cdef vector[uint32_t] group_of, offsets, order
    cdef vector[Crossing] crossings
    cdef vector[pair[uint64_t, uint32_t]] signed_rays
    cdef Crossing c
    cdef OcTreeKey key, kv
    cdef KeyCounts* entry
    cdef int a, b, step, code_bits, nk, d_a
    cdef long jj
    cdef double delta, eb, r, r_min, r_max, r_abs, s, b1, b2, t, y, kb, border, slack
    cdef double far2
    cdef double dp[3]
    cdef double inv[3]
    cdef uint64_t code
    cdef bint ok
    oc[0] = o.x()
    oc[1] = o.y()
    oc[2] = o.z()
    eb = ldexp(res, -21)          # 4 x the single-precision offset of liboctomap's borders
    # groups of rays by end cell, for the cells with at least `threshold` end points
    group_of.assign(n, 0)
    for i in range(n):
        if truncated[i]:
            continue
        entry = table.find(_pack(end_keys[i]))
        if entry == NULL or entry.n_hit < <uint32_t>threshold:
            continue
        if entry.group == 0:
            n_groups += 1
            entry.group = n_groups
        group_of[i] = entry.group
    offsets.assign(n_groups + 2, 0)
    for i in range(n):
        if group_of[i]:
            offsets[group_of[i] + 1] += 1
        else:
            rays.push_back(<uint32_t>i)
            weights.push_back(1)
    for g in range(1, n_groups + 2):
        offsets[g] += offsets[g - 1]
    order.resize(offsets[n_groups + 1])
    for i in range(n):
        if group_of[i]:
            order[offsets[group_of[i]]] = <uint32_t>i
            offsets[group_of[i]] += 1
    # offsets[g] now ends group g (1-based), i.e. starts group g + 1
    for g in range(1, n_groups + 1):
        first = offsets[g - 1]
        kv = end_keys[order[first]]
        far2 = 0
        for a in range(3):
            lo[a] = (<double>kv[a] - _MAX_VAL) * res
            hi[a] = lo[a] + res
            far2 += _dmax((lo[a] - oc[a]) ** 2, (hi[a] - oc[a]) ** 2)
        # 2^-19 (length + res): 4 x the error of liboctomap's float32 ray direction
        delta = ldexp(sqrt(far2) + res, -19)
        ok = True
        crossings.clear()
        code_bits = 0
        a = 0
        while ok and a < 3:
            d_a = <int>kv[a] - <int>ko[a]
            if d_a != 0:
                step = 1 if d_a > 0 else -1
                for b in range(a + 1, 3):
                    if kv[b] == ko[b]:
                        continue     # the rays stay in one b-slab: the end margins certify it
                    # the slopes d_b / d_a of the rays into the end cell: extreme at corners
                    r_min = 1e300
                    r_max = -1e300
                    for i in range(4):
                        s = (hi[a] if i & 1 else lo[a]) - oc[a]
                        if s == 0:
                            continue   # the origin on the end cell's face: only X_1, at t = 0
                        r = ((hi[b] if i & 2 else lo[b]) - oc[b]) / s
                        r_min = _dmin(r_min, r)
                        r_max = _dmax(r_max, r)
                    slack = delta + eb * _dmax(fabs(r_min), fabs(r_max))
                    for jj in range(1, abs(d_a) + 1):
                        border = (<double>(<int>ko[a] + (jj if step > 0 else 1 - jj))
                                  - _MAX_VAL) * res
                        s = border - oc[a]
                        if s == 0:         # crossed at the origin by every ray
                            b1 = b2 = oc[b]
                        elif r_min > r_max:
                            ok = False     # degenerate end cell: leave the group plain
                            break
                        else:
                            b1 = oc[b] + s * r_min
                            b2 = oc[b] + s * r_max
                        c.key_lo = <int>floor((_dmin(b1, b2) - slack) * rf)
                        nk = <int>floor((_dmax(b1, b2) + slack) * rf) - c.key_lo + 1
                        if nk == 1:
                            continue     # every ray of the group has the same key here
                        code_bits += 64 - _clz64(<uint64_t>(nk - 1))
                        if code_bits > 62:
                            ok = False
                            break
                        c.axis = a
                        c.other = b
                        c.border = border
                        c.n_keys = nk
                        crossings.push_back(c)
                    if not ok:
                        break
            a += 1
        if not ok:
            for m in range(first, offsets[g]):
                rays.push_back(order[m])
                weights.push_back(1)
            continue
        signed_rays.clear()
        for m in range(first, offsets[g]):
            idx = order[m]
            pc[0] = ends[idx].x()
            pc[1] = ends[idx].y()
            pc[2] = ends[idx].z()
            ok = True
            for a in range(3):
                if _dmin(pc[a] - lo[a], hi[a] - pc[a]) <= delta:
                    ok = False
                dp[a] = pc[a] - oc[a]
                # the rays of a group cross borders of axis a only when dp[a] != 0
                inv[a] = 1.0 / dp[a] if dp[a] != 0 else 0.0
            code = 0
            j = 0
            while ok and j < <Py_ssize_t>crossings.size():
                c = crossings[j]
                r_abs = fabs(dp[c.other] * inv[c.axis])
                y = oc[c.other] + (c.border - oc[c.axis]) * inv[c.axis] * dp[c.other]
                kb = floor(y * rf)
                if (_dmin(y - kb * res, (kb + 1) * res - y) <= delta + eb * r_abs
                        or kb < c.key_lo or kb >= c.key_lo + c.n_keys):
                    ok = False
                else:
                    code = code * <uint64_t>c.n_keys + <uint64_t>(<int>kb - c.key_lo)
                j += 1
            if ok:
                signed_rays.push_back(pair[uint64_t, uint32_t](code, idx))
            else:
                rays.push_back(idx)
                weights.push_back(1)
        sort(signed_rays.begin(), signed_rays.end())
        m = 0
        while m < <Py_ssize_t>signed_rays.size():
            j = m
            while (j < <Py_ssize_t>signed_rays.size()
                   and signed_rays[j].first == signed_rays[m].first):
                j += 1
            rays.push_back(signed_rays[m].second)
            weights.push_back(<uint32_t>(j - m))
            m = j
    return 0


cdef inline bint _in_region(const CellBox& region, const OcTreeKey& key) noexcept nogil:
    return (region.inside(key[0], key[1], key[2])
            and region.test(key[0], key[1], key[2]))


cdef long _build_region(OcTree* tree, const OcTreeKey& ko, const int* lo, const int* hi,
                        int max_level, const KeyTable& ends, CellBox& region) noexcept nogil:
    """Grow the scan's culling region (Kwon, dissertation §2.3.5, Alg. 3).

    Breadth first over Manhattan levels from the sensor's cell, inside the key
    box of the scan: a cell joins when it is fully free (log-odds at the lower
    clamp), holds no end point of the scan (occgp's exactness rule), and each of
    its test cells (one step toward the origin on every axis where its key
    differs from the origin's) is already in. Returns the number of cells, or
    -1 when the box is too large (no culling).
    """
    cdef CellBox seen
    cdef vector[OcTreeKey] frontier, next_frontier
    cdef OcTreeKey c, nb, t
    cdef OcTreeNode* node
    cdef float floor_log = tree.getClampingThresMinLog()
    cdef int level, axis, b, d, step
    cdef size_t j
    cdef long count = 0
    cdef bint ok
    if (not region.reset(lo, hi, _MAX_REGION_CELLS)
            or not seen.reset(lo, hi, _MAX_REGION_CELLS)):
        return -1
    node = tree.search(ko, 0)
    if node == NULL or node.getLogOdds() > floor_log or ends.contains(_pack(ko)):
        return 0
    region.set(ko[0], ko[1], ko[2])
    seen.set(ko[0], ko[1], ko[2])
    frontier.push_back(ko)
    count = 1
    for level in range(1, max_level + 1):
        next_frontier.clear()
        for j in range(frontier.size()):
            c = frontier[j]
            for axis in range(3):
                for d in range(2):
                    step = 1 if d == 0 else -1
                    if c[axis] != ko[axis] and (step > 0) != (c[axis] > ko[axis]):
                        continue            # only away from the origin
                    nb = c
                    nb[axis] = <key_type>(<int>c[axis] + step)
                    if (not seen.inside(nb[0], nb[1], nb[2])
                            or seen.test(nb[0], nb[1], nb[2])):
                        continue
                    seen.set(nb[0], nb[1], nb[2])
                    ok = True
                    for b in range(3):      # test cells: one step back toward the origin
                        if nb[b] == ko[b]:
                            continue
                        t = nb
                        t[b] = <key_type>(<int>nb[b] + (-1 if nb[b] > ko[b] else 1))
                        if not _in_region(region, t):
                            ok = False
                            break
                    if not ok or ends.contains(_pack(nb)):
                        continue
                    node = tree.search(nb, 0)
                    if node == NULL or node.getLogOdds() > floor_log:
                        continue
                    region.set(nb[0], nb[1], nb[2])
                    next_frontier.push_back(nb)
                    count += 1
        if next_frontier.empty():
            break
        frontier.swap(next_frontier)
    return count


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
    """Walk a .bt data block without building anything.

    Returns (number of nodes, end offset), or raises ValueError when the block is
    truncated or describes a node deeper than the 16 levels of an OcTree.
    liboctomap trusts its input; this walk makes sure it gets only valid input.
    """
    cdef Py_ssize_t pos = offset, n = data.shape[0], nodes = 1
    cdef vector[uint8_t] stack            # depth of each inner node still to read
    cdef uint8_t depth
    cdef unsigned code, bits, i
    cdef int err = 0
    stack.push_back(0)
    with nogil:
        while not stack.empty():
            depth = stack.back()
            stack.pop_back()
            if pos + 2 > n:
                err = 1
                break
            bits = data[pos] | (<unsigned>data[pos + 1] << 8)
            pos += 2
            # children with children are read depth-first in child order: push in reverse
            for i in range(7, -1, -1):
                code = (bits >> (2 * i)) & 3
                if code != 0:
                    nodes += 1
                if code == 3:
                    if depth + 1 >= _DEPTH:
                        err = 2
                        break
                    stack.push_back(depth + 1)
            if err:
                break
    if err == 1:
        raise ValueError(f"truncated data: the tree needs more than the {n - offset} bytes given")
    if err == 2:
        raise ValueError("corrupt data: a node lies deeper than the 16 levels of an OcTree")
    return nodes, pos


def _check_full_data(const uint8_t[::1] data, Py_ssize_t offset):
    """Like :func:`_check_binary_data` for a .ot data block (float log-odds + child mask)."""
    cdef Py_ssize_t pos = offset, n = data.shape[0], nodes = 0
    cdef vector[uint8_t] stack
    cdef uint8_t depth, mask
    cdef float value
    cdef int i, err = 0
    stack.push_back(0)
    with nogil:
        while not stack.empty():
            depth = stack.back()
            stack.pop_back()
            if pos + 5 > n:
                err = 1
                break
            memcpy(&value, &data[pos], sizeof(float))
            mask = data[pos + 4]
            pos += 5
            nodes += 1
            if not isfinite(value):
                err = 3
                break
            if mask != 0 and depth + 1 > _DEPTH:
                err = 2
                break
            for i in range(7, -1, -1):
                if (mask >> i) & 1:
                    stack.push_back(depth + 1)
    if err == 1:
        raise ValueError(f"truncated data: the tree needs more than the {n - offset} bytes given")
    if err == 2:
        raise ValueError("corrupt data: a node lies deeper than the 16 levels of an OcTree")
    if err == 3:
        raise ValueError("corrupt data: a node holds a non-finite log-odds value")
    return nodes, pos
