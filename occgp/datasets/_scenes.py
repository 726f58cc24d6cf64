"""Synthetic 3D rooms with exact ground truth and an la3dm-like range sensor.

Two rooms of 10 x 7 x 2 m (x in [-5, 5], y in [-3.5, 3.5], z in [0, 2]) with a
floor, four walls and no ceiling: :func:`structured_room` furnishes it with
axis-aligned boxes and vertical cylinders, :func:`unstructured_room` with
slanted boxes, spheres, ellipsoids and cones. Membership, signed distance and
ray casting are exact (analytic), so occupancy metrics computed against a
:class:`Scene` are exact too.

The simulated sensor mimics the la3dm "sim_structured" scans of the
BGKOctoMap / AKIMap papers (measured from their PCD files): 4 poses at 0.1 m
above the floor, 3 scans per pose whose headings are 120 degrees apart, each
scan a sector 117 degrees wide and from 0 to 42 degrees in elevation (the
sensor looks level and up; it never sees the floor), 3500 returns per scan.
The la3dm room is 7 x 10 m with the sensor at (1, 1), (4, 2), (5, 5), (3, 8)
and headings 0, 120, 240 degrees; here the room is turned by -90 degrees
(x along the 10 m side), which puts the poses at (-4, 2.5), (-3, -0.5),
(0, -1.5), (3, 0.5) with headings -90, 30, 150 degrees.
"""

import copy
import numbers

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._docfill import fill_doc
from .._validation import as_numeric, as_point, as_points, check_int
from ._geometry import Box, Ellipsoid, Frustum, rotation_matrix
from ..io._scan import Scan

__all__ = ["Scene", "structured_room", "unstructured_room", "make_scene"]

ROOM_HALF = np.array([5.0, 3.5])
ROOM_HEIGHT = 2.0
WALL_THICKNESS = 0.15
SENSOR_HEIGHT = 0.1
DEFAULT_POSITIONS = np.array(
    [[-4.0, 2.5, SENSOR_HEIGHT], [-3.0, -0.5, SENSOR_HEIGHT], [0.0, -1.5, SENSOR_HEIGHT],
     [3.0, 0.5, SENSOR_HEIGHT]]
)
DEFAULT_HEADING = -np.pi / 2
HORIZONTAL_FOV = np.radians(117.0)
ELEVATION_RANGE = (0.0, np.radians(42.0))
_CLEARANCE = 0.3  # minimum distance from a sensor position to any object
MAX_POSES = 10_000  # most sensor poses Scene.poses places


def as_rays(origins, directions, dim=3):
    """Validate rays: returns (origins (n, dim), unit directions (n, dim))."""
    directions = as_points(directions, "directions", dim)
    origins = as_numeric(origins, "origins")
    if origins.shape == (dim,):
        origins = np.broadcast_to(as_point(origins, "origins", dim), directions.shape)
    elif origins.shape == directions.shape:
        origins = as_points(origins, "origins", dim)
    else:
        raise ValueError(
            f"origins must have shape ({dim},) or the shape of directions "
            f"{directions.shape}, got {origins.shape}"
        )
    # scaled first, so that neither 1e300 nor 1e-300 over- or underflows
    scale = np.abs(directions).max(axis=1, keepdims=True) if len(directions) else 1.0
    if np.any(scale == 0):
        raise ValueError("directions must be non-zero vectors")
    unit = directions / scale
    return origins, unit / np.linalg.norm(unit, axis=1, keepdims=True)


def check_max_range(max_range):
    if isinstance(max_range, (bool, np.bool_)) or not isinstance(
            max_range, (numbers.Real, np.floating, np.integer)):
        raise TypeError(f"max_range must be a real number, got {type(max_range).__name__}")
    max_range = float(max_range)
    if not max_range > 0:
        raise ValueError(f"max_range must be positive (inf: no limit), got {max_range}")
    return max_range


def first_hits(solids, origins, directions, max_range, dim=3):
    """``ray_cast`` of a scene of `solids`: checks the rays, returns ``(distances, hit)``."""
    origins, directions = as_rays(origins, directions, dim)
    max_range = check_max_range(max_range)
    t = np.full(len(directions), np.inf)
    for solid in solids:
        np.minimum(t, solid.intersect(origins, directions), out=t)
    hit = (t <= max_range) & np.isfinite(t)
    return np.where(hit, t, max_range), hit


