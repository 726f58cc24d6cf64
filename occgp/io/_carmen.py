"""CARMEN 2D laser logs: ``FLASER`` and ``ROBOTLASER1`` lines with their poses.

A CARMEN log is a text file (often gzip-compressed), one message a line. Two
messages carry a laser scan with the laser's pose:

* ``FLASER n r_0 ... r_(n-1) x y theta odom_x odom_y odom_theta t host t_log``
  (the old front-laser message): n ranges, then the laser pose in the map frame
  and the robot's odometry pose. Its beams span 180 degrees counter-clockwise
  from the robot's right: beam i leaves at ``theta - pi/2 + i * pi / n``
  (CARMEN's convention; 1 degree for 180 beams, 0.5 degree for 360).
* ``ROBOTLASER1 type start_angle fov resolution max_range accuracy
  remission_mode n r_0 ... r_(n-1) n_rem rem_0 ... laser_x laser_y laser_theta
  robot_x robot_y robot_theta tv rv forward side turn t host t_log``: beam i
  leaves at ``laser_theta + start_angle + i * resolution``.

SICK scanners report a beam that saw nothing with a *no-return code*, a range
at or beyond the device's maximum (about 81.9 m on the Radish logs; FLASER
lines do not state the maximum, :data:`FLASER_NO_RETURN` is the cut-off).
Such a reading is never a hit.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._validation import as_numeric, check_choice, check_real
from ._fileio import as_path, read_text
from ._scan import Scan
from ._scan2d import LaserScan2D

__all__ = ["FLASER_NO_RETURN", "LaserLog", "read_carmen"]

#: Readings of FLASER lines at or beyond this range (metres) are no-return codes.
FLASER_NO_RETURN = 49.99
_MESSAGES = ("FLASER", "ROBOTLASER1")
#: The most beams a line may hold (a SICK LMS gives at most 721; this is far beyond).
_MAX_BEAMS = 100_000


def _numbers(tokens, what, path, line_no):
    """Floats of `tokens`; ValueError naming the line when one is not a number."""
    try:
        values = np.array(tokens, dtype=np.float64)
    except ValueError:
        bad = next(t for t in tokens if not _is_float(t))
        raise ValueError(f"{path}: line {line_no}: {what} must be numbers, got "
                         f"{bad[:40]!r}") from None
    return values


def _is_float(text):
    try:
        float(text)
    except ValueError:
        return False
    return True


def _count(token, path, line_no, what):
    """A beam or remission count: a non-negative integer below _MAX_BEAMS."""
    try:
        n = int(token)
    except ValueError:
        raise ValueError(f"{path}: line {line_no}: {what} must be an integer, got "
                         f"{token[:40]!r}") from None
    if not 0 <= n <= _MAX_BEAMS:
        raise ValueError(f"{path}: line {line_no}: {what} must lie in [0, {_MAX_BEAMS}], "
                         f"got {n}")
    return n


def _need(tokens, count, path, line_no, message):
    if len(tokens) < count:
        raise ValueError(f"{path}: line {line_no}: truncated {message} line: expected at "
                         f"least {count} fields, got {len(tokens)}")


def _parse_flaser(tokens, path, line_no, angles):
    """(ranges, pose (x, y, theta), t, beam angles, no-return cut-off) of a FLASER line."""
    _need(tokens, 2, path, line_no, "FLASER")
    n = _count(tokens[1], path, line_no, "the FLASER beam count")
    _need(tokens, 2 + n + 7, path, line_no, "FLASER")
    ranges = _numbers(tokens[2:2 + n], "the ranges", path, line_no)
    pose = _numbers(tokens[2 + n:5 + n], "the laser pose", path, line_no)
    t = _numbers(tokens[8 + n:9 + n], "the time stamp", path, line_no)[0]
    if angles is None:
        beam = -0.5 * math.pi + np.arange(n) * (math.pi / n) if n else np.empty(0)
    elif len(angles) != n:
        raise ValueError(f"{path}: line {line_no}: flaser_angles holds {len(angles)} angles "
                         f"for a FLASER line of {n} beams")
    else:
        beam = angles
    return ranges, pose, t, beam, FLASER_NO_RETURN


def _parse_robotlaser(tokens, path, line_no):
    """The same for a ROBOTLASER1 line; the cut-off is the line's maximum range."""
    _need(tokens, 9, path, line_no, "ROBOTLASER1")
    head = _numbers(tokens[2:7], "the laser configuration", path, line_no)
    start, _fov, step, max_range, _accuracy = head
    n = _count(tokens[8], path, line_no, "the ROBOTLASER1 beam count")
    _need(tokens, 9 + n + 1, path, line_no, "ROBOTLASER1")
    ranges = _numbers(tokens[9:9 + n], "the ranges", path, line_no)
    m = _count(tokens[9 + n], path, line_no, "the ROBOTLASER1 remission count")
    at = 10 + n + m
    _need(tokens, at + 12, path, line_no, "ROBOTLASER1")
    pose = _numbers(tokens[at:at + 3], "the laser pose", path, line_no)
    t = _numbers(tokens[at + 11:at + 12], "the time stamp", path, line_no)[0]
    if not (np.isfinite(head).all() and 0 < max_range <= 1e6 and abs(start) <= 1e3
            and abs(step) <= 1e3):
        raise ValueError(f"{path}: line {line_no}: the laser configuration must be finite, "
                         f"with a maximum range in (0, 1e6] m and start and step angles within "
                         f"1e3 rad, got {head.tolist()}")
    return ranges, pose, t, start + np.arange(n) * step, max_range


