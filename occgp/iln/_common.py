"""Helpers shared by the front ends of occgp.iln (up-sampling, evaluation, experiment, data).

Argument checks (sizes, poses) and the path from a model name to an up-sampled image:
:func:`resolve` (a name or a model -> a model, torch imported on first use), :func:`out_model`
(the checked output sensor) and :func:`predict_image`. numpy alone is imported here.
"""

from __future__ import annotations

import re
from collections.abc import Mapping

import numpy as np

from .._validation import as_float, as_numeric, check_int
from ._range import LidarModel

__all__ = ["MAX_OUTPUT_PIXELS", "MODEL_NAMES", "torch_models", "pretrained_model", "resolve",
           "check_images",
           "resolve_models", "out_model", "predict_image", "as_size", "as_size_list", "as_lidar",
           "as_pose", "check_rows", "column_line", "DOC_SECTIONS"]

#: Largest up-sampled image, pixels (e.g. 512 x 8192): bounds the memory of one call.
MAX_OUTPUT_PIXELS = 2 ** 22
#: Model names :func:`occgp.iln.upsample.resolve_model` accepts.
MODEL_NAMES = ("bilinear", "inverse-bilinear", "edge-aware", "pretrained")
#: Largest deviation of a pose's rotation from orthonormal (``R R^T - I``).
_ORTHO_TOL = 1e-6
#: Docstring sections of the front ends (fragments for :func:`occgp._docfill.fill_doc`):
#: ``model_errors``, the errors of building a model by name, and ``table_sections``, the
#: Returns and Raises sections of the table formatters.
DOC_SECTIONS = {
    "model_errors": """OSError
    If ``"pretrained"`` is asked and no weights ship with this
    installation.
ImportError
    If PyTorch is not installed.""",
    "table_sections": """Returns
-------
table : str

Raises
------
ValueError
    If a row lacks a field.
TypeError
    If a row is not a mapping.""",
}


def torch_models(name):
    """``(RangeModel, make)`` of occgp.iln.models, or the ImportError of a missing torch."""
    try:
        from .models import RangeModel, make
    except ModuleNotFoundError as exc:
        if exc.name != "torch":
            raise
        raise ImportError(f"occgp.iln.{name} needs PyTorch: pip install 'occgp[iln]' (after "
                          f"pip install torch==2.13.0 on CPU machines)") from None
    return RangeModel, make


def pretrained_model():
    """``occgp.iln.pretrained()``, or OSError when this installation has no shipped weights."""
    try:
        import torch  # noqa: F401  (the shipped models need it)
        from ._weights import pretrained
    except ImportError:
        pretrained = None
    if not callable(pretrained):
        raise OSError("model='pretrained' needs occgp.iln.pretrained() and its shipped weights "
                      "(occgp/iln/weights/), which this installation lacks; pass a trained "
                      "model (occgp.iln.models.make(spec, load_sd=True)) or 'bilinear'")
    return pretrained()


def resolve(model, lidar, device, caller):
    """The model that a name of :data:`MODEL_NAMES` or a model stands for.

    A name builds a model on `device` (``max_range`` from `lidar` when given); a model is
    returned as it is. `caller` names the public function in the ImportError without torch.
    """
    RangeModel, make = torch_models(caller)
    if isinstance(model, str):
        if model in ("bilinear", "inverse-bilinear", "edge-aware"):
            args = {} if lidar is None else {"max_range": float(lidar.max_range)}
            built = make({"name": model, "args": args})
        elif model == "pretrained":
            built = pretrained_model()
        else:
            raise ValueError(f"model must be one of {MODEL_NAMES} or an occgp.iln model, "
                             f"got {model!r}")
        return built.to(device) if device is not None else built
    if not isinstance(model, RangeModel):
        raise TypeError(f"model must be one of {MODEL_NAMES} or an occgp.iln model "
                        f"(occgp.iln.models.make), got {type(model).__name__}")
    return model


