"""Scan insertion into the occupancy octree: :func:`insert_scan`.

A method of :class:`occgp.OccupancyOctree`, which binds it in its class body
(``insert_scan = _insert.insert_scan``), so its first argument is the map, named
``self``. It checks the call (:class:`~occgp.octree.InsertOptions` for the rare
options, ``_options.py``), then chooses the traversal: liboctomap's own
``insertPointCloud`` for ``method="plain"`` in scan mode, occgp's compiled pipeline
(``_OcTree._insert_batch``) otherwise; see docs/architecture.rst, "How a scan goes
into the octree".
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._docfill import fill_doc
from ._logodds import MODES
from .._octree import KEYRAY_CELLS
from ._options import InsertOptions, resolve_options
from .._scan_input import join_free, prefilter
from ._superray_policy import adaptive_threshold
from .._validation import check_choice, n_threads

__all__ = ["insert_scan"]


@fill_doc()
def insert_scan(
    self,
    points: ArrayLike,
    origin: ArrayLike,
    *,
    max_range: float | None = None,
    mode: str = "scan",
    free_points: ArrayLike | None = None,
    stamp: float | None = None,
    options: InsertOptions | None = None,
    **kwargs: Any,
):
    """Integrate one range scan into the map.

    Each ray from `origin` to a point in `points` marks the cells it crosses
    as free and its end cell as occupied.

    The scan (`points`, `origin`, `free_points`, `stamp`) and the two options
    most runs set (`max_range`, `mode`) are keywords; the rarely changed ones,
    how rays are traversed and filtered, are an :class:`~occgp.octree.InsertOptions`
    (`method`, `superray_threshold`, `discretize`, `bbox`, `min_range`), built
    and checked once for a run. They may also be given as keywords, as before:
    ``insert_scan(p, o, method="plain")`` is
    ``insert_scan(p, o, options=InsertOptions(method="plain"))``. The threads
    are the map's `n_jobs` (a constructor parameter).

    {ray_scan_parameters}
    mode : {"scan", "ray"}, default="scan"
        ``"scan"`` is liboctomap's ``insertPointCloud``: the scan's sets of
        free and occupied cells are computed first, a cell in both counts as
        occupied, and every cell gets at most one update. The tree is
        identical, leaf for leaf, to liboctomap's. ``"ray"`` counts rays:
        each cell gets ``n_free * l_miss + n_hit * l_hit`` (``n`` = how many
        rays pass through / end in it) and is clamped once, whatever the
        order of the rays.
    free_points : array-like of shape (n_free, 3), default=None
        End points of rays that only clear (octomap_server inserts its
        ground points so): the cells such a ray crosses count as free,
        and its end cell gets nothing from it, as for a ray cut at
        `max_range` (which applies to these rays too). They join the same
        update as `points`: with ``mode="scan"`` a cell in both the free
        and the occupied sets is occupied and every cell is updated once;
        with ``mode="ray"`` each crossed cell counts one more miss. Free
        rays are never grouped into super rays, so every method gives
        the same map. With `bbox`, a free ray counts when its end lies in
        the box and within `max_range`, as a point's ray does, and clears
        its cells inside the box. Not with `discretize`. Each must be
        finite and in the key range (after truncation at `max_range`).
    stamp : float, default=None
        Stamp every cell the scan updates with this time (see
        :meth:`stamps` and :meth:`decay`). The culling region is then not
        used (its cells are observed too, and are stamped), and the
        traversal is occgp's (liboctomap's ``insertPointCloud`` records no
        cells); the map is the same.
    options : InsertOptions, default=None
        The traversal and filter options (None: their defaults): `method`
        (``"auto"``, ``"plain"``, ``"culling"``, ``"superray"``,
        ``"superray+culling"``; every method gives the same map, bit for
        bit), `superray_threshold`, `discretize`, `bbox` (update only inside
        a box, as liboctomap's ``useBBXLimit``) and `min_range` (points
        nearer to `origin` cast no ray); see
        :class:`~occgp.octree.InsertOptions`.
    **kwargs
        The fields of :class:`~occgp.octree.InsertOptions` by name, as in
        earlier releases (a field may not be given both here and in a
        non-default `options`). ``n_jobs=`` is deprecated (a
        :class:`DeprecationWarning`; removed in the next release): give
        `n_jobs` to the constructor or :meth:`set_params`; for this call it
        still sets the threads.

    Returns
    -------
    self : OccupancyOctree
        The updated map, to allow chaining.

    Raises
    ------
    TypeError
        If `points` or `origin` does not hold real numbers, `options` is not
        an InsertOptions, or a keyword is unknown or given twice.
    ValueError
        If `points` is not of shape (n_points, 3), `origin` not of shape
        (3,), either holds NaN or inf or lies outside the key range (after
        truncation at `max_range`), a ray is shorter than 1.1e-19 m yet
        crosses a cell border (too short for the single-precision
        traversal), the scan reaches more than :attr:`MAX_SCAN_CELLS`
        distinct cells (the same scans for every `n_jobs`), or `max_range`,
        `mode` or an option is invalid (see
        :class:`~occgp.octree.InsertOptions`; `discretize` needs
        ``mode="scan"`` and ``method="plain"``); `min_range` is not less
        than `max_range`; `free_points` is not of shape (n_free, 3), holds
        NaN or inf, has an end (after truncation) outside the key range, or
        comes with `discretize`; `bbox` has a corner outside the key range;
        or `stamp` is not finite. The map is then unchanged.

    Examples
    --------
    >>> from occgp import OccupancyOctree
    >>> m = OccupancyOctree(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0], mode="ray")
    >>> m.is_occupied([[1.0, 0, 0]]).tolist()
    [True]

    A point nearer than `min_range` casts no ray; a free point's ray only
    clears:

    >>> from occgp.octree import InsertOptions
    >>> m = OccupancyOctree(0.1).insert_scan(
    ...     [[0.05, 0.05, 1.05], [0.05, 0.05, 0.35]], [0.05, 0.05, 0.05],
    ...     free_points=[[1.05, 0.05, 0.05]], options=InsertOptions(min_range=0.5))
    >>> m.is_occupied([[0.05, 0.05, 1.05], [0.05, 0.05, 0.35]], return_unknown=True)
    (array([ True, False]), array([False, False]))
    >>> m.is_occupied([[0.95, 0.05, 0.05], [1.05, 0.05, 0.05]], return_unknown=True)
    (array([False, False]), array([False,  True]))
    """
    opts, n_jobs = resolve_options(options, kwargs, f"{type(self).__name__}.insert_scan")
    threads = self._threads() if n_jobs is None else n_threads(n_jobs)
    points, free64, _ = prefilter(points, origin, opts.min_range, max_range, free_points)
    stamping = self._stamped(stamp)
    discretize = opts.discretize
    mode = check_choice(mode, "mode", MODES)
    method, threshold = self._check_method(opts.method, opts.superray_threshold)
    if discretize and mode != "scan":
        raise ValueError("discretize=True is only defined for mode='scan'")
    if discretize and free64 is not None:
        raise ValueError("free_points do not combine with discretize=True")
    liboctomap = mode == "scan" and method == "plain" and free64 is None
    if discretize:
        # liboctomap's discretize (checks every point's key, before truncation); occgp's
        # pipeline then runs on the distinct cells' centers
        centers = self._discretized_points(points)
        if not liboctomap:
            points = centers
    box = None if opts.bbox is None else self._check_bbox(opts.bbox)
    scan = join_free(
        self._validated_scan(points, origin, max_range, mode,
                             check_ends=liboctomap or free64 is not None),
        None if free64 is None else self._validated_scan(free64, origin, max_range, mode,
                                                         name="free_points"))
    if scan is None:
        return self
    pts, org, rng, cells, free_only = scan
    if liboctomap:
        # rays within liboctomap's key buffer, and a bound on the cells they reach
        # within MAX_SCAN_CELLS: otherwise occgp's traversal, which checks it
        reach = cells.sum() + len(cells)
        # (with change tracking, occgp's traversal, which gives the same map and
        # records the changes)
        if (cells.max() <= KEYRAY_CELLS and reach <= self._max_scan_cells()
                and not self._is_tracking() and stamp is None):
            self._insert_point_cloud(pts, org, rng, bool(discretize), box)
            self.last_insert_ = {"rays": len(pts)}
            return self
        # a ray too long for liboctomap's key buffer (KEYRAY_CELLS): occgp's
        # traversal visits the cells computeRayKeys visits, and gives the map
        # insertPointCloud would give with a buffer large enough
        if discretize:
            pts, org, rng, _ = self._validated_scan(centers, origin, max_range, mode,
                                                    check_ends=False)
    key_box = None
    if box is not None:
        # liboctomap keeps the rays that end in the box within range, and of their
        # cells those in the box's keys
        kept = self._bbx_rays(pts, org, rng, box)
        pts = np.ascontiguousarray(pts[kept])
        free_only = None if free_only is None else np.ascontiguousarray(free_only[kept])
        key_box = self.coord_to_key(box)
        if len(pts) == 0:
            self.last_insert_ = {"rays": 0}
            return self
    threshold = adaptive_threshold(self, method, threshold)
    # the culling region's cells are observed, so a stamped scan walks them too
    culling = method.endswith("culling") and stamp is None
    with stamping:
        stats = self._insert_batch(pts, org, rng, mode == "ray", culling, None, threshold,
                                   False, self._max_scan_cells(), key_box, threads,
                                   free_only)
    self._record_insert(stats, pts, org, rng, method, threshold)
    return self

