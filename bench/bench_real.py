"""Every map on every shared real log: the held-out benchmark of ``occgp.evaluation``.

Logs (``../shared/data``; a log whose files are absent is skipped with a message):

* ``intel`` and ``fr079``: the CARMEN 2D laser logs (``read_carmen``, no-return
  readings dropped); the 2D maps (``gp-grid``, ``gpom``, ``gpomik``,
  ``gp-mixture``) are each fitted once on every training beam,
  ``fit(hits, segment_starts, segment_ends)``;
* ``hku_mb``: the Livox LiDAR sequence (``ScanSequence`` of ``Scans/`` posed by
  ``optimized_poses.txt``); the 3D maps (``octree``, ``grid``, ``bgk``,
  ``akimap``, ``knn``) insert the training scans one by one.

Scans ``i % 10 == 5`` are held out (``RealLogBenchmark``): their hits within
``--max-range`` (30 m) are occupied test points, and each gives one free test
point on its beam, between 0.3 m from the sensor and 0.2 m before the hit (half of
them within 1 m of that margin: near the surface). Every map is built as a user
would build it: ``make_map(name, resolution=R)`` with only the resolution given
(``--resolutions``, 0.1 m by default) and, for the maps that draw random numbers,
``random_state=0`` (so that the tables are reproduced); rows named ``name(k=v,...)`` (``--extra``)
add other parameters. Printed per map: AUC, accuracy at the map's own threshold,
Brier score, NLL, the accuracy on occupied, free and near-surface free points, the
unknown fraction, build and query seconds, the map's own ``memory_usage()`` and the
peak resident memory of building and querying it (MB; each map is built in a forked
process of its own), and each map's total time over the fastest map of the same log
and resolution.

Run: ``python bench/bench_real.py [--logs intel fr079 hku_mb] [--maps gpom ...]
[--resolutions 0.1 0.2] [--max-points N] [--extra "bgk(max_range=30)"]
[--json out.json] [--rst docs/real_log_tables.rst]``; ``--from-json a.json b.json
--rst ...`` writes the tables of earlier runs (merged) without running anything.
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")   # idle BLAS threads spin on 2 cores

import argparse
import ast
import json
import multiprocessing
import re
import sys
import time
from pathlib import Path
from types import SimpleNamespace

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
LOGS = {
    "intel": DATA / "carmen" / "intel-corrected.log.gz",
    "fr079": DATA / "carmen" / "freiburg-079-corrected.log.gz",
    "hku_mb": DATA / "lidar_seq" / "hku_mb",
}
MAPS_2D = ("gp-grid", "gpom", "gpomik", "gp-mixture")
MAPS_3D = ("octree", "grid", "bgk", "akimap", "knn")
COLUMNS = ("method", "auc", "accuracy", "brier", "nll", "acc_occupied", "acc_free",
           "acc_near", "unknown_fraction", "build_seconds", "query_seconds", "map_mb",
           "peak_mb", "vs_fastest")


def load(name):
    """The log as the benchmark takes it."""
    from occgp.io import ScanSequence, read_carmen

    if name == "hku_mb":
        return ScanSequence(LOGS[name] / "Scans", LOGS[name] / "optimized_poses.txt",
                            progress=False)
    return read_carmen(LOGS[name])


def parse_spec(text):
    """``"name"`` or ``"name(k=v, ...)"`` as (name, params)."""
    m = re.fullmatch(r"\s*([\w-]+)\s*(?:\((.*)\))?\s*", text)
    if not m:
        raise SystemExit(f"cannot read the map spec {text!r}: expected name or name(k=v,...)")
    params = {}
    if m.group(2):
        for item in m.group(2).split(","):
            key, _, value = item.partition("=")
            try:
                params[key.strip()] = ast.literal_eval(value.strip())
            except (ValueError, SyntaxError):
                params[key.strip()] = value.strip()
    return m.group(1), params


def _child(bench, label, spec, conn):
    try:
        row = bench.evaluate(label, spec)._asdict()
        row.pop("map")
        conn.send(row)
    except (ValueError, MemoryError) as exc:
        conn.send(f"{type(exc).__name__}: {exc}")
    conn.close()


def isolated(bench, label, spec):
    """bench.evaluate(label, spec) in a forked process of its own (so that its peak
    memory is its own), as a dict without the map, or the error's text."""
    ctx = multiprocessing.get_context("fork")
    parent, child = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(bench, label, spec, child))
    proc.start()
    child.close()
    try:
        out = parent.recv()
    except EOFError:
        out = f"the process died (exit code {proc.exitcode}; out of memory?)"
    proc.join()
    return out


