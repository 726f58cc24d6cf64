"""What each mapping method costs: points inserted per second, by resolution.

The same dense trajectory for every method: ``--scans`` poses 1 m apart in the real
building map ``../shared/data/octomap/geb079.bt``, each a 720 x 150-beam laser scan
(about 100k points), as ``bench/bench_updates.py`` simulates them. Every method
inserts all the scans, in order, into a new map at each resolution, on one thread and
then on every core (``n_jobs=-1`` for the maps that take it); the table gives points
per second (millions), the best of ``--repeats`` runs, with the machine's line. The
kernel maps (BGK, AKIMap) and the k-NN map do more per point than the log-odds maps
(kernel inference on blocks of cells, a neighbour search), which the table shows.

Run: ``python bench/bench_costs.py [--scans 6] [--resolutions 0.05 0.1 0.2 0.4 1.0]``;
the table goes to the README and the user guide.
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

from bench_peers import hardware_line  # noqa: E402
from bench_updates import DATA, geb079_trajectory  # noqa: E402

from occgp import AKIMap, BGKMap, GridMap, KNNMap, OccupancyOctree  # noqa: E402

# (label, build(resolution, threads) -> map, insert options, whether it takes threads)
METHODS = [
    ("octree, scan (default)", lambda r, j: OccupancyOctree(r, n_jobs=j), {"mode": "scan"}, True),
    ("octree, scan, plain (liboctomap)", lambda r, j: OccupancyOctree(r, n_jobs=j),
     {"mode": "scan", "method": "plain"}, False),
    ("octree, ray", lambda r, j: OccupancyOctree(r, n_jobs=j), {"mode": "ray"}, True),
    ("grid, scan", lambda r, j: GridMap(r, n_jobs=j), {"mode": "scan"}, True),
    ("k-NN map", lambda r, j: KNNMap(r, max_range=20.0), {}, True),
    ("BGK", lambda r, j: BGKMap(r, n_jobs=j), {}, True),
    ("AKIMap", lambda r, j: AKIMap(r, n_jobs=j, random_state=0), {}, True),
]


def run(scans, label, build, options, resolution, threads):
    m = build(resolution, threads)
    kwargs = dict(options)
    t0 = time.perf_counter()
    for points, origin in scans:
        m.insert_scan(points, origin, **kwargs)
    return time.perf_counter() - t0


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scans", type=int, default=6)
    parser.add_argument("--resolutions", type=float, nargs="+",
                        default=[0.05, 0.1, 0.2, 0.4, 1.0])
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--methods", nargs="+", default=None, metavar="TEXT",
                        help="only the methods whose label holds one of these texts")
    args = parser.parse_args(argv)
    if not (DATA / "geb079.bt").exists():
        print(f"skipped: {DATA} is absent (the shared data sets)")
        return 0
    scans = geb079_trajectory(args.scans)
    n_points = sum(len(p) for p, _ in scans)
    cores = os.cpu_count() or 1
    print(hardware_line())
    print(f"geb079 trajectory: {len(scans)} scans, {n_points / len(scans):,.0f} points a "
          f"scan; points per second (millions), best of {args.repeats}; "
          f"1 thread / {cores} threads")
    header = "| method | " + " | ".join(f"{r:g} m" for r in args.resolutions) + " |"
    print()
    print(header)
    print("|---|" + "---:|" * len(args.resolutions))
    for label, build, options, threaded in METHODS:
        if args.methods and not any(t in label for t in args.methods):
            continue
        cells = []
        for res in args.resolutions:
            rates = []
            for threads in ((1, -1) if threaded and cores > 1 else (1,)):
                best = min(run(scans, label, build, options, res, threads)
                           for _ in range(args.repeats))
                rates.append(f"{n_points / best / 1e6:.2f}")
            cells.append(" / ".join(rates))
        print(f"| {label} | " + " | ".join(cells) + " |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
