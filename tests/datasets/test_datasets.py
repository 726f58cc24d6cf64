"""Tests of the synthetic scenes and sensor simulators in occgp.datasets."""

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from occgp.datasets import (
    LaserScan2D,
    Scan,
    Scene,
    Scene2D,
    make_scene,
    room_2d,
    structured_room,
    unstructured_room,
)
from occgp.datasets._geometry import Box, Ellipsoid, Frustum, rotation_matrix


@pytest.fixture(scope="module", params=["structured", "unstructured"])
def scene(request):
    return make_scene(request.param)


@pytest.fixture(scope="module")
def scans(scene):
    return scene.scan(n_poses=2, scans_per_pose=3, n_points=300, seed=0)


def _unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


# --------------------------------------------------------------------------- #
# construction
# --------------------------------------------------------------------------- #
def test_make_scene_returns_named_scenes():
    assert isinstance(make_scene("structured"), Scene)
    assert make_scene("unstructured").name == "unstructured"


def test_make_scene_rejects_unknown_name():
    with pytest.raises(ValueError, match=r"name must be one of \['structured', 'unstructured'\]"):
        make_scene("kitchen")
    with pytest.raises(TypeError, match="name must be a str"):
        make_scene(3)


@pytest.mark.parametrize("bad, exc", [(-1, ValueError), (1.5, TypeError), (True, TypeError)])
def test_room_rejects_bad_seed(bad, exc):
    with pytest.raises(exc, match="seed must be a non-negative int"):
        structured_room(bad)


def test_bounds_and_interior(scene):
    lo, hi = scene.bounds
    assert_allclose(lo, [-5.15, -3.65, -0.15])
    assert_allclose(hi, [5.15, 3.65, 2.0])
    ilo, ihi = scene.interior_bounds
    assert_allclose(ilo, [-5, -3.5, 0])
    assert_allclose(ihi, [5, 3.5, 2])


def test_nothing_occupied_outside_bounds(scene):
    rng = np.random.default_rng(0)
    lo, hi = scene.bounds
    p = rng.uniform(lo - 1, hi + 1, (20000, 3))
    outside = np.any((p < lo) | (p > hi), axis=1)
    assert not scene.occupancy(p[outside]).any()


def test_default_scene_is_deterministic_and_seed_jitters():
    a, b, c = structured_room(), structured_room(0), structured_room(1)
    assert [s.center.tolist() for s in a.solids] == [s.center.tolist() for s in b.solids]
    assert [s.center.tolist() for s in a.solids] != [s.center.tolist() for s in c.solids]
    u0, u1 = unstructured_room(0), unstructured_room(2)
    assert any(not np.allclose(x.rotation, y.rotation) for x, y in zip(u0.solids, u1.solids))


@pytest.mark.parametrize("factory", [structured_room, unstructured_room])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_default_poses_are_free(factory, seed):
    scene = factory(seed)
    assert not scene.occupancy(scene.sensor_positions).any()
    assert scene.signed_distance(scene.sensor_positions).min() >= 0.09  # 0.1 m above the floor


# --------------------------------------------------------------------------- #
# occupancy and distance
# --------------------------------------------------------------------------- #
def test_occupancy_of_shell_points(scene):
    pts = np.array([
        [0.0, 0.0, 1.0],      # room center at 1 m: free
        [0.0, 0.0, -0.05],    # floor
        [5.07, 0.0, 1.0],     # wall +x
        [-5.07, 1.0, 0.5],    # wall -x
        [0.0, 3.6, 1.5],      # wall +y
        [0.0, -3.6, 0.1],     # wall -y
        [0.0, 0.0, 2.5],      # above the open top: free
    ])
    assert scene.occupancy(pts).tolist() == [False, True, True, True, True, True, False]


def test_occupancy_of_structured_objects():
    scene = structured_room()
    pts = np.array([
        [-1.5, 1.8, 0.74],    # table top
        [-1.5, 1.8, 0.5],     # under the table: free
        [1.5, -2.0, 1.9],     # pillar
        [1.5 + 0.26, -2.0, 1.0],  # just beside the pillar
        [4.55, -2.6, 1.7],    # shelf
        [1.075, 3.0, 1.9],    # partition wall
    ])
    assert scene.occupancy(pts).tolist() == [True, False, True, False, True, True]


