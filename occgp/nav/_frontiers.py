"""Frontiers: the known-free cells next to unknown space, grouped into clusters.

:func:`find_frontiers` works on a dense grid of cell states (1 occupied, 0 free,
-1 unknown) in 2D or 3D; the log-odds maps (``frontiers`` of
:class:`occgp.OccupancyOctree` and :class:`occgp.GridMap`) and
:class:`occgp.OccupancyGrid2D` build that grid and call it.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from .._validation import check_int

__all__ = ["Frontiers", "find_frontiers"]


class Frontiers(NamedTuple):
    """Frontier cells and their clusters (see :meth:`occgp.OccupancyOctree.frontiers`).

    A frontier cell is a known-free cell with at least one unknown face
    neighbour (6 in 3D, 4 in 2D). Frontier cells are grouped into clusters, the
    connected components of the frontier cells with 26-connectivity in 3D and
    8-connectivity in 2D (cells sharing a face, an edge or a corner). Clusters
    come largest first (ties in the order of their first cell along the
    grid's last axis fastest); each cluster's cells are contiguous in `cells`.
    """

    #: Centers of the frontier cells, shape (n_cells, n_dims), metres; grouped by cluster.
    cells: NDArray[np.float64]
    #: The cluster of each cell, shape (n_cells,): an index into `sizes` and `centroids`.
    labels: NDArray[np.int64]
    #: Mean of each cluster's cell centers, shape (n_clusters, n_dims), metres.
    centroids: NDArray[np.float64]
    #: Number of cells of each cluster, shape (n_clusters,), in decreasing order.
    sizes: NDArray[np.int64]

    @property
    def n_clusters(self) -> int:
        """Number of clusters."""
        return len(self.sizes)

    def cluster(self, i: int) -> NDArray[np.float64]:
        """The centers of the cells of one cluster.

        Parameters
        ----------
        i : int
            The cluster, in ``[0, n_clusters)`` (0 is the largest).

        Returns
        -------
        cells : ndarray of shape (sizes[i], n_dims)
            Cell centers in metres.

        Raises
        ------
        TypeError
            If `i` is not an int.
        ValueError
            If `i` lies outside ``[0, n_clusters)``.

        Examples
        --------
        >>> import numpy as np
        >>> from occgp import OccupancyGrid2D
        >>> grid = OccupancyGrid2D([[0, 0, -1]], origin=[0, 0], resolution=1.0)
        >>> grid.frontiers().cluster(0).tolist()
        [[0.5, 0.5], [0.5, 1.5]]
        """
        if self.n_clusters == 0:
            raise ValueError("i: there are no frontier clusters")
        i = check_int(i, "i", low=0, high=self.n_clusters - 1)
        return self.cells[self.labels == i]


def empty_frontiers(n_dims: int) -> Frontiers:
    """Frontiers without any cell, in `n_dims` dimensions."""
    return Frontiers(np.empty((0, n_dims)), np.empty(0, dtype=np.int64),
                     np.empty((0, n_dims)), np.empty(0, dtype=np.int64))


def find_frontiers(states: np.ndarray, origin: np.ndarray, resolution: float,
                   min_size: int, *, padded: bool = False) -> Frontiers:
    """The frontiers of a dense grid of cell states.

    Parameters
    ----------
    states : ndarray of int8, 2D or 3D
        1 occupied, 0 free, -1 unknown, indexed along x, y (, z). With `padded`,
        it holds one more cell on each side of every axis (the states around the
        grid); otherwise the cells beyond the grid count as unknown.
    origin : ndarray of shape (n_dims,)
        Minimum corner of the grid (without the padding), metres.
    resolution : float
        Cell edge, metres.
    min_size : int
        Clusters of fewer cells are dropped (checked by the caller).
    padded : bool, default=False
        Whether `states` holds the ring of neighbouring states.

    Returns
    -------
    frontiers : Frontiers
    """
    from scipy import ndimage  # type: ignore[import-untyped]

    d = states.ndim
    if not padded:
        states = np.pad(states, 1, constant_values=-1)
    inner = tuple(slice(1, n - 1) for n in states.shape)
    unknown = states == -1
    near_unknown = np.zeros(tuple(n - 2 for n in states.shape), dtype=bool)
    for axis in range(d):
        for step in (-1, 1):
            shifted = list(inner)
            shifted[axis] = slice(1 + step, states.shape[axis] - 1 + step)
            near_unknown |= unknown[tuple(shifted)]
    mask = (states[inner] == 0) & near_unknown
    del unknown, near_unknown
    labelled, n = ndimage.label(mask, structure=np.ones((3,) * d, dtype=bool))
    if n == 0:
        return empty_frontiers(d)
    flat = np.flatnonzero(mask.ravel())
    old = labelled.ravel()[flat].astype(np.int64) - 1
    sizes = np.bincount(old, minlength=n)
    order = np.argsort(-sizes, kind="stable")
    order = order[sizes[order] >= min_size]
    if len(order) == 0:
        return empty_frontiers(d)
    new = np.full(n, -1, dtype=np.int64)
    new[order] = np.arange(len(order))
    labels = new[old]
    keep = labels >= 0
    flat, labels = flat[keep], labels[keep]
    by_cluster = np.argsort(labels, kind="stable")
    flat, labels = flat[by_cluster], labels[by_cluster]
    index = np.column_stack(np.unravel_index(flat, mask.shape))
    cells = origin + (index + 0.5) * resolution
    counts = sizes[order]
    sums = np.stack([np.bincount(labels, weights=cells[:, a], minlength=len(order))
                     for a in range(d)], axis=1)
    return Frontiers(cells, labels, sums / counts[:, None], counts.astype(np.int64))
