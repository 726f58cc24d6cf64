"""GridMap: cell for cell the octree's finest level, queries, pickling, bad input."""

import copy
import pickle

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from _helpers import random_scans, share_between_threads
from conftest import data_path
from occgp import GridMap, OccupancyOctree
from octomap_reference import MAX_VAL, leaf_values, ray_mode_reference
from _helpers import grid_values, assert_same_cells

PARAMS = dict(prob_hit=0.75, prob_miss=0.35, clamping_min=0.12, clamping_max=0.97)


def grid_scans(rng, n_scans=4, n_points=150):
    """Scans of random rays from origins scattered around the map's center."""
    return random_scans(rng, n_scans, n_points, origins=0.7, near=0.1)


def with_revisits(scans):
    """`scans`, the first again, then four times one that saturates its cells (clamping)."""
    points, origin = scans[1]
    return [*scans, scans[0], *[(np.repeat(points[:8], 10, axis=0), origin)] * 4, scans[2]]


def build_both(scans, resolution, **kwargs):
    grid, tree = GridMap(resolution, **PARAMS), OccupancyOctree(resolution, **PARAMS)
    for points, origin in scans:
        assert grid.insert_scan(points, origin, **kwargs) is grid
        tree.insert_scan(points, origin, **kwargs)
    return grid, tree


# ---------------------------------------------------------------------- exactness
@pytest.mark.parametrize("mode", ["scan", "ray"])
@pytest.mark.parametrize("max_range", [None, 1.1])
@pytest.mark.parametrize("resolution", [0.05, 0.1])
def test_random_scans_equal_octree_cell_for_cell(mode, max_range, resolution):
    scans = with_revisits(grid_scans(np.random.default_rng(0)))
    grid, tree = build_both(scans, resolution, mode=mode, max_range=max_range)
    expected = leaf_values(tree)
    assert_same_cells(grid_values(grid), expected)
    assert grid.num_cells == len(expected) > 300
    values = np.array(list(expected.values()))
    for bound in (0.12, 0.97):                                   # cells saturated both ways
        assert (values == np.float32(np.log(bound / (1 - bound)))).any()


@pytest.mark.parametrize("mode", ["scan", "ray"])
@pytest.mark.parametrize("max_range", [None, 0.8])
def test_tiny_room_equals_octree_cell_for_cell(tiny_room, mode, max_range):
    points, origin = tiny_room
    shifted = [(points, origin + offset) for offset in ([0, 0, 0], [0.3, -0.2, 0.1])]
    grid, tree = build_both(shifted * 2, 0.1, mode=mode, max_range=max_range)
    assert_same_cells(grid_values(grid), leaf_values(tree))


@pytest.mark.parametrize("max_range", [None, 0.9])
def test_ray_mode_equals_pure_python_reference(max_range):
    scans = with_revisits(grid_scans(np.random.default_rng(1), n_scans=3, n_points=40))
    grid = GridMap(0.1)
    for points, origin in scans:
        grid.insert_scan(points, origin, mode="ray", max_range=max_range)
    assert_same_cells(grid_values(grid), ray_mode_reference(scans, 0.1, max_range=max_range))


@pytest.mark.slow
def test_real_scan_equals_octree():
    from occgp.io import read_xyz

    scan = read_xyz(data_path("octomap", "scan.dat.bz2"))
    points = scan.points[::32]
    for mode in ("scan", "ray"):
        grid = GridMap(0.2).insert_scan(points, scan.origin, mode=mode)
        tree = OccupancyOctree(0.2).insert_scan(points, scan.origin, mode=mode)
        assert_same_cells(grid_values(grid), leaf_values(tree))


def test_weighted_rays_count_as_copies():
    (points, origin), = grid_scans(np.random.default_rng(5), n_scans=1, n_points=30)
    weights = np.random.default_rng(6).integers(1, 6, len(points)).astype(np.uint32)
    weighted = GridMap(0.1)
    weighted._insert(points.astype(np.float32), origin.astype(np.float32), -1.0, True, False,
                     weights)
    copies = GridMap(0.1).insert_scan(np.repeat(points, weights, axis=0), origin, mode="ray")
    assert_same_cells(grid_values(weighted), grid_values(copies))
    with pytest.raises(ValueError, match="weights must have length 30, got 2"):
        weighted._insert(points.astype(np.float32), origin.astype(np.float32), -1.0, True,
                         False, weights[:2])


