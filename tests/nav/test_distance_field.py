"""Distance fields: the dense field's signed distances, closest cells and gradients,
and the blocked DistanceMap against the dense field and against itself updated."""

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy.spatial.distance import cdist

import occgp
from occgp import DistanceField, DistanceMap, GridMap, OccupancyOctree


def random_map(seed=0, res=0.25, n=150, extent=2.0):
    rng = np.random.default_rng(seed)
    m = OccupancyOctree(res)
    m.insert_scan(rng.uniform(-extent, extent, (n, 3)), [0.0, 0.0, 0.0])
    return m, rng


BOX = np.array([[-1.5, -1.5, -1.0], [1.5, 1.25, 1.0]])


def brute_force(m, field, unknown, signed):
    """Distances to the nearest obstacle (and inside, non-obstacle) cell center."""
    c = field.centers().reshape(-1, 3)
    occ, unk = m.is_occupied(c, return_unknown=True)
    obstacle = occ | unk if unknown == "occupied" else occ
    out = cdist(c, c[obstacle]).min(axis=1) if obstacle.any() else np.full(len(c), np.inf)
    if signed:
        out[obstacle] = -cdist(c[obstacle], c[~obstacle]).min(axis=1)
    return out.reshape(field.distances.shape), obstacle.reshape(field.distances.shape)


# --------------------------------------------------------------------------- #
# the dense field
# --------------------------------------------------------------------------- #
def test_distance_field_has_one_public_path():
    from occgp.nav import DistanceField as nav_field
    assert nav_field is DistanceField is occgp.DistanceField
    assert DistanceField.__module__ == "occgp.nav"


@pytest.mark.parametrize("unknown", ["occupied", "free"])
@pytest.mark.parametrize("signed", [False, True])
def test_dense_field_is_the_brute_force_distance(unknown, signed):
    m, _ = random_map()
    field, closest, gradient = m.distance_field(BOX, unknown=unknown, signed=signed,
                                                return_closest=True, return_gradient=True)
    expected, obstacle = brute_force(m, field, unknown, signed)
    assert_allclose(field.distances, expected, rtol=1e-14, atol=0)
    # the closest cell lies at the distance, and is an obstacle (inside: a free cell)
    here = field.centers()
    assert_allclose(np.linalg.norm(here - closest, axis=-1), np.abs(field.distances),
                    rtol=1e-12, atol=1e-12)
    occ, unk = m.is_occupied(closest.reshape(-1, 3), return_unknown=True)
    is_obstacle = (occ | unk if unknown == "occupied" else occ).reshape(obstacle.shape)
    if signed:          # outside: an obstacle; inside: a non-obstacle cell
        assert_array_equal(is_obstacle, ~obstacle)
    else:               # outside: an obstacle; inside: the cell itself
        assert is_obstacle.all()
        assert_array_equal(closest[obstacle], here[obstacle])
    # the gradient: a unit vector along (here - closest) / distance
    moving = field.distances != 0
    assert_allclose(np.linalg.norm(gradient[moving], axis=-1), 1.0, rtol=1e-12)
    assert_allclose(gradient[moving],
                    (here - closest)[moving] / field.distances[moving][:, None])
    assert_array_equal(gradient[~moving], 0.0)
    if signed:
        assert (field.distances != 0).all()
        assert_array_equal(field.distances < 0, obstacle)


def test_dense_distances_are_sqrt_of_integer_offsets_times_the_resolution():
    m, _ = random_map(1)
    field, closest = m.distance_field(BOX, signed=True, return_closest=True)
    offsets = np.rint((closest - field.centers()) / field.resolution)
    d2 = np.sum(offsets.astype(np.int64) ** 2, axis=-1)
    expected = np.sqrt(d2.astype(np.float64)) * field.resolution
    assert_array_equal(np.abs(field.distances), expected)


def test_signed_field_at_a_boundary():
    m = OccupancyOctree(0.5).set_cells([[x * 0.5 + 0.25, 0.25, 0.25] for x in range(6)],
                                       [2.0, 2.0, 2.0, -2.0, -2.0, -2.0])
    field, closest, gradient = m.distance_field([[0, 0, 0], [3, 0.5, 0.5]], signed=True,
                                                unknown="free", return_closest=True,
                                                return_gradient=True)
    assert_array_equal(field.distances[:, 0, 0], [-1.5, -1.0, -0.5, 0.5, 1.0, 1.5])
    assert_array_equal(closest[:, 0, 0, 0], [1.75, 1.75, 1.75, 1.25, 1.25, 1.25])
    assert_array_equal(gradient[:, 0, 0], [[1.0, 0, 0]] * 6)     # towards growing distance
    unsigned = m.distance_field([[0, 0, 0], [3, 0.5, 0.5]], unknown="free")
    assert_array_equal(unsigned.distances[:, 0, 0], [0, 0, 0, 0.5, 1.0, 1.5])


