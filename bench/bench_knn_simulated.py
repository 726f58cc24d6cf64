"""The k-NN inverse sensor model against OctoMap on the noisy stereo data sets.

Miao, Hunter and Georgilas's comparison, best against best, on occgp's
simulated stereo data sets (``occgp.datasets.stereo_datasets()``: 5 tetromino
layouts x plain / textured boxes x buildings / open lot, at camera depth noise
0.005, 0.01 and 0.02 m at 1 m; the default 320 x 180 camera, 2 orbits of 40
frames, clouds voxel-filtered at 0.1 m). Every map is a 0.1 m octree with a
4 m sensor range. Tables (all measured in this run, side by side):

1. Per data set: OctoMap's best TPR-FDR AUC after its grid search
   (``OCTOMAP_GRID``, 180 combinations with the 9 thresholds) against the k-NN
   method's best after its grid search (``KNN_GRID``, 4,050), both replayed
   from one ``ScanReplay(scans, ks=(1,))`` and scored against
   ``cell_labels`` of the scene; the improvement, the best parameters of each,
   the seconds of each search, of the replay's set-up and of the k-NN search
   with its set-up.
2. The improvement per noise level.
3. The paper's Fig. 5 as a table: the improvement against OctoMap's best AUC,
   sorted by it, and its mean per tercile of OctoMap's AUC.
4. NCA parameter weights (the paper's section 3.5): on the I / textured /
   buildings data set at each noise level, random operating points of
   ``KNN_WEIGHT_GRID`` (k in 1, 3, 5, 7; the clamping varied too) with their
   thresholds; the normalised weight of each of the 8 parameters for TPR and
   for FDR (``nca_feature_weights``; the paper: k < 0.1).
5. Insert time per scan, ``KNNMap`` against ``OccupancyOctree`` (``max_range
   = 4``), on the same scans, interleaved repeats; the median ratio.
6. The run-time models of section 3.6 fitted by least squares over map builds
   from prefixes of the scans: OctoMap ``t = a N + b``, k-NN ``t = (a k + b) N
   + c`` (N: points inserted).
7. The issue's targets, met or missed, as measured above.

Run: ``python bench/bench_knn.py`` (about 15 minutes on 2 cores);
``--quick`` (6 data sets, NCA on one with 2,000 samples, one repeat set:
under 3 minutes) for a smoke run; ``--plot fig5.png`` also draws table 3.
"""

from __future__ import annotations

import argparse
import itertools
import math
import sys
import time

import numpy as np

from occgp import KNNMap, OccupancyOctree
from occgp.datasets import stereo_datasets
from occgp.evaluation import (KNN_GRID, KNN_WEIGHT_GRID, OCTOMAP_GRID, THRESHOLDS, cell_labels,
                              grid_search, nca_feature_weights)
from occgp.knn import ScanReplay, check_knn_params

from bench_gp import table  # the GP bench's (same folder)

RESOLUTION = 0.1
SENSOR_RANGE = 4.0
NCA_FEATURES = ("k", "p_u", "p_l", "p_m", "p_m_out", "p_min", "p_max", "occupancy_threshold")
NCA_KS = (1, 3, 5, 7)
#: The data sets of the quick run (2 per noise level) and of tables 4-6.
QUICK_SETS = ("I_textured_buildings", "S_plain_open")
DETAIL_SETS = ("I_textured_buildings",)


def log(msg):
    print(msg, file=sys.stderr, flush=True)


def base_name(d):
    return d.name.rsplit("_noise", 1)[0]


# ---------------------------------------------------------------- 1-3: best against best
def compare(d, n_jobs):
    """One data set: simulate, replay, label, both searches."""
    t0 = time.perf_counter()
    scans = d.scans()
    t_sim = time.perf_counter() - t0
    t0 = time.perf_counter()
    replay = ScanReplay(scans, RESOLUTION, max_range=SENSOR_RANGE, ks=(1,))
    t_replay = time.perf_counter() - t0
    t0 = time.perf_counter()
    labels = cell_labels(d.scene(), replay.centers, RESOLUTION)
    t_labels = time.perf_counter() - t0
    octo = grid_search(replay, labels, OCTOMAP_GRID, method="octomap", n_jobs=n_jobs)
    knn = grid_search(replay, labels, KNN_GRID, method="knn", n_jobs=n_jobs)
    row = dict(name=d.name, noise=d.depth_noise, scans=len(scans), points=replay.n_points,
               near=replay.n_near, cells=replay.num_cells, occupied=int(labels.sum()),
               octo_auc=octo.best_score, knn_auc=knn.best_score,
               gain=knn.best_score - octo.best_score, octo_params=octo.best_params,
               knn_params=knn.best_params, octo_s=octo.seconds, knn_s=knn.seconds,
               replay_s=t_replay, labels_s=t_labels, sim_s=t_sim,
               octo_maps=len(octo.results), knn_maps=len(knn.results))
    return row, scans, labels


