"""
=======================================================================
Where learning helps interpolation: the candidate selector at the edges
=======================================================================

Interpolating the *inverse* range between the 4 neighbouring beams is exact
to first order on any plane, so on roads and walls, which are most of a
street scan. Where it fails is at depth edges: between a car and the wall
behind it, it puts a point in mid-air, on neither. The candidate selector
shipped with :mod:`occgp.iln` (:class:`occgp.iln.CandidateSelector`,
:func:`occgp.iln.pretrained`) keeps that prior and learns only where to
leave it: for each new beam a small network reads the 4 x 4 measured pixels
around it and picks one of ten analytic candidates -- inverse bilinear,
a copy of the row above or below or the column to the left or right, the
planar extension of ``1 / r`` from the two rows above or below (or columns
to either side), or no return -- switching away from the prior only where it
is confident.

This example up-samples a 16-beam scan of a held-out street scene, simulated
with sensor noise, dropouts and vegetation, shows which candidate each pixel
took, and scores the planar pixels and the depth edges apart. The last cell
scores the same models on two real LiDAR frames when they are present.
"""

# Author: the occgp developers
# License: BSD 3 clause

# %%
# A noisy 16-beam scan
# --------------------
# The scene is a held-out one (no model was trained on it), with vegetation
# clutter; :func:`occgp.iln.apply_sensor_effects` adds 2 cm range noise and
# the dropouts of a real sensor (grazing incidence, dark surfaces by the
# reflectivity of the solid hit, far range) to each image independently, as
# ``occgp iln make-dataset --effects --vegetation`` does for training data.
import matplotlib.pyplot as plt
import numpy as np

import occgp.iln
from occgp.datasets import outdoor_scene
from occgp.iln import (
    CANDIDATES, LidarModel, SensorEffects, apply_sensor_effects, choose_candidates, evaluate,
    format_region_table, format_table, image_queries, simulate_range_image, solid_reflectivity,
)
from occgp.iln.data import TEST_SEED_OFFSET

scene = outdoor_scene(TEST_SEED_OFFSET + 3, vegetation=True)
pose = scene.trajectory(3, margin=25.0)[1]
sparse = LidarModel.carla(16, 1024)
dense = sparse.with_size(64, 1024)
rng = np.random.default_rng(0)
albedo = np.append(solid_reflectivity(scene.labels), 0.0)  # index -1: no solid hit
images = {}
for lidar in (sparse, dense):
    clean, ids = simulate_range_image(scene, pose, lidar, return_ids=True)
    noisy = apply_sensor_effects(clean, lidar, SensorEffects(), rng, reflectivity=albedo[ids])
    images[lidar.shape] = noisy[None]

# %%
# Scores, and scores by region
# ----------------------------
# :func:`occgp.iln.evaluate` up-samples the scan with each model and scores
# it against the true 64-beam scan; with ``regions=True`` it also splits the
# pixels into *planar* ones (inverse bilinear within 0.5 m of the truth),
# *depth edges* (off by more) and *no-return boundaries* (the pixel or one
# of its 4 input neighbours has no return). The prior and the selector err
# alike on the planes, where the selector leaves the prior alone; the gain
# is on the edges.
selector = occgp.iln.pretrained()
models = {"inverse bilinear": "inverse-bilinear", "edge-aware": "edge-aware",
          "selector": selector}
rows = evaluate(models, images, out_sizes=[(64, 1024)], regions=True, progress=False)
print(format_table(rows))
print(format_region_table(rows))

# %%
# Which candidate each pixel took
# -------------------------------
# :meth:`~occgp.iln.CandidateSelector.candidate_table` gives every
# candidate's range and probability (at the queries of
# :func:`~occgp.iln.image_queries`: the 64-beam pixel centers in the 16-beam
# image); :func:`~occgp.iln.choose_candidates` applies the shipped model's two thresholds (chosen on held-out training
# scenes). A sector ahead of the sensor: the true scan, then the choice per
# pixel -- grey where the prior stays, colours where a copy, an extension or
# a no-return replaced it. The replacements line the outlines of cars,
# trunks, poles and building corners.
queries, inside, wrap = image_queries(sparse, dense)
ranges, probs = selector.candidate_table(images[sparse.shape][0], queries, wrap=wrap)
choice = np.full(dense.rows * dense.cols, -1)
choice[inside] = choose_candidates(probs, selector.threshold, selector.no_return_threshold)
choice = choice.reshape(dense.shape)
share = {name: float(np.mean(choice == k)) for k, name in enumerate(CANDIDATES)}
print("share of the pixels: " + ", ".join(f"{k} {v:.1%}" for k, v in share.items() if v > 0))

sector = slice(384, 640)
fig, axes = plt.subplots(2, 1, figsize=(8, 4.5), constrained_layout=True)
cmap = plt.get_cmap("viridis_r").with_extremes(bad="black")
axes[0].imshow(np.ma.masked_equal(images[dense.shape][0][:, sector], 0.0), cmap=cmap, vmin=0,
               vmax=40, aspect="auto", interpolation="nearest")
axes[0].set_title("true 64 x 1024 scan (nearest in yellow, black: no return)", fontsize=9)
colours = plt.get_cmap("tab10")(np.arange(len(CANDIDATES)))
colours[0] = (0.85, 0.85, 0.85, 1.0)
shown = colours[np.maximum(choice[:, sector], 0)]
axes[1].imshow(shown, aspect="auto", interpolation="nearest")
axes[1].set_title("the selector's choice (grey: inverse bilinear kept)", fontsize=9)
handles = [plt.Rectangle((0, 0), 1, 1, color=colours[k]) for k, name in enumerate(CANDIDATES)
           if share[name] > 0]
axes[1].legend(handles, [name for name in CANDIDATES if share[name] > 0], fontsize=7,
               ncol=5, loc="upper center", bbox_to_anchor=(0.5, -0.02))
for ax in axes:
    ax.set_xticks([])
    ax.set_yticks([])

# %%
# Real frames
# -----------
# The same models on real scans: a KITTI HDL-64E frame (front half) and an
# Ouster OS1-64 frame (off-road), each read one row per beam on its measured
# elevation table; every 4th beam is kept and the 48 others predicted at
# their true elevations (:func:`occgp.iln.real_frame_scores`). The frames
# live in the project's shared data folder and are not installed with the
# package; without them this cell says so.
from pathlib import Path

from occgp.iln import format_real_table, read_lidar_frame, real_frame_scores

folder = Path.cwd()
for parent in (folder, *folder.parents):
    if (parent / "shared" / "data" / "lidar_frames").is_dir():
        folder = parent / "shared" / "data" / "lidar_frames"
        break
frames = (("KITTI HDL-64E", "kitti_hdl64e_front.bin", "hdl64e"),
          ("Ouster OS1-64", "os1_64_full.bin", "os1-64"))
for title, name, sensor in frames:
    if not (folder / name).is_file():
        print(f"{title}: {name} not found beside the project; skipped")
        continue
    image, lidar = read_lidar_frame(folder / name, sensor, cols=2048)
    rows = real_frame_scores({"bilinear": "bilinear", **models}, image, lidar, keep_every=4)
    print(f"{title}:\n{format_real_table(rows)}")
plt.show()
