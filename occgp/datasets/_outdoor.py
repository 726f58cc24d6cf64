"""Procedural outdoor scenes: streets with buildings, poles, trees, cars and walls.

:func:`outdoor_scene` builds a seeded square town block of ``size`` metres
(x, y in ``[-size/2, size/2]``) out of the analytic solids of
``occgp.datasets._geometry``, so that occupancy and ray casting are exact,
as in the rooms:

* the **ground**, a slab whose top is z = 0, reaching ``ground_margin``
  metres beyond the square (so that low beams hit ground, not sky), with
  sloped **hills**: tilted slabs half buried in the ground off the roads;
* a **main road** along x (8 m wide, centered on y = 0) and a **cross road**
  along y at a seeded x, both flat at z = 0, with **curbs** 0.15 m high;
* **buildings**: boxes of seeded footprint (6-20 m) and height (3-25 m)
  along both sides of the roads, a few turned slightly;
* **walls** (0.3 m thick, 1-2.5 m high) in the gaps between buildings;
* **poles** (street lamps: a thin cylinder, some with an arm) and **trees**
  (a cylindrical trunk and an ellipsoid crown) on the sidewalks;
* **cars** (a body and a cabin box) parked along the roads' edges and in
  the far lane of the main road;
* with ``vegetation=True``, vegetation-like clutter off the roads: each
  tree crown becomes a porous cluster of small ellipsoids, **hedges**
  (rows of overlapping ellipsoids) line the sidewalks' outer edges,
  **bushes** (clusters of 3 to 5 ellipsoids) and patches of **grass**
  tufts (thin cones) stand in the open ground. They draw from their own
  seeded stream, so the rest of the scene is the same as without them.

The sensor drives along the main road's right lane (y = -1.5, heading +x):
:meth:`OutdoorScene.trajectory` gives evenly spaced sensor-to-world poses
at a given height (1.73 m by default) for mapping experiments;
:meth:`OutdoorScene.random_poses` draws seeded poses anywhere on the roads
(clear of cars, poles and curbs) for training data.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .._docfill import fill_doc
from .._validation import check_bool, check_int, check_real
from ._geometry import Box, Ellipsoid, Frustum, rotation_matrix
from ._scenes import Scene

__all__ = ["OutdoorScene", "outdoor_scene"]

ROAD_HALF_WIDTH = 4.0
SIDEWALK = 3.0
LANE_Y = -1.5  # the trajectory's lane on the main road
#: KITTI's HDL-64E mounting height. Off the 0.1 m lattice on purpose: at a height of 1.7 m the
#: flat road would lie exactly on a face of the 0.1 m voxel grid of the sensor-frame scores
#: (occgp.iln.voxel_scores), where rounding alone decides each point's voxel.
SENSOR_HEIGHT = 1.73
MAX_SIZE = 400.0
MIN_SIZE = 30.0
_CLEARANCE = 0.5
#: The Returns section of the pose makers, and the first entry of their Raises section.
_POSES_RETURNS = """Returns
-------
poses : ndarray of shape (n_poses, 4, 4)
    Sensor-to-world transforms.

