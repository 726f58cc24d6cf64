"""
=====================================
Mapping a real ROS bag, poses from TF
=====================================

A real log, read as a user reads their own: the akimap sample bag (a mobile
robot's LiDAR, 73 ``sensor_msgs/PointCloud2`` clouds over 15 s, LOAM odometry
on ``/tf``) from ``../shared/data``. :func:`occgp.io.read_rosbag`
decodes the clouds and composes the TF chain from the ``map`` frame to each
cloud's stamp; the sensor origin is the ``camera`` frame. The scans go into an
:class:`~occgp.OccupancyOctree`, whose occupied cells are written as a PLY
file that MeshLab, CloudCompare or Open3D open.

The bag is not part of occgp: without it (or without the ``ros`` extra,
``rosbags``) this example says so and stops.
"""

# Author: the occgp developers
# License: BSD 3 clause

# %%
# Read the bag
# ------------
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from occgp import OccupancyOctree
from occgp.io import read_rosbag

candidates = [Path(p) / "akimap_sample" / "sample.bag"
              for p in ("../shared/data", "../../shared/data", "../../../shared/data")]
bag = next((p for p in candidates if p.exists()), None)
try:
    import rosbags  # noqa: F401
except ImportError:
    rosbags = None
if bag is None or rosbags is None:
    print("the akimap sample bag (../shared/data) or the rosbags package is missing: "
          "nothing to map")
    scans = []
else:
    scans = read_rosbag(bag, fixed_frame="map", sensor_frame="camera")
    print(f"{len(scans)} clouds in frame {scans.fixed_frame!r}, origins at "
          f"{scans.sensor_frame!r}")

# %%
# Map it and export the occupied cells
# ------------------------------------
# Each cloud is inserted from the camera's position at its stamp, with rays
# cut at 20 m. The PLY holds one vertex per occupied leaf, with its size and
# occupancy probability and a colour by height.
if scans:
    tree = OccupancyOctree(0.2)
    origins = []
    for points, origin in scans:
        tree.insert_scan(points, origin, max_range=20.0)
        origins.append(origin)
    origins = np.array(origins)
    out = Path(tempfile.mkdtemp()) / "akimap_sample.ply"
    tree.save_ply(out)
    centers, sizes = tree.extract_points()
    print(f"{scans.n_points} points ({scans.n_dropped} non-finite dropped); "
          f"{tree.num_leaves} leaves, {len(centers)} occupied; wrote {out.name} "
          f"({out.stat().st_size // 1024} kB)")

    # %%
    # The map from above
    # ------------------
    # The occupied cells coloured by height, and the sensor's path from TF.
    fig, ax = plt.subplots(figsize=(7, 5), layout="constrained")
    order = np.argsort(centers[:, 2])
    sc = ax.scatter(centers[order, 0], centers[order, 1], c=centers[order, 2], s=2,
                    cmap="viridis", lw=0)
    ax.plot(origins[:, 0], origins[:, 1], "r.-", ms=3, lw=1, label="sensor path (TF)")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m] (map frame)")
    ax.set_ylabel("y [m]")
    ax.legend(loc="upper right")
    fig.colorbar(sc, ax=ax, label="z [m]")
    plt.show()
