# cython: language_level=3
"""A scan's cell updates, shared by the compiled maps (``ext/_scan.h``): declarations only.

:cpp:func:`scan_updates` turns a scan into one update per cell (rays, super rays,
culling region), and each map applies them its own way (``ext/_octree.pyx`` in one
pass over the tree, ``ext/_grid.pyx`` in its hash map). The modules that use it are
built with OpenMP (``OPENMP_MODULES`` in ``setup.py``). What a map's scan insertion
returns to Python is built in ``ext/_scan_result.pxi``.
"""

from libc.stdint cimport uint8_t, uint32_t, uint64_t
from libcpp cimport bool
from libcpp.vector cimport vector
from posix.time cimport timespec

from _status cimport Status
from liboctomap cimport OcTree, OcTreeKey, point3d


cdef extern from "_scan.h" namespace "occgp" nogil:
    #: Whether the map's cell at a key is known and at the lower clamping bound.
    ctypedef bool (*FreeTest)(void* map, const OcTreeKey& key) noexcept nogil

    cdef struct ScanCell:
        uint64_t key      # packed key (pack_key)
        float update      # the log-odds to add, as updateNode(key, update) adds it

    cdef struct ScanStats:
        long region_cells      # cells in the culling region; -1 without culling
        long rays              # rays traversed (super rays count once)
        long traversed_cells   # cell visits that counted a ray
        long spared_cells      # the visits super rays spared
        long culled_rays       # rays the culling region hid whole: not walked
        long region_spared     # the visits the culling region spared the walked rays
        long unnecessary       # with `diagnose`: visits to cells whose update is a no-op
        timespec clock[5]      # start; end points, super rays, culling region, traversal done

    # the statistics of a scan before (or without) its traversal, every clock now
    void empty_stats(ScanStats* stats)

    # one update per cell of a scan of `n` points (rows of three floats) appended to
    # `cells`; ok, out_of_range, ray_too_short or too_many_cells (nothing collected)
    Status scan_updates(const OcTree& keys, const float* points, Py_ssize_t n,
                        const point3d& o, double max_range, bool ray_mode, bool culling,
                        const uint32_t* weights, int superray_threshold, FreeTest fully_free,
                        void* map, vector[uint32_t]& counts, bool& counts_dirty,
                        vector[ScanCell]& cells, ScanStats* stats, bool diagnose,
                        uint64_t max_cells, int n_threads) except +
    # the same, where rays i with free_only[i] (NULL: none) only clear, as rays cut at
    # max_range do (their end cell gets nothing from them)
    Status scan_updates_free_only "occgp::scan_updates"(
        const OcTree& keys, const float* points, Py_ssize_t n, const point3d& o,
        double max_range, bool ray_mode, bool culling, const uint32_t* weights,
        int superray_threshold, FreeTest fully_free, void* map, vector[uint32_t]& counts,
        bool& counts_dirty, vector[ScanCell]& cells, ScanStats* stats, bool diagnose,
        uint64_t max_cells, int n_threads, const uint8_t* free_only) except +


cdef extern from "_superrays.h" namespace "occgp::scan_detail" nogil:
    # the adaptive super rays' cost model, in cell visits of the traversal: a ray's start
    const long kRayVisits