def test_gradient_agrees_with_finite_differences_of_the_field():
    m = OccupancyOctree(0.1).set_cells([[0.05, 0.05, 0.05]], [2.0])
    field, gradient = m.distance_field([[-1, -1, -1], [1, 1, 1]], unknown="free",
                                       return_gradient=True)
    numeric = np.stack(np.gradient(field.distances, 0.1), axis=-1)
    inner = (slice(2, -2),) * 3
    far = np.abs(field.distances[inner]) > 0.3
    assert_allclose(gradient[inner][far], numeric[inner][far], atol=0.05)


def test_closest_and_gradient_are_nan_without_an_obstacle():
    m = OccupancyOctree(0.5).set_cells([[0.25, 0.25, 0.25]], [-2.0])
    field, closest, gradient = m.distance_field([[0, 0, 0], [1, 1, 1]], unknown="free",
                                                return_closest=True, return_gradient=True)
    assert np.isinf(field.distances).all()
    assert np.isnan(closest).all() and np.isnan(gradient).all()
    field = m.distance_field([[0, 0, 0], [1, 1, 1]], unknown="free", signed=True)
    assert np.isposinf(field.distances).all()
    field = OccupancyOctree(0.5).distance_field([[0, 0, 0], [1, 1, 1]], signed=True)
    assert np.isneginf(field.distances).all()                 # all unknown: all obstacle


def test_dense_extras_come_in_order():
    m, _ = random_map()
    plain = m.distance_field(BOX)
    assert isinstance(plain, DistanceField)
    field, closest = m.distance_field(BOX, return_closest=True)
    field2, gradient = m.distance_field(BOX, return_gradient=True)
    assert closest.shape == gradient.shape == (*field.distances.shape, 3)
    assert_array_equal(field.distances, plain.distances)
    assert_array_equal(field2.distances, plain.distances)


@pytest.mark.parametrize("kwargs, match", [
    ({"signed": 1}, "signed must be a bool"),
    ({"return_closest": "yes"}, "return_closest must be a bool"),
    ({"return_gradient": None}, "return_gradient must be a bool"),
])
def test_dense_rejects_bad_flags(kwargs, match):
    with pytest.raises(TypeError, match=match):
        OccupancyOctree(0.1).distance_field([[0, 0, 0], [1, 1, 1]], **kwargs)


# --------------------------------------------------------------------------- #
# the blocked field against the dense one
# --------------------------------------------------------------------------- #
CONFIGS = [
    dict(max_distance=None, signed=False, unknown="occupied", block_size=4),
    dict(max_distance=0.6, signed=False, unknown="free", block_size=4),
    dict(max_distance=0.6, signed=True, unknown="occupied", block_size=8),
    dict(max_distance=None, signed=True, unknown="free", block_size=8),
    dict(max_distance=2.0, signed=True, unknown="free", block_size=4),
]


def clamp(d, max_distance):
    return d if max_distance is None else np.clip(d, -max_distance, max_distance)


@pytest.mark.parametrize("cfg", CONFIGS)
def test_blocked_field_equals_the_dense_field_on_every_cell(cfg):
    m, _ = random_map(2)
    blocked = DistanceMap(**cfg, bbox=BOX).fit(m)
    dense = m.distance_field(BOX, unknown=cfg["unknown"], signed=cfg["signed"])
    got, closest = blocked.dense(BOX, return_closest=True)
    assert_array_equal(got.origin, dense.origin)
    covered = ~np.isnan(got.distances)
    # every known cell is covered
    occ, unk = m.is_occupied(dense.centers().reshape(-1, 3), return_unknown=True)
    assert covered.reshape(-1)[~unk].all()
    assert_array_equal(got.distances[covered], clamp(dense.distances, cfg["max_distance"])[covered])
    # the closest cells lie at the (exactly equal) distance
    has = ~np.isnan(closest[..., 0])
    off = np.rint((closest[has] - dense.centers()[has]) / m.resolution).astype(np.int64)
    d = np.sqrt(np.sum(off**2, axis=-1).astype(np.float64)) * m.resolution
    assert_array_equal(d, np.abs(got.distances[has]))
    if cfg["max_distance"] is not None:
        assert_array_equal(np.isnan(closest[..., 0])[covered],
                           (np.abs(dense.distances) > cfg["max_distance"])[covered])


