"""Rendered stereo pairs of analytic scenes: a rectified grey camera pair, ray cast exactly.

:func:`render_stereo` renders what a rectified stereo camera (:class:`StereoRig`)
sees of a :class:`~occgp.datasets.Scene`: each camera casts one ray per pixel
through the scene's solids (exact first hits, screen-space culled), shades
the hit with a Lambertian sun and sky (cast shadows by shadow rays) and a
procedural texture (:mod:`occgp.datasets._textures`), then applies the
sensor's effects (optical and motion blur, gain mismatch, rectification
error, noise, 8-bit quantisation, JPEG). The left and right images are
rendered separately, so occlusions and disparities are exact; a stereo
matcher run on them makes the errors it makes on real images (weak texture,
repeated patterns, occlusion edges).
"""

from __future__ import annotations

import fnmatch
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.ndimage import convolve1d, gaussian_filter
from scipy.ndimage import shift as shift_image

from .._validation import as_point, check_bool, check_int, check_real
from ._geometry import Box, Ellipsoid, Frustum
from ._scenes import Scene
from ._textures import TEXTURES, texture_albedo

__all__ = ["StereoRig", "StereoPair", "render_stereo", "scene_materials", "TEXTURES"]

MAX_PIXELS = 1920 * 1080
SKY_HORIZON, SKY_ZENITH = 240.0, 210.0   # grey level of the sky at the horizon and overhead
_NEAR = 1e-6         # near plane of the screen-space culling, metres
_SHADOW_EPS = 1e-6   # shadow rays start this far (metres, relative) off the surface
_GROUND = ("ground", "floor", "road", "street", "curb", "hill")
_BUILDING = ("building", "wall", "facade")


