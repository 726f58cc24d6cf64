"""The :class:`Scan` record shared by the scene simulators and the readers."""

import logging
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["Scan"]

logger = logging.getLogger("occgp")


class Scan(NamedTuple):
    """One range scan: end points in the world frame and the sensor position.

    A scan sequence is a plain ``list[Scan]``.

    Attributes
    ----------
    points : ndarray of shape (n_points, 3), dtype float64
        Ray end points (returns) in the world frame, in metres.
    origin : ndarray of shape (3,), dtype float64
        Sensor position in the world frame, in metres.

    Examples
    --------
    >>> import numpy as np
    >>> scan = Scan(np.zeros((2, 3)), np.array([0.0, 0.0, 1.0]))
    >>> scan.points.shape, scan.origin.tolist()
    ((2, 3), [0.0, 0.0, 1.0])
    >>> points, origin = scan
    """

    points: NDArray[np.float64]
    origin: NDArray[np.float64]


def _as_float_array(value, name):
    """``np.asarray(value, float64)`` with a TypeError / ValueError naming `name`."""
    if isinstance(value, (str, bytes)):
        raise TypeError(f"{name} must be an array of numbers, got {type(value).__name__}")
    try:
        return np.array(value, dtype=np.float64)
    except TypeError:
        raise TypeError(
            f"{name} must be an array of numbers, got {type(value).__name__}"
        ) from None
    except ValueError as exc:  # ragged lists, strings inside
        raise ValueError(f"{name} must be an array of numbers ({exc})") from None


def check_origin(origin: ArrayLike, name: str = "origin") -> NDArray[np.float64]:
    """Coerce a sensor origin to a finite float64 array of shape (3,)."""
    out = _as_float_array(origin, name)
    if out.shape != (3,):
        raise ValueError(f"{name} must have shape (3,), got {out.shape}")
    if not np.isfinite(out).all():
        raise ValueError(f"{name} must be finite (no NaN or inf), got {out.tolist()}")
    return out


def make_scan(points: ArrayLike, origin: ArrayLike, source: str = "points",
               origin_name: str = "origin") -> Scan:
    """Coerce to a :class:`Scan` with C-contiguous float64 arrays, checking shapes.

    The origin must be finite; points may hold NaN / inf (see :func:`drop_non_finite`).
    """
    points = np.ascontiguousarray(_as_float_array(points, source))
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"{source} must have shape (n_points, 3), got {points.shape}")
    return Scan(points, check_origin(origin, origin_name))


def drop_non_finite(points, source):
    """Drop the points with a NaN or inf coordinate, logging how many (PCL's habit).

    `points` is a float64 array of shape (n, 3); `source` names the file in the log.
    """
    keep = np.isfinite(points).all(axis=1)
    if keep.all():
        return points
    dropped = int(points.shape[0] - np.count_nonzero(keep))
    logger.warning("%s: dropped %d of %d points with a non-finite coordinate (NaN or inf)",
                   source, dropped, points.shape[0])
    return np.ascontiguousarray(points[keep])