def scene_doc_sections(dim):
    """The docstring sections that the scenes' queries share, for scenes of `dim` dimensions.

    Fragments for :func:`occgp._docfill.fill_doc`: ``points_param`` (the Parameters
    section of ``occupancy`` and ``signed_distance``), ``points_raises`` (the errors of
    ``occupancy``), ``as_occupancy`` (the Raises section of ``signed_distance``) and
    ``ray_cast_sections`` (Parameters, Returns and Raises of ``ray_cast``).
    """
    return {
        "points_param": f"""Parameters
----------
points : array-like of shape (n_points, {dim})
    Query points in the world frame, in metres.""",
        "points_raises": f"""TypeError
    If `points` does not hold real numbers.
ValueError
    If `points` is not of shape (n_points, {dim}) or holds NaN or inf.""",
        "as_occupancy": """Raises
------
TypeError, ValueError
    As :meth:`occupancy`.""",
        "ray_cast_sections": f"""Parameters
----------
origins : array-like of shape ({dim},) or (n_rays, {dim})
    Ray origins; one origin is shared by all rays.
directions : array-like of shape (n_rays, {dim})
    Ray directions (normalised internally; must be non-zero).
max_range : float, default=inf
    Positive; rays that hit nothing closer are misses.

Returns
-------
distances : ndarray of shape (n_rays,)
    Distance to the first hit along the unit direction, `max_range`
    for misses. A ray starting inside a solid hits at 0.
hit : ndarray of shape (n_rays,), dtype bool

Raises
------
TypeError
    If `origins` or `directions` does not hold real numbers, or
    `max_range` is not a real number.
ValueError
    If `directions` is not of shape (n_rays, {dim}), `origins` neither of
    shape ({dim},) nor that of `directions`, either holds NaN or inf, a
    direction is zero, or `max_range` is not positive.""",
    }


#: The Returns and Raises sections of the room builders that take a `seed` alone.
SEED_SECTIONS = """Returns
-------
scene : {scene}

Raises
------
TypeError
    If `seed` is not an int.
ValueError
    If `seed` is negative."""
_ROOM_SECTIONS = SEED_SECTIONS.format(scene="Scene")


