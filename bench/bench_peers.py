"""Benchmark occgp against the Python OctoMap bindings, each in its own process.

The peers are ``octomap-python`` (module ``octomap``) and ``pyoctomap``, two
Cython wrappers of liboctomap's ``OcTree``. The bench creates a virtual
environment for them once (``build/peers-venv``, git-ignored, reused by later
runs) and pip-installs the pinned versions there; a package that cannot be
installed is reported and left out, and the bench goes on with the others.

Each package runs in a fresh process of its own (this file with ``--worker``:
the peers' venv Python for the peers, this Python for occgp), on the same points
written once to ``.npy`` files:

* ``scan.dat``: OctoMap's real dense scan (``../shared/data/octomap/scan.dat.bz2``,
  88,206 points, sensor at the origin);
* ``geb079``: one dense laser scan (720 x 150 beams, about 106k points) ray cast
  in the real OctoMap of building 079 from the first pose of ``bench_updates.py``'s
  trajectory.

Measured, at 0.1 m and 0.2 m, each the best of several repeats:

* inserting the scan into a fresh tree, in points per second: the peers'
  ``insertPointCloud(points, origin)`` and occgp's ``insert_scan(points, origin)``
  (``mode="scan"``, the default method), and occgp with ``n_jobs=2`` as an extra
  row (the peers' calls run on one thread); then, each with ``n_jobs=1``, occgp's
  ``GridMap.insert_scan(points, origin)`` (the same map as the octree, against the
  peers' ``insertPointCloud``), the discretized insertion
  ``insert_scan(points, origin, discretize=True)`` of the octree and of the grid
  (one ray per distinct end cell: liboctomap's ``insertPointCloud(points, origin,
  discretize=True)``, the peers' call it is timed against), and the grid's
  ``ray_model="bresenham"`` (Bonxai's ``ProbabilisticMap`` rules: one integer
  Bresenham line per distinct end cell; another map, timed against the peers'
  discretized call, the nearest they have);
* querying 1,000,000 points (half of them within 5 cm of a scan point, half
  uniform in the scan's bounding box, float32 values), in points per second, with
  each package's fastest public call: the occupancy probability (occgp's vectorised
  ``occupancy``; the peers have no vectorised call for it, so a Python loop over
  ``search(point)`` and ``node.getOccupancy()``), and the occupied / free /
  unknown label (occgp's ``is_occupied(..., return_unknown=True)``; the peers'
  ``getLabels(points)``, a compiled loop that calls back into Python per point).

Every map is checked identical: each worker writes its tree as ``.ot`` (full
log-odds) and ``.bt`` (maximum likelihood) files and the parent compares the
bytes with occgp's (and, where bytes differ, the leaves read back with
``OccupancyOctree.load``); the query results are compared value for value. The
grid's maps (as ``GridMap.to_octree()``) are checked against occgp's octree, and the
discretized maps against each other and the peers' discretized ``.ot``; for the
Bresenham map the bench prints the Jaccard index of its free and of its occupied
cells against the discretized 3D-DDA map's (they differ by design).

Run: ``python bench/bench_peers.py [--repeats 5] [--query-repeats 3]``; the README's
"Speed" section is one run of it.
"""

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / ".." / "shared" / "data" / "octomap"
VENV = ROOT / "build" / "peers-venv"
PEERS = {  # package name on PyPI -> (pinned version, module)
    "octomap-python": ("1.10.0.0", "octomap"),
    "pyoctomap": ("1.2.2", "pyoctomap"),
}
PACKAGES = ["octomap-python", "pyoctomap", "occgp"]
# occgp's extra insertion rows: result key -> (class name, insert_scan options, table label,
# the peers' timing it is compared with, suffix of the .ot it writes or None)
OCCGP_INSERTS = {
    "insert_grid_s": ("GridMap", {}, "insert, occgp grid", "insert_s", "_grid"),
    "insert_discretize_s": ("OccupancyOctree", dict(discretize=True),
                            "insert discretize, occgp octree", "insert_discretize_s",
                            "_discretize"),
    "insert_grid_discretize_s": ("GridMap", dict(discretize=True),
                                 "insert discretize, occgp grid", "insert_discretize_s",
                                 "_grid_discretize"),
    "insert_grid_bresenham_s": ("GridMap", dict(ray_model="bresenham"),
                                "insert, occgp grid bresenham (another map)",
                                "insert_discretize_s", None),
}


