"""A 2D room seen by a planar laser: the setting of the GP occupancy papers.

The room is 22 x 18 m (interior x in [-11, 11], y in [-9, 9]) with 0.2 m
walls, four interior walls with doorways, five (partly rotated) boxes and
five round pillars. A robot follows a fixed path through the doorways and
takes 26 scans with a 180-degree, 17-beam laser of 8 m range (O'Callaghan &
Ramos, "Gaussian process occupancy maps"; Kim & Kim, "Continuous occupancy
maps using overlapping local Gaussian processes"). Beams without a return
(``hit`` False) have range ``max_range``; the GP methods use them as free
segments.
"""

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._docfill import fill_doc
from .._validation import as_points, check_int, check_real
from ._geometry import slab_interval
from ..io import LaserScan2D
from ._scenes import SEED_SECTIONS, check_max_range, first_hits, scene_doc_sections

__all__ = ["Scene2D", "room_2d"]

_INF = np.inf
MAX_BEAMS = 2**26  # most beams (n_poses * n_beams) one Scene2D.scan casts
MAX_POSES = 10**7  # most poses Scene2D.poses makes
_SECTIONS = scene_doc_sections(2)


def _padded(lo, hi):
    """A box grown by far more than the rounding error of the solids' membership tests."""
    pad = 1e-9 * (1.0 + np.maximum(np.abs(lo), np.abs(hi)).max() + (hi - lo).max())
    return lo - pad, hi + pad


class Rect:
    """Solid rectangle ``|x_i| <= half_i`` in a frame turned by `angle`."""

    def __init__(self, center, half, angle=0.0):
        self.center = np.asarray(center, dtype=np.float64)
        self.half = np.asarray(half, dtype=np.float64)
        c, s = np.cos(angle), np.sin(angle)
        self.rotation = np.array([[c, -s], [s, c]])

    def _local(self, p):
        return (p - self.center) @ self.rotation

    def bounding_box(self):
        """``(min (2,), max (2,))`` enclosing the rectangle, with a margin past rounding."""
        reach = np.abs(self.rotation) @ self.half
        return _padded(self.center - reach, self.center + reach)

    def contains(self, p):
        return np.all(np.abs(self._local(p)) <= self.half, axis=1)

    def signed_distance(self, p):
        q = np.abs(self._local(p)) - self.half
        return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)

    def intersect(self, o, d):
        o, d = self._local(o), d @ self.rotation
        ax, bx = slab_interval(o[:, 0], d[:, 0], -self.half[0], self.half[0])
        ay, by = slab_interval(o[:, 1], d[:, 1], -self.half[1], self.half[1])
        t0, t1 = np.maximum(ax, ay), np.minimum(bx, by)
        start = np.maximum(t0, 0.0)
        return np.where((t1 >= start) & (t0 <= t1), start, _INF)


class Circle:
    """Solid disc of `radius` about `center`."""

    def __init__(self, center, radius):
        self.center = np.asarray(center, dtype=np.float64)
        self.radius = float(radius)

    def bounding_box(self):
        """``(min (2,), max (2,))`` enclosing the disc, with a margin past rounding."""
        return _padded(self.center - self.radius, self.center + self.radius)

    def contains(self, p):
        return np.sum((p - self.center) ** 2, axis=1) <= self.radius**2

    def signed_distance(self, p):
        return np.linalg.norm(p - self.center, axis=1) - self.radius

    def intersect(self, o, d):
        oc = o - self.center
        b = np.sum(oc * d, axis=1)
        c = np.sum(oc * oc, axis=1) - self.radius**2
        disc = b * b - c
        sq = np.sqrt(np.maximum(disc, 0.0))
        t0, t1 = -b - sq, -b + sq
        start = np.maximum(t0, 0.0)
        return np.where((disc >= 0) & (t1 >= start), start, _INF)


