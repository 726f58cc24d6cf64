# cython: language_level=3
"""A scan's cell updates, shared by the compiled maps: rays, super rays and the culling region.

Inline ``nogil`` code only (no module of its own): :func:`scan_updates` turns a
scan into one update per cell, and each map applies them its own way
(``ext/_octree.pyx`` in one pass over the tree, ``ext/_grid.pyx`` in its hash
map). The rays of a scan may be walked on several OpenMP threads, each into its
own counts, merged (integer sums) before the cells are collected: the modules
that cimport this are built with OpenMP (``OPENMP_MODULES`` in ``setup.py``). Keys, ray ends and the sensor model come from a liboctomap ``OcTree`` of
the map's resolution, so every map finds the cells liboctomap finds.
"""

from libc.math cimport fabs, floor, ldexp, sqrt
from libc.stdint cimport uint8_t, uint32_t, uint64_t
from libcpp.vector cimport vector
from cython.parallel cimport prange, threadid
from posix.time cimport CLOCK_MONOTONIC, clock_gettime, timespec

from _keys cimport (
    KEY_EMPTY, KEY_MAX_VAL as _MAX_VAL, CellBox, KeyCounts, KeyTable, RayWalker,
    effective_end as _effective_end, pack_key as _pack, unpack_key as _unpack,
    walkable as _walkable,
)
from liboctomap cimport OcTree, OcTreeKey, key_type, point3d


cdef extern from "_keytable.h" namespace "occgp" nogil:
    cdef cppclass StopFlag:   # set by one thread of a traversal, polled by all
        StopFlag()
        bint get() const
        void set()


cdef extern from *:
    int _clz64 "__builtin_clzll"(unsigned long long x) nogil

cdef enum:
    _MAX_REGION_CELLS = 1 << 28   # larger scan key boxes are not culled (2 x 32 MB of bits)
    _MAX_DENSE_CELLS = 1 << 24    # up to this, a scan's free counts live in arrays (64 MB)
    _MIN_THREAD_RAYS = 64         # fewer rays per thread than this: fewer threads
    _MAX_THREADS = 256
    _CHUNKS_PER_THREAD = 16       # the rays are handed out in chunks, first come first served

#: Whether the map's cell at a key is known and at the lower clamping bound.
ctypedef bint (*FreeTest)(void* map, const OcTreeKey& key) noexcept nogil


cdef struct ScanCell:
    uint64_t key      # packed key (pack_key)
    float update      # the log-odds to add, as updateNode(key, update) adds it


cdef struct ScanStats:
    long region_cells      # cells in the culling region; -1 without culling
    long rays              # rays traversed (super rays count once)
    long traversed_cells   # cell visits that counted a ray
    long unnecessary       # with `diagnose`: visits to cells whose update is a no-op
    long bad_ends          # ray ends outside the key range (then nothing is collected)
    bint too_many          # the scan reached more than max_cells cells (nothing collected)
    timespec clock[5]      # start; end points, super rays, culling region, traversal done


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
                            const uint64_t* dims, uint32_t* free_counts,
                            vector[uint64_t]* touched, KeyTable* table) except -1 nogil:
    """Count `w` rays through the cell (kx, ky, kz): in the scan's dense box (`free_counts`,
    new cells appended to `touched`), or the table."""
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


cdef inline const uint32_t* scan_weights(const uint32_t[::1] weights, Py_ssize_t n,
                                         int superray_threshold) except? NULL:
    """The ray weights for :func:`scan_updates` (NULL: none), checked against the scan."""
    if weights is None:
        return NULL
    if weights.shape[0] != n:
        raise ValueError(f"weights must have length {n}, got {weights.shape[0]}")
    if superray_threshold > 0:
        raise ValueError("weights and super rays do not combine")
    return &weights[0] if n else NULL


cdef inline double _elapsed(const timespec& a, const timespec& b) noexcept nogil:
    return (b.tv_sec - a.tv_sec) + 1e-9 * (b.tv_nsec - a.tv_nsec)


