"""File formats below the maps and the data sets: every scan reader and writer.

Point clouds: :func:`read_pcd` / :func:`write_pcd` (PCD ascii, binary,
binary_compressed with PCL's LZF codec), :func:`read_kitti_bin` (KITTI and nuScenes
``.bin``), :func:`read_scan_graph` / :func:`write_scan_graph` (OctoMap ``.graph``),
:func:`read_xyz` (text, optionally compressed), :func:`read_scan_log` (OctoMap text
logs), :func:`load_scan_folder` and :func:`read_scans` (dispatch by suffix). Every
scan is a :class:`Scan` ``(points, origin)``; a sequence of scans is a ``list[Scan]``.

Real logs: :class:`ScanSequence` reads a folder of scans in the sensor frame with a
KITTI or TUM pose file (:func:`read_poses`, :func:`read_kitti_poses`,
:func:`read_tum_trajectory`, :func:`apply_poses`) lazily, scan by scan, as
``occgp map FOLDER --poses FILE`` does; :func:`read_carmen` reads a CARMEN 2D laser
log (``FLASER`` / ``ROBOTLASER1`` lines) into a :class:`LaserLog` of
:class:`LaserScan2D`; :func:`read_rosbag` reads ``sensor_msgs/PointCloud2`` scans of
a ROS 1 / ROS 2 bag posed by TF (:class:`RosbagScans`).

The maps' exports (``occgp/io/_export.py``) write PCD through here; the data sets'
simulators return the same records (:class:`Scan`, :class:`LaserScan2D`), which
:mod:`occgp.datasets` re-exports.

Examples
--------
>>> import os, tempfile
>>> from occgp.io import read_scans, write_pcd
>>> path = os.path.join(tempfile.mkdtemp(), "scan.pcd")
>>> write_pcd(path, [[1.0, 0.0, 0.0]])
>>> read_scans(path)[0].points.tolist()
[[1.0, 0.0, 0.0]]
"""

from ._carmen import FLASER_NO_RETURN, LaserLog, read_carmen
from ._kitti_bin import read_kitti_bin
from ._pcd import lzf_decompress, read_pcd, write_pcd
from ._readers import load_scan_folder, read_scan_log, read_scans, read_xyz
from ._rosbag import RosbagScans, read_rosbag
from ._scan import Scan
from ._scan2d import LaserScan2D
from ._scan_graph import read_scan_graph, write_scan_graph
from ._sequence import POSE_FORMATS, ScanSequence, read_poses
from ._trajectory import apply_poses, read_kitti_poses, read_tum_trajectory

__all__ = [
    "Scan",
    "LaserScan2D",
    "read_pcd",
    "write_pcd",
    "lzf_decompress",
    "read_kitti_bin",
    "read_scan_graph",
    "write_scan_graph",
    "read_xyz",
    "read_scan_log",
    "load_scan_folder",
    "read_scans",
    "read_carmen",
    "LaserLog",
    "FLASER_NO_RETURN",
    "ScanSequence",
    "read_poses",
    "POSE_FORMATS",
    "read_kitti_poses",
    "read_tum_trajectory",
    "apply_poses",
    "read_rosbag",
    "RosbagScans",
]
