"""Dense occupancy from sparse scans by Bayesian kernel inference on cells.

:class:`BGKMap` is Doherty et al.'s Bayesian generalized kernel inference
("BGKOctoMap", the baseline of AKIMap): every cell keeps a Beta posterior whose
parameters collect the kernel-weighted labels of nearby samples. The compiled
accumulation (``ext/_kernel.pyx``) is shared with the adaptive-kernel map.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._kernel import _KernelCells, sparse_kernel
from .octree import OccupancyOctree
from ._validation import as_point, as_points, check_real

__all__ = ["BGKMap", "KernelCells", "sparse_kernel", "voxel_centroids"]

_MAX_VAL = 32768


class KernelCells(NamedTuple):
    """The cells of a kernel map, as arrays (one row per cell)."""

    #: Cell centres, shape (n_cells, 3), in metres.
    centers: NDArray[np.float64]
    #: Occupied evidence alpha (prior included), shape (n_cells,).
    alpha: NDArray[np.float64]
    #: Free evidence beta (prior included), shape (n_cells,).
    beta: NDArray[np.float64]


def voxel_centroids(points: NDArray[np.float64], size: float) -> NDArray[np.float64]:
    """The centroid of the points in each cube of edge `size` that holds any (PCL's
    ``VoxelGrid``), ordered by cube."""
    if len(points) == 0:
        return np.empty((0, 3))
    keys = np.floor(points / size).astype(np.int64)
    _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    sums = np.zeros((len(counts), 3))
    for a in range(3):
        sums[:, a] = np.bincount(inverse, weights=points[:, a], minlength=len(counts))
    return sums / counts[:, None]


class _KernelMap(_KernelCells):
    """What the kernel maps share: cells, Beta posteriors and queries."""

    def _init_cells(self, resolution: float, prior: float) -> None:
        self.resolution = check_real(resolution, "resolution", low=0.0)
        self.prior = check_real(prior, "prior", low=0.0)
        self._setup(self.resolution)

    def _validated_scan(self, points: ArrayLike, origin: ArrayLike):
        pts = as_points(points, "points")
        org = as_point(origin, "origin")
        limit = _MAX_VAL * self.resolution
        for name, arr in (("points", pts), ("origin", org[None])):
            bad = ~np.all((arr >= -limit) & (arr < limit), axis=1)
            if bad.any():
                raise ValueError(
                    f"{int(bad.sum())} of {len(arr)} {name} lie outside the map's key range "
                    f"[{-limit:g}, {limit:g}) m at resolution {self.resolution:g} "
                    f"(first: row {int(np.flatnonzero(bad)[0])}); the map is unchanged")
        return pts, org

    # ------------------------------------------------------------------ queries
    def occupancy(self, points: ArrayLike) -> NDArray[np.float64]:
        """Posterior mean of occupancy, alpha / (alpha + beta), at each point's cell.

        Returns NaN where no sample's kernel ever reached the cell (unknown).
        """
        return self._query(as_points(points, "points"), self.prior, 0)

    def variance(self, points: ArrayLike) -> NDArray[np.float64]:
        """Posterior variance of occupancy, ab / ((a + b)^2 (a + b + 1)); NaN where unknown."""
        return self._query(as_points(points, "points"), self.prior, 1)

    def is_occupied(self, points: ArrayLike, threshold: float = 0.5) -> NDArray[np.bool_]:
        """Whether each point's cell has occupancy above `threshold` (unknown: False)."""
        threshold = check_real(threshold, "threshold", low=0.0, high=1.0)
        p = self.occupancy(points)
        return np.where(np.isnan(p), False, p > threshold)

    def cells(self) -> KernelCells:
        """Every cell any kernel reached, ordered by key (z, then y, then x)."""
        keys, alpha, beta = self._cells_arrays()
        order = np.lexsort(keys.T)
        keys, alpha, beta = keys[order], alpha[order], beta[order]
        centers = (keys.astype(np.float64) - _MAX_VAL + 0.5) * self.resolution
        return KernelCells(centers, alpha + self.prior, beta + self.prior)

    @property
    def num_cells(self) -> int:
        """Number of cells any kernel reached."""
        return int(self._num_cells())

    def to_octree(self, *, clamping_min: float = 0.001,
                  clamping_max: float = 0.999) -> OccupancyOctree:
        """An :class:`~occgp.OccupancyOctree` of the same resolution holding each cell's
        posterior mean as log-odds (float32, within the clamping bounds given), pruned,
        so that ``.bt`` / ``.ot`` export and OctoMap's viewers work. Cells no kernel
        reached stay unknown."""
        tree = OccupancyOctree(self.resolution, clamping_min=clamping_min,
                               clamping_max=clamping_max)
        keys, alpha, beta = self._cells_arrays()
        if len(keys):
            p = (alpha + self.prior) / (alpha + beta + 2 * self.prior)
            log_odds = np.log(p) - np.log1p(-p)
            tree._set_values(np.ascontiguousarray(keys), log_odds.astype(np.float32))
        return tree

    def __reduce__(self):
        keys, alpha, beta = self._cells_arrays()
        return _restore, (type(self), self.get_params(), keys, alpha, beta)


