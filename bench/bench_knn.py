"""The k-NN inverse sensor model against OctoMap on rendered stereo matched by StereoSGBM.

Miao, Hunter and Georgilas's protocol on exact synthetic ground truth: the 20
data sets (``occgp.datasets.rendered_stereo_datasets()``: 5 tetromino layouts x
plain / textured boxes x buildings / open lot), each an orbit of 80 keyframes
(2 x 40) rendered as rectified 640 x 360 grey pairs (f = 337.2 px, baseline
0.12 m; Voronoi or cardboard boxes, asphalt, brick facades, sun and shadows,
sensor blur, noise and gain mismatch), matched by OpenCV's StereoSGBM,
triangulated within 8 m and voxel-filtered at 0.1 m. Every map is a 0.1 m
octree with a 4 m sensor range.

Per data set, a seeded sample of the authors' 1,600 StereoSGBM parameter sets
(``sgbm_parameter_sets(RANK_SETS, seed=0)``: a uniform sample keeps the full
grid's spread) is ranked by the FDR of its naive map (every cell holding a
point occupied) over every ``RANK_EVERY``-th keyframe, and the 1st, middle and
last sets are matched on all 80 keyframes. On each of these 60 cloud sets both
grid searches run (``KNN_GRID``, 4,050 combinations, and ``OCTOMAP_GRID``,
180, with the 9 thresholds), and on the last-ranked sets the multi-scan k-NN
score (``KNNMap(history=HISTORY)``, beyond the paper) gets the same 4,050. Each
combination is scored under both protocols in one pass:

* occgp's strict protocol (the default, ``auc_exact``): every cell the scans
  reach, exact cells, area anchored at (0, 0) and (1, 1);
* the authors' (``scoring="authors"``): the cells known both in the map and in
  the reference map (the map of the true-depth clouds of the same keyframes,
  through the same pipeline), true positives by the ±1-cell one-to-one rule,
  the area under the measured points only.

Tables (all measured in this run):

1. The clouds' errors against the exact geometry (``point_errors``): share of
   points beyond 0.1 / 0.3 / 1 m of a surface, in front of and behind the
   first surface on their ray, by surface kind, for the 1st / middle / last
   sets, plain and textured boxes.
2. Per data set and rank: the naive map's FDR, OctoMap's best AUC and the
   k-NN model's (paper's score and multi-scan) under both protocols.
3. The paper's Fig. 5 as a table: the gain against OctoMap's best AUC, sorted,
   absolute and relative, both protocols.
4. Summary per rank and half (``tune`` / ``test``): mean and maximum gains.
5. Defaults chosen on the tuning half (the combination with the best mean
   strict AUC over the tuning data sets, all ranks) and reported on the test
   half beside each data set's best.
6. Times per data set: render, rank, match, replays and searches.
7. The issue's targets on the test half, met or missed.

Run: ``python bench/bench_knn.py --n-jobs 2`` (about 50 minutes on 2 cores);
``--tables-only --json FILE`` prints the tables of a kept run again;
``--quick`` (4 data sets, 12 ranked sets, 24 keyframes) for a smoke run.
``--json FILE`` keeps every data set's result as it is measured and
``--resume`` skips those already in it. ``bench/bench_knn_simulated.py`` holds
the earlier comparison on the analytic noise model (Gaussian depth noise and
speckle), with the NCA parameter weights and run-time models.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

import numpy as np

from occgp.datasets import (PointErrors, Scan, StereoRig, disparity_to_points, point_errors,
                            rank_sgbm_sets, rendered_stereo_datasets, sgbm_parameter_sets,
                            voxel_filter)
from occgp.evaluation import KNN_GRID, OCTOMAP_GRID, cell_labels, grid_search
from occgp.knn import ScanReplay

from bench_gp import table  # the GP bench's (same folder)

RESOLUTION = 0.1
SENSOR_RANGE = 4.0
N_FRAMES, ORBITS = 40, 2
RANK_SETS, RANK_EVERY = 24, 10
HISTORY = 4
RANKS = ("1st", "middle", "last")
QUICK_SETS = ("I_plain_buildings", "I_textured_open", "T_plain_open", "T_textured_buildings")


def signed(x, digits=4):
    """``+0.0012``; blank for NaN (a search not run)."""
    return "" if math.isnan(x) else f"{x:+.{digits}f}"


def log(msg):
    print(msg, file=sys.stderr, flush=True)


def true_scans(pairs, rig):
    """The keyframes' clouds from the renderer's true depth, through the same pipeline."""
    out = []
    for p in pairs:
        with np.errstate(divide="ignore"):
            disparity = rig.focal_length * rig.baseline / p.depth
        points = voxel_filter(disparity_to_points(disparity, rig, p.position, p.rotation),
                              RESOLUTION)
        out.append(Scan(points, np.asarray(p.position, dtype=np.float64)))
    return out


def aucs(result):
    """(strict, authors) AUC arrays of a search scored under the authors' protocol."""
    rows = result.results
    return (np.array([r["auc_exact"] for r in rows]), np.array([r["auc"] for r in rows]))


