# cython: language_level=3
"""Key arithmetic shared by the compiled maps: liboctomap's 16-bit keys, packed and checked.

Inline ``nogil`` helpers and declarations only, so this file builds no module of
its own: ``from _keys cimport pack_key, KeyTable, ...``. The arithmetic is
liboctomap's, so every map that uses it finds the same cells as its ``OcTree``.
"""

from libc.math cimport floor
from libc.stdint cimport int64_t, uint8_t, uint32_t, uint64_t
from libcpp.vector cimport vector

from _status cimport Status
from liboctomap cimport OcTree, OcTreeKey, key_type, point3d


cdef extern from "_keytable.h" namespace "occgp" nogil:
    cdef cppclass KeyCounts:
        uint64_t key
        uint32_t n_free       # rays passing through the cell
        uint32_t n_hit        # rays ending in the cell
        uint32_t group        # super rays: 1 + index of the cell's group of end points, or 0

    cdef cppclass KeyTable:   # packed key -> KeyCounts, for the cells of one scan
        KeyTable() except +
        void reset(size_t expected) except +
        KeyCounts* get(uint64_t key) except +
        KeyCounts* find(uint64_t key)
        bint contains(uint64_t key) const
        size_t size()
        size_t capacity() const
        const KeyCounts& slot(size_t i) const

    cdef cppclass CellBox:    # a bitset over a box of keys
        CellBox() except +
        bint reset(const int* lo, const int* hi, uint64_t max_cells) except +
        bint inside(int x, int y, int z) const
        bint test(int x, int y, int z) const
        void set(int x, int y, int z)

cdef extern from "_keytable.h" nogil:
    const uint64_t KEY_EMPTY "occgp::KeyTable::kEmpty"

cdef extern from "_raywalk.h" namespace "occgp" nogil:
    cdef cppclass RayWalker:  # liboctomap's computeRayKeys, one cell at a time
        bint start(double resolution, const point3d& origin, const OcTreeKey& key_origin,
                   const point3d& end, const OcTreeKey& key_end)
        bint next()
        int key(int axis) const
        bint walk_back(const CellBox& region, vector[uint64_t]& cells) except + nogil

cdef extern from "_keys.h" namespace "occgp" nogil:
    # the three 16-bit keys in one integer (x in the low bits), for hash maps
    uint64_t pack_key(const OcTreeKey& key)
    OcTreeKey unpack_key(uint64_t packed)
    # set `end` to the ray's end as liboctomap's computeUpdate does; True when truncated
    # (`max_range` < 0: no limit)
    bint effective_end(const point3d& origin, const point3d& point, double max_range,
                       point3d* end)
    # whether liboctomap's traversal of a ray between two different cells ends
    bint walkable(const point3d& origin, const point3d& end)

cdef enum:
    KEY_MAX_VAL = 32768     # half the number of keys per axis (liboctomap's tree_max_val)
    KEY_DEPTH = 16          # depth of the finest cells in a 16-bit key tree


cdef inline bint in_key_range(double resolution_factor, float coordinate) noexcept nogil:
    """liboctomap's coordToKeyChecked: floor(coord / res) + 32768 must lie in [0, 65536)."""
    cdef double scaled = floor(resolution_factor * <double>coordinate)
    return scaled >= -KEY_MAX_VAL and scaled < KEY_MAX_VAL


cdef inline void mark_in_range(double resolution_factor, const float[:, ::1] points,
                               uint8_t[::1] ok) noexcept nogil:
    """ok[i] = whether row i of `points` has a valid key on every axis."""
    cdef Py_ssize_t i
    for i in range(points.shape[0]):
        ok[i] = (in_key_range(resolution_factor, points[i, 0])
                 and in_key_range(resolution_factor, points[i, 1])
                 and in_key_range(resolution_factor, points[i, 2]))


cdef enum:
    # liboctomap's KeyRay holds 100000 keys and computeRayKeys does not check it (an
    # assert, off in release builds): a ray may walk at most this many cells there
    KEYRAY_SAFE_CELLS = 99990


cdef inline void mark_rays(double resolution_factor, const float[:, ::1] points,
                           point3d origin, double max_range, uint8_t[::1] code,
                           int64_t[::1] cells) noexcept nogil:
    """Per ray (after truncation at `max_range`; < 0: none): its status (ok, out_of_range
    or ray_too_short, ``ext/_status.h``) and the
    Manhattan distance between the keys of its ends (an upper bound, up to 3, of the
    cells its traversal visits); -1 when its end is out of range."""
    cdef Py_ssize_t i
    cdef int axis
    cdef point3d end
    cdef int64_t key_o[3]
    cdef int64_t key_e[3]
    cdef int64_t n
    key_o[0] = <int64_t>floor(resolution_factor * <double>origin.x())
    key_o[1] = <int64_t>floor(resolution_factor * <double>origin.y())
    key_o[2] = <int64_t>floor(resolution_factor * <double>origin.z())
    for i in range(points.shape[0]):
        effective_end(origin, point3d(points[i, 0], points[i, 1], points[i, 2]), max_range,
                      &end)
        cells[i] = -1
        if not (in_key_range(resolution_factor, end.x())
                and in_key_range(resolution_factor, end.y())
                and in_key_range(resolution_factor, end.z())):
            code[i] = <uint8_t>Status.out_of_range
            continue
        key_e[0] = <int64_t>floor(resolution_factor * <double>end.x())
        key_e[1] = <int64_t>floor(resolution_factor * <double>end.y())
        key_e[2] = <int64_t>floor(resolution_factor * <double>end.z())
        n = 0
        for axis in range(3):
            n += key_e[axis] - key_o[axis] if key_e[axis] >= key_o[axis] else key_o[axis] - key_e[axis]
        cells[i] = n
        code[i] = <uint8_t>(Status.ok if n == 0 or walkable(origin, end) else Status.ray_too_short)


cdef inline void set_sensor_model(OcTree* tree, double prob_hit, double prob_miss,
                                  double clamping_min, double clamping_max,
                                  double occupancy_threshold) noexcept nogil:
    """The sensor model and thresholds of a map, as probabilities (validated by the caller)."""
    tree.setProbHit(prob_hit)
    tree.setProbMiss(prob_miss)
    tree.setClampingThresMin(clamping_min)
    tree.setClampingThresMax(clamping_max)
    tree.setOccupancyThres(occupancy_threshold)


cdef inline object in_range_mask(double resolution_factor, const float[:, ::1] points):
    """Boolean array: which rows of `points` have a valid key on every axis."""
    import numpy as np
    out = np.empty(points.shape[0], dtype=np.bool_)
    cdef uint8_t[::1] ok = out.view(np.uint8)
    with nogil:
        mark_in_range(resolution_factor, points, ok)
    return out


cdef inline object ray_codes(double resolution_factor, const float[:, ::1] points,
                            const float[::1] origin, double max_range):
    """(codes, cells): see :func:`mark_rays`; codes uint8, cells int64."""
    import numpy as np
    cdef point3d o = point3d(origin[0], origin[1], origin[2])
    codes = np.empty(points.shape[0], dtype=np.uint8)
    cells = np.empty(points.shape[0], dtype=np.int64)
    cdef uint8_t[::1] c = codes
    cdef int64_t[::1] m = cells
    with nogil:
        mark_rays(resolution_factor, points, o, max_range, c, m)
    return codes, cells
