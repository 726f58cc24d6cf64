"""OccupancyOctree: exactness against liboctomap and a pure-Python model, queries, I/O."""

import copy
import pickle

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from _helpers import random_scans, share_between_threads
from conftest import data_path
from occgp import OccupancyOctree
from octomap_reference import leaf_values, octomap_insert, ray_mode_reference
from _helpers import assert_same_leaves


# ---------------------------------------------------------------------- behaviour
def test_update_marks_walls_occupied_and_interior_free(tiny_room):
    points, origin = tiny_room
    m = OccupancyOctree(resolution=0.1).insert_scan(points, origin)
    assert np.mean(m.occupancy(points) > 0.5) > 0.95
    assert m.occupancy(origin[None])[0] < 0.5
    assert np.isnan(m.occupancy([[5.0, 5.0, 5.0]])[0])


@pytest.mark.parametrize("mode", ["scan", "ray"])
def test_queries_agree(tiny_room, mode):
    points, origin = tiny_room
    m = OccupancyOctree(0.1).insert_scan(points, origin, mode=mode)
    q = np.vstack([points, [[0, 0, 0.5], [7, 7, 7]]])
    p, lo = m.occupancy(q), m.log_odds(q)
    assert_allclose(p, 1 - 1 / (1 + np.exp(lo)), rtol=1e-6)
    occ, unknown = m.is_occupied(q, return_unknown=True)
    assert_array_equal(unknown, np.isnan(p))
    assert_array_equal(occ, np.nan_to_num(p, nan=0) >= 0.5)
    assert_array_equal(m.is_occupied(q), occ)


def test_parameters_and_repr():
    m = OccupancyOctree(0.05, prob_hit=0.8, prob_miss=0.3, clamping_min=0.2,
                        clamping_max=0.9, occupancy_threshold=0.6)
    assert m.resolution == 0.05 and m.prob_hit == 0.8 and m.occupancy_threshold == 0.6
    assert m.get_params()["clamping_max"] == 0.9
    assert m.key_range == (-32768 * 0.05, 32768 * 0.05)
    assert repr(m) == "OccupancyOctree(resolution=0.05, num_leaves=0)"
    m.insert_scan([[1.0, 0, 0]] * 5, [0, 0, 0])
    assert m.log_odds([[1.0, 0, 0]])[0] == pytest.approx(np.log(0.8 / 0.2), rel=1e-6)


def test_occupancy_threshold_changes_classification():
    pts, org = [[1.0, 0, 0]], [0, 0, 0]
    assert OccupancyOctree(0.1).insert_scan(pts, org).is_occupied(pts)[0]
    strict = OccupancyOctree(0.1, occupancy_threshold=0.8).insert_scan(pts, org)
    assert not strict.is_occupied(pts)[0]


def test_ray_mode_counts_every_ray_scan_mode_once_per_cell():
    origin = np.zeros(3)
    points = np.tile([[1.05, 0.05, 0.05]], (6, 1))
    scan = OccupancyOctree(0.1).insert_scan(points, origin, mode="scan")
    ray = OccupancyOctree(0.1).insert_scan(points, origin, mode="ray")
    logit = lambda p: np.float32(np.log(p / (1 - p)))  # noqa: E731
    assert scan.log_odds(points[:1])[0] == logit(0.7)
    assert scan.log_odds([[0.55, 0.05, 0.05]])[0] == logit(0.4)
    assert ray.log_odds(points[:1])[0] == logit(0.971)           # 6 hits: clamped
    assert ray.log_odds([[0.55, 0.05, 0.05]])[0] == logit(0.1192)   # 6 misses: clamped


def test_max_range_truncates_rays():
    m = OccupancyOctree(0.1).insert_scan([[3.05, 0.05, 0.05]], [0.05, 0.05, 0.05], max_range=1.0)
    occ, unknown = m.is_occupied([[3.05, 0.05, 0.05], [0.55, 0.05, 0.05]], return_unknown=True)
    assert unknown[0] and not occ[1] and not unknown[1]
    assert m.leaves(occupied_only=True).sizes.size == 0


def test_empty_scan_is_a_no_op():
    m = OccupancyOctree(0.1)
    assert m.insert_scan(np.empty((0, 3)), [0, 0, 0]) is m
    assert m.num_leaves == 0 and m.num_nodes == 0
    assert np.isnan(m.bounds[0]).all()


