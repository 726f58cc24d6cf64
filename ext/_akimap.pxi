# AKIMap's adaptive bandwidths (Kwon et al.; dissertation 3.3.3): included by
# ext/_kernel.pyx, whose tabulated sparse kernel (_kernel_r2) and cimports it uses.
#
# Per sample: the covariance of its same-label neighbours within a search radius that
# grows with the distance from the sensor, then the length-scale factor of Eq. 3.7
# (occgp's grid and golden-section minimiser, or the published code's gradient
# descent); the samples are computed on OpenMP threads, each by one thread.

cdef enum:
    _SCALE_GRID = 16        # occgp's minimiser: coarse grid of log-scales, then golden section
    _GOLDEN_ITERS = 24
    _GD_EPOCHS = 100        # the reference code's gradient descent
    _CANDIDATES = 256       # neighbour candidates tested at a time
cdef double _GD_TOLERANCE = 0.001
cdef double _GD_RATE = 0.01
cdef double _COV_NOISE = 0.001


cdef extern from * nogil:
    """
    #if defined(__SSE2__)
    #include <emmintrin.h>
    #endif
    /* The candidates t in [start, stop) of the samples `xs` (x, y, z each) within
       r2max (squared) of xi, as t - start into `inside` (in order); returns their
       number. Two at a time where SSE2 is there: each lane's sum of squares is
       the scalar one's, ((dx dx + dy dy) + dz dz), and "not above r2max" the same
       test. */
    static inline int occgp_in_ball(const double* xs, long start, long stop,
                                    const double* xi, double r2max, int* inside) {
        int n = 0;
        long t = start;
    #if defined(__SSE2__)
        const __m128d cx = _mm_set1_pd(xi[0]), cy = _mm_set1_pd(xi[1]);
        const __m128d cz = _mm_set1_pd(xi[2]), r = _mm_set1_pd(r2max);
        for (; t + 1 < stop; t += 2) {
            const double* p = xs + 3 * t;
            __m128d a = _mm_loadu_pd(p), b = _mm_loadu_pd(p + 2), c = _mm_loadu_pd(p + 4);
            __m128d dx = _mm_sub_pd(_mm_shuffle_pd(a, b, 2), cx);
            __m128d dy = _mm_sub_pd(_mm_shuffle_pd(a, c, 1), cy);
            __m128d dz = _mm_sub_pd(_mm_shuffle_pd(b, c, 2), cz);
            __m128d q = _mm_add_pd(_mm_add_pd(_mm_mul_pd(dx, dx), _mm_mul_pd(dy, dy)),
                                   _mm_mul_pd(dz, dz));
            int mask = _mm_movemask_pd(_mm_cmpngt_pd(q, r));
            inside[n] = (int)(t - start);
            n += mask & 1;
            inside[n] = (int)(t + 1 - start);
            n += (mask >> 1) & 1;
        }
    #endif
        for (; t < stop; ++t) {
            double d0 = xs[3 * t] - xi[0], d1 = xs[3 * t + 1] - xi[1];
            double d2 = xs[3 * t + 2] - xi[2];
            inside[n] = (int)(t - start);
            n += !(d0 * d0 + d1 * d1 + d2 * d2 > r2max);
        }
        return n;
    }
    """
    int _in_ball "occgp_in_ball" (const double* xs, long start, long stop,
                                  const double* xi, double r2max, int* inside)


cdef inline double _largest_eigenvalue(const double* s) noexcept nogil:
    """Largest eigenvalue of the symmetric 3x3 matrix s (row-major), in closed form
    (the trigonometric solution of the characteristic cubic)."""
    cdef double p1 = s[1] * s[1] + s[2] * s[2] + s[5] * s[5]
    cdef double q = (s[0] + s[4] + s[8]) / 3.0
    cdef double a = s[0] - q, b = s[4] - q, c = s[8] - q
    cdef double p2 = a * a + b * b + c * c + 2.0 * p1
    cdef double p, det, r
    if p2 <= 0.0:
        return q
    p = sqrt(p2 / 6.0)
    det = (a * (b * c - s[5] * s[5]) - s[1] * (s[1] * c - s[5] * s[2])
           + s[2] * (s[1] * s[5] - b * s[2])) / (p * p * p)
    r = 0.5 * det
    if r <= -1.0:
        return q + p            # phi = pi / 3: 2 p cos(pi / 3)
    if r >= 1.0:
        return q + 2.0 * p
    return q + 2.0 * p * cos(acos(r) / 3.0)


