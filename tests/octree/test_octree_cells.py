"""Per-cell access of the octree: update_cells, set_cells, keys, extraction, max likelihood."""

import math

import numpy as np
import pytest

from occgp import OccupancyOctree
from octomap_reference import MAX_VAL, f32, leaf_values, logodds32


def sequential_reference(points, values, resolution, lo, hi, start=None):
    """updateNode(point, value) row by row: float32 add, clamp after each."""
    out = dict(start or {})
    rf = 1.0 / resolution
    for p, v in zip(np.asarray(points, np.float32), values):
        key = tuple(math.floor(rf * float(c)) + MAX_VAL for c in p)
        value = f32(out.get(key, f32(0.0)) + f32(v))
        out[key] = lo if value < lo else (hi if value > hi else value)
    return out


def test_update_cells_is_updatenode_row_by_row():
    rng = np.random.default_rng(0)
    # 300 rows in 40 cells: many repeats, large values, so clamping interleaves
    cells = rng.integers(-20, 20, (40, 3)) * 0.1 + 0.05
    points = cells[rng.integers(0, 40, 300)] + rng.uniform(-0.04, 0.04, (300, 3))
    values = rng.normal(0.0, 1.5, 300).astype(np.float32)
    m = OccupancyOctree(0.1, clamping_min=0.2, clamping_max=0.8)
    m.insert_scan(points[:50], [0.05, 0.05, 0.05])
    before = leaf_values(m)
    m.update_cells(points, values)
    ref = sequential_reference(points, values, 0.1, logodds32(0.2), logodds32(0.8), before)
    assert leaf_values(m) == ref


def test_update_cells_occupied_uses_the_sensor_model():
    pts = [[0.05, 0.05, 0.05], [1.05, 0.05, 0.05], [0.05, 0.05, 0.05]]
    a = OccupancyOctree(0.1, prob_hit=0.8, prob_miss=0.3).update_cells(
        pts, occupied=np.array([True, False, True]))
    b = OccupancyOctree(0.1, prob_hit=0.8, prob_miss=0.3).update_cells(
        pts, [logodds32(0.8), logodds32(0.3), logodds32(0.8)])
    assert a.to_bytes() == b.to_bytes()
    c = OccupancyOctree(0.1, prob_hit=0.8).update_cells(pts[:1], occupied=True)
    assert c.log_odds(pts[:1])[0] == logodds32(0.8)


def test_set_cells_last_value_wins_and_clamps():
    m = OccupancyOctree(0.1).set_cells([[0.05, 0.05, 0.05], [0.05, 0.05, 0.05],
                                        [1.05, 0, 0]], [1.0, -0.5, 100.0])
    assert m.log_odds([[0.05, 0.05, 0.05]])[0] == np.float32(-0.5)
    assert m.log_odds([[1.05, 0, 0]])[0] == logodds32(0.971)


def test_keys_round_trip_against_liboctomap_cells():
    rng = np.random.default_rng(1)
    m = OccupancyOctree(0.07).insert_scan(rng.uniform(-3, 3, (200, 3)), [0.01, 0.02, 0.03])
    centers, sizes, _ = m.expand().leaves()
    keys = m.coord_to_key(centers)
    # liboctomap: floor of the single-precision coordinate times 1 / resolution
    ref = np.floor(centers.astype(np.float32).astype(np.float64) * (1 / 0.07)) + MAX_VAL
    np.testing.assert_array_equal(keys, ref)
    np.testing.assert_array_equal(m.key_to_coord(keys), centers)
    assert keys.dtype == np.uint16


def test_key_to_coord_at_depth_is_the_pruned_leaf_center():
    # a fully observed 0.8 m cube of free space prunes into coarse leaves
    m = OccupancyOctree(0.1)
    g = (np.arange(8) + 0.5) * 0.1
    cube = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    m.set_cells(cube, -1.0)
    centers, sizes, _ = m.leaves()
    assert len(centers) == 1 and sizes[0] == pytest.approx(0.8)
    depth = 16 - 3
    np.testing.assert_allclose(m.key_to_coord(m.coord_to_key(cube[:5]), depth),
                               np.repeat(centers, 5, axis=0))


