"""The spatial cells of GPOMIK: local GPs, their split by median bisection, their
tile-by-tile prediction and the KL gain of active sampling."""

from __future__ import annotations

import numpy as np
import scipy.linalg as sl
from scipy.linalg import lapack

from .. import _integral
from ._integral_kernel import covariance
from ._observations import Observations

__all__ = ["Cell", "spatial_groups", "kl_gain", "predict_cell", "downdated_cell", "TILE",
           "BLOCK_ENTRIES"]

#: Edge of the query tiles of predict, in length scales.
TILE = 4.0
#: Most cross-covariance entries computed in one call of predict (64 MB).
BLOCK_ENTRIES = 8_000_000


def distance_to_segments(x, A, B):
    """Distance from point `x` to each segment A[i]-B[i] (points when A[i] == B[i])."""
    d = B - A
    dd = np.einsum("ij,ij->i", d, d)
    t = np.clip(np.einsum("ij,ij->i", x - A, d) / np.where(dd > 0, dd, 1.0), 0.0, 1.0)
    return np.linalg.norm(A + t[:, None] * d - x, axis=1)


class Cell:
    """One local GP: its observations, Cholesky factor and ``alpha = K^-1 y``."""

    def __init__(self, obs: Observations, L, alpha):
        self.obs = obs
        self.L = L
        self.alpha = alpha
        self.kinv = None  # K^-1, computed by the first predict that needs it

    @property
    def size(self) -> int:
        """Number of observations."""
        return len(self.obs.y)

    @property
    def nbytes(self) -> int:
        """Bytes of the cell's arrays (observations, factor, alpha, and K^-1 once computed)."""
        arrays = [*self.obs, self.L, self.alpha] + ([] if self.kinv is None else [self.kinv])
        return int(sum(a.nbytes for a in arrays))

    def inverse(self):
        """``K^-1`` (noise included), computed once from the factor and kept.

        LAPACK's ``dpotri`` (the inverse from the Cholesky factor, two thirds
        of ``n^3`` operations) fills one triangle; the other is mirrored.
        """
        if self.kinv is None:
            inv, info = lapack.dpotri(self.L, lower=1)
            if info != 0:
                raise np.linalg.LinAlgError(f"the inverse of a local model of {self.size} "
                                            f"observations failed (dpotri info {info})")
            inv = np.tril(inv)
            self.kinv = inv + np.tril(inv, -1).T
        return self.kinv

    def bounds(self, margin):
        """The box of the observations widened by `margin`: (low corner, high corner)."""
        pts = np.vstack([self.obs.starts, self.obs.ends])
        return pts.min(axis=0) - margin, pts.max(axis=0) + margin


def kl_gain(var, mu, y, noise):
    """KL(after || before) of a latent N(mu, var) conditioned on target y with `noise`."""
    var_after = var * noise / (var + noise)
    shift = var / (var + noise) * (y - mu)
    return 0.5 * (np.log(var / var_after) + (var_after + shift ** 2) / var - 1.0)


def spatial_groups(anchors, max_size, is_hit=None):
    """Split indices into groups of at most `max_size` by median bisection of `anchors`.

    A group larger than `max_size` is cut in two at the median of its
    anchors along its longest axis, and so on until every group fits.

    With `is_hit` (bool, one per anchor: a hit or a beam) the groups are the
    experts of :class:`~occgp.gp.GPMixture`, and a cut falls only between
    distinct coordinates along its axis (anchors at one place stay together)
    and only where both halves keep a hit and a beam (an expert needs both
    for its classifier): the allowed cut nearest the median along the
    longest axis, or along the next longest where that axis has none. A
    group that no cut splits so stays whole, larger than `max_size`.
    """
    todo, done = [np.arange(len(anchors))], []
    while todo:
        idx = todo.pop()
        if len(idx) <= max_size:
            done.append(idx)
            continue
        pts = anchors[idx]
        extent = np.ptp(pts, axis=0)
        if is_hit is None:
            axis = int(np.argmax(extent))
            order = idx[np.argsort(pts[:, axis], kind="stable")]
            half = len(order) // 2
            todo += [order[half:], order[:half]]
            continue
        for axis in np.argsort(-extent, kind="stable"):
            sort = np.argsort(pts[:, axis], kind="stable")
            cut = _class_cut(pts[sort, axis], is_hit[idx[sort]])
            if cut is not None:
                order = idx[sort]
                todo += [order[cut:], order[:cut]]
                break
        else:
            done.append(idx)
    return done


