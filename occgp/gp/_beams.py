"""Clusters of beams for the mixture of GP experts (Kim & Kim 2022, §3.1.1).

Hits are clustered first (:mod:`occgp.gp._clustering`); :func:`assign_beams`
then gives each beam a cluster (its hit's, or that of the most similar
returning beam under the line integral kernel) and :func:`merge_small_clusters`
folds clusters that could not train a classifier into their nearest neighbour.
:func:`match_beams` finds the hit of each beam, in either convention: beams
ending at their hits (occgp's) or stopping short of them (the integral-kernel
paper's).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree
from scipy.special import erf, erfc

from .._validation import as_numeric, as_points, check_int, check_real
from ._clustering import best_per_row, segment_distance
from ._integral_kernel import check_kernel, check_quadrature, covariance, as_segments
from ._kernels import SquaredExponential
from ._limits import check_coordinates, check_segments, threads
from ._observations import check_beam_hits

__all__ = ["assign_beams", "beam_sources", "merge_small_clusters", "match_beams", "match_call",
           "no_return_error", "HIT_TOLERANCE"]

#: Default of how far (metres) beyond a beam's end its hit may lie
#: (:func:`match_beams`): a beam that stops short of its return by up to one
#: 0.1 m map cell still finds it. The hit must also lie on the beam's ray
#: (up to rounding), so a wider window rarely matches a wrong hit.
HIT_TOLERANCE = 0.1
#: Relative rounding allowed in "the hit lies on the beam's ray": a distance
#: off the ray (and a step back from the end) of at most
#: ``_ON_RAY * (1 + |coordinates| + distance from the sensor)``.
_ON_RAY = 1e-6

#: Most (beam, hit) pairs :func:`match_beams` examines at once (about 200 bytes
#: each at peak: at most 60 MB whatever the tolerance).
_PAIR_BUDGET = 2**18
#: Length (metres) of the sections of a beam's capsule :func:`match_beams`
#: searches at a time, nearest first ...
_SECTION = HIT_TOLERANCE
#: ... and the most sections of a capsule (longer sections beyond).
_MAX_SECTIONS = 64

#: Free beams per kernel evaluation (one ``covariance`` call against the union
#: of their candidates); consecutive beams share most candidates.
_CHUNK = 32
#: Most balls covering the strip of one free beam (see _candidates).
_MAX_BALLS = 256
#: Nearest returning beams (by midpoint) that give each free beam its first
#: similarity bound.
_FIRST_CANDIDATES = 8


def _as_labels(labels, name, n=None):
    arr = as_numeric(labels, name, kinds="iufb")
    if arr.dtype.kind not in "iu":
        raise TypeError(f"{name} must hold integers, got dtype {arr.dtype}")
    if arr.ndim != 1 or (n is not None and len(arr) != n):
        want = "(n,)" if n is None else f"({n},)"
        raise ValueError(f"{name} must have shape {want}, got {arr.shape}")
    arr = arr.astype(np.int64)
    if len(arr) and arr.min() < 0:
        raise ValueError(f"{name} must be non-negative, got {int(arr.min())}")
    return arr


def row_index(rows, table):
    """Index of the first row of `table` equal to each row of `rows` (-1: none)."""
    out = np.full(len(rows), -1, dtype=np.int64)
    if not len(table) or not len(rows):
        return out
    key = np.dtype((np.void, 8 * table.shape[1]))
    t = np.ascontiguousarray(table + 0.0).view(key).ravel()    # + 0.0: -0.0 equals 0.0
    r = np.ascontiguousarray(rows + 0.0).view(key).ravel()
    unique, first = np.unique(t, return_index=True)             # stable: first occurrence
    pos = np.minimum(np.searchsorted(unique, r), len(unique) - 1)
    found = unique[pos] == r
    out[found] = first[pos[found]]
    return out


def match_beams(hits: ArrayLike, segment_starts: ArrayLike, segment_ends: ArrayLike, *,
                hit_tolerance: float = HIT_TOLERANCE,
                beam_hits: ArrayLike | None = None) -> NDArray[np.int64]:
    """The hit of each beam (its return), or -1 for a beam without one.

    Two conventions are recognised, beam by beam:

    * **exact** (occgp's, :func:`observations_from_scans` by default): the
      beam ends exactly on its hit (row equality; of coinciding hits, the
      first counts);
    * **stopped short** (the integral-kernel paper's: the free segment ends
      before the return, so that the hit's cell is not observed free): a
      beam that ends on no hit takes the hit that lies on its ray, from the
      start through the end, at most `hit_tolerance` beyond its end. "On the
      ray" allows for rounding: a distance off the ray, or a step back from
      the end, of at most ``1e-6 * (1 + |coordinates| + distance from the
      start)``. Of several such hits the nearest along the ray counts, then
      the lowest index. A hit that is exactly some beam's end is taken by
      that beam and is no candidate here, so data in the exact convention
      matches exactly as before; a zero-length beam (a return closer than
      the margin) matches only exactly.

    The search is vectorised and its memory bounded whatever
    `hit_tolerance`: a k-d tree of the hits is queried along each beam's
    ray beyond its end, in sections of 0.1 m (at most 64 sections), nearest
    first, and a beam stops at the first section that holds a candidate; the
    (beam, hit) pairs within reach of a section are examined at most 2**18 at
    a time. Beyond arrays the size of the input, it holds under 48 MB (about
    140 bytes a pair): 20,000 beams from a sensor, half stopping 5 cm short
    of their hits, at ``hit_tolerance=5`` take 6 MB and 0.1 s, where pairing
    every end with every hit within the tolerance took 7.7 GB and 23 s. The
    answer is that of testing every hit against every beam.

    Parameters
    ----------
    hits : array-like of shape (n_hits, D)
        The hits, D in 1..3.
    segment_starts, segment_ends : array-like of shape (n_beams, D)
        The beams, from the sensor to (or short of) the return, or to the
        maximum range.
    hit_tolerance : float, default=0.1
        Farthest (metres, >= 0) a hit may lie beyond the end of its beam;
        0 matches only beams ending on their hits (up to rounding).
    beam_hits : array-like of int of shape (n_beams,), default=None
        The answer, given: each beam's hit index, or -1 for no return. It
        replaces the search (and is returned, checked). Several beams may
        name one hit.

    Returns
    -------
    beam_hits : ndarray of shape (n_beams,), dtype int64
        Index into `hits` of each beam's hit, -1 where it has none.

    Raises
    ------
    ValueError
        On NaN or inf, wrong shapes, a negative or infinite `hit_tolerance`,
        or `beam_hits` of the wrong shape or with an entry outside
        ``-1..n_hits-1``.
    TypeError
        On non-numeric data, a `hit_tolerance` that is not a real number, or
        `beam_hits` that are not integers.

    Examples
    --------
    Beam 0 ends on hit 1, beam 1 stops 5 cm short of hit 0, beam 2 has no
    return:

    >>> import numpy as np
    >>> hits = np.array([[2.0, 0.0], [0.0, 2.0]])
    >>> starts = np.zeros((3, 2))
    >>> ends = np.array([[0.0, 2.0], [1.95, 0.0], [-3.0, 0.0]])
    >>> match_beams(hits, starts, ends).tolist()
    [1, 0, -1]
    """
    hit_tolerance = check_real(hit_tolerance, "hit_tolerance", low=0.0, low_open=False)
    arr = as_numeric(hits, "hits")
    if arr.ndim != 2 or not 1 <= arr.shape[1] <= 3:
        raise ValueError(f"hits must have shape (n_hits, D) with D in 1..3, got {arr.shape}")
    hits = as_points(arr, "hits", arr.shape[1])
    starts, ends = as_segments(segment_starts, segment_ends, "segment", dim=hits.shape[1])
    if beam_hits is not None:
        return check_beam_hits(beam_hits, len(ends), len(hits))
    return _match(hits, starts, ends, hit_tolerance)


def _match(hits, starts, ends, tolerance):
    """:func:`match_beams` on checked arrays, without `beam_hits`.

    Each free beam's candidates lie in its capsule: within ``slack`` of its ray,
    from ``slack`` before its end to ``tolerance + slack`` beyond. The capsule is
    cut into at most :data:`_MAX_SECTIONS` sections along the ray, searched
    nearest first, each with the ball around it (:func:`_bounded_pairs`: at most
    :data:`_PAIR_BUDGET` pairs at a time); a beam stops once its best candidate
    lies within the sections searched, as no later one can be nearer. The
    answer is that of testing every hit against every capsule.
    """
    out = row_index(ends, hits)
    free = np.flatnonzero(out < 0)
    taken = row_index(hits, ends) >= 0             # hits that end some beam exactly
    if not len(free) or taken.all():
        return out
    spare = np.flatnonzero(~taken)
    s, e = starts[free], ends[free]
    delta = e - s
    length = np.linalg.norm(delta, axis=1)
    moving = length > 0                            # zero-length beams match only exactly
    free, s, e, delta, length = free[moving], s[moving], e[moving], delta[moving], length[moving]
    if not len(free):
        return out
    u = delta / length[:, None]
    scale = 1.0 + np.maximum(np.abs(s).max(axis=1), np.abs(e).max(axis=1)) + length
    slack = _ON_RAY * (scale + tolerance)
    n_sections = int(min(_MAX_SECTIONS, max(1.0, np.ceil(tolerance / _SECTION))))
    step = (tolerance + 2.0 * slack) / n_sections  # per beam: the capsule's length, cut
    best_t = np.full(len(free), np.inf)
    best_j = np.full(len(free), -1, dtype=np.int64)
    tree = cKDTree(hits[spare])
    active = np.arange(len(free))
    for k in range(n_sections):
        lo = -slack[active] + k * step[active]     # this section: lo .. lo + step
        centres = e[active] + (lo + 0.5 * step[active])[:, None] * u[active]
        # the ball holds the section's slice of the capsule with a margin of slack
        radius = float(np.max(0.5 * step[active] + 2.0 * slack[active]))
        for rows, cols in _bounded_pairs(tree, centres, radius):
            i, j = active[rows], spare[cols]
            w = hits[j] - e[i]
            t = w[:, 0] * u[i, 0]                  # distance beyond the end, along the ray
            for a in range(1, w.shape[1]):
                t += w[:, a] * u[i, a]
            off = np.linalg.norm(w - t[:, None] * u[i], axis=1)   # distance off the ray
            keep = (off <= slack[i]) & (t >= -slack[i]) & (t <= tolerance + slack[i])
            r, pick, score = best_per_row(i[keep], j[keep], t[keep])
            better = (score < best_t[r]) | ((score == best_t[r]) & (pick < best_j[r]))
            best_t[r[better]], best_j[r[better]] = score[better], pick[better]
        active = active[~(best_t[active] <= lo + step[active])]
        if not len(active):
            break
    found = best_j >= 0
    out[free[found]] = best_j[found]
    return out


def _bounded_pairs(tree, centres, radius, budget=None):
    """(row, column) pairs of the tree's points within `radius` of each centre, in
    chunks of whole centres of at most `budget` pairs (one centre may exceed it
    alone: at most the tree's size)."""
    budget = _PAIR_BUDGET if budget is None else budget
    counts = tree.query_ball_point(centres, radius, return_length=True)   # no pairs kept
    ends = np.cumsum(counts)
    start = 0
    while start < len(centres):
        base = ends[start - 1] if start else 0
        stop = max(start + 1, int(np.searchsorted(ends, base + budget, side="right")))
        if ends[stop - 1] > base:
            found = cKDTree(centres[start:stop]).sparse_distance_matrix(
                tree, radius, output_type="ndarray")
            yield found["i"].astype(np.int64) + start, found["j"].astype(np.int64)
        start = stop


def no_return_error(n_beams, hit_tolerance, given):
    """The ValueError for `n_beams` beams of which none has a return (`given`: by beam_hits)."""
    how = ("beam_hits names no hit" if given else
           f"no beam ends on a hit or stops short of one by at most hit_tolerance="
           f"{hit_tolerance:g} along its ray")
    return ValueError(f"{n_beams} beams have no return ({how}) and no beam has one: a free "
                      "beam takes the cluster of a returning beam, so give the beams that end "
                      "at (or just short of) the hits, a larger hit_tolerance, or beam_hits")


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


def _pairs(tree, centres, radii):
    """(row, column) pairs of the tree's points within `radii` of each centre."""
    if not len(centres):
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    found = cKDTree(centres).sparse_distance_matrix(tree, float(np.max(radii)),
                                                     output_type="ndarray")
    keep = found["v"] <= radii[found["i"]]
    return found["i"][keep].astype(np.int64), found["j"][keep].astype(np.int64)


def assign_beams(hit_labels: ArrayLike, hits: ArrayLike, segment_starts: ArrayLike,
                 segment_ends: ArrayLike, *, kernel=None, quadrature=None,
                 n_jobs: int | None = None, hit_tolerance: float = HIT_TOLERANCE,
                 beam_hits: ArrayLike | None = None) -> NDArray[np.int64]:
    """Cluster of each beam, from the clusters of the hits (Kim & Kim, §3.1.1).

    * A beam **with a return** takes its hit's label. Its hit is given by
      `beam_hits`, or else found by :func:`match_beams`: the hit its end
      equals exactly (occgp's convention, beams ending at their hits; of
      coinciding hits, the first counts), or else the hit on its ray at most
      `hit_tolerance` beyond its end (the integral-kernel paper's
      convention, free segments stopping short of the return).
    * A beam **without a return** takes the label of the most similar
      returning beam, the similarity being the line–line integral kernel in
      the paper's form (Eq. 11, parameters ``u, v`` in [0, 1]): occgp's
      integral kernel (over arc length) divided by the two lengths, a
      zero-length beam counting as a point of length 1. Ties go to the
      returning beam listed first.

    The search is exact (the argmax over every returning beam) but pruned,
    so that it scales to tens of thousands of beams. The 8 returning beams
    nearest by midpoint (k-d tree) give each free beam a first similarity
    ``s``; then only returning beams whose similarity could reach ``s`` are
    evaluated. Bounds, for any of occgp's kernels: the kernel at the beams'
    closest approach (they must pass within the distance where it falls to
    ``s``) and the kernel's integral along a line over the longer length; for
    the squared exponential also its integral along the other beam's whole
    line, which confines a candidate's midpoint to a strip along the free
    beam. The survivors are evaluated with one kernel call per chunk of 32
    free beams when they share their candidates, one per free beam
    otherwise. A free beam beyond the kernel's reach (``sqrt(cutoff2)``
    length scales) of every returning beam, where every similarity is 0,
    takes the label of the returning beam nearest to it (Euclidean
    segment-to-segment distance; ties: the first listed).

    Cost, measured on 2 cores: about 3 s for the 12,750 beams (2,728
    without a return) of ``room_2d().scan(n_poses=750)``, a third of it in
    the kernel evaluations; 0.05 s for the 26-pose scan.

    Parameters
    ----------
    hit_labels : array-like of int of shape (n_hits,)
        Cluster of each hit (non-negative).
    hits : array-like of shape (n_hits, D)
        The hits, D in 1..3.
    segment_starts, segment_ends : array-like of shape (n_beams, D)
        The beams, from the sensor to the return (or short of it) or to the
        maximum range.
    kernel : SquaredExponential, Matern32 or SparseKernel, default=None
        The point kernel whose integral measures similarity; None means
        ``SquaredExponential(1.0, 1.0)``.
    quadrature : {"clenshaw-curtis", "simpson"}, ClenshawCurtis, Simpson or None
        The integration rule (None: Clenshaw–Curtis; the paper used
        Simpson's, about 20 times slower).
    n_jobs : int, default=None
        Threads of the kernel evaluation (None: 1; -1: every core); the
        result does not depend on it.
    hit_tolerance : float, default=0.1
        Farthest (metres) a hit may lie beyond the end of its beam, on its
        ray (see :func:`match_beams`); 0: beams end at their hits.
    beam_hits : array-like of int of shape (n_beams,), default=None
        Each beam's hit index, or -1 for a beam without a return; replaces
        the matching (`hit_tolerance` is then unused).

    Returns
    -------
    beam_labels : ndarray of shape (n_beams,), dtype int64

    Raises
    ------
    ValueError
        On NaN or inf, wrong shapes or lengths, negative labels, data beyond
        the integral kernel's limits (coordinates past 1e10 length scales,
        beams longer than 1e4 length scales), a bad `hit_tolerance` or
        `beam_hits` (shape, an entry outside ``-1..n_hits-1``), or beams
        without a return when no beam has one.
    TypeError
        On non-numeric data, non-integer labels or `beam_hits`, or a kernel
        or quadrature of another kind.

    Examples
    --------
    Two returning beams in clusters 0 and 1, and a free beam beside the
    second:

    >>> import numpy as np
    >>> hits = np.array([[2.0, 0.0], [0.0, 2.0]])
    >>> starts = np.zeros((3, 2))
    >>> ends = np.array([[2.0, 0.0], [0.0, 2.0], [0.5, 3.0]])
    >>> assign_beams([0, 1], hits, starts, ends).tolist()
    [0, 1, 1]
    """
    return beam_sources(hit_labels, hits, segment_starts, segment_ends, kernel=kernel,
                        quadrature=quadrature, n_jobs=n_jobs, hit_tolerance=hit_tolerance,
                        beam_hits=beam_hits)[0]


def beam_sources(hit_labels, hits, segment_starts, segment_ends, *, kernel=None,
                 quadrature=None, n_jobs=None, hit_tolerance=HIT_TOLERANCE, beam_hits=None):
    """:func:`assign_beams`'s labels, and the hit each beam takes its label from.

    That hit is the beam's own for a beam with a return, the most similar
    returning beam's for one without. Same parameters and errors as
    :func:`assign_beams`; returns ``(beam_labels, source_hits)``, both int64
    of shape (n_beams,), ``beam_labels == hit_labels[source_hits]``.
    """
    kernel = SquaredExponential(1.0, 1.0) if kernel is None else check_kernel(kernel)
    kernel._checked()
    quadrature = check_quadrature(quadrature)
    n_threads = threads(n_jobs)
    arr = as_numeric(hits, "hits")
    if arr.ndim != 2 or not 1 <= arr.shape[1] <= 3:
        raise ValueError(f"hits must have shape (n_hits, D) with D in 1..3, got {arr.shape}")
    dim = arr.shape[1]
    hits = as_points(arr, "hits", dim)
    labels = _as_labels(hit_labels, "hit_labels", len(hits))
    starts, ends = as_segments(segment_starts, segment_ends, "segment", dim=dim)
    inv = kernel.inverse_length_scales(dim)
    check_coordinates({"hits": hits, "segment_starts": starts, "segment_ends": ends}, inv,
                      fix="shift the data towards the origin or use a longer length scale")
    check_segments(starts, ends, inv)
    hit_tolerance = check_real(hit_tolerance, "hit_tolerance", low=0.0, low_open=False)
    if beam_hits is not None:
        hit_of = check_beam_hits(beam_hits, len(ends), len(hits))
    else:
        hit_of = _match(hits, starts, ends, hit_tolerance)
    source = np.asarray(hit_of, dtype=np.int64).copy()
    free = np.flatnonzero(hit_of < 0)
    ret = np.flatnonzero(hit_of >= 0)
    if len(free):
        if not len(ret):
            raise no_return_error(len(free), hit_tolerance, beam_hits is not None)
        best = _most_similar(kernel, quadrature, starts[free], ends[free], starts[ret],
                             ends[ret], n_threads)
        source[free] = source[ret[best]]
    return labels[source], source


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
            centres = fs[rows][owner] + t[:, None] * u[owner]
            ball = np.sqrt(w ** 2 + (0.5 * step) ** 2)[owner]
            k, j = _pairs(tree, centres, ball)
            key = np.unique(rows[owner[k]] * len(tree.data) + j)
            parts.append((key // len(tree.data), key % len(tree.data)))
    rows = np.flatnonzero(disc)
    if len(rows):
        i, j = _pairs(tree, f_mid[rows], f_half[rows] + r_half_max + radius[rows])
        parts.append((rows[i], j))
    if not parts:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])


def _most_similar(kernel, quadrature, fs, fe, rs, re, n_threads):
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


def merge_small_clusters(labels: ArrayLike, points: ArrayLike, is_hit: ArrayLike,
                         min_hits: int = 3, min_size: int = 1) -> NDArray[np.int64]:
    """Fold clusters that cannot train a classifier into their nearest neighbour.

    A cluster is *kept* when it holds at least `min_hits` hits and at least
    one beam (an observation with `is_hit` False): a GP classifier needs both
    classes; and at least `min_size` observations. Every other cluster (too
    few hits or observations, hits only, or beams only) is
    merged whole into the kept cluster nearest to it: the one holding the
    point nearest to any of its points (k-d tree; ties go to the lower
    label). The kept clusters are then numbered 0..k-1 in the order of their
    old labels. If no cluster is kept, every observation goes to cluster 0.

    Parameters
    ----------
    labels : array-like of int of shape (n_obs,)
        Cluster of each observation (non-negative).
    points : array-like of shape (n_obs, D)
        Where each observation lies (D in 1..3): a hit, or e.g. a beam's
        midpoint.
    is_hit : array-like of bool of shape (n_obs,)
        True for hits, False for beams.
    min_hits : int, default=3
        Fewest hits of a kept cluster (at least 1).
    min_size : int, default=1
        Fewest observations of a kept cluster (at least 1): larger values
        give fewer, larger clusters on fragmented data.

    Returns
    -------
    labels : ndarray of shape (n_obs,), dtype int64
        A new array. When every cluster is kept nothing merges, and it is
        `labels` renumbered 0..k-1 in order (a copy of `labels` when they
        were already 0..k-1).

    Raises
    ------
    ValueError
        On wrong shapes or lengths, negative labels, NaN or inf points, or
        a bad `min_hits`.
    TypeError
        On non-integer labels, non-bool `is_hit` or non-numeric points.

    Examples
    --------
    Cluster 1 has a single hit, so it merges into cluster 0 (nearer than 2):

    >>> import numpy as np
    >>> labels = [0, 0, 0, 0, 1, 2, 2, 2, 2]
    >>> points = np.array([[0, 0], [0, 1], [0, 2], [1, 1], [0, 3.5],
    ...                    [0, 8], [0, 9], [0, 10], [1, 9]], dtype=float)
    >>> is_hit = [True, True, True, False, True, True, True, True, False]
    >>> merge_small_clusters(labels, points, is_hit).tolist()
    [0, 0, 0, 0, 0, 1, 1, 1, 1]
    """
    labels = _as_labels(labels, "labels")
    n = len(labels)
    arr = as_numeric(points, "points")
    if arr.ndim != 2 or not 1 <= arr.shape[1] <= 3 or len(arr) != n:
        raise ValueError(f"points must have shape ({n}, D) with D in 1..3 (one row per label), "
                         f"got {arr.shape}")
    points = as_points(arr, "points", arr.shape[1])
    hit = as_numeric(is_hit, "is_hit", kinds="iufb")
    if hit.dtype != bool:
        raise TypeError(f"is_hit must hold booleans, got dtype {hit.dtype}")
    if hit.shape != (n,):
        raise ValueError(f"is_hit must have shape ({n},), got {hit.shape}")
    min_hits = check_int(min_hits, "min_hits", low=1)
    min_size = check_int(min_size, "min_size", low=1)
    if not n:
        return np.zeros(0, dtype=np.int64)
    old, cluster = np.unique(labels, return_inverse=True)
    k = len(old)
    n_hits = np.bincount(cluster[hit], minlength=k)
    n_beams = np.bincount(cluster[~hit], minlength=k)
    kept = (n_hits >= min_hits) & (n_beams >= 1) & (n_hits + n_beams >= min_size)
    if not kept.any():
        return np.zeros(n, dtype=np.int64)
    rank = np.cumsum(kept) - 1
    out = cluster.copy()
    lone = ~kept[cluster]
    if lone.any():
        anchor = np.flatnonzero(~lone)
        dist, nearest = cKDTree(points[anchor]).query(points[lone], k=1)
        source, target, _ = best_per_row(cluster[lone], cluster[anchor[nearest]], dist)
        into = np.arange(k)
        into[source] = target
        out = into[cluster]
    return rank[out].astype(np.int64)


def match_call(obs, n_hits, beam_hits, matched, old, old_beam_hits, hit_tolerance):
    """The hit of each beam of `obs` (hits first), indexing the hits of every call so
    far (-1: none), for a mixture's :meth:`fit` (`old` None) or :meth:`update` (`old`:
    the earlier calls' observations, `old_beam_hits` their beams' hits).

    `beam_hits` (given to ``fit`` / ``update``) indexes the hits of `obs`;
    `matched` (a saved model's) is the answer already. Without either, the beams
    of every call are matched to all the hits (an earlier call's returning beams
    keep theirs), within `hit_tolerance`.
    """
    hits = obs.starts[:n_hits]
    starts, ends = obs.starts[n_hits:], obs.ends[n_hits:]
    n_old = 0 if old is None else int(np.count_nonzero(old.labels > 0))
    if matched is not None:
        return check_beam_hits(matched, len(starts), n_old + n_hits)
    if beam_hits is not None:
        local = check_beam_hits(beam_hits, len(starts), n_hits)
        return np.where(local >= 0, local + n_old, -1)
    if old is None:
        return match_beams(hits, starts, ends, hit_tolerance=hit_tolerance)
    old_hit = old.labels > 0
    return match_beams(np.vstack([old.starts[old_hit], hits]),
                       np.vstack([old.starts[~old_hit], starts]),
                       np.vstack([old.ends[~old_hit], ends]),
                       hit_tolerance=hit_tolerance)[len(old_beam_hits):]