@pytest.mark.parametrize("unknown", ["occupied", "free"])
def test_blocked_field_without_a_box_sees_the_whole_map(unknown):
    m, _ = random_map(3)
    blocked = DistanceMap(unknown=unknown, signed=True, block_size=4).fit(m)
    got = blocked.dense()
    grown = [got.origin - 2 * m.resolution,
             got.origin + (np.array(got.distances.shape) + 2) * m.resolution]
    dense = m.distance_field(grown, unknown=unknown, signed=True)
    inner = dense.distances[2:-2, 2:-2, 2:-2]
    covered = ~np.isnan(got.distances)
    assert_array_equal(got.distances[covered], inner[covered])


def test_query_by_nearest_cell_and_nan_outside():
    m = OccupancyOctree(0.5).set_cells([[0.25, 0.25, 0.25], [1.75, 0.25, 0.25]],
                                       [2.0, -2.0])
    field = DistanceMap(unknown="free", block_size=4).fit(m)
    d, closest, grad = field.query([[1.9, 0.4, 0.1], [100.0, 0, 0], [1e30, 0, 0]],
                                   return_closest=True, return_gradient=True)
    assert_array_equal(d[:1], [1.5])
    assert np.isnan(d[1:]).all()
    assert_array_equal(closest[0], [0.25, 0.25, 0.25])
    assert_array_equal(grad[0], [1.0, 0.0, 0.0])
    assert np.isnan(closest[1:]).all() and np.isnan(grad[1:]).all()
    assert field.query(np.empty((0, 3))).shape == (0,)


def test_truncated_field_clamps_and_has_no_closest_beyond():
    m = OccupancyOctree(0.5).set_cells([[0.25, 0.25, 0.25], [3.25, 0.25, 0.25]],
                                       [2.0, -2.0])
    field = DistanceMap(max_distance=1.2, unknown="free", block_size=4).fit(m)
    d, closest, grad = field.query([[0.75, 0.25, 0.25], [3.25, 0.25, 0.25]],
                                   return_closest=True, return_gradient=True)
    assert_array_equal(d, [0.5, 1.2])
    assert np.isnan(closest[1]).all() and np.isnan(grad[1]).all()


def test_blocks_are_allocated_only_where_the_map_is_known_and_memory():
    m = OccupancyOctree(0.1).set_cells([[0.05, 0.05, 0.05], [5.05, 0.05, 0.05]], [2.0, 2.0])
    field = DistanceMap(max_distance=0.5, unknown="free", block_size=8).fit(m)
    assert field.num_blocks_ == 2
    assert field.memory_usage() == 2 * (21 * 8**3 + 32)
    assert field.resolution_ == 0.1
    assert "DistanceMap(max_distance=0.5" in repr(field)


def test_grid_map_fits_and_updates_from_points():
    g = GridMap(0.5).insert_scan([[2.25, 0.25, 0.25]], [0.25, 0.25, 0.25])
    field = DistanceMap(unknown="free", block_size=4).fit(g)
    assert_array_equal(field.query([[0.25, 0.25, 0.25]]), [2.0])
    g.insert_scan([[1.25, 0.25, 0.25]], [0.25, 0.25, 0.25])
    field.update(g, [[1.25, 0.25, 0.25]])
    assert_array_equal(field.query([[0.25, 0.25, 0.25]]), [1.0])


# --------------------------------------------------------------------------- #
# incremental updates
# --------------------------------------------------------------------------- #
def assert_same_field(a, b):
    assert a.num_blocks_ == b.num_blocks_
    fa, ca = a.dense(return_closest=True)
    fb, cb = b.dense(return_closest=True)
    assert_array_equal(fa.origin, fb.origin)
    assert_array_equal(fa.distances, fb.distances)          # bit for bit, NaN where uncovered
    assert_array_equal(ca, cb)


@pytest.mark.parametrize("cfg", CONFIGS)
@pytest.mark.parametrize("with_box", [pytest.param(False, marks=pytest.mark.slow), True])
def test_update_equals_a_new_fit_after_random_changes(cfg, with_box):
    m, rng = random_map(4, n=100, extent=1.5)
    kw = dict(cfg, bbox=BOX if with_box else None)
    m.track_changes = True
    field = DistanceMap(**kw).fit(m)
    B = cfg["block_size"] * m.resolution
    for step in range(6):
        kind = step % 3
        # cells on both sides of block borders, and anywhere
        border = rng.integers(-2, 3, (10, 3)) * B + rng.choice([-0.5, 0.5], (10, 3)) * m.resolution
        pts = np.concatenate([border, rng.uniform(-2, 2, (10, 3))])
        deleted = None
        if kind == 0:
            m.insert_scan(rng.uniform(-2.5, 2.5, (20, 3)), rng.uniform(-0.5, 0.5, 3))
        elif kind == 1:
            m.set_cells(pts, rng.choice([-2.0, 2.0], len(pts)))
        else:
            m.delete_cells(pts)
            deleted = pts
        field.update(m, deleted)
        m.reset_changes()
        assert_same_field(field, DistanceMap(**kw).fit(m))


