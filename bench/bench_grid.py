"""The grid's insertion against the octree's, side by side in one run.

``python bench/bench_grid.py`` times, on OctoMap's real ``scan.dat`` (one scan) and
on a dense ``geb079`` trajectory (``--scans`` scans of about 100k points, poses 1 m
apart), at each of ``--resolutions``:

* ``octree``: :class:`occgp.OccupancyOctree`'s default insertion (``method="auto"``);
* ``grid``: :class:`occgp.GridMap`'s default, the same cells and log-odds;
* ``octree discretize``: ``discretize=True`` through occgp's pipeline (``"auto"``);
* ``liboctomap discretize``: the same map by liboctomap's own
  ``insertPointCloud(..., discretize=true)`` (``method="plain"``);
* ``grid discretize``: the grid with ``discretize=True``;
* ``grid bresenham``: ``ray_model="bresenham"``, Bonxai's rules (a different map).

Each round runs every case once on a fresh map, in a rotated order; the table gives
the median time of a whole run over ``--rounds`` rounds and the median of the
per-round ratios to the octree's default and to liboctomap's discretize. It checks
that the discretized maps are liboctomap's, cell for cell, and reports how far the
Bresenham map's free and occupied cells agree with the discretized 3D-DDA map's
(Jaccard index of the cell sets) and the grid's bytes per stored cell. The machine is
shared: compare ratios within one run.
"""

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_updates import geb079_trajectory, scan_dat_poses  # noqa: E402

from occgp import GridMap, OccupancyOctree  # noqa: E402

CASES = {
    "octree": (OccupancyOctree, {}),
    "grid": (GridMap, {}),
    "octree discretize": (OccupancyOctree, dict(discretize=True)),
    "liboctomap discretize": (OccupancyOctree, dict(discretize=True, method="plain")),
    "grid discretize": (GridMap, dict(discretize=True)),
    "grid bresenham": (GridMap, dict(ray_model="bresenham")),
}


def run(case, scans, resolution):
    cls, options = CASES[case]
    m = cls(resolution, n_jobs=1)
    start = time.perf_counter()
    for points, origin in scans:
        m.insert_scan(points, origin, **options)
    return time.perf_counter() - start, m


def cell_sets(m):
    """(free, occupied) sets of finest-cell centers (rounded) of a map."""
    cells = m.cells() if isinstance(m, GridMap) else m.expand().leaves()
    centers = np.round(cells.centers / m.resolution).astype(np.int64)
    free = cells.log_odds < 0
    return set(map(tuple, centers[free])), set(map(tuple, centers[~free]))


def jaccard(a, b):
    return len(a & b) / max(1, len(a | b))


def bench(name, scans, resolution, rounds):
    names = list(CASES)
    times = {case: [] for case in names}
    maps = {}
    for r in range(rounds):
        order = names[r % len(names):] + names[:r % len(names)]
        for case in order:
            seconds, maps[case] = run(case, scans, resolution)
            times[case].append(seconds)
    ref_free, ref_occ = cell_sets(maps["liboctomap discretize"])
    for case in ("octree discretize", "grid discretize"):
        free, occ = cell_sets(maps[case])
        assert (free, occ) == (ref_free, ref_occ), f"{case} differs from liboctomap's"
    free, occ = cell_sets(maps["grid bresenham"])
    print(f"\n{name}, {resolution:g} m, {rounds} rounds, "
          f"{sum(len(p) for p, _ in scans):,} points")
    print(f"{'case':24s} {'median s':>9s} {'octree/this':>12s} {'libdisc/this':>13s}"
          f" {'cells':>10s} {'bytes/cell':>11s}")
    for case in names:
        vs_octree = statistics.median(a / b for a, b in zip(times["octree"], times[case]))
        vs_lib = statistics.median(a / b for a, b in
                                   zip(times["liboctomap discretize"], times[case]))
        m = maps[case]
        per_cell = m.memory_usage() / max(1, m.num_cells)
        print(f"{case:24s} {statistics.median(times[case]):9.3f} {vs_octree:11.2f}x"
              f" {vs_lib:12.2f}x {m.num_cells:10,d} {per_cell:11.1f}")
    print(f"discretized maps: liboctomap's, cell for cell; bresenham vs discretized 3D-DDA: "
          f"free Jaccard {jaccard(free, ref_free):.3f}, occupied Jaccard "
          f"{jaccard(occ, ref_occ):.3f}")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--resolutions", type=float, nargs="+", default=[0.1, 0.2])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--scans", type=int, default=20, help="geb079 trajectory length")
    args = parser.parse_args(argv)
    data = {"scan.dat": scan_dat_poses(1),
            f"geb079, {args.scans} scans": geb079_trajectory(args.scans)}
    for name, scans in data.items():
        scans = [(np.asarray(p, np.float32), np.asarray(o, np.float32)) for p, o in scans]
        for resolution in args.resolutions:
            bench(name, scans, resolution, args.rounds)


if __name__ == "__main__":
    main()
