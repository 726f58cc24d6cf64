"""The ``occgp`` command line: ``occgp demo`` (the main job) and ``occgp map``.

``occgp demo`` maps the synthetic structured room with every mapping method
(:func:`mapping_methods`: the octree and the grid in scan and ray mode, BGK,
AKIMap in both variants and the k-NN map), prints their scores, then maps a
noisy version of the same scans with the octree and the k-NN map
(:func:`noisy_mapping_methods`) and prints theirs, and writes ``map.bt`` and
figures. ``occgp map`` builds a map from scan files with ``--method octree``
(the default), ``bgk`` (:class:`~occgp.BGKMap`), ``akimap``
(:class:`~occgp.AKIMap`) or ``knn`` (:class:`~occgp.KNNMap`) and writes it as
an OctoMap ``.bt`` or ``.ot`` file (a kernel map through its
:meth:`~occgp.BGKMap.to_octree`).
"""

from __future__ import annotations

import argparse
import inspect
import re
import sys
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from . import __version__
from ._validation import check_real
from .grid import GridMap
from .kernel import AKIMap, BGKMap
from .knn import CDFS, KNN_PARAMS, KNNMap, check_knn_params
from .octree import OccupancyOctree

__all__ = ["main", "demo", "map_scans", "mapping_methods", "noisy_mapping_methods"]

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


def demo(outdir: str | Path = "demo_out", *, resolution: float = 0.1, seed: int = 0,
         progress: bool | None = None, out=None) -> list:
    """Map the synthetic structured room with every method and score the maps.

    The room (10 x 7 x 2 m) is scanned like the la3dm data set (4 poses x 3
    scans x 3500 points, ranges up to 8 m). Each scan is split by the held-out
    protocol: 80% of its points build the maps, the held-out 20% give occupied
    test points and, on their rays, free test points. The methods are those of
    :func:`mapping_methods`. Then the same training scans get the noise of
    :class:`occgp.datasets.StereoCamera` at its defaults (depth noise
    ``depth_noise * d**2`` along each ray, a fraction `speckle` of outliers
    between the sensor and the surface; seeded by `seed`) and are mapped by
    the methods of :func:`noisy_mapping_methods` (the octree and the k-NN
    map, both cut at 8 m), scored on the same test set. Prints a table for
    each (AUC, MSE, accuracies, update time) and writes ``map.bt`` (the
    scan-mode octree of the clean scans), ``slice.png`` (a horizontal slice of
    each map beside the ground truth) and ``roc.png`` to `outdir`.

    Returns
    -------
    rows : list of MapResult
        The rows of :func:`mapping_methods`, then those of
        :func:`noisy_mapping_methods` (names ending in ", noisy").
    """
    from .datasets import StereoCamera, structured_room
    from .evaluation import compare_methods, format_table, held_out_split

    out = sys.stdout if out is None else out
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    scene = structured_room(seed=seed)
    scans = scene.scan(max_range=_DEMO_RANGE, seed=seed)
    train, test = held_out_split(scans, fraction=0.2, seed=seed)
    n_points = sum(len(s.points) for s in train)
    print(f"occgp {__version__} demo: structured room 10 x 7 x 2 m, {len(scans)} scans, "
          f"{n_points:,} points mapped, {len(test.points):,} held-out test points, "
          f"resolution {resolution} m", file=out)
    rows = compare_methods(mapping_methods(resolution), train, test, progress=progress)
    print(format_table(rows), file=out)

    camera = StereoCamera()
    noisy = _noisy_scans(train, depth_noise=camera.depth_noise, speckle=camera.speckle,
                         seed=seed)
    print(f"\nnoisy scans: the same scans with stereo-camera noise (depth noise "
          f"{camera.depth_noise:g} m x (range / 1 m)^2,\n{camera.speckle:.0%} speckle outliers "
          f"between sensor and surface), rays cut at {_DEMO_RANGE:g} m, the same test points",
          file=out)
    noisy_rows = compare_methods(noisy_mapping_methods(resolution), noisy, test,
                                 progress=progress)
    print(format_table(noisy_rows), file=out)
    rows += noisy_rows

    next(r for r in rows if r.method == "octree (scan)").map.save(outdir / "map.bt")
    _plot_slice(rows, scene, train, outdir / "slice.png")
    _plot_roc(rows, test, outdir / "roc.png")
    print(f"wrote {outdir / 'map.bt'}, {outdir / 'slice.png'}, {outdir / 'roc.png'}", file=out)
    return rows


