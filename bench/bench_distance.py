"""Distance fields: the incremental update of :class:`occgp.DistanceMap` vs a full
recomputation, side by side in one run, for small changes to a real-size map.

Scene: OctoMap's ``geb079.bt`` (a building floor, 0.08 m cells, about 3.5 M
cells in its bounding box) from ``../shared/data/octomap/`` when it is there,
else occgp's structured room mapped from 8 simulated LiDAR scans at 0.05 m.

For each field configuration (truncated unsigned, truncated signed,
untruncated), the field is fitted on the map with ``track_changes`` on, then
each change is applied to the map and the field is brought up to date twice:
by ``update`` (the blocks the change can reach) and by a new ``fit`` (every
block). The two fields are checked equal (bit for bit) and the table gives the
changed cells, the cells whose obstacle state flipped, the blocks recomputed,
both times and their ratio. The last column is the dense
``distance_field`` of the map's box (one scipy transform over every cell, the
unsigned field with no truncation), for scale.

Changes:

* ``scan``: one simulated LiDAR scan (3,600 beams) from a free pose, inserted.
* ``box moved``: a 0.4 m box of obstacle cells moved by 0.5 m (deleted cells
  passed to ``update``).
* ``one cell``: one free cell set occupied.

Run: ``python bench/bench_distance.py`` (``--quick``: the first configuration).
"""

from __future__ import annotations

import argparse
import pathlib
import time

import numpy as np

from occgp import DistanceMap, OccupancyOctree
from occgp.datasets import LidarSensor, simulate_scans, structured_room

DATA = pathlib.Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "octomap"
SENSOR = LidarSensor(n_horizontal=240, n_vertical=15, max_range=8.0)


def load_scene():
    path = DATA / "geb079.bt"
    if path.exists():
        return "geb079.bt", OccupancyOctree.load(path)
    scene = structured_room()
    poses, _ = scene.poses(8)
    tree = OccupancyOctree(0.05)
    for scan in simulate_scans(scene, poses, SENSOR, progress=False):
        tree.insert_scan(scan.points, scan.origin)
    return "structured_room (geb079.bt absent)", tree


def free_pose(tree, rng):
    """A free cell center near the middle of the map, at least 0.5 m from obstacles."""
    lo, hi = tree.bounds
    centers = tree.leaves()[0]
    free = centers[~tree.is_occupied(centers)]
    mid = (lo + hi) / 2
    order = np.argsort(np.linalg.norm((free - mid)[:, :2], axis=1))
    for c in free[order[:2000]]:
        probe = c + rng.uniform(-0.5, 0.5, (64, 3))
        occ, unk = tree.is_occupied(probe, return_unknown=True)
        if not (occ | unk).any():
            return c
    return free[order[0]]


def changes(tree, rng):
    """(name, apply) pairs: apply(tree) changes the map, returns the deleted points."""
    res = tree.resolution
    pose = free_pose(tree, rng)
    scan = simulate_scans(tree, [pose], SENSOR, seed=1, progress=False)[0]
    noisy = scan.points + rng.normal(0, res / 2, scan.points.shape)
    ar = np.arange(int(round(0.4 / res))) * res
    box = np.stack(np.meshgrid(ar, ar, ar, indexing="ij"), -1).reshape(-1, 3)
    a = pose + np.array([0.6, 0.0, -0.2])
    b = a + np.array([0.5, 0.0, 0.0])

    def do_scan(t):
        t.insert_scan(noisy, scan.origin)
        return None

    def move_box(t):
        t.delete_cells(a + box)
        t.set_cells(b + box, np.full(len(box), 2.0))
        return a + box

    def one_cell(t):
        t.set_cells((pose + [0.0, 0.3, 0.0])[None], [2.0])
        return None

    def place_box(t):
        t.set_cells(a + box, np.full(len(box), 2.0))

    return place_box, [("scan", do_scan), ("box moved", move_box), ("one cell", one_cell)]


def same(f, g) -> bool:
    if set(f._slot) != set(g._slot):
        return False
    return all(np.array_equal(f._dist[s], g._dist[g._slot[k]], equal_nan=True)
               and np.array_equal(f._near[s], g._near[g._slot[k]])
               for k, s in f._slot.items())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="the first configuration only")
    args = parser.parse_args()
    name, base = load_scene()
    lo, hi = base.bounds
    print(f"scene: {name}, resolution {base.resolution} m, {base.num_cells} leaves, box "
          f"{np.round(hi - lo, 2).tolist()} m")
    t = time.perf_counter()
    base.distance_field([lo, hi])
    dense = time.perf_counter() - t
    configs = [dict(max_distance=0.5), dict(max_distance=1.0, signed=True), dict()]
    if args.quick:
        configs = configs[:1]
    header = (f"{'field':<32}{'change':<11}{'cells':>7}{'flips':>7}{'blocks':>13}"
              f"{'update s':>10}{'full s':>9}{'full/upd':>9}{'equal':>7}{'dense s':>9}")
    print(header)
    print("-" * len(header))
    for cfg in configs:
        rng = np.random.default_rng(0)
        tree = load_scene()[1]          # a fresh copy of the map per configuration
        place_box, steps = changes(tree, rng)
        place_box(tree)
        field = DistanceMap(**cfg).fit(tree)
        tree.track_changes = True
        label = ", ".join(f"{k}={v}" for k, v in cfg.items()) or "untruncated"
        for change, apply in steps:
            deleted = apply(tree)
            t = time.perf_counter()
            field.update(tree, deleted)
            upd = time.perf_counter() - t
            tree.reset_changes()
            t = time.perf_counter()
            full = DistanceMap(**cfg).fit(tree)
            fit = time.perf_counter() - t
            st = field.last_update_
            blocks = f"{st['recomputed']}/{st['blocks']}"
            print(f"{label:<32}{change:<11}{st['changed_cells']:>7}{st['obstacle_changes']:>7}"
                  f"{blocks:>13}{upd:>10.3f}{fit:>9.2f}{fit / upd:>9.1f}"
                  f"{str(same(field, full)):>7}{dense:>9.2f}")
    print(f"\nmemory: {field.memory_usage() / 2**20:.1f} MiB for {field.num_blocks_} blocks "
          f"of 16^3 cells (21 bytes per cell)")


if __name__ == "__main__":
    main()
