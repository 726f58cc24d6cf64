"""The rarely changed options of a scan insertion, in one typed, checked object.

``insert_scan(points, origin, *, max_range=None, mode="scan", free_points=None,
stamp=None, options=None, **kwargs)``: the scan (its points, origin and free
rays, its time stamp) and the two options most scans set (``max_range``,
``mode``) are keywords of their own; how the rays are traversed and filtered
(``method``, ``superray_threshold``, ``discretize``, ``bbox``, ``min_range``) is
an :class:`InsertOptions`, built and checked once, then passed with every scan.
The fields may still be given as keywords (``insert_scan(p, o, method="plain")``,
the form of every earlier release); both forms give the same map.

``n_jobs`` is a constructor parameter of every map (``OccupancyOctree(0.1,
n_jobs=2)``); ``insert_scan(..., n_jobs=)`` still works for one release, with a
:class:`DeprecationWarning`.
"""

from __future__ import annotations

import dataclasses
import warnings
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._scan_input import check_min_range
from .._validation import as_numeric, check_bool, check_choice, check_int, check_n_jobs

__all__ = ["InsertOptions", "METHODS", "RAY_MODELS", "resolve_options", "check_bbox"]

#: How the rays of a scan are traversed (see :class:`InsertOptions`).
METHODS = ("auto", "plain", "culling", "superray", "superray+culling")
#: How a ray's cells are found: liboctomap's 3D-DDA and rules, or Bonxai's (the grid).
RAY_MODELS = ("octomap", "bresenham")


def check_bbox(bbox: ArrayLike) -> np.ndarray:
    """`bbox` as a float32 array of shape (2, 3): finite in single precision and
    min <= max on every axis (the key range is the map's to check)."""
    box = as_numeric(bbox, "bbox")
    if box.shape != (2, 3):
        raise ValueError(f"bbox must have shape (2, 3) (min and max corner), got {box.shape}")
    with np.errstate(over="ignore"):
        box32 = np.ascontiguousarray(box, dtype=np.float32)
    if not np.isfinite(box32).all():
        raise ValueError("bbox must be finite (in single precision)")
    if (box32[0] > box32[1]).any():
        raise ValueError(f"bbox must have min <= max on every axis, got {box.tolist()}")
    return box32


@dataclasses.dataclass(frozen=True)
class InsertOptions:
    """How :meth:`occgp.OccupancyOctree.insert_scan` traverses and filters a scan's rays.

    The options a mapping run sets once and keeps for every scan, checked when
    the object is built (a wrong value raises there, naming the field), so a
    run builds it once and passes it with each scan::

        options = InsertOptions(method="culling", min_range=0.3)
        for points, origin in scans:
            tree.insert_scan(points, origin, max_range=8.0, options=options)

    :meth:`~occgp.OccupancyOctree.insert_scan` also takes each field as a
    keyword (``insert_scan(points, origin, method="culling")``), as before;
    :class:`~occgp.GridMap`, :class:`~occgp.ColorOctree` and
    :class:`~occgp.KNNMap` take the fields they support (the others must keep
    their defaults). :meth:`replace` gives a copy with some fields changed.

    Parameters
    ----------
    method : {"auto", "plain", "culling", "superray", "superray+culling"}, \
default="auto"
        How the rays are traversed; every method gives the same map, bit for
        bit (the user guide's "Update methods" tells how each works).
        ``"auto"`` is ``"superray+culling"``.
        ``"plain"`` traverses every ray in full (with ``mode="scan"``,
        liboctomap's ``insertPointCloud`` itself). ``"superray"`` traverses
        once for all the rays of a *super ray* (rays ending in a cell with at
        least `superray_threshold` end points that provably cross the same
        cells). ``"culling"`` skips each ray's cells inside the scan's
        *culling region* (fully free cells around the sensor, whose updates
        would change nothing). ``"superray+culling"`` does both, groups only
        the cells where grouping can pay, and pauses super rays for
        ``SUPERRAY_BACKOFF`` scans (doubling in a row) after a scan whose
        grouping cost more than it saved (Kwon's dissertation, ch. 2).
    superray_threshold : int, default=20
        With the super-ray methods, the fewest end points a cell must hold for
        its rays to be grouped; at least 1.
    discretize : bool, default=False
        Only with ``mode="scan"``: cast one ray per distinct end cell, to its
        center (liboctomap's ``insertPointCloud(..., discretize=true)``), which
        is faster for dense scans; a different map from the one of every point's
        ray, identical, leaf for leaf, to liboctomap's discretized one for every
        `method` (``"plain"`` calls liboctomap's own; the others run occgp's
        pipeline on the distinct cells' centers). Every point, before truncation
        at `max_range`, must lie in the key range. Not with `free_points`. The
        octree and the grid.
    bbox : array-like of shape (2, 3), default=None
        ``[min_corner, max_corner]``: update only inside this box, as
        liboctomap's ``useBBXLimit`` does. A ray counts only when its end point
        lies in the box (a closed box, compared in single precision) and within
        `max_range`; it marks its end cell occupied and its cells inside the box
        free (rays ending outside the box, or cut at `max_range`, change
        nothing). Every method gives liboctomap's map. Both corners must lie in
        the map's key range. Stored as a tuple of two ``(x, y, z)`` tuples of
        the single-precision corners. The octree only.
    ray_model : {"octomap", "bresenham"}, default="octomap"
        How a ray's cells are found. ``"octomap"``: liboctomap's 3D-DDA and
        update rules (every map above). ``"bresenham"``, the grid only: Bonxai's
        ``ProbabilisticMap`` rules, a different and faster map -- one integer
        Bresenham line from the origin's cell to each distinct end cell, each
        cell updated once a scan, end cells first in point order, a point at
        `max_range` or beyond moved onto that sphere with its cell updated free
        (``ext/_bresenham.h`` and :class:`~occgp.GridMap` tell the rules). Only
        with ``mode="scan"``, the default `method`, no `discretize`, no
        `free_points`; on one thread.
    min_range : float, default=None
        Points nearer to the origin than this (and free points) are dropped
        before anything else: they cast no ray at all (octomap_server's
        ``sensor_model/min_range``). The distance is Euclidean, computed in
        double precision from the points and the origin as given, before their
        conversion to single precision; a point at exactly `min_range` is kept.
        The map is the one the pre-filtered scan gives, for every method and
        mode. None (or 0): no filter. Must be finite, >= 0 and (checked at
        insertion) less than `max_range`.

    Raises
    ------
    TypeError
        If a field has the wrong type (`superray_threshold` not an int,
        `discretize` not a bool, `bbox` or `min_range` not numbers).
    ValueError
        If `method` or `ray_model` is not one of its choices, `superray_threshold` is below
        1, `bbox` is not of shape (2, 3), not finite or has min > max on an
        axis, or `min_range` is negative or not finite.

    Examples
    --------
    >>> from occgp import OccupancyOctree
    >>> from occgp.octree import InsertOptions
    >>> options = InsertOptions(method="culling", min_range=0.3)
    >>> m = OccupancyOctree(0.1).insert_scan([[1.0, 0, 0], [0.1, 0, 0]], [0, 0, 0],
    ...                                      options=options)
    >>> m.is_occupied([[1.0, 0, 0], [0.1, 0, 0]]).tolist()   # 0.1 m: nearer than min_range
    [True, False]
    >>> options.replace(method="plain").method
    'plain'
    """

    method: str = "auto"
    superray_threshold: int = 20
    discretize: bool = False
    bbox: tuple[tuple[float, float, float], tuple[float, float, float]] | None = None
    min_range: float | None = None
    ray_model: str = "octomap"

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "method", check_choice(self.method, "method", METHODS))
        set_(self, "superray_threshold", int(check_int(
            self.superray_threshold, "superray_threshold", low=1, high=2**31 - 1)))
        set_(self, "discretize", check_bool(self.discretize, "discretize"))
        if self.bbox is not None:
            box = check_bbox(self.bbox)
            set_(self, "bbox", tuple(tuple(float(v) for v in row) for row in box))
        set_(self, "min_range", check_min_range(self.min_range))
        set_(self, "ray_model", check_choice(self.ray_model, "ray_model", RAY_MODELS))

    def replace(self, **changes: Any) -> "InsertOptions":
        """A copy with the fields in `changes` changed (checked as the constructor
        checks them).

        Parameters
        ----------
        **changes
            Field names and their new values.

        Returns
        -------
        options : InsertOptions
        """
        return dataclasses.replace(self, **changes)


