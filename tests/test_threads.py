"""Threaded scan updates: the map is the same, cell for cell, for every n_jobs."""

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from _helpers import random_scans
from occgp import GridMap, KNNMap, OccupancyOctree
from occgp._status import Status
from occgp.cli import main
from occgp.datasets import structured_room
from occgp.io import write_pcd
from occgp.knn import ScanReplay
from _helpers import room_sequence

N_JOBS = [1, 2, 3, 4, -1]
METHODS = ["plain", "culling", "superray", "superray+culling"]
# the counts of last_insert_ that do not depend on timing (with an explicit method)
COUNTS = ("rays", "updated_cells", "traversed_cells", "region_cells", "culled_rays",
          "region_spared_cells")


def scenes():
    """(name, scans, resolution): a revisited room (the culling region grows), random
    rays from moving origins, a dense cloud whose end cells hold many points (super
    rays form)."""
    rng = np.random.default_rng(7)
    dense = []
    for k in range(3):
        origin = np.array([0.05, 0.05, 0.05]) + 0.1 * k
        wall = np.column_stack([np.full(500, 1.5), rng.uniform(-0.4, 0.4, (500, 2))])
        d = rng.normal(size=(100, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        dense.append((np.vstack([wall, origin + d * rng.uniform(0.5, 1.5, (100, 1))]), origin))
    return [("room", room_sequence(np.random.default_rng(0), n_scans=4, n_points=400), 0.1),
            ("random", random_scans(np.random.default_rng(1), n_scans=2, n_points=300), 0.05),
            ("dense", dense, 0.2)]


SCENES = scenes()
# the room (4 scans of 400 points) is the slow case of every method and mode
SCENE_PARAMS = [pytest.param(*s, id=s[0], marks=[pytest.mark.slow] if s[0] == "room" else [])
                for s in SCENES]


def build(cls, scans, resolution, n_jobs=None, **kwargs):
    """Insert `scans` in order into a map with `n_jobs`; return the map and each scan's
    timing-free counts."""
    m = cls(resolution, n_jobs=n_jobs)
    counts = []
    for points, origin in scans:
        m.insert_scan(points, origin, **kwargs)
        counts.append({k: m.last_insert_.get(k) for k in COUNTS})
    return m, counts


def assert_same_octree(a, b):
    la, lb = a.leaves(), b.leaves()
    assert a.num_nodes == b.num_nodes and a.num_leaves == b.num_leaves
    # leaves() walks the tree in one order: equal trees give equal arrays
    assert_array_equal(la.centers, lb.centers)
    assert_array_equal(la.sizes, lb.sizes)
    assert_array_equal(la.log_odds, lb.log_odds)


def assert_same_grid(a, b):
    ca, cb = a.cells(), b.cells()
    assert a.num_cells == b.num_cells
    assert_array_equal(ca.centers, cb.centers)
    assert_array_equal(ca.log_odds, cb.log_odds)


@pytest.mark.parametrize("name,scans,resolution", SCENE_PARAMS)
@pytest.mark.parametrize("mode", ["scan", "ray"])
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("cls, assert_same", [(OccupancyOctree, assert_same_octree),
                                              (GridMap, assert_same_grid)],
                         ids=["octree", "grid"])
def test_map_is_identical_for_every_n_jobs(cls, assert_same, name, scans, resolution, mode,
                                           method):
    kwargs = dict(mode=mode, method=method, superray_threshold=3)
    ref, ref_counts = build(cls, scans, resolution, n_jobs=1, **kwargs)
    for n_jobs in N_JOBS[1:]:
        m, counts = build(cls, scans, resolution, n_jobs=n_jobs, **kwargs)
        assert_same(m, ref)
        # (superray+culling backs off from super rays by measured times: its counts vary)
        assert counts == ref_counts or method == "superray+culling", n_jobs


@pytest.mark.parametrize("cls", [OccupancyOctree, GridMap])
def test_auto_method_gives_the_same_map_for_every_n_jobs(cls):
    """"auto" adapts to measured times (its counts may differ), never its map."""
    _, scans, res = SCENES[0]
    ref, _ = build(cls, scans, res, n_jobs=1)
    for n_jobs in N_JOBS[1:]:
        m, _ = build(cls, scans, res, n_jobs=n_jobs)
        (assert_same_octree if cls is OccupancyOctree else assert_same_grid)(m, ref)


def _core_insert(m, points, origin, n_threads, **kw):
    """The compiled insertion of a map with an explicit thread count (beyond the cores)."""
    pts = np.ascontiguousarray(points, np.float32)
    org = np.asarray(origin, np.float32)
    args = (pts, org, kw.get("max_range", -1.0), kw.get("ray_mode", False),
            kw.get("culling", False), kw.get("weights"), kw.get("threshold", 0),
            kw.get("diagnose", False), kw.get("max_cells", 0))
    if isinstance(m, GridMap):
        return m._insert(*args, n_threads)
    return m._insert_batch(*args, kw.get("key_box"), n_threads)


@pytest.mark.parametrize("cls", [OccupancyOctree, GridMap])
@pytest.mark.parametrize("kw", [
    dict(), dict(ray_mode=True), dict(culling=True), dict(threshold=3),
    dict(ray_mode=True, culling=True, threshold=3), dict(max_range=0.8),
    dict(ray_mode=True, weights="w"), dict(diagnose=True, culling=True),
], ids=["scan", "ray", "culling", "superray", "ray+superray+culling", "max_range",
        "weights", "diagnose"])
def test_more_threads_than_cores_give_the_same_map(cls, kw):
    """The core's thread count, unbounded by the cores: 1 to 7 threads (and more
    threads than rays / 64, which the core reduces)."""
    _, scans, res = SCENES[0]
    results = []
    for n_threads in (1, 2, 3, 4, 7, 50):
        m = cls(res)
        stats = []
        for k, (points, origin) in enumerate(scans):
            args = dict(kw)
            if args.get("weights") == "w":
                args["weights"] = (np.arange(len(points)) % 5 + 1).astype(np.uint32)
            out = _core_insert(m, points, origin, n_threads, **args)
            stats.append(out[:4] + out[5:])          # all but the seconds
        results.append((m, stats))
    ref, ref_stats = results[0]
    for m, stats in results[1:]:
        (assert_same_octree if cls is OccupancyOctree else assert_same_grid)(m, ref)
        assert stats == ref_stats


@pytest.mark.slow
def test_bbox_max_range_and_key_tables_give_the_same_map():
    """bbox= and max_range on occgp's traversal; a key box of 10.6M cells (dense counts
    for one thread only: 2 x 10.6M > 2^24 cells, so the core keeps one thread), and one
    of 17.8M cells (> 2^24: every thread counts in its own hash table)."""
    _, scans, res = SCENES[1]
    box = [[-1.0, -1.2, -0.8], [1.1, 0.9, 1.0]]
    for method in ("plain", "culling", "superray"):
        kwargs = dict(mode="ray", method=method, bbox=box, max_range=1.5, superray_threshold=2)
        ref, ref_counts = build(OccupancyOctree, scans, res, n_jobs=1, **kwargs)
        for n_jobs in N_JOBS[1:]:
            m, counts = build(OccupancyOctree, scans, res, n_jobs=n_jobs, **kwargs)
            assert_same_octree(m, ref)
            assert counts == ref_counts
    rng = np.random.default_rng(3)
    for edge in (2.19, 2.6):                   # key boxes 220^3 and 261^3 at 1 cm
        points = rng.uniform(0.0, edge, (300, 3))
        points[:2] = [[0.0, 0.0, 0.0], [edge, edge, edge]]
        for cls in (OccupancyOctree, GridMap):
            maps = []
            for n_threads in (1, 2, 3):
                m = cls(0.01)
                out = _core_insert(m, points, [1.1, 1.1, 1.1], n_threads, ray_mode=True)
                maps.append((m, out[:4]))
            for m, out in maps[1:]:
                (assert_same_octree if cls is OccupancyOctree else assert_same_grid)(
                    m, maps[0][0])
                assert out == maps[0][1]


def test_change_tracking_is_the_same_for_every_n_jobs():
    _, scans, res = SCENES[0]
    got = []
    for n_jobs in N_JOBS:
        m = OccupancyOctree(res, n_jobs=n_jobs)
        m.insert_scan(*scans[0], method="plain")
        m.track_changes = True
        for points, origin in scans[1:]:
            m.insert_scan(points, origin, method="plain")   # occgp's traversal
        got.append(m.changed_cells())
    for changes in got[1:]:
        assert_array_equal(changes.keys, got[0].keys)
        assert_array_equal(changes.new, got[0].new)
    assert len(got[0].keys) > 0


@pytest.mark.parametrize("cls", [OccupancyOctree, GridMap])
def test_max_scan_cells_gives_the_same_outcome_for_every_n_jobs(cls):
    """The scan's distinct cells decide: at that many, every n_jobs inserts it; one
    fewer, every n_jobs rejects it (and changes nothing)."""
    _, scans, res = SCENES[2]
    points, origin = scans[0]
    for method in ("plain", "culling", "superray"):
        distinct = cls(res).insert_scan(points, origin, mode="ray", method=method,
                                        superray_threshold=3).last_insert_["updated_cells"]
        for n_threads in (1, 2, 3, 4, 7):
            m = cls(res)
            kw = dict(ray_mode=True, culling=method == "culling",
                      threshold=3 if method == "superray" else 0)
            assert _core_insert(m, points, origin, n_threads, max_cells=distinct - 1,
                                **kw) == Status.TOO_MANY_CELLS
            assert (m.num_cells if cls is GridMap else m.num_nodes) == 0
            assert _core_insert(m, points, origin, n_threads, max_cells=distinct,
                                **kw)[1] == distinct
        for n_jobs in N_JOBS:
            m = cls(res, n_jobs=n_jobs)
            m.MAX_SCAN_CELLS = distinct // 10        # threads stop early, alike
            with pytest.raises(ValueError, match=r"reach more than MAX_SCAN_CELLS"):
                m.insert_scan(points, origin, mode="ray", method=method)
            assert (m.num_cells if cls is GridMap else m.num_nodes) == 0
            m.MAX_SCAN_CELLS = distinct
            m.insert_scan(points, origin, mode="ray", method=method, superray_threshold=3)
            assert m.last_insert_["updated_cells"] == distinct


def test_knn_map_is_identical_for_every_n_jobs():
    _, scans, res = SCENES[0]
    scans = scans[:3]
    ref = None
    for n_jobs in (1, 2, -1):
        for method in ("plain", "superray+culling"):
            m = KNNMap(res, k=2, max_range=1.8, n_jobs=n_jobs)
            for points, origin in scans:
                m.insert_scan(points, origin, method=method)
            if ref is None:
                ref = m
            assert_same_octree(m, ref)
    # the core's cells and classes, for thread counts beyond the cores
    points, origin = scans[0]
    pts, org = points.astype(np.float32), origin.astype(np.float32)
    base = None
    for n_threads in (1, 2, 3, 5):
        near, keys, kinds, point_cell, stats = KNNMap(res)._knn_cells(
            pts, org, 1.8, False, 3, 0, n_threads)
        order = np.argsort(keys)
        got = (near, keys[order], kinds[order], keys[point_cell], stats[:4])
        if base is None:
            base = got
        for a, b in zip(got, base):
            assert_array_equal(a, b)
    replay = [ScanReplay(scans, res, max_range=1.8, ks=(2,), n_jobs=n).octomap_log_odds(
        [dict(prob_hit=0.7, prob_miss=0.4, clamping_min=0.12, clamping_max=0.97)])
        for n in (1, 2)]
    assert_array_equal(replay[0], replay[1])


@pytest.mark.parametrize("cls", [OccupancyOctree, GridMap])
@pytest.mark.parametrize("n_jobs", [0, 1.5, "2", True, np.float64(2.0)])
def test_bad_n_jobs_is_rejected_before_the_map_changes(cls, n_jobs):
    bad = r"n_jobs must be None, a positive int or a negative int \(-1: every core\), got"
    with pytest.raises(ValueError, match=bad):
        cls(0.1, n_jobs=n_jobs)
    m = cls(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0])
    before = m.num_cells if cls is GridMap else m.num_nodes
    with pytest.raises(ValueError, match=bad):
        m.set_params(n_jobs=n_jobs)
    assert m.n_jobs is None and m.get_params()["n_jobs"] is None
    for method in ("plain", "auto"):          # the deprecated per-call form
        with pytest.raises(ValueError, match=bad):
            m.insert_scan([[0, 1.0, 0]], [0, 0, 0], method=method, n_jobs=n_jobs)
    assert (m.num_cells if cls is GridMap else m.num_nodes) == before


@pytest.mark.parametrize("cls", [OccupancyOctree, GridMap])
def test_n_jobs_is_a_parameter_and_the_per_call_form_is_deprecated(cls):
    """n_jobs is the constructor's (get_params, set_params, clone, pickles); the
    per-call ``insert_scan(n_jobs=)`` of earlier releases warns and still works."""
    import pickle

    from sklearn.base import clone

    _, scans, res = SCENES[1]
    ref, _ = build(cls, scans, res, n_jobs=1)
    m = cls(res, n_jobs=2)
    assert m.n_jobs == 2 and m.get_params()["n_jobs"] == 2
    assert clone(m).n_jobs == 2 and pickle.loads(pickle.dumps(m)).n_jobs == 2
    assert m.set_params(n_jobs=-1).n_jobs == -1
    old = cls(res)
    for points, origin in scans:
        m.insert_scan(points, origin)
        with pytest.warns(DeprecationWarning, match=r"insert_scan\(n_jobs=\) is deprecated"):
            old.insert_scan(points, origin, n_jobs=2)
    (assert_same_grid if cls is GridMap else assert_same_octree)(m, ref)
    (assert_same_grid if cls is GridMap else assert_same_octree)(old, ref)
    assert old.n_jobs is None                  # the call's threads, not the map's


def test_liboctomap_path_takes_n_jobs_and_gives_its_map():
    """mode="scan", method="plain" is liboctomap's insertPointCloud, on one thread."""
    _, scans, res = SCENES[1]
    ref, _ = build(OccupancyOctree, scans, res, method="plain")
    m, _ = build(OccupancyOctree, scans, res, method="plain", n_jobs=2)
    assert_same_octree(m, ref)


def test_cli_map_with_n_jobs_gives_the_single_thread_map(tmp_path, capsys):
    scans = structured_room().scan(n_poses=1, scans_per_pose=2, n_points=500)
    paths = [tmp_path / f"s{i}.pcd" for i in range(len(scans))]
    for path, scan in zip(paths, scans):
        write_pcd(path, scan.points, scan.origin)
    maps = []
    for n_jobs in ("1", "2"):
        out = tmp_path / f"m{n_jobs}.ot"
        assert main(["map", *map(str, paths), "-o", str(out), "--resolution", "0.1",
                     "--mode", "ray", "--n-jobs", n_jobs, "--no-progress"]) == 0
        maps.append(OccupancyOctree.load(out))
    capsys.readouterr()
    assert_same_octree(maps[1], maps[0])
    expected = OccupancyOctree(0.1)
    for scan in scans:
        expected.insert_scan(scan.points.astype(np.float32), scan.origin, mode="ray")
    assert_same_octree(maps[1], expected)
