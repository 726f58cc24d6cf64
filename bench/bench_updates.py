"""Benchmark scan insertion methods against liboctomap (dissertation ch. 2, Tables 2.2-2.4).

Datasets, simulated or read in the same run:

* ``geb079``: a dense trajectory in the real OctoMap of building 079
  (``../shared/data/octomap/geb079.bt``): ``--scans`` poses 1 m apart along a
  collision-free path at 1 m height, each a 720 x 150-beam laser scan
  (about 106k points);
* ``scan.dat``: OctoMap's real dense scan (88,206 points) inserted from
  ``--poses`` nearby sensor positions (the points shifted with the sensor).

For every resolution, every method inserts the same scans in order into one
map, and the table gives frames per second, the mean pre-processing time
(super rays, culling region) and update time per scan (ms), the cells updated
and the rays traversed per scan, and the speed-up over
liboctomap's ``insertPointCloud`` (``mode="scan"`` rows) or
``insertPointCloudRays`` (``mode="ray"`` rows), both called from C++ on the
same points. Every occgp method's map is checked to equal the plain method's,
leaf for leaf. Times are wall clock, single thread; ratios, not absolute
times, are what carries over between machines.

Run: ``python bench/bench_updates.py [--scans 20] [--resolutions 0.1 0.2 ...]``.
"""

import argparse
import multiprocessing
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from octomap_reference import build_octomap_insert, time_octomap_sequence, write_scan_bin  # noqa: E402

from occgp import OccupancyOctree  # noqa: E402
from occgp.datasets import free_path, read_xyz, simulate_scans  # noqa: E402

DATA = ROOT / ".." / "shared" / "data" / "octomap"
METHODS = [(mode, method) for mode in ("scan", "ray")
           for method in ("plain", "culling", "superray", "superray+culling")]


def geb079_trajectory(n_scans, seed=0):
    env = OccupancyOctree.load(DATA / "geb079.bt")
    poses = free_path(env, n_scans, step=1.0, seed=seed)
    return simulate_scans(env, poses, seed=seed, progress=False)


def scan_dat_poses(n_poses, seed=0):
    scan = read_xyz(DATA / "scan.dat.bz2")
    rng = np.random.default_rng(seed)
    shifts = np.vstack([np.zeros(3), rng.uniform(-0.5, 0.5, (n_poses - 1, 3)) * [1, 1, 0.2]])
    return [(scan.points + s, scan.origin + s) for s in shifts]


def run_fresh(scans, resolution, mode, method):
    """:func:`run_occgp` in a new process, as the C++ reference runs: a long-lived
    process's fragmented heap slows liboctomap's node allocations, which would blur
    the comparison."""
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=1, mp_context=ctx) as pool:
        return pool.submit(run_occgp, scans, resolution, mode, method).result()


def run_occgp(scans, resolution, mode, method):
    """Insert the scans in order with ``insert_scan``; return the map, per-scan seconds,
    pre-processing seconds (super rays, culling region), updated cells and traversed rays."""
    tree = OccupancyOctree(resolution)
    total, proc, cells, rays = [], [], [], []
    for points, origin in scans:
        t0 = time.perf_counter()
        tree.insert_scan(points, origin, mode=mode, method=method)
        total.append(time.perf_counter() - t0)
        stats = tree.last_insert_
        proc.append(stats.get("preprocessing_seconds", 0.0))
        cells.append(stats.get("updated_cells", 0))
        rays.append(stats["rays"])
    return tree, np.array(total), np.array(proc), np.array(cells), np.array(rays)


def same_map(a, b):
    la, lb = a.leaves(), b.leaves()
    if len(la.sizes) != len(lb.sizes):
        return False
    oa = np.lexsort((la.sizes, *la.centers.T))
    ob = np.lexsort((lb.sizes, *lb.centers.T))
    return (np.array_equal(la.centers[oa], lb.centers[ob])
            and np.array_equal(la.log_odds[oa], lb.log_odds[ob]))


def bench_dataset(name, scans, resolutions, exe, tmp):
    n_pts = np.mean([len(p) for p, _ in scans])
    print(f"\n== {name}: {len(scans)} scans, {n_pts:,.0f} points per scan ==")
    files = [write_scan_bin(Path(tmp) / f"{name}_{i}.bin", p, o) for i, (p, o) in enumerate(scans)]
    header = (f"{'res':>5}  {'method':<41}{'FPS':>7}{'proc ms':>9}{'update ms':>11}"
              f"{'cells/scan':>12}{'rays/scan':>11}{'speed-up':>10}  map")
    print(header)
    print("-" * len(header))
    for res in resolutions:
        ref = {"scan": time_octomap_sequence(exe, files, res),
               "ray": time_octomap_sequence(exe, files, res, rays=True)}
        for mode, label in (("scan", "insertPointCloud"), ("ray", "insertPointCloudRays")):
            t = np.sum(ref[mode])
            print(f"{res:>5.2f}  {'liboctomap ' + label:<41}{len(files) / t:>7.2f}{'':>9}"
                  f"{1e3 * t / len(files):>11.1f}{'':>12}{n_pts:>11,.0f}{1.0:>9.2f}x")
        plain = {}
        for mode, method in METHODS:
            tree, total, region, cells, rays = run_fresh(scans, res, mode, method)
            if method == "plain":
                plain[mode] = tree
                same = "(reference)"
            else:
                same = "identical" if same_map(tree, plain[mode]) else "DIFFERENT"
            t = total.sum()
            proc_ms = f"{1e3 * region.mean():.1f}" if method != "plain" else ""
            cell_txt = f"{cells.mean():,.0f}" if cells.any() else ""
            print(f"{res:>5.2f}  {f'occgp octree mode={mode} {method}':<41}{len(scans) / t:>7.2f}"
                  f"{proc_ms:>9}{1e3 * (t - region.sum()) / len(scans):>11.1f}{cell_txt:>12}"
                  f"{rays.mean():>11,.0f}{np.sum(ref[mode]) / t:>9.2f}x  {same}")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scans", type=int, default=20)
    parser.add_argument("--poses", type=int, default=4)
    parser.add_argument("--resolutions", type=float, nargs="+",
                        default=[0.1, 0.2, 0.4, 0.8, 1.0])
    parser.add_argument("--datasets", nargs="+", default=["geb079", "scan.dat"])
    args = parser.parse_args(argv)
    if not DATA.exists():
        sys.exit(f"{DATA} is absent (../shared/data beside the project root)")
    with tempfile.TemporaryDirectory() as tmp:
        exe = build_octomap_insert(Path(tmp))
        if exe is None:
            sys.exit("no C++ compiler or liboctomap pkg-config file to build the reference")
        for name in args.datasets:
            scans = (geb079_trajectory(args.scans) if name == "geb079"
                     else scan_dat_poses(args.poses))
            bench_dataset(name, scans, args.resolutions, exe, tmp)
    print("\nspeed-up: liboctomap's time over occgp's on the same scans, same run "
          "(mode=scan rows vs insertPointCloud, mode=ray rows vs insertPointCloudRays).")


if __name__ == "__main__":
    main()
