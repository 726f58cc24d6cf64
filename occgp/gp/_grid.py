"""The log-odds occupancy grid baseline in 2D or 3D, and evaluation of maps on grids.

:class:`OccupancyGrid` takes the data of the Gaussian-process maps (laser hits
and free beam segments) and integrates it with OctoMap's sensor model, so that
both can be scored on the same test points. :func:`grid_points` and
:func:`predict_grid` evaluate any fitted map on the cell centres of a box.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import expit, logit
from sklearn.base import BaseEstimator
from sklearn.utils.validation import check_is_fitted

from .._validation import as_point, as_points, check_real

__all__ = ["OccupancyGrid", "grid_points", "predict_grid"]

#: Crossing intervals shorter than this (in cells along the segment's longest axis) are skipped,
#: so a segment through a grid corner or edge marks no cell it only touches.
_TOL = 1e-9


def _unique_rows(keys: NDArray[np.int64]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Rows of `keys` sorted lexicographically without repeats, and where each row went.

    As ``np.unique(keys, axis=0, return_inverse=True)``, several times faster.
    """
    order = np.lexsort(keys.T[::-1])
    ordered = keys[order]
    new = np.ones(len(keys), dtype=bool)
    new[1:] = (ordered[1:] != ordered[:-1]).any(axis=1)
    inverse = np.empty(len(keys), dtype=np.int64)
    inverse[order] = np.cumsum(new) - 1
    return ordered[new], inverse


