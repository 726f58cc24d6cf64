# cython: language_level=3
# distutils: language = c++
"""Compiled core of the kernel-inference maps (:mod:`occgp.kernel`): Beta posteriors on cells.

Every cell of edge ``resolution`` holds the evidence of the samples whose kernel
support reaches its centre: alpha (occupied) and beta (free), the prior not
included. A sample at x with label y in [0, 1], support ellipsoid
``{c : (c - x)^T P (c - x) < 1}`` (P the inverse of the bandwidth matrix H) and
weight w adds ``w k(r) y`` to alpha and ``w k(r) (1 - y)`` to beta of every cell
whose centre c lies inside, with ``r = sqrt((c - x)^T P (c - x))`` and k the
sparse kernel of Melkumyan and Ramos (times ``sf2``; tabulated in r^2, within
3e-8 of the formula). Cells are keyed like liboctomap's: ``floor(x / resolution)
+ 32768`` per axis, centre ``(key - 32768 + 0.5) * resolution``, and stored in
hashed blocks of 4 x 4 x 4 cells with float32 alpha and beta (``_beta_blocks.h``).

AKIMap's bandwidths (:func:`_akimap_bandwidths`, ``ext/_akimap.pxi``) are
computed per sample on OpenMP threads. An update's evidence is summed in double
precision tile by tile (dense cubes of 64 x 64 x 64 cells of its key box; only
the tiles that some sample's support box meets), the tiles shared among the
threads (every cell is summed by one thread, in sample order: the map does not
depend on the number of threads, nor on where the tiles cut the supports), then
added to the blocks once per cell.

Nothing here validates user input: :mod:`occgp.kernel` checks every array first.
The loops run without the GIL; a per-map lock serialises operations on one map.
"""

cimport cython
from cython.operator cimport dereference as deref, preincrement as inc
from cython.parallel cimport prange, threadid
from libc.math cimport M_PI, acos, ceil, cos, exp, fabs, floor, isnan, log, sin, sqrt
from libc.stdint cimport int32_t, int64_t, uint8_t, uint16_t, uint32_t, uint64_t
from libc.string cimport memset
from libcpp.mutex cimport mutex
from libcpp.vector cimport vector

import threading

import numpy as np

cdef enum:
    _MAX_VAL = 32768        # half the number of keys per axis, as liboctomap's 16-bit keys
    _TILE = 64              # an update accumulates tile by tile, 64 x 64 x 64 cells
    _TILE_BRICKS = 4096     # (_TILE / 4)^3 bricks of 4 x 4 x 4 cells a tile
    _MAX_PAIRS = 1 << 22    # (tile, sample) pairs sorted at a time


cdef extern from "_beta_blocks.h" namespace "occgp" nogil:
    cdef cppclass BetaBlock:      # 4 x 4 x 4 cells: reached-mask, float alpha, float beta
        uint64_t mask
        float alpha[64]
        float beta[64]

    cdef cppclass BlockSlot:
        uint64_t key
        uint64_t index

    cdef cppclass BetaBlocks:
        void clear() except +
        void prefetch_index(uint64_t bkey)
        size_t get_index(uint64_t bkey) except +
        BetaBlock* block(size_t i)
        const BetaBlock* find(uint64_t bkey)
        void add(long kx, long ky, long kz, float alpha, float beta) except +
        size_t num_cells()
        void add_cells(size_t n)
        size_t index_capacity()
        const BlockSlot& index_slot(size_t i)
        size_t memory_bytes()

    const uint64_t EMPTY_KEY "occgp::kEmptyKey"


cdef extern from * nogil:
    void __builtin_prefetch(const void* address, int rw, int locality)


