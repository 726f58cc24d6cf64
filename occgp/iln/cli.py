"""``occgp iln ...``: the command line of occgp.iln.

Subcommands:

``occgp iln make-dataset FOLDER --n-train N --n-test N --sizes 16x1024 64x1024 ... --seed S``
    Simulate range images in procedural outdoor scenes and write them as
    compressed shards (:func:`occgp.iln.data.make_dataset`); ``--effects``
    adds the default sensor effects (:class:`occgp.iln.SensorEffects`),
    ``--vegetation`` vegetation clutter, ``--sensor hdl64e`` simulates
    KITTI's HDL-64E with its real beam table (64 rows: every beam, 16 rows:
    every 4th beam).
``occgp iln train CONFIG.yaml``
    Train a model from a YAML configuration (``occgp.iln.train``; needs
    PyTorch).
``occgp iln tune-threshold CHECKPOINT FOLDER OUTPUT --skip N``
    Choose a trained :class:`~occgp.iln.models.CandidateSelector`'s
    confidence thresholds on held-out training images (those after the first
    N of FOLDER's train split) and write the checkpoint with it
    (:func:`occgp.iln.tuning.tune_checkpoint`; needs PyTorch).

:func:`main` takes the arguments after ``iln`` and returns the exit status:
0 on success, 1 for a failed command (its message on stderr), 2 for bad
arguments (argparse's usage message).
"""

from __future__ import annotations

import argparse
import sys

__all__ = ["main", "build_parser"]


def _positive_int(text):
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an int, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a non-negative int, got {value}")
    return value


