"""Planes grown over the k-NN graph of 3D hits, the Dirichlet process for what is not planar."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from .._validation import check_int, check_n_jobs, check_real, n_threads
from ._checks import check_angle, check_at_least
from ._clustering import (Clustering, DirichletProcessClustering, best_per_row, components,
                          first_appearance, group_starts)

__all__ = ["PlaneClustering", "Planes"]

class Planes(NamedTuple):
    """The fitted plane of each cluster of :class:`PlaneClustering` (arrays over clusters)."""

    #: Mean of the cluster's hits, shape (n_clusters, 3).
    centroid: NDArray[np.float64]
    #: Unit normal of the plane, shape (n_clusters, 3) (for a cluster that is
    #: not a plane, the direction of least spread of its hits).
    normal: NDArray[np.float64]
    #: Corners of the hits' axis-aligned bounding box, shape (n_clusters, 3) each.
    lower: NDArray[np.float64]
    upper: NDArray[np.float64]
    #: Hits in the cluster, shape (n_clusters,).
    n_points: NDArray[np.int64]
    #: Whether the cluster is a grown plane (False: a Dirichlet-process cluster
    #: of the hits left over), shape (n_clusters,).
    is_plane: NDArray[np.bool_]


#: Most neighbours per hit (PlaneClustering's n_neighbors), and hits whose
#: neighbourhoods are analysed at once (bounds the memory of the PCA).
_MAX_NEIGHBORS = 100
_PCA_BLOCK = 20_000
#: Kinds of a hit's neighbourhood (its local principal spreads against distance_threshold).
_POINT, _LINE, _PLANE = 0, 1, 2


def _local_shape(points, neighbours, distance, tan):
    """Normal, main direction, kind and curvature of each point's neighbourhood (PCA)."""
    C = np.empty((len(neighbours), 3, 3))
    for lo in range(0, len(neighbours), _PCA_BLOCK):
        P = points[neighbours[lo:lo + _PCA_BLOCK]]
        Q = P - P.mean(axis=1, keepdims=True)
        C[lo:lo + _PCA_BLOCK] = np.einsum("nki,nkj->nij", Q, Q) / neighbours.shape[1]
    w, v = np.linalg.eigh(C)
    w = np.maximum(w, 0.0)
    spread = np.sqrt(w)
    thick = (spread[:, 0] > distance) | (spread[:, 0] > tan * spread[:, 1])
    kind = np.where(thick, _POINT,
                    np.where(spread[:, 1] >= distance, _PLANE,
                             np.where(spread[:, 2] >= distance, _LINE, _POINT)))
    total = w.sum(axis=1)
    curvature = np.where(total > 0, w[:, 0] / np.where(total > 0, total, 1.0), 0.0)
    return v[:, :, 0], v[:, :, 2], kind, curvature


def _plane_moments(points, groups, k):
    """Counts, means, scatters (k, 3, 3), bounding boxes of the `k` groups of `points`."""
    n = np.bincount(groups, minlength=k).astype(np.float64)
    mean = np.column_stack([np.bincount(groups, points[:, d], k) for d in range(3)]) / n[:, None]
    q = points - mean[groups]
    scatter = np.stack([np.stack([np.bincount(groups, q[:, a] * q[:, b], k) for b in range(3)],
                                 axis=1) for a in range(3)], axis=1)
    order, starts = group_starts(groups)
    lower = np.minimum.reduceat(points[order], starts, axis=0)
    upper = np.maximum.reduceat(points[order], starts, axis=0)
    return n, mean, scatter, lower, upper


def _normals(scatter):
    """Direction of least spread of each (3, 3) scatter."""
    return np.linalg.eigh(scatter)[1][:, :, 0]


