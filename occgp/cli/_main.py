"""The ``occgp`` command line: ``occgp demo`` (the main job) and ``occgp map``.

``occgp demo`` (:func:`demo`, in ``occgp/cli/_demo.py``) maps the synthetic
structured room with every mapping method (:func:`mapping_methods`: the octree
and the grid in scan and ray mode, BGK, AKIMap in both variants and the k-NN
map), clouds of a small stereo scene rendered and matched by OpenCV's StereoSGBM
with the octree and the k-NN map (:func:`noisy_mapping_methods`), and the 2D room with the GP maps
(:func:`gp_mapping_methods`), scores every map against the scene's exact ground
truth (:func:`occgp.evaluation.exact_test_set`), prints a table for each and
writes ``map.bt`` and figures. ``occgp map`` (:func:`map_scans`) builds a map
from scan files and ROS bags (PointCloud2 posed by TF; ``--topic``,
``--fixed-frame``, ``--sensor-frame``), optionally posed by a KITTI or TUM trajectory
(``--poses``), with any registered 3D map type (``--method``, see
:func:`map_methods` and :mod:`occgp.maps`: ``octree``, the default, ``grid``,
``bgk``, ``akimap``, ``knn``, ...), optionally continuing a saved map
(``--input-map``), and writes it by the output's suffix: the map's own format
(e.g. a kernel map's ``.npz``), or an OctoMap ``.bt`` or ``.ot`` file or the
occupied cells as ``.ply`` or ``.pcd`` through the map's ``to_octree()``.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import textwrap

from .. import __version__
from ..filters import GROUND_MODES
from ..knn import CDFS
from ..maps import available_maps, map_type
from ._map_command import (
    KNN_DEFAULTS, KNN_OPTIONS, OPTION_OF, POSE_FORMATS, OptionError, OptionTypeError,
    check_knn_options,
    knn_error, map_methods, map_scans, option_name, parse_fields, parse_param,
)
from ._demo import (  # noqa: F401  (re-exported: occgp.cli is the demo's public home)
    demo, gp_mapping_methods, mapping_methods, noisy_mapping_methods,
)

__all__ = ["main", "demo", "map_scans", "map_methods", "mapping_methods",
           "noisy_mapping_methods", "gp_mapping_methods"]


def _map_types_help(width: int | None = None) -> str:
    """The ``map types`` list of ``occgp map -h``: every registered map (built-in and
    plugins', :func:`occgp.maps.available_maps`) with its one-line description.

    Parameters
    ----------
    width : int, default=None
        Line width; None: the terminal's (as argparse's help), at most 100.

    Returns
    -------
    text : str
    """
    if width is None:
        width = min(max(shutil.get_terminal_size().columns - 2, 40), 100)
    methods = set(map_methods())
    names = available_maps()
    pad = max(map(len, names), default=0) + 4
    lines = ["map types (occgp.maps, plugins included; --method takes those marked *):"]
    for name in names:
        entry = map_type(name)
        text = entry.description.rstrip(".")
        if name not in methods:
            text += ("; not for occgp map's 3D scans" if 3 not in entry.dims
                     else "; not for occgp map: its insert_scan needs more than points "
                     "and origin")
        if entry.plugin:
            text += f" [plugin {entry.plugin}]"
        mark = "*" if name in methods else " "
        lines.append(textwrap.fill(text, width, initial_indent=f"  {mark} {name:<{pad - 4}}  ",
                                   subsequent_indent=" " * (pad + 2)))
    return "\n".join(lines)


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="occgp", description="Occupancy mapping from range "
                                     "sensors: OctoMap octrees, kernel, k-NN and GP maps.")
    parser.add_argument("--version", action="version", version=f"occgp {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("demo", help="map the synthetic structured room with every method "
                       "(and noisy scans of it with the octree and the k-NN map) and the 2D "
                       "room with the GP maps, print scores against the exact ground truth, "
                       "write map.bt and figures")
    p.add_argument("-o", "--output", default="demo_out", help="output folder (default: %(default)s)")
    p.add_argument("--resolution", type=float, default=0.1,
                   help="cell size in metres (default: %(default)s)")
    p.add_argument("--seed", type=int, default=0,
                   help="seed of the scene, scans and noise (default: %(default)s)")
    p.add_argument("--no-progress", action="store_true",
                   help="no progress bars (default: shown on a terminal)")

    p = sub.add_parser("iln", help="the Implicit LiDAR Network: simulated range-image data "
                       "sets and model training (occgp iln -h)")
    from ..iln.cli import build_parser as _iln_parser  # numpy only; torch when training
    _iln_parser(p)

    p = sub.add_parser("map", help="build a map from scan files (.pcd, .bin, .pcd.bin, "
                       ".graph, x y z text, a folder of them) and ROS bags, and write it as "
                       "an OctoMap file, PLY / PCD cells or the map's own .npz",
                       description="Build a map from scan files and ROS bags (PointCloud2 "
                       "posed by TF) and write it.", epilog=_map_types_help(),
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.set_defaults(map_parser=p)
    p.add_argument("scans", nargs="+", help="scan files or folders (.pcd, .bin, .pcd.bin, "
                   ".graph, .xyz/.txt, ...), CARMEN 2D laser logs (FLASER / ROBOTLASER1 "
                   "lines, maybe .gz; planar scans at z = 0) and ROS bags (.bag, .db3, .mcap, "
                   "a ROS 2 bag folder), inserted in this order")
    p.add_argument("-o", "--output", required=True,
                   help="the map file, format by suffix: .bt/.ot (OctoMap), .ply/.pcd (the "
                   "occupied cells), .npz (bgk, akimap, grid: the map with its evidence, for "
                   "--input-map); required, no default")
    p.add_argument("--resolution", type=float, default=None,
                   help="cell size in metres (default: 0.1, or the resolution the map type "
                   "registered, or the --input-map's)")
    methods = map_methods()
    p.add_argument("--method", choices=methods, default="octree", metavar="NAME",
                   help="the map type: a registered 3D map (built-in or a plugin's; see "
                   "'map types' below: " + ", ".join(methods) + "); a map is written to "
                   ".bt/.ot/.ply/.pcd through its to_octree() unless the suffix is one of "
                   "its own formats (default: %(default)s)")
    p.add_argument("--mode", choices=["scan", "ray"], default=None,
                   help="the update mode (default: scan; octree and grid only)")
    p.add_argument("--max-range", type=float, default=None,
                   help="range limit in metres: octree: longer beams are free space up to "
                   "it (default: no limit); bgk: longer beams are dropped (default: 8, or the "
                   "--input-map's); akimap: end points farther from the sensor are dropped "
                   "(default: no limit); knn: farther points are not inserted and their "
                   f"rays are cut here (default: {KNN_DEFAULTS['max_range']})")
    p.add_argument("--n-jobs", type=int, default=-1,
                   help="threads of the map; -1: every core; the map does not depend on it "
                   "(default: %(default)s)")
    p.add_argument("--input-map", default=None, metavar="PATH",
                   help="continue a saved map in one of the method's own formats: .bt/.ot "
                   "for octree and knn, .ot for color-octree, .npz (written by -o X.npz) for bgk, akimap and "
                   "grid; the scans are inserted into it (default: a new map)")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   type=parse_param, help="a constructor parameter of the map, repeatable (e.g. "
                   "--param prob_hit=0.8); the value is read as a Python literal, else kept "
                   "as text, and checked by the map before any scan is read (a bad value is a "
                   "usage error); a parameter with an option of its own (--resolution, "
                   "--n-jobs, --max-range, the k-NN options with --method knn) is refused: "
                   "give it there (default: the map type's defaults)")
    p.add_argument("--project-2d", type=float, nargs=2, default=None,
                   metavar=("Z_MIN", "Z_MAX"),
                   help="write a 2D map of this height band instead (occupied if any cell "
                   "in the band is, free if its known cells all are): map_server / Nav2's "
                   "YAML, with -o MAP.yaml, and its MAP.pgm image (default: the 3D map)")
    p.add_argument("--no-progress", action="store_true",
                   help="no progress bar (default: shown on a terminal)")
    g = p.add_argument_group("poses and record layouts")
    g.add_argument("--poses", default=None, metavar="FILE",
                   help="sensor-to-world poses, one per scan in input order: KITTI poses.txt "
                   "(3x4 row-major) or TUM (t x y z qx qy qz qw; timestamps not matched) "
                   "(default: none, the scans are in the world frame)")
    g.add_argument("--poses-format", choices=POSE_FORMATS, default=None,
                   help="format of --poses (default: guessed from the columns: 12 kitti, "
                   "8 tum)")
    g.add_argument("--fields", type=parse_fields, default=None,
                   help="record layout of .bin scans: an int (float32 values per record, x y "
                   "z first), kitti, nuscenes, or name:dtype,... such as x:<f4,y:<f4,z:<f4,"
                   "t:<u4 (default: by file name: nuscenes for .pcd.bin, else kitti)")
    g = p.add_argument_group("scan filters (octomap_server's; world frame, applied to every "
                             "scan before it is inserted)")
    g.add_argument("--min-range", type=float, default=None, metavar="M",
                   help="drop the points nearer to the sensor than M metres (default: none)")
    g.add_argument("--z-min", type=float, default=None,
                   help="drop the points below this height (default: none)")
    g.add_argument("--z-max", type=float, default=None,
                   help="drop the points above this height (default: none)")
    g.add_argument("--self-box", type=float, nargs=6, default=None,
                   metavar=("X0", "Y0", "Z0", "X1", "Y1", "Z1"),
                   help="drop the points in this box of offsets from the sensor (the "
                   "robot's body; axis-aligned) (default: none)")
    g.add_argument("--ground", choices=GROUND_MODES, default="keep",
                   help="the ground plane's points (RANSAC, a plane within --ground-angle "
                   "of horizontal and --ground-plane-distance of --ground-height): keep "
                   "them, drop them, or insert them as free space, as octomap_server does "
                   "(octree and grid) (default: %(default)s)")
    g.add_argument("--ground-distance", type=float, default=0.04,
                   help="points within this distance of the plane are ground "
                   "(default: %(default)s)")
    g.add_argument("--ground-angle", type=float, default=0.15,
                   help="the plane's largest tilt, radians (default: %(default)s)")
    g.add_argument("--ground-plane-distance", type=float, default=0.07,
                   help="the plane's largest distance from --ground-height "
                   "(default: %(default)s)")
    g.add_argument("--ground-height", type=float, default=0.0,
                   help="height of the ground in the world frame (default: %(default)s)")
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
    d = KNN_DEFAULTS
    g.add_argument("--k", type=int, default=None,
                   help=f"nearest neighbours scoring each point, in [1, 1000] "
                   f"(default: {d['k']})")
    g.add_argument("--sensor-range", type=float, default=None, metavar="M",
                   help="deprecated, read as --max-range (default: not given)")
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
    g.add_argument("--occupancy-threshold", type=float, default=None,
                   help=f"occupancy threshold (the paper's p_t), in [--p-min, --p-max] "
                   f"(default: {d['occupancy_threshold']})")
    g.add_argument("--p-t", type=float, default=None, metavar="P_T",
                   help="deprecated, read as --occupancy-threshold (default: not given)")
    g.add_argument("--cdf", choices=CDFS, default=None,
                   help=f"the CDF of the scores: normal (the paper's) or truncated at 0 "
                   f"(default: {d['cdf']})")
    return parser


#: The deprecated k-NN options (one release), by the option each one is read as.
_OLD_KNN_OPTIONS = {"sensor_range": "max_range", "p_t": "occupancy_threshold"}


def _knn_args(args) -> dict | None:
    """The k-NN options given on the command line (None: none), checked; exits with
    parser.error (code 2) on a bad one or one given with another method. A deprecated
    option (--sensor-range, --p-t) is read as its new one, with a note on stderr."""
    parser = args.map_parser
    for old, new in _OLD_KNN_OPTIONS.items():
        value = getattr(args, old)
        if value is None:
            continue
        print(f"occgp map: note: {option_name(old)} is deprecated and will be removed in "
              f"the next release; use {option_name(new)}", file=sys.stderr)
        if getattr(args, new) is not None:
            parser.error(f"argument {option_name(old)}: not with {option_name(new)}; give "
                         f"{option_name(new)} only")
        if new == "max_range" and args.method != "knn":
            parser.error(f"argument {option_name(old)}: applies to --method knn only (the "
                         f"range limit of every map is --max-range), got --method "
                         f"{args.method}")
        setattr(args, new, value)
    knn_only = [name for name in KNN_OPTIONS if name != "max_range"]
    given = {name: getattr(args, name) for name in knn_only if getattr(args, name) is not None}
    if args.method != "knn":
        if given:
            parser.error(f"argument {'/'.join(map(option_name, given))}: applies to --method "
                         f"knn only, got --method {args.method}")
        return None
    if args.max_range is not None:
        given["max_range"] = args.max_range
    try:
        check_knn_options(given)
    except (ValueError, TypeError) as exc:
        knn_error(parser, exc)
    return given


def _scan_filter(args):
    """The ScanFilter of the filter options, None when none is given."""
    from ..filters import ScanFilter
    given = (args.min_range, args.z_min, args.z_max, args.self_box)
    if all(v is None for v in given) and args.ground == "keep":
        return None
    box = None if args.self_box is None else [args.self_box[:3], args.self_box[3:]]
    return ScanFilter(min_range=args.min_range, z_min=args.z_min, z_max=args.z_max,
                      self_box=box, ground=args.ground, ground_distance=args.ground_distance,
                      ground_angle=args.ground_angle,
                      ground_plane_distance=args.ground_plane_distance,
                      ground_height=args.ground_height, random_state=0)


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    if args.command == "iln":
        from ..iln.cli import run as _iln_run
        return _iln_run(args)
    progress = False if args.no_progress else None
    knn_params = _knn_args(args) if args.command == "map" else None
    try:
        if args.command == "demo":
            demo(args.output, resolution=args.resolution, seed=args.seed, progress=progress)
        else:
            map_scans(args.scans, args.output, resolution=args.resolution,
                      method=args.method, mode=args.mode,
                      max_range=args.max_range if knn_params is None else None,
                      knn_params=knn_params, poses=args.poses, poses_format=args.poses_format,
                      topic=args.topic, fixed_frame=args.fixed_frame,
                      sensor_frame=args.sensor_frame, tf_tolerance=args.tf_tolerance,
                      fields=args.fields, input_map=args.input_map, n_jobs=args.n_jobs,
                      params=dict(args.param), project_2d=args.project_2d,
                      scan_filter=_scan_filter(args), progress=progress)
    except (OptionError, OptionTypeError) as exc:
        args.map_parser.error(f"argument {OPTION_OF.get(exc.param, exc.param)}: {exc}")
    except (ValueError, TypeError, OSError, ImportError) as exc:
        print(f"occgp {args.command}: error: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
