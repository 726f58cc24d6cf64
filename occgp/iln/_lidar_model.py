"""The :class:`LidarModel` of a spinning LiDAR: its beams, field of view, pixel angles and
presets, and the checks of sensor-frame points it shares with the range-image
conversions of ``_range.py`` (which see for the conventions)."""

from __future__ import annotations

import dataclasses
import json
import numbers

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._docfill import fill_doc
from .._validation import as_float, as_numeric, as_points, check_bool, show_number
from . import _beam_tables as _beams
from ._sensor_docs import SIZE_SECTIONS as _SIZE_SECTIONS, preset as _preset

__all__ = ["LidarModel", "MAX_PIXELS", "MAX_RANGE_LIMIT", "check_points", "finite_array",
           "spherical"]

#: Most pixels (rows * cols) of a :class:`LidarModel` (e.g. 4096 x 4096, 16x the
#: largest training size): the pixel directions alone take 400 MB there.
MAX_PIXELS = 2**24
#: Largest ``max_range`` (metres) a :class:`LidarModel` accepts.
MAX_RANGE_LIMIT = 1e5
_MAX_SIDE = 65536


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
        centered on +x.
    max_range : float, default=80.0
        Farthest return, metres, in (0, 1e5].
    beam_elevations : sequence of float, optional
        Per-beam elevation table, degrees, one per row, top beam first,
        strictly decreasing and strictly inside `vertical_fov`: row ``i``'s
        center looks at ``beam_elevations[i]``, and fractional rows map to
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
             "        With `table`, beam centers from +10.67 to -30.67 degrees, 4/3 degree\n"
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
        _, elev, _ = spherical(check_points(points))
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
        """Elevation of each row's center, degrees, top row first.

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
        """Azimuth of each column's center, degrees, left edge first.

        Returns
        -------
        ndarray of float64, shape (cols,)
            ``hfov / 2 - (j + 0.5) * hfov / cols`` for column ``j``.
        """
        h = self.horizontal_fov
        return h / 2 - (np.arange(self.cols) + 0.5) * h / self.cols

    def pixel_angles(self) -> tuple:
        """Elevation and azimuth grids of the pixel centers, degrees.

        Returns
        -------
        elevation, azimuth : ndarray of shape (rows, cols)
        """
        e, a = np.meshgrid(self.elevations(), self.azimuths(), indexing="ij")
        return e, a

    def directions(self) -> NDArray[np.float64]:
        """Unit ray directions of the pixel centers in the sensor frame.

        Returns
        -------
        ndarray of float64, shape (rows, cols, 3)
            ``(x, y, z)`` of each pixel center's direction (+x forward, +z up).
        """
        e = np.radians(self.elevations())[:, None]
        a = np.radians(self.azimuths())[None, :]
        ce = np.cos(e)
        return np.stack(np.broadcast_arrays(ce * np.cos(a), ce * np.sin(a), np.sin(e)), axis=-1)

    def angles_to_pixels(self, elevation: ArrayLike, azimuth: ArrayLike) -> tuple:
        """Fractional pixel coordinates ``(v, u)`` of directions given by angles (degrees).

        Pixel centers fall at integer + 0.5. Azimuths are first wrapped into
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
        e = finite_array(elevation, "elevation")
        a = finite_array(azimuth, "azimuth")
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
            Fractional row coordinates, pixel units (row ``i``'s center at
            ``i + 0.5``); any finite value, not limited to ``[0, rows)``.
        u : array-like of real numbers
            Fractional column coordinates, pixel units (column ``j``'s center
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
        v = finite_array(v, "v")
        u = finite_array(u, "u")
        low, high = self.vertical_fov
        h = self.horizontal_fov
        if self.beam_elevations is not None:
            e = _beams.elevation_at(v, self.beam_elevations, self.vertical_fov)
        else:
            e = high - v * (high - low) / self.rows
        return e, h / 2 - u * h / self.cols


def finite_array(x, name):
    arr = np.asarray(as_numeric(x, name), dtype=np.float64)
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} must be finite (no NaN or inf)")
    return arr


def spherical(points):
    """Range, elevation and azimuth (degrees) of sensor-frame points (range > 0 only)."""
    r = np.sqrt(np.einsum("ij,ij->i", points, points))
    with np.errstate(invalid="ignore", divide="ignore"):
        elev = np.degrees(np.arcsin(np.clip(points[:, 2] / r, -1.0, 1.0)))
    azim = np.degrees(np.arctan2(points[:, 1], points[:, 0]))
    return r, elev, azim


def check_points(points):
    points = as_points(points, "points")
    if len(points) and np.abs(points).max() > 1e15:
        raise ValueError(f"points must have coordinates of magnitude at most 1e15 m, "
                         f"got {float(np.abs(points).max())!r}")
    return points
