"""The confidence thresholds of a trained :class:`~occgp.iln.models.CandidateSelector`.

:func:`tune_threshold` scores a selector at several thresholds on held-out images (training
scenes the model did not see, never the test scenes) and picks the one of best mean IoU over
the resolutions; :func:`tune_checkpoint` does so for a checkpoint of ``occgp iln train`` and
writes a copy with the chosen threshold and the table it was chosen from
(``occgp iln tune-threshold``).
"""

from __future__ import annotations

import copy
import os
from pathlib import Path
from typing import Any

import numpy as np

from .._atomic import atomic_open
from .._validation import as_float, as_path, check_int, check_real
from ._common import as_lidar, as_size, as_size_list, check_images, out_model
from ._range import range_image_to_points
from .metrics import range_mae, voxel_scores

__all__ = ["tune_threshold", "tune_checkpoint", "DEFAULT_THRESHOLDS", "DEFAULT_NO_RETURN_THRESHOLDS"]

#: The thresholds :func:`tune_threshold` tries by default.
DEFAULT_THRESHOLDS = (0.1, 0.15, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7)
#: The no-return thresholds :func:`tune_threshold` tries by default.
DEFAULT_NO_RETURN_THRESHOLDS = (0.8, 0.9, 0.95, 1.0)


def _grid(values, name) -> list:
    try:
        out = [as_float(v) for v in values]     # a huge int: inf, refused below
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a sequence of numbers, got {values!r}") from None
    if not out or not all(0.0 <= v <= 1.0 for v in out):
        raise ValueError(f"{name} must be a non-empty sequence of numbers in [0, 1], got {values!r}")
    return sorted(set(out))


