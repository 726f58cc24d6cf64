"""Tests of the LiDAR simulator (LidarSensor, simulate_scans) and free_path."""

import dataclasses

import numpy as np
import pytest
from conftest import data_path
from numpy.testing import assert_allclose, assert_array_equal

from occgp import OccupancyOctree
from occgp.datasets import LidarSensor, Scan, free_path, simulate_scans, structured_room

RES = 0.1
BOX_ORIGIN = np.array([0.05, 0.05, 0.45])


@pytest.fixture(scope="module")
def box_map():
    """A closed 2 x 2 x 1.2 m box of occupied cells (resolution 0.1), free inside."""
    g = np.arange(-0.95, 0.96, 0.05)
    gz = np.arange(-0.05, 1.06, 0.05)
    a, b = np.meshgrid(g, g)
    a, b = a.ravel(), b.ravel()
    c, z = (m.ravel() for m in np.meshgrid(g, gz))
    faces = [np.column_stack([a, b, np.full_like(a, v)]) for v in (-0.05, 1.05)]
    faces += [np.column_stack([np.full_like(c, v), c, z]) for v in (-0.95, 0.95)]
    faces += [np.column_stack([c, np.full_like(c, v), z]) for v in (-0.95, 0.95)]
    return OccupancyOctree(RES).insert_scan(np.vstack(faces), BOX_ORIGIN)


@pytest.fixture(scope="module")
def geb079():
    return OccupancyOctree.load(data_path("octomap", "geb079.bt"))


@pytest.fixture(scope="module")
def geb079_path(geb079):
    return free_path(geb079, 12, seed=0)


SMALL = LidarSensor(n_horizontal=60, n_vertical=20, vertical_fov=(-1.2, 1.2), max_range=5.0)


# --------------------------------------------------------------------------- LidarSensor
@pytest.mark.parametrize("kwargs, exc, match", [
    (dict(n_horizontal=0), ValueError, "n_horizontal must be a positive int, got 0"),
    (dict(n_vertical=-3), ValueError, "n_vertical must be a positive int"),
    (dict(n_vertical=2.5), TypeError, "n_vertical must be a positive int, got float"),
    (dict(horizontal_fov=0.0), ValueError, r"horizontal_fov must lie in \(0.0, "),
    (dict(horizontal_fov=7.0), ValueError, "horizontal_fov must lie in"),
    (dict(vertical_fov=(0.5, 0.1)), ValueError, r"vertical_fov must be \(low, high\)"),
    (dict(vertical_fov=(-2.0, 0.1)), ValueError, "vertical_fov must be"),
    (dict(vertical_fov=(0.1,)), ValueError, "vertical_fov must be"),
    (dict(vertical_fov=("a", "b")), TypeError, "vertical_fov must hold real numbers"),
    (dict(max_range=0.0), ValueError, "max_range must lie in"),
    (dict(max_range=np.inf), ValueError, "max_range must lie in"),
    (dict(range_noise=-0.01), ValueError, r"range_noise must lie in \[0.0, inf\)"),
    (dict(range_noise="0.1"), TypeError, "range_noise must be a real number, got str"),
])
def test_sensor_rejects_bad_parameters(kwargs, exc, match):
    with pytest.raises(exc, match=match):
        LidarSensor(**kwargs)


