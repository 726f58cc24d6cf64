"""What occgp's log-odds maps share: parameters, scan validation and queries.

:class:`occgp.OccupancyOctree`, :class:`occgp.ColorOctree` and
:class:`occgp.GridMap` put :class:`LogOddsMap` in front of their compiled cores
(``class OccupancyOctree(LogOddsMap, _OcTree)``), which provide ``_setup``,
``_in_range``, ``_check_rays`` and ``_query`` with the same meaning. Its other
parts are plain functions in modules of their own, bound in the class body as
methods: the files and geometries it writes (``_outputs.py``), the planners'
projection and frontiers (``occgp/nav/_planning.py``).
"""

from __future__ import annotations

from numbers import Real
from typing import TYPE_CHECKING, Any, ClassVar, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._docfill import fill_doc
from .._params import Check, Interval, ParamsMixin, param_names
from .._grid import _discretize
from .._octree import TREE_MAX_VAL
from ..nav import _planning
from . import _outputs
from ._options import METHODS
from .._status import Status, check_status
from ._superray_policy import learn_superrays
from .._validation import (
    as_point, as_points, check_bool, check_choice, check_int, check_n_jobs, check_probability,
    check_real, check_resolution, n_threads,
)

__all__ = ["LogOddsMap", "Leaves", "MODES", "METHODS", "SENSOR_MODEL", "N_JOBS",
           "OCTREE_ATTRIBUTES", "check_params"]

MODES = ("scan", "ray")
#: Rays between two cells whose float squared length is below FLT_MIN cannot be walked.
_SHORTEST_RAY = float(np.sqrt(np.finfo(np.float32).tiny))
#: Longest ray whose float squared length is finite.
_LONGEST_RAY = float(np.sqrt(np.finfo(np.float32).max))
#: The settable sensor-model parameters (:meth:`LogOddsMap.set_params`).
_SENSOR_PARAMS = ("prob_hit", "prob_miss", "clamping_min", "clamping_max",
                  "occupancy_threshold")
#: The other parameters set_params may change, on the maps that have them.
_RUN_PARAMS = ("n_jobs",)


#: The sensor model of the log-odds maps (liboctomap's), as numpydoc parameters.
SENSOR_MODEL = """\
prob_hit : float, default=0.7
    Probability that a cell is occupied given a ray ends in it; in (0.5, 1).
prob_miss : float, default=0.4
    Probability that a cell is occupied given a ray crosses it; in (0, 0.5).
clamping_min : float, default=0.1192
    Lower clamping bound (probability); in (0, 0.5).
clamping_max : float, default=0.971
    Upper clamping bound (probability); in (0.5, 1).
occupancy_threshold : float, default=0.5
    Cells at or above this probability count as occupied; in (0, 1)."""

#: The threads of a scan insertion, as numpydoc parameters (octree and grid).
N_JOBS = """\
n_jobs : int or None, default=None
    Threads that walk each scan's rays in :meth:`insert_scan` (None: 1, -1:
    every core; at most the cores, and about one per 64 rays). The threads'
    counts are merged (integer sums) before the cells are updated, so the map
    and :attr:`last_insert_`'s counts are the same for every `n_jobs`. A
    run-time setting: :meth:`set_params` may change it; pickles keep it, map
    files do not."""

#: The attributes every octree shows.
OCTREE_ATTRIBUTES = """\
resolution : float
    Edge length of the smallest cells.
num_leaves : int
    Number of leaves (known cells after pruning).
num_nodes : int
    Number of nodes, inner ones included.
bounds : tuple of ndarray of shape (3,)
    Minimum and maximum corner of the known space (NaN when empty)."""


class Leaves(NamedTuple):
    """The leaves (cells) of a map, as arrays (one row per leaf)."""

    #: Cell centers, shape (n_leaves, 3), in metres.
    centers: NDArray[np.float64]
    #: Cell edge lengths, shape (n_leaves,): the resolution times a power of two.
    sizes: NDArray[np.float64]
    #: Log-odds of occupancy, shape (n_leaves,), float32 as liboctomap stores them.
    log_odds: NDArray[np.float32]