cdef inline double _scale_loss(const double* r2, const double* target, int m,
                               double c) noexcept nogil:
    """Eq. 3.7 over the neighbours inside the initial support, up to the factor
    |Sigma|^-1/2 / 2: c^-3 sum_j (t_j - k(r_j / c))^2, with H = c^2 Sigma."""
    cdef double e, total = 0.0, inv = 1.0 / (c * c)
    cdef int j
    for j in range(m):
        e = target[j] - _kernel_r2(_below_one(r2[j] * inv))
        total += e * e
    return total / (c * c * c)


cdef void _scale_loss4(const double* r2, const double* target, int m, const double* c,
                       double* out) noexcept nogil:
    """`_scale_loss` at the four scales c[0..3] (each sum in the same order: the same
    values), in one pass over the neighbours."""
    cdef double e0, e1, e2, e3, t
    cdef double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0
    cdef double i0 = 1.0 / (c[0] * c[0]), i1 = 1.0 / (c[1] * c[1])
    cdef double i2 = 1.0 / (c[2] * c[2]), i3 = 1.0 / (c[3] * c[3])
    cdef int j
    for j in range(m):
        t = target[j]
        e0 = t - _kernel_r2(_below_one(r2[j] * i0))
        e1 = t - _kernel_r2(_below_one(r2[j] * i1))
        e2 = t - _kernel_r2(_below_one(r2[j] * i2))
        e3 = t - _kernel_r2(_below_one(r2[j] * i3))
        s0 += e0 * e0
        s1 += e1 * e1
        s2 += e2 * e2
        s3 += e3 * e3
    out[0] = s0 / (c[0] * c[0] * c[0])
    out[1] = s1 / (c[1] * c[1] * c[1])
    out[2] = s2 / (c[2] * c[2] * c[2])
    out[3] = s3 / (c[3] * c[3] * c[3])


cdef double _scale_minimise(const double* r2, const double* target, int m,
                            double lo) noexcept nogil:
    """The length-scale factor c in [lo, 1] minimising Eq. 3.7: the best of a grid of
    _SCALE_GRID log-spaced values (1 included), refined by golden-section search
    between its grid neighbours (the loss need not be unimodal on [lo, 1])."""
    cdef double best_c, best
    cdef double step, a, b, x1, x2, f1, f2
    cdef double g = 0.6180339887498949
    cdef double grid[_SCALE_GRID]
    cdef double loss[_SCALE_GRID]
    cdef int j, best_j = _SCALE_GRID - 1
    step = log(lo) / (_SCALE_GRID - 1)
    # the grid's losses four at a time (c = lo, ..., the last one c = 1), then
    # compared from 1 on, in the grid's order
    for j in range(_SCALE_GRID - 1):
        grid[j] = exp(log(lo) - j * step) if j else lo
    grid[_SCALE_GRID - 1] = 1.0
    for j in range(0, _SCALE_GRID, 4):
        _scale_loss4(r2, target, m, grid + j, loss + j)
    best_c = 1.0
    best = loss[_SCALE_GRID - 1]
    for j in range(_SCALE_GRID - 1):
        if loss[j] < best:
            best, best_c, best_j = loss[j], grid[j], j
    # bracket [c_{j-1}, c_{j+1}] in log space
    a = log(lo) - (best_j - 1) * step if best_j > 0 else log(lo)
    b = log(lo) - (best_j + 1) * step if best_j < _SCALE_GRID - 1 else 0.0
    if b > 0.0:
        b = 0.0
    x1 = b - g * (b - a)
    x2 = a + g * (b - a)
    f1 = _scale_loss(r2, target, m, exp(x1))
    f2 = _scale_loss(r2, target, m, exp(x2))
    for j in range(_GOLDEN_ITERS):
        if f1 < f2:
            b, x2, f2 = x2, x1, f1
            x1 = b - g * (b - a)
            f1 = _scale_loss(r2, target, m, exp(x1))
        else:
            a, x1, f1 = x1, x2, f2
            x2 = a + g * (b - a)
            f2 = _scale_loss(r2, target, m, exp(x2))
    if f1 < best:
        best, best_c = f1, exp(x1)
    if f2 < best:
        best, best_c = f2, exp(x2)
    return best_c