class Scene2D:
    """A 2D room of rectangles and discs, with exact occupancy and ray casting.

    Build it with :func:`room_2d` or :func:`floor_plan_2d`.

    Parameters
    ----------
    solids : list of primitives
        Rectangles and discs; the scene is their union.
    labels : list of str
        One name per solid.
    interior_bounds : tuple of two array-like of shape (2,)
        The free interior box (inside the outer walls).
    wall_thickness : float
        Thickness of the outer walls.
    path : array-like of shape (n_vertices, 2)
        Polyline followed by the robot, see :meth:`poses`.

    Examples
    --------
    >>> room = room_2d()
    >>> room.occupancy([[0.0, 0.0], [11.1, 0.0]]).tolist()
    [False, True]
    """

    def __init__(self, solids, labels, interior_bounds, wall_thickness, path):
        self.solids = list(solids)
        self.labels = list(labels)
        self._interior = tuple(np.asarray(b, dtype=np.float64) for b in interior_bounds)
        self.wall_thickness = float(wall_thickness)
        self.path = np.asarray(path, dtype=np.float64)

    def __repr__(self):
        return f"Scene2D(n_solids={len(self.solids)})"

    @property
    def bounds(self):
        """``(min (2,), max (2,))`` of the room including the outer walls."""
        return self._interior[0] - self.wall_thickness, self._interior[1] + self.wall_thickness

    @property
    def interior_bounds(self):
        """``(min (2,), max (2,))`` inside the outer walls."""
        return self._interior[0].copy(), self._interior[1].copy()

    @fill_doc(**_SECTIONS)
    def occupancy(self, points: ArrayLike) -> NDArray[np.bool_]:
        """Exact membership of 2D `points` in the union of the solids.

        {points_param}

        Returns
        -------
        occupied : ndarray of shape (n_points,), dtype bool
            True inside or on the boundary of a solid.

        Raises
        ------
        {points_raises}

        Examples
        --------
        >>> room_2d().occupancy([[-1.0, 6.5]]).tolist()    # a pillar
        [True]
        """
        points = as_points(points, "points", dim=2)
        out = np.zeros(len(points), dtype=bool)
        if not len(points):
            return out
        # each solid tests only the points in its bounding box: those in its x range are
        # a slice of the points sorted by x, then a y test picks the ones to test exactly
        order = np.argsort(points[:, 0], kind="stable")
        xs, ys = points[order, 0], points[order, 1]
        for solid in self.solids:
            lo, hi = solid.bounding_box()
            a = np.searchsorted(xs, lo[0], side="left")
            b = np.searchsorted(xs, hi[0], side="right")
            if a >= b:
                continue
            inside = (ys[a:b] >= lo[1]) & (ys[a:b] <= hi[1])
            idx = order[a:b][inside]
            if idx.size:
                out[idx] |= solid.contains(points[idx])
        return out

    @fill_doc(**_SECTIONS)
    def signed_distance(self, points: ArrayLike) -> NDArray[np.float64]:
        """Signed Euclidean distance to the solids (negative inside).

        Exact outside the solids; inside overlapping solids, the magnitude is
        the depth inside the deepest single solid (a lower bound).

        {points_param}

        Returns
        -------
        distance : ndarray of shape (n_points,)
            In metres; inf everywhere for a scene without solids.

        {as_occupancy}

        Examples
        --------
        >>> round(float(room_2d().signed_distance([[0.0, 8.5]])[0]), 12)
        0.5
        """
        points = as_points(points, "points", dim=2)
        out = np.full(len(points), np.inf)
        for solid in self.solids:
            np.minimum(out, solid.signed_distance(points), out=out)
        return out

    @fill_doc(**_SECTIONS)
    def ray_cast(self, origins: ArrayLike, directions: ArrayLike, max_range: float = np.inf):
        """Exact first intersection of 2D rays with the solids.

        {ray_cast_sections}

        Examples
        --------
        >>> d, hit = room_2d().ray_cast([0.0, 0.0], [[0.0, 1.0]])
        >>> float(d[0]), bool(hit[0])
        (9.0, True)
        """
        return first_hits(self.solids, origins, directions, max_range, dim=2)

    def poses(self, n_poses: int = 26):
        """Poses equally spaced (by arc length) along :attr:`path`.

        Parameters
        ----------
        n_poses : int, default=26
            Number of poses, in [1, ``MAX_POSES``] (10^7); the first is the
            path's start and the last (for more than one) its end.

        Returns
        -------
        origins : ndarray of shape (n_poses, 2)
        headings : ndarray of shape (n_poses,)
            Direction of travel, radians from +x.

        Raises
        ------
        TypeError
            If `n_poses` is not an int.
        ValueError
            If `n_poses` is below 1 or above ``MAX_POSES``.

        Examples
        --------
        >>> origins, headings = room_2d().poses()
        >>> origins.shape, headings.shape
        ((26, 2), (26,))
        """
        n_poses = check_int(n_poses, "n_poses", low=1, high=MAX_POSES)
        return along_path(self.path, lambda total: np.linspace(0.0, total, n_poses)
                          if n_poses > 1 else np.zeros(1))

    def scan(
        self,
        n_poses: int = 26,
        n_beams: int = 17,
        fov: float = np.pi,
        max_range: float = 8.0,
        noise: float = 0.0,
        seed: int = 0,
    ) -> list:
        """Simulate a planar laser along the robot's path.

        Parameters
        ----------
        n_poses : int, default=26
            Scans, equally spaced along :attr:`path` (see :meth:`poses`).
        n_beams : int, default=17
            Beams per scan, evenly spread over `fov` (both ends included).
        fov : float, default=pi
            Field of view, radians, centered on the heading.
        max_range : float, default=8.0
            Beams with no return closer than this have ``hit`` False and
            range `max_range`.
        noise : float, default=0.0
            Standard deviation (metres) of Gaussian noise added to the
            ranges of returning beams.
        seed : int, default=0
            Seed of the noise (``np.random.default_rng(seed)``).

        Returns
        -------
        scans : list of LaserScan2D
            One scan per pose.

        Raises
        ------
        TypeError
            If `n_poses`, `n_beams` or `seed` is not an int, or `fov`,
            `max_range` or `noise` not a real number.
        ValueError
            If `n_poses` or `n_beams` is below 1, ``n_poses * n_beams`` above
            ``MAX_BEAMS`` (2^26), `fov` outside [0, 2 pi], `max_range` not
            positive and finite, `noise` negative or not finite, or `seed`
            negative.

        Examples
        --------
        >>> scans = room_2d().scan()
        >>> len(scans), scans[0].ranges.shape
        (26, (17,))
        """
        n_beams = check_int(n_beams, "n_beams", low=1)
        n_poses = check_int(n_poses, "n_poses", low=1)
        if n_poses * n_beams > MAX_BEAMS:
            raise ValueError(f"n_poses * n_beams must be at most {MAX_BEAMS} beams, got "
                             f"{n_poses} x {n_beams}")
        fov = check_real(fov, "fov", low=0.0, high=2 * np.pi, low_open=False,
                         high_open=False)
        max_range = check_max_range(max_range)
        if not np.isfinite(max_range):
            raise ValueError("max_range must be finite for a laser scan")
        noise = check_real(noise, "noise", low=0.0, low_open=False)
        rng = np.random.default_rng(check_int(seed, "seed", low=0))
        origins, headings = self.poses(n_poses)
        angles = np.linspace(-fov / 2, fov / 2, n_beams) if n_beams > 1 else np.zeros(1)
        world = headings[:, None] + angles  # (n_poses, n_beams)
        dirs = np.stack([np.cos(world), np.sin(world)], axis=-1).reshape(-1, 2)
        ray_origins = np.repeat(origins, n_beams, axis=0)
        ranges, hit = self.ray_cast(ray_origins, dirs, max_range)
        if noise > 0:
            eps = rng.normal(0.0, noise, len(ranges))
            ranges = np.where(hit, np.clip(ranges + eps, 0.0, None), ranges)
        ranges = ranges.reshape(n_poses, n_beams)
        hit = hit.reshape(n_poses, n_beams)
        return [
            LaserScan2D(origins[i].copy(), float(headings[i]), angles.copy(), ranges[i].copy(),
                        hit[i].copy(), max_range)
            for i in range(len(origins))
        ]


