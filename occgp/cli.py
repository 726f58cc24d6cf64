"""The ``occgp`` command line: ``occgp demo`` (the main job) and ``occgp map``.

``occgp demo`` maps the synthetic structured room with every mapping method
(:func:`mapping_methods`: the octree and the grid in scan and ray mode, BGK,
AKIMap in both variants and the k-NN map), prints their scores, then maps a
noisy version of the same scans with the octree and the k-NN map
(:func:`noisy_mapping_methods`) and prints theirs, and writes ``map.bt`` and
figures. ``occgp map`` (:func:`map_scans`) builds a map from scan files and ROS
bags (PointCloud2 posed by TF; ``--topic``, ``--fixed-frame``,
``--sensor-frame``), optionally posed by a KITTI or TUM trajectory
(``--poses``), with ``--method octree`` (the default), ``bgk``
(:class:`~occgp.BGKMap`), ``akimap`` (:class:`~occgp.AKIMap`) or ``knn``
(:class:`~occgp.KNNMap`), optionally continuing a saved map
(``--input-map``), and writes it by the output's suffix: an OctoMap ``.bt`` or
``.ot`` file, the occupied cells as ``.ply`` or ``.pcd`` (a kernel map through
its :meth:`~occgp.BGKMap.to_octree`), or a kernel map's ``.npz``.
"""

from __future__ import annotations

import argparse
import errno
import inspect
import re
import sys
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from . import __version__
from ._validation import check_n_jobs, check_real, check_resolution
from .grid import GridMap
from .kernel import AKIMap, BGKMap
from .knn import CDFS, KNN_PARAMS, KNNMap, check_knn_params
from .octree import OccupancyOctree

__all__ = ["main", "demo", "map_scans", "mapping_methods", "noisy_mapping_methods",
           "gp_mapping_methods"]

# the maps `occgp map` can build (--method); each is written as an octree
_MAP_METHODS = ("octree", "bgk", "akimap", "knn")
# KNNMap's model parameters (those of `occgp map --method knn`) and their defaults,
# read from its signature
_KNN_OPTIONS = KNN_PARAMS + ("cdf",)
_KNN_DEFAULTS = {name: prm.default for name, prm in
                 inspect.signature(KNNMap.__init__).parameters.items() if name in _KNN_OPTIONS}
# the demo's scanner range (Scene.scan's max_range): every return lies within it, so
# the k-NN map's sensor_range of that length cuts no clean ray
_DEMO_RANGE = 8.0


class _RayModeOctree(OccupancyOctree):
    """An octree whose scans go in with per-ray counting (``mode="ray"``)."""

    def insert_scan(self, points, origin, **kwargs):
        return super().insert_scan(points, origin, mode="ray", **kwargs)


class _RayModeGrid(GridMap):
    """A grid whose scans go in with per-ray counting (``mode="ray"``)."""

    def insert_scan(self, points, origin, **kwargs):
        return super().insert_scan(points, origin, mode="ray", **kwargs)


class _RangedOctree(OccupancyOctree):
    """An octree whose scans go in with a range limit (``max_range=``), in scan mode."""

    def __init__(self, resolution, max_range):
        super().__init__(resolution)
        self._max_range = max_range

    def insert_scan(self, points, origin, **kwargs):
        return super().insert_scan(points, origin, max_range=self._max_range, **kwargs)


def mapping_methods(resolution: float) -> dict:
    """Every mapping method of ``occgp demo``, as name → factory of an empty map.

    The octree and the grid in scan and ray mode, :class:`~occgp.BGKMap`
    ("BGK"), :class:`~occgp.AKIMap` in its two variants ("AKIMap",
    "AKIMap (published)") and :class:`~occgp.KNNMap` ("k-NN", its default
    parameters, with ``sensor_range`` 8 m, the demo scanner's range: it cuts
    no ray, as the octree's unlimited range); the kernel maps use every core
    and AKIMap draws its free samples with ``random_state=0``.

    Parameters
    ----------
    resolution : float
        Cell size of every map, in metres.

    Returns
    -------
    methods : dict of str to callable
        Each factory returns a new, empty map with ``insert_scan(points, origin)``
        and ``occupancy(points)``.
    """
    return {
        "octree (scan)": lambda: OccupancyOctree(resolution),
        "octree (ray)": lambda: _RayModeOctree(resolution),
        "grid (scan)": lambda: GridMap(resolution),
        "grid (ray)": lambda: _RayModeGrid(resolution),
        "BGK": lambda: BGKMap(resolution, n_jobs=-1),
        "AKIMap": lambda: AKIMap(resolution, random_state=0, n_jobs=-1),
        "AKIMap (published)": lambda: AKIMap(resolution, variant="published", random_state=0,
                                             n_jobs=-1),
        "k-NN": lambda: KNNMap(resolution, sensor_range=_DEMO_RANGE),
    }


def noisy_mapping_methods(resolution: float) -> dict:
    """The methods of ``occgp demo``'s noisy-scan table, as name → factory of an empty map.

    "octree (scan), noisy": :class:`~occgp.OccupancyOctree` in scan mode with
    ``max_range`` 8 m, and "k-NN, noisy": :class:`~occgp.KNNMap` (its default
    parameters) with ``sensor_range`` 8 m: both cut the rays that depth noise
    takes past the demo scanner's range at the same length, so the two read
    the same scans alike.

    Parameters
    ----------
    resolution : float
        Cell size of every map, in metres.

    Returns
    -------
    methods : dict of str to callable
        Each factory returns a new, empty map.
    """
    return {
        "octree (scan), noisy": lambda: _RangedOctree(resolution, _DEMO_RANGE),
        "k-NN, noisy": lambda: KNNMap(resolution, sensor_range=_DEMO_RANGE),
    }


def _noisy_scans(scans, *, depth_noise: float, speckle: float, seed: int) -> list:
    """The scans with stereo-like noise (the error model of
    :class:`occgp.datasets.StereoCamera`, on the range ``d``): each point is, with
    probability `speckle`, moved to ``U(0, 1)`` times its range on its ray (an
    outlier between the sensor and the surface), else along its ray by
    ``depth_noise * d**2 * N(0, 1)`` (kept at 0.001 of its range at least, in
    front of the sensor). One generator, ``default_rng([seed, 1])``,
    draws over the scans in order."""
    rng = np.random.default_rng([seed, 1])
    out = []
    for scan in scans:
        points = np.asarray(scan.points, dtype=np.float64)
        origin = np.asarray(scan.origin, dtype=np.float64)
        rays = points - origin
        dist = np.linalg.norm(rays, axis=1)
        n = len(points)
        outlier = rng.random(n) < speckle
        fraction = rng.random(n)
        noise = rng.standard_normal(n)
        scale = np.where(outlier, fraction, np.maximum(1.0 + depth_noise * dist * noise, 1e-3))
        out.append(scan._replace(points=origin + scale[:, None] * rays))
    return out