cdef extern from * nogil:
    """
    #include <mutex>
    /* out[j] = the block of keys[j] (created empty when absent) for j < n, under
       `lock`, fetching the index slots a few keys ahead and each block's mask and
       first cells; false (out undefined) when a block could not be made */
    static bool occgp_blocks_locked(occgp::BetaBlocks* cells, std::mutex* lock,
                                    const uint64_t* keys, occgp::BetaBlock** out,
                                    size_t n) {
        const size_t ahead = 8;
        try {
            std::lock_guard<std::mutex> guard(*lock);
            for (size_t j = 0; j < n && j < ahead; ++j) cells->prefetch_index(keys[j]);
            for (size_t j = 0; j < n; ++j) {
                if (j + ahead < n) cells->prefetch_index(keys[j + ahead]);
                out[j] = cells->get(keys[j]);
                __builtin_prefetch(out[j], 1, 3);
            }
            return true;
        } catch (...) {
            return false;
        }
    }
    """
    bint _blocks_locked "occgp_blocks_locked" (BetaBlocks* cells, mutex* lock,
                                               const uint64_t* keys, BetaBlock** out,
                                               size_t n)


cdef extern from * nogil:
    """
    #if defined(__SSE2__)
    #include <emmintrin.h>
    /* x where x < 1, else 1 (NaN too), by one minsd: a comparison the compiler can
       neither split into branches nor fold the constant 1 through */
    static inline double occgp_below_one(double x) {
        return _mm_cvtsd_f64(_mm_min_sd(_mm_set_sd(x), _mm_set_sd(1.0)));
    }
    /* x where x < t, else t (NaN too) */
    static inline double occgp_below(double x, double t) {
        return _mm_cvtsd_f64(_mm_min_sd(_mm_set_sd(x), _mm_set_sd(t)));
    }
    /* table[2 j] + (x - j) table[2 j + 1], j = (int)x (truncated): the conversions
       packed, which write their whole register (the scalar cvtsi2sd would wait for
       the previous value of its register) */
    static inline double occgp_interpolate(const double* table, double x) {
        __m128i ji = _mm_cvttpd_epi32(_mm_set_sd(x));
        const double* e = table + 2 * (long)_mm_cvtsi128_si32(ji);
        return e[0] + (x - _mm_cvtsd_f64(_mm_cvtepi32_pd(ji))) * e[1];
    }
    /* sqrt(x) for x > 0, else 0 (NaN too): one sqrtsd, without libm's errno path */
    static inline double occgp_sqrt_positive(double x) {
        __m128d v = _mm_max_sd(_mm_set_sd(x), _mm_setzero_pd());
        return _mm_cvtsd_f64(_mm_sqrt_sd(v, v));
    }
    /* out[j] = occgp_sqrt_positive(x[j]) for j < n, two at a time (sqrtpd rounds
       each lane as sqrtsd does: the same values, in half the square roots) */
    static inline void occgp_sqrt_positive_n(const double* x, double* out, int n) {
        int j = 0;
        for (; j + 1 < n; j += 2) {
            __m128d v = _mm_max_pd(_mm_loadu_pd(x + j), _mm_setzero_pd());
            _mm_storeu_pd(out + j, _mm_sqrt_pd(v));
        }
        if (j < n) out[j] = occgp_sqrt_positive(x[j]);
    }
    #else
    static inline double occgp_below_one(double x) { return x < 1.0 ? x : 1.0; }
    static inline double occgp_sqrt_positive(double x) { return x > 0.0 ? sqrt(x) : 0.0; }
    static inline void occgp_sqrt_positive_n(const double* x, double* out, int n) {
        for (int j = 0; j < n; ++j) out[j] = occgp_sqrt_positive(x[j]);
    }
    static inline double occgp_below(double x, double t) { return x < t ? x : t; }
    static inline double occgp_interpolate(const double* table, double x) {
        int j = (int)x;
        const double* e = table + 2 * (long)j;
        return e[0] + (x - (double)j) * e[1];
    }
    #endif
    """
    double _below_one "occgp_below_one" (double x)
    double _sqrt_positive "occgp_sqrt_positive" (double x)
    void _sqrt_positive_n "occgp_sqrt_positive_n" (const double* x, double* out, int n)
    double _below "occgp_below" (double x, double t)
    double _interpolate "occgp_interpolate" (const double* table, double x)


cdef inline uint64_t _block_key(long kx, long ky, long kz) noexcept nogil:
    return (<uint64_t>(kx >> 2)) | ((<uint64_t>(ky >> 2)) << 16) | ((<uint64_t>(kz >> 2)) << 32)


