"""What the kernel maps hand out: their cells and kernels as named arrays, the
sparse kernel and voxel-grid centroids."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._kernel import sparse_kernel as _compiled_sparse_kernel
from .._validation import as_points, check_real
from ._kernel_samples import cube_sums


class KernelCells(NamedTuple):
    """The cells of a kernel map, as arrays (one row per cell)."""

    #: Cell centers, shape (n_cells, 3), in metres.
    centers: NDArray[np.float64]
    #: Occupied evidence alpha (prior included), shape (n_cells,).
    alpha: NDArray[np.float64]
    #: Free evidence beta (prior included), shape (n_cells,).
    beta: NDArray[np.float64]


class Bandwidths(NamedTuple):
    """Per-sample kernels of an :class:`AKIMap` update (see :meth:`AKIMap.bandwidths`)."""

    #: Inverse bandwidth matrices H^-1, shape (n_samples, 3, 3).
    precision: NDArray[np.float64]
    #: Half-size of each support's bounding box per axis, shape (n_samples, 3), metres.
    extent: NDArray[np.float64]
    #: Kernel weights ``|H|^-1/2``, shape (n_samples,).
    weight: NDArray[np.float64]
    #: Length-scale factor c of H = c^2 Sigma (1 for the isotropic fallback).
    scale: NDArray[np.float64]
    #: Same-label samples in each search ball, the sample itself included.
    n_same: NDArray[np.int64]


def sparse_kernel(r: ArrayLike) -> NDArray[np.float64]:
    """The sparse kernel ``((2 + cos 2 pi r)(1 - r)) / 3 + sin(2 pi r) / (2 pi)`` for
    ``|r| < 1``, 0 beyond (Melkumyan and Ramos, 2009), element-wise; NaN where `r`
    is NaN.

    Parameters
    ----------
    r : array-like of real numbers, any shape
        Normalised distances.

    Returns
    -------
    ndarray of the shape of `r`

    Raises
    ------
    TypeError
        If `r` does not hold real numbers.

    Examples
    --------
    >>> from occgp.kernel import sparse_kernel
    >>> sparse_kernel([0.0, 1.0, 2.0]).tolist()
    [1.0, 0.0, 0.0]
    """
    arr = np.asarray(r)
    if arr.dtype.kind not in "biuf":
        raise TypeError(f"r must hold real numbers, got dtype {arr.dtype}")
    flat = np.ascontiguousarray(arr, dtype=np.float64).ravel()
    out = _compiled_sparse_kernel(flat)
    out[np.isnan(flat)] = np.nan
    return out.reshape(arr.shape)


def voxel_centroids(points: ArrayLike, size: float) -> NDArray[np.float64]:
    """The centroid of the points in each cube of edge `size` that holds any (PCL's
    ``VoxelGrid``), ordered by cube.

    Parameters
    ----------
    points : array-like of shape (n_points, 3)
        The points, in metres.
    size : float
        Edge of the cubes, in metres.

    Returns
    -------
    centroids : ndarray of shape (n_cubes, 3)
        One row per cube holding a point, ordered by z, then y, then x.

    Raises
    ------
    TypeError, ValueError
        If `points` is not a finite array of shape (n_points, 3), `size` not a
        positive real, or the points span more than 2^21 cubes on an axis.

    Examples
    --------
    >>> from occgp.kernel import voxel_centroids
    >>> voxel_centroids([[0.1, 0, 0], [0.3, 0, 0], [1.5, 0, 0]], 1.0).tolist()
    [[0.2, 0.0, 0.0], [1.5, 0.0, 0.0]]
    """
    points = as_points(points, "points")
    size = check_real(size, "size", low=0.0)
    if len(points) == 0:
        return np.empty((0, 3))
    _, sums, counts = cube_sums(points, size)
    return sums / counts[:, None]
