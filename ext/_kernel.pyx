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
3e-8 of the formula). Cells live in an open-addressing table of 16-byte slots
(packed key, float32 alpha and beta, as la3dm stores them), keyed like
liboctomap's: ``floor(x / resolution) + 32768`` per axis, centre
``(key - 32768 + 0.5) * resolution``.

Nothing here validates user input: :mod:`occgp.kernel` checks every array first.
The loops run without the GIL; a per-map lock serialises operations on one map.
"""

cimport cython
from cython.operator cimport dereference as deref, preincrement as inc
from libc.math cimport M_PI, ceil, cos, floor, isnan, sin, sqrt
from libc.stdint cimport uint16_t, uint64_t
from libcpp.vector cimport vector

import threading

import numpy as np

cdef enum:
    _MAX_VAL = 32768        # half the number of keys per axis, as liboctomap's 16-bit keys
    _MAX_DENSE = 1 << 22    # up to this many cells, an update accumulates in a dense box


cdef struct Beta:
    double alpha
    double beta


cdef extern from "_keytable.h" namespace "occgp" nogil:
    cdef cppclass BetaCell:       # 16 bytes: packed key, float alpha, float beta
        uint64_t key
        float alpha
        float beta

    cdef cppclass BetaTable:      # packed key -> BetaCell, open addressing
        BetaTable() except +
        void reset(size_t expected) except +
        BetaCell* get(uint64_t key) except +
        BetaCell* find(uint64_t key)
        size_t size()
        size_t capacity() const
        const BetaCell& slot(size_t i) const

    const uint64_t EMPTY_KEY "occgp::kEmptyKey"


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


cdef inline uint64_t _pack(long kx, long ky, long kz) noexcept nogil:
    return (<uint64_t>kx) | ((<uint64_t>ky) << 16) | ((<uint64_t>kz) << 32)


cdef inline void _support_keys(const double[:, ::1] samples, const double[:, ::1] extent,
                               Py_ssize_t i, double res, long* lo, long* hi) noexcept nogil:
    """The keys whose centre ``(key - 32768 + 0.5) res`` lies in sample i's support box."""
    cdef int a
    for a in range(3):
        lo[a] = max(<long>ceil((samples[i, a] - extent[i, a]) / res - 0.5) + _MAX_VAL, 0)
        hi[a] = min(<long>floor((samples[i, a] + extent[i, a]) / res - 0.5) + _MAX_VAL,
                    2 * _MAX_VAL - 1)


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