@dataclass(frozen=True)
class StereoRig:
    """A rectified stereo camera pair, its sensor's effects and the scene's lighting.

    Two identical pinhole cameras with the same rotation; the right camera
    sits `baseline` metres along the left camera's x (right) axis. Pixel
    ``(row, col)`` has its center at ``(col + 0.5, row + 0.5)``; the principal
    point is the image center ``(width / 2, height / 2)``, x to the right, y
    down, z forward (OpenCV's convention). A point at depth ``z`` has the
    disparity ``focal_length * baseline / z`` (pixels, left column minus right
    column).

    The defaults are a ZED at half resolution (640 x 360, 337.2 px) with mild
    sensor effects; :meth:`zed` gives the full 1280 x 720 camera.

    Parameters
    ----------
    width, height : int, default=640, 360
        Image size in pixels, each at least 1, at most 1920 x 1080 in all.
    focal_length : float, default=337.2
        Focal length in pixels, in (0, 1e5].
    baseline : float, default=0.12
        Distance between the camera centers, metres, in (0, 10].
    max_depth : float, default=8.0
        Longest depth a matcher should trust, metres, in (0, 1000] (kept for
        the disparity-to-points step; the renderer draws everything).
    blur : float, default=0.5
        Optical blur, the sigma of a Gaussian in pixels, in [0, 20].
    motion_blur : float, default=0.0
        Length of a horizontal box blur in pixels, in [0, 100] (0 or up to 1:
        none).
    gain : float, default=0.03
        Relative gain of the right image over the left, in [-0.5, 0.5].
    offset : float, default=1.5
        Grey-level offset added to the right image, in [-50, 50].
    rectification : float, default=0.0
        Vertical misalignment of the right image, pixels (its content moves
        down by this much, bilinear), in [-20, 20].
    noise : float, default=2.0
        Standard deviation of additive Gaussian noise, grey levels of 0-255,
        in [0, 100].
    jpeg : int or None, default=None
        JPEG quality in [1, 100] of a compression round trip (needs OpenCV:
        ``pip install occgp[stereo]``); None: none.
    sun_azimuth : float, default=45.0
        Direction of the sun, degrees counter-clockwise from +x, in [-360, 360].
    sun_elevation : float, default=35.0
        Height of the sun above the horizon, degrees, in (0, 90].
    ambient : float, default=0.35
        Share of the light that comes from the sky (no shadows), in [0, 1].

    Attributes
    ----------
    intrinsics : tuple of float
        ``(focal_length, cx, cy)``.
    camera_matrix : ndarray of shape (3, 3)
        The pinhole matrix ``K``.
    sun : ndarray of shape (3,)
        Unit vector toward the sun.

    Raises
    ------
    TypeError, ValueError
        For a field of the wrong type or out of its range (the message names
        the field).

    Examples
    --------
    >>> rig = StereoRig(width=64, height=36, focal_length=33.72)
    >>> rig.intrinsics
    (33.72, 32.0, 18.0)
    >>> StereoRig.zed().width, StereoRig.zed().baseline
    (1280, 0.11968)
    """

    width: int = 640
    height: int = 360
    focal_length: float = 337.2
    baseline: float = 0.12
    max_depth: float = 8.0
    blur: float = 0.5
    motion_blur: float = 0.0
    gain: float = 0.03
    offset: float = 1.5
    rectification: float = 0.0
    noise: float = 2.0
    jpeg: int | None = None
    sun_azimuth: float = 45.0
    sun_elevation: float = 35.0
    ambient: float = 0.35

    _RANGES = {  # field: (low, high, low_open, high_open)
        "focal_length": (0.0, 1e5, True, False), "baseline": (0.0, 10.0, True, False),
        "max_depth": (0.0, 1000.0, True, False), "blur": (0.0, 20.0, False, False),
        "motion_blur": (0.0, 100.0, False, False), "gain": (-0.5, 0.5, False, False),
        "offset": (-50.0, 50.0, False, False), "rectification": (-20.0, 20.0, False, False),
        "noise": (0.0, 100.0, False, False), "sun_azimuth": (-360.0, 360.0, False, False),
        "sun_elevation": (0.0, 90.0, True, False), "ambient": (0.0, 1.0, False, False),
    }

    def __post_init__(self) -> None:
        fix = lambda name, value: object.__setattr__(self, name, value)  # noqa: E731
        fix("width", check_int(self.width, "width", low=1))
        fix("height", check_int(self.height, "height", low=1))
        if self.width * self.height > MAX_PIXELS:
            raise ValueError(f"width * height must be at most {MAX_PIXELS} pixels (1920 x 1080), "
                             f"got {self.width} x {self.height}")
        for name, (lo, hi, lo_open, hi_open) in self._RANGES.items():
            fix(name, check_real(getattr(self, name), name, low=lo, high=hi,
                                 low_open=lo_open, high_open=hi_open))
        if self.jpeg is not None:
            fix("jpeg", check_int(self.jpeg, "jpeg", low=1, high=100))

    @classmethod
    def zed(cls, **kwargs) -> StereoRig:
        """The full-resolution ZED: 1280 x 720 pixels, 674.31 px, baseline 0.11968 m.

        Parameters
        ----------
        **kwargs
            Other fields (sensor effects, lighting), or overrides of these.

        Returns
        -------
        rig : StereoRig

        Raises
        ------
        TypeError, ValueError
            As :class:`StereoRig`.
        """
        return cls(**{"width": 1280, "height": 720, "focal_length": 674.31,
                      "baseline": 0.11968, **kwargs})

    @property
    def intrinsics(self) -> tuple[float, float, float]:
        """``(focal_length, cx, cy)`` in pixels, the principal point at the image center."""
        return (self.focal_length, self.width / 2, self.height / 2)

    @property
    def camera_matrix(self) -> NDArray[np.float64]:
        """The (3, 3) pinhole matrix ``[[f, 0, cx], [0, f, cy], [0, 0, 1]]``."""
        f, cx, cy = self.intrinsics
        return np.array([[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]])

    @property
    def sun(self) -> NDArray[np.float64]:
        """Unit vector toward the sun (world frame, z up)."""
        az, el = np.radians(self.sun_azimuth), np.radians(self.sun_elevation)
        return np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])


