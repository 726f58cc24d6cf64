"""Synthetic scenes with exact ground truth and sensor simulators.

Scenes
------
:func:`structured_room`, :func:`unstructured_room` (or :func:`make_scene`)
build 10 x 7 x 2 m rooms of analytic solids (:class:`Scene`) with exact
occupancy, signed distance and ray casting, and an la3dm-like sensor
(:meth:`Scene.scan`: 4 poses x 3 scans x 3500 returns). :func:`room_2d`
builds the 22 x 18 m 2D room of the GP papers (:class:`Scene2D`), scanned by
a 180-degree, 17-beam, 8 m laser along a 26-pose path
(:class:`~occgp.io.LaserScan2D`). :func:`floor_plan_2d` builds a seeded 2D building of
rooms, corridors and furniture (60 x 40 m by default, :class:`FloorPlan2D`)
with a path through every room, for scaling studies: the same laser gives
about 32 observations per pose, 20,000 at 619 poses.
:func:`scene_family_2d` draws a 2D scene (office, warehouse, hall or cluttered
rooms, :data:`FAMILY_KINDS`) and its laser setting from a seed
(:class:`FamilyScene2D`); defaults are chosen on :data:`TUNING_SEEDS` and
reported on :data:`TEST_SEEDS`.
:func:`tetromino_scene` builds the k-NN paper's tetromino layouts of box pairs
(:class:`TetrominoScene`), which :func:`simulate_stereo` orbits with a noisy
:class:`StereoCamera` (depth noise growing with depth squared, speckle,
missing blobs on weak texture, :func:`voxel_filter` at 0.1 m);
:func:`stereo_datasets` lists the 20 data sets at several noise levels.
:func:`render_stereo` renders the rectified grey image pair a :class:`StereoRig`
sees of any scene (exact ray casting, procedural textures from
:data:`TEXTURES` chosen by :func:`scene_materials`, sun and cast shadows,
sensor blur, noise and gain mismatch), for a real stereo matcher
(:class:`StereoPair`).

Readers
-------
The scan files and real logs are read by :mod:`occgp.io` (``read_pcd``,
``read_scans``, ``read_carmen``, ``ScanSequence``, ``read_rosbag`` ...). Their old
paths here (``occgp.datasets.read_pcd`` ...) still work for one release with a
:class:`DeprecationWarning`. The records the simulators return,
:class:`~occgp.io.Scan` and :class:`~occgp.io.LaserScan2D`, stay importable from here.

Examples
--------
>>> from occgp.datasets import structured_room
>>> scans = structured_room().scan(n_poses=1, scans_per_pose=1, n_points=50)
>>> scans[0].points.shape
(50, 3)
"""

import warnings

from .. import io as _io
from ..io import LaserScan2D, Scan
from ._family2d import (
    FAMILY_KINDS,
    TEST_SEEDS,
    TUNING_SEEDS,
    FamilyScene2D,
    SensorSetting2D,
    scene_family_2d,
)
from ._floorplan import FloorPlan2D, floor_plan_2d
from ._outdoor import OutdoorScene, outdoor_scene
from ._render import TEXTURES, StereoPair, StereoRig, render_stereo, scene_materials
from ._rendered_sets import RenderedStereoDataset, rendered_stereo_datasets
from ._sgbm import (
    disparity_to_points,
    match_stereo,
    naive_fdr,
    point_errors,
    PointErrors,
    rank_sgbm_sets,
    render_orbit,
    SGBM_DEFAULT,
    SGBM_GRID,
    sgbm_parameter_sets,
    stereo_scans,
)
from ._scene2d import Scene2D, room_2d
from ._scenes import Scene, make_scene, structured_room, unstructured_room
from ._simulate import LidarSensor, free_path, simulate_scans
from ._stereo import (
    StereoCamera,
    TetrominoScene,
    simulate_stereo,
    tetromino_scene,
    voxel_filter,
)
from ._stereo_sets import StereoDataset, stereo_datasets

__all__ = [
    "Scan",
    "Scene",
    "Scene2D",
    "LaserScan2D",
    "structured_room",
    "unstructured_room",
    "make_scene",
    "OutdoorScene",
    "outdoor_scene",
    "room_2d",
    "FloorPlan2D",
    "floor_plan_2d",
    "scene_family_2d",
    "FamilyScene2D",
    "SensorSetting2D",
    "FAMILY_KINDS",
    "TUNING_SEEDS",
    "TEST_SEEDS",
    "LidarSensor",
    "simulate_scans",
    "free_path",
    "TetrominoScene",
    "tetromino_scene",
    "StereoCamera",
    "simulate_stereo",
    "StereoDataset",
    "stereo_datasets",
    "voxel_filter",
    "StereoRig",
    "StereoPair",
    "render_stereo",
    "scene_materials",
    "TEXTURES",
    "SGBM_GRID",
    "SGBM_DEFAULT",
    "sgbm_parameter_sets",
    "match_stereo",
    "disparity_to_points",
    "render_orbit",
    "stereo_scans",
    "naive_fdr",
    "rank_sgbm_sets",
    "PointErrors",
    "point_errors",
    "RenderedStereoDataset",
    "rendered_stereo_datasets",
]

#: The readers that moved to :mod:`occgp.io`; their old paths here warn for one release.
_MOVED_TO_IO = frozenset({
    "read_pcd", "write_pcd", "lzf_decompress", "read_kitti_bin", "read_scan_graph",
    "write_scan_graph", "read_xyz", "read_scan_log", "load_scan_folder", "read_scans",
    "read_carmen", "LaserLog", "FLASER_NO_RETURN", "ScanSequence", "read_poses",
    "POSE_FORMATS", "read_kitti_poses", "read_tum_trajectory", "apply_poses",
    "read_rosbag", "RosbagScans",
})


def __getattr__(name):
    if name in _MOVED_TO_IO:
        warnings.warn(f"occgp.datasets.{name} is deprecated; import it from occgp.io "
                      "(the old path goes in the next release)", DeprecationWarning,
                      stacklevel=2)
        return getattr(_io, name)
    raise AttributeError(f"module 'occgp.datasets' has no attribute {name!r}")
