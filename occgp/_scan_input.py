"""The scan filters every map's ``insert_scan`` shares: ``min_range`` and free-only rays.

``min_range`` drops the points nearer to the sensor than it (no ray at all), as
octomap_server's ``sensor_model/min_range`` does; the distance is the Euclidean one,
computed in double precision from the points and the origin as given (before the
maps convert them to single precision), and a point at exactly `min_range` is kept.
Filtering here, before any other work, makes an insertion with `min_range` the
insertion of the pre-filtered scan, for every method and mode.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._validation import as_point, as_points, check_real

__all__ = ["check_min_range", "far_enough", "prefilter", "join_free"]


def check_min_range(min_range: object, max_range: float | None = None,
                    range_name: str = "max_range") -> float | None:
    """`min_range` as a float (None: no filter), finite, >= 0 and < `max_range` when
    that is given (None or < 0: no limit; `range_name`: its name in the error)."""
    if min_range is None:
        return None
    value = check_real(min_range, "min_range", low=0.0, low_open=False)
    if max_range is not None and max_range >= 0 and not value < max_range:
        raise ValueError(f"min_range must be less than {range_name} ({max_range!r}), "
                         f"got {min_range!r}")
    return value


def far_enough(points: NDArray[np.float64], origin: NDArray[np.float64],
               min_range: float) -> NDArray[np.bool_]:
    """Whether each point lies at least `min_range` from `origin` (float64 distances;
    a distance too large for float64 is inf, and kept)."""
    d = points - origin
    with np.errstate(over="ignore"):
        dist = np.sqrt(np.einsum("ij,ij->i", d, d))
    return dist >= min_range


def prefilter(points: ArrayLike, origin: ArrayLike, min_range: object,
              max_range: object, free_points: ArrayLike | None = None,
              range_name: str = "max_range"):
    """Check and apply `min_range` to a scan (and its free-only rays).

    Returns ``(points, free_points, keep)``: the kept points as float64 (the
    points as given when `min_range` is None), the kept free points (None when
    none were given or none is left), and the mask of the kept points (None
    without `min_range`). `range_name`: the name of `max_range` in errors. Raises
    ValueError / TypeError naming the argument.
    """
    rng = None if max_range is None else check_real(max_range, range_name, low=0.0)
    near = check_min_range(min_range, rng, range_name)
    if near is None and free_points is None:
        return points, None, None
    pts = as_points(points, "points")
    free = None if free_points is None else as_points(free_points, "free_points")
    keep = None
    if near is not None:
        org = as_point(origin, "origin")
        keep = far_enough(pts, org, near)
        pts = pts[keep]
        if free is not None:
            free = free[far_enough(free, org, near)]
    if free is not None and len(free) == 0:
        free = None
    return pts, free, keep


def join_free(scan, free):
    """One ray set from a map's validated scan and validated free-only rays (each
    ``(points, origin, max_range, cells)`` or None when empty): ``(points, origin,
    max_range, cells, free_only)`` with the free rays after the points and
    `free_only` their uint8 flags (None without free rays), or None when both are
    empty."""
    if free is None:
        return None if scan is None else (*scan, None)
    fpts, org, rng, fcells = free
    if scan is None:
        pts, cells = np.empty((0, 3), np.float32), np.empty(0, np.int64)
    else:
        pts, _, _, cells = scan
    flags = np.zeros(len(pts) + len(fpts), np.uint8)
    flags[len(pts):] = 1
    both = np.ascontiguousarray(np.concatenate([pts, fpts]), dtype=np.float32)
    cells = None if cells is None or fcells is None else np.concatenate([cells, fcells])
    return both, org, rng, cells, flags
