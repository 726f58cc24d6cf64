"""The most similar returning beam of each free beam under the line integral kernel, for
:func:`occgp.gp._beams.beam_sources` (Kim & Kim 2022, §3.1.1): candidates from a
k-d tree of beam midpoints, pruned by an upper bound on the similarity, then exact
kernel evaluations in chunks."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree
from scipy.special import erf, erfc

from ._clustering import best_per_row, segment_distance
from ._integral_kernel import covariance
from ._kernels import SquaredExponential

__all__ = ["most_similar"]

#: Free beams per kernel evaluation (one ``covariance`` call against the union
#: of their candidates); consecutive beams share most candidates.
_CHUNK = 32
#: Most balls covering the strip of one free beam (see _candidates).
_MAX_BALLS = 256
#: Nearest returning beams (by midpoint) that give each free beam its first
#: similarity bound.
_FIRST_CANDIDATES = 8


def _reach_table(kernel):
    """(s, f(s)): the kernel's profile on squared scaled distances up to its cutoff."""
    cutoff2 = float(type(kernel).cutoff2)
    s = np.linspace(0.0, cutoff2, 4097)
    return s, kernel._profile(s)


def _reach(value, table):
    """Scaled distance beyond which the profile is below `value` (a safe over-estimate)."""
    s, f = table
    count = np.searchsorted(-f, -value, side="right")       # grid points with f >= value
    return np.sqrt(s[np.minimum(count, len(s) - 1)])


def _pairs(tree, centers, radii):
    """(row, column) pairs of the tree's points within `radii` of each center."""
    if not len(centers):
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    found = cKDTree(centers).sparse_distance_matrix(tree, float(np.max(radii)),
                                                     output_type="ndarray")
    keep = found["v"] <= radii[found["i"]]
    return found["i"][keep].astype(np.int64), found["j"][keep].astype(np.int64)


def _erf_diff(a, b):
    """``erf(b) - erf(a)`` for ``a <= b``, without cancellation in the tails."""
    return np.where(a >= 0, erfc(a) - erfc(b),
                    np.where(b <= 0, erfc(-b) - erfc(-a), erf(b) - erf(a)))


def _line_mean(x0, x1, y0, y1):
    """Upper bound of the mean over segment x of ``exp(-h^2 / 2)``, h the distance to line y.

    With ``h(u)^2 = A u^2 + 2 B u + C`` along x (u in [0, 1]) the mean is an erf
    difference; for a segment (nearly) parallel to the line, or a point,
    ``exp(-min h^2 / 2)``. Coordinates are scaled (unit length scale).
    """
    v = y1 - y0
    length = np.linalg.norm(v, axis=1)
    u = v / np.where(length > 0, length, 1.0)[:, None]
    a = x0 - y0
    a -= np.einsum("ij,ij->i", a, u)[:, None] * u
    b = x1 - x0
    b -= np.einsum("ij,ij->i", b, u)[:, None] * u
    A = np.einsum("ij,ij->i", b, b)
    B = np.einsum("ij,ij->i", a, b)
    C = np.einsum("ij,ij->i", a, a)
    # the least h^2 on [0, 1]: at the vertex of the (convex) quadratic, clamped
    vertex = np.where(A > 0, np.clip(-B / np.where(A > 0, A, 1.0), 0.0, 1.0), 0.0)
    h2_min = np.maximum(C + 2.0 * B * vertex + A * vertex ** 2, 0.0)
    curved = A > 1e-8
    As = np.where(curved, A, 1.0)
    r = np.sqrt(As / 2.0)
    with np.errstate(under="ignore"):
        exact = np.exp(-0.5 * np.maximum(C - B * B / As, 0.0)) * np.sqrt(np.pi / (2.0 * As)) \
            * _erf_diff(r * B / As, r * (1.0 + B / As))
    return np.where(curved, np.minimum(exact, np.exp(-0.5 * h2_min)), np.exp(-0.5 * h2_min))


