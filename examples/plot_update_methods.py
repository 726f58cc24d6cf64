"""
===================================================
Faster scan insertion with an identical map
===================================================

Simulate a dense laser scanner moving through the synthetic structured room,
insert the scans with each update method of :meth:`occgp.OccupancyOctree.insert_scan`
and compare scans per second. The culling region (Kwon's dissertation, ch. 2)
skips the cells that are already fully free; every method gives the same map,
bit for bit, which we check.
"""

# Author: the occgp developers
# License: BSD 3 clause

# %%
# A dense trajectory
# ------------------
import time

import matplotlib.pyplot as plt
import numpy as np

from occgp import OccupancyOctree
from occgp.datasets import LidarSensor, free_path, simulate_scans, structured_room

room = structured_room()
poses = free_path(room, 6, step=0.8, seed=0)
sensor = LidarSensor(n_horizontal=360, n_vertical=60, max_range=12.0)
scans = simulate_scans(room, poses, sensor, progress=False)
print(f"{len(scans)} scans of about {len(scans[0].points):,} points")

# %%
# Insert with every method
# ------------------------
methods = [("scan", "plain"), ("scan", "culling"), ("ray", "plain"), ("ray", "culling")]
resolutions = [0.1, 0.2, 0.4]
fps = {m: [] for m in methods}
for res in resolutions:
    maps = {}
    for mode, method in methods:
        tree = OccupancyOctree(res)
        t0 = time.perf_counter()
        for points, origin in scans:
            tree.insert_scan(points, origin, mode=mode, method=method)
        fps[mode, method].append(len(scans) / (time.perf_counter() - t0))
        maps[mode, method] = tree.leaves()
    for mode in ("scan", "ray"):
        a, b = maps[mode, "plain"], maps[mode, "culling"]
        assert np.array_equal(np.sort(a.log_odds), np.sort(b.log_odds))   # same map

# %%
# Scans per second
# ----------------
# Timings of a documentation build are noisy; ``bench/bench_updates.py``
# measures the methods against liboctomap itself.
fig, ax = plt.subplots(figsize=(7, 3.5), layout="constrained")
width = 0.2
x = np.arange(len(resolutions))
for i, m in enumerate(methods):
    ax.bar(x + (i - 1.5) * width, fps[m], width, label=f"mode={m[0]}, {m[1]}")
ax.set_xticks(x, [f"{r} m" for r in resolutions])
ax.set_ylabel("scans per second")
ax.legend(ncols=2, fontsize="small")
plt.show()
