# cython: language_level=3
"""Integral kernels between points and line segments (compiled core of occgp.gp).

An observation is a point (length 0) or a segment ``A + t (B - A)``, t in [0, 1];
its covariance with another observation is the kernel integrated over arc
length on each segment (O'Callaghan & Ramos). Kernels are ``variance * f(s)``
with ``s`` the squared distance scaled by the length scales; this module works
in scaled ("warped") coordinates and returns the matrix divided by the
variance, plus, on request, the gradient with respect to each log length scale
(``-2 f'(s) * q_d ** 2`` integrated, ``q`` the scaled difference).

* point-point: ``f(s)``;
* segment-point: a closed form through erf for the squared exponential
  (moments of a truncated Gaussian for the gradient; a 5-point Gauss-Legendre
  rule on segments shorter than 0.25 length scales, where the closed form would
  cancel), and for the other kernels a quadrature split at the closest point of
  the segment (where their profile has a kink) and clipped to the support;
* segment-segment: the shorter segment's quadrature of the segment-point
  integral over the other one, split at the closest approach for the kernels
  that are not smooth.

The quadrature rule of a piece of scaled length L is the lowest tabulated order
whose calibrated reach is at least L (composite panels of the highest order
beyond): the adaptive order of the GPOMIK paper. Rows are distributed over
OpenMP threads; every entry is computed by one thread in a fixed order, so the
result does not depend on the number of threads.
"""

from cython.parallel cimport prange
from libc.math cimport exp, sqrt, erf, erfc, cos, sin, ceil, M_PI, INFINITY

import numpy as np

cdef enum:
    MAXD = 3
    KIND_SE = 0
    KIND_MATERN32 = 1
    KIND_SPARSE = 2

cdef double SQRT3 = sqrt(3.0)
cdef double TWO_PI = 2.0 * M_PI
cdef double SQRT_HALF = sqrt(0.5)
cdef double SQRT_HALF_PI = sqrt(0.5 * M_PI)

# 5-point Gauss-Legendre on [0, 1]
cdef double GL5_X[5]
cdef double GL5_W[5]
GL5_X[:] = [0.04691007703066800, 0.23076534494715845, 0.5,
            0.76923465505284155, 0.95308992296933200]
GL5_W[:] = [0.11846344252809454, 0.23931433524968324, 0.28444444444444444,
            0.23931433524968324, 0.11846344252809454]


cdef struct Rule:
    const double* nodes      # all orders, concatenated; nodes on [0, 1]
    const double* weights    # matching weights, summing to 1 per order
    const Py_ssize_t* offsets  # n_orders + 1
    const double* reach      # scaled length each order integrates to tolerance
    Py_ssize_t n_orders


cdef struct Kern:
    int kind
    int dim
    double cutoff2
    bint grad


# ----------------------------------------------------------------- profiles
cdef inline double _profile(int kind, double s) noexcept nogil:
    cdef double r, e
    if kind == KIND_SE:
        return exp(-0.5 * s)
    r = sqrt(s)
    if kind == KIND_MATERN32:
        e = SQRT3 * r
        return (1.0 + e) * exp(-e)
    if r >= 1.0:
        return 0.0
    return (2.0 + cos(TWO_PI * r)) / 3.0 * (1.0 - r) + sin(TWO_PI * r) / TWO_PI


cdef inline double _gfactor(int kind, double s) noexcept nogil:
    """-2 f'(s): the weight of q_d**2 in the derivative by log l_d."""
    cdef double r
    if kind == KIND_SE:
        return exp(-0.5 * s)
    r = sqrt(s)
    if kind == KIND_MATERN32:
        return 3.0 * exp(-SQRT3 * r)
    if r >= 1.0:
        return 0.0
    if r < 1e-4:
        return 4.0 * M_PI * M_PI / 3.0
    return ((TWO_PI / 3.0) * sin(TWO_PI * r) * (1.0 - r)
            - (2.0 / 3.0) * (cos(TWO_PI * r) - 1.0)) / r


# ------------------------------------------------------------- quadrature
cdef inline void _add_node(const Kern* k, const double* c, const double* v, double t,
                           double w, double* acc) noexcept nogil:
    """acc += w * (f(s), gfac(s) q_d^2) at q = c + t v."""
    cdef double q[MAXD]
    cdef double s = 0.0, g
    cdef int d
    for d in range(k.dim):
        q[d] = c[d] + t * v[d]
        s = s + q[d] * q[d]
    if s > k.cutoff2:
        return
    acc[0] += w * _profile(k.kind, s)
    if k.grad:
        g = w * _gfactor(k.kind, s)
        for d in range(k.dim):
            acc[1 + d] += g * q[d] * q[d]


