"""A uniform 3D occupancy grid with the octree's update semantics (the "GridMap" baseline)."""

from __future__ import annotations

import os
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from ._docfill import fill_doc
from .io import _npz as _npz_io
from ._grid import _Grid
from ._status import Status
from .octree._logodds import MODES, N_JOBS, SENSOR_MODEL, Leaves, LogOddsMap
from .octree._options import InsertOptions, resolve_options
from .maps import register
from ._scan_input import join_free, prefilter
from .octree._superray_policy import adaptive_threshold
from ._validation import check_bool, check_choice, check_real, n_threads

if TYPE_CHECKING:
    from .octree._tree import OccupancyOctree

__all__ = ["GridMap"]

#: Pickle payload: per cell three little-endian uint16 keys, then the float32 log-odds.
_KEY_DTYPE, _VALUE_DTYPE = np.dtype("<u2"), np.dtype("<f4")
_CELL_BYTES = 3 * _KEY_DTYPE.itemsize + _VALUE_DTYPE.itemsize
#: The ``.npz`` file of :meth:`GridMap.save`.
_FORMAT, _VERSIONS = "occgp.grid_map", (1,)


@register("grid", formats=(".npz",),
          description="A uniform 3D log-odds grid (OctoMap's update, 3D-DDA)", resolution=0.1)
