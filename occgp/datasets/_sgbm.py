"""Point clouds from rendered stereo pairs matched by OpenCV's StereoSGBM.

The k-NN paper's pipeline on exact synthetic ground truth: a rectified stereo
pair is rendered per keyframe (:func:`~occgp.datasets.render_stereo`), matched
by the real semi-global block matcher of OpenCV with one of the authors' 1,600
parameter sets (:data:`SGBM_GRID`), and each valid disparity within the
camera's ``max_depth`` becomes a point, placed with the keyframe's pose
(optionally perturbed, as a SLAM estimate would be) and voxel-filtered at
0.1 m in the world frame. OpenCV is the optional extra ``occgp[stereo]``
(``opencv-python-headless``); the renderer itself needs only numpy and scipy.
The 20 rendered data sets built on this pipeline are in ``_rendered_sets.py``.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from contextlib import contextmanager
from typing import Any, NamedTuple

import numpy as np
from joblib import Parallel, delayed
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation  # type: ignore[import-untyped]
from threadpoolctl import threadpool_limits

from .._validation import (as_point, as_points, check_bool, check_int,
                           check_n_jobs, check_real)
from ._render import StereoPair, StereoRig, render_stereo
from ..io._scan import Scan
from ._labels import cell_labels
from ._stereo import check_scene, orbit_positions, voxel_filter

__all__ = ["SGBM_GRID", "SGBM_DEFAULT", "sgbm_parameter_sets", "match_stereo",
           "disparity_to_points", "render_orbit", "stereo_scans", "naive_fdr",
           "rank_sgbm_sets", "PointErrors", "point_errors"]

#: The authors' StereoSGBM parameter grid (4 x 2 x 5 x 4 x 5 x 2 = 1,600 sets); every set
#: also has ``numDisparities=80``, ``mode=STEREO_SGBM_MODE_HH``, ``P1 = 8 blockSize**2``
#: and ``P2 = 32 blockSize**2`` (grey images). OpenCV treats ``disp12MaxDiff <= 0`` as 1
#: (the check is then off), so the two values 0 and 1 differ.
SGBM_GRID: dict[str, tuple[int, ...]] = {
    "blockSize": (3, 7, 11, 15),
    "disp12MaxDiff": (0, 1),
    "preFilterCap": (10, 20, 30, 40, 50),
    "uniquenessRatio": (5, 15, 25, 35),
    "speckleWindowSize": (200, 400, 600, 800, 1000),
    "speckleRange": (1, 2),
}
#: The parameter set :func:`match_stereo` uses when given none (a middle one of the grid).
SGBM_DEFAULT: dict[str, int] = {"blockSize": 7, "disp12MaxDiff": 1, "preFilterCap": 30,
                                "uniquenessRatio": 15, "speckleWindowSize": 600,
                                "speckleRange": 2}
NUM_DISPARITIES = 80


def _cv2():
    try:
        import cv2  # type: ignore[import-not-found]
    except ImportError as exc:  # pragma: no cover - the extra is installed by make test
        raise ImportError("stereo matching needs OpenCV: pip install 'occgp[stereo]' "
                          "(opencv-python-headless)") from exc
    return cv2


@contextmanager
def _one_thread():
    """One OpenCV and one BLAS thread inside (a worker of a parallel loop)."""
    cv2 = _cv2()
    before = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        with threadpool_limits(1):
            yield
    finally:
        cv2.setNumThreads(before)


def sgbm_parameter_sets(n: int | None = None, *, seed: int = 0) -> list[dict[str, int]]:
    """The authors' StereoSGBM parameter sets, or a seeded subset of them.

    Parameters
    ----------
    n : int or None, default=None
        None: all 1,600 sets, in the grid's order (:data:`SGBM_GRID`, the last
        key varying fastest). An int in [1, 1600]: `n` sets drawn without
        replacement by ``numpy.random.default_rng(seed)``, in grid order (a
        uniform sample keeps the spread of the full grid's ranking).
    seed : int, default=0

    Returns
    -------
    sets : list of dict
        Each maps the :data:`SGBM_GRID` names to ints.

    Raises
    ------
    TypeError, ValueError
        If `n` or `seed` is not an int or out of range.

    Examples
    --------
    >>> sets = sgbm_parameter_sets()
    >>> len(sets), sets[0]["blockSize"], sets[-1]["speckleWindowSize"]
    (1600, 3, 1000)
    >>> len(sgbm_parameter_sets(16, seed=1))
    16
    """
    names = list(SGBM_GRID)
    sets = [dict(zip(names, values)) for values in itertools.product(*SGBM_GRID.values())]
    if n is None:
        return sets
    n = check_int(n, "n", low=1, high=len(sets))
    seed = check_int(seed, "seed", low=0)
    pick = np.sort(np.random.default_rng(seed).choice(len(sets), n, replace=False))
    return [sets[i] for i in pick]


def _check_params(params):
    if params is None:
        return dict(SGBM_DEFAULT)
    if not isinstance(params, Mapping):
        raise TypeError(f"params must be a dict of StereoSGBM parameters, "
                        f"got {type(params).__name__}")
    unknown = sorted(set(params) - set(SGBM_GRID))
    if unknown:
        raise ValueError(f"params holds unknown StereoSGBM parameters {unknown}; "
                         f"known: {sorted(SGBM_GRID)}")
    out = dict(SGBM_DEFAULT)
    bounds = {"blockSize": (1, 255), "disp12MaxDiff": (-1, 10_000), "preFilterCap": (1, 63),
              "uniquenessRatio": (0, 100), "speckleWindowSize": (0, 100_000),
              "speckleRange": (0, 10_000)}
    for name, value in params.items():
        low, high = bounds[name]
        out[name] = check_int(value, f"params[{name!r}]", low=low, high=high)
    if out["blockSize"] % 2 == 0:
        raise ValueError(f"params['blockSize'] must be odd, got {out['blockSize']}")
    return out


def _check_image(image, name):
    image = np.asarray(image)
    if image.dtype != np.uint8:
        raise TypeError(f"{name} must be a uint8 grey image, got dtype {image.dtype}")
    if image.ndim != 2 or min(image.shape) < 1:
        raise ValueError(f"{name} must be a 2D grey image of shape (height, width), "
                         f"got shape {image.shape}")
    return np.ascontiguousarray(image)


def match_stereo(left: ArrayLike, right: ArrayLike,
                 params: Mapping[str, int] | None = None) -> NDArray[np.float32]:
    """Disparity of a rectified grey pair by OpenCV's StereoSGBM (the authors' settings).

    ``cv2.StereoSGBM_create(minDisparity=0, numDisparities=80, blockSize=b,
    P1=8 b**2, P2=32 b**2, mode=STEREO_SGBM_MODE_HH, **params)``; OpenCV's
    fixed-point result (16 x the disparity) is divided by 16.

    Parameters
    ----------
    left, right : array-like of uint8, shape (height, width)
        The rectified pair; a point of the scene at left column ``u`` lies at
        right column ``u - d``.
    params : dict or None, default=None
        Any of the :data:`SGBM_GRID` names (ints; `blockSize` odd); the others
        take :data:`SGBM_DEFAULT`.

    Returns
    -------
    disparity : ndarray of float32, shape (height, width)
        Pixels; NaN where the matcher found none (or found 0, a point at
        infinity).

    Raises
    ------
    TypeError
        If an image is not uint8 or a parameter not an int.
    ValueError
        If the images differ in shape or are not 2D, or a parameter is
        unknown or out of range.
    ImportError
        Without OpenCV (the ``stereo`` extra).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> left = rng.integers(0, 256, (40, 200), dtype=np.uint8)
    >>> right = np.roll(left, -12, axis=1)           # every point 12 px to the left
    >>> d = match_stereo(left, right, {"blockSize": 5})
    >>> float(np.nanmedian(d))
    12.0
    """
    left = _check_image(left, "left")
    right = _check_image(right, "right")
    if left.shape != right.shape:
        raise ValueError(f"left and right must have one shape, got {left.shape} and "
                         f"{right.shape}")
    p = _check_params(params)
    cv2 = _cv2()
    b = p["blockSize"]
    matcher = cv2.StereoSGBM_create(minDisparity=0, numDisparities=NUM_DISPARITIES,
                                    P1=8 * b * b, P2=32 * b * b,
                                    mode=cv2.STEREO_SGBM_MODE_HH, **p)
    raw = matcher.compute(left, right)
    disparity = raw.astype(np.float32) / np.float32(16.0)
    disparity[raw <= 0] = np.nan
    return disparity


def _check_rig(rig):
    if not isinstance(rig, StereoRig):
        raise TypeError(f"rig must be a StereoRig, got {type(rig).__name__}")
    return rig


def disparity_to_points(disparity: ArrayLike, rig: StereoRig, position: ArrayLike,
                        rotation: ArrayLike, *,
                        max_depth: float | None = None) -> NDArray[np.float64]:
    """Triangulate a left-camera disparity map into world points.

    A pixel ``(v, u)`` (row, column; center at ``u + 0.5``) with disparity
    ``d`` lies at depth ``z = f B / d`` on its ray, ``x = (u + 0.5 - W/2) z /
    f``, ``y = (v + 0.5 - H/2) z / f`` in the camera frame (x right, y down, z
    forward), then ``position + rotation @ (x, y, z)``.

    Parameters
    ----------
    disparity : array-like of shape (rig.height, rig.width)
        Pixels; NaN or non-positive: no point.
    rig : StereoRig
        Focal length `f`, baseline `B` and image size.
    position : array-like of shape (3,)
        Left camera center, world frame, metres.
    rotation : array-like of shape (3, 3)
        Camera-to-world rotation (columns: the camera's x, y, z axes).
    max_depth : float or None, default=None
        Keep points with ``z <= max_depth`` (metres); None: ``rig.max_depth``.

    Returns
    -------
    points : ndarray of shape (n_points, 3)
        Row-major over the image.

    Raises
    ------
    TypeError
        If `rig` is not a StereoRig.
    ValueError
        If a shape is wrong, a value not finite, or `max_depth` not positive.
    """
    rig = _check_rig(rig)
    d = np.asarray(disparity, dtype=np.float64)
    if d.shape != (rig.height, rig.width):
        raise ValueError(f"disparity must be of shape {(rig.height, rig.width)} (the rig's "
                         f"image), got {d.shape}")
    position = as_point(position, "position")
    rotation = np.asarray(rotation, dtype=np.float64)
    if rotation.shape != (3, 3) or not np.isfinite(rotation).all():
        raise ValueError(f"rotation must be a finite (3, 3) matrix, got shape {rotation.shape}")
    max_depth = rig.max_depth if max_depth is None else check_real(
        max_depth, "max_depth", low=0.0, high=1e6, high_open=False)
    f = rig.focal_length
    with np.errstate(divide="ignore", invalid="ignore"):
        z = f * rig.baseline / d
    v, u = np.nonzero((d > 0) & (z <= max_depth))
    z = z[v, u]
    cam = np.column_stack([(u + 0.5 - rig.width / 2) * z / f,
                           (v + 0.5 - rig.height / 2) * z / f, z])
    return position + cam @ rotation.T


def render_orbit(scene, rig: StereoRig | None = None, *, n_frames: int = 40, orbits: int = 2,
                 radius: float = 4.0, height: float = 1.5, seed: int = 0, truth: bool = False,
                 n_jobs: int | None = None) -> list[StereoPair]:
    """Render the stereo pairs of the keyframes of an orbit around a scene.

    The orbit of :func:`~occgp.datasets.simulate_stereo` (`orbits` circles of
    `n_frames` keyframes at `radius` and `height` around the layout's center,
    looking at it); keyframe ``i`` renders with the ``i``-th word of
    ``numpy.random.SeedSequence(seed).generate_state(n_frames * orbits)`` as
    its seed.

    Parameters
    ----------
    scene : Scene
        Usually a :func:`~occgp.datasets.tetromino_scene`.
    rig : StereoRig or None, default=None
        None: ``StereoRig()`` (640 x 360, f = 337.2 px, baseline 0.12 m).
    n_frames : int, default=40
        Keyframes per orbit, in [1, 10000].
    orbits : int, default=2
        In [1, 100].
    radius, height : float, default=4.0, 1.5
        Metres.
    seed : int, default=0
        Sensor noise of the renderer.
    truth : bool, default=False
        Also render the true depth and solid of each left pixel.
    n_jobs : int or None, default=None
        Worker processes (joblib; one BLAS thread each); None: one.

    Returns
    -------
    pairs : list of StereoPair
        ``n_frames * orbits`` pairs, in orbit order.

    Raises
    ------
    TypeError, ValueError
        As :func:`~occgp.datasets.simulate_stereo` and
        :func:`~occgp.datasets.render_stereo`.
    """
    check_scene(scene)
    rig = StereoRig() if rig is None else _check_rig(rig)
    n_frames = check_int(n_frames, "n_frames", low=1, high=10_000)
    orbits = check_int(orbits, "orbits", low=1, high=100)
    radius = check_real(radius, "radius", low=0.0, high=1000.0, high_open=False)
    height = check_real(height, "height", low=-1000.0, high=1000.0, low_open=False,
                        high_open=False)
    seed = check_int(seed, "seed", low=0)
    truth = check_bool(truth, "truth")
    n_jobs = check_n_jobs(n_jobs)
    positions, center = orbit_positions(scene, n_frames, orbits, radius, height)
    seeds = np.random.SeedSequence(seed).generate_state(len(positions))
    tasks = [delayed(_render_frame)(scene, rig, p, center, int(s), truth)
             for p, s in zip(positions, seeds)]
    return Parallel(n_jobs=n_jobs)(tasks)


def _render_frame(scene, rig, position, look_at, seed, truth):
    with threadpool_limits(1):
        return render_stereo(scene, position, look_at, rig, seed=seed, truth=truth)


def _check_pose_noise(pose_noise):
    if pose_noise is None:
        return 0.0, 0.0
    try:
        t, r = pose_noise
    except (TypeError, ValueError):
        raise TypeError("pose_noise must be None or a (metres, degrees) pair") from None
    return (check_real(t, "pose_noise[0]", low=0.0, high=10.0, low_open=False,
                       high_open=False),
            check_real(r, "pose_noise[1]", low=0.0, high=90.0, low_open=False,
                       high_open=False))


def _small_rotation(rng, sigma_deg):
    """A rotation by a Gaussian rotation vector of standard deviation `sigma_deg` per axis."""
    return Rotation.from_rotvec(np.radians(sigma_deg) * rng.standard_normal(3)).as_matrix()


def _frame_points(pair, rig, params, voxel, pose_noise, seed):
    with _one_thread():
        disparity = match_stereo(pair.left, pair.right, params)
    position, rotation = pair.position, pair.rotation
    if pose_noise != (0.0, 0.0):
        rng = np.random.default_rng(seed)
        position = position + pose_noise[0] * rng.standard_normal(3)
        rotation = _small_rotation(rng, pose_noise[1]) @ rotation
    points = disparity_to_points(disparity, rig, position, rotation)
    if voxel is not None:
        points = voxel_filter(points, voxel)
    return Scan(points, np.array(position, dtype=np.float64))


def _check_pairs(pairs):
    if isinstance(pairs, StereoPair):
        raise TypeError("pairs must be a sequence of StereoPair, got one StereoPair")
    pairs = list(pairs)
    for i, p in enumerate(pairs):
        if not isinstance(p, StereoPair):
            raise TypeError(f"pairs[{i}] must be a StereoPair, got {type(p).__name__}")
    return pairs


def stereo_scans(pairs: Sequence[StereoPair], rig: StereoRig,
                 params: Mapping[str, int] | None = None, *, voxel: float | None = 0.1,
                 pose_noise: tuple[float, float] | None = None, seed: int = 0,
                 n_jobs: int | None = None) -> list[Scan]:
    """Match rendered pairs with StereoSGBM and return one voxel-filtered cloud per keyframe.

    Each pair is matched (:func:`match_stereo`, one OpenCV thread per worker),
    its valid disparities within ``rig.max_depth`` triangulated
    (:func:`disparity_to_points`) with the keyframe's pose, perturbed by
    `pose_noise` when given (a SLAM estimate: the points and the scan's
    origin both move), and voxel-filtered in the world frame
    (:func:`~occgp.datasets.voxel_filter`).

    Parameters
    ----------
    pairs : sequence of StereoPair
        As :func:`render_orbit` returns them.
    rig : StereoRig
        The rig that rendered them.
    params : dict or None, default=None
        StereoSGBM parameters (:func:`match_stereo`).
    voxel : float or None, default=0.1
        Voxel filter size, metres; None keeps every point.
    pose_noise : (float, float) or None, default=None
        Standard deviations of the pose error: translation per axis (metres,
        in [0, 10]) and rotation per axis (degrees, in [0, 90]); keyframe ``i``
        draws from ``numpy.random.default_rng([seed, i])``. None: true poses.
    seed : int, default=0
    n_jobs : int or None, default=None
        Worker processes (joblib); None: one.

    Returns
    -------
    scans : list of Scan
        One per pair, ``Scan(points, origin)`` with the (estimated) left
        camera center as origin.

    Raises
    ------
    TypeError, ValueError
        As :func:`match_stereo`, and for a pair that is not a StereoPair or a
        bad `voxel`, `pose_noise` or `seed`.
    ImportError
        Without OpenCV (the ``stereo`` extra).
    """
    pairs = _check_pairs(pairs)
    rig = _check_rig(rig)
    params = _check_params(params)
    if voxel is not None:
        voxel = check_real(voxel, "voxel", low=1e-6, high=1000.0, low_open=False,
                           high_open=False)
    pose_noise = _check_pose_noise(pose_noise)
    seed = check_int(seed, "seed", low=0)
    n_jobs = check_n_jobs(n_jobs)
    _cv2()
    tasks = [delayed(_frame_points)(p, rig, params, voxel, pose_noise, [seed, i])
             for i, p in enumerate(pairs)]
    return Parallel(n_jobs=n_jobs)(tasks)


def naive_fdr(scans: Sequence[Scan], scene, resolution: float = 0.1) -> float:
    """False discovery rate of the naive map: every cell holding a point is occupied.

    The authors' ranking of StereoSGBM parameter sets: the share of the cells
    (edge `resolution`, aligned on the origin as an octree's) holding a point
    of any scan that are free in the scene (:func:`occgp.evaluation.cell_labels`).

    Parameters
    ----------
    scans : sequence of (points, origin)
    scene : Scene
        Ground truth.
    resolution : float, default=0.1

    Returns
    -------
    fdr : float
        In [0, 1]; NaN when no scan holds a point.

    Raises
    ------
    TypeError, ValueError
        For a bad scan, scene or resolution.
    """
    check_scene(scene)
    resolution = check_real(resolution, "resolution", low=1e-6, high=1000.0)
    keys = [np.floor(as_points(s[0], f"scans[{i}].points") / resolution).astype(np.int64)
            for i, s in enumerate(scans)]
    keys = np.unique(np.concatenate(keys), axis=0) if keys else np.empty((0, 3), np.int64)
    if len(keys) == 0:
        return float("nan")
    occupied = cell_labels(scene, (keys + 0.5) * resolution, resolution)
    return float(1.0 - occupied.mean())


def rank_sgbm_sets(pairs: Sequence[StereoPair], rig: StereoRig, scene,
                   parameter_sets: Sequence[Mapping[str, int]], *, resolution: float = 0.1,
                   n_jobs: int | None = None) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Rank StereoSGBM parameter sets by the FDR of their naive maps (the authors' ranking).

    Parameters
    ----------
    pairs : sequence of StereoPair
        The keyframes to match (a subset of a data set's keeps the cost down).
    rig : StereoRig
    scene : Scene
        Ground truth.
    parameter_sets : sequence of dict
        As :func:`sgbm_parameter_sets` returns them; at least one.
    resolution : float, default=0.1
    n_jobs : int or None, default=None
        Worker processes over the parameter sets; None: one.

    Returns
    -------
    order : ndarray of int64
        Indices into `parameter_sets`, lowest FDR first (stable: ties keep
        their order).
    fdr : ndarray of float64
        The naive map's FDR of each set, in the order of `parameter_sets`.

    Raises
    ------
    TypeError, ValueError
        As :func:`stereo_scans` and :func:`naive_fdr`, or for no set.
    """
    pairs = _check_pairs(pairs)
    rig = _check_rig(rig)
    check_scene(scene)
    sets = [_check_params(p) for p in parameter_sets]
    if not sets:
        raise ValueError("parameter_sets must hold at least one set, got none")
    n_jobs = check_n_jobs(n_jobs)
    fdr = np.array(Parallel(n_jobs=n_jobs)(
        delayed(_set_fdr)(pairs, rig, p, scene, resolution) for p in sets))
    return np.argsort(fdr, kind="stable"), fdr


def _set_fdr(pairs, rig, params, scene, resolution):
    return naive_fdr(stereo_scans(pairs, rig, params, voxel=None), scene, resolution)


class PointErrors(NamedTuple):
    """Where the points of stereo clouds lie against the exact scene (:func:`point_errors`).

    Attributes
    ----------
    distance : ndarray of float64
        Distance of each point to the nearest surface (``|signed_distance|``), metres.
    along : ndarray of float64
        The point's range minus the range of the first surface on its ray
        from the scan's origin: positive behind that surface, negative in
        front of it (in free space); NaN when the ray meets no surface.
    surface : ndarray of str
        Kind of that first surface: the first word of its solid's label
        (``"ground"``, ``"box"``, ``"building"``), ``"none"`` without one.
    """

    distance: NDArray[np.float64]
    along: NDArray[np.float64]
    surface: NDArray[np.str_]

    def table(self, thresholds: Sequence[float] = (0.1, 0.3, 1.0)) -> list[dict[str, Any]]:
        """Share of points beyond each threshold of a surface, in front and behind, by kind.

        Parameters
        ----------
        thresholds : sequence of float, default=(0.1, 0.3, 1.0)
            Metres.

        Returns
        -------
        rows : list of dict
            One per surface kind and one ``"all"``: ``surface``, ``points``
            and, per threshold ``t``, ``">t"`` (share with ``distance > t``),
            ``">t front"`` and ``">t behind"`` (those with ``along`` < 0, > 0).
        """
        kinds = ["all"] + sorted(set(self.surface.tolist()))
        rows = []
        for kind in kinds:
            sel = np.ones(len(self.distance), bool) if kind == "all" else self.surface == kind
            n = int(sel.sum())
            row: dict[str, Any] = {"surface": kind, "points": n}
            for t in thresholds:
                far = sel & (self.distance > t)
                row[f">{t:g}"] = far.sum() / n if n else float("nan")
                row[f">{t:g} front"] = (far & (self.along < 0)).sum() / n if n else float("nan")
                row[f">{t:g} behind"] = (far & (self.along > 0)).sum() / n if n else float("nan")
            rows.append(row)
        return rows


def point_errors(scene, scans: Sequence[Scan]) -> PointErrors:
    """Measure the points of a data set's clouds against the scene's exact geometry.

    Parameters
    ----------
    scene : Scene
    scans : sequence of (points, origin)

    Returns
    -------
    errors : PointErrors
        One entry per point, scans concatenated in order.

    Raises
    ------
    TypeError, ValueError
        For a bad scene or scan.
    """
    check_scene(scene)
    dist, along, surface = [], [], []
    kinds = np.array([label.split("_")[0] for label in scene.labels] + ["none"])
    for i, scan in enumerate(scans):
        points = as_points(scan[0], f"scans[{i}].points")
        origin = as_point(scan[1], f"scans[{i}].origin")
        if len(points) == 0:
            continue
        ray = points - origin
        rng = np.linalg.norm(ray, axis=1)
        dirs = ray / np.where(rng > 0, rng, 1.0)[:, None]
        t = np.stack([s.intersect(np.broadcast_to(origin, points.shape), dirs)
                      for s in scene.solids])
        first = np.argmin(t, axis=0)
        t_first = t[first, np.arange(len(points))]
        hit = np.isfinite(t_first)
        dist.append(np.abs(scene.signed_distance(points)))
        along.append(np.where(hit, rng - t_first, np.nan))
        surface.append(kinds[np.where(hit, first, len(kinds) - 1)])
    if not dist:
        return PointErrors(np.empty(0), np.empty(0), np.empty(0, dtype=kinds.dtype))
    return PointErrors(np.concatenate(dist), np.concatenate(along), np.concatenate(surface))
