"""Benchmark OccupancyOctree against liboctomap called directly from C++.

On OctoMap's real dense scan (``../shared/data/octomap/scan.dat.bz2``, 88,206
points) at 0.1 m and 0.2 m, in one run:

* ``liboctomap (C++)`` — a small C++ program (``tests/reference/octomap_insert.cpp``)
  calling ``OcTree::insertPointCloud`` on the same float32 points, timed in C++;
* ``occgp scan`` — ``OccupancyOctree.insert_scan(points, origin)`` from Python,
  validation and conversion included;
* ``occgp ray`` — the same with ``mode="ray"`` (per-ray counting);

each the best of several fresh-tree insertions, with the overhead of occgp over
liboctomap as a ratio; then the query throughput of ``occupancy`` (points/s).

Run: ``python bench/bench_octree.py [--repeats N]`` (``make bench``).
"""

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from octomap_reference import build_octomap_insert, time_octomap_insert, write_scan_bin  # noqa: E402

from occgp import OccupancyOctree  # noqa: E402
from occgp.io import read_xyz  # noqa: E402

SCAN = ROOT / ".." / "shared" / "data" / "octomap" / "scan.dat.bz2"


def best_of(repeats, fn):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--queries", type=int, default=1_000_000)
    args = parser.parse_args(argv)
    if not SCAN.exists():
        sys.exit(f"the scan {SCAN} is absent (../shared/data beside the project root)")
    scan = read_xyz(SCAN)
    points, origin = scan.points, scan.origin
    print(f"scan: {SCAN.name}, {len(points):,} points, sensor at {origin.tolist()}; "
          f"best of {args.repeats}\n")

    with tempfile.TemporaryDirectory() as tmp:
        exe = build_octomap_insert(Path(tmp))
        if exe is None:
            sys.exit("no C++ compiler or liboctomap pkg-config file to build the reference")
        scan_file = write_scan_bin(Path(tmp) / "scan.bin", points, origin)
        header = (f"{'resolution':>10}  {'method':<18}{'insert s':>10}{'vs C++':>9}"
                  f"{'leaves':>10}")
        print(header)
        print("-" * len(header))
        for res in (0.1, 0.2):
            # interleaved repeats, so that drift of the machine hits every method alike
            times = {"liboctomap (C++)": [], "occgp scan": [], "occgp ray": []}
            for _ in range(args.repeats):
                times["liboctomap (C++)"].append(time_octomap_insert(exe, scan_file, res, 1))
                for mode in ("scan", "ray"):
                    times[f"occgp {mode}"].append(best_of(1, lambda: OccupancyOctree(
                        res).insert_scan(points, origin, mode=mode)))
            t_cpp = min(times["liboctomap (C++)"])
            for name, ts in times.items():
                mode = name.split()[-1]
                leaves = (OccupancyOctree(res).insert_scan(points, origin, mode=mode).num_leaves
                          if name.startswith("occgp") else None)
                print(f"{res:>10.2f}  {name:<18}{min(ts):>10.4f}{min(ts) / t_cpp:>8.3f}x"
                      f"{'' if leaves is None else f'{leaves:,}':>10}")
        print("\n(vs C++: occgp's time over liboctomap's on the same points; "
              "1.05x = 5% overhead)\n")

    rng = np.random.default_rng(0)
    header = f"{'resolution':>10}  {'query':<18}{'points/s':>14}{'known':>9}"
    print(header)
    print("-" * len(header))
    for res in (0.1, 0.2):
        m = OccupancyOctree(res).insert_scan(points, origin)
        lo, hi = points.min(axis=0), points.max(axis=0)
        q = rng.uniform(lo, hi, (args.queries, 3))
        for name, fn in (("occupancy", m.occupancy), ("is_occupied", m.is_occupied)):
            t = best_of(args.repeats, lambda: fn(q))
            known = np.isfinite(m.occupancy(q)).mean()
            print(f"{res:>10.2f}  {name:<18}{len(q) / t:>14,.0f}{known:>9.1%}")


if __name__ == "__main__":
    main()
