"""Range images of a spinning LiDAR (numpy only).

A :class:`LidarModel` describes the sensor: ``rows`` beams spread uniformly
over the vertical field of view ``(low, high)`` and ``cols`` firings over
the horizontal field of view, in degrees. Row 0 is the highest elevation;
row ``i`` looks at elevation ``high - (i + 0.5) * (high - low) / rows``.
Column ``j`` looks at azimuth ``hfov / 2 - (j + 0.5) * hfov / cols``
(degrees about +z, from +x, counter-clockwise): column 0 is the left edge of
the field of view when looking along +x, and for 360 degrees the columns
wrap around. A range image is a float32 array of shape ``(rows, cols)`` in
metres; **0.0 means no return** (sky, beyond ``max_range``, outside a
cropped field of view). Points are in the sensor frame (origin at the
sensor, +z up, +x forward).

With ``beam_elevations`` (a per-beam table, see :mod:`occgp.iln._beam_tables`), row
``i`` looks at the table's entry ``i`` instead, and fractional rows map to
elevations linearly between neighbouring entries.

Continuous pixel coordinates ``(v, u)`` count in pixel units with pixel
centers at integer + 0.5: pixel ``(i, j)`` covers ``i <= v < i + 1`` and
``j <= u < j + 1``.
This module holds the conversions between points and range images; the
:class:`LidarModel` itself is in ``_lidar_model.py`` (re-exported here).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._validation import as_numeric, check_choice
from ._lidar_model import MAX_PIXELS, MAX_RANGE_LIMIT, LidarModel, check_points, spherical

__all__ = [
    "LidarModel",
    "points_to_range_image",
    "range_image_to_points",
    "range_image_from_points",
    "MAX_PIXELS",
    "MAX_RANGE_LIMIT",
]

_EDGE = 1e-7  # pixels: points this close beyond a field of view's edge fall on it


def pixel_angles(model) -> tuple[np.ndarray, np.ndarray]:
    """Elevation and azimuth grids (rows, cols) of the pixel centers of `model`, degrees.

    `model` is a :class:`LidarModel` or any object with its ``rows``, ``cols``,
    ``vertical_fov`` and ``horizontal_fov`` (the models of occgp.iln.models accept both).
    """
    if hasattr(model, "pixel_angles"):
        elev, azim = model.pixel_angles()
        return np.asarray(elev, dtype=np.float64), np.asarray(azim, dtype=np.float64)
    low, high = (float(a) for a in model.vertical_fov)
    hfov = float(model.horizontal_fov)
    rows, cols = model.rows, model.cols
    e = high - (np.arange(rows) + 0.5) * (high - low) / rows
    a = hfov / 2 - (np.arange(cols) + 0.5) * hfov / cols
    return np.broadcast_to(e[:, None], (rows, cols)), np.broadcast_to(a[None], (rows, cols))


def angles_to_pixels(model, elev: np.ndarray, azim: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fractional ``(v, u)`` of angles (degrees) in `model` (pixel centers at integer + 0.5).

    `model` as in :func:`pixel_angles`; ``u`` wraps around for a 360-degree model.
    """
    if hasattr(model, "angles_to_pixels"):
        v, u = model.angles_to_pixels(elev, azim)
        return np.asarray(v, dtype=np.float64), np.asarray(u, dtype=np.float64)
    low, high = (float(a) for a in model.vertical_fov)
    hfov = float(model.horizontal_fov)
    v = (high - elev) * model.rows / (high - low)
    u = (hfov / 2 - ((azim + 180.0) % 360.0 - 180.0)) * model.cols / hfov
    if hfov >= 360.0:
        u = np.mod(u, model.cols)
    return v, u


def _check_model(model):
    if not isinstance(model, LidarModel):
        raise TypeError(f"model must be a LidarModel, got {type(model).__name__}")
    return model


def check_pixels(arr, model, name, note=""):
    """`arr` as float64, checked to hold real numbers, to have `model`'s image shape
    (rows, cols) and to be finite; the errors name `name` (`note` follows "must be
    finite" in the last one)."""
    arr = as_numeric(arr, name)
    if arr.shape != model.shape:
        raise ValueError(f"{name} must have shape {model.shape} (the model's rows, cols), "
                         f"got {arr.shape}")
    arr = np.asarray(arr, dtype=np.float64)
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} must be finite{note}, found NaN or inf")
    return arr