def params_of(result):
    keys = [k for k in result.results[0] if k not in ("auc", "auc_exact", "thresholds",
                                                       "tpr", "fdr")]
    return [{k: r[k] for k in keys} for r in result.results]


def error_counts(errors: PointErrors):
    rows = errors.table()
    return {r["surface"]: {k: (v * r["points"] if k not in ("surface", "points") else v)
                           for k, v in r.items()} for r in rows}


def measure(d, rig, quick, n_jobs):
    """One data set: render, rank, match the three sets, replay, search."""
    times = {}
    scene = d.scene()
    t0 = time.perf_counter()
    n_frames = 12 if quick else N_FRAMES
    pairs = d.render(rig, n_frames=n_frames, orbits=ORBITS, truth=True, n_jobs=n_jobs)
    times["render"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    sets = sgbm_parameter_sets(12 if quick else RANK_SETS, seed=0)
    order, fdr = rank_sgbm_sets(pairs[::4 if quick else RANK_EVERY], rig, scene, sets,
                                resolution=RESOLUTION, n_jobs=n_jobs)
    times["rank"] = time.perf_counter() - t0
    ref = ScanReplay(true_scans(pairs, rig), RESOLUTION, max_range=SENSOR_RANGE)
    picks = {"1st": int(order[0]), "middle": int(order[len(order) // 2]),
             "last": int(order[-1])}
    out = {"name": d.name, "half": d.half, "texture": d.texture, "ranks": {},
           "rank_fdr": {"min": float(fdr.min()), "median": float(np.median(fdr)),
                        "max": float(fdr.max())}}
    for rank, i in picks.items():
        t0 = time.perf_counter()
        scans = d.scans(sets[i], rig=rig, pairs=pairs, n_jobs=n_jobs)
        t_match = time.perf_counter() - t0
        t0 = time.perf_counter()
        replay = ScanReplay(scans, RESOLUTION, max_range=SENSOR_RANGE, ks=(1,))
        labels = cell_labels(scene, replay.centers, RESOLUTION)
        mask = np.isin(replay.keys, ref.keys)
        t_replay = time.perf_counter() - t0
        kw = dict(scoring="authors", mask=mask, n_jobs=n_jobs)
        octo = grid_search(replay, labels, OCTOMAP_GRID, method="octomap", **kw)
        knn = grid_search(replay, labels, KNN_GRID, method="knn", **kw)
        searches = [("octo", octo), ("knn", knn)]
        t_hist = math.nan
        if rank == "last":      # the multi-scan score: its target is on the last-ranked sets
            t0 = time.perf_counter()
            hist_replay = ScanReplay(scans, RESOLUTION, max_range=SENSOR_RANGE, ks=(1,),
                                     history=HISTORY)
            assert np.array_equal(hist_replay.keys, replay.keys)
            hist = grid_search(hist_replay, labels, KNN_GRID, method="knn", **kw)
            t_hist = time.perf_counter() - t0
            searches.append(("hist", hist))
        errors = error_counts(point_errors(scene, scans))
        entry = {"sgbm": sets[i], "naive_fdr": float(fdr[i]),
                 "points": int(replay.n_points), "cells": int(replay.num_cells),
                 "scored": int(mask.sum()), "errors": errors,
                 "times": {"match": t_match, "replay": t_replay, "octo": octo.seconds,
                           "knn": knn.seconds, "history": t_hist}}
        for name, res in searches:
            strict, authors = aucs(res)
            entry[name] = {"strict": strict.tolist(), "authors": authors.tolist()}
        out["ranks"][rank] = entry
        if "octo_params" not in out:
            out["octo_params"] = params_of(octo)
            out["knn_params"] = params_of(knn)
    out["times"] = times
    return out


# ------------------------------------------------------------------------ tables
def best(entry, method, protocol):
    """The best AUC of a search; NaN for the multi-scan search off the last rank."""
    return max(entry[method][protocol]) if method in entry else math.nan


def error_table(results):
    print("== 1. Cloud errors against the exact geometry (share of points; front: in free "
          "space before the first surface on the ray, behind: past it) ==")
    rows = []
    for texture in (False, True):
        for rank in RANKS:
            total = {}
            for r in results:
                if r["texture"] != texture:
                    continue
                for kind, c in r["ranks"][rank]["errors"].items():
                    acc = total.setdefault(kind, {})
                    for k, v in c.items():
                        if k != "surface":
                            acc[k] = acc.get(k, 0) + v
            for kind in sorted(total, key=lambda k: (k != "all", k)):
                c = total[kind]
                n = c["points"]
                if not n:
                    continue
                rows.append(["textured" if texture else "plain", rank, kind, f"{n}"]
                            + [f"{c[k] / n:.3f}" for k in (">0.1", ">0.1 front", ">0.1 behind",
                                                           ">0.3", ">0.3 front", ">0.3 behind",
                                                           ">1", ">1 front", ">1 behind")])
    table(rows, ["boxes", "SGBM rank", "surface", "points", ">0.1 m", "front", "behind",
                 ">0.3 m", "front", "behind", ">1 m", "front", "behind"])


def per_dataset_table(results):
    print("== 2. Best AUC per data set and SGBM rank (strict: occgp's protocol; authors': "
          "Miao et al.'s) ==")
    rows = []
    for r in results:
        for rank in RANKS:
            e = r["ranks"][rank]
            row = [r["name"], r["half"], rank, f"{e['naive_fdr']:.3f}", f"{e['points']}"]
            for protocol in ("strict", "authors"):
                o = best(e, "octo", protocol)
                row += [f"{o:.4f}", signed(best(e, "knn", protocol) - o),
                        signed(best(e, "hist", protocol) - o)]
            rows.append(row)
    table(rows, ["data set", "half", "rank", "naive FDR", "points", "OctoMap strict",
                 "k-NN gain", f"k-NN h={HISTORY} gain", "OctoMap authors'", "k-NN gain",
                 f"k-NN h={HISTORY} gain"])


def fig5_table(results):
    print("== 3. Fig. 5: gain of the k-NN model's best AUC over OctoMap's best against "
          "OctoMap's best (sorted by it; relative gain in %) ==")
    for protocol in ("authors", "strict"):
        rows = []
        for r in results:
            for rank in RANKS:
                e = r["ranks"][rank]
                o = best(e, "octo", protocol)
                g = best(e, "knn", protocol) - o
                h = best(e, "hist", protocol) - o
                rows.append((o, [r["name"], rank, f"{o:.4f}", signed(g),
                                 signed(100 * g / o, 1), signed(h), signed(100 * h / o, 1)]))
        rows.sort(key=lambda x: x[0])
        print(f"-- {protocol} protocol --")
        table([row for _, row in rows], ["data set", "rank", "OctoMap best", "k-NN gain",
                                         "rel %", f"h={HISTORY} gain", "rel %"])


def gains(results, rank, protocol, method, half=None):
    out = []
    for r in results:
        if half is not None and r["half"] != half:
            continue
        e = r["ranks"][rank]
        o = best(e, "octo", protocol)
        out.append((best(e, method, protocol) - o, (best(e, method, protocol) - o) / o))
    return np.array(out).reshape(-1, 2)


def summary_table(results):
    print("== 4. Gains per SGBM rank and half (absolute; relative in %) ==")
    rows = []
    for half in ("tune", "test", None):
        for rank in RANKS:
            for protocol in ("authors", "strict"):
                for method in ("knn", "hist"):
                    g = gains(results, rank, protocol, method, half)
                    if not len(g) or np.isnan(g).all():
                        continue
                    rows.append([half or "all", rank, protocol,
                                 "k-NN" if method == "knn" else f"k-NN h={HISTORY}",
                                 f"{len(g)}", f"{g[:, 0].mean():+.4f}", f"{g[:, 0].max():+.4f}",
                                 f"{g[:, 0].min():+.4f}", f"{100 * g[:, 1].mean():+.1f}",
                                 f"{100 * g[:, 1].max():+.1f}"])
    table(rows, ["half", "rank", "protocol", "model", "sets", "mean", "max", "min", "mean %",
                 "max %"])


def choose_defaults(results):
    """The combination with the best mean strict AUC over the tuning half, every rank."""
    tune = [r for r in results if r["half"] == "tune"] or results
    chosen = {}
    for method, params in (("octo", "octo_params"), ("knn", "knn_params"),
                           ("hist", "knn_params")):
        mean = np.mean([r["ranks"][rank][method]["strict"] for r in tune for rank in RANKS
                        if method in r["ranks"][rank]], axis=0)
        i = int(np.argmax(mean))
        chosen[method] = (i, tune[0][params][i], float(mean[i]))
    return chosen


def defaults_table(results, chosen):
    print("== 5. Defaults chosen on the tuning half (best mean strict AUC), reported on the "
          "test half ==")
    for method, (_, p, m) in chosen.items():
        print(f"{method:5s} {p}  (tuning mean strict AUC {m:.4f})")
    rows = []
    for rank in RANKS:
        for protocol in ("strict", "authors"):
            test = [r for r in results if r["half"] == "test"]
            if not test:
                continue
            cells = [rank, protocol]
            for method in ("octo", "knn", "hist"):
                if method not in test[0]["ranks"][rank]:
                    cells += ["", ""]
                    continue
                i = chosen[method][0]
                cells += [f"{np.mean([r['ranks'][rank][method][protocol][i] for r in test]):.4f}",
                          f"{np.mean([best(r['ranks'][rank], method, protocol) for r in test]):.4f}"]
            rows.append(cells)
    if not rows:
        print("(no test data set measured)\n")
        return
    table(rows, ["rank", "protocol", "OctoMap default", "OctoMap best", "k-NN default",
                 "k-NN best", f"h={HISTORY} default", f"h={HISTORY} best"])


def times_table(results):
    print("== 6. Seconds per data set (render: 80 keyframes with true depth; rank: the "
          "sample of SGBM sets on the ranking keyframes; per rank: match, replay, searches) ==")
    rows = []
    for r in results:
        t = r["times"]
        e = [r["ranks"][rank]["times"] for rank in RANKS]
        rows.append([r["name"], f"{t['render']:.1f}", f"{t['rank']:.1f}",
                     f"{np.mean([x['match'] for x in e]):.1f}",
                     f"{np.mean([x['replay'] for x in e]):.1f}",
                     f"{np.mean([x['octo'] for x in e]):.1f}",
                     f"{np.mean([x['knn'] for x in e]):.1f}",
                     f"{e[-1]['history']:.1f}"])
    table(rows, ["data set", "render", "rank", "match", "replay+labels", "OctoMap search",
                 "k-NN search", f"h={HISTORY} replay+search"])


def targets_table(results):
    print("== 7. Targets (test half) ==")
    test = [r for r in results if r["half"] == "test"] or results
    rows = []

    def mark(ok):
        return "met" if ok else "MISSED"

    for protocol in ("authors", "strict"):
        g = gains(test, "last", protocol, "knn")[:, 0]
        worst = min(gains(test, rank, protocol, "knn")[:, 0].min() for rank in RANKS)
        rows.append([f"{protocol}: k-NN best - OctoMap best, mean over last-ranked sets "
                     ">= +0.03", f"{g.mean():+.4f}",
                     mark(g.mean() >= 0.03) if protocol == "authors" else "reported"])
        rows.append([f"{protocol}: never below OctoMap's best by more than 0.01",
                     f"{worst:+.4f}", mark(worst >= -0.01) if protocol == "authors"
                     else "reported"])
    h = gains(test, "last", "strict", "hist")[:, 0]
    rows.append([f"strict: k-NN h={HISTORY} best - OctoMap best, mean over last-ranked "
                 ">= +0.02", f"{h.mean():+.4f}", mark(h.mean() >= 0.02)])
    table(rows, ["target", "measured", "result"])


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help="4 data sets, 12 ranked sets, 24 keyframes")
    parser.add_argument("--n-jobs", type=int, default=None,
                        help="workers (joblib processes; default: 1)")
    parser.add_argument("--json", default=None, help="keep the results in this file")
    parser.add_argument("--resume", action="store_true",
                        help="skip the data sets already in --json")
    parser.add_argument("--tables-only", action="store_true",
                        help="print the tables of the data sets in --json, measure nothing")
    args = parser.parse_args()
    t_start = time.perf_counter()
    rig = StereoRig()
    sets = rendered_stereo_datasets()
    if args.quick:
        sets = [d for d in sets if d.name in QUICK_SETS]
    # the tuning half first: the defaults only need it
    sets.sort(key=lambda d: d.half != "tune")
    results = []
    if (args.resume or args.tables_only) and args.json and os.path.exists(args.json):
        with open(args.json) as f:
            results = json.load(f)
    done = {r["name"] for r in results}
    if args.tables_only:
        sets = []
    for i, d in enumerate(sets):
        if d.name in done:
            continue
        r = measure(d, rig, args.quick, args.n_jobs)
        results.append(r)
        if args.json:
            with open(args.json, "w") as f:
                json.dump(results, f)
        e = r["ranks"]
        log(f"[{i + 1}/{len(sets)}] {d.name} ({d.half}): "
            + "; ".join(f"{rank} OctoMap {best(e[rank], 'octo', 'authors'):.3f} k-NN "
                        f"{best(e[rank], 'knn', 'authors') - best(e[rank], 'octo', 'authors'):+.3f}"
                        for rank in RANKS)
            + f"; {time.perf_counter() - t_start:.0f} s")
    order = {d.name: i for i, d in enumerate(rendered_stereo_datasets())}
    results.sort(key=lambda r: order[r["name"]])
    print(f"{len(results)} data sets x {len(RANKS)} StereoSGBM ranks; rig {rig.width} x "
          f"{rig.height}, f = {rig.focal_length} px, baseline {rig.baseline} m; "
          f"{len(results[0]['knn_params'])} k-NN and "
          f"{len(results[0]['octo_params'])} OctoMap parameter combinations, each at the 9 "
          f"thresholds\n")
    error_table(results)
    per_dataset_table(results)
    fig5_table(results)
    summary_table(results)
    defaults_table(results, choose_defaults(results))
    times_table(results)
    targets_table(results)
    print(f"(bench run time {time.perf_counter() - t_start:.0f} s)")


if __name__ == "__main__":
    main()