def gp_mapping_methods(resolution: float) -> dict:
    """The 2D maps of ``occgp demo``'s second table, as name → factory of an unfitted model.

    :class:`~occgp.gp.GPOMIK` (integral kernels, one model for every query)
    and :class:`~occgp.gp.GPOM` (beams cut into free points, a local GP per
    query) with the squared-exponential hyper-parameters their optimisers find
    on :func:`~occgp.datasets.room_2d`, rounded, and the optimiser off
    (``GPOMIK``: variance 1.7, length scale 0.6 m, noise 1e-4; ``GPOM``: 0.66,
    1.0 m, 0.13; as in the gallery's GP example), so that the demo runs in
    seconds; :class:`~occgp.gp.GPMixture` ("GP mixture", line-tracking
    clusters, its own hyper-parameter fit); and the log-odds
    :class:`~occgp.gp.OccupancyGrid` ("log-odds grid") with cells of
    `resolution`. Every model is seeded with ``random_state=0``.

    Parameters
    ----------
    resolution : float
        Cell size of the log-odds grid, in metres.

    Returns
    -------
    methods : dict of str to callable
        Each factory returns a new, unfitted model with
        ``fit(hits, segment_starts, segment_ends)`` and ``predict_proba(X)``.
    """
    from .gp import GPOM, GPOMIK, GPMixture, OccupancyGrid, SquaredExponential

    return {
        "GPOMIK": lambda: GPOMIK(SquaredExponential(1.7, 0.6), noise=1e-4, optimizer=False,
                                 random_state=0),
        "GPOM": lambda: GPOM(SquaredExponential(0.66, 1.0), noise=0.13, optimizer=False,
                             random_state=0),
        "GP mixture": lambda: GPMixture(clustering="line", random_state=0),
        "log-odds grid": lambda: OccupancyGrid(resolution),
    }


class _Proba:
    """A fitted 2D model seen as a map: ``occupancy`` is its ``predict_proba``, NaN
    where a log-odds grid has no evidence; `test_proba` keeps its answer on the test
    points (for the ROC curves)."""

    def __init__(self, model):
        self.model = model
        self.test_proba = None

    def occupancy(self, points):
        p = self.model.predict_proba(points)
        if hasattr(self.model, "is_known"):
            p = np.where(self.model.is_known(points), p, np.nan)
        return p


def _run_gp(name, factory, observations, n_scans, test):
    """Fit one 2D model on all observations at once (timed) and score it (a MapResult)."""
    from .evaluation import MapResult
    from .metrics import score_all

    hits, starts, ends = observations
    model = factory()
    t0 = time.perf_counter()
    model.fit(hits, starts, ends)
    seconds = time.perf_counter() - t0
    answer = _Proba(model)
    answer.test_proba = answer.occupancy(test.points)
    sc = score_all(test.labels, answer.test_proba)
    return MapResult(name, sc["auc"], sc["mse"], sc["acc_occupied"], sc["acc_free"],
                     sc["tpr_fdr_auc"], seconds, n_scans, len(hits) + len(starts),
                     sc["n_test"], sc["unknown_fraction"], 1.0, answer)


# the demo's tables: no "data" column (every method gets all of it), "unknown" added
_DEMO_COLUMNS = ("method", "auc", "mse", "acc_occupied", "acc_free", "tpr_fdr_auc",
                 "unknown_fraction", "seconds")