def test_leaves_filters_and_bbox(tiny_room):
    points, origin = tiny_room
    m = OccupancyOctree(0.1).insert_scan(points, origin)
    all_ = m.leaves()
    occ = m.leaves(occupied_only=True)
    assert len(all_.sizes) == m.num_leaves
    assert (occ.log_odds >= 0).all() and len(occ.sizes) < len(all_.sizes)
    box = np.array([[0.0, 0.0, 0.0], [1.2, 1.2, 1.2]])
    inside = m.leaves(bbox=box)
    # the leaves that meet the cells from the one holding min to the one holding max
    half = inside.sizes[:, None] / 2
    assert ((inside.centers + half > box[0]) & (inside.centers - half <= box[1])).all()
    half = all_.sizes[:, None] / 2
    meets = ((all_.centers + half > box[0]) & (all_.centers - half < box[1])).all(axis=1)
    assert 0 < meets.sum() <= len(inside.sizes) < len(all_.sizes)
    assert set(map(tuple, all_.centers[meets])) <= set(map(tuple, inside.centers))
    huge = m.leaves(bbox=[[-1e9] * 3, [1e9] * 3])
    assert len(huge.sizes) == len(all_.sizes)


def test_prune_expand_clear_memory_bounds(tiny_room):
    points, origin = tiny_room
    m = OccupancyOctree(0.1).insert_scan(points, origin)
    n = m.num_leaves
    values = leaf_values(m)
    m.expand()
    assert m.num_leaves >= n and (m.leaves().sizes == 0.1).all()
    m.prune()
    assert m.num_leaves == n and leaf_values(m) == values
    lo, hi = m.bounds
    assert (lo <= points.min(0)).all() and (hi >= points.max(0)).all()
    assert m.memory_usage() > 0
    assert m.clear().num_leaves == 0


def test_cast_rays():
    m = OccupancyOctree(0.1).insert_scan([[1.05, 0.05, 0.05], [0.05, 1.05, 0.05]],
                                         [0.05, 0.05, 0.05])
    ends, hits = m.cast_rays([0.05, 0.05, 0.05], [[1, 0, 0], [0, 2, 0], [0, 0, 1], [-1, 0, 0]])
    assert hits.tolist() == [True, True, False, False]
    assert_allclose(ends[:2], [[1.05, 0.05, 0.05], [0.05, 1.05, 0.05]], atol=1e-6)
    # unknown cells stop a ray unless ignored; with a range, ignored rays stop there
    ends, hits = m.cast_rays(np.tile([0.05, 0.05, 0.05], (2, 1)), [[0, 0, 1], [0, 0, 1]],
                             ignore_unknown=True, max_range=[0.5, 0.8])
    assert not hits.any() and ends[1, 2] > ends[0, 2] > 0.4
    ends, hits = m.cast_rays([0.05, 0.05, 0.05], [[0, 0, 1]], ignore_unknown=True)
    assert not hits[0]


# ---------------------------------------------------------------------- exactness
@pytest.mark.parametrize("method", ["plain", "auto"])
@pytest.mark.parametrize("max_range, discretize", [(None, False), (1.2, False), (None, True)])
def test_scan_mode_equals_liboctomap_insert_point_cloud(octomap_insert_exe, tmp_path,
                                                         max_range, discretize, method):
    """Against liboctomap's own insertPointCloud, compiled in a separate program: the
    "plain" method calls it, "auto" (the culling region) is occgp's pipeline."""
    rng = np.random.default_rng(0)
    scans = random_scans(rng, n_scans=4, n_points=300)
    params = dict(prob_hit=0.75, prob_miss=0.35, clamping_min=0.12, clamping_max=0.97)
    ref = OccupancyOctree.from_bytes(
        octomap_insert(octomap_insert_exe, tmp_path, scans, 0.05, max_range=max_range,
                       discretize=discretize, **params), **params)
    m = OccupancyOctree(0.05, **params)
    for points, origin in scans:
        m.insert_scan(points, origin, max_range=max_range, discretize=discretize,
                      method=method)
    assert ref.num_leaves > 1000
    assert_same_leaves(m, ref)