class StereoPair(NamedTuple):
    """A rendered rectified stereo pair (see :func:`render_stereo`).

    Attributes
    ----------
    left, right : ndarray of shape (height, width), dtype uint8
        Grey images of the left and right camera.
    depth : ndarray of shape (height, width) or None
        Exact depth along the left camera's optical axis, metres (inf where
        the pixel sees the sky); None unless rendered with ``truth=True``.
    solid : ndarray of shape (height, width), dtype int16, or None
        Index into ``scene.solids`` of what each left pixel sees, -1 for the
        sky; None unless rendered with ``truth=True``.
    position : ndarray of shape (3,)
        Center of the left camera, world frame.
    rotation : ndarray of shape (3, 3)
        Camera-to-world rotation of the left camera: its columns are the
        camera's x (right), y (down) and z (forward) axes in the world frame.
        The right camera's center is ``position + baseline * rotation[:, 0]``.
    """

    left: NDArray[np.uint8]
    right: NDArray[np.uint8]
    depth: NDArray[np.float64] | None
    solid: NDArray[np.int16] | None
    position: NDArray[np.float64]
    rotation: NDArray[np.float64]


def scene_materials(scene: Scene) -> list[str]:
    """The default material (texture name) of each solid of a scene.

    A :class:`~occgp.datasets.TetrominoScene` gets ``"asphalt"`` on its
    ground, ``"voronoi"`` on its boxes when it is textured, ``"cardboard"``
    when it is plain, and ``"facade"`` on its buildings. For any other scene
    the labels decide: ground-like solids (labels containing ``"ground"``,
    ``"floor"``, ``"road"``, ``"street"``, ``"curb"`` or ``"hill"``) get
    ``"asphalt"``, buildings and walls ``"facade"``, everything else
    ``"voronoi"``.

    Parameters
    ----------
    scene : Scene

    Returns
    -------
    materials : list of str
        One of :data:`TEXTURES` per solid, in the order of ``scene.solids``.

    Raises
    ------
    TypeError
        If `scene` is not a Scene.

    Examples
    --------
    >>> from occgp.datasets import tetromino_scene
    >>> scene_materials(tetromino_scene("I", texture=False))[:4]
    ['asphalt', 'cardboard', 'cardboard', 'cardboard']
    """
    _check_scene(scene)
    plain = getattr(scene, "texture", True) is False and hasattr(scene, "targets")
    out = []
    for label in scene.labels:
        label = str(label).lower()
        if any(word in label for word in _GROUND):
            out.append("asphalt")
        elif any(word in label for word in _BUILDING):
            out.append("facade")
        elif plain and label.startswith("box"):
            out.append("cardboard")
        else:
            out.append("voronoi")
    return out