# ---------------------------------------------------------------------- worker
# Runs in the peers' venv too: stdlib and numpy only at module level.

def _best(repeats, setup, fn):
    """Best wall-clock seconds of ``fn(setup())`` over `repeats` runs, and the last result."""
    best, out = np.inf, None
    for _ in range(repeats):
        arg = setup()
        t0 = time.perf_counter()
        out = fn(arg)
        best = min(best, time.perf_counter() - t0)
    return best, out


def _occgp_ops():
    from occgp import GridMap, OccupancyOctree, __version__

    classes = {"GridMap": GridMap, "OccupancyOctree": OccupancyOctree}

    def new(resolution, n_jobs=None, cls="OccupancyOctree"):
        return classes[cls](resolution, n_jobs=n_jobs)

    def insert(tree, points, origin):
        tree.insert_scan(points, origin)

    def labels(tree, q):
        occupied, unknown = tree.is_occupied(q, return_unknown=True)
        return np.where(unknown, -1, occupied.astype(np.int32)).astype(np.int32)

    return dict(
        version=__version__, new=new, insert=insert,
        occupancy=lambda tree, q: tree.occupancy(q), labels=labels,
        write_ot=lambda tree, path: tree.save(path), write_bt=lambda tree, path: tree.save(path),
        calls=dict(insert="insert_scan(points, origin)",
                   insert_discretize="insert_scan(points, origin, discretize=True)",
                   insert_grid_bresenham='insert_scan(points, origin, ray_model="bresenham")',
                   occupancy="occupancy(points)",
                   labels="is_occupied(points, return_unknown=True)"))


def _peer_ops(package):
    from importlib import import_module
    from importlib.metadata import version

    mod = import_module(PEERS[package][1])
    missing = getattr(mod, "NullPointerException", AttributeError)

    def occupancy(tree, q):
        out = np.full(len(q), np.nan)
        search = tree.search
        for i, point in enumerate(q):      # no vectorised call: one search per point
            node = search(point)
            if node is not None:
                try:
                    out[i] = node.getOccupancy()
                except missing:            # octomap-python: a NULL node raises
                    pass
        return out

    return dict(
        version=version(package), new=mod.OcTree,
        insert=lambda tree, points, origin: tree.insertPointCloud(points, origin),
        insert_discretize=lambda tree, points, origin: tree.insertPointCloud(
            points, origin, discretize=True),
        occupancy=occupancy,
        labels=lambda tree, q: np.asarray(tree.getLabels(q), dtype=np.int32),
        # writeBinary turns the tree to maximum likelihood: write the .ot first
        write_ot=lambda tree, path: tree.write(str(path)),
        write_bt=lambda tree, path: tree.writeBinary(str(path)),
        calls=dict(insert="insertPointCloud(points, origin)",
                   insert_discretize="insertPointCloud(points, origin, discretize=True)",
                   occupancy="loop: search(point).getOccupancy()",
                   labels="getLabels(points)"))


def _jaccards(a, b):
    """Jaccard indices of the free and of the occupied cells of two grids: [free, occupied]."""
    out = []
    for free in (True, False):
        sets = []
        for m in (a, b):
            cells = m.cells()
            keys = np.floor(cells.centers[(cells.log_odds < 0) == free] / m.resolution)
            sets.append(set(map(tuple, keys.astype(np.int64).tolist())))
        out.append(len(sets[0] & sets[1]) / max(1, len(sets[0] | sets[1])))
    return out


