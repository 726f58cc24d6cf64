"""The log-odds occupancy grid baseline in 2D or 3D.

:class:`OccupancyGrid` takes the data of the Gaussian-process maps (laser hits
and free beam segments) and integrates it with OctoMap's sensor model, so that
both can be scored on the same test points.
"""

from __future__ import annotations

import math
import os

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import expit, logit
from sklearn.base import BaseEstimator
from sklearn.utils.validation import check_is_fitted

from .._docfill import fill_doc
from .._params import DEFAULT_RESOLUTION
from .._validation import as_points, check_probability, check_real
from ._io import gp_fitted, read_gp, write_gp
from ..maps import register
from ._map_protocol import MapProtocol

__all__ = ["OccupancyGrid", "shape_of"]

#: Crossing intervals shorter than this (in cells along the segment's longest axis) are skipped,
#: so a segment through a grid corner or edge marks no cell it only touches.
_TOL = 1e-9
#: Largest ``|x| / resolution`` of the data of an :class:`OccupancyGrid`: cell keys stay exact
#: in float64 (below 2**53) and in int64.
MAX_CELL_INDEX = 1e15
#: Most cells one segment may cross; segments are also traversed in chunks of about this many
#: crossings, so memory stays bounded (about 130 bytes a crossing).
MAX_SEGMENT_CELLS = 4_000_000
#: The sections of the grid's queries (see :func:`occgp._docs.fill_doc`).
_QUERY_PARAMETERS = """\
Parameters
----------
X : array-like of shape (n_points, n_dims)
    Query points, in metres. Must be finite."""
_AS_LOG_ODDS_RAISES = """\
Raises
------
NotFittedError, ValueError, TypeError
    As :meth:`log_odds`."""


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


def _crossing_counts(starts, ends, resolution):
    """Upper bound on the cells each segment crosses (grid planes strictly inside it, + 1)."""
    a, b = starts / resolution, ends / resolution
    planes = np.ceil(np.maximum(a, b)) - np.floor(np.minimum(a, b)) - 1
    return np.maximum(planes, 0).sum(axis=1) + 1


def _free_cell_counts(starts, ends, resolution):
    """Distinct keys of the cells the segments cross (end cells excepted) and their counts.

    Segments are traversed in chunks of at most about `MAX_SEGMENT_CELLS`
    crossings, so that a large call never builds the whole crossing list at once.
    """
    dim = starts.shape[1]
    if not len(starts):
        return np.empty((0, dim), dtype=np.int64), np.empty(0, dtype=np.int64)
    per_segment = _crossing_counts(starts, ends, resolution)
    worst = int(np.argmax(per_segment))
    if per_segment[worst] > MAX_SEGMENT_CELLS:
        raise ValueError(
            f"segment {worst} (from {starts[worst].tolist()} to {ends[worst].tolist()}) crosses "
            f"about {per_segment[worst]:.3g} cells at resolution {resolution!r}, more than the "
            f"limit of {MAX_SEGMENT_CELLS}; use a coarser resolution or shorter segments")
    total = np.cumsum(per_segment)
    bounds = [0]
    while bounds[-1] < len(starts):
        base = total[bounds[-1] - 1] if bounds[-1] else 0.0
        bounds.append(max(int(np.searchsorted(total, base + MAX_SEGMENT_CELLS, side="right")),
                          bounds[-1] + 1))
    if len(bounds) == 2:
        return _unique_counts(_free_cells(starts, ends, resolution))
    keys, counts = [], []
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        k, c = _unique_counts(_free_cells(starts[lo:hi], ends[lo:hi], resolution))
        keys.append(k)
        counts.append(c)
    keys, inverse = _unique_rows(np.concatenate(keys))
    return keys, np.bincount(inverse, weights=np.concatenate(counts),
                             minlength=len(keys)).astype(np.int64)


def _unique_counts(keys):
    if not len(keys):
        return keys, np.empty(0, dtype=np.int64)
    table, inverse = _unique_rows(keys)
    return table, np.bincount(inverse, minlength=len(table))