def fmt_octo(p):
    return f"hit {p['prob_hit']:.2f} miss {p['prob_miss']:.2f}"


def fmt_knn(p):
    return f"u {p['p_u']:.2f} l {p['p_l']:.2f} m {p['p_m']:.2f} m_out {p['p_m_out']:.2f}"


def per_dataset_table(rows):
    r0 = rows[0]
    print(f"== 1. Best against best per data set ({len(rows)} data sets): OctoMap "
          f"{r0['octo_maps']} maps x {len(THRESHOLDS)} thresholds = "
          f"{r0['octo_maps'] * len(THRESHOLDS)} combinations, k-NN (k = 1) {r0['knn_maps']} "
          f"maps x {len(THRESHOLDS)} = {r0['knn_maps'] * len(THRESHOLDS)}; AUC of the TPR-FDR "
          f"curve against exact ground truth of the cells the scans reach; seconds on "
          f"1 process ==")
    table([[r["name"], f"{r['noise']:g}", r["points"], r["cells"], f"{r['octo_auc']:.4f}",
            f"{r['knn_auc']:.4f}", f"{r['gain']:+.4f}", fmt_octo(r["octo_params"]),
            fmt_knn(r["knn_params"]), f"{r['octo_s']:.2f}", f"{r['replay_s']:.2f}",
            f"{r['knn_s']:.2f}", f"{r['replay_s'] + r['knn_s']:.2f}"] for r in rows],
          ["data set", "noise", "points", "cells", "OctoMap AUC", "k-NN AUC", "improvement",
           "OctoMap best", "k-NN best", "OctoMap search [s]", "replay set-up [s]",
           "k-NN search [s]", "k-NN total [s]"])
    sim = sum(r["sim_s"] for r in rows)
    lab = sum(r["labels_s"] for r in rows)
    print(f"(not in the searches: simulating the scans took {sim:.1f} s in all, "
          f"{sim / len(rows):.1f} s a data set; labelling the cells {lab:.1f} s, "
          f"{lab / len(rows):.2f} s a data set)\n")


def noise_table(rows):
    print("== 2. Improvement (k-NN best AUC - OctoMap best AUC) per noise level ==")
    out = []
    for noise in sorted({r["noise"] for r in rows}):
        g = np.array([r["gain"] for r in rows if r["noise"] == noise])
        o = np.array([r["octo_auc"] for r in rows if r["noise"] == noise])
        k = np.array([r["knn_auc"] for r in rows if r["noise"] == noise])
        out.append([f"{noise:g}", len(g), f"{o.mean():.4f}", f"{k.mean():.4f}",
                    f"{g.mean():+.4f}", f"{g.min():+.4f}", f"{g.max():+.4f}",
                    int((g > 1e-9).sum()), int((np.abs(g) <= 1e-9).sum()),
                    int((g < -1e-9).sum())])
    table(out, ["noise", "data sets", "mean OctoMap AUC", "mean k-NN AUC", "mean improvement",
                "min", "max", "k-NN better", "equal", "k-NN worse"])


def fig5_table(rows, plot):
    rows = sorted(rows, key=lambda r: r["octo_auc"])
    print("== 3. The paper's Fig. 5: improvement against OctoMap's best AUC, sorted by "
          "OctoMap's AUC ==")
    table([[i + 1, r["name"], f"{r['octo_auc']:.4f}", f"{r['knn_auc']:.4f}",
            f"{r['gain']:+.4f}"] for i, r in enumerate(rows)],
          ["rank", "data set", "OctoMap AUC", "k-NN AUC", "improvement"])
    print("Terciles of OctoMap's best AUC:")
    out = []
    for t, part in enumerate(np.array_split(np.arange(len(rows)), 3)):
        if not len(part):
            continue
        sub = [rows[i] for i in part]
        g = np.array([r["gain"] for r in sub])
        noises = sorted({r["noise"] for r in rows})
        counts = " / ".join(str(sum(r["noise"] == n for r in sub)) for n in noises)
        out.append([("lowest", "middle", "highest")[t], len(sub),
                    f"{sub[0]['octo_auc']:.4f} - {sub[-1]['octo_auc']:.4f}",
                    f"{g.mean():+.4f}", f"{g.min():+.4f}", f"{g.max():+.4f}", counts])
    table(out, ["tercile", "data sets", "OctoMap AUC", "mean improvement", "min", "max",
                "at noise " + " / ".join(f"{n:g}" for n in sorted({r['noise'] for r in rows}))])
    if plot:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(figsize=(6, 4), layout="constrained")
        for noise in sorted({r["noise"] for r in rows}):
            sub = [r for r in rows if r["noise"] == noise]
            ax.scatter([r["octo_auc"] for r in sub], [r["gain"] for r in sub], s=18,
                       label=f"depth noise {noise:g}")
        ax.axhline(0, color="k", lw=0.8)
        ax.set_xlabel("OctoMap's best TPR-FDR AUC")
        ax.set_ylabel("k-NN best AUC - OctoMap best AUC")
        ax.legend()
        fig.savefig(plot, dpi=120)
        print(f"(Fig. 5 drawn to {plot})\n")


