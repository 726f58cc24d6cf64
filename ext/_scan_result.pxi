# What the maps' scan insertion takes from and returns to Python (included by
# ext/_octree.pyx and ext/_grid.pyx, which cimport _scan).

from posix.time cimport CLOCK_MONOTONIC, clock_gettime, timespec

from _scan cimport kRayVisits
from occgp._status import Status as _Status, check_status as _check_status

#: A ray's start in the traversal costs about as much as this many cell visits (the
#: adaptive super rays' cost model, ext/_superrays.h; occgp/_superray_policy.py).
RAY_VISITS = kRayVisits


cdef inline const uint32_t* scan_weights(const uint32_t[::1] weights, Py_ssize_t n,
                                         int superray_threshold) except? NULL:
    """The ray weights for ``scan_updates`` (NULL: none), checked against the scan."""
    if weights is None:
        return NULL
    if weights.shape[0] != n:
        _check_status(<int>Status.weights_length, expected=n, got=weights.shape[0])
    if superray_threshold != 0:
        _check_status(<int>Status.weights_with_superrays)
    return &weights[0] if n else NULL


cdef inline const uint8_t* scan_free_only(const uint8_t[::1] free_only,
                                           Py_ssize_t n) except? NULL:
    """The per-ray "clears only" flags for ``scan_updates`` (NULL: none), checked
    against the scan."""
    if free_only is None:
        return NULL
    if free_only.shape[0] != n:
        raise ValueError(f"free_only must have {n} entries, got {free_only.shape[0]}")
    return &free_only[0] if n else NULL


cdef inline const float* scan_points(const float[:, ::1] points) noexcept nogil:
    """The rows of `points` for ``scan_updates`` (NULL when there are none)."""
    return &points[0, 0] if points.shape[0] else NULL


cdef inline double _elapsed(const timespec& a, const timespec& b) noexcept nogil:
    return (b.tv_sec - a.tv_sec) + 1e-9 * (b.tv_nsec - a.tv_nsec)


cdef inline object scan_result(Status status, const ScanStats& stats, size_t updated,
                               const timespec& done):
    """What the maps' scan insertion returns: (region_cells, updated_cells,
    traversed_rays, traversed_cells, seconds, unnecessary_traversals, spared_cells,
    culled_rays, region_spared_cells), seconds = (end points, super rays, culling
    region, traversal, map update) with the update ending at `done`; the failure's
    :class:`occgp._status.Status` when the scan was not inserted (a ray end out of range or too short to walk, or more cells than
    its limit: nothing changed)."""
    if status != Status.ok:
        return _Status(<int>status)
    seconds = tuple([_elapsed(stats.clock[k], stats.clock[k + 1]) for k in range(4)]
                    + [_elapsed(stats.clock[4], done)])
    return (stats.region_cells, updated, stats.rays, stats.traversed_cells, seconds,
            stats.unnecessary, stats.spared_cells, stats.culled_rays, stats.region_spared)