def test_occupancy_of_unstructured_objects():
    scene = unstructured_room()
    pts = np.array([
        [-1.8, -1.9, 0.5],        # sphere center
        [-1.8, -1.9, 1.01],       # just above it
        [-4.2, -2.6, 1.45],       # just below the cone apex
        [-4.2 + 0.1, -2.6, 1.45],  # beside the apex
        [1.5, 2.2, 0.6],          # ellipsoid center
    ])
    assert scene.occupancy(pts).tolist() == [True, False, True, False, True]


def test_signed_distance_sign_matches_occupancy(scene):
    rng = np.random.default_rng(0)
    lo, hi = scene.bounds
    p = rng.uniform(lo, hi, (5000, 3))
    d = scene.signed_distance(p)
    assert_array_equal(d <= 0, scene.occupancy(p))


def test_signed_distance_known_values():
    scene = structured_room()
    # room center at 1 m: nearest surface is the floor or an object, not closer than 0.6 m
    assert scene.signed_distance([[0.0, 0.0, 1.0]])[0] == pytest.approx(1.0)
    assert scene.signed_distance([[0.0, 0.0, -0.05]])[0] == pytest.approx(-0.05)


@pytest.mark.parametrize(
    "bad", [np.zeros((5, 2)), np.zeros(3), np.zeros((2, 3, 1)), np.array([[0.0, np.nan, 0.0]])]
)
def test_occupancy_rejects_bad_points(bad):
    with pytest.raises(ValueError, match=r"points must (have shape \(n_points, 3\)|be finite)"):
        structured_room().occupancy(bad)


# --------------------------------------------------------------------------- #
# primitives: exact analytic distances
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize(
    "solid, origin, direction, expected",
    [
        (Box([0, 0, 0], [1, 2, 3]), [-5, 0.5, 0.5], [1, 0, 0], 4.0),
        (Box([0, 0, 0], [1, 1, 1], rotation_matrix(yaw=np.pi / 4)), [-5, 0, 0], [1, 0, 0],
         5 - np.sqrt(2)),
        (Ellipsoid([1, 1, 1], [0.5, 0.5, 0.5]), [1, 1, 5], [0, 0, -1], 3.5),
        (Ellipsoid([0, 0, 0], [3, 2, 1], rotation_matrix(yaw=np.pi / 2)), [0, -10, 0],
         [0, 1, 0], 7.0),
        (Frustum([0, 0, 0], 1, 1, 2), [4, 0, 1], [-1, 0, 0], 3.0),      # cylinder side
        (Frustum([0, 0, 0], 1, 1, 2), [0.5, 0, 5], [0, 0, -1], 3.0),    # cylinder top cap
        (Frustum([0, 0, 0], 1, 0, 2), [3, 0, 1], [-1, 0, 0], 2.5),      # cone side, r(1) = 0.5
        (Frustum([0, 0, 0], 1, 0, 2), [0.2, 0, -1], [0, 0, 1], 1.0),    # cone base
        (Frustum([0, 0, 0], 1, 0, 2), [0, 0, 5], [0, 0, -1], 3.0),      # cone apex
        (Frustum([0, 0, 0], 0.5, 1.0, 1), [0.9, 0, -1], [0, 0, 1], 1.8),  # inverted frustum side
    ],
)
def test_primitive_ray_distance(solid, origin, direction, expected):
    t = solid.intersect(np.array([origin], float), _unit([direction]))
    assert t[0] == pytest.approx(expected, abs=1e-12)


@pytest.mark.parametrize(
    "solid",
    [Box([0, 0, 0], [1, 2, 3]), Ellipsoid([0, 0, 0], [1, 2, 3]), Frustum([0, 0, 0], 1, 0.3, 2)],
)
def test_primitive_misses_and_inside(solid):
    o = np.array([[10.0, 10.0, 10.0], [0.0, 0.0, 0.5]])
    d = _unit([[1.0, 0.0, 0.0], [0.3, 0.2, 0.1]])
    t = solid.intersect(o, d)
    assert np.isinf(t[0])
    assert t[1] == 0.0  # starts inside