class Scene:
    """A room made of solid primitives, with exact occupancy and ray casting.

    Build one with :func:`structured_room`, :func:`unstructured_room` or
    :func:`make_scene`.

    Parameters
    ----------
    solids : list of primitives
        Convex solids (``Box``, ``Ellipsoid``, ``Frustum`` from
        ``occgp.datasets._geometry``); the scene is their union.
    labels : list of str
        One name per solid (``"floor"``, ``"wall_-x"``, ``"table_top"``, ...).
    interior_bounds : tuple of two array-like of shape (3,)
        The free interior box of the room (without the walls and floor).
    name : str
        Scene name.
    sensor_positions : array-like of shape (n, 3)
        Default sensor positions, see :meth:`poses`.
    base_heading : float
        Heading (radians, about +z, from +x) of the first scan at each pose.
    wall_thickness : float, default=0.15
        Thickness of the floor and wall slabs around the interior.

    Attributes
    ----------
    solids, labels, name, wall_thickness : as given
    sensor_positions : ndarray of shape (n, 3)
    base_heading : float

    Examples
    --------
    >>> scene = structured_room()
    >>> scene.occupancy(np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -0.05]])).tolist()
    [False, True]
    """

    def __init__(self, solids, labels, interior_bounds, name, sensor_positions, base_heading,
                 wall_thickness=WALL_THICKNESS):
        self.solids = list(solids)
        self.labels = list(labels)
        self._interior = tuple(np.asarray(b, dtype=np.float64) for b in interior_bounds)
        self.name = name
        self.sensor_positions = np.asarray(sensor_positions, dtype=np.float64)
        self.base_heading = float(base_heading)
        self.wall_thickness = float(wall_thickness)

    def __repr__(self):
        return f"Scene(name={self.name!r}, n_solids={len(self.solids)})"

    @property
    def bounds(self):
        """``(min (3,), max (3,))`` of the room including walls and floor.

        Every solid lies inside these bounds (objects touch, never cross,
        the outer faces of the walls and floor).
        """
        lo, hi = self._interior
        t = self.wall_thickness
        return lo - t, hi + np.array([t, t, 0.0])

    @property
    def interior_bounds(self):
        """``(min (3,), max (3,))`` of the free interior box of the room."""
        return self._interior[0].copy(), self._interior[1].copy()

    @fill_doc(**scene_doc_sections(3))
    def occupancy(self, points: ArrayLike) -> NDArray[np.bool_]:
        """Exact membership of `points` in the union of the solids.

        {points_param}

        Returns
        -------
        occupied : ndarray of shape (n_points,), dtype bool
            True inside or on the surface of a solid (floor, walls, objects).

        Raises
        ------
        {points_raises}

        Examples
        --------
        >>> structured_room().occupancy([[5.05, 0.0, 1.0]]).tolist()   # in a wall
        [True]
        """
        points = as_points(points, "points")
        out = np.zeros(len(points), dtype=bool)
        for solid in self.solids:
            out |= solid.contains(points)
        return out

    @fill_doc(**scene_doc_sections(3))
    def signed_distance(self, points: ArrayLike) -> NDArray[np.float64]:
        """Signed Euclidean distance to the scene's surface (negative inside).

        Exact outside the solids; inside, where solids overlap, the magnitude
        is the depth inside the deepest single solid (a lower bound). The
        sign always agrees with :meth:`occupancy`.

        {points_param}

        Returns
        -------
        distance : ndarray of shape (n_points,)
            In metres.

        {as_occupancy}

        Examples
        --------
        >>> d = structured_room().signed_distance([[0.0, 0.0, 1.0]])
        >>> bool(d[0] > 0)
        True
        """
        points = as_points(points, "points")
        return np.min([s.signed_distance(points) for s in self.solids], axis=0)

    @fill_doc(**scene_doc_sections(3))
    def ray_cast(self, origins: ArrayLike, directions: ArrayLike, max_range: float = np.inf):
        """Exact first intersection of rays with the solids.

        {ray_cast_sections}

        Examples
        --------
        >>> d, hit = structured_room().ray_cast([0.0, 0.0, 1.0], [[0.0, 0.0, -1.0]])
        >>> float(d[0]), bool(hit[0])
        (1.0, True)
        """
        return first_hits(self.solids, origins, directions, max_range)

    def moved(self, label: str, offset: ArrayLike) -> "Scene":
        """The scene with one object moved (for dynamic-scene experiments).

        Parameters
        ----------
        label : str
            The object's label (:attr:`labels`); an object made of several
            solids (``"table"``: ``"table_0"``, ``"table_1"``, ...) moves whole.
        offset : array-like of shape (3,)
            Translation in metres, finite.

        Returns
        -------
        scene : Scene
            A new scene; this one is unchanged. Nothing checks that the
            object stays clear of the others or of the sensor poses.

        Raises
        ------
        TypeError
            If `label` is not a str, or `offset` does not hold numbers.
        ValueError
            If no object has `label`, or `offset` is not three finite numbers.

        Examples
        --------
        >>> room = structured_room()
        >>> moved = room.moved("crate", [-1.0, 0.0, 0.0])
        >>> point = [[1.3, -1.1, 0.25]]         # 1 m left of the crate's center
        >>> room.occupancy(point).tolist(), moved.occupancy(point).tolist()
        ([False], [True])
        """
        shift = as_point(offset, "offset")
        if not isinstance(label, str):
            raise TypeError(f"label must be a str, got {type(label).__name__}")
        parts = [i for i, name in enumerate(self.labels) if name == label
                 or (name.startswith(f"{label}_") and name[len(label) + 1:].isdigit())]
        if not parts:
            raise ValueError(f"label must name an object of the scene ({', '.join(self.labels)}), "
                             f"got {label!r}")
        solids = list(self.solids)
        for i in parts:
            solids[i] = copy.copy(solids[i])
            solids[i].center = solids[i].center + shift
        return Scene(solids, self.labels, self._interior, self.name, self.sensor_positions,
                     self.base_heading, self.wall_thickness)

    def poses(self, n_poses: int = 4, scans_per_pose: int = 3, seed: int = 0):
        """Sensor positions and scan headings.

        The first (up to 4) poses are the fixed la3dm-like positions in
        :attr:`sensor_positions`; further poses are drawn (seeded) uniformly
        in the interior, at the same height, at least 0.3 m from any object.

        Parameters
        ----------
        n_poses : int, default=4
            At most ``MAX_POSES`` (10,000).
        scans_per_pose : int, default=3
            Scans at one pose turn by ``2 pi / scans_per_pose``, starting from
            :attr:`base_heading` (random for the extra poses).
        seed : int, default=0

        Returns
        -------
        origins : ndarray of shape (n_poses, 3)
        headings : ndarray of shape (n_poses, scans_per_pose)
            Radians about +z, measured from +x, in [-pi, pi).

        Raises
        ------
        TypeError
            If `n_poses`, `scans_per_pose` or `seed` is not an int.
        ValueError
            If `n_poses` or `scans_per_pose` is below 1, `n_poses` above
            ``MAX_POSES``, or `seed` negative; or if the extra poses cannot all
            be placed clear of the objects (1000 rounds of 256 candidates).

        Examples
        --------
        >>> origins, headings = structured_room().poses()
        >>> origins.shape, np.degrees(headings[0]).round().tolist()
        ((4, 3), [-90.0, 30.0, 150.0])
        """
        n_poses = check_int(n_poses, "n_poses", low=1, high=MAX_POSES)
        scans_per_pose = check_int(scans_per_pose, "scans_per_pose", low=1)
        seed = check_int(seed, "seed", low=0)
        n_fixed = min(n_poses, len(self.sensor_positions))
        origins = [self.sensor_positions[:n_fixed]]
        base = np.full(n_fixed, self.base_heading)
        bases = [base]
        n_extra = n_poses - n_fixed
        if n_extra:
            rng = np.random.default_rng([seed, 7919])
            lo, hi = self.interior_bounds
            objects = [s for s, label in zip(self.solids, self.labels)
                       if label != "floor" and not label.startswith("wall")]
            found = np.empty((0, 3))
            for _ in range(1000):
                cand = np.column_stack([
                    rng.uniform(lo[0] + 0.5, hi[0] - 0.5, 256),
                    rng.uniform(lo[1] + 0.5, hi[1] - 0.5, 256),
                    np.full(256, self.sensor_positions[0, 2]),
                ])
                clear = np.min([s.signed_distance(cand) for s in objects], axis=0) >= _CLEARANCE
                found = np.vstack([found, cand[clear]])
                if len(found) >= n_extra:
                    break
            else:  # pragma: no cover - the rooms have room for MAX_POSES poses
                raise ValueError(f"n_poses: could not place {n_extra} extra sensor poses "
                                 f"{_CLEARANCE} m clear of the objects, found "
                                 f"{len(found)}; use fewer poses")
            origins.append(found[:n_extra])
            bases.append(rng.uniform(-np.pi, np.pi, n_extra))
        steps = 2 * np.pi * np.arange(scans_per_pose) / scans_per_pose
        headings = np.concatenate(bases)[:, None] + steps
        headings = (headings + np.pi) % (2 * np.pi) - np.pi
        return np.vstack(origins), headings

    def scan(
        self,
        n_poses: int = 4,
        scans_per_pose: int = 3,
        n_points: int = 3500,
        noise: float = 0.0,
        max_range: float = 8.0,
        seed: int = 0,
        *,
        horizontal_fov: float = HORIZONTAL_FOV,
        elevation_range: tuple = ELEVATION_RANGE,
    ) -> list:
        """Simulate la3dm-like range scans of the scene.

        Each scan casts rays from a pose, with directions drawn uniformly in
        azimuth (``heading +- horizontal_fov / 2``) and elevation
        (`elevation_range`), and keeps the first `n_points` rays that hit a
        solid within `max_range` (rays that leave the room through the open
        top, or hit beyond `max_range`, are dropped and replaced by others).

        Parameters
        ----------
        n_poses : int, default=4
            Number of sensor poses (see :meth:`poses`).
        scans_per_pose : int, default=3
            Scans per pose, with headings 360/scans_per_pose degrees apart.
        n_points : int, default=3500
            Returns per scan.
        noise : float, default=0.0
            Standard deviation (metres) of Gaussian range noise, added along
            each ray.
        max_range : float, default=8.0
            Maximum range of a return, in metres.
        seed : int, default=0
            Seed of the ray directions and noise; the result is deterministic
            for a given seed. Scan ``k`` of pose ``i`` draws from
            ``np.random.default_rng([seed, i, k])``.
        horizontal_fov : float, default=radians(117)
            Width of a scan's sector, radians.
        elevation_range : tuple of float, default=(0, radians(42))
            Lowest and highest elevation of a ray, radians.

        Returns
        -------
        scans : list of Scan
            ``n_poses * scans_per_pose`` scans, pose-major; each has points of
            shape (n_points, 3).

        Raises
        ------
        ValueError
            For a non-positive count, negative noise, non-positive range or
            field of view, or when no ray of a scan can hit within `max_range`.

        Examples
        --------
        >>> scans = structured_room().scan(n_poses=1, scans_per_pose=2, n_points=100)
        >>> len(scans), scans[0].points.shape, scans[0].origin.tolist()
        (2, (100, 3), [-4.0, 2.5, 0.1])
        """
        n_points = check_int(n_points, "n_points", low=1)
        noise = float(noise)
        if not noise >= 0:
            raise ValueError(f"noise must be non-negative, got {noise}")
        max_range = check_max_range(max_range)
        horizontal_fov = float(horizontal_fov)
        if not 0 < horizontal_fov <= 2 * np.pi:
            raise ValueError(f"horizontal_fov must be in (0, 2 pi], got {horizontal_fov}")
        el_lo, el_hi = (float(v) for v in elevation_range)
        if not -np.pi / 2 <= el_lo <= el_hi <= np.pi / 2:
            raise ValueError(
                f"elevation_range must satisfy -pi/2 <= low <= high <= pi/2, got {elevation_range}"
            )
        origins, headings = self.poses(n_poses, scans_per_pose, seed)
        scans = []
        for i, origin in enumerate(origins):
            for k, heading in enumerate(headings[i]):
                rng = np.random.default_rng([seed, i, k])
                points = self._sample_returns(
                    rng, origin, heading, n_points, noise, max_range,
                    horizontal_fov, (el_lo, el_hi),
                )
                scans.append(Scan(points, origin.copy()))
        return scans

    def _sample_returns(self, rng, origin, heading, n_points, noise, max_range, hfov, elev):
        chunks, n_found, n_cast = [], 0, 0
        batch = int(1.3 * n_points) + 64
        # give up when fewer than 1 ray in 100 hits (after at least 3 batches)
        while len(chunks) < 3 or n_found * 100 >= n_cast:
            az = heading + rng.uniform(-hfov / 2, hfov / 2, batch)
            el = rng.uniform(elev[0], elev[1], batch)
            dirs = np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
            dist, hit = self.ray_cast(origin, dirs, max_range)
            if noise > 0:
                dist = dist + rng.normal(0.0, noise, batch)
            chunks.append(origin + dist[hit, None] * dirs[hit])
            n_found += int(hit.sum())
            n_cast += batch
            if n_found >= n_points:
                return np.vstack(chunks)[:n_points]
            rate = max(n_found, 1) / n_cast
            batch = int(min(1.3 * (n_points - n_found) / rate + 64, 10 * n_points + 64))
        raise ValueError(
            f"too few rays from {origin.tolist()} (heading {heading:.3f} rad) hit within "
            f"max_range={max_range}: found {n_found} of n_points={n_points}"
        )


