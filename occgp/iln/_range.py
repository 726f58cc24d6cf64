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
centres at integer + 0.5: pixel ``(i, j)`` covers ``i <= v < i + 1`` and
``j <= u < j + 1``.
"""

from __future__ import annotations

import dataclasses
import json
import numbers

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._docfill import fill_doc
from .._validation import (as_float, as_numeric, as_points, check_bool, check_choice,
                           show_number)
from . import _beam_tables as _beams
from ._sensor_docs import SIZE_SECTIONS as _SIZE_SECTIONS, preset as _preset

__all__ = [
    "LidarModel",
    "points_to_range_image",
    "range_image_to_points",
    "range_image_from_points",
    "MAX_PIXELS",
    "MAX_RANGE_LIMIT",
]

#: Most pixels (rows * cols) of a :class:`LidarModel` (e.g. 4096 x 4096, 16x the
#: largest training size): the pixel directions alone take 400 MB there.
MAX_PIXELS = 2**24
#: Largest ``max_range`` (metres) a :class:`LidarModel` accepts.
MAX_RANGE_LIMIT = 1e5
_MAX_SIDE = 65536
_EDGE = 1e-7  # pixels: points this close beyond a field of view's edge fall on it


def _real(value, name):
    if isinstance(value, (bool, np.bool_)) or not isinstance(
            value, (numbers.Real, np.floating, np.integer)):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__}")
    return as_float(value)     # an int too large for a float: inf, refused by the range


def _side(value, name):
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (numbers.Integral, np.integer)):
        raise TypeError(f"{name} must be a positive int, got {type(value).__name__}")
    value = int(value)
    if not 1 <= value <= _MAX_SIDE:
        raise ValueError(f"{name} must lie in [1, {_MAX_SIDE}], got {value}")
    return value


@dataclasses.dataclass(frozen=True)
class LidarModel:
    """A spinning LiDAR's beam layout: the geometry of its range images.

    Parameters
    ----------
    rows : int
        Beams (image rows), 1 to 65536.
    cols : int
        Firings per revolution, or per horizontal field of view (image
        columns), 1 to 65536; ``rows * cols`` at most ``MAX_PIXELS`` (2**24).
    vertical_fov : tuple of two float
        ``(low, high)`` elevations of the field of view's bottom and top
        edges, degrees, ``-90 <= low < high <= 90``. Stored as a tuple of
        floats.
    horizontal_fov : float, default=360.0
        Width of the horizontal field of view, degrees, in (0, 360],
        centred on +x.
    max_range : float, default=80.0
        Farthest return, metres, in (0, 1e5].
    beam_elevations : sequence of float, optional
        Per-beam elevation table, degrees, one per row, top beam first,
        strictly decreasing and strictly inside `vertical_fov`: row ``i``'s
        centre looks at ``beam_elevations[i]``, and fractional rows map to
        elevations linearly between entries (and between the end entries and
        the field of view's edges). Stored as a tuple of floats. Default:
        uniform rows.

    Attributes
    ----------
    rows, cols, vertical_fov, horizontal_fov, max_range, beam_elevations : as given

    Raises
    ------
    TypeError
        If a field has a wrong type.
    ValueError
        If a field is out of its range or not finite.

    Examples
    --------
    >>> m = LidarModel.carla()
    >>> m.rows, m.cols, m.vertical_fov, m.max_range
    (16, 1024, (-15.0, 15.0), 80.0)
    >>> float(m.pixel_angles()[0][0, 0])               # row 0: the top beam
    14.0625
    >>> m.with_size(64, 2048).shape
    (64, 2048)
    """

    rows: int
    cols: int
    vertical_fov: tuple = (-15.0, 15.0)
    horizontal_fov: float = 360.0
    max_range: float = 80.0
    beam_elevations: tuple | None = None

    def __post_init__(self):
        rows = _side(self.rows, "rows")
        cols = _side(self.cols, "cols")
        if rows * cols > MAX_PIXELS:
            raise ValueError(f"rows * cols must be at most {MAX_PIXELS} pixels, "
                             f"got {rows} x {cols} = {rows * cols}")
        fov = self.vertical_fov
        if isinstance(fov, (str, bytes)) or not hasattr(fov, "__len__") or len(fov) != 2:
            raise TypeError(f"vertical_fov must be a pair (low, high) of degrees, got {fov!r}")
        low = _real(fov[0], "vertical_fov[0]")
        high = _real(fov[1], "vertical_fov[1]")
        if not (-90.0 <= low < high <= 90.0):
            raise ValueError(f"vertical_fov must satisfy -90 <= low < high <= 90 degrees, "
                             f"got ({low!r}, {high!r})")
        hfov = _real(self.horizontal_fov, "horizontal_fov")
        if not 0.0 < hfov <= 360.0:
            raise ValueError(f"horizontal_fov must lie in (0, 360] degrees, "
                             f"got {show_number(self.horizontal_fov)}")
        max_range = _real(self.max_range, "max_range")
        if not 0.0 < max_range <= MAX_RANGE_LIMIT:
            raise ValueError(f"max_range must lie in (0, {MAX_RANGE_LIMIT:g}] metres, "
                             f"got {show_number(self.max_range)}")
        table = self.beam_elevations
        if table is not None:
            table = _beams.check_table(table, rows)
            if not (low < table[-1] and table[0] < high):
                raise ValueError(f"beam_elevations must lie strictly inside vertical_fov "
                                 f"({low!r}, {high!r}), got {table[-1]!r} to {table[0]!r}")
        for name, value in (("rows", rows), ("cols", cols), ("vertical_fov", (low, high)),
                            ("horizontal_fov", hfov), ("max_range", max_range),
                            ("beam_elevations", table)):
            object.__setattr__(self, name, value)

    # ------------------------------------------------------------------ presets
    @classmethod
    @_preset("The dissertation's CARLA sensor: -15 to 15 degrees, 360 degrees, 80 m.", 16)
    def carla(cls, rows: int = 16, cols: int = 1024) -> "LidarModel":
        return cls(rows, cols, (-15.0, 15.0), 360.0, 80.0)

    @classmethod
    @_preset("KITTI's Velodyne HDL-64E: -24.8 to 2.0 degrees, 360 degrees, 120 m.\n\n"
             "        With `table`, the real beams: upper block +2.0 to -8.33 degrees at 1/3\n"
             "        degree, lower block -8.83 to -24.33 at 1/2 degree (field of view\n"
             "        -24.58 to 2.17).", 64, table=True)
    def hdl64e(cls, rows: int = 64, cols: int = 1024, *, table: bool = False) -> "LidarModel":
        if not check_bool(table, "table"):
            return cls(rows, cols, (-24.8, 2.0), 360.0, 120.0)
        return cls._table(_beams.HDL64E_TABLE, rows, cols, 120.0)

    @classmethod
    @_preset("nuScenes' Velodyne HDL-32E: -30.67 to 10.67 degrees, 360 degrees, 100 m.\n\n"
             "        With `table`, beam centres from +10.67 to -30.67 degrees, 4/3 degree\n"
             "        apart (field of view -31.33 to 11.33).", 32, table=True)
    def hdl32e(cls, rows: int = 32, cols: int = 1024, *, table: bool = False) -> "LidarModel":
        if not check_bool(table, "table"):
            return cls(rows, cols, (-30.67, 10.67), 360.0, 100.0)
        return cls._table(_beams.HDL32E_TABLE, rows, cols, 100.0)

    @classmethod
    @_preset("Velodyne VLP-16: 16 beams from +15 to -15 degrees, 2 degrees apart (field\n"
             "        of view -16 to 16, uniform rows), 360 degrees, 100 m.", 16)
    def vlp16(cls, rows: int = 16, cols: int = 1024) -> "LidarModel":
        return cls(rows, cols, (-16.0, 16.0), 360.0, 100.0)

    @classmethod
    @_preset("Ouster OS1-64: the 64 beam elevations measured in a real frame (+17.02 to\n"
             "        -16.44 degrees, 0.44 to 0.62 degree apart), 360 degrees, 120 m.", 64)
    def os1_64(cls, rows: int = 64, cols: int = 1024) -> "LidarModel":
        return cls._table(_beams.OS1_64_TABLE, rows, cols, 120.0)

    @classmethod
    def _table(cls, table, rows, cols, max_range):
        model = cls(len(table), 1, _beams.table_fov(table), 360.0, max_range, table)
        return model.with_size(rows, cols)

    @classmethod
    def from_points(cls, points: ArrayLike, rows: int, cols: int = 1024, *,
                    ring: ArrayLike | None = None, horizontal_fov: float = 360.0,
                    max_range: float = 120.0) -> "LidarModel":
        """A model whose per-beam table is estimated from a real frame's points.

        With `ring` (the beam or scan-order ring of each point), each ring's
        median elevation is a beam, rings with the closest medians merged
        until `rows` remain; without it, the points' elevations are clustered
        into `rows` beams (1-D k-medians). The field of view extends the
        table's ends by half their pitches.

        Parameters
        ----------
        points : array-like of shape (n_points, 3)
            Sensor-frame points, metres; points at the origin are ignored.
        rows : int
            Beams of the sensor, 2 to 65536.
        cols : int, default=1024
            Image columns.
        ring : array-like of int, shape (n_points,), optional
            Ring index of each point (any integers; at least `rows` distinct).
        horizontal_fov : float, default=360.0
            Degrees, in (0, 360].
        max_range : float, default=120.0
            Metres, in (0, 1e5].

        Returns
        -------
        LidarModel
            With ``beam_elevations`` set.

        Raises
        ------
        ValueError
            If `points` or `ring` has a wrong shape, or there are fewer
            distinct rings (or elevations) than `rows`.
        TypeError
            If an argument has a wrong type.

        Examples
        --------
        >>> pts = [[10.0, 0.0, z] for z in (1.0, 0.0, -1.0, -2.0)]
        >>> [round(e, 2) for e in LidarModel.from_points(pts, rows=4).beam_elevations]
        [5.71, 0.0, -5.71, -11.31]
        """
        _, elev, _ = _spherical(_check_points(points))
        table = _beams.estimate_table(elev, _side(rows, "rows"), ring)
        return cls(rows, cols, _beams.table_fov(table), horizontal_fov, max_range, table)

    @fill_doc(**_SIZE_SECTIONS)
    def with_size(self, rows: int, cols: int) -> "LidarModel":
        """The same fields of view and range at another image size.

        A per-beam table is resampled: row ``k`` of the new model looks at
        the elevation of fractional row ``(k + 0.5) * self.rows / rows`` of
        this one (linear between the table's entries).

        Parameters
        ----------
        {size_params}

        Returns
        -------
        LidarModel
            A new model; this one is unchanged.

        Raises
        ------
        {size_errors}
        """
        if self.beam_elevations is None or _side(rows, "rows") == self.rows:
            return dataclasses.replace(self, rows=rows, cols=cols)
        table = _beams.resample_table(self.beam_elevations, self.vertical_fov, rows)
        return dataclasses.replace(self, rows=rows, cols=cols, beam_elevations=table)

    @property
    def shape(self) -> tuple:
        """``(rows, cols)``."""
        return (self.rows, self.cols)

    # ------------------------------------------------------------------ JSON
    def to_json(self) -> str:
        """JSON of the fields except rows and cols (the shards' ``lidar`` entry).

        Returns
        -------
        str
            A JSON object with the keys ``horizontal_fov``, ``max_range`` and
            ``vertical_fov`` (a list of two floats), and ``beam_elevations`` (a
            list) for a model with a table, sorted; read back by
            :meth:`from_json`.
        """
        fields = {"vertical_fov": list(self.vertical_fov),
                  "horizontal_fov": self.horizontal_fov, "max_range": self.max_range}
        if self.beam_elevations is not None:
            fields["beam_elevations"] = list(self.beam_elevations)
        return json.dumps(fields, sort_keys=True)

    @classmethod
    @fill_doc(**_SIZE_SECTIONS)
    def from_json(cls, text: str, rows: int, cols: int) -> "LidarModel":
        """The model of :meth:`to_json`'s `text` at size ``(rows, cols)``.

        Parameters
        ----------
        text : str
            JSON of an object with exactly the keys ``vertical_fov`` (a list
            of two numbers), ``horizontal_fov`` and ``max_range``, and
            optionally ``beam_elevations`` (a list, resampled as
            :meth:`with_size` does when its length differs from `rows`), as
            :meth:`to_json` writes.
        {size_params}

        Returns
        -------
        LidarModel

        Raises
        ------
        ValueError
            If `text` is not JSON of an object with exactly the keys
            ``vertical_fov``, ``horizontal_fov`` and ``max_range``, or a
            value (or `rows`, `cols`) is out of range.
        TypeError
            If `text` is not a str, or a value (or `rows`, `cols`) has a
            wrong type.
        """
        if not isinstance(text, str):
            raise TypeError(f"text must be a JSON str, got {type(text).__name__}")
        try:
            fields = json.loads(text)
        except ValueError as exc:
            raise ValueError(f"text is not valid JSON of a LidarModel: {exc}") from None
        keys = {"vertical_fov", "horizontal_fov", "max_range"}
        if not isinstance(fields, dict) or set(fields) - {"beam_elevations"} != keys:
            got = sorted(fields) if isinstance(fields, dict) else type(fields).__name__
            raise ValueError(f"text must be a JSON object with the keys {sorted(keys)}, got {got}")
        fov = fields["vertical_fov"]
        fov = tuple(fov) if isinstance(fov, list) else fov
        table = fields.get("beam_elevations")
        if table is None:
            return cls(rows, cols, fov, fields["horizontal_fov"], fields["max_range"])
        if not isinstance(table, list):
            raise TypeError(f"beam_elevations must be a JSON list, got {type(table).__name__}")
        model = cls(len(table), cols, fov, fields["horizontal_fov"], fields["max_range"],
                    tuple(table))
        return model.with_size(rows, cols)

    # ------------------------------------------------------------------ angles
    @property
    def full_circle(self) -> bool:
        """True when the horizontal field of view is 360 degrees (columns wrap)."""
        return self.horizontal_fov == 360.0

    def elevations(self) -> NDArray[np.float64]:
        """Elevation of each row's centre, degrees, top row first.

        Returns
        -------
        ndarray of float64, shape (rows,)
            ``high - (i + 0.5) * (high - low) / rows`` for row ``i``, or
            ``beam_elevations``.
        """
        if self.beam_elevations is not None:
            return np.array(self.beam_elevations, dtype=np.float64)
        low, high = self.vertical_fov
        return high - (np.arange(self.rows) + 0.5) * (high - low) / self.rows

    def azimuths(self) -> NDArray[np.float64]:
        """Azimuth of each column's centre, degrees, left edge first.

        Returns
        -------
        ndarray of float64, shape (cols,)
            ``hfov / 2 - (j + 0.5) * hfov / cols`` for column ``j``.
        """
        h = self.horizontal_fov
        return h / 2 - (np.arange(self.cols) + 0.5) * h / self.cols

    def pixel_angles(self) -> tuple:
        """Elevation and azimuth grids of the pixel centres, degrees.

        Returns
        -------
        elevation, azimuth : ndarray of shape (rows, cols)
        """
        e, a = np.meshgrid(self.elevations(), self.azimuths(), indexing="ij")
        return e, a

    def directions(self) -> NDArray[np.float64]:
        """Unit ray directions of the pixel centres in the sensor frame.

        Returns
        -------
        ndarray of float64, shape (rows, cols, 3)
            ``(x, y, z)`` of each pixel centre's direction (+x forward, +z up).
        """
        e = np.radians(self.elevations())[:, None]
        a = np.radians(self.azimuths())[None, :]
        ce = np.cos(e)
        return np.stack(np.broadcast_arrays(ce * np.cos(a), ce * np.sin(a), np.sin(e)), axis=-1)

    def angles_to_pixels(self, elevation: ArrayLike, azimuth: ArrayLike) -> tuple:
        """Fractional pixel coordinates ``(v, u)`` of directions given by angles (degrees).

        Pixel centres fall at integer + 0.5. Azimuths are first wrapped into
        [-180, 180). For a 360-degree model ``u`` is wrapped into
        ``[0, cols)``; for a cropped one, directions outside the field of
        view get ``u`` outside ``[0, cols)`` (and elevations outside it a
        ``v`` outside ``[0, rows)``).

        Parameters
        ----------
        elevation, azimuth : array-like (broadcastable), degrees

        Returns
        -------
        v, u : ndarray of float64

        Raises
        ------
        TypeError
            If an argument does not hold real numbers.
        ValueError
            If an argument holds NaN or inf, or they do not broadcast.

        Examples
        --------
        >>> m = LidarModel.carla(16, 1024)
        >>> v, u = m.angles_to_pixels(m.elevations()[3], m.azimuths()[7])
        >>> float(v), float(u)
        (3.5, 7.5)
        """
        e = _finite(elevation, "elevation")
        a = _finite(azimuth, "azimuth")
        try:
            e, a = np.broadcast_arrays(e, a)
        except ValueError:
            raise ValueError(f"elevation and azimuth must broadcast together, got shapes "
                             f"{e.shape} and {a.shape}") from None
        low, high = self.vertical_fov
        if self.beam_elevations is not None:
            v = _beams.row_at(e, self.beam_elevations, self.vertical_fov)
        else:
            v = (high - e) * (self.rows / (high - low))
        h = self.horizontal_fov
        a = (a + 180.0) % 360.0 - 180.0
        u = (h / 2 - a) * (self.cols / h)
        if self.full_circle:
            u = u % self.cols
        return v, u

    def pixels_to_angles(self, v: ArrayLike, u: ArrayLike) -> tuple:
        """Elevation and azimuth (degrees) of fractional pixel coordinates ``(v, u)``.

        The inverse of :meth:`angles_to_pixels` (azimuths not wrapped).

        Parameters
        ----------
        v : array-like of real numbers
            Fractional row coordinates, pixel units (row ``i``'s centre at
            ``i + 0.5``); any finite value, not limited to ``[0, rows)``.
        u : array-like of real numbers
            Fractional column coordinates, pixel units (column ``j``'s centre
            at ``j + 0.5``); any finite value, not limited to ``[0, cols)``.

        Returns
        -------
        elevation : ndarray of float64, shape of `v`
            Degrees, ``high - v * (high - low) / rows`` (with a table:
            linear between its entries, see the class).
        azimuth : ndarray of float64, shape of `u`
            Degrees, ``hfov / 2 - u * hfov / cols`` (not wrapped). `v` and
            `u` are converted independently, so they need not broadcast.

        Raises
        ------
        TypeError
            If `v` or `u` does not hold real numbers.
        ValueError
            If `v` or `u` holds NaN or inf, or cannot be converted to an array.
        """
        v = _finite(v, "v")
        u = _finite(u, "u")
        low, high = self.vertical_fov
        h = self.horizontal_fov
        if self.beam_elevations is not None:
            e = _beams.elevation_at(v, self.beam_elevations, self.vertical_fov)
        else:
            e = high - v * (high - low) / self.rows
        return e, h / 2 - u * h / self.cols


def pixel_angles(model) -> tuple[np.ndarray, np.ndarray]:
    """Elevation and azimuth grids (rows, cols) of the pixel centres of `model`, degrees.

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
    """Fractional ``(v, u)`` of angles (degrees) in `model` (pixel centres at integer + 0.5).

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


def _finite(x, name):
    arr = np.asarray(as_numeric(x, name), dtype=np.float64)
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} must be finite (no NaN or inf)")
    return arr


def _check_model(model):
    if not isinstance(model, LidarModel):
        raise TypeError(f"model must be a LidarModel, got {type(model).__name__}")
    return model


def _check_image(image, model, name="image"):
    arr = as_numeric(image, name)
    if arr.shape != model.shape:
        raise ValueError(f"{name} must have shape {model.shape} (the model's rows, cols), "
                         f"got {arr.shape}")
    arr = np.asarray(arr, dtype=np.float64)
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} must be finite (0 marks no return), found NaN or inf")
    if (arr < 0).any():
        raise ValueError(f"{name} must hold ranges >= 0 (0 marks no return), "
                         f"found {float(arr.min())!r}")
    limit = float(np.float32(model.max_range))
    if (arr > limit).any():
        raise ValueError(f"{name} holds ranges up to {float(arr.max())!r} m, beyond the "
                         f"model's max_range={model.max_range!r}")
    return arr


def _spherical(points):
    """Range, elevation and azimuth (degrees) of sensor-frame points (range > 0 only)."""
    r = np.sqrt(np.einsum("ij,ij->i", points, points))
    with np.errstate(invalid="ignore", divide="ignore"):
        elev = np.degrees(np.arcsin(np.clip(points[:, 2] / r, -1.0, 1.0)))
    azim = np.degrees(np.arctan2(points[:, 1], points[:, 0]))
    return r, elev, azim


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


def _check_points(points):
    points = as_points(points, "points")
    if len(points) and np.abs(points).max() > 1e15:
        raise ValueError(f"points must have coordinates of magnitude at most 1e15 m, "
                         f"got {float(np.abs(points).max())!r}")
    return points


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
    points = _check_points(points)
    r, elev, azim = _spherical(points)
    keep = (r > 0) & (r <= model.max_range)
    r, elev, azim = r[keep], elev[keep], azim[keep]
    v, _ = model.angles_to_pixels(elev, 0.0)
    i = _edges(v, np.floor(v).astype(np.int64), model.rows)
    j = _column(model, azim)
    ok = (i >= 0) & (i < model.rows) & (j >= 0)
    return _scatter_nearest(model, i[ok], j[ok], r[ok])


def range_image_to_points(image: ArrayLike, model: LidarModel, *, return_pixels: bool = False):
    """Sensor-frame points of a range image, along the pixel-centre directions.

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
    points = _check_points(points)
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
    r, _, azim = _spherical(points)
    keep = (r > 0) & (r <= model.max_range)
    i = ring[keep]
    if ring_order == "bottom_up":
        i = model.rows - 1 - i
    j = _column(model, azim[keep])
    ok = j >= 0
    return _scatter_nearest(model, i[ok], j[ok], r[keep][ok])