def _row_codes(table: NDArray[np.int64],
               query: NDArray[np.int64]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Integer codes of the rows of `table` (sorted and unique) and `query`.

    Equal rows get equal codes and the table codes increase, so that
    ``np.searchsorted`` finds query rows in the table.
    """
    low = table.min(axis=0)
    extent = table.max(axis=0) - low + 1
    if math.prod(extent.tolist()) < 2**62:  # mixed radix over the table's bounding box
        stride = np.cumprod(np.r_[1, extent[:0:-1]])[::-1]
        inside = ((query >= low) & (query - low < extent)).all(axis=1)
        query = np.where(inside[:, None], query, low)
        return (table - low) @ stride, np.where(inside, (query - low) @ stride, -1)
    _, inverse = _unique_rows(np.concatenate([table, query]))  # ranks keep the table's order
    return inverse[:len(table)], inverse[len(table):]


def _free_cells(starts: NDArray[np.float64], ends: NDArray[np.float64],
                resolution: float) -> NDArray[np.int64]:
    """Keys of the cells whose interior each segment crosses, its end cell excepted.

    Returns one row per segment and cell (a segment visits a cell at most once).
    The crossing parameters t in (0, 1) of every segment with every grid plane
    are generated at once, sorted by (segment, t), and each interval between
    consecutive parameters is one cell: the start cell stepped once per plane
    crossed so far on each axis (an exact DDA, without floor() of midpoints).
    """
    a, b = starts / resolution, ends / resolution
    n, dim = a.shape
    step = np.sign(b - a).astype(np.int64)
    first_key = np.where(step < 0, np.ceil(a) - 1, np.floor(a)).astype(np.int64)
    # Sentinels at t=0 and t=1 bracket each segment's crossings.
    seg_parts, t_parts, axis_parts = [np.arange(n)], [np.zeros(n)], [np.full(n, -1)]
    counts = np.empty((n, dim), dtype=np.int64)  # planes crossed per segment and axis
    for d in range(dim):
        lo = np.floor(np.minimum(a[:, d], b[:, d])) + 1  # planes strictly inside
        hi = np.ceil(np.maximum(a[:, d], b[:, d])) - 1
        counts[:, d] = count = np.maximum(hi - lo + 1, 0).astype(np.int64)
        seg = np.repeat(np.arange(n), count)
        offset = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
        plane = np.repeat(lo, count) + offset
        seg_parts.append(seg)
        t_parts.append((plane - a[seg, d]) / (b[seg, d] - a[seg, d]))
        axis_parts.append(np.full(seg.size, d))
    seg_parts.append(np.arange(n))
    t_parts.append(np.ones(n))
    axis_parts.append(np.full(n, -1))
    seg, t, axis = (np.concatenate(p) for p in (seg_parts, t_parts, axis_parts))
    # As np.lexsort((t, seg)), faster. The order of equal t does not matter:
    # the interval between them is empty and skipped.
    order = np.argsort(t)
    order = order[np.argsort(seg[order], kind="stable")]
    seg, t, axis = seg[order], t[order], axis[order]

    crossed = np.cumsum(axis[:, None] == np.arange(dim), axis=0)  # over all segments
    crossed_before = np.cumsum(counts, axis=0) - counts
    span = np.abs(b - a).max(axis=1)
    keep = (seg[:-1] == seg[1:]) & ((t[1:] - t[:-1]) * span[seg[:-1]] > _TOL)
    idx = np.flatnonzero(keep)
    s = seg[idx]
    keys = first_key[s] + step[s] * (crossed[idx] - crossed_before[s])
    end_key = np.floor(b).astype(np.int64)
    return keys[~(keys == end_key[s]).all(axis=1)]


def _shape(x) -> tuple[int, ...] | None:
    """Shape of `x` if it converts to a numeric array, else None (as_points says why)."""
    try:
        arr = np.asarray(x)
    except (ValueError, TypeError):
        return None
    return arr.shape if arr.dtype.kind in "iuf" else None


def _check_data(hits, segment_starts, segment_ends, dim=None):
    """Validated (hits, starts, ends), float64 of `dim` columns (2 or 3 from the data if None)."""
    if (segment_starts is None) != (segment_ends is None):
        missing = "segment_ends" if segment_ends is None else "segment_starts"
        raise ValueError("segment_starts and segment_ends must both be given or both be "
                         f"None, got {missing}=None")
    given = [(name, x) for name, x in (("hits", hits), ("segment_starts", segment_starts),
                                       ("segment_ends", segment_ends)) if x is not None]
    if not given:
        raise ValueError("no data: give hits, or segment_starts and segment_ends")
    if dim is None:
        found = {}
        for name, x in given:
            shape = _shape(x)
            if shape is not None and (len(shape) != 2 or shape[1] not in (2, 3)):
                raise ValueError(
                    f"{name} must have shape (n_points, 2) or (n_points, 3), got {shape}")
            if shape is not None:
                found[name] = shape[1]
        if len(set(found.values())) > 1:
            got = ", ".join(f"{name} {n}" for name, n in found.items())
            raise ValueError(f"all arrays must have the same number of columns, got {got}")
        dim = next(iter(found.values()), 3)
    arrays = {name: as_points(x, name, dim) for name, x in given}
    empty = np.empty((0, dim))
    hits = arrays.get("hits", empty)
    starts = arrays.get("segment_starts", empty)
    ends = arrays.get("segment_ends", empty)
    if len(starts) != len(ends):
        raise ValueError("segment_starts and segment_ends must have the same length, "
                         f"got {len(starts)} and {len(ends)}")
    if len(hits) == 0 and len(starts) == 0:
        raise ValueError("no data: got 0 hits and 0 segments")
    return hits, starts, ends


class OccupancyGrid(BaseEstimator):
    """Log-odds occupancy grid in 2D or 3D, the classic baseline of GP maps.

    The plane (or space) is cut into square (cubic) cells of edge `resolution`;
    each observed cell holds the log-odds of being occupied. Every free beam
    segment marks the cells it crosses as free, except the cell holding its end
    point (OctoMap's convention: a beam's end cell is left to the hit). Every
    hit marks its cell as occupied. In one call to :meth:`fit` or
    :meth:`update` a cell crossed by ``n_free`` segments and holding ``n_hit``
    hits gains ``n_free * logit(prob_miss) + n_hit * logit(prob_hit)``, and the
    result is clamped to ``[logit(clamping_min), logit(clamping_max)]`` ("ray
    mode": the order of the data within a call does not matter).

    The traversal is exact: a segment marks every cell whose interior it
    passes through, as a DDA would, and nothing else; through a grid corner it
    steps diagonally. A segment inside one cell, or of zero length, marks
    nothing. A point on a cell boundary belongs to the cell above it: cell keys
    are ``floor(x / resolution)`` per axis.

    Parameters
    ----------
    resolution : float, default=0.1
        Edge length of the cells, in metres. Must be positive.
    prob_hit : float, default=0.7
        Probability that a cell is occupied given a hit in it; in (0.5, 1).
    prob_miss : float, default=0.4
        Probability that a cell is occupied given a beam crosses it; in (0, 0.5).
    clamping_min : float, default=0.1192
        Lower clamping bound (probability); in (0, 0.5).
    clamping_max : float, default=0.971
        Upper clamping bound (probability); in (0.5, 1).

    Attributes
    ----------
    keys_ : ndarray of shape (n_cells, n_dims), dtype int64
        Integer coordinates of the observed cells, sorted lexicographically.
    log_odds_ : ndarray of shape (n_cells,)
        Log-odds of occupancy of the cells in `keys_`.
    n_dims_ : int
        Dimension of the map (2 or 3), taken from the data at :meth:`fit`.
    n_updates_ : int
        Number of calls to :meth:`fit` and :meth:`update` since the last fit.

    See Also
    --------
    occgp.GridMap : The 3D grid on the compiled OctoMap core, fed by scans.

    References
    ----------
    .. [1] A. Hornung, K. M. Wurm, M. Bennewitz, C. Stachniss and W. Burgard,
       "OctoMap: an efficient probabilistic 3D mapping framework based on
       octrees", Autonomous Robots 34(3), 2013.

    Examples
    --------
    One beam from (0.5, 0.5) ending in a hit at (3.5, 0.5):

    >>> grid = OccupancyGrid(resolution=1.0).fit(
    ...     [[3.5, 0.5]], segment_starts=[[0.5, 0.5]], segment_ends=[[3.5, 0.5]])
    >>> grid.keys_
    array([[0, 0],
           [1, 0],
           [2, 0],
           [3, 0]])
    >>> grid.predict_proba([[1.5, 0.5], [3.5, 0.5], [9.0, 9.0]])  # free, hit, unknown
    array([0.4, 0.7, 0.5])
    """

    def __init__(self, resolution: float = 0.1, prob_hit: float = 0.7,
                 prob_miss: float = 0.4, clamping_min: float = 0.1192,
                 clamping_max: float = 0.971):
        self.resolution = resolution
        self.prob_hit = prob_hit
        self.prob_miss = prob_miss
        self.clamping_min = clamping_min
        self.clamping_max = clamping_max

    def fit(self, hits: ArrayLike | None, segment_starts: ArrayLike | None,
            segment_ends: ArrayLike | None) -> "OccupancyGrid":
        """Build the map from hits and free beam segments, discarding any earlier map.

        Parameters
        ----------
        hits : array-like of shape (n_hits, n_dims) or None
            Laser returns (occupied points), in metres; ``n_dims`` is 2 or 3.
            None is the same as no hits.
        segment_starts : array-like of shape (n_segments, n_dims) or None
            Start of each free segment (the sensor origin), in metres.
        segment_ends : array-like of shape (n_segments, n_dims) or None
            End of each free segment (the beam end), in metres. None if and only
            if `segment_starts` is None.

        Returns
        -------
        self : OccupancyGrid
            The fitted map.

        Raises
        ------
        ValueError
            If a parameter is out of range, if an array is not of shape
            (n, 2) or (n, 3), if the arrays differ in dimension, if starts and
            ends differ in length or only one is given, if a value is NaN or
            inf, or if there are neither hits nor segments.
        TypeError
            If an array does not hold real numbers.

        Examples
        --------
        >>> grid = OccupancyGrid(resolution=0.5).fit([[1.2, 0.3, 0.1]], None, None)
        >>> grid.n_dims_, grid.keys_.tolist()
        (3, [[2, 0, 0]])
        """
        params = {
            "resolution": check_real(self.resolution, "resolution", low=0.0),
            "prob_hit": check_real(self.prob_hit, "prob_hit", low=0.5, high=1.0),
            "prob_miss": check_real(self.prob_miss, "prob_miss", low=0.0, high=0.5),
            "clamping_min": check_real(self.clamping_min, "clamping_min", low=0.0, high=0.5),
            "clamping_max": check_real(self.clamping_max, "clamping_max", low=0.5, high=1.0),
        }
        data = _check_data(hits, segment_starts, segment_ends)
        self._params = params
        self.n_dims_ = data[0].shape[1]
        self.keys_ = np.empty((0, self.n_dims_), dtype=np.int64)
        self.log_odds_ = np.empty(0)
        self.n_updates_ = 0
        return self._integrate(*data)

    def update(self, hits: ArrayLike | None = None, segment_starts: ArrayLike | None = None,
               segment_ends: ArrayLike | None = None) -> "OccupancyGrid":
        """Add hits and free segments to the fitted map.

        Takes the same data as :meth:`fit`, in the dimension of the map. Bad
        input raises before anything changes. Clamping applies once per call,
        so without clamping, fit then update equals one fit on all the data.

        Parameters
        ----------
        hits : array-like of shape (n_hits, n_dims), default=None
            Laser returns (occupied points), in metres.
        segment_starts : array-like of shape (n_segments, n_dims), default=None
            Start of each free segment, in metres.
        segment_ends : array-like of shape (n_segments, n_dims), default=None
            End of each free segment, in metres.

        Returns
        -------
        self : OccupancyGrid
            The updated map.

        Raises
        ------
        NotFittedError
            If the map is not fitted.
        ValueError, TypeError
            As for :meth:`fit`; an array of another dimension than the map
            raises ValueError.

        Examples
        --------
        >>> grid = OccupancyGrid(resolution=1.0).fit([[0.5, 0.5]], None, None)
        >>> grid = grid.update(hits=[[0.5, 0.5]])
        >>> grid.n_updates_, round(float(grid.log_odds_[0]), 3)
        (2, 1.695)
        """
        check_is_fitted(self)
        data = _check_data(hits, segment_starts, segment_ends, self.n_dims_)
        return self._integrate(*data)

    def _integrate(self, hits, starts, ends):
        p = self._params
        free = _free_cells(starts, ends, p["resolution"])
        hit = np.floor(hits / p["resolution"]).astype(np.int64)
        n_old, n_new = len(self.keys_), len(self.keys_) + len(free)
        keys, inverse = _unique_rows(np.concatenate([self.keys_, free, hit]))
        n_free = np.bincount(inverse[n_old:n_new], minlength=len(keys))
        n_hit = np.bincount(inverse[n_new:], minlength=len(keys))
        log_odds = n_free * logit(p["prob_miss"]) + n_hit * logit(p["prob_hit"])
        log_odds[inverse[:n_old]] += self.log_odds_  # old keys are unique: no repeats
        lo, hi = logit(p["clamping_min"]), logit(p["clamping_max"])
        self.keys_ = keys
        self.log_odds_ = np.clip(log_odds, lo, hi)
        self.n_updates_ += 1
        return self

    def _lookup(self, X):
        """Index in `keys_` of the cell of each point of X, and whether it is known."""
        check_is_fitted(self)
        X = as_points(X, "X", self.n_dims_)
        query = np.floor(X / self._params["resolution"]).astype(np.int64)
        if len(self.keys_) == 0:
            return np.zeros(len(query), dtype=np.intp), np.zeros(len(query), dtype=bool)
        table, query = _row_codes(self.keys_, query)
        index = np.searchsorted(table, query)
        known = index < len(table)
        known[known] = table[index[known]] == query[known]
        return index, known

    def log_odds(self, X: ArrayLike) -> NDArray[np.float64]:
        """Log-odds of occupancy of the cells holding the points of `X`; NaN where unknown.

        Parameters
        ----------
        X : array-like of shape (n_points, n_dims)
            Query points, in metres. Must be finite.

        Returns
        -------
        log_odds : ndarray of shape (n_points,)
            Log-odds of the cell of each point, NaN for a cell never observed.

        Examples
        --------
        >>> grid = OccupancyGrid(resolution=1.0).fit([[0.5, 0.5]], None, None)
        >>> grid.log_odds([[0.2, 0.9], [1.5, 0.5]]).round(3)
        array([0.847,   nan])
        """
        index, known = self._lookup(X)
        out = np.full(len(known), np.nan)
        out[known] = self.log_odds_[index[known]]
        return out

    def predict_proba(self, X: ArrayLike) -> NDArray[np.float64]:
        """Probability that the cells holding the points of `X` are occupied.

        Parameters
        ----------
        X : array-like of shape (n_points, n_dims)
            Query points, in metres. Must be finite.

        Returns
        -------
        proba : ndarray of shape (n_points,)
            Occupancy probability of the cell of each point; 0.5 (the prior)
            for a cell never observed.

        Examples
        --------
        >>> grid = OccupancyGrid(resolution=1.0).fit([[0.5, 0.5]], None, None)
        >>> grid.predict_proba([[0.2, 0.9], [1.5, 0.5]])
        array([0.7, 0.5])
        """
        return np.nan_to_num(expit(self.log_odds(X)), nan=0.5)

    def is_known(self, X: ArrayLike) -> NDArray[np.bool_]:
        """Whether the cells holding the points of `X` have been observed.

        Parameters
        ----------
        X : array-like of shape (n_points, n_dims)
            Query points, in metres. Must be finite.

        Returns
        -------
        known : ndarray of shape (n_points,), dtype bool

        Examples
        --------
        >>> grid = OccupancyGrid(resolution=1.0).fit([[0.5, 0.5]], None, None)
        >>> grid.is_known([[0.2, 0.9], [1.5, 0.5]])
        array([ True, False])
        """
        return self._lookup(X)[1]

    def cells(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Centres and occupancy probabilities of the observed cells.

        Returns
        -------
        centres : ndarray of shape (n_cells, n_dims)
            Cell centres ``(keys_ + 0.5) * resolution``, in metres.
        proba : ndarray of shape (n_cells,)
            Occupancy probability of each cell.

        Examples
        --------
        >>> grid = OccupancyGrid(resolution=1.0).fit([[0.5, 2.5]], None, None)
        >>> grid.cells()
        (array([[0.5, 2.5]]), array([0.7]))
        """
        check_is_fitted(self)
        return (self.keys_ + 0.5) * self._params["resolution"], expit(self.log_odds_)


def grid_points(lower: ArrayLike, upper: ArrayLike,
                resolution: float) -> tuple[NDArray[np.float64], tuple[int, ...]]:
    """Centres of a regular grid of cells covering the box [lower, upper).

    Cell ``i`` along axis ``d`` has its centre at
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

    Returns
    -------
    points : ndarray of shape (n_points, n_dims)
        The cell centres, ordered so that ``values.reshape(shape)`` is indexed
        ``[i_0, i_1(, i_2)]`` (the first axis is x).
    shape : tuple of int
        Number of cells along each axis.

    Raises
    ------
    ValueError
        If `lower` and `upper` are not finite of equal length 2 or 3, if
        ``lower >= upper`` on some axis, or if `resolution` is not positive.

    Examples
    --------
    >>> points, shape = grid_points([0.0, 0.0], [1.0, 0.5], 0.5)
    >>> shape
    (2, 1)
    >>> points
    array([[0.25, 0.25],
           [0.75, 0.25]])
    """
    lower_shape = _shape(lower)
    if lower_shape is not None and lower_shape not in ((2,), (3,)):
        raise ValueError(f"lower must have shape (2,) or (3,), got {lower_shape}")
    dim = 3 if lower_shape is None else lower_shape[0]  # else as_point says what is wrong
    lower = as_point(lower, "lower", dim)
    upper = as_point(upper, "upper", dim)
    resolution = check_real(resolution, "resolution", low=0.0)
    if not (lower < upper).all():
        raise ValueError(f"lower must be below upper on every axis, got lower={lower.tolist()} "
                         f"and upper={upper.tolist()}")
    shape = tuple(int(n) for n in np.ceil((upper - lower) / resolution - 1e-9))
    axes = [lo + (np.arange(n) + 0.5) * resolution for lo, n in zip(lower, shape)]
    mesh = np.meshgrid(*axes, indexing="ij")
    return np.column_stack([m.reshape(-1) for m in mesh]), shape


_OUTPUTS = ("proba", "mean", "var")


def predict_grid(model, lower: ArrayLike, upper: ArrayLike, resolution: float, *,
                 output: str = "proba", batch_size: int = 50_000) -> NDArray[np.float64]:
    """Evaluate a fitted map on the cell centres of a regular grid.

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

    Returns
    -------
    values : ndarray of shape ``shape``
        The values at the cell centres, indexed ``[i_0, i_1(, i_2)]``, where
        ``shape`` is that of :func:`grid_points`.

    Raises
    ------
    ValueError
        If `output` is unknown, `batch_size` is not a positive integer, or the
        grid is invalid (see :func:`grid_points`).

    Examples
    --------
    >>> grid = OccupancyGrid(resolution=1.0).fit([[0.5, 0.5]], None, None)
    >>> predict_grid(grid, [0.0, 0.0], [2.0, 1.0], 1.0)
    array([[0.7],
           [0.5]])
    """
    if output not in _OUTPUTS:
        raise ValueError(f"output must be one of {_OUTPUTS}, got {output!r}")
    if isinstance(batch_size, bool) or not isinstance(batch_size, (int, np.integer)):
        raise TypeError(f"batch_size must be an integer, got {type(batch_size).__name__}")
    if batch_size < 1:
        raise ValueError(f"batch_size must be a positive integer, got {batch_size}")
    points, shape = grid_points(lower, upper, resolution)
    values = np.empty(len(points))
    for start in range(0, len(points), batch_size):
        batch = points[start:start + batch_size]
        if output == "proba":
            values[start:start + batch_size] = model.predict_proba(batch)
        else:
            mean, var = model.predict(batch, return_var=True)
            values[start:start + batch_size] = mean if output == "mean" else var
    return values.reshape(shape)