def resolve_models(models, lidar, device, caller="evaluate"):
    """``{name: model}`` of a name, a list of names or a dict name -> model (or name)."""
    if isinstance(models, str):
        models = [models]
    if isinstance(models, Mapping):
        items = list(models.items())
    elif isinstance(models, (list, tuple)):
        items = []
        for m in models:
            if not isinstance(m, str):
                raise TypeError(f"models given as a list must hold names; pass a dict "
                                f"name -> model for models, got {type(m).__name__}")
            items.append((m, m))
    else:
        raise TypeError(f"models must be a dict name -> model (or name), or a list of names, "
                        f"got {type(models).__name__}")
    if not items:
        raise ValueError("models must name at least one model, got none")
    out = {}
    for name, model in items:
        if not isinstance(name, str):
            raise TypeError(f"models keys must be str, got {type(name).__name__}")
        out[name] = resolve(model, lidar, device, caller)
    return out


def out_model(lidar, rows, cols):
    """`lidar` at the output size ``(rows, cols)``, checked against :data:`MAX_OUTPUT_PIXELS`."""
    rows = check_int(rows, "rows", low=1)
    cols = check_int(cols, "cols", low=1)
    if rows * cols > MAX_OUTPUT_PIXELS:
        raise ValueError(f"rows * cols must be at most {MAX_OUTPUT_PIXELS} pixels, got "
                         f"{rows} x {cols} = {rows * cols}")
    return lidar.with_size(rows, cols)


def predict_image(net, image, lidar, out_lidar):
    """Up-sampled image(s) (..., rows, cols) of checked input, cut to the maximum range."""
    from .models import upsample_image

    out = np.asarray(upsample_image(net, image, lidar, out_lidar), dtype=np.float32)
    np.clip(out, 0.0, np.float32(out_lidar.max_range), out=out)
    return out


def as_size(size, name):
    """``(rows, cols)`` from a pair or a string ``"64x1024"`` / ``"r64x1024"``."""
    if isinstance(size, str):
        m = re.fullmatch(r"\s*r?(\d+)\s*[xX]\s*(\d+)\s*", size)
        if not m:
            raise ValueError(f"{name} must be a (rows, cols) pair or a string like '64x1024', "
                             f"got {size!r}")
        rows, cols = int(m.group(1)), int(m.group(2))
    else:
        try:
            rows, cols = size
        except (TypeError, ValueError):
            raise TypeError(f"{name} must be a (rows, cols) pair or a string like '64x1024', "
                            f"got {size!r}") from None
        if isinstance(rows, (bool, np.bool_)) or isinstance(cols, (bool, np.bool_)) or not (
                isinstance(rows, (int, np.integer)) and isinstance(cols, (int, np.integer))):
            raise TypeError(f"{name} must hold two ints, got {size!r}")
        rows, cols = int(rows), int(cols)
    if rows < 1 or cols < 1:
        raise ValueError(f"{name} must be positive (rows, cols), got ({rows}, {cols})")
    return rows, cols


def as_size_list(value, name, allow_empty=False):
    """A list of checked ``(rows, cols)`` from one size or a sequence of them, none repeated."""
    if isinstance(value, str) or (isinstance(value, tuple) and len(value) == 2 and all(
            isinstance(s, (int, np.integer)) for s in value)):
        value = [value]                           # one size
    if not hasattr(value, "__iter__"):
        raise TypeError(f"{name} must be a sequence of sizes, got {type(value).__name__}")
    out = [as_size(s, f"{name}[{i}]") for i, s in enumerate(value)]
    if not out and not allow_empty:
        raise ValueError(f"{name} must hold at least one size")
    if len(set(out)) != len(out):
        raise ValueError(f"{name} must not repeat a size, got {['%dx%d' % s for s in out]}")
    return out


def as_lidar(lidar):
    """`lidar`, a :class:`~occgp.iln.LidarModel`, or ``LidarModel.carla()`` for None."""
    lidar = LidarModel.carla() if lidar is None else lidar
    if not isinstance(lidar, LidarModel):
        raise TypeError(f"lidar must be a LidarModel (occgp.iln), got {type(lidar).__name__}")
    return lidar


def check_rows(rows, fields):
    """`rows` as a list of mappings that hold every key of `fields` (the table formatters)."""
    records = []
    for i, row in enumerate(rows):
        if not isinstance(row, Mapping):
            raise TypeError(f"rows[{i}] must be a dict, got {type(row).__name__}")
        missing = [f for f in fields if f not in row]
        if missing:
            raise ValueError(f"rows[{i}] lacks {missing}")
        records.append(row)
    return records


