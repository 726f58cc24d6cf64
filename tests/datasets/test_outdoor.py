"""Procedural outdoor scenes (occgp.datasets.outdoor_scene)."""

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from occgp.datasets import OutdoorScene, Scene, outdoor_scene


@pytest.fixture(scope="module")
def scene():
    return outdoor_scene(seed=1)


def test_scene_has_every_kind_of_object(scene):
    assert isinstance(scene, OutdoorScene) and isinstance(scene, Scene)
    kinds = set(scene.labels)
    assert {"ground", "hill", "building", "wall", "pole", "tree_trunk", "tree_crown", "car_body",
            "car_cabin", "curb"} <= kinds
    assert 40 <= len(scene.solids) <= 150
    assert len(scene.labels) == len(scene.solids)
    heights = [s.aabb[1][2] for s, label in zip(scene.solids, scene.labels) if label == "building"]
    assert min(heights) >= 3.0 - 1e-9 and max(heights) <= 25.0 + 1e-9
    assert np.ptp(heights) > 5.0                              # varied sizes
    lo, hi = scene.bounds
    assert_allclose(lo, [-40, -40, -1]) and hi[0] == 40 and hi[2] >= max(heights)
    assert "OutdoorScene(size=80.0, seed=1" in repr(scene)


def test_seeded():
    a, b, c = outdoor_scene(5, size=50), outdoor_scene(5, size=50), outdoor_scene(6, size=50)
    assert a.labels == b.labels
    assert all(np.array_equal(x.center, y.center) for x, y in zip(a.solids, b.solids))
    assert a.labels != c.labels or not all(
        np.array_equal(x.center, y.center) for x, y in zip(a.solids, c.solids))


def test_hills_are_slopes_above_the_ground(scene):
    hills = [s for s, label in zip(scene.solids, scene.labels) if label == "hill"]
    for hill in hills:
        up = hill.rotation[:, 2]                   # the tilted top face's normal
        assert 0.97 < up[2] < 0.998                # 4 to 12 degrees
        # some of the slab rises above the ground, and its top is reachable from above
        top = hill.center + hill.rotation @ [hill.half_extents[0] * 0.9, 0, hill.half_extents[2]]
        assert top[2] > 0
        d, hit = scene.ray_cast(top + [0, 0, 5.0], [[0, 0, -1.0]])
        assert hit[0] and d[0] <= 5.0 + 1e-9


def test_occupancy_and_ray_cast_are_exact(scene):
    # straight down from the trajectory: the flat road at z = 0
    origins = scene.trajectory(15)[:, :3, 3]
    for o in origins:
        d, hit = scene.ray_cast(o, [[0.0, 0.0, -1.0]])
        assert hit[0] and d[0] == pytest.approx(1.73)
    assert not scene.occupancy(origins).any()
    assert scene.occupancy([[0.0, 0.0, -0.5], [0.0, 0.0, 0.0]]).all()
    # a building's center is occupied; a ray at it stops on its face
    b = next(s for s, label in zip(scene.solids, scene.labels) if label == "building")
    assert scene.occupancy(b.center[None])[0]
    d, hit = scene.ray_cast(b.center + [0.0, 0.0, 100.0], [[0.0, 0.0, -1.0]])
    assert hit[0] and d[0] == pytest.approx(100.0 - b.half_extents[2], abs=1e-9)
    d, hit = scene.ray_cast([0.0, -1.5, 1.7], [[0.0, 0.0, 1.0]])
    assert not hit[0]                                              # the sky
    assert np.isfinite(scene.signed_distance(origins)).all()


def test_trajectory(scene):
    poses = scene.trajectory(15)
    assert poses.shape == (15, 4, 4)
    assert_allclose(poses[:, :3, 3][:, 1:], [[-1.5, 1.73]] * 15)
    assert_allclose(np.diff(poses[:, 0, 3]), 70 / 14)
    assert_array_equal(poses[:, :3, :3], np.broadcast_to(np.eye(3), (15, 3, 3)))
    assert (scene.signed_distance(poses[:, :3, 3]) > 0.3).all()
    assert_allclose(scene.trajectory(1, height=2.0)[0, :3, 3], [0, -1.5, 2.0])
    origins, headings = scene.poses(4, 2)
    assert origins.shape == (4, 3) and headings.shape == (4, 2)
    assert_allclose(headings[0], [0.0, -np.pi])


def test_random_poses(scene):
    poses = scene.random_poses(40, seed=3)
    assert poses.shape == (40, 4, 4)
    assert_array_equal(poses, scene.random_poses(40, seed=3))
    assert not np.array_equal(poses, scene.random_poses(40, seed=4))
    origins = poses[:, :3, 3]
    assert (scene.signed_distance(origins) >= 0.5 - 1e-9).all()
    assert_allclose(origins[:, 2], 1.73)
    on_main = np.abs(origins[:, 1]) < 4.0
    on_cross = np.abs(origins[:, 0] - scene.cross_x) < 4.0
    assert (on_main | on_cross).all() and on_main.any() and on_cross.any()
    rot = poses[:, :3, :3]
    assert_allclose(rot @ rot.transpose(0, 2, 1), np.broadcast_to(np.eye(3), (40, 3, 3)),
                    atol=1e-12)