Raises
------
TypeError
    If an argument has a wrong type."""


class OutdoorScene(Scene):
    """A procedural street scene with exact occupancy and ray casting.

    Build one with :func:`outdoor_scene`. It is a :class:`Scene` (same
    :meth:`occupancy`, :meth:`signed_distance`, :meth:`ray_cast`, and
    :meth:`poses` / :meth:`scan` along the trajectory), with its own
    bounds and road layout.

    Attributes
    ----------
    solids, labels, name : as in :class:`Scene`
    size : float
        Side of the square, metres.
    seed : int
    cross_x : float
        x of the cross road's center line.
    ground_margin : float
        How far the ground slab reaches beyond the square, metres.
    vegetation : bool
        Whether the scene has vegetation clutter (see :func:`outdoor_scene`).
    """

    def __init__(self, solids, labels, size, seed, cross_x, ground_margin, top,
                 vegetation=False):
        half = size / 2
        super().__init__(solids, labels, ([-half, -half, 0.0], [half, half, top]),
                         f"outdoor-{seed}", np.array([[-half + 5.0, LANE_Y, SENSOR_HEIGHT]]),
                         0.0, wall_thickness=0.0)
        self.size = float(size)
        self.seed = int(seed)
        self.cross_x = float(cross_x)
        self.ground_margin = float(ground_margin)
        self.vegetation = bool(vegetation)

    def __repr__(self):
        return f"OutdoorScene(size={self.size}, seed={self.seed}, n_solids={len(self.solids)})"

    @property
    def bounds(self):
        """``(min (3,), max (3,))`` of the square, from 1 m below ground to the tallest solid.

        The ground slab reaches `ground_margin` beyond it in x and y.
        """
        lo, hi = self._interior
        return lo - np.array([0.0, 0.0, 1.0]), hi.copy()

    # ------------------------------------------------------------------ poses
    @fill_doc(poses_returns=_POSES_RETURNS)
    def trajectory(self, n_poses: int = 15, height: float = SENSOR_HEIGHT,
                   margin: float = 5.0) -> NDArray[np.float64]:
        """Evenly spaced sensor poses driving along the main road's right lane.

        The sensor moves along +x at ``y = -1.5``, from ``-size/2 + margin``
        to ``size/2 - margin``, at `height` above the (flat) road, heading
        +x, level.

        Parameters
        ----------
        n_poses : int, default=15
            1 to 10,000.
        height : float, default=1.73
            Sensor height above the road, metres, in (0.2, 50).
        margin : float, default=5.0
            Distance kept from the square's edges, metres, in [0, size / 2).

        {poses_returns}
        ValueError
            If an argument is out of its range.

        Examples
        --------
        >>> poses = outdoor_scene(0, size=40).trajectory(3)
        >>> poses[:, :3, 3].tolist()
        [[-15.0, -1.5, 1.73], [0.0, -1.5, 1.73], [15.0, -1.5, 1.73]]
        """
        n_poses = check_int(n_poses, "n_poses", low=1, high=10_000)
        height = check_real(height, "height", low=0.2, high=50.0)
        half = self.size / 2
        margin = check_real(margin, "margin", low=0.0, high=half, low_open=False)
        x = np.linspace(-half + margin, half - margin, n_poses) if n_poses > 1 else np.zeros(1)
        origins = np.column_stack([x, np.full(n_poses, LANE_Y), np.full(n_poses, height)])
        return _poses(origins, np.zeros(n_poses))

    @fill_doc(poses_returns=_POSES_RETURNS)
    def random_poses(self, n_poses: int, seed: int = 0, height: float = SENSOR_HEIGHT,
                     heading_jitter: float = 0.3) -> NDArray[np.float64]:
        """Seeded sensor poses on the roads, clear of every object by 0.5 m.

        Each pose lies on the main road or the cross road (chosen at
        random), at a random offset across it, at `height` above the road,
        heading along the road (either way) turned by up to `heading_jitter`
        radians, level.

        Parameters
        ----------
        n_poses : int
            1 to 10,000.
        seed : int, default=0
            Non-negative.
        height : float, default=1.73
            Metres above the road, in (0.2, 50).
        heading_jitter : float, default=0.3
            Largest turn from the road's direction, radians, in [0, pi].

        {poses_returns}
        ValueError
            If an argument is out of its range, or the poses cannot be
            placed (100 rounds of 256 candidates).

        Examples
        --------
        >>> poses = outdoor_scene(0, size=40).random_poses(4, seed=1)
        >>> poses.shape, poses[:, 2, 3].tolist()
        ((4, 4, 4), [1.73, 1.73, 1.73, 1.73])
        """
        n_poses = check_int(n_poses, "n_poses", low=1, high=10_000)
        seed = check_int(seed, "seed", low=0)
        height = check_real(height, "height", low=0.2, high=50.0)
        jitter = check_real(heading_jitter, "heading_jitter", low=0.0, high=np.pi,
                            low_open=False, high_open=False)
        rng = np.random.default_rng([seed, 4099])
        half = self.size / 2
        objects = [s for s, label in zip(self.solids, self.labels) if label != "ground"]
        # only solids whose box comes within the clearance of the roads can reject a pose
        reach = ROAD_HALF_WIDTH - 0.7
        strips = (([-half + 2.0, -reach, height], [half - 2.0, reach, height]),
                  ([self.cross_x - reach, -half + 2.0, height],
                   [self.cross_x + reach, half - 2.0, height]))
        objects = [s for s in objects if min(
            np.linalg.norm(np.maximum(np.maximum(np.asarray(lo) - s.aabb[1],
                                                 s.aabb[0] - np.asarray(hi)), 0.0))
            for lo, hi in strips) < _CLEARANCE + 1e-6]
        found, headings = [], []
        n_found = 0
        for _ in range(100):
            along = rng.uniform(-half + 2.0, half - 2.0, 256)
            across = rng.uniform(-ROAD_HALF_WIDTH + 0.7, ROAD_HALF_WIDTH - 0.7, 256)
            main = rng.random(256) < 0.6
            x = np.where(main, along, self.cross_x + across)
            y = np.where(main, across, along)
            heading = np.where(main, 0.0, np.pi / 2) + np.where(rng.random(256) < 0.5, 0, np.pi)
            heading = heading + rng.uniform(-jitter, jitter, 256)
            cand = np.column_stack([x, y, np.full(256, height)])
            clear = _free_of(objects, cand, _CLEARANCE)
            found.append(cand[clear])
            headings.append(heading[clear])
            n_found += int(clear.sum())
            if n_found >= n_poses:
                break
        else:  # pragma: no cover - the roads are wide open
            raise ValueError(f"n_poses: could only place {n_found} of {n_poses} poses on the roads")
        return _poses(np.vstack(found)[:n_poses], np.concatenate(headings)[:n_poses])

    def poses(self, n_poses: int = 4, scans_per_pose: int = 3, seed: int = 0):
        """Positions and headings along :meth:`trajectory` (the :class:`Scene` interface).

        Parameters
        ----------
        n_poses : int, default=4
        scans_per_pose : int, default=3
            Scans at one pose turn by ``2 pi / scans_per_pose`` from +x.
        seed : int, default=0
            Unused (the trajectory is fixed); checked for the interface.

        Returns
        -------
        origins : ndarray of shape (n_poses, 3)
        headings : ndarray of shape (n_poses, scans_per_pose)
            Radians, in [-pi, pi).

        Raises
        ------
        TypeError, ValueError
            For a bad count or seed.
        """
        scans_per_pose = check_int(scans_per_pose, "scans_per_pose", low=1)
        check_int(seed, "seed", low=0)
        origins = self.trajectory(n_poses)[:, :3, 3]
        steps = 2 * np.pi * np.arange(scans_per_pose) / scans_per_pose
        headings = (np.zeros((len(origins), 1)) + steps + np.pi) % (2 * np.pi) - np.pi
        return origins, headings


def _poses(origins, headings):
    poses = np.zeros((len(origins), 4, 4))
    c, s = np.cos(headings), np.sin(headings)
    poses[:, 0, 0], poses[:, 0, 1], poses[:, 1, 0], poses[:, 1, 1] = c, -s, s, c
    poses[:, 2, 2] = poses[:, 3, 3] = 1.0
    poses[:, :3, 3] = origins
    return poses


# --------------------------------------------------------------------------- #
# construction
# --------------------------------------------------------------------------- #
class _Builder:
    def __init__(self):
        self.solids, self.labels = [], []

    def add(self, label, solid):
        self.solids.append(solid)
        self.labels.append(label)


def _road_segments(lo, hi, cut, width):
    """[lo, hi] minus (cut - width, cut + width), as a list of (a, b)."""
    out = []
    if cut - width > lo:
        out.append((lo, min(cut - width, hi)))
    if cut + width < hi:
        out.append((max(cut + width, lo), hi))
    return [(a, b) for a, b in out if b - a > 0.5]


def _street_side(b, rng, axis, side, lo, hi, cross, half, tall):
    """Buildings, walls, poles, trees and cars along one side of a road.

    `axis` 0: a road along x (the main road), the side is the sign of y;
    axis 1: the cross road along y at x = `cross`, the side the sign of x - cross.
    """
    def place(a, across):  # (along, across) -> world x, y
        return (a, side * across) if axis == 0 else (cross + side * across, a)

    def yaw():
        return 0.0 if axis == 0 else np.pi / 2

    edge = ROAD_HALF_WIDTH + SIDEWALK
    other = ROAD_HALF_WIDTH + SIDEWALK  # keep clear of the other road
    segments = _road_segments(lo, hi, cross if axis == 0 else 0.0, other)
    for a0, a1 in segments:
        # curb along the road edge
        mid = (a0 + a1) / 2
        cx, cy = place(mid, ROAD_HALF_WIDTH + 0.1)
        b.add("curb", Box([cx, cy, 0.075], [(a1 - a0) / 2, 0.1, 0.075], rotation_matrix(yaw())))
        # buildings and walls, beyond the sidewalk
        a = a0 + rng.uniform(0.0, 3.0)
        while a < a1 - 3.0:
            width = min(rng.uniform(6.0, 20.0), a1 - a)
            if rng.random() < 0.8 and width >= 4.0:
                depth = rng.uniform(6.0, 20.0)
                setback = rng.uniform(0.0, 4.0)
                across = edge + setback + depth / 2
                if across + depth / 2 > half + 10.0:
                    depth = max(half + 10.0 - edge - setback, 3.0)
                    across = edge + setback + depth / 2
                height = rng.uniform(3.0, 25.0)
                turn = rng.uniform(-0.15, 0.15) if rng.random() < 0.25 else 0.0
                cx, cy = place(a + width / 2, across)
                b.add("building", Box([cx, cy, height / 2], [width / 2, depth / 2, height / 2],
                                      rotation_matrix(yaw() + turn)))
                tall[0] = max(tall[0], height)
            else:
                cx, cy = place(a + width / 2, edge + rng.uniform(0.3, 2.0))
                h = rng.uniform(1.0, 2.5)
                b.add("wall", Box([cx, cy, h / 2], [width / 2, 0.15, h / 2],
                                  rotation_matrix(yaw())))
            gap = rng.uniform(1.0, 6.0)
            if gap > 3.0 and rng.random() < 0.5 and a + width + gap < a1:
                cx, cy = place(a + width + gap / 2, edge + rng.uniform(0.3, 1.5))
                h = rng.uniform(1.0, 2.5)
                b.add("wall", Box([cx, cy, h / 2], [gap / 2 - 0.2, 0.15, h / 2],
                                  rotation_matrix(yaw())))
            a += width + gap
        # poles and trees on the sidewalk
        a = a0 + rng.uniform(1.0, 6.0)
        while a < a1 - 1.0:
            if rng.random() < 0.5:
                cx, cy = place(a, ROAD_HALF_WIDTH + 0.6)
                h = rng.uniform(5.0, 8.0)
                b.add("pole", Frustum([cx, cy, 0.0], 0.12, 0.1, h))
                if rng.random() < 0.6:
                    ax, ay = place(a, ROAD_HALF_WIDTH + 0.6 - 0.9)
                    b.add("pole_arm", Box([ax, ay, h - 0.1], [0.08, 0.9, 0.06],
                                          rotation_matrix(yaw())))
            else:
                cx, cy = place(a, ROAD_HALF_WIDTH + rng.uniform(1.5, SIDEWALK - 0.5))
                trunk = rng.uniform(2.0, 3.5)
                b.add("tree_trunk", Frustum([cx, cy, 0.0], rng.uniform(0.15, 0.25), 0.12, trunk))
                rx = rng.uniform(1.2, 2.5)
                rz = rng.uniform(1.5, 3.0)
                b.add("tree_crown", Ellipsoid([cx, cy, trunk + rz * 0.7],
                                              [rx, rx * rng.uniform(0.8, 1.2), rz]))
            a += rng.uniform(8.0, 18.0)
        # parked cars at the road edge
        a = a0 + rng.uniform(1.0, 8.0)
        while a < a1 - 3.0:
            if rng.random() < 0.5:
                _car(b, *place(a, ROAD_HALF_WIDTH - 1.1), yaw() + rng.uniform(-0.05, 0.05), rng)
            a += rng.uniform(6.0, 14.0)


def _car(b, x, y, heading, rng):
    length, width = rng.uniform(3.8, 4.8), rng.uniform(1.6, 1.9)
    body_h = rng.uniform(0.7, 1.0)
    rot = rotation_matrix(heading)
    b.add("car_body", Box([x, y, 0.2 + body_h / 2], [length / 2, width / 2, body_h / 2], rot))
    cabin_l = length * rng.uniform(0.45, 0.6)
    shift = rot @ [rng.uniform(-0.3, 0.1), 0.0, 0.0]
    b.add("car_cabin", Box([x + shift[0], y + shift[1], 0.2 + body_h + 0.3],
                           [cabin_l / 2, width / 2 - 0.1, 0.3], rot))


def _hills(b, rng, half, cross):
    """Tilted slabs half buried in the ground, in the corners away from the roads."""
    n = rng.integers(2, 5)
    placed = 0
    for _ in range(50):
        if placed == n:
            break
        x, y = rng.uniform(-half, half, 2)
        a, w = rng.uniform(6.0, 15.0), rng.uniform(5.0, 12.0)
        reach = np.hypot(a, w) + 1.0
        if abs(y) < ROAD_HALF_WIDTH + SIDEWALK + reach or \
                abs(x - cross) < ROAD_HALF_WIDTH + SIDEWALK + reach:
            continue
        pitch = np.radians(rng.uniform(4.0, 12.0))
        thick = 1.0
        top = a * np.sin(pitch)
        rise = rng.uniform(min(0.5, top), top)  # height of the top edge above ground
        # top face at local z = +thick; its high edge (local x = +a) at world z = rise
        zc = rise - a * np.sin(pitch) - thick * np.cos(pitch)
        rot = rotation_matrix(yaw=rng.uniform(-np.pi, np.pi), pitch=-pitch)
        b.add("hill", Box([x, y, zc], [a, w, thick], rot))
        placed += 1


def _free_of(solids, centers, margin):
    """Whether each of `centers` (n, 3) lies at least `margin` outside every solid."""
    if not len(solids) or not len(centers):
        return np.ones(len(centers), dtype=bool)
    return np.min([s.signed_distance(centers) for s in solids], axis=0) >= margin


def _off_roads(xy, cross, reach):
    """Whether points (n, 2) lie farther than `reach` from both roads' center lines."""
    return (np.abs(xy[:, 1]) > reach) & (np.abs(xy[:, 0] - cross) > reach)