def _class_cut(coord, hit):
    """The cut ``k`` of sorted `coord` nearest ``len // 2`` with ``coord[k - 1] < coord[k]``
    and a True and a False of `hit` on each side (``hit[:k]``, ``hit[k:]``); None if none."""
    hits, beams = np.flatnonzero(hit), np.flatnonzero(~hit)
    if not (len(hits) and len(beams)):
        return None
    lo, hi = max(hits[0], beams[0]) + 1, min(hits[-1], beams[-1])
    cuts = np.flatnonzero(coord[1:] > coord[:-1]) + 1
    cuts = cuts[(cuts >= lo) & (cuts <= hi)]
    if not len(cuts):
        return None
    return int(cuts[np.argmin(np.abs(cuts - len(coord) // 2))])


def predict_cell(cell, X, kernel, quadrature, n_threads, return_var):
    """Mean (and variance) of one cell at `X`, tile by tile.

    Queries beyond the kernel's reach (its cutoff) of the cell's box get
    the prior, as the tiles would give them. The others are grouped into
    square tiles of `TILE` (4) length scales; a tile
    only meets the observations that come within the kernel's cutoff of
    it (the other entries of its cross-covariance are exactly 0), so each
    tile solves a small dense problem: ``mean = k_S . alpha_S`` and
    ``var = k(x, x) - k_S^T [K^-1]_SS k_S``. The blocks of many tiles are
    computed in one parallel call, then the products run tile by tile.
    """
    n_dims = X.shape[1]
    inv = kernel.inverse_length_scales(n_dims)
    reach = np.sqrt(type(kernel).cutoff2)
    lo, hi = cell.bounds(reach / inv)
    inside = np.all((X >= lo) & (X <= hi), axis=1)
    if not inside.all():  # beyond the kernel's reach of every observation: the prior
        mean = np.zeros(len(X))
        var = np.full(len(X), float(kernel.variance)) if return_var else None
        if inside.any():
            m, v = predict_cell(cell, X[inside], kernel, quadrature, n_threads, return_var)
            mean[inside] = m
            if return_var:
                var[inside] = v
        return mean, var
    mean = np.empty(len(X))
    var = np.empty(len(X)) if return_var else None
    if not len(X):
        return mean, var
    kinv = cell.inverse() if return_var else None
    Xs = np.ascontiguousarray(X * inv)
    A = np.ascontiguousarray(cell.obs.starts * inv)
    V = np.ascontiguousarray((cell.obs.ends - cell.obs.starts) * inv)
    lengths = np.ascontiguousarray(cell.obs.lengths)
    keys = np.floor(Xs / TILE).astype(np.int64)
    _, tile_of, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    rows = np.argsort(tile_of.ravel(), kind="stable").astype(np.intp)
    row_ptr = np.r_[0, np.cumsum(counts)].astype(np.intp)
    half_diag = 0.5 * TILE * np.sqrt(n_dims)
    near = [np.flatnonzero(distance_to_segments((keys[rows[row_ptr[t]]] + 0.5) * TILE, A, A + V)
                           <= reach + half_diag) for t in range(len(counts))]
    sizes = counts * np.array([len(n) for n in near])
    nodes, weights, offsets, q_reach = quadrature.table(kernel)
    prior, variance = float(kernel.variance), float(kernel.variance)
    t0 = 0
    while t0 < len(counts):  # chunks of tiles whose blocks fit in BLOCK_ENTRIES
        t1 = t0 + max(1, int(np.searchsorted(np.cumsum(sizes[t0:]), BLOCK_ENTRIES)))
        cols = np.concatenate(near[t0:t1]).astype(np.intp)
        col_ptr = np.r_[0, np.cumsum([len(n) for n in near[t0:t1]])].astype(np.intp)
        out_ptr = np.r_[0, np.cumsum(sizes[t0:t1])].astype(np.intp)
        out = np.empty(int(out_ptr[-1]))
        _integral.tile_covariance(
            type(kernel).kind, float(type(kernel).cutoff2), Xs, A, V, lengths,
            rows[row_ptr[t0]:row_ptr[t1]], row_ptr[t0:t1 + 1] - row_ptr[t0], cols, col_ptr,
            out_ptr, nodes, weights, offsets, q_reach, out, n_threads)
        for t in range(t0, t1):
            q = rows[row_ptr[t]:row_ptr[t + 1]]
            Ks = variance * out[out_ptr[t - t0]:out_ptr[t - t0 + 1]].reshape(len(q), -1)
            mean[q] = Ks @ cell.alpha[near[t]]
            if return_var:
                quad = np.einsum("ij,ij->i", Ks @ kinv[np.ix_(near[t], near[t])], Ks)
                var[q] = np.maximum(prior - quad, 0.0)
        t0 = t1
    return mean, var


def downdated_cell(cell, kernel, quadrature, n_threads, X, pos):
    """Latent mean and variance of `cell` at X[j] without its observation pos[j].

    With ``c = C^-1 k_x`` the removal of observation ``i`` is a rank-one
    downdate: ``mean - c_i alpha_i / [C^-1]_ii`` and ``var + c_i^2 / [C^-1]_ii``.
    From the factor ``C = L L^T``: ``v = L^-1 k_x`` gives the variance and
    ``c = L^-T v``, and ``[C^-1]_ii = |L^-1 e_i|^2`` (``C^-1`` is never formed).
    """
    k = covariance(kernel, quadrature, cell.obs.starts, cell.obs.ends, X, X,
                   n_threads=n_threads)
    v = sl.solve_triangular(cell.L, k, lower=True, check_finite=False)
    c = sl.solve_triangular(cell.L, v, lower=True, trans="T", check_finite=False)
    unit = np.zeros((cell.size, len(pos)))
    unit[pos, np.arange(len(pos))] = 1.0
    e = sl.solve_triangular(cell.L, unit, lower=True, check_finite=False)
    mean = k.T @ cell.alpha
    var = float(kernel.variance) - np.einsum("ij,ij->j", v, v)
    ci = c[pos, np.arange(len(pos))]
    d = np.einsum("ij,ij->j", e, e)
    return mean - ci * cell.alpha[pos] / d, np.maximum(var, 0.0) + ci * ci / d