def test_sensor_is_frozen_with_float_fov():
    sensor = LidarSensor(vertical_fov=[-1, 1])
    assert sensor.vertical_fov == (-1.0, 1.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        sensor.max_range = 3.0


def test_default_sensor_is_dense():
    sensor = LidarSensor()
    assert sensor.n_rays == 720 * 150 == len(sensor.directions())


@pytest.mark.parametrize("heading", [0.0, 1.0, -2.5])
def test_directions_are_a_unit_grid_rotated_by_heading(heading):
    sensor = LidarSensor(horizontal_fov=2.0, n_horizontal=7, vertical_fov=(-0.4, 0.3),
                         n_vertical=3)
    d = sensor.directions(heading)
    assert d.shape == (21, 3)
    assert_allclose(np.linalg.norm(d, axis=1), 1.0)
    el = np.arcsin(d[:, 2]).reshape(3, 7)
    assert_allclose(el, np.linspace(-0.4, 0.3, 7)[[1, 3, 5]][:, None].repeat(7, axis=1))
    az = np.arctan2(d[:, 1], d[:, 0]).reshape(3, 7)
    expected = heading + np.linspace(-1.0, 1.0, 15)[1::2]
    assert_allclose(np.angle(np.exp(1j * (az - expected))), 0.0, atol=1e-12)


def test_full_turn_repeats_no_azimuth():
    d = LidarSensor(n_horizontal=8, n_vertical=1, vertical_fov=(-0.1, 0.1)).directions()
    az = np.sort(np.arctan2(d[:, 1], d[:, 0]))
    assert_allclose(np.diff(az), np.pi / 4)


def test_directions_rejects_bad_heading():
    with pytest.raises(ValueError, match="heading must lie in"):
        LidarSensor().directions(np.nan)


# --------------------------------------------------------------------------- scenes
def test_scene_scan_points_lie_on_surfaces():
    scene = structured_room()
    origin = np.array([0.0, 0.0, 1.0])
    scans = simulate_scans(scene, [origin], SMALL, headings=[0.3])
    assert len(scans) == 1 and isinstance(scans[0], Scan)
    points, org = scans[0]
    assert_array_equal(org, origin)
    _, hit = scene.ray_cast(origin, SMALL.directions(0.3), SMALL.max_range)
    assert len(points) == hit.sum() > 0.5 * SMALL.n_rays
    assert_allclose(scene.signed_distance(points), 0.0, atol=1e-9)


def test_scene_noise_is_seeded_along_the_rays():
    scene, origin = structured_room(), np.array([[0.0, 0.0, 1.0]])
    noisy = LidarSensor(n_horizontal=60, n_vertical=20, vertical_fov=(-1.2, 0.0),
                        range_noise=0.05)
    clean = simulate_scans(scene, origin, dataclasses.replace(noisy, range_noise=0.0))[0]
    a = simulate_scans(scene, origin, noisy, seed=3)[0]
    b = simulate_scans(scene, origin, noisy, seed=3)[0]
    c = simulate_scans(scene, origin, noisy, seed=4)[0]
    assert_array_equal(a.points, b.points)
    assert not np.array_equal(a.points, c.points)
    err = np.linalg.norm(a.points - origin, axis=1) - np.linalg.norm(clean.points - origin, axis=1)
    assert 0.03 < err.std() < 0.07
    # the noise moves points along their rays
    u = (clean.points - origin) / np.linalg.norm(clean.points - origin, axis=1)[:, None]
    assert_allclose(np.cross(a.points - origin, u), 0.0, atol=1e-9)


def test_scene_free_path_is_exact():
    scene = structured_room()
    poses = free_path(scene, 8, step=0.5, clearance=0.3, seed=2)
    assert poses.shape == (8, 3)
    assert_allclose(poses[:, 2], 1.0)
    assert_allclose(np.linalg.norm(np.diff(poses, axis=0), axis=1), 0.5)
    assert (scene.signed_distance(poses) >= 0.3).all()
    _, hit = scene.ray_cast(poses[:-1], np.diff(poses, axis=0), 0.5)
    assert not hit.any()
    assert_array_equal(poses, free_path(scene, 8, step=0.5, clearance=0.3, seed=2))
    assert not np.array_equal(poses, free_path(scene, 8, step=0.5, clearance=0.3, seed=5))


# --------------------------------------------------------------------------- octree
def test_octree_points_lie_in_the_first_occupied_cell(box_map):
    scan = simulate_scans(box_map, [BOX_ORIGIN], SMALL)[0]
    points = scan.points
    assert len(points) == SMALL.n_rays           # the box is closed: every ray returns
    assert box_map.is_occupied(points).all()
    # the points lie on their rays, at the entry into the hit cell (the cell's surface)
    dirs = SMALL.directions()
    assert_allclose(np.cross(points - BOX_ORIGIN, dirs), 0.0, atol=1e-5)
    cells = np.floor(points / RES)
    dist_to_face = np.minimum(points / RES - cells, cells + 1 - points / RES).min(axis=1)
    assert (dist_to_face < 1e-3).all()
    # and many returns in one cell are spread, not stacked on its center
    assert len(np.unique(points.round(6), axis=0)) == len(points)
    # nothing occupied lies before them: casting towards a point stops in its cell
    ends, hit = box_map.cast_rays(BOX_ORIGIN, points - BOX_ORIGIN, ignore_unknown=True)
    assert hit.all()
    assert (np.floor(ends / RES) == cells).all(axis=1).mean() > 0.99


def test_octree_scan_drops_rays_without_return(box_map):
    sensor = dataclasses.replace(SMALL, max_range=0.6)
    points = simulate_scans(box_map, [BOX_ORIGIN], sensor)[0].points
    assert 0 < len(points) < sensor.n_rays
    assert (np.linalg.norm(points - BOX_ORIGIN, axis=1) <= 0.6).all()
    assert box_map.is_occupied(points).all()


def test_octree_scans_are_deterministic_and_noisy(box_map):
    poses = [BOX_ORIGIN, BOX_ORIGIN + [0.3, -0.2, 0.1]]
    noisy = dataclasses.replace(SMALL, range_noise=0.02)
    a = simulate_scans(box_map, poses, noisy, headings=[0.0, 1.0], seed=1, progress=False)
    b = simulate_scans(box_map, poses, noisy, headings=[0.0, 1.0], seed=1, progress=False)
    clean = simulate_scans(box_map, poses, SMALL, headings=[0.0, 1.0])
    assert len(a) == 2
    for sa, sb, sc in zip(a, b, clean):
        assert_array_equal(sa.points, sb.points)
        assert sa.points.shape == sc.points.shape
        assert 0.01 < np.linalg.norm(sa.points - sc.points, axis=1).mean() < 0.03


def test_progress_bar_goes_to_stderr(box_map, capsys):
    simulate_scans(box_map, [BOX_ORIGIN], SMALL, progress=True)
    assert "simulating scans" in capsys.readouterr().err


@pytest.mark.parametrize("environment", ["room", object(), None])
def test_simulate_rejects_bad_environment(environment):
    with pytest.raises(TypeError, match="environment must be an OccupancyOctree or have a "
                                        "ray_cast"):
        simulate_scans(environment, [[0.0, 0.0, 0.0]], SMALL)


def test_simulate_rejects_bad_sensor(box_map):
    with pytest.raises(TypeError, match="sensor must be a LidarSensor, got dict"):
        simulate_scans(box_map, [BOX_ORIGIN], {"max_range": 3})


@pytest.mark.parametrize("poses", [np.zeros(3), np.zeros((2, 2)), np.zeros((1, 3, 1))])
def test_simulate_rejects_bad_pose_shape(box_map, poses):
    with pytest.raises(ValueError, match=r"poses must have shape \(n_poses, 3\), got"):
        simulate_scans(box_map, poses, SMALL)


def test_simulate_rejects_bad_poses_and_headings(box_map):
    with pytest.raises(ValueError, match="poses must be finite"):
        simulate_scans(box_map, [[np.nan, 0, 0]], SMALL)
    with pytest.raises(TypeError, match="poses must hold real numbers"):
        simulate_scans(box_map, [["a", "b", "c"]], SMALL)
    with pytest.raises(ValueError, match=r"headings must have shape \(1,\) to match poses"):
        simulate_scans(box_map, [BOX_ORIGIN], SMALL, headings=[0.0, 1.0])


@pytest.mark.parametrize("env", ["octree", "scene"])
def test_simulate_rejects_origin_inside_occupied_space(box_map, env):
    environment = box_map if env == "octree" else structured_room()
    inside = [0.95, 0.05, 0.45] if env == "octree" else [0.0, 0.0, -0.05]
    with pytest.raises(ValueError, match=r"poses\[1\] = .* lies inside an occupied"):
        simulate_scans(environment, [BOX_ORIGIN, inside], SMALL)


def test_octree_free_path_in_a_box(box_map):
    poses = free_path(box_map, 6, step=0.3, clearance=0.3, height=0.45, seed=1)
    assert poses.shape == (6, 3)
    assert_allclose(np.linalg.norm(np.diff(poses, axis=0), axis=1), 0.3)
    occupied, unknown = box_map.is_occupied(poses, return_unknown=True)
    assert not (occupied | unknown).any()
    # the walls' inner faces are at +-0.9, the floor's top at 0 and the ceiling at 1.0
    assert (np.abs(poses[:, :2]) <= 0.9 - 0.3).all()


@pytest.mark.parametrize("kwargs, exc, match", [
    (dict(n_poses=0), ValueError, "n_poses must be a positive int"),
    (dict(n_poses=2.0), TypeError, "n_poses must be a positive int"),
    (dict(n_poses=3, step=0.0), ValueError, "step must lie in"),
    (dict(n_poses=3, clearance=-1.0), ValueError, r"clearance must lie in \[0.0"),
    (dict(n_poses=3, clearance=2.0), ValueError, "no collision-free path of n_poses=3"),
    (dict(n_poses=3, height=5.0), ValueError, r"found at height=5 from 0 free start\(s\)"),
])
def test_free_path_errors(box_map, kwargs, exc, match):
    with pytest.raises(exc, match=match):
        free_path(box_map, **kwargs)


def test_free_path_rejects_bad_environment():
    with pytest.raises(TypeError, match="environment must be an OccupancyOctree"):
        free_path([1, 2, 3], 3)


# --------------------------------------------------------------------------- geb079 (real map)
@pytest.mark.slow
def test_geb079_free_path_is_collision_free(geb079, geb079_path):
    poses = geb079_path
    assert poses.shape == (12, 3)
    assert_allclose(poses[:, 2], 1.0)            # 1 m above the floor (its top is at z = 0)
    assert_allclose(np.linalg.norm(np.diff(poses, axis=0), axis=1), 1.0)
    occupied, unknown = geb079.is_occupied(poses, return_unknown=True)
    assert not (occupied | unknown).any()
    # every segment crosses known free cells only
    s = np.linspace(0.0, 1.0, 51)
    along = poses[:-1, None] + s[None, :, None] * np.diff(poses, axis=0)[:, None]
    occupied, unknown = geb079.is_occupied(along.reshape(-1, 3), return_unknown=True)
    assert not (occupied | unknown).any()
    _, hit = geb079.cast_rays(poses[:-1], np.diff(poses, axis=0), max_range=1.0)
    assert not hit.any()
    # at least `clearance` (0.5 m) from every occupied cell
    centers, sizes, _ = geb079.leaves(occupied_only=True)
    gap = np.abs(poses[:, None] - centers) - sizes[:, None] / 2
    assert np.linalg.norm(np.maximum(gap, 0), axis=2).min() >= 0.5
    assert_array_equal(poses, free_path(geb079, 12, seed=0))


@pytest.mark.slow
def test_geb079_dense_scan(geb079, geb079_path):
    """The slowest test here (about 0.5 s): one default 108k-ray scan of the real map."""
    scan = simulate_scans(geb079, geb079_path[:1])[0]
    assert len(scan.points) > 50_000
    assert geb079.is_occupied(scan.points).all()
    # dense: many returns per occupied cell, spread inside it
    cells = np.unique(np.floor(scan.points / geb079.resolution), axis=0)
    assert len(scan.points) / len(cells) > 4