@fill_doc(seed_sections=SEED_SECTIONS.format(scene="Scene2D"))
def room_2d(seed: int = 0) -> Scene2D:
    """The 22 x 18 m 2D room of the GP occupancy-map experiments.

    Interior ``[-11, 11] x [-9, 9]`` inside 0.2 m outer walls; four interior
    walls with doorways, five boxes (two rotated) and five discs. The
    robot's path (:attr:`Scene2D.path`) stays at least 0.5 m from every
    obstacle.

    Parameters
    ----------
    seed : int, default=0
        0 gives the fixed default room; another seed moves each box and disc
        by up to 0.3 m (deterministically), keeping them 0.5 m from the path.

    {seed_sections}

    Examples
    --------
    >>> room = room_2d()
    >>> [b.tolist() for b in room.bounds]
    [[-11.2, -9.2], [11.2, 9.2]]
    """
    seed = check_int(seed, "seed", low=0)
    hx, hy, t = 11.0, 9.0, 0.2
    solids = [
        Rect([-hx - t / 2, 0.0], [t / 2, hy + t]),
        Rect([hx + t / 2, 0.0], [t / 2, hy + t]),
        Rect([0.0, -hy - t / 2], [hx + t, t / 2]),
        Rect([0.0, hy + t / 2], [hx + t, t / 2]),
        # interior walls (doorways at y in [-2, 1] on x = -3, x in [-2.9, 2.9] at y = 2.5)
        Rect([-3.0, -5.5], [0.1, 3.5]),
        Rect([-3.0, 5.0], [0.1, 4.0]),
        Rect([7.0, 2.5], [4.0, 0.1]),
        Rect([-9.0, 3.0], [2.0, 0.1]),
    ]
    labels = ["wall_-x", "wall_+x", "wall_-y", "wall_+y",
              "inner_wall_1", "inner_wall_2", "inner_wall_3", "inner_wall_4"]
    path = np.array([
        [-9.0, -4.0], [-5.5, -6.5], [-5.0, -0.5], [0.0, -0.5], [0.5, -5.5], [4.5, -7.0],
        [9.0, -4.0], [9.0, 0.8], [4.0, 1.2], [0.0, 1.5], [0.0, 4.0], [2.0, 7.5], [8.5, 7.5],
    ])
    objects = [
        ("box_1", lambda dx, dy: Rect([-8.5 + dx, -7.0 + dy], [1.2, 0.7])),
        ("box_2", lambda dx, dy: Rect([-8.0 + dx, 6.5 + dy], [0.8, 0.8], np.radians(30))),
        ("box_3", lambda dx, dy: Rect([6.0 + dx, -3.0 + dy], [1.6, 0.5], np.radians(-20))),
        ("box_4", lambda dx, dy: Rect([8.0 + dx, 4.5 + dy], [0.6, 1.2])),
        ("box_5", lambda dx, dy: Rect([-1.0 + dx, -7.6 + dy], [1.0, 0.5], np.radians(15))),
        ("disc_1", lambda dx, dy: Circle([-7.0 + dx, -1.5 + dy], 0.6)),
        ("disc_2", lambda dx, dy: Circle([2.5 + dx, -3.0 + dy], 0.8)),
        ("disc_3", lambda dx, dy: Circle([6.0 + dx, -0.5 + dy], 0.5)),
        ("disc_4", lambda dx, dy: Circle([-1.0 + dx, 6.5 + dy], 0.8)),
        ("disc_5", lambda dx, dy: Circle([-6.0 + dx, 6.0 + dy], 0.5)),
    ]
    rng = np.random.default_rng(seed) if seed else None
    samples = path_samples(path)
    for label, build in objects:
        solid = build(0.0, 0.0)
        if rng is not None:
            for _ in range(20):
                cand = build(*rng.uniform(-0.3, 0.3, 2))
                if cand.signed_distance(samples).min() >= 0.5:
                    solid = cand
                    break
        solids.append(solid)
        labels.append(label)
    return Scene2D(solids, labels, ([-hx, -hy], [hx, hy]), t, path)


def along_path(path, arc_lengths):
    """Points and headings of a polyline at arc lengths ``arc_lengths(total_length)``.

    Returns ``(points (n, 2), headings (n,))``, the heading being the
    direction of the segment each point lies on, radians from +x.
    """
    seg = np.diff(path, axis=0)
    length = np.linalg.norm(seg, axis=1)
    cum = np.concatenate([[0.0], np.cumsum(length)])
    s = arc_lengths(cum[-1])
    k = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(seg) - 1)
    u = (s - cum[k]) / length[k]
    return path[k] + u[:, None] * seg[k], np.arctan2(seg[k, 1], seg[k, 0])


def path_samples(path, step=0.05):
    """Points every `step` metres along a polyline (for clearance checks)."""
    out = [path[:1]]
    for a, b in zip(path[:-1], path[1:]):
        n = max(int(np.ceil(np.linalg.norm(b - a) / step)), 1)
        out.append(a + np.linspace(0, 1, n + 1)[1:, None] * (b - a))
    return np.vstack(out)