# --------------------------------------------------------------------------- #
# room construction
# --------------------------------------------------------------------------- #
def _shell():
    """Floor and four walls, slabs outside the interior box."""
    hx, hy = ROOM_HALF
    t, h = WALL_THICKNESS, ROOM_HEIGHT
    zc, zh = (h - t) / 2, (h + t) / 2
    solids = [
        Box([0, 0, -t / 2], [hx + t, hy + t, t / 2]),
        Box([-hx - t / 2, 0, zc], [t / 2, hy + t, zh]),
        Box([hx + t / 2, 0, zc], [t / 2, hy + t, zh]),
        Box([0, -hy - t / 2, zc], [hx + t, t / 2, zh]),
        Box([0, hy + t / 2, zc], [hx + t, t / 2, zh]),
    ]
    labels = ["floor", "wall_-x", "wall_+x", "wall_-y", "wall_+y"]
    return solids, labels


def _structured_objects():
    """(label, builder(dx, dy, dyaw) -> list of solids) of the structured room."""

    def table(dx, dy, _):
        cx, cy = -1.5 + dx, 1.8 + dy
        legs = [Box([cx + sx * 0.72, cy + sy * 0.38, 0.355], [0.04, 0.04, 0.355])
                for sx in (-1, 1) for sy in (-1, 1)]
        return [Box([cx, cy, 0.74], [0.8, 0.45, 0.03])] + legs

    def round_table(dx, dy, _):
        cx, cy = 3.2 + dx, 2.3 + dy
        return [Frustum([cx, cy, 0.7], 0.5, 0.5, 0.04), Frustum([cx, cy, 0.0], 0.06, 0.06, 0.7)]

    return [
        ("table", table),
        ("shelf", lambda dx, dy, _: [Box([4.55 + dx / 4, -2.6 + dy, 0.9], [0.35, 0.6, 0.9])]),
        ("cabinet", lambda dx, dy, _: [Box([-4.45 + dx / 4, -2.75 + dy / 4, 0.5],
                                           [0.45, 0.65, 0.5])]),
        ("pillar_1", lambda dx, dy, _: [Frustum([1.5 + dx, -2.0 + dy, 0.0], 0.25, 0.25, 2.0)]),
        ("pillar_2", lambda dx, dy, _: [Frustum([-2.0 + dx, -2.6 + dy, 0.0], 0.2, 0.2, 2.0)]),
        ("partition", lambda dx, dy, _: [Box([1.075 + dx, 2.5, 1.0], [0.075, 1.0, 1.0])]),
        ("round_table", round_table),
        ("crate", lambda dx, dy, _: [Box([2.3 + dx, -1.1 + dy, 0.25], [0.3, 0.3, 0.25])]),
        ("bench", lambda dx, dy, _: [Box([-2.0 + dx, 0.9 + dy, 0.22], [0.6, 0.2, 0.22])]),
    ]