def _check_extent(arrays, resolution):
    """Reject data whose cell keys ``floor(x / resolution)`` would not be exact."""
    for name, x in arrays.items():
        if not len(x):
            continue
        worst = float(np.abs(x).max())
        if worst / resolution > MAX_CELL_INDEX:
            raise ValueError(
                f"{name} must lie within {MAX_CELL_INDEX:g} cells of the origin "
                f"(|x| <= {MAX_CELL_INDEX:g} * resolution = {MAX_CELL_INDEX * resolution:.6g}), "
                f"got a coordinate of {worst:.6g} at resolution {resolution!r}; shift the data "
                f"towards the origin or use a coarser resolution")


def shape_of(x) -> tuple[int, ...] | None:
    """Shape of `x` if it converts to a numeric array, else None (as_points says why)."""
    try:
        arr = np.asarray(x)
    except (ValueError, TypeError):
        return None
    return arr.shape if arr.dtype.kind in "iuf" else None


def _check_data(hits, segment_starts, segment_ends, dim=None, resolution=None):
    """Validated (hits, starts, ends), float64 of `dim` columns (2 or 3 from the data if None).

    With `resolution`, coordinates must lie within `MAX_CELL_INDEX` cells of the origin.
    """
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
            shape = shape_of(x)
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
    if resolution is not None:
        _check_extent(arrays, resolution)
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


@register("gp-grid", dims=(2, 3), formats=(".npz",),
          description="Log-odds occupancy grid of hits and beams, the GP maps' baseline")