class PlaneClustering(Clustering):
    """Planes grown over the k-nearest-neighbour graph of 3D hits, with a DP fallback.

    The 3D counterpart of line tracking (Kim & Kim's future work):

    1. **Local shape.** Each hit's `n_neighbors` nearest hits (and itself;
       :class:`scipy.spatial.cKDTree`) are analysed by PCA, with principal
       spreads (standard deviations) ``s0 <= s1 <= s2``. The neighbourhood
       is *planar*, and gives the hit a normal, when it is thin
       (``s0 <= distance_threshold`` and ``s0 <= tan(angle_threshold) * s1``,
       so that the normal is known to about the angle threshold) and wide
       (``s1 >= distance_threshold``); *linear*, giving a direction, when
       only ``s2`` reaches `distance_threshold` (one row of a sparse LiDAR);
       otherwise (a corner, an edge, a lone hit) *point-like*. The curvature
       is ``s0^2 / (s0^2 + s1^2 + s2^2)``.
    2. **Region growing.** Planar hits are seeds in order of increasing
       curvature. A region starts with the seed's plane and grows
       breadth-first over the k-NN graph: a neighbour joins when it lies
       within `distance_threshold` of the region's plane and its shape
       agrees with it within `angle_threshold` (a planar hit's normal with
       the plane's normal; a linear hit's direction with the plane). The
       plane is refit on the region's hits after each breadth-first level,
       once they spread by at least `distance_threshold` in two directions.
    3. **Merging.** Regions of at least `min_region_size` hits are planes;
       two planes whose normals agree within `angle_threshold`, each
       centroid within `distance_threshold` of the other's plane, and whose
       bounding boxes overlap once grown by a margin (the median distance of
       a hit to its `n_neighbors`-th neighbour) are merged (transitively)
       and refit: the same wall seen from several poses is one plane.
    4. **Fallback.** The hits of smaller regions and those in no region are
       clustered by :class:`DirichletProcessClustering` (`concentration`,
       `random_state`).

    Labels are numbered in order of each cluster's first hit. In
    :meth:`partial_fit` the new hits' shapes are computed with neighbours
    among all hits so far, and the existing planes grow into the new hits
    over that k-NN graph: a new hit that has a hit of a plane among its
    neighbours (so it lies within the plane's extent, grown by one
    neighbourhood) joins it when it lies within `distance_threshold` of the
    plane and agrees with it (as in step 2), the nearest plane winning, and
    so on breadth-first; the planes are then refit. The other new hits are
    clustered among themselves as in :meth:`fit` (steps 2–4, over their own
    k-NN graph) and get new labels. Existing clusters never merge, and
    Dirichlet-process clusters never grow. The hits are kept
    (``n_hits x 3`` floats) for the neighbourhoods of later updates, and
    each update rebuilds the k-d tree of all of them.

    Parameters
    ----------
    distance_threshold : float, default=0.05
        Largest distance (m) of a hit from the plane it joins; also the
        spread that makes a neighbourhood planar or linear.
    angle_threshold : float, default=10.0
        Largest angle (degrees, in [0, 90]) between normals that agree.
    n_neighbors : int, default=10
        Neighbours of each hit (itself excluded) for its local shape and
        the graph; 2 to 100.
    min_region_size : int, default=30
        Smallest region kept as a plane.
    concentration : float, default=1.0
        Concentration of the Dirichlet-process fallback.
    random_state : int, numpy Generator, RandomState or None, default=None
        Seeds the Dirichlet-process fallback.
    n_jobs : int, default=None
        Threads of the neighbour queries (None: 1; -1: every core).

    Attributes
    ----------
    labels_ : ndarray of shape (n_hits,), dtype int64
    n_clusters_ : int
    n_planes_ : int
        Clusters that are planes (the others come from the fallback).
    n_dims_ : int
        Always 3.
    planes_ : Planes
        ``centroid``, ``normal``, ``lower``, ``upper``, ``n_points`` and
        ``is_plane`` of each cluster.

    Notes
    -----
    On ``structured_room(0)`` scanned from 4 poses by a 64 x 4 LiDAR (862
    hits, as in ``bench/bench_gp.py``) the defaults give 19 clusters, 7 of
    them planes (the floor, the four walls, the partition and the table
    top); the furniture's other faces, with a few hits each, go to the
    fallback. 10,000 hits (the same poses, a 256 x 12 LiDAR) take about
    0.3 s on 2 cores (33 clusters, 19 planes).

    References
    ----------
    T. Rabbani, F. van den Heuvel, G. Vosselman, "Segmentation of point
    clouds using smoothness constraint", ISPRS Archives 36(5), 2006.

    Examples
    --------
    Three faces of a box corner, seen from one pose:

    >>> import numpy as np
    >>> u, v = np.meshgrid(np.linspace(0.1, 1, 8), np.linspace(0.1, 1, 8))
    >>> u, v, o = u.ravel(), v.ravel(), np.zeros(64)
    >>> hits = np.vstack([np.column_stack([u, v, o]), np.column_stack([u, o, v]),
    ...                   np.column_stack([o, u, v])])
    >>> pc = PlaneClustering(random_state=0).fit(hits, np.ones_like(hits))
    >>> pc.n_clusters_, pc.n_planes_
    (3, 3)
    """

    _dims = (3,)
    _what = " for plane clustering"

    def __init__(self, distance_threshold=0.05, angle_threshold=10.0, n_neighbors=10,
                 min_region_size=30, concentration=1.0, random_state=None, n_jobs=None):
        self.distance_threshold = distance_threshold
        self.angle_threshold = angle_threshold
        self.n_neighbors = n_neighbors
        self.min_region_size = min_region_size
        self.concentration = concentration
        self.random_state = random_state
        self.n_jobs = n_jobs

    def _check_params(self):
        angle = np.radians(check_angle(self.angle_threshold, "angle_threshold"))
        params = dict(
            distance=check_real(self.distance_threshold, "distance_threshold", low=0.0),
            cos=np.cos(angle), sin=np.sin(angle), tan=np.tan(angle),
            k=check_at_least(self.n_neighbors, "n_neighbors", 2, _MAX_NEIGHBORS),
            min_size=check_int(self.min_region_size, "min_region_size", low=1),
            n_jobs=check_n_jobs(self.n_jobs))
        params["dp"] = DirichletProcessClustering(concentration=self.concentration,
                                                  random_state=self.random_state)
        params["dp"]._check_params()
        return params

    # ----------------------------------------------------------- local shape
    @staticmethod
    def _neighbours(points, k, n_jobs, queries=None):
        tree = cKDTree(points)
        k = min(k + 1, len(points))
        dist, nb = tree.query(points if queries is None else queries, k=k,
                              workers=n_threads(n_jobs))
        return dist.reshape(len(nb), -1), nb.reshape(len(nb), -1)

    @staticmethod
    def _agrees(kind, normal, direction, plane_normal, params):
        """Whether each hit's local shape agrees with `plane_normal` (rows or one)."""
        cos_n = np.abs(np.sum(normal * plane_normal, axis=-1))
        cos_d = np.abs(np.sum(direction * plane_normal, axis=-1))
        return np.where(kind == _PLANE, cos_n >= params["cos"],
                        np.where(kind == _LINE, cos_d <= params["sin"], True))

    def _grow(self, points, nb, shape, params):
        """Region of each point (-1: none), grown from the planar seeds."""
        normal, direction, kind, curvature = shape
        n = len(points)
        region = np.full(n, -1, dtype=np.int64)
        seeds = np.flatnonzero(kind == _PLANE)
        seeds = seeds[np.argsort(curvature[seeds], kind="stable")]
        dt = params["distance"]
        r = 0
        for seed in seeds:
            if region[seed] >= 0:
                continue
            region[seed] = r
            ref = points[seed]
            plane_n, plane_c = normal[seed], ref
            cnt, s1, s2 = 1.0, np.zeros(3), np.zeros((3, 3))
            frontier = np.array([seed])
            while len(frontier):
                cand = np.unique(nb[frontier].ravel())
                cand = cand[region[cand] < 0]
                if not len(cand):
                    break
                dist = np.abs((points[cand] - plane_c) @ plane_n)
                ok = (dist <= dt) & self._agrees(kind[cand], normal[cand], direction[cand],
                                                 plane_n, params)
                frontier = cand[ok]
                region[frontier] = r
                q = points[frontier] - ref
                cnt, s1, s2 = cnt + len(q), s1 + q.sum(axis=0), s2 + q.T @ q
                mean = s1 / cnt
                w, v = np.linalg.eigh(s2 / cnt - np.outer(mean, mean))
                if w[1] >= dt * dt:
                    plane_n, plane_c = v[:, 0], ref + mean
            r += 1
        return region, r

    def _cluster(self, points, nb, shape, params, margin):
        """Labels (0..k-1, first appearance) and _planes state of `points`."""
        region, n_regions = self._grow(points, nb, shape, params)
        size = np.bincount(region[region >= 0], minlength=n_regions)
        big = np.flatnonzero(size >= params["min_size"])
        remap = np.full(n_regions + 1, -1, dtype=np.int64)
        remap[big] = np.arange(len(big))
        plane = remap[region]                     # region -1 maps to the last entry: -1
        n_planes = len(big)
        if n_planes > 1:
            n, mean, scatter, lower, upper = _plane_moments(points[plane >= 0],
                                                            plane[plane >= 0], n_planes)
            nrm = _normals(scatter)
            i, j = np.triu_indices(n_planes, 1)
            cos = np.abs(np.einsum("ij,ij->i", nrm[i], nrm[j]))
            off = np.maximum(np.abs(np.einsum("ij,ij->i", mean[j] - mean[i], nrm[i])),
                             np.abs(np.einsum("ij,ij->i", mean[i] - mean[j], nrm[j])))
            overlap = np.all((lower[i] - margin <= upper[j] + margin)
                             & (lower[j] - margin <= upper[i] + margin), axis=1)
            ok = (cos >= params["cos"]) & (off <= params["distance"]) & overlap
            comp = components(n_planes, i[ok], j[ok])
            plane = np.where(plane >= 0, comp[np.maximum(plane, 0)], -1)
            n_planes = int(comp.max()) + 1
        cluster = plane.copy()
        rest = plane < 0
        if rest.any():
            dp = params["dp"]
            cluster[rest] = n_planes + dp.fit_predict(points[rest], np.zeros_like(points[rest]))
        k = int(cluster.max()) + 1
        rank = first_appearance(cluster, k)
        labels = rank[cluster]
        is_plane = np.zeros(k, dtype=bool)
        is_plane[rank[:n_planes]] = True
        return labels, k, is_plane

    @staticmethod
    def _plane_state(points, labels, k, is_plane):
        n, mean, scatter, lower, upper = _plane_moments(points, labels, k)
        return dict(n=n, mean=mean, scatter=scatter, lower=lower, upper=upper,
                    normal=_normals(scatter), is_plane=is_plane)

    @staticmethod
    def _public(planes):
        return Planes(planes["mean"].copy(), planes["normal"].copy(), planes["lower"].copy(),
                      planes["upper"].copy(), planes["n"].astype(np.int64),
                      planes["is_plane"].copy())

    def _fit(self, hits, origins, params):
        dist, nb = self._neighbours(hits, params["k"], params["n_jobs"])
        shape = _local_shape(hits, nb, params["distance"], params["tan"])
        margin = float(np.median(dist[:, -1]))
        labels, k, is_plane = self._cluster(hits, nb, shape, params, margin)
        planes = self._plane_state(hits, labels, k, is_plane)
        return dict(_hits=hits, _planes=planes, _margin=margin, planes_=self._public(planes),
                    n_planes_=int(is_plane.sum())), labels

    def _partial(self, hits, origins, params):
        everything = np.vstack([self._hits, hits])
        _, nb = self._neighbours(everything, params["k"], params["n_jobs"], queries=hits)
        normal, direction, kind, curvature = _local_shape(everything, nb, params["distance"],
                                                         params["tan"])
        old = self._planes
        m = len(old["n"])
        margin = self._margin
        n_old = len(self._hits)
        # grow the existing planes over the k-NN graph into the new hits
        owner = np.concatenate([np.where(old["is_plane"][self.labels_], self.labels_, -1),
                                np.full(len(hits), -1, dtype=np.int64)])
        while True:
            free = np.flatnonzero(owner[n_old:] < 0)
            cand = owner[nb[free]]
            rows, cols = np.nonzero(cand >= 0)
            if not len(rows):
                break
            q, p = free[rows], cand[rows, cols]
            dist = np.abs(np.einsum("ij,ij->i", hits[q] - old["mean"][p], old["normal"][p]))
            ok = (dist <= params["distance"]) & self._agrees(
                kind[q], normal[q], direction[q], old["normal"][p], params)
            if not ok.any():
                break
            q, p, _ = best_per_row(q[ok], p[ok], dist[ok])
            owner[n_old + q] = p
        labels = owner[n_old:].copy()
        joined = labels >= 0
        new = dict(old)
        if joined.any():
            new = _combine_planes(old, hits[joined], labels[joined])
        rest = np.flatnonzero(~joined)
        n_new_planes = 0
        if len(rest):
            pts = hits[rest]
            _, nb_rest = self._neighbours(pts, params["k"], params["n_jobs"])
            shape = (normal[rest], direction[rest], kind[rest], curvature[rest])
            sub, k, is_plane = self._cluster(pts, nb_rest, shape, params, margin)
            labels[rest] = m + sub
            fresh = self._plane_state(pts, sub, k, is_plane)
            new = {key: np.concatenate([new[key], fresh[key]]) for key in new}
            n_new_planes = int(is_plane.sum())
        return dict(_hits=everything, _planes=new, planes_=self._public(new),
                    n_planes_=self.n_planes_ + n_new_planes), labels


