"""The calls of :class:`occgp.maps.OccupancyMap` for occgp.gp's estimators.

:class:`MapProtocol` gives :class:`~occgp.gp.GPOMIK`, :class:`~occgp.gp.GPOM`,
:class:`~occgp.gp.GPMixture` and :class:`~occgp.gp.OccupancyGrid` the map
protocol on top of their scikit-learn ``fit`` / ``update`` / ``predict_proba``:
a scan becomes hits and beams (:func:`scan_observations`), and queries say
where the model has no evidence. Each model provides the hooks ``_fitted``,
``_insert``, ``_known``, ``_known_bounds``, ``_num_cells`` and ``_nbytes``.
"""

from __future__ import annotations

import copy

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import logit

from .._docfill import fill_doc
from .._params import ParamsMixin
from .._validation import (as_numeric, as_point, as_points, check_bool, check_probability,
                           check_resolution)

__all__ = ["MapProtocol", "scan_observations", "DEFAULT_OCTREE_RESOLUTION", "MAX_OCTREE_CELLS"]

#: Cell edge (metres) of :meth:`MapProtocol.to_octree` for the models without cells.
DEFAULT_OCTREE_RESOLUTION = 0.1
#: Most cells :meth:`MapProtocol.to_octree` evaluates a model on.
MAX_OCTREE_CELLS = 20_000_000
#: Log-odds written to the octree are clipped to this magnitude (p = 1 - 2e-9).
_MAX_LOG_ODDS = 20.0


def _dims_text(dims):
    return " or ".join(str(d) for d in dims)


def scan_observations(points: ArrayLike, origin: ArrayLike, hit: ArrayLike | None,
                      dims: tuple[int, ...], name: str, dim: int | None = None):
    """Hits and beams of one scan: ``(hits, segment_starts, segment_ends)``.

    Every point ends a beam from `origin`; the points where `hit` is True (all
    of them when `hit` is None) are also hits, the others beams without a
    return (free up to the point, as ``observations_from_scans`` treats a
    laser's maximum-range beams). `dims` are the dimensions the map `name`
    takes, `dim` the fitted map's (None before the first scan).
    """
    pts = as_numeric(points, "points")
    got = pts.shape[1] if pts.ndim == 2 else -1
    if got not in dims:
        if pts.ndim == 2 and got == 3 and dims == (2,):
            raise ValueError(f"{name} maps 2D scans: points must have shape (n_points, 2), "
                             f"got {pts.shape} (a 3D scan; fit() takes 3D observations)")
        raise ValueError(f"points must have shape (n_points, {_dims_text(dims)}), "
                         f"got {pts.shape}")
    if dim is not None and got != dim:
        raise ValueError(f"points must have shape (n_points, {dim}) (the map's dimension), "
                         f"got {pts.shape}")
    pts = as_points(pts, "points", got)
    org = as_point(origin, "origin", got)
    if hit is None:
        mask = np.ones(len(pts), dtype=bool)
    else:
        mask = np.asarray(hit)
        if mask.dtype != np.bool_:
            raise TypeError(f"hit must be a bool array, got dtype {mask.dtype}")
        if mask.shape != (len(pts),):
            raise ValueError(f"hit must have shape ({len(pts)},), got {mask.shape}")
    starts = np.ascontiguousarray(np.broadcast_to(org, pts.shape))
    return pts[mask], starts, pts


