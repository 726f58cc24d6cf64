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

AKIMap's bandwidths (:func:`_akimap_bandwidths`) are computed per sample on
OpenMP threads; an update's evidence is summed in double precision over dense
slabs of its key box, each slab's block rows split among the threads (every cell
is summed by one thread, in sample order: the map does not depend on the number
of threads), then added to the blocks once per cell.

Nothing here validates user input: :mod:`occgp.kernel` checks every array first.
The loops run without the GIL; a per-map lock serialises operations on one map.
"""

cimport cython
from cython.operator cimport dereference as deref, preincrement as inc
from cython.parallel cimport prange, threadid
from libc.math cimport M_PI, acos, ceil, cos, exp, fabs, floor, isnan, log, sin, sqrt
from libc.stdint cimport int64_t, uint8_t, uint16_t, uint64_t
from libcpp.vector cimport vector

import threading

import numpy as np

cdef enum:
    _MAX_VAL = 32768        # half the number of keys per axis, as liboctomap's 16-bit keys
    _MAX_DENSE = 1 << 22    # an update accumulates in dense slabs of at most this many cells


cdef struct Beta:
    double alpha
    double beta


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

cdef double _KERNEL_R2[_TABLE + 2]


cdef void _fill_table() noexcept:
    cdef int j
    for j in range(_TABLE + 1):
        _KERNEL_R2[j] = _sparse(sqrt(<double>j / _TABLE))
    _KERNEL_R2[_TABLE + 1] = 0.0


_fill_table()


cdef inline double _kernel_r2(double r2) noexcept nogil:
    """The sparse kernel at squared normalised distance r2 < 1, by linear interpolation
    in r2, where it is smooth (1 - (2 pi^2 / 3) r2 + O(r2^2) at 0, ~(1 - r)^5 at 1):
    within 3e-8 of the formula, without its sqrt, sin and cos."""
    cdef double x = r2 * _TABLE
    cdef int j = <int>x
    return _KERNEL_R2[j] + (x - j) * (_KERNEL_R2[j + 1] - _KERNEL_R2[j])


def kernel_from_table(const double[::1] r2):
    """The tabulated kernel the accumulation uses, at squared distances in [0, 1)
    (for tests)."""
    out = np.empty(r2.shape[0])
    cdef double[::1] o = out
    cdef Py_ssize_t i
    for i in range(r2.shape[0]):
        o[i] = _kernel_r2(r2[i]) if 0.0 <= r2[i] < 1.0 else 0.0
    return out


cdef inline void _support_keys(const double* x, const double* ext, double res,
                               long* lo, long* hi) noexcept nogil:
    """The keys whose centre ``(key - 32768 + 0.5) res`` lies in the support box of the
    sample at x with half-extents ext."""
    cdef int a
    cdef double l, h
    for a in range(3):
        # clamped in double first: a support wider than the key range casts safely
        l = ceil((x[a] - ext[a]) / res - 0.5)
        h = floor((x[a] + ext[a]) / res - 0.5)
        l = min(max(l, -_MAX_VAL - 1.0), <double>_MAX_VAL)
        h = min(max(h, -_MAX_VAL - 1.0), <double>_MAX_VAL)
        lo[a] = max(<long>l + _MAX_VAL, 0)
        hi[a] = min(<long>h + _MAX_VAL, 2 * _MAX_VAL - 1)


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


cdef long _accumulate_slab(const double* xs, const double* labels, const double* prec,
                           const double* ext, const double* weights, const int64_t* order,
                           Py_ssize_t n, double sf2, double res, long za, long zb,
                           const long* org, const long* dims, Beta* box,
                           uint8_t* touched) noexcept nogil:
    """Add the evidence of the samples (in `order`) to the rows za <= kz < zb of the
    dense slab whose lowest key is `org` and row size `dims[0] x dims[1]`
    (block-aligned), flagging the slab's 4x4x4 blocks that get any; returns the
    number of contributions."""
    cdef Py_ssize_t t, i
    cdef long lo[3]
    cdef long hi[3]
    cdef long kx, ky, kz, row_lo, row_hi, bx
    cdef double d0, d1, d2, qb, qc, disc, p00, r2, dr, ddr, k, y, wk
    cdef const double* x
    cdef const double* p
    cdef uint64_t row, brow
    cdef long updates = 0
    cdef long bdx = dims[0] >> 2, bdy = dims[1] >> 2
    cdef Beta* cell
    for t in range(n):
        i = order[t]
        x = xs + 3 * i
        p = prec + 9 * i
        _support_keys(x, ext + 3 * i, res, lo, hi)
        if hi[2] < za or lo[2] >= zb:
            continue
        y = labels[i]
        wk = sf2 * weights[i]
        p00 = p[0]
        ddr = 2.0 * p00 * res * res
        for kz in range(max(lo[2], za), min(hi[2], zb - 1) + 1):
            d2 = (<double>(kz - _MAX_VAL) + 0.5) * res - x[2]
            for ky in range(lo[1], hi[1] + 1):
                d1 = (<double>(ky - _MAX_VAL) + 0.5) * res - x[1]
                # the row's cells inside the ellipsoid: r2 is quadratic in d0; widened
                # by a cell each way, the test below decides
                qb = 0.5 * (p[1] + p[3]) * d1 + 0.5 * (p[2] + p[6]) * d2
                qc = p[4] * d1 * d1 + (p[5] + p[7]) * d1 * d2 + p[8] * d2 * d2
                disc = qb * qb - p00 * (qc - 1.0)
                if not disc > 0.0:
                    continue
                disc = sqrt(disc)
                row_lo = max(lo[0], <long>floor((x[0] + (-qb - disc) / p00) / res - 0.5)
                             + _MAX_VAL)
                row_hi = min(hi[0], <long>ceil((x[0] + (-qb + disc) / p00) / res - 0.5)
                             + _MAX_VAL)
                if row_lo > row_hi:
                    continue
                row = (<uint64_t>(kz - org[2]) * <uint64_t>dims[1]
                       + <uint64_t>(ky - org[1])) * <uint64_t>dims[0]
                brow = ((<uint64_t>((kz - org[2]) >> 2) * <uint64_t>bdy
                         + <uint64_t>((ky - org[1]) >> 2)) * <uint64_t>bdx)
                for bx in range((row_lo - org[0]) >> 2, ((row_hi - org[0]) >> 2) + 1):
                    touched[brow + <uint64_t>bx] = 1
                # r2 along the row by second differences: r2(d0 + res) = r2 + dr,
                # dr(d0 + res) = dr + 2 p00 res^2
                d0 = (<double>(row_lo - _MAX_VAL) + 0.5) * res - x[0]
                r2 = (p00 * d0 + 2.0 * qb) * d0 + qc
                dr = (2.0 * p00 * d0 + 2.0 * qb + p00 * res) * res
                cell = box + row + <uint64_t>(row_lo - org[0])
                for kx in range(row_lo, row_hi + 1):
                    if r2 < 1.0:
                        k = wk * _kernel_r2(r2)
                        cell.alpha += k * y
                        cell.beta += k * (1.0 - y)
                        updates += 1
                    r2 += dr
                    dr += ddr
                    cell += 1
    return updates


cdef long _accumulate_direct(BetaBlocks* cells, const double* xs, const double* labels,
                             const double* prec, const double* ext, const double* weights,
                             const int64_t* order, Py_ssize_t n, double sf2,
                             double res) except -1 nogil:
    """Add each contribution straight to the blocks in float32 (updates whose key box
    is too wide for one dense slab of four rows)."""
    cdef Py_ssize_t t, i
    cdef long lo[3]
    cdef long hi[3]
    cdef long kx, ky, kz
    cdef double d[3]
    cdef double r2, k, y
    cdef const double* x
    cdef const double* p
    cdef long updates = 0
    for t in range(n):
        i = order[t]
        x = xs + 3 * i
        p = prec + 9 * i
        _support_keys(x, ext + 3 * i, res, lo, hi)
        y = labels[i]
        for kz in range(lo[2], hi[2] + 1):
            d[2] = (<double>(kz - _MAX_VAL) + 0.5) * res - x[2]
            for ky in range(lo[1], hi[1] + 1):
                d[1] = (<double>(ky - _MAX_VAL) + 0.5) * res - x[1]
                for kx in range(lo[0], hi[0] + 1):
                    d[0] = (<double>(kx - _MAX_VAL) + 0.5) * res - x[0]
                    r2 = (p[0] * d[0] * d[0] + p[4] * d[1] * d[1] + p[8] * d[2] * d[2]
                          + (p[1] + p[3]) * d[0] * d[1] + (p[2] + p[6]) * d[0] * d[2]
                          + (p[5] + p[7]) * d[1] * d[2])
                    if not r2 < 1.0:
                        continue
                    k = sf2 * weights[i] * _kernel_r2(r2)
                    if k <= 0.0:
                        continue
                    cells.add(kx, ky, kz, <float>(k * y), <float>(k * (1.0 - y)))
                    updates += 1
    return updates


@cython.auto_pickle(False)
cdef class _KernelCells:
    """Beta evidence on hashed blocks of cells. Use :class:`occgp.BGKMap` or
    :class:`occgp.AKIMap`."""

    cdef BetaBlocks _cells
    cdef double _res
    cdef object _lock
    cdef vector[Beta] _box          # an update's evidence over one slab, zero between
    cdef vector[uint8_t] _touched   # the slab's 4x4x4 blocks with evidence, zero between
    cdef bint _box_dirty            # an exception left _box / _touched non-zero

    def __cinit__(self, *args, **kwargs):
        self._lock = threading.Lock()
        self._res = 0.0

    def _setup(self, double resolution):
        with self._lock:
            self._cells.clear()
            self._res = resolution

    def _accumulate(self, const double[:, ::1] samples, const double[::1] labels,
                    const double[:, :, ::1] precision, const double[:, ::1] extent,
                    const double[::1] weights, double sf2, int n_threads=1):
        """Add the evidence of each sample to the cells its support reaches.

        `precision[i]` is the inverse bandwidth matrix of sample i, `extent[i]`
        the half-size of its support's bounding box per axis (metres),
        `weights[i]` its weight. The update's key box (aligned to blocks) is
        swept in slabs of whole block rows of at most 2^22 cells; in each slab
        the evidence is summed in double precision (the slab's rows split among
        `n_threads` threads, balanced by samples), then added to the blocks once
        per cell. Returns the number of (sample, cell) contributions.
        """
        cdef Py_ssize_t n = samples.shape[0]
        cdef long updates
        if n == 0:
            return 0
        # samples in the order of their cells (z, then y, then x): consecutive samples
        # then write to the same rows of the slab, which stay in cache
        cell = np.floor(np.asarray(samples) / self._res).astype(np.int64)
        cell -= cell.min(axis=0)
        order_arr = np.lexsort((cell[:, 0], cell[:, 1], cell[:, 2])).astype(np.int64)
        cdef const int64_t[::1] order = order_arr
        with self._lock:
            with nogil:
                updates = self._accumulate_core(&samples[0, 0], &labels[0],
                                                &precision[0, 0, 0], &extent[0, 0],
                                                &weights[0], &order[0], n, sf2,
                                                max(n_threads, 1))
        return updates

    cdef long _accumulate_core(self, const double* xs, const double* labels,
                               const double* ps, const double* es, const double* ws,
                               const int64_t* order, Py_ssize_t n, double sf2,
                               int nt) except -1 nogil:
        cdef Py_ssize_t i
        cdef long lo[3]
        cdef long hi[3]
        cdef long org[3]
        cdef long slab[3]
        cdef long top[3]
        cdef long dims[3]
        cdef long layer, height, z0, z1, za, zb, nb, kz, bz
        cdef long updates = 0, upd, new_cells
        cdef int a, t
        cdef double res = self._res
        cdef uint64_t cells_in_slab, nblocks, b, bkey
        cdef vector[long] splits
        cdef vector[long] counts
        cdef vector[size_t] block_ids
        cdef BetaBlocks* cells = &self._cells
        cdef Beta* box
        cdef uint8_t* touched
        cdef double visits = 0.0, boxes
        for a in range(3):
            org[a] = 2 * _MAX_VAL
            top[a] = -1
        for i in range(n):
            _support_keys(xs + 3 * i, es + 3 * i, res, lo, hi)
            boxes = 1.0
            for a in range(3):
                org[a] = min(org[a], lo[a])
                top[a] = max(top[a], hi[a])
                boxes *= <double>max(hi[a] - lo[a] + 1, 0)
            visits += boxes
        for a in range(3):
            if top[a] < org[a]:      # no cell centre in any support
                return 0
            org[a] = org[a] & ~3L
            dims[a] = ((top[a] | 3) + 1) - org[a]
        layer = dims[0] * dims[1]
        # the slabs sweep the whole key box (about a tenth of its cells' time each);
        # where the supports fill little of a wide box, straight to the blocks
        if 4 * layer > _MAX_DENSE or \
                <double>layer * <double>dims[2] > 64.0 * visits + <double>_MAX_DENSE:
            return _accumulate_direct(cells, xs, labels, ps, es, ws, order, n, sf2, res)
        height = max(((_MAX_DENSE // layer) >> 2) << 2, 4)
        height = min(height, dims[2])
        cells_in_slab = <uint64_t>(layer * height)
        if self._box_dirty:
            self._box.assign(self._box.size(), Beta(0.0, 0.0))
            self._touched.assign(self._touched.size(), 0)
        if self._box.size() < cells_in_slab:
            self._box.resize(cells_in_slab)
        if self._touched.size() < cells_in_slab // 64:
            self._touched.resize(cells_in_slab // 64)
        self._box_dirty = True
        box = &self._box[0]
        touched = &self._touched[0]
        z0 = org[2]
        while z0 < org[2] + dims[2]:
            z1 = min(z0 + height, org[2] + dims[2])
            # split the slab's block rows among the threads by sample heights
            nb = (z1 - z0) >> 2
            counts.assign(nb, 0)
            for i in range(n):
                _support_keys(xs + 3 * i, es + 3 * i, res, lo, hi)
                kz = (lo[2] + hi[2]) // 2
                if z0 <= kz < z1:
                    counts[(kz - z0) >> 2] += 1
            splits.assign(nt + 1, nb)
            splits[0] = 0
            _balanced_splits(counts, nt, splits)
            slab[0] = org[0]
            slab[1] = org[1]
            slab[2] = z0
            for t in prange(nt, num_threads=nt, schedule="static", chunksize=1):
                za = z0 + 4 * splits[t]
                zb = z0 + 4 * splits[t + 1]
                if za < zb:
                    upd = _accumulate_slab(
                        xs, labels, ps, es, ws, order, n, sf2, res,
                        za, zb, slab, dims, box, touched)
                    updates += upd
            # blocks with evidence: created serially, then filled in parallel, one
            # layer of blocks per task, reading the slab row by row
            nblocks = <uint64_t>((z1 - z0) * layer) >> 6
            block_ids.assign(nblocks, <size_t>-1)
            for b in range(nblocks):
                if touched[b]:
                    touched[b] = 0
                    bz = <long>(b // <uint64_t>((dims[0] >> 2) * (dims[1] >> 2)))
                    bkey = _block_key(
                        org[0] + 4 * <long>(b % <uint64_t>(dims[0] >> 2)),
                        org[1] + 4 * <long>((b // <uint64_t>(dims[0] >> 2))
                                            % <uint64_t>(dims[1] >> 2)),
                        z0 + 4 * bz)
                    block_ids[b] = cells.get_index(bkey)
            new_cells = 0
            for i in prange((z1 - z0) >> 2, num_threads=nt, schedule="dynamic"):
                new_cells += _merge_layer(cells, box, &block_ids[0], i, dims)
            cells.add_cells(new_cells)
            z0 = z1
        self._box_dirty = False
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


cdef void _balanced_splits(const vector[long]& counts, int nt, vector[long]& splits) noexcept nogil:
    """Block-row boundaries splitting `counts` (samples per block row) into `nt`
    consecutive ranges of about equal sums; splits[0] = 0, splits[nt] = len(counts)."""
    cdef long total = 0, acc = 0
    cdef size_t r
    cdef int t = 1
    for r in range(counts.size()):
        total += counts[r]
    for r in range(counts.size()):
        acc += counts[r]
        while t < nt and acc * nt >= total * t:
            splits[t] = <long>r + 1
            t += 1
    while t < nt:
        splits[t] = <long>counts.size()
        t += 1


cdef long _merge_layer(BetaBlocks* cells, Beta* box, const size_t* block_ids, long bz,
                       const long* dims) noexcept nogil:
    """Add the evidence of the slab's layer bz of 4x4x4 blocks to the map's blocks
    (`block_ids[b]`: the map's index of the slab's block b, or -1), zeroing it in the
    slab; returns the number of cells newly reached."""
    cdef long bdx = dims[0] >> 2, bdy = dims[1] >> 2, kz, ky, bx
    cdef int c, cx
    cdef size_t bid
    cdef long fresh = 0
    cdef Beta* cell
    cdef BetaBlock* blk
    for kz in range(4 * bz, 4 * bz + 4):
        for ky in range(dims[1]):
            cell = box + (<uint64_t>kz * <uint64_t>dims[1] + <uint64_t>ky) * <uint64_t>dims[0]
            for bx in range(bdx):
                bid = block_ids[(bz * bdy + (ky >> 2)) * bdx + bx]
                if bid == <size_t>-1:
                    cell += 4
                    continue
                blk = cells.block(bid)
                c = ((ky & 3) << 2) | ((kz & 3) << 4)
                for cx in range(4):
                    if cell.alpha != 0.0 or cell.beta != 0.0:
                        blk.alpha[c + cx] += <float>cell.alpha
                        blk.beta[c + cx] += <float>cell.beta
                        if not (blk.mask >> (c + cx)) & 1:
                            blk.mask |= (<uint64_t>1) << (c + cx)
                            fresh += 1
                        cell.alpha = 0.0
                        cell.beta = 0.0
                    cell += 1
    return fresh

# ----------------------------------------------------------------------------------------
# AKIMap's adaptive bandwidths (Kwon et al.; dissertation §3.3.3)
# ----------------------------------------------------------------------------------------

cdef enum:
    _SCALE_GRID = 16        # occgp's minimiser: coarse grid of log-scales, then golden section
    _GOLDEN_ITERS = 24
    _GD_EPOCHS = 100        # the reference code's gradient descent
cdef double _GD_TOLERANCE = 0.001
cdef double _GD_RATE = 0.01
cdef double _COV_NOISE = 0.001


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
        e = target[j] - (_kernel_r2(r2[j] * inv) if r2[j] * inv < 1.0 else 0.0)
        total += e * e
    return total / (c * c * c)


cdef double _scale_minimise(const double* r2, const double* target, int m,
                            double lo) noexcept nogil:
    """The length-scale factor c in [lo, 1] minimising Eq. 3.7: the best of a grid of
    _SCALE_GRID log-spaced values (1 included), refined by golden-section search
    between its grid neighbours (the loss need not be unimodal on [lo, 1])."""
    cdef double best_c = 1.0, best = _scale_loss(r2, target, m, 1.0), c, f
    cdef double step, a, b, x1, x2, f1, f2
    cdef double g = 0.6180339887498949
    cdef int j, best_j = _SCALE_GRID - 1
    step = log(lo) / (_SCALE_GRID - 1)
    for j in range(_SCALE_GRID - 1):
        c = exp(log(lo) - j * step) if j else lo
        f = _scale_loss(r2, target, m, c)
        if f < best:
            best, best_c, best_j = f, c, j
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


cdef inline long _cell_find(const int64_t* keys, long n, int64_t key) noexcept nogil:
    """Index of `key` in the sorted array `keys`, or -1."""
    cdef long lo = 0, hi = n, mid
    while lo < hi:
        mid = (lo + hi) >> 1
        if keys[mid] < key:
            lo = mid + 1
        else:
            hi = mid
    return lo if lo < n and keys[lo] == key else -1


cdef void _bandwidth_one(
        Py_ssize_t i, const double* x, const uint8_t* labels, const double* origin,
        double res, double radius_max, double max_range, bint published, double floor2,
        double cell, const int64_t* grid_lo, const int64_t* grid_dims,
        const int64_t* cell_keys, long n_cells, const int64_t* cell_start,
        const int64_t* order, double* buf, double* precision, double* extent,
        double* weight, double* scale, int64_t* n_same) noexcept nogil:
    """Sample i's bandwidth: covariance of its same-label neighbours within the
    search radius, then the scale of Eq. 3.7 (see AKIMap._bandwidths)."""
    cdef double xi[3]
    cdef double d[3]
    cdef double sig[9]
    cdef double inv[9]
    cdef double dist, radius, r2max, det, lo_scale, c, w0, q
    cdef long cmin[3]
    cdef long cmax[3]
    cdef long cx, cy, cz, slot
    cdef int64_t t, j
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
        cmin[a] = max(<long>floor((xi[a] - radius) / cell) - <long>grid_lo[a], 0)
        cmax[a] = min(<long>floor((xi[a] + radius) / cell) - <long>grid_lo[a],
                      <long>grid_dims[a] - 1)
    # pass 1: the neighbours (offsets and labels into buf, 4 doubles each) and the
    # scatter of the same-label ones about x_i
    for cz in range(cmin[2], cmax[2] + 1):
        for cy in range(cmin[1], cmax[1] + 1):
            for cx in range(cmin[0], cmax[0] + 1):
                slot = _cell_find(cell_keys, n_cells,
                                  (cz * grid_dims[1] + cy) * grid_dims[0] + cx)
                if slot < 0:
                    continue
                for t in range(cell_start[slot], cell_start[slot + 1]):
                    j = order[t]
                    for a in range(3):
                        d[a] = x[3 * j + a] - xi[a]
                    if d[0] * d[0] + d[1] * d[1] + d[2] * d[2] > r2max:
                        continue
                    buf[4 * m] = d[0]
                    buf[4 * m + 1] = d[1]
                    buf[4 * m + 2] = d[2]
                    buf[4 * m + 3] = 1.0 if labels[j] == y else 0.0
                    m += 1
                    if labels[j] == y:
                        same += 1
                        for a in range(3):
                            for b in range(3):
                                sig[3 * a + b] += d[a] * d[b]
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
        if q < 1.0:
            if buf[4 * t + 3] == 0.0:
                other += 1
            # compact in place: entry k <- (q, target); k <= t so no overwrite ahead
            r2buf[2 * k] = q
            r2buf[2 * k + 1] = _kernel_r2(q) if buf[4 * t + 3] != 0.0 else 0.0
            k += 1
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


def _akimap_bandwidths(const double[:, ::1] samples, const uint8_t[::1] labels,
                       const double[::1] origin, double res, double radius_max,
                       double max_range, bint published, double floor, int n_threads,
                       double cell):
    """Per sample: precision (inverse bandwidth, (n, 3, 3)), support half-extents (n, 3),
    weight |H|^-1/2, the length-scale factor c (H = c^2 Sigma + floor^2 I) and the
    number of same-label samples in its search ball (itself included). The samples
    are bucketed in cubes of edge `cell` (at least `radius_max`; wider where they
    would span more than 2^20 cubes)."""
    cdef Py_ssize_t n = samples.shape[0], i
    precision = np.empty((n, 3, 3))
    extent = np.empty((n, 3))
    weight = np.empty(n)
    scale = np.empty(n)
    n_same = np.empty(n, dtype=np.int64)
    if n == 0:
        return precision, extent, weight, scale, n_same
    # samples bucketed in cubes of edge cell, the cubes sorted by key
    cell = max(cell, radius_max)
    ck = np.floor(np.asarray(samples) / cell).astype(np.int64)
    lo = ck.min(axis=0)
    dims = ck.max(axis=0) - lo + 1
    ck -= lo
    flat = (ck[:, 2] * dims[1] + ck[:, 1]) * dims[0] + ck[:, 0]
    order = np.argsort(flat, kind="stable").astype(np.int64)
    keys, start = np.unique(flat[order], return_index=True)
    start = np.append(start, n).astype(np.int64)
    keys = np.ascontiguousarray(keys, dtype=np.int64)
    lo = np.ascontiguousarray(lo, dtype=np.int64)
    dims = np.ascontiguousarray(dims, dtype=np.int64)
    cdef const int64_t[::1] lo_v = lo, dims_v = dims, keys_v = keys, start_v = start
    cdef const int64_t[::1] order_v = order
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
                           &keys_v[0], n_cells, &start_v[0], &order_v[0],
                           &buf[threadid(), 0],
                           &p_v[0, 0, 0], &e_v[0, 0], &w_v[0], &s_v[0], &n_v[0])
    return precision, extent, weight, scale, n_same
