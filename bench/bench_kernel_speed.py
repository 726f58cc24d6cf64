"""Time the kernel maps' scan inserts (BGKMap and AKIMap), one thread by default.

For each data set, the maps map the same scans; printed per map: the seconds
spent in ``insert_scan`` over all scans (best of ``--repeats`` builds) and the
AUC of the map on the test set (:mod:`occgp.evaluation`). Data sets:

* ``la3dm``: the structured Gazebo scene (``../shared/data/la3dm_sim_structured``),
  held-out protocol (20% of each scan's points held out, split seed 0), as
  ``bench/bench_kernel.py`` runs it; ``BGKMap(0.05)`` and ``AKIMap(0.05)``
  (occgp's variant, ``random_state=0``);
* ``unstructured``: occgp's synthetic unstructured room (scan seed 0), scored
  against the exact occupancy of every cell center at 0.05 m; the same maps;
* ``hku_mb``: the real LiDAR sequence ``../shared/data/lidar_seq/hku_mb`` (Livox
  Avia, 457 keyframes of ~5,100 body-frame points, FAST-LIO2 poses; ranges up
  to 349 m), mapped at 0.1 m by ``OccupancyOctree(0.1)`` (its default
  ``n_jobs``), ``BGKMap(0.1)`` and ``AKIMap(0.1, random_state=0)``, each with
  its defaults otherwise, scan by scan; ``--max-range R`` gives all three the
  same range limit (the octree's ``insert_scan(..., max_range=R)`` cuts the
  longer rays there, and so do the kernel maps' ``max_range=R``; a baseline
  from before ``far_beams`` drops those beams whole, and an AKIMap without
  ``max_range``, in an older one still, gets the scans with those points
  dropped: the same map, so ``--compare`` differs there). Scans ``i % 10 == 5`` are
  held out: their end points are the occupied test points, and each gives one
  free test point drawn uniformly between 0.3 m and 0.2 m before it on its ray
  (seed 0). ``--scans`` picks a slice of the training scans (``::4``: every
  4th) to iterate quickly. The table adds each map's time over the octree's,
  both timed in the same round.

A data set whose files are absent is skipped with a message. Each checkout is
timed in its own subprocess. With ``--baseline DIR`` the same is measured with
the ``occgp`` package found in DIR (a checkout with its extensions built, e.g.
the main branch), the two alternating run by run so that both see the same
load, and printed side by side with the ratio new / base; ``--compare`` then
also checks that the two checkouts build the same cells (keys, and the largest
relative difference of alpha and beta).

Run: ``python bench/bench_kernel_speed.py [--threads 1 2] [--repeats 3]
[--sets la3dm unstructured hku_mb] [--scans ::4] [--max-range 30] [--maps ...]
[--baseline ../main [--compare]]``.
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")   # idle BLAS threads spin on 2 cores

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
LA3DM = DATA / "la3dm_sim_structured"
HKU = DATA / "lidar_seq" / "hku_mb"
RES = {"la3dm": 0.05, "unstructured": 0.05, "hku_mb": 0.1}
MAPS = {"la3dm": ("BGKMap", "AKIMap"), "unstructured": ("BGKMap", "AKIMap"),
        "hku_mb": ("OccupancyOctree", "BGKMap", "AKIMap")}
SETS = tuple(RES)


def available(name):
    """None if the data set can be run, else why not."""
    if name == "la3dm" and not LA3DM.is_dir():
        return f"{LA3DM} not found"
    if name == "hku_mb" and not (HKU / "optimized_poses.txt").is_file():
        return f"{HKU / 'optimized_poses.txt'} not found"
    return None


def hku_scans_and_test(scans_slice):
    """The hku_mb training scans (world frame; `scans_slice` of them) and the test set
    of its held-out scans (i % 10 == 5)."""
    import numpy as np
    from occgp.io import apply_poses, read_kitti_poses, read_pcd
    from occgp.evaluation import TestSet
    poses = read_kitti_poses(HKU / "optimized_poses.txt")
    scans = apply_poses([read_pcd(HKU / "Scans" / f"{i:06d}.pcd")
                         for i in range(len(poses))], poses)
    train = [s for i, s in enumerate(scans) if i % 10 != 5][scans_slice]
    rng = np.random.default_rng(0)
    occupied, free = [], []
    for pts, org in (s for i, s in enumerate(scans) if i % 10 == 5):
        ray = pts - org
        length = np.linalg.norm(ray, axis=1)
        back = rng.uniform(0.2, 0.3, len(pts))
        occupied.append(pts)
        free.append(pts - ray / length[:, None] * back[:, None])
    points = np.vstack(occupied + free)
    labels = np.arange(len(points)) < sum(len(p) for p in occupied)
    return train, TestSet(points, labels)


def scans_and_test(name, scans_slice):
    from occgp.datasets import unstructured_room
    from occgp.io import read_scans
    from occgp.evaluation import grid_test_set, held_out_split
    if name == "la3dm":
        return held_out_split(read_scans(LA3DM), fraction=0.2, seed=0)
    if name == "hku_mb":
        return hku_scans_and_test(scans_slice)
    scene = unstructured_room(seed=0)
    return scene.scan(seed=0), grid_test_set(scene, RES[name])


def make(name, kind, threads, max_range=None):
    """(the map, insert_scan's keyword arguments, whether to drop the points beyond
    `max_range` before inserting)."""
    import inspect
    from occgp import AKIMap, BGKMap, OccupancyOctree
    res = RES[name]
    if kind == "OccupancyOctree":
        return OccupancyOctree(res), ({} if max_range is None
                                      else {"max_range": max_range}), False
    cls = BGKMap if kind == "BGKMap" else AKIMap
    kw = {"n_jobs": threads} if kind == "BGKMap" else {"random_state": 0, "n_jobs": threads}
    if max_range is None:
        return cls(res, **kw), {}, False
    if "max_range" in inspect.signature(cls).parameters:
        return cls(res, max_range=max_range, **kw), {}, False
    return cls(res, **kw), {}, True


def insert_all(name, kind, threads, train, test, cells_to, max_range=None):
    """(seconds spent in insert_scan over all scans, AUC, file of the cells or None) of
    one fresh map."""
    import numpy as np
    from occgp.evaluation import evaluate_map
    m, options, drop = make(name, kind, threads, max_range)
    total = 0.0
    for pts, org in train:
        if drop:
            pts = pts[np.linalg.norm(pts - org, axis=1) <= max_range]
        t0 = time.perf_counter()
        m.insert_scan(pts, org, **options)
        total += time.perf_counter() - t0
    saved = None
    if cells_to and hasattr(m, "cells"):
        c = m.cells()
        fd, saved = tempfile.mkstemp(suffix=".npz", dir=cells_to)
        os.close(fd)
        np.savez(saved, centers=c.centers, alpha=c.alpha, beta=c.beta)
    return total, evaluate_map(m, test)["auc"], saved


def worker(sets, scans_slice, cells_to, max_range=None):
    """Answer lines ``set map threads`` on stdin with ``[seconds, auc, cells]`` (JSON)."""
    import numpy as np
    data = {}
    for name in sets:
        train, test = scans_and_test(name, scans_slice)
        data[name] = ([(np.ascontiguousarray(p, dtype=np.float64),
                        np.ascontiguousarray(o, dtype=np.float64)) for p, o in train], test)
    print("ready", flush=True)
    for line in sys.stdin:
        name, kind, threads = line.split()
        print(json.dumps(insert_all(name, kind, int(threads), *data[name], cells_to,
                                    max_range if name == "hku_mb" else None)), flush=True)


class Worker:
    """A subprocess timing the occgp of one checkout."""

    def __init__(self, root, sets, scans, cells_to, max_range=None):
        cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", "--occgp-from",
               str(root), "--sets", *sets, f"--scans={scans}"]
        if max_range is not None:
            cmd += ["--max-range", str(max_range)]
        if cells_to:
            cmd += ["--cells-to", cells_to]
        self.proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     text=True)
        if self.proc.stdout.readline().strip() != "ready":
            raise RuntimeError(f"the worker for {root} did not start")

    def run(self, name, kind, threads):
        self.proc.stdin.write(f"{name} {kind} {threads}\n")
        self.proc.stdin.flush()
        return json.loads(self.proc.stdout.readline())

    def close(self):
        self.proc.stdin.close()
        self.proc.wait()


def parse_slice(text):
    parts = [int(p) if p.strip() else None for p in text.split(":")]
    if not 1 <= len(parts) <= 3:
        raise argparse.ArgumentTypeError(f"--scans takes a slice start:stop:step, got {text!r}")
    return slice(*parts) if len(parts) > 1 else slice(parts[0], parts[0] + 1)


def compare_cells(new_file, base_file):
    """A line saying whether two maps' cells agree."""
    import numpy as np
    a, b = np.load(new_file), np.load(base_file)
    if a["centers"].shape != b["centers"].shape or \
            not np.array_equal(a["centers"], b["centers"]):
        return (f"cells differ: {len(a['centers'])} new vs {len(b['centers'])} base "
                f"(keys not the same)")
    worst = 0.0
    same = True
    for f in ("alpha", "beta"):
        x, y = a[f], b[f]
        same &= np.array_equal(x, y)
        worst = max(worst, float(np.max(np.abs(x - y) / np.maximum(np.abs(y), 1e-30),
                                        initial=0.0)))
    return ("bit-identical" if same else f"same keys, largest relative difference of "
            f"alpha/beta {worst:.2e}") + f" ({len(a['centers'])} cells)"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, nargs="+", default=[1],
                    help="n_jobs of the kernel maps (the octree keeps its default)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--sets", nargs="+", default=["la3dm", "unstructured"], choices=SETS)
    ap.add_argument("--maps", nargs="+", default=None,
                    choices=["OccupancyOctree", "BGKMap", "AKIMap"],
                    help="time only these maps (default: every map of each set)")
    ap.add_argument("--scans", type=str, default="::1",
                    help="hku_mb: slice start:stop:step of its training scans")
    ap.add_argument("--max-range", type=float, default=None,
                    help="hku_mb: every map's range limit, in metres (default: none)")
    ap.add_argument("--baseline", type=Path, default=None,
                    help="a checkout whose occgp (extensions built) to time side by side")
    ap.add_argument("--compare", action="store_true",
                    help="with --baseline: check that both build the same cells")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--cells-to", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--occgp-from", type=Path, default=Path(__file__).resolve().parents[1],
                    help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    scans_slice = parse_slice(args.scans)
    if args.maps:
        for name in MAPS:
            MAPS[name] = tuple(k for k in MAPS[name] if k in args.maps)
    if args.worker:
        sys.path.insert(0, str(args.occgp_from.resolve()))
        worker(args.sets, scans_slice, args.cells_to, args.max_range)
        return
    sets = []
    for name in args.sets:
        why = available(name)
        if why is None:
            sets.append(name)
        else:
            print(f"skipping {name}: {why}")
    if not sets:
        return
    tmp = tempfile.TemporaryDirectory() if args.compare and args.baseline else None
    cells_to = tmp.name if tmp else None
    # one worker per checkout; their runs alternate, so that both see the same load
    workers = {"new": Worker(args.occgp_from.resolve(), sets, args.scans, cells_to,
                             args.max_range)}
    if args.baseline is not None:
        workers["base"] = Worker(args.baseline.resolve(), sets, args.scans, cells_to,
                                 args.max_range)
    best, ratio, files = {}, {}, {}
    for name in sets:
        for nt in args.threads:
            for _ in range(args.repeats):
                octree = {}
                for kind in MAPS[name]:
                    for tag, w in workers.items():
                        s, auc, saved = w.run(name, kind, nt)
                        key = (tag, name, kind, nt)
                        best[key] = (min(s, best.get(key, (s,))[0]), auc)
                        files[key] = saved
                        if kind == "OccupancyOctree":
                            octree[tag] = s
                        elif tag in octree:   # over the octree of the same round
                            ratio.setdefault(key, []).append(s / octree[tag])
    for w in workers.values():
        w.close()
    print(f"occgp from {args.occgp_from.resolve()}"
          + (f"; baseline from {args.baseline.resolve()}" if "base" in workers else ""))
    print(f"insert seconds over all scans, best of {args.repeats}; AUC of the map; "
          f"/octree: the map's time over the octree's in the same round (each round)")
    if "hku_mb" in sets:
        print(f"hku_mb training scans: slice {args.scans}; range limit "
              f"{'none' if args.max_range is None else f'{args.max_range:g} m'}")
    head = f"{'set':<13}{'map':<16}{'threads':>8}{'seconds':>9}{'AUC':>8}{'/octree':>16}"
    if "base" in workers:
        head += f"{'base s':>9}{'base AUC':>10}{'base /octree':>16}{'new/base':>9}"
    print(head)
    for name in sets:
        for kind in MAPS[name]:
            for nt in args.threads:
                s, auc = best[("new", name, kind, nt)]
                r = ratio.get(("new", name, kind, nt))
                rs = " ".join(f"{v:.2f}" for v in r) if r else "-"
                line = f"{name:<13}{kind:<16}{nt:>8}{s:>9.3f}{auc:>8.4f}{rs:>16}"
                if "base" in workers:
                    bs, bauc = best[("base", name, kind, nt)]
                    r = ratio.get(("base", name, kind, nt))
                    rs = " ".join(f"{v:.2f}" for v in r) if r else "-"
                    line += f"{bs:>9.3f}{bauc:>10.4f}{rs:>16}{s / bs:>9.2f}"
                print(line)
    if cells_to:
        print("cells, new vs base (last build):")
        for name in sets:
            for kind in MAPS[name]:
                for nt in args.threads:
                    a = files.get(("new", name, kind, nt))
                    b = files.get(("base", name, kind, nt))
                    if a and b:
                        print(f"  {name} {kind} threads={nt}: {compare_cells(a, b)}")
        tmp.cleanup()


if __name__ == "__main__":
    main()