cdef double _scale_descent(const double* r2, const double* target, int m, double lo,
                           double w0) noexcept nogil:
    """The published reference code's scale: gradient descent from c = 1 with step
    0.01 / epoch, at most 100 epochs, clamped to [lo, 1], stopping when the
    gradient, the loss or the step falls below 0.001. Its gradient is kept as
    published (the weight's derivative taken as -1.5 w / c)."""
    cdef double c = 1.0, r, rot, sn, cs, k, kg, err, w, wg, ksum, esum, grad, loss, new_c
    cdef int epoch, j
    for epoch in range(1, _GD_EPOCHS + 1):
        ksum = 0.0
        esum = 0.0
        for j in range(m):
            r = sqrt(r2[j]) / c
            rot = 2.0 * M_PI * r
            sn = sin(rot)
            cs = cos(rot)
            k = (2.0 + cs) * (1.0 - r) / 3.0 + sn / (2.0 * M_PI)
            if k < 0.0:
                k = 0.0
            kg = ((1.0 - r) * rot * sn / (3.0 * c) + (cs + 2.0) * r / (3.0 * c)
                  - r * cs / c)
            err = target[j] - k
            ksum += err * kg
            esum += err * err
        w = w0 / (c * c * c)
        wg = -1.5 * w / c
        grad = wg * esum - w * ksum
        loss = 0.5 * w * esum
        new_c = min(1.0, max(c - _GD_RATE * grad / epoch, lo))
        if fabs(grad) < _GD_TOLERANCE or fabs(loss) < _GD_TOLERANCE or \
                fabs(c - new_c) < _GD_TOLERANCE:
            break
        c = new_c
    return c


cdef inline void _set_bandwidth(const double* h, Py_ssize_t i, double* precision,
                                double* extent, double* weight) noexcept nogil:
    """Sample i's kernel from its bandwidth matrix h (symmetric positive definite, row
    major): precision h^-1, support half-extents sqrt(h_aa), weight |h|^-1/2."""
    cdef double inv[9]
    cdef double det
    cdef int a
    inv[0] = h[4] * h[8] - h[5] * h[7]
    inv[1] = h[2] * h[7] - h[1] * h[8]
    inv[2] = h[1] * h[5] - h[2] * h[4]
    inv[4] = h[0] * h[8] - h[2] * h[6]
    inv[5] = h[2] * h[3] - h[0] * h[5]
    inv[8] = h[0] * h[4] - h[1] * h[3]
    inv[3] = inv[1]
    inv[6] = inv[2]
    inv[7] = inv[5]
    det = h[0] * inv[0] + h[1] * inv[3] + h[2] * inv[6]
    for a in range(9):
        precision[9 * i + a] = inv[a] / det
    for a in range(3):
        extent[3 * i + a] = sqrt(h[4 * a])
    weight[i] = 1.0 / sqrt(det)


cdef inline long _floor_cube(double v) noexcept nogil:
    """floor(v) for |v| < 2^62 (the search cubes' coordinates stay within 2^53), by a
    cast, without the libm call."""
    cdef long t = <long>v
    return t - (<double>t > v)


cdef inline long _lower_bound(const int64_t* keys, long n, int64_t key) noexcept nogil:
    """Index of the first entry of the sorted array `keys` not below `key` (n if none)."""
    cdef long lo = 0, hi = n, mid
    while lo < hi:
        mid = (lo + hi) >> 1
        if keys[mid] < key:
            lo = mid + 1
        else:
            hi = mid
    return lo