@pytest.mark.parametrize("method", ["plain", "auto", "superray", "culling", "superray+culling"])
@pytest.mark.parametrize("max_range", [None, 1.2])
def test_discretize_equals_liboctomap_for_every_method(octomap_insert_exe, tmp_path, method,
                                                       max_range):
    """discretize=True through occgp's pipeline (every method but "plain") and on the
    grid: liboctomap's insertPointCloud(..., discretize=true), leaf for leaf."""
    from occgp import GridMap

    rng = np.random.default_rng(1)
    scans = random_scans(rng, n_scans=4, n_points=400)
    # points sharing end cells, so that discretizing changes the rays
    scans = [(np.vstack([p, p[:100] + 0.01]), o) for p, o in scans]
    ref = OccupancyOctree.from_bytes(
        octomap_insert(octomap_insert_exe, tmp_path, scans, 0.05, max_range=max_range,
                       discretize=True))
    m = OccupancyOctree(0.05)
    grid = GridMap(0.05)
    for points, origin in scans:
        m.insert_scan(points, origin, max_range=max_range, discretize=True, method=method)
        if method != "plain":
            grid.insert_scan(points, origin, max_range=max_range, discretize=True,
                             method=method)
    assert_same_leaves(m, ref)
    if method != "plain":
        finest = ref.expand().leaves()
        cells = grid.cells()
        assert len(cells.centers) == len(finest.centers)
        a, b = np.lexsort(cells.centers.T), np.lexsort(finest.centers.T)
        assert_array_equal(cells.centers[a], finest.centers[b])
        assert_array_equal(cells.log_odds[a], finest.log_odds[b].astype(np.float32))


@pytest.mark.slow
def test_scan_mode_equals_liboctomap_on_real_scan(octomap_insert_exe, tmp_path):
    from occgp.io import read_xyz

    scan = read_xyz(data_path("octomap", "scan.dat.bz2"))
    points = scan.points[::4]
    ref = OccupancyOctree.from_bytes(
        octomap_insert(octomap_insert_exe, tmp_path, [(points, scan.origin)], 0.2))
    for method in ("plain", "auto", "superray+culling"):
        m = OccupancyOctree(0.2).insert_scan(points, scan.origin, method=method)
        assert_same_leaves(m, ref)


@pytest.mark.parametrize("max_range", [None, 0.9])
def test_ray_mode_equals_pure_python_reference(max_range):
    rng = np.random.default_rng(1)
    scans = random_scans(rng, n_scans=3, n_points=40, spread=1.5)
    scans.append(scans[0])                  # revisit: per-scan clamping
    scans.append((np.repeat(scans[1][0][:5], 8, axis=0), scans[1][1]))   # saturates
    ref = ray_mode_reference(scans, 0.1, max_range=max_range)
    m = OccupancyOctree(0.1)
    for points, origin in scans:
        m.insert_scan(points, origin, mode="ray", max_range=max_range)
    got = leaf_values(m)
    assert got.keys() == ref.keys()
    assert all(got[k] == ref[k] for k in ref)
    assert len(ref) > 200


def test_ray_mode_is_order_independent():
    rng = np.random.default_rng(2)
    (points, origin), = random_scans(rng, n_scans=1, n_points=500)
    a = OccupancyOctree(0.05).insert_scan(points, origin, mode="ray")
    b = OccupancyOctree(0.05).insert_scan(points[::-1], origin, mode="ray")
    assert_same_leaves(a, b)


# ---------------------------------------------------------------------- I/O
@pytest.fixture
def small_map(tiny_room):
    points, origin = tiny_room
    return OccupancyOctree(0.1).insert_scan(points, origin).insert_scan(points[:50], origin)


def test_ot_round_trip_keeps_every_leaf(small_map, tmp_path):
    small_map.save(tmp_path / "m.ot")
    assert_same_leaves(OccupancyOctree.load(tmp_path / "m.ot"), small_map)
    assert_same_leaves(OccupancyOctree.from_bytes(small_map.to_bytes()), small_map)