def demo(outdir: str | Path = "demo_out", *, resolution: float = 0.1, seed: int = 0,
         progress: bool | None = None, out=None) -> list:
    """Map the synthetic rooms with every method and score them against exact ground truth.

    **3D.** The structured room (10 x 7 x 2 m) is scanned like the la3dm data
    set (4 poses x 3 scans x 3500 points, ranges up to 8 m); every method of
    :func:`mapping_methods` maps all the scans. **Protocol:** the test points
    are the centres of the cells of `resolution` that the scans could see
    (:func:`occgp.evaluation.exact_test_set`: within 8 m of a scan's origin,
    in its field of view, in line of sight by exact ray casting), labelled by
    the room's exact geometry (occupied where a solid reaches into the
    cell); cells that no scan could see (inside solids, behind walls, the
    floor below the scanners' lowest ray) are left out, cells in view but
    between the rays are kept, and the free cells are subsampled (seeded) to
    as many as the occupied ones. A map that leaves a cell unknown scores
    p = 0.5 there. Then the same scans get the noise of
    :class:`occgp.datasets.StereoCamera` at its defaults (depth noise
    ``depth_noise * d**2`` along each ray, a fraction `speckle` of outliers
    between the sensor and the surface; seeded by `seed`) and are mapped by
    the methods of :func:`noisy_mapping_methods` (the octree and the k-NN
    map, both cut at 8 m), scored on the same test cells.

    **2D.** :func:`occgp.datasets.room_2d` (22 x 18 m) seen by a 180-degree,
    17-beam, 8 m laser at 26 poses; the models of :func:`gp_mapping_methods`
    are fitted on all its hits and beams at once and scored by the same
    protocol on 2D cells of `resolution`.

    Prints a table for each (AUC, MSE, accuracies, TPR-FDR AUC, the fraction
    of test cells left unknown, and the update or fit time) and writes
    ``map.bt`` (the scan-mode octree of the clean scans), ``slice.png`` (a
    horizontal slice of each 3D map beside the ground truth), ``roc.png``
    (the 3D maps' ROC curves) and ``gp_2d.png`` (the 2D maps beside the
    ground truth, and their ROC curves) to `outdir`.

    Parameters
    ----------
    outdir : str or Path, default="demo_out"
        Folder of the written files; created if missing.
    resolution : float, default=0.1
        Cell size of the maps and of the test cells, in metres.
    seed : int, default=0
        Seed of the scene, the 3D scans, the noise and the test cells'
        subsampling.
    progress : bool or None, default=None
        Show progress bars; None shows them only on a terminal.
    out : file, optional
        Where to print; default ``sys.stdout``.

    Returns
    -------
    rows : list of MapResult
        The rows of :func:`mapping_methods`, then those of
        :func:`noisy_mapping_methods` (names ending in ", noisy"), then those
        of :func:`gp_mapping_methods` (their ``map`` answers ``occupancy``
        with the model's ``predict_proba``).
    """
    from .datasets import StereoCamera, room_2d, structured_room
    from .evaluation import compare_methods, exact_test_set, format_table
    from .gp import observations_from_scans

    out = sys.stdout if out is None else out
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    scene = structured_room(seed=seed)
    scans = scene.scan(max_range=_DEMO_RANGE, seed=seed)
    test = exact_test_set(scene, resolution, scans, max_range=_DEMO_RANGE, seed=seed)
    n_points = sum(len(s.points) for s in scans)
    n_occ = int(test.labels.sum())
    print(f"occgp {__version__} demo: every map scored against the scene's exact ground "
          f"truth\n\n3D: structured room 10 x 7 x 2 m, {len(scans)} scans, {n_points:,} "
          f"points mapped, resolution {resolution:g} m\ntest points: the {resolution:g} m "
          f"cells the scans could see (within {_DEMO_RANGE:g} m, in a field of view, in line "
          f"of sight),\nlabelled by the room (occupied where a solid reaches into the cell): "
          f"{n_occ:,} occupied, {len(test.points) - n_occ:,} free\n(subsampled); cells no "
          f"scan could see are left out; unknown: the fraction of test cells a map\nleaves "
          f"unknown (scored p = 0.5); time: the map's updates", file=out)
    rows = compare_methods(mapping_methods(resolution), scans, test, progress=progress)
    print(format_table(rows, columns=_DEMO_COLUMNS), file=out)

    camera = StereoCamera()
    noisy = _noisy_scans(scans, depth_noise=camera.depth_noise, speckle=camera.speckle,
                         seed=seed)
    print(f"\nnoisy scans: the same scans with stereo-camera noise (depth noise "
          f"{camera.depth_noise:g} m x (range / 1 m)^2,\n{camera.speckle:.0%} speckle outliers "
          f"between sensor and surface), rays cut at {_DEMO_RANGE:g} m, the same test points",
          file=out)
    noisy_rows = compare_methods(noisy_mapping_methods(resolution), noisy, test,
                                 progress=progress)
    print(format_table(noisy_rows, columns=_DEMO_COLUMNS), file=out)
    rows += noisy_rows

    room = room_2d()
    scans_2d = room.scan(n_poses=26, n_beams=17, fov=np.pi, max_range=_DEMO_RANGE)
    observations = observations_from_scans(scans_2d)
    test_2d = exact_test_set(room, resolution, scans_2d, max_range=_DEMO_RANGE, seed=seed)
    n_occ = int(test_2d.labels.sum())
    print(f"\n2D: room 22 x 18 m, {len(scans_2d)} laser scans (180 deg, 17 beams, "
          f"{_DEMO_RANGE:g} m): {len(observations[0])} hits and {len(observations[1])} beams, "
          f"fitted at once\ntest points: the {resolution:g} m cells in view by the same "
          f"protocol, {n_occ:,} occupied, {len(test_2d.points) - n_occ:,} free; time: the "
          f"fit", file=out)
    gp_rows = [_run_gp(name, factory, observations, len(scans_2d), test_2d)
               for name, factory in gp_mapping_methods(resolution).items()]
    print(format_table(gp_rows, columns=_DEMO_COLUMNS), file=out)

    next(r for r in rows if r.method == "octree (scan)").map.save(outdir / "map.bt")
    _plot_slice(rows, scene, scans, outdir / "slice.png")
    _plot_roc(rows, test, outdir / "roc.png")
    _plot_2d(gp_rows, room, scans_2d, test_2d, resolution, outdir / "gp_2d.png")
    print(f"wrote {outdir / 'map.bt'}, {outdir / 'slice.png'}, {outdir / 'roc.png'}, "
          f"{outdir / 'gp_2d.png'}", file=out)
    return rows + gp_rows


def _lattice(lo, hi, res):
    """The centres ``(k + 0.5) * res`` of the map cells inside ``[lo, hi]`` on each axis."""
    return [(np.arange(np.ceil(a / res - 0.5 - 1e-9), np.floor(b / res - 0.5 + 1e-9) + 1)
             + 0.5) * res for a, b in zip(lo, hi)]


def _truth_panel(scene, centres, res, scans):
    """The cells' exact labels (closed-cell rule), NaN where no scan could see them."""
    from ._ground_truth import exact_labels
    from .evaluation import cells_in_view

    truth = exact_labels(scene, centres, res).astype(float)
    truth[~cells_in_view(scene, centres, res, scans, max_range=_DEMO_RANGE)] = np.nan
    return truth


def _plot_slice(rows, scene, scans, path: Path, z: float | None = None) -> None:

    lo, hi = (np.asarray(b, dtype=float) for b in scene.bounds)
    res = rows[0].map.resolution
    if z is None:   # the cell layer holding the mean sensor height: the best observed plane
        z = (np.floor(np.mean([s.origin[2] for s in scans]) / res + 1e-9) + 0.5) * res
    xs, ys = _lattice(lo[:2], hi[:2], res)
    gx, gy = np.meshgrid(xs, ys)
    q = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, z)])
    panels = [("ground truth (grey: not in view)",
               _truth_panel(scene, q, res, scans).reshape(gx.shape))]
    panels += [(r.method, r.map.occupancy(q).reshape(gx.shape)) for r in rows]
    extent = (xs[0] - res / 2, xs[-1] + res / 2, ys[0] - res / 2, ys[-1] + res / 2)
    fig, axes = _panels(panels, extent, (4.2, 3.6))
    for s in scans:
        axes[0, 0].plot(*s.origin[:2], "r^", ms=6)
    fig.suptitle(f"horizontal slice at z = {z:.2f} m")
    fig.savefig(path, dpi=110)