@fill_doc(query_parameters=_QUERY_PARAMETERS, as_log_odds_raises=_AS_LOG_ODDS_RAISES)
class OccupancyGrid(MapProtocol, BaseEstimator):
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

    Limits: data must lie within ``MAX_CELL_INDEX = 1e15`` cells of the
    origin (``|x| <= 1e15 * resolution``, where float64 still resolves a
    cell), and one segment may cross at most ``MAX_SEGMENT_CELLS = 4e6``
    cells; a call may hold any number of segments (they are traversed in
    chunks of about 4e6 crossings). Queries beyond the data's range are
    simply unknown.

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
    occupancy_threshold : float, default=0.5
        :meth:`is_occupied`'s threshold: a cell is occupied when its
        probability is at least this; in (0, 1).

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

    Notes
    -----
    **As a map** (:class:`occgp.maps.OccupancyMap`, registered as
    ``"gp-grid"``, 2D or 3D): :meth:`insert_scan` turns a scan into hits and
    beams; the first scan is :meth:`fit`, each later one :meth:`update`
    (clamped once per scan, as OctoMap clamps once per scan in ray mode).
    :meth:`occupancy` is NaN in the cells never observed (where
    :meth:`predict_proba` gives the prior 0.5), :attr:`num_cells` the number
    of observed cells, and :meth:`to_octree` copies the cells at the grid's
    resolution.

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

    def __init__(self, resolution: float = DEFAULT_RESOLUTION, prob_hit: float = 0.7,
                 prob_miss: float = 0.4, clamping_min: float = 0.1192,
                 clamping_max: float = 0.971, occupancy_threshold: float = 0.5):
        self.resolution = resolution
        self.prob_hit = prob_hit
        self.prob_miss = prob_miss
        self.clamping_min = clamping_min
        self.clamping_max = clamping_max
        self.occupancy_threshold = occupancy_threshold

    def _check_params(self) -> dict:
        """The checked parameters of the sensor model."""
        params = {
            "resolution": check_real(self.resolution, "resolution", low=0.0),
            "prob_hit": check_real(self.prob_hit, "prob_hit", low=0.5, high=1.0),
            "prob_miss": check_real(self.prob_miss, "prob_miss", low=0.0, high=0.5),
            "clamping_min": check_real(self.clamping_min, "clamping_min", low=0.0, high=0.5),
            "clamping_max": check_real(self.clamping_max, "clamping_max", low=0.5, high=1.0),
        }
        check_probability(self.occupancy_threshold, "occupancy_threshold")
        return params

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
            inf, if there are neither hits nor segments, if a coordinate lies
            more than 1e15 cells from the origin, or if a segment crosses
            more than 4e6 cells.
        TypeError
            If an array does not hold real numbers.

        Examples
        --------
        >>> grid = OccupancyGrid(resolution=0.5).fit([[1.2, 0.3, 0.1]], None, None)
        >>> grid.n_dims_, grid.keys_.tolist()
        (3, [[2, 0, 0]])
        """
        params = self._check_params()
        data = _check_data(hits, segment_starts, segment_ends, resolution=params["resolution"])
        free = _free_cell_counts(data[1], data[2], params["resolution"])
        self._params = params
        self.n_dims_ = data[0].shape[1]
        self.keys_ = np.empty((0, self.n_dims_), dtype=np.int64)
        self.log_odds_ = np.empty(0)
        self.n_updates_ = 0
        return self._integrate(data[0], free)

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
        resolution = self._params["resolution"]
        data = _check_data(hits, segment_starts, segment_ends, self.n_dims_, resolution)
        return self._integrate(data[0], _free_cell_counts(data[1], data[2], resolution))

    def _integrate(self, hits, free):
        """Add the hits and the free cells ``(keys, counts)``; nothing can fail here."""
        p = self._params
        free_keys, free_counts = free
        hit = np.floor(hits / p["resolution"]).astype(np.int64)
        n_old, n_new = len(self.keys_), len(self.keys_) + len(free_keys)
        keys, inverse = _unique_rows(np.concatenate([self.keys_, free_keys, hit]))
        n_free = np.bincount(inverse[n_old:n_new], weights=free_counts, minlength=len(keys))
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
        scaled = X / self._params["resolution"]
        near = (np.abs(scaled) <= MAX_CELL_INDEX + 2).all(axis=1)  # no data beyond: unknown
        query = np.floor(np.where(near[:, None], scaled, 0.0)).astype(np.int64)
        if len(self.keys_) == 0:
            return np.zeros(len(query), dtype=np.intp), np.zeros(len(query), dtype=bool)
        table, query = _row_codes(self.keys_, query)
        index = np.searchsorted(table, query)
        known = near & (index < len(table))
        known[known] = table[index[known]] == query[known]
        return index, known

    def log_odds(self, X: ArrayLike) -> NDArray[np.float64]:
        """Log-odds of occupancy of the cells holding the points of `X`; NaN where unknown.

        {query_parameters}

        Returns
        -------
        log_odds : ndarray of shape (n_points,)
            Log-odds of the cell of each point, NaN for a cell never observed.

        Raises
        ------
        NotFittedError
            If called before :meth:`fit`.
        ValueError
            If `X` is not of shape (n_points, n_dims) or holds NaN or inf.
        TypeError
            If `X` does not hold real numbers.

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

        {query_parameters}

        Returns
        -------
        proba : ndarray of shape (n_points,)
            Occupancy probability of the cell of each point; 0.5 (the prior)
            for a cell never observed.

        {as_log_odds_raises}

        Examples
        --------
        >>> grid = OccupancyGrid(resolution=1.0).fit([[0.5, 0.5]], None, None)
        >>> grid.predict_proba([[0.2, 0.9], [1.5, 0.5]])
        array([0.7, 0.5])
        """
        return np.nan_to_num(expit(self.log_odds(X)), nan=0.5)

    def is_known(self, X: ArrayLike) -> NDArray[np.bool_]:
        """Whether the cells holding the points of `X` have been observed.

        {query_parameters}

        Returns
        -------
        known : ndarray of shape (n_points,), dtype bool
            False for a cell never observed, or a point beyond the grid's
            key range.

        {as_log_odds_raises}

        Examples
        --------
        >>> grid = OccupancyGrid(resolution=1.0).fit([[0.5, 0.5]], None, None)
        >>> grid.is_known([[0.2, 0.9], [1.5, 0.5]])
        array([ True, False])
        """
        return self._lookup(X)[1]

    def cells(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Centers and occupancy probabilities of the observed cells.

        Returns
        -------
        centers : ndarray of shape (n_cells, n_dims)
            Cell centers ``(keys_ + 0.5) * resolution``, in metres.
        proba : ndarray of shape (n_cells,)
            Occupancy probability of each cell.

        Raises
        ------
        NotFittedError
            If called before :meth:`fit`.

        Examples
        --------
        >>> grid = OccupancyGrid(resolution=1.0).fit([[0.5, 2.5]], None, None)
        >>> grid.cells()
        (array([[0.5, 2.5]]), array([0.7]))
        """
        check_is_fitted(self)
        return (self.keys_ + 0.5) * self._params["resolution"], expit(self.log_odds_)

    # ---------------------------------------------------------- map protocol
    _scan_dims = (2, 3)

    def _fitted(self):
        return hasattr(self, "keys_")

    def _known(self, X):
        return self.is_known(X)

    def _known_bounds(self):
        if not len(self.keys_):
            return np.full(self.n_dims_, np.nan), np.full(self.n_dims_, np.nan)
        res = self._params["resolution"]
        return self.keys_.min(axis=0) * res, (self.keys_.max(axis=0) + 1) * res

    def _num_cells(self):
        return len(self.keys_)

    def _nbytes(self):
        return self.keys_.nbytes + self.log_odds_.nbytes

    def _octree_resolution(self, resolution):
        return self.resolution if resolution is None else resolution

    def _octree_cells(self, res):
        if res != self._params["resolution"]:
            return super()._octree_cells(res)
        return (self.keys_ + 0.5) * res, self.log_odds_   # the cells as they are

    # ----------------------------------------------------------------- files
    _SPEC = {"keys": (np.int64, ("n_cells", "n_dims")), "log_odds": (np.float64, ("n_cells",))}
    _FITTED = ("n_dims_", "n_updates_")

    def save(self, path: str | os.PathLike) -> "OccupancyGrid":
        """Write the grid (parameters and, once fitted, its cells) to an ``.npz``.

        The format of :meth:`GPOMIK.save <occgp.gp.GPOMIK.save>`
        (``"occgp.gp_model"``, version 1, class ``"OccupancyGrid"``,
        ``params``), with, for a fitted grid: ``fitted`` (0-d str, JSON:
        ``n_dims_``, ``n_updates_``), ``keys`` (int64 (n_cells, n_dims):
        ``keys_``) and ``log_odds`` (float64 (n_cells,): ``log_odds_``).
        :meth:`load` reads it back into a grid that answers, and goes on
        updating, exactly as this one.

        {save_parameters}

        Returns
        -------
        self : OccupancyGrid

        {gp_save_raises}
        """
        arrays = {}
        if self._fitted():
            arrays["fitted"] = gp_fitted({"n_dims_": int(self.n_dims_),
                                          "n_updates_": int(self.n_updates_)})
            arrays["keys"], arrays["log_odds"] = self.keys_, self.log_odds_
        return write_gp(self, path, arrays)

    @classmethod
    def load(cls, path: str | os.PathLike) -> "OccupancyGrid":
        """Read a grid written by :meth:`save`.

        {load_parameters}

        Returns
        -------
        OccupancyGrid
            Fitted when the saved grid was.

        {load_raises}
            Also if its cells are not valid (keys not sorted and distinct,
            log-odds outside the clamping bounds, a dimension other than 2
            or 3).
        """
        source, model, arrays, fitted = read_gp(cls, path, cls._SPEC)
        if fitted is None:
            return model
        keys, log_odds = arrays["keys"], arrays["log_odds"]
        params = model._check_params()
        lo, hi = logit(params["clamping_min"]), logit(params["clamping_max"])
        bad = ""
        if sorted(fitted) != sorted(cls._FITTED):
            bad = f"'fitted' must hold {sorted(cls._FITTED)}, got {sorted(fitted)[:20]}"
        elif keys.shape[1] not in (2, 3) or fitted["n_dims_"] != keys.shape[1]:
            bad = f"n_dims_ must be the keys' width, 2 or 3, got {fitted['n_dims_']!r:.40}"
        elif isinstance(fitted["n_updates_"], bool) or not isinstance(fitted["n_updates_"], int) \
                or fitted["n_updates_"] < 1:
            bad = f"n_updates_ must be a positive int, got {fitted['n_updates_']!r:.40}"
        elif len(keys) and not np.array_equal(_unique_rows(keys)[0], keys):
            bad = "'keys' must be sorted lexicographically without repeats"
        elif (np.abs(keys) > MAX_CELL_INDEX).any():
            bad = f"'keys' must lie within {MAX_CELL_INDEX:g} cells of the origin"
        elif not ((log_odds >= lo - 1e-9) & (log_odds <= hi + 1e-9)).all():
            bad = "'log_odds' must lie within the clamping bounds"
        if bad:
            raise ValueError(f"{source}: corrupt fitted state of an OccupancyGrid: {bad}")
        model._params = params
        model.n_dims_ = keys.shape[1]
        model.keys_, model.log_odds_ = keys, log_odds
        model.n_updates_ = int(fitted["n_updates_"])
        return model
