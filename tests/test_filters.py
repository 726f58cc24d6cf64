"""occgp.filters: height band, self box, ground segmentation and ScanFilter."""

import math

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from occgp import GridMap, OccupancyOctree
from occgp.filters import GroundPlane, ScanFilter, box_filter, height_band, segment_ground
from _helpers import assert_same_leaves


def scene(seed=0, n_floor=400, n_wall=150, n_table=0, tilt=0.0, floor_z=0.0):
    """Floor points (z = floor_z, tilted by `tilt` radians about x), a wall at x = 2 and
    an optional table top at z = 0.7."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-3, 3, (n_floor, 2))
    floor = np.column_stack([xy, floor_z + xy[:, 1] * math.tan(tilt)
                             + rng.normal(0, 0.005, n_floor)])
    wall = np.column_stack([np.full(n_wall, 2.0), rng.uniform(-3, 3, n_wall),
                            rng.uniform(0.1, 2.0, n_wall)])
    table = np.column_stack([rng.uniform(-1.5, -0.5, (n_table, 2)), np.full(n_table, 0.7)])
    return np.vstack([floor, wall, table])


# ---------------------------------------------------------------------- height_band
def test_height_band_keeps_its_closed_interval():
    pts = np.array([[0, 0, -0.5], [0, 0, 0.0], [0, 0, 1.0], [0, 0, 1.5]])
    assert height_band(pts, 0.0, 1.0).tolist() == [False, True, True, False]
    assert height_band(pts, z_min=0.0).tolist() == [False, True, True, True]
    assert height_band(pts, z_max=0.0).tolist() == [True, True, False, False]
    assert height_band(pts).all()
    assert height_band(np.empty((0, 3)), 0, 1).shape == (0,)


@pytest.mark.parametrize("kwargs, exc, match", [
    ({"z_min": 2.0, "z_max": 1.0}, ValueError, "z_min must be <= z_max"),
    ({"z_min": np.nan}, ValueError, "z_min must lie in"),
    ({"z_max": "1"}, TypeError, "z_max must be a real number"),
])
def test_height_band_rejects_bad_bounds(kwargs, exc, match):
    with pytest.raises(exc, match=match):
        height_band([[0, 0, 0]], **kwargs)


# ---------------------------------------------------------------------- box_filter
def test_box_filter_drops_or_keeps_the_box():
    pts = np.array([[0.0, 0, 0], [0.3, 0.3, 1.0], [0.31, 0, 0.5], [5, 5, 5]])
    box = [[-0.3, -0.3, 0.0], [0.3, 0.3, 1.0]]
    assert box_filter(pts, box).tolist() == [False, False, True, True]
    assert box_filter(pts, box, inside=True).tolist() == [True, True, False, False]


def test_box_filter_with_a_pose_tests_in_the_box_frame():
    # the box frame is rotated 90 degrees about z and moved to (2, 0, 0): its x axis is
    # the world's y axis, so a box long in its x is long in world y
    pose = np.array([[0.0, -1, 0, 2], [1, 0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
    box = [[-1.0, -0.1, -0.1], [1.0, 0.1, 0.1]]
    pts = np.array([[2.0, 0.9, 0.0], [2.9, 0.0, 0.0], [2.05, -0.5, 0.05]])
    assert box_filter(pts, box, pose=pose, inside=True).tolist() == [True, False, True]
    local = (pts - pose[:3, 3]) @ pose[:3, :3]
    assert_array_equal(box_filter(pts, box, pose=pose), box_filter(local, box))


@pytest.mark.parametrize("kwargs, exc, match", [
    ({"box": [[0, 0, 0]]}, ValueError, r"box must have shape \(2, 3\)"),
    ({"box": [[1, 0, 0], [0, 1, 1]]}, ValueError, "min_corner <= max_corner"),
    ({"box": [[0, 0, 0], [1, 1, np.inf]]}, ValueError, "box must be finite"),
    ({"box": [[0, 0, 0], [1, 1, 1]], "inside": 1}, TypeError, "inside must be a bool"),
    ({"box": [[0, 0, 0], [1, 1, 1]], "pose": np.eye(3)}, ValueError,
     r"pose must have shape \(4, 4\), got \(3, 3\)"),
    ({"box": [[0, 0, 0], [1, 1, 1]], "pose": 2 * np.eye(4)}, ValueError, "rigid transform"),
])
def test_box_filter_rejects_bad_input(kwargs, exc, match):
    with pytest.raises(exc, match=match):
        box_filter([[0.5, 0.5, 0.5]], **kwargs)


# ---------------------------------------------------------------------- segment_ground
def test_segment_ground_finds_the_floor():
    pts = scene()
    mask, plane = segment_ground(pts, random_state=0)
    assert mask[:400].all() and not mask[400:].any()
    assert plane[2] > 0.999 and abs(plane[3]) < 0.01
    assert np.isclose(np.linalg.norm(plane[:3]), 1.0)


def test_segment_ground_skips_a_larger_horizontal_plane_that_is_not_the_ground():
    pts = scene(1, n_floor=200, n_table=600)      # the table has the most points
    mask, plane = segment_ground(pts, random_state=0)
    assert mask[:200].all() and not mask[200:].any()
    assert abs(plane[3]) < 0.07


def test_segment_ground_with_a_ground_height():
    pts = scene(2, floor_z=-1.2)
    mask, plane = segment_ground(pts, ground_height=-1.2, random_state=0)
    assert mask[:400].all() and not mask[400:].any()
    assert abs(plane[2] * -1.2 + plane[3]) < 0.07


def test_segment_ground_falls_back_to_a_height_band():
    # a floor tilted past the angle limit is no ground plane: octomap_server's fallback
    # takes the points with |z| <= plane_distance
    pts = scene(3, n_wall=0, tilt=0.4)
    mask, plane = segment_ground(pts, angle=0.15, random_state=0)
    assert plane is None
    assert_array_equal(mask, np.abs(pts[:, 2]) <= 0.07)


def test_segment_ground_needs_min_points():
    pts = scene(4, n_floor=30, n_wall=10)
    found = segment_ground(pts, random_state=0)
    assert isinstance(found, GroundPlane) and found.plane is None and not found.mask.any()
    assert segment_ground(pts, min_points=20, random_state=0).mask[:30].all()


def test_segment_ground_is_reproducible_with_a_seed():
    pts = scene(5) + np.random.default_rng(9).normal(0, 0.02, (550, 3))
    a = segment_ground(pts, random_state=3)
    b = segment_ground(pts, random_state=3)
    assert_array_equal(a.mask, b.mask)
    assert_array_equal(a.plane, b.plane)


@pytest.mark.parametrize("kwargs, exc, match", [
    ({"distance": 0.0}, ValueError, r"distance must lie in \(0.0, inf\)"),
    ({"angle": 2.0}, ValueError, "angle must lie in"),
    ({"plane_distance": -1.0}, ValueError, "plane_distance must lie in"),
    ({"max_iterations": 0}, ValueError, "max_iterations"),
    ({"max_iterations": 2.5}, TypeError, "max_iterations"),
    ({"random_state": "seed"}, TypeError, "random_state"),
])
def test_segment_ground_rejects_bad_parameters(kwargs, exc, match):
    with pytest.raises(exc, match=match):
        segment_ground(scene(), **kwargs)


# ---------------------------------------------------------------------- ScanFilter
def test_scan_filter_init_only_stores():
    f = ScanFilter(min_range=-3, ground="sky")          # checked by apply, not here
    assert f.get_params()["min_range"] == -3 and f.ground == "sky"
    with pytest.raises(ValueError, match="ground must be one of"):
        f.apply(scene(), [0, 0, 1])
    f.set_params(ground="free", min_range=0.5)
    assert f.get_params()["ground"] == "free"
    with pytest.raises(ValueError, match="'bad' is not a parameter of ScanFilter"):
        f.set_params(bad=1)


def test_scan_filter_composes_the_filters():
    pts = scene(6, n_table=100)
    origin = np.array([0.0, 0.0, 1.0])
    f = ScanFilter(min_range=0.8, z_min=-0.5, z_max=1.5, ground="free",
                   self_box=[[-0.5, -0.5, -0.5], [0.5, 0.5, 0.5]], random_state=0)
    points, free = f.apply(pts, origin)
    band = height_band(pts, -0.5, 1.5) & box_filter(pts, np.array([[-0.5] * 3, [0.5] * 3])
                                                    + origin)
    ground = np.zeros(len(pts), bool)
    ground[np.flatnonzero(band)[segment_ground(pts[band], random_state=0).mask]] = True
    far = np.linalg.norm(pts - origin, axis=1) >= 0.8
    assert_array_equal(points, pts[band & ~ground & far])
    assert_array_equal(free, pts[ground & far])
    keep, on_ground = f.masks(pts, origin)
    assert not (keep & on_ground).any()
    dropped = ScanFilter(min_range=0.8, z_min=-0.5, z_max=1.5, ground="drop",
                         self_box=[[-0.5, -0.5, -0.5], [0.5, 0.5, 0.5]], random_state=0)
    p2, f2 = dropped.apply(pts, origin)
    assert_array_equal(p2, points) and f2 is None
    p3, f3 = ScanFilter().apply(pts, origin)
    assert_array_equal(p3, pts) and f3 is None


@pytest.mark.parametrize("cls", [OccupancyOctree, GridMap])
def test_scan_filter_output_inserts_as_octomap_server_would(cls):
    pts = scene(7)
    origin = np.array([0.1, 0.1, 0.6])
    points, free = ScanFilter(ground="free", min_range=0.3, random_state=0).apply(pts, origin)
    m = cls(0.1).insert_scan(points, origin, free_points=free)
    occ, unknown = m.is_occupied(free, return_unknown=True)
    assert not occ[~unknown].any()            # the floor's rays cleared, nothing occupied there
    assert m.is_occupied(points).mean() > 0.9


def test_scan_filter_rejects_a_bad_self_box():
    with pytest.raises(ValueError, match="self_box must have min_corner <= max_corner"):
        ScanFilter(self_box=[[1, 1, 1], [0, 0, 0]]).apply(scene(), [0, 0, 1])
    with pytest.raises(ValueError, match=r"min_range must lie in \[0.0, inf\)"):
        ScanFilter(min_range=-1).apply(scene(), [0, 0, 1])
