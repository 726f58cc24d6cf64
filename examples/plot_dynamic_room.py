"""
=====================================================================
A robot in a room with a moving box: decay, 2D map, frontiers, ESDF
=====================================================================

A robot drives through the structured room of :mod:`occgp.datasets` with a
spinning LiDAR; half-way, the crate in the room is moved. The octree keeps a
stamp per cell (``insert_scan(..., stamp=t)``) and lets cells the sensor no
longer confirms fade (:meth:`~occgp.OccupancyOctree.decay`, liboctomap's
``degradeOutdatedNodes``). For the planner the map gives a 2D occupancy grid
of the robot's height band (:meth:`~occgp.OccupancyOctree.project_2d`, saved
as map_server / Nav2's YAML + PGM), its frontiers (free cells next to unknown
space, :meth:`~occgp.OccupancyGrid2D.frontiers`) and a signed distance field
with the closest obstacles, kept current scan by scan
(:class:`occgp.DistanceMap`).
"""

# Author: the occgp developers
# License: BSD 3 clause

# %%
# The room, the crate's two places and the robot's path
# -----------------------------------------------------
# :meth:`~occgp.datasets.Scene.moved` gives the room with the crate moved 0.7 m
# towards the robot's path, so that it now hides part of its old place. The
# robot looks around from 20 places along a line (the crate moves after the
# sixth); the sensor sees 8 m, 30 degrees down and 15 up.
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from occgp import DistanceMap, OccupancyGrid2D, OccupancyOctree
from occgp.datasets import LidarSensor, simulate_scans, structured_room

before = structured_room()
after = before.moved("crate", [-0.7, 0.0, 0.0])
sensor = LidarSensor(n_horizontal=360, vertical_fov=(-np.pi / 6, np.pi / 12), n_vertical=24,
                     max_range=8.0)
path = np.column_stack([np.linspace(-3.5, 1.0, 20), np.full(20, -0.3), np.full(20, 0.6)])
scans = (simulate_scans(before, path[:6], sensor, seed=0)
         + simulate_scans(after, path[6:], sensor, seed=1))
print(f"{len(scans)} scans of about {np.mean([len(s.points) for s in scans]):.0f} points")

# %%
# Map with stamps and decay, and without
# --------------------------------------
# Scan ``t`` is stamped ``t`` (seconds). After each scan, every occupied cell
# not confirmed for more than 1 s loses one miss (``max_age=1``); a cell the
# sensor still sees is re-stamped by every scan and never decays.
res = 0.1
kept, tree = OccupancyOctree(res), OccupancyOctree(res)
for t, (points, origin) in enumerate(scans):
    kept.insert_scan(points, origin)
    tree.insert_scan(points, origin, stamp=float(t))
    tree.decay(float(t), max_age=1.0)
print(f"stamped cells: {len(tree.stamps().keys):,}")

# %%
# The cells the crate left behind
# -------------------------------
# A slice through the crate's old and new place, 0.25 m above the floor. Where
# rays now pass through the old place, both maps clear it; the part the robot
# no longer sees stays occupied in the map without decay (a "ghost") and fades
# from the map with decay.
lo, hi = before.bounds
xs = np.arange(lo[0], hi[0], res) + res / 2
ys = np.arange(lo[1], hi[1], res) + res / 2
gx, gy = np.meshgrid(xs, ys)
q = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, 0.25)])
old = before.occupancy(q) & ~after.occupancy(q)
print(f"cells of the old place in the slice: {old.sum()}; still occupied without decay: "
      f"{kept.is_occupied(q[old]).sum()}, with decay: {tree.is_occupied(q[old]).sum()}")

cmap = plt.get_cmap("viridis").with_extremes(bad="0.75")
extent = (lo[0], hi[0], lo[1], hi[1])
fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), layout="constrained", sharey=True)
for ax, m, title in ((axes[0], kept, "without decay"), (axes[1], tree, "stamps + decay")):
    im = ax.imshow(m.occupancy(q).reshape(gx.shape), origin="lower", extent=extent,
                   cmap=cmap, vmin=0, vmax=1)
    ax.contour(xs, ys, old.reshape(gx.shape), levels=[0.5], colors="r", linewidths=1)
    ax.plot(path[:, 0], path[:, 1], "w.-", ms=4)
    ax.set_title(title)