def _panels(panels, extent, size, extra=0):
    """A figure of p(occupied) images, up to 4 in a row, `extra` empty axes after them."""
    from matplotlib.figure import Figure

    n = len(panels) + extra
    nrows = -(-n // 4)
    ncols = -(-n // nrows)
    fig = Figure(figsize=(size[0] * ncols, size[1] * nrows), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False)
    cmap = _cmap()
    for ax in axes.flat[n:]:
        ax.set_axis_off()
    for ax, (title, img) in zip(axes.flat, panels):
        im = ax.imshow(img, origin="lower", extent=extent, cmap=cmap, vmin=0, vmax=1,
                       interpolation="nearest")
        ax.set_title(title)
        ax.set_xlabel("x [m]")
        ax.set_aspect("equal")
    for ax in axes[:, 0]:
        ax.set_ylabel("y [m]")
    fig.colorbar(im, ax=axes, shrink=0.8 / nrows ** 0.5,
                 label="p(occupied); grey: unknown")
    return fig, axes


def _cmap():
    from matplotlib import colormaps

    return colormaps["viridis"].with_extremes(bad="0.75")


def _roc_axes(ax, rows, test, title):
    from .metrics import roc_curve

    for r in rows:
        proba = getattr(r.map, "test_proba", None)
        proba = r.map.occupancy(test.points) if proba is None else proba
        fpr, tpr, _ = roc_curve(test.labels, proba)
        ax.plot(fpr, tpr, label=f"{r.method} (AUC {r.auc:.3f})")
    ax.plot([0, 1], [0, 1], "k:", lw=0.8)
    ax.set_xlabel("false positive rate")
    ax.set_ylabel("true positive rate")
    ax.set_title(title)
    ax.legend(loc="lower right", fontsize="small")


def _plot_roc(rows, test, path: Path) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(5.2, 4.8), layout="constrained")
    _roc_axes(fig.subplots(), rows, test, "ROC on the cells in view (exact ground truth)")
    fig.savefig(path, dpi=110)


def _plot_2d(rows, room, scans, test, resolution, path: Path) -> None:
    """The 2D maps on cells of `resolution` (0.25 m at least, for speed) over the room,
    beside the ground truth, and their ROC curves."""
    lo, hi = (np.asarray(b, dtype=float) for b in room.bounds)
    res = max(resolution, 0.25)
    xs, ys = _lattice(lo, hi, res)
    gx, gy = np.meshgrid(xs, ys)
    q = np.column_stack([gx.ravel(), gy.ravel()])
    panels = [("ground truth (grey: not in view)",
               _truth_panel(room, q, res, scans).reshape(gx.shape))]
    panels += [(r.method, r.map.occupancy(q).reshape(gx.shape)) for r in rows]
    extent = (xs[0] - res / 2, xs[-1] + res / 2, ys[0] - res / 2, ys[-1] + res / 2)
    fig, axes = _panels(panels, extent, (4.4, 3.8), extra=1)
    axes[0, 0].plot(*np.array([s.origin for s in scans]).T, "r.", ms=3)
    _roc_axes(axes.flat[len(panels)], rows, test, "ROC on the 2D cells in view")
    axes.flat[len(panels)].set_aspect("auto")
    fig.suptitle(f"2D room: GP maps, cells of {res:g} m")
    fig.savefig(path, dpi=110)


def _check_knn_options(knn_params) -> dict:
    """KNNMap's defaults updated by `knn_params`, checked (see :func:`map_scans`)."""
    if not isinstance(knn_params, Mapping):
        raise TypeError(f"knn_params must be a mapping of KNNMap parameters, "
                        f"got {type(knn_params).__name__}")
    unknown = sorted(set(knn_params) - set(_KNN_OPTIONS), key=str)
    if unknown:
        raise ValueError(f"knn_params holds {unknown}, which KNNMap does not take; it takes "
                         f"{list(_KNN_OPTIONS)}")
    params = {**_KNN_DEFAULTS, **knn_params}
    cdf = params.pop("cdf")
    if not isinstance(cdf, str) or cdf not in CDFS:
        raise ValueError(f"cdf must be one of {CDFS}, got {cdf!r}")
    return {**check_knn_params(params), "cdf": cdf}

class _OptionError(ValueError):
    """A ValueError about one argument of :func:`map_scans` (its name in `param`);
    ``occgp map`` reports it as a usage error of the matching option (exit code 2)."""

    def __init__(self, param: str, message: str) -> None:
        super().__init__(message)
        self.param = param


# the option of each map_scans argument an _OptionError can name
_OPTION_OF = {"output": "-o/--output", "method": "--method", "mode": "--mode",
              "resolution": "--resolution", "max_range": "--max-range", "n_jobs": "--n-jobs",
              "poses": "--poses", "poses_format": "--poses-format", "topic": "--topic",
              "fixed_frame": "--fixed-frame", "sensor_frame": "--sensor-frame",
              "tf_tolerance": "--tf-tolerance", "input_map": "--input-map",
              "fields": "--fields", "paths": "scans"}
_KERNEL_METHODS = ("bgk", "akimap")
_POSE_FORMATS = ("kitti", "tum")
# the output suffixes of each method, and the saved maps --input-map takes
_OUTPUTS = {"octree": (".bt", ".ot", ".ply", ".pcd"), "knn": (".bt", ".ot", ".ply", ".pcd"),
            "bgk": (".bt", ".ot", ".ply", ".pcd", ".npz"),
            "akimap": (".bt", ".ot", ".ply", ".pcd", ".npz")}
_INPUT_MAPS = {"octree": (".bt", ".ot"), "knn": (".bt", ".ot"), "bgk": (".npz",),
               "akimap": (".npz",)}
_BAG_SUFFIXES = (".bag", ".db3", ".mcap")
# whether the octree's insert_scan takes n_jobs (threaded ray counting)
_OCTREE_N_JOBS = "n_jobs" in inspect.signature(OccupancyOctree.insert_scan).parameters


def _is_bag(path) -> bool:
    """Whether `path` is read with read_rosbag: a ``.bag`` / ``.db3`` / ``.mcap`` file or
    a ROS 2 bag folder (one holding ``metadata.yaml``)."""
    path = Path(path)
    if path.is_dir():
        return (path / "metadata.yaml").is_file()
    return path.suffix.lower() in _BAG_SUFFIXES


def _suffix(path: Path) -> str:
    return path.suffix.lower()


def _read_poses(path, poses_format):
    """The (n, 4, 4) poses of a KITTI or TUM file; the format guessed from the first
    line's column count when `poses_format` is None."""
    from .datasets import read_kitti_poses, read_tum_trajectory
    from .datasets._fileio import read_maybe_compressed

    if poses_format is None:
        try:
            text = read_maybe_compressed(path).decode("utf-8")
        except UnicodeDecodeError:
            raise ValueError(f"{path}: not a text file (invalid UTF-8)") from None
        first = next(((i, line.split("#", 1)[0].split())
                      for i, line in enumerate(text.splitlines(), start=1)
                      if line.split("#", 1)[0].split()), None)
        if first is None:
            raise _OptionError("poses", f"poses file {str(path)!r} holds no poses")
        n = len(first[1])
        if n not in (12, 8):
            raise _OptionError("poses", f"cannot tell the format of poses file {str(path)!r}: "
                               f"line {first[0]} has {n} columns; expected 12 (kitti: a 3x4 "
                               f"row-major pose) or 8 (tum: t x y z qx qy qz qw); pass "
                               f"poses_format")
        poses_format = "kitti" if n == 12 else "tum"
    if poses_format == "kitti":
        return read_kitti_poses(path)
    return read_tum_trajectory(path)[1]


def _check_map_args(paths, output, method, mode, resolution, max_range, knn_params, n_jobs,
                    poses, poses_format, bag_options,
                    input_map) -> tuple[Path, float | None, float | None, int | None,
                                        Path | None]:
    """Check map_scans' arguments before anything is read; return (output, resolution,
    max_range, n_jobs, input_map) as used."""
    if method not in _MAP_METHODS:
        raise _OptionError("method", f"method must be one of {_MAP_METHODS}, got {method!r}")
    output = Path(output)
    fits = _OUTPUTS[method]
    if _suffix(output) not in fits:
        note = " (.npz: bgk and akimap only)" if _suffix(output) == ".npz" else ""
        raise _OptionError("output", f"output must end in {', '.join(fits[:-1])} or "
                           f"{fits[-1]} for method={method!r}{note}, got {str(output)!r}")
    if not output.parent.is_dir():
        raise FileNotFoundError(errno.ENOENT, "output: no such folder for the map file",
                                str(output.parent))
    if mode is not None and method != "octree":
        raise _OptionError("mode", f"mode applies to method='octree' only, got mode={mode!r} "
                           f"with method={method!r}")
    if mode is not None and mode not in ("scan", "ray"):
        raise _OptionError("mode", f"mode must be 'scan' or 'ray', got {mode!r}")
    if knn_params is not None and method != "knn":
        raise ValueError(f"knn_params applies to method='knn' only, got method={method!r}")
    if max_range is not None and method == "knn":
        raise _OptionError("max_range", f"max_range does not apply to method='knn': its range "
                           f"limit is knn_params['sensor_range'] (default "
                           f"{_KNN_DEFAULTS['sensor_range']} m), got max_range={max_range!r}")
    try:
        if max_range is not None:
            max_range = check_real(max_range, "max_range", low=0.0)
    except ValueError as exc:
        raise _OptionError("max_range", str(exc)) from None
    if resolution is not None:
        try:
            resolution = check_resolution(resolution)
        except ValueError as exc:
            raise _OptionError("resolution", str(exc)) from None
    try:
        n_jobs = check_n_jobs(n_jobs)
    except ValueError as exc:
        raise _OptionError("n_jobs", str(exc)) from None
    if poses_format is not None:
        if poses is None:
            raise _OptionError("poses_format", f"poses_format applies with poses only, got "
                               f"poses_format={poses_format!r} and no poses")
        if poses_format not in _POSE_FORMATS:
            raise _OptionError("poses_format", f"poses_format must be one of {_POSE_FORMATS} "
                               f"or None (guess from the columns), got {poses_format!r}")
    if isinstance(paths, (str, bytes)) or not len(paths):
        raise _OptionError("paths", f"paths must be a non-empty sequence of scan files or "
                           f"folders, got {paths!r}")
    try:
        check_real(bag_options["tf_tolerance"], "tf_tolerance", low=0.0, high=1e9,
                   low_open=False)
    except ValueError as exc:
        raise _OptionError("tf_tolerance", str(exc)) from None
    given = {k: v for k, v in bag_options.items() if v not in (None, 0.0)}
    if given and not any(_is_bag(p) for p in paths):
        name = next(iter(given))
        raise _OptionError(name, f"{name} applies to ROS bag inputs only (.bag, .db3, .mcap "
                           f"files or ROS 2 bag folders), and none is among the scans")
    if input_map is not None:
        input_map = Path(input_map)
        if _suffix(input_map) not in _INPUT_MAPS[method]:
            kinds = " or ".join(_INPUT_MAPS[method])
            raise _OptionError("input_map", f"input_map must be a {kinds} file to continue a "
                               f"{method} map, got {str(input_map)!r}")
    return output, resolution, max_range, n_jobs, input_map


def _new_map(method, resolution, max_range, knn, n_jobs, input_map):
    """The map to insert into: loaded from `input_map` or new."""
    if input_map is None:
        res = 0.1 if resolution is None else resolution
        if method == "octree":
            return OccupancyOctree(res)
        if method == "knn":
            return KNNMap(res, **knn, n_jobs=n_jobs)
        if method == "bgk":
            return BGKMap(res, n_jobs=n_jobs) if max_range is None else \
                BGKMap(res, max_range=max_range, n_jobs=n_jobs)
        return AKIMap(res, random_state=0, n_jobs=n_jobs)
    cls = {"octree": OccupancyOctree, "knn": KNNMap, "bgk": BGKMap, "akimap": AKIMap}[method]
    try:
        mapper = cls.load(input_map, **knn, n_jobs=n_jobs) if method == "knn" else \
            cls.load(input_map)
    except ValueError as exc:
        raise ValueError(f"input_map: cannot continue it as a {method} map: {exc}") from None
    if resolution is not None and resolution != mapper.resolution:
        raise _OptionError("resolution", f"resolution {resolution:g} differs from that of "
                           f"input_map {str(input_map)!r} ({mapper.resolution:g}); leave it "
                           f"out to continue the map at its own")
    if method in _KERNEL_METHODS:
        mapper.n_jobs = n_jobs
        if method == "bgk" and max_range is not None:
            mapper.max_range = max_range
    return mapper


def map_scans(paths, output: str | Path, *, resolution: float | None = None,
              method: str = "octree", mode: str | None = None,
              max_range: float | None = None, knn_params: Mapping[str, Any] | None = None,
              poses: str | Path | None = None, poses_format: str | None = None,
              topic: str | None = None, fixed_frame: str | None = None,
              sensor_frame: str | None = None, tf_tolerance: float = 0.0, fields=None,
              input_map: str | Path | None = None, n_jobs: int | None = -1,
              progress: bool | None = None, out=None):
    """Build a map from scan files and ROS bags and save it.

    Every step (loading `input_map`, reading each scan file, inserting each
    scan, converting a kernel map to an octree, saving) advances one progress
    bar. At the end one line gives the scans, points, cells, the insertion
    time and the wall time of the whole call; lines before it say how many
    points were dropped (non-finite points of bags) or cut at the range
    limit.

    Parameters
    ----------
    paths : sequence of str or path-like
        Scan files or folders, read with :func:`occgp.datasets.read_scans`,
        and ROS bags (a ``.bag``, ``.db3`` or ``.mcap`` file, or a ROS 2 bag
        folder holding ``metadata.yaml``), read with
        :func:`occgp.datasets.read_rosbag`. Scans go in in this order.
    output : str or path-like
        The map file; its suffix gives the format: ``.bt`` / ``.ot``
        (OctoMap), ``.ply`` / ``.pcd`` (the occupied cells, see
        :meth:`~occgp.OccupancyOctree.save_ply` /
        :meth:`~occgp.OccupancyOctree.save_pcd`) or, for ``method="bgk"`` and
        ``"akimap"`` only, ``.npz`` (the kernel map with its evidence, see
        :meth:`~occgp.BGKMap.save`). A kernel map goes to the other formats
        through its ``to_octree()``: each cell holds its posterior mean as
        log-odds (a ``.bt`` file keeps only whether it is above 0.5); cells
        no kernel reached stay unknown.
    resolution : float, default=None
        Cell size in metres; None means 0.1, or the resolution of
        `input_map` (which a value given must equal).
    method : {"octree", "bgk", "akimap", "knn"}, default="octree"
        The map: :class:`~occgp.OccupancyOctree`, :class:`~occgp.BGKMap`,
        :class:`~occgp.AKIMap` (``random_state=0``) or :class:`~occgp.KNNMap`
        (an octree, written as it is).
    mode : {"scan", "ray"}, default=None
        The octree's update mode (None: ``"scan"``); only for ``method="octree"``.
    max_range : float, default=None
        Range limit in metres; None means none (and BGKMap's own 8 m for
        ``method="bgk"``; a loaded BGK map keeps its own). The octree inserts
        longer beams up to `max_range` as free space only; BGK drops them
        whole (its ``max_range``); AKIMap gets only the end points within
        `max_range` of the sensor. Not for ``method="knn"``, whose range
        limit is its ``sensor_range`` (in `knn_params`). The points beyond
        the limit are counted and reported (raw points: BGK applies its
        limit to the centroids of its down-sampling cubes).
    knn_params : mapping, default=None
        For ``method="knn"`` only: :class:`~occgp.KNNMap`'s ``k``, ``p_u``,
        ``p_l``, ``p_m``, ``p_m_out``, ``p_min``, ``p_max``, ``p_t``,
        ``sensor_range`` and ``cdf``; those left out take KNNMap's defaults
        (``sensor_range`` 4 m: points farther from the sensor are not
        inserted, their rays are cut there). Checked as KNNMap checks them
        (Miao et al.'s Eq. 12) before any scan is read.
    poses : str or path-like, default=None
        A trajectory file: KITTI odometry poses (12 numbers a line, a 3 x 4
        row-major sensor-to-world pose) or TUM (``t x y z qx qy qz qw``).
        Pose ``i`` moves scan ``i`` (in input order, over all `paths`) with
        :func:`occgp.datasets.apply_poses`; the file must hold one pose per
        scan. TUM timestamps are not matched to scans, only the order counts.
    poses_format : {"kitti", "tum"}, default=None
        The format of `poses`; None guesses it from the first line's columns
        (12: kitti, 8: tum).
    topic, fixed_frame, sensor_frame, tf_tolerance
        For ROS bags only, passed to :func:`occgp.datasets.read_rosbag`
        (defaults: the only PointCloud2 topic, the root of the TF tree, the
        cloud's frame, 0 s).
    fields : int, str or numpy.dtype, default=None
        Record layout of ``.bin`` scan files, passed to
        :func:`occgp.datasets.read_scans` (None: by file name).
    input_map : str or path-like, default=None
        A saved map to continue: ``.bt`` / ``.ot`` for ``method="octree"``
        and ``"knn"`` (the k-NN parameters then come from `knn_params`),
        ``.npz`` (written by ``save``) for ``"bgk"`` and ``"akimap"``, which
        must hold a map of that class. The scans are inserted into it.
    n_jobs : int, default=-1
        Threads of BGKMap, AKIMap and KNNMap (and of the octree's
        ``insert_scan`` where it takes ``n_jobs``): -1 every core, None or 1
        one. The map does not depend on it.
    progress : bool, default=None
        Show a progress bar (None: only on a terminal).
    out : file-like, default=None
        Where the summary lines go (None: standard output).

    Returns
    -------
    map : OccupancyOctree, BGKMap, AKIMap or KNNMap
        The map built.

    Raises
    ------
    ValueError
        If `output` has a suffix other than those above or one that does not
        fit `method`; `method` or `mode` is not one of the choices (or `mode`
        is given with another method than the octree); `max_range` or
        `resolution` is not positive, or `max_range` is given with
        ``method="knn"``; `n_jobs` is 0; `knn_params` is given with another
        method, names a parameter KNNMap does not take or holds a value
        KNNMap rejects; `poses_format` is given without `poses` or is not a
        choice; the format of `poses` cannot be guessed, or it does not hold
        one pose per scan; a bag option is given and no bag is among `paths`;
        `input_map` does not fit `method`, holds another class of map, or its
        resolution differs from `resolution`; a file is malformed; or no scan
        is found. The arguments are checked before any file is read; the pose
        count and `input_map` before any scan is inserted. Nothing is written
        when an error is raised.
    TypeError
        If `max_range`, `resolution` or `tf_tolerance` is not a real number,
        `knn_params` is not a mapping or holds a value of the wrong type.
    OSError
        If a scan, pose or map file cannot be read, the folder of `output`
        does not exist (checked first) or the output cannot be written.
    ImportError
        If a bag is given and the ``rosbags`` package is not installed.
    """
    from tqdm.auto import tqdm

    from .datasets import apply_poses, read_rosbag, read_scans

    t_start = time.perf_counter()
    out = sys.stdout if out is None else out
    bag_options = {"topic": topic, "fixed_frame": fixed_frame, "sensor_frame": sensor_frame,
                   "tf_tolerance": tf_tolerance}
    output_path, resolution, max_range, n_jobs, input_path = _check_map_args(
        paths, output, method, mode, resolution, max_range, knn_params, n_jobs, poses,
        poses_format, bag_options, input_map)
    knn = _check_knn_options({} if knn_params is None else knn_params) \
        if method == "knn" else {}
    pose_array = None if poses is None else _read_poses(poses, poses_format)
    convert = method in _KERNEL_METHODS and _suffix(output_path) != ".npz"
    bar = tqdm(total=(input_path is not None) + len(paths) + convert + 1, unit="step",
               disable=None if progress is None else not progress)
    try:
        if input_path is not None:
            bar.set_description(f"loading {input_path.name}")
        mapper: Any = _new_map(method, resolution, max_range, knn, n_jobs, input_path)
        if input_path is not None:
            bar.update()
        sources = []
        for path in paths:
            bar.set_description(f"reading {Path(path).name}")
            if _is_bag(path):
                source = read_rosbag(path, topic, fixed_frame=fixed_frame,
                                     sensor_frame=sensor_frame, tf_tolerance=tf_tolerance)
            else:
                source = read_scans(path, fields=fields)
            sources.append(source)
            bar.total += len(source)
            bar.update()
        n_scans = sum(len(s) for s in sources)
        if not n_scans:
            raise ValueError("no scans found in " + ", ".join(map(str, paths)))
        if pose_array is not None and len(pose_array) != n_scans:
            raise _OptionError("poses", f"poses file {str(poses)!r} holds {len(pose_array)} "
                               f"poses for {n_scans} scans; expected one pose per scan, in "
                               f"input order")
        insert, limit = _inserter(mapper, method, mode, max_range, n_jobs)
        n_points = n_beyond = n_done = 0
        beams = np.zeros(2, dtype=np.int64)     # BGK's (kept, dropped) beams
        dropped = []
        t0 = time.perf_counter()
        bar.set_description("inserting scans")
        for path, source in zip(paths, sources):
            for scan in source:
                if pose_array is not None:
                    scan = apply_poses([scan], pose_array[n_done:n_done + 1])[0]
                points = scan.points
                n_points += len(points)
                if limit is not None and len(points):
                    far = np.linalg.norm(np.asarray(points, dtype=np.float64)
                                         - np.asarray(scan.origin, dtype=np.float64),
                                         axis=1) > limit
                    n_beyond += int(np.count_nonzero(far))
                    if method == "akimap":
                        points = points[~far]
                insert(points, scan.origin)
                if method == "bgk":
                    beams += mapper.last_beams_
                n_done += 1
                bar.update()
            if getattr(source, "n_dropped", 0):
                dropped.append((path, source.n_dropped, source.n_points))
        seconds = time.perf_counter() - t0
        tree = mapper
        if convert:
            bar.set_description("converting to an octree")
            tree = mapper.to_octree()
            bar.update()
        bar.set_description(f"writing {output_path.name}")
        _save(mapper, tree, output_path)
        bar.update()
    finally:
        bar.close()
    wall = time.perf_counter() - t_start
    for path, n, total in dropped:
        print(f"dropped {n:,} of {total:,} points of {path} with a NaN or inf coordinate",
              file=out)
    if limit is not None and n_beyond:
        print(_beyond_message(method, n_beyond, n_points, limit, beams), file=out)
    if method in ("octree", "knn"):
        built = f"{mapper.num_leaves:,} leaves"
    elif convert:
        built = f"{mapper.num_cells:,} cells ({tree.num_leaves:,} octree leaves)"
    else:
        built = f"{mapper.num_cells:,} cells"
    start = f"{input_path} + " if input_path is not None else ""
    print(f"{start}{n_scans} scans, {n_points:,} points → {built}; inserted in "
          f"{seconds:.2f} s, wall time {wall:.2f} s; wrote {output_path}", file=out)
    return mapper


def _inserter(mapper, method, mode, max_range, n_jobs):
    """(insert(points, origin), the range limit whose points are counted, or None)."""
    if method == "octree":
        kwargs = {"max_range": max_range, "mode": "scan" if mode is None else mode}
        if _OCTREE_N_JOBS:
            kwargs["n_jobs"] = n_jobs

        def insert(points, origin):
            mapper.insert_scan(points, origin, **kwargs)
        return insert, max_range
    if method == "knn":
        return mapper.insert_scan, mapper.sensor_range
    if method == "bgk":
        return mapper.update, mapper.max_range
    return mapper.update, max_range


def _beyond_message(method, n, total, limit, beams) -> str:
    where = f"{n:,} of {total:,} points lie beyond"
    if method == "octree":
        return f"{where} max_range {limit:g} m: their rays were cut there (free space only)"
    if method == "knn":
        return (f"{where} sensor_range {limit:g} m: not inserted, their rays were cut "
                f"there")
    if method == "bgk":
        kept, dropped = (int(b) for b in beams)
        return (f"{where} max_range {limit:g} m: BGK dropped {dropped:,} of its "
                f"{kept + dropped:,} beams (to the end points' centroids per cube of "
                f"ds_resolution) beyond it")
    return f"{where} max_range {limit:g} m: dropped (AKIMap got only the nearer ones)"


def _save(mapper, tree, output: Path) -> None:
    suffix = _suffix(output)
    if suffix == ".npz":
        mapper.save(output)
    elif suffix == ".ply":
        tree.save_ply(output)
    elif suffix == ".pcd":
        tree.save_pcd(output)
    else:
        tree.save(output, format=suffix[1:])


def _option(name: str) -> str:
    """The command-line option of a KNNMap parameter: ``p_m_out`` → ``--p-m-out``."""
    return "--" + name.replace("_", "-")


def _knn_error(parser: argparse.ArgumentParser, exc: Exception) -> None:
    """parser.error for a rejected k-NN option, naming the options the message names."""
    message = str(exc)
    named = sorted({m.start(): m.group(1) for m in re.finditer(
        r"(?<![\w-])(" + "|".join(sorted(_KNN_OPTIONS, key=len, reverse=True)) + r")(?![\w-])",
        message)}.items())
    options = "/".join(dict.fromkeys(_option(name) for _, name in named)) or "k-NN options"
    parser.error(f"argument {options}: {message}")


_FIELD_NAMES = ("kitti", "nuscenes")


def _fields(text: str):
    """--fields: an int (float32 values per record), "kitti" / "nuscenes", or a record
    layout ``name:dtype,...`` (e.g. ``x:<f8,y:<f8,z:<f8,t:<u4``)."""
    text = text.strip()
    if text.isdigit():
        return int(text)
    if text in _FIELD_NAMES:
        return text
    try:
        items = [item.split(":") for item in text.split(",")]
        if not all(len(item) == 2 and item[0] for item in items):
            raise ValueError
        return np.dtype([(name.strip(), np.dtype(kind.strip())) for name, kind in items])
    except (TypeError, ValueError):
        raise argparse.ArgumentTypeError(
            f"expected an int (float32 values per record), kitti, nuscenes or name:dtype,... "
            f"(e.g. x:<f4,y:<f4,z:<f4,t:<u4), got {text[:60]!r}") from None


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="occgp", description="Occupancy mapping from range "
                                     "sensors: OctoMap octrees, kernel, k-NN and GP maps.")
    parser.add_argument("--version", action="version", version=f"occgp {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("demo", help="map the synthetic structured room with every method "
                       "(and noisy scans of it with the octree and the k-NN map), print "
                       "scores, write map.bt and figures")
    p.add_argument("-o", "--output", default="demo_out", help="output folder (default: %(default)s)")
    p.add_argument("--resolution", type=float, default=0.1,
                   help="cell size in metres (default: %(default)s)")
    p.add_argument("--seed", type=int, default=0,
                   help="seed of the scene, scans and noise (default: %(default)s)")
    p.add_argument("--no-progress", action="store_true",
                   help="no progress bars (default: shown on a terminal)")

    p = sub.add_parser("map", help="build a map from scan files (.pcd, .bin, .pcd.bin, "
                       ".graph, x y z text, a folder of them) and ROS bags, and write it as "
                       "an OctoMap file, PLY / PCD cells or a kernel map's .npz",
                       description="Build a map from scan files and ROS bags (PointCloud2 "
                       "posed by TF) and write it.")
    p.set_defaults(map_parser=p)
    p.add_argument("scans", nargs="+", help="scan files or folders (.pcd, .bin, .pcd.bin, "
                   ".graph, .xyz/.txt, ...) and ROS bags (.bag, .db3, .mcap, a ROS 2 bag "
                   "folder), inserted in this order")
    p.add_argument("-o", "--output", required=True,
                   help="the map file, format by suffix: .bt/.ot (OctoMap), .ply/.pcd (the "
                   "occupied cells), .npz (bgk/akimap only: the kernel map with its "
                   "evidence, for --input-map); required, no default")
    p.add_argument("--resolution", type=float, default=None,
                   help="cell size in metres (default: 0.1, or the --input-map's)")
    p.add_argument("--method", choices=_MAP_METHODS, default="octree",
                   help="octree: OctoMap log-odds; bgk: BGK kernel inference; akimap: "
                   "adaptive kernel inference; knn: the k-NN inverse sensor model on the "
                   "octree; a kernel map is written to .bt/.ot/.ply/.pcd as an octree of its "
                   "posterior means (default: %(default)s)")
    p.add_argument("--mode", choices=["scan", "ray"], default=None,
                   help="the octree's update mode (default: scan; --method octree only)")
    p.add_argument("--max-range", type=float, default=None,
                   help="range limit in metres: octree: longer beams are free space up to "
                   "it (default: no limit); bgk: longer beams are dropped (default: 8, or the "
                   "--input-map's); akimap: end points farther from the sensor are dropped "
                   "(default: no limit); not with knn, whose range limit is --sensor-range")
    p.add_argument("--n-jobs", type=int, default=-1,
                   help="threads of bgk, akimap and knn" + (" and the octree" if _OCTREE_N_JOBS
                                                            else "") +
                   "; -1: every core; the map does not depend on it (default: %(default)s)")
    p.add_argument("--input-map", default=None, metavar="PATH",
                   help="continue a saved map: .bt/.ot for octree and knn, .npz (written by "
                   "-o X.npz) for bgk and akimap; the scans are inserted into it "
                   "(default: a new map)")
    p.add_argument("--no-progress", action="store_true",
                   help="no progress bar (default: shown on a terminal)")
    g = p.add_argument_group("poses and record layouts")
    g.add_argument("--poses", default=None, metavar="FILE",
                   help="sensor-to-world poses, one per scan in input order: KITTI poses.txt "
                   "(3x4 row-major) or TUM (t x y z qx qy qz qw; timestamps not matched) "
                   "(default: none, the scans are in the world frame)")
    g.add_argument("--poses-format", choices=_POSE_FORMATS, default=None,
                   help="format of --poses (default: guessed from the columns: 12 kitti, "
                   "8 tum)")
    g.add_argument("--fields", type=_fields, default=None,
                   help="record layout of .bin scans: an int (float32 values per record, x y "
                   "z first), kitti, nuscenes, or name:dtype,... such as x:<f4,y:<f4,z:<f4,"
                   "t:<u4 (default: by file name: nuscenes for .pcd.bin, else kitti)")
    g = p.add_argument_group("ROS bags (PointCloud2 messages posed by /tf and /tf_static)")
    g.add_argument("--topic", default=None,
                   help="the PointCloud2 topic (default: the bag's only one)")
    g.add_argument("--fixed-frame", default=None,
                   help="the world frame of the map (default: the root of the TF tree)")
    g.add_argument("--sensor-frame", default=None,
                   help="the frame whose origin is the sensor position (default: the "
                   "cloud's header.frame_id)")
    g.add_argument("--tf-tolerance", type=float, default=0.0,
                   help="seconds a cloud stamp may lie outside a TF edge's stamps "
                   "(default: %(default)s)")
    g = p.add_argument_group("k-NN inverse sensor model (--method knn only; defaults: "
                             "KNNMap's)")
    d = _KNN_DEFAULTS
    g.add_argument("--k", type=int, default=None,
                   help=f"nearest neighbours scoring each point, in [1, 1000] "
                   f"(default: {d['k']})")
    g.add_argument("--sensor-range", type=float, default=None,
                   help=f"range s_c in metres: farther points are not inserted and their "
                   f"rays are cut here, as --max-range cuts the octree's "
                   f"(default: {d['sensor_range']})")
    g.add_argument("--p-u", type=float, default=None,
                   help=f"probability of the best-supported points (default: {d['p_u']})")
    g.add_argument("--p-l", type=float, default=None,
                   help=f"probability of the most isolated points, <= --p-u "
                   f"(default: {d['p_l']})")
    g.add_argument("--p-m", type=float, default=None,
                   help=f"miss probability of cells on rays to points within range, "
                   f">= --p-min (default: {d['p_m']})")
    g.add_argument("--p-m-out", type=float, default=None,
                   help=f"miss probability of cells only on rays cut at the range, "
                   f"in [--p-m, 0.5) (default: {d['p_m_out']})")
    g.add_argument("--p-min", type=float, default=None,
                   help=f"lower clamping bound (default: {d['p_min']})")
    g.add_argument("--p-max", type=float, default=None,
                   help=f"upper clamping bound, < 1 (default: {d['p_max']})")
    g.add_argument("--p-t", type=float, default=None,
                   help=f"occupancy threshold, in [--p-min, --p-max] (default: {d['p_t']})")
    g.add_argument("--cdf", choices=CDFS, default=None,
                   help=f"the CDF of the scores: normal (the paper's) or truncated at 0 "
                   f"(default: {d['cdf']})")
    return parser