def _size(text):
    from .data import parse_size  # noqa: PLC0415

    try:
        return parse_size(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def build_parser(parser: argparse.ArgumentParser | None = None) -> argparse.ArgumentParser:
    """The ``iln`` argument parser, or its subcommands added to `parser` (e.g. a subparser
    of ``occgp``).

    Parameters
    ----------
    parser : argparse.ArgumentParser, optional
        Parser to add the ``make-dataset``, ``train`` and ``tune-threshold`` subcommands to (as
        ``args.iln_command``); default: a new parser with ``prog="occgp iln"``.

    Returns
    -------
    parser : argparse.ArgumentParser
        `parser` itself when given, else the new parser.
    """
    if parser is None:
        parser = argparse.ArgumentParser(
            prog="occgp iln", description="Implicit LiDAR network: training data and models.")
    sub = parser.add_subparsers(dest="iln_command", required=True, metavar="COMMAND")
    make = sub.add_parser(
        "make-dataset", help="simulate range images and write them as .npz shards",
        description="Simulate range images in procedural outdoor scenes (train scenes seeded "
        "0..N-1, test scenes 100000..) and write them as compressed .npz shards to "
        "FOLDER/train and FOLDER/test. Nothing is downloaded.")
    make.add_argument("folder", metavar="FOLDER", help="the dataset folder (created if missing)")
    make.add_argument("--n-train", type=_positive_int, required=True, metavar="N",
                      help="number of train scenes")
    make.add_argument("--n-test", type=_positive_int, required=True, metavar="N",
                      help="number of test scenes")
    make.add_argument("--sizes", type=_size, nargs="+", default=None, metavar="ROWSxCOLS",
                      help="image sizes, any of 16x1024 64x1024 128x2048 256x4096 "
                      "(default: 16x1024 64x1024)")
    make.add_argument("--images-per-scene", type=_positive_int, default=4, metavar="N",
                      help="sensor poses per scene (default: 4)")
    make.add_argument("--images-per-shard", type=_positive_int, default=32, metavar="N",
                      help="most images in one shard file (default: 32)")
    make.add_argument("--seed", type=_positive_int, default=0, metavar="S",
                      help="seed of the sensor poses (default: 0)")
    make.add_argument("--n-jobs", type=int, default=None, metavar="N",
                      help="scenes simulated in parallel (joblib; -1: every core; default: 1)")
    make.add_argument("--effects", action="store_true",
                      help="apply the default sensor effects to each image: 2 cm range noise, "
                      "dropouts at grazing incidence, on dark surfaces and near the maximum "
                      "range (default: exact images)")
    make.add_argument("--vegetation", action="store_true",
                      help="add vegetation clutter to the scenes: porous tree crowns, hedges, "
                      "bushes, grass")
    make.add_argument("--sensor", choices=("carla", "hdl64e"), default="carla",
                      help="the simulated sensor: carla (-15 to 15 degrees, uniform rows, 80 m; "
                      "the default) or hdl64e (KITTI's HDL-64E beam table, 120 m: a 64-row size "
                      "holds every beam, a 16-row size every 4th beam)")
    make.add_argument("--overwrite", action="store_true",
                      help="replace the shards of an earlier run in FOLDER")
    make.add_argument("--no-progress", action="store_true", help="no progress bar")
    train = sub.add_parser("train", help="train a model from a YAML configuration (PyTorch)",
                           description="Train an occgp.iln model from a YAML configuration.")
    train.add_argument("config", metavar="CONFIG.yaml", help="the training configuration")
    tune = sub.add_parser(
        "tune-threshold", help="choose a selector's confidence threshold on held-out images",
        description="Score a trained candidate selector at several confidence thresholds on "
        "held-out training images (FOLDER's train split after the first --skip images), pick "
        "the pair of largest relative gain over inverse bilinear in IoU and range MAE at "
        "64x1024 and 128x2048, and write the checkpoint with it.")
    tune.add_argument("checkpoint", metavar="CHECKPOINT", help="model.pt of `occgp iln train`")
    tune.add_argument("folder", metavar="FOLDER", help="the dataset folder")
    tune.add_argument("output", metavar="OUTPUT", help="the checkpoint to write")
    tune.add_argument("--skip", type=_positive_int, default=0, metavar="N",
                      help="leave out the first N images (those trained on; default: 0)")
    tune.add_argument("--max-images", type=_positive_int, default=None, metavar="N",
                      help="use at most N images after the skipped ones")
    tune.add_argument("--thresholds", type=float, nargs="+", default=None, metavar="T",
                      help="the thresholds tried (default: 0.1 0.15 0.2 0.3 ... 0.7)")
    tune.add_argument("--no-return-thresholds", type=float, nargs="+", default=None,
                      metavar="T", help="the no-return thresholds tried "
                      "(default: 0.8 0.9 0.95 1)")
    return parser


def run(args) -> int:
    """Run the parsed ``iln`` command `args`.

    Parameters
    ----------
    args : argparse.Namespace
        What :func:`build_parser`'s parser returned.

    Returns
    -------
    status : int
        0 on success; 1 if the command raised ValueError, TypeError, OSError or ImportError
        (its message printed on stderr).
    """
    try:
        if args.iln_command == "make-dataset":
            from ._effects import SensorEffects  # noqa: PLC0415
            from ._range import LidarModel  # noqa: PLC0415
            from .data import make_dataset  # noqa: PLC0415

            sizes = args.sizes if args.sizes is not None else ["16x1024", "64x1024"]
            sensor = getattr(args, "sensor", "carla")
            model = LidarModel.hdl64e(table=True) if sensor == "hdl64e" else None
            counts = make_dataset(args.folder, args.n_train, args.n_test, sizes,
                                  images_per_scene=args.images_per_scene,
                                  images_per_shard=args.images_per_shard, seed=args.seed,
                                  model=model, overwrite=args.overwrite, n_jobs=args.n_jobs,
                                  progress=False if args.no_progress else None,
                                  effects=SensorEffects() if getattr(args, "effects", False)
                                  else None, vegetation=getattr(args, "vegetation", False))
            print(f"wrote {counts['train']} train and {counts['test']} test images "
                  f"({counts['shards']} shards) to {args.folder}")
        elif args.iln_command == "tune-threshold":
            from .tuning import (  # noqa: PLC0415
                DEFAULT_NO_RETURN_THRESHOLDS, DEFAULT_THRESHOLDS, tune_checkpoint,
            )

            record = tune_checkpoint(
                args.checkpoint, args.folder, args.output, skip=args.skip,
                max_images=args.max_images or None,
                thresholds=args.thresholds or DEFAULT_THRESHOLDS,
                no_return_thresholds=args.no_return_thresholds or DEFAULT_NO_RETURN_THRESHOLDS)
            print(f"threshold {record['threshold']:g}, no-return threshold "
                  f"{record['no_return_threshold']:g} (chosen on {record['images']} images) "
                  f"written to {args.output}")
        else:
            from .training import train_from_yaml  # noqa: PLC0415 - needs torch

            train_from_yaml(args.config)
    except (ValueError, TypeError, OSError, ImportError) as exc:
        print(f"occgp iln {args.iln_command}: error: {exc}", file=sys.stderr)
        return 1
    return 0


def main(argv=None) -> int:
    """``occgp iln`` with the arguments `argv`.

    Parameters
    ----------
    argv : list of str, optional
        The arguments after ``iln``; default: ``sys.argv[1:]``.

    Returns
    -------
    status : int
        0 on success; 1 for a failed command (its message on stderr).

    Raises
    ------
    SystemExit
        From argparse: code 2 for bad arguments (the usage message on stderr), 0 for
        ``--help``.
    """
    args = build_parser().parse_args(argv)
    return run(args)


if __name__ == "__main__":
    sys.exit(main())
