"""Real LiDAR frames as range images, each beam in its own row (numpy only).

:func:`read_lidar_frame` reads a KITTI-style ``.bin`` frame (float32 x y z
intensity per record) and returns its range image with a
:class:`~occgp.iln.LidarModel` whose per-beam elevation table is measured in
the frame itself, so that every row holds one real beam:

* ``"os1-64"`` (Ouster OS1-64, records stored column by column: record
  ``c * 64 + b`` is beam ``b``, beam 0 the top one; no-returns are all
  zeros): the beam of a point is its record index modulo 64, and each beam's
  elevation is the median of its returns' (every return of a beam has the
  same elevation, to 0.01 degree, in the RELLIS-3D frame);
* ``"hdl64e"`` (Velodyne HDL-64E, KITTI): KITTI stores the points beam by
  beam, each beam one sweep in azimuth, so a jump of the azimuth by more than
  90 degrees starts a new scan-order ring (:func:`scan_rings`); each ring's
  median elevation is a beam, and rings whose medians nearly coincide (a
  beam's sweep cut in two by the frame's start) are merged until 64 remain.
  With ``beams="table"`` the points are binned instead by their elevation to
  the nearest entry of the nominal table (``LidarModel.hdl64e(table=True)``).

The column of a point always comes from its azimuth (the OS1's beams fire at
slightly different azimuths within one record column). Each pixel keeps its
nearest return.
"""

from __future__ import annotations

import os

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._reading import read_regular
from .._validation import (
    as_float, as_path, as_points, check_choice, check_int, show_number,
)
from . import _beam_tables
from ._range import LidarModel, points_to_range_image, range_image_from_points

__all__ = ["read_lidar_frame", "frame_range_image", "scan_rings", "SENSORS"]

#: Sensors :func:`read_lidar_frame` knows: name -> (beams, default columns, max range).
SENSORS = {"hdl64e": (64, 2048, 120.0), "os1-64": (64, 2048, 120.0)}


def scan_rings(points: ArrayLike, jump: float = 90.0) -> NDArray[np.int64]:
    """Scan-order ring of each point of a frame stored beam by beam (KITTI).

    A new ring starts wherever the azimuth of consecutive points jumps by
    more than `jump` degrees (one beam's sweep ends, the next one's begins).

    Parameters
    ----------
    points : array-like of shape (n_points, 3)
        Sensor-frame points in the file's order, metres.
    jump : float, default=90.0
        Degrees, in (0, 360).

    Returns
    -------
    ring : ndarray of int64, shape (n_points,)
        0 for the first sweep, then 1, 2, ...; empty for no points.

    Raises
    ------
    ValueError
        If `points` is not of shape (n_points, 3) or not finite, or `jump`
        is outside (0, 360).
    TypeError
        If `points` does not hold real numbers or `jump` is not a real.

    Examples
    --------
    >>> pts = [[1, 0.1, 0], [1, 0.5, 0], [1, -0.5, 0.1], [1, -0.1, 0.1]]
    >>> scan_rings(np.array(pts) * [[-1, 1, 1]]).tolist()
    [0, 0, 1, 1]
    >>> scan_rings(np.zeros((0, 3))).shape
    (0,)
    """
    points = as_points(points, "points")
    if isinstance(jump, (bool, np.bool_)) or not isinstance(jump, (int, float, np.number)):
        raise TypeError(f"jump must be a real number (degrees), got {type(jump).__name__}")
    if not 0.0 < as_float(jump) < 360.0:
        raise ValueError(f"jump must lie in (0, 360) degrees, got {show_number(jump)}")
    azim = np.degrees(np.arctan2(points[:, 1], points[:, 0]))
    return _beam_tables.scan_rings(azim, float(jump))


def frame_range_image(points: ArrayLike, rows: int, *, ring: ArrayLike | None = None,
                      cols: int = 2048, max_range: float = 120.0) -> tuple:
    """The range image of a real frame, one row per beam, and its measured sensor model.

    The beam elevations are estimated with :meth:`LidarModel.from_points`
    (from `ring` when given, else by clustering the elevations); each point
    then goes to the row of its ring's beam (with `ring`) or of the nearest
    beam by elevation (without), and to the column of its azimuth.

    Parameters
    ----------
    points : array-like of shape (n_points, 3)
        Sensor-frame points, metres; points at the origin (no-returns) are
        dropped.
    rows : int
        Beams, at least 2.
    ring : array-like of int, shape (n_points,), optional
        Beam or scan-order ring of each point.
    cols : int, default=2048
        Columns over 360 degrees.
    max_range : float, default=120.0
        Metres; farther points are dropped.

    Returns
    -------
    image : ndarray of float32, shape (rows, cols)
        0.0 where no return.
    lidar : LidarModel
        With ``beam_elevations`` the measured table.

    Raises
    ------
    ValueError
        If `points` or `ring` has a wrong shape, or holds fewer rings
        (elevations) than `rows`.
    TypeError
        If an argument has a wrong type.
    """
    points = as_points(points, "points")
    rows = check_int(rows, "rows", low=2)
    cols = check_int(cols, "cols", low=1)
    hit = np.einsum("ij,ij->i", points, points) > 0
    if ring is not None:
        ring = np.asarray(ring)
        if ring.shape != (len(points),):
            raise ValueError(f"ring must have shape (n_points,) = ({len(points)},), "
                             f"got {ring.shape}")
        ring = ring[hit]
    points = points[hit]
    lidar = LidarModel.from_points(points, rows, cols, ring=ring, max_range=max_range)
    if ring is None:
        return points_to_range_image(points, lidar), lidar
    r = np.linalg.norm(points, axis=1)
    elev = np.degrees(np.arcsin(np.clip(points[:, 2] / r, -1.0, 1.0)))
    _, row = _beam_tables.ring_table(elev, ring, rows)
    return range_image_from_points(points, lidar, row, ring_order="top_down"), lidar


