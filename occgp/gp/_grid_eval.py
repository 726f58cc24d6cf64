"""Evaluation of fitted maps on the cell centers of a regular grid.

:func:`grid_points` and :func:`predict_grid` evaluate any fitted map (a
Gaussian-process model, the log-odds :class:`~occgp.gp.OccupancyGrid`) on the
cell centers of a box.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._validation import as_point, check_real
from ._occupancy_grid import OccupancyGrid, shape_of  # noqa: F401 (OccupancyGrid: doctests)

__all__ = ["grid_points", "predict_grid", "MAX_GRID_POINTS"]

#: Default most cells of :func:`grid_points` and :func:`predict_grid` (points of 24 bytes each
#: in 3D, 16 in 2D).
MAX_GRID_POINTS = 20_000_000


def _check_count(value, name):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be an integer, got {type(value).__name__}")
    if value < 1:
        raise ValueError(f"{name} must be a positive integer, got {value}")
    return int(value)


def _grid_shape(lower, upper, resolution, max_points):
    """Validated lower corner and the number of cells per axis of a grid."""
    lower_shape = shape_of(lower)
    if lower_shape is not None and lower_shape not in ((2,), (3,)):
        raise ValueError(f"lower must have shape (2,) or (3,), got {lower_shape}")
    dim = 3 if lower_shape is None else lower_shape[0]  # else as_point says what is wrong
    lower = as_point(lower, "lower", dim)
    upper = as_point(upper, "upper", dim)
    resolution = check_real(resolution, "resolution", low=0.0)
    max_points = _check_count(max_points, "max_points")
    if not (lower < upper).all():
        raise ValueError(f"lower must be below upper on every axis, got lower={lower.tolist()} "
                         f"and upper={upper.tolist()}")
    with np.errstate(over="ignore"):
        cells = np.maximum(np.ceil((upper - lower) / resolution - 1e-9), 1.0)   # may be inf
        total = float(np.prod(cells))
    if not total <= max_points:
        raise ValueError(
            f"the grid from lower={lower.tolist()} to upper={upper.tolist()} at resolution "
            f"{resolution!r} has {total:.4g} cells, more than max_points={max_points}; use a "
            f"coarser resolution, a smaller box, or raise max_points")
    shape = tuple(int(n) for n in cells)
    return lower, shape


def grid_points(lower: ArrayLike, upper: ArrayLike, resolution: float, *,
                max_points: int = MAX_GRID_POINTS) -> tuple[NDArray[np.float64], tuple[int, ...]]:
    """Centers of a regular grid of cells covering the box [lower, upper).

    Cell ``i`` along axis ``d`` has its center at
    ``lower[d] + (i + 0.5) * resolution``; there are
    ``ceil((upper[d] - lower[d]) / resolution)`` cells along axis ``d`` (up to
    a 1e-9 tolerance), so the last cell may stick out of the box.

    Parameters
    ----------
    lower : array-like of shape (n_dims,)
        Lower corner of the box, in metres; ``n_dims`` is 2 or 3.
    upper : array-like of shape (n_dims,)
        Upper corner of the box, in metres; above `lower` on every axis.
    resolution : float
        Edge length of the cells, in metres. Must be positive.
    max_points : int, default=20_000_000
        Most cells the grid may have (``prod(shape)``); a larger box raises
        before anything is allocated. The points take ``8 * n_dims`` bytes
        each (480 MB in 3D at the default).

    Returns
    -------
    points : ndarray of shape (n_points, n_dims)
        The cell centers, ordered so that ``values.reshape(shape)`` is indexed
        ``[i_0, i_1(, i_2)]`` (the first axis is x).
    shape : tuple of int
        Number of cells along each axis.

    Raises
    ------
    ValueError
        If `lower` and `upper` are not finite of equal length 2 or 3, if
        ``lower >= upper`` on some axis, if `resolution` is not positive, or
        if the grid would have more than `max_points` cells.
    TypeError
        If an argument has the wrong type.

    Examples
    --------
    >>> points, shape = grid_points([0.0, 0.0], [1.0, 0.5], 0.5)
    >>> shape
    (2, 1)
    >>> points
    array([[0.25, 0.25],
           [0.75, 0.25]])
    """
    lower, shape = _grid_shape(lower, upper, resolution, max_points)
    axes = [lo + (np.arange(n) + 0.5) * resolution for lo, n in zip(lower, shape)]
    mesh = np.meshgrid(*axes, indexing="ij")
    return np.column_stack([m.reshape(-1) for m in mesh]), shape


_OUTPUTS = ("proba", "mean", "var")




def predict_grid(model, lower: ArrayLike, upper: ArrayLike, resolution: float, *,
                 output: str = "proba", batch_size: int = 50_000,
                 max_points: int = MAX_GRID_POINTS) -> NDArray[np.float64]:
    """Evaluate a fitted map on the cell centers of a regular grid.

    Parameters
    ----------
    model : object
        A fitted map: with ``predict_proba(points)`` for ``output="proba"``,
        with ``predict(points, return_var=True)`` returning ``(mean, var)``
        otherwise.
    lower, upper, resolution
        The grid, as for :func:`grid_points`.
    output : {"proba", "mean", "var"}, default="proba"
        What to evaluate: the occupancy probability, or the predictive mean or
        variance of a Gaussian-process model.
    batch_size : int, default=50_000
        Number of points passed to the model at once.
    max_points : int, default=20_000_000
        Most cells of the grid, as for :func:`grid_points`; the values take
        8 bytes a cell, and only one batch of points exists at a time.

    Returns
    -------
    values : ndarray of shape ``shape``
        The values at the cell centers, indexed ``[i_0, i_1(, i_2)]``, where
        ``shape`` is that of :func:`grid_points`.

    Raises
    ------
    ValueError
        If `output` is unknown, `batch_size` is not a positive integer, or the
        grid is invalid or larger than `max_points` (see :func:`grid_points`).
    TypeError
        If `output` is not a string or `batch_size` not an integer.

    Examples
    --------
    >>> grid = OccupancyGrid(resolution=1.0).fit([[0.5, 0.5]], None, None)
    >>> predict_grid(grid, [0.0, 0.0], [2.0, 1.0], 1.0)
    array([[0.7],
           [0.5]])
    """
    if not isinstance(output, str):
        raise TypeError(f"output must be one of {_OUTPUTS}, got {type(output).__name__}")
    if output not in _OUTPUTS:
        raise ValueError(f"output must be one of {_OUTPUTS}, got {output!r}")
    batch_size = _check_count(batch_size, "batch_size")
    method = "predict_proba" if output == "proba" else "predict"
    if not callable(getattr(model, method, None)):
        raise TypeError(f"model must have a {method}() method for output={output!r}, got "
                        f"{type(model).__name__}")
    # points are made batch by batch, never all at once
    lower_arr, shape = _grid_shape(lower, upper, resolution, max_points)
    n = math.prod(shape)
    strides = np.cumprod((shape[1:] + (1,))[::-1])[::-1]
    batch_size = min(batch_size, n)
    values = np.empty(n)
    for start in range(0, n, batch_size):
        index = np.arange(start, min(start + batch_size, n))
        cell = (index[:, None] // strides) % np.asarray(shape)
        batch = lower_arr + (cell + 0.5) * float(resolution)
        if output == "proba":
            values[start:start + batch_size] = model.predict_proba(batch)
        else:
            mean, var = model.predict(batch, return_var=True)
            values[start:start + batch_size] = mean if output == "mean" else var
    return values.reshape(shape)