fig.colorbar(im, ax=axes, label="p(occupied), z = 0.25 m")
plt.show()

# %%
# The 2D map for navigation, and its frontiers
# --------------------------------------------
# A cell of the 2D grid is occupied if any occupied cell lies in the robot's
# height band (0.15 to 1.2 m: above the floor), free if the band's known
# cells are all free, unknown otherwise. ``save_ros_map`` writes what
# map_server and Nav2 read.
# Frontiers are free cells beside unknown space, grouped into clusters; the
# largest are where exploring would pay most.
grid = tree.project_2d(0.15, 1.2)
with tempfile.TemporaryDirectory() as tmp:
    yaml_path, pgm_path = grid.save_ros_map(Path(tmp) / "room.yaml")
    print(yaml_path.read_text())
    assert np.array_equal(OccupancyGrid2D.load_ros_map(yaml_path).states, grid.states)
front = grid.frontiers(min_size=5)
print(f"{front.n_clusters} frontier clusters, sizes {front.sizes.tolist()}")

fig, ax = plt.subplots(figsize=(6.5, 4.2), layout="constrained")
ax.imshow(grid.occupancy_image(), cmap="gray", vmin=0, vmax=255,
          extent=(grid.origin[0], grid.origin[0] + grid.shape[0] * grid.resolution,
                  grid.origin[1], grid.origin[1] + grid.shape[1] * grid.resolution))
ax.scatter(*front.cells.T, s=3, c=front.labels, cmap="tab10")
ax.scatter(*front.centroids.T, s=60, marker="x", c="r")
ax.set_title("2D map (black occupied, white free, grey unknown) and frontiers")
plt.show()

# %%
# The signed distance field and the closest obstacles
# ---------------------------------------------------
# :class:`occgp.DistanceMap` keeps the distance to the nearest obstacle
# (unknown space counts as one), negative inside obstacles, truncated at 1 m,
# in blocks of 16³ cells. With ``track_changes`` on, an update reads the cells
# that changed and recomputes only the blocks they reach, and the result
# equals a new fit exactly. Here the crate goes back to its first place and
# the robot, at the end of its path, scans again. (In a room this small the
# 1 m reach of a change touches most blocks; on a building map one scan
# recomputes about an eighth of them, see ``bench/bench_distance.py``.)
tree.track_changes = True
field = DistanceMap(max_distance=1.0, signed=True).fit(tree)
points, origin = simulate_scans(before, path[-1:], sensor, seed=2)[0]
tree.insert_scan(points, origin, stamp=float(len(scans)))
field.update(tree)
tree.reset_changes()
print({k: field.last_update_[k] for k in ("changed_cells", "blocks", "recomputed")})
fresh = DistanceMap(max_distance=1.0, signed=True).fit(tree)
assert np.array_equal(field.dense().distances, fresh.dense().distances, equal_nan=True)

# %%
# At the robot's height, the arrows point away from the closest obstacle (the
# gradient): where a planner pushes a path that comes too close.
q[:, 2] = 0.6
d, closest, gradient = field.query(q, return_closest=True, return_gradient=True)
fig, ax = plt.subplots(figsize=(6.5, 4.2), layout="constrained")
im = ax.imshow(d.reshape(gx.shape), origin="lower", extent=extent, cmap="RdBu", vmin=-0.5,
               vmax=1.0)
step = (slice(None, None, 6), slice(None, None, 6))
ax.quiver(gx[step], gy[step], gradient[:, 0].reshape(gx.shape)[step],
          gradient[:, 1].reshape(gx.shape)[step], scale=30, width=0.003)
ax.plot(path[:, 0], path[:, 1], "k.-", ms=4)
fig.colorbar(im, ax=ax, label="signed distance [m], z = 0.6 m")
plt.show()
