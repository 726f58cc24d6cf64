"""Line tracking of 2D laser scans (Kim & Kim 2022, §3.1.2, Algorithm 1), lines merged across scans."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from .. import _linetrack
from .._validation import check_real
from ._checks import check_angle, check_at_least
from ._clustering import (Clustering, best_per_row, components, first_appearance, group_starts,
                          scan_ids, segment_distance)

__all__ = ["LineTracking", "Lines"]

class Lines(NamedTuple):
    """The fitted line of each cluster of :class:`LineTracking` (arrays over clusters)."""

    #: Mean of the cluster's hits, shape (n_clusters, 2).
    centroid: NDArray[np.float64]
    #: Unit direction of the total-least-squares line, shape (n_clusters, 2).
    direction: NDArray[np.float64]
    #: ``(t_min, t_max)``: the hits' extent along `direction` from `centroid`,
    #: shape (n_clusters, 2).
    extent: NDArray[np.float64]
    #: Hits in the cluster, shape (n_clusters,).
    n_points: NDArray[np.int64]


class _LineSet(NamedTuple):
    """Moments and fitted segments of groups of 2D points."""

    n: NDArray[np.float64]
    mean: NDArray[np.float64]      # (k, 2)
    scatter: NDArray[np.float64]   # (k, 3): sums of centered xx, xy, yy
    direction: NDArray[np.float64]
    tmin: NDArray[np.float64]
    tmax: NDArray[np.float64]

    @property
    def starts(self):
        return self.mean + self.tmin[:, None] * self.direction

    @property
    def ends(self):
        return self.mean + self.tmax[:, None] * self.direction

    def take(self, idx):
        return _LineSet(*(a[idx] for a in self))


def _direction(scatter):
    """Principal unit direction of each (xx, xy, yy) scatter (x-axis when it vanishes)."""
    theta = 0.5 * np.arctan2(2.0 * scatter[:, 1], scatter[:, 0] - scatter[:, 2])
    return np.column_stack([np.cos(theta), np.sin(theta)])


def _line_set(points, groups, k):
    """Exact moments, TLS directions and extents of the `k` groups of `points`."""
    n = np.bincount(groups, minlength=k).astype(np.float64)
    mean = np.column_stack([np.bincount(groups, points[:, d], k) for d in range(2)]) / n[:, None]
    q = points - mean[groups]
    scatter = np.column_stack([np.bincount(groups, q[:, 0] * q[:, 0], k),
                               np.bincount(groups, q[:, 0] * q[:, 1], k),
                               np.bincount(groups, q[:, 1] * q[:, 1], k)])
    direction = _direction(scatter)
    t = np.einsum("ij,ij->i", q, direction[groups])
    order, starts = group_starts(groups)
    return _LineSet(n, mean, scatter, direction, np.minimum.reduceat(t[order], starts),
                    np.maximum.reduceat(t[order], starts))


def _segment_samples(starts, ends, spacing):
    """Points at most `spacing` apart along each segment, and the segment of each."""
    length = np.linalg.norm(ends - starts, axis=1)
    m = np.ceil(length / spacing).astype(np.int64) + 1
    owner = np.repeat(np.arange(len(starts)), m)
    first = np.cumsum(m) - m
    u = (np.arange(len(owner)) - first[owner]) / np.maximum(m[owner] - 1, 1)
    return starts[owner] + u[:, None] * (ends - starts)[owner], owner


def _near_pairs(a_starts, a_ends, b_starts=None, b_ends=None, *, reach):
    """Pairs (i, j) of segments of A (and B, or A again with i < j) possibly within `reach`.

    Every pair whose segment distance is at most `reach` is returned (and some
    more): points sampled `reach` apart along each segment come within
    ``2 * reach`` of each other.
    """
    pa, oa = _segment_samples(a_starts, a_ends, reach)
    tree_a = cKDTree(pa)
    if b_starts is None:
        pairs = tree_a.query_pairs(2.0 * reach, output_type="ndarray")
        i, j = oa[pairs[:, 0]], oa[pairs[:, 1]]
        i, j = np.minimum(i, j), np.maximum(i, j)
        keep = i != j
        n = len(a_starts)
    else:
        pb, ob = _segment_samples(b_starts, b_ends, reach)
        sdm = tree_a.sparse_distance_matrix(cKDTree(pb), 2.0 * reach, output_type="ndarray")
        i, j = oa[sdm["i"]], ob[sdm["j"]]
        keep = np.ones(len(i), dtype=bool)
        n = len(b_starts)
    key = np.sort(i[keep] * n + j[keep])   # sorted, then distinct: np.unique's answer,
    key = key[np.r_[True, key[1:] != key[:-1]]] if len(key) else key   # without its hashing
    return key // n, key % n


class LineTracking(Clustering):
    """Line tracking of planar laser scans (Kim & Kim's LT-clustering, Algorithm 1).

    1. **Tracking.** Within each scan (a run of hits with the same origin),
       hits are ordered by bearing about the origin, starting after the
       widest angular gap (so a scan across the -x axis is not split; ties
       keep the input order). A line starts with the first hit; the next hit
       joins it when it lies within `distance_threshold` of the line's total
       least-squares fit (the principal axis of its hits' scatter, kept as
       running sums; with one point so far, any hit) and within
       `gap_threshold` of the previous hit; otherwise that hit starts a new
       line. A lone hit is a line of one point. The loop is compiled
       (``occgp._linetrack``), O(1) per hit.
    2. **Merging.** Two lines of at least `min_points` hits (of any scans)
       are one cluster when their directions differ by at most
       `merge_angle`, both endpoints of the shorter one lie within
       `merge_distance` of the longer one's line, and their extents along
       the longer one's direction overlap or are at most `gap_threshold`
       apart. Merging is transitive; each cluster's line is refit on all its
       hits and the clusters are tested again until none merge (walls seen
       from many poses become one cluster each).
    3. **Short lines** (fewer than `min_points` hits, whose direction is
       unreliable) join the cluster whose line they match best by the test
       above without the angle (smallest distance of their endpoints to its
       line), but never bridge two clusters; those matching none are
       clusters of their own, merged with each other when within
       `gap_threshold`. Clusters of few hits are left to
       :func:`merge_small_clusters`.

    Labels are numbered in order of each cluster's first hit. In
    :meth:`partial_fit`, the new scans are tracked, each new line of at least
    `min_points` hits joins the existing cluster it matches best (which is
    refit; the extent of its earlier hits is carried by its old segment's
    endpoints), the others merge among themselves as in :meth:`fit` into new
    clusters, then the new short lines are placed as in step 3. Existing
    clusters never merge with one another.

    Parameters
    ----------
    distance_threshold : float, default=0.1
        Largest distance (m) of a hit from the line it joins.
    gap_threshold : float, default=2.0
        Largest distance (m) between consecutive hits of a line, and between
        the extents of lines that merge. The default suits a 17-beam,
        180-degree, 8 m laser (hits up to 1.6 m apart on a wall facing it).
    merge_angle : float, default=10.0
        Largest angle (degrees, in [0, 90]) between lines that merge.
    merge_distance : float, default=0.15
        Largest distance (m) of the shorter line's endpoints from the longer
        one's line (below the 0.2 m walls of :func:`occgp.datasets.room_2d`,
        whose two faces stay apart).
    min_points : int, default=3
        Lines with fewer hits (at least 2) do not define a direction for
        merging (step 3).

    Attributes
    ----------
    labels_ : ndarray of shape (n_hits,), dtype int64
    n_clusters_ : int
    n_dims_ : int
        Always 2.
    n_lines_ : int
        Lines tracked in all scans so far (before merging).
    lines_ : Lines
        The fitted line of each cluster: ``centroid``, ``direction``,
        ``extent`` (``t_min, t_max`` along the direction) and ``n_points``.

    Notes
    -----
    On ``room_2d().scan()`` (351 hits, 26 scans) the defaults give 26
    clusters (23 once :func:`merge_small_clusters` has folded those that
    cannot train a classifier); Kim & Kim report 18 on their room. A fit of
    10,000 hits (``room_2d().scan(n_poses=750)``, 3,313 lines, 38 clusters)
    takes about 0.2 s on 2 cores, of which the tracking is 1.4 ms (the
    compiled loop 0.13 ms, against 15–20 ms in pure Python) and the rest the
    vectorised merging; :meth:`partial_fit` scan by scan costs about 1 ms a
    scan. Updates cannot merge clusters, so a map built scan by scan has
    more of them than one fit at once (119 against 38 there; 53 against 26
    on the 26-pose scan).

    References
    ----------
    A. Siadat, A. Kaske, S. Klausmann, M. Dufaut, R. Husson, "An optimized
    segmentation method for a 2D laser-scanner applied to mobile robot
    navigation", IFAC ICICA 1997; S. Kim, J. Kim, "Efficient clustering for
    continuous occupancy mapping using a mixture of Gaussian processes",
    Sensors 22(18), 6832 (2022), §3.1.2, Algorithm 1.

    Examples
    --------
    Two walls at right angles seen from one pose (the corner hit goes with
    the wall tracked first, by bearing):

    >>> import numpy as np
    >>> t = np.linspace(0.0, 2.0, 9)
    >>> hits = np.vstack([np.column_stack([t, np.full(9, 2.0)]),
    ...                   np.column_stack([np.full(8, 2.0), t[:-1][::-1]])])
    >>> lt = LineTracking().fit(hits, np.zeros_like(hits))
    >>> lt.n_clusters_, np.bincount(lt.labels_).tolist()
    (2, [8, 9])
    """

    _dims = (2,)
    _what = " for line tracking"

    def __init__(self, distance_threshold=0.1, gap_threshold=2.0, merge_angle=10.0,
                 merge_distance=0.15, min_points=3):
        self.distance_threshold = distance_threshold
        self.gap_threshold = gap_threshold
        self.merge_angle = merge_angle
        self.merge_distance = merge_distance
        self.min_points = min_points

    def _check_params(self):
        return dict(
            distance=check_real(self.distance_threshold, "distance_threshold", low=0.0),
            gap=check_real(self.gap_threshold, "gap_threshold", low=0.0),
            cos_angle=np.cos(np.radians(check_angle(self.merge_angle, "merge_angle"))),
            merge=check_real(self.merge_distance, "merge_distance", low=0.0),
            min_points=check_at_least(self.min_points, "min_points", 2))

    # ------------------------------------------------------------- tracking
    @staticmethod
    def _track(hits, origins, params):
        """Line of every hit (in input order) and the number of lines."""
        scan = scan_ids(origins)
        d = hits - origins
        angle = np.arctan2(d[:, 1], d[:, 0])
        order = np.lexsort((np.arange(len(hits)), angle, scan))
        a, s = angle[order], scan[order]
        first = np.flatnonzero(np.r_[True, s[1:] != s[:-1]])
        size = np.diff(np.r_[first, len(s)])
        gap = np.empty_like(a)
        gap[1:] = a[1:] - a[:-1]
        last = first + size - 1
        gap[first] = a[first] + 2.0 * np.pi - a[last]
        # per scan, start after the widest gap: rotate the scan's sorted positions
        pos = np.arange(len(a)) - first[s]
        widest = np.maximum.reduceat(gap, first)
        is_widest = gap == widest[s]
        start = np.minimum.reduceat(np.where(is_widest, pos, len(a)), first)
        rank = (pos - start[s]) % size[s]
        order = order[np.lexsort((rank, s))]
        ptr = np.r_[first, len(s)].astype(np.intp)
        line_sorted = np.empty(len(hits), dtype=np.intp)
        n_lines = _linetrack.track_lines(np.ascontiguousarray(hits[order]), ptr,
                                         params["distance"], params["gap"], line_sorted)
        line = np.empty(len(hits), dtype=np.int64)
        line[order] = line_sorted
        return line, int(n_lines)

    # ---------------------------------------------------------------- tests
    @staticmethod
    def _match(one, i, two, j, params, angle=True):
        """Whether lines ``one[i]`` and ``two[j]`` merge, and a score (lower is better)."""
        len_i, len_j = one.tmax[i] - one.tmin[i], two.tmax[j] - two.tmin[j]
        i_long = len_i >= len_j
        c_l = np.where(i_long[:, None], one.mean[i], two.mean[j])
        d_l = np.where(i_long[:, None], one.direction[i], two.direction[j])
        lo_l = np.where(i_long, one.tmin[i], two.tmin[j])
        hi_l = np.where(i_long, one.tmax[i], two.tmax[j])
        s0 = np.where(i_long[:, None], two.starts[j], one.starts[i])
        s1 = np.where(i_long[:, None], two.ends[j], one.ends[i])
        normal = np.column_stack([-d_l[:, 1], d_l[:, 0]])
        perp = np.maximum(np.abs(np.einsum("ij,ij->i", s0 - c_l, normal)),
                          np.abs(np.einsum("ij,ij->i", s1 - c_l, normal)))
        t0 = np.einsum("ij,ij->i", s0 - c_l, d_l)
        t1 = np.einsum("ij,ij->i", s1 - c_l, d_l)
        gap = np.maximum(np.minimum(t0, t1) - hi_l, lo_l - np.maximum(t0, t1))
        ok = (perp <= params["merge"]) & (gap <= params["gap"])
        if angle:
            cos = np.abs(np.einsum("ij,ij->i", one.direction[i], two.direction[j]))
            ok &= cos >= params["cos_angle"]
        return ok, perp

    def _reach(self, params):
        return params["gap"] + params["merge"]

    def _agglomerate(self, points, groups, k, params):
        """Merge the `k` groups of `points` (lines) transitively until no pair merges.

        Returns (cluster of each group, number of clusters).
        """
        cluster = np.arange(k, dtype=np.int64)
        n_clusters = k
        while n_clusters > 1:
            lines = _line_set(points, cluster[groups], n_clusters)
            i, j = _near_pairs(lines.starts, lines.ends, reach=self._reach(params))
            ok, _ = self._match(lines, i, lines, j, params)
            comp = components(n_clusters, i[ok], j[ok])
            n_new = int(comp.max()) + 1
            if n_new == n_clusters:
                break
            cluster, n_clusters = comp[cluster], n_new
        return cluster, n_clusters

    def _short_clusters(self, points, groups, k, params):
        """Clusters of short lines: transitively merged when within `gap_threshold`."""
        lines = _line_set(points, groups, k)
        reach = params["gap"]
        i, j = _near_pairs(lines.starts, lines.ends, reach=reach)
        close = segment_distance(lines.starts[i], lines.ends[i], lines.starts[j],
                                  lines.ends[j]) <= reach
        comp = components(k, i[close], j[close])
        return comp, int(comp.max()) + 1 if k else 0

    def _attach(self, short, clusters, params):
        """Best cluster of each short line (-1: none matches)."""
        best = np.full(len(short.n), -1, dtype=np.int64)
        if not len(short.n) or not len(clusters.n):
            return best
        i, j = _near_pairs(short.starts, short.ends, clusters.starts, clusters.ends,
                           reach=self._reach(params))
        ok, score = self._match(short, i, clusters, j, params, angle=False)
        rows, picks, _ = best_per_row(i[ok], j[ok], score[ok])
        best[rows] = picks
        return best

    # ------------------------------------------------------------- clusters
    def _cluster_new(self, hits, line, n_lines, params, existing=None):
        """Cluster of each new hit: existing clusters (0..m-1), then new ones (m..).

        `existing` is the _LineSet of the existing clusters (None in fit).
        Returns (cluster of each hit, number of new clusters, the short mask of lines).
        """
        m = 0 if existing is None else len(existing.n)
        lines = _line_set(hits, line, n_lines)
        short = (lines.n < params["min_points"]) | (lines.scatter[:, 0] + lines.scatter[:, 2] <= 0)
        long_idx, short_idx = np.flatnonzero(~short), np.flatnonzero(short)
        cluster_of_line = np.full(n_lines, -1, dtype=np.int64)
        # long lines: join an existing cluster, or merge among themselves
        if m and len(long_idx):
            cluster_of_line[long_idx] = self._attach_long(lines.take(long_idx), existing, params)
        free = long_idx[cluster_of_line[long_idx] < 0]
        n_new = 0
        if len(free):
            sel = np.isin(line, free)
            remap = np.full(n_lines, -1, dtype=np.int64)
            remap[free] = np.arange(len(free))
            comp, n_new = self._agglomerate(hits[sel], remap[line[sel]], len(free), params)
            cluster_of_line[free] = m + comp
        # short lines: join the best cluster (existing or new), or cluster among themselves
        if len(short_idx):
            long_hits = cluster_of_line[line] >= m          # hits of the new long clusters
            sets = []
            if m:
                sets.append(existing)
            if n_new:
                sets.append(_line_set(hits[long_hits], cluster_of_line[line[long_hits]] - m,
                                      n_new))
            clusters = _LineSet(*(np.concatenate(parts) for parts in zip(*sets))) \
                if sets else None
            best = self._attach(lines.take(short_idx), clusters, params) \
                if clusters is not None else np.full(len(short_idx), -1)
            # an attached short line keeps its cluster index (existing first, then new)
            cluster_of_line[short_idx] = best
            lone = short_idx[best < 0]
            if len(lone):
                sel = np.isin(line, lone)
                remap = np.full(n_lines, -1, dtype=np.int64)
                remap[lone] = np.arange(len(lone))
                comp, n_short = self._short_clusters(hits[sel], remap[line[sel]], len(lone),
                                                     params)
                cluster_of_line[lone] = m + n_new + comp
                n_new += n_short
        return cluster_of_line[line], n_new

    def _attach_long(self, lines, existing, params):
        best = np.full(len(lines.n), -1, dtype=np.int64)
        i, j = _near_pairs(lines.starts, lines.ends, existing.starts, existing.ends,
                           reach=self._reach(params))
        ok, score = self._match(lines, i, existing, j, params)
        rows, picks, _ = best_per_row(i[ok], j[ok], score[ok])
        best[rows] = picks
        return best

    def _fit(self, hits, origins, params):
        line, n_lines = self._track(hits, origins, params)
        cluster, k = self._cluster_new(hits, line, n_lines, params)
        rank = first_appearance(cluster, k)
        labels = rank[cluster]
        lines = _line_set(hits, labels, k)
        return dict(_lines=lines, lines_=_public_lines(lines), n_lines_=n_lines), labels

    def _partial(self, hits, origins, params):
        old = self._lines
        m = len(old.n)
        line, n_lines = self._track(hits, origins, params)
        cluster, n_new = self._cluster_new(hits, line, n_lines, params, existing=old)
        # new clusters numbered m.. in order of their first hit
        rank = np.arange(m + n_new, dtype=np.int64)
        is_new = cluster >= m
        if n_new:
            rank[m:] = m + first_appearance(cluster[is_new] - m, n_new)
        labels = rank[cluster]
        # refit: existing clusters that received hits, and the new clusters
        joined = labels[~is_new]
        lines = old
        if len(joined):
            lines = _combine(old, hits[~is_new], joined)
        if n_new:
            fresh = _line_set(hits[is_new], labels[is_new] - m, n_new)
            lines = _LineSet(*(np.concatenate([a, b]) for a, b in zip(lines, fresh)))
        return dict(_lines=lines, lines_=_public_lines(lines),
                    n_lines_=self.n_lines_ + n_lines), labels


def _public_lines(lines):
    return Lines(lines.mean.copy(), lines.direction.copy(),
                 np.column_stack([lines.tmin, lines.tmax]), lines.n.astype(np.int64))


def _combine(old, points, labels):
    """`old` with `points` added to the groups `labels` (Chan's pairwise moments).

    The extent of the old points along a refit direction is that of the old
    segment's endpoints.
    """
    k = len(old.n)
    n_b = np.bincount(labels, minlength=k).astype(np.float64)
    touched = n_b > 0
    safe = np.where(touched, n_b, 1.0)
    mean_b = np.column_stack([np.bincount(labels, points[:, d], k) for d in range(2)]) \
        / safe[:, None]
    q = points - mean_b[labels]
    scatter_b = np.column_stack([np.bincount(labels, q[:, 0] * q[:, 0], k),
                                 np.bincount(labels, q[:, 0] * q[:, 1], k),
                                 np.bincount(labels, q[:, 1] * q[:, 1], k)])
    n = old.n + n_b
    delta = mean_b - old.mean
    w = np.where(touched, old.n * n_b / n, 0.0)
    mean = np.where(touched[:, None], old.mean + delta * (n_b / n)[:, None], old.mean)
    scatter = old.scatter + scatter_b + w[:, None] * np.column_stack(
        [delta[:, 0] ** 2, delta[:, 0] * delta[:, 1], delta[:, 1] ** 2])
    direction = np.where(touched[:, None], _direction(scatter), old.direction)
    # extents: the old endpoints and the new points, projected on the new line
    t_old = np.stack([np.einsum("ij,ij->i", e - mean, direction)
                      for e in (old.starts, old.ends)])
    t_new = np.einsum("ij,ij->i", points - mean[labels], direction[labels])
    tmin, tmax = t_old.min(axis=0), t_old.max(axis=0)
    np.minimum.at(tmin, labels, t_new)
    np.maximum.at(tmax, labels, t_new)
    return _LineSet(n, mean, scatter, direction, tmin, tmax)





# ============================================================== plane clustering
