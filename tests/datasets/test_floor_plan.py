"""The large 2D floor plan: seeded layout, a clear path through every room, open
doorways, exact occupancy, and the documented observation counts."""

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from occgp.datasets import FloorPlan2D, Scene2D, floor_plan_2d, room_2d
from occgp.datasets._scene2d import Circle, Rect, path_samples
from occgp.gp import observations_from_scans

# (n_poses, observations) of seed 0 at the default size, as floor_plan_2d's docstring
TABLE = [(31, 998), (62, 1987), (154, 4985), (310, 10000), (619, 19989)]


@pytest.fixture(scope="module")
def plan():
    return floor_plan_2d()


def n_observations(scene, n_poses):
    hits, starts, _ = observations_from_scans(scene.scan(n_poses=n_poses))
    return len(hits) + len(starts)


def path_length(scene):
    return float(np.linalg.norm(np.diff(scene.path, axis=0), axis=1).sum())


def test_default_layout(plan):
    assert isinstance(plan, FloorPlan2D) and isinstance(plan, Scene2D)
    assert [b.tolist() for b in plan.interior_bounds] == [[-30.0, -20.0], [30.0, 20.0]]
    assert_allclose(np.subtract(*plan.bounds[::-1]), [60.4, 40.4])
    assert (len(plan.rooms), len(plan.solids)) == (32, 221)
    assert len(plan.path) == 176
    assert path_length(plan) == pytest.approx(508.0, abs=0.05)
    assert len(set(plan.labels)) == len(plan.labels) == len(plan.solids)
    assert {"outer_wall_-x", "outer_wall_+x", "outer_wall_-y", "outer_wall_+y"} <= set(
        plan.labels)
    for prefix in ("room_", "side_corridor_", "box_", "disc_"):
        assert any(label.startswith(prefix) for label in plan.labels)


@pytest.mark.parametrize("kwargs", [{}, {"seed": 3, "width": 31.0, "height": 23.0,
                                         "wall_thickness": 0.05, "furniture": 10}])
def test_rooms_corridors_and_doorways_have_their_sizes(kwargs):
    scene = floor_plan_2d(**kwargs)
    t = scene.wall_thickness
    size = scene.rooms[:, 1] - scene.rooms[:, 0] + t       # between wall center lines
    assert size.min() >= 4.0 - 1e-9 and size.max() <= 10.0 + 1e-9
    across = (scene.corridors[:, 1] - scene.corridors[:, 0]).min(axis=1)
    assert across.min() >= 2.0 and across.max() <= 3.0
    width = np.linalg.norm(scene.doorways[:, 1] - scene.doorways[:, 0], axis=1)
    assert width.min() >= 0.9 and width.max() <= 1.5


def test_same_seed_same_scene_other_seed_other_scene(plan):
    again, other = floor_plan_2d(0), floor_plan_2d(1)
    assert again.labels == plan.labels
    assert_array_equal(again.path, plan.path)
    for a, b in zip(again.solids, plan.solids):
        assert type(a) is type(b)
        assert_array_equal(a.center, b.center)
    assert_array_equal(again.occupancy(plan.path), plan.occupancy(plan.path))
    assert not np.array_equal(other.path, plan.path)
    assert any(not np.allclose(a.center, b.center) for a, b in zip(other.solids, plan.solids))


@pytest.mark.parametrize("kwargs", [
    {}, {"seed": 1}, {"seed": 2},
    {"width": 12.0, "height": 12.0, "wall_thickness": 0.5},
    {"seed": 3, "width": 12.0, "height": 30.0},
    {"seed": 3, "width": 31.0, "height": 23.0, "wall_thickness": 0.05, "furniture": 10},
    {"seed": 4, "width": 80.0, "height": 14.0},
])
def test_path_is_clear_and_reaches_every_room(kwargs):
    scene = floor_plan_2d(**kwargs)
    samples = path_samples(scene.path)
    assert scene.signed_distance(samples).min() >= 0.5
    assert not scene.occupancy(samples).any()
    assert np.all(np.linalg.norm(np.diff(scene.path, axis=0), axis=1) > 0)
    lo, hi = scene.interior_bounds
    assert np.all((scene.path >= lo) & (scene.path <= hi))
    for k, (rlo, rhi) in enumerate(scene.rooms):
        inside = np.all((samples > rlo + 0.5) & (samples < rhi - 0.5), axis=1)
        assert inside.any(), f"room {k} is not visited"
    for clo, chi in scene.corridors:   # and every corridor
        assert np.all((samples > clo) & (samples < chi), axis=1).any()