cdef inline object scan_result(const ScanStats& stats, size_t updated, const timespec& done):
    """What the maps' scan insertion returns: (region_cells, updated_cells,
    traversed_rays, traversed_cells, seconds, unnecessary_traversals), seconds =
    (end points, super rays, culling region, traversal, map update) with the update
    ending at `done`; None when a ray end was out of range, "too many cells" when the
    scan reached more cells than its limit (nothing changed either way)."""
    if stats.bad_ends:
        return None
    if stats.too_many:
        return "too many cells"
    seconds = tuple([_elapsed(stats.clock[k], stats.clock[k + 1]) for k in range(4)]
                    + [_elapsed(stats.clock[4], done)])
    return (stats.region_cells, updated, stats.rays, stats.traversed_cells, seconds,
            stats.unnecessary)


cdef inline bint _key_checked(double resolution_factor, float coordinate,
                              key_type* key) noexcept nogil:
    """liboctomap's coordToKeyChecked on one axis, with its arithmetic (floor of the
    double product, plus 32768); the range is tested on the double first, where
    liboctomap would cast a huge value to int unchecked."""
    cdef double scaled = floor(resolution_factor * <double>coordinate)
    if scaled < -_MAX_VAL or scaled >= _MAX_VAL:
        return False
    key[0] = <key_type>(<int>scaled + _MAX_VAL)
    return True


cdef inline uint64_t _mix(uint64_t k) noexcept nogil:
    """The murmur3 finaliser: spreads the bits of a signature for hashing."""
    k ^= k >> 33
    k *= 0xff51afd7ed558ccdULL
    k ^= k >> 33
    return k


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
    int key_min       # the keys of `other` from the origin's cell to the end cell:
    int key_max       # only the borders between them are crossed