@fill_doc(sensor_model=SENSOR_MODEL, n_jobs=N_JOBS)
class GridMap(LogOddsMap, _Grid):
    """Probabilistic 3D occupancy map on a uniform grid (hashed cells).

    Every cell has the edge length `resolution` and holds the log-odds of being
    occupied; only observed cells are stored, in dense blocks of 8 x 8 x 8 cells
    under a hashed root (``ext/_block_grid.h``). Keys, ray traversal (3D-DDA), sensor model, clamping
    and both update modes are exactly those of :class:`OccupancyOctree`: after
    the same scans, the grid holds the same cells with the same float32
    log-odds as the octree expanded to its finest level. Without the tree,
    nothing is pruned or propagated to parents, which makes updates cheaper and
    uniform free space more expensive to store. This is the "GridMap" baseline
    of the super-ray and culling-region experiments [1]_.

    Coordinates are converted to single precision. Keys are 16 bits per axis:
    the map covers ``[-32768, 32768) * resolution`` metres on each axis.

    Parameters
    ----------
    resolution : float
        Edge length of the cells, in metres. Must lie in ``[1e-15, 1e14]``:
        the range where liboctomap's single-precision ray traversal is sound
        (see the user guide's notes on single precision).
    {sensor_model}
    {n_jobs}

    Attributes
    ----------
    resolution : float
        Edge length of the cells.
    num_cells : int
        Number of known cells.
    bounds : tuple of ndarray of shape (3,)
        Minimum and maximum corner of the known space (NaN when empty).
    last_insert_ : dict
        Statistics of the last :meth:`insert_scan`, as for
        :attr:`OccupancyOctree.last_insert_`.

    See Also
    --------
    OccupancyOctree : The same map on liboctomap's octree.

    References
    ----------
    .. [1] Y. Kwon, "Real-time dense occupancy mapping using spatial correlation
       of point clouds", Ph.D. dissertation, KAIST, 2022, ch. 2 (super rays and
       culling region; GridMap + 3D-DDA baseline, §2.4.1).

    Examples
    --------
    >>> import numpy as np
    >>> from occgp import GridMap
    >>> m = GridMap(resolution=0.1)
    >>> m = m.insert_scan([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], origin=[0.0, 0.0, 0.0])
    >>> m.is_occupied([[1.0, 0.0, 0.0], [0.5, 0.0, 0.0]])
    array([ True, False])
    >>> float(np.round(m.occupancy([[1.0, 0.0, 0.0]])[0], 2))
    0.7
    >>> bool(np.isnan(m.occupancy([[5.0, 5.0, 5.0]])[0]))   # never observed
    True
    """

    _kind = "grid"

    def __init__(
        self,
        resolution: float,
        *,
        prob_hit: float = 0.7,
        prob_miss: float = 0.4,
        clamping_min: float = 0.1192,
        clamping_max: float = 0.971,
        occupancy_threshold: float = 0.5,
        n_jobs: int | None = None,
    ) -> None:
        self._build_checked(dict(
            resolution=resolution, prob_hit=prob_hit, prob_miss=prob_miss,
            clamping_min=clamping_min, clamping_max=clamping_max,
            occupancy_threshold=occupancy_threshold, n_jobs=n_jobs))

    def __repr__(self) -> str:
        return f"{type(self).__name__}(resolution={self.resolution!r}, num_cells={self.num_cells})"

    # ------------------------------------------------------------------ updates
    def insert_scan(
        self,
        points: ArrayLike,
        origin: ArrayLike,
        *,
        max_range: float | None = None,
        mode: str = "scan",
        free_points: ArrayLike | None = None,
        options: InsertOptions | None = None,
        **kwargs: Any,
    ) -> "GridMap":
        """Integrate one range scan into the map.

        Each ray from `origin` to a point in `points` marks the cells it crosses
        as free and its end cell as occupied, cell for cell as
        :meth:`OccupancyOctree.insert_scan` does, with the same methods.

        {ray_scan_parameters}
        mode : {"scan", "ray"}, default="scan"
            ``"scan"`` follows liboctomap's ``insertPointCloud``: the scan's sets
            of free and occupied cells are computed first, a cell in both counts
            as occupied, and every cell gets at most one update. ``"ray"`` counts
            rays: each cell gets ``n_free * l_miss + n_hit * l_hit`` (``n`` = how
            many rays pass through / end in it) and is clamped once.
        free_points : array-like of shape (n_free, 3), default=None
            End points of rays that only clear (their end cell gets nothing
            from them), joined to the same update as `points`, as for
            :meth:`OccupancyOctree.insert_scan`.
        options : InsertOptions, default=None
            Of :class:`~occgp.octree.InsertOptions`, the grid takes `method`
            (every method gives the same map, cell for cell: ``"auto"`` is
            ``"superray+culling"``, which backs off from super rays while they
            do not pay; ``"plain"`` walks every ray, ``"superray"`` groups rays
            into super rays, ``"culling"`` skips the scan's culling region of
            fully free cells, grown over this grid's cells, after Kwon's
            dissertation, ch. 2), `superray_threshold`, `min_range` (points
            nearer to `origin` cast no ray) and `discretize` (one ray per
            distinct end cell, to its center: liboctomap's discretized map), as
            for :meth:`OccupancyOctree.insert_scan`, and `ray_model`:
            ``"bresenham"`` builds a different, faster map by Bonxai's rules
            (see Notes); `bbox` must keep its default.
        **kwargs
            Those fields by name, as in earlier releases. ``n_jobs=`` is
            deprecated (a :class:`DeprecationWarning`; removed in the next
            release): give `n_jobs` to the constructor or :meth:`set_params`.

        Returns
        -------
        self : GridMap
            The updated map, to allow chaining.

        Raises
        ------
        TypeError
            If `points` or `origin` does not hold real numbers.
        ValueError
            If `points` is not of shape (n_points, 3), `origin` not of shape
            (3,), either holds NaN or inf or lies outside the key range (after
            truncation at `max_range`), a ray is shorter than 1.1e-19 m yet
            crosses a cell border (too short for the single-precision
            traversal), the scan reaches more than :attr:`MAX_SCAN_CELLS`
            distinct cells (the same scans for every `n_jobs`), or
            `max_range`, `mode` or an option is invalid (see
            :class:`~occgp.octree.InsertOptions`); `min_range` is not less
            than `max_range`; `free_points` is not of shape
            (n_free, 3), holds NaN or inf or has an end outside the key range.
            The map is then unchanged.

        Notes
        -----
        With ``ray_model="bresenham"`` (``ext/_bresenham.h``) the scan is
        inserted as Bonxai's ``ProbabilisticMap.insertPointCloud`` inserts it: a
        point's cell is ``floor(coordinate / resolution)`` per axis, as the
        octree's key; a point at `max_range` or farther (None: no limit) is
        moved onto the sphere of that radius and its cell is updated free. The
        points are taken in order and a cell is updated once a scan, so a
        point whose cell was updated already casts no ray; then each distinct
        end cell (those of the hits first) casts one integer Bresenham line
        from the origin's cell, whose cells before the end cell are updated
        free when this scan has not updated them yet. The log-odds are float32
        with OctoMap's sensor model and clamping (Bonxai keeps fixed-point
        integers), and a cell is skipped only when this scan updated it
        (Bonxai's three-valued marker also skips a cell updated exactly 3, 6,
        ... scans earlier). Its free space differs from the 3D-DDA map's
        (``bench/bench_grid.py`` measures the agreement); one thread.

        Examples
        --------
        >>> m = GridMap(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0], mode="ray")
        >>> m.is_occupied([[1.0, 0, 0]]).tolist()
        [True]
        >>> m.num_cells        # the cells the ray crosses, and its end cell
        10
        """
        opts, n_jobs = resolve_options(
            options, kwargs, f"{type(self).__name__}.insert_scan",
            ("method", "superray_threshold", "min_range", "discretize", "ray_model"))
        threads = self._threads() if n_jobs is None else n_threads(n_jobs)
        points, free64, _ = prefilter(points, origin, opts.min_range, max_range, free_points)
        method, threshold = self._check_method(opts.method, opts.superray_threshold)
        if opts.ray_model == "bresenham":
            return self._insert_bresenham_scan(points, origin, max_range, mode, opts, free64)
        if opts.discretize:
            if check_choice(mode, "mode", MODES) != "scan":
                raise ValueError("discretize=True is only defined for mode='scan'")
            if free64 is not None:
                raise ValueError("free_points do not combine with discretize=True")
            points = self._discretized_points(points)
        scan = join_free(
            self._validated_scan(points, origin, max_range, mode,
                                 check_ends=free64 is not None),
            None if free64 is None else self._validated_scan(free64, origin, max_range, mode,
                                                             name="free_points"))
        if scan is not None:
            pts, org, rng, _, free_only = scan
            threshold = adaptive_threshold(self, method, threshold)
            self._record_insert(self._insert(
                pts, org, rng, mode == "ray", method.endswith("culling"), None, threshold,
                False, self._max_scan_cells(), threads, free_only), pts, org, rng, method,
                threshold)
        return self

    def _insert_bresenham_scan(self, points, origin, max_range, mode, opts, free64):
        """insert_scan with ``ray_model="bresenham"`` (checked here; see its Notes)."""
        if check_choice(mode, "mode", MODES) != "scan":
            raise ValueError("ray_model='bresenham' is only defined for mode='scan'")
        if opts.method != "auto" or opts.discretize or free64 is not None:
            raise ValueError("ray_model='bresenham' takes no method, discretize or "
                             "free_points: it casts one ray per distinct end cell")
        rng = -1.0 if max_range is None else check_real(max_range, "max_range", low=0.0)
        pts = self._as_float32_points(points, "points")
        org = self._as_float32_origin(origin)
        status, rays, visits, updated, first_bad = self._insert_bresenham(pts, org, rng)
        if status:
            # an end cell without a key (the scan changed nothing): the rows whose ends,
            # cut as the octree cuts them, lie outside, and the row the core stopped at
            ok = self._check_rays(pts, org, rng)[0] != Status.OUT_OF_RANGE
            if first_bad >= 0:
                ok[first_bad] = False
            self._raise_out_of_range("points", ok,
                                     " (after truncation at max_range)" if rng >= 0 else "")
        self.last_insert_ = {"rays": int(rays), "traversed_cells": int(visits),
                             "updated_cells": int(updated), "ray_model": "bresenham"}
        return self

    # ------------------------------------------------------------------ queries
    def cells(self, *, occupied_only: bool = False) -> Leaves:
        """Return every known cell as arrays, ordered by key (z, then y, then x).

        Parameters
        ----------
        occupied_only : bool, default=False
            Keep only the occupied cells.

        Returns
        -------
        cells : Leaves
            Named tuple ``(centers, sizes, log_odds)``; every size is the
            resolution, centers are liboctomap's (``keyToCoord``).

        Examples
        --------
        >>> m = GridMap(0.1).insert_scan([[0.55, 0.05, 0.05]], [0.05, 0.05, 0.05])
        >>> centers, sizes, log_odds = m.cells(occupied_only=True)
        >>> centers.round(2).tolist(), sizes.round(2).tolist()
        ([[0.55, 0.05, 0.05]], [0.1])
        """
        _, centers, values = self._cells_sorted(check_bool(occupied_only, "occupied_only"))
        return Leaves(centers, np.full(len(values), self.resolution), values)

    # ------------------------------------------------------------------ files
    def save(self, path: str | os.PathLike) -> "GridMap":
        """Write the map with every cell to an ``.npz`` file.

        The file is a NumPy archive of plain arrays (see
        :mod:`occgp.io._npz`): ``format`` ``"occgp.grid_map"``, ``version``
        1, ``class``, ``params`` (the constructor's parameters as JSON),
        ``keys`` (uint16, shape (n_cells, 3), the cells' keys in key order)
        and ``log_odds`` (float32, shape (n_cells,)). `n_jobs`, a run-time
        setting, is not written (:meth:`load` gives the map the default;
        :meth:`set_params` changes it).

        The file is written atomically: a temporary file beside `path` replaces
        it once complete, so the previous file stays intact if the write fails.

        Parameters
        ----------
        path : str or path-like
            Destination, written as given (no suffix is added).

        Returns
        -------
        self : GridMap

        Raises
        ------
        TypeError
            If `path` is not a str or os.PathLike.
        OSError
            If the file cannot be written.

        Examples
        --------
        >>> import os, tempfile
        >>> m = GridMap(0.1).insert_scan([[1.0, 0.0, 0.0]], [0.0, 0.0, 0.0])
        >>> path = os.path.join(tempfile.mkdtemp(), "grid.npz")
        >>> GridMap.load(m.save(path) and path).num_cells == m.num_cells
        True
        """
        keys, _, values = self._cells_sorted(False)
        _npz_io.write_npz(path, _FORMAT, _VERSIONS[-1], type(self).__name__,
                          _npz_io.encode_value(_saved_params(self.get_params())),
                          {"keys": keys.astype(np.uint16), "log_odds": values.astype(np.float32)})
        return self

    @classmethod
    def load(cls, path: str | os.PathLike) -> "GridMap":
        """Read a map written by :meth:`save`.

        Parameters
        ----------
        path : str or path-like

        Returns
        -------
        map : GridMap
            A map of the class this is called on, with the file's parameters
            and cells.

        Raises
        ------
        OSError
            If the file cannot be read.
        ValueError
            If it is not a grid-map file of this class, is truncated or
            corrupt, holds non-finite log-odds, or parameters the constructor
            rejects (the message names the file).
        """
        spec = {"keys": (np.uint16, ("n", 3)), "log_odds": (np.float32, ("n",))}
        _, _, params, arrays = _npz_io.read_npz(path, _FORMAT, _VERSIONS, (cls.__name__,),
                                                spec)
        source = os.fspath(path)
        _npz_io.check_finite(arrays, ("log_odds",), source)
        if not isinstance(params, dict):
            raise ValueError(f"{source}: corrupt params: not a JSON object")
        try:
            grid = cls(**_npz_io.decode_value(params, source))
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{source}: corrupt params: {exc}") from None
        grid._set_cells(np.ascontiguousarray(arrays["keys"], np.uint16),
                        np.ascontiguousarray(arrays["log_odds"], np.float32))
        return grid

    def to_octree(self) -> "OccupancyOctree":
        """The map as an :class:`~occgp.OccupancyOctree` with the same parameters.

        Each cell's log-odds goes to the octree's finest cell with the same key
        (the grid's keys are the octree's), then the tree prunes eight equal
        children into their parent, as after the same scans.

        Returns
        -------
        tree : OccupancyOctree
        """
        from .octree._tree import OccupancyOctree

        tree = OccupancyOctree(**self.get_params())
        keys, _, values = self._cells_sorted(False)
        if len(keys):
            tree._set_values(np.ascontiguousarray(keys, np.uint16),
                             np.ascontiguousarray(values, np.float32))
        return tree

    def __reduce__(self):
        keys, _, values = self._cells_sorted(False)
        payload = keys.astype(_KEY_DTYPE).tobytes() + values.astype(_VALUE_DTYPE).tobytes()
        return (_rebuild, (type(self), self.get_params(), payload))

    # ------------------------------------------------------------------ helpers
    def _load_payload(self, payload: bytes) -> "GridMap":
        """Replace the cells by those in a :meth:`__reduce__` payload."""
        if len(payload) % _CELL_BYTES:
            raise ValueError(f"payload must hold {_CELL_BYTES} bytes per cell, "
                             f"got {len(payload)} bytes")
        n = len(payload) // _CELL_BYTES
        keys = np.frombuffer(payload, _KEY_DTYPE, 3 * n).reshape(n, 3)
        values = np.frombuffer(payload, _VALUE_DTYPE, n, offset=keys.nbytes)
        if not np.isfinite(values).all():
            raise ValueError("payload holds non-finite log-odds")
        self._set_cells(np.ascontiguousarray(keys, np.uint16),
                        np.ascontiguousarray(values, np.float32))
        return self

def _saved_params(params: dict) -> dict:
    """The parameters a grid's file stores: all but the run-time ``n_jobs`` (so that
    files stay readable by the releases whose grid has no ``n_jobs``)."""
    return {k: v for k, v in params.items() if k != "n_jobs"}


def _rebuild(cls, params: dict, payload: bytes) -> GridMap:
    """Unpickle a :class:`GridMap`."""
    return cls(**params)._load_payload(payload)
