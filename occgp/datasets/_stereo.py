"""A noisy stereo camera orbiting tetromino layouts of boxes, with exact ground truth.

The data sets of Miao, Hunter and Georgilas (k-NN inverse sensor model): a ZED
stereo camera (1280 x 720 pixels) orbits, twice, a layout of boxes in the
shape of a free tetromino (I, O, T, L, S), plain or textured, in front of
buildings or in an open lot; the point clouds come from StereoSGBM disparity
maps and are voxel-filtered at 0.1 m. Here the geometry is analytic
(:class:`TetrominoScene`, a :class:`~occgp.datasets.Scene`), so occupancy
ground truth is exact, and the camera (:class:`StereoCamera`) reproduces the
errors that stereo matching makes:

* depth noise that grows with the square of the depth, as a constant
  disparity error does (``sigma(z) = depth_noise * z**2``);
* speckle: mismatched pixels whose depth falls anywhere between the camera
  and the surface;
* missing regions: connected blobs of pixels without a disparity, many on
  weakly textured (plain) boxes, few elsewhere.

:func:`simulate_stereo` flies the orbit and voxel-filters each frame
(:func:`voxel_filter`);
:func:`stereo_datasets` lists the 20 layouts x textures x environments at
several noise levels, lazily (in ``_stereo_sets.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.ndimage import gaussian_filter
from tqdm.auto import tqdm

from .._validation import (as_point, as_points, check_bool, check_choice, check_int, check_real,
                           check_seed)
from ._geometry import Box, rotation_matrix
from ._render import camera_rotation
from ..io._scan import Scan
from ._scenes import Scene

__all__ = ["TetrominoScene", "tetromino_scene", "StereoCamera", "simulate_stereo",
           "voxel_filter", "TETROMINOES", "ENVIRONMENTS"]

#: Cells (column, row) of the five free tetrominoes.
TETROMINOES = {
    "I": ((0, 0), (1, 0), (2, 0), (3, 0)),
    "O": ((0, 0), (1, 0), (0, 1), (1, 1)),
    "T": ((0, 0), (1, 0), (2, 0), (1, 1)),
    "L": ((0, 0), (1, 0), (2, 0), (2, 1)),
    "S": ((0, 0), (1, 0), (1, 1), (2, 1)),
}
ENVIRONMENTS = ("buildings", "open")

CELL = 0.8                      # tetromino cell pitch, metres
LOWER_HALF = (0.35, 0.35, 0.25)  # lower box of a cell: 0.7 x 0.7 x 0.5 m
UPPER_HALF = (0.25, 0.25, 0.2)   # upper box, stacked on it: 0.5 x 0.5 x 0.4 m
GROUND_HALF = 15.0               # the ground slab covers [-15, 15]^2
GROUND_THICKNESS = 0.15
SKY = 10.0                       # top of the scene's bounds, metres
BASE_MISSING = 0.1               # every pixel: lost at missing * BASE_MISSING, in blobs
MAX_PIXELS = 1920 * 1080
_BLOB = 0.025                    # blob size (Gaussian sigma) as a fraction of the width


class TetrominoScene(Scene):
    """A tetromino layout of box pairs on a ground plane (see :func:`tetromino_scene`).

    A :class:`~occgp.datasets.Scene` (exact occupancy, signed distance, ray
    casting) with what the stereo simulator needs to know about it.

    Attributes
    ----------
    layout : str
        ``"I"``, ``"O"``, ``"T"``, ``"L"`` or ``"S"``.
    texture : bool
        Whether the boxes are textured; plain boxes (False) lose many pixels
        in stereo matching (see :class:`StereoCamera`).
    environment : str
        ``"buildings"`` or ``"open"``.
    target_center : ndarray of shape (3,)
        Center of the layout at half its height, where the camera looks.
    targets : list of Box
        The boxes of the layout (the weakly textured surfaces when `texture`
        is False).
    """

    def __init__(self, solids, labels, *, layout, texture, environment, target_center):
        lo = np.array([-GROUND_HALF, -GROUND_HALF, 0.0])
        hi = np.array([GROUND_HALF, GROUND_HALF, SKY])
        ring = np.linspace(0, 2 * np.pi, 4, endpoint=False)
        positions = np.column_stack([4 * np.cos(ring), 4 * np.sin(ring), np.full(4, 1.5)])
        positions[:, :2] += target_center[:2]
        super().__init__(solids, labels, (lo, hi),
                         f"tetromino_{layout}_{'textured' if texture else 'plain'}_{environment}",
                         positions, np.pi, wall_thickness=GROUND_THICKNESS)
        self.layout = layout
        self.texture = texture
        self.environment = environment
        self.target_center = np.asarray(target_center, dtype=np.float64)
        self.targets = [s for s, name in zip(self.solids, self.labels) if name.startswith("box")]


def tetromino_scene(layout: str = "I", *, texture: bool = True, environment: str = "buildings",
                    seed: int = 0) -> TetrominoScene:
    """Box pairs in the shape of a tetromino on a ground plane, with exact ground truth.

    Each of the tetromino's 4 cells (0.8 m apart) holds a pair of stacked
    boxes: a 0.7 x 0.7 x 0.5 m box on the ground and a 0.5 x 0.5 x 0.4 m box
    centered on top of it (0.9 m in all). The layout is centered on the origin.
    The ground is a 0.15 m slab under ``z = 0`` covering ``[-15, 15]^2``.
    With ``environment="buildings"``, three building blocks stand around the
    layout (bearings 120 degrees apart, turned and jittered by the seed):
    near facades 5 to 7 m from the center, 6 to 10 m wide, 3 to 5 m deep and
    4 to 9 m tall. ``"open"`` is the ground alone (an open lot).

    Parameters
    ----------
    layout : {"I", "O", "T", "L", "S"}, default="I"
        The free tetromino.
    texture : bool, default=True
        Textured boxes (the paper's Voronoi pattern) or plain ones (weak
        texture, which the camera partly fails to match).
    environment : {"buildings", "open"}, default="buildings"
    seed : int, default=0
        Places the buildings (deterministically); unused for ``"open"``.

    Returns
    -------
    scene : TetrominoScene
        Solids labelled ``"ground"``, ``"box_<cell>_lower"``,
        ``"box_<cell>_upper"`` and ``"building_<k>"``.

    Raises
    ------
    ValueError
        For an unknown `layout` or `environment`, or a negative `seed`.
    TypeError
        If `texture` is not a bool or `seed` not an int.

    Examples
    --------
    >>> scene = tetromino_scene("O", texture=False, environment="open")
    >>> scene.name, len(scene.targets)
    ('tetromino_O_plain_open', 8)
    >>> scene.occupancy([[0.4, 0.4, 0.7], [0.4, 0.4, 1.0], [3.0, 3.0, -0.05]]).tolist()
    [True, False, True]
    """
    layout = check_choice(layout, "layout", tuple(TETROMINOES))
    texture = check_bool(texture, "texture")
    environment = check_choice(environment, "environment", ENVIRONMENTS)
    seed = check_int(seed, "seed", low=0)
    cells = np.array(TETROMINOES[layout], dtype=np.float64) * CELL
    cells -= cells.mean(axis=0)
    solids = [Box([0.0, 0.0, -GROUND_THICKNESS / 2],
                  [GROUND_HALF, GROUND_HALF, GROUND_THICKNESS / 2])]
    labels = ["ground"]
    lower_h, upper_h = LOWER_HALF[2], UPPER_HALF[2]
    for i, (x, y) in enumerate(cells):
        solids += [Box([x, y, lower_h], LOWER_HALF),
                   Box([x, y, 2 * lower_h + upper_h], UPPER_HALF)]
        labels += [f"box_{i}_lower", f"box_{i}_upper"]
    if environment == "buildings":
        rng = np.random.default_rng([seed, 1013])
        bearings = rng.uniform(0, 2 * np.pi) + np.radians(
            120 * np.arange(3) + rng.uniform(-20, 20, 3))
        for k, bearing in enumerate(bearings):
            near, width = rng.uniform(5.0, 7.0), rng.uniform(6.0, 10.0)
            depth, tall = rng.uniform(3.0, 5.0), rng.uniform(4.0, 9.0)
            r = near + depth / 2
            solids.append(Box([r * np.cos(bearing), r * np.sin(bearing), tall / 2],
                              [depth / 2, width / 2, tall / 2], rotation_matrix(yaw=bearing)))
            labels.append(f"building_{k}")
    center = np.array([0.0, 0.0, lower_h + upper_h])
    return TetrominoScene(solids, labels, layout=layout, texture=texture,
                          environment=environment, target_center=center)


@dataclass(frozen=True)
class StereoCamera:
    """A pinhole stereo camera with the error model of stereo matching.

    The paper's camera is a ZED at 1280 x 720 pixels with a 90 degree
    horizontal field of view; the default here is that image downscaled by 4
    (320 x 180), for speed (point clouds are voxel-filtered at 0.1 m anyway).
    Pixels are square; one ray passes through the center of each pixel.

    Error model, per frame (see :meth:`capture`):

    * **Depth noise.** A pixel whose ray hits a surface at depth ``z`` (along
      the optical axis) measures ``z + sigma(z) * N(0, 1)`` with
      ``sigma(z) = depth_noise * z**2`` (a constant disparity error); the
      point moves along its ray.
    * **Speckle.** Each returning pixel is, with probability `speckle`, a
      mismatch: its range is ``U(0, 1)`` times the true range, so the point
      lies uniformly between the camera and the surface (no depth noise on
      top).
    * **Missing regions.** Pixels without a disparity come in connected
      blobs (the top values of a smooth random field, Gaussian-filtered with
      sigma 2.5% of the image width). Every scene loses a fraction
      ``missing * BASE_MISSING`` (``BASE_MISSING = 0.1``) of all pixels
      (glare, occlusion edges); a scene with ``texture=False`` loses, in
      addition, a fraction `missing` of the pixels on its boxes (weak
      texture). ``missing=0`` loses nothing.
    * A pixel returns only when its true depth is at most `max_depth` and its
      measured depth lies in ``(0, max_depth]``.

    Parameters
    ----------
    width, height : int, default=320, 180
        Image size in pixels, each at least 1, at most 1920 x 1080 in all.
    fov : float, default=90.0
        Horizontal field of view, degrees, in (0, 180).
    max_depth : float, default=8.0
        Longest depth that gives a return, metres, in (0, 1000].
    depth_noise : float, default=0.01
        Standard deviation of the depth at 1 m, metres, in [0, 1].
    speckle : float, default=0.02
        Fraction of returning pixels that are outliers, in [0, 1].
    missing : float, default=0.1
        Fraction of weak-texture pixels lost, in [0, 1].

    Attributes
    ----------
    n_pixels : int
    focal_length : float
        In pixels, ``width / 2 / tan(fov / 2)``.

    Examples
    --------
    >>> cam = StereoCamera(width=32, height=18)
    >>> cam.n_pixels, round(cam.focal_length, 6)
    (576, 16.0)
    """

    width: int = 320
    height: int = 180
    fov: float = 90.0
    max_depth: float = 8.0
    depth_noise: float = 0.01
    speckle: float = 0.02
    missing: float = 0.1

    def __post_init__(self) -> None:
        fix = lambda name, value: object.__setattr__(self, name, value)  # noqa: E731
        fix("width", check_int(self.width, "width", low=1))
        fix("height", check_int(self.height, "height", low=1))
        if self.width * self.height > MAX_PIXELS:
            raise ValueError(f"width * height must be at most {MAX_PIXELS} pixels (1920 x 1080), "
                             f"got {self.width} x {self.height}")
        fix("fov", check_real(self.fov, "fov", low=0.0, high=180.0))
        fix("max_depth", check_real(self.max_depth, "max_depth", low=0.0, high=1000.0,
                                    high_open=False))
        for name in ("depth_noise", "speckle", "missing"):
            fix(name, check_real(getattr(self, name), name, low=0.0, high=1.0,
                                 low_open=False, high_open=False))

    @property
    def n_pixels(self) -> int:
        """Pixels per image, ``width * height``."""
        return self.width * self.height

    @property
    def focal_length(self) -> float:
        """Focal length in pixels."""
        return float(self.width / 2 / np.tan(np.radians(self.fov) / 2))

    def _rays(self, position, look_at):
        """Unit ray directions, row-major over the image, and the optical axis."""
        right, down, forward = camera_rotation(position, look_at).T
        f = self.focal_length
        u = (np.arange(self.width) + 0.5 - self.width / 2) / f
        v = (np.arange(self.height) + 0.5 - self.height / 2) / f
        v, u = np.meshgrid(v, u, indexing="ij")
        dirs = forward + u.reshape(-1, 1) * right + v.reshape(-1, 1) * down
        return dirs / np.linalg.norm(dirs, axis=1, keepdims=True), forward

    def capture(self, scene: Scene, position: ArrayLike, look_at: ArrayLike, *,
                seed: int | np.random.Generator | None = 0) -> NDArray[np.float64]:
        """The point cloud of one frame, before any voxel filter.

        Parameters
        ----------
        scene : Scene
            What the camera sees. Its boxes are weakly textured when it has
            ``texture=False`` and ``targets`` (a :class:`TetrominoScene`);
            any other scene counts as textured.
        position : array-like of shape (3,)
            Camera center in the world frame, metres; must lie in free space.
        look_at : array-like of shape (3,)
            A point on the optical axis; the image's up is toward +z.
        seed : int, numpy.random.Generator or None, default=0
            Seeds the noise, speckle and missing regions of the frame (None:
            fresh entropy, not reproducible).

        Returns
        -------
        points : ndarray of shape (n_returns, 3)
            Measured points of the returning pixels, row-major over the
            image, in the world frame.

        Raises
        ------
        TypeError
            If `scene` is not a Scene.
        ValueError
            If `position` or `look_at` is not a finite point of shape (3,),
            `position` lies inside a solid, `look_at` equals `position` or
            lies straight above or below it.

        Examples
        --------
        >>> cam = StereoCamera(width=32, height=18, depth_noise=0.0, speckle=0.0, missing=0.0)
        >>> scene = tetromino_scene("O")
        >>> points = cam.capture(scene, [4.0, 0.0, 1.5], [0.0, 0.0, 0.45])
        >>> points.shape        # of 576 pixels, the rest see sky or lie beyond max_depth
        (403, 3)
        >>> bool(np.abs(scene.signed_distance(points)).max() < 1e-9)   # on the surfaces
        True
        """
        check_scene(scene)
        position = as_point(position, "position")
        look_at = as_point(look_at, "look_at")
        if scene.occupancy(position[None])[0]:
            raise ValueError(f"position {position.tolist()} lies inside a solid; the camera "
                             "must stand in free space")
        rng = check_seed(seed)
        dirs, forward = self._rays(position, look_at)
        return self._capture(scene, position, dirs, forward, rng)

    def _capture(self, scene, position, dirs, forward, rng):
        n = len(dirs)
        cos = dirs @ forward
        dist, hit = scene.ray_cast(position, dirs, self.max_depth / cos.min())
        # every draw is made for every pixel, so the streams do not depend on the scene
        base_field = gaussian_filter(rng.standard_normal((self.height, self.width)),
                                     max(1.0, _BLOB * self.width)).ravel()
        weak_field = gaussian_filter(rng.standard_normal((self.height, self.width)),
                                     max(1.0, _BLOB * self.width)).ravel()
        is_speckle = rng.random(n) < self.speckle
        fraction = rng.random(n)
        noise = rng.standard_normal(n)

        z = dist * cos
        ok = hit & (z <= self.max_depth)
        lost = _top(base_field, np.ones(n, dtype=bool), self.missing * BASE_MISSING)
        targets = getattr(scene, "targets", [])
        if self.missing > 0 and getattr(scene, "texture", True) is False and targets:
            origins = np.broadcast_to(position, dirs.shape)
            t_target = np.min([s.intersect(origins, dirs) for s in targets], axis=0)
            lost |= _top(weak_field, ok & (t_target <= dist), self.missing)
        ok &= ~lost

        z_meas = z + self.depth_noise * z * z * noise
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(is_speckle, fraction * dist, dist * z_meas / z)
        z_meas = np.where(is_speckle, fraction * z, z_meas)
        ok &= (z_meas > 0) & (z_meas <= self.max_depth)
        return position + t[ok, None] * dirs[ok]


def _top(field, candidates, fraction):
    """Mask of the ``round(fraction * n)`` candidates with the largest field values."""
    idx = np.flatnonzero(candidates)
    k = int(round(fraction * len(idx)))
    mask = np.zeros(len(field), dtype=bool)
    if k:
        mask[idx[np.argpartition(field[idx], len(idx) - k)[len(idx) - k:]]] = True
    return mask


def check_scene(scene):
    """Raise TypeError unless `scene` is a :class:`~occgp.datasets.Scene`."""
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be a Scene, got {type(scene).__name__}")


def voxel_filter(points: ArrayLike, voxel: float = 0.1) -> NDArray[np.float64]:
    """One point per occupied voxel: the centroid of the points in it (as PCL's VoxelGrid).

    Voxels are the cubes ``[i, i + 1) * voxel`` (per axis) aligned on the
    origin, the cells of an octree of resolution `voxel`. A centroid that
    rounding would move out of its voxel is replaced by the voxel's first
    point, so every voxel keeps exactly one point.

    Parameters
    ----------
    points : array-like of shape (n_points, 3)
        Finite points, metres.
    voxel : float, default=0.1
        Voxel side, metres, in [1e-6, 1000].

    Returns
    -------
    filtered : ndarray of shape (n_voxels, 3)
        One point per occupied voxel, sorted by voxel.

    Raises
    ------
    ValueError
        If `points` is not a finite array of shape (n_points, 3), `voxel` lies
        outside [1e-6, 1000], or a point is so far out (``|x| / voxel >=
        2**62``) that its voxel index would overflow.

    Examples
    --------
    >>> voxel_filter([[0.01, 0.0, 0.0], [0.03, 0.0, 0.0], [0.5, 0.0, 0.0]], 0.1).tolist()
    [[0.02, 0.0, 0.0], [0.5, 0.0, 0.0]]
    """
    points = as_points(points, "points")
    voxel = _check_voxel(voxel)
    if len(points) and np.abs(points).max() / voxel >= 2.0 ** 62:
        raise ValueError(f"points must satisfy |x| / voxel < 2**62 (voxel indices are int64), "
                         f"got |x| up to {np.abs(points).max():g} with voxel={voxel:g}")
    return _voxel_filter(points, voxel)


def _check_voxel(voxel):
    return check_real(voxel, "voxel", low=1e-6, high=1000.0, low_open=False, high_open=False)


def _voxel_filter(points, voxel):
    if len(points) == 0:
        return points
    keys = np.floor(points / voxel).astype(np.int64)
    lo = keys.min(axis=0)
    span = keys.max(axis=0) - lo + 1
    if float(np.prod(span.astype(np.float64))) < 2.0 ** 62:   # one int64 per voxel: fast
        flat = ((keys[:, 0] - lo[0]) * span[1] + keys[:, 1] - lo[1]) * span[2] + keys[:, 2] - lo[2]
        _, first, inverse, counts = np.unique(flat, return_index=True, return_inverse=True,
                                              return_counts=True)
        uniq = keys[first]
    else:
        uniq, first, inverse, counts = np.unique(keys, axis=0, return_index=True,
                                                 return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    sums = np.column_stack([np.bincount(inverse, points[:, k], len(uniq)) for k in range(3)])
    centroids = sums / counts[:, None]
    moved = (np.floor(centroids / voxel).astype(np.int64) != uniq).any(axis=1)
    centroids[moved] = points[first[moved]]
    return centroids


def orbit_positions(scene, n_frames, orbits, radius, height):
    """Camera centers of the orbit of :func:`simulate_stereo` (checked arguments) and the
    point they look at: ``(positions of shape (n_frames * orbits, 3), center)``."""
    center = getattr(scene, "target_center", None)
    if center is None:
        lo, hi = scene.interior_bounds
        center = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2] + 0.5])
    frame = np.arange(n_frames * orbits)
    azimuth = 2 * np.pi * (frame % n_frames + (frame // n_frames) / orbits) / n_frames
    positions = np.column_stack([center[0] + radius * np.cos(azimuth),
                                 center[1] + radius * np.sin(azimuth),
                                 np.full(len(frame), height)])
    inside = scene.occupancy(positions)
    if inside.any():
        i = int(np.flatnonzero(inside)[0])
        raise ValueError(f"the camera position of frame {i}, {positions[i].tolist()}, lies "
                         "inside a solid; choose radius and height in free space")
    return positions, np.asarray(center, dtype=np.float64)


def simulate_stereo(scene: Scene, camera: StereoCamera = StereoCamera(), *, n_frames: int = 40,
                    orbits: int = 2, radius: float = 4.0, height: float = 1.5,
                    voxel: float | None = 0.1, seed: int = 0,
                    progress: bool | None = False) -> list[Scan]:
    """Fly a stereo camera around a scene's layout and return its voxel-filtered clouds.

    The camera circles the layout's center (``scene.target_center``; for
    another :class:`~occgp.datasets.Scene`, the center of its interior at
    0.5 m above its floor) `orbits` times at `radius` and `height`, with
    `n_frames` frames per orbit, looking at the center. Frame ``i`` of orbit
    ``o`` is at azimuth ``2 pi (i + o / orbits) / n_frames``: later orbits
    interleave with the first. Each frame is captured with
    :meth:`StereoCamera.capture` (one ray per pixel, noise, speckle, missing
    regions, invalid pixels dropped) and voxel-filtered: one point per
    occupied voxel of side `voxel` (aligned on the origin, as an octree's
    cells), the centroid of the frame's points in it.

    Parameters
    ----------
    scene : Scene
        Usually a :func:`tetromino_scene`.
    camera : StereoCamera, default=StereoCamera()
    n_frames : int, default=40
        Frames per orbit, in [1, 10000].
    orbits : int, default=2
        Number of orbits, in [1, 100].
    radius : float, default=4.0
        Orbit radius, metres, in (0, 1000].
    height : float, default=1.5
        Camera height (z), metres, in [-1000, 1000].
    voxel : float or None, default=0.1
        Voxel filter size, metres, in [1e-6, 1000]; None keeps every point.
    seed : int, default=0
        Frame ``f`` (orbit-major) draws from ``numpy.random.default_rng([seed, f])``:
        the result is deterministic for a given seed.
    progress : bool or None, default=False
        Show a progress bar over frames; None: only in an interactive terminal.

    Returns
    -------
    scans : list of Scan
        ``n_frames * orbits`` scans, ``Scan(points, origin)`` with the camera
        center as origin.

    Raises
    ------
    TypeError
        If `scene` is not a Scene, `camera` not a StereoCamera, or a count or
        size has the wrong type.
    ValueError
        For an argument out of its range, or a camera position inside a
        solid.

    See Also
    --------
    stereo_datasets : The 20 layouts x textures x environments at several noise levels.

    Examples
    --------
    >>> scans = simulate_stereo(tetromino_scene("T"), StereoCamera(32, 18), n_frames=3)
    >>> len(scans), scans[0].origin.round(6).tolist()
    (6, [4.0, 0.0, 1.5])
    >>> keys = np.floor(scans[0].points / 0.1)
    >>> len(np.unique(keys, axis=0)) == len(keys)     # one point per voxel
    True
    """
    check_scene(scene)
    if not isinstance(camera, StereoCamera):
        raise TypeError(f"camera must be a StereoCamera, got {type(camera).__name__}")
    n_frames = check_int(n_frames, "n_frames", low=1, high=10_000)
    orbits = check_int(orbits, "orbits", low=1, high=100)
    radius = check_real(radius, "radius", low=0.0, high=1000.0, high_open=False)
    height = check_real(height, "height", low=-1000.0, high=1000.0, low_open=False,
                        high_open=False)
    if voxel is not None:
        voxel = _check_voxel(voxel)
    seed = check_int(seed, "seed", low=0)
    positions, center = orbit_positions(scene, n_frames, orbits, radius, height)
    scans = []
    for f, position in enumerate(tqdm(positions, unit="frame", desc="simulating stereo",
                                      disable=None if progress is None else not progress)):
        dirs, forward = camera._rays(position, center)
        points = camera._capture(scene, position, dirs, forward,
                                 np.random.default_rng([seed, f]))
        if voxel is not None:
            points = _voxel_filter(points, voxel)
        scans.append(Scan(points, position.copy()))
    return scans