cdef inline int _super_rays(double res, const point3d& o, const OcTreeKey& ko,
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
    when it is *certified* -- its end point clears the borders of its cell by
    more than `delta` = 2^-19 (length + resolution), 4 x the error of
    liboctomap's float direction, and at every crossing (critical or not) the
    other coordinate clears the borders of its cell that the ray crosses (those
    between the origin's cell and the end cell) by more than `delta` plus
    2^-21 resolution times the slope |d_b / d_a|, for the single-precision
    half-cell offset of liboctomap's borders. Its float traversal then equals
    the exact one. Every other ray is traversed on its own. A crossing is
    skipped as non-critical only when every certified ray of the group clears
    the same borders there by that margin: the slopes are bounded over the end
    cell shrunk by `delta` (where the origin lies on the end cell's face, at
    t = 0 of the rays' first crossing, rays that end near that face are steep,
    and the half-cell offset moves their first crossing far along them), and
    the key ranges are computed in doubles, cut to the keys the rays can have.
    """
    cdef double rf = 1.0 / res
    cdef double oc[3]
    cdef double lo[3]
    cdef double hi[3]
    cdef double pc[3]
    cdef Py_ssize_t n = ends.size(), i, j, g, m, first
    cdef uint32_t n_groups = 0, idx
    cdef vector[uint32_t] group_of, offsets, order
    cdef vector[Crossing] crossings
    cdef vector[uint64_t] class_code
    cdef vector[uint32_t] class_ray
    cdef size_t cap, h
    cdef Crossing c
    cdef OcTreeKey key, kv
    cdef KeyCounts* entry
    cdef int a, b, step, code_bits, nk, d_a
    cdef long jj
    cdef double delta, eb, r, r_min, r_max, r_abs, s, b1, b2, t, y, kb, border, slack
    cdef double k_first, k_last, margin
    cdef double far2
    cdef long segments
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
            hi[a] = (<double>kv[a] + 1 - _MAX_VAL) * res
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
                    # the slopes d_b / d_a of the rays into the end cell, extreme at the
                    # corners of the cell shrunk by the end margin `delta` (every other
                    # ray is traversed on its own): finite even where the origin lies on
                    # the end cell's a-face, and there as steep as such rays may be
                    r_min = 1e300
                    r_max = -1e300
                    for i in range(4):
                        s = (hi[a] - delta if i & 1 else lo[a] + delta) - oc[a]
                        if not (s * step >= 0.5 * delta):
                            ok = False     # degenerate end cell: leave the group plain
                            break
                        r = ((hi[b] if i & 2 else lo[b]) - oc[b]) / s
                        r_min = _dmin(r_min, r)
                        r_max = _dmax(r_max, r)
                    if not ok:
                        break
                    slack = delta + eb * _dmax(fabs(r_min), fabs(r_max))
                    c.key_min = min(<int>ko[b], <int>kv[b]) - _MAX_VAL
                    c.key_max = max(<int>ko[b], <int>kv[b]) - _MAX_VAL
                    for jj in range(1, abs(d_a) + 1):
                        border = (<double>(<int>ko[a] + (jj if step > 0 else 1 - jj))
                                  - _MAX_VAL) * res
                        s = border - oc[a]
                        b1 = oc[b] + s * r_min
                        b2 = oc[b] + s * r_max
                        # the keys the rays may have there, in doubles (steep rays give
                        # far ends), cut to the keys between the origin's and the end
                        # cell's: the borders outside are never crossed
                        k_first = _dmax(floor((_dmin(b1, b2) - slack) * rf), c.key_min)
                        k_last = _dmin(floor((_dmax(b1, b2) + slack) * rf), c.key_max)
                        if not (k_first <= k_last):
                            ok = False     # no key left (rounding): leave the group plain
                            break
                        c.key_lo = <int>k_first
                        nk = <int>k_last - c.key_lo + 1
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
        if ok:
            # each crossing where the rays can take nk keys splits them nk ways: when
            # that alone leaves fewer rays than classes, grouping cannot pay its cost
            segments = 1
            for j in range(<Py_ssize_t>crossings.size()):
                segments += crossings[j].n_keys - 1
            if segments >= offsets[g] - first:
                ok = False
        if not ok:
            for m in range(first, offsets[g]):
                rays.push_back(order[m])
                weights.push_back(1)
            continue
        # the classes: equal signatures, found in a small hash table
        cap = 16
        while cap < 2 * (offsets[g] - first):
            cap <<= 1
        class_code.assign(cap, KEY_EMPTY)      # signatures have at most 62 bits
        class_ray.resize(cap)
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
                # the margin to the borders of that key the rays cross
                margin = 1e300
                if kb > c.key_min:
                    margin = y - kb * res
                if kb < c.key_max:
                    margin = _dmin(margin, (kb + 1) * res - y)
                if (not (margin > delta + eb * r_abs)
                        or kb < c.key_lo or kb >= c.key_lo + c.n_keys):
                    ok = False
                else:
                    code = code * <uint64_t>c.n_keys + <uint64_t>(<int>kb - c.key_lo)
                j += 1
            if ok:
                h = _mix(code) & (cap - 1)
                while class_code[h] != KEY_EMPTY and class_code[h] != code:
                    h = (h + 1) & (cap - 1)
                if class_code[h] == code:
                    weights[class_ray[h]] += 1
                else:
                    class_code[h] = code
                    class_ray[h] = <uint32_t>rays.size()
                    rays.push_back(idx)
                    weights.push_back(1)
            else:
                rays.push_back(idx)
                weights.push_back(1)
    return 0


cdef inline bint _in_region(const CellBox& region, const OcTreeKey& key) noexcept nogil:
    return (region.inside(key[0], key[1], key[2])
            and region.test(key[0], key[1], key[2]))


cdef inline long _build_region(FreeTest fully_free, void* map, const OcTreeKey& ko,
                               const int* lo, const int* hi, int max_level,
                               const KeyTable& ends, CellBox& region) noexcept nogil:
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
    cdef int level, axis, b, d, step
    cdef size_t j
    cdef long count = 0
    cdef bint ok
    if (not region.reset(lo, hi, _MAX_REGION_CELLS)
            or not seen.reset(lo, hi, _MAX_REGION_CELLS)):
        return -1
    if not fully_free(map, ko) or ends.contains(_pack(ko)):
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
                    if not fully_free(map, nb):
                        continue
                    region.set(nb[0], nb[1], nb[2])
                    next_frontier.push_back(nb)
                    count += 1
        if next_frontier.empty():
            break
        frontier.swap(next_frontier)
    return count


cdef struct _Rays:
    # what the threads of one scan's traversal share, read only
    double res
    const point3d* origin
    const OcTreeKey* key_origin
    const point3d* ends            # per ray: its end after truncation
    const OcTreeKey* end_keys
    const uint8_t* end_ok
    const uint32_t* ray_ids        # super rays: the rays to walk and their weights; NULL
    const uint32_t* ray_weights
    const uint32_t* weights        # per ray, or NULL
    const CellBox* region          # the culling region over the scan's key box
    bint cull                      # the region holds cells
    bint dense                     # counts in box arrays (else in tables)
    const int* lo                  # the scan's key box
    const uint64_t* dims
    uint64_t max_cells             # 0: no limit


cdef inline int _walk_rays(const _Rays* s, Py_ssize_t r0, Py_ssize_t r1, uint32_t* counts,
                           vector[uint64_t]* touched, KeyTable* table, size_t table_base,
                           KeyTable* visits, long* traversed, StopFlag* stop) except -1 nogil:
    """Walk rays ``r0 <= r < r1`` of a scan (of its super rays when it has them) into one
    thread's counts: cells of the scan's key box in `counts` (dense; new ones appended
    to `touched`), other cells in `table`'s ``n_free``. Adds the cell visits to
    `traversed`; with `visits` (diagnose), counts every visit there too.

    With ``s.max_cells``, stops (setting `stop`) once ``touched`` and the entries of
    `table` past its first `table_base` ones -- distinct cells of the scan, as no
    two of them are one -- outnumber it; stops when another thread set `stop`.
    """
    cdef Py_ssize_t r, i
    cdef uint32_t w = 1
    cdef RayWalker walker
    cdef vector[uint64_t] back
    cdef bint more
    cdef size_t j
    cdef uint64_t idx
    cdef OcTreeKey key
    cdef long n_visits = 0
    cdef const CellBox* region = s.region
    for r in range(r0, r1):
        if stop.get():
            break
        if s.ray_ids != NULL:
            i = s.ray_ids[r]
            w = s.ray_weights[r]
        else:
            i = r
            if s.weights != NULL:
                w = s.weights[i]
        if not s.end_ok[i]:
            continue        # computeRayKeys's out-of-range check
        more = walker.start(s.res, s.origin[0], s.key_origin[0], s.ends[i], s.end_keys[i])
        if more and s.cull:
            back.clear()
            if walker.walk_back(region[0], back):
                # the region's box is the scan's key box, the one `counts` covers
                for j in range(back.size()):
                    idx = back[j]
                    if s.dense:
                        if counts[idx] == 0:
                            touched.push_back(idx)
                        counts[idx] += w
                    else:
                        table.get(_pack(_box_key(idx, s.lo, s.dims))).n_free += w
                    if visits != NULL:
                        visits.get(_pack(_box_key(idx, s.lo, s.dims))).n_free += 1
                n_visits += back.size()
                more = False
            else:
                # the region is closed under stepping toward the origin, so a
                # ray's cells in it form a prefix of its traversal
                while more and region.inside(walker.key(0), walker.key(1),
                                             walker.key(2)) and region.test(
                        walker.key(0), walker.key(1), walker.key(2)):
                    more = walker.next()
        while more:
            _count_free(walker.key(0), walker.key(1), walker.key(2), w, s.dense, s.lo,
                        s.dims, counts, touched, table)
            if visits != NULL:
                key[0] = <key_type>walker.key(0)
                key[1] = <key_type>walker.key(1)
                key[2] = <key_type>walker.key(2)
                visits.get(_pack(key)).n_free += 1
            n_visits += 1
            more = walker.next()
        if s.max_cells and touched.size() + (table.size() - table_base) > s.max_cells:
            stop.set()
            break
    traversed[0] += n_visits
    return 0


cdef inline void empty_stats(ScanStats* stats) noexcept nogil:
    """The statistics of a scan before (or without) its traversal, every clock now."""
    cdef int k
    stats.region_cells = -1
    stats.rays = 0
    stats.traversed_cells = 0
    stats.unnecessary = -1
    stats.bad_ends = 0
    stats.too_many = False
    for k in range(5):
        clock_gettime(CLOCK_MONOTONIC, &stats.clock[k])


cdef inline int scan_updates(
        OcTree* keys, const float[:, ::1] points, const point3d& o, double max_range,
        bint ray_mode, bint culling, const uint32_t* weights, int superray_threshold,
        FreeTest fully_free, void* map, vector[uint32_t]& counts, bint* counts_dirty,
        vector[ScanCell]& cells, ScanStats* stats, bint diagnose=False,
        uint64_t max_cells=0, int n_threads=1) except -1 nogil:
    """Collect one update per cell for a scan (appended to `cells`, keys distinct).

    Every ray is traversed as liboctomap's ``computeRayKeys`` traverses it
    (:cpp:class:`RayWalker`); the cells are collected with their counts (rays
    passing through, rays ending in) and each gets one update: in scan mode
    ``l_hit`` if any ray ends in it, else ``l_miss`` (liboctomap's
    ``insertPointCloud``); in ray mode ``n_free*l_miss + n_hit*l_hit``. With
    `culling`, the cells of the scan's culling region (:func:`_build_region`,
    using `fully_free` on `map`) are skipped: they are at the lower clamp and
    hold no end point, so their update is a no-op; rays are walked back from
    their end until they enter it. With `weights` (ray mode; NULL: none), ray
    i counts ``weights[i]`` times. With `superray_threshold` > 0 the rays are
    first grouped into super rays (:func:`_super_rays`) and one ray per class
    is traversed. `counts` is the caller's scratch array, zero between calls
    unless ``counts_dirty[0]`` (an exception left it dirty). When a ray's end
    (after truncation) lies outside the key range, ``stats.bad_ends`` counts
    them and nothing is collected. With `diagnose`
    (slow), ``stats.unnecessary`` counts the visits of the walked rays to cells
    whose update changes nothing: fully free cells that no ray ends in (the
    dissertation's "unnecessary traversals", Table 2.3). With `max_cells` > 0, a scan
    whose rays reach more than that many distinct cells sets ``stats.too_many`` and
    collects nothing (a lower bound on them is checked after each ray, so memory
    stays within one ray per thread of it plus the end cells; the exact count decides).

    The rays are walked on up to `n_threads` OpenMP threads (fewer for small scans;
    one with `diagnose`), each into its own counts: a slice of `counts` over the
    scan's key box (no more threads than slices fit the dense limit), or, where the
    box alone exceeds the limit, a table of its own. The counts are merged (integer sums) before the cells are collected,
    so the cells, their updates and the statistics are the same for every
    `n_threads`; only the order of `cells` may differ.
    """
    cdef Py_ssize_t i, n = points.shape[0]
    cdef bint weighted = weights != NULL
    cdef vector[uint32_t] ray_ids, ray_weights     # the rays to traverse, super rays
    cdef Py_ssize_t n_trav = n
    cdef vector[point3d] ends
    cdef vector[uint8_t] truncated
    cdef KeyTable table
    cdef CellBox region
    cdef OcTreeKey ko, key
    cdef KeyCounts* entry
    cdef int lo[3]
    cdef int hi[3]
    cdef int axis, max_level = 0, level
    cdef size_t slot, j
    cdef float l_hit = keys.getProbHitLog(), l_miss = keys.getProbMissLog()
    cdef vector[uint64_t] touched         # box indices with a nonzero count
    cdef uint64_t dims[3]
    cdef uint64_t idx, box_cells = 1
    cdef bint dense
    cdef uint32_t n_free
    cdef vector[OcTreeKey] end_keys
    cdef vector[uint8_t] end_ok
    cdef KeyTable visits                  # with diagnose: walked visits per cell
    cdef double res = keys.getResolution(), rf = 1.0 / res
    cdef ScanCell cell
    cdef _Rays rays
    cdef StopFlag stop
    cdef size_t hits
    cdef uint64_t distinct
    cdef uint32_t* part
    cdef Py_ssize_t c, n_chunks
    cdef int t
    cdef vector[vector[uint64_t]] part_touched    # threads 1, 2, ...: their new box cells
    cdef vector[KeyTable] part_tables             # and their other cells
    cdef vector[long] part_visits
    empty_stats(stats)
    keys.coordToKeyChecked(o, ko)
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
        end_ok[i] = (_key_checked(rf, ends[i].x(), &key[0])
                     and _key_checked(rf, ends[i].y(), &key[1])
                     and _key_checked(rf, ends[i].z(), &key[2]))
        if end_ok[i] and not (key == ko) and not _walkable(o, ends[i]):
            end_ok[i] = False   # a ray too short to walk: the caller reports it
        if not end_ok[i]:
            stats.bad_ends += 1
            continue
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
    clock_gettime(CLOCK_MONOTONIC, &stats.clock[1])
    if stats.bad_ends:
        return 0            # nothing changed: the caller reports the bad rows
    if superray_threshold > 0:
        _super_rays(res, o, ko, ends, end_keys, truncated, table, superray_threshold,
                    ray_ids, ray_weights)
        n_trav = ray_ids.size()
    clock_gettime(CLOCK_MONOTONIC, &stats.clock[2])
    if culling:
        stats.region_cells = _build_region(fully_free, map, ko, lo, hi, max_level, table,
                                              region)
    clock_gettime(CLOCK_MONOTONIC, &stats.clock[3])
    for axis in range(3):
        dims[axis] = <uint64_t>(hi[axis] - lo[axis] + 1)
        box_cells *= dims[axis]
    # threads: one with `diagnose`, and at least _MIN_THREAD_RAYS rays each
    if diagnose or n_threads < 1:
        n_threads = 1
    n_threads = min(n_threads, <int>_MAX_THREADS, <int>max(n_trav // _MIN_THREAD_RAYS, 1))
    # each thread's counts get their own slice of `counts`, within the dense limit:
    # no more threads than slices fit (counting in tables instead is several times
    # slower); a box larger than the limit is counted in tables by every thread
    dense = box_cells <= _MAX_DENSE_CELLS
    if dense:
        n_threads = <int>min(<uint64_t>n_threads, _MAX_DENSE_CELLS // box_cells)
    if dense and (counts_dirty[0] or counts.size() < box_cells * n_threads):
        counts.assign(max(box_cells * n_threads, counts.size()), 0)
    counts_dirty[0] = True
    rays.res = res
    rays.origin = &o
    rays.key_origin = &ko
    rays.ends = ends.data()
    rays.end_keys = end_keys.data()
    rays.end_ok = end_ok.data()
    rays.ray_ids = ray_ids.data() if superray_threshold > 0 else NULL
    rays.ray_weights = ray_weights.data() if superray_threshold > 0 else NULL
    rays.weights = weights if weighted else NULL
    rays.region = &region
    rays.cull = stats.region_cells > 0
    rays.dense = dense
    rays.lo = lo
    rays.dims = dims
    rays.max_cells = max_cells
    # thread 0 counts into the scan's own table (its first `hits` entries: the end
    # cells), the others into tables of their own
    hits = table.size()
    if n_threads == 1:
        _walk_rays(&rays, 0, n_trav, counts.data() if dense else NULL, &touched, &table,
                   hits, &visits if diagnose else NULL, &stats.traversed_cells, &stop)
    else:
        part_touched.resize(n_threads)
        part_tables.resize(n_threads - 1)
        part_visits.assign(n_threads, 0)
        n_chunks = min(n_trav, <Py_ssize_t>n_threads * _CHUNKS_PER_THREAD)
        for c in prange(n_chunks, num_threads=n_threads, schedule="dynamic"):
            t = threadid()
            _walk_rays(&rays, c * n_trav // n_chunks, (c + 1) * n_trav // n_chunks,
                       (counts.data() + <uint64_t>t * box_cells) if dense else NULL,
                       &touched if t == 0 else &part_touched[t],
                       &table if t == 0 else &part_tables[t - 1], hits if t == 0 else 0,
                       NULL, &part_visits[t], &stop)
        # merge into thread 0's counts (integer sums: the order does not matter),
        # leaving the other slices zero
        stats.traversed_cells += part_visits[0]
        for t in range(1, n_threads):
            if dense:
                part = counts.data() + <uint64_t>t * box_cells
                for j in range(part_touched[t].size()):
                    idx = part_touched[t][j]
                    if counts[idx] == 0:
                        touched.push_back(idx)
                    counts[idx] += part[idx]
                    part[idx] = 0
            if not stop.get():
                for slot in range(part_tables[t - 1].capacity()):
                    if part_tables[t - 1].slot(slot).key != KEY_EMPTY:
                        table.get(part_tables[t - 1].slot(slot).key).n_free += \
                            part_tables[t - 1].slot(slot).n_free
            stats.traversed_cells += part_visits[t]
    clock_gettime(CLOCK_MONOTONIC, &stats.clock[4])
    if stop.get():
        stats.too_many = True
    elif max_cells:
        # the distinct cells: those counted in the box, and the table's others
        distinct = touched.size() + table.size()
        if dense:
            for slot in range(table.capacity()):
                if table.slot(slot).key == KEY_EMPTY:
                    continue
                key = _unpack(table.slot(slot).key)
                if _in_box(key, lo, dims) and counts[_box_index(key, lo, dims)]:
                    distinct -= 1
        stats.too_many = distinct > max_cells
    if stats.too_many:
        for j in range(touched.size()):
            counts[touched[j]] = 0
        counts_dirty[0] = False
        return 0            # nothing changed: the caller reports it
    # one update per cell: the traversed cells, then end cells no ray crossed
    cells.reserve(touched.size() + table.size())
    for j in range(touched.size()):
        idx = touched[j]
        key = _box_key(idx, lo, dims)
        entry = table.find(_pack(key))
        cell.key = _pack(key)
        cell.update = _update_value(counts[idx],
                                    entry.n_hit if entry != NULL else 0,
                                    ray_mode, l_hit, l_miss)
        cells.push_back(cell)
    for slot in range(table.capacity()):
        if table.slot(slot).key == KEY_EMPTY:
            continue
        key = _unpack(table.slot(slot).key)
        n_free = table.slot(slot).n_free
        if dense and _in_box(key, lo, dims):
            if counts[_box_index(key, lo, dims)]:
                continue        # collected above
            n_free = 0
        cell.key = _pack(key)
        cell.update = _update_value(n_free, table.slot(slot).n_hit, ray_mode,
                                    l_hit, l_miss)
        cells.push_back(cell)
    for j in range(touched.size()):
        counts[touched[j]] = 0
    counts_dirty[0] = False
    stats.rays = n_trav
    if diagnose:
        stats.unnecessary = 0
        for slot in range(visits.capacity()):
            if visits.slot(slot).key == KEY_EMPTY:
                continue
            entry = table.find(visits.slot(slot).key)
            if ((entry == NULL or entry.n_hit == 0)
                    and fully_free(map, _unpack(visits.slot(slot).key))):
                stats.unnecessary += visits.slot(slot).n_free
    return 0
