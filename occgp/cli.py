"""The ``occgp`` command line: ``occgp demo`` (the main job) and ``occgp map``.

``occgp demo`` maps the synthetic structured room with every mapping method
(:func:`mapping_methods`: the octree and the grid in scan and ray mode, BGK,
and AKIMap in both variants), prints their scores and writes ``map.bt`` and
figures. ``occgp map`` builds a map from scan files with ``--method octree``
(the default), ``bgk`` (:class:`~occgp.BGKMap`) or ``akimap``
(:class:`~occgp.AKIMap`) and writes it as an OctoMap ``.bt`` or ``.ot`` file
(a kernel map through its :meth:`~occgp.BGKMap.to_octree`).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from . import __version__
from ._validation import check_real
from .grid import GridMap
from .kernel import AKIMap, BGKMap
from .octree import OccupancyOctree

__all__ = ["main", "demo", "map_scans", "mapping_methods"]

# the maps `occgp map` can build (--method); each is written as an octree
_MAP_METHODS = ("octree", "bgk", "akimap")


class _RayModeOctree(OccupancyOctree):
    """An octree whose scans go in with per-ray counting (``mode="ray"``)."""

    def insert_scan(self, points, origin, **kwargs):
        return super().insert_scan(points, origin, mode="ray", **kwargs)


class _RayModeGrid(GridMap):
    """A grid whose scans go in with per-ray counting (``mode="ray"``)."""

    def insert_scan(self, points, origin, **kwargs):
        return super().insert_scan(points, origin, mode="ray", **kwargs)


def mapping_methods(resolution: float) -> dict:
    """Every mapping method of ``occgp demo``, as name → factory of an empty map.

    The octree and the grid in scan and ray mode, :class:`~occgp.BGKMap`
    ("BGK") and :class:`~occgp.AKIMap` in its two variants ("AKIMap",
    "AKIMap (published)"); the kernel maps use every core and AKIMap draws its
    free samples with ``random_state=0``.

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
    }


def demo(outdir: str | Path = "demo_out", *, resolution: float = 0.1, seed: int = 0,
         progress: bool | None = None, out=None) -> list:
    """Map the synthetic structured room with every method and score the maps.

    The room (10 x 7 x 2 m) is scanned like the la3dm data set (4 poses x 3
    scans x 3500 points). Each scan is split by the held-out protocol: 80% of
    its points build the maps, the held-out 20% give occupied test points and,
    on their rays, free test points. The methods are those of
    :func:`mapping_methods`. Prints a table (AUC, MSE, accuracies, update
    time) and writes ``map.bt`` (the scan-mode octree), ``slice.png`` (a
    horizontal slice of each map beside the ground truth) and ``roc.png`` to
    `outdir`.

    Returns
    -------
    rows : list of MapResult
    """
    from .datasets import structured_room
    from .evaluation import compare_methods, format_table, held_out_split

    out = sys.stdout if out is None else out
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    scene = structured_room(seed=seed)
    scans = scene.scan(seed=seed)
    train, test = held_out_split(scans, fraction=0.2, seed=seed)
    n_points = sum(len(s.points) for s in train)
    print(f"occgp {__version__} demo: structured room 10 x 7 x 2 m, {len(scans)} scans, "
          f"{n_points:,} points mapped, {len(test.points):,} held-out test points, "
          f"resolution {resolution} m", file=out)
    rows = compare_methods(mapping_methods(resolution), train, test, progress=progress)
    print(format_table(rows), file=out)

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


