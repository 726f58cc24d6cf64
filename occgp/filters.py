"""Scan filters after octomap_server: height band, self box, ground plane, minimum range.

Each function takes points as an array of shape (n_points, 3) and returns a
boolean mask over them, so that the same mask can select colours or other
per-point data (``points[mask]``). :class:`ScanFilter` bundles them into the one
call a scan loop makes before :meth:`occgp.OccupancyOctree.insert_scan`.

Every function works on the points it is given, in their frame: octomap_server
applies its height band and ground segmentation in the robot's base frame
(``base_frame_id``) when ground filtering is on, in the world frame otherwise;
here the caller chooses the frame by the points it passes (and `ground_height`
says where the ground lies in it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._docfill import fill_doc
from ._params import ParamsMixin
from ._scan_input import check_min_range, far_enough
from ._validation import (as_numeric, as_point, as_points, check_bool, check_choice, check_int,
                          check_real, check_seed)

__all__ = ["height_band", "box_filter", "segment_ground", "GroundPlane", "ScanFilter",
           "GROUND_MODES"]

#: What :class:`ScanFilter` does with the ground points.
GROUND_MODES = ("keep", "drop", "free")


def _as_matrix(x: ArrayLike, name: str, shape: tuple[int, int],
               what: str = "") -> NDArray[np.float64]:
    arr = as_numeric(x, name)
    if arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}{what}, got {arr.shape}")
    arr = np.asarray(arr, dtype=np.float64)
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} must be finite, got {arr.tolist()}")
    return arr


def _check_box(box: ArrayLike, name: str = "box") -> NDArray[np.float64]:
    arr = _as_matrix(box, name, (2, 3), " ([min_corner, max_corner])")
    if not (arr[0] <= arr[1]).all():
        raise ValueError(f"{name} must have min_corner <= max_corner on every axis, "
                         f"got {arr.tolist()}")
    return arr


def _check_pose(pose: ArrayLike) -> NDArray[np.float64]:
    arr = _as_matrix(pose, "pose", (4, 4))
    rot = arr[:3, :3]
    if not np.allclose(arr[3], [0, 0, 0, 1]) or not np.allclose(rot.T @ rot, np.eye(3),
                                                                   atol=1e-6):
        raise ValueError("pose must be a rigid transform (a rotation and a translation, "
                         "last row [0, 0, 0, 1])")
    return arr


def height_band(points: ArrayLike, z_min: float | None = None,
                z_max: float | None = None) -> NDArray[np.bool_]:
    """Which points lie in the height band ``z_min <= z <= z_max``.

    octomap_server's ``pointcloud_min_z`` / ``pointcloud_max_z`` (a PCL
    pass-through filter on z, bounds included).

    Parameters
    ----------
    points : array-like of shape (n_points, 3)
        Finite points, in the frame whose z the band bounds (e.g. the world).
    z_min : float, default=None
        Lowest height kept; None: no lower bound.
    z_max : float, default=None
        Highest height kept; None: no upper bound.

    Returns
    -------
    mask : ndarray of shape (n_points,), dtype bool
        True for the points in the band (to keep).

    Raises
    ------
    TypeError
        If `points` does not hold real numbers, or a bound is not a real number.
    ValueError
        If `points` is not of shape (n_points, 3) or holds NaN or inf, a bound
        is not finite, or ``z_min > z_max``.

    Examples
    --------
    >>> from occgp.filters import height_band
    >>> height_band([[0, 0, -1.0], [0, 0, 0.5], [0, 0, 3.0]], z_min=0.0, z_max=2.0).tolist()
    [False, True, False]
    """
    pts = as_points(points, "points")
    lo = -math.inf if z_min is None else check_real(z_min, "z_min")
    hi = math.inf if z_max is None else check_real(z_max, "z_max")
    if lo > hi:
        raise ValueError(f"z_min must be <= z_max, got z_min={z_min!r}, z_max={z_max!r}")
    return (pts[:, 2] >= lo) & (pts[:, 2] <= hi)


def box_filter(points: ArrayLike, box: ArrayLike, *, inside: bool = False,
               pose: ArrayLike | None = None) -> NDArray[np.bool_]:
    """Which points to keep with respect to an axis-aligned box (a self filter).

    By default the points *in* the box are dropped: give the box around the
    robot's own body so that its returns do not become obstacles. With
    ``inside=True`` only the points in the box are kept (a crop box).

    Parameters
    ----------
    points : array-like of shape (n_points, 3)
        Finite points, in metres.
    box : array-like of shape (2, 3)
        ``[min_corner, max_corner]``, a closed box, axis-aligned in its own
        frame (the points' frame without `pose`).
    inside : bool, default=False
        False: keep the points outside the box; True: keep those inside.
    pose : array-like of shape (4, 4), default=None
        Rigid transform from the box's frame (e.g. the robot's base or the
        sensor) to the points' frame; the points are mapped into the box's
        frame by its inverse before the test. None: the box is given in the
        points' frame.

    Returns
    -------
    mask : ndarray of shape (n_points,), dtype bool
        True for the points to keep.

    Raises
    ------
    TypeError
        If an array does not hold real numbers, or `inside` is not a bool.
    ValueError
        If `points` is not of shape (n_points, 3) or holds NaN or inf; `box`
        is not of shape (2, 3), not finite or has a min corner above its max
        corner; `pose` is not a (4, 4) rigid transform.

    Examples
    --------
    >>> from occgp.filters import box_filter
    >>> pts = [[0.1, 0.0, 0.2], [2.0, 0.0, 0.2]]
    >>> box_filter(pts, [[-0.3, -0.3, 0.0], [0.3, 0.3, 1.0]]).tolist()
    [False, True]
    >>> pose = [[1, 0, 0, 2.0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]   # box at x = 2
    >>> box_filter(pts, [[-0.3, -0.3, 0.0], [0.3, 0.3, 1.0]], pose=pose).tolist()
    [True, False]
    """
    pts = as_points(points, "points")
    lo, hi = _check_box(box)
    inside = check_bool(inside, "inside")
    if pose is not None:
        tf = _check_pose(pose)
        pts = (pts - tf[:3, 3]) @ tf[:3, :3]       # R^T (p - t), row by row
    within = np.all((pts >= lo) & (pts <= hi), axis=1)
    return within if inside else ~within


class GroundPlane(NamedTuple):
    """What :func:`segment_ground` found."""

    #: True for the ground points, shape (n_points,).
    mask: NDArray[np.bool_]
    #: The accepted plane ``(a, b, c, d)``, ``a x + b y + c z + d = 0`` with a unit
    #: normal pointing up (c > 0); None when no plane was accepted.
    plane: NDArray[np.float64] | None


def _plane_fit(pts: NDArray[np.float64]) -> NDArray[np.float64]:
    """Least-squares plane through `pts` (the normal is the direction of least spread)."""
    center = pts.mean(axis=0)
    _, vecs = np.linalg.eigh(np.cov((pts - center).T, bias=True))
    n = vecs[:, 0]
    return np.append(n, -n @ center)


def _ransac_plane(pts, distance, cos_angle, max_iterations, rng, probability=0.99):
    """octomap_server's PCL RANSAC (SACMODEL_PERPENDICULAR_PLANE): planes through three
    random points whose normal lies within the angle of z, the one with most points
    within `distance` wins; stops after `max_iterations` samples or once the best
    plane's inlier ratio makes a better one unlikely (`probability`), then refits it by
    least squares over its inliers. Returns (inlier mask, plane) or (None, None)."""
    n = len(pts)
    best_count, best_plane = 0, None
    needed, done = float(max_iterations), 0
    chunk = max(1, min(max_iterations, (1 << 22) // max(n, 1)))
    while done < min(needed, max_iterations):
        k = min(chunk, max_iterations - done)
        idx = rng.integers(0, n, size=(k, 3))
        a, b, c = pts[idx[:, 0]], pts[idx[:, 1]], pts[idx[:, 2]]
        normal = np.cross(b - a, c - a)
        norm = np.linalg.norm(normal, axis=1)
        ok = norm > 0
        normal[ok] /= norm[ok, None]
        ok &= np.abs(normal[:, 2]) >= cos_angle
        done += k
        if not ok.any():
            continue
        normal, a = normal[ok], a[ok]
        d = -np.einsum("ij,ij->i", normal, a)
        counts = (np.abs(pts @ normal.T + d) <= distance).sum(axis=0)
        j = int(np.argmax(counts))
        if counts[j] > best_count:
            best_count, best_plane = int(counts[j]), np.append(normal[j], d[j])
            w = best_count / n
            miss = 1.0 - w ** 3
            needed = (math.log(1.0 - probability) / math.log(miss) if 0 < miss < 1
                      else 0.0 if miss <= 0 else float(max_iterations))
    if best_plane is None:
        return None, None
    inliers = np.abs(pts @ best_plane[:3] + best_plane[3]) <= distance
    refit = _plane_fit(pts[inliers]) if inliers.sum() >= 3 else best_plane
    if abs(refit[2]) >= cos_angle:
        best_plane = refit
        inliers = np.abs(pts @ best_plane[:3] + best_plane[3]) <= distance
    return inliers, best_plane


def segment_ground(points: ArrayLike, *, distance: float = 0.04, angle: float = 0.15,
                   plane_distance: float = 0.07, ground_height: float = 0.0,
                   max_iterations: int = 200, min_points: int = 50,
                   random_state=None) -> GroundPlane:
    """Find the ground points of a scan, as octomap_server's ``filterGroundPlane`` does.

    A RANSAC search for planes whose normal lies within `angle` of the vertical
    (z): planes through three random points, the one with the most points
    within `distance` kept and refitted by least squares over them (if the refit
    tilts past `angle`, the sampled plane stays). If the plane passes within
    `plane_distance` of the point ``(0, 0, ground_height)`` it is the ground,
    and the points within `distance` of it are the ground points. Otherwise it is
    some other horizontal surface (a table top): its points are set aside and
    the search runs again on the rest, while more than 10 points remain. When no
    ground plane is found, octomap_server's fallback applies: the ground points
    are those with ``|z - ground_height| <= plane_distance``. A scan of fewer
    than `min_points` points has no ground (octomap_server skips the search and
    the fallback).

    Each RANSAC search draws at most `max_iterations` planes, fewer once its best
    plane holds enough of the points that a better one would have been drawn
    with probability 0.99 (PCL's stopping rule). The draws come from a numpy
    Generator seeded with `random_state`: the same seed gives the same result.

    Parameters
    ----------
    points : array-like of shape (n_points, 3)
        Finite points, in a frame whose z axis is vertical and whose ground lies
        at height `ground_height` (octomap_server: the robot's base frame,
        ground at 0).
    distance : float, default=0.04
        Largest distance (metres) of a ground point from the plane
        (``ground_filter/distance``); > 0.
    angle : float, default=0.15
        Largest angle (radians) between the plane's normal and the vertical
        (``ground_filter/angle``); in [0, pi/2].
    plane_distance : float, default=0.07
        Largest distance (metres) of the plane from ``(0, 0, ground_height)``
        for it to be the ground, and the half height of the fallback band
        (``ground_filter/plane_distance``); >= 0.
    ground_height : float, default=0.0
        Height of the expected ground in the points' frame.
    max_iterations : int, default=200
        Most planes each RANSAC search draws (PCL's ``setMaxIterations`` in
        octomap_server); >= 1.
    min_points : int, default=50
        Fewest points for a search; smaller scans have no ground points.
    random_state : int, numpy.random.Generator or None, default=None
        Seed of the draws.

    Returns
    -------
    ground : GroundPlane
        Named tuple ``(mask, plane)``: the ground points' mask, and the plane
        ``(a, b, c, d)`` (unit normal up, ``a x + b y + c z + d = 0``) or None
        when no plane was accepted (the fallback band, or too few points).

    Raises
    ------
    TypeError
        If `points` does not hold real numbers, or a parameter has the wrong
        type.
    ValueError
        If `points` is not of shape (n_points, 3) or holds NaN or inf, or a
        parameter lies outside its range.

    Examples
    --------
    >>> import numpy as np
    >>> from occgp.filters import segment_ground
    >>> rng = np.random.default_rng(0)
    >>> floor = np.column_stack([rng.uniform(-3, 3, (300, 2)), rng.normal(0, 0.005, 300)])
    >>> wall = np.column_stack([np.full(100, 2.0), rng.uniform(-3, 3, 100),
    ...                         rng.uniform(0.1, 2, 100)])
    >>> mask, plane = segment_ground(np.vstack([floor, wall]), random_state=0)
    >>> int(mask[:300].sum()), int(mask[300:].sum()), bool(abs(plane[2]) > 0.99)
    (300, 0, True)
    """
    pts = as_points(points, "points")
    distance = check_real(distance, "distance", low=0.0)
    angle = check_real(angle, "angle", low=0.0, high=math.pi / 2, low_open=False,
                       high_open=False)
    plane_distance = check_real(plane_distance, "plane_distance", low=0.0, low_open=False)
    ground_height = check_real(ground_height, "ground_height")
    max_iterations = check_int(max_iterations, "max_iterations", low=1, high=2**31 - 1)
    min_points = check_int(min_points, "min_points", low=0, high=2**62)
    rng = check_seed(random_state, "random_state")
    mask = np.zeros(len(pts), dtype=bool)
    if len(pts) < min_points:
        return GroundPlane(mask, None)
    cos_angle = math.cos(angle)
    rest = np.arange(len(pts))
    while len(rest) > 10:
        inliers, plane = _ransac_plane(pts[rest], distance, cos_angle, max_iterations, rng)
        if inliers is None or not inliers.any():
            break
        if plane[2] < 0:
            plane = -plane
        if abs(plane[2] * ground_height + plane[3]) < plane_distance:
            mask[rest[inliers]] = True
            return GroundPlane(mask, plane)
        rest = rest[~inliers]          # another horizontal surface: search the rest
    return GroundPlane(np.abs(pts[:, 2] - ground_height) <= plane_distance, None)


#: The Parameters of ScanFilter.masks and .apply (see :func:`occgp._docfill.fill_doc`).
_FILTER_PARAMETERS = """\
Parameters
----------
points : array-like of shape (n_points, 3)
    The scan in the world frame, finite.
origin : array-like of shape (3,)
    The sensor's position in the world frame."""


@dataclass(init=False, repr=True, eq=False)
class ScanFilter(ParamsMixin):
    """The scan filters of octomap_server, in one object.

    :meth:`apply` takes a scan in the world frame and returns the points to
    insert and the ground points to insert as free (or None), for
    ``m.insert_scan(points, origin, free_points=free)``. The steps, in order:

    1. the height band ``z_min <= z <= z_max`` (:func:`height_band`);
    2. the self filter: the points in ``origin + self_box`` (a box given as
       offsets from the sensor, axis-aligned in the world frame) are dropped
       (:func:`box_filter`);
    3. with ``ground="drop"`` or ``"free"``, the ground points
       (:func:`segment_ground`, on the points left, with the ground at height
       ``ground_height`` in the world frame) are removed from the points, and
       with ``"free"`` returned as free points (octomap_server's behaviour);
    4. ``min_range``: the points and free points nearer to `origin` than it are
       dropped (octomap_server applies it at insertion, after the ground
       segmentation; as :meth:`occgp.OccupancyOctree.insert_scan` does).

    As in scikit-learn, ``__init__`` only stores its arguments; they are
    checked by :meth:`apply`.

    Parameters
    ----------
    min_range : float, default=None
        Points nearer to the sensor than this are dropped; None: none.
    z_min, z_max : float, default=None
        The height band (world frame); None: unbounded.
    self_box : array-like of shape (2, 3), default=None
        ``[min_corner, max_corner]`` offsets from the sensor's position of the
        box whose points are dropped (the robot's body); None: no self filter.
    ground : {"keep", "drop", "free"}, default="keep"
        What to do with the ground points: nothing (no segmentation), drop
        them, or return them as free points.
    ground_distance, ground_angle, ground_plane_distance : float
        `distance` (default 0.04), `angle` (0.15) and `plane_distance` (0.07)
        of :func:`segment_ground`.
    ground_height : float, default=0.0
        Height of the ground in the world frame.
    max_iterations : int, default=200
        Most planes each RANSAC search draws.
    random_state : int, numpy.random.Generator or None, default=None
        Seed of the ground search; an int gives the same draws on every scan.

    Examples
    --------
    >>> import numpy as np
    >>> from occgp import OccupancyOctree
    >>> from occgp.filters import ScanFilter
    >>> rng = np.random.default_rng(0)
    >>> floor = np.column_stack([rng.uniform(-3, 3, (300, 2)), np.zeros(300)])
    >>> wall = np.column_stack([np.full(100, 2.0), rng.uniform(-3, 3, 100),
    ...                         rng.uniform(0.1, 2, 100)])
    >>> origin = np.array([0.0, 0.0, 1.0])
    >>> f = ScanFilter(min_range=0.5, ground="free", random_state=0)
    >>> points, free = f.apply(np.vstack([floor, wall]), origin)
    >>> len(points), len(free)
    (100, 300)
    >>> m = OccupancyOctree(0.1).insert_scan(points, origin, free_points=free)
    """

    min_range: float | None
    z_min: float | None
    z_max: float | None
    self_box: ArrayLike | None
    ground: str
    ground_distance: float
    ground_angle: float
    ground_plane_distance: float
    ground_height: float
    max_iterations: int
    random_state: object

    def __init__(self, *, min_range: float | None = None, z_min: float | None = None,
                 z_max: float | None = None, self_box: ArrayLike | None = None,
                 ground: str = "keep", ground_distance: float = 0.04,
                 ground_angle: float = 0.15, ground_plane_distance: float = 0.07,
                 ground_height: float = 0.0, max_iterations: int = 200,
                 random_state=None) -> None:
        self.min_range = min_range
        self.z_min = z_min
        self.z_max = z_max
        self.self_box = self_box
        self.ground = ground
        self.ground_distance = ground_distance
        self.ground_angle = ground_angle
        self.ground_plane_distance = ground_plane_distance
        self.ground_height = ground_height
        self.max_iterations = max_iterations
        self.random_state = random_state

    def _check_params_together(self, params):
        type(self)(**params).masks(np.empty((0, 3)), np.zeros(3))   # checks every value
        return params

    def set_params(self, **params) -> "ScanFilter":
        """Set parameters by name (scikit-learn's ``set_params``), checked as
        :meth:`apply` checks them before any changes.

        Parameters
        ----------
        **params
            The parameters to change.

        Returns
        -------
        self : ScanFilter

        Raises
        ------
        TypeError, ValueError
            If a name is not a parameter or a value is rejected (as by
            :meth:`apply`); nothing has changed then.
        """
        return super().set_params(**params)

    @fill_doc(filter_parameters=_FILTER_PARAMETERS)
    def masks(self, points: ArrayLike, origin: ArrayLike) -> tuple[NDArray[np.bool_],
                                                                  NDArray[np.bool_]]:
        """The masks :meth:`apply` selects with: the points to insert and the ground
        points (to insert as free with ``ground="free"``); disjoint.

        {filter_parameters}

        Returns
        -------
        keep : ndarray of shape (n_points,), dtype bool
            The points to insert as hits (select their colours with it too).
        ground : ndarray of shape (n_points,), dtype bool
            The ground points left after `min_range` (all False unless
            ``ground`` is ``"drop"`` or ``"free"``).

        Raises
        ------
        TypeError, ValueError
            If the points, the origin or a parameter is invalid (named).
        """
        pts = as_points(points, "points")
        org = as_point(origin, "origin")
        ground = check_choice(self.ground, "ground", GROUND_MODES)
        near = check_min_range(self.min_range)
        keep = height_band(pts, self.z_min, self.z_max)
        if self.self_box is not None:
            box = _check_box(self.self_box, "self_box") + org
            keep &= box_filter(pts, box)
        on_ground = np.zeros(len(pts), dtype=bool)
        if ground != "keep":
            rows = np.flatnonzero(keep)
            # checked here under this class's names (segment_ground names its own)
            found = segment_ground(
                pts[rows], distance=check_real(self.ground_distance, "ground_distance",
                                               low=0.0),
                angle=check_real(self.ground_angle, "ground_angle", low=0.0,
                                 high=math.pi / 2, low_open=False, high_open=False),
                plane_distance=check_real(self.ground_plane_distance,
                                          "ground_plane_distance", low=0.0, low_open=False),
                ground_height=check_real(self.ground_height, "ground_height"),
                max_iterations=self.max_iterations, random_state=self.random_state)
            on_ground[rows[found.mask]] = True
            keep &= ~on_ground
        if near is not None:
            far = far_enough(pts, org, near)
            keep &= far
            on_ground &= far
        return keep, on_ground

    @fill_doc(filter_parameters=_FILTER_PARAMETERS)
    def apply(self, points: ArrayLike, origin: ArrayLike):
        """Filter one scan.

        {filter_parameters}

        Returns
        -------
        points : ndarray of shape (n_kept, 3)
            The points to insert (float64).
        free_points : ndarray of shape (n_ground, 3) or None
            With ``ground="free"``, the ground points to insert as free
            (``insert_scan(..., free_points=free_points)``); None otherwise.

        Raises
        ------
        TypeError, ValueError
            If the points, the origin or a parameter is invalid (named).
        """
        keep, on_ground = self.masks(points, origin)
        pts = as_points(points, "points")
        free = pts[on_ground] if self.ground == "free" else None
        return pts[keep], free