def column_line(header, cells):
    """``(line, widths)``: `line` joins a row of strings into columns as wide as the `header`
    and `cells` strings need, the first left-aligned and the others right-aligned."""
    widths = [max([len(h)] + [len(c[j]) for c in cells]) for j, h in enumerate(header)]

    def line(items):
        return "  ".join(s.ljust(w) if j == 0 else s.rjust(w)
                         for j, (s, w) in enumerate(zip(items, widths)))
    return line, widths


def as_pose(pose):
    """A checked (4, 4) sensor-to-world pose from a 4x4 array or (origin, heading)."""
    if isinstance(pose, tuple) and len(pose) == 2:
        origin = as_numeric(pose[0], "pose origin")
        if origin.shape != (3,):
            raise ValueError(f"pose origin must have shape (3,), got {origin.shape}")
        heading = pose[1]
        if isinstance(heading, (bool, np.bool_)) or not np.isscalar(heading) or \
                not isinstance(heading, (int, float, np.integer, np.floating)):
            raise TypeError(f"pose heading must be a real number (radians), got "
                            f"{type(heading).__name__}")
        origin = origin.astype(np.float64)
        heading = as_float(heading)     # an int too large for a float: inf, refused
        if not (np.isfinite(origin).all() and np.isfinite(heading)):
            raise ValueError("pose origin and heading must be finite")
        c, s = np.cos(heading), np.sin(heading)
        out = np.eye(4)
        out[:2, :2] = [[c, -s], [s, c]]
        out[:3, 3] = origin
    else:
        out = as_numeric(pose, "pose")
        if out.shape != (4, 4):
            raise ValueError(f"pose must be a (4, 4) sensor-to-world matrix or an "
                             f"(origin, heading) pair, got shape {out.shape}")
        out = out.astype(np.float64)
        if not np.isfinite(out).all():
            raise ValueError("pose must be finite (no NaN or inf)")
        rot = out[:3, :3]
        if not (np.allclose(out[3], [0, 0, 0, 1], atol=0, rtol=0)
                and np.abs(rot @ rot.T - np.eye(3)).max() <= _ORTHO_TOL
                and np.linalg.det(rot) > 0):
            raise ValueError("pose must be a rigid transform: an orthonormal rotation with "
                             "determinant 1 (to 1e-6) and last row [0, 0, 0, 1]")
    if np.abs(out[:3, 3]).max() > 1e7:
        raise ValueError(f"pose translation must have coordinates of magnitude at most 1e7 m, "
                         f"got {out[:3, 3].tolist()}")
    return out


def check_images(test_images, sizes):
    """Checked ``{(rows, cols): float32 array (n, rows, cols)}`` for each of `sizes`."""
    if not isinstance(test_images, Mapping):
        raise TypeError(f"test_images must be a dict of size -> images (n, rows, cols), e.g. "
                        f"load_shards' result, got {type(test_images).__name__}")
    by_size = {}
    for key, value in test_images.items():
        size = as_size(key, f"test_images key {key!r}")
        if size in by_size:
            raise ValueError(f"test_images holds size {size[0]}x{size[1]} twice")
        by_size[size] = value
    out, n = {}, None
    for size in sizes:
        if size not in by_size:
            have = ", ".join(f"{r}x{c}" for r, c in by_size) or "none"
            raise ValueError(f"test_images lacks size {size[0]}x{size[1]} (has {have})")
        name = f"test_images[{size[0]}x{size[1]}]"
        arr = as_numeric(by_size[size], name)
        if arr.ndim != 3 or arr.shape[1:] != size or arr.shape[0] == 0:
            raise ValueError(f"{name} must have shape (n_images, {size[0]}, {size[1]}) with "
                             f"n_images >= 1, got {arr.shape}")
        if n is not None and arr.shape[0] != n:
            raise ValueError(f"test_images must hold as many images of every size, got {n} "
                             f"and {arr.shape[0]} ({name})")
        n = arr.shape[0]
        arr = np.asarray(arr, dtype=np.float32)
        if not np.isfinite(arr).all():
            raise ValueError(f"{name} must be finite (0.0 marks no return)")
        if (arr < 0).any():
            raise ValueError(f"{name} must hold ranges >= 0 (0.0 marks no return)")
        out[size] = arr
    return out