def test_ellipsoid_signed_distance_is_exact():
    e = Ellipsoid([0, 0, 0], [3.0, 2.0, 1.0], rotation_matrix(0.3, 0.2, 0.1))
    rng = np.random.default_rng(0)
    q = rng.uniform(-3.5, 3.5, (30, 3))
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 360), np.linspace(0, np.pi, 180))
    local = np.column_stack([3 * np.cos(u).ravel() * np.sin(v).ravel(),
                             2 * np.sin(u).ravel() * np.sin(v).ravel(), np.cos(v).ravel()])
    surface = local @ e.rotation.T
    brute = np.sqrt(((q[:, None, :] - surface[None]) ** 2).sum(-1)).min(axis=1)
    sd = e.signed_distance(q)
    assert np.all(np.abs(sd) <= brute + 1e-9)  # never beyond a surface point
    assert np.all(brute - np.abs(sd) < 0.02)   # and within the sampling error of the best
    assert_array_equal(sd < 0, e.contains(q))
    # center, and a degenerate interior point on the long axis (Eberly's closed form)
    special = np.array([[0.0, 0, 0], [0.5, 0, 0]]) @ e.rotation.T
    x0 = 9 * 0.5 / 8
    expected = -np.hypot(x0 - 0.5, np.sqrt(1 - x0**2 / 9))
    assert_allclose(e.signed_distance(special), [-1.0, expected], atol=1e-9)


def test_frustum_signed_distance_known_values():
    cone = Frustum([0, 0, 0], 1.0, 0.0, 1.0)
    p = np.array([[0, 0, 2.0], [0, 0, -0.5], [2.0, 0, 0], [0, 0, 0.1]])
    assert_allclose(cone.signed_distance(p), [1.0, 0.5, 1.0, -0.1])


# --------------------------------------------------------------------------- #
# ray casting in scenes
# --------------------------------------------------------------------------- #
def test_scene_ray_cast_known_distances():
    origin = [0.0, 0.0, 1.0]
    dirs = [[0, 0, -1], [1, 0, 0], [0, 0, 1], [0, -2, 0]]
    d, hit = structured_room().ray_cast(origin, dirs, max_range=8.0)
    assert_allclose(d, [1.0, 5.0, 8.0, 3.5])
    assert hit.tolist() == [True, True, False, True]
    # unstructured: the sphere in the +x wall, center (4.7, 0.2, 1.0), radius 0.45
    d, hit = unstructured_room().ray_cast(origin, [[1.0, 0, 0]])
    assert d[0] == pytest.approx(4.7 - np.sqrt(0.45**2 - 0.2**2))


def test_ray_cast_miss_distance_is_max_range():
    d, hit = structured_room().ray_cast([0.0, 0.0, 1.0], [[0.0, 0.0, 1.0]])
    assert np.isinf(d[0]) and not hit[0]


def test_ray_cast_accepts_per_ray_origins_and_rejects_bad_input():
    scene = structured_room()
    o = np.array([[0.0, 0, 1], [0.0, 0, 0.5]])
    d, _ = scene.ray_cast(o, [[0, 0, -1], [0, 0, -1]])
    assert_allclose(d, [1.0, 0.5])
    with pytest.raises(ValueError, match="directions must be non-zero"):
        scene.ray_cast([0, 0, 1], [[0.0, 0, 0]])
    with pytest.raises(ValueError, match=r"origins must have shape \(3,\)"):
        scene.ray_cast(np.zeros((3, 3)), np.ones((2, 3)))
    with pytest.raises(ValueError, match="max_range must be positive"):
        scene.ray_cast([0, 0, 1], [[1.0, 0, 0]], max_range=0)


# --------------------------------------------------------------------------- #
# the la3dm-like sensor
# --------------------------------------------------------------------------- #
def test_poses_mimic_la3dm_layout():
    origins, headings = structured_room().poses()
    assert_allclose(origins, [[-4, 2.5, 0.1], [-3, -0.5, 0.1], [0, -1.5, 0.1], [3, 0.5, 0.1]])
    assert_allclose(np.degrees(headings), np.tile([-90.0, 30.0, 150.0], (4, 1)))


def test_extra_poses_are_seeded_and_free(scene):
    origins, headings = scene.poses(n_poses=7, scans_per_pose=2, seed=3)
    assert origins.shape == (7, 3) and headings.shape == (7, 2)
    assert not scene.occupancy(origins).any()
    again, _ = scene.poses(n_poses=7, scans_per_pose=2, seed=3)
    assert_array_equal(origins, again)


