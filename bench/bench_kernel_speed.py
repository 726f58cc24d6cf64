"""Time the kernel maps' scan inserts (BGKMap and AKIMap at 0.05 m, one thread).

For each data set, ``BGKMap(0.05)`` and ``AKIMap(0.05)`` (occgp's variant,
``random_state=0``) map the same scans; printed per map: the seconds spent in
``insert_scan`` over all scans (best of ``--repeats`` builds) and the AUC of the
map on the test set (:mod:`occgp.evaluation`). Data sets:

* ``la3dm``: the structured Gazebo scene (``../shared/data/la3dm_sim_structured``),
  held-out protocol (20% of each scan's points held out, split seed 0), as
  ``bench/bench_kernel.py`` runs it;
* ``unstructured``: occgp's synthetic unstructured room (scan seed 0), scored
  against the exact occupancy of every cell centre at 0.05 m.

Each checkout is timed in its own subprocess. With ``--baseline DIR`` the same
is measured with the ``occgp`` package found in DIR (a checkout with its
extensions built, e.g. the main branch), the two alternating run by run so that
both see the same load, and printed side by side with the ratio new / base.

Run: ``python bench/bench_kernel_speed.py [--threads 1 2] [--repeats 3]
[--sets la3dm unstructured] [--baseline ../main]``.
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")   # idle BLAS threads spin on 2 cores

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

LA3DM = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "la3dm_sim_structured"
RES = 0.05
MAPS = ("BGKMap", "AKIMap")


def scans_and_test(name):
    from occgp.datasets import read_scans, unstructured_room
    from occgp.evaluation import grid_test_set, held_out_split
    if name == "la3dm":
        return held_out_split(read_scans(LA3DM), fraction=0.2, seed=0)
    scene = unstructured_room(seed=0)
    return scene.scan(seed=0), grid_test_set(scene, RES)


def make(kind, threads):
    from occgp import AKIMap, BGKMap
    if kind == "BGKMap":
        return BGKMap(RES, n_jobs=threads)
    return AKIMap(RES, random_state=0, n_jobs=threads)


def insert_all(kind, threads, train, test):
    """(seconds spent in insert_scan over all scans, AUC) of one fresh map."""
    from occgp.evaluation import evaluate_map
    m = make(kind, threads)
    total = 0.0
    for pts, org in train:
        t0 = time.perf_counter()
        m.insert_scan(pts, org)
        total += time.perf_counter() - t0
    return total, evaluate_map(m, test)["auc"]


def worker(sets):
    """Answer lines ``set map threads`` on stdin with ``[seconds, auc]`` (JSON)."""
    import numpy as np
    data = {}
    for name in sets:
        train, test = scans_and_test(name)
        data[name] = ([(np.ascontiguousarray(p, dtype=np.float64),
                        np.ascontiguousarray(o, dtype=np.float64)) for p, o in train], test)
    print("ready", flush=True)
    for line in sys.stdin:
        name, kind, threads = line.split()
        print(json.dumps(insert_all(kind, int(threads), *data[name])), flush=True)


class Worker:
    """A subprocess timing the occgp of one checkout."""

    def __init__(self, root, sets):
        self.proc = subprocess.Popen(
            [sys.executable, str(Path(__file__).resolve()), "--worker", "--occgp-from",
             str(root), "--sets", *sets], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
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


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, nargs="+", default=[1])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--sets", nargs="+", default=["la3dm", "unstructured"],
                    choices=["la3dm", "unstructured"])
    ap.add_argument("--baseline", type=Path, default=None,
                    help="a checkout whose occgp (extensions built) to time side by side")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--occgp-from", type=Path, default=Path(__file__).resolve().parents[1],
                    help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    sets = [s for s in args.sets if s != "la3dm" or LA3DM.is_dir()]
    if args.worker:
        sys.path.insert(0, str(args.occgp_from.resolve()))
        worker(sets)
        return
    # one worker per checkout; their runs alternate, so that both see the same load
    workers = {"new": Worker(args.occgp_from.resolve(), sets)}
    if args.baseline is not None:
        workers["base"] = Worker(args.baseline.resolve(), sets)
    best = {}
    for name in sets:
        for kind in MAPS:
            for nt in args.threads:
                for _ in range(args.repeats):
                    for tag, w in workers.items():
                        s, auc = w.run(name, kind, nt)
                        key = (tag, name, kind, nt)
                        best[key] = (min(s, best.get(key, (s,))[0]), auc)
    for w in workers.values():
        w.close()
    print(f"occgp from {args.occgp_from.resolve()}"
          + (f"; baseline from {args.baseline.resolve()}" if "base" in workers else ""))
    print(f"insert seconds over all scans, best of {args.repeats}; AUC of the map")
    head = f"{'set':<13}{'map':<8}{'threads':>8}{'seconds':>9}{'AUC':>8}"
    if "base" in workers:
        head += f"{'base s':>9}{'base AUC':>10}{'ratio':>7}"
    print(head)
    for name in sets:
        for kind in MAPS:
            for nt in args.threads:
                s, auc = best[("new", name, kind, nt)]
                line = f"{name:<13}{kind:<8}{nt:>8}{s:>9.3f}{auc:>8.4f}"
                if "base" in workers:
                    bs, bauc = best[("base", name, kind, nt)]
                    line += f"{bs:>9.3f}{bauc:>10.4f}{s / bs:>7.2f}"
                print(line)


if __name__ == "__main__":
    main()
