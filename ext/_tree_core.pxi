# The operations that occgp's liboctomap occupancy trees share, written once.
#
# Included by ext/_octree.pyx (OcTree) and ext/_color.pyx (ColorOcTree), each of which
# first defines, for its tree:
#
#     ctypedef <liboctomap tree class> Tree     # OcTree, ColorOcTree
#     ctypedef <its node class> Node            # OcTreeNode, ColorOcTreeNode
#     cdef str _PUBLIC_CLASS = "<the public class built on it>"
#
# and derives its core class from _TreeCore, overriding _reset when it keeps state
# derived from the tree's nodes. Every liboctomap call that does real work runs without
# the GIL; the tree's lock serialises the operations on one tree.

from cython.operator cimport dereference as _deref
from libcpp.memory cimport unique_ptr
from libcpp.string cimport string

from _keys cimport in_range_mask, ray_codes
from _status cimport Status
from liboctomap cimport istringstream

import threading

from occgp._status import check_status as _check_status


@cython.auto_pickle(False)
cdef class _TreeCore:
    """What every occgp liboctomap tree shares: its C++ tree, its lock, the sensor
    model, key checks, point queries, size, extent and reading data."""

    cdef unique_ptr[Tree] _tree
    cdef object _lock

    def __cinit__(self, *args, **kwargs):
        self._lock = threading.Lock()

    cdef Tree* _get(self) except NULL:
        cdef Tree* tree = self._tree.get()
        if tree == NULL:
            raise ValueError(f"{type(self).__name__} was not initialised "
                             f"(create it with {_PUBLIC_CLASS}(resolution))")
        return tree

    cdef void _reset(self) noexcept:
        """Drop the state derived from the tree's nodes (the lock is held): the tree was
        created, cleared or read anew. Nothing here; subclasses may add."""
        pass

    cdef void _set_model(self, Tree* tree, double prob_hit, double prob_miss,
                         double clamping_min, double clamping_max,
                         double occupancy_threshold) noexcept:
        tree.setProbHit(prob_hit)
        tree.setProbMiss(prob_miss)
        tree.setClampingThresMin(clamping_min)
        tree.setClampingThresMax(clamping_max)
        tree.setOccupancyThres(occupancy_threshold)

    def _setup(self, double resolution, double prob_hit, double prob_miss,
               double clamping_min, double clamping_max, double occupancy_threshold):
        """Create the C++ tree (parameters were validated by the caller)."""
        with self._lock:
            self._tree.reset(new Tree(resolution))
            self._set_model(self._tree.get(), prob_hit, prob_miss, clamping_min, clamping_max,
                            occupancy_threshold)
            self._reset()

    def _set_sensor_model(self, double prob_hit, double prob_miss, double clamping_min,
                          double clamping_max, double occupancy_threshold):
        """liboctomap's setters of the sensor model (validated by the caller); the stored
        values are left as they are."""
        cdef Tree* tree = self._get()
        with self._lock:
            self._set_model(tree, prob_hit, prob_miss, clamping_min, clamping_max,
                            occupancy_threshold)

    def _log_odds_thresholds(self):
        """(clamping min, clamping max, occupancy threshold, hit, miss) as the tree
        holds them: float32 log-odds."""
        cdef Tree* tree = self._get()
        return (tree.getClampingThresMinLog(), tree.getClampingThresMaxLog(),
                tree.getOccupancyThresLog(), tree.getProbHitLog(), tree.getProbMissLog())

    # ------------------------------------------------------------------ key range
    def _in_range(self, const float[:, ::1] points):
        """Boolean mask: which rows of `points` have a valid key on every axis."""
        return in_range_mask(1.0 / self._get().getResolution(), points)

    def _check_rays(self, const float[:, ::1] points, const float[::1] origin,
                    double max_range):
        """(codes, cells) of the rays after truncation at `max_range` (< 0: none): see
        ``mark_rays`` in ``ext/_keys.pxd``."""
        return ray_codes(1.0 / self._get().getResolution(), points, origin, max_range)

    # ------------------------------------------------------------------ queries
    def _query(self, const float[:, ::1] points, int what):
        """Per point: 0 → occupancy probability, 1 → log-odds (NaN where unknown),
        2 → int8 state (-1 unknown, 0 free, 1 occupied)."""
        cdef Tree* tree = self._get()
        cdef Py_ssize_t i, n = points.shape[0]
        cdef OcTreeKey key
        cdef Node* node
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

    # ------------------------------------------------------------------ structure
    def _num_leaves(self):
        cdef Tree* tree = self._get()
        cdef size_t n = 0
        with self._lock:
            with nogil:
                if tree.size() > 0:
                    n = tree.getNumLeafNodes()
        return n

    def _num_nodes(self):
        return self._get().size()

    def _memory_usage(self):
        return self._get().memoryUsage()

    def _bounds(self):
        cdef Tree* tree = self._get()
        cdef double x0 = 0, y0 = 0, z0 = 0, x1 = 0, y1 = 0, z1 = 0
        with self._lock:
            tree.getMetricMin(x0, y0, z0)
            tree.getMetricMax(x1, y1, z1)
        return np.array([x0, y0, z0]), np.array([x1, y1, z1])

    def _clear(self):
        cdef Tree* tree = self._get()
        with self._lock:
            tree.clear()
            self._reset()

    # ------------------------------------------------------------------ serialisation
    cdef _read(self, bytes payload, bint binary, double resolution):
        """Replace the tree by the data block `payload` in the .bt (`binary`) or .ot
        encoding (validated by the caller)."""
        cdef Tree* tree = self._get()
        cdef string data = payload
        cdef unique_ptr[istringstream] stream
        with self._lock:
            with nogil:
                tree.clear()
                tree.setResolution(resolution)
                stream.reset(new istringstream(data))
                if binary:
                    tree.readBinaryData(_deref(stream))
                else:
                    tree.readData(_deref(stream))
            failed = _deref(stream).fail()
            self._reset()
        if failed:
            with self._lock:
                tree.clear()
            _check_status(<int>Status.unreadable_data)
