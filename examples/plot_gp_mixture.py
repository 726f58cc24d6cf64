"""
===================================================
A mixture of Gaussian-process experts on a 2D room
===================================================

One GP over every observation costs ``O(n^3)``. Kim & Kim split the
observations into clusters, fit one GP expert per cluster and merge the
experts' predictions with a committee. :class:`occgp.gp.GPMixture` does this
with occgp's own :class:`~occgp.gp.GPOMIK` as the experts: hits are clustered
by line tracking (walls become lines, merged across scans) or by a Dirichlet
process, beams follow their hit (or, without a return, the most similar
returning beam under the line integral kernel), and the merged latent mean
and variance become probabilities through PLSC. This example colours the
clusters, draws the merged probability and variance beside single GPOMIK's,
and compares ROC curves against the room's exact ground truth.
"""

# Author: the occgp developers
# License: BSD 3 clause

# %%
# Scan the room and fit the maps
# ------------------------------
# The same 26 scans of 17 beams as :ref:`sphx_glr_auto_examples_plot_gp_maps.py`.
# The mixture fits its hyper-parameters and classifier as GPOMIK fits its
# own, on a random subset of the observations (``hyperparameters="global"``,
# the default), then each expert's factor. Single GPOMIK's hyper-parameters are passed as its optimiser
# finds them (see that example) to keep this one fast.
import time

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import LineCollection

from occgp.datasets import room_2d
from occgp.gp import (GPOMIK, GPMixture, SquaredExponential, grid_points,
                      observations_from_scans, predict_grid)
from occgp.metrics import roc_auc, roc_curve

room = room_2d()
hits, starts, ends = observations_from_scans(room.scan())
print(f"{len(hits)} hits, {len(starts)} beams")

maps = {
    "single GPOMIK": GPOMIK(SquaredExponential(1.7, 0.6), noise=1e-4, optimizer=False),
    "mixture, line tracking": GPMixture(clustering="line", combine="gpoe", random_state=0),
    "mixture, Dirichlet process": GPMixture(clustering="dp", combine="gpoe", random_state=0),
}
for name, model in maps.items():
    t0 = time.perf_counter()
    model.fit(hits, starts, ends)
    extra = (f": {model.n_clusters_} clusters, {model.n_experts_} experts"
             if isinstance(model, GPMixture) else "")
    print(f"{name:<27} fitted in {time.perf_counter() - t0:5.2f} s{extra}")

# %%
# The clusters
# ------------
# ``labels_`` gives the expert of every observation: the hits first, then the
# beams. Line tracking follows the walls; the Dirichlet process groups hits
# by their spread in the plane, so one cluster can span two walls.
fig, axes = plt.subplots(1, 2, figsize=(12, 4.8), layout="constrained")
colours = plt.get_cmap("tab20")
for ax, name in zip(axes, ["mixture, line tracking", "mixture, Dirichlet process"]):
    model = maps[name]
    hit_expert, beam_expert = model.labels_[:len(hits)], model.labels_[len(hits):]
    ax.add_collection(LineCollection(np.stack([starts, ends], axis=1),
                                     colors=colours(beam_expert % 20), linewidths=0.5,
                                     alpha=0.35))
    ax.scatter(hits[:, 0], hits[:, 1], c=colours(hit_expert % 20), s=9)
    ax.set_xlim(room.bounds[0][0], room.bounds[1][0])
    ax.set_ylim(room.bounds[0][1], room.bounds[1][1])
    ax.set_aspect("equal")
    ax.set_title(f"{name}: {model.n_experts_} experts")
plt.show()

# %%
# Merged probability and variance
# -------------------------------
# Each expert is evaluated only where it can differ from its prior by more
# than ``prior_tol`` (a bound from the distance to its observations); the
# generalised product of experts (``combine="gpoe"``) weights them by how
# much each one reduces its uncertainty, so far from all data the merged
# map returns to the prior, as single GPOMIK does.
lo, hi = room.bounds
resolution = 0.1
extent = (lo[0], hi[0], lo[1], hi[1])
fig, axes = plt.subplots(2, 2, figsize=(12, 8.5), layout="constrained")
for row, name in enumerate(["single GPOMIK", "mixture, line tracking"]):
    t0 = time.perf_counter()
    proba = predict_grid(maps[name], lo, hi, resolution)
    var = predict_grid(maps[name], lo, hi, resolution, output="var")
    print(f"{name:<27} grid of {proba.size} cells in {time.perf_counter() - t0:.2f} s")
    im = axes[row, 0].imshow(proba.T, origin="lower", extent=extent, cmap="viridis",
                             vmin=0, vmax=1, interpolation="nearest")
    axes[row, 0].set_title(f"{name}: p(occupied)")
    im_var = axes[row, 1].imshow(var.T, origin="lower", extent=extent, cmap="magma",
                                 interpolation="nearest")
    axes[row, 1].set_title(f"{name}: latent variance")
    fig.colorbar(im_var, ax=axes[row, 1])
fig.colorbar(im, ax=axes[:, 0], label="p(occupied)", shrink=0.6)
plt.show()

# %%
# ROC curves against the ground truth
# -----------------------------------
# Every cell center of the 0.1 m grid is a test point, labelled by the room.
points, _ = grid_points(lo, hi, resolution)
truth = room.occupancy(points)
fig, ax = plt.subplots(figsize=(5.5, 5), layout="constrained")
for name, model in maps.items():
    p = model.predict_proba(points)
    fpr, tpr, _ = roc_curve(truth, p)
    ax.plot(fpr, tpr, label=f"{name} (AUC {roc_auc(truth, p):.3f})")
ax.plot([0, 1], [0, 1], ":", color="grey")
ax.set_xlabel("false-positive rate")
ax.set_ylabel("true-positive rate")
ax.legend(loc="lower right")
plt.show()