cdef inline double _sparse(double r) noexcept nogil:
    """The sparse kernel at normalised distance r (0 for r >= 1; rounding just below 1,
    where it vanishes to fifth order, is clamped at 0 as la3dm clamps it)."""
    cdef double k
    if r >= 1.0:
        return 0.0
    k = (2.0 + cos(2.0 * M_PI * r)) * (1.0 - r) / 3.0 + sin(2.0 * M_PI * r) / (2.0 * M_PI)
    return k if k > 0.0 else 0.0


cdef enum:
    _TABLE = 16384          # the kernel tabulated in r^2 on this many intervals of [0, 1]

# the kernel at r2 = j / _TABLE (entry 2 j) and its difference to the next node (entry
# 2 j + 1, the interpolation's slope), side by side: one cache line per lookup
cdef double _KERNEL_R2[2 * _TABLE + 4]


cdef void _fill_table() noexcept:
    cdef int j
    for j in range(_TABLE + 1):
        _KERNEL_R2[2 * j] = _sparse(sqrt(<double>j / _TABLE))
    _KERNEL_R2[2 * _TABLE + 2] = 0.0
    for j in range(_TABLE + 1):
        _KERNEL_R2[2 * j + 1] = _KERNEL_R2[2 * j + 2] - _KERNEL_R2[2 * j]
    _KERNEL_R2[2 * _TABLE + 3] = 0.0


_fill_table()


cdef inline double _kernel_r2(double r2) noexcept nogil:
    """The sparse kernel at squared normalised distance r2 < 1, by linear interpolation
    in r2, where it is smooth (1 - (2 pi^2 / 3) r2 + O(r2^2) at 0, ~(1 - r)^5 at 1):
    within 3e-8 of the formula, without its sqrt, sin and cos."""
    return _interpolate(_KERNEL_R2, r2 * _TABLE)


def kernel_from_table(const double[::1] r2):
    """The tabulated kernel the accumulation uses, at squared distances in [0, 1)
    (for tests)."""
    out = np.empty(r2.shape[0])
    cdef double[::1] o = out
    cdef Py_ssize_t i
    for i in range(r2.shape[0]):
        o[i] = _kernel_r2(r2[i]) if 0.0 <= r2[i] < 1.0 else 0.0
    return out


cdef inline long _floor_key(double v) noexcept nogil:
    """floor(v), v clamped to +-2^40 first (NaN to -2^40): the same as the libm call
    on the keys' range, without it."""
    cdef long t
    v = min(max(v, -1099511627776.0), 1099511627776.0)
    t = <long>v
    return t - 1 if <double>t > v else t


cdef inline long _ceil_key(double v) noexcept nogil:
    """ceil(v), v clamped to +-2^40 first (NaN to -2^40)."""
    cdef long t
    v = min(max(v, -1099511627776.0), 1099511627776.0)
    t = <long>v
    return t + 1 if <double>t < v else t


cdef inline void _support_keys(const double* x, const double* ext, double res,
                               long* lo, long* hi) noexcept nogil:
    """The keys whose centre ``(key - 32768 + 0.5) res`` lies in the support box of the
    sample at x with half-extents ext."""
    cdef int a
    cdef double l, h
    for a in range(3):
        # clamped in double first (to integers: the same as clamping the rounded
        # value), so that a support wider than the key range casts safely; then
        # rounded up (l) and down (h) without the libm calls
        l = (x[a] - ext[a]) / res - 0.5
        h = (x[a] + ext[a]) / res - 0.5
        l = min(max(l, -_MAX_VAL - 1.0), <double>_MAX_VAL)
        h = min(max(h, -_MAX_VAL - 1.0), <double>_MAX_VAL)
        lo[a] = max(_ceil_key(l) + _MAX_VAL, 0)
        hi[a] = min(_floor_key(h) + _MAX_VAL, 2 * _MAX_VAL - 1)


def _support_cells(const double[:, ::1] samples, const double[:, ::1] extent,
                   double res):
    """Cells in the support boxes of the samples, as the accumulation visits them (the
    keys of _support_keys): the sum over the samples of the boxes' cell counts, in
    double precision (exact below 2^53), in one pass without temporaries."""
    cdef Py_ssize_t i
    cdef long lo[3]
    cdef long hi[3]
    cdef double total = 0.0, box
    cdef int a
    with nogil:
        for i in range(samples.shape[0]):
            _support_keys(&samples[i, 0], &extent[i, 0], res, lo, hi)
            box = 1.0
            for a in range(3):
                box *= <double>max(hi[a] - lo[a] + 1, 0)
            total += box
    return total