def _knn_args(args) -> dict | None:
    """The k-NN options given on the command line (None: none), checked; exits with
    parser.error (code 2) on a bad one or one given with another method."""
    parser = args.map_parser
    given = {name: getattr(args, name) for name in _KNN_OPTIONS
             if getattr(args, name) is not None}
    if args.method != "knn":
        if given:
            parser.error(f"argument {'/'.join(map(_option, given))}: applies to --method "
                         f"knn only, got --method {args.method}")
        return None
    if args.max_range is not None:
        parser.error(f"argument --max-range: not with --method knn, whose range limit is "
                     f"--sensor-range (default: {_KNN_DEFAULTS['sensor_range']}); it cuts "
                     f"rays as --max-range does for the octree")
    try:
        _check_knn_options(given)
    except (ValueError, TypeError) as exc:
        _knn_error(parser, exc)
    return given


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    progress = False if args.no_progress else None
    knn_params = _knn_args(args) if args.command == "map" else None
    try:
        if args.command == "demo":
            demo(args.output, resolution=args.resolution, seed=args.seed, progress=progress)
        else:
            map_scans(args.scans, args.output, resolution=args.resolution,
                      method=args.method, mode=args.mode, max_range=args.max_range,
                      knn_params=knn_params, poses=args.poses, poses_format=args.poses_format,
                      topic=args.topic, fixed_frame=args.fixed_frame,
                      sensor_frame=args.sensor_frame, tf_tolerance=args.tf_tolerance,
                      fields=args.fields, input_map=args.input_map, n_jobs=args.n_jobs,
                      progress=progress)
    except _OptionError as exc:
        args.map_parser.error(f"argument {_OPTION_OF.get(exc.param, exc.param)}: {exc}")
    except (ValueError, TypeError, OSError, ImportError) as exc:
        print(f"occgp {args.command}: error: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