def test_bt_round_trip_keeps_every_leaf_state(small_map, tmp_path):
    before = small_map.leaves()
    small_map.save(tmp_path / "m.bt")
    assert_array_equal(small_map.leaves().log_odds, before.log_odds)   # map unchanged
    loaded = OccupancyOctree.load(tmp_path / "m.bt")
    # .bt stores the max-likelihood map: each cell's state, clamped
    q = before.centers
    assert_array_equal(loaded.is_occupied(q, return_unknown=True)[0], small_map.is_occupied(q))
    logit = lambda p: np.float32(np.log(p / (1 - p)))  # noqa: E731
    assert set(np.unique(loaded.leaves().log_odds)) <= {logit(0.1192), logit(0.971)}
    assert loaded.to_bytes("bt") == small_map.to_bytes("bt")


def test_resolution_survives_files_exactly(tmp_path):
    m = OccupancyOctree(1 / 3).insert_scan([[1.0, 0, 0]], [0, 0, 0])
    for fmt in ("ot", "bt"):
        assert OccupancyOctree.from_bytes(m.to_bytes(fmt)).resolution == 1 / 3


def test_pickle_and_deepcopy_keep_every_leaf(small_map):
    small = OccupancyOctree(0.1, prob_hit=0.8)
    small.insert_scan([[1.0, 0, 0]], [0, 0, 0])
    for original in (small_map, small):
        for clone in (pickle.loads(pickle.dumps(original)), copy.deepcopy(original)):
            assert clone is not original and clone.get_params() == original.get_params()
            assert_same_leaves(clone, original)
    clone = copy.deepcopy(small_map)
    clone.insert_scan([[0.5, 0.5, 0.5]], [0, 0, 0.5])
    assert clone.num_leaves != small_map.num_leaves or leaf_values(clone) != leaf_values(small_map)


def test_reads_real_bt_file_and_writes_it_back_identically():
    path = data_path("octomap", "geb079.bt")
    m = OccupancyOctree.load(path)
    assert m.resolution == 0.08
    assert 400_000 < m.num_leaves < 460_000
    assert m.to_bytes("bt") == path.read_bytes()


def test_graph2tree_reads_what_occgp_writes_and_agrees(tmp_path):
    """OctoMap's own tool builds the same (max-likelihood) map from a .graph file."""
    import shutil
    import subprocess

    from occgp.io import write_scan_graph

    if shutil.which("graph2tree") is None:
        pytest.skip("OctoMap's graph2tree tool (Debian: octomap-tools) is not installed")
    rng = np.random.default_rng(3)
    scans = random_scans(rng, n_scans=2, n_points=200)
    scans = [(p, np.zeros(3)) for p, _ in scans]      # identity poses: no float re-transform
    write_scan_graph(tmp_path / "s.graph", scans)
    subprocess.run(["graph2tree", "-i", str(tmp_path / "s.graph"), "-o", str(tmp_path / "s.bt"),
                    "-res", "0.1"], check=True, capture_output=True)
    theirs = OccupancyOctree.load(tmp_path / "s.bt")
    ours = OccupancyOctree(0.1)
    for points, origin in scans:
        ours.insert_scan(points, origin)
    assert_same_leaves(OccupancyOctree.from_bytes(ours.to_bytes("bt")), theirs)


def test_threads_share_a_tree_safely(tiny_room):
    """Queries from several threads while another inserts: no crash, same final map."""
    shared, sequential, errors = share_between_threads(
        lambda: OccupancyOctree(0.05), tiny_room,
        lambda m, points: (m.occupancy(points), m.leaves(occupied_only=True)))
    assert not errors
    assert_same_leaves(shared, sequential)


def test_weighted_rays_count_as_copies():
    """The compiled ray counter's weights (used by super rays): weight w == w copies."""
    rng = np.random.default_rng(5)
    (points, origin), = random_scans(rng, n_scans=1, n_points=30)
    weights = rng.integers(1, 6, len(points)).astype(np.uint32)
    weighted = OccupancyOctree(0.1)
    weighted._insert_batch(points.astype(np.float32), origin.astype(np.float32), -1.0, True,
                           False, weights)
    copies = OccupancyOctree(0.1).insert_scan(np.repeat(points, weights, axis=0), origin,
                                              mode="ray")
    assert_same_leaves(weighted, copies)
    with pytest.raises(ValueError, match="weights must have length 30, got 2"):
        weighted._insert_batch(points.astype(np.float32), origin.astype(np.float32), -1.0,
                               True, False, weights[:2])