def map_scans(paths, output: str | Path, *, resolution: float = 0.1, method: str = "octree",
              mode: str | None = None, max_range: float | None = None,
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
    method : {"octree", "bgk", "akimap"}, default="octree"
        The map: :class:`~occgp.OccupancyOctree`, :class:`~occgp.BGKMap` or
        :class:`~occgp.AKIMap` (``random_state=0``). The kernel maps use every
        core and are written through their ``to_octree()``: each cell holds its
        posterior mean as log-odds (a ``.bt`` file keeps only whether it is
        above 0.5); cells no kernel reached stay unknown.
    mode : {"scan", "ray"}, default=None
        The octree's update mode (None: ``"scan"``); only for ``method="octree"``.
    max_range : float, default=None
        Range limit in metres; None means none (and BGKMap's own 8 m for
        ``method="bgk"``). The octree inserts longer beams up to `max_range` as
        free space only; BGK drops them whole (its ``max_range``); AKIMap gets
        only the end points within `max_range` of the sensor.
    progress : bool, default=None
        Show a progress bar (None: only on a terminal).
    out : file-like, default=None
        Where the summary line goes (None: standard output).

    Returns
    -------
    map : OccupancyOctree, BGKMap or AKIMap
        The map built.

    Raises
    ------
    ValueError
        If `output` does not end in ``.bt`` or ``.ot``, `method` or `mode` is
        not one of the choices (or `mode` is given with a kernel map),
        `max_range` is not positive, or no scan is found.
    TypeError
        If `max_range` is not a real number.
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
    if max_range is not None:
        max_range = check_real(max_range, "max_range", low=0.0)
    if method == "octree":
        mapper = OccupancyOctree(resolution)
        mode = "scan" if mode is None else mode

        def insert(points, origin):
            mapper.insert_scan(points, origin, max_range=max_range, mode=mode)
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
    if method == "octree":
        mapper.save(output)
        built = f"{mapper.num_leaves:,} leaves"
    else:
        tree = mapper.to_octree()
        tree.save(output)
        built = f"{mapper.num_cells:,} cells ({tree.num_leaves:,} octree leaves)"
    print(f"{len(scans)} scans, {n:,} points → {built} in {seconds:.2f} s; wrote {output}",
          file=out)
    return mapper


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="occgp", description="Occupancy mapping from range "
                                     "sensors: OctoMap octrees, kernel and GP maps.")
    parser.add_argument("--version", action="version", version=f"occgp {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("demo", help="map the synthetic structured room with every method, "
                       "print scores, write map.bt and figures")
    p.add_argument("-o", "--output", default="demo_out", help="output folder (default: %(default)s)")
    p.add_argument("--resolution", type=float, default=0.1, help="cell size in metres")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-progress", action="store_true")

    p = sub.add_parser("map", help="build a map from scan files (.pcd, .bin, .graph, "
                       "x y z text, or a folder of .pcd) and write it as an OctoMap file")
    p.add_argument("scans", nargs="+", help="scan files or folders")
    p.add_argument("-o", "--output", required=True, help="the map file (.bt or .ot)")
    p.add_argument("--resolution", type=float, default=0.1, help="cell size in metres")
    p.add_argument("--method", choices=_MAP_METHODS, default="octree",
                   help="octree: OctoMap log-odds; bgk: BGK kernel inference; akimap: "
                   "adaptive kernel inference; a kernel map is written as an octree of "
                   "its posterior means (default: %(default)s)")
    p.add_argument("--mode", choices=["scan", "ray"], default=None,
                   help="the octree's update mode (default: scan; --method octree only)")
    p.add_argument("--max-range", type=float, default=None,
                   help="range limit in metres: octree: longer beams are free space up to "
                   "it; bgk: longer beams are dropped (default: 8); akimap: end points "
                   "farther from the sensor are dropped (default: no limit)")
    p.add_argument("--no-progress", action="store_true")
    return parser


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    progress = False if args.no_progress else None
    try:
        if args.command == "demo":
            demo(args.output, resolution=args.resolution, seed=args.seed, progress=progress)
        else:
            map_scans(args.scans, args.output, resolution=args.resolution,
                      method=args.method, mode=args.mode, max_range=args.max_range,
                      progress=progress)
    except (ValueError, TypeError, OSError) as exc:
        print(f"occgp {args.command}: error: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
