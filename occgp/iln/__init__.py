"""occgp.iln: the Implicit LiDAR Network and its range images (Kwon, dissertation ch. 4).

Range images and their training data need numpy alone and are imported here
eagerly: :class:`LidarModel` (a spinning LiDAR's pixel grid, with the CARLA,
HDL-64E and HDL-32E presets), :func:`points_to_range_image`,
:func:`range_image_to_points`, :func:`range_image_from_points` (a real scan, by
elevation or by its ring index), :func:`read_lidar_frame`,
:func:`frame_range_image` and :func:`scan_rings` (real frames, one row per
beam, on a measured per-beam elevation table), :func:`simulate_range_image` (exact ray casting
in the procedural outdoor scenes of :func:`occgp.datasets.outdoor_scene`),
:class:`SensorEffects`, :func:`apply_sensor_effects` and :func:`solid_reflectivity`
(range noise and dropped returns of a real sensor on the exact images),
:func:`make_dataset` and :func:`load_shards` (the ``occgp iln make-dataset``
shards), and the evaluation: :func:`range_mae` and :func:`voxel_scores`
(dissertation §4.4), :func:`region_masks` (planar pixels, depth edges,
no-return boundaries), :func:`evaluate` / :func:`format_table` (Table 4.1) /
:func:`format_region_table` (its per-region scores),
:func:`upsample` (sparse scan in, dense sensor-frame points out) and
:func:`mapping_experiment` (§4.4.5: maps from up-sampled scans),
:func:`real_frame_scores` / :func:`format_real_table` (dropped beams of a real
frame predicted at their true elevations) and :func:`kept_beams_model`. These run
without torch and ask for it only when a learned model is used.

The models and their training need PyTorch (the ``iln`` extra: ``pip install
torch==2.13.0`` on CPU machines, then ``pip install 'occgp[iln]'``). Their names
-- :func:`pretrained` (the shipped models), :func:`make`, :func:`register`,
:func:`available_models`, :class:`ILN`, :class:`LIIF`, :class:`Bilinear`,
:class:`InverseBilinear`, :class:`EdgeAwareInterpolation`, :class:`CandidateSelector` (a learnt
choice among the analytic candidates :data:`CANDIDATES`, with :func:`choose_candidates`,
:func:`hard_queries`, :func:`selector_labels`, :func:`tune_threshold` and
:func:`tune_checkpoint`), :func:`upsample_image`, :func:`image_queries`, :func:`train`,
:func:`train_from_yaml`, :func:`load_checkpoint` -- are imported from this
package on first use, so that ``import occgp.iln`` works without torch and
raises a clear ImportError only when a torch part is asked for.
"""

import importlib

from ._effects import SensorEffects, apply_sensor_effects, solid_reflectivity
from ._range import LidarModel, points_to_range_image, range_image_from_points, \
    range_image_to_points
from .data import load_shards, make_dataset, simulate_range_image
from .evaluate import evaluate, format_region_table, format_table
from .experiment import format_mapping_table, mapping_experiment
from .frames import frame_range_image, read_lidar_frame, scan_rings
from .metrics import range_mae, region_masks, voxel_scores
from .real import format_real_table, kept_beams_model, real_frame_scores
from .upsample import upsample, upsample_range_image

#: The torch parts of the package: public name -> submodule.
_TORCH_NAMES = {
    "make": "models", "register": "models", "available_models": "models",
    "EDSRBaseline": "models", "ILN": "models", "LIIF": "models", "Bilinear": "models",
    "InverseBilinear": "models", "EdgeAwareInterpolation": "models",
    "CandidateSelector": "models", "hard_queries": "models", "selector_labels": "models",
    "choose_candidates": "models", "CANDIDATES": "models", "image_queries": "models",
    "upsample_image": "models", "tune_threshold": "tuning", "tune_checkpoint": "tuning",
    "train": "training", "train_from_yaml": "training", "load_checkpoint": "training",
    "pretrained": "_weights",
}

__all__ = ["LidarModel", "points_to_range_image", "range_image_to_points",
           "range_image_from_points", "simulate_range_image", "SensorEffects",
           "apply_sensor_effects", "solid_reflectivity", "make_dataset", "load_shards",
           "upsample", "upsample_range_image", "evaluate", "format_table", "format_region_table",
           "mapping_experiment", "format_mapping_table", "range_mae", "voxel_scores",
           "region_masks", "read_lidar_frame", "frame_range_image", "scan_rings",
           "real_frame_scores", "format_real_table", "kept_beams_model", *_TORCH_NAMES]


def __getattr__(name):
    module = _TORCH_NAMES.get(name)
    if module is None:
        raise AttributeError(f"module 'occgp.iln' has no attribute {name!r}")
    try:
        importlib.import_module("torch")
    except ImportError as exc:
        raise ImportError(
            f"occgp.iln.{name} needs PyTorch: pip install 'occgp[iln]' (on CPU machines "
            f"first pip install torch==2.13.0, the CPU build)") from exc
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_TORCH_NAMES))
