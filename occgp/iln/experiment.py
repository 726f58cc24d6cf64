"""The dissertation's §4.4.5 experiment: occupancy maps from up-sampled sparse scans.

:func:`mapping_experiment` drives a simulated LiDAR along a trajectory in a
procedural outdoor scene (:func:`occgp.datasets.outdoor_scene`), builds an
:class:`occgp.OccupancyOctree` from the sparse (16 x 1024) scans, from the
scans up-sampled by each model to each resolution, and from the true scans
of higher resolution, and scores every map against the scene's exact ground
truth (ROC AUC, unknown cells counting as p = 0.5), with the time split
into up-sampling and map update (Fig. 4.10). :func:`format_mapping_table`
prints the rows.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from .._docfill import fill_doc
from .._validation import check_bool, check_int, check_real
from ._common import (
    DOC_SECTIONS, as_lidar, as_pose, as_size, as_size_list, check_rows, column_line, out_model,
    predict_image, resolve_models,
)
from ._range import LidarModel, range_image_to_points

__all__ = ["mapping_experiment", "format_mapping_table", "DEFAULT_SIZES"]

#: The up-sampled resolutions of the experiment (the issue's 64 x 1024 and 128 x 2048).
DEFAULT_SIZES = ((64, 1024), (128, 2048))
_MAX_TEST_CELLS = 10_000_000
_COLUMNS = (("method", "Map from", "s"), ("n_points", "points/scan", "d"),
            ("auc", "AUC", ".3f"), ("known", "known", ".1%"),
            ("upsample_seconds", "up-sample [s/scan]", ".3f"),
            ("update_seconds", "update [s/scan]", ".3f"),
            ("total_seconds", "total [s/scan]", ".3f"))


def _check_scene(scene, poses, n_scans):
    """The scene and its (n, 4, 4) sensor-to-world poses."""
    from ..datasets import outdoor_scene
    from .data import TEST_SEED_OFFSET

    if scene is None:
        scene = outdoor_scene(TEST_SEED_OFFSET)
    for attr in ("ray_cast", "occupancy", "bounds"):
        if not hasattr(scene, attr):
            raise TypeError(f"scene must be a Scene of occgp.datasets (e.g. outdoor_scene()), "
                            f"{type(scene).__name__} lacks {attr}")
    if poses is None:
        if not callable(getattr(scene, "trajectory", None)):
            raise TypeError(f"scene must have a trajectory(n_poses) method when poses is not "
                            f"given, {type(scene).__name__} has none")
        poses = scene.trajectory(n_scans)
    else:
        arr = np.asarray(poses) if not isinstance(poses, np.ndarray) else poses
        if arr.ndim != 3 or arr.shape[1:] != (4, 4) or len(arr) == 0:
            raise ValueError(f"poses must have shape (n_scans, 4, 4) with n_scans >= 1, "
                             f"got {arr.shape}")
        checked = []
        for i, p in enumerate(arr):
            try:
                checked.append(as_pose(p))
            except (TypeError, ValueError) as exc:
                raise type(exc)(f"poses[{i}]: {exc}") from None
        poses = np.stack(checked)
    return scene, np.asarray(poses, dtype=np.float64)


def _test_cells(scene, truth_scans, lidar, resolution, n_cells, test_range, rng):
    """A seeded uniform sample of the map's lattice cells near the trajectory that the true
    scans could see, and their exact labels."""
    from ..evaluation import TestSet, cells_in_view, exact_labels

    origins = np.array([o for _, o in truth_scans])
    lo_b, hi_b = (np.asarray(b, dtype=np.float64) for b in scene.bounds)
    lo = np.maximum(origins.min(axis=0) - test_range, lo_b)
    hi = np.minimum(origins.max(axis=0) + test_range, hi_b)
    top = origins[:, 2].max() + test_range * math.tan(math.radians(lidar.vertical_fov[1]))
    lo[2] = max(lo_b[2], -2 * resolution)
    hi[2] = min(hi_b[2], max(top, lo[2] + resolution))
    k_lo = np.floor(lo / resolution).astype(np.int64)
    k_hi = np.maximum(np.ceil(hi / resolution).astype(np.int64), k_lo + 1)
    keys = np.unique(rng.integers(k_lo, k_hi, size=(n_cells, 3)), axis=0)
    centers = (keys + 0.5) * resolution
    seen = cells_in_view(scene, centers, resolution, truth_scans, max_range=test_range)
    centers = centers[seen]
    labels = exact_labels(scene, centers, resolution)
    n_occ = int(labels.sum())
    if n_occ == 0 or n_occ == len(labels):
        raise ValueError(f"the {len(labels)} sampled test cells in view hold {n_occ} occupied "
                         f"ones; a test set needs both classes (raise n_test_cells)")
    return TestSet(np.ascontiguousarray(centers), labels)


def _world(points, pose):
    return points @ pose[:3, :3].T + pose[:3, 3]


@fill_doc(**DOC_SECTIONS)
def mapping_experiment(models: Any = None, *, scene: Any = None, poses: Any = None,
                       n_scans: int = 10, in_size: Any = (16, 1024),
                       sizes: Any = DEFAULT_SIZES, truth_sizes: Any = ((64, 1024),),
                       lidar: LidarModel | None = None, resolution: float = 0.2,
                       n_test_cells: int = 100_000, test_range: float = 25.0, seed: int = 0,
                       device: Any = None, keep_maps: bool = False,
                       progress: bool | None = None) -> list[dict[str, Any]]:
    """Occupancy maps from sparse, up-sampled and true scans, scored by exact ground truth.

    The sensor (`lidar`'s fields of view and range) drives along `poses`
    (default: ``scene.trajectory(n_scans)``, the main road's right lane);
    at each pose the scene is ray cast exactly at `in_size` (the sparse
    scan) and at each of `truth_sizes` (the true dense scans,
    :func:`occgp.iln.data.simulate_range_image`). One
    ``OccupancyOctree(resolution)`` is built with ``insert_scan(...,
    method="auto")`` (super rays and the culling region) from each of:

    * the sparse scans (``"16x1024 (input)"``);
    * the sparse scans up-sampled by each model to each of `sizes`
      (``"ILN 64x1024"``; :func:`occgp.iln.upsample.upsample_range_image`,
      no-return pixels dropped);
    * the true scans of each of `truth_sizes` (``"64x1024 (true)"``).

    **Ground truth.** The test cells are a seeded uniform sample of
    `n_test_cells` cells of the map's lattice (cell centers ``(k + 0.5) *
    resolution``) in the box around the trajectory reaching `test_range`
    beyond its ends in x and y and from just below the ground to the top
    of the field of view at that distance, kept where a true scan of the
    largest of `truth_sizes` could see them (:func:`occgp.evaluation.cells_in_view`
    within `test_range`: in line of sight, or holding a return) and labelled
    by the scene's exact geometry (occupied where a solid reaches into the
    cell, :func:`occgp.evaluation.cell_labels`). Every map is scored on the
    same cells; a cell a map leaves unknown counts as p = 0.5.

    Parameters
    ----------
    models : dict of str to model, or list of str, optional
        Models that up-sample the sparse scans (see
        :func:`occgp.iln.evaluate.evaluate`); default ``{"selector":
        "pretrained"}`` (the shipped candidate selector). An empty dict maps only the sparse and true scans.
    scene : Scene, optional
        Default ``outdoor_scene(TEST_SEED_OFFSET)``, a held-out test scene.
    poses : array-like of shape (n_scans, 4, 4), optional
        Sensor-to-world poses; default ``scene.trajectory(n_scans)``.
    n_scans : int, default=10
        Poses of the default trajectory, 1 to 1000.
    in_size : (int, int) or str, default=(16, 1024)
        Size of the sparse scans.
    sizes : sequence of (int, int) or str, default=((64, 1024), (128, 2048))
        Up-sampled resolutions.
    truth_sizes : sequence of (int, int) or str, default=((64, 1024),)
        Resolutions of the true scans mapped for comparison; at least one.
    lidar : LidarModel, optional
        Fields of view and range (its size is ignored); default
        ``LidarModel.carla()``.
    resolution : float, default=0.2
        Cell size of the maps and of the test cells, metres.
    n_test_cells : int, default=100000
        Candidate test cells drawn (duplicates merged), 1 to 10,000,000.
    test_range : float, default=25.0
        Range within which the test cells lie, metres, in (0, lidar.max_range].
    seed : int, default=0
        Seed of the test-cell sample.
    device : str or torch.device, optional
        Where models built from names run.
    keep_maps : bool, default=False
        Keep each built map in its row (``"map"``).
    progress : bool or None, default=None
        Show a progress bar; None shows it only on a terminal.

    Returns
    -------
    rows : list of dict
        One per map: ``method``, ``resolution``, ``n_points`` (mean points
        inserted per scan), ``auc``, ``known`` (fraction of test cells the
        map knows), ``upsample_seconds``, ``update_seconds`` and
        ``total_seconds`` (means per scan), ``n_scans``, ``n_test``
        (test cells; ``n_occupied`` of them occupied) and, with
        `keep_maps`, ``map``.

    Raises
    ------
    ValueError
        If a size, count, range, resolution or the poses are malformed or
        out of range, a size is repeated, `truth_sizes` is empty, a model name is unknown, or the
        sampled test cells in view hold only one class.
    TypeError
        If an argument has a wrong type or `scene` is not a Scene.
    {model_errors}

    Examples
    --------
    >>> from occgp.datasets import outdoor_scene
    >>> rows = mapping_experiment(["bilinear"], scene=outdoor_scene(1, size=40), n_scans=2,
    ...                           in_size="8x256", sizes=["16x256"], truth_sizes=["16x256"],
    ...                           n_test_cells=3000, test_range=8.0, progress=False)
    >>> [r["method"] for r in rows]
    ['8x256 (input)', 'bilinear 16x256', '16x256 (true)']
    """
    from tqdm.auto import tqdm

    from .. import OccupancyOctree
    from ..evaluation import evaluate_map
    from .data import simulate_range_image

    models = {"selector": "pretrained"} if models is None else models
    n_scans = check_int(n_scans, "n_scans", low=1, high=1000)
    lidar = as_lidar(lidar)
    in_size = as_size(in_size, "in_size")

    def size_list(value, name, allow_empty):
        out = as_size_list(value, name, allow_empty)
        for s in out:
            out_model(lidar, *s)               # checks the pixel count
        return out

    sizes = size_list(sizes, "sizes", True)
    truth_sizes = size_list(truth_sizes, "truth_sizes", False)
    out_model(lidar, *in_size)
    resolution = check_real(resolution, "resolution", low=0.0, high=10.0, high_open=False)
    if resolution < 1e-3:
        raise ValueError(f"resolution must lie in [0.001, 10] m, got {resolution!r}")
    n_test_cells = check_int(n_test_cells, "n_test_cells", low=1, high=_MAX_TEST_CELLS)
    test_range = check_real(test_range, "test_range", low=0.0, high=lidar.max_range,
                            high_open=False)
    seed = check_int(seed, "seed", low=0)
    keep_maps = check_bool(keep_maps, "keep_maps")
    nets = resolve_models(models, lidar, device, "mapping_experiment") if (not hasattr(models, "__len__") or len(models)) \
        else {}
    scene, poses = _check_scene(scene, poses, n_scans)
    n = len(poses)

    in_lidar = lidar.with_size(*in_size)
    sparse = [simulate_range_image(scene, p, in_lidar) for p in poses]
    truths = {s: [simulate_range_image(scene, p, lidar.with_size(*s)) for p in poses]
              for s in truth_sizes}
    biggest = max(truth_sizes, key=lambda s: s[0] * s[1])
    view_scans = [(_world(range_image_to_points(im, lidar.with_size(*biggest)), p), p[:3, 3])
                  for im, p in zip(truths[biggest], poses)]
    test = _test_cells(scene, view_scans, lidar, resolution, n_test_cells, test_range,
                       np.random.default_rng([seed, 4451]))

    configs = [(f"{in_size[0]}x{in_size[1]} (input)", in_size, None, sparse)]
    configs += [(f"{name} {s[0]}x{s[1]}", s, net, sparse) for s in sizes
                for name, net in nets.items()]
    configs += [(f"{s[0]}x{s[1]} (true)", s, None, truths[s]) for s in truth_sizes]
    rows = []
    bar = tqdm(total=len(configs) * n, disable=None if progress is None else not progress,
               desc="mapping", unit="scan")
    try:
        for name, size, net, images in configs:
            out_lidar = lidar.with_size(*size)
            tree = OccupancyOctree(resolution)
            t_up = t_map = 0.0
            n_points = 0
            for image, pose in zip(images, poses):
                t0 = time.perf_counter()
                if net is not None:
                    image = predict_image(net, image, in_lidar, out_lidar)
                points = range_image_to_points(image, out_lidar)
                t1 = time.perf_counter()
                tree.insert_scan(_world(points, pose), pose[:3, 3], method="auto")
                t2 = time.perf_counter()
                t_up += t1 - t0 if net is not None else 0.0
                t_map += t2 - t1
                n_points += len(points)
                bar.update()
            known = float(np.isfinite(tree.occupancy(test.points)).mean())
            row = {"method": name, "resolution": f"{size[0]}x{size[1]}",
                   "n_points": n_points // n, "auc": evaluate_map(tree, test)["auc"],
                   "known": known, "upsample_seconds": t_up / n, "update_seconds": t_map / n,
                   "total_seconds": (t_up + t_map) / n, "n_scans": n,
                   "n_test": len(test.labels), "n_occupied": int(test.labels.sum())}
            if keep_maps:
                row["map"] = tree
            rows.append(row)
    finally:
        bar.close()
    return rows


@fill_doc(**DOC_SECTIONS)
def format_mapping_table(rows: Any) -> str:
    """Rows of :func:`mapping_experiment` as a table (AUC, known cells, time per scan).

    Parameters
    ----------
    rows : iterable of dict

    {table_sections}

    Examples
    --------
    >>> print(format_mapping_table([{"method": "16x1024 (input)", "n_points": 11800,
    ...     "auc": 0.8, "known": 0.5, "upsample_seconds": 0.0, "update_seconds": 0.1,
    ...     "total_seconds": 0.1}]))
    Map from         points/scan    AUC  known  up-sample [s/scan]  update [s/scan]  total [s/scan]
    ---------------  -----------  -----  -----  ------------------  ---------------  --------------
    16x1024 (input)        11800  0.800  50.0%               0.000            0.100           0.100
    """
    records = check_rows(rows, [key for key, _, _ in _COLUMNS])
    header = [label for _, label, _ in _COLUMNS]
    cells = [[format(r[key], fmt) for key, _, fmt in _COLUMNS] for r in records]
    line, widths = column_line(header, cells)
    return "\n".join([line(header), "  ".join("-" * w for w in widths)]
                     + [line(c) for c in cells])
