"""
===================================================
Faster scan insertion with an identical map
===================================================

Simulate a dense laser scanner moving through the synthetic structured room,
insert the scans with each update method of :meth:`occgp.OccupancyOctree.insert_scan`
and compare scans per second. Super rays group the rays that traverse the same
cells; the culling region skips the cells that are already fully free (Kwon's
dissertation, ch. 2). Every method gives the same map, bit for bit, which we
check leaf for leaf.
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
methods = ["plain", "culling", "superray", "superray+culling"]
resolutions = [0.1, 0.2, 0.4]
fps = {m: [] for m in methods}


def sorted_leaves(tree):
    leaves = tree.leaves()
    order = np.lexsort((leaves.sizes, *leaves.centers.T))
    return leaves.centers[order], leaves.log_odds[order]


for res in resolutions:
    maps = {}
    for method in methods:
        tree = OccupancyOctree(res)
        t0 = time.perf_counter()
        for points, origin in scans:
            tree.insert_scan(points, origin, method=method)
        fps[method].append(len(scans) / (time.perf_counter() - t0))
        maps[method] = sorted_leaves(tree)
    for method in methods[1:]:                       # the same map, leaf for leaf
        assert all(np.array_equal(a, b) for a, b in zip(maps[method], maps["plain"]))
    print(f"{res} m, last scan: {len(scans[-1].points):,} points, "
          f"{tree.last_insert_['rays']:,} (super) rays traversed")

# %%
# Scans per second
# ----------------
# ``"plain"`` is liboctomap's own ``insertPointCloud``. Timings of a
# documentation build are noisy; ``bench/bench_updates.py`` measures the
# methods against liboctomap itself on a dense trajectory in a real map.
fig, ax = plt.subplots(figsize=(7, 3.5), layout="constrained")
width = 0.2
x = np.arange(len(resolutions))
for i, m in enumerate(methods):
    ax.bar(x + (i - 1.5) * width, fps[m], width, label=m)
ax.set_xticks(x, [f"{r} m" for r in resolutions])
ax.set_xlabel("resolution")
ax.set_ylabel("scans per second")
ax.legend(ncols=2, fontsize="small")
plt.show()