def test_scan_shapes_and_dtypes(scene, scans):
    assert len(scans) == 6
    origins, _ = scene.poses(2)
    for i, s in enumerate(scans):
        assert isinstance(s, Scan)
        assert s.points.shape == (300, 3) and s.points.dtype == np.float64
        assert s.origin.shape == (3,) and s.origin.dtype == np.float64
        assert_array_equal(s.origin, origins[i // 3])


def test_scan_points_lie_on_surfaces(scene, scans):
    for s in scans:
        assert np.abs(scene.signed_distance(s.points)).max() < 1e-9
        d = _unit(s.points - s.origin)
        ahead = scene.occupancy(s.points + 0.01 * d)
        behind = scene.occupancy(s.points - 0.01 * d)
        assert ahead.mean() > 0.97 and not behind.mean() > 0.03


def test_scan_respects_range_and_field_of_view(scene, scans):
    _, headings = scene.poses(2)
    for i, s in enumerate(scans):
        v = s.points - s.origin
        r = np.linalg.norm(v, axis=1)
        assert r.max() <= 8.0
        az = np.angle(np.exp(1j * (np.arctan2(v[:, 1], v[:, 0]) - headings[i // 3, i % 3])))
        assert np.abs(az).max() <= np.radians(117) / 2 + 1e-9
        el = np.arcsin(v[:, 2] / r)
        assert el.min() >= -1e-9 and el.max() <= np.radians(42) + 1e-9


def test_scan_is_deterministic_for_a_seed(scene, scans):
    again = scene.scan(n_poses=2, scans_per_pose=3, n_points=300, seed=0)
    other = scene.scan(n_poses=2, scans_per_pose=3, n_points=300, seed=1)
    for a, b, c in zip(scans, again, other):
        assert_array_equal(a.points, b.points)
        assert not np.allclose(a.points, c.points)


def test_scan_noise_perturbs_ranges(scene):
    noisy = scene.scan(n_poses=1, scans_per_pose=1, n_points=400, noise=0.02, seed=0)[0]
    sd = np.abs(scene.signed_distance(noisy.points))
    assert np.median(sd) > 0.002
    assert sd.max() < 6 * 0.02


def test_scan_max_range_drops_far_returns():
    s = structured_room().scan(n_poses=1, scans_per_pose=1, n_points=200, max_range=2.0)[0]
    assert np.linalg.norm(s.points - s.origin, axis=1).max() <= 2.0


@pytest.mark.parametrize(
    "kwargs, exc, match",
    [
        ({"n_points": 0}, ValueError, "n_points must be a positive int"),
        ({"n_poses": 2.0}, TypeError, "n_poses must be a positive int"),
        ({"noise": -0.1}, ValueError, "noise must be non-negative"),
        ({"max_range": -1}, ValueError, "max_range must be positive"),
        ({"seed": -3}, ValueError, "seed must be a non-negative int"),
        ({"horizontal_fov": 0}, ValueError, "horizontal_fov must be in"),
        ({"elevation_range": (0.5, 0.1)}, ValueError, "elevation_range must satisfy"),
        ({"max_range": 0.05, "n_points": 10}, ValueError, "too few rays"),
    ],
)
def test_scan_rejects_bad_arguments(kwargs, exc, match):
    with pytest.raises(exc, match=match):
        structured_room().scan(**{"n_poses": 1, "scans_per_pose": 1, **kwargs})


# --------------------------------------------------------------------------- #
# 2D room
# --------------------------------------------------------------------------- #
@pytest.fixture(scope="module")
def room():
    return room_2d()


@pytest.fixture(scope="module")
def laser(room):
    return room.scan()


def test_room_2d_geometry(room):
    assert isinstance(room, Scene2D)
    lo, hi = room.bounds
    assert_allclose(hi - lo, [22.4, 18.4])
    assert room.occupancy([[0.0, 0.0], [11.1, 0.0], [-3.0, -5.0], [-1.0, 6.5]]).tolist() == [
        False, True, True, True]
    # to the outer wall, and down onto disc_2 (center (2.5, -3), radius 0.8)
    d, hit = room.ray_cast([[0.0, 0.0], [2.5, 0.0]], [[0.0, 1.0], [0.0, -1.0]])
    assert_allclose(d, [9.0, 2.2])
    assert hit.all()
    d, hit = room.ray_cast([0.0, 0.0], [[0.0, 1.0]], max_range=5.0)
    assert d[0] == 5.0 and not hit[0]


def test_room_2d_scan_layout(laser):
    assert len(laser) == 26
    for s in laser:
        assert isinstance(s, LaserScan2D)
        assert s.angles.shape == s.ranges.shape == s.hit.shape == (17,)
        assert_allclose(s.angles[[0, -1]], [-np.pi / 2, np.pi / 2])
        assert s.points.shape == (s.hit.sum(), 2)
        assert s.max_range == 8.0
    hit = np.concatenate([s.hit for s in laser])
    ranges = np.concatenate([s.ranges for s in laser])
    assert hit.any() and (~hit).any()
    assert_array_equal(ranges[~hit], 8.0)
    assert ranges[hit].max() <= 8.0


def test_room_2d_hits_lie_on_obstacles(room, laser):
    for s in laser:
        p = s.points
        assert np.abs(room.signed_distance(p)).max() < 1e-9
        d = s.directions[s.hit]
        assert room.occupancy(p + 0.01 * d).all()
        assert not room.occupancy(p - 0.01 * d).any()


def test_room_2d_path_is_clear(room):
    origins, headings = room.poses(200)
    assert room.signed_distance(origins).min() >= 0.5
    assert headings.shape == (200,)


def test_room_2d_noise_is_seeded(room, laser):
    a = room.scan(noise=0.05, seed=1)
    b = room.scan(noise=0.05, seed=1)
    c = room.scan(noise=0.05, seed=2)
    ra = np.concatenate([s.ranges for s in a])
    assert_array_equal(ra, np.concatenate([s.ranges for s in b]))
    assert not np.array_equal(ra, np.concatenate([s.ranges for s in c]))
    clean = np.concatenate([s.ranges for s in laser])
    hit = np.concatenate([s.hit for s in laser])
    assert not np.allclose(ra[hit], clean[hit])
    assert_array_equal(ra[~hit], clean[~hit])


def test_room_2d_seed_moves_obstacles():
    a, b = room_2d(0), room_2d(1)
    assert any(not np.allclose(x.center, y.center) for x, y in zip(a.solids, b.solids))
    assert b.signed_distance(b.poses(200)[0]).min() >= 0.5


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"n_beams": 0}, "n_beams must be a positive int"),
        ({"fov": -1.0}, r"fov must lie in \[0.0, 6.28"),
        ({"max_range": np.inf}, "max_range must be finite"),
        ({"noise": -1.0}, r"noise must lie in \[0.0, inf\), got -1"),
        ({"noise": np.inf}, r"noise must lie in \[0.0, inf\), got inf"),
        ({"n_poses": 10**6, "n_beams": 10**3}, "n_poses \\* n_beams must be at most 67108864"),
    ],
)
def test_room_2d_scan_rejects_bad_arguments(room, kwargs, match):
    with pytest.raises(ValueError, match=match):
        room.scan(**kwargs)


def test_scenes_and_sensors_reject_huge_or_mistyped_sizes(room):
    from occgp.datasets import LidarSensor, structured_room
    with pytest.raises(TypeError, match="fov must be a real number, got str"):
        room.scan(fov="wide")
    with pytest.raises(ValueError, match=r"n_poses must lie in \[1, 10000000\]"):
        room.poses(10**9)
    with pytest.raises(ValueError, match=r"n_poses must lie in \[1, 10000\], got 10001"):
        structured_room().poses(10_001)
    with pytest.raises(ValueError, match="n_vertical \\* n_horizontal must be at most 16777216"):
        LidarSensor(n_horizontal=10**5, n_vertical=10**5)


def test_room_2d_rejects_bad_points(room):
    with pytest.raises(ValueError, match=r"points must have shape \(n_points, 2\)"):
        room.occupancy(np.zeros((3, 3)))


def test_scene_moved_moves_one_object_whole_and_leaves_the_scene_as_it_was():
    room = structured_room(seed=2)
    moved = room.moved("table", [0.5, -0.25, 0.0])
    for label, a, b in zip(room.labels, room.solids, moved.solids):
        shift = [0.5, -0.25, 0.0] if label.startswith("table_") else [0.0, 0.0, 0.0]
        assert np.array_equal(b.center, a.center + shift)
    assert moved.labels == room.labels and moved.name == room.name
    top = np.array([room.solids[room.labels.index("table_0")].center])
    assert room.occupancy(top).tolist() == [True]
    assert moved.occupancy(top + [0.5, -0.25, 0.0]).tolist() == [True]
    with pytest.raises(TypeError, match="label"):
        room.moved(3, [0, 0, 0])
