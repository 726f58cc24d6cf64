"""The :class:`Scan` record shared by the scene simulators and the readers."""

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["Scan"]


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


def _make_scan(points: ArrayLike, origin: ArrayLike, source: str = "points") -> Scan:
    """Coerce to a :class:`Scan` with C-contiguous float64 arrays, checking shapes."""
    points = np.ascontiguousarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"{source} must have shape (n_points, 3), got {points.shape}")
    origin = np.array(origin, dtype=np.float64).reshape(-1)
    if origin.shape != (3,):
        raise ValueError(f"origin must have shape (3,), got {np.shape(origin)}")
    return Scan(points, origin)
