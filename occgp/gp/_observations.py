"""Range observations as GP training data: hits (points, +1) and beams (segments, -length)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from .._validation import as_numeric, as_point, as_points
from ._integral_kernel import as_segments

__all__ = ["Observations", "observations_from_scans", "make_observations"]


class Observations(NamedTuple):
    """Observations in the integral-kernel form: a point has ``start == end``."""

    #: Start points, shape (n, D).
    starts: NDArray[np.float64]
    #: End points, shape (n, D).
    ends: NDArray[np.float64]
    #: Regression targets: +1 for a hit, -length for a beam (-1 for a zero-length beam).
    y: NDArray[np.float64]
    #: Class labels, +1 (hit) or -1 (beam).
    labels: NDArray[np.float64]
    #: Arc lengths; 0 for points.
    lengths: NDArray[np.float64]

    @property
    def anchors(self) -> NDArray[np.float64]:
        """Where each observation sits: the point, or the segment's midpoint."""
        return 0.5 * (self.starts + self.ends)

    def take(self, index) -> "Observations":
        """The observations at `index`.

        Parameters
        ----------
        index : int array, boolean mask of shape (n,) or slice
            Any NumPy index of the first axis.

        Returns
        -------
        observations : Observations
            The selected rows of every field.

        Raises
        ------
        ValueError
            If `index` is not a valid NumPy index of the observations (out of
            bounds, a mask of the wrong length, another type).
        """
        try:
            return Observations(*(a[index] for a in self))
        except IndexError as exc:
            raise ValueError(f"index: {exc} (there are {len(self.y)} observations)") \
                from None


def _dimension(hits, starts):
    shapes = []
    for name, arr in (("hits", hits), ("segment_starts", starts)):
        if arr is not None:
            shape = as_numeric(arr, name).shape
            if len(shape) == 2 and 1 <= shape[1] <= 3:
                return shape[1]
            shapes.append(shape)
    raise ValueError(f"hits and segment_starts must have shape (n, D) with D in 1..3, got {shapes}")


def make_observations(hits, segment_starts, segment_ends, dim=None) -> Observations:
    """Validate hits and beams and turn them into :class:`Observations`.

    Either part may be None or empty; a zero-length beam becomes a free point
    (target -1). Raises ValueError / TypeError naming the argument.
    """
    if (segment_starts is None) != (segment_ends is None):
        raise ValueError("segment_starts and segment_ends must be given together")
    if hits is None and segment_starts is None:
        raise ValueError("no observations: give hits and/or segment_starts and segment_ends")
    if dim is None:
        dim = _dimension(hits, segment_starts)
    hits = np.empty((0, dim)) if hits is None else as_points(hits, "hits", dim)
    if segment_starts is None:
        starts = ends = np.empty((0, dim))
    else:
        starts, ends = as_segments(segment_starts, segment_ends, "segment", dim=dim)
    with np.errstate(over="ignore"):  # inf beyond 1e154: the coordinate limits reject those
        lengths = np.linalg.norm(ends - starts, axis=1)
    n_hits = len(hits)
    return Observations(
        np.vstack([hits, starts]), np.vstack([hits, ends]),
        np.r_[np.ones(n_hits), np.where(lengths > 0, -lengths, -1.0)],
        np.r_[np.ones(n_hits), -np.ones(len(starts))],
        np.r_[np.zeros(n_hits), lengths])


def observations_from_scans(scans) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                            NDArray[np.float64]]:
    """Hits and beams of a list of scans, ready for ``fit(hits, starts, ends)``.

    Parameters
    ----------
    scans : list of LaserScan2D, Scan or (points, origin) pairs
        Planar laser scans (:meth:`occgp.datasets.Scene2D.scan`: beams without
        a return count as free segments to `max_range`) or 3D scans (every
        point is a hit at the end of its beam).

    Returns
    -------
    hits : ndarray of shape (n_hits, D)
    segment_starts, segment_ends : ndarray of shape (n_beams, D)

    Raises
    ------
    ValueError
        If there is no scan, or a scan's points or origin have a bad shape,
        differ in dimension from the first scan's, or hold NaN or inf.
    TypeError
        If `scans` is not a list of scans or the arrays are not numeric.

    Examples
    --------
    >>> from occgp.datasets import room_2d
    >>> hits, starts, ends = observations_from_scans(room_2d().scan(n_poses=2))
    >>> starts.shape, ends.shape, hits.shape[1]
    ((34, 2), (34, 2), 2)
    """
    if isinstance(scans, (str, bytes)) or not hasattr(scans, "__iter__"):
        raise TypeError(f"scans must be a list of scans, got {type(scans).__name__}")
    hits, starts, ends = [], [], []
    dim = None
    for i, scan in enumerate(scans):
        laser = hasattr(scan, "hit") and hasattr(scan, "end_points")
        if not laser and (isinstance(scan, (str, bytes)) or not hasattr(scan, "__len__")
                          or len(scan) != 2):
            raise TypeError(f"scans[{i}] must be a LaserScan2D, a Scan or a (points, origin) "
                            f"pair, got {type(scan).__name__}")
        points = as_numeric(scan.end_points if laser else scan[0], f"scans[{i}].points")
        if dim is None:
            dim = points.shape[-1] if points.ndim == 2 else -1
            if not 1 <= dim <= 3:
                raise ValueError(f"scans[{i}] points must have shape (n_points, D) with D in "
                                 f"1..3, got {np.shape(points)}")
        end = as_points(points, f"scans[{i}].points", dim)
        origin = as_point(scan.origin if laser else scan[1], f"scans[{i}].origin", dim)
        if laser:
            hit = np.asarray(scan.hit)
            if hit.dtype != bool or hit.shape != (len(end),):
                raise ValueError(f"scans[{i}].hit must be a bool array of shape ({len(end)},), "
                                 f"got dtype {hit.dtype} and shape {hit.shape}")
        hits.append(end[hit] if laser else end)
        starts.append(np.broadcast_to(origin, end.shape))
        ends.append(end)
    if not ends:
        raise ValueError("scans must hold at least one scan")
    return np.vstack(hits), np.vstack(starts), np.vstack(ends)