def _unstructured_objects():
    """(label, builder(dx, dy, dyaw) -> list of solids) of the unstructured room."""
    R = rotation_matrix
    return [
        ("plank", lambda dx, dy, a: [Box([-1.5 + dx, 3.1, 0.85], [0.9, 0.03, 0.9],
                                         R(roll=-0.35))]),
        ("tilted_box", lambda dx, dy, a: [Box([2.0 + dx, -2.2 + dy, 0.45], [0.4, 0.3, 0.35],
                                              R(yaw=0.5 + a, pitch=0.25, roll=0.2))]),
        ("sphere", lambda dx, dy, a: [Ellipsoid([-1.8 + dx, -1.9 + dy, 0.5], [0.5, 0.5, 0.5])]),
        ("ellipsoid", lambda dx, dy, a: [Ellipsoid([1.5 + dx, 2.2 + dy, 0.6], [0.7, 0.4, 0.6],
                                                   R(yaw=0.7 + a, pitch=0.3))]),
        ("cone", lambda dx, dy, a: [Frustum([-4.2 + dx / 2, -2.6 + dy / 2, 0.0], 0.6, 0.0, 1.5)]),
        ("frustum", lambda dx, dy, a: [Frustum([3.9 + dx / 2, -2.5 + dy / 2, 0.0], 0.5, 0.2, 1.2,
                                               R(yaw=a, pitch=0.1))]),
        ("pole", lambda dx, dy, a: [Frustum([4.2 + dx / 2, 2.8 + dy / 2, -0.1], 0.12, 0.12, 2.0,
                                            R(yaw=2.4 + a, pitch=0.35))]),
        ("ramp", lambda dx, dy, a: [Box([0.2 + dx, 1.2 + dy, 0.3], [0.9, 0.5, 0.03],
                                        R(yaw=a, pitch=0.3))]),
        ("wall_sphere", lambda dx, dy, a: [Ellipsoid([4.7, 0.2 + dy, 1.0], [0.45, 0.45, 0.45])]),
        ("rock", lambda dx, dy, a: [Ellipsoid([-3.0 + dx, 1.6 + dy, 0.05], [0.5, 0.35, 0.2],
                                              R(yaw=0.3 + a))]),
    ]


