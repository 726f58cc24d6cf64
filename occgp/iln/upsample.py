"""Denser scans for mapping: up-sample a sparse LiDAR scan with a range-image model.

:func:`upsample` takes a scan as sensor-frame points or as a range image,
up-samples its range image to any resolution of the same fields of view
with a model (bilinear, the shipped candidate selector, or any model of
:mod:`occgp.iln.models`) and returns the new points in the sensor frame,
ready for :meth:`occgp.OccupancyOctree.insert_scan` (after the sensor-to-world
pose). :func:`upsample_range_image` returns the up-sampled image itself.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._docfill import fill_doc
from .._validation import as_numeric, check_bool
from ._common import (
    DOC_SECTIONS, MAX_OUTPUT_PIXELS, MODEL_NAMES, out_model, predict_image, resolve,
)
from ._range import LidarModel, points_to_range_image, range_image_to_points

__all__ = ["upsample", "upsample_range_image", "resolve_model", "MAX_OUTPUT_PIXELS",
           "MODEL_NAMES"]

@fill_doc(**DOC_SECTIONS)
def resolve_model(model: Any, lidar: LidarModel | None = None, device: Any = None):
    """The range-image model that a name or a model stands for.

    Parameters
    ----------
    model : {"bilinear", "inverse-bilinear", "edge-aware", "pretrained"} or RangeModel
        ``"bilinear"``: bilinear interpolation of the 4 neighbours (no
        training); ``"inverse-bilinear"``: bilinear interpolation of their
        inverse ranges (no training); ``"edge-aware"``: inverse bilinear that
        copies the nearer row across depth edges (no training,
        :class:`~occgp.iln.models.EdgeAwareInterpolation`); ``"pretrained"``: the
        candidate selector shipped with occgp (``occgp.iln.pretrained()``,
        :class:`~occgp.iln.models.CandidateSelector`); or a model of
        :mod:`occgp.iln.models` (used as it is, on its own device).
    lidar : LidarModel, optional
        Its ``max_range`` normalises the bilinear model (no effect on the
        result).
    device : str or torch.device, optional
        Where a model built from a name runs; default the CPU.

    Returns
    -------
    model : RangeModel

    Raises
    ------
    ValueError
        If `model` is an unknown name.
    TypeError
        If `model` is neither a str nor an occgp.iln model.
    {model_errors}
    """
    return resolve(model, lidar, device, "resolve_model")


def _check_lidar(lidar, name="lidar"):
    if not isinstance(lidar, LidarModel):
        raise TypeError(f"{name} must be a LidarModel (occgp.iln), got {type(lidar).__name__}")
    return lidar


def _input_image(data, lidar):
    """The input range image and its LidarModel from points or an image."""
    arr = as_numeric(data, "points_or_range_image")
    if arr.ndim != 2 or arr.size == 0:
        raise ValueError(f"points_or_range_image must be points of shape (n_points, 3) or a "
                         f"range image of shape (rows, cols), non-empty, got shape {arr.shape}")
    if lidar is not None:
        _check_lidar(lidar)
    is_image = (lidar is not None and arr.shape == lidar.shape) or arr.shape[1] != 3
    if not is_image:
        lidar = LidarModel.carla() if lidar is None else lidar
        return points_to_range_image(arr, lidar), lidar
    if lidar is None:
        lidar = LidarModel.carla(*arr.shape)
    elif arr.shape != lidar.shape:
        raise ValueError(f"points_or_range_image: a range image must have lidar's shape "
                         f"{lidar.shape}, got {arr.shape}")
    image = np.asarray(arr, dtype=np.float64)
    if not np.isfinite(image).all():
        raise ValueError("points_or_range_image must be finite (0.0 marks no return), found "
                         f"{int(np.count_nonzero(~np.isfinite(image)))} NaN or inf values")
    if (image < 0).any() or (image > lidar.max_range).any():
        raise ValueError(f"points_or_range_image: ranges must lie in [0, lidar.max_range = "
                         f"{lidar.max_range:g}] m, got [{image.min():g}, {image.max():g}]")
    return image.astype(np.float32), lidar


@fill_doc(**DOC_SECTIONS)
def upsample_range_image(range_image: ArrayLike, *, rows: int = 64, cols: int = 1024,
                         model: Any = "bilinear", lidar: LidarModel | None = None,
                         device: Any = None) -> NDArray[np.float32]:
    """Up-sample a range image to ``(rows, cols)`` over the same fields of view.

    Every output pixel center is turned into its elevation and azimuth and
    queried in the input image (:func:`occgp.iln.models.upsample_image`);
    ranges a value-predicting model puts beyond ``lidar.max_range`` are cut
    to it, and 0.0 (no return) stays wherever the model returns no return.

    Parameters
    ----------
    range_image : array-like of shape (lidar.rows, lidar.cols)
        Ranges in metres in ``[0, lidar.max_range]``; 0.0 means no return.
    rows, cols : int, default=64, 1024
        Output size, ``rows * cols <= MAX_OUTPUT_PIXELS`` (4,194,304).
    model : {"bilinear", "inverse-bilinear", "edge-aware", "pretrained"} or RangeModel, default="bilinear"
        See :func:`resolve_model`.
    lidar : LidarModel, optional
        The input image's sensor; default ``LidarModel.carla(*shape)``.
    device : str or torch.device, optional
        Where a model built from a name runs; default the CPU.

    Returns
    -------
    image : ndarray of shape (rows, cols), float32

    Raises
    ------
    ValueError
        If the image is empty, not 2-D, not of `lidar`'s shape, not finite,
        or holds ranges outside ``[0, lidar.max_range]``; `rows` or `cols`
        is not positive or the output too large; or `model` is an unknown
        name.
    TypeError
        If an argument has a wrong type.
    {model_errors}

    Examples
    --------
    >>> image = np.full((16, 1024), 10.0, dtype=np.float32)
    >>> out = upsample_range_image(image, rows=64, cols=1024)
    >>> out.shape, float(out.min()), float(out.max())
    ((64, 1024), 10.0, 10.0)
    """
    arr = as_numeric(range_image, "range_image")
    if arr.ndim != 2 or arr.size == 0:
        raise ValueError(f"range_image must have shape (rows, cols), non-empty, got {arr.shape}")
    if lidar is not None:
        _check_lidar(lidar)
        if arr.shape != lidar.shape:
            raise ValueError(f"range_image must have lidar's shape {lidar.shape}, got "
                             f"{arr.shape}")
    image, lidar = _input_image(arr, lidar if lidar is not None else LidarModel.carla(*arr.shape))
    out_lidar = out_model(lidar, rows, cols)
    net = resolve(model, lidar, device, "upsample_range_image")
    return predict_image(net, image, lidar, out_lidar)


@fill_doc(**DOC_SECTIONS)
def upsample(points_or_range_image: ArrayLike, *, rows: int = 64, cols: int = 1024,
             model: Any = "bilinear", lidar: LidarModel | None = None, device: Any = None,
             return_image: bool = False):
    """Up-sampled points of a LiDAR scan, in the sensor frame.

    The scan's range image (given, or made from its points with
    :func:`~occgp.iln._range.points_to_range_image`: the nearest return per
    pixel) is up-sampled to ``(rows, cols)`` over the same fields of view by
    :func:`upsample_range_image`, and each output pixel with a return gives a
    point along its pixel-center direction. No-return pixels are dropped.

    Parameters
    ----------
    points_or_range_image : array-like of shape (n_points, 3) or (lidar.rows, lidar.cols)
        Sensor-frame points in metres (origin at the sensor, +z up, +x
        forward), or a range image (metres, 0.0 for no return). A 2-D array
        with 3 columns is read as points unless `lidar` is given with that
        shape.
    rows, cols : int, default=64, 1024
        Size of the up-sampled range image, ``rows * cols <=
        MAX_OUTPUT_PIXELS``.
    model : {"bilinear", "inverse-bilinear", "edge-aware", "pretrained"} or RangeModel, default="bilinear"
        ``"pretrained"`` is the shipped candidate selector (``occgp.iln.pretrained()``); see
        :func:`resolve_model`.
    lidar : LidarModel, optional
        The input scan's sensor. Default: ``LidarModel.carla()`` (16 x
        1024, -15 to 15 degrees, 80 m) for points, ``LidarModel.carla(*shape)``
        for a range image.
    device : str or torch.device, optional
        Where a model built from a name runs; default the CPU.
    return_image : bool, default=False
        Also return the up-sampled range image.

    Returns
    -------
    points : ndarray of shape (n_returns, 3), float64
        Sensor-frame points of the up-sampled image, in row-major pixel order.
    image : ndarray of shape (rows, cols), float32
        Only if `return_image`.

    Raises
    ------
    ValueError
        If the input is empty or of a wrong shape, not finite, holds ranges
        outside ``[0, lidar.max_range]`` or coordinates above 1e15; `rows`
        or `cols` is not positive or the output is too large; or `model` is
        an unknown name.
    TypeError
        If an argument has a wrong type.
    {model_errors}

    Examples
    --------
    >>> from occgp.iln._range import LidarModel, range_image_to_points
    >>> lidar = LidarModel.carla(16, 256)
    >>> scan = range_image_to_points(np.full((16, 256), 20.0), lidar)
    >>> upsample(scan, rows=64, cols=256, lidar=lidar).shape
    (16384, 3)
    """
    return_image = check_bool(return_image, "return_image")
    image, lidar = _input_image(points_or_range_image, lidar)
    out_lidar = out_model(lidar, rows, cols)
    net = resolve(model, lidar, device, "upsample")
    out = predict_image(net, image, lidar, out_lidar)
    points = range_image_to_points(out, out_lidar)
    return (points, out) if return_image else points
