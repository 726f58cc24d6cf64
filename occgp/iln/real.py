"""Up-sampling scored on a real frame: keep every k-th beam, predict the others at their elevations.

:func:`real_frame_scores` keeps every `keep_every`-th row of a real range
image (e.g. 16 of an HDL-64E's 64 beams) as the input and predicts the other
rows with each model at the true elevations of their beams: the input's
:class:`~occgp.iln.LidarModel` has the kept beams' elevations as its table,
so a predicted beam's query row lies between its two kept neighbours at the
fraction of its elevation between theirs (linear in elevation, see
:mod:`occgp.iln._beam_tables`), whatever the pitches. It scores, over the
predicted beams only (the kept ones are the input), the range MAE over their
true returns and IoU, precision, recall and F1 of their points on a voxel
grid (:mod:`occgp.iln.metrics`), and times each model.
:func:`format_real_table` prints the rows with each model's IoU as a ratio to
a baseline's.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._docfill import fill_doc
from .._validation import as_numeric, check_int, check_real
from ._common import DOC_SECTIONS, MODEL_NAMES, check_rows, column_line, predict_image, \
    resolve, torch_models
from ._range import LidarModel, range_image_to_points
from .metrics import range_mae, voxel_scores

__all__ = ["real_frame_scores", "format_real_table", "kept_beams_model", "REAL_FIELDS"]

#: The fields of a row of :func:`real_frame_scores`.
REAL_FIELDS = ("model", "mae", "iou", "precision", "recall", "f1", "seconds")


def kept_beams_model(lidar: LidarModel, keep_every: int = 4) -> tuple:
    """The sensor model of every `keep_every`-th beam of `lidar`, and the kept rows.

    Parameters
    ----------
    lidar : LidarModel
        The full sensor (with or without a per-beam table).
    keep_every : int, default=4
        Keep rows ``0, k, 2k, ...``; at least 2, and at most ``lidar.rows - 1``.

    Returns
    -------
    kept_lidar : LidarModel
        Same fields of view, columns and range, ``beam_elevations`` the kept
        rows' elevations.
    kept : ndarray of int64
        The kept rows of `lidar`.

    Raises
    ------
    TypeError
        If `lidar` is not a LidarModel or `keep_every` not an int.
    ValueError
        If `keep_every` is out of range.

    Examples
    --------
    >>> m, kept = kept_beams_model(LidarModel.hdl64e(table=True), 4)
    >>> m.rows, kept[:3].tolist(), m.beam_elevations[:2]
    (16, [0, 4, 8], (2.0, 0.6667))
    """
    if not isinstance(lidar, LidarModel):
        raise TypeError(f"lidar must be a LidarModel (occgp.iln), got {type(lidar).__name__}")
    keep_every = check_int(keep_every, "keep_every", low=2, high=max(lidar.rows - 1, 2))
    kept = np.arange(0, lidar.rows, keep_every, dtype=np.int64)
    table = tuple(float(e) for e in lidar.elevations()[kept])
    return LidarModel(len(kept), lidar.cols, lidar.vertical_fov, lidar.horizontal_fov,
                      lidar.max_range, table), kept


def _resolve(name, model, lidar, device):
    """A model from a name of MODEL_NAMES, any registered name, a spec dict or a model."""
    RangeModel, make = torch_models("real_frame_scores")
    if isinstance(model, str) and model not in MODEL_NAMES:
        from .models import available_models
        if model not in available_models():
            raise ValueError(f"models[{name!r}] must be one of {MODEL_NAMES}, a registered "
                             f"model name {available_models()}, a spec dict or a model, "
                             f"got {model!r}")
        model = {"name": model, "args": {}}
    if isinstance(model, Mapping):
        spec = dict(model)
        args = dict(spec.get("args", {}))
        try:  # the sensor's max_range, where the model takes one
            built = make({**spec, "args": {"max_range": float(lidar.max_range), **args}},
                         load_sd="sd" in spec)
        except ValueError:
            built = make(spec, load_sd="sd" in spec)
        return built.to(device) if device is not None else built
    return resolve(model, lidar, device, "real_frame_scores")


def _models(models):
    if isinstance(models, str):
        return [(models, models)]
    if isinstance(models, Mapping):
        items = list(models.items())
    elif isinstance(models, (list, tuple)):
        items = [(m if isinstance(m, str) else type(m).__name__, m) for m in models]
    else:
        raise TypeError(f"models must be a name, a list of names or models, or a dict "
                        f"label -> model, got {type(models).__name__}")
    if not items:
        raise ValueError("models must name at least one model, got none")
    for label, _ in items:
        if not isinstance(label, str):
            raise TypeError(f"models keys must be str, got {type(label).__name__}")
    return items


@fill_doc(**DOC_SECTIONS)
def real_frame_scores(models: Any, image: ArrayLike, lidar: LidarModel, *,
                      keep_every: int = 4, voxel_size: float = 0.1,
                      device: Any = None) -> list[dict[str, Any]]:
    """Score up-sampling models on a real frame by predicting its dropped beams.

    Rows ``0, k, 2k, ...`` (``k = keep_every``) of `image` are the input, on
    :func:`kept_beams_model`'s sensor; each model predicts the full image of
    `lidar` (the other rows at their true elevations, see the module), and
    only the dropped rows are scored: the range MAE over their true returns
    (:func:`~occgp.iln.metrics.range_mae`) and the voxel scores of their
    points against the true ones (:func:`~occgp.iln.metrics.voxel_scores`).
    A dropped beam below the lowest kept one is predicted from that one
    alone (the models clamp their vertical neighbours).

    Parameters
    ----------
    models : str, list or dict
        A model or several: ``"bilinear"``, ``"inverse-bilinear"``,
        ``"pretrained"`` (the shipped candidate selector), any name of
        :func:`occgp.iln.available_models` (built with its default arguments
        and `lidar`'s ``max_range``), a spec dict for :func:`occgp.iln.make`,
        or a model; a dict maps row labels to any of these.
    image : array-like of shape (lidar.rows, lidar.cols)
        The real frame's ranges in metres, 0.0 for no return, e.g. from
        :func:`occgp.iln.read_lidar_frame`.
    lidar : LidarModel
        Its sensor (with its per-beam table, if any).
    keep_every : int, default=4
        Keep every `keep_every`-th beam, from 2 to ``lidar.rows - 1``.
    voxel_size : float, default=0.1
        Voxel edge of the voxel scores, metres.
    device : str or torch.device, optional
        Where models built from names run; default the CPU.

    Returns
    -------
    rows : list of dict
        One per model, with the keys ``model`` (its label), ``mae``
        (metres), ``iou``, ``precision``, ``recall``, ``f1`` and
        ``seconds`` (the up-sampling's wall time).

    Raises
    ------
    ValueError
        If `image` does not have `lidar`'s shape, is not finite or holds
        ranges outside ``[0, lidar.max_range]``, the dropped beams hold no
        return, `keep_every` or `voxel_size` is out of range, or a model
        name is unknown.
    TypeError
        If an argument has a wrong type.
    {model_errors}
    """
    if not isinstance(lidar, LidarModel):
        raise TypeError(f"lidar must be a LidarModel (occgp.iln), got {type(lidar).__name__}")
    truth = as_numeric(image, "image")
    if truth.shape != lidar.shape:
        raise ValueError(f"image must have lidar's shape {lidar.shape}, got {truth.shape}")
    truth = np.asarray(truth, dtype=np.float32)
    if not np.isfinite(truth).all() or (truth < 0).any() or (truth > lidar.max_range).any():
        raise ValueError(f"image must hold finite ranges in [0, lidar.max_range = "
                         f"{lidar.max_range:g}] m (0.0 for no return)")
    voxel_size = check_real(voxel_size, "voxel_size", low=0.0)
    kept_lidar, kept = kept_beams_model(lidar, keep_every)
    held = np.setdiff1d(np.arange(lidar.rows), kept)
    true_held = np.zeros_like(truth)
    true_held[held] = truth[held]
    if not (true_held > 0).any():
        raise ValueError("image holds no return in the dropped beams: nothing to score")
    true_points = range_image_to_points(true_held, lidar)
    out = []
    for label, spec in _models(models):
        net = _resolve(label, spec, lidar, device)
        start = time.perf_counter()
        pred = predict_image(net, truth[kept], kept_lidar, lidar)
        seconds = time.perf_counter() - start
        pred_held = np.zeros_like(pred)
        pred_held[held] = pred[held]
        scores = voxel_scores(range_image_to_points(pred_held, lidar), true_points, voxel_size)
        out.append({"model": label, "mae": range_mae(pred[held], truth[held]), **scores,
                    "seconds": seconds})
    return out


@fill_doc(**DOC_SECTIONS)
def format_real_table(rows: list, baseline: str = "bilinear") -> str:
    """The rows of :func:`real_frame_scores` as a table, with IoU ratios to `baseline`'s.

    Parameters
    ----------
    rows : list of dict
        As :func:`real_frame_scores` returns.
    baseline : str, default="bilinear"
        The label whose IoU the ``IoU / base`` column divides by; the column
        is left blank when no row has that label.

    {table_sections}

    Examples
    --------
    >>> row = {"model": "bilinear", "mae": 1.0, "iou": 0.2, "precision": 0.3,
    ...        "recall": 0.4, "f1": 0.34, "seconds": 0.01}
    >>> print(format_real_table([row]))
    Model     MAE (m)    IoU  Precision  Recall  IoU / base  Time (s)
    bilinear    1.000  0.200      0.300   0.400        1.00      0.01
    """
    records = check_rows(rows, REAL_FIELDS)
    base = next((r["iou"] for r in records if r["model"] == baseline), None)
    header = ["Model", "MAE (m)", "IoU", "Precision", "Recall", "IoU / base", "Time (s)"]
    cells = [[str(r["model"]), f"{r['mae']:.3f}", f"{r['iou']:.3f}", f"{r['precision']:.3f}",
              f"{r['recall']:.3f}", f"{r['iou'] / base:.2f}" if base else "",
              f"{r['seconds']:.2f}"] for r in records]
    line, _ = column_line(header, cells)
    return "\n".join([line(header)] + [line(c) for c in cells])
