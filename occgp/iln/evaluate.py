"""Table 4.1 of the dissertation: up-sampling models scored on held-out range images.

:func:`evaluate` up-samples every low-resolution test image with each model
to each test resolution and scores the result against the true image of that
resolution (the same pose): the range MAE (:func:`~occgp.iln.metrics.range_mae`)
and IoU, precision, recall and F1 of the 3D points on a 0.1 m voxel grid
(:func:`~occgp.iln.metrics.voxel_scores`), each averaged over the images.
:func:`format_table` prints the rows in Table 4.1's layout. With
``regions=True`` the rows also score planar pixels, depth edges and no-return
boundaries apart (:func:`~occgp.iln.metrics.region_masks`), and
:func:`format_region_table` prints those columns.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

import numpy as np

from .._docfill import fill_doc
from .._validation import as_numeric, check_bool, check_real
from ._common import (
    DOC_SECTIONS, as_lidar, as_size, as_size_list, check_images, check_rows, column_line,
    out_model,
    predict_image, resolve, resolve_models,
)
from ._range import LidarModel, range_image_to_points
from .metrics import REGIONS, range_mae, region_masks, voxel_scores

__all__ = ["evaluate", "format_table", "format_region_table", "METRICS", "REGION_COLUMNS",
           "DEFAULT_OUT_SIZES"]

#: The scores of a row, in Table 4.1's order.
METRICS = ("mae", "iou", "precision", "recall", "f1")
#: Table 4.1's test resolutions (from 16 x 1024 inputs).
DEFAULT_OUT_SIZES = ((64, 1024), (128, 2048), (256, 4096))
_LABELS = {"mae": "MAE", "iou": "IoU", "precision": "Precision", "recall": "Recall",
           "f1": "F1"}
#: The per-region columns of a row of ``evaluate(..., regions=True)``: the MAE and the share of
#: the pixels of each region of :func:`~occgp.iln.metrics.region_masks`.
REGION_COLUMNS = tuple(f"{kind}_{region}" for region in REGIONS for kind in ("share", "mae"))


def _near_no_return(low, in_lidar, out_lidar):
    """(n, rows, cols) bool: an input pixel around the out pixel's query lacks a return.

    The 4 input pixels are those the models read (:mod:`occgp.iln.models`): rows clamped,
    columns wrapped for a 360° sensor and clamped otherwise; pixels outside the input's field
    of view count as near a no-return (no model reads anything for them).
    """
    elev, azim = out_lidar.pixel_angles()
    v, u = in_lidar.angles_to_pixels(np.asarray(elev).ravel(), np.asarray(azim).ravel())
    rows, cols = in_lidar.rows, in_lidar.cols
    eps = 1e-4
    inside = (v >= -eps) & (v <= rows + eps) & (u >= -eps) & (u <= cols + eps)
    v = np.clip(v, 0, rows) - 0.5
    u = np.clip(u, 0, cols) - 0.5
    i0 = np.floor(v).astype(np.int64)
    j0 = np.floor(u).astype(np.int64)
    ii = np.clip(np.stack([i0, i0 + 1]), 0, rows - 1)
    jj = np.stack([j0, j0 + 1])
    jj = np.mod(jj, cols) if float(in_lidar.horizontal_fov) >= 360.0 else np.clip(jj, 0, cols - 1)
    empty = low <= 0                                                  # (n, rows, cols)
    near = np.zeros((len(low), v.size), dtype=bool)
    for i in ii:
        for j in jj:
            near |= empty[:, i, j]
    near |= ~inside
    return near.reshape(len(low), out_lidar.rows, out_lidar.cols)


@fill_doc(**DOC_SECTIONS)
def evaluate(models: Any, test_images: Mapping[Any, Any], *,
             in_size: Any = (16, 1024), out_sizes: Any = DEFAULT_OUT_SIZES,
             lidar: LidarModel | None = None, voxel_size: float = 0.1,
             device: Any = None, progress: bool | None = None, regions: bool = False,
             edge_threshold: float = 0.5) -> list[dict[str, Any]]:
    """Score up-sampling models on held-out range images (Table 4.1), optionally by region.

    For each test resolution and each model, every image of `in_size` is
    up-sampled to that resolution over the same fields of view
    (:func:`occgp.iln.upsample.upsample_range_image`) and compared with the
    true image of that resolution: the MAE of the ranges over the pixels
    where the truth has a return (a predicted no-return counts with the true
    range as its error), and IoU, precision, recall and F1 of the two point
    clouds (pixel-center directions, no-return pixels dropped) on a
    `voxel_size` grid in the sensor frame. Each score is the mean over the
    images (images whose truth holds no return are skipped, and counted in
    ``n_images``' complement).

    With `regions`, each row also scores three regions of the true pixels
    (:func:`~occgp.iln.metrics.region_masks`): *planar* pixels (a true
    return that inverse bilinear interpolation predicts within
    `edge_threshold`), *depth edges* (inverse bilinear off by more than
    `edge_threshold`) and *no-return boundaries* (the true pixel, or one of
    the 4 input pixels its query reads, has no return). The regions depend on
    the truth and the input only, never on the model scored, so every row
    splits the same pixels. ``mae_<region>`` is the MAE over the region's
    true returns and ``share_<region>`` the region's fraction of all pixels,
    both pooled over the images (not averaged per image: a region may be
    empty in one image); ``mae_<region>`` is NaN where the region holds no
    true return.

    Parameters
    ----------
    models : dict of str to model, or list of str
        Row names to models: ``"bilinear"``, ``"inverse-bilinear"``, ``"edge-aware"``,
        ``"pretrained"`` or a model of :mod:`occgp.iln.models` (see
        :func:`occgp.iln.upsample.resolve_model`).
        A list of names uses each name as its row's name.
    test_images : dict
        Size -> float32 images of shape (n_images, rows, cols), the same
        poses at every size (e.g. the result of
        ``occgp.iln.data.load_shards(folder, sizes)``). Sizes are
        ``(rows, cols)`` pairs or strings like ``"64x1024"`` /
        ``"r64x1024"``; it must hold `in_size` and every `out_sizes`.
    in_size : (int, int) or str, default=(16, 1024)
        Size of the input images.
    out_sizes : sequence of (int, int) or str, default=((64, 1024), (128, 2048), (256, 4096))
        Test resolutions.
    lidar : LidarModel, optional
        The sensor's fields of view and range (its size is ignored); default
        ``LidarModel.carla()``.
    voxel_size : float, default=0.1
        Voxel edge of the point scores, metres, > 0.
    device : str or torch.device, optional
        Where models built from names run.
    progress : bool or None, default=None
        Show a progress bar; None shows it only on a terminal.
    regions : bool, default=False
        Add the per-region columns :data:`REGION_COLUMNS` to every row
        (up-samples every image once more, with inverse bilinear
        interpolation, to find the depth edges).
    edge_threshold : float, default=0.5
        Error of inverse bilinear interpolation in metres above which a
        pixel is a depth edge, > 0 (used with `regions`).

    Returns
    -------
    rows : list of dict
        One per (resolution, model), resolution by resolution in the order of
        `out_sizes`, models in the order given: ``method``, ``resolution``
        (``"64x1024"``), ``mae``, ``iou``, ``precision``, ``recall``, ``f1``,
        ``n_images`` and ``seconds_per_image`` (up-sampling time); with
        `regions` also the columns of :data:`REGION_COLUMNS`
        (``share_planar``, ``mae_planar``, ``share_edge``, ...).

    Raises
    ------
    ValueError
        If a size is malformed, repeated in `out_sizes` or missing from
        `test_images`, the images of a
        size are not of shape (n_images, rows, cols), hold NaN, inf or
        negative ranges or ranges beyond ``lidar.max_range``, the sizes hold
        different numbers of images, `models` is empty or names an unknown
        model, or `voxel_size` or `edge_threshold` is not positive.
    TypeError
        If an argument has a wrong type.
    {model_errors}

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> low = rng.uniform(5, 20, (1, 4, 64)).astype(np.float32)
    >>> high = np.repeat(low, 4, axis=1)
    >>> rows = evaluate(["bilinear"], {"4x64": low, "16x64": high}, in_size="4x64",
    ...                 out_sizes=["16x64"], progress=False)
    >>> rows[0]["method"], rows[0]["resolution"], rows[0]["n_images"]
    ('bilinear', '16x64', 1)
    """
    from tqdm.auto import tqdm

    in_size = as_size(in_size, "in_size")
    out_sizes = as_size_list(out_sizes, "out_sizes")
    voxel_size = check_real(voxel_size, "voxel_size", low=0.0)
    regions = check_bool(regions, "regions")
    edge_threshold = check_real(edge_threshold, "edge_threshold", low=0.0)
    lidar = as_lidar(lidar)
    images = check_images(test_images, [in_size] + [s for s in out_sizes if s != in_size])
    in_lidar = lidar.with_size(*in_size)
    for size, arr in images.items():
        if arr.max() > lidar.max_range:
            raise ValueError(f"test_images[{size[0]}x{size[1]}] holds ranges up to "
                             f"{arr.max():g} m, beyond lidar.max_range = {lidar.max_range:g}")
    nets = resolve_models(models, lidar, device)
    prior_net = resolve("inverse-bilinear", lidar, device, "evaluate") if regions else None
    low = images[in_size]
    n = len(low)
    rows = []
    bar = tqdm(total=len(out_sizes) * len(nets) * n, disable=None if progress is None
               else not progress, desc="evaluate", unit="image")
    try:
        for size in out_sizes:
            out_lidar = out_model(lidar, *size)
            truth = images[size]
            masks = (_region_masks(prior_net, low, truth, in_lidar, out_lidar, edge_threshold)
                     if regions else None)
            for name, net in nets.items():
                sums = dict.fromkeys(METRICS, 0.0)
                region_sums = {r: [0.0, 0] for r in REGIONS}
                counted, seconds = 0, 0.0
                for k in range(n):
                    t0 = time.perf_counter()
                    pred = predict_image(net, low[k], in_lidar, out_lidar)
                    seconds += time.perf_counter() - t0
                    bar.update()
                    if masks is not None:
                        hit = truth[k] > 0
                        err = np.abs(pred.astype(np.float64) - truth[k])
                        for region in REGIONS:
                            sel = masks[region][k] & hit
                            region_sums[region][0] += float(err[sel].sum())
                            region_sums[region][1] += int(np.count_nonzero(sel))
                    if not (truth[k] > 0).any():
                        continue
                    sums["mae"] += range_mae(pred, truth[k])
                    scores = voxel_scores(range_image_to_points(pred, out_lidar),
                                          range_image_to_points(truth[k], out_lidar),
                                          voxel_size)
                    for key, value in scores.items():
                        sums[key] += value
                    counted += 1
                row = {"method": name, "resolution": f"{size[0]}x{size[1]}"}
                row.update({key: (sums[key] / counted if counted else float("nan"))
                            for key in METRICS})
                row.update(n_images=counted, seconds_per_image=seconds / n)
                if masks is not None:
                    for region in REGIONS:
                        total, count = region_sums[region]
                        row[f"share_{region}"] = float(masks[region].mean())
                        row[f"mae_{region}"] = total / count if count else float("nan")
                rows.append(row)
    finally:
        bar.close()
    return rows


def _region_masks(prior_net, low, truth, in_lidar, out_lidar, edge_threshold):
    """:func:`region_masks` of every test image of one resolution (stacked)."""
    prior = predict_image(prior_net, low, in_lidar, out_lidar)
    near = _near_no_return(low, in_lidar, out_lidar)
    return region_masks(truth, prior, near, edge_threshold=edge_threshold)


@fill_doc(**DOC_SECTIONS)
def format_table(rows: Any, *, floatfmt: str = ".3f", with_time: bool = False) -> str:
    """Rows of :func:`evaluate` in Table 4.1's layout.

    One block per test resolution, headed ``Test resolution: 64x1024``, with
    a line per method: MAE, IoU, Precision, Recall, F1 (and, with `with_time`,
    the up-sampling seconds per image).

    Parameters
    ----------
    rows : iterable of dict
        With ``method``, ``resolution`` and the scores of :data:`METRICS`.
    floatfmt : str, default=".3f"
        Format of the scores.
    with_time : bool, default=False
        Add a column of ``seconds_per_image``.

    {table_sections}

    Examples
    --------
    >>> print(format_table([{"method": "Bilinear", "resolution": "64x1024", "mae": 2.372,
    ...                      "iou": 0.202, "precision": 0.322, "recall": 0.328, "f1": 0.325}]))
    Method      MAE    IoU  Precision  Recall     F1
    Test resolution: 64x1024
    Bilinear  2.372  0.202      0.322   0.328  0.325
    """
    fields = ("method", "resolution") + METRICS + (("seconds_per_image",) if with_time else ())
    records = check_rows(rows, fields)
    columns = METRICS + (("seconds_per_image",) if with_time else ())
    header = ["Method"] + [_LABELS.get(c, "time [s]") for c in columns]
    cells = [[str(r["method"])] + [format(float(r[c]), floatfmt) for c in columns]
             for r in records]
    return _grouped_table(header, cells, records)


def _grouped_table(header, cells, records):
    """The lines of a table, a ``Test resolution: ...`` line before each resolution's rows."""
    line, _ = column_line(header, cells)
    lines = [line(header)]
    current = None
    for rec, cell in zip(records, cells):
        if rec["resolution"] != current:
            current = rec["resolution"]
            lines.append(f"Test resolution: {current}")
        lines.append(line(cell))
    return "\n".join(lines)


@fill_doc(**DOC_SECTIONS)
def format_region_table(rows: Any, *, floatfmt: str = ".3f") -> str:
    """The per-region columns of ``evaluate(..., regions=True)`` as a table.

    One block per test resolution, headed ``Test resolution: 64x1024``, with a line per
    method: for the planar pixels, the depth edges and the no-return boundaries, the MAE over
    the region's true returns and the region's share of the pixels.

    Parameters
    ----------
    rows : iterable of dict
        With ``method``, ``resolution`` and the columns of :data:`REGION_COLUMNS`.
    floatfmt : str, default=".3f"
        Format of the scores.

    {table_sections}

    Examples
    --------
    >>> row = {"method": "Bilinear", "resolution": "64x1024", "share_planar": 0.8,
    ...        "mae_planar": 0.05, "share_edge": 0.1, "mae_edge": 2.5,
    ...        "share_boundary": 0.1, "mae_boundary": 4.0}
    >>> print(format_region_table([row]))
    Method    planar share  planar MAE  edge share  edge MAE  boundary share  boundary MAE
    Test resolution: 64x1024
    Bilinear         0.800       0.050       0.100     2.500           0.100         4.000
    """
    records = check_rows(rows, ("method", "resolution") + REGION_COLUMNS)
    header = ["Method"] + [f"{c.split('_', 1)[1]} {'MAE' if c.startswith('mae') else 'share'}"
                           for c in REGION_COLUMNS]
    cells = [[str(r["method"])] + [format(float(r[c]), floatfmt) for c in REGION_COLUMNS]
             for r in records]
    return _grouped_table(header, cells, records)