def run_worker(job):
    """Time one package on every data set of `job` and write its maps and answers.

    `job` is a dict: ``package``, ``datasets`` (each ``name``, ``points`` and
    ``queries`` .npy paths, ``origin``), ``resolutions``, ``repeats``,
    ``query_repeats``, ``n_jobs`` (occgp's extra thread counts) and ``out`` (a
    folder). Returns the result dict, also written to ``out/<package>.json``.
    """
    package, out = job["package"], Path(job["out"])
    ops = _occgp_ops() if package == "occgp" else _peer_ops(package)
    result = dict(package=package, version=ops["version"], calls=ops["calls"],
                  python=platform.python_version(), numpy=np.__version__, runs=[])
    for data in job["datasets"]:
        points = np.load(data["points"])
        queries = np.load(data["queries"])
        origin = np.asarray(data["origin"], dtype=np.float64)
        for res in job["resolutions"]:
            stem = out / f"{package}_{data['name']}_{res}"
            run = dict(dataset=data["name"], resolution=res, n_points=len(points),
                       n_queries=len(queries))
            t, _ = _best(job["repeats"], lambda: ops["new"](res),
                         lambda tree: ops["insert"](tree, points, origin))
            run["insert_s"] = t
            if package == "occgp":
                for n in job["n_jobs"]:
                    t, tree = _best(job["repeats"], lambda: ops["new"](res, n),
                                    lambda tree: (ops["insert"](tree, points, origin), tree)[1])
                    run[f"insert_n_jobs_{n}_s"] = t
                    tree.save(f"{stem}_n_jobs_{n}.ot")
                maps = {}
                for key, (cls, options, _, _, suffix) in OCCGP_INSERTS.items():
                    t, maps[key] = _best(
                        job["repeats"], lambda: ops["new"](res, 1, cls),
                        lambda m: (m.insert_scan(points, origin, **options), m)[1])
                    run[key] = t
                    if suffix:
                        (maps[key].to_octree() if cls == "GridMap" else maps[key]).save(
                            f"{stem}{suffix}.ot")
                run["bresenham_jaccard"] = _jaccards(maps["insert_grid_bresenham_s"],
                                                     maps["insert_grid_discretize_s"])
            else:
                t, tree = _best(job["repeats"], lambda: ops["new"](res),
                                lambda tree: (ops["insert_discretize"](tree, points, origin),
                                              tree)[1])
                run["insert_discretize_s"] = t
                ops["write_ot"](tree, f"{stem}_discretize.ot")
            tree = ops["new"](res)
            ops["insert"](tree, points, origin)
            for what in ("occupancy", "labels"):
                t, answer = _best(job["query_repeats"], lambda: tree,
                                  lambda tree: ops[what](tree, queries))
                run[f"{what}_s"] = t
                np.save(f"{stem}_{what}.npy", answer)
            ops["write_ot"](tree, f"{stem}.ot")
            ops["write_bt"](tree, f"{stem}.bt")
            result["runs"].append(run)
    (out / f"{package}.json").write_text(json.dumps(result, indent=1))
    return result


# ---------------------------------------------------------------------- parent

def prepare_datasets(folder, n_queries, seed=0, names=("scan.dat", "geb079")):
    """Write each data set's points and queries to ``.npy`` files in `folder`; the job entries."""
    sys.path.insert(0, str(ROOT / "bench"))
    from bench_updates import geb079_trajectory, scan_dat_poses

    rng = np.random.default_rng(seed)
    out = []
    for name in names:
        scan = geb079_trajectory(1)[0] if name == "geb079" else scan_dat_poses(1)[0]
        points, origin = np.ascontiguousarray(scan[0], dtype=np.float64), np.asarray(scan[1])
        out.append(write_dataset(folder, name, points, origin, make_queries(points, n_queries, rng)))
    return out