def render_stereo(scene: Scene, position: ArrayLike, look_at: ArrayLike,
                  rig: StereoRig = StereoRig(), *, seed: int = 0, truth: bool = False,
                  materials: Sequence[str] | Mapping[str, str] | None = None) -> StereoPair:
    """Render the rectified grey stereo pair a :class:`StereoRig` sees of a scene.

    Each camera casts one ray through each pixel center; the first hit
    (exact) is shaded as ``albedo * (ambient + (1 - ambient) * max(0, n . sun)
    * lit)``, times 255, where the albedo comes from the solid's procedural
    texture at the hit, ``n`` is the surface normal and ``lit`` is 0 where a
    ray from the hit toward the sun meets a solid (cast shadow). Rays that
    hit nothing see a bright sky (grey 240 at the horizon to 210 overhead).
    The images then go through the sensor's effects in this order: optical
    blur, motion blur, the right image's gain and offset, the right image's
    vertical misalignment, noise, rounding to uint8, JPEG.

    Textures are fixed on the surfaces (seeded by the solid and face, not by
    the frame): both cameras and every frame see the same pattern.

    Parameters
    ----------
    scene : Scene
        What the cameras see, e.g. a :func:`tetromino_scene`.
    position : array-like of shape (3,)
        Center of the left camera, world frame, metres; both cameras must
        stand in free space.
    look_at : array-like of shape (3,)
        A point on the left camera's optical axis; the image's up is toward
        +z (no roll).
    rig : StereoRig, default=StereoRig()
        Cameras, sensor effects and lighting.
    seed : int, default=0
        Seeds the sensor noise (``numpy.random.default_rng([seed, ...])``),
        non-negative.
    truth : bool, default=False
        Also return the left camera's exact depth and solid index per pixel.
    materials : sequence of str, or dict of str to str, default=None
        Texture of each solid, names from :data:`TEXTURES`: a sequence (one
        per solid), or a dict from label patterns (``fnmatch``, e.g.
        ``"box_*"``) to names that overrides :func:`scene_materials`. None:
        :func:`scene_materials`.

    Returns
    -------
    pair : StereoPair
        ``left``, ``right`` (uint8 of shape (height, width)), ``depth`` and
        ``solid`` (None unless `truth`), ``position`` and ``rotation`` of the
        left camera.

    Raises
    ------
    TypeError
        If `scene` is not a Scene, `rig` not a StereoRig, `seed` not an int,
        `truth` not a bool, or `materials` of the wrong type.
    ValueError
        If `position` or `look_at` is not a finite point of shape (3,), a
        camera lies inside a solid, `look_at` equals `position` or lies
        straight above or below it, or `materials` names an unknown texture,
        matches no label or has the wrong length.
    ImportError
        If ``rig.jpeg`` is set and OpenCV is not installed.

    Examples
    --------
    >>> from occgp.datasets import tetromino_scene
    >>> scene = tetromino_scene("T", texture=True)
    >>> rig = StereoRig(width=64, height=36, focal_length=33.72)
    >>> pair = render_stereo(scene, [4.0, 0.0, 1.5], scene.target_center, rig, truth=True)
    >>> pair.left.shape, pair.left.dtype, pair.solid.dtype
    ((36, 64), dtype('uint8'), dtype('int16'))
    >>> bool(np.isinf(pair.depth[0, 40])), scene.labels[pair.solid[24, 30]]   # sky; a box
    (True, 'box_2_lower')
    """
    _check_scene(scene)
    if not isinstance(rig, StereoRig):
        raise TypeError(f"rig must be a StereoRig, got {type(rig).__name__}")
    position = as_point(position, "position")
    look_at = as_point(look_at, "look_at")
    seed = check_int(seed, "seed", low=0)
    truth = check_bool(truth, "truth")
    names = _resolve_materials(scene, materials)
    if len(scene.solids) > np.iinfo(np.int16).max:
        raise ValueError(f"scene must have at most {np.iinfo(np.int16).max} solids (the "
                         f"solid indices are int16), got {len(scene.solids)}")
    rotation = camera_rotation(position, look_at)
    right_position = position + rig.baseline * rotation[:, 0]
    inside = scene.occupancy(np.array([position, right_position]))
    if inside[0]:
        raise ValueError(f"position {position.tolist()} lies inside a solid; the cameras "
                         "must stand in free space")
    if inside[1]:
        raise ValueError(f"the right camera, at {right_position.tolist()} (position + baseline "
                         "along the image's x axis), lies inside a solid")
    units, norm = _pixel_rays(rig, rotation)
    rng = np.random.default_rng([seed, 0x57E2E0])
    images, depth, solid = [], None, None
    for k, origin in enumerate((position, right_position)):
        radiance, t, ids = _render_view(scene, names, rig, origin, rotation, units)
        if k == 0 and truth:
            depth = t / norm
            solid = ids
        images.append(_sensor(radiance, rig, rng, right=k == 1))
    return StereoPair(images[0], images[1], depth, solid, position, rotation)


