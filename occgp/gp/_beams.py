"""Clusters of beams for the mixture of GP experts (Kim & Kim 2022, §3.1.1).

Hits are clustered first (:mod:`occgp.gp._clustering`); :func:`assign_beams`
then gives each beam a cluster (its hit's, or that of the most similar
returning beam under the line integral kernel) and :func:`merge_small_clusters`
folds clusters that could not train a classifier into their nearest neighbour.
:func:`match_beams` finds the hit of each beam, in either convention: beams
ending at their hits (occgp's) or stopping short of them (the integral-kernel
paper's). The search for the most similar returning beam is in
``_beam_similarity.py``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from .._validation import as_numeric, as_points, check_int, check_real
from ._beam_similarity import most_similar
from ._clustering import best_per_row
from ._integral_kernel import check_kernel, check_quadrature, as_segments
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
        centers = e[active] + (lo + 0.5 * step[active])[:, None] * u[active]
        # the ball holds the section's slice of the capsule with a margin of slack
        radius = float(np.max(0.5 * step[active] + 2.0 * slack[active]))
        for rows, cols in _bounded_pairs(tree, centers, radius):
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


def _bounded_pairs(tree, centers, radius, budget=None):
    """(row, column) pairs of the tree's points within `radius` of each center, in
    chunks of whole centers of at most `budget` pairs (one center may exceed it
    alone: at most the tree's size)."""
    budget = _PAIR_BUDGET if budget is None else budget
    counts = tree.query_ball_point(centers, radius, return_length=True)   # no pairs kept
    ends = np.cumsum(counts)
    start = 0
    while start < len(centers):
        base = ends[start - 1] if start else 0
        stop = max(start + 1, int(np.searchsorted(ends, base + budget, side="right")))
        if ends[stop - 1] > base:
            found = cKDTree(centers[start:stop]).sparse_distance_matrix(
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
        best = most_similar(kernel, quadrature, starts[free], ends[free], starts[ret],
                            ends[ret], n_threads)
        source[free] = source[ret[best]]
    return labels[source], source


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