def _plot_slice(rows, scene, scans, path: Path, z: float | None = None) -> None:
    from matplotlib.figure import Figure

    lo, hi = (np.asarray(b, dtype=float) for b in scene.bounds)
    if z is None:   # the mean sensor height: the best observed plane
        z = float(np.mean([s.origin[2] for s in scans]))
    res = rows[0].map.resolution
    xs = np.arange(lo[0] + res / 2, hi[0], res)
    ys = np.arange(lo[1] + res / 2, hi[1], res)
    gx, gy = np.meshgrid(xs, ys)
    q = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, z)])
    truth = scene.occupancy(q).reshape(gx.shape)
    panels = [("ground truth", truth.astype(float))]
    panels += [(r.method, r.map.occupancy(q).reshape(gx.shape)) for r in rows]
    # up to 4 panels in a row, in as few rows as that allows
    nrows = -(-len(panels) // 4)
    ncols = -(-len(panels) // nrows)
    fig = Figure(figsize=(4.2 * ncols, 3.6 * nrows), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False)
    cmap = _cmap()
    for ax in axes.flat[len(panels):]:
        ax.set_axis_off()
    for ax, (title, img) in zip(axes.flat, panels):
        im = ax.imshow(img, origin="lower", extent=(lo[0], hi[0], lo[1], hi[1]),
                       cmap=cmap, vmin=0, vmax=1, interpolation="nearest")
        ax.set_title(title)
        ax.set_xlabel("x [m]")
        ax.set_aspect("equal")
    for ax in axes[:, 0]:
        ax.set_ylabel("y [m]")
    for s in scans:
        axes[0, 0].plot(*s.origin[:2], "r^", ms=6)
    fig.colorbar(im, ax=axes, shrink=0.8 / nrows ** 0.5,
                 label="p(occupied); grey: unknown")
    fig.suptitle(f"horizontal slice at z = {z:.2f} m")
    fig.savefig(path, dpi=110)


def _cmap():
    from matplotlib import colormaps

    return colormaps["viridis"].with_extremes(bad="0.75")


def _plot_roc(rows, test, path: Path) -> None:
    from matplotlib.figure import Figure

    from .metrics import roc_curve

    fig = Figure(figsize=(5.2, 4.8), layout="constrained")
    ax = fig.subplots()
    for r in rows:
        fpr, tpr, _ = roc_curve(test.labels, r.map.occupancy(test.points))
        ax.plot(fpr, tpr, label=f"{r.method} (AUC {r.auc:.3f})")
    ax.plot([0, 1], [0, 1], "k:", lw=0.8)
    ax.set_xlabel("false positive rate")
    ax.set_ylabel("true positive rate")
    ax.set_title("ROC on held-out test points")
    ax.legend(loc="lower right", fontsize="small")
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


def map_scans(paths, output: str | Path, *, resolution: float = 0.1, method: str = "octree",
              mode: str | None = None, max_range: float | None = None,
              knn_params: Mapping[str, Any] | None = None,
              progress: bool | None = None, out=None):
    """Build a map from scan files and save it as an OctoMap file (``.bt`` or ``.ot``).

    Parameters
    ----------
    paths : sequence of str or path-like
        Scan files or folders, read with :func:`occgp.datasets.read_scans`.
    output : str or path-like
        The map file; its suffix, ``.bt`` or ``.ot``, gives the format.
    resolution : float, default=0.1
        Cell size in metres.
    method : {"octree", "bgk", "akimap", "knn"}, default="octree"
        The map: :class:`~occgp.OccupancyOctree`, :class:`~occgp.BGKMap`,
        :class:`~occgp.AKIMap` (``random_state=0``) or :class:`~occgp.KNNMap`.
        The kernel maps use every core and are written through their
        ``to_octree()``: each cell holds its posterior mean as log-odds (a
        ``.bt`` file keeps only whether it is above 0.5); cells no kernel
        reached stay unknown. The k-NN map is an octree (its k-NN queries use
        every core) and is written as it is.
    mode : {"scan", "ray"}, default=None
        The octree's update mode (None: ``"scan"``); only for ``method="octree"``.
    max_range : float, default=None
        Range limit in metres; None means none (and BGKMap's own 8 m for
        ``method="bgk"``). The octree inserts longer beams up to `max_range` as
        free space only; BGK drops them whole (its ``max_range``); AKIMap gets
        only the end points within `max_range` of the sensor. Not for
        ``method="knn"``, whose range limit is its ``sensor_range`` (in
        `knn_params`), which acts as the octree's `max_range` does.
    knn_params : mapping, default=None
        For ``method="knn"`` only: :class:`~occgp.KNNMap`'s ``k``, ``p_u``,
        ``p_l``, ``p_m``, ``p_m_out``, ``p_min``, ``p_max``, ``p_t``,
        ``sensor_range`` and ``cdf``; those left out take KNNMap's defaults
        (``sensor_range`` 4 m: points farther from the sensor are not
        inserted, their rays are cut there). Checked as KNNMap checks them
        (Miao et al.'s Eq. 12) before any scan is read.
    progress : bool, default=None
        Show a progress bar (None: only on a terminal).
    out : file-like, default=None
        Where the summary line goes (None: standard output).

    Returns
    -------
    map : OccupancyOctree, BGKMap, AKIMap or KNNMap
        The map built.

    Raises
    ------
    ValueError
        If `output` does not end in ``.bt`` or ``.ot``, `method` or `mode` is
        not one of the choices (or `mode` is given with another method than
        the octree), `max_range` is not positive or is given with
        ``method="knn"``, `knn_params` is given with another method, names a
        parameter KNNMap does not take or holds a value KNNMap rejects, or no
        scan is found.
    TypeError
        If `max_range` is not a real number, `knn_params` is not a mapping or
        holds a value of the wrong type.
    OSError
        If a scan file cannot be read or the output cannot be written.
    """
    from tqdm.auto import tqdm

    from .datasets import read_scans

    out = sys.stdout if out is None else out
    output = Path(output)
    if output.suffix not in (".bt", ".ot"):
        raise ValueError(f"output must end in .bt or .ot, got {str(output)!r}")
    if method not in _MAP_METHODS:
        raise ValueError(f"method must be one of {_MAP_METHODS}, got {method!r}")
    if mode is not None and method != "octree":
        raise ValueError(f"mode applies to method='octree' only, got mode={mode!r} with "
                         f"method={method!r}")
    if knn_params is not None and method != "knn":
        raise ValueError(f"knn_params applies to method='knn' only, got method={method!r}")
    if max_range is not None and method == "knn":
        raise ValueError(f"max_range does not apply to method='knn': its range limit is "
                         f"knn_params['sensor_range'] (default {_KNN_DEFAULTS['sensor_range']} "
                         f"m), got max_range={max_range!r}")
    if max_range is not None:
        max_range = check_real(max_range, "max_range", low=0.0)
    mapper: Any
    if method == "octree":
        mapper = OccupancyOctree(resolution)
        mode = "scan" if mode is None else mode

        def insert(points, origin):
            mapper.insert_scan(points, origin, max_range=max_range, mode=mode)
    elif method == "knn":
        mapper = KNNMap(resolution, **_check_knn_options({} if knn_params is None
                                                         else knn_params), n_jobs=-1)

        def insert(points, origin):
            mapper.insert_scan(points, origin)
    else:
        if method == "bgk":
            mapper = BGKMap(resolution, n_jobs=-1) if max_range is None else \
                BGKMap(resolution, max_range=max_range, n_jobs=-1)
        else:
            mapper = AKIMap(resolution, random_state=0, n_jobs=-1)

        def insert(points, origin):
            if method == "akimap" and max_range is not None:
                points = np.asarray(points, dtype=np.float64)
                near = np.linalg.norm(points - np.asarray(origin, dtype=np.float64),
                                      axis=1) <= max_range
                points = points[near]
            mapper.update(points, origin)
    scans = [scan for path in paths for scan in read_scans(path)]
    if not scans:
        raise ValueError("no scans found in " + ", ".join(map(str, paths)))
    t0 = time.perf_counter()
    for scan in tqdm(scans, desc="inserting scans", unit="scan",
                     disable=None if progress is None else not progress):
        insert(scan.points, scan.origin)
    seconds = time.perf_counter() - t0
    n = sum(len(s.points) for s in scans)
    if method in ("octree", "knn"):
        mapper.save(output)
        built = f"{mapper.num_leaves:,} leaves"
    else:
        tree = mapper.to_octree()
        tree.save(output)
        built = f"{mapper.num_cells:,} cells ({tree.num_leaves:,} octree leaves)"
    print(f"{len(scans)} scans, {n:,} points → {built} in {seconds:.2f} s; wrote {output}",
          file=out)
    return mapper


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


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="occgp", description="Occupancy mapping from range "
                                     "sensors: OctoMap octrees, kernel, k-NN and GP maps.")
    parser.add_argument("--version", action="version", version=f"occgp {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("demo", help="map the synthetic structured room with every method "
                       "(and noisy scans of it with the octree and the k-NN map), print "
                       "scores, write map.bt and figures")
    p.add_argument("-o", "--output", default="demo_out", help="output folder (default: %(default)s)")
    p.add_argument("--resolution", type=float, default=0.1, help="cell size in metres")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-progress", action="store_true")

    p = sub.add_parser("map", help="build a map from scan files (.pcd, .bin, .graph, "
                       "x y z text, or a folder of .pcd) and write it as an OctoMap file")
    p.set_defaults(map_parser=p)
    p.add_argument("scans", nargs="+", help="scan files or folders")
    p.add_argument("-o", "--output", required=True, help="the map file (.bt or .ot)")
    p.add_argument("--resolution", type=float, default=0.1, help="cell size in metres")
    p.add_argument("--method", choices=_MAP_METHODS, default="octree",
                   help="octree: OctoMap log-odds; bgk: BGK kernel inference; akimap: "
                   "adaptive kernel inference; knn: the k-NN inverse sensor model on the "
                   "octree; a kernel map is written as an octree of its posterior means "
                   "(default: %(default)s)")
    p.add_argument("--mode", choices=["scan", "ray"], default=None,
                   help="the octree's update mode (default: scan; --method octree only)")
    p.add_argument("--max-range", type=float, default=None,
                   help="range limit in metres: octree: longer beams are free space up to "
                   "it; bgk: longer beams are dropped (default: 8); akimap: end points "
                   "farther from the sensor are dropped (default: no limit); not with knn, "
                   "whose range limit is --sensor-range")
    p.add_argument("--no-progress", action="store_true")
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
                      knn_params=knn_params, progress=progress)
    except (ValueError, TypeError, OSError) as exc:
        print(f"occgp {args.command}: error: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