def run_log(name, args, headers):
    from occgp.evaluation import RealLogBenchmark, format_table
    from occgp.maps import map_type

    path = LOGS[name]
    if not path.exists():
        print(f"== {name}: skipped, {path} not found ==")
        return []
    t0 = time.perf_counter()
    log = load(name)
    bench = RealLogBenchmark(log, max_range=args.max_range, max_points=args.max_points,
                             seed=0, progress=False)
    test = bench.test_set
    if bench.dims == 2:
        bench.training_observations()           # made once, before the maps' processes fork
    two_d = bench.dims == 2
    maps = args.maps or (MAPS_2D if two_d else MAPS_3D)
    maps = [m for m in maps if (m in MAPS_2D) == two_d or "(" in m]
    specs = [parse_spec(m) for m in maps] + [parse_spec(e) for e in args.extra
                                             if (parse_spec(e)[0] in MAPS_2D) == two_d]
    headers[name] = (f"{name}: {len(log)} scans, {len(bench.train_indices)} mapped, "
                     f"{len(bench.test_indices)} held out; {int(test.labels.sum()):,} occupied "
                     f"and {int((~test.labels).sum()):,} free test points "
                     f"({int(test.near_surface.sum()):,} near the surface).")
    print(f"== {headers[name]} Read in {time.perf_counter() - t0:.1f} s ==", flush=True)
    records = []
    for res in args.resolutions:
        rows = []
        for map_name, params in specs:
            spec = {"map": map_name, **params}
            names = map_type(map_name).parameters()
            if "resolution" in names:
                spec["resolution"] = res
            if "random_state" in names and "random_state" not in spec:
                spec["random_state"] = 0       # the same tables on every run
            label = map_name + ("" if not params else "(" + ", ".join(
                f"{k}={v}" for k, v in params.items()) + ")")
            rec = isolated(bench, label, spec)
            if isinstance(rec, str):
                print(f"  {label} @ {res:g} m: failed: {rec}", flush=True)
                continue
            rec.update(log=name, resolution=res, header=headers[name])
            row = SimpleNamespace(**rec)
            rows.append(rec)
            print(f"  {label} @ {res:g} m: AUC {row.auc:.4f}, accuracy {row.accuracy:.3f}, "
                  f"{row.build_seconds:.1f} s + {row.query_seconds:.1f} s", flush=True)
        if not rows:
            continue
        fastest = min(r["build_seconds"] + r["query_seconds"] for r in rows)
        for r in rows:
            r["vs_fastest"] = (r["build_seconds"] + r["query_seconds"]) / fastest
        print(f"\n{name}, resolution {res:g} m")
        print(format_table(rows, columns=COLUMNS, floatfmt=".3f"))
        print()
        records += rows
    return records


RST_COLUMNS = (("method", "map", "{}"), ("auc", "AUC", "{:.3f}"),
               ("accuracy", "accuracy", "{:.3f}"), ("brier", "Brier", "{:.3f}"),
               ("nll", "NLL", "{:.3f}"), ("acc_occupied", "acc occ", "{:.3f}"),
               ("acc_free", "acc free", "{:.3f}"), ("acc_near", "acc near", "{:.3f}"),
               ("unknown_fraction", "unknown", "{:.3f}"), ("build_seconds", "build s", "{:.1f}"),
               ("query_seconds", "query s", "{:.1f}"), ("map_mb", "map MB", "{:.0f}"),
               ("peak_mb", "peak MB", "{:.0f}"))


def rst_table(rows):
    """The rows as a reStructuredText simple table."""
    cells = [[head for _, head, _ in RST_COLUMNS]] + [
        [fmt.format(r[key]) for key, _, fmt in RST_COLUMNS] for r in rows]
    widths = [max(len(row[j]) for row in cells) for j in range(len(RST_COLUMNS))]
    rule = "  ".join("=" * w for w in widths)
    lines = [rule, "  ".join(c.ljust(w) for c, w in zip(cells[0], widths)).rstrip(), rule]
    lines += ["  ".join(c.ljust(w) for c, w in zip(row, widths)).rstrip() for row in cells[1:]]
    return "\n".join(lines + [rule])


def write_rst(path, records, headers):
    """Every log's tables, one per resolution, under its header line."""
    out = [".. This file is written by bench/bench_real.py --rst; do not edit it by hand.", ""]
    for log, header in headers.items():
        rows = [r for r in records if r["log"] == log]
        if not rows:
            continue
        out += [f".. {log}", "", header, ""]
        for res in sorted({r["resolution"] for r in rows}):
            part = [r for r in rows if r["resolution"] == res]
            if len({r["resolution"] for r in rows}) > 1 or log == "hku_mb":
                out += [f"Cells of {res:g} m:", ""]
            out += [rst_table(part), ""]
    Path(path).write_text("\n".join(out))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--logs", nargs="+", default=list(LOGS), choices=list(LOGS))
    parser.add_argument("--maps", nargs="+", default=None,
                        help="registered map names (default: every 2D map on the 2D logs, "
                        "every 3D map on hku_mb)")
    parser.add_argument("--extra", nargs="+", default=[],
                        help="more rows: name(k=v, ...) with other parameters")
    parser.add_argument("--resolutions", nargs="+", type=float, default=[0.1])
    parser.add_argument("--max-range", type=float, default=30.0)
    parser.add_argument("--max-points", type=int, default=None,
                        help="at most this many held-out hits (a seeded subsample)")
    parser.add_argument("--json", default=None, help="write the rows to this file")
    parser.add_argument("--rst", default=None,
                        help="write the tables as reStructuredText to this file (the docs' "
                        "docs/real_log_tables.rst)")
    parser.add_argument("--from-json", nargs="+", default=None, metavar="FILE",
                        help="run nothing: the rows of these --json files (later files "
                        "replace the same log, resolution and map) go to --rst and --json")
    args = parser.parse_args(argv)
    records, headers = [], {}
    if args.from_json:
        merged = {}
        for path in args.from_json:
            for rec in json.loads(Path(path).read_text()):
                merged[(rec["log"], rec["resolution"], rec["method"])] = rec
        order = {name: k for k, name in enumerate(LOGS)}
        records = sorted(merged.values(), key=lambda r: (order[r["log"]], r["resolution"]))
        headers = {r["log"]: r["header"] for r in records}
    else:
        for name in args.logs:
            records += run_log(name, args, headers)
    if args.json:
        Path(args.json).write_text(json.dumps(records, indent=1))
    if args.rst:
        write_rst(args.rst, records, headers)
    return 0


if __name__ == "__main__":
    sys.exit(main())
