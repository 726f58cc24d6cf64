"""KITTI and nuScenes lidar scans: packed float32 records whose first fields are x y z
(:func:`read_kitti_bin`, its named layouts :data:`BIN_LAYOUTS`)."""

import numpy as np
from numpy.typing import ArrayLike

from .._docfill import fill_doc
from ._fileio import READER_SECTIONS, as_path, read_bytes
from ._scan import Scan, check_origin, drop_non_finite

__all__ = ["BIN_LAYOUTS", "read_kitti_bin"]


# --------------------------------------------------------------------------- #
# KITTI / nuScenes .bin
# --------------------------------------------------------------------------- #
#: Named record layouts of :func:`read_kitti_bin`: name -> (float32 fields, description).
BIN_LAYOUTS = {
    "kitti": (4, "KITTI: float32 x y z reflectance"),
    "nuscenes": (5, "nuScenes: float32 x y z intensity ring_index"),
}
_MAX_BIN_FIELDS = 1024
#: Names of the fields after x y z in the named layouts (``return_fields=True``).
_BIN_NAMES = {"kitti": ["reflectance"], "nuscenes": ["intensity", "ring"]}


def bin_record(fields, path):
    """Return (record dtype with fields x, y, z, description) for :func:`read_kitti_bin`."""
    if fields is None:
        fields = "nuscenes" if path.name.lower().endswith(".pcd.bin") else "kitti"
    if isinstance(fields, str):
        key = fields.lower()
        if key not in BIN_LAYOUTS:
            raise ValueError(
                f"fields must be a number of float32 fields, a numpy record dtype or one of "
                f"{sorted(BIN_LAYOUTS)}, got {fields!r}"
            )
        n, what = BIN_LAYOUTS[key]
        names = ["x", "y", "z"] + _BIN_NAMES[key]
        return np.dtype({"names": names, "formats": ["<f4"] * n}), what
    elif isinstance(fields, np.dtype):
        if fields.names is None or not {"x", "y", "z"} <= set(fields.names):
            raise ValueError(f"fields as a dtype must be a record dtype with fields x, y and z, "
                             f"got {fields}")
        for axis in "xyz":
            sub = fields.fields[axis][0]
            if sub.kind not in "fiu" or sub.shape != ():
                raise ValueError(
                    f"fields: the field {axis!r} must be a scalar number type, got {sub}"
                )
        if fields.itemsize == 0:
            raise ValueError(f"fields: the record dtype {fields} has size 0")
        return fields, f"records of dtype {fields}"
    elif isinstance(fields, (int, np.integer)) and not isinstance(fields, (bool, np.bool_)):
        fields = int(fields)
        if not 3 <= fields <= _MAX_BIN_FIELDS:
            raise ValueError(
                f"fields must be between 3 and {_MAX_BIN_FIELDS} float32 fields per record "
                f"(x y z first), got {fields}"
            )
        what = next((d for n, d in BIN_LAYOUTS.values() if n == fields),
                    f"{fields} float32 fields, x y z first")
    else:
        raise TypeError(
            "fields must be None, an int (float32 fields per record), a layout name "
            f"({', '.join(sorted(BIN_LAYOUTS))}) or a numpy record dtype, got "
            f"{type(fields).__name__}"
        )
    names = ["x", "y", "z"] + [f"f{k}" for k in range(3, fields)]
    return np.dtype({"names": names, "formats": ["<f4"] * fields}), what