def make_queries(points, n_queries, rng):
    """Half the queries within 5 cm of a scan point, half uniform in the scan's box.

    The coordinates are float32 values (stored as float64): occgp, like liboctomap's
    ``point3d``, looks points up in single precision, while the peers' ``search(point)``
    computes the key in double precision, and the two may pick neighbouring cells
    for a point within a float32 step of a cell border.
    """
    near = points[rng.integers(0, len(points), n_queries // 2)]
    near = near + rng.uniform(-0.05, 0.05, near.shape)
    box = rng.uniform(points.min(axis=0), points.max(axis=0), (n_queries - len(near), 3))
    queries = rng.permutation(np.vstack([near, box])).astype(np.float32)
    return np.ascontiguousarray(queries, dtype=np.float64)


def write_dataset(folder, name, points, origin, queries):
    """Save one data set for the workers; return its job entry."""
    folder = Path(folder)
    np.save(folder / f"{name}_points.npy", np.ascontiguousarray(points, dtype=np.float64))
    np.save(folder / f"{name}_queries.npy", np.ascontiguousarray(queries, dtype=np.float64))
    return dict(name=name, points=str(folder / f"{name}_points.npy"),
                queries=str(folder / f"{name}_queries.npy"),
                origin=[float(v) for v in np.asarray(origin, dtype=np.float64)])


def peers_python(venv=VENV, packages=tuple(PEERS)):
    """The peers' venv Python (created once) and the packages that import in it.

    Returns ``(python, {package: None or the reason it is missing})``.
    """
    python = Path(venv) / "bin" / "python"
    status = {}
    if not python.exists():
        made = subprocess.run([sys.executable, "-m", "venv", str(venv)],
                              capture_output=True, text=True)
        if made.returncode != 0:
            reason = f"could not create {venv}: {made.stderr.strip()[-300:]}"
            return None, {p: reason for p in packages}
    for package in packages:
        pinned, module = PEERS[package]
        probe = [str(python), "-c", f"import {module}; from importlib.metadata import version; "
                 f"assert version({package!r}) == {pinned!r}"]
        if subprocess.run(probe, capture_output=True).returncode == 0:
            status[package] = None
            continue
        print(f"installing {package}=={pinned} into {venv} ...", flush=True)
        pip = subprocess.run([str(python), "-m", "pip", "install", "-q", f"{package}=={pinned}"],
                             capture_output=True, text=True)
        ok = pip.returncode == 0 and subprocess.run(probe, capture_output=True).returncode == 0
        status[package] = None if ok else (
            f"pip install {package}=={pinned} failed: "
            f"{(pip.stderr or pip.stdout).strip().splitlines()[-1:] or ['import failed']}")
    return python, status


def launch_worker(python, job, folder, env=None, timeout=3600):
    """Run ``--worker`` for one package with `python` in a fresh process; its result dict."""
    job_file = Path(folder) / f"job_{job['package']}.json"
    job_file.write_text(json.dumps(job))
    done = subprocess.run([str(python), str(Path(__file__).resolve()), "--worker", str(job_file)],
                          capture_output=True, text=True, env=env, timeout=timeout)
    if done.returncode != 0:
        raise RuntimeError(f"the {job['package']} worker failed:\n{done.stderr[-2000:]}")
    return json.loads((Path(job["out"]) / f"{job['package']}.json").read_text())


def occgp_env():
    """The environment that makes a child Python import this process's occgp."""
    import occgp

    env = dict(os.environ)
    here = str(Path(occgp.__file__).resolve().parents[1])
    env["PYTHONPATH"] = os.pathsep.join([here] + [p for p in [env.get("PYTHONPATH")] if p])
    return env


def same_map(path_a, path_b):
    """"bytes" when the files are equal, "leaves" when their trees' leaves are, else ""."""
    a, b = Path(path_a).read_bytes(), Path(path_b).read_bytes()
    if a == b:
        return "bytes"
    from occgp import OccupancyOctree

    la, lb = (OccupancyOctree.load(p).leaves() for p in (path_a, path_b))
    oa = np.lexsort((la.sizes, *la.centers.T))
    ob = np.lexsort((lb.sizes, *lb.centers.T))
    same = (len(la.sizes) == len(lb.sizes) and np.array_equal(la.centers[oa], lb.centers[ob])
            and np.array_equal(la.log_odds[oa], lb.log_odds[ob]))
    return "leaves" if same else ""


def check_identical(results, out, n_jobs):
    """Compare every package's maps and query answers with occgp's; a list of problems.

    The grid's maps and the discretized maps (occgp's and the peers') are compared
    where their runs wrote them.
    """
    problems = []
    for run in results["occgp"]["runs"]:
        where = f"({run['dataset']}, {run['resolution']} m)"
        ref = Path(out) / f"occgp_{run['dataset']}_{run['resolution']}"
        discretized = Path(f"{ref}_discretize.ot")
        # (who, its map, occgp's map it must equal, required)
        pairs = [(f"occgp n_jobs={n}", Path(f"{ref}_n_jobs_{n}.ot"), Path(f"{ref}.ot"), True)
                 for n in n_jobs]
        pairs += [("occgp grid", Path(f"{ref}_grid.ot"), Path(f"{ref}.ot"), False),
                  ("occgp grid discretize", Path(f"{ref}_grid_discretize.ot"), discretized, False)]
        for package in results:
            if package != "occgp":
                stem = Path(out) / f"{package}_{run['dataset']}_{run['resolution']}"
                pairs += [(package, Path(f"{stem}{ext}"), Path(f"{ref}{ext}"), True)
                          for ext in (".ot", ".bt")]
                pairs += [(f"{package} discretize", Path(f"{stem}_discretize.ot"), discretized,
                           False)]
                for what in ("occupancy", "labels"):
                    mine = np.load(f"{ref}_{what}.npy")
                    theirs = np.load(f"{stem}_{what}.npy")
                    if not np.array_equal(mine, theirs, equal_nan=what == "occupancy"):
                        problems.append(f"{package} {what} answers differ {where}")
        for who, path, mine, required in pairs:
            if not required and not (path.exists() and mine.exists()):
                continue
            if not same_map(mine, path):
                problems.append(f"{who} {path.suffix} map differs {where}")
    return problems


def hardware_line():
    """CPU model, cores, Python, numpy and the liboctomap occgp links, in one line."""
    info = {}
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            key, _, value = line.partition(":")
            info.setdefault(key.strip(), value.strip())
    except OSError:
        pass
    cpu = info.get("model name") or platform.processor() or "unknown CPU"
    details = [f"family {info['cpu family']} model {info['model']}"] if "model" in info else []
    if "cpu MHz" in info:
        details.append(f"{float(info['cpu MHz']) / 1e3:.1f} GHz")
    if " hypervisor" in f" {info.get('flags', '')} ":
        details.append("virtual machine")
    cpu += f" ({', '.join(details)})" if details else ""
    try:
        lib = subprocess.run(["pkg-config", "--modversion", "octomap"], capture_output=True,
                             text=True).stdout.strip()
    except OSError:
        lib = ""
    return (f"{cpu}, {os.cpu_count()} cores, Linux {platform.release()}, "
            f"Python {platform.python_version()}, numpy {np.__version__}"
            + (f", liboctomap {lib} (occgp's)" if lib else ""))


def _rate(n, seconds):
    return f"{n / seconds / 1e6:.2f} M" if seconds else "–"


def markdown_table(results, missing, n_jobs):
    """The table of points per second: one column per package, then occgp's ratios."""
    peers = [p for p in PEERS if p in results]
    head = ["data", "res. (m)", "operation"]
    head += [f"{p} {results[p]['version']}" for p in peers]
    head += [f"occgp {results['occgp']['version']}"] + [f"occgp / {p}" for p in peers]
    lines = ["| " + " | ".join(head) + " |",
             "|" + "|".join(["---"] * 3 + ["---:"] * (len(head) - 3)) + "|"]
    by = {p: {(r["dataset"], r["resolution"]): r for r in results[p]["runs"]} for p in results}
    for key, run in by["occgp"].items():
        data = f"{key[0]} ({run['n_points']:,} pts)"
        # (label, the peers' timing, occgp's, count, what the peers' column shows instead of
        # their rate: None for the rate)
        rows = [("insert", "insert_s", "insert_s", run["n_points"], None)]
        rows += [(f"insert, occgp n_jobs={n}", "insert_s", f"insert_n_jobs_{n}_s", run["n_points"],
                  "(1 thread)") for n in n_jobs]
        shown = {"insert_s"}
        for own_key, (_, _, label, peer_key, _) in OCCGP_INSERTS.items():
            if own_key in run:
                rows.append((label, peer_key, own_key, run["n_points"],
                             "(as above)" if peer_key in shown else None))
                shown.add(peer_key)
        rows += [("occupancy, 1M queries", "occupancy_s", "occupancy_s", run["n_queries"], None),
                 ("label, 1M queries", "labels_s", "labels_s", run["n_queries"], None)]
        for label, peer_key, own_key, n, instead in rows:
            if run["n_queries"] != 1_000_000:
                label = label.replace("1M", f"{run['n_queries']:,}")
            own = run[own_key]
            theirs = [by[p][key].get(peer_key) for p in peers]
            cells = [data, f"{key[1]:g}", label]
            cells += [instead or _rate(n, t) if t else "–" for t in theirs]
            cells += [_rate(n, own)]
            cells += [f"{t / own:.1f}x" if t else "–" for t in theirs]
            lines.append("| " + " | ".join(cells) + " |")
    notes = [f"{p}: not measured ({why})" for p, why in missing.items() if why]
    notes += [f"occgp grid bresenham vs the discretized 3D-DDA map, {r['dataset']} "
              f"{r['resolution']:g} m: Jaccard of the free cells {r['bresenham_jaccard'][0]:.3f}, "
              f"of the occupied cells {r['bresenham_jaccard'][1]:.3f}"
              for r in results["occgp"]["runs"] if "bresenham_jaccard" in r]
    return "\n".join(lines), notes


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--worker", metavar="JOB", help=argparse.SUPPRESS)
    parser.add_argument("--repeats", type=int, default=5, help="insertions per figure (best of)")
    parser.add_argument("--query-repeats", type=int, default=3, help="query runs per figure")
    parser.add_argument("--queries", type=int, default=1_000_000)
    parser.add_argument("--resolutions", type=float, nargs="+", default=[0.1, 0.2])
    parser.add_argument("--n-jobs", type=int, nargs="+", default=[2],
                        help="occgp's extra thread counts (default 2)")
    parser.add_argument("--datasets", nargs="+", default=["scan.dat", "geb079"])
    parser.add_argument("--out", default=str(ROOT / "build" / "peers-bench"),
                        help="folder for the points, maps and answers")
    parser.add_argument("--venv", default=str(VENV),
                        help="the peers' virtual environment (created once, then reused)")
    args = parser.parse_args(argv)
    if args.worker:
        run_worker(json.loads(Path(args.worker).read_text()))
        return
    if not DATA.exists():
        sys.exit(f"{DATA} is absent (../shared/data beside the project root)")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    print(f"load average before the run: {os.getloadavg()[0]:.2f}", flush=True)
    datasets = prepare_datasets(out, args.queries, names=args.datasets)
    python, missing = peers_python(args.venv)
    job = dict(datasets=datasets, resolutions=args.resolutions, repeats=args.repeats,
               query_repeats=args.query_repeats, n_jobs=args.n_jobs, out=str(out))
    results = {}
    for package in PACKAGES:
        if missing.get(package):
            print(f"{package}: not installed, left out ({missing[package]})", flush=True)
            continue
        print(f"running {package} ...", flush=True)
        try:
            results[package] = launch_worker(
                sys.executable if package == "occgp" else python, dict(job, package=package),
                out, env=occgp_env() if package == "occgp" else None)
        except (RuntimeError, subprocess.TimeoutExpired) as exc:
            missing[package] = str(exc).splitlines()[0]
            print(f"{package}: failed, left out ({exc})", flush=True)
    if "occgp" not in results:
        sys.exit("occgp's worker failed")
    table, notes = markdown_table(results, missing, args.n_jobs)
    problems = check_identical(results, out, args.n_jobs)
    given = sys.argv[1:] if argv is None else list(argv)
    print("\n$ python bench/bench_peers.py" + "".join(f" {a}" for a in given))
    print(f"{hardware_line()}; "
          + ", ".join(f"{p} {r['version']}" for p, r in results.items())
          + f"; load average after: {os.getloadavg()[0]:.2f}")
    print(f"points per second (M = millions), best of {args.repeats} insertions into a fresh "
          f"tree and of {args.query_repeats} query runs\n")
    print(table)
    print()
    for p, r in results.items():
        print(f"{p}: " + "; ".join(f"{k}: {v}" for k, v in r["calls"].items()))
    for note in notes:
        print(note)
    print("maps (.ot and .bt bytes; the grid's and the discretized maps too) and query answers "
          "identical to occgp's: "
          + ("all" if not problems else "NO\n  " + "\n  ".join(problems)))


if __name__ == "__main__":
    main()