# --------------------------------------------------------------------------- #
# cameras and ray casting
# --------------------------------------------------------------------------- #
def camera_rotation(position, look_at):
    """Camera-to-world rotation (columns: right, down, forward) looking from `position`
    at `look_at`, with no roll (the image's up toward +z)."""
    forward = look_at - position
    norm = np.linalg.norm(forward)
    if not norm > 0:
        raise ValueError(f"look_at must differ from position, got {look_at.tolist()} for both")
    forward = forward / norm
    right = np.cross(forward, [0.0, 0.0, 1.0])
    if not np.linalg.norm(right) > 1e-9:
        raise ValueError("look_at must not lie straight above or below position "
                         "(the camera's roll would be undefined)")
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    return np.column_stack([right, down, forward])


def _pixel_rays(rig, rotation):
    """Unit ray directions (height, width, 3) in the world frame, and ``|(x, y, 1)|`` per
    pixel (a hit at distance t along the ray lies at depth ``t / norm``)."""
    f, cx, cy = rig.intrinsics
    x = (np.arange(rig.width) + 0.5 - cx) / f
    y = (np.arange(rig.height) + 0.5 - cy) / f
    cam = np.empty((rig.height, rig.width, 3))
    cam[..., 0] = x[None, :]
    cam[..., 1] = y[:, None]
    cam[..., 2] = 1.0
    norm = np.sqrt(1.0 + x[None, :] ** 2 + y[:, None] ** 2)
    return (cam @ rotation.T) / norm[..., None], norm


def _box_corners(lo, hi):
    bits = np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], dtype=bool)
    return np.where(bits, hi, lo)


_EDGES = np.array([(i, i | (1 << b)) for i in range(8) for b in range(3) if not i & (1 << b)])


def _screen_rect(lo, hi, origin, rotation, rig):
    """Pixel rectangle ``(r0, r1, c0, c1)`` (half-open) that holds the image of the box
    ``[lo, hi]``, or None when the box lies behind the camera or outside the image.

    The box is clipped by the near plane first (corners in front, and the points where
    its edges cross the plane), so that a box partly behind the camera is bounded too.
    """
    cam = (_box_corners(lo, hi) - origin) @ rotation
    z = cam[:, 2]
    front = z > _NEAR
    if not front.any():
        return None
    pts = [cam[front]]
    a, b = _EDGES[:, 0], _EDGES[:, 1]
    cross = front[a] != front[b]
    if cross.any():
        pa, pb = cam[a[cross]], cam[b[cross]]
        s = (_NEAR - pa[:, 2]) / (pb[:, 2] - pa[:, 2])
        pts.append(pa + s[:, None] * (pb - pa))
    p = np.concatenate(pts)
    f, cx, cy = rig.intrinsics
    u = f * p[:, 0] / p[:, 2] + cx
    v = f * p[:, 1] / p[:, 2] + cy
    # pixel (r, c) has its center at (c + 0.5, r + 0.5); one pixel of margin for rounding
    c0 = int(np.clip(np.floor(u.min() - 0.5) - 1, 0, rig.width))
    c1 = int(np.clip(np.ceil(u.max() - 0.5) + 2, 0, rig.width))
    r0 = int(np.clip(np.floor(v.min() - 0.5) - 1, 0, rig.height))
    r1 = int(np.clip(np.ceil(v.max() - 0.5) + 2, 0, rig.height))
    if c0 >= c1 or r0 >= r1:
        return None
    return r0, r1, c0, c1