class LaserLog:
    """The scans of a 2D laser log, in file order, with their time stamps.

    A sequence of :class:`LaserScan2D` (``len``, indexing, iteration; an index
    array or a slice gives a smaller :class:`LaserLog`), as :func:`read_carmen`
    returns it. Each scan holds the beams a map should take: its returns
    (``hit`` True) and, when the log was read with a `no_return_range`, its
    no-return beams as free segments of that length (``hit`` False).

    Parameters
    ----------
    scans : sequence of LaserScan2D
        The scans.
    times : array-like of shape (n_scans,)
        Their time stamps, in seconds (file order is kept even where they step
        back).
    n_no_return : int, default=0
        How many no-return readings the log held (kept or dropped).
    n_cut : int, default=0
        How many returns lay beyond the reader's `max_range` (cut to free
        beams).

    Attributes
    ----------
    times : ndarray of shape (n_scans,)
    n_no_return : int
    n_cut : int

    Examples
    --------
    >>> s = LaserScan2D(np.zeros(2), 0.0, np.array([0.0]), np.array([2.0]),
    ...                 np.array([True]), 80.0)
    >>> log = LaserLog([s, s], [0.0, 0.1])
    >>> hits, starts, ends = log.observations()
    >>> hits.tolist(), len(log[1:])
    ([[2.0, 0.0], [2.0, 0.0]], 1)
    """

    def __init__(self, scans: Sequence[LaserScan2D], times: ArrayLike, *,
                 n_no_return: int = 0, n_cut: int = 0):
        self._scans = list(scans)
        self.times = np.asarray(times, dtype=np.float64).reshape(-1)
        if len(self.times) != len(self._scans):
            raise ValueError(f"times must hold one time per scan ({len(self._scans)}), got "
                             f"{len(self.times)}")
        self.n_no_return = int(n_no_return)
        self.n_cut = int(n_cut)

    def __len__(self) -> int:
        return len(self._scans)

    def __iter__(self):
        return iter(self._scans)

    def __getitem__(self, index):
        if isinstance(index, (int, np.integer)):
            return self._scans[index]
        idx = np.arange(len(self))[index]
        return LaserLog([self._scans[i] for i in idx], self.times[idx])

    def __repr__(self) -> str:
        beams = sum(len(s.ranges) for s in self._scans)
        return f"LaserLog({len(self)} scans, {beams:,} beams)"

    @property
    def poses(self) -> NDArray[np.float64]:
        """The laser poses ``(x, y, theta)`` of the scans, shape (n_scans, 3)."""
        if not len(self):
            return np.empty((0, 3))
        return np.array([[*s.origin, s.heading] for s in self._scans], dtype=np.float64)

    def observations(self, indices: ArrayLike | None = None):
        """Hits and beams of the scans, for the 2D maps' ``fit(hits, starts, ends)``.

        Every beam runs from its scan's origin to its end: the hit for a
        return (occgp's convention), the free end for a no-return beam kept
        by the reader.

        Parameters
        ----------
        indices : array-like of int, default=None
            The scans to take (None: all).

        Returns
        -------
        hits : ndarray of shape (n_hits, 2)
        segment_starts, segment_ends : ndarray of shape (n_beams, 2)
        """
        scans = self._scans if indices is None else [self._scans[i] for i in
                                                     np.asarray(indices, dtype=np.intp)]
        if not scans:
            return np.empty((0, 2)), np.empty((0, 2)), np.empty((0, 2))
        ends = [s.end_points for s in scans]
        hits = np.vstack([e[s.hit] for e, s in zip(ends, scans)])
        starts = np.repeat(np.array([s.origin for s in scans]),
                           [len(s.ranges) for s in scans], axis=0)
        return hits, starts, np.vstack(ends)

    def scans_3d(self, z: float = 0.0) -> list:
        """The scans in 3D at one height, for the 3D maps.

        Parameters
        ----------
        z : float, default=0.0
            The height of the scan plane, in metres.

        Returns
        -------
        scans : list of (Scan, ndarray)
            Each scan's returns and origin as a :class:`Scan` (z = `z`), and
            the ends of its beams without a return, shape (n_free, 3): free
            space up to them (the ``free_points`` of the octree's
            ``insert_scan``).
        """
        z = check_real(z, "z", state_bounds=True)
        out = []
        for s in self._scans:
            ends = np.column_stack([s.end_points, np.full(len(s.ranges), z)])
            out.append((Scan(ends[s.hit], np.array([*s.origin, z])), ends[~s.hit]))
        return out