def read_lidar_frame(path: str | os.PathLike, sensor: str, *, cols: int | None = None,
                     beams: str = "scan") -> tuple:
    """Read a real KITTI-style ``.bin`` frame as a range image with its sensor model.

    Parameters
    ----------
    path : str or path-like
        File of float32 records ``x y z intensity`` (sensor frame, metres).
    sensor : {"hdl64e", "os1-64"}
        ``"hdl64e"``: KITTI's Velodyne HDL-64E, points stored beam by beam;
        ``"os1-64"``: an Ouster OS1-64 frame stored column by column, 64
        records per column (zeros for no-returns).
    cols : int, optional
        Columns over 360 degrees; default 2048.
    beams : {"scan", "table"}, default="scan"
        How a point finds its beam (rows): ``"scan"`` -- from the file's
        order (scan-order rings for the HDL-64E, record index modulo 64 for
        the OS1-64) with the table measured in the frame; ``"table"`` -- by
        elevation, to the nearest entry of the sensor's nominal table
        (``LidarModel.hdl64e(table=True)`` or ``LidarModel.os1_64()``).

    Returns
    -------
    image : ndarray of float32, shape (64, cols)
        Ranges in metres, 0.0 for no return; row 0 the top beam.
    lidar : LidarModel
        The frame's sensor: 360 degrees, 120 m, with ``beam_elevations``.

    Raises
    ------
    ValueError
        If `sensor` or `beams` is not one of the names; or, naming the file,
        if the file is empty, its size is not a whole number of 16-byte
        records (stray trailing bytes), it holds not a whole number of
        64-record columns (OS1-64), or NaN or inf; with ``beams="scan"`` also
        if the frame holds no returns (every record at the origin), or fewer
        scan-order rings (HDL-64E), beams with a return (OS1-64) or distinct
        elevations than the sensor's 64 beams, so that the beams cannot be
        measured from it.
    TypeError
        If `path` is not a str or path-like, or `cols` is not an int.
    OSError
        If the file cannot be read, or is not a regular file (a named pipe,
        a device such as ``/dev/zero``: refused before it is opened).

    Examples
    --------
    >>> image, lidar = read_lidar_frame(path, "os1-64")       # doctest: +SKIP
    >>> image.shape, lidar.beam_elevations[0]                 # doctest: +SKIP
    ((64, 2048), 17.02)
    """
    check_choice(sensor, "sensor", tuple(SENSORS))
    check_choice(beams, "beams", ("scan", "table"))
    rows, default_cols, max_range = SENSORS[sensor]
    cols = default_cols if cols is None else check_int(cols, "cols", low=1)
    path = as_path(path)
    raw = read_regular(path, what="a LiDAR frame")
    if len(raw) % 16:
        raise ValueError(f"{path}: a LiDAR frame holds whole records of 4 float32 (x y z "
                         f"intensity, 16 bytes each), got {len(raw)} bytes: "
                         f"{len(raw) // 16} records and {len(raw) % 16} stray bytes")
    if not raw:
        raise ValueError(f"{path}: the LiDAR frame is empty (a file of 0 bytes)")
    records = np.frombuffer(raw, dtype="<f4").reshape(-1, 4)[:, :3].astype(np.float64)
    if not np.isfinite(records).all():
        raise ValueError(f"{path}: the LiDAR frame holds NaN or inf coordinates")
    if sensor == "os1-64" and len(records) % rows:
        raise ValueError(f"{path}: an OS1-64 frame holds 64 records per column, got "
                         f"{len(records)} records")
    if beams == "table":
        nominal = LidarModel.hdl64e(table=True) if sensor == "hdl64e" else LidarModel.os1_64()
        lidar = nominal.with_size(rows, cols)
        return points_to_range_image(records, lidar), lidar
    if sensor == "os1-64":
        ring = np.arange(len(records)) % rows
    else:
        ring = scan_rings(records)
    _check_measurable(path, sensor, records, ring, rows)
    try:
        return frame_range_image(records, rows, ring=ring, cols=cols, max_range=max_range)
    except ValueError as exc:   # the rings' elevations do not give `rows` distinct beams
        raise ValueError(f"{path}: the {sensor}'s {rows} beam elevations cannot be measured "
                         f"from the frame ({exc}); read it with beams='table' for the "
                         "nominal table") from None


def _check_measurable(path, sensor, records, ring, rows):
    """ValueError naming the file when a frame holds too few returns, rings or
    elevations to measure `rows` beams from."""
    hit = np.einsum("ij,ij->i", records, records) > 0
    n_hit = int(hit.sum())
    what = "scan-order rings" if sensor == "hdl64e" else "beams with a return"
    hint = "; read it with beams='table' for the sensor's nominal table"
    if n_hit == 0:
        raise ValueError(f"{path}: the LiDAR frame's {len(records)} records are all at the "
                         f"origin (no returns): no beam elevation can be measured{hint}")
    n_rings = len(np.unique(ring[hit]))
    if n_rings < rows:
        raise ValueError(f"{path}: the LiDAR frame's {n_hit} returns lie in {n_rings} "
                         f"{what}, fewer than the {sensor}'s {rows} beams{hint}")
    pts = records[hit]
    elev = np.degrees(np.arcsin(np.clip(pts[:, 2] / np.linalg.norm(pts, axis=1), -1, 1)))
    n_elev = len(np.unique(np.round(elev, 2)))
    if n_elev < rows:
        raise ValueError(f"{path}: the LiDAR frame's returns hold {n_elev} distinct "
                         f"elevation(s) (to 0.01 degree), fewer than the {sensor}'s {rows} "
                         f"beams{hint}")
