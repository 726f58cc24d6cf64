"""Convex solid primitives with exact membership, distance and ray casting.

Every primitive lives in its own local frame, given by a center ``c`` and a
rotation matrix ``R`` whose columns are the local axes in the world frame
(``world = R @ local + c``). Rays are moved into the local frame, where the
solid has a canonical shape; since ``R`` is orthonormal, ray parameters
(distances along unit directions) are the same in both frames.

Ray casting intersects the ray with the solid as an interval ``[lo, hi]`` of
ray parameters: each primitive is an intersection of convex sets (slabs,
quadrics), whose intervals are intersected. The first hit is ``max(lo, 0)``
when ``hi >= max(lo, 0)``: a ray that starts inside a solid hits it at 0.

All methods are vectorised over points or rays; nothing loops per point.
"""

import numpy as np

__all__ = ["Box", "Ellipsoid", "Frustum", "rotation_matrix"]

_INF = np.inf


def rotation_matrix(yaw: float = 0.0, pitch: float = 0.0, roll: float = 0.0) -> np.ndarray:
    """Rotation ``Rz(yaw) @ Ry(pitch) @ Rx(roll)`` (radians), as a (3, 3) array.

    Examples
    --------
    >>> R = rotation_matrix(yaw=np.pi / 2)
    >>> np.round(R @ [1.0, 0.0, 0.0], 12).tolist()
    [0.0, 1.0, 0.0]
    """
    cy, sy = np.cos(yaw), np.sin(yaw)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cr, sr = np.cos(roll), np.sin(roll)
    rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    return rz @ ry @ rx