# ---------------------------------------------------------------- 4: NCA weights
def weight_grid_points():
    """Every valid combination of KNN_WEIGHT_GRID and its number of thresholds."""
    keys = list(KNN_WEIGHT_GRID)
    combos, n_thr = [], []
    for values in itertools.product(*(KNN_WEIGHT_GRID[k] for k in keys)):
        c = dict(zip(keys, values))
        try:
            check_knn_params({**c, "occupancy_threshold": c["p_min"], "max_range": SENSOR_RANGE})
        except ValueError:
            continue
        combos.append(c)
        n_thr.append(sum(c["p_min"] - 1e-12 <= t <= c["p_max"] + 1e-12 for t in THRESHOLDS))
    return combos, np.array(n_thr)


def nca_table(details, n_samples, n_jobs, seed=0):
    combos, n_thr = weight_grid_points()
    total = int(n_thr.sum())
    rng = np.random.default_rng(seed)
    # sample the maps first, then the operating points among theirs (thresholds that
    # leave no cell occupied give none: top up with more maps until there are enough)
    n_first = min(len(combos), math.ceil(1.25 * n_samples / n_thr.mean()))
    out, notes = [], []
    for name, (scans, labels) in details.items():
        t0 = time.perf_counter()
        replay = ScanReplay(scans, RESOLUTION, max_range=SENSOR_RANGE, ks=NCA_KS)
        t_replay = time.perf_counter() - t0
        assert replay.num_cells == len(labels)
        order = rng.permutation(len(combos))
        points, n_maps, t_search = [], 0, 0.0
        while len(points) < n_samples and n_maps < len(combos):
            step = n_first if n_maps == 0 else max(
                1, math.ceil(1.25 * (n_samples - len(points)) / n_thr.mean()))
            pick = np.sort(order[n_maps:n_maps + step])
            res = grid_search(replay, labels, [combos[i] for i in pick], method="knn",
                              n_jobs=n_jobs)
            points += res.operating_points()
            n_maps += len(pick)
            t_search += res.seconds
        take = rng.choice(len(points), min(n_samples, len(points)), replace=False)
        X = np.array([[points[i][f] for f in NCA_FEATURES] for i in take], dtype=np.float64)
        for metric in ("tpr", "fdr"):
            y = np.array([points[i][metric] for i in take])
            t0 = time.perf_counter()
            w = nca_feature_weights(X, y)
            t_nca = time.perf_counter() - t0
            share = float(w.weights[0] / w.weights.sum()) if w.weights.sum() > 0 else 0.0
            out.append([name, metric.upper(), *(f"{v:.3f}" for v in w.normalized),
                        f"{share:.3f}", "yes" if w.normalized[0] < 0.1 else "no",
                        "yes" if share < 0.1 else "no", len(take), w.n_iter,
                        "yes" if w.converged else "no", f"{t_nca:.1f}"])
        notes.append(f"{name}: replay (ks = {NCA_KS}) {t_replay:.1f} s, {n_maps} maps drawn "
                     f"and searched in {t_search:.1f} s giving {len(points)} operating points, "
                     f"{len(take)} of them drawn")
    print(f"== 4. NCA parameter weights (Yang et al.'s NCA-FS, regression, standardised, "
          f"lambda = 1/n): {n_samples} random operating points of KNN_WEIGHT_GRID per data "
          f"set ({len(combos)} valid maps x their thresholds = {total} in all; maps drawn first, "
          f"seeded, then the points among theirs); weights normalised to a maximum of 1, and k's "
          f"share of their sum ==")
    table(out, ["data set", "response", *NCA_FEATURES, "k / sum", "k < 0.1 (max 1)",
                "k < 0.1 (sum 1)", "samples", "iterations",
                "converged", "NCA [s]"])
    for n in notes:
        print(f"  {n}")
    print()
    return out