def cast_image(solids, origin, rotation, rig, units):
    """First hits of the pixel rays `units` (height, width, 3) from `origin`: distances
    (inf for none) and solid indices (int16, -1 for none), each of shape (height, width).

    Each solid is intersected only with the rays of its screen rectangle; the result is
    that of intersecting every ray with every solid.
    """
    t = np.full(units.shape[:2], np.inf)
    ids = np.full(units.shape[:2], -1, dtype=np.int16)
    for k, solid in enumerate(solids):
        lo, hi = solid.aabb
        rect = _screen_rect(lo, hi, origin, rotation, rig)
        if rect is None:
            continue
        r0, r1, c0, c1 = rect
        dirs = units[r0:r1, c0:c1].reshape(-1, 3)
        tk = solid.intersect(np.broadcast_to(origin, dirs.shape), dirs).reshape(r1 - r0, c1 - c0)
        sub_t, sub_ids = t[r0:r1, c0:c1], ids[r0:r1, c0:c1]
        closer = tk < sub_t
        sub_t[closer] = tk[closer]
        sub_ids[closer] = k
    return t, ids


def _shadowed(solids, points, hit_ids, sun):
    """Whether a ray from each of `points` (already off the surface) toward `sun` meets a
    solid other than the convex one it leaves (``hit_ids``)."""
    blocked = np.zeros(len(points), dtype=bool)
    if not len(points):
        return blocked
    # the rays are parallel: a solid can only block points whose projection along the
    # sun falls in its own projection's bounding rectangle, and that lie before it
    a = np.cross(sun, [0.0, 0.0, 1.0] if abs(sun[2]) < 0.9 else [1.0, 0.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(sun, a)
    pa, pb = points @ a, points @ b
    first, last = points.min(axis=0), points.max(axis=0)
    for k, solid in enumerate(solids):
        lo, hi = solid.aabb
        if np.any((sun > 0) & (hi < first)) or np.any((sun < 0) & (lo > last)):
            continue        # every point lies beyond the solid along the sun
        corners = _box_corners(lo, hi)
        ca, cb = corners @ a, corners @ b
        sel = np.flatnonzero((pa >= ca.min()) & (pa <= ca.max()))
        if not len(sel):
            continue
        p = points[sel]
        m = (pb[sel] >= cb.min()) & (pb[sel] <= cb.max()) & (hit_ids[sel] != k) & ~blocked[sel]
        for j in range(3):
            if sun[j] > 0:
                m &= p[:, j] <= hi[j]
            elif sun[j] < 0:
                m &= p[:, j] >= lo[j]
        sel, p = sel[m], p[m]
        if len(sel):
            hits = np.isfinite(solid.intersect(p, np.broadcast_to(sun, p.shape)))
            blocked[sel[hits]] = True
    return blocked


# --------------------------------------------------------------------------- #
# surfaces: normals and texture coordinates
# --------------------------------------------------------------------------- #
def surface_frame(solid, points):
    """Outward unit normals (n, 3), face coordinates uv (n, 2, metres from a corner of
    the face), face ids (n,) and the faces' sizes ``{face: (size_u, size_v)}`` of the
    points `points` on the surface of `solid`."""
    local = (points - solid.center) @ solid.rotation
    n = len(points)
    rows = np.arange(n)
    if isinstance(solid, Box):
        half = solid.half_extents
        x, y, z = local[:, 0], local[:, 1], local[:, 2]
        ax, ay, az = np.abs(x) / half[0], np.abs(y) / half[1], np.abs(z) / half[2]
        on_x = (ax >= ay) & (ax >= az)
        on_z = ~on_x & (az >= ay)
        axis = np.where(on_x, 0, np.where(on_z, 2, 1))
        sign = np.where(np.where(on_x, x, np.where(on_z, z, y)) >= 0, 1.0, -1.0)
        normal = solid.rotation.T[axis] * sign[:, None]
        uv = np.column_stack([np.where(on_x, y + half[1], x + half[0]),
                              np.where(on_z, y + half[1], z + half[2])])
        face = 2 * axis + (sign > 0)
        axes = {0: (1, 2), 1: (0, 2), 2: (0, 1)}
        sizes = {f: tuple(2 * half[list(axes[f // 2])]) for f in range(6)}
        return normal, uv, face, sizes
    elif isinstance(solid, Ellipsoid):
        r = solid.radii
        normal = local / (r * r)
        ring = 0.5 * (r[0] + r[1])
        uv = np.column_stack([(np.arctan2(local[:, 1], local[:, 0]) + np.pi) * ring,
                              local[:, 2] + r[2]])
        face = np.zeros(n, dtype=np.int64)
        sizes = {0: (2 * np.pi * ring, 2 * r[2])}
    elif isinstance(solid, Frustum):
        z, rho = local[:, 2], np.hypot(local[:, 0], local[:, 1])
        slope = (solid.radius_top - solid.radius_bottom) / solid.height
        side = np.abs(rho - (solid.radius_bottom + slope * z)) / np.hypot(1.0, slope)
        face = np.argmin(np.column_stack([np.abs(z), np.abs(z - solid.height), side]), axis=1)
        safe = np.where(rho > 0, rho, 1.0)
        normal = np.column_stack([local[:, 0] / safe, local[:, 1] / safe, np.full(n, -slope)])
        normal[face == 0] = (0.0, 0.0, -1.0)
        normal[face == 1] = (0.0, 0.0, 1.0)
        rmax = max(solid.radius_bottom, solid.radius_top)
        angle = (np.arctan2(local[:, 1], local[:, 0]) + np.pi) * rmax
        uv = np.where((face == 2)[:, None], np.column_stack([angle, z]),
                      local[:, :2] + rmax)
        sizes = {0: (2 * rmax, 2 * rmax), 1: (2 * rmax, 2 * rmax),
                 2: (2 * np.pi * rmax, solid.height)}
    else:   # any other solid: the gradient of its signed distance
        eps = 1e-6
        normal = np.column_stack([
            solid.signed_distance(points + eps * e) - solid.signed_distance(points - eps * e)
            for e in np.eye(3)]) @ solid.rotation
        uv = points[:, :2].copy()
        face = np.zeros(n, dtype=np.int64)
        sizes = {0: (np.inf, np.inf)}
    normal = normal @ solid.rotation.T
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    return normal, uv, face, sizes


def _render_view(scene, names, rig, origin, rotation, units):
    """Radiance (grey levels, float) of one camera, with its hit distances and ids."""
    t, ids = cast_image(scene.solids, origin, rotation, rig, units)
    h, w = ids.shape
    out = np.empty((h, w))
    # sky: brighter toward the horizon, a function of the direction only (no disparity)
    up = np.clip(units[..., 2], 0.0, 1.0)
    out[:] = SKY_HORIZON + (SKY_ZENITH - SKY_HORIZON) * up
    hit = np.flatnonzero(ids.ravel() >= 0)
    if not len(hit):
        return out, t, ids
    dirs = units.reshape(-1, 3)[hit]
    dist = t.ravel()[hit]
    hit_ids = ids.ravel()[hit]
    points = origin + dist[:, None] * dirs
    normals = np.empty_like(points)
    albedo = np.empty(len(hit))
    f = rig.focal_length
    depth = dist * (dirs @ rotation[:, 2])
    order = np.argsort(hit_ids, kind="stable")
    solids, starts = np.unique(hit_ids[order], return_index=True)
    for k, a, b in zip(solids, starts, list(starts[1:]) + [len(order)]):
        sel = order[a:b]
        normal, uv, face, sizes = surface_frame(scene.solids[k], points[sel])
        normals[sel] = normal
        d = dirs[sel]
        cos = np.abs(normal[:, 0] * d[:, 0] + normal[:, 1] * d[:, 1] + normal[:, 2] * d[:, 2])
        footprint = depth[sel] / f / np.sqrt(np.maximum(cos, 0.05))
        for fid in np.unique(face):
            on = np.flatnonzero(face == fid)
            albedo[sel[on]] = texture_albedo(names[k], uv[on], footprint[on],
                                             seed=1009 * int(k) + int(fid), size=sizes[fid])
    sun = rig.sun
    facing = normals @ sun
    light = np.full(len(hit), rig.ambient)
    toward = np.flatnonzero(facing > 0)
    if len(toward) and rig.ambient < 1:
        p = points[toward]
        p = p + normals[toward] * (_SHADOW_EPS * (1.0 + np.abs(origin).max() + dist.max()))
        lit = ~_shadowed(scene.solids, p, hit_ids[toward], sun)
        light[toward] += (1 - rig.ambient) * facing[toward] * lit
    out.ravel()[hit] = 255.0 * albedo * light
    return out, t, ids


# --------------------------------------------------------------------------- #
# sensor
# --------------------------------------------------------------------------- #
def _motion_kernel(length):
    """Normalised horizontal box kernel of `length` pixels (fractional ends)."""
    if length <= 1:
        return np.ones(1)
    m = int(2 * np.ceil((length - 1) / 2) + 1)
    kernel = np.ones(m)
    kernel[0] = kernel[-1] = (length - (m - 2)) / 2
    return kernel / kernel.sum()


def _sensor(image, rig, rng, *, right):
    """Apply the sensor's effects to a radiance image; uint8 out."""
    if rig.blur > 0:
        image = gaussian_filter(image, rig.blur, mode="nearest")
    if rig.motion_blur > 1:
        image = convolve1d(image, _motion_kernel(rig.motion_blur), axis=1, mode="nearest")
    if right:
        image = image * (1.0 + rig.gain) + rig.offset
        if rig.rectification:
            image = shift_image(image, (rig.rectification, 0.0), order=1, mode="nearest")
    if rig.noise > 0:
        image = image + rig.noise * rng.standard_normal(image.shape)
    image = np.clip(np.rint(image), 0, 255).astype(np.uint8)
    if rig.jpeg is not None:
        image = _jpeg(image, rig.jpeg)
    return image


def _jpeg(image, quality):
    try:
        import cv2
    except ImportError as exc:
        raise ImportError("StereoRig(jpeg=...) needs OpenCV (the cv2 module): "
                          "pip install occgp[stereo]") from exc
    ok, buf = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:  # pragma: no cover - OpenCV encodes any uint8 grey image
        raise RuntimeError("OpenCV could not encode the image as JPEG")
    return cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE)


# --------------------------------------------------------------------------- #
# validation
# --------------------------------------------------------------------------- #
def _check_scene(scene):
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be a Scene, got {type(scene).__name__}")


def _check_material(name, where):
    if not isinstance(name, str):
        raise TypeError(f"{where} must be a material name (str), got {type(name).__name__}")
    if name not in TEXTURES:
        raise ValueError(f"{where} must be one of {TEXTURES}, got {name!r}")
    return name


def _resolve_materials(scene, materials):
    names = scene_materials(scene)
    if materials is None:
        return names
    if isinstance(materials, Mapping):
        for key, name in materials.items():
            if not isinstance(key, str):
                raise TypeError(f"materials keys must be label patterns (str), "
                                f"got {type(key).__name__}")
            _check_material(name, f"materials[{key!r}]")
            matched = [i for i, label in enumerate(scene.labels)
                       if fnmatch.fnmatchcase(str(label), key)]
            if not matched:
                raise ValueError(f"materials: the pattern {key!r} matches no label of the scene "
                                 f"(labels: {sorted(set(scene.labels))})")
            for i in matched:
                names[i] = name
        return names
    if isinstance(materials, (str, bytes)) or not isinstance(materials, Sequence):
        raise TypeError(f"materials must be a sequence of material names, a dict from labels "
                        f"to names or None, got {type(materials).__name__}")
    if len(materials) != len(scene.solids):
        raise ValueError(f"materials must name one material per solid ({len(scene.solids)}), "
                         f"got {len(materials)}")
    return [_check_material(name, f"materials[{i}]") for i, name in enumerate(materials)]