def test_update_after_coarse_deletions():
    m, rng = random_map(5, n=200, extent=2.0)
    m.track_changes = True
    field = DistanceMap(max_distance=0.5, unknown="free", block_size=4).fit(m)
    pts = rng.uniform(-1.5, 1.5, (3, 3))
    m.delete_cells(pts, depth=14)
    field.update(m, pts, depth=14)
    assert_same_field(field, DistanceMap(max_distance=0.5, unknown="free", block_size=4).fit(m))


def test_update_recomputes_only_the_blocks_a_change_reaches():
    m = OccupancyOctree(0.1)
    ar = np.arange(-30, 30) * 0.1 + 0.05
    floor = np.stack(np.meshgrid(ar, ar, [0.05], indexing="ij"), -1).reshape(-1, 3)
    m.set_cells(floor, np.full(len(floor), -2.0))
    m.track_changes = True
    field = DistanceMap(max_distance=0.3, unknown="free", block_size=8).fit(m)
    assert field.num_blocks_ == 64
    m.set_cells([[1.25, 1.25, 0.05]], [2.0])              # inside one block, 3 cells reach
    field.update(m)
    assert field.last_update_["obstacle_changes"] == 1
    assert field.last_update_["recomputed"] == 1
    m.reset_changes()
    m.set_cells([[0.05, 0.05, 0.05]], [2.0])              # at a corner of four blocks
    field.update(m)
    assert field.last_update_["recomputed"] == 4
    m.reset_changes()
    m.set_cells([[-0.55, -0.55, 0.05]], [-2.0])           # free stays free: nothing to do
    assert field.update(m).last_update_["recomputed"] == 0


def test_update_without_changes_or_resetting_twice_is_harmless():
    m, rng = random_map(6)
    m.track_changes = True
    field = DistanceMap(max_distance=0.5, block_size=4).fit(m)
    m.set_cells(rng.uniform(-1, 1, (5, 3)), np.full(5, 2.0))
    field.update(m)
    field.update(m)                                       # the same record again
    assert field.last_update_["obstacle_changes"] == 0
    assert_same_field(field, DistanceMap(max_distance=0.5, block_size=4).fit(m))


# --------------------------------------------------------------------------- #
# bad input
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("kwargs, exc, match", [
    ({"max_distance": 0.0}, ValueError, r"max_distance must lie in \(0.0, inf\)"),
    ({"max_distance": "1"}, TypeError, "max_distance must be a real number"),
    ({"signed": "no"}, TypeError, "signed must be a bool"),
    ({"unknown": "maybe"}, ValueError, "unknown must be one of"),
    ({"block_size": 12}, ValueError, r"block_size must be a power of 2 in \[4, 128\]"),
    ({"block_size": 2}, ValueError, "block_size must be a power of 2"),
    ({"block_size": 16.0}, TypeError, "block_size must be a positive int"),
    ({"bbox": [[0, 0, 0], [1, 0, 1]]}, ValueError, "bbox must have min < max"),
    ({"bbox": np.zeros(3)}, ValueError, r"bbox must have shape \(2, 3\)"),
])
def test_fit_rejects_bad_parameters(kwargs, exc, match):
    with pytest.raises(exc, match=match):
        DistanceMap(**kwargs).fit(OccupancyOctree(0.1))


def test_bad_calls():
    m = OccupancyOctree(0.1).set_cells([[0.05, 0.05, 0.05]], [2.0])
    field = DistanceMap()
    with pytest.raises(ValueError, match="not fitted yet"):
        field.query([[0, 0, 0]])
    with pytest.raises(ValueError, match="not fitted yet"):
        field.update(m)
    with pytest.raises(TypeError, match="tree must be an OccupancyOctree or a GridMap"):
        field.fit(None)
    field.fit(m)
    with pytest.raises(ValueError, match="tree records no changes"):
        field.update(m)
    with pytest.raises(ValueError, match="tree must have the field's resolution 0.1"):
        field.update(OccupancyOctree(0.2), [[0, 0, 0]])
    with pytest.raises(ValueError, match=r"depth must lie in \[0, 16\]"):
        field.update(m, [[0, 0, 0]], depth=17)
    with pytest.raises(ValueError, match=r"points must have shape \(n_points, 3\)"):
        field.query([0, 0, 0])
    with pytest.raises(ValueError, match="points must be finite"):
        field.query([[np.nan, 0, 0]])
    with pytest.raises(TypeError, match="return_closest must be a bool"):
        field.query([[0, 0, 0]], return_closest=1)
    with pytest.raises(ValueError, match="more than max_cells=10"):
        field.dense(max_cells=10)


