"""
==========================================
Which map on a real log: held-out scans
==========================================

Real logs have no ground truth, but every scan says where space was free (along
its beams) and where it was not (at its hits). :class:`~occgp.evaluation.RealLogBenchmark`
holds out every tenth scan (``i % 10 == 5``), builds each map from the others
and scores it on the held-out hits and on samples along the held-out beams,
half of them within a metre of the surface.

Two logs from ``../shared/data``: the Intel Research Lab's CARMEN 2D laser log
(:func:`occgp.io.read_carmen`; 910 scans of 180 beams, SLAM-corrected
poses) and the ``hku_mb`` Livox LiDAR sequence
(:class:`occgp.io.ScanSequence`: 457 keyframes of about 5,100 points with
FAST-LIO2 poses). The logs are not part of occgp: without them this example
says so and stops. ``bench/bench_real.py`` runs every map on every log; the
"Which map when" page (``docs/which_map.rst``) has its tables.
"""

# Author: the occgp developers
# License: BSD 3 clause

# %%
# Find the logs
# -------------
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from occgp.io import ScanSequence, read_carmen
from occgp.evaluation import RealLogBenchmark

roots = [Path(p) for p in ("../shared/data", "../../shared/data", "../../../shared/data")]
data = next((p for p in roots if (p / "carmen" / "intel-corrected.log.gz").exists()), None)
if data is None:
    print("the shared logs (../shared/data) are missing: nothing to map")

# %%
# The Intel lab: the four 2D maps side by side
# --------------------------------------------
# Every 2D map is fitted once on every training beam. The grid leaves the
# cells no beam crossed unknown and places each hit in its 0.1 m cell; GPOM
# (a local GP per query, its probabilities calibrated on its own training
# points) fills the gaps between beams; GPOMIK (integral kernels, spatial
# cells) and the GP mixture (line-tracked experts merged by a committee) keep
# a budget of the log's 287,400 observations (``max_observations``) and
# calibrate on their own leave-one-out predictions. The pictures sample the
# maps every 0.15 m.
if data is not None:
    log = read_carmen(data / "carmen" / "intel-corrected.log.gz")
    bench = RealLogBenchmark(log)
    rows = [bench.evaluate("log-odds grid, 0.1 m", {"map": "gp-grid", "resolution": 0.1})]
    rows += [bench.evaluate(label, {"map": name, "random_state": 0})
             for label, name in (("GPOM", "gpom"), ("GPOMIK", "gpomik"),
                                 ("GP mixture", "gp-mixture"))]
    for r in rows:
        print(f"{r.method:22s} AUC {r.auc:.3f}  accuracy {r.accuracy:.3f}  Brier "
              f"{r.brier:.3f}  unknown {r.unknown_fraction:.3f}  "
              f"{r.build_seconds + r.query_seconds:.1f} s")

    hits = log.observations(bench.train_indices)[0]
    lo, hi = hits.min(axis=0) - 0.5, hits.max(axis=0) + 0.5
    xs, ys = np.arange(lo[0], hi[0], 0.15), np.arange(lo[1], hi[1], 0.15)
    grid = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    fig, axes = plt.subplots(2, 2, figsize=(10, 9.5), layout="constrained")
    for ax, r in zip(axes.ravel(), rows):
        p = r.map.occupancy(grid).reshape(len(ys), len(xs))
        im = ax.imshow(np.where(np.isnan(p), 0.5, p), origin="lower", cmap="gray_r",
                       extent=(lo[0], hi[0], lo[1], hi[1]), vmin=0, vmax=1)
        ax.set_title(f"{r.method}: AUC {r.auc:.3f}, accuracy {r.accuracy:.3f}", fontsize=10)
    for ax in axes[1]:
        ax.set_xlabel("x [m]")
    for ax in axes[:, 0]:
        ax.set_ylabel("y [m]")
    fig.colorbar(im, ax=axes, label="P(occupied) (unknown: 0.5)", shrink=0.6)
    plt.show()

# %%
# The HKU main building: a height slice of the octree and BGK
# ------------------------------------------------------------
# Every third scan of the sequence at 0.2 m (to keep this example short; the
# bench maps them all), a slice at 1.5 m above the first keyframe. The
# octree knows only the cells its rays crossed; BGK's kernels spread each
# sample over its neighbours and close the gaps between the sparse Livox rays.
hku = None if data is None else data / "lidar_seq" / "hku_mb"
if hku is not None and (hku / "optimized_poses.txt").exists():
    seq = ScanSequence(hku / "Scans", hku / "optimized_poses.txt", progress=False)
    seq = seq.subset(np.arange(0, len(seq), 3))
    bench3 = RealLogBenchmark(seq)
    rows3 = [bench3.evaluate("octree, 0.2 m", {"map": "octree", "resolution": 0.2}),
             bench3.evaluate("BGK, 0.2 m, 60 m range",
                             {"map": "bgk", "resolution": 0.2, "max_range": 60.0})]
    origins = np.array([seq[int(i)].origin for i in bench3.train_indices[::10]])
    lo, hi = origins.min(axis=0) - 25, origins.max(axis=0) + 25
    xs, ys = np.arange(lo[0], hi[0], 0.2), np.arange(lo[1], hi[1], 0.2)
    plane = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    plane = np.column_stack([plane, np.full(len(plane), 1.5)])
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5), layout="constrained")
    for ax, r in zip(axes, rows3):
        p = r.map.occupancy(plane).reshape(len(ys), len(xs))
        shown = np.ma.masked_invalid(p)
        im = ax.imshow(shown, origin="lower", cmap="viridis",
                       extent=(lo[0], hi[0], lo[1], hi[1]), vmin=0, vmax=1)
        ax.plot(origins[:, 0], origins[:, 1], "r.", ms=2)
        ax.set_title(f"{r.method}: AUC {r.auc:.3f}, acc. {r.accuracy:.3f}", fontsize=10)
        ax.set_xlabel("x [m]")
    axes[0].set_ylabel("y [m]")
    fig.colorbar(im, ax=axes, label="P(occupied) (white: unknown)", shrink=0.8)
    plt.show()
