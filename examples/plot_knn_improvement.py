"""
=========================================================
k-NN against OctoMap, best against best, by noise level
=========================================================

Miao, Hunter and Georgilas compare the k-NN inverse sensor model with OctoMap
after tuning both by grid search, and plot the improvement of the k-NN
model's best TPR–FDR AUC over OctoMap's best against OctoMap's AUC (their
Fig. 5). This example draws that figure for a sample of occgp's simulated
stereo data sets: two layouts at each of the three noise levels, with a
smaller camera than the bench's so that it runs in seconds.
``bench/bench_knn_simulated.py`` computes the full figure: all 60 data sets at
the default camera, with the table behind it; ``bench/bench_knn.py`` computes
it on rendered stereo pairs matched by OpenCV's StereoSGBM
(:ref:`sphx_glr_auto_examples_plot_rendered_stereo.py`).
"""

# Author: the occgp developers
# License: BSD 3 clause

# %%
# Both searches on each data set
# ------------------------------
# One :class:`~occgp.knn.ScanReplay` per data set serves both searches: the
# paper's 180 OctoMap combinations (:data:`~occgp.evaluation.OCTOMAP_GRID`)
# and its 4,050 k-NN combinations (:data:`~occgp.evaluation.KNN_GRID`),
# each scored against the cells' exact ground truth.
import matplotlib.pyplot as plt
import numpy as np

from occgp.datasets import StereoCamera, stereo_datasets
from occgp.evaluation import KNN_GRID, OCTOMAP_GRID, cell_labels, grid_search
from occgp.knn import ScanReplay

rows = []
for ds in stereo_datasets():
    if ds.layout not in ("O", "L") or not ds.texture or ds.environment != "open":
        continue
    scans = ds.scans(StereoCamera(160, 90, depth_noise=ds.depth_noise), n_frames=20)
    replay = ScanReplay(scans, 0.1, max_range=4.0)
    labels = cell_labels(ds.scene(), replay.centers, 0.1)
    octomap = grid_search(replay, labels, OCTOMAP_GRID, method="octomap").best_score
    knn = grid_search(replay, labels, KNN_GRID).best_score
    rows.append((ds.name, ds.depth_noise, octomap, knn))
    print(f"{ds.name:<28} OctoMap {octomap:.4f}  k-NN {knn:.4f}  ({knn - octomap:+.4f})")

# %%
# The improvement against OctoMap's AUC
# -------------------------------------
# Each dot is a data set, coloured by its depth noise. As in the paper, the
# gain grows as OctoMap's AUC falls, but here it stays below 0.01 (the paper
# reports up to 0.1): the clouds' errors are mostly Gaussian depth noise,
# which leaves most points near neighbours after the 0.1 m voxel filter, so
# the k-NN score singles out few of them. The user guide discusses the
# bench's numbers.
fig, ax = plt.subplots(figsize=(6, 4), layout="constrained")
noise = np.array([r[1] for r in rows])
octo = np.array([r[2] for r in rows])
gain = np.array([r[3] - r[2] for r in rows])
points = ax.scatter(octo, gain, c=np.log10(noise), cmap="viridis", s=40)
ax.axhline(0.0, color="0.5", lw=0.8)
ax.set_xlabel("OctoMap's best TPR–FDR AUC")
ax.set_ylabel("k-NN best AUC - OctoMap best AUC")
bar = fig.colorbar(points, ax=ax)
bar.set_label("log10 depth noise (m at 1 m)")
plt.show()
