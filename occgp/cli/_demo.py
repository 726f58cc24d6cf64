"""``occgp demo``: every mapping method on synthetic scenes, scored against their exact
ground truth (:func:`demo`; re-exported by :mod:`occgp.cli`).

The 3D methods (:func:`mapping_methods`) map the structured room's scans, the octree
and the k-NN map (:func:`noisy_mapping_methods`) clouds of rendered stereo pairs matched
by StereoSGBM (:func:`stereo_scans_of_scene`), and the 2D GP
maps (:func:`gp_mapping_methods`) the 2D room's laser scans; each table is scored on
:func:`occgp.evaluation.exact_test_set`, the cells the scans could see.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from .. import __version__
from .._atomic import atomic_open

__all__ = ["demo", "mapping_methods", "noisy_mapping_methods", "gp_mapping_methods",
           "stereo_scans_of_scene"]

# the demo's scanner range (Scene.scan's max_range): every return lies within it, so
# the k-NN map's max_range of that length cuts no clean ray
_DEMO_RANGE = 8.0


def mapping_methods(resolution: float) -> dict:
    """Every mapping method of ``occgp demo``, as name → registered map and parameters.

    The octree and the grid in scan and ray mode, :class:`~occgp.BGKMap`
    ("BGK"), :class:`~occgp.AKIMap` in its two variants ("AKIMap",
    "AKIMap (published)", with ``schedule_range`` 8 m, the demo scanner's range,
    where its search radius is widest) and :class:`~occgp.KNNMap` ("k-NN", its
    default parameters, with ``max_range`` 8 m: it cuts no ray, as the
    octree's unlimited range); the kernel maps use every core and AKIMap
    draws its free samples with ``random_state=0``.

    Parameters
    ----------
    resolution : float
        Cell size of every map, in metres.

    Returns
    -------
    methods : dict of str to dict
        Each method as :func:`occgp.evaluation.compare_methods` reads it:
        ``{"map": registered name, **parameters}``, with the options of every
        ``insert_scan`` under ``"insert"`` (ray mode).
    """
    res = {"resolution": resolution}
    return {
        "octree (scan)": {"map": "octree", **res},
        "octree (ray)": {"map": "octree", **res, "insert": {"mode": "ray"}},
        "grid (scan)": {"map": "grid", **res},
        "grid (ray)": {"map": "grid", **res, "insert": {"mode": "ray"}},
        "BGK": {"map": "bgk", **res, "n_jobs": -1},
        "AKIMap": {"map": "akimap", **res, "schedule_range": _DEMO_RANGE, "random_state": 0,
                   "n_jobs": -1},
        "AKIMap (published)": {"map": "akimap", **res, "variant": "published",
                               "schedule_range": _DEMO_RANGE, "random_state": 0, "n_jobs": -1},
        "k-NN": {"map": "knn", **res, "max_range": _DEMO_RANGE},
    }


#: The demo's stereo scene (not one of ``rendered_stereo_datasets()``: its buildings are
#: placed by another seed): plain boxes, the case stereo matching gets wrong.
STEREO_SCENE = {"layout": "L", "texture": False, "environment": "buildings", "seed": 99}
#: Keyframes per orbit (2 orbits) of the demo's stereo table.
STEREO_FRAMES = 12
#: Its StereoSGBM set: the one ranked last (highest naive-map FDR) on every tuning data set
#: among buildings (bench/bench_knn.py), the paper's worst case.
STEREO_SGBM = {"blockSize": 3, "disp12MaxDiff": 0, "preFilterCap": 10, "uniquenessRatio": 5,
               "speckleWindowSize": 600, "speckleRange": 1}
#: Sensor range (the k-NN model's s_c, the octree's max_range) of the stereo table, metres.
STEREO_RANGE = 4.0
#: The parameters of the stereo table's maps: for each map, the combination of the paper's
#: grid with the best mean strict TPR-FDR AUC over the tuning half of
#: ``rendered_stereo_datasets()`` (its 1st, middle and last StereoSGBM sets; bench/bench_knn.py,
#: table 5), never tuned on the demo's scene.
STEREO_OCTREE = {"prob_hit": 0.74, "prob_miss": 0.26, "clamping_min": 0.02,
                 "clamping_max": 0.98}
STEREO_KNN = {"k": 1, "p_u": 0.86, "p_l": 0.74, "p_m": 0.26, "p_m_out": 0.26, "p_min": 0.02,
              "p_max": 0.98}
#: The multi-scan score's choice (on the last-ranked sets): p_u = p_l, every point the same
#: update, the score left unused.
STEREO_KNN_HISTORY = {"k": 1, "p_u": 0.74, "p_l": 0.74, "p_m": 0.26, "p_m_out": 0.26,
                      "p_min": 0.02, "p_max": 0.98}
STEREO_HISTORY = 4


def noisy_mapping_methods(resolution: float) -> dict:
    """The methods of ``occgp demo``'s stereo table, as name → registered map and parameters.

    "octree, stereo": :class:`~occgp.OccupancyOctree` with ``max_range``
    :data:`STEREO_RANGE` and :data:`STEREO_OCTREE`; "k-NN, stereo":
    :class:`~occgp.KNNMap` with ``max_range`` :data:`STEREO_RANGE` and
    :data:`STEREO_KNN`; "k-NN 4 scans, stereo": ``history``
    :data:`STEREO_HISTORY` (each point scored against the previous keyframes'
    clouds) with :data:`STEREO_KNN_HISTORY`. The parameters were chosen on other
    scenes (the tuning half of :func:`occgp.datasets.rendered_stereo_datasets`).

    Parameters
    ----------
    resolution : float
        Cell size of every map, in metres.

    Returns
    -------
    methods : dict of str to dict
        Each method as :func:`mapping_methods` gives them.
    """
    knn = {"map": "knn", "resolution": resolution, "max_range": STEREO_RANGE, **STEREO_KNN}
    return {
        "octree, stereo": {"map": "octree", "resolution": resolution, **STEREO_OCTREE,
                           "insert": {"max_range": STEREO_RANGE}},
        "k-NN, stereo": knn,
        f"k-NN {STEREO_HISTORY} scans, stereo": {**knn, **STEREO_KNN_HISTORY,
                                                  "history": STEREO_HISTORY},
    }


def stereo_scans_of_scene(seed: int = 0, *, n_jobs: int | None = -1):
    """The demo's stereo scene and its clouds: :data:`STEREO_SCENE` orbited twice with
    :data:`STEREO_FRAMES` rendered keyframes per orbit, matched by StereoSGBM with
    :data:`STEREO_SGBM` (renderer noise seeded by `seed`)."""
    from ..datasets import StereoRig, render_orbit, stereo_scans, tetromino_scene
    params = dict(STEREO_SCENE)
    scene = tetromino_scene(params.pop("layout"), **params)
    rig = StereoRig()
    pairs = render_orbit(scene, rig, n_frames=STEREO_FRAMES, orbits=2, seed=seed,
                         n_jobs=n_jobs)
    return scene, stereo_scans(pairs, rig, STEREO_SGBM, n_jobs=n_jobs)


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
        ``fit(hits, segment_starts, segment_ends)`` that answers the map protocol
        (:class:`occgp.maps.OccupancyMap`: ``occupancy`` is NaN where it has no
        evidence).
    """
    from ..gp import GPOM, GPOMIK, GPMixture, OccupancyGrid, SquaredExponential

    return {
        "GPOMIK": lambda: GPOMIK(SquaredExponential(1.7, 0.6), noise=1e-4, optimizer=False,
                                 random_state=0),
        "GPOM": lambda: GPOM(SquaredExponential(0.66, 1.0), noise=0.13, optimizer=False,
                             random_state=0),
        "GP mixture": lambda: GPMixture(clustering="line", random_state=0),
        "log-odds grid": lambda: OccupancyGrid(resolution),
    }


def _run_gp(name, factory, observations, n_scans, test):
    """Fit one 2D model on all observations at once (timed) and score it (a MapResult)."""
    from ..evaluation import MapResult
    from ..metrics import score_all

    hits, starts, ends = observations
    model = factory()
    t0 = time.perf_counter()
    model.fit(hits, starts, ends)
    seconds = time.perf_counter() - t0
    sc = score_all(test.labels, model.occupancy(test.points))
    return MapResult(name, sc["auc"], sc["mse"], sc["acc_occupied"], sc["acc_free"],
                     sc["tpr_fdr_auc"], seconds, n_scans, len(hits) + len(starts),
                     sc["n_test"], sc["unknown_fraction"], 1.0, model)


# the demo's tables: no "data" column (every method gets all of it), "unknown" added
_DEMO_COLUMNS = ("method", "auc", "mse", "acc_occupied", "acc_free", "tpr_fdr_auc",
                 "unknown_fraction", "seconds")


def demo(outdir: str | Path = "demo_out", *, resolution: float = 0.1, seed: int = 0,
         progress: bool | None = None, out=None) -> list:
    """Map the synthetic rooms with every method and score them against exact ground truth.

    **3D.** The structured room (10 x 7 x 2 m) is scanned like the la3dm data
    set (4 poses x 3 scans x 3500 points, ranges up to 8 m); every method of
    :func:`mapping_methods` maps all the scans. **Protocol:** the test points
    are the centers of the cells of `resolution` that the scans could see
    (:func:`occgp.evaluation.exact_test_set`: within 8 m of a scan's origin,
    in its field of view, in line of sight by exact ray casting), labelled by
    the room's exact geometry (occupied where a solid reaches into the
    cell); cells that no scan could see (inside solids, behind walls, the
    floor below the scanners' lowest ray) are left out, cells in view but
    between the rays are kept, and the free cells are subsampled (seeded) to
    as many as the occupied ones. A map that leaves a cell unknown scores
    p = 0.5 there.

    **Stereo.** A small stereo scene (:data:`STEREO_SCENE`: plain boxes in an
    L among buildings) is orbited twice by a rendered stereo rig
    (:func:`occgp.datasets.render_orbit`, :data:`STEREO_FRAMES` keyframes per
    orbit), matched by OpenCV's StereoSGBM with :data:`STEREO_SGBM` and
    mapped by the methods of :func:`noisy_mapping_methods` (the octree and
    the k-NN map, one-scan and multi-scan scores, rays cut at 4 m, parameters
    chosen on the tuning half of
    :func:`~occgp.datasets.rendered_stereo_datasets`), scored by the same
    protocol on the cells in view within 6 m of the layout. Without OpenCV
    (the ``stereo`` extra) the table is skipped.

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
        :func:`noisy_mapping_methods` (names ending in ", stereo"), then those
        of :func:`gp_mapping_methods` (their ``map`` answers ``occupancy``
        with the model's ``predict_proba``).
    """
    from ..datasets import room_2d, structured_room
    from ..evaluation import compare_methods, exact_test_set, format_table
    from ..gp import observations_from_scans

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

    try:
        import cv2  # noqa: F401  (the stereo extra)
    except ImportError:
        print("\nstereo table skipped: it needs OpenCV (pip install 'occgp[stereo]')",
              file=out)
    else:
        stereo_scene, stereo = stereo_scans_of_scene(seed)
        box = (np.array([-6.0, -6.0, -0.2]), np.array([6.0, 6.0, 3.0]))
        test_s = exact_test_set(stereo_scene, resolution, stereo, max_range=STEREO_RANGE,
                                seed=seed, bbox=box)
        n_occ = int(test_s.labels.sum())
        print(f"\nstereo: plain boxes in an L among buildings, {len(stereo)} keyframes "
              f"rendered at 640 x 360 and matched by OpenCV's StereoSGBM\n(a last-ranked set of "
              f"the authors' grid), {sum(len(s.points) for s in stereo):,} points after the "
              f"0.1 m voxel filter, rays cut at {STEREO_RANGE:g} m;\nparameters chosen on "
              f"other scenes; test points: the cells in view within 6 m of the layout, "
              f"{n_occ:,} occupied, {len(test_s.points) - n_occ:,} free", file=out)
        noisy_rows = compare_methods(noisy_mapping_methods(resolution), stereo, test_s,
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
    """The centers ``(k + 0.5) * res`` of the map cells inside ``[lo, hi]`` on each axis."""
    return [(np.arange(np.ceil(a / res - 0.5 - 1e-9), np.floor(b / res - 0.5 + 1e-9) + 1)
             + 0.5) * res for a, b in zip(lo, hi)]


def _truth_panel(scene, centers, res, scans):
    """The cells' exact labels (closed-cell rule), NaN where no scan could see them."""
    from ..evaluation import cells_in_view, exact_labels

    truth = exact_labels(scene, centers, res).astype(float)
    truth[~cells_in_view(scene, centers, res, scans, max_range=_DEMO_RANGE)] = np.nan
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
    _save_figure(fig, path)


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
    from ..metrics import roc_curve

    for r in rows:
        proba = r.map.occupancy(test.points)
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
    _save_figure(fig, path)


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
    _save_figure(fig, path)


def _save_figure(fig, path: Path) -> None:
    """Write `fig` as a PNG at `path`, atomically (the old figure stays if it fails)."""
    with atomic_open(path) as fh:
        fig.savefig(fh, dpi=110, format="png")