#: The options of an insertion that gives none.
DEFAULT = InsertOptions()
_FIELDS = tuple(f.name for f in dataclasses.fields(InsertOptions))
#: The fields the octree takes (``ray_model`` is the grid's).
OCTREE_FIELDS = tuple(name for name in _FIELDS if name != "ray_model")


def resolve_options(options: InsertOptions | None, kwargs: dict, owner: str,
                    supported: tuple[str, ...] = OCTREE_FIELDS,
                    threaded: bool = True) -> tuple[InsertOptions, int | None]:
    """The options of one ``insert_scan`` call: `options` (None: the defaults) with the
    fields given as keywords in `kwargs`, and the deprecated per-call ``n_jobs`` (None
    when not given; checked). `owner` names the method in errors; `supported`: the
    fields the map takes (the others must keep their defaults); `threaded`: whether
    the map has threads (else ``n_jobs`` is an unknown keyword).

    Raises TypeError for an unknown keyword, a field given both ways, or `options` not
    an InsertOptions; ValueError for a field the map does not support."""
    n_jobs = None
    if threaded and "n_jobs" in kwargs:
        kwargs = dict(kwargs)
        n_jobs = check_n_jobs(kwargs.pop("n_jobs"))
        cls = owner.split(".")[0]
        warnings.warn(f"{owner}(n_jobs=) is deprecated and will be removed in the next "
                      f"release; give n_jobs to the map's constructor ({cls}(..., "
                      f"n_jobs=...)) or set_params(n_jobs=...)", DeprecationWarning,
                      stacklevel=3)
    if options is None:
        options = DEFAULT
    elif not isinstance(options, InsertOptions):
        raise TypeError(f"options must be an occgp.octree.InsertOptions or None, got "
                        f"{type(options).__name__}")
    if kwargs:
        for name in kwargs:
            if name not in _FIELDS:
                raise TypeError(f"{owner}() got an unexpected keyword argument {name!r}")
            if getattr(options, name) != getattr(DEFAULT, name):
                raise TypeError(f"{owner}() got {name!r} both as a keyword and in options")
        options = dataclasses.replace(options, **kwargs)
    for name in _FIELDS:
        if name not in supported and getattr(options, name) != getattr(DEFAULT, name):
            raise ValueError(f"{owner}() does not take the option {name!r} (it takes "
                             f"{', '.join(supported) or 'none'})")
    return options, n_jobs
