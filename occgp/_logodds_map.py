"""What occgp's log-odds maps share: parameters, scan validation and queries.

:class:`occgp.OccupancyOctree` and :class:`occgp.GridMap` put this class in
front of their compiled cores, which provide ``_setup``, ``_in_range``,
``_ends_in_range`` and ``_query`` with the same meaning.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._octree import TREE_MAX_VAL
from ._validation import as_point, as_points, check_probability, check_real

__all__ = ["LogOddsMap", "Leaves", "MODES", "METHODS"]

MODES = ("scan", "ray")
METHODS = ("auto", "plain", "culling", "superray", "superray+culling")


class Leaves(NamedTuple):
    """The leaves (cells) of a map, as arrays (one row per leaf)."""

    #: Cell centres, shape (n_leaves, 3), in metres.
    centers: NDArray[np.float64]
    #: Cell edge lengths, shape (n_leaves,): the resolution times a power of two.
    sizes: NDArray[np.float64]
    #: Log-odds of occupancy, shape (n_leaves,), float32 as liboctomap stores them.
    log_odds: NDArray[np.float32]


class LogOddsMap:
    """Base of the log-odds maps: see :class:`occgp.OccupancyOctree` for the parameters."""

    #: What the map is called in error messages.
    _kind = "map"
    #: After a scan where grouping its rays into super rays took longer than the
    #: traversal it saved, ``method="superray+culling"`` inserts this many scans with
    #: the culling region alone, then tries super rays again; each further such scan
    #: in a row doubles the pause, up to 8 times this.
    SUPERRAY_BACKOFF = 8
    _superray_skip = 0
    _superray_pause = SUPERRAY_BACKOFF

    if TYPE_CHECKING:  # provided by the compiled core the subclass also derives from
        def _setup(self, resolution: float, prob_hit: float, prob_miss: float,
                   clamping_min: float, clamping_max: float,
                   occupancy_threshold: float) -> None: ...
        def _in_range(self, points: NDArray[np.float32]) -> NDArray[np.bool_]: ...
        def _ends_in_range(self, points: NDArray[np.float32], origin: NDArray[np.float32],
                           max_range: float) -> NDArray[np.bool_]: ...
        def _query(self, points: NDArray[np.float32], what: int) -> Any: ...

    def __init__(
        self,
        resolution: float,
        *,
        prob_hit: float = 0.7,
        prob_miss: float = 0.4,
        clamping_min: float = 0.1192,
        clamping_max: float = 0.971,
        occupancy_threshold: float = 0.5,
    ) -> None:
        params = dict(
            resolution=resolution, prob_hit=prob_hit, prob_miss=prob_miss,
            clamping_min=clamping_min, clamping_max=clamping_max,
            occupancy_threshold=occupancy_threshold,
        )
        self._params = check_params(params)
        self._setup(*self._params.values())
        self._superray_skip = 0
        self._superray_pause = self.SUPERRAY_BACKOFF

    # ------------------------------------------------------------------ parameters
    def get_params(self) -> dict:
        """Return the constructor's parameters as a dict."""
        return dict(self._params)

    @property
    def resolution(self) -> float:
        """Edge length of the smallest cells, in metres."""
        return self._params["resolution"]

    @property
    def prob_hit(self) -> float:
        return self._params["prob_hit"]

    @property
    def prob_miss(self) -> float:
        return self._params["prob_miss"]

    @property
    def clamping_min(self) -> float:
        return self._params["clamping_min"]

    @property
    def clamping_max(self) -> float:
        return self._params["clamping_max"]

    @property
    def occupancy_threshold(self) -> float:
        return self._params["occupancy_threshold"]

    @property
    def key_range(self) -> tuple[float, float]:
        """The interval ``[low, high)`` of coordinates (metres, every axis) the map can hold."""
        r = self.resolution
        return -TREE_MAX_VAL * r, TREE_MAX_VAL * r

    # ------------------------------------------------------------------ queries
    def occupancy(self, points: ArrayLike) -> NDArray[np.float64]:
        """Probability of occupancy at each point, NaN where the map knows nothing.

        Parameters
        ----------
        points : array-like of shape (n_points, 3)
            Query points, in metres. Points outside the key range are unknown.

        Returns
        -------
        p : ndarray of shape (n_points,)
            Occupancy probability of the cell holding each point, or NaN.
        """
        return self._query(self._as_float32_points(points, "points"), 0)

    def log_odds(self, points: ArrayLike) -> NDArray[np.float64]:
        """Log-odds of occupancy at each point, NaN where the map knows nothing.

        Parameters
        ----------
        points : array-like of shape (n_points, 3)

        Returns
        -------
        l : ndarray of shape (n_points,)
            The cell's stored log-odds (float32 values), or NaN.
        """
        return self._query(self._as_float32_points(points, "points"), 1)

    def is_occupied(self, points: ArrayLike, *, return_unknown: bool = False):
        """Whether each point lies in an occupied cell.

        A cell is occupied when its probability is at least
        ``occupancy_threshold``. Unknown cells are reported as not occupied;
        ask for `return_unknown` to tell them apart from free ones.

        Parameters
        ----------
        points : array-like of shape (n_points, 3)
        return_unknown : bool, default=False
            Also return the mask of points in unknown cells.

        Returns
        -------
        occupied : ndarray of bool, shape (n_points,)
        unknown : ndarray of bool, shape (n_points,)
            Only when `return_unknown` is True.

        Examples
        --------
        >>> from occgp import OccupancyOctree
        >>> m = OccupancyOctree(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0])
        >>> occ, unk = m.is_occupied([[1.0, 0, 0], [0.5, 0, 0], [9, 9, 9]], return_unknown=True)
        >>> occ.tolist(), unk.tolist()
        ([True, False, False], [False, False, True])
        """
        state = self._query(self._as_float32_points(points, "points"), 2)
        occupied = state == 1
        return (occupied, state < 0) if return_unknown else occupied

    # ------------------------------------------------------------------ helpers
    @staticmethod
    def _check_method(method: str, superray_threshold: int) -> tuple[str, int]:
        """Validate `method` and `superray_threshold`; return the method ("auto" chosen:
        "culling", the fastest on bench/bench_updates.py's trajectories) and the
        threshold the core takes (0: no super rays)."""
        if method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {method!r}")
        if isinstance(superray_threshold, (bool, np.bool_)) or not isinstance(
                superray_threshold, (int, np.integer)):
            raise TypeError(f"superray_threshold must be an int, "
                            f"got {type(superray_threshold).__name__}")
        if superray_threshold < 1:
            raise ValueError(f"superray_threshold must be >= 1, got {superray_threshold}")
        if method == "auto":
            method = "superray+culling"
        return method, int(superray_threshold) if method.startswith("superray") else 0

    def _adaptive_threshold(self, method: str, threshold: int) -> int:
        """The super-ray threshold for this scan: 0 while "superray+culling" backs off."""
        if method == "superray+culling" and self._superray_skip > 0:
            self._superray_skip -= 1
            return 0
        return threshold

    def _learn_superrays(self, method: str, n_points: int) -> None:
        """After a "superray+culling" scan that grouped rays: back off when the grouping
        (``superray_seconds``) cost more than the traversal it saved, estimated as the
        rays it spared times the scan's traversal time per traversed ray."""
        stats = self.last_insert_
        if method != "superray+culling" or not stats["superrays"] or stats["rays"] == 0:
            return
        saved = (n_points - stats["rays"]) * stats["traversal_seconds"] / stats["rays"]
        if saved < stats["superray_seconds"]:
            self._superray_skip = self._superray_pause
            self._superray_pause = min(2 * self._superray_pause, 8 * self.SUPERRAY_BACKOFF)
        else:
            self._superray_pause = self.SUPERRAY_BACKOFF

    @staticmethod
    def _insert_statistics(stats: tuple) -> dict[str, float]:
        """``last_insert_`` from what a core's scan insertion returns."""
        region, cells, rays, traversed, seconds, unnecessary = stats
        out = {"rays": rays, "updated_cells": cells, "traversed_cells": traversed,
               "region_cells": region, "endpoint_seconds": seconds[0],
               "superray_seconds": seconds[1], "region_seconds": seconds[2],
               "preprocessing_seconds": seconds[1] + seconds[2],
               "traversal_seconds": seconds[3], "update_seconds": seconds[4]}
        if unnecessary >= 0:
            out["unnecessary_traversals"] = unnecessary
        return out

    def _validated_scan(self, points: ArrayLike, origin: ArrayLike, max_range, mode: str,
                        check_ends: bool = True):
        """Check a scan for insertion; return (points, origin, max_range) as the core wants
        them (float32, -1 for no limit), or None for an empty scan. Without `check_ends`
        the caller's core checks the key range of the ray ends itself (and calls
        :meth:`_raise_bad_ends` when one is out)."""
        if mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
        rng = -1.0 if max_range is None else check_real(max_range, "max_range", low=0.0)
        pts = self._as_float32_points(points, "points")
        org = self._as_float32_origin(origin)
        if len(pts) == 0:
            return None
        if check_ends:
            self._raise_bad_ends(pts, org, rng)
        return pts, org, rng

    def _raise_bad_ends(self, pts: np.ndarray, org: np.ndarray, rng: float) -> None:
        """Raise ValueError if a ray end (after truncation at `rng`) is out of key range."""
        ok = self._ends_in_range(pts, org, rng)
        if not ok.all():
            self._raise_out_of_range("points", ok, " (after truncation at max_range)"
                                     if rng >= 0 else "")

    def _record_insert(self, stats, pts: np.ndarray, org: np.ndarray, rng: float,
                       method: str, threshold: int) -> None:
        """Set ``last_insert_`` from a core's scan insertion, or raise for bad ray ends
        (None: the core changed nothing)."""
        if stats is None:
            self._raise_bad_ends(pts, org, rng)
            raise AssertionError("the core reported a ray end out of range")  # unreachable
        self.last_insert_ = self._insert_statistics(stats)
        self.last_insert_["superrays"] = threshold > 0
        self._learn_superrays(method, len(pts))

    def _as_float32_points(self, x: ArrayLike, name: str) -> np.ndarray:
        return np.ascontiguousarray(as_points(x, name), dtype=np.float32)

    def _as_float32_origin(self, x: ArrayLike, name: str = "origin") -> np.ndarray:
        org = np.ascontiguousarray(as_point(x, name), dtype=np.float32)
        if not self._in_range(org[None]).all():
            lo, hi = self.key_range
            raise ValueError(f"{name} {org.tolist()} lies outside the {self._kind}'s key range "
                             f"[{lo:g}, {hi:g}) m at resolution {self.resolution:g}")
        return org

    def _raise_out_of_range(self, name: str, ok: np.ndarray, what: str) -> None:
        lo, hi = self.key_range
        bad = int(np.count_nonzero(~ok))
        raise ValueError(
            f"{bad} of {len(ok)} {name}{what} lie outside the {self._kind}'s key range "
            f"[{lo:g}, {hi:g}) m on some axis at resolution {self.resolution:g} "
            f"(first: row {int(np.flatnonzero(~ok)[0])}); the map is unchanged"
        )


def check_params(params: dict) -> dict:
    """Validate a log-odds map's parameters; return them as floats."""
    out = dict(params)
    out["resolution"] = check_real(params["resolution"], "resolution", low=0.0)
    out["prob_hit"] = check_real(params["prob_hit"], "prob_hit", low=0.5, high=1.0)
    out["prob_miss"] = check_real(params["prob_miss"], "prob_miss", low=0.0, high=0.5)
    out["clamping_min"] = check_real(params["clamping_min"], "clamping_min", low=0.0, high=0.5)
    out["clamping_max"] = check_real(params["clamping_max"], "clamping_max", low=0.5, high=1.0)
    out["occupancy_threshold"] = check_probability(params["occupancy_threshold"],
                                                   "occupancy_threshold")
    return out