def _restore(cls, params, keys, alpha, beta):
    m = cls(**params)
    m._set_cells(np.ascontiguousarray(keys), np.ascontiguousarray(alpha),
                 np.ascontiguousarray(beta))
    return m


class BGKMap(_KernelMap):
    """Occupancy by Bayesian generalized kernel inference (Doherty et al., "BGKOctoMap").

    Each scan becomes training samples: its end points within `max_range`
    (occupied, label 1) and points every `free_resolution` metres along each
    beam plus the sensor origin (free, label 0), both reduced to one centroid per
    cube of edge `ds_resolution`. Every cell whose centre lies within `ell` of a
    sample gets ``k(r) y`` added to alpha and ``k(r) (1 - y)`` to beta, with
    ``r = distance / ell`` and k the sparse kernel times `sf2`. The occupancy of
    a cell is the posterior mean ``alpha / (alpha + beta)`` with `prior` added to
    both; this is la3dm's BGKOctoMap on a hashed grid of cells.

    Parameters
    ----------
    resolution : float, default=0.1
        Edge length of the cells, in metres.
    ell : float, default=0.2
        Kernel length scale (support radius), in metres.
    sf2 : float, default=1.0
        Kernel signal variance (scale of the kernel).
    free_resolution : float, default=0.5
        Spacing of the free samples along each beam, in metres.
    ds_resolution : float, default=None
        Edge of the cubes that reduce the samples to centroids; None means
        `resolution`.
    prior : float, default=0.001
        Prior alpha and beta of every cell.
    max_range : float, default=8.0
        Beams longer than this are dropped whole (la3dm's rule); None keeps all.

    Attributes
    ----------
    num_cells : int
        Number of cells any kernel reached.

    See Also
    --------
    OccupancyOctree : Log-odds mapping of the same scans.

    References
    ----------
    .. [1] K. Doherty, J. Wang, B. Englot, "Bayesian generalized kernel inference
       for occupancy map prediction", ICRA 2017; la3dm's BGKOctoMap.

    Examples
    --------
    >>> import numpy as np
    >>> from occgp import BGKMap
    >>> wall = np.column_stack([np.full(21, 2.0), np.linspace(-1, 1, 21), np.zeros(21)])
    >>> m = BGKMap(0.1).update(wall, origin=[0.0, 0.0, 0.0])
    >>> bool(m.occupancy([[2.0, 0.0, 0.0]])[0] > 0.5), bool(m.occupancy([[1.0, 0, 0]])[0] < 0.5)
    (True, True)
    """

    def __init__(
        self,
        resolution: float = 0.1,
        *,
        ell: float = 0.2,
        sf2: float = 1.0,
        free_resolution: float = 0.5,
        ds_resolution: float | None = None,
        prior: float = 0.001,
        max_range: float | None = 8.0,
    ) -> None:
        self._init_cells(resolution, prior)
        self.ell = check_real(ell, "ell", low=0.0)
        self.sf2 = check_real(sf2, "sf2", low=0.0)
        self.free_resolution = check_real(free_resolution, "free_resolution", low=0.0)
        self.ds_resolution = (None if ds_resolution is None
                              else check_real(ds_resolution, "ds_resolution", low=0.0))
        self.max_range = None if max_range is None else check_real(max_range, "max_range",
                                                                   low=0.0)

    def get_params(self) -> dict:
        """The constructor's parameters, as a dict."""
        return dict(resolution=self.resolution, ell=self.ell, sf2=self.sf2,
                    free_resolution=self.free_resolution, ds_resolution=self.ds_resolution,
                    prior=self.prior, max_range=self.max_range)

    def __repr__(self) -> str:
        return f"BGKMap(resolution={self.resolution!r}, ell={self.ell!r}, " \
               f"num_cells={self.num_cells})"

    def training_data(self, points: ArrayLike,
                      origin: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The samples and labels (1 occupied, 0 free) that :meth:`update` uses."""
        pts, org = self._validated_scan(points, origin)
        return self._training_data(pts, org)

    def _training_data(self, pts, org):
        ds = self.resolution if self.ds_resolution is None else self.ds_resolution
        hits = voxel_centroids(pts, ds)
        if self.max_range is not None:
            hits = hits[np.linalg.norm(hits - org, axis=1) <= self.max_range]
        if len(hits) == 0:
            return np.empty((0, 3)), np.empty(0)
        # free samples every free_resolution metres along each beam (d < length), and
        # the origin once per beam (so it weighs in its cube's centroid), as la3dm's
        # beam_sample and get_training_data
        length = np.linalg.norm(hits - org, axis=1)
        n_free = np.maximum(np.ceil(length / self.free_resolution).astype(np.int64) - 1, 0)
        beam = np.repeat(np.arange(len(hits)), n_free)
        step = np.arange(len(beam)) - np.repeat(np.cumsum(n_free) - n_free, n_free) + 1
        unit = (hits - org) / np.where(length > 0, length, 1.0)[:, None]
        frees = org + unit[beam] * (step * self.free_resolution)[:, None]
        frees = voxel_centroids(np.vstack([frees, np.repeat(org[None], len(hits), axis=0)]), ds)
        samples = np.vstack([hits, frees])
        labels = np.concatenate([np.ones(len(hits)), np.zeros(len(frees))])
        return samples, labels

    def update(self, points: ArrayLike, origin: ArrayLike) -> "BGKMap":
        """Add one scan's evidence; return self.

        Parameters
        ----------
        points : array-like of shape (n_points, 3)
            End points of the beams in the world frame, in metres. An empty scan
            changes nothing.
        origin : array-like of shape (3,)
            Sensor position, in metres.

        Raises
        ------
        TypeError
            If `points` or `origin` does not hold real numbers.
        ValueError
            If their shapes are wrong, they hold NaN or inf, or lie outside the
            key range; the map is then unchanged.
        """
        pts, org = self._validated_scan(points, origin)
        samples, labels = self._training_data(pts, org)
        if len(samples):
            n = len(samples)
            precision = np.broadcast_to(np.eye(3) / self.ell ** 2, (n, 3, 3)).copy()
            extent = np.full((n, 3), self.ell)
            self._accumulate(np.ascontiguousarray(samples), labels, precision, extent,
                             np.ones(n), self.sf2)
        return self

    # evaluation harness protocol: maps take scans through insert_scan
    def insert_scan(self, points: ArrayLike, origin: ArrayLike) -> "BGKMap":
        """Alias of :meth:`update`, for :mod:`occgp.evaluation`."""
        return self.update(points, origin)