@pytest.mark.parametrize("call, exc, match", [
    (lambda: outdoor_scene(-1), ValueError, r"seed must be a non-negative int, got -1"),
    (lambda: outdoor_scene(1.5), TypeError, r"seed must be a non-negative int, got float"),
    (lambda: outdoor_scene(0, size=10), ValueError, r"size must lie in \[30.0, 400.0\]"),
    (lambda: outdoor_scene(0, size=1e30), ValueError, r"size must lie in \[30.0, 400.0\]"),
    (lambda: outdoor_scene(0, size=np.nan), ValueError, r"size must lie in"),
    (lambda: outdoor_scene(0, size="80"), TypeError, r"size must be a real number"),
    (lambda: outdoor_scene(0, ground_margin=-1), ValueError, r"ground_margin must lie in"),
    (lambda: outdoor_scene(0, vegetation="yes"), TypeError, r"vegetation must be a bool"),
    (lambda: outdoor_scene(0, size=40).trajectory(0), ValueError,
     r"n_poses must lie in \[1, 10000\], got 0"),
    (lambda: outdoor_scene(0, size=40).trajectory(3, height=0.0), ValueError,
     r"height must lie in \(0.2, 50.0\)"),
    (lambda: outdoor_scene(0, size=40).trajectory(3, margin=30.0), ValueError,
     r"margin must lie in \[0.0, 20.0\)"),
    (lambda: outdoor_scene(0, size=40).random_poses(3, seed=-2), ValueError,
     r"seed must be a non-negative int"),
    (lambda: outdoor_scene(0, size=40).random_poses(3, heading_jitter=4.0), ValueError,
     r"heading_jitter must lie in \[0.0, 3.14"),
])
def test_bad_input(call, exc, match):
    with pytest.raises(exc, match=match):
        call()


def test_every_seed_of_the_first_hundreds_builds_a_scene():
    # a hill short and shallow enough that its top edge lies below 0.5 m once failed
    # in the random draw of its height (seeds 50, 113, 120, 154, 175, 198)
    for seed in (50, 113, 120, 154, 175, 198, *range(0, 300, 29)):
        assert len(outdoor_scene(seed).solids) > 50


@pytest.fixture(scope="module")
def green():
    return outdoor_scene(seed=1, vegetation=True)


@pytest.mark.slow
def test_vegetation_adds_clutter_and_keeps_the_rest(scene, green):
    kinds = list(green.labels)
    for kind, least in (("hedge", 4), ("bush", 20), ("grass", 30)):
        assert kinds.count(kind) >= least, kind
    assert green.vegetation and not scene.vegetation
    assert len(green.solids) <= 500
    # each tree crown became several small ellipsoids
    assert kinds.count("tree_crown") >= 5 * scene.labels.count("tree_crown")
    # everything but the crowns is the same solid as without vegetation
    plain = [(label, s) for s, label in zip(scene.solids, scene.labels) if label != "tree_crown"]
    same = [(label, s) for s, label in zip(green.solids, green.labels)
            if label not in ("tree_crown", "hedge", "bush", "grass")]
    assert [label for label, _ in plain] == [label for label, _ in same]
    assert all(np.array_equal(a.center, b.center) for (_, a), (_, b) in zip(plain, same))
    # vegetation stands off the roads (and off the sidewalks but for hedges)
    for s, label in zip(green.solids, green.labels):
        if label in ("hedge", "bush", "grass"):
            x, y = s.center[:2]
            reach = 4.0 + (0.5 if label == "hedge" else 3.0)
            assert abs(y) > reach or abs(x - green.cross_x) > reach
            lo, hi = s.aabb
            assert hi[2] < 2.5 and lo[2] > -1.0


@pytest.mark.slow
def test_vegetation_is_exact_and_seeded(green):
    again = outdoor_scene(seed=1, vegetation=True)
    assert again.labels == green.labels
    assert all(np.array_equal(a.center, b.center) for a, b in zip(again.solids, green.solids))
    for kind in ("bush", "hedge", "grass", "tree_crown"):
        solid = green.solids[green.labels.index(kind)]
        assert green.occupancy(solid.center[None])[0]          # exact occupancy
        top, down = solid.center + [0.0, 0.0, 10.0], np.array([[0.0, 0.0, -1.0]])
        d, hit = green.ray_cast(top, down)
        # a ray straight down onto the solid stops on it, or on a solid above it
        first = min(s.intersect(top[None], down)[0] for s in green.solids)
        assert hit[0] and d[0] == pytest.approx(first)
        assert d[0] <= solid.intersect(top[None], down)[0] < 10.0


@pytest.mark.slow
def test_vegetation_scene_poses_stay_clear(green):
    poses = green.random_poses(40, seed=3)
    origins = poses[:, :3, 3]
    assert (green.signed_distance(origins) >= 0.5 - 1e-9).all()
    assert (green.signed_distance(green.trajectory(15)[:, :3, 3]) > 0.3).all()