@fill_doc()
class MapProtocol(ParamsMixin):
    """Mix-in: the map protocol (:class:`occgp.maps.OccupancyMap`) of a 2D estimator.

    The class must define ``occupancy_threshold`` (a constructor parameter),
    ``_check_params()``, ``fit`` and ``predict_proba``, and the hooks below.
    Its ``get_params`` / ``set_params`` are :class:`occgp._params.ParamsMixin`'s
    (before scikit-learn's ``BaseEstimator``), which checks new values with
    ``_check_params`` before any changes.
    """

    #: The dimensions of the points :meth:`insert_scan` takes.
    _scan_dims: tuple[int, ...] = (2,)

    # ----------------------------------------------------------------- hooks
    def _fitted(self) -> bool:
        """Whether the model holds evidence (it has been fitted)."""
        raise NotImplementedError

    def _insert(self, hits, starts, ends) -> None:
        """Add one scan's observations to the fitted model (its ``update``)."""
        self.update(hits, starts, ends)

    def _known(self, X) -> NDArray[np.bool_]:
        """Where the fitted model has evidence (checked points `X`)."""
        raise NotImplementedError

    def _known_bounds(self):
        """(low, high) corners of the fitted model's known space."""
        raise NotImplementedError

    def _num_cells(self) -> int:
        raise NotImplementedError

    def _nbytes(self) -> int:
        raise NotImplementedError

    def _octree_resolution(self, resolution):
        """The resolution of :meth:`to_octree` (None: the default)."""
        return DEFAULT_OCTREE_RESOLUTION if resolution is None else resolution

    # -------------------------------------------------------------- protocol
    def insert_scan(self, points: ArrayLike, origin: ArrayLike, *,
                    hit: ArrayLike | None = None):
        """Integrate one range scan: fit on the first, update with each next one.

        Every point ends a beam from `origin` (a free segment) and is a hit
        (an occupied point) unless `hit` says otherwise. The first scan of an
        unfitted model calls ``fit(hits, segment_starts, segment_ends)``; each
        later one adds its observations to the evidence so far, as described
        in the class docstring (``update``, or a new fit on all of it).

        Parameters
        ----------
        points : array-like of shape (n_points, 2)
            Beam end points in the world frame, in metres (the map's dimension;
            3D only where the class says so).
        origin : array-like of shape (2,)
            Sensor position, in metres.
        hit : array-like of bool, shape (n_points,), default=None
            Which points are returns; the others end beams without a return
            (free up to the point, e.g. at the maximum range). None: all are
            returns.

        Returns
        -------
        self
            The updated map.

        Raises
        ------
        ValueError
            If `points` is not of shape (n_points, D) for a dimension the map
            takes (a 3D scan given to a 2D map says so) or differs from the
            fitted dimension, holds NaN or inf, `origin` is malformed, `hit`
            has the wrong shape, or ``fit`` / ``update`` reject the data; the
            map is then unchanged.
        TypeError
            If an array does not hold real numbers or `hit` booleans.
        """
        fitted = self._fitted()
        hits, starts, ends = scan_observations(
            points, origin, hit, self._scan_dims, type(self).__name__,
            self.n_dims_ if fitted else None)
        if not len(ends):
            return self
        if fitted:
            self._insert(hits, starts, ends)
        else:
            self.fit(hits, starts, ends)
        return self

    def _query_points(self, points):
        if self._fitted():
            return as_points(points, "points", self.n_dims_)
        pts = as_numeric(points, "points")
        dim = pts.shape[1] if pts.ndim == 2 else -1
        if dim not in self._scan_dims:
            raise ValueError(f"points must have shape (n_points, "
                             f"{_dims_text(self._scan_dims)}), got {pts.shape}")
        return as_points(pts, "points", dim)

    def occupancy(self, points: ArrayLike) -> NDArray[np.float64]:
        """Probability of occupancy at each point, NaN where the model has no evidence.

        Where the model has evidence this is :meth:`predict_proba`; where it
        has none (see the class docstring's "Unknown space"), and everywhere
        before the first scan or fit, NaN.

        Parameters
        ----------
        points : array-like of shape (n_points, D)
            Query points, in metres, in the map's dimension D.

        Returns
        -------
        p : ndarray of shape (n_points,)

        Raises
        ------
        ValueError
            If `points` is not of shape (n_points, D) or holds NaN or inf.
        TypeError
            If `points` does not hold real numbers.
        """
        X = self._query_points(points)
        if not self._fitted():
            return np.full(len(X), np.nan)
        return np.where(self._known(X), self.predict_proba(X), np.nan)

    def is_occupied(self, points: ArrayLike, *, return_unknown: bool = False):
        """Whether each point is occupied: its probability is at least ``occupancy_threshold``.

        Unknown points (NaN in :meth:`occupancy`) are not occupied; ask for
        `return_unknown` to tell them apart from free ones.

        Parameters
        ----------
        points : array-like of shape (n_points, D)
            Query points, in metres.
        return_unknown : bool, default=False
            Also return the mask of unknown points.

        {occupied_returns}

        Raises
        ------
        ValueError, TypeError
            As :meth:`occupancy`; also if `occupancy_threshold` is not in (0, 1)
            or `return_unknown` is not a bool.
        """
        return_unknown = check_bool(return_unknown, "return_unknown")
        threshold = check_probability(self.occupancy_threshold, "occupancy_threshold")
        p = self.occupancy(points)
        unknown = np.isnan(p)
        occupied = np.greater_equal(p, threshold, where=~unknown, out=np.zeros(len(p), bool))
        return (occupied, unknown) if return_unknown else occupied

    @property
    def bounds(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(min corner, max corner) of the known space, in metres; NaN before the first fit."""
        if not self._fitted():
            dim = self._scan_dims[0]
            return np.full(dim, np.nan), np.full(dim, np.nan)
        lo, hi = self._known_bounds()
        return np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)

    @property
    def num_cells(self) -> int:
        """Number of cells (observations for the GP models) holding evidence; 0 when unfitted."""
        return int(self._num_cells()) if self._fitted() else 0

    def memory_usage(self) -> int:
        """Bytes of the model's arrays.

        Returns
        -------
        nbytes : int
            0 before the first fit.
        """
        return int(self._nbytes()) if self._fitted() else 0

    def set_params(self, **params):
        """Set the constructor's parameters (scikit-learn's convention), checked.

        Parameters
        ----------
        **params
            Parameter names and values (``name__sub`` for a nested object's).

        {map_returns}

        Raises
        ------
        ValueError
            If a name is not a parameter, or a value is rejected (the message
            names the parameter); nothing is changed then.
        TypeError
            If a value has the wrong type; nothing is changed then.
        """
        return super().set_params(**params)

    def _check_params_together(self, params):
        """Every parameter checked by the class's ``_check_params``, on a shallow copy
        that holds the new values (the map itself changes only once they pass)."""
        trial = copy.copy(self)
        for name, value in params.items():
            setattr(trial, name, value)
        trial._check_params()
        return params

    def to_octree(self, resolution: float | None = None):
        """The map as an :class:`~occgp.OccupancyOctree`: its posterior as log-odds.

        The model's :meth:`occupancy` at the centers of the octree's cells
        that cover :attr:`bounds` becomes their log-odds (clamped by the
        octree to [0.001, 0.999]); unknown cells stay unknown. A 2D model
        gives one layer of cells: those holding z = 0 (from 0 to
        `resolution`).

        Parameters
        ----------
        resolution : float, default=None
            Edge of the octree's cells, in metres; None: the model's own
            (0.1 for the models without cells).

        Returns
        -------
        tree : OccupancyOctree
            Empty before the first fit; its ``occupancy_threshold`` is the
            model's.

        Raises
        ------
        ValueError
            If `resolution` is not positive, the box holds more than
            ``MAX_OCTREE_CELLS`` (2e7) cells at it, or lies beyond the octree's
            key range.
        TypeError
            If `resolution` is not a real number.
        """
        from ..octree._tree import OccupancyOctree

        res = check_resolution(self._octree_resolution(resolution))
        tree = OccupancyOctree(res, clamping_min=0.001, clamping_max=0.999,
                               occupancy_threshold=check_probability(
                                   self.occupancy_threshold, "occupancy_threshold"))
        if not self._fitted():
            return tree
        centers, log_odds = self._octree_cells(res)
        if len(centers):
            if centers.shape[1] == 2:
                centers = np.column_stack([centers, np.zeros(len(centers))])
            tree.set_cells(centers, np.clip(log_odds, -_MAX_LOG_ODDS, _MAX_LOG_ODDS))
        return tree

    def _octree_cells(self, res):
        """Centers and log-odds of the known cells of edge `res` covering the bounds."""
        lo, hi = self.bounds
        first, last = np.floor(lo / res), np.floor(hi / res)
        with np.errstate(over="ignore"):
            total = float(np.prod(last - first + 1))
        if not total <= MAX_OCTREE_CELLS:
            raise ValueError(f"the map's bounds hold {total:.4g} cells at resolution {res!r}, "
                             f"more than {MAX_OCTREE_CELLS}; use a coarser resolution")
        axes = [(np.arange(a, b + 1) + 0.5) * res for a, b in zip(first, last)]
        centers = np.column_stack([m.ravel() for m in np.meshgrid(*axes, indexing="ij")])
        p = self.occupancy(centers)
        known = ~np.isnan(p)
        return centers[known], logit(p[known])
