"""Range observations as GP training data: hits (points, +1) and beams (segments, -length)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from .._validation import as_numeric, as_point, as_points, check_bool, check_real
from ._integral_kernel import as_segments

__all__ = ["Observations", "observations_from_scans", "make_observations", "check_beam_hits",
           "draw_subset", "draw_balanced", "loo_sample"]


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


def draw_subset(labels, size, rng) -> NDArray[np.intp]:
    """Sorted indices of `size` observations drawn at random (all when fewer), with both
    classes where `labels` (+1 hit, -1 beam) has both: a classifier is fitted on them.

    Where the draw (``rng.choice`` without replacement) misses a class, one of
    its entries, drawn at random, is swapped for an observation of that class
    drawn at random; other draws are ``rng.choice``'s, sorted.
    """
    n = len(labels)
    if n <= size:
        return np.arange(n)
    take = rng.choice(n, size, replace=False)
    for members in (labels > 0, labels < 0):
        if members.any() and not members[take].any():
            take[rng.integers(size)] = rng.choice(np.flatnonzero(members))
    return np.sort(take)


def draw_balanced(labels, size, rng) -> NDArray[np.intp]:
    """Sorted indices of at most `size` observations, as many hits (+1) as beams (-1) where
    both classes have enough (the rest from the larger class), each class drawn at random
    without replacement (``rng.choice``, hits first)."""
    hits, beams = np.flatnonzero(labels > 0), np.flatnonzero(labels < 0)
    k_hit = min(len(hits), max(size // 2, size - len(beams)))
    k_beam = min(len(beams), size - k_hit)
    return np.sort(np.r_[rng.choice(hits, k_hit, replace=False),
                         rng.choice(beams, k_beam, replace=False)])


def loo_sample(obs, size, rng):
    """Where the leave-one-out classifiers are fitted: ``(take, X)``.

    `take` (:func:`draw_balanced`) indexes at most `size` observations of
    `obs`, as many hits as beams; ``X[j]`` is the hit itself, or a point drawn
    uniformly on the beam (``rng.random``, after the draw of `take`).
    """
    take = draw_balanced(obs.labels, size, rng)
    u = rng.random(len(take))
    return take, obs.starts[take] + u[:, None] * (obs.ends[take] - obs.starts[take])


def check_beam_hits(beam_hits, n_beams: int, n_hits: int) -> NDArray[np.int64]:
    """`beam_hits` checked: int array of shape (n_beams,), each -1 or a hit index.

    Several beams may name the same hit (repeated beams of one return).
    Raises TypeError (not integers) or ValueError (shape, range), naming
    `beam_hits`.
    """
    arr = as_numeric(beam_hits, "beam_hits", kinds="iufb")
    if arr.dtype.kind not in "iu":
        raise TypeError(f"beam_hits must hold integers (a hit index, or -1 for a beam without "
                        f"a return), got dtype {arr.dtype}")
    if arr.shape != (n_beams,):
        raise ValueError(f"beam_hits must have shape ({n_beams},) (one entry per beam), got "
                         f"{arr.shape}")
    if len(arr) and (arr.min() < -1 or arr.max() >= n_hits):
        bad = arr[(arr < -1) | (arr >= n_hits)][0]
        raise ValueError(f"beam_hits must hold -1 (no return) or a hit index in 0..{n_hits - 1} "
                         f"(there are {n_hits} hits), got {int(bad)}")
    return arr.astype(np.int64)


def observations_from_scans(scans, *, stop_short: float = 0.0,
                            return_beam_hits: bool = False) -> tuple[NDArray[np.float64], ...]:
    """Hits and beams of a list of scans, ready for ``fit(hits, starts, ends)``.

    Two conventions for a beam with a return: by default (``stop_short=0``,
    occgp's) it ends exactly at its hit; with ``stop_short > 0`` (the
    integral-kernel paper's) its free segment stops that far before the hit,
    so that the hit's own surroundings are not observed free: the beam runs
    from the sensor to ``max(range - stop_short, 0)`` along the ray (a
    return closer than `stop_short` gives a zero-length beam at the sensor).
    Beams without a return end at the maximum range either way. The maps
    accept both: :class:`GPMixture` and :func:`assign_beams` find the hit of
    a shortened beam on its ray (see :func:`occgp.gp._beams.match_beams`),
    or take `beam_hits` from ``return_beam_hits=True``.

    Parameters
    ----------
    scans : list of LaserScan2D, Scan or (points, origin) pairs
        Planar laser scans (:meth:`occgp.datasets.Scene2D.scan`: beams without
        a return count as free segments to `max_range`) or 3D scans (every
        point is a hit at the end of its beam).
    stop_short : float, default=0.0
        How far (metres, >= 0) a returning beam's free segment stops before
        its hit.
    return_beam_hits : bool, default=False
        Also return, for each beam, the index of its hit in `hits` (-1 for a
        beam without a return): the ``beam_hits`` of the maps' ``fit``.

    Returns
    -------
    hits : ndarray of shape (n_hits, D)
    segment_starts, segment_ends : ndarray of shape (n_beams, D)
    beam_hits : ndarray of shape (n_beams,), dtype int64
        Only with ``return_beam_hits=True``.

    Raises
    ------
    ValueError
        If there is no scan, or a scan's points or origin have a bad shape,
        differ in dimension from the first scan's, or hold NaN or inf, or
        `stop_short` is negative or not finite.
    TypeError
        If `scans` is not a list of scans or the arrays are not numeric, or
        `stop_short` is not a real number or `return_beam_hits` not a bool.

    Examples
    --------
    >>> from occgp.datasets import room_2d
    >>> hits, starts, ends = observations_from_scans(room_2d().scan(n_poses=2))
    >>> starts.shape, ends.shape, hits.shape[1]
    ((34, 2), (34, 2), 2)

    The paper's convention, beams stopping 5 cm short of their hits:

    >>> import numpy as np
    >>> h, s, e, beam_hits = observations_from_scans(
    ...     room_2d().scan(n_poses=2), stop_short=0.05, return_beam_hits=True)
    >>> back = np.linalg.norm(h[beam_hits[beam_hits >= 0]] - e[beam_hits >= 0], axis=1)
    >>> bool(np.allclose(back, 0.05)), int((beam_hits < 0).sum()) == len(e) - len(h)
    (True, True)
    """
    if isinstance(scans, (str, bytes)) or not hasattr(scans, "__iter__"):
        raise TypeError(f"scans must be a list of scans, got {type(scans).__name__}")
    stop_short = check_real(stop_short, "stop_short", low=0.0, low_open=False)
    return_beam_hits = check_bool(return_beam_hits, "return_beam_hits")
    hits, starts, ends, beam_hits = [], [], [], []
    n_hits = 0
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
        else:
            hit = np.ones(len(end), dtype=bool)
        hits.append(end[hit])
        starts.append(np.broadcast_to(origin, end.shape))
        index = np.full(len(end), -1, dtype=np.int64)
        index[hit] = n_hits + np.arange(int(np.count_nonzero(hit)))
        n_hits += int(np.count_nonzero(hit))
        beam_hits.append(index)
        if stop_short > 0:
            end = _stop_short(origin, end, hit, stop_short)
        ends.append(end)
    if not ends:
        raise ValueError("scans must hold at least one scan")
    out = (np.vstack(hits), np.vstack(starts), np.vstack(ends))
    return out + (np.concatenate(beam_hits),) if return_beam_hits else out


def _stop_short(origin, end, hit, margin):
    """`end` with each returning beam (`hit`) ending `margin` before it (clamped at the origin)."""
    delta = end[hit] - origin
    length = np.linalg.norm(delta, axis=1)
    scale = np.divide(np.maximum(length - margin, 0.0), length, out=np.zeros_like(length),
                      where=length > 0)
    out = end.copy()
    out[hit] = origin + scale[:, None] * delta
    return out