# ---------------------------------------------------------------- 5: insert time
def insert_table(details, repeats):
    out, ratios = [], []
    for name, (scans, _) in details.items():
        t_oct = np.zeros((repeats, len(scans)))
        t_knn = np.zeros((repeats, len(scans)))
        t_query = np.zeros((repeats, len(scans)))
        for rep in range(repeats):
            octree = OccupancyOctree(RESOLUTION)
            knn = KNNMap(RESOLUTION, max_range=SENSOR_RANGE)
            for i, (points, origin) in enumerate(scans):
                order = (0, 1) if (i + rep) % 2 == 0 else (1, 0)
                for which in order:
                    t0 = time.perf_counter()
                    if which == 0:
                        octree.insert_scan(points, origin, max_range=SENSOR_RANGE)
                        t_oct[rep, i] = time.perf_counter() - t0
                    else:
                        knn.insert_scan(points, origin)
                        t_knn[rep, i] = time.perf_counter() - t0
                        t_query[rep, i] = knn.last_insert_["knn_seconds"]
        ratio = float(np.median(t_knn.sum(axis=1) / t_oct.sum(axis=1)))
        ratios.append(ratio)
        n = len(scans)
        out.append([name, n, int(np.mean([len(s.points) for s in scans])),
                    f"{1e3 * np.median(t_oct.sum(axis=1)) / n:.2f}",
                    f"{1e3 * np.median(t_knn.sum(axis=1)) / n:.2f}",
                    f"{1e3 * np.median(t_query.sum(axis=1)) / n:.2f}",
                    f"{float(np.median(t_knn / t_oct)):.2f}", f"{ratio:.2f}"])
    print(f"== 5. Insert time per scan: KNNMap (k = 1) against OccupancyOctree (max_range "
          f"= {SENSOR_RANGE:g}, method auto), the same scans, {repeats} interleaved repeats "
          f"(medians) ==")
    table(out, ["data set", "scans", "points / scan", "OccupancyOctree [ms]", "KNNMap [ms]",
                "of which k-NN scores [ms]", "median per-scan ratio", "ratio (totals)"])
    return max(ratios)


# ---------------------------------------------------------------- 6: run-time models
def build_seconds(make, scans, **kwargs):
    t0 = time.perf_counter()
    tree = make()
    for points, origin in scans:
        tree.insert_scan(points, origin, **kwargs)
    return time.perf_counter() - t0


def runtime_table(details, prefixes, repeats):
    data = []          # (name, m, N, t_octomap, {k: t_knn}), each the fastest of the repeats
    for name, (scans, _) in details.items():
        for m in prefixes:
            part = scans[:m]
            N = sum(len(s.points) for s in part)
            t_oct, t_knn = math.inf, dict.fromkeys(NCA_KS, math.inf)
            for _ in range(repeats):
                t_oct = min(t_oct, build_seconds(lambda: OccupancyOctree(RESOLUTION), part,
                                                 max_range=SENSOR_RANGE))
                for k in NCA_KS:
                    t_knn[k] = min(t_knn[k], build_seconds(
                        lambda: KNNMap(RESOLUTION, k=k, max_range=SENSOR_RANGE), part))
            data.append((name, m, N, t_oct, t_knn))
    print(f"== 6. Run-time models (the paper's section 3.6): map builds from the first m "
          f"scans of each data set; N = points inserted; each time the fastest of "
          f"{repeats} build(s) ==")
    table([[name, m, N, f"{t:.3f}", *(f"{tk[k]:.3f}" for k in NCA_KS)]
           for name, m, N, t, tk in data],
          ["data set", "scans m", "N", "OctoMap [s]", *(f"k-NN k={k} [s]" for k in NCA_KS)])
    N = np.array([d[2] for d in data], dtype=np.float64)
    t = np.array([d[3] for d in data])
    A = np.column_stack([N, np.ones_like(N)])
    coef_o, r2_o = fit(A, t)
    kk = np.repeat([NCA_KS], len(data), axis=0).ravel().astype(np.float64)
    NN = np.repeat(N, len(NCA_KS))
    tk = np.array([[d[4][k] for k in NCA_KS] for d in data]).ravel()
    coef_k, r2_k = fit(np.column_stack([kk * NN, NN, np.ones_like(NN)]), tk)
    table([["OctoMap", "t = a N + b", f"{coef_o[0]:.4e}", f"{coef_o[1]:.4e}", "", len(t),
            f"{r2_o:.4f}"],
           ["k-NN", "t = (a k + b) N + c", f"{coef_k[0]:.4e}", f"{coef_k[1]:.4e}",
            f"{coef_k[2]:.4e}", len(tk), f"{r2_k:.4f}"]],
          ["method", "model", "a", "b", "c", "builds", "R^2"])