cdef inline Py_ssize_t _pick_order(const Rule* rule, double scaled_len,
                                   Py_ssize_t* n_panels) noexcept nogil:
    """The lowest order whose reach covers `scaled_len`; panels of the highest beyond."""
    cdef Py_ssize_t o = 0
    while o < rule.n_orders - 1 and rule.reach[o] < scaled_len:
        o += 1
    n_panels[0] = 1
    if rule.reach[o] < scaled_len:
        n_panels[0] = <Py_ssize_t>ceil(scaled_len / rule.reach[o])
    return o


cdef inline void _quad_piece(const Kern* k, const Rule* rule, const double* c,
                             const double* v, double t0, double t1, double scaled_len,
                             double* acc) noexcept nogil:
    """Integrate over t in [t0, t1] (a piece of scaled length `scaled_len`)."""
    cdef Py_ssize_t o, i, p, n_panels, lo, hi
    cdef double width, h
    if t1 <= t0:
        return
    o = _pick_order(rule, scaled_len, &n_panels)
    lo = rule.offsets[o]
    hi = rule.offsets[o + 1]
    width = (t1 - t0) / n_panels
    for p in range(n_panels):
        h = t0 + p * width
        for i in range(lo, hi):
            _add_node(k, c, v, h + width * rule.nodes[i], width * rule.weights[i], acc)


cdef inline double _clip01(double t) noexcept nogil:
    return 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)


cdef void _segment_point(const Kern* k, const Rule* rule, const double* c,
                         const double* v, double* acc) noexcept nogil:
    """acc += integral over t in [0, 1] of (f, gradient terms) at q = c + t v.

    c = (A - x) / l, v = (B - A) / l, both scaled. The arc-length factor is
    applied by the caller.
    """
    cdef double a = 0.0, b = 0.0, e = 0.0, m, dperp2, L, sq, zlo, zhi, G, diff
    cdef double M0, g0, g1, Iu, Iu2, h, lo, hi, half
    cdef int d, i
    for d in range(k.dim):
        a += v[d] * v[d]
        b += c[d] * v[d]
        e += c[d] * c[d]
    if a <= 0.0:  # a point: callers never pass one, but stay correct
        _add_node(k, c, v, 0.0, 1.0, acc)
        return
    m = -b / a
    # squared scaled distance from x to the closest point of the segment
    h = _clip01(m)
    dperp2 = e + 2.0 * b * h + a * h * h
    if dperp2 > k.cutoff2:
        return
    L = sqrt(a)
    if k.kind == KIND_SE and L >= 0.25:
        dperp2 = e - b * b / a
        if dperp2 < 0.0:
            dperp2 = 0.0
        sq = SQRT_HALF * L
        zlo = -sq * m
        zhi = sq * (1.0 - m)
        if zlo >= 0.0:
            diff = erfc(zlo) - erfc(zhi)
        elif zhi <= 0.0:
            diff = erfc(-zhi) - erfc(-zlo)
        else:
            diff = erf(zhi) - erf(zlo)
        G = exp(-0.5 * dperp2)
        M0 = G * (SQRT_HALF_PI / L) * diff
        acc[0] += M0
        if k.grad:
            # q_d(t) = h_d + u v_d with u = t - m and h the foot of x on the line
            g0 = exp(-0.5 * e)
            g1 = exp(-0.5 * (e + 2.0 * b + a))
            Iu = (g0 - g1) / a                                  # int u g
            Iu2 = (-(1.0 - m) * g1 - m * g0 + M0) / a           # int u^2 g
            for d in range(k.dim):
                h = c[d] + m * v[d]
                acc[1 + d] += h * h * M0 + 2.0 * h * v[d] * Iu + v[d] * v[d] * Iu2
        return
    if k.kind == KIND_SE:
        for i in range(5):
            _add_node(k, c, v, GL5_X[i], GL5_W[i], acc)
        return
    lo = 0.0
    hi = 1.0
    if k.kind == KIND_SPARSE:
        dperp2 = e - b * b / a
        if dperp2 >= 1.0:
            return
        half = sqrt((1.0 - dperp2) / a)
        lo = _clip01(m - half)
        hi = _clip01(m + half)
    if lo < m < hi:
        _quad_piece(k, rule, c, v, lo, m, L * (m - lo), acc)
        _quad_piece(k, rule, c, v, m, hi, L * (hi - m), acc)
    else:
        _quad_piece(k, rule, c, v, lo, hi, L * (hi - lo), acc)