def test_poses_stay_clear(plan):
    origins, headings = plan.poses(800)
    assert plan.signed_distance(origins).min() >= 0.5
    step = np.linalg.norm(np.diff(origins, axis=0), axis=1)
    assert step.max() <= path_length(plan) / 799 + 1e-9
    assert headings.shape == (800,)


def test_doorways_are_open_and_their_jambs_are_walls(plan):
    center = plan.doorways.mean(axis=1)
    along = plan.doorways[:, 1] - plan.doorways[:, 0]
    half = np.linalg.norm(along, axis=1) / 2
    along /= 2 * half[:, None]
    normal = np.column_stack([-along[:, 1], along[:, 0]])
    for sign in (1.0, -1.0):              # across the doorway, both ways: no hit
        _, hit = plan.ray_cast(center - sign * 0.6 * normal, sign * normal, max_range=1.2)
        assert not hit.any()
    # beside the doorway, 5 cm past a jamb, the same ray meets the wall's face
    t = plan.wall_thickness
    beside = center + (half + 0.05)[:, None] * along
    d, hit = plan.ray_cast(beside - 0.6 * normal, normal, max_range=1.2)
    assert hit.all()
    assert_allclose(d, 0.6 - t / 2, atol=1e-12)


def test_occupancy_is_exact_on_hand_picked_points(plan):
    # the +x outer wall fills x in [30, 30.2] (both faces included); the main corridor
    # (the middle one of three) crosses x = 0 at y = 0
    e = 1e-9
    points = [[0.0, 0.0], [30.0 + e, 5.0], [30.2 - e, 5.0], [30.0 - e, 5.0], [30.2 + e, 5.0],
              [0.0, -20.1], [0.0, 20.2 - e], [0.0, -20.2 - e]]
    assert plan.occupancy(points).tolist() == [False, True, True, False, False, True,
                                               True, False]
    # inside every solid: a wall's or a box's center, a disc's center
    assert plan.occupancy([s.center for s in plan.solids]).all()
    # every corridor is free (no furniture in corridors)
    for lo, hi in plan.corridors:
        g = np.stack(np.meshgrid(np.linspace(lo[0], hi[0], 40)[1:-1],
                                 np.linspace(lo[1], hi[1], 7)[1:-1]), -1).reshape(-1, 2)
        assert not plan.occupancy(g).any()
    # room 0 (bottom left) ends at its +y wall, t thick, beyond which lies corridor 0;
    # 0.2 m from the room's left end there is no doorway
    t = plan.wall_thickness
    lo, hi = plan.rooms[0]
    x = lo[0] + 0.2
    face = [[x, hi[1] - 1e-9], [x, hi[1] + 1e-9], [x, hi[1] + t - 1e-9], [x, hi[1] + t + 1e-9]]
    assert plan.occupancy(face).tolist() == [False, True, True, False]


def test_room_walls_are_where_the_rooms_end(plan):
    t = plan.wall_thickness
    rooms_walls = [s for s, label in zip(plan.solids, plan.labels) if label.startswith("room_")]
    assert all(isinstance(s, Rect) and np.isclose(min(s.half), t / 2) for s in rooms_walls)
    # every point of a room's free box is at least its distance from the box's edge from
    # the walls: a wall never reaches into a room
    for lo, hi in plan.rooms[:5]:
        g = np.stack(np.meshgrid(np.linspace(lo[0], hi[0], 30),
                                 np.linspace(lo[1], hi[1], 30)), -1).reshape(-1, 2)
        to_edge = np.minimum(np.minimum(g[:, 0] - lo[0], hi[0] - g[:, 0]),
                             np.minimum(g[:, 1] - lo[1], hi[1] - g[:, 1]))
        walls = np.min([s.signed_distance(g) for s in rooms_walls], axis=0)
        assert np.all(walls >= to_edge - 1e-9)


def test_furniture_boxes_some_rotated_and_discs(plan):
    boxes = [s for s, label in zip(plan.solids, plan.labels) if label.startswith("box_")]
    discs = [s for s, label in zip(plan.solids, plan.labels) if label.startswith("disc_")]
    assert boxes and discs
    assert all(isinstance(s, Rect) for s in boxes) and all(isinstance(s, Circle)
                                                            for s in discs)
    rotated = [not np.allclose(s.rotation, np.eye(2)) for s in boxes]
    assert any(rotated) and not all(rotated)
    bare = floor_plan_2d(furniture=0)
    assert not any(label.startswith(("box_", "disc_")) for label in bare.labels)
    assert_array_equal(bare.rooms, plan.rooms)      # furniture comes after the layout


