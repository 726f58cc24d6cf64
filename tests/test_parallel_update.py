"""The octree's tree update on several threads (``OccupancyOctree(n_jobs=)``): the tree is
the one a single thread builds, node for node (the ``.ot`` bytes hold every node's
value and children), on scans large enough to take the threaded path (at least 4096
cells), over fresh, pruned, clamped and re-opened trees."""

import numpy as np
import pytest

from occgp import OccupancyOctree
from occgp.datasets import structured_room


def room_scans(n_points=6000, seed=0):
    return structured_room(seed=seed).scan(n_poses=3, scans_per_pose=2, n_points=n_points,
                                           seed=seed)


def same_tree(a, b):
    assert a.num_nodes == b.num_nodes and a.num_leaves == b.num_leaves
    assert a.to_bytes("ot") == b.to_bytes("ot")
    assert a.memory_usage() == b.memory_usage()


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["scan", "ray"])
@pytest.mark.parametrize("method", ["plain", "culling", "superray+culling"])
@pytest.mark.parametrize("resolution", [0.05, 0.2])
def test_threaded_tree_update_gives_the_single_thread_tree(mode, method, resolution):
    scans = room_scans()
    trees = {n: OccupancyOctree(resolution, n_jobs=n) for n in (1, 2, 3, 8)}
    for points, origin in scans:
        for n, m in trees.items():
            m.insert_scan(points, origin, mode=mode, method=method)
            assert m.last_insert_.get("updated_cells", 5000) >= 4096 or resolution == 0.2
        for n in (2, 3, 8):
            same_tree(trees[n], trees[1])


@pytest.mark.slow
def test_pruned_clamped_and_reopened_trees_update_alike():
    """The same scan again and again clamps its cells (their updates abort) and prunes
    the free space into large leaves; a block set free and a block set occupied, then
    scans through them, expand pruned leaves below and above the split depth."""
    scans = room_scans(n_points=4000, seed=1)
    trees = [OccupancyOctree(0.1, n_jobs=n) for n in (1, 2, 4)]
    ar = np.arange(32) * 0.1 + 0.05
    block = np.stack(np.meshgrid(ar - 1.6, ar - 1.6, ar * 0.25, indexing="ij"),
                     -1).reshape(-1, 3)
    for m in trees:
        m.set_cells(block, -2.0)                    # one pruned 3.2 m leaf
        m.set_cells(block[::7] + [0, 0, 0.8], 3.5)  # occupied cells above it
    for rep in range(6):
        for points, origin in scans[:2]:
            for m in trees:
                m.insert_scan(points, origin, mode="ray" if rep % 2 else "scan")
        same_tree(trees[1], trees[0])
        same_tree(trees[2], trees[0])
    # the opposite evidence re-opens clamped, pruned leaves
    for m in trees:
        m.insert_scan(scans[3].points, scans[3].origin)
    same_tree(trees[1], trees[0])
    same_tree(trees[2], trees[0])


def test_threaded_update_into_a_loaded_tree_and_with_a_box():
    scans = room_scans(n_points=5000, seed=2)
    base = OccupancyOctree(0.05)
    for points, origin in scans[:2]:
        base.insert_scan(points, origin)
    data = base.to_bytes("bt")               # clamped, pruned, as a .bt file gives it
    one, two = OccupancyOctree.from_bytes(data), OccupancyOctree.from_bytes(data, n_jobs=2)
    box = [[-3.0, -2.0, 0.0], [2.0, 2.5, 1.5]]
    for points, origin in scans[2:]:
        one.insert_scan(points, origin, bbox=box)
        two.insert_scan(points, origin, bbox=box)
    same_tree(two, one)


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["scan", "ray"])
@pytest.mark.parametrize("method", ["plain", "superray+culling"])
def test_grid_updates_on_threads_give_the_single_thread_grid(mode, method):
    """GridMap applies a large scan's updates on the threads (cells it holds updated
    there, new ones inserted after, at least 32768 cells): every cell's log-odds is the
    single thread's, over repeated scans that clamp and re-open cells."""
    from occgp import GridMap
    scans = room_scans(n_points=4000, seed=3)
    grids = {n: GridMap(0.05, n_jobs=n) for n in (1, 2, 3, 8)}
    sizes = []
    for points, origin in scans + scans[::-1]:
        for n, m in grids.items():
            m.insert_scan(points, origin, mode=mode, method=method)
        sizes.append(grids[1].last_insert_["updated_cells"])
        ref = grids[1].cells()
        for n in (2, 3, 8):
            got = grids[n].cells()
            assert grids[n].num_cells == grids[1].num_cells
            np.testing.assert_array_equal(got.centers, ref.centers)
            np.testing.assert_array_equal(got.log_odds, ref.log_odds)
    assert max(sizes[1:]) >= 1 << 15       # the threaded path was taken
    floor = np.log(grids[1].clamping_min / (1 - grids[1].clamping_min))
    assert np.sum(np.abs(ref.log_odds - floor) < 1e-5) > 100   # clamped cells were updated


@pytest.mark.slow
def test_knn_map_updates_its_tree_on_threads_as_on_one():
    """KNNMap's cell updates go through the threaded tree update with its n_jobs: the
    tree is the single thread's, node for node, on scans of 4096+ cells."""
    from occgp import KNNMap
    scans = room_scans(n_points=3000, seed=5)[:4]
    maps = {n: KNNMap(0.05, k=3, max_range=6.0, n_jobs=n) for n in (1, 2, 3)}
    sizes = []
    for points, origin in scans:
        for m in maps.values():
            m.insert_scan(points, origin)
        sizes.append(maps[1].last_insert_["updated_cells"])
        for n in (2, 3):
            same_tree(maps[n], maps[1])
    assert min(sizes) >= 4096


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["scan", "ray"])
def test_super_rays_grouped_on_threads_give_the_single_thread_map(mode):
    """A dense wall (1600 end cells of about 25 points): the end cells' groups are
    classified on the threads; the super rays, their weights, the statistics and the
    tree are the single thread's."""
    rng = np.random.default_rng(11)
    scans = []
    for k in range(3):
        origin = np.array([0.03, 0.02, 0.01]) + 0.07 * k
        wall = np.column_stack([np.full(40000, 3.05), rng.uniform(-2, 2, (40000, 2))])
        scans.append((wall, origin))
    trees = {n: OccupancyOctree(0.1, n_jobs=n) for n in (1, 2, 3)}
    for points, origin in scans:
        stats = {}
        for n, m in trees.items():
            m.insert_scan(points, origin, mode=mode, method="superray")
            stats[n] = {k: m.last_insert_[k] for k in ("rays", "traversed_cells",
                                                         "updated_cells")}
        assert stats[1]["rays"] < len(points) - 500         # rays were grouped
        for n in (2, 3):
            assert stats[n] == stats[1]
            same_tree(trees[n], trees[1])