cdef void _bandwidth_one(
        Py_ssize_t i, const double* x, const uint8_t* labels, const double* origin,
        double res, double radius_max, double max_range, bint published, double floor2,
        double cell, const int64_t* grid_lo, const int64_t* grid_dims,
        const int64_t* cell_keys, long n_cells, const int64_t* cell_start,
        const int64_t* cube_of, const int64_t* row_first,
        const double* xs_sorted, const uint8_t* labels_sorted, double* buf,
        double* precision, double* extent, double* weight, double* scale,
        int64_t* n_same) noexcept nogil:
    """Sample i's bandwidth: covariance of its same-label neighbours within the
    search radius, then the scale of Eq. 3.7 (see AKIMap._bandwidths). The
    neighbours are met cube by cube (z, then y, then x), in sample order within a
    cube: `xs_sorted` and `labels_sorted` hold the samples in that order, the
    samples of cube `cell_keys[s]` from `cell_start[s]` on. Sample i lies in cube
    `cube_of[i]`, and `row_first[9 s + 3 (dz + 1) + dy + 1]` is the first cube of
    `cell_keys` at or after the cube (x - 1, y + dy, z + dz) of cube s (x, y, z):
    where the search box stays within the 3 x 3 x 3 cubes about the sample's own
    (always, but for rounding), each row of cubes starts there."""
    cdef double xi[3]
    cdef double d[3]
    cdef double sig[9]
    cdef double inv[9]
    cdef double dist, radius, r2max, det, lo_scale, c, w0, q, lab_t
    cdef long cmin[3]
    cdef long cmax[3]
    cdef long own[3]
    cdef long cy, cz, first, last, target
    cdef int64_t key_own
    cdef bint near
    cdef int64_t t, row_key, start, stop
    cdef int inside[_CANDIDATES]
    cdef int n_in, s_in
    cdef uint8_t lab
    cdef int a, b, m = 0, same = 0, other = 0, k
    cdef uint8_t y = labels[i]
    cdef double* r2buf = buf
    for a in range(3):
        xi[a] = x[3 * i + a]
    dist = sqrt((xi[0] - origin[0]) ** 2 + (xi[1] - origin[1]) ** 2
                + (xi[2] - origin[2]) ** 2)
    # r(d) = min((R - res) / sensor_range * d + res, R), R from sensor_range on (so a
    # tiny sensor_range gives no 0 * inf); R where R < res (the formula dips below R)
    if dist >= max_range:
        radius = radius_max
    else:
        radius = min((radius_max - res) / max_range * dist + res, radius_max)
    if not radius >= min(radius_max, res):
        radius = min(radius_max, res)
    r2max = radius * radius
    for a in range(9):
        sig[a] = 0.0
    for a in range(3):
        cmin[a] = max(_floor_cube((xi[a] - radius) / cell) - <long>grid_lo[a], 0)
        cmax[a] = min(_floor_cube((xi[a] + radius) / cell) - <long>grid_lo[a],
                      <long>grid_dims[a] - 1)
    # the sample's own cube, from its key
    key_own = cell_keys[cube_of[i]]
    own[0] = <long>(key_own % grid_dims[0])
    own[1] = <long>((key_own // grid_dims[0]) % grid_dims[1])
    own[2] = <long>(key_own // (grid_dims[0] * grid_dims[1]))
    near = True
    for a in range(3):
        near = near and cmin[a] >= own[a] - 1 and cmax[a] <= own[a] + 1
    # pass 1: the neighbours (offsets and labels into buf, 4 doubles each) and the
    # scatter of the same-label ones about x_i. The cubes cmin[0] .. cmax[0] of a row
    # (cy, cz) have consecutive keys: their samples are one run of the sorted ones.
    for cz in range(cmin[2], cmax[2] + 1):
        for cy in range(cmin[1], cmax[1] + 1):
            if cmin[0] > cmax[0]:
                continue
            row_key = (cz * grid_dims[1] + cy) * grid_dims[0]
            target = row_key + cmin[0]
            if near:
                # the first cube at or after (own x - 1) of the row, then at most a
                # step to the first at or after cmin[0]: the lower bound of the keys
                first = row_first[9 * cube_of[i] + 3 * (cz - own[2] + 1) + cy - own[1] + 1]
                while first < n_cells and cell_keys[first] < target:
                    first += 1
            else:
                first = _lower_bound(cell_keys, n_cells, target)
            last = first
            while last < n_cells and cell_keys[last] <= row_key + cmax[0]:
                last += 1
            # in chunks: the candidates inside the ball picked without a branch, then
            # taken in order
            start = cell_start[first]
            while start < cell_start[last]:
                stop = min(start + _CANDIDATES, cell_start[last])
                n_in = _in_ball(xs_sorted, start, stop, xi, r2max, inside)
                for s_in in range(n_in):
                    t = start + inside[s_in]
                    for a in range(3):
                        d[a] = xs_sorted[3 * t + a] - xi[a]
                    lab = labels_sorted[t]
                    buf[4 * m] = d[0]
                    buf[4 * m + 1] = d[1]
                    buf[4 * m + 2] = d[2]
                    buf[4 * m + 3] = 1.0 if lab == y else 0.0
                    m += 1
                    if lab == y:
                        # the upper triangle (the lower one holds the same sums)
                        same += 1
                        sig[0] += d[0] * d[0]
                        sig[1] += d[0] * d[1]
                        sig[2] += d[0] * d[2]
                        sig[4] += d[1] * d[1]
                        sig[5] += d[1] * d[2]
                        sig[8] += d[2] * d[2]
                start = stop
    sig[3] = sig[1]
    sig[6] = sig[2]
    sig[7] = sig[5]
    n_same[i] = same
    if same <= 2:               # isotropic fallback: H = res^2 I (+ floor^2 I)
        for a in range(9):
            sig[a] = 0.0
        for a in range(3):
            sig[4 * a] = res * res + floor2
        _set_bandwidth(sig, i, precision, extent, weight)
        scale[i] = 1.0
        return
    for a in range(9):
        sig[a] /= (same - 2)
    for a in range(3):
        sig[4 * a] += _COV_NOISE
    inv[0] = sig[4] * sig[8] - sig[5] * sig[7]
    inv[1] = sig[2] * sig[7] - sig[1] * sig[8]
    inv[2] = sig[1] * sig[5] - sig[2] * sig[4]
    inv[4] = sig[0] * sig[8] - sig[2] * sig[6]
    inv[5] = sig[2] * sig[3] - sig[0] * sig[5]
    inv[8] = sig[0] * sig[4] - sig[1] * sig[3]
    det = sig[0] * inv[0] + sig[1] * (sig[5] * sig[6] - sig[3] * sig[8]) \
        + sig[2] * (sig[3] * sig[7] - sig[4] * sig[6])
    inv[3] = inv[1]
    inv[6] = inv[2]
    inv[7] = inv[5]
    for a in range(9):
        inv[a] /= det
    w0 = 1.0 / sqrt(det)
    lo_scale = res / sqrt(_largest_eigenvalue(sig))
    # pass 2: squared normalised distances under Sigma of the neighbours inside the
    # initial support, and their targets (Eq. 3.6): k(r_j) if same label, else 0
    k = 0
    for t in range(m):
        d[0] = buf[4 * t]
        d[1] = buf[4 * t + 1]
        d[2] = buf[4 * t + 2]
        q = (inv[0] * d[0] * d[0] + inv[4] * d[1] * d[1] + inv[8] * d[2] * d[2]
             + 2.0 * (inv[1] * d[0] * d[1] + inv[2] * d[0] * d[2] + inv[5] * d[1] * d[2]))
        # compact in place, without a branch: entry k <- (q, target), kept when q < 1
        # (k <= t, so nothing ahead is overwritten); the target k(r_j) times the
        # label 1 or 0 is k(r_j) or +0
        lab_t = buf[4 * t + 3]
        r2buf[2 * k] = q
        r2buf[2 * k + 1] = _kernel_r2(_below_one(q)) * lab_t
        other += (q < 1.0) & (lab_t == 0.0)
        k += q < 1.0
    c = 1.0
    if other > 0 and lo_scale < 1.0:
        # de-interleave (r2, target) pairs into two arrays after the k pairs
        for t in range(k):
            buf[2 * k + t] = r2buf[2 * t]
            buf[3 * k + t] = r2buf[2 * t + 1]
        if published:
            c = _scale_descent(buf + 2 * k, buf + 3 * k, k, lo_scale, w0)
        else:
            c = _scale_minimise(buf + 2 * k, buf + 3 * k, k, lo_scale)
    if floor2 > 0.0:            # H = c^2 Sigma + floor^2 I
        for a in range(9):
            sig[a] *= c * c
        for a in range(3):
            sig[4 * a] += floor2
        _set_bandwidth(sig, i, precision, extent, weight)
    else:
        for a in range(9):
            precision[9 * i + a] = inv[a] / (c * c)
        for a in range(3):
            extent[3 * i + a] = c * sqrt(sig[4 * a])
        weight[i] = w0 / (c * c * c)
    scale[i] = c


def _merge_search(const int64_t[::1] keys, queries, bint right):
    """np.searchsorted(keys, queries, side="right" if right else "left") for
    non-decreasing `queries` (keys sorted), by one merge of the two."""
    cdef const int64_t[::1] q = np.ascontiguousarray(queries, dtype=np.int64)
    cdef Py_ssize_t n = keys.shape[0], m = q.shape[0], j, k = 0
    out = np.empty(m, dtype=np.int64)
    cdef int64_t[::1] o = out
    with nogil:
        for j in range(m):
            if right:
                while k < n and keys[k] <= q[j]:
                    k += 1
            else:
                while k < n and keys[k] < q[j]:
                    k += 1
            o[j] = k
    return out


def _search_cubes(const double[:, ::1] samples, double cell):
    """The samples bucketed in cubes of edge `cell`, for the neighbour search:
    (order (the samples sorted by cube, z then y then x, stably), the occupied
    cubes' keys (sorted) and first positions in that order (one more: n), each
    sample's cube, the cubes' row starts (see _bandwidth_one), grid's lowest cube
    and size, pairs): `pairs` counts, for each sample, the samples in the 3 x 3 x 3
    cubes about its own (the work the search may do)."""
    cdef Py_ssize_t n = samples.shape[0]
    ck = np.floor(np.asarray(samples) / cell).astype(np.int64)
    lo = ck.min(axis=0)
    dims = ck.max(axis=0) - lo + 1
    ck -= lo
    flat = (ck[:, 2] * dims[1] + ck[:, 1]) * dims[0] + ck[:, 0]
    order = np.argsort(flat, kind="stable").astype(np.int64)
    # the occupied cubes, their first positions in that order and each sample's cube,
    # from the sorted keys' runs (what np.unique gives, without sorting them again)
    sorted_flat = flat[order]
    new = np.empty(n, dtype=bool)
    new[0] = True
    np.not_equal(sorted_flat[1:], sorted_flat[:-1], out=new[1:])
    start = np.flatnonzero(new)
    keys = sorted_flat[start]
    cube_of = np.empty(n, dtype=np.int64)
    cube_of[order] = np.cumsum(new) - 1
    counts = np.diff(np.append(start, n))
    start = np.append(start, n).astype(np.int64)
    d0, d1, d2 = (int(d) for d in dims)
    cx, cy, cz = keys % d0, (keys // d0) % d1, keys // (d0 * d1)
    row_first = np.empty((len(keys), 9), dtype=np.int64)
    near = np.zeros(len(keys), dtype=np.int64)
    for dz in (-1, 0, 1):
        for dy in (-1, 0, 1):
            row = (cz + dz) * d1 + (cy + dy)
            # the queries below grow with the keys (each is the key shifted by a
            # constant, give or take the clamps at the grid's x ends): searched by a
            # merge, as np.searchsorted finds them
            row_first[:, 3 * (dz + 1) + dy + 1] = _merge_search(keys, row * d0 + cx - 1,
                                                                False)
            # the samples of the row's cubes x - 1 .. x + 1 inside the grid
            inside = (cy + dy >= 0) & (cy + dy < d1) & (cz + dz >= 0) & (cz + dz < d2)
            first = _merge_search(keys, row * d0 + np.maximum(cx - 1, 0), False)
            last = _merge_search(keys, row * d0 + np.minimum(cx + 1, d0 - 1), True)
            near += np.where(inside, start[last] - start[first], 0)
    pairs = float(np.dot(counts, near))
    return (order, np.ascontiguousarray(keys, dtype=np.int64), start, cube_of,
            np.ascontiguousarray(row_first), np.ascontiguousarray(lo, dtype=np.int64),
            np.ascontiguousarray(dims, dtype=np.int64), pairs)


def _akimap_bandwidths(const double[:, ::1] samples, const uint8_t[::1] labels,
                       const double[::1] origin, double res, double radius_max,
                       double max_range, bint published, double floor, int n_threads,
                       double cell, double max_pairs):
    """(pairs, bandwidths): the (sample, candidate) pairs the neighbour search
    examines (for each sample, the samples in the 3 x 3 x 3 search cubes about its
    own), and, unless they are more than `max_pairs` (then None), per sample:
    precision (inverse bandwidth, (n, 3, 3)), support half-extents (n, 3), weight
    |H|^-1/2, the length-scale factor c (H = c^2 Sigma + floor^2 I) and the number
    of same-label samples in its search ball (itself included). The samples are
    bucketed in cubes of edge `cell` (at least `radius_max`; wider where they would
    span more than 2^20 cubes)."""
    cdef Py_ssize_t n = samples.shape[0], i
    if n == 0:
        return 0.0, (np.empty((0, 3, 3)), np.empty((0, 3)), np.empty(0), np.empty(0),
                     np.empty(0, dtype=np.int64))
    # samples bucketed in cubes of edge cell, the cubes sorted by key
    cell = max(cell, radius_max)
    order, keys, start, cube_of, row_first, lo, dims, pairs = _search_cubes(samples, cell)
    if pairs > max_pairs:
        return pairs, None
    precision = np.empty((n, 3, 3))
    extent = np.empty((n, 3))
    weight = np.empty(n)
    scale = np.empty(n)
    n_same = np.empty(n, dtype=np.int64)
    xs_sorted = np.ascontiguousarray(np.asarray(samples)[order])
    labels_sorted = np.ascontiguousarray(np.asarray(labels)[order])
    cdef const int64_t[::1] lo_v = lo, dims_v = dims, keys_v = keys, start_v = start
    cdef const int64_t[::1] cube_v = cube_of
    cdef const int64_t[:, ::1] first_v = row_first
    cdef const double[:, ::1] xs_v = xs_sorted
    cdef const uint8_t[::1] lab_v = labels_sorted
    cdef double[:, :, ::1] p_v = precision
    cdef double[:, ::1] e_v = extent
    cdef double[::1] w_v = weight, s_v = scale
    cdef int64_t[::1] n_v = n_same
    cdef long n_cells = keys.shape[0]
    n_threads = max(n_threads, 1)
    scratch = np.empty((n_threads, 4 * n))   # per thread: a sample's neighbours
    cdef double[:, ::1] buf = scratch
    with nogil:
        for i in prange(n, schedule="dynamic", chunksize=64, num_threads=n_threads):
            _bandwidth_one(i, &samples[0, 0], &labels[0], &origin[0], res, radius_max,
                           max_range, published, floor * floor, cell, &lo_v[0], &dims_v[0],
                           &keys_v[0], n_cells, &start_v[0], &cube_v[0], &first_v[0, 0],
                           &xs_v[0, 0], &lab_v[0], &buf[threadid(), 0],
                           &p_v[0, 0, 0], &e_v[0, 0], &w_v[0], &s_v[0], &n_v[0])
    return pairs, (precision, extent, weight, scale, n_same)