# --------------------------------------------------------------------------- #
# interval helpers (all arrays of shape (n,))
# --------------------------------------------------------------------------- #
def slab_interval(o, d, lo, hi):
    """Ray parameters with ``lo <= o + t d <= hi`` as an interval (t0, t1)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        ta = (lo - o) / d
        tb = (hi - o) / d
    t0 = np.minimum(ta, tb)
    t1 = np.maximum(ta, tb)
    parallel = d == 0.0
    if parallel.any():
        inside = (o >= lo) & (o <= hi)
        t0 = np.where(parallel, np.where(inside, -_INF, _INF), t0)
        t1 = np.where(parallel, np.where(inside, _INF, -_INF), t1)
    return t0, t1


def _quadric_interval(a, b, c):
    """Interval of t with ``a t^2 + 2 b t + c <= 0`` for ``a > 0`` (else empty)."""
    disc = b * b - a * c
    ok = (a > 0.0) & (disc >= 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        sq = np.sqrt(np.where(ok, disc, 0.0))
        # numerically stable roots
        q = -(b + np.copysign(sq, b))
        r1 = q / a
        r2 = c / q
    r2 = np.where(q == 0.0, r1, r2)
    t0 = np.where(ok, np.minimum(r1, r2), _INF)
    t1 = np.where(ok, np.maximum(r1, r2), -_INF)
    return t0, t1


def first_hit(t0, t1):
    """First non-negative parameter of the interval, +inf where it is missed."""
    start = np.maximum(t0, 0.0)
    return np.where((t1 >= start) & (t0 <= t1), start, _INF)


def _segment_distance(px, py, ax, ay, bx, by):
    """Distance from 2D points (px, py) to the segment a-b (scalars a, b)."""
    ex, ey = bx - ax, by - ay
    den = ex * ex + ey * ey
    u = np.clip(((px - ax) * ex + (py - ay) * ey) / den, 0.0, 1.0) if den > 0 else 0.0
    return np.hypot(px - ax - u * ex, py - ay - u * ey)


# --------------------------------------------------------------------------- #
# primitives
# --------------------------------------------------------------------------- #
class _Solid:
    """Common frame handling: center ``center`` and rotation ``rotation``."""

    def __init__(self, center, rotation=None):
        self.center = np.asarray(center, dtype=np.float64).reshape(3)
        self.rotation = (
            np.eye(3) if rotation is None else np.asarray(rotation, dtype=np.float64).reshape(3, 3)
        )

    def _to_local(self, points):
        return (points - self.center) @ self.rotation

    def _dirs_to_local(self, directions):
        return directions @ self.rotation

    def _local_corners(self):  # pragma: no cover - overridden
        raise NotImplementedError

    @property
    def aabb(self):
        """Axis-aligned bounding box ``(min (3,), max (3,))`` in the world frame."""
        corners = self._local_corners() @ self.rotation.T + self.center
        return corners.min(axis=0), corners.max(axis=0)

    def intersect(self, origins, directions):
        """First hit parameter along unit `directions` (+inf where missed)."""
        t0, t1 = self._interval(self._to_local(origins), self._dirs_to_local(directions))
        return first_hit(t0, t1)


class Box(_Solid):
    """Solid box ``|x_i| <= half_extents_i`` in its local frame (rotated box).

    Examples
    --------
    >>> b = Box(center=[0, 0, 0], half_extents=[1, 2, 3])
    >>> b.contains(np.array([[0.5, 1.5, 2.5], [1.5, 0, 0]])).tolist()
    [True, False]
    >>> float(b.intersect(np.array([[-5.0, 0, 0]]), np.array([[1.0, 0, 0]]))[0])
    4.0
    """

    def __init__(self, center, half_extents, rotation=None):
        super().__init__(center, rotation)
        self.half_extents = np.asarray(half_extents, dtype=np.float64).reshape(3)
        if np.any(self.half_extents <= 0):
            raise ValueError(f"half_extents must be positive, got {self.half_extents}")

    def _local_corners(self):
        signs = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T
        return signs * self.half_extents

    def contains(self, points):
        return np.all(np.abs(self._to_local(points)) <= self.half_extents, axis=1)

    def signed_distance(self, points):
        q = np.abs(self._to_local(points)) - self.half_extents
        outside = np.linalg.norm(np.maximum(q, 0.0), axis=1)
        inside = np.minimum(q.max(axis=1), 0.0)
        return outside + inside

    def _interval(self, o, d):
        t0 = np.full(len(o), -_INF)
        t1 = np.full(len(o), _INF)
        for k in range(3):
            a, b = slab_interval(o[:, k], d[:, k], -self.half_extents[k], self.half_extents[k])
            t0 = np.maximum(t0, a)
            t1 = np.minimum(t1, b)
        return t0, t1


class Ellipsoid(_Solid):
    """Solid ellipsoid ``sum (x_i / radii_i)^2 <= 1`` in its local frame.

    A sphere is an ellipsoid with three equal radii. The signed distance is
    exact: the nearest surface point is found by bisection on the Lagrange
    multiplier (Eberly, "Distance from a point to an ellipse, an ellipsoid,
    or a hyperellipsoid"), including the degenerate case of interior points
    on a symmetry plane.

    Examples
    --------
    >>> s = Ellipsoid(center=[0, 0, 1], radii=[1, 1, 1])
    >>> float(s.signed_distance(np.array([[0.0, 0.0, 3.0]]))[0])
    1.0
    >>> float(s.intersect(np.array([[0.0, 0, -2]]), np.array([[0.0, 0, 1]]))[0])
    2.0
    """

    def __init__(self, center, radii, rotation=None):
        super().__init__(center, rotation)
        self.radii = np.asarray(radii, dtype=np.float64).reshape(3)
        if np.any(self.radii <= 0):
            raise ValueError(f"radii must be positive, got {self.radii}")

    def _local_corners(self):
        return Box([0, 0, 0], self.radii)._local_corners()

    def contains(self, points):
        return np.sum((self._to_local(points) / self.radii) ** 2, axis=1) <= 1.0

    def _interval(self, o, d):
        o = o / self.radii
        d = d / self.radii
        return _quadric_interval(
            np.sum(d * d, axis=1), np.sum(o * d, axis=1), np.sum(o * o, axis=1) - 1.0
        )

    def signed_distance(self, points):
        local = self._to_local(points)
        if np.ptp(self.radii) == 0.0:  # sphere
            return np.linalg.norm(local, axis=1) - self.radii[0]
        e = self.radii
        e2 = e * e
        emin2 = e2.min()
        # fold into the first octant; flush tiny coordinates to exact zeros so
        # that near-degenerate points take the closed form below
        y = np.abs(local)
        y = np.where(y < 1e-12 * e.max(), 0.0, y)

        def excess(t):  # F(t) = sum (e_i y_i / (t + e_i^2))^2 - 1, zero terms for y_i = 0
            with np.errstate(divide="ignore", invalid="ignore"):
                terms = np.where(y > 0, e * y / (t[:, None] + e2), 0.0)
            return np.sum(terms**2, axis=1) - 1.0

        # F decreases on (-emin2, inf); its root there gives the nearest point
        lo = np.full(len(y), -emin2)
        hi = np.linalg.norm(y, axis=1) * e.max() + 1e-12
        f_lo = excess(lo)
        for _ in range(100):
            mid = 0.5 * (lo + hi)
            pos = excess(mid) > 0.0
            lo = np.where(pos, mid, lo)
            hi = np.where(pos, hi, mid)
        t = 0.5 * (lo + hi)
        with np.errstate(divide="ignore", invalid="ignore"):
            x = np.where(y > 0, e2 * y / (t[:, None] + e2), 0.0)
        # degenerate case: y on the symmetry plane(s) of the smallest axes
        # and F(-emin2) <= 0 (no root): Eberly's closed form.
        degenerate = ~(f_lo > 0.0)
        if degenerate.any():
            small = e2 == emin2
            yd = y[degenerate]
            xd = np.zeros_like(yd)
            with np.errstate(divide="ignore", invalid="ignore"):
                xd[:, ~small] = e2[~small] * yd[:, ~small] / (e2[~small] - emin2)
            rest = np.sqrt(np.maximum(1.0 - np.sum((xd[:, ~small] / e[~small]) ** 2, axis=1), 0.0))
            ys = yd[:, small]
            norm = np.linalg.norm(ys, axis=1)
            unit = np.zeros_like(ys)
            unit[:, 0] = 1.0
            unit = np.where(norm[:, None] > 0, ys / np.where(norm > 0, norm, 1.0)[:, None], unit)
            xd[:, small] = unit * (rest * np.sqrt(emin2))[:, None]
            x[degenerate] = xd
        dist = np.linalg.norm(x - y, axis=1)
        return np.where(self.contains(points), -dist, dist)


class Frustum(_Solid):
    """Solid truncated cone about the local z axis, ``0 <= z <= height``.

    The radius varies linearly from `radius_bottom` at ``z = 0`` to
    `radius_top` at ``z = height``: equal radii give a capped cylinder,
    ``radius_top = 0`` a cone. `center` is the center of the bottom disc.

    Examples
    --------
    >>> cyl = Frustum(center=[0, 0, 0], radius_bottom=1, radius_top=1, height=2)
    >>> cyl.contains(np.array([[0.5, 0, 1], [0, 0, 2.5]])).tolist()
    [True, False]
    >>> float(cyl.intersect(np.array([[3.0, 0, 1]]), np.array([[-1.0, 0, 0]]))[0])
    2.0
    >>> cone = Frustum(center=[0, 0, 0], radius_bottom=1, radius_top=0, height=1)
    >>> round(float(cone.signed_distance(np.array([[0.0, 0.0, 2.0]]))[0]), 12)
    1.0
    """

    def __init__(self, center, radius_bottom, radius_top, height, rotation=None):
        super().__init__(center, rotation)
        self.radius_bottom = float(radius_bottom)
        self.radius_top = float(radius_top)
        self.height = float(height)
        if self.radius_bottom <= 0 or self.radius_top < 0 or self.height <= 0:
            raise ValueError(
                "radius_bottom and height must be positive and radius_top non-negative, got "
                f"{self.radius_bottom}, {self.radius_top}, {self.height}"
            )
        self._slope = (self.radius_top - self.radius_bottom) / self.height

    def _local_corners(self):
        r = max(self.radius_bottom, self.radius_top)
        return Box([0, 0, 0], [r, r, self.height / 2])._local_corners() + [0, 0, self.height / 2]

    def _radius_at(self, z):
        return self.radius_bottom + self._slope * z

    def contains(self, points):
        p = self._to_local(points)
        z = p[:, 2]
        return (z >= 0) & (z <= self.height) & (np.hypot(p[:, 0], p[:, 1]) <= self._radius_at(z))

    def signed_distance(self, points):
        p = self._to_local(points)
        rho, z = np.hypot(p[:, 0], p[:, 1]), p[:, 2]
        r0, r1, h = self.radius_bottom, self.radius_top, self.height
        # distance to the profile's boundary in the (rho, z) half plane
        dist = np.minimum(
            _segment_distance(rho, z, 0.0, 0.0, r0, 0.0),
            _segment_distance(rho, z, r0, 0.0, r1, h),
        )
        if r1 > 0:
            dist = np.minimum(dist, _segment_distance(rho, z, 0.0, h, r1, h))
        return np.where(self.contains(points), -dist, dist)

    def _interval(self, o, d):
        s, r0 = self._slope, self.radius_bottom
        # the nappe {rho <= g(z)}, g(z) = r0 + s z, is convex; rho^2 - g^2 = A t^2 + 2B t + C
        g0 = r0 + s * o[:, 2]
        gd = s * d[:, 2]
        a = d[:, 0] ** 2 + d[:, 1] ** 2 - gd * gd
        b = o[:, 0] * d[:, 0] + o[:, 1] * d[:, 1] - g0 * gd
        c = o[:, 0] ** 2 + o[:, 1] ** 2 - g0 * g0
        n = len(o)
        t0 = np.full(n, _INF)
        t1 = np.full(n, -_INF)
        disc = b * b - a * c
        with np.errstate(divide="ignore", invalid="ignore"):
            # a > 0: between the roots, if that chord lies on the g >= 0 nappe
            q0, q1 = _quadric_interval(a, b, c)
            mid = np.where(np.isfinite(q0), 0.5 * (q0 + q1), 0.0)
            pos = (a > 0) & (g0 + gd * mid >= 0)
            t0 = np.where(pos, q0, t0)
            t1 = np.where(pos, q1, t1)
            # a < 0: outside the roots; keep the branch where g grows
            neg = a < 0
            sq = np.sqrt(np.where(neg & (disc >= 0), disc, 0.0))
            ra, rb = (-b - sq) / a, (-b + sq) / a
            lo_root, hi_root = np.minimum(ra, rb), np.maximum(ra, rb)
            no_root = neg & (disc < 0)
            up = gd > 0
            t0 = np.where(neg, np.where(no_root | ~up, -_INF, hi_root), t0)
            t1 = np.where(neg, np.where(no_root | up, _INF, lo_root), t1)
            # a == 0: the quadratic is linear, 2 b t + c <= 0
            lin = a == 0
            root = -c / (2 * b)
            t0 = np.where(lin, np.where(b < 0, root, np.where((b == 0) & (c <= 0), -_INF, t0)), t0)
            t1 = np.where(lin, np.where(b > 0, root, np.where((b == 0) & (c <= 0), _INF, t1)), t1)
        # keep g >= 0 (a single nappe) and 0 <= z <= height
        ga, gb = slab_interval(g0, gd, 0.0, _INF)
        za, zb = slab_interval(o[:, 2], d[:, 2], 0.0, self.height)
        return np.maximum.reduce([t0, ga, za]), np.minimum.reduce([t1, gb, zb])