def _check_image(image, model, name="image"):
    arr = check_pixels(image, model, name, " (0 marks no return)")
    if (arr < 0).any():
        raise ValueError(f"{name} must hold ranges >= 0 (0 marks no return), "
                         f"found {float(arr.min())!r}")
    limit = float(np.float32(model.max_range))
    if (arr > limit).any():
        raise ValueError(f"{name} holds ranges up to {float(arr.max())!r} m, beyond the "
                         f"model's max_range={model.max_range!r}")
    return arr


def _column(model, azim):
    """Integer column of each azimuth (degrees), -1 outside a cropped field of view."""
    _, u = model.angles_to_pixels(0.0, azim)
    j = np.floor(u).astype(np.int64)
    if model.full_circle:
        return np.where(j >= model.cols, j - model.cols, j)  # u % cols may round to cols
    j = _edges(u, j, model.cols)
    return np.where((j >= 0) & (j < model.cols), j, -1)


def _edges(x, k, n):
    """Pixel index `k` of coordinates `x`, with points on (or 1e-7 pixels beyond) the edges
    of ``[0, n]`` moved into the first / last pixel."""
    k = np.where((x < 0) & (x >= -_EDGE), 0, k)
    return np.where((x >= n) & (x <= n + _EDGE), n - 1, k)


def _scatter_nearest(model, i, j, r):
    """Image with the smallest `r` of each pixel (i, j); 0 where none."""
    image = np.full(model.rows * model.cols, np.inf)
    np.minimum.at(image, i * model.cols + j, r)
    image[np.isinf(image)] = 0.0
    return image.reshape(model.shape).astype(np.float32)


def points_to_range_image(points: ArrayLike, model: LidarModel) -> NDArray[np.float32]:
    """The range image of sensor-frame points: the nearest return per pixel.

    Each point falls in the pixel of its elevation and azimuth; a pixel
    hit by several points keeps the smallest range. Points at the origin,
    beyond ``model.max_range`` or outside the fields of view are dropped
    (points on an edge of a field of view, to within 1e-7 pixels, fall in
    the edge's row / column). Points made by :func:`range_image_to_points` from an image
    give that image back exactly.

    Parameters
    ----------
    points : array-like of shape (n_points, 3)
        Sensor-frame points, metres (any real dtype; computed in float64).
    model : LidarModel

    Returns
    -------
    image : ndarray of shape (model.rows, model.cols), dtype float32
        Ranges in metres, 0.0 where no point fell.

    Raises
    ------
    TypeError
        If `points` does not hold real numbers or `model` is not a
        LidarModel.
    ValueError
        If `points` is not of shape (n_points, 3), holds NaN or inf, or a
        coordinate of magnitude above 1e15.

    Examples
    --------
    >>> m = LidarModel.carla(16, 8)
    >>> image = points_to_range_image([[10.0, 0.0, 0.0], [5.0, 0.0, 0.0]], m)
    >>> image.shape, float(image.max())
    ((16, 8), 5.0)
    """
    model = _check_model(model)
    points = check_points(points)
    r, elev, azim = spherical(points)
    keep = (r > 0) & (r <= model.max_range)
    r, elev, azim = r[keep], elev[keep], azim[keep]
    v, _ = model.angles_to_pixels(elev, 0.0)
    i = _edges(v, np.floor(v).astype(np.int64), model.rows)
    j = _column(model, azim)
    ok = (i >= 0) & (i < model.rows) & (j >= 0)
    return _scatter_nearest(model, i[ok], j[ok], r[ok])


def range_image_to_points(image: ArrayLike, model: LidarModel, *, return_pixels: bool = False):
    """Sensor-frame points of a range image, along the pixel-center directions.

    Pixels without a return (0.0) are skipped. Points come in row-major
    pixel order.

    Parameters
    ----------
    image : array-like of shape (model.rows, model.cols)
        Ranges in metres, ``0 <= range <= model.max_range``; 0 marks no
        return.
    model : LidarModel
    return_pixels : bool, default=False
        Also return the pixel of each point.

    Returns
    -------
    points : ndarray of shape (n_returns, 3), float64
    pixels : ndarray of shape (n_returns, 2), int64
        ``(row, col)`` of each point; only if `return_pixels`.

    Raises
    ------
    TypeError
        If `image` does not hold real numbers or `model` is not a
        LidarModel.
    ValueError
        If `image` is not of the model's shape, holds NaN, inf or negative
        values, or ranges beyond ``model.max_range``.

    Examples
    --------
    >>> m = LidarModel.carla(16, 8)
    >>> image = np.zeros((16, 8), dtype=np.float32)
    >>> image[8, 4] = 10.0
    >>> points, pixels = range_image_to_points(image, m, return_pixels=True)
    >>> np.round(points, 3).tolist(), pixels.tolist()
    ([[9.238, -3.826, -0.164]], [[8, 4]])
    """
    model = _check_model(model)
    image = _check_image(image, model)
    if not isinstance(return_pixels, (bool, np.bool_)):
        raise TypeError(f"return_pixels must be a bool, got {type(return_pixels).__name__}")
    i, j = np.nonzero(image > 0)
    e = np.radians(model.elevations())[i]
    a = np.radians(model.azimuths())[j]
    r = image[i, j]
    ce = np.cos(e)
    points = np.column_stack([r * ce * np.cos(a), r * ce * np.sin(a), r * np.sin(e)])
    if return_pixels:
        return points, np.column_stack([i, j]).astype(np.int64)
    return points