def tune_threshold(model: Any, images: Any, *, thresholds: Any = DEFAULT_THRESHOLDS,
                   no_return_thresholds: Any = DEFAULT_NO_RETURN_THRESHOLDS,
                   in_size: Any = (16, 1024), out_sizes: Any = ((64, 1024), (128, 2048)),
                   lidar: Any = None, voxel_size: float = 0.1,
                   progress: bool | None = None) -> tuple:
    """The confidence thresholds of a selector that score best on held-out images.

    Every pair of `thresholds` x `no_return_thresholds` is scored on every image at every
    resolution of `out_sizes` (range MAE and 0.1 m voxel IoU, as :func:`evaluate`), and so is
    the prior (inverse bilinear interpolation, the selector that never switches). Among the
    pairs whose MAE is at most the prior's at every resolution, the one chosen has the largest
    gain over the prior in both scores, ``IoU / IoU_prior - MAE / MAE_prior`` averaged over
    the resolutions (a relative IoU gain and a relative MAE drop weigh the same); where no
    pair gains, ``(1.0, 1.0)``, the prior.
    The network runs once per image and resolution; each pair then chooses among the
    candidates' ranges (:meth:`CandidateSelector.candidate_table`).

    Parameters
    ----------
    model : CandidateSelector
        A trained selector (not changed).
    images : dict
        Size -> float32 images (n, rows, cols) of the same poses, as :func:`evaluate` takes
        them: held-out *training* scenes (choosing on the test scenes would tune on them).
    thresholds : sequence of float, default=DEFAULT_THRESHOLDS
        Values of ``threshold`` tried, in [0, 1].
    no_return_thresholds : sequence of float, default=DEFAULT_NO_RETURN_THRESHOLDS
        Values of ``no_return_threshold`` tried, in [0, 1].
    in_size : (int, int) or str, default=(16, 1024)
        Size of the input images.
    out_sizes : sequence, default=((64, 1024), (128, 2048))
        The resolutions scored.
    lidar : LidarModel, optional
        The sensor (default ``LidarModel.carla()``).
    voxel_size : float, default=0.1
        Voxel edge of the IoU, metres.
    progress : bool or None, default=None
        Progress bar (None: only on a terminal).

    Returns
    -------
    threshold : float
    no_return_threshold : float
        The chosen pair.
    rows : list of dict
        One per pair and resolution, then the prior's: ``threshold``,
        ``no_return_threshold`` (None for the prior), ``resolution`` (``"64x1024"``),
        ``iou`` and ``mae`` averaged over the images.

    Raises
    ------
    TypeError
        If `model` is not a :class:`CandidateSelector` or a grid is not numeric.
    ValueError
        If a grid is empty or holds a value outside [0, 1], or as :func:`evaluate` for the
        images and sizes.
    """
    from tqdm.auto import tqdm

    from .models import CandidateSelector, choose_candidates, image_queries

    if not isinstance(model, CandidateSelector):
        raise TypeError(f"model must be a CandidateSelector, got {type(model).__name__}")
    pairs = [(t, n) for t in _grid(thresholds, "thresholds")
             for n in _grid(no_return_thresholds, "no_return_thresholds")]
    voxel_size = check_real(voxel_size, "voxel_size", low=0.0)
    in_size = as_size(in_size, "in_size")
    out_sizes = as_size_list(out_sizes, "out_sizes")
    lidar = as_lidar(lidar)
    checked = check_images(images, [in_size] + [s for s in out_sizes if s != in_size])
    low = checked[in_size]
    in_lidar = lidar.with_size(*in_size)
    keys = pairs + [None]  # None: the prior
    sums = {(key, size): [0.0, 0.0, 0] for key in keys for size in out_sizes}
    bar = tqdm(total=len(out_sizes) * len(low), disable=None if progress is None
               else not progress, desc="tune threshold", unit="image")
    try:
        for size in out_sizes:
            out_lidar = out_model(lidar, *size)
            queries, inside, wrap = image_queries(in_lidar, out_lidar)
            for k, image in enumerate(low):
                truth = checked[size][k]
                bar.update()
                if not (truth > 0).any():
                    continue
                ranges, probs = model.candidate_table(image, queries, wrap=wrap)
                true_points = range_image_to_points(truth, out_lidar)
                for key in keys:
                    if key is None:
                        chosen = ranges[:, 0]
                    else:
                        choice = choose_candidates(probs, *key)
                        chosen = np.take_along_axis(ranges, choice[:, None], 1)[:, 0]
                    pred = np.zeros(out_lidar.rows * out_lidar.cols, np.float32)
                    pred[inside] = np.minimum(chosen, np.float32(out_lidar.max_range))
                    pred = pred.reshape(out_lidar.rows, out_lidar.cols)
                    iou = voxel_scores(range_image_to_points(pred, out_lidar), true_points,
                                       voxel_size)["iou"]
                    entry = sums[(key, size)]
                    entry[0] += iou
                    entry[1] += range_mae(pred, truth)
                    entry[2] += 1
    finally:
        bar.close()
    rows = []
    for key in keys:
        for size in out_sizes:
            iou, mae, count = sums[(key, size)]
            rows.append({"threshold": 1.0 if key is None else key[0],
                         "no_return_threshold": None if key is None else key[1],
                         "resolution": f"{size[0]}x{size[1]}",
                         "iou": iou / count if count else float("nan"),
                         "mae": mae / count if count else float("nan")})
    prior = {r["resolution"]: r for r in rows if r["no_return_threshold"] is None}
    best, best_gain = (1.0, 1.0), 0.0
    for key in pairs:
        mine = [r for r in rows if (r["threshold"], r["no_return_threshold"]) == key]
        if any(r["mae"] > prior[r["resolution"]]["mae"] for r in mine):
            continue
        gain = float(np.mean([r["iou"] / prior[r["resolution"]]["iou"]
                              - r["mae"] / prior[r["resolution"]]["mae"] for r in mine]))
        if gain > best_gain:
            best, best_gain = key, gain
    return best[0], best[1], rows