def _upper_bound(kernel, table, line_integral, fs, fe, rs, re, dist):
    """Upper bound of the (length-normalised) similarity of segment pairs, scaled coordinates.

    Every kernel: ``f(d^2)`` at the closest approach ``d``, and
    ``I1 / (longer length)`` with ``I1`` the kernel's integral along a line.
    The squared exponential also factorises along a line, which bounds the
    similarity by the mean of ``sqrt(2 pi) exp(-h^2 / 2)`` over one segment
    (h its distance to the other's line) over the other's length, both ways.
    """
    s, f = table
    # the profile at the table point just below d^2: an over-estimate (f decreases)
    profile = f[np.maximum(np.searchsorted(s, dist * dist, side="right") - 1, 0)]
    f_len, r_len = np.linalg.norm(fe - fs, axis=1), np.linalg.norm(re - rs, axis=1)
    longer = np.maximum(f_len, r_len)
    with np.errstate(divide="ignore"):
        bound = np.minimum(profile, np.where(longer > 0, line_integral / longer, np.inf))
        if isinstance(kernel, SquaredExponential):
            root = np.sqrt(2.0 * np.pi)
            to_r = np.where(r_len > 0, root * _line_mean(fs, fe, rs, re) / r_len, np.inf)
            to_f = np.where(f_len > 0, root * _line_mean(rs, re, fs, fe) / f_len, np.inf)
            bound = np.minimum(bound, np.minimum(to_r, to_f))
    # slack for rounding in the bounds and in the kernel's own evaluation
    return float(kernel.variance) * (bound * (1.0 + 1e-6) + 1e-300)


def _candidates(tree, f_mid, f_half, fs, fe, r_half_max, radius, value):
    """(row, returning beam) pairs that may come within `radius` of each free beam.

    Those whose midpoint is within ``f_half + r_half_max + radius`` of the
    free beam's midpoint (a k-d tree ball). For the squared exponential with a
    similarity ``value`` (over the variance) to beat, the line bound of
    :func:`_upper_bound` says more: with ``c = value * length / sqrt(2 pi)``
    above 1/2, ``exp(-h^2 / 2) >= 2 c - 1`` on at least half of a candidate
    (h: the distance to the free beam's line, convex along it), so its
    midpoint lies within ``w = sqrt(-2 log(2 c - 1))`` of that line: a strip
    of half-width `w` along the free beam extended by ``radius + r_half_max``
    at both ends, covered by balls along its axis.
    """
    length = 2.0 * f_half
    disc = np.ones(len(f_mid), dtype=bool)
    parts = []
    if value is not None:
        c = value * length / np.sqrt(2.0 * np.pi)
        strip = (c > 0.5) & (length > 0)
        disc = ~strip
        rows = np.flatnonzero(strip)
        if len(rows):
            w = np.sqrt(-2.0 * np.log(np.minimum(2.0 * c[rows] - 1.0, 1.0)))
            extend = radius[rows] + r_half_max
            span = length[rows] + 2.0 * extend
            step = np.maximum(w, span / _MAX_BALLS)
            m = np.ceil(span / step).astype(np.int64) + 1
            owner = np.repeat(np.arange(len(rows)), m)
            first = np.cumsum(m) - m
            t = (np.arange(len(owner)) - first[owner]) * step[owner] - extend[owner]
            u = (fe[rows] - fs[rows]) / length[rows, None]
            centers = fs[rows][owner] + t[:, None] * u[owner]
            ball = np.sqrt(w ** 2 + (0.5 * step) ** 2)[owner]
            k, j = _pairs(tree, centers, ball)
            key = np.unique(rows[owner[k]] * len(tree.data) + j)
            parts.append((key // len(tree.data), key % len(tree.data)))
    rows = np.flatnonzero(disc)
    if len(rows):
        i, j = _pairs(tree, f_mid[rows], f_half[rows] + r_half_max + radius[rows])
        parts.append((rows[i], j))
    if not parts:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])


