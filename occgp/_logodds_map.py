"""What occgp's log-odds maps share: parameters, scan validation and queries.

:class:`occgp.OccupancyOctree` and :class:`occgp.GridMap` put this class in
front of their compiled cores, which provide ``_setup``, ``_in_range``,
``_check_rays`` and ``_query`` with the same meaning.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._octree import TREE_MAX_VAL
from ._validation import (
    as_point, as_points, check_bool, check_choice, check_int, check_probability, check_real,
    check_resolution,
)

__all__ = ["LogOddsMap", "Leaves", "MODES", "METHODS"]

MODES = ("scan", "ray")
# codes of the compiled cores' _check_rays (ext/_keys.pxd)
_RAY_OUT_OF_RANGE, _RAY_TOO_SHORT = 1, 2
#: Rays between two cells whose float squared length is below FLT_MIN cannot be walked.
_SHORTEST_RAY = float(np.sqrt(np.finfo(np.float32).tiny))
#: Longest ray whose float squared length is finite.
_LONGEST_RAY = float(np.sqrt(np.finfo(np.float32).max))
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
    #: The most distinct cells one scan may reach (its rays' cells and end cells): a
    #: scan past it raises ValueError and changes nothing, instead of collecting
    #: tens of gigabytes of cells (e.g. a resolution a thousand times too fine for
    #: its rays). About 48 bytes a cell while the scan is collected, plus the map's
    #: own nodes; raise it on the class or the map for larger scans.
    MAX_SCAN_CELLS = 2**27
    _superray_skip = 0
    _superray_pause = SUPERRAY_BACKOFF

    if TYPE_CHECKING:  # provided by the compiled core the subclass also derives from
        def _setup(self, resolution: float, prob_hit: float, prob_miss: float,
                   clamping_min: float, clamping_max: float,
                   occupancy_threshold: float) -> None: ...
        def _in_range(self, points: NDArray[np.float32]) -> NDArray[np.bool_]: ...
        def _check_rays(self, points: NDArray[np.float32], origin: NDArray[np.float32],
                        max_range: float) -> tuple[NDArray[np.uint8], NDArray[np.int64]]: ...
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
        return_unknown = check_bool(return_unknown, "return_unknown")
        state = self._query(self._as_float32_points(points, "points"), 2)
        occupied = state == 1
        return (occupied, state < 0) if return_unknown else occupied

    # ------------------------------------------------------------------ maps out
    def save_ply(self, path, *, occupied: bool = True, binary: bool = True,
                 cubes: bool = False, color: bool = True):
        """Write the occupied (or free) cells to a PLY file; return self.

        See :func:`occgp._export.save_ply` for the file's properties: points
        (cell centres with ``size`` and ``probability``, optional height
        colours) or, with `cubes`, one cube mesh per cell.
        """
        from . import _export
        _export.save_ply(self, path, occupied=occupied, binary=binary, cubes=cubes,
                         color=color)
        return self

    def save_pcd(self, path, *, occupied: bool = True, binary: bool = True):
        """Write the occupied (or free) cell centres to a PCD v0.7 file (``x y z
        intensity``, intensity = probability); return self."""
        from . import _export
        _export.save_pcd(self, path, occupied=occupied, binary=binary)
        return self

    def to_open3d(self, *, kind: str = "voxels", occupied: bool = True,
                  max_voxels: int | None = None):
        """The occupied (or free) cells as an ``open3d.geometry.VoxelGrid``
        (``kind="voxels"``, finest cells, at most `max_voxels`, default
        :data:`occgp._export.MAX_VOXELS`) or ``PointCloud`` (``"points"``, leaf
        centres). Needs the ``open3d`` extra (``open3d-cpu`` or ``open3d``)."""
        from . import _export
        return _export.to_open3d(self, kind=kind, occupied=occupied,
                                 max_voxels=_export.MAX_VOXELS if max_voxels is None
                                 else max_voxels)

    def distance_field(self, bbox: ArrayLike, resolution: float | None = None, *,
                       unknown: str = "occupied", max_cells: int | None = None):
        """Euclidean distance from each cell of a grid over `bbox` to the nearest
        obstacle (occupied cells, and unknown ones with ``unknown="occupied"``), for
        planners; see :func:`occgp._export.distance_field`. Returns a
        :class:`~occgp._export.DistanceField` ``(distances, origin, resolution)``."""
        from . import _export
        return _export.distance_field(self, bbox, resolution, unknown=unknown,
                                      max_cells=_export.MAX_DISTANCE_CELLS
                                      if max_cells is None else max_cells)

    # ------------------------------------------------------------------ helpers
    @staticmethod
    def _check_method(method: str, superray_threshold: int) -> tuple[str, int]:
        """Validate `method` and `superray_threshold`; return the method ("auto" chosen:
        "culling", the fastest on bench/bench_updates.py's trajectories) and the
        threshold the core takes (0: no super rays)."""
        method = check_choice(method, "method", METHODS)
        superray_threshold = check_int(superray_threshold, "superray_threshold", low=1,
                                       high=2**31 - 1)
        if method == "auto":
            method = "superray+culling"
        return method, int(superray_threshold) if method.startswith("superray") else 0

    def _max_scan_cells(self) -> int:
        """MAX_SCAN_CELLS, checked (it may be set on the class or the map)."""
        return check_int(self.MAX_SCAN_CELLS, "MAX_SCAN_CELLS", low=1, high=2**62)

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
        """Check a scan for insertion; return (points, origin, max_range, cells) as the
        core wants them (float32, -1 for no limit; cells: see :meth:`_raise_bad_ends`), or
        None for an empty scan. Without `check_ends` the caller's core checks the ray ends
        itself (and calls :meth:`_raise_bad_ends` when one is out of range or cannot be
        walked), and cells is None."""
        mode = check_choice(mode, "mode", MODES)
        rng = -1.0 if max_range is None else check_real(max_range, "max_range", low=0.0)
        pts64 = as_points(points, "points")
        org = self._as_float32_origin(origin)
        with np.errstate(over="ignore"):
            pts = pts64.astype(np.float32)
        if len(pts) == 0:
            return None
        if rng >= 0:
            pts = _cut_far_rays(pts64, pts, org, rng)
        cells = self._raise_bad_ends(pts, org, rng) if check_ends else None
        return pts, org, rng, cells

    def _raise_bad_ends(self, pts: np.ndarray, org: np.ndarray, rng: float) -> np.ndarray:
        """Raise ValueError if a ray end (after truncation at `rng`) is out of key range,
        or a ray is too short for the single-precision traversal to walk it; otherwise
        return each ray's key distance (a bound on the cells it crosses)."""
        codes, cells = self._check_rays(pts, org, rng)
        if (codes == _RAY_OUT_OF_RANGE).any():
            self._raise_out_of_range("points", codes != _RAY_OUT_OF_RANGE,
                                     " (after truncation at max_range)" if rng >= 0 else "")
        if (codes == _RAY_TOO_SHORT).any():
            bad = np.flatnonzero(codes == _RAY_TOO_SHORT)
            raise ValueError(
                f"{len(bad)} of {len(codes)} rays from origin to points are shorter than "
                f"{_SHORTEST_RAY:.2g} m yet cross a cell border (first: row {int(bad[0])}): "
                "liboctomap's single-precision traversal cannot walk them; the map is "
                "unchanged")
        return cells

    def _record_insert(self, stats, pts: np.ndarray, org: np.ndarray, rng: float,
                       method: str, threshold: int) -> None:
        """Set ``last_insert_`` from a core's scan insertion, or raise for bad ray ends
        (None: the core changed nothing)."""
        if stats is None:
            self._raise_bad_ends(pts, org, rng)
            raise AssertionError("the core reported a ray end out of range")  # unreachable
        if isinstance(stats, str):
            raise ValueError(
                f"the scan's {len(pts)} rays reach more than MAX_SCAN_CELLS="
                f"{self.MAX_SCAN_CELLS} cells at resolution {self.resolution:g} m; use a "
                "coarser resolution, max_range or fewer points, or raise MAX_SCAN_CELLS; "
                "the map is unchanged")
        self.last_insert_ = self._insert_statistics(stats)
        self.last_insert_["superrays"] = threshold > 0
        self._learn_superrays(method, len(pts))

    def _as_float32_points(self, x: ArrayLike, name: str) -> np.ndarray:
        # beyond float range is beyond every key range: inf, which no key holds
        with np.errstate(over="ignore"):
            return np.ascontiguousarray(as_points(x, name), dtype=np.float32)

    def _as_float32_origin(self, x: ArrayLike, name: str = "origin") -> np.ndarray:
        with np.errstate(over="ignore"):
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
    out["resolution"] = check_resolution(params["resolution"])
    out["prob_hit"] = check_real(params["prob_hit"], "prob_hit", low=0.5, high=1.0)
    out["prob_miss"] = check_real(params["prob_miss"], "prob_miss", low=0.0, high=0.5)
    out["clamping_min"] = check_real(params["clamping_min"], "clamping_min", low=0.0, high=0.5)
    out["clamping_max"] = check_real(params["clamping_max"], "clamping_max", low=0.5, high=1.0)
    out["occupancy_threshold"] = check_probability(params["occupancy_threshold"],
                                                   "occupancy_threshold")
    return out


def _cut_far_rays(pts64: np.ndarray, pts: np.ndarray, org: np.ndarray, rng: float) -> np.ndarray:
    """Make rays to far points cut at `rng` as they should be.

    liboctomap truncates a ray at ``max_range`` along ``(p - origin).normalized()``, in
    single precision: a point so far (over ~1.8e19 m, or beyond float range) that its
    squared distance overflows gives a zero direction, and the ray would vanish. Those
    points (only those: every other ray keeps liboctomap's arithmetic) are moved, in
    double precision, onto their ray at twice `rng`, where the truncation gives the cut
    the ray should have. When twice `rng` is itself that far, the cut end lies beyond
    every key range, and the point is left to be reported out of range.
    """
    with np.errstate(over="ignore", invalid="ignore"):
        d = pts - org
        nsq = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2]
    far = ~np.isfinite(nsq)
    if not far.any():
        return pts
    delta = pts64[far] - org.astype(np.float64)
    scale = np.abs(delta).max(axis=1, keepdims=True)
    unit = delta / scale
    dist = scale[:, 0] * np.linalg.norm(unit, axis=1)
    unit /= np.linalg.norm(unit, axis=1, keepdims=True)
    cut = dist > rng
    if 2 * rng >= 0.5 * _LONGEST_RAY:
        return pts
    pts = pts.copy()
    rows = np.flatnonzero(far)[cut]
    pts[rows] = (org.astype(np.float64) + unit[cut] * (2 * rng)).astype(np.float32)
    return pts