@cython.auto_pickle(False)
cdef class _KernelCells:
    """Beta evidence on hashed cells. Use :class:`occgp.BGKMap` or :class:`occgp.AKIMap`."""

    cdef BetaTable _cells
    cdef double _res
    cdef object _lock
    cdef vector[Beta] _box          # an update's evidence over its key box, zero between
    cdef vector[uint64_t] _touched  # box indices with evidence
    cdef bint _box_dirty            # an exception left _box / _touched non-zero

    def __cinit__(self, *args, **kwargs):
        self._lock = threading.Lock()
        self._res = 0.0

    def _setup(self, double resolution):
        with self._lock:
            self._cells.reset(16)
            self._res = resolution

    def _accumulate(self, const double[:, ::1] samples, const double[::1] labels,
                    const double[:, :, ::1] precision, const double[:, ::1] extent,
                    const double[::1] weights, double sf2):
        """Add the evidence of each sample to the cells its support reaches.

        `precision[i]` is the inverse bandwidth matrix of sample i, `extent[i]`
        the half-size of its support's bounding box per axis (metres),
        `weights[i]` its weight. The evidence is first summed over the update's
        key box (a dense array, when the box has at most 2^22 cells), then
        added to the hashed cells once per cell. Returns the number of
        (sample, cell) contributions.
        """
        cdef Py_ssize_t i, n = samples.shape[0]
        cdef long kx, ky, kz
        cdef long lo[3]
        cdef long hi[3]
        cdef long box_lo[3]
        cdef long box_hi[3]
        cdef uint64_t dims[3]
        cdef uint64_t idx, row, box_cells = 1
        cdef int a
        cdef double d[3]
        cdef double r2, k, y, res = self._res, qb, qc, disc, p00
        cdef long updates = 0, row_lo, row_hi
        cdef bint dense
        cdef Beta* cell
        cdef BetaCell* stored
        cdef size_t j
        if n == 0:
            return 0
        with self._lock:
            with nogil:
                for a in range(3):
                    box_lo[a] = 2 * _MAX_VAL
                    box_hi[a] = -1
                for i in range(n):
                    _support_keys(samples, extent, i, res, lo, hi)
                    for a in range(3):
                        box_lo[a] = min(box_lo[a], lo[a])
                        box_hi[a] = max(box_hi[a], hi[a])
                for a in range(3):
                    dims[a] = <uint64_t>max(box_hi[a] - box_lo[a] + 1, 0)
                    box_cells *= dims[a]
                dense = 0 < box_cells <= _MAX_DENSE
                if self._box_dirty:
                    self._box.assign(self._box.size(), Beta(0.0, 0.0))
                    self._touched.clear()
                if dense and self._box.size() < box_cells:
                    self._box.resize(box_cells)
                self._box_dirty = True
                for i in range(n):
                    _support_keys(samples, extent, i, res, lo, hi)
                    y = labels[i]
                    for kz in range(lo[2], hi[2] + 1):
                        d[2] = (<double>(kz - _MAX_VAL) + 0.5) * res - samples[i, 2]
                        for ky in range(lo[1], hi[1] + 1):
                            d[1] = (<double>(ky - _MAX_VAL) + 0.5) * res - samples[i, 1]
                            row = ((<uint64_t>(kz - box_lo[2]) * dims[1]
                                    + <uint64_t>(ky - box_lo[1])) * dims[0])
                            # the row's cells inside the ellipsoid: r2 is quadratic in d[0];
                            # widened by a cell each way, the test below decides
                            qb = (0.5 * (precision[i, 0, 1] + precision[i, 1, 0]) * d[1]
                                  + 0.5 * (precision[i, 0, 2] + precision[i, 2, 0]) * d[2])
                            qc = (precision[i, 1, 1] * d[1] * d[1]
                                  + (precision[i, 1, 2] + precision[i, 2, 1]) * d[1] * d[2]
                                  + precision[i, 2, 2] * d[2] * d[2])
                            disc = qb * qb - precision[i, 0, 0] * (qc - 1.0)
                            if not disc > 0.0:
                                continue
                            disc = sqrt(disc)
                            row_lo = max(lo[0], <long>floor(
                                (samples[i, 0] + (-qb - disc) / precision[i, 0, 0]) / res
                                - 0.5) + _MAX_VAL)
                            row_hi = min(hi[0], <long>ceil(
                                (samples[i, 0] + (-qb + disc) / precision[i, 0, 0]) / res
                                - 0.5) + _MAX_VAL)
                            p00 = precision[i, 0, 0]
                            for kx in range(row_lo, row_hi + 1):
                                d[0] = (<double>(kx - _MAX_VAL) + 0.5) * res - samples[i, 0]
                                r2 = (p00 * d[0] + 2.0 * qb) * d[0] + qc
                                if not r2 < 1.0:
                                    continue
                                k = sf2 * weights[i] * _kernel_r2(r2)
                                if k <= 0.0:
                                    continue
                                if dense:
                                    idx = row + <uint64_t>(kx - box_lo[0])
                                    cell = &self._box[idx]
                                    if cell.alpha == 0.0 and cell.beta == 0.0:
                                        self._touched.push_back(idx)
                                    cell.alpha += k * y
                                    cell.beta += k * (1.0 - y)
                                else:
                                    stored = self._cells.get(_pack(kx, ky, kz))
                                    stored.alpha += <float>(k * y)
                                    stored.beta += <float>(k * (1.0 - y))
                                updates += 1
                for j in range(self._touched.size()):
                    idx = self._touched[j]
                    kx = box_lo[0] + <long>(idx % dims[0])
                    ky = box_lo[1] + <long>((idx // dims[0]) % dims[1])
                    kz = box_lo[2] + <long>(idx // (dims[0] * dims[1]))
                    stored = self._cells.get(_pack(kx, ky, kz))
                    stored.alpha += <float>self._box[idx].alpha
                    stored.beta += <float>self._box[idx].beta
                    self._box[idx].alpha = 0.0
                    self._box[idx].beta = 0.0
                self._touched.clear()
                self._box_dirty = False
        return updates

    def _query(self, const double[:, ::1] points, double prior, int what):
        """Per point: 0 -> posterior mean of occupancy, 1 -> its variance (NaN where no
        kernel ever reached the point's cell)."""
        cdef Py_ssize_t i, n = points.shape[0]
        out = np.full(n, np.nan)
        cdef double[::1] o = out
        cdef long key[3]
        cdef int a
        cdef bint inside
        cdef double s, res = self._res, al, be
        cdef BetaCell* found
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
                    found = self._cells.find(_pack(key[0], key[1], key[2]))
                    if found == NULL:
                        continue
                    al = found.alpha + prior
                    be = found.beta + prior
                    if what == 0:
                        o[i] = al / (al + be)
                    else:
                        o[i] = al * be / ((al + be) * (al + be) * (al + be + 1.0))
        return out

    def _cells_arrays(self):
        """(keys uint16 (n, 3), alpha, beta) of every cell, in no particular order."""
        cdef Py_ssize_t n
        with self._lock:
            n = self._cells.size()
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
        with nogil:
            for slot in range(self._cells.capacity()):
                packed = self._cells.slot(slot).key
                if packed == EMPTY_KEY:
                    continue
                keys[j, 0] = <uint16_t>(packed & 0xFFFF)
                keys[j, 1] = <uint16_t>((packed >> 16) & 0xFFFF)
                keys[j, 2] = <uint16_t>((packed >> 32) & 0xFFFF)
                alpha[j] = self._cells.slot(slot).alpha
                beta[j] = self._cells.slot(slot).beta
                j += 1

    def _set_cells(self, const uint16_t[:, ::1] keys, const double[::1] alpha,
                   const double[::1] beta):
        """Replace the cells (for unpickling)."""
        cdef Py_ssize_t j
        cdef BetaCell* stored
        with self._lock:
            self._cells.reset(keys.shape[0])
            with nogil:
                for j in range(keys.shape[0]):
                    stored = self._cells.get(_pack(keys[j, 0], keys[j, 1], keys[j, 2]))
                    stored.alpha = <float>alpha[j]
                    stored.beta = <float>beta[j]

    def _num_cells(self):
        return self._cells.size()