def range_image_from_points(points: ArrayLike, model: LidarModel, ring: ArrayLike | None = None,
                            *, ring_order: str = "bottom_up") -> NDArray[np.float32]:
    """The range image of a real scan, from its points (and ring index, if known).

    Without `ring`, each point's row comes from its elevation binned over
    ``model.vertical_fov`` (as :func:`points_to_range_image`; points outside
    the field of view are dropped): choose a model whose rows and field of
    view match the sensor's beams, e.g. :meth:`LidarModel.hdl64e` for KITTI.
    With `ring` (the laser index of each point, as nuScenes' ``.pcd.bin``
    files hold, see ``read_kitti_bin(..., return_fields=True)``), the row is
    the ring itself, which follows the real, non-uniform beam elevations:
    ``model.rows`` must be the number of rings, and the elevation of a point
    is ignored. The column always comes from the azimuth. Each pixel keeps
    its nearest return; points at the origin or beyond ``model.max_range``
    are dropped.

    Parameters
    ----------
    points : array-like of shape (n_points, 3)
        Sensor-frame points, metres.
    model : LidarModel
    ring : array-like of shape (n_points,), optional
        Ring (laser) index of each point, integers in ``[0, model.rows)``
        (integral floats are accepted, as stored in nuScenes files).
    ring_order : {"bottom_up", "top_down"}, default="bottom_up"
        How rings count: ``"bottom_up"`` (nuScenes' HDL-32E: ring 0 is the
        lowest beam) puts ring ``k`` in row ``rows - 1 - k``; ``"top_down"``
        (ring 0 the highest beam, e.g. Ouster) in row ``k``. Row 0 is
        always the highest beam.

    Returns
    -------
    image : ndarray of shape (model.rows, model.cols), dtype float32

    Raises
    ------
    TypeError
        If `points` or `ring` does not hold real numbers, or `model` is not
        a LidarModel.
    ValueError
        As :func:`points_to_range_image`; and if `ring` is not of shape
        (n_points,), holds non-integral or non-finite values or values
        outside ``[0, model.rows)``, or `ring_order` is not one of the two
        names.

    Examples
    --------
    >>> m = LidarModel.hdl32e(rows=32, cols=8)
    >>> image = range_image_from_points([[10.0, 0.0, -1.0]], m, ring=[0])
    >>> int(np.flatnonzero(image.any(axis=1))[0])     # ring 0 = the bottom row
    31
    """
    model = _check_model(model)
    check_choice(ring_order, "ring_order", ("bottom_up", "top_down"))
    if ring is None:
        return points_to_range_image(points, model)
    points = check_points(points)
    ring = as_numeric(ring, "ring")
    if ring.shape != (len(points),):
        raise ValueError(f"ring must have shape (n_points,) = ({len(points)},), got {ring.shape}")
    if ring.dtype.kind == "f":
        if not np.isfinite(ring).all():
            raise ValueError("ring must be finite (no NaN or inf)")
        if (ring != np.round(ring)).any():
            raise ValueError("ring must hold integers (ring indices), found non-integral values")
    if len(ring) and (ring.min() < 0 or ring.max() >= model.rows):
        raise ValueError(f"ring must lie in [0, {model.rows}) (model.rows: one row per ring), "
                         f"got values from {ring.min()} to {ring.max()}")
    ring = ring.astype(np.int64)
    r, _, azim = spherical(points)
    keep = (r > 0) & (r <= model.max_range)
    i = ring[keep]
    if ring_order == "bottom_up":
        i = model.rows - 1 - i
    j = _column(model, azim[keep])
    ok = j >= 0
    return _scatter_nearest(model, i[ok], j[ok], r[keep][ok])
