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

With ``--baseline DIR`` the same is measured, in a subprocess, with the
``occgp`` package found in DIR (a checkout with its extensions built, e.g. the
main branch), and the two are printed side by side with the ratio.

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


def measure(sets, threads, repeats):
    """{set: {map: {threads: (best seconds, auc)}}} with the occgp importable here."""
    import numpy as np
    from occgp.evaluation import evaluate_map
    out = {}
    for name in sets:
        train, test = scans_and_test(name)
        train = [(np.ascontiguousarray(p, dtype=np.float64),
                  np.ascontiguousarray(o, dtype=np.float64)) for p, o in train]
        out[name] = {}
        for kind in MAPS:
            out[name][kind] = {}
            for nt in threads:
                best, auc = float("inf"), None
                for _ in range(repeats):
                    m = make(kind, nt)
                    total = 0.0
                    for pts, org in train:
                        t0 = time.perf_counter()
                        m.insert_scan(pts, org)
                        total += time.perf_counter() - t0
                    best = min(best, total)
                    auc = evaluate_map(m, test)["auc"]
                out[name][kind][str(nt)] = (best, auc)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, nargs="+", default=[1])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--sets", nargs="+", default=["la3dm", "unstructured"],
                    choices=["la3dm", "unstructured"])
    ap.add_argument("--baseline", type=Path, default=None,
                    help="a checkout whose occgp (extensions built) to time side by side")
    ap.add_argument("--json", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--occgp-from", type=Path, default=Path(__file__).resolve().parents[1],
                    help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    sys.path.insert(0, str(args.occgp_from.resolve()))
    sets = [s for s in args.sets if s != "la3dm" or LA3DM.is_dir()]
    if args.json:
        print(json.dumps(measure(sets, args.threads, args.repeats)))
        return
    base = None
    if args.baseline is not None:
        cmd = [sys.executable, str(Path(__file__).resolve()), "--json",
               "--occgp-from", str(args.baseline.resolve()), "--repeats", str(args.repeats),
               "--threads", *map(str, args.threads), "--sets", *sets]
        run = subprocess.run(cmd, capture_output=True, text=True, check=True)
        base = json.loads(run.stdout.strip().splitlines()[-1])
    new = measure(sets, args.threads, args.repeats)
    import occgp
    print(f"occgp from {Path(occgp.__file__).parent}"
          + (f"; baseline from {args.baseline.resolve()}" if base is not None else ""))
    print(f"insert seconds over all scans, best of {args.repeats}; AUC of the map")
    head = f"{'set':<13}{'map':<8}{'threads':>8}{'seconds':>9}{'AUC':>8}"
    if base is not None:
        head += f"{'base s':>9}{'base AUC':>10}{'ratio':>7}"
    print(head)
    for name in sets:
        for kind in MAPS:
            for nt in map(str, args.threads):
                s, auc = new[name][kind][nt]
                line = f"{name:<13}{kind:<8}{nt:>8}{s:>9.3f}{auc:>8.4f}"
                if base is not None:
                    bs, bauc = base[name][kind][nt]
                    line += f"{bs:>9.3f}{bauc:>10.4f}{s / bs:>7.2f}"
                print(line)


if __name__ == "__main__":
    main()