def tune_checkpoint(checkpoint: Any, folder: Any, output: Any, *, split: str = "train",
                    skip: int = 0, max_images: int | None = None,
                    thresholds: Any = DEFAULT_THRESHOLDS,
                    no_return_thresholds: Any = DEFAULT_NO_RETURN_THRESHOLDS, in_size: Any = (16, 1024),
                    out_sizes: Any = ((64, 1024), (128, 2048)),
                    progress: bool | None = None) -> dict:
    """Tune the threshold of a selector checkpoint and write a copy holding it.

    Parameters
    ----------
    checkpoint : str or os.PathLike
        ``model.pt`` or ``last.pt`` of ``occgp iln train`` holding a selector.
    folder : str or os.PathLike
        The data set of :func:`~occgp.iln.data.make_dataset` (or a split folder).
    output : str or os.PathLike
        The checkpoint to write: `checkpoint`'s content with the model's two thresholds set,
        and ``threshold_tuning``: the images used, the pairs tried and their IoU and MAE.
        The file is written atomically: the previous file stays intact if the write fails.
    split : str, default="train"
        The split of `folder` to read.
    skip : int, default=0
        Leave out the first `skip` images (those the model was trained on, e.g. the
        training run's ``max_images``).
    max_images : int, optional
        Use at most this many images after the skipped ones.
    thresholds, no_return_thresholds : sequence of float
        The grids of :func:`tune_threshold`.
    in_size : (int, int) or str, default=(16, 1024)
        Size of the input images.
    out_sizes : sequence, default=((64, 1024), (128, 2048))
        The resolutions scored.
    progress : bool or None, default=None
        Progress bar.

    Returns
    -------
    record : dict
        The ``threshold_tuning`` entry written: ``threshold``, ``no_return_threshold``,
        ``images``, ``skip``, ``scene_seeds`` (first and last) and ``rows`` (those of
        :func:`tune_threshold`).

    Raises
    ------
    OSError
        If a file cannot be read or written.
    ValueError
        If the checkpoint holds no selector, no image is left after `skip`, or as
        :func:`tune_threshold`.
    """
    import torch

    from .data import load_shards
    from .models import make
    from .training import load_checkpoint

    skip = check_int(skip, "skip", low=0)
    if max_images is not None:
        max_images = check_int(max_images, "max_images", low=1)
    ckpt = load_checkpoint(checkpoint)
    spec = ckpt["model"]
    if spec.get("name") != "selector":
        raise ValueError(f"checkpoint {str(checkpoint)!r} holds a {spec.get('name')!r} model, "
                         f"not a selector")
    model = make(spec, load_sd=True)
    sizes = [f"{r}x{c}" for r, c in [as_size(in_size, "in_size"),
                                     *as_size_list(out_sizes, "out_sizes")]]
    folder = Path(os.path.expanduser(str(folder)))
    sub = folder / split
    images, meta = load_shards(sub if sub.is_dir() else folder, sizes, return_meta=True)
    stop = None if max_images is None else skip + max_images
    held = {k: images[k][skip:stop] for k in sizes}
    n = len(held[sizes[0]])
    if n == 0:
        raise ValueError(f"no image is left after skip={skip} ({len(images[sizes[0]])} in all)")
    lidar = meta["model"]
    threshold, no_return, rows = tune_threshold(
        model, held, thresholds=thresholds, no_return_thresholds=no_return_thresholds,
        in_size=sizes[0], out_sizes=sizes[1:], lidar=lidar, progress=progress)
    seeds = meta["seeds"][skip:stop]
    record = {"threshold": threshold, "no_return_threshold": no_return, "images": n,
              "skip": skip, "scene_seeds": [int(seeds.min()), int(seeds.max())],
              "rows": rows}
    out = dict(ckpt)
    out["model"] = copy.deepcopy(spec)
    out["model"]["args"] = dict(spec["args"], threshold=threshold,
                                no_return_threshold=no_return)
    out["threshold_tuning"] = record
    path = as_path(output, "output")
    with atomic_open(path, name="output") as fh:
        torch.save(out, fh)
    return record