cdef double _closest_param(const double* p, const double* u, const double* q,
                           const double* w, int dim, double* dist2) noexcept nogil:
    """Parameter s in [0, 1] of the point of segment p + s u closest to segment q + t w.

    Also stores the squared distance between the two segments in dist2.
    """
    cdef double r[MAXD]
    cdef double a = 0.0, e = 0.0, b = 0.0, c = 0.0, f = 0.0, den, s, t, x
    cdef int d
    for d in range(dim):
        r[d] = p[d] - q[d]
        a += u[d] * u[d]
        e += w[d] * w[d]
        b += u[d] * w[d]
        c += u[d] * r[d]
        f += w[d] * r[d]
    den = a * e - b * b
    if den > 1e-14 * a * e:
        s = _clip01((b * f - c * e) / den)
    else:  # parallel: any point does
        s = 0.0
    t = (b * s + f) / e
    if t < 0.0:
        t = 0.0
        s = _clip01(-c / a)
    elif t > 1.0:
        t = 1.0
        s = _clip01((b - c) / a)
    dist2[0] = 0.0
    for d in range(dim):
        x = r[d] + s * u[d] - t * w[d]
        dist2[0] += x * x
    return s


cdef inline void _add_roots(double qa, double qb, double qc, double* cuts,
                            int* n) noexcept nogil:
    """Append the roots in (0, 1) of qa t^2 + 2 qb t + qc = 0 to cuts."""
    cdef double disc, r, t
    cdef int sgn
    if qa <= 0.0:
        return
    disc = qb * qb - qa * qc
    if disc <= 0.0:
        return
    r = sqrt(disc)
    for sgn in range(2):
        t = (-qb - r) / qa if sgn == 0 else (-qb + r) / qa
        if 0.0 < t < 1.0:
            cuts[n[0]] = t
            n[0] += 1


cdef int _outer_cuts(const Kern* k, const double* Ao, const double* vo, const double* Ai,
                     const double* vi, double ts, double* cuts) noexcept nogil:
    """Break points in (0, 1) of the outer integrand, sorted, framed by 0 and 1.

    The closest approach `ts` for the kernels with a kink at distance 0; for the
    sparse kernel also where the outer point's distance to the inner segment
    crosses the support radius 1 (its distance to either end point or to the
    inner line equals 1), where the inner integral loses smoothness.
    """
    cdef int n = 1, d, i, j
    cdef double r0[MAXD]
    cdef double w0[MAXD]
    cdef double w1[MAXD]
    cdef double a = 0.0, b = 0.0, c = 0.0, e = 0.0, p0 = 0.0, p1 = 0.0, x
    cuts[0] = 0.0
    if k.kind == KIND_SE:
        cuts[1] = 1.0
        return 1
    if 0.0 < ts < 1.0:
        cuts[n] = ts
        n += 1
    if k.kind == KIND_SPARSE:
        for d in range(k.dim):
            r0[d] = Ao[d] - Ai[d]
            a += vo[d] * vo[d]
            b += vo[d] * r0[d]
            c += r0[d] * r0[d]
            e += vi[d] * vi[d]
        _add_roots(a, b, c - 1.0, cuts, &n)                       # |p - Ai| = 1
        b = 0.0
        c = 0.0
        for d in range(k.dim):
            b += vo[d] * (r0[d] - vi[d])
            c += (r0[d] - vi[d]) * (r0[d] - vi[d])
        _add_roots(a, b, c - 1.0, cuts, &n)                       # |p - Bi| = 1
        for d in range(k.dim):                                    # distance to the line
            p0 += r0[d] * vi[d]
            p1 += vo[d] * vi[d]
        for d in range(k.dim):
            w0[d] = r0[d] - p0 / e * vi[d]
            w1[d] = vo[d] - p1 / e * vi[d]
        a = 0.0
        b = 0.0
        c = 0.0
        for d in range(k.dim):
            a += w1[d] * w1[d]
            b += w0[d] * w1[d]
            c += w0[d] * w0[d]
        _add_roots(a, b, c - 1.0, cuts, &n)
    for i in range(2, n):                                         # insertion sort
        x = cuts[i]
        j = i - 1
        while j >= 1 and cuts[j] > x:
            cuts[j + 1] = cuts[j]
            j -= 1
        cuts[j + 1] = x
    cuts[n] = 1.0
    return n