@pytest.mark.parametrize("make", [room_2d, lambda: room_2d(1), lambda: floor_plan_2d(2)],
                         ids=["room_2d", "room_2d(1)", "floor_plan_2d(2)"])
def test_occupancy_equals_the_union_of_every_solid(make):
    # Scene2D.occupancy tests each solid on the points of its bounding box only
    scene = make()
    rng = np.random.default_rng(0)
    lo, hi = scene.bounds
    g = np.stack(np.meshgrid(np.arange(lo[0], hi[0], 0.3),
                             np.arange(lo[1], hi[1], 0.3)), -1).reshape(-1, 2)
    edges = []
    for s in scene.solids:                # points on, just inside and just outside edges
        if isinstance(s, Rect):
            local = rng.uniform(-1, 1, (20, 2)) * s.half
            local[:10, 0] = np.sign(local[:10, 0]) * s.half[0]
            local[10:, 1] = np.sign(local[10:, 1]) * s.half[1]
            edges.append(s.center + local @ s.rotation.T)
        else:
            a = rng.uniform(0, 2 * np.pi, 20)
            edges.append(s.center + s.radius * np.column_stack([np.cos(a), np.sin(a)]))
    e = np.vstack(edges)
    points = np.vstack([g, e, np.nextafter(e, e + 1), np.nextafter(e, e - 1)])
    union = np.zeros(len(points), dtype=bool)
    for s in scene.solids:
        union |= s.contains(points)
    assert_array_equal(scene.occupancy(points), union)
    assert union.any() and not union.all()


def test_occupancy_and_signed_distance_of_no_points(plan):
    assert plan.occupancy(np.zeros((0, 2))).shape == (0,)
    assert plan.signed_distance(np.zeros((0, 2))).shape == (0,)


@pytest.mark.parametrize("n_poses, expected", TABLE[:3])
def test_observation_counts_are_as_documented(plan, n_poses, expected):
    assert n_observations(plan, n_poses) == expected


@pytest.mark.parametrize("seed", [1, 2])
def test_observation_counts_of_other_seeds_are_close(seed):
    scene = floor_plan_2d(seed)
    for n_poses, expected in TABLE[:2]:
        assert abs(n_observations(scene, n_poses) - expected) <= 0.03 * expected
    assert 30 <= n_observations(scene, 62) / 62 <= 34     # the rule of thumb: ~32 per pose


def test_scan_hits_lie_on_the_solids(plan):
    for s in plan.scan(n_poses=20):
        assert np.abs(plan.signed_distance(s.points)).max() < 1e-9
        d = s.directions[s.hit]
        assert plan.occupancy(s.points + 0.01 * d).all()
        assert not plan.occupancy(s.points - 0.01 * d).any()


@pytest.mark.parametrize(
    "kwargs, exc, match",
    [
        ({"seed": -1}, ValueError, "seed must be a non-negative int, got -1"),
        ({"seed": 1.5}, TypeError, "seed must be a non-negative int, got float"),
        ({"width": 5.0}, ValueError, r"width must lie in \[12, 1000\] m .* got 5.0"),
        ({"height": 11.9}, ValueError, r"height must lie in \[12, 1000\] m"),
        ({"width": 1e30}, ValueError, r"width must lie in \[12, 1000\] m"),
        ({"height": 1000.5}, ValueError, r"height must lie in \[12, 1000\] m"),
        ({"width": np.nan}, ValueError, r"width must lie in \[12, 1000\] m .* got nan"),
        ({"height": np.inf}, ValueError, r"height must lie in \[12, 1000\] m .* got inf"),
        ({"width": "60"}, TypeError, "width must be a real number, got str"),
        ({"height": None}, TypeError, "height must be a real number, got NoneType"),
        ({"wall_thickness": 0.0}, ValueError, r"wall_thickness must lie in \[0.05, 0.5\]"),
        ({"wall_thickness": 2.0}, ValueError, r"wall_thickness must lie in \[0.05, 0.5\]"),
        ({"wall_thickness": True}, TypeError, "wall_thickness must be a real number"),
        ({"furniture": -1}, ValueError, r"furniture must lie in \[0, 10\], got -1"),
        ({"furniture": 11}, ValueError, r"furniture must lie in \[0, 10\], got 11"),
        ({"furniture": 2.0}, TypeError, "furniture must be a non-negative int, got float"),
    ],
)
def test_rejects_bad_arguments(kwargs, exc, match):
    with pytest.raises(exc, match=match):
        floor_plan_2d(**kwargs)


def test_sizes_are_keyword_only():
    with pytest.raises(TypeError, match="positional"):
        floor_plan_2d(0, 60.0)