def _build_room(name, objects, seed, jitter_xy, jitter_yaw):
    seed = check_int(seed, "seed", low=0)
    solids, labels = _shell()
    rng = np.random.default_rng(seed) if seed else None
    probe = DEFAULT_POSITIONS
    for label, build in objects:
        parts = build(0.0, 0.0, 0.0)
        if rng is not None:
            for _ in range(20):  # jittered placement keeping the sensor poses free
                dx, dy = rng.uniform(-jitter_xy, jitter_xy, 2)
                cand = build(dx, dy, rng.uniform(-jitter_yaw, jitter_yaw))
                if min(s.signed_distance(probe).min() for s in cand) >= _CLEARANCE:
                    parts = cand
                    break
        solids += parts
        labels += [label if len(parts) == 1 else f"{label}_{j}" for j in range(len(parts))]
    lo = np.array([-ROOM_HALF[0], -ROOM_HALF[1], 0.0])
    hi = np.array([ROOM_HALF[0], ROOM_HALF[1], ROOM_HEIGHT])
    return Scene(solids, labels, (lo, hi), name, DEFAULT_POSITIONS, DEFAULT_HEADING)


@fill_doc(seed_sections=_ROOM_SECTIONS)
def structured_room(seed: int = 0) -> Scene:
    """A 10 x 7 x 2 m room with axis-aligned furniture (boxes, cylinders).

    Floor and walls are 0.15 m slabs outside the interior ``[-5, 5] x
    [-3.5, 3.5] x [0, 2]``; there is no ceiling. Objects: a table on four
    legs, a shelf, a cabinet, two pillars, a partition wall, a round table,
    a crate and a bench.

    Parameters
    ----------
    seed : int, default=0
        0 gives the fixed default layout; any other seed moves each object
        (deterministically) by up to 0.3 m, keeping the sensor poses free.

    {seed_sections}

    Examples
    --------
    >>> scene = structured_room()
    >>> [b.tolist() for b in scene.interior_bounds]
    [[-5.0, -3.5, 0.0], [5.0, 3.5, 2.0]]
    >>> scene.occupancy([[-1.5, 1.8, 0.74]]).tolist()   # the table top
    [True]
    """
    return _build_room("structured", _structured_objects(), seed, 0.3, 0.0)