class LogOddsMap:
    """Base of the log-odds maps: see :class:`occgp.OccupancyOctree` for the parameters.

    The one Python class between a log-odds map and its compiled core: parameters,
    queries, scan checks; :meth:`save_ply`, :meth:`save_pcd`, :meth:`to_open3d`,
    :meth:`distance_field` (``_outputs.py``), :meth:`project_2d` and
    :meth:`frontiers` (``occgp/nav/_planning.py``) are functions bound here.
    """

    #: The constructor's parameters and what each may be (occgp._params; the maps'
    #: get_params / set_params read it).
    _parameter_constraints: ClassVar[dict[str, list]] = {
        "resolution": [Check(check_resolution, "a resolution in RESOLUTION_RANGE")],
        "prob_hit": [Interval(Real, 0.5, 1.0, closed="neither")],
        "prob_miss": [Interval(Real, 0.0, 0.5, closed="neither")],
        "clamping_min": [Interval(Real, 0.0, 0.5, closed="neither")],
        "clamping_max": [Interval(Real, 0.5, 1.0, closed="neither")],
        "occupancy_threshold": [Check(check_probability, "a probability")],
        "n_jobs": [None, Check(check_n_jobs, "an int != 0, or None")],
    }
    _deprecated_params: ClassVar[dict[str, str]] = {}
    # occgp's one parameter mechanism, bound here rather than inherited (the maps'
    # class chain stays short): the table above, the values in self._params
    _get_param_names = classmethod(param_names)
    get_params = ParamsMixin.get_params

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
        def _set_sensor_model(self, prob_hit: float, prob_miss: float, clamping_min: float,
                              clamping_max: float, occupancy_threshold: float) -> None: ...
        def _in_range(self, points: NDArray[np.float32]) -> NDArray[np.bool_]: ...
        def _check_rays(self, points: NDArray[np.float32], origin: NDArray[np.float32],
                        max_range: float) -> tuple[NDArray[np.uint8], NDArray[np.int64]]: ...
        def _query(self, points: NDArray[np.float32], what: int) -> Any: ...
        def _num_cells(self) -> int: ...
        def _bounds(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]: ...
        def _memory_usage(self) -> int: ...
        def _clear(self) -> None: ...

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
        self._build_checked(params)

    def _build_checked(self, params: dict) -> None:
        """:meth:`_build` with the constructor's `params`, checked (:func:`check_params`)."""
        checked = check_params(params)
        self._build(checked, *(checked[k] for k in _SENSOR_PARAMS))

    def _build(self, params: dict, prob_hit: float, prob_miss: float, clamping_min: float,
               clamping_max: float, occupancy_threshold: float) -> None:
        """Build the empty map: its checked constructor `params` and the compiled core's
        sensor model. The map's cells live in the compiled core, so a log-odds map is
        built (and its parameters checked) at construction."""
        self._params = params
        self._setup(params["resolution"], prob_hit, prob_miss, clamping_min, clamping_max,
                    occupancy_threshold)
        self._superray_skip = 0
        self._superray_pause = self.SUPERRAY_BACKOFF

    # ------------------------------------------------------------------ parameters
    def _get_param(self, name: str) -> Any:
        return self._params.get(name)

    @property
    def resolution(self) -> float:
        """Edge length of the smallest cells, in metres."""
        return self._params["resolution"]

    @property
    def n_jobs(self) -> int | None:
        """Threads of :meth:`insert_scan` (None: one; the constructor's ``n_jobs``)."""
        return self._params.get("n_jobs")

    def _threads(self) -> int:
        """The threads of the map's ``n_jobs``, as the compiled cores take them."""
        return n_threads(self._params.get("n_jobs"))

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

    # ------------------------------------------------------------------ structure
    @property
    def num_cells(self) -> int:
        """Number of cells holding evidence (an octree's pruned leaf counts once)."""
        return self._num_cells()

    @property
    def bounds(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(min corner, max corner) of the known space, in metres; NaN when empty."""
        if self.num_cells == 0:
            return np.full(3, np.nan), np.full(3, np.nan)
        return self._bounds()

    def memory_usage(self) -> int:
        """Bytes used by the map's cells: the octree's nodes (liboctomap's
        ``memoryUsage``), the grid's blocks and the slots of their hashed root.

        Returns
        -------
        nbytes : int
        """
        return self._memory_usage()

    def clear(self):
        """Remove every cell (the parameters stay).

        Returns
        -------
        self
            The map.
        """
        self._clear()
        return self

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

    @fill_doc()
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

        {occupied_returns}

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

    def set_params(self, **params):
        """Change the sensor model (liboctomap's ``setProbHit``, ``setClampingThresMin``, ...).

        Sets any of ``prob_hit``, ``prob_miss``, ``clamping_min``,
        ``clamping_max`` and ``occupancy_threshold`` (and ``n_jobs`` on the
        maps that take it), checked as the constructor checks them (scikit-learn's ``set_params``;
        :meth:`get_params` reads them back). As with liboctomap's setters, the
        stored log-odds do not change: the new values apply to later updates
        (and clamps) and to the queries that compare with a threshold
        (:meth:`is_occupied`, and the octree's ``is_at_threshold`` and
        ``extract_points``, ...). The resolution is fixed: ``resolution`` is accepted only with
        the map's own value (so that ``set_params(**other.get_params())``
        works between maps of one resolution). Pickles keep the new values;
        ``.bt`` / ``.ot`` files store only the resolution, so pass the values
        to :meth:`load` again.

        Parameters
        ----------
        **params
            The parameters to change, by name.

        Returns
        -------
        self
            The map.

        Raises
        ------
        TypeError
            If a value is not a real number.
        ValueError
            If a name is not a parameter of the map's constructor, `resolution`
            differs from the map's, or a value lies outside the constructor's
            range. The map is then unchanged.

        Examples
        --------
        >>> from occgp import OccupancyOctree
        >>> m = OccupancyOctree(0.1).set_params(prob_hit=0.9, clamping_max=0.99)
        >>> m.prob_hit, m.get_params()["clamping_max"]
        (0.9, 0.99)
        """
        return ParamsMixin.set_params(self, **params)

    def _check_params_together(self, params: dict) -> dict:
        if params["resolution"] != self.resolution:
            raise ValueError(f"resolution is fixed at construction ({self.resolution!r}), "
                             f"got {params['resolution']!r}; build a new map instead")
        return check_params(params)

    def _set_checked_params(self, params: dict, checked: dict) -> None:
        self._set_sensor_model(*(checked[k] for k in _SENSOR_PARAMS))
        self._params = checked

    # ------------------------------------------------------------------ maps out
    save_ply = _outputs.save_ply
    save_pcd = _outputs.save_pcd
    to_open3d = _outputs.to_open3d
    distance_field = _outputs.distance_field
    project_2d = _planning.project_2d
    frontiers = _planning.frontiers

    # ------------------------------------------------------------------ helpers
    @staticmethod
    def _check_method(method: str, superray_threshold: int) -> tuple[str, int]:
        """Validate `method` and `superray_threshold`; return the method ("auto" becomes
        "superray+culling", which backs off super rays on scans where grouping does not
        pay) and the threshold the core takes (0: no super rays)."""
        method = check_choice(method, "method", METHODS)
        superray_threshold = check_int(superray_threshold, "superray_threshold", low=1,
                                       high=2**31 - 1)
        if method == "auto":
            method = "superray+culling"
        return method, int(superray_threshold) if method.startswith("superray") else 0

    def _max_scan_cells(self) -> int:
        """MAX_SCAN_CELLS, checked (it may be set on the class or the map)."""
        return check_int(self.MAX_SCAN_CELLS, "MAX_SCAN_CELLS", low=1, high=2**62)

    @staticmethod
    def _insert_statistics(stats: tuple) -> dict[str, float]:
        """``last_insert_`` from what a core's scan insertion returns."""
        region, cells, rays, traversed, seconds, unnecessary, spared, culled, region_spared = stats
        out = {"rays": rays, "updated_cells": cells, "traversed_cells": traversed,
               "spared_cells": spared, "culled_rays": culled,
               "region_spared_cells": region_spared,
               "region_cells": region, "endpoint_seconds": seconds[0],
               "superray_seconds": seconds[1], "region_seconds": seconds[2],
               "preprocessing_seconds": seconds[1] + seconds[2],
               "traversal_seconds": seconds[3], "update_seconds": seconds[4]}
        if unnecessary >= 0:
            out["unnecessary_traversals"] = unnecessary
        return out

    def _validated_scan(self, points: ArrayLike, origin: ArrayLike, max_range, mode: str,
                        check_ends: bool = True, name: str = "points"):
        """Check a scan for insertion; return (points, origin, max_range, cells) as the
        core wants them (float32, -1 for no limit; cells: see :meth:`_raise_bad_ends`), or
        None for an empty scan. Without `check_ends` the caller's core checks the ray ends
        itself (and calls :meth:`_raise_bad_ends` when one is out of range or cannot be
        walked), and cells is None. `name`: the points' name in errors."""
        mode = check_choice(mode, "mode", MODES)
        rng = -1.0 if max_range is None else check_real(max_range, "max_range", low=0.0)
        pts = self._as_float32_points(points, name)
        org = self._as_float32_origin(origin)
        if len(pts) == 0:
            return None
        if rng >= 0:
            pts = _cut_far_rays(points, pts, org, rng, name)
        cells = self._raise_bad_ends(pts, org, rng, name) if check_ends else None
        return pts, org, rng, cells

    def _raise_bad_ends(self, pts: np.ndarray, org: np.ndarray, rng: float,
                        name: str = "points") -> np.ndarray:
        """Raise ValueError if a ray end (after truncation at `rng`) is out of key range,
        or a ray is too short for the single-precision traversal to walk it; otherwise
        return each ray's key distance (a bound on the cells it crosses)."""
        codes, cells = self._check_rays(pts, org, rng)
        if (codes == Status.OUT_OF_RANGE).any():
            self._raise_out_of_range(name, codes != Status.OUT_OF_RANGE,
                                     " (after truncation at max_range)" if rng >= 0 else "")
        if (codes == Status.RAY_TOO_SHORT).any():
            bad = np.flatnonzero(codes == Status.RAY_TOO_SHORT)
            check_status(Status.RAY_TOO_SHORT, n_bad=len(bad), n_total=len(codes),
                         shortest=_SHORTEST_RAY, first=int(bad[0]))
        return cells

    def _record_insert(self, stats, pts: np.ndarray, org: np.ndarray, rng: float,
                       method: str, threshold: int) -> None:
        """Set ``last_insert_`` from a core's scan insertion, or raise for its Status
        (the core changed nothing)."""
        if isinstance(stats, Status):
            if stats != Status.TOO_MANY_CELLS:
                self._raise_bad_ends(pts, org, rng)     # the rays at fault, by row
            check_status(stats, n_rays=len(pts), max_scan_cells=self.MAX_SCAN_CELLS,
                         resolution=self.resolution)
        self.last_insert_ = self._insert_statistics(stats)
        self.last_insert_["superrays"] = threshold != 0
        learn_superrays(self, method, len(pts))

    def _discretized_points(self, points: ArrayLike) -> np.ndarray:
        """liboctomap's ``discretize``: the center of each distinct cell that holds a
        point of `points` (as single-precision points, keys as ``coordToKey`` computes
        them), compiled (``ext/_discretize.h``). Raises ValueError if a point lies
        outside the key range (liboctomap discretizes before it truncates at max_range,
        with unchecked keys)."""
        pts = self._as_float32_points(points, "points")
        bad, centers = _discretize(self.resolution, pts)
        if bad >= 0:
            self._raise_out_of_range("points", self._in_range(pts),
                                     " (with discretize=True, before truncation)")
        return centers

    def _as_float32_points(self, x: ArrayLike, name: str) -> np.ndarray:
        if (type(x) is np.ndarray and x.dtype == np.float32 and x.ndim == 2
                and x.shape[1] == 3 and np.isfinite(x).all()):
            return np.ascontiguousarray(x)      # already what as_points would accept
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
        check_status(Status.OUT_OF_RANGE, n_bad=int(np.count_nonzero(~ok)), n_total=len(ok),
                     name=name, what=what, kind=self._kind, lo=lo, hi=hi,
                     resolution=self.resolution, first=int(np.flatnonzero(~ok)[0]))


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
    if "n_jobs" in params:
        out["n_jobs"] = check_n_jobs(params["n_jobs"])
    return out


def _cut_far_rays(points: ArrayLike, pts: np.ndarray, org: np.ndarray, rng: float,
                  name: str) -> np.ndarray:
    """Make rays to far points cut at `rng` as they should be (`points`: the scan as
    given, checked; `pts`: its float32 copy).

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
    delta = as_points(points, name)[far] - org.astype(np.float64)
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