def sparse_kernel(const double[::1] r):
    """The sparse kernel ``((2 + cos 2 pi r)(1 - r)) / 3 + sin(2 pi r) / (2 pi)`` for
    r < 1, 0 beyond (Melkumyan and Ramos, 2009), element-wise."""
    out = np.empty(r.shape[0])
    cdef double[::1] o = out
    cdef Py_ssize_t i
    with nogil:
        for i in range(r.shape[0]):
            o[i] = _sparse(r[i] if r[i] >= 0 else -r[i])
    return out


cdef inline long _row_end(double x0, double a, double p00, double ip00, double res,
                          double ires, bint upper) noexcept nogil:
    """floor (ceil if `upper`) of ``(x0 + a / p00) / res - 0.5``, exactly as written,
    from the products by the reciprocals ip00 = 1 / p00 and ires = 1 / res: they are
    within 12 units in the last place of (|x0| + |a / p00|) / res of the quotients'
    result, so where a far wider margin e about it holds no integer, the quotients
    give the same key; else (or beyond 2^40, or NaN) they are computed."""
    cdef double q = a * ip00
    cdef double v = (x0 + q) * ires - 0.5
    cdef double e = 1e-13 * ((fabs(x0) + fabs(q)) * ires + 1.0)
    cdef double frac
    cdef long f
    if fabs(v) < 1099511627776.0:
        f = _floor_key(v)
        frac = v - <double>f            # in [0, 1), exact
        if frac > e and frac < 1.0 - e:
            return f + 1 if upper else f
    if upper:
        return _ceil_key((x0 + a / p00) / res - 0.5)
    return _floor_key((x0 + a / p00) / res - 0.5)


# the tile accumulation (Row, _accumulate_tile, _sort_by_tile, _tile_update)
include "_kernel_tiles.pxi"


