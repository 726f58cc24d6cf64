"""Full range images: every pixel of one sensor model queried in an image of another."""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from .._range import angles_to_pixels, pixel_angles
from ._base import DEFAULT_CHUNK, RangeModel, as_tensor, check_image

__all__ = ["upsample_image", "image_queries"]


def _check_lidar_model(m: Any, name: str) -> None:
    for attr in ("rows", "cols", "vertical_fov", "horizontal_fov"):
        if not hasattr(m, attr):
            raise TypeError(f"{name} must be a LidarModel (occgp.iln), got {type(m).__name__}")


def image_queries(in_model, out_model):
    """The queries of :func:`upsample_image`: `out_model`'s pixel centers in `in_model`'s pixels.

    Parameters
    ----------
    in_model, out_model : LidarModel
        The sensor models of the input and of the output image.

    Returns
    -------
    queries : numpy.ndarray of float32, shape (n, 2)
        ``(v, u)`` of the output pixels inside `in_model`'s field of view, in row-major order.
    inside : numpy.ndarray of bool, shape (out_model.rows * out_model.cols,)
        Which output pixels those are (the others get no return).
    wrap : bool
        Whether `in_model` covers 360 degrees.
    """
    elev, azim = pixel_angles(out_model)
    v, u = angles_to_pixels(in_model, elev.ravel(), azim.ravel())
    eps = 1e-4
    inside = (v >= -eps) & (v <= in_model.rows + eps) & (u >= -eps) & (u <= in_model.cols + eps)
    q = np.stack([np.clip(v, 0, in_model.rows), np.clip(u, 0, in_model.cols)], axis=-1)[inside]
    return q.astype(np.float32), inside, float(in_model.horizontal_fov) >= 360.0


def upsample_image(model: RangeModel, image, in_model, out_model, chunk: int = DEFAULT_CHUNK):
    """Full range image of `out_model`'s resolution from an image of `in_model`.

    Every out-resolution pixel center is converted to its elevation and azimuth, then to
    fractional pixel coordinates of `in_model`, and queried. Pixels outside `in_model`'s field of
    view get 0 (no return).

    Parameters
    ----------
    model : RangeModel
        An ILN, LIIF or bilinear model (see :func:`make`).
    image : array-like or torch.Tensor of shape (in_model.rows, in_model.cols) or (batch, rows, cols)
        Input ranges in metres, 0 for no return.
    in_model, out_model : LidarModel
        Sensor models of the input and the output image.
    chunk : int, default=65536
        Queries evaluated at once.

    Returns
    -------
    ranges : numpy.ndarray or torch.Tensor of shape (out_model.rows, out_model.cols) or (batch, ...)
        float32 ranges, 0 for no return (numpy unless `image` is a tensor).

    Raises
    ------
    TypeError
        If `model` is not a RangeModel or `in_model` / `out_model` are not LidarModels.
    ValueError
        If `image`'s shape does not match `in_model`, or `image` is empty or holds NaN, inf or
        negative ranges.

    Examples
    --------
    >>> from types import SimpleNamespace as M
    >>> from occgp.iln.models import make
    >>> lo = M(rows=2, cols=4, vertical_fov=(-15.0, 15.0), horizontal_fov=360.0)
    >>> hi = M(rows=4, cols=4, vertical_fov=(-15.0, 15.0), horizontal_fov=360.0)
    >>> upsample_image(make({"name": "bilinear"}), np.full((2, 4), 5.0), lo, hi).shape
    (4, 4)
    """
    if not isinstance(model, RangeModel):
        raise TypeError(f"model must be an occgp.iln model (see make), got {type(model).__name__}")
    _check_lidar_model(in_model, "in_model")
    _check_lidar_model(out_model, "out_model")
    images, was_numpy = as_tensor(image, "image")
    check_image(images, "image")
    if tuple(images.shape[-2:]) != (in_model.rows, in_model.cols):
        raise ValueError(
            f"image must have shape ({in_model.rows}, {in_model.cols}) of in_model "
            f"(optionally with a leading batch axis), got {tuple(images.shape)}"
        )
    q, inside, wrap = image_queries(in_model, out_model)
    pred = model.predict(images, q, wrap=wrap, chunk=chunk)
    shape = tuple(images.shape[:-2]) + (out_model.rows * out_model.cols,)
    out = torch.zeros(shape, dtype=torch.float32, device=pred.device)
    out[..., torch.from_numpy(inside).to(pred.device)] = pred
    out = out.reshape(tuple(images.shape[:-2]) + (out_model.rows, out_model.cols))
    if was_numpy:
        return out.cpu().numpy()
    return out.to(images.device)