# ---------------------------------------------------------------------- queries
@pytest.mark.parametrize("mode", ["scan", "ray"])
def test_queries_agree_with_octree(tiny_room, mode):
    points, origin = tiny_room
    grid, tree = build_both([(points, origin)], 0.1, mode=mode)
    rng = np.random.default_rng(2)
    q = np.vstack([points, rng.uniform(-1.5, 1.5, (300, 3)), [[0, 0, 0.5], [7, 7, 7],
                                                                [1e6, 0, 0]]])
    p = grid.occupancy(q)
    assert np.isnan(p).any() and not np.isnan(p).all()
    assert_array_equal(p, tree.occupancy(q))                  # NaN where unknown, too
    assert_array_equal(grid.log_odds(q), tree.log_odds(q))
    occ, unknown = grid.is_occupied(q, return_unknown=True)
    tree_occ, tree_unknown = tree.is_occupied(q, return_unknown=True)
    assert_array_equal(occ, tree_occ)
    assert_array_equal(unknown, tree_unknown)
    assert_array_equal(unknown, np.isnan(p))
    assert_array_equal(grid.is_occupied(q), occ)


def test_cells_bounds_and_structure(tiny_room):
    points, origin = tiny_room
    grid, tree = build_both([(points, origin)], 0.1)
    leaves = OccupancyOctree.from_bytes(tree.to_bytes(), **PARAMS).expand().leaves()
    order = np.lexsort(leaves.centers.T)
    cells = grid.cells()
    assert_array_equal(cells.centers, leaves.centers[order])      # keyToCoord, sorted by key
    assert_array_equal(cells.log_odds, leaves.log_odds[order])
    occupied = grid.cells(occupied_only=True)
    assert 0 < len(occupied.sizes) < len(cells.sizes)
    assert grid.is_occupied(occupied.centers).all()
    for got, expected in zip(grid.bounds, tree.bounds):
        assert_allclose(got, expected, rtol=0, atol=1e-12)
    assert grid.memory_usage() > grid.num_cells * 12
    assert grid.clear() is grid and grid.num_cells == 0
    assert np.isnan(grid.bounds[0]).all() and len(grid.cells().sizes) == 0
    assert np.isnan(grid.occupancy(points)).all()


def test_parameters_repr_and_empty_scan():
    m = GridMap(0.05, prob_hit=0.8, prob_miss=0.3, clamping_min=0.2, clamping_max=0.9,
                occupancy_threshold=0.6)
    assert m.resolution == 0.05 and m.prob_hit == 0.8 and m.prob_miss == 0.3
    assert m.clamping_min == 0.2 and m.clamping_max == 0.9 and m.occupancy_threshold == 0.6
    assert m.get_params() == dict(resolution=0.05, prob_hit=0.8, prob_miss=0.3,
                                  clamping_min=0.2, clamping_max=0.9, occupancy_threshold=0.6,
                                  n_jobs=None)
    assert m.key_range == (-32768 * 0.05, 32768 * 0.05)
    assert repr(m) == "GridMap(resolution=0.05, num_cells=0)"
    assert m.insert_scan(np.empty((0, 3)), [0, 0, 0]) is m and m.num_cells == 0
    m.insert_scan([[1.0, 0, 0]] * 5, [0, 0, 0])
    assert m.log_odds([[1.0, 0, 0]])[0] == pytest.approx(np.log(0.8 / 0.2), rel=1e-6)
    assert m.is_occupied([[1.0, 0, 0]])[0]
    strict = GridMap(0.1, occupancy_threshold=0.8).insert_scan([[1.0, 0, 0]], [0, 0, 0])
    assert not strict.is_occupied([[1.0, 0, 0]])[0]               # p = 0.7 < 0.8
    assert repr(m) == f"GridMap(resolution=0.05, num_cells={m.num_cells})"


def test_max_range_truncates_rays():
    m = GridMap(0.1).insert_scan([[3.05, 0.05, 0.05]], [0.05, 0.05, 0.05], max_range=1.0)
    occ, unknown = m.is_occupied([[3.05, 0.05, 0.05], [0.55, 0.05, 0.05]], return_unknown=True)
    assert unknown[0] and not occ[1] and not unknown[1]
    assert len(m.cells(occupied_only=True).sizes) == 0


# ---------------------------------------------------------------------- copies, threads
@pytest.fixture
def small_map(tiny_room):
    points, origin = tiny_room
    return GridMap(0.1, **PARAMS).insert_scan(points, origin).insert_scan(points[:50], origin,
                                                                          mode="ray")


def test_pickle_and_deepcopy_keep_every_cell(small_map):
    for original in (small_map, GridMap(0.2, prob_hit=0.8)):
        for clone in (pickle.loads(pickle.dumps(original)), copy.deepcopy(original)):
            assert type(clone) is GridMap and clone is not original
            assert clone.get_params() == original.get_params()
            assert_same_cells(grid_values(clone), grid_values(original))
    clone = copy.deepcopy(small_map)
    clone.insert_scan([[0.5, 0.5, 0.5]], [0, 0, 0.5])
    assert grid_values(clone) != grid_values(small_map)
    assert len(pickle.dumps(small_map)) < 11 * small_map.num_cells + 500