def _combine_planes(old, points, labels):
    """Plane state `old` with `points` added to the clusters `labels`."""
    k = len(old["n"])
    n_b = np.bincount(labels, minlength=k).astype(np.float64)
    touched = n_b > 0
    safe = np.where(touched, n_b, 1.0)
    mean_b = np.column_stack([np.bincount(labels, points[:, d], k) for d in range(3)]) \
        / safe[:, None]
    q = points - mean_b[labels]
    scatter_b = np.stack([np.stack([np.bincount(labels, q[:, a] * q[:, b], k) for b in range(3)],
                                   axis=1) for a in range(3)], axis=1)
    n = old["n"] + n_b
    delta = mean_b - old["mean"]
    w = np.where(touched, old["n"] * n_b / n, 0.0)
    mean = np.where(touched[:, None], old["mean"] + delta * (n_b / n)[:, None], old["mean"])
    scatter = old["scatter"] + scatter_b + w[:, None, None] * np.einsum("ki,kj->kij", delta, delta)
    lower, upper = old["lower"].copy(), old["upper"].copy()
    np.minimum.at(lower, labels, points)
    np.maximum.at(upper, labels, points)
    normal = np.where(touched[:, None], _normals(scatter), old["normal"])
    return dict(n=n, mean=mean, scatter=scatter, lower=lower, upper=upper, normal=normal,
                is_plane=old["is_plane"].copy())
