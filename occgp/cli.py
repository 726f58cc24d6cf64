"""The ``occgp`` command line: ``occgp demo`` (the main job) and ``occgp map``."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from . import __version__
from .grid import GridMap
from .octree import OccupancyOctree

__all__ = ["main", "demo", "map_scans"]


class _RayModeOctree(OccupancyOctree):
    """An octree whose scans go in with per-ray counting (``mode="ray"``)."""

    def insert_scan(self, points, origin, **kwargs):
        return super().insert_scan(points, origin, mode="ray", **kwargs)


class _RayModeGrid(GridMap):
    """A grid whose scans go in with per-ray counting (``mode="ray"``)."""

    def insert_scan(self, points, origin, **kwargs):
        return super().insert_scan(points, origin, mode="ray", **kwargs)


def mapping_methods(resolution: float) -> dict:
    """Every mapping method occgp has, as name → factory of an empty map."""
    return {
        "octree (scan)": lambda: OccupancyOctree(resolution),
        "octree (ray)": lambda: _RayModeOctree(resolution),
        "grid (scan)": lambda: GridMap(resolution),
        "grid (ray)": lambda: _RayModeGrid(resolution),
    }


def demo(outdir: str | Path = "demo_out", *, resolution: float = 0.1, seed: int = 0,
         progress: bool | None = None, out=None) -> list:
    """Map the synthetic structured room with every method and score the maps.

    The room (10 x 7 x 2 m) is scanned like the la3dm data set (4 poses x 3
    scans x 3500 points). Each scan is split by the held-out protocol: 80% of
    its points build the maps, the held-out 20% give occupied test points and,
    on their rays, free test points. Prints a table (AUC, MSE, accuracies,
    update time) and writes ``map.bt`` (the scan-mode octree),
    ``slice.png`` (a horizontal slice of each map) and ``roc.png`` to
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

    rows[0].map.save(outdir / "map.bt")
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
    fig = Figure(figsize=(4.2 * len(panels), 3.6), layout="constrained")
    axes = fig.subplots(1, len(panels))
    cmap = _cmap()
    for ax, (title, img) in zip(np.atleast_1d(axes), panels):
        im = ax.imshow(img, origin="lower", extent=(lo[0], hi[0], lo[1], hi[1]),
                       cmap=cmap, vmin=0, vmax=1, interpolation="nearest")
        ax.set_title(title)
        ax.set_xlabel("x [m]")
        ax.set_aspect("equal")
    np.atleast_1d(axes)[0].set_ylabel("y [m]")
    for s in scans:
        np.atleast_1d(axes)[0].plot(*s.origin[:2], "r^", ms=6)
    fig.colorbar(im, ax=axes, shrink=0.8, label="p(occupied); grey: unknown")
    fig.suptitle(f"horizontal slice at z = {z:.2f} m")
    fig.savefig(path, dpi=110)


def _cmap():
    from matplotlib import colormaps

    return colormaps["viridis"].with_extremes(bad="0.75")


def _plot_roc(rows, test, path: Path) -> None:
    from matplotlib.figure import Figure

    from .metrics import roc_curve

    fig = Figure(figsize=(4.5, 4.2), layout="constrained")
    ax = fig.subplots()
    for r in rows:
        fpr, tpr, _ = roc_curve(test.labels, r.map.occupancy(test.points))
        ax.plot(fpr, tpr, label=f"{r.method} (AUC {r.auc:.3f})")
    ax.plot([0, 1], [0, 1], "k:", lw=0.8)
    ax.set_xlabel("false positive rate")
    ax.set_ylabel("true positive rate")
    ax.set_title("ROC on held-out test points")
    ax.legend(loc="lower right")
    fig.savefig(path, dpi=110)


def map_scans(paths, output: str | Path, *, resolution: float = 0.1, mode: str = "scan",
              max_range: float | None = None, progress: bool | None = None, out=None):
    """Build an octree from scan files and save it (``.bt`` or ``.ot``).

    Returns
    -------
    tree : OccupancyOctree
    """
    from tqdm.auto import tqdm

    from .datasets import read_scans

    out = sys.stdout if out is None else out
    output = Path(output)
    if output.suffix not in (".bt", ".ot"):
        raise ValueError(f"output must end in .bt or .ot, got {str(output)!r}")
    scans = [scan for path in paths for scan in read_scans(path)]
    if not scans:
        raise ValueError("no scans found in " + ", ".join(map(str, paths)))
    tree = OccupancyOctree(resolution)
    t0 = time.perf_counter()
    for scan in tqdm(scans, desc="inserting scans", unit="scan",
                     disable=None if progress is None else not progress):
        tree.insert_scan(scan.points, scan.origin, max_range=max_range, mode=mode)
    seconds = time.perf_counter() - t0
    tree.save(output)
    n = sum(len(s.points) for s in scans)
    print(f"{len(scans)} scans, {n:,} points → {tree.num_leaves:,} leaves in {seconds:.2f} s; "
          f"wrote {output}", file=out)
    return tree


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

    p = sub.add_parser("map", help="build an octree from scan files (.pcd, .bin, .graph, "
                       "x y z text, or a folder of .pcd)")
    p.add_argument("scans", nargs="+", help="scan files or folders")
    p.add_argument("-o", "--output", required=True, help="the map file (.bt or .ot)")
    p.add_argument("--resolution", type=float, default=0.1, help="cell size in metres")
    p.add_argument("--mode", choices=["scan", "ray"], default="scan")
    p.add_argument("--max-range", type=float, default=None)
    p.add_argument("--no-progress", action="store_true")
    return parser


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    progress = False if args.no_progress else None
    try:
        if args.command == "demo":
            demo(args.output, resolution=args.resolution, seed=args.seed, progress=progress)
        else:
            map_scans(args.scans, args.output, resolution=args.resolution, mode=args.mode,
                      max_range=args.max_range, progress=progress)
    except (ValueError, TypeError, OSError) as exc:
        print(f"occgp {args.command}: error: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