@fill_doc(seed_sections=_ROOM_SECTIONS)
def unstructured_room(seed: int = 0) -> Scene:
    """A 10 x 7 x 2 m room with irregular objects (slanted, curved, conical).

    Same shell as :func:`structured_room`; objects: a plank leaning on a
    wall, a tilted box, a sphere, a rotated ellipsoid, a cone, a tilted
    frustum, a leaning pole, a ramp, a sphere half in a wall and a half-buried
    rock (ellipsoid).

    Parameters
    ----------
    seed : int, default=0
        0 gives the fixed default layout; any other seed moves and turns
        each object (by up to 0.3 m and 20 degrees), keeping the poses free.

    {seed_sections}

    Examples
    --------
    >>> scene = unstructured_room()
    >>> scene.occupancy([[-1.8, -1.9, 0.5], [0.0, 0.0, 1.5]]).tolist()
    [True, False]
    """
    return _build_room("unstructured", _unstructured_objects(), seed, 0.3, np.radians(20))


def make_scene(name: str, seed: int = 0) -> Scene:
    """Build a synthetic 3D room by name: ``"structured"`` or ``"unstructured"``.

    Parameters
    ----------
    name : {"structured", "unstructured"}
        :func:`structured_room` or :func:`unstructured_room`.
    seed : int, default=0
        Non-negative; 0 gives the fixed default layout (see those functions).

    Returns
    -------
    scene : Scene

    Raises
    ------
    TypeError
        If `name` is not a str, or `seed` is not an int.
    ValueError
        If `name` is not one of the two, or `seed` is negative.

    Examples
    --------
    >>> make_scene("unstructured").name
    'unstructured'
    """
    factories = {"structured": structured_room, "unstructured": unstructured_room}
    if not isinstance(name, str):
        raise TypeError(f"name must be a str, got {type(name).__name__}")
    if name not in factories:
        raise ValueError(f"name must be one of {sorted(factories)}, got {name!r}")
    return factories[name](seed)
