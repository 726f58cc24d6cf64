# cython: language_level=3
# distutils: language = c++
"""Compiled core of :class:`occgp.GridMap`: a hashed uniform grid on liboctomap's keys.

The cells live in a block grid (``ext/_block_grid.h``): a hashed root of dense
8 x 8 x 8 blocks of float32 log-odds, on liboctomap's 16-bit keys. A private liboctomap ``OcTree`` of the same
resolution holds the sensor model and computes the keys and the ray traversals
(``computeRayKeys``, ``coordToKeyChecked``, ``keyToCoord``), so the grid finds
exactly the cells the octree finds; a scan's cells are collected by the
octree's own pipeline (``ext/_scan.pxd``: rays, super rays, culling region)
and each is updated once, as ``updateNode`` does.

Nothing here validates user input: :mod:`occgp.grid` coerces and checks every
array before it reaches these methods. Every loop runs without the GIL; a
per-map lock serialises the operations on one map.
"""

cimport cython
from libc.math cimport exp
from libc.stdint cimport int64_t, uint8_t, uint16_t, uint32_t, uint64_t
from libcpp cimport bool
from libcpp.algorithm cimport sort
from libcpp.memory cimport unique_ptr
from libcpp.utility cimport pair
from libcpp.vector cimport vector

from liboctomap cimport OcTree, OcTreeKey, point3d
from _keys cimport (
    KEY_DEPTH, ray_codes, in_range_mask, pack_key, set_sensor_model, unpack_key,
)
from _scan cimport FreeTest, ScanCell, ScanStats
from _status cimport Status


cdef extern from "_block_grid.h" namespace "occgp" nogil:
    cdef cppclass BlockGrid:
        float* find(uint64_t packed)
        void set(uint64_t packed, float value) except +
        size_t size()
        size_t num_blocks()
        void clear()
        void reserve_blocks(size_t n) except +
        size_t memory_usage()
        void collect(vector[pair[uint64_t, float]]& out, bool occupied_only,
                     float threshold) except +
        void key_bounds(uint16_t* lo, uint16_t* hi)
    cdef cppclass BlockAccessor:
        void reset(BlockGrid* grid)
        float* find(uint64_t packed)

cdef extern from "_bresenham.h" namespace "occgp" nogil:
    cdef struct BresenhamStats:
        uint64_t rays
        uint64_t visits
        uint64_t updated
        int64_t first_bad
    Status bresenham_scan(BlockGrid& grid, const float* points, Py_ssize_t n,
                          const float* origin, double resolution, double max_range,
                          float hit, float miss, float lo, float hi,
                          BresenhamStats* stats) except +

cdef extern from "_grid_apply.h" namespace "occgp" nogil:
    void apply_grid_updates(BlockGrid& cells, const vector[ScanCell]& found,
                            float lo, float hi, int n_threads) except +
    cdef cppclass GridDirect:
        uint64_t updated
        void reset(BlockGrid* grid, float lo, float hi)
    # scan_updates with the grid's in-place updates (ext/_scan.h, `direct`)
    Status scan_updates_in_place "occgp::scan_updates"(
        const OcTree& keys, const float* points, Py_ssize_t n, const point3d& o,
        double max_range, bool ray_mode, bool culling, const uint32_t* weights,
        int superray_threshold, FreeTest fully_free, void* map, vector[uint32_t]& counts,
        bool& counts_dirty, vector[ScanCell]& found, ScanStats* stats, bool diagnose,
        uint64_t max_cells, int n_threads, const uint8_t* free_only,
        GridDirect* direct) except +

cdef extern from "_discretize.h" namespace "occgp" nogil:
    Py_ssize_t discretize_points(const float* points, Py_ssize_t n, double resolution,
                                 vector[float]& centers) except +