def test_extract_points_splits_the_leaves():
    rng = np.random.default_rng(2)
    m = OccupancyOctree(0.1).insert_scan(rng.uniform(-2, 2, (100, 3)), [0.05, 0.05, 0.05])
    occ, occ_sizes = m.extract_points()
    free, _ = m.extract_points(occupied=False)
    assert len(occ) + len(free) == m.num_leaves
    assert m.is_occupied(occ).all() and not m.is_occupied(free).any()
    assert len(occ_sizes) == len(occ)


def test_to_max_likelihood():
    m = OccupancyOctree(0.1).insert_scan([[1.05, 0.05, 0.05]], [0.05, 0.05, 0.05])
    occupied = m.is_occupied([[1.05, 0.05, 0.05], [0.55, 0.05, 0.05]])
    assert m.to_max_likelihood() is m
    np.testing.assert_array_equal(m.is_occupied([[1.05, 0.05, 0.05], [0.55, 0.05, 0.05]]),
                                  occupied)
    values = set(np.unique(m.leaves().log_odds).tolist())
    assert values == {float(logodds32(0.1192)), float(logodds32(0.971))}


@pytest.mark.parametrize("call, exc, match", [
    (lambda m: m.update_cells([[np.nan, 0, 0]], 1.0), ValueError, "points"),
    (lambda m: m.update_cells([[1e30, 0, 0]], 1.0), ValueError, "key range"),
    (lambda m: m.update_cells([[0, 0, 0], [1, 0, 0]], [1.0]), ValueError, r"shape \(2,\)"),
    (lambda m: m.update_cells([[0, 0, 0]], [1e39]), ValueError, "finite in single"),
    (lambda m: m.update_cells([[0, 0, 0]], ["a"]), TypeError, "log_odds"),
    (lambda m: m.update_cells([[0, 0, 0]]), ValueError, "exactly one"),
    (lambda m: m.update_cells([[0, 0, 0]], 1.0, occupied=True), ValueError, "exactly one"),
    (lambda m: m.update_cells([[0, 0, 0]], occupied=[1]), TypeError, "booleans"),
    (lambda m: m.set_cells([[0, 0, 0]], np.inf), ValueError, "finite"),
    (lambda m: m.key_to_coord([[0, 0, 70000]]), ValueError, r"\[0, 65535\]"),
    (lambda m: m.key_to_coord([[0, 0]]), ValueError, "shape"),
    (lambda m: m.key_to_coord([[0.5, 0, 0]]), TypeError, "keys"),
    (lambda m: m.key_to_coord([[0, 0, 0]], depth=17), ValueError, "depth"),
    (lambda m: m.coord_to_key([[0, 0, 1e30]]), ValueError, "key range"),
    (lambda m: m.extract_points(occupied="yes"), TypeError, "occupied"),
])
def test_bad_input_leaves_the_map_unchanged(call, exc, match):
    m = OccupancyOctree(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0])
    before = m.to_bytes()
    with pytest.raises(exc, match=match):
        call(m)
    assert m.to_bytes() == before


# ---------------------------------------------------------------------- bbox
BOX = np.array([[-1.0, -0.7, 0.1], [1.3, 0.9, 1.6]])


@pytest.mark.parametrize("method", ["culling", "superray", "superray+culling"])
@pytest.mark.parametrize("max_range", [None, 1.5])
def test_bbox_insert_equals_liboctomap(method, max_range):
    from _helpers import room_sequence
    scans = room_sequence(np.random.default_rng(3), n_scans=6, n_points=600)
    ref, other = OccupancyOctree(0.1), OccupancyOctree(0.1)
    for points, origin in scans:
        ref.insert_scan(points, origin, method="plain", bbox=BOX, max_range=max_range)
        other.insert_scan(points, origin, method=method, bbox=BOX, max_range=max_range)
    assert leaf_values(ref) == leaf_values(other)
    lo, hi = ref.coord_to_key(BOX)
    keys = np.array(list(leaf_values(ref)))
    assert len(keys) and ((keys >= lo) & (keys <= hi)).all()