cdef void _segment_segment(const Kern* k, const Rule* rule, const double* Ao,
                           const double* vo, const double* Ai, const double* vi,
                           double* acc) noexcept nogil:
    """acc += double integral (t, t' in [0, 1]) over outer segment o and inner segment i.

    Ao, vo, Ai, vi are scaled start points and directions.
    """
    cdef double c[MAXD]
    cdef double tmp[1 + MAXD]
    cdef double cuts[10]
    cdef double dist2, ts, Lo = 0.0, width, h, t, w, t0, t1
    cdef Py_ssize_t o, n_panels, lo, hi, i, p
    cdef int d, piece, n_pieces
    for d in range(k.dim):
        Lo += vo[d] * vo[d]
    Lo = sqrt(Lo)
    ts = _closest_param(Ao, vo, Ai, vi, k.dim, &dist2)
    if dist2 > k.cutoff2:
        return
    n_pieces = _outer_cuts(k, Ao, vo, Ai, vi, ts, cuts)
    for piece in range(n_pieces):
        t0 = cuts[piece]
        t1 = cuts[piece + 1]
        if t1 <= t0:
            continue
        o = _pick_order(rule, Lo * (t1 - t0), &n_panels)
        lo = rule.offsets[o]
        hi = rule.offsets[o + 1]
        width = (t1 - t0) / n_panels
        for p in range(n_panels):
            h = t0 + p * width
            for i in range(lo, hi):
                t = h + width * rule.nodes[i]
                w = width * rule.weights[i]
                for d in range(k.dim):
                    c[d] = Ai[d] - (Ao[d] + t * vo[d])
                    tmp[d + 1] = 0.0
                tmp[0] = 0.0
                _segment_point(k, rule, c, vi, tmp)
                acc[0] += w * tmp[0]
                if k.grad:
                    for d in range(k.dim):
                        acc[1 + d] += w * tmp[1 + d]


cdef bint _outer_first(const double* A1, const double* v1, double len1, const double* A2,
                       const double* v2, double len2, int dim) noexcept nogil:
    """Whether observation 1 is the outer segment of the pair (the shorter one).

    Ties are broken on the coordinates, so that the choice depends on the pair
    only, not on its order: K[i, j] and K[j, i] are the same number.
    """
    cdef double s1 = 0.0, s2 = 0.0
    cdef int d
    for d in range(dim):
        s1 += v1[d] * v1[d]
        s2 += v2[d] * v2[d]
    if s1 != s2:
        return s1 < s2
    for d in range(dim):
        if A1[d] != A2[d]:
            return A1[d] < A2[d]
    for d in range(dim):
        if v1[d] != v2[d]:
            return v1[d] < v2[d]
    return True


cdef void _entry(const Kern* k, const Rule* rule, const double* A1, const double* v1,
                 double len1, const double* A2, const double* v2, double len2,
                 double* acc) noexcept nogil:
    """acc = (covariance / variance, gradient terms) of observations 1 and 2."""
    cdef double c[MAXD]
    cdef double s = 0.0, scale
    cdef int d
    for d in range(1 + k.dim):
        acc[d] = 0.0
    if len1 == 0.0 and len2 == 0.0:
        for d in range(k.dim):
            c[d] = A1[d] - A2[d]
        _add_node(k, c, v1, 0.0, 1.0, acc)
        return
    if len1 == 0.0 or len2 == 0.0:
        if len1 == 0.0:
            for d in range(k.dim):
                c[d] = A2[d] - A1[d]
            _segment_point(k, rule, c, v2, acc)
            scale = len2
        else:
            for d in range(k.dim):
                c[d] = A1[d] - A2[d]
            _segment_point(k, rule, c, v1, acc)
            scale = len1
    else:
        if _outer_first(A1, v1, len1, A2, v2, len2, k.dim):
            _segment_segment(k, rule, A1, v1, A2, v2, acc)
        else:
            _segment_segment(k, rule, A2, v2, A1, v1, acc)
        scale = len1 * len2
    for d in range(1 + k.dim):
        acc[d] *= scale


cdef void _row(const Kern* k, const Rule* rule, Py_ssize_t i,
               const double[:, ::1] A1, const double[:, ::1] V1, const double[::1] len1,
               const double[:, ::1] A2, const double[:, ::1] V2, const double[::1] len2,
               bint same, double[:, ::1] out, double[:, :, ::1] grad) noexcept nogil:
    cdef double acc[1 + MAXD]
    cdef Py_ssize_t j, j0 = i if same else 0
    cdef int d
    for j in range(j0, A2.shape[0]):
        _entry(k, rule, &A1[i, 0], &V1[i, 0], len1[i], &A2[j, 0], &V2[j, 0], len2[j], acc)
        out[i, j] = acc[0]
        if same:
            out[j, i] = acc[0]
        if k.grad:
            for d in range(k.dim):
                grad[d, i, j] = acc[1 + d]
                if same:
                    grad[d, j, i] = acc[1 + d]