def _porous_crowns(b, rng):
    """Replace each tree crown by a cluster of 5 to 8 small ellipsoids inside its volume."""
    solids, labels = [], []
    for solid, label in zip(b.solids, b.labels):
        if label != "tree_crown":
            solids.append(solid)
            labels.append(label)
            continue
        radii = solid.radii
        n = int(rng.integers(5, 9))
        unit = rng.normal(size=(n, 3))
        unit *= (rng.random((n, 1)) ** (1 / 3)) / np.linalg.norm(unit, axis=1, keepdims=True)
        for offset, scale in zip(unit * radii * 0.6, rng.uniform(0.35, 0.55, (n, 3))):
            solids.append(Ellipsoid(solid.center + offset, radii * scale))
            labels.append("tree_crown")
    b.solids, b.labels = solids, labels


def _hedges(b, rng, half, cross, objects):
    """Hedges along the sidewalks' outer edges: rows of overlapping ellipsoids."""
    edge = ROAD_HALF_WIDTH + SIDEWALK
    for axis in (0, 1):
        for side in (-1, 1):
            for a0, a1 in _road_segments(-half, half, cross if axis == 0 else 0.0, edge):
                a = a0 + rng.uniform(0.0, 8.0)
                while a < a1 - 2.0:
                    length = min(rng.uniform(2.0, 7.0), a1 - a)
                    across = edge + rng.uniform(-0.4, 0.8)
                    n = max(int(length / 1.0), 2)
                    along = a + (np.arange(n) + 0.5) * length / n
                    rx, ry = rng.uniform(0.6, 0.9, n), rng.uniform(0.35, 0.55, n)
                    rz = rng.uniform(0.5, 0.9, n)
                    across_k = side * (across + rng.uniform(-0.1, 0.1, n))
                    xy = np.column_stack([along, across_k]) if axis == 0 else \
                        np.column_stack([cross + across_k, along])
                    centers = np.column_stack([xy, rz * 0.6])
                    if _free_of(objects, centers, 0.3).all():
                        for c, r in zip(centers, np.column_stack([rx, ry, rz])):
                            b.add("hedge", Ellipsoid(c, r, rotation_matrix(
                                0.0 if axis == 0 else np.pi / 2)))
                    a += length + rng.uniform(2.0, 10.0)