def most_similar(kernel, quadrature, fs, fe, rs, re, n_threads):
    """Index of the returning beam (rs, re) most similar to each free beam (fs, fe)."""
    inv = kernel.inverse_length_scales(fs.shape[1])
    variance = float(kernel.variance)
    table = _reach_table(kernel)
    cutoff = float(np.sqrt(type(kernel).cutoff2))
    r_grid = np.sqrt(table[0])
    line_integral = 1.01 * 2.0 * float(np.sum(0.5 * (table[1][1:] + table[1][:-1])
                                             * np.diff(r_grid)))
    f_len, r_len = np.linalg.norm(fe - fs, axis=1), np.linalg.norm(re - rs, axis=1)
    f_norm, r_norm = np.where(f_len > 0, f_len, 1.0), np.where(r_len > 0, r_len, 1.0)

    def similarity(rows, cols):
        return covariance(kernel, quadrature, fs[rows], fe[rows], rs[cols], re[cols],
                           n_threads=n_threads) / (f_norm[rows, None] * r_norm[None, cols])

    # pruning geometry in scaled coordinates
    fs_s, fe_s, rs_s, re_s = fs * inv, fe * inv, rs * inv, re * inv
    f_mid, r_mid = 0.5 * (fs_s + fe_s), 0.5 * (rs_s + re_s)
    f_half = 0.5 * np.linalg.norm(fe_s - fs_s, axis=1)
    r_half = 0.5 * np.linalg.norm(re_s - rs_s, axis=1)
    r_half_max = float(r_half.max())
    tree = cKDTree(r_mid)
    squared_exp = isinstance(kernel, SquaredExponential)
    k0 = min(_FIRST_CANDIDATES, len(rs))
    best = np.full(len(fs), -1, dtype=np.int64)
    for lo in range(0, len(fs), _CHUNK):
        rows = np.arange(lo, min(lo + _CHUNK, len(fs)))
        # 1. a first similarity from the nearest midpoints
        _, nn = tree.query(f_mid[rows], k=k0)
        first = np.unique(nn)
        S_first = similarity(rows, first)
        value = S_first.max(axis=1)
        col = first[np.argmax(S_first, axis=1)]
        # 2. every returning beam whose bound reaches that similarity
        radius = np.where(value > 0, np.minimum(_reach(value / variance, table), cutoff), cutoff)
        i, j = _candidates(tree, f_mid[rows], f_half[rows], fs_s[rows], fe_s[rows],
                           r_half_max, radius, value / variance if squared_exp else None)
        gap = np.linalg.norm(f_mid[rows[i]] - r_mid[j], axis=1) - f_half[rows[i]] - r_half[j]
        keep = gap <= radius[i]
        i, j = i[keep], j[keep]
        d = segment_distance(fs_s[rows[i]], fe_s[rows[i]], rs_s[j], re_s[j])
        keep = d <= radius[i]
        i, j, d = i[keep], j[keep], d[keep]
        keep = _upper_bound(kernel, table, line_integral, fs_s[rows[i]], fe_s[rows[i]],
                            rs_s[j], re_s[j], d) >= np.where(value[i] > 0, value[i], 1e-300)
        i, j = i[keep], j[keep]
        if len(i):
            # 3. exact similarities of the survivors: one call for the chunk when the
            # rows share their candidates, one per row otherwise
            cols = np.unique(j)
            if len(cols) * len(rows) <= 2 * len(i):
                S = similarity(rows, cols)[i, np.searchsorted(cols, j)]
            else:
                order = np.argsort(i, kind="stable")
                i, j = i[order], j[order]
                bounds = np.searchsorted(i, np.arange(len(rows) + 1))
                S = np.concatenate([similarity(rows[a:a + 1], j[bounds[a]:bounds[a + 1]])[0]
                                    for a in range(len(rows)) if bounds[a + 1] > bounds[a]])
            # the best per row (ties: the lowest index), against the first pass
            i = np.r_[i, np.arange(len(rows))]
            j = np.r_[j, col]
            S = np.r_[S, value]
            _, col, value = best_per_row(i, j, -S)       # every row is present
            value = -value
        best[rows] = np.where(value > 0, col, -1)
    lost = np.flatnonzero(best < 0)
    if len(lost):
        best[lost] = _nearest_segment(fs[lost], fe[lost], rs, re)
    return best


def _nearest_segment(fs, fe, rs, re):
    """Index of the segment (rs, re) nearest to each segment (fs, fe); ties: lowest."""
    r_mid = 0.5 * (rs + re)
    r_half_max = 0.5 * float(np.linalg.norm(re - rs, axis=1).max())
    f_mid, f_half = 0.5 * (fs + fe), 0.5 * np.linalg.norm(fe - fs, axis=1)
    tree = cKDTree(r_mid)
    _, nn = tree.query(f_mid, k=1)
    bound = segment_distance(fs, fe, rs[nn], re[nn])
    # any nearer segment has its midpoint within bound + both half-lengths
    i, j = _pairs(tree, f_mid, bound + f_half + r_half_max + 1e-12 * (1 + bound))
    rows, picks, _ = best_per_row(i, j, segment_distance(fs[i], fe[i], rs[j], re[j]))
    out = nn.astype(np.int64)
    out[rows] = picks
    return out
