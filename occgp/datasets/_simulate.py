"""A spinning 3D LiDAR simulator and collision-free sensor paths.

:func:`simulate_scans` casts the beams of a :class:`LidarSensor` into an
:class:`~occgp.OccupancyOctree` (a real map from a ``.bt`` file) or an analytic
:class:`Scene`, from poses that :func:`free_path` grows through free space:
dense scan sequences (about 100k returns per scan) for benchmarks.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree
from tqdm.auto import tqdm

from .._validation import as_points, check_int, check_real
from ..octree._tree import OccupancyOctree
from ..io._scan import Scan
from ._scenes import Scene

__all__ = ["LidarSensor", "simulate_scans", "free_path"]

_NEIGHBOURS = 64  # occupied cells checked for a pose's clearance
_CANDIDATES = 24  # headings tried per path step (the last one turns back)
_MAX_STARTS = 50  # start poses tried before free_path gives up
MAX_RAYS = 2**24  # most beams of a LidarSensor (n_vertical * n_horizontal)


@dataclass(frozen=True)
class LidarSensor:
    """A spinning 3D laser scanner with a regular grid of beams.

    Beams lie on a grid of `n_vertical` elevations x `n_horizontal` azimuths,
    each at the center of its bin (so a full turn repeats no azimuth).

    Parameters
    ----------
    horizontal_fov : float, default=2*pi
        Width of the scanned sector about the heading, radians; in (0, 2 pi].
    n_horizontal : int, default=720
        Beams per elevation (0.5 degree steps for a full turn).
    vertical_fov : tuple of float, default=(-pi/4, pi/6)
        Lowest and highest beam elevation, radians, with
        ``-pi/2 <= low < high <= pi/2``.
    n_vertical : int, default=150
        Number of elevations (0.5 degree steps by default). At most
        ``MAX_RAYS`` (2^24) beams in all, ``n_vertical * n_horizontal``.
    max_range : float, default=20.0
        Longest range that gives a return, metres.
    range_noise : float, default=0.0
        Standard deviation of Gaussian range noise along each beam, metres.

    Attributes
    ----------
    n_rays : int
        ``n_vertical * n_horizontal`` beams per scan (108000 by default).

    Examples
    --------
    >>> sensor = LidarSensor(n_horizontal=8, n_vertical=2)
    >>> sensor.n_rays, sensor.directions().shape
    (16, (16, 3))
    """

    horizontal_fov: float = 2 * np.pi
    n_horizontal: int = 720
    vertical_fov: tuple[float, float] = (-np.pi / 4, np.pi / 6)
    n_vertical: int = 150
    max_range: float = 20.0
    range_noise: float = 0.0

    def __post_init__(self) -> None:
        fix = lambda name, value: object.__setattr__(self, name, value)  # noqa: E731
        fix("horizontal_fov", check_real(self.horizontal_fov, "horizontal_fov", low=0.0,
                                         high=2 * np.pi, high_open=False))
        fix("n_horizontal", check_int(self.n_horizontal, "n_horizontal", low=1))
        fix("n_vertical", check_int(self.n_vertical, "n_vertical", low=1))
        if self.n_vertical * self.n_horizontal > MAX_RAYS:
            raise ValueError(f"n_vertical * n_horizontal must be at most {MAX_RAYS} beams, got "
                             f"{self.n_vertical} x {self.n_horizontal}")
        fov = np.asarray(self.vertical_fov)
        if fov.dtype.kind not in "iuf":
            raise TypeError(f"vertical_fov must hold real numbers, got dtype {fov.dtype}")
        if fov.shape != (2,) or not (-np.pi / 2 <= fov[0] < fov[1] <= np.pi / 2):
            raise ValueError("vertical_fov must be (low, high) with -pi/2 <= low < high <= pi/2,"
                             f" got {self.vertical_fov!r}")
        fix("vertical_fov", (float(fov[0]), float(fov[1])))
        fix("max_range", check_real(self.max_range, "max_range", low=0.0))
        fix("range_noise", check_real(self.range_noise, "range_noise", low=0.0, low_open=False))

    @property
    def n_rays(self) -> int:
        """Beams per scan, ``n_vertical * n_horizontal``."""
        return self.n_vertical * self.n_horizontal

    def directions(self, heading: float = 0.0) -> NDArray[np.float64]:
        """Unit beam directions in the world frame.

        Parameters
        ----------
        heading : float, default=0.0
            Yaw of the sensor, radians about +z from +x; the sector is
            centered on it.

        Returns
        -------
        directions : ndarray of shape (n_rays, 3)
            Row ``j * n_horizontal + i`` is elevation ``j`` (lowest first) and
            azimuth ``i`` (counter-clockwise), so per-beam values reshape to a
            ``(n_vertical, n_horizontal)`` range image.

        Raises
        ------
        TypeError
            If `heading` is not a real number.
        ValueError
            If `heading` is NaN or inf.

        Examples
        --------
        >>> d = LidarSensor(horizontal_fov=np.pi, n_horizontal=2, vertical_fov=(-0.1, 0.1),
        ...                 n_vertical=1).directions(heading=np.pi / 2)
        >>> d.round(3).tolist()
        [[0.707, 0.707, 0.0], [-0.707, 0.707, 0.0]]
        """
        heading = check_real(heading, "heading")
        az = heading + self.horizontal_fov * ((np.arange(self.n_horizontal) + 0.5)
                                              / self.n_horizontal - 0.5)
        lo, hi = self.vertical_fov
        el = lo + (hi - lo) * (np.arange(self.n_vertical) + 0.5) / self.n_vertical
        el, az = np.meshgrid(el, az, indexing="ij")
        return np.column_stack([(np.cos(el) * np.cos(az)).ravel(),
                                (np.cos(el) * np.sin(az)).ravel(), np.sin(el).ravel()])


def simulate_scans(
    environment: OccupancyOctree | Scene,
    poses: ArrayLike,
    sensor: LidarSensor = LidarSensor(),
    *,
    headings: ArrayLike | None = None,
    seed: int | np.random.Generator = 0,
    progress: bool | None = None,
) -> list[Scan]:
    """Simulate one LiDAR scan per pose by casting the sensor's beams.

    For an :class:`~occgp.OccupancyOctree` a beam returns where it enters the
    first occupied cell (unknown cells are seen through); the point is the
    exact entry point of the beam into that cell, moved a few float32 steps
    inside it, so that the many returns from one cell are spread over its
    surface. For an analytic scene (any object with ``ray_cast(origins,
    directions, max_range)``) it is the exact surface point. Beams with no
    return within ``sensor.max_range`` are dropped.

    Parameters
    ----------
    environment : OccupancyOctree or Scene
        What the sensor sees.
    poses : array-like of shape (n_poses, 3)
        Sensor positions in the world frame, metres.
    sensor : LidarSensor, default=LidarSensor()
        Beam pattern, range and noise.
    headings : array-like of shape (n_poses,), default=None
        Sensor yaw per pose, radians; None: 0 for every pose.
    seed : int or numpy.random.Generator, default=0
        Seeds one generator for the range noise of the whole call.
    progress : bool, default=None
        Show a progress bar over poses; None: only in an interactive terminal.

    Returns
    -------
    scans : list of Scan
        One ``Scan(points, origin)`` per pose, points of shape (n_returns, 3).

    Raises
    ------
    TypeError
        If `environment` cannot cast rays or `sensor` is not a LidarSensor.
    ValueError
        If `poses` or `headings` have the wrong shape or hold NaN or inf, or
        a pose lies inside an occupied cell (or solid).

    See Also
    --------
    free_path : Collision-free poses to scan from.

    Examples
    --------
    >>> from occgp.datasets import structured_room
    >>> sensor = LidarSensor(n_horizontal=90, n_vertical=10, range_noise=0.01)
    >>> scans = simulate_scans(structured_room(), [[0.0, 0.0, 1.0]], sensor)
    >>> len(scans), scans[0].points.shape    # the room has no ceiling: 210 rays miss
    (1, (690, 3))
    """
    world = _as_world(environment)
    if not isinstance(sensor, LidarSensor):
        raise TypeError(f"sensor must be a LidarSensor, got {type(sensor).__name__}")
    arr = np.asarray(poses)
    if arr.dtype.kind in "iuf" and (arr.ndim != 2 or arr.shape[1] != 3):
        raise ValueError(f"poses must have shape (n_poses, 3), got {arr.shape}")
    poses = as_points(arr, "poses")
    headings = np.zeros(len(poses)) if headings is None else np.asarray(headings)
    if headings.shape != (len(poses),):
        raise ValueError(f"headings must have shape ({len(poses)},) to match poses, "
                         f"got {headings.shape}")
    headings = as_points(headings[:, None], "headings", dim=1)[:, 0]
    inside = world.occupied(poses)
    if inside.any():
        i = int(np.flatnonzero(inside)[0])
        raise ValueError(f"poses[{i}] = {poses[i].tolist()} lies inside an occupied "
                         f"{world.what}; a sensor must stand in free space")
    rng = np.random.default_rng(seed)
    scans = []
    for origin, heading in tqdm(zip(poses, headings), total=len(poses), unit="scan",
                                desc="simulating scans",
                                disable=None if progress is None else not progress):
        dirs = sensor.directions(heading)
        points, hit = world.returns(origin, dirs, sensor.max_range)
        points, dirs = points[hit], dirs[hit]
        if sensor.range_noise > 0:
            points += rng.normal(0.0, sensor.range_noise, len(points))[:, None] * dirs
        scans.append(Scan(points, origin.copy()))
    return scans


def free_path(
    environment: OccupancyOctree | Scene,
    n_poses: int,
    *,
    step: float = 1.0,
    clearance: float = 0.5,
    height: float | None = None,
    seed: int | np.random.Generator = 0,
) -> NDArray[np.float64]:
    """Grow a collision-free path of sensor poses through known free space.

    The path is a random walk with momentum at a constant height: it starts at
    a random free location, then moves `step` metres at a time, preferring to
    go on straight, turning where it must. Every pose lies in a known free
    cell at least `clearance` from every occupied cell (unknown space may be
    nearer), and every segment between consecutive poses crosses only known
    free cells. For an analytic scene free space is the room's interior.

    Parameters
    ----------
    environment : OccupancyOctree or Scene
        The map to walk through.
    n_poses : int
        Number of poses.
    step : float, default=1.0
        Distance between consecutive poses, metres.
    clearance : float, default=0.5
        Least distance from a pose to occupied space, metres.
    height : float, default=None
        z of the path, metres. None: 1 m above the floor, that is above the
        densest occupied layer of cells in the lower half of an octree (for
        geb079: z = 1.0), or above ``interior_bounds`` of a scene.
    seed : int or numpy.random.Generator, default=0
        The path is deterministic for a given seed.

    Returns
    -------
    poses : ndarray of shape (n_poses, 3)

    Raises
    ------
    TypeError
        If `environment` cannot cast rays.
    ValueError
        For a non-positive `n_poses` or `step`, a negative `clearance`, or
        when no path can be grown from any of (at most 50) free starts at
        `height`.

    Examples
    --------
    >>> from occgp.datasets import structured_room
    >>> poses = free_path(structured_room(), 5, step=0.5, seed=1)
    >>> poses.shape, np.linalg.norm(np.diff(poses, axis=0), axis=1).round(6).tolist()
    ((5, 3), [0.5, 0.5, 0.5, 0.5])
    """
    world = _as_world(environment)
    n_poses = check_int(n_poses, "n_poses", low=1)
    step = check_real(step, "step", low=0.0)
    clearance = check_real(clearance, "clearance", low=0.0, low_open=False)
    height = world.default_height() if height is None else check_real(height, "height")
    rng = np.random.default_rng(seed)
    starts = world.start_candidates(height, rng)[: 20 * _MAX_STARTS]
    starts = starts[_valid_poses(world, starts, clearance)]
    # start in open space: keep the (random) candidates with the longest free sight lines
    ring = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    ring = np.column_stack([np.cos(ring), np.sin(ring), np.zeros(8)])
    sight = world.free_distance(np.repeat(starts, len(ring), axis=0),
                                np.tile(ring, (len(starts), 1)), 5 * step)
    sight = sight.reshape(len(starts), len(ring)).mean(axis=1)
    starts = starts[sight >= np.quantile(sight, 0.75)][:_MAX_STARTS] if len(starts) else starts
    for start in starts:
        path, theta = [start], rng.uniform(-np.pi, np.pi)
        while len(path) < n_poses:
            # small random turns first, then the least sharp of random turns, then turn back
            sharp = rng.uniform(-np.pi, np.pi, _CANDIDATES // 2 - 1)
            turn = np.concatenate([rng.normal(0.0, 0.25, _CANDIDATES // 2),
                                   sharp[np.argsort(np.abs(sharp))], [np.pi]])
            cand = theta + turn
            dirs = np.column_stack([np.cos(cand), np.sin(cand), np.zeros_like(cand)])
            ok = world.segments_free(path[-1], dirs, step)
            ok[ok] = _valid_poses(world, path[-1] + step * dirs[ok], clearance)
            if not ok.any():
                break
            k = int(np.argmax(ok))
            theta = cand[k]
            path.append(path[-1] + step * dirs[k])
        if len(path) == n_poses:
            return np.array(path)
    raise ValueError(
        f"no collision-free path of n_poses={n_poses} with step={step} and clearance="
        f"{clearance} found at height={height:g} from {len(starts)} free start(s); "
        "try another height, a shorter step or less clearance"
    )


def _as_world(environment):
    if isinstance(environment, OccupancyOctree):
        return _OctreeWorld(environment)
    if callable(getattr(environment, "ray_cast", None)):
        return _SceneWorld(environment)
    raise TypeError("environment must be an OccupancyOctree or have a ray_cast(origins, "
                    f"directions, max_range) method, got {type(environment).__name__}")


class _OctreeWorld:
    what = "cell"

    def __init__(self, tree: OccupancyOctree):
        self.tree, self.res = tree, tree.resolution
        self._cells = self._kdtree = None

    def occupied(self, points):
        return self.tree.is_occupied(points)

    def known_free(self, points):
        occupied, unknown = self.tree.is_occupied(points, return_unknown=True)
        return ~occupied & ~unknown

    def returns(self, origin, dirs, max_range):
        """Entry points of the rays into the first occupied voxel, and the hit mask."""
        ends, hit = self.tree.cast_rays(origin, dirs, max_range=max_range, ignore_unknown=True)
        points = np.zeros_like(dirs)
        # the traversal ran on the float32 ray: intersect that ray with the hit voxel (slabs)
        o = origin.astype(np.float32).astype(np.float64)
        o = o[hit] if o.ndim == 2 else o
        d = dirs[hit].astype(np.float32).astype(np.float64)
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        lo = np.floor(ends[hit] / self.res) * self.res
        hi = lo + self.res
        with np.errstate(divide="ignore", invalid="ignore"):
            t1, t2 = (lo - o) / d, (hi - o) / d
        t_entry = np.maximum(np.where(d != 0, np.minimum(t1, t2), -np.inf).max(axis=1), 0.0)
        # rounding may leave the entry point a hair outside: clip it a few float32
        # steps (at least 1e-6 resolution) inside the voxel, so that it lies in it
        big = np.maximum(np.abs(lo), np.abs(hi)).astype(np.float32)
        margin = np.maximum(1e-6 * self.res, 8 * np.spacing(big).astype(np.float64))
        points[hit] = np.clip(o + t_entry[:, None] * d, lo + margin, hi - margin)
        hit[hit] = t_entry <= max_range
        return points, hit

    def free_distance(self, origins, dirs, length):
        ends, _ = self.tree.cast_rays(origins, dirs, max_range=length, ignore_unknown=False)
        return np.minimum(np.linalg.norm(ends - origins, axis=1), length)

    def segments_free(self, origin, dirs, length):
        ends, hit = self.tree.cast_rays(origin, dirs, max_range=length, ignore_unknown=False)
        # a cast stopped by an unknown cell ends there; one that ran its course ends beyond
        ok = ~hit & (np.linalg.norm(ends - origin, axis=1) > length)
        s = np.arange(1, int(np.ceil(2 * length / self.res)) + 1) / np.ceil(2 * length / self.res)
        samples = origin + length * s[None, :, None] * dirs[:, None, :]
        return ok & self.known_free(samples.reshape(-1, 3)).reshape(len(dirs), -1).all(axis=1)

    def _occupied_cells(self):
        """Centers of the occupied cells at the finest resolution (cached, with a k-d tree)."""
        if self._cells is None:
            centers, sizes, _ = self.tree.leaves(occupied_only=True)
            self._cells = _finest_cells(centers, sizes, self.res)
            self._kdtree = cKDTree(self._cells) if len(self._cells) else None
        return self._cells

    def clear(self, points, clearance):
        """Whether each point is `clearance` from every occupied cell (exact, cautious)."""
        cells = self._occupied_cells()
        if len(cells) == 0 or clearance == 0:
            return np.ones(len(points), dtype=bool)
        # a cell within `clearance` has its center within `reach`; check the k nearest
        half, k = self.res / 2, min(_NEIGHBOURS, len(cells))
        reach = clearance + np.sqrt(3) * half
        dist, idx = self._kdtree.query(points, k=k, distance_upper_bound=reach)
        dist, idx = dist.reshape(len(points), k), idx.reshape(len(points), k)
        found = np.isfinite(dist)
        gap = np.abs(points[:, None] - cells[np.where(found, idx, 0)]) - half
        near = (found & (np.linalg.norm(np.maximum(gap, 0), axis=2) < clearance)).any(axis=1)
        # more than k cells within reach: the nearest may be among the others
        unsure = found[:, -1] & (dist[:, -1] - np.sqrt(3) * half < clearance)
        return ~near & ~unsure

    def default_height(self):
        """1 m above the top of the densest occupied layer in the lower half (a cell center)."""
        layer = np.floor(self._occupied_cells()[:, 2] / self.res).astype(np.int64)
        if len(layer) == 0:
            raise ValueError("environment has no occupied cells: give height explicitly")
        counts = np.bincount(layer - layer.min())
        floor_top = (layer.min() + np.argmax(counts[: max(1, len(counts) // 2)]) + 1) * self.res
        return (np.floor((floor_top + 1.0) / self.res) + 0.5) * self.res

    def start_candidates(self, height, rng):
        lo, hi = self.tree.bounds
        if not np.isfinite(lo).all():
            return np.empty((0, 3))
        box = np.array([[lo[0], lo[1], height], [hi[0], hi[1], height]])
        centers = self.tree.leaves(bbox=box).centers
        centers[:, 2] = height
        return rng.permutation(centers[self.known_free(centers)])


class _SceneWorld:
    what = "solid"

    def __init__(self, scene):
        self.scene = scene

    def occupied(self, points):
        return np.asarray(self.scene.occupancy(points), dtype=bool)

    def returns(self, origin, dirs, max_range):
        dist, hit = self.scene.ray_cast(origin, dirs, max_range)
        return origin + dist[:, None] * dirs, hit

    def known_free(self, points):
        lo, hi = self.scene.interior_bounds
        inside = ((points > lo) & (points < hi)).all(axis=1)
        return inside & ~self.occupied(points)

    def free_distance(self, origins, dirs, length):
        return self.scene.ray_cast(origins, dirs, length)[0]

    def segments_free(self, origin, dirs, length):
        _, hit = self.scene.ray_cast(origin, dirs, length)
        return ~hit & self.known_free(origin + length * dirs)

    def clear(self, points, clearance):
        return self.scene.signed_distance(points) >= clearance

    def default_height(self):
        return float(self.scene.interior_bounds[0][2]) + 1.0

    def start_candidates(self, height, rng):
        lo, hi = self.scene.interior_bounds
        xy = rng.uniform(lo[:2], hi[:2], (4 * _MAX_STARTS, 2))
        points = np.column_stack([xy, np.full(len(xy), height)])
        return points[self.known_free(points)]


def _valid_poses(world, points, clearance):
    ok = world.known_free(points)
    ok[ok] = world.clear(points[ok], clearance)
    return ok


def _finest_cells(centers, sizes, res):
    """Centers of the finest cells that make up the given leaves."""
    out = [np.empty((0, 3))]
    for size in np.unique(sizes):
        g = (np.arange(round(size / res)) - (round(size / res) - 1) / 2) * res
        offsets = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
        out.append((centers[sizes == size][:, None] + offsets).reshape(-1, 3))
    return np.concatenate(out)