def _bushes_and_grass(b, rng, half, cross, objects):
    """Bushes (clusters of 3 to 5 ellipsoids) and grass tufts (thin cones, in patches)
    in the open ground off the roads and sidewalks."""
    area = (2 * half) ** 2
    reach = ROAD_HALF_WIDTH + SIDEWALK + 1.0
    cand = rng.uniform(-half, half, (int(area / 200) * 4, 2))
    cand = cand[_off_roads(cand, cross, reach)]
    cand = cand[_free_of(objects, np.column_stack([cand, np.full(len(cand), 0.5)]), 1.2)]
    for x, y in cand[: int(area / 400)]:
        n = int(rng.integers(3, 6))
        r = rng.uniform(0.3, 0.8, (n, 3)) * [1.0, 1.0, 0.8]
        offsets = rng.uniform(-0.6, 0.6, (n, 2))
        for (dx, dy), radii in zip(offsets, r):
            b.add("bush", Ellipsoid([x + dx, y + dy, radii[2] * 0.5], radii))
    patches = rng.uniform(-half, half, (int(area / 250) * 4, 2))
    patches = patches[_off_roads(patches, cross, reach)]
    patches = patches[_free_of(objects, np.column_stack([patches, np.full(len(patches), 0.3)]),
                               1.0)]
    for x, y in patches[: int(area / 350)]:
        n = int(rng.integers(4, 9))
        for dx, dy in rng.uniform(-0.7, 0.7, (n, 2)):
            tilt = rotation_matrix(yaw=rng.uniform(-np.pi, np.pi), pitch=rng.uniform(0.0, 0.3))
            b.add("grass", Frustum([x + dx, y + dy, -0.05], rng.uniform(0.03, 0.07), 0.0,
                                   rng.uniform(0.2, 0.55), tilt))