def fit(A, t):
    coef, *_ = np.linalg.lstsq(A, t, rcond=None)
    resid = t - A @ coef
    r2 = 1.0 - float(resid @ resid) / float(((t - t.mean()) ** 2).sum())
    return coef, r2


# ---------------------------------------------------------------- 7: targets
def targets_table(rows, insert_ratio, quick):
    noisy = [r for r in rows if r["noise"] == max(r["noise"] for r in rows)]
    clean = [r for r in rows if r["noise"] == min(r["noise"] for r in rows)]
    gain_noisy = float(np.mean([r["gain"] for r in noisy]))
    worst = min(clean, key=lambda r: r["gain"])
    slowest = max(rows, key=lambda r: r["replay_s"] + r["knn_s"])
    t_max = slowest["replay_s"] + slowest["knn_s"]
    mark = lambda ok: "met" if ok else "missed"  # noqa: E731
    n_all = len(rows)
    print(f"== 7. The issue's targets, as measured above"
          f"{' (quick run: a subset of the data sets, not the targets proper)' if quick else ''}"
          f" ==")
    table([[f"noisiest third (noise {noisy[0]['noise']:g}): mean improvement >= +0.03",
            f"{gain_noisy:+.4f} over {len(noisy)} data sets", mark(gain_noisy >= 0.03)],
           [f"cleanest third (noise {clean[0]['noise']:g}): every improvement >= -0.01",
            f"worst {worst['gain']:+.4f} ({worst['name']})", mark(worst["gain"] >= -0.01)],
           ["4,050-combination search <= 60 s per data set (replay set-up + search)",
            f"max {t_max:.2f} s ({slowest['name']}) over {n_all}", mark(t_max <= 60.0)],
           ["KNNMap insert <= 2x OccupancyOctree's (worst data set's median ratio)",
            f"{insert_ratio:.2f}", mark(insert_ratio <= 2.0)]],
          ["target", "measured", "result"])


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help="6 data sets, NCA on one with 2,000 samples, fewer repeats")
    parser.add_argument("--n-jobs", type=int, default=None,
                        help="grid-search workers (joblib; default: 1 process)")
    parser.add_argument("--nca-samples", type=int, default=None,
                        help="operating points per NCA fit (default 5,625; quick 2,000)")
    parser.add_argument("--plot", default=None, help="draw table 3 (Fig. 5) to this PNG")
    args = parser.parse_args()
    t_start = time.perf_counter()
    sets = stereo_datasets()
    noisiest = max(d.depth_noise for d in sets)
    if args.quick:
        sets = [d for d in sets if base_name(d) in QUICK_SETS]
        detail = {d.name for d in sets if base_name(d) in DETAIL_SETS
                  and d.depth_noise == noisiest}
    else:
        detail = {d.name for d in sets if base_name(d) in DETAIL_SETS}
    n_samples = args.nca_samples or (2000 if args.quick else 5625)
    rows, details = [], {}
    for i, d in enumerate(sets):
        row, scans, labels = compare(d, args.n_jobs)
        rows.append(row)
        if d.name in detail:
            details[d.name] = (scans, labels)
        log(f"[{i + 1}/{len(sets)}] {d.name}: OctoMap {row['octo_auc']:.4f}, k-NN "
            f"{row['knn_auc']:.4f} ({row['gain']:+.4f}); {time.perf_counter() - t_start:.0f} s")
    per_dataset_table(rows)
    noise_table(rows)
    fig5_table(rows, args.plot)
    log("NCA weights ...")
    nca_table(details, n_samples, args.n_jobs)
    log("insert times ...")
    insert_ratio = insert_table(details, 2 if args.quick else 3)
    log("run-time models ...")
    runtime_table(details, (10, 20, 40, 80), 1 if args.quick else 2)
    targets_table(rows, insert_ratio, args.quick)
    print(f"(bench run time {time.perf_counter() - t_start:.0f} s)")


if __name__ == "__main__":
    main()