def read_carmen(path, *, message: str | None = None, no_return_range: float | None = None,
                max_range: float | None = None,
                flaser_angles: ArrayLike | None = None) -> LaserLog:
    """Read the laser scans of a CARMEN log (``FLASER`` or ``ROBOTLASER1`` lines).

    Every scan is placed by the laser pose its line carries (the corrected
    pose, in a SLAM-corrected log). Other messages (``ODOM``, ``PARAM``,
    ``NEFF``, raw laser lines without a pose, ``#`` comments) are skipped;
    ``.gz``, ``.bz2`` and ``.xz`` files are decompressed by suffix. The
    scans keep the file's order (time stamps may step back).

    **No-return readings** (at or beyond :data:`FLASER_NO_RETURN`, 49.99 m,
    on FLASER lines; at or beyond the line's maximum range on ROBOTLASER1
    lines) are never hits. By default they are dropped: indoors, a SICK
    laser's no-return mostly marks a surface it did not see (glass, black or
    glancing surfaces), not open space. On the Intel and Freiburg 079 logs
    every no-return beam crosses a wall that other scans hit, at 3.0 m and
    0.5 m (medians) from the sensor, so taking them as free up to any
    range beyond a few metres would clear walls. Pass `no_return_range` to
    keep them as free beams of that length.

    Parameters
    ----------
    path : str or os.PathLike
        The log file.
    message : {"FLASER", "ROBOTLASER1"}, default=None
        Which lines to read; None reads the FLASER lines, or the ROBOTLASER1
        lines of a log that has no FLASER line (a log may carry the same scans
        in both messages: one kind is read, never both).
    no_return_range : float, default=None
        Keep no-return beams as beams without a hit, free up to this range
        (metres, > 0); None drops them.
    max_range : float, default=None
        Range limit (metres, > 0): a return farther than it becomes a beam
        without a hit, free up to `max_range`, and so does a kept no-return
        beam longer than it. None: no limit.
    flaser_angles : array-like of shape (n_beams,), default=None
        Beam angles of FLASER lines relative to the laser's heading, radians;
        None uses CARMEN's convention above. Every FLASER line must then hold
        that many beams.

    Returns
    -------
    log : LaserLog
        The scans (:class:`LaserScan2D`: origin, heading, beam angles,
        ranges, hit flags, and as ``max_range`` the range of the free beams),
        their times and the counts of no-return and cut readings.

    Raises
    ------
    OSError
        If the file is missing or unreadable.
    ValueError
        If the file is not UTF-8 text or its compressed stream is corrupt,
        holds no line of the kind read, a line of that kind is truncated or
        holds a non-number, a negative or NaN range or a non-finite pose
        (with the line number), or a parameter is out of range.
    TypeError
        If `path` is not a str or os.PathLike, or a parameter has a wrong type.

    Examples
    --------
    >>> import os, tempfile
    >>> from pathlib import Path
    >>> path = Path(tempfile.mkdtemp()) / "tiny.log"
    >>> _ = path.write_text("FLASER 2 1.0 81.83 0 0 0 0 0 0 5.0 host 5.0\\n")
    >>> log = read_carmen(path)
    >>> log[0].ranges.tolist(), log.n_no_return       # beam 1 had no return
    ([1.0], 1)
    >>> log[0].points.round(12).tolist()              # beam 0 looks right (-y)
    [[0.0, -1.0]]
    """
    path = as_path(path)
    if message is not None:
        message = check_choice(message, "message", _MESSAGES)
    if no_return_range is not None:
        no_return_range = check_real(no_return_range, "no_return_range", low=0.0, high=1e6,
                                     high_open=False)
    if max_range is not None:
        max_range = check_real(max_range, "max_range", low=0.0, high=1e6, high_open=False)
    angles = None
    if flaser_angles is not None:
        angles = np.asarray(as_numeric(flaser_angles, "flaser_angles"), dtype=np.float64)
        if angles.ndim != 1 or not np.isfinite(angles).all():
            raise ValueError(f"flaser_angles must be a 1-D array of finite angles, got shape "
                             f"{angles.shape}")
    lines = read_text(path).splitlines()
    wanted = message or "FLASER or ROBOTLASER1"
    if message is None:
        message = "FLASER" if any(line.startswith("FLASER") for line in lines) \
            else "ROBOTLASER1"
    scans, times = [], []
    n_no_return = n_cut = 0
    for line_no, line in enumerate(lines, start=1):
        if not line.startswith(message):
            continue
        tokens = line.split()
        if tokens[0] != message:
            continue
        if message == "FLASER":
            ranges, pose, t, beam, cutoff = _parse_flaser(tokens, path, line_no, angles)
        else:
            ranges, pose, t, beam, cutoff = _parse_robotlaser(tokens, path, line_no)
        if not np.isfinite(pose).all() or np.abs(pose).max() > 1e9:
            raise ValueError(f"{path}: line {line_no}: the laser pose must be finite and "
                             f"within 1e9 m, got {pose.tolist()}")
        if not np.isfinite(t):
            raise ValueError(f"{path}: line {line_no}: the time stamp must be finite, got {t}")
        if len(ranges) and not (ranges >= 0).all():   # NaN fails too
            bad = ranges[~(ranges >= 0)][0]
            raise ValueError(f"{path}: line {line_no}: ranges must be non-negative numbers, "
                             f"got {bad}")
        hit = ranges < cutoff
        n_no_return += int(np.count_nonzero(~hit))
        keep = hit if no_return_range is None else np.ones(len(ranges), dtype=bool)
        if no_return_range is not None:
            ranges = np.where(hit, ranges, no_return_range)
        ranges = ranges[keep]
        hit, beam = hit[keep], beam[keep]
        free_range = no_return_range if no_return_range is not None else cutoff
        if max_range is not None:
            far = ranges > max_range
            n_cut += int(np.count_nonzero(far & hit))
            ranges = np.where(far, max_range, ranges)
            hit = hit & ~far
            free_range = min(free_range, max_range)
        scans.append(LaserScan2D(pose[:2].copy(), float(pose[2]), np.asarray(beam, float),
                                 ranges, hit, float(free_range)))
        times.append(t)
    if not scans:
        raise ValueError(f"{path}: no {wanted} lines: not a CARMEN laser log, or its scans "
                         f"are in other messages (read_carmen reads FLASER and ROBOTLASER1)")
    return LaserLog(scans, times, n_no_return=n_no_return, n_cut=n_cut)


def is_carmen_log(path) -> bool:
    """Whether a text file's first 200 non-comment lines hold a FLASER or ROBOTLASER1
    line (a quick look for :func:`occgp.io.read_scans`' dispatch)."""
    try:
        text = read_text(Path(path))
    except (OSError, ValueError):
        return False
    seen = 0
    for line in text.splitlines():
        if not line.strip() or line.startswith("#"):
            continue
        if line.startswith(_MESSAGES):
            return True
        seen += 1
        if seen >= 200:
            break
    return False