@cython.auto_pickle(False)
cdef class _KernelCells:
    """Beta evidence on hashed blocks of cells. Use :class:`occgp.BGKMap` or
    :class:`occgp.AKIMap`."""

    cdef BetaBlocks _cells
    cdef double _res
    cdef object _lock
    cdef vector[double] _box        # per thread, an update's evidence over one tile
                                    # (alphas, then betas), zero between
    cdef vector[uint8_t] _touched   # per thread, the tile's 4x4x4 blocks with evidence,
                                    # zero between
    cdef bint _box_dirty            # a failure left _box / _touched non-zero
    # an update's sample boxes, (tile, sample) pairs and the like, kept between
    # updates so that their memory is not mapped afresh every time
    cdef vector[int32_t] _boxes
    cdef vector[Py_ssize_t] _per_sample
    cdef vector[uint64_t] _pairs
    cdef vector[uint64_t] _spare
    cdef vector[int64_t] _members
    cdef vector[Py_ssize_t] _runs

    def __cinit__(self, *args, **kwargs):
        self._lock = threading.Lock()
        self._res = 0.0

    def _setup(self, double resolution):
        with self._lock:
            self._cells.clear()
            self._res = resolution

    def _accumulate(self, const double[:, ::1] samples, const double[::1] labels,
                    const double[:, :, ::1] precision, const double[:, ::1] extent,
                    const double[::1] weights, double sf2, int n_threads=1,
                    Py_ssize_t max_pairs=_MAX_PAIRS):
        """Add the evidence of each sample to the cells its support reaches.

        `precision[i]` is the inverse bandwidth matrix of sample i, `extent[i]`
        the half-size of its support's bounding box per axis (metres),
        `weights[i]` its weight. The update's key box (aligned to blocks) is
        cut in tiles of 64 x 64 x 64 cells; each tile that a sample's support
        box meets sums its samples' evidence in double precision (in the
        samples' order below: the same sums whatever tile a support is cut in),
        then adds it to the blocks once per cell, the tiles shared among
        `n_threads` threads. The samples go in chunks of at most `max_pairs`
        (tile, sample) pairs (one chunk unless the supports span very many
        tiles; each chunk adds to the blocks once per cell). Returns the number
        of (sample, cell) contributions.
        """
        cdef Py_ssize_t n = samples.shape[0]
        cdef long updates
        if n == 0:
            return 0
        # samples in the order of their cells (z, then y, then x; stably): consecutive
        # samples then write to the same rows of the tile, which stay in cache. One
        # sort of the packed cell keys (the same order as sorting by each in turn).
        cell = np.floor(np.asarray(samples) / self._res).astype(np.int64)
        cell -= cell.min(axis=0)
        if cell.max() < (1 << 21):
            order_arr = np.argsort((cell[:, 2] << 42) | (cell[:, 1] << 21) | cell[:, 0],
                                   kind="stable")
        else:
            order_arr = np.lexsort((cell[:, 0], cell[:, 1], cell[:, 2]))
        # the samples' arrays put in that order, so that each tile reads its samples'
        # data in sequence
        cdef const double[:, ::1] xs = np.asarray(samples)[order_arr]
        cdef const double[::1] ys = np.asarray(labels)[order_arr]
        cdef const double[:, :, ::1] ps = np.asarray(precision)[order_arr]
        cdef const double[:, ::1] es = np.asarray(extent)[order_arr]
        cdef const double[::1] ws = np.asarray(weights)[order_arr]
        cdef const int64_t[::1] order = np.arange(n, dtype=np.int64)
        with self._lock:
            with nogil:
                updates = self._accumulate_core(&xs[0, 0], &ys[0], &ps[0, 0, 0], &es[0, 0],
                                                &ws[0], &order[0], n, sf2,
                                                max(n_threads, 1), max(max_pairs, 1))
        return updates

    cdef long _accumulate_core(self, const double* xs, const double* labels,
                               const double* ps, const double* es, const double* ws,
                               const int64_t* order, Py_ssize_t n, double sf2,
                               int nt, Py_ssize_t max_pairs) except -1 nogil:
        cdef Py_ssize_t i, t, t0, t1, k, n_pairs
        cdef long lo[3]
        cdef long hi[3]
        cdef long org[3]
        cdef long top[3]
        cdef long dims[3]
        cdef long tile[3]
        cdef long n_tile[3]
        cdef long updates = 0, new_cells = 0
        cdef int a, failed = 0
        cdef int* fail = &failed
        cdef double res = self._res
        cdef mutex lock
        for a in range(3):
            org[a] = 2 * _MAX_VAL
            top[a] = -1
        # each sample's support keys, and the key box of them all
        self._boxes.resize(6 * n)
        for i in range(n):
            _support_keys(xs + 3 * i, es + 3 * i, res, lo, hi)
            for a in range(3):
                self._boxes[6 * i + a] = <int32_t>lo[a]
                self._boxes[6 * i + 3 + a] = <int32_t>hi[a]
                org[a] = min(org[a], lo[a])
                top[a] = max(top[a], hi[a])
        for a in range(3):
            if top[a] < org[a]:      # no cell centre in any support
                return 0
            org[a] = org[a] & ~3L
            dims[a] = ((top[a] | 3) + 1) - org[a]
            tile[a] = min(<long>_TILE, dims[a])
            n_tile[a] = (dims[a] + tile[a] - 1) // tile[a]
        # the (tile, sample) pairs: a sample with every tile its support box meets
        self._per_sample.resize(n)
        for t in range(n):
            i = order[t]
            k = 1
            for a in range(3):
                # no cell centre inside
                if self._boxes[6 * i + 3 + a] < self._boxes[6 * i + a]:
                    k = 0
                    break
                k *= ((self._boxes[6 * i + 3 + a] - org[a]) // tile[a]
                      - (self._boxes[6 * i + a] - org[a]) // tile[a] + 1)
            self._per_sample[t] = k
        # the samples in chunks of consecutive ones in `order`, at most max_pairs pairs
        # each (but one sample at least): one chunk for all but giant supports
        t0 = 0
        while t0 < n:
            n_pairs = self._per_sample[t0]
            t1 = t0 + 1
            while t1 < n and n_pairs + self._per_sample[t1] <= max_pairs:
                n_pairs += self._per_sample[t1]
                t1 += 1
            updates += self._accumulate_chunk(
                xs, labels, ps, ws, &self._boxes[0], order, t0, t1, n_pairs, sf2, org, tile,
                n_tile, nt, &new_cells, fail, &lock)
            t0 = t1
        self._cells.add_cells(new_cells)
        if failed:
            with gil:
                raise MemoryError("no memory for the kernel map's blocks")
        return updates

    cdef long _accumulate_chunk(
            self, const double* xs, const double* labels, const double* ps,
            const double* ws, const int32_t* boxes, const int64_t* order, Py_ssize_t t0,
            Py_ssize_t t1, Py_ssize_t n_pairs, double sf2, const long* org,
            const long* tile, const long* n_tile, int nt, long* new_cells, int* fail,
            mutex* lock) except -1 nogil:
        """Add the evidence of the samples order[t0 .. t1) (`n_pairs` (tile, sample)
        pairs) tile by tile, on `nt` threads; returns the number of contributions."""
        cdef Py_ssize_t t, i, k, n_tiles
        cdef long tlo[3]
        cdef long thi[3]
        cdef long tx, ty, tz, updates = 0, upd, fresh, fresh_sum = 0
        cdef int a, tid
        cdef bint empty
        cdef uint64_t tkey
        cdef size_t tile_cells = <size_t>(tile[0] * tile[1] * tile[2])
        cdef size_t tile_bricks = tile_cells >> 6
        cdef double* box
        cdef uint8_t* touched
        cdef const int64_t* members
        cdef const Py_ssize_t* runs
        cdef const uint64_t* pairs
        if n_pairs == 0:
            return 0
        # each pair as (tile << 32 | position in `order` from t0), sorted by tile
        # (stably: in each tile the samples stay in `order`)
        self._pairs.clear()
        self._runs.clear()
        self._pairs.reserve(n_pairs)
        for t in range(t0, t1):
            i = order[t]
            empty = False
            for a in range(3):
                empty = empty or boxes[6 * i + 3 + a] < boxes[6 * i + a]
                tlo[a] = (boxes[6 * i + a] - org[a]) // tile[a]
                thi[a] = (boxes[6 * i + 3 + a] - org[a]) // tile[a]
            if empty:
                continue
            for tz in range(tlo[2], thi[2] + 1):
                for ty in range(tlo[1], thi[1] + 1):
                    for tx in range(tlo[0], thi[0] + 1):
                        tkey = <uint64_t>((tz * n_tile[1] + ty) * n_tile[0] + tx)
                        self._pairs.push_back(tkey << 32 | <uint64_t>(t - t0))
        _sort_by_tile(self._pairs, self._spare,
                      <uint64_t>(n_tile[0] * n_tile[1] * n_tile[2]))
        n_pairs = <Py_ssize_t>self._pairs.size()
        if n_pairs == 0:
            return 0
        self._members.resize(n_pairs)
        self._runs.push_back(0)
        for k in range(n_pairs):
            self._members[k] = order[t0 + <Py_ssize_t>(self._pairs[k]
                                                       & <uint64_t>0xFFFFFFFF)]
            if k and (self._pairs[k] >> 32) != (self._pairs[k - 1] >> 32):
                self._runs.push_back(k)
        self._runs.push_back(n_pairs)
        n_tiles = <Py_ssize_t>self._runs.size() - 1
        # a scratch tile per thread
        nt = <int>max(min(<Py_ssize_t>nt, n_tiles), 1)
        if self._box_dirty:
            if self._box.size():
                memset(&self._box[0], 0, self._box.size() * sizeof(double))
            self._touched.assign(self._touched.size(), 0)
        if self._box.size() < 2 * tile_cells * nt:
            self._box.resize(2 * tile_cells * nt)
        if self._touched.size() < tile_bricks * nt:
            self._touched.resize(tile_bricks * nt)
        self._box_dirty = True
        box = &self._box[0]
        touched = &self._touched[0]
        members = &self._members[0]
        runs = &self._runs[0]
        pairs = &self._pairs[0]
        for k in prange(n_tiles, num_threads=nt, schedule="dynamic", chunksize=1):
            tid = threadid()
            upd, fresh = _tile_update(
                &self._cells, lock, xs, labels, ps, ws, boxes, members + runs[k],
                runs[k + 1] - runs[k], pairs[runs[k]] >> 32, sf2, self._res, org, tile,
                n_tile, box + 2 * tile_cells * <size_t>tid, tile_cells,
                touched + tile_bricks * <size_t>tid, fail)
            updates += upd
            fresh_sum += fresh
        new_cells[0] += fresh_sum
        self._box_dirty = fail[0] != 0
        return updates

    def _query(self, const double[:, ::1] points, double prior, int what):
        """Per point: 0 -> posterior mean of occupancy, 1 -> its variance (NaN where no
        kernel ever reached the point's cell)."""
        cdef Py_ssize_t i, n = points.shape[0]
        out = np.full(n, np.nan)
        cdef double[::1] o = out
        cdef long key[3]
        cdef int a, c
        cdef bint inside
        cdef double s, res = self._res, al, be
        cdef const BetaBlock* found
        with self._lock:
            with nogil:
                for i in range(n):
                    inside = True
                    for a in range(3):
                        s = floor(points[i, a] / res)
                        if not (s >= -_MAX_VAL and s < _MAX_VAL):
                            inside = False
                            break
                        key[a] = <long>s + _MAX_VAL
                    if not inside:
                        continue
                    found = self._cells.find(_block_key(key[0], key[1], key[2]))
                    if found == NULL:
                        continue
                    c = (key[0] & 3) | ((key[1] & 3) << 2) | ((key[2] & 3) << 4)
                    if not (found.mask >> c) & 1:
                        continue
                    al = found.alpha[c] + prior
                    be = found.beta[c] + prior
                    if what == 0:
                        o[i] = al / (al + be)
                    else:
                        o[i] = al * be / ((al + be) * (al + be) * (al + be + 1.0))
        return out

    def _cells_arrays(self):
        """(keys uint16 (n, 3), alpha, beta) of every cell, in no particular order."""
        cdef Py_ssize_t n
        with self._lock:
            n = self._cells.num_cells()
            keys = np.empty((n, 3), dtype=np.uint16)
            alpha = np.empty(n)
            beta = np.empty(n)
            if n:
                self._fill(keys, alpha, beta)
        return keys, alpha, beta

    cdef void _fill(self, uint16_t[:, ::1] keys, double[::1] alpha, double[::1] beta) noexcept:
        cdef Py_ssize_t j = 0
        cdef size_t slot
        cdef uint64_t packed
        cdef int c
        cdef long bx, by, bz
        cdef const BetaBlock* blk
        with nogil:
            for slot in range(self._cells.index_capacity()):
                packed = self._cells.index_slot(slot).key
                if packed == EMPTY_KEY:
                    continue
                blk = self._cells.block(self._cells.index_slot(slot).index - 1)
                bx = <long>(packed & 0xFFFF) << 2
                by = <long>((packed >> 16) & 0xFFFF) << 2
                bz = <long>((packed >> 32) & 0xFFFF) << 2
                for c in range(64):
                    if not (blk.mask >> c) & 1:
                        continue
                    keys[j, 0] = <uint16_t>(bx + (c & 3))
                    keys[j, 1] = <uint16_t>(by + ((c >> 2) & 3))
                    keys[j, 2] = <uint16_t>(bz + (c >> 4))
                    alpha[j] = blk.alpha[c]
                    beta[j] = blk.beta[c]
                    j += 1

    def _set_cells(self, const uint16_t[:, ::1] keys, const double[::1] alpha,
                   const double[::1] beta):
        """Replace the cells (for unpickling)."""
        cdef Py_ssize_t j
        with self._lock:
            self._cells.clear()
            with nogil:
                for j in range(keys.shape[0]):
                    self._cells.add(keys[j, 0], keys[j, 1], keys[j, 2], <float>alpha[j],
                                    <float>beta[j])

    def _num_cells(self):
        return self._cells.num_cells()

    def _memory_bytes(self):
        """Bytes the cells take (blocks and their index; not the update's scratch box)."""
        return self._cells.memory_bytes()


# AKIMap's adaptive bandwidths (its own concern, in its own file; it reads the
# tabulated kernel above)
include "_akimap.pxi"