# --------------------------------------------------------------------------- #
# empty maps (issue 40): a valid start, empty in, empty out
# --------------------------------------------------------------------------- #
EMPTY_CASES = {
    "empty octree": (lambda: OccupancyOctree(0.25), None),
    "empty grid map": (lambda: GridMap(0.25), None),
    # every known cell lies outside the box
    "known cells outside bbox": (
        lambda: OccupancyOctree(0.25).insert_scan([[1.0, 0.1, 0.1]], [0.1, 0.1, 0.1]),
        [[5.0, 5.0, 5.0], [6.0, 6.0, 6.0]]),
}


@pytest.mark.parametrize("case", list(EMPTY_CASES))
@pytest.mark.parametrize("cfg", CONFIGS[:3])
def test_fit_of_an_empty_map_is_an_empty_field(case, cfg):
    make, bbox = EMPTY_CASES[case]
    field = DistanceMap(**cfg, bbox=bbox).fit(make())
    assert field.num_blocks_ == 0 and field.memory_usage() == 0
    assert field.last_update_["blocks"] == field.last_update_["recomputed"] == 0
    d, closest, grad = field.query([[0.1, 0.1, 0.1], [5.5, 5.5, 5.5]], return_closest=True,
                                   return_gradient=True)
    assert np.isnan(d).all() and np.isnan(closest).all() and np.isnan(grad).all()
    dense, closest = field.dense(return_closest=True)
    assert dense.distances.shape == (0, 0, 0) and closest.shape == (0, 0, 0, 3)
    boxed = field.dense([[5.0, 5.0, 5.0], [5.5, 5.5, 5.5]])
    assert boxed.distances.shape == (2, 2, 2) and np.isnan(boxed.distances).all()


def test_known_free_space_without_obstacles_is_inf_or_max_distance():
    m = OccupancyOctree(0.25).set_cells([[0.1, 0.1, 0.1]], [-2.0])
    assert_array_equal(DistanceMap(unknown="free", block_size=4).fit(m)
                       .query([[0.1, 0.1, 0.1]]), [np.inf])
    assert_array_equal(DistanceMap(0.5, unknown="free", block_size=4).fit(m)
                       .query([[0.1, 0.1, 0.1]]), [0.5])


@pytest.mark.parametrize("cfg", CONFIGS)
@pytest.mark.parametrize("with_box", [False, True])
def test_start_empty_fit_then_update_after_each_scan_equals_a_fit(cfg, with_box):
    """The robot's workflow: an empty map, a field fitted on it, then a scan and an
    update at a time; after each, every cell equals a new fit's."""
    rng = np.random.default_rng(7)
    kw = dict(cfg, bbox=BOX if with_box else None)
    m = OccupancyOctree(0.25)
    m.track_changes = True
    field = DistanceMap(**kw).fit(m)
    grid = np.stack(np.meshgrid(*[np.arange(-2.5, 2.5, 0.25) + 0.125] * 3, indexing="ij"),
                    -1).reshape(-1, 3)
    for _ in range(2):
        m.insert_scan(rng.uniform(-2.0, 2.0, (30, 3)), rng.uniform(-0.3, 0.3, 3))
        field.update(m)
        m.reset_changes()
        fresh = DistanceMap(**kw).fit(m)
        assert field.num_blocks_ == fresh.num_blocks_ > 0
        assert_same_field(field, fresh)
        for a, b in zip(field.query(grid, return_closest=True),
                        fresh.query(grid, return_closest=True)):
            assert_array_equal(a, b)                         # every cell, NaN included


def test_grid_map_starts_empty_and_updates_from_points():
    g = GridMap(0.5)
    field = DistanceMap(unknown="free", block_size=4).fit(g)
    g.insert_scan([[2.25, 0.25, 0.25]], [0.25, 0.25, 0.25])
    field.update(g, [[x + 0.25, 0.25, 0.25] for x in np.arange(0.0, 2.5, 0.5)])
    assert_same_field(field, DistanceMap(unknown="free", block_size=4).fit(g))
    assert_array_equal(field.query([[0.25, 0.25, 0.25]]), [2.0])
