"""
==========================================
Mapping a synthetic room with the octree
==========================================

Scan the structured room of :mod:`occgp.datasets` (10 x 7 x 2 m, 4 poses x 3
scans x 3500 points, as in the la3dm data set), insert the scans into an
:class:`occgp.OccupancyOctree`, and compare a horizontal slice of the map with
the ground truth.
"""

# Author: the occgp developers
# License: BSD 3 clause

# %%
# Scan the room
# -------------
# The scene knows its exact geometry, so every map can be checked against it.
import matplotlib.pyplot as plt
import numpy as np

from occgp import OccupancyOctree
from occgp.datasets import structured_room

room = structured_room(seed=0)
scans = room.scan(seed=0)
print(f"{len(scans)} scans of {len(scans[0].points)} points")

# %%
# Build the map
# -------------
# ``insert_scan`` is liboctomap's ``insertPointCloud``: the tree is the one
# OctoMap builds, leaf for leaf.
tree = OccupancyOctree(resolution=0.05)
for points, origin in scans:
    tree.insert_scan(points, origin)
print(tree, f"{tree.memory_usage() / 1e6:.1f} MB")

# %%
# A horizontal slice
# ------------------
# Unknown cells (never seen) are NaN and drawn grey: a sparse scanner leaves
# many of them, which is what the kernel and GP maps of occgp fill in.
z = float(np.mean([s.origin[2] for s in scans]))
lo, hi = room.bounds
xs = np.arange(lo[0], hi[0], 0.05) + 0.025
ys = np.arange(lo[1], hi[1], 0.05) + 0.025
gx, gy = np.meshgrid(xs, ys)
q = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, z)])

cmap = plt.get_cmap("viridis").with_extremes(bad="0.75")
fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), layout="constrained")
extent = (lo[0], hi[0], lo[1], hi[1])
axes[0].imshow(room.occupancy(q).reshape(gx.shape), origin="lower", extent=extent,
               cmap=cmap, vmin=0, vmax=1)
axes[0].set_title("ground truth")
im = axes[1].imshow(tree.occupancy(q).reshape(gx.shape), origin="lower", extent=extent,
                    cmap=cmap, vmin=0, vmax=1)
axes[1].set_title("octree")
fig.colorbar(im, ax=axes, label="p(occupied)")
plt.show()