def _discretize(double resolution, const float[:, ::1] points):
    """liboctomap's discretize (``ext/_discretize.h``): (first point outside the key
    range or -1, the centers of the distinct cells holding the points, float32 (n, 3),
    in the order of each cell's first point)."""
    cdef vector[float] centers
    cdef Py_ssize_t bad
    cdef const float* first = &points[0, 0] if points.shape[0] else NULL
    with nogil:
        bad = discretize_points(first, points.shape[0], resolution, centers)
    out = np.empty((centers.size() // 3, 3), dtype=np.float32)
    cdef float[:, ::1] view = out
    cdef Py_ssize_t i
    for i in range(<Py_ssize_t>centers.size()):
        view[i // 3, i % 3] = centers[i]
    return bad, out


include "_scan_result.pxi"

import threading

import numpy as np

ctypedef pair[uint64_t, float] Cell                     # packed key, log-odds


cdef struct GridView:
    BlockAccessor* cells  # lookups only: the culling region is grown before any update
    float floor           # lower clamping bound (log-odds)


cdef bool _fully_free(void* view, const OcTreeKey& key) noexcept nogil:
    """FreeTest of a grid: the cell is known and at the lower clamping bound."""
    cdef GridView* v = <GridView*>view
    cdef float* found = v.cells.find(pack_key(key))
    return found != NULL and found[0] <= v.floor


@cython.auto_pickle(False)
cdef class _Grid:
    """A hashed uniform grid owned by Python. Use :class:`occgp.GridMap`."""

    cdef unique_ptr[OcTree] _key_tree   # key calculator and sensor model; holds no cells
    cdef BlockGrid _cells
    cdef object _lock
    cdef vector[uint32_t] _counts       # scratch of scan_updates, zero between scans
    cdef bool _counts_dirty

    def __cinit__(self, *args, **kwargs):
        self._lock = threading.Lock()

    cdef OcTree* _get(self) except NULL:
        cdef OcTree* tree = self._key_tree.get()
        if tree == NULL:
            raise ValueError(f"{type(self).__name__} was not initialised "
                             "(create it with GridMap(resolution))")
        return tree

    def _setup(self, double resolution, double prob_hit, double prob_miss,
               double clamping_min, double clamping_max, double occupancy_threshold):
        """Create the key calculator (parameters were validated by the caller)."""
        cdef OcTree* tree
        with self._lock:
            self._cells.clear()
            self._key_tree.reset(new OcTree(resolution))
            tree = self._key_tree.get()
            set_sensor_model(tree, prob_hit, prob_miss, clamping_min, clamping_max,
                             occupancy_threshold)

    def _set_sensor_model(self, double prob_hit, double prob_miss, double clamping_min,
                          double clamping_max, double occupancy_threshold):
        """liboctomap's setters on the key calculator, whose sensor model every update
        and query reads (validated by the caller); the stored values are left as they
        are."""
        cdef OcTree* tree = self._get()
        with self._lock:
            set_sensor_model(tree, prob_hit, prob_miss, clamping_min, clamping_max,
                             occupancy_threshold)

    # ------------------------------------------------------------------ key range
    def _in_range(self, const float[:, ::1] points):
        """Boolean mask: which rows of `points` have a valid key on every axis."""
        return in_range_mask(1.0 / self._get().getResolution(), points)

    def _check_rays(self, const float[:, ::1] points, const float[::1] origin,
                    double max_range):
        """(codes, cells) of the rays after truncation at `max_range` (< 0: none): see
        ``mark_rays`` in ``ext/_keys.pxd``."""
        return ray_codes(1.0 / self._get().getResolution(), points, origin, max_range)

    # ------------------------------------------------------------------ updates
    def _insert(self, const float[:, ::1] points, const float[::1] origin, double max_range,
                bint ray_mode, bint culling=False, const uint32_t[::1] weights=None,
                int superray_threshold=0, bint diagnose=False, uint64_t max_cells=0,
                int n_threads=1, const uint8_t[::1] free_only=None):
        """Insert a scan: one update per cell (see ``scan_updates`` in ``ext/_scan.pxd``).

        The cells, their counts and updates are the octree's; each update is
        applied to the block grid as liboctomap's ``updateNode`` applies it. With
        `culling` the scan's culling region is grown over this grid's cells;
        with `weights` (ray mode), ray i counts ``weights[i]`` times; with
        `superray_threshold` != 0 the rays are grouped into super rays first (as the
        octree's). The rays
        are walked, and the updates applied (``ext/_grid_apply.h``), on up to `n_threads`
        threads (the walk on one with `diagnose`); in scan mode on one thread the cells
        are updated in place as the walk reaches them (``GridDirect``, no flags over
        the scan's box and no update pass). The grid and the statistics are the
        same for every `n_threads`. Rays i with ``free_only[i]``
        (None: none) only clear, as rays cut at `max_range`.

        Returns (region_cells, updated_cells, traversed_rays, traversed_cells,
        seconds, unnecessary_traversals, spared_cells, culled_rays, region_spared_cells) as
        ``OccupancyOctree``'s
        ``_insert_batch``.
        """
        cdef OcTree* tree = self._get()
        cdef const uint32_t* w = scan_weights(weights, points.shape[0], superray_threshold)
        cdef const uint8_t* fo = scan_free_only(free_only, points.shape[0])
        cdef point3d o = point3d(origin[0], origin[1], origin[2])
        cdef vector[ScanCell] found
        cdef ScanStats stats
        cdef GridView view
        cdef BlockAccessor cache
        cdef GridDirect direct
        cdef float lo = tree.getClampingThresMinLog(), hi = tree.getClampingThresMaxLog()
        cdef timespec done
        cdef Status status = Status.ok
        cache.reset(&self._cells)
        view.cells = &cache
        view.floor = lo
        with self._lock:
            with nogil:
                direct.reset(&self._cells, lo, hi)
                status = scan_updates_in_place(
                    tree[0], scan_points(points), points.shape[0], o, max_range, ray_mode,
                    culling, w, superray_threshold, _fully_free, &view, self._counts,
                    self._counts_dirty, found, &stats, diagnose, max_cells, n_threads, fo,
                    &direct)
                apply_grid_updates(self._cells, found, lo, hi, n_threads)
                clock_gettime(CLOCK_MONOTONIC, &done)
        return scan_result(status, stats, found.size() + direct.updated, done)

    def _insert_bresenham(self, const float[:, ::1] points, const float[::1] origin,
                          double max_range):
        """Insert a scan with Bonxai's ray model (``ext/_bresenham.h``): one integer
        Bresenham line per distinct end cell, each cell updated once. `max_range` < 0:
        no limit. Returns (status, rays, visited cells, updated cells, the first point
        without a key or -1); nothing changed unless status is ok."""
        cdef OcTree* tree = self._get()
        cdef BresenhamStats stats
        cdef Status status
        cdef float hit = tree.getProbHitLog(), miss = tree.getProbMissLog()
        cdef float lo = tree.getClampingThresMinLog(), hi = tree.getClampingThresMaxLog()
        cdef const float* first = &points[0, 0] if points.shape[0] else NULL
        with self._lock:
            with nogil:
                status = bresenham_scan(self._cells, first, points.shape[0], &origin[0],
                                        tree.getResolution(), max_range, hit, miss, lo, hi,
                                        &stats)
        return int(status), stats.rays, stats.visits, stats.updated, stats.first_bad

    # ------------------------------------------------------------------ queries
    def _query(self, const float[:, ::1] points, int what):
        """Per point: 0 → occupancy probability, 1 → log-odds (NaN where unknown),
        2 → int8 state (-1 unknown, 0 free, 1 occupied)."""
        cdef OcTree* tree = self._get()
        cdef Py_ssize_t i, n = points.shape[0]
        cdef OcTreeKey key
        cdef float* found
        cdef float value, threshold = tree.getOccupancyThresLog()
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
                    found = self._cells.find(pack_key(key))
                    if found == NULL:
                        continue
                    value = found[0]
                    if what == 0:      # liboctomap's probability(log-odds)
                        values[i] = 1. - (1. / (1. + exp(<double>value)))
                    elif what == 1:
                        values[i] = value
                    else:
                        states[i] = 1 if value >= threshold else 0
        return out

    def _cells_sorted(self, bint occupied_only):
        """Keys (n, 3) uint16, centres (n, 3) and float32 log-odds of the cells, by packed key."""
        cdef OcTree* tree = self._get()
        cdef float threshold = tree.getOccupancyThresLog()
        cdef vector[Cell] cells
        cdef OcTreeKey key
        cdef Py_ssize_t i, n
        cdef int axis
        with self._lock:
            with nogil:
                self._cells.collect(cells, occupied_only, threshold)
        n = cells.size()
        keys = np.empty((n, 3), dtype=np.uint16)
        centers = np.empty((n, 3))
        values = np.empty(n, dtype=np.float32)
        cdef uint16_t[:, ::1] kv = keys
        cdef double[:, ::1] cv = centers
        cdef float[::1] vv = values
        with nogil:
            sort(cells.begin(), cells.end())
            for i in range(n):
                key = unpack_key(cells[i].first)
                for axis in range(3):
                    kv[i, axis] = key[axis]
                    cv[i, axis] = tree.keyToCoord(key[axis], KEY_DEPTH)
                vv[i] = cells[i].second
        return keys, centers, values

    def _set_cells(self, const uint16_t[:, ::1] keys, const float[::1] values):
        """Replace every cell by `keys` (n, 3) and `values` (n,) (validated by the caller)."""
        self._get()
        cdef Py_ssize_t i, n = keys.shape[0]
        with self._lock:
            with nogil:
                self._cells.clear()
                for i in range(n):
                    self._cells.set(pack_key(OcTreeKey(keys[i, 0], keys[i, 1], keys[i, 2])),
                                    values[i])

    # ------------------------------------------------------------------ structure
    def _num_cells(self):
        with self._lock:
            return self._cells.size()

    def _memory_usage(self):
        """Bytes of the block grid: the blocks, their owning pointers and the root's slots."""
        with self._lock:
            return self._cells.memory_usage()

    def _num_blocks(self):
        with self._lock:
            return self._cells.num_blocks()

    def _bounds(self):
        """(min corner, max corner) of the known cells, as liboctomap's getMetricMin/Max."""
        cdef OcTree* tree = self._get()
        cdef double half = tree.getResolution() / 2.0
        cdef uint16_t lo[3]
        cdef uint16_t hi[3]
        cdef int axis
        for axis in range(3):
            lo[axis] = 0xFFFF
            hi[axis] = 0
        with self._lock:
            with nogil:
                self._cells.key_bounds(lo, hi)
        return (np.array([tree.keyToCoord(lo[axis], KEY_DEPTH) - half for axis in range(3)]),
                np.array([tree.keyToCoord(hi[axis], KEY_DEPTH) + half for axis in range(3)]))

    def _clear(self):
        with self._lock:
            with nogil:
                self._cells.clear()            # frees the blocks and the root's slots
