"""The :class:`LaserScan2D` record: one planar laser scan (origin, heading, beam angles,
ranges, returns), as the 2D scene simulators make it and the CARMEN reader reads it."""

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

__all__ = ["LaserScan2D"]


class LaserScan2D(NamedTuple):
    """One planar laser scan.

    Attributes
    ----------
    origin : ndarray of shape (2,)
        Sensor position in the world frame, metres.
    heading : float
        Sensor heading, radians from +x.
    angles : ndarray of shape (n_beams,)
        Beam angles relative to `heading`, radians.
    ranges : ndarray of shape (n_beams,)
        Measured ranges; `max_range` for beams without a return.
    hit : ndarray of shape (n_beams,), dtype bool
        Whether each beam returned.
    max_range : float
        Maximum range of the laser.

    Examples
    --------
    >>> s = LaserScan2D(np.zeros(2), 0.0, np.array([0.0, np.pi / 2]),
    ...                 np.array([1.0, 8.0]), np.array([True, False]), 8.0)
    >>> s.points.round(12).tolist()
    [[1.0, 0.0]]
    >>> s.end_points.round(12).tolist()
    [[1.0, 0.0], [0.0, 8.0]]
    """

    origin: NDArray[np.float64]
    heading: float
    angles: NDArray[np.float64]
    ranges: NDArray[np.float64]
    hit: NDArray[np.bool_]
    max_range: float

    @property
    def directions(self) -> NDArray[np.float64]:
        """Unit beam directions in the world frame, shape (n_beams, 2)."""
        world = self.heading + self.angles
        return np.column_stack([np.cos(world), np.sin(world)])

    @property
    def end_points(self) -> NDArray[np.float64]:
        """End of every beam (at `max_range` for no return), shape (n_beams, 2)."""
        return self.origin + self.ranges[:, None] * self.directions

    @property
    def points(self) -> NDArray[np.float64]:
        """End points of the beams with a return, shape (n_hits, 2)."""
        return self.end_points[self.hit]