@fill_doc(**READER_SECTIONS)
def read_kitti_bin(path, origin: ArrayLike = (0.0, 0.0, 0.0), *, fields=None,
                   return_fields: bool = False):
    """Read a KITTI or nuScenes lidar scan: packed records whose first fields are x y z.

    KITTI Velodyne files (``*.bin``) hold float32 ``x y z reflectance``
    records (16 bytes); nuScenes files (``*.pcd.bin``, binary despite the
    name) hold float32 ``x y z intensity ring_index`` records (20 bytes). The
    layout is chosen by the file name unless `fields` says otherwise; a name
    cannot be told from the size alone (34,688 nuScenes points are 693,760
    bytes, a multiple of 16 too). Points with a NaN or inf coordinate are
    dropped, and their number logged on the ``"occgp"`` logger (PCL's
    habit).

    Parameters
    ----------
    path : str or os.PathLike
    origin : array-like of shape (3,), default=(0, 0, 0)
        Sensor origin (KITTI and nuScenes points are in the sensor frame).
        Must be finite.
    fields : int, str or numpy.dtype, optional
        The record layout. None (default) picks ``"nuscenes"`` for names
        ending in ``.pcd.bin`` and ``"kitti"`` otherwise. A name:
        ``"kitti"`` (4 float32) or ``"nuscenes"`` (5 float32). An int
        ``n`` (3 to 1024): records of ``n`` little-endian float32 values,
        x y z first (e.g. ``fields=3`` for bare ``x y z``). A numpy record
        dtype with fields ``x``, ``y`` and ``z`` for any other layout, e.g.
        ``np.dtype([("x", "<f8"), ("y", "<f8"), ("z", "<f8"), ("t", "<u4")])``.
    return_fields : bool, default=False
        Also return the fields after x y z, by name, for the points kept
        (same order as ``scan.points``).

    Returns
    -------
    scan : Scan
    extra : dict of str to ndarray of shape (n_points,)
        Only if `return_fields`. The named layouts name their fields:
        ``"kitti"`` gives ``{"reflectance": float32}``, ``"nuscenes"``
        ``{"intensity": float32, "ring": int64}`` (the laser index, 0 to 31
        on nuScenes' HDL-32E, counted from the bottom beam: pass it to
        ``occgp.iln.range_image_from_points(points, model, ring=...)``); an
        int layout names its extra fields ``"f3"``, ``"f4"``, ...; a record
        dtype gives its own field names (values in the dtype's native byte
        order).

    {raises_oserror}
    ValueError
        If the file size is not a whole number of records (the message
        gives the file, its size and the record size, and suggests
        ``fields=5`` when a KITTI-named file fits nuScenes' layout), if
        `fields` is not a known layout, or `origin` is not of shape (3,)
        or not finite; with `return_fields`, if a nuScenes ring index of a
        kept point is not a finite integer in [0, 2**31).
    TypeError
        If `path`, `origin`, `fields` or `return_fields` has a wrong type.

    Examples
    --------
    >>> import tempfile, os
    >>> folder = tempfile.mkdtemp()
    >>> path = os.path.join(folder, "000000.bin")
    >>> np.array([[1, 2, 3, 0.5]], dtype=np.float32).tofile(path)
    >>> read_kitti_bin(path).points.tolist()
    [[1.0, 2.0, 3.0]]
    >>> path = os.path.join(folder, "n008__LIDAR_TOP__1533151603547590.pcd.bin")
    >>> np.array([[1, 2, 3, 7, 31]], dtype=np.float32).tofile(path)
    >>> read_kitti_bin(path).points.tolist()
    [[1.0, 2.0, 3.0]]
    >>> scan, extra = read_kitti_bin(path, return_fields=True)
    >>> extra["ring"].tolist(), extra["intensity"].tolist()
    ([31], [7.0])
    """
    path = as_path(path)
    origin = check_origin(origin)
    if not isinstance(return_fields, (bool, np.bool_)):
        raise TypeError(f"return_fields must be a bool, got {type(return_fields).__name__}")
    record, what = bin_record(fields, path)
    raw = read_bytes(path)
    if len(raw) % record.itemsize:
        hint = ""
        if fields is None and record.itemsize == 16 and len(raw) % 20 == 0:
            hint = ("; it is a whole number of nuScenes records: pass fields=5 (or 'nuscenes'), "
                    "or name the file *.pcd.bin")
        elif fields is None and record.itemsize == 20 and len(raw) % 16 == 0:
            hint = "; it is a whole number of KITTI records: pass fields=4 (or 'kitti')"
        raise ValueError(
            f"{path}: size {len(raw)} bytes is not a multiple of {record.itemsize}, the size of "
            f"a record ({what}); the file is truncated or has another layout{hint}"
        )
    data = np.frombuffer(raw, dtype=record)
    points = np.empty((len(data), 3))
    with np.errstate(over="ignore", invalid="ignore"):
        for k, axis in enumerate("xyz"):
            points[:, k] = data[axis]
    scan = Scan(drop_non_finite(points, path), origin)
    if not return_fields:
        return scan
    keep = np.isfinite(points).all(axis=1)
    extra = {}
    for name in record.names:
        if name in ("x", "y", "z"):
            continue
        values = data[name][keep]
        values = values.astype(values.dtype.newbyteorder("="))
        if name == "ring" and (fields is None or isinstance(fields, str)):  # nuScenes' layout
            values = _ring_index(values, path)
        extra[name] = values
    return scan, extra


def _ring_index(values, path):
    """nuScenes ring indices (stored as float32) as int64, checked."""
    with np.errstate(invalid="ignore"):
        bad = ~(np.isfinite(values) & (values >= 0) & (values < 2**31) & (values == np.round(values)))
    if bad.any():
        bad = values[bad][0]
        raise ValueError(f"{path}: the ring field must hold integer laser indices, "
                         f"found {float(bad)!r}")
    return values.astype(np.int64)
