"""A/B bench of scan insertion: this checkout against an earlier commit, in one run.

``python bench/bench_ab.py --compare REF`` checks ``REF`` (a commit, branch or tag)
out in a worktree under ``build/ab-<sha>``, builds its extensions there (once; reused
while the commit is the same), and times both builds on the same scans:

* ``geb079``: a dense trajectory simulated in ``../shared/data/octomap/geb079.bt``
  (720 x 150-beam scans, about 100k points each, poses 1 m apart);
* ``scan.dat``: OctoMap's real 88k-point scan from nearby poses.

Each build runs in its own long-lived process (``--worker``) that loads the scans
once; the parent sends every case to one build and then to the other, alternating
which goes first, ``--repeats`` times, and keeps each build's fastest time. Cases:
the octree in scan and ray mode with the default method (``"auto"``) and with
``"plain"`` (in scan mode liboctomap's ``insertPointCloud``), in scan mode with
``"culling"`` (``"auto"`` decides by measured times whether super rays pay, so its
times jump between runs; ``"culling"`` does not), one and two threads, and the
grid's default method; at ``--resolutions`` (default 0.1 0.2 0.4 m). Both
builds must give the same map (a hash of the octree's ``.ot`` bytes, of the grid's
cells). The table gives each build's milliseconds per scan and the ratio
``this / REF`` (below 1: faster); the script exits with status 1 when a case is
slower than ``REF`` by more than ``--margin`` (default 5 %) or a map differs.

Machines here are noisy and shared: compare ratios from one run, and rerun a case
that fails by a hair before believing it.
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import hashlib
import inspect
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / ".." / "shared" / "data" / "octomap"
KINDS = [  # (kind, mode, method, threads)
    ("octree", "scan", "auto", 1), ("octree", "scan", "auto", 2),
    ("octree", "scan", "plain", 1),
    ("octree", "scan", "culling", 1), ("octree", "scan", "culling", 2),
    ("octree", "ray", "auto", 1), ("octree", "ray", "auto", 2),
    ("octree", "ray", "plain", 1),
    ("grid", "scan", "auto", 1), ("grid", "scan", "auto", 2),
]


# ---------------------------------------------------------------------- the worker
def worker(root: str, scans_path: str) -> None:
    """Serve cases on stdin (one JSON object a line) with the occgp of `root`."""
    sys.path.insert(0, root)
    import occgp
    from occgp import GridMap, OccupancyOctree

    assert Path(occgp.__file__).resolve().is_relative_to(Path(root).resolve()), occgp.__file__
    data = np.load(scans_path)
    sets = {}
    for name in sorted({k.split("/")[0] for k in data.files}):
        n = len([k for k in data.files if k.startswith(f"{name}/points")])
        sets[name] = [(data[f"{name}/points{i}"], data[f"{name}/origin{i}"]) for i in range(n)]
    print(json.dumps({"ready": occgp.__file__}), flush=True)
    for line in sys.stdin:
        case = json.loads(line)
        cls = OccupancyOctree if case["kind"] == "octree" else GridMap
        options = {"mode": case["mode"], "method": case["method"]}
        params = {}
        if "n_jobs" in inspect.signature(cls).parameters:
            params["n_jobs"] = case["threads"]          # the map's (this release on)
        elif "n_jobs" in inspect.signature(cls.insert_scan).parameters:
            options["n_jobs"] = case["threads"]         # insert_scan's (older builds)
        elif case["threads"] != 1:      # an older build without threads
            print(json.dumps({"skipped": True}), flush=True)
            continue
        m = cls(case["resolution"], **params)
        t0 = time.perf_counter()
        for points, origin in sets[case["dataset"]]:
            m.insert_scan(points, origin, **options)
        seconds = time.perf_counter() - t0
        if case["kind"] == "octree":
            digest = hashlib.sha1(m.to_bytes("ot")).hexdigest()
        else:
            cells = m.cells()
            order = np.lexsort(cells.centers.T)
            digest = hashlib.sha1(cells.centers[order].tobytes()
                                  + cells.log_odds[order].tobytes()).hexdigest()
        print(json.dumps({"seconds": seconds, "digest": digest}), flush=True)


class Worker:
    def __init__(self, root: Path, scans: Path) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, __file__, "--worker", str(root), str(scans)],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=str(root))
        self.ready = json.loads(self.proc.stdout.readline())["ready"]

    def run(self, case: dict) -> dict:
        self.proc.stdin.write(json.dumps(case) + "\n")
        self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError(f"worker {self.ready} died on {case}")
        return json.loads(line)

    def close(self) -> None:
        self.proc.stdin.close()
        self.proc.wait()


# ---------------------------------------------------------------------- the parent
def build_ref(ref: str) -> Path:
    """The worktree of `ref` with its extensions built in place."""
    sha = subprocess.run(["git", "rev-parse", "--verify", f"{ref}^{{commit}}"], cwd=ROOT,
                         check=True, capture_output=True, text=True).stdout.strip()
    tree = ROOT / "build" / f"ab-{sha[:12]}"
    if not (tree / "setup.py").exists():
        tree.parent.mkdir(exist_ok=True)
        subprocess.run(["git", "worktree", "add", "--detach", str(tree), sha], cwd=ROOT,
                       check=True, capture_output=True)
    if not list((tree / "occgp").glob("_octree*.so")):
        print(f"building {ref} ({sha[:12]}) in {tree} ...", flush=True)
        subprocess.run([sys.executable, "setup.py", "-q", "build_ext", "--inplace", "-j", "2"],
                       cwd=tree, check=True, capture_output=True)
    return tree


def make_scans(path: Path, n_geb: int, n_dat: int) -> None:
    """Simulate / read the scans once, with this checkout's occgp."""
    sys.path.insert(0, str(ROOT))
    from occgp import OccupancyOctree
    from occgp.datasets import free_path, simulate_scans
    from occgp.io import read_xyz

    out = {}
    if n_geb:
        env = OccupancyOctree.load(DATA / "geb079.bt")
        poses = free_path(env, n_geb, step=1.0, seed=0)
        for i, (p, o) in enumerate(simulate_scans(env, poses, seed=0, progress=False)):
            out[f"geb079/points{i}"], out[f"geb079/origin{i}"] = p, o
    if n_dat:
        scan = read_xyz(DATA / "scan.dat.bz2")
        rng = np.random.default_rng(0)
        shifts = np.vstack([np.zeros(3), rng.uniform(-0.5, 0.5, (n_dat - 1, 3)) * [1, 1, 0.2]])
        for i, s in enumerate(shifts):
            out[f"scan.dat/points{i}"] = scan.points + s
            out[f"scan.dat/origin{i}"] = scan.origin + s
    np.savez(path, **out)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--compare", metavar="REF", default="HEAD~1",
                        help="the commit to compare with (default: %(default)s)")
    parser.add_argument("--resolutions", type=float, nargs="+", default=[0.1, 0.2, 0.4])
    parser.add_argument("--geb079-scans", type=int, default=6)
    parser.add_argument("--scan-dat-poses", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--margin", type=float, default=0.05,
                        help="the slow-down past which a case fails (default: %(default)s)")
    parser.add_argument("--only", nargs="+", default=None, metavar="TEXT",
                        help="run the cases whose label holds one of these texts (e.g. "
                        "'octree scan auto n_jobs=1')")
    parser.add_argument("--quick", action="store_true",
                        help="2 geb079 scans and 1 scan.dat pose at 0.2 m, 2 repeats")
    parser.add_argument("--worker", nargs=2, metavar=("ROOT", "SCANS"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        worker(*args.worker)
        return 0
    if not (DATA / "geb079.bt").exists():
        print(f"skipped: {DATA} is absent (the shared data sets)")
        return 0
    if args.quick:
        args.geb079_scans, args.scan_dat_poses, args.resolutions, args.repeats = 2, 1, [0.2], 2
    ref_root = build_ref(args.compare)
    failed = False
    with tempfile.TemporaryDirectory() as tmp:
        scans = Path(tmp) / "scans.npz"
        make_scans(scans, args.geb079_scans, args.scan_dat_poses)
        builds = {"ref": Worker(ref_root, scans), "this": Worker(ROOT, scans)}
        try:
            datasets = [d for d, n in (("geb079", args.geb079_scans),
                                       ("scan.dat", args.scan_dat_poses)) if n]
            counts = {"geb079": args.geb079_scans, "scan.dat": args.scan_dat_poses}
            print(f"this checkout against {args.compare} ({ref_root.name}); "
                  f"best of {args.repeats}, ms per scan")
            header = (f"{'dataset':<9}{'res':>5}  {'case':<28}{'REF ms':>9}{'this ms':>9}"
                      f"{'this/REF':>10}  map")
            print(header)
            print("-" * len(header))
            for dataset in datasets:
                for res in args.resolutions:
                    for kind, mode, method, threads in KINDS:
                        case = dict(dataset=dataset, resolution=res, kind=kind, mode=mode,
                                    method=method, threads=threads)
                        best = {"ref": np.inf, "this": np.inf}
                        digests = {}
                        label = f"{kind} {mode} {method} n_jobs={threads}"
                        if args.only and not any(t in label for t in args.only):
                            continue
                        for r in range(args.repeats):
                            for name in (("ref", "this") if r % 2 == 0 else ("this", "ref")):
                                out = builds[name].run(case)
                                if out.get("skipped"):
                                    break
                                best[name] = min(best[name], out["seconds"])
                                digests[name] = out["digest"]
                            else:
                                continue
                            break
                        if len(digests) < 2:
                            print(f"{dataset:<9}{res:>5.2f}  {label:<28}  (a build has no "
                                  f"n_jobs)", flush=True)
                            continue
                        ratio = best["this"] / best["ref"]
                        same = digests["ref"] == digests["this"]
                        slow = ratio > 1.0 + args.margin
                        failed |= slow or not same
                        n = counts[dataset]
                        print(f"{dataset:<9}{res:>5.2f}  {label:<28}"
                              f"{1e3 * best['ref'] / n:>9.1f}{1e3 * best['this'] / n:>9.1f}"
                              f"{ratio:>9.3f}x  {'identical' if same else 'DIFFERENT'}"
                              f"{'  SLOWER' if slow else ''}", flush=True)
        finally:
            for w in builds.values():
                w.close()
    print("FAILED: a case is slower than the margin or a map differs" if failed
          else f"passed: no case slower than {args.compare} by more than "
               f"{100 * args.margin:.0f} %, every map identical")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