def _vegetation(b, seed, half, cross):
    """Vegetation clutter off the roads, from its own stream of `seed`."""
    rng = np.random.default_rng([seed, 31337, 1])
    objects = [s for s, label in zip(b.solids, b.labels) if label != "ground"]
    _porous_crowns(b, rng)
    _hedges(b, rng, half, cross, objects)
    _bushes_and_grass(b, rng, half, cross, objects)


def outdoor_scene(seed: int = 0, size: float = 80.0, *, ground_margin: float = 40.0,
                  vegetation: bool = False) -> OutdoorScene:
    """A seeded procedural street scene (see the module docs for its layout).

    Parameters
    ----------
    seed : int, default=0
        Non-negative; the same seed and size give the same scene.
    size : float, default=80.0
        Side of the square, metres, in [30, 400]; about 100 solids at 80 m.
    ground_margin : float, default=40.0
        How far the ground reaches beyond the square, metres, in [0, 1000].
    vegetation : bool, default=False
        Add vegetation clutter off the roads (porous tree crowns, hedges,
        bushes, grass tufts; see the module docs): about 250 more solids
        at 80 m. Every other solid is the same as without it.

    Returns
    -------
    scene : OutdoorScene

    Raises
    ------
    TypeError
        If an argument has a wrong type.
    ValueError
        If an argument is out of its range.

    Examples
    --------
    >>> scene = outdoor_scene(seed=3, size=60)
    >>> scene.occupancy([[0.0, -1.5, 1.7], [0.0, 0.0, -0.1]]).tolist()
    [False, True]
    >>> d, hit = scene.ray_cast([0.0, -1.5, 1.7], [[0.0, 0.0, -1.0]])
    >>> float(d[0]), bool(hit[0])
    (1.7, True)
    """
    seed = check_int(seed, "seed", low=0)
    size = check_real(size, "size", low=MIN_SIZE, high=MAX_SIZE, low_open=False,
                      high_open=False)
    ground_margin = check_real(ground_margin, "ground_margin", low=0.0, high=1000.0,
                               low_open=False, high_open=False)
    vegetation = check_bool(vegetation, "vegetation")
    rng = np.random.default_rng([seed, 31337])
    half = size / 2
    b = _Builder()
    g = half + ground_margin
    b.add("ground", Box([0.0, 0.0, -0.5], [g, g, 0.5]))
    cross = float(rng.uniform(-half / 3, half / 3))
    tall = [3.0]
    for side in (-1, 1):
        _street_side(b, rng, 0, side, -half, half, cross, half, tall)
        _street_side(b, rng, 1, side, -half, half, cross, half, tall)
    # oncoming / parked cars in the far lane of the main road, clear of the crossing
    a = -half + rng.uniform(2.0, 10.0)
    while a < half - 3.0:
        if abs(a - cross) > ROAD_HALF_WIDTH + 3.0 and rng.random() < 0.4:
            _car(b, a, rng.uniform(1.4, 2.2), np.pi + rng.uniform(-0.05, 0.05), rng)
        a += rng.uniform(8.0, 20.0)
    _hills(b, rng, half, cross)
    if vegetation:
        _vegetation(b, seed, half, cross)
    top = max(max(s.aabb[1][2] for s in b.solids), tall[0])
    return OutdoorScene(b.solids, b.labels, size, seed, cross, ground_margin, top, vegetation)