def observation_covariance(int kind, double cutoff2, const double[:, ::1] A1, const double[:, ::1] V1,
                           const double[::1] len1, const double[:, ::1] A2,
                           const double[:, ::1] V2, const double[::1] len2, bint same,
                           const double[::1] nodes, const double[::1] weights,
                           const Py_ssize_t[::1] offsets, const double[::1] reach,
                           double[:, ::1] out, double[:, :, ::1] grad, int n_threads):
    """Fill `out` (n1, n2) with the covariances / variance; `grad` (dim, n1, n2) if not None.

    A and V are scaled start points and scaled directions (B - A) / l; len the
    arc lengths in metres (0 for points). With `same` the two sets are one and
    only the upper triangle is computed, then mirrored.
    """
    cdef Kern k
    cdef Rule rule
    cdef Py_ssize_t i, n1 = A1.shape[0]
    cdef int d, dim = A1.shape[1]
    if not 1 <= dim <= MAXD:
        raise ValueError(f"inputs must have 1 to {MAXD} dimensions, got {dim}")
    k.kind = kind
    k.dim = dim
    k.cutoff2 = cutoff2
    k.grad = grad is not None
    rule.nodes = &nodes[0]
    rule.weights = &weights[0]
    rule.offsets = &offsets[0]
    rule.reach = &reach[0]
    rule.n_orders = reach.shape[0]
    if n1 == 0 or A2.shape[0] == 0:
        return
    with nogil:
        for i in prange(n1, schedule="dynamic", num_threads=n_threads):
            _row(&k, &rule, i, A1, V1, len1, A2, V2, len2, same, out, grad)


cdef void _tile(const Kern* k, const Rule* rule, Py_ssize_t t, const double[:, ::1] X,
                const double[:, ::1] A2, const double[:, ::1] V2, const double[::1] len2,
                const Py_ssize_t[::1] rows, const Py_ssize_t[::1] row_ptr,
                const Py_ssize_t[::1] cols, const Py_ssize_t[::1] col_ptr,
                const Py_ssize_t[::1] out_ptr, double[::1] out) noexcept nogil:
    cdef double acc[1 + MAXD]
    cdef double zero[MAXD]
    cdef Py_ssize_t a, b, i, j, n_cols = col_ptr[t + 1] - col_ptr[t]
    cdef Py_ssize_t base = out_ptr[t]
    cdef int d
    for d in range(MAXD):
        zero[d] = 0.0
    for a in range(row_ptr[t + 1] - row_ptr[t]):
        i = rows[row_ptr[t] + a]
        for b in range(n_cols):
            j = cols[col_ptr[t] + b]
            _entry(k, rule, &X[i, 0], zero, 0.0, &A2[j, 0], &V2[j, 0], len2[j], acc)
            out[base + a * n_cols + b] = acc[0]


def tile_covariance(int kind, double cutoff2, const double[:, ::1] X,
                    const double[:, ::1] A2, const double[:, ::1] V2, const double[::1] len2,
                    const Py_ssize_t[::1] rows, const Py_ssize_t[::1] row_ptr,
                    const Py_ssize_t[::1] cols, const Py_ssize_t[::1] col_ptr,
                    const Py_ssize_t[::1] out_ptr, const double[::1] nodes,
                    const double[::1] weights, const Py_ssize_t[::1] offsets,
                    const double[::1] reach, double[::1] out, int n_threads):
    """Covariances / variance between query points and observations, tile by tile.

    Tile t pairs the scaled queries ``X[rows[row_ptr[t]:row_ptr[t+1]]]`` with the
    observations ``cols[col_ptr[t]:col_ptr[t+1]]``; its block, row-major, is
    stored in ``out`` from ``out_ptr[t]``. One parallel region for all tiles.
    """
    cdef Kern k
    cdef Rule rule
    cdef Py_ssize_t t, n_tiles = row_ptr.shape[0] - 1
    cdef int dim = X.shape[1]
    if not 1 <= dim <= MAXD or A2.shape[1] != dim:
        raise ValueError(f"inputs must have 1 to {MAXD} matching dimensions")
    k.kind = kind
    k.dim = dim
    k.cutoff2 = cutoff2
    k.grad = False
    rule.nodes = &nodes[0]
    rule.weights = &weights[0]
    rule.offsets = &offsets[0]
    rule.reach = &reach[0]
    rule.n_orders = reach.shape[0]
    if n_tiles <= 0:
        return
    with nogil:
        for t in prange(n_tiles, schedule="dynamic", num_threads=n_threads):
            _tile(&k, &rule, t, X, A2, V2, len2, rows, row_ptr, cols, col_ptr, out_ptr, out)