def test_corrupt_payload_is_refused(small_map):
    payload = small_map.__reduce__()[1][2]
    with pytest.raises(ValueError, match="payload must hold 10 bytes per cell, got 7 bytes"):
        GridMap(0.1)._load_payload(payload[:7])
    bad = bytearray(payload)
    bad[-4:] = np.float32(np.inf).tobytes()
    with pytest.raises(ValueError, match="payload holds non-finite log-odds"):
        GridMap(0.1)._load_payload(bytes(bad))


def test_threads_share_a_map_safely(tiny_room):
    shared, sequential, errors = share_between_threads(
        lambda: GridMap(0.05), tiny_room,
        lambda m, points: (m.occupancy(points), m.cells(occupied_only=True)))
    assert not errors
    assert_same_cells(grid_values(shared), grid_values(sequential))


# ---------------------------------------------------------------------- bad input
@pytest.fixture
def m():
    return GridMap(0.1).insert_scan([[1.0, 0, 0], [0, 1.0, 0]], [0, 0, 0])


# the checks the grid shares with the octree (points and origin of insert_scan, query
# points, constructor parameters) are in test_octree_errors.py

@pytest.mark.parametrize("mode", ["scan", "ray"])
def test_points_outside_key_range_rejected_and_map_unchanged(m, mode):
    before = grid_values(m)
    pts = np.array([[1.0, 0, 0], [4000.0, 0, 0], [0, -3300, 0]])
    with pytest.raises(ValueError, match=r"2 of 3 points lie outside the grid's key range "
                       r"\[-3276.8, 3276.8\) m .* row 1\); the map is unchanged"):
        m.insert_scan(pts, [0, 0, 0], mode=mode)
    with pytest.raises(ValueError, match=r"origin \[5000.0, 0.0, 0.0\] lies outside"):
        m.insert_scan([[1.0, 0, 0]], [5000, 0, 0], mode=mode)
    assert grid_values(m) == before
    m.insert_scan([[4000.0, 0, 0]], [0, 0, 0], max_range=2.0, mode=mode)   # truncated: fine
    assert not m.is_occupied([[1.5, 0, 0]])[0]


@pytest.mark.parametrize("kwargs, err, match", [
    (dict(mode="fast"), ValueError, r"mode must be one of \('scan', 'ray'\), got 'fast'"),
    (dict(max_range=0.0), ValueError, r"max_range must lie in \(0.0, inf\), got 0.0"),
    (dict(max_range=np.nan), ValueError, "max_range must lie in"),
    (dict(max_range="5"), TypeError, "max_range must be a real number, got str"),
])
def test_insert_rejects_bad_options(m, kwargs, err, match):
    with pytest.raises(err, match=match):
        m.insert_scan([[1.0, 0, 0]], [0, 0, 0], **kwargs)


def test_uninitialised_core_raises():
    with pytest.raises(ValueError, match="was not initialised"):
        GridMap.__new__(GridMap).occupancy([[0.0, 0.0, 0.0]])


# ---------------------------------------------------------------------- methods
@pytest.mark.parametrize("resolution", [pytest.param(0.1, marks=pytest.mark.slow), 0.4])
@pytest.mark.parametrize("mode", ["scan", "ray"])
def test_every_method_gives_the_plain_grid(mode, resolution):
    """Super rays and the culling region on the grid: the same cells, bit for bit, as
    the plain method and as the octree (revisits saturate free space for culling)."""
    from _helpers import room_sequence
    scans = room_sequence(np.random.default_rng(7), n_scans=8, n_points=1500)
    maps = {}
    for method in ("plain", "culling", "superray", "superray+culling"):
        m = GridMap(resolution)
        rays = []
        for points, origin in scans:
            m.insert_scan(points, origin, mode=mode, method=method, superray_threshold=3)
            rays.append(m.last_insert_["rays"])
        maps[method] = grid_values(m)
        if method == "superray" and resolution == 0.4:
            assert min(rays) < len(scans[0][0])         # some rays grouped
        if method == "superray+culling" and resolution == 0.1:
            # (at 0.4 m, the last scan's new points lie in cells near the sensor)
            assert m.last_insert_["region_cells"] > (0 if mode == "ray" else -1)
    for method in ("culling", "superray", "superray+culling"):
        assert_same_cells(maps[method], maps["plain"])
    octree = OccupancyOctree(resolution)
    for points, origin in scans:
        octree.insert_scan(points, origin, mode=mode)
    octree.expand()
    assert_same_cells(maps["plain"], leaf_values(octree))


def test_grid_method_is_checked():
    with pytest.raises(ValueError, match="method must be one of"):
        GridMap(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0], method="fast")
    with pytest.raises(ValueError, match=r"superray_threshold must lie in \[1, 2147483647\], got 0"):
        GridMap(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0], method="superray",
                                 superray_threshold=0)
    with pytest.raises(TypeError, match="superray_threshold must be a positive int, got float"):
        GridMap(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0], superray_threshold=2.5)