def test_bbox_rays_ending_outside_change_nothing():
    m = OccupancyOctree(0.1)
    m.insert_scan([[3.0, 0.05, 0.5], [5.0, 5.0, 5.0]], [0.05, 0.05, 0.5], bbox=BOX)
    assert m.num_leaves == 0
    m.insert_scan([[1.0, 0.05, 0.5]], [-3.05, 0.05, 0.5], bbox=BOX, method="culling")
    # the ray's cells inside the box only: x from -1.0 to its end cell at 1.0
    centers = m.extract_points(occupied=False)[0]
    assert centers[:, 0].min() > -1.0 and m.is_occupied([[1.0, 0.05, 0.5]])[0]


@pytest.mark.parametrize("bbox, match", [
    ([[0, 0, 0]], r"shape \(2, 3\)"), ([[1, 0, 0], [0, 1, 1]], "min <= max"),
    ([[0, 0, 0], [np.inf, 1, 1]], "finite"), ([[0, 0, 0], [1e30, 1, 1]], "bbox corners"),
])
def test_bad_bbox(bbox, match):
    m = OccupancyOctree(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0])
    before = m.to_bytes()
    with pytest.raises(ValueError, match=match):
        m.insert_scan([[0.5, 0, 0]], [0, 0, 0], bbox=bbox)
    assert m.to_bytes() == before


# ---------------------------------------------------------------------- changes
def record(changes, before, after, occ_log):
    """liboctomap's change-detection rule, from the cells' values before and after."""
    for key, value in after.items():
        if key not in before:
            changes.setdefault(key, True)
        elif (before[key] >= occ_log) != (value >= occ_log):
            if key not in changes:
                changes[key] = False
            elif changes[key] is False:
                del changes[key]


@pytest.mark.slow
@pytest.mark.parametrize("method", ["plain", "culling", "superray+culling"])
def test_change_detection_follows_liboctomaps_rule(method):
    from _helpers import room_sequence
    scans = room_sequence(np.random.default_rng(6), n_scans=6, n_points=400)
    occ_log = logodds32(0.5)
    m = OccupancyOctree(0.1)
    m.track_changes = True
    plain = OccupancyOctree(0.1)
    expected: dict = {}
    rng = np.random.default_rng(1)
    for i, (points, origin) in enumerate(scans):
        before = leaf_values(plain)
        plain.insert_scan(points, origin, method="plain")
        m.insert_scan(points, origin, method=method)
        if i == 3:       # cells set and updated by hand flip too
            pts = points[:30]
            vals = rng.normal(0, 3, 30).astype(np.float32)
            plain.update_cells(pts, vals)
            m.update_cells(pts, vals)
        record(expected, before, leaf_values(plain), occ_log)
        if i == 4:
            got = m.changed_cells()
            assert {tuple(k): bool(n) for k, n in zip(got.keys.tolist(), got.new)} == expected
            m.reset_changes()
            expected = {}
    assert m.to_bytes() == plain.to_bytes()
    got = m.changed_cells()
    assert {tuple(k): bool(n) for k, n in zip(got.keys.tolist(), got.new)} == expected
    assert expected and not all(expected.values())     # flips were recorded, not only new
    np.testing.assert_allclose(got.centers, m.key_to_coord(got.keys))


def test_change_detection_off_by_default_and_with_set_cells():
    m = OccupancyOctree(0.1).insert_scan([[0.35, 0.05, 0.05]], [0.05, 0.05, 0.05])
    assert not m.track_changes and len(m.changed_cells().keys) == 0
    m.track_changes = True
    m.set_cells([[0.35, 0.05, 0.05], [2.05, 0.05, 0.05]], [-2.0, 1.0])
    got = m.changed_cells()
    assert got.new.tolist() == [False, True]          # a flip, then a new cell
    with pytest.raises(TypeError, match="track_changes"):
        m.track_changes = "yes"
