"""Safe, versioned ``.npz`` files of occgp's models (kernel maps, GP models).

A file is a NumPy ``.npz`` archive (``numpy.savez_compressed``) of plain arrays,
never pickled objects:

``format``
    0-d str, the kind of file (e.g. ``"occgp.kernel_map"``).
``version``
    0-d int64, the version of that format.
``class``
    0-d str, the name of the class that wrote it (e.g. ``"AKIMap"``).
``params``
    0-d str, the constructor's parameters as a JSON object.
other keys
    The model's state, each an array of a fixed dtype and shape (see the
    class's ``save``).

Reading (:func:`read_npz`) opens the archive with ``numpy.load(...,
allow_pickle=False)``, checks each member's ``.npy`` header (dtype, shape and
the size it declares) before reading its data, and turns every problem of the
file into an ``OSError`` (cannot be read) or a ``ValueError`` (not such a
file, truncated, corrupt) naming the file.
"""

from __future__ import annotations

import json
import math
import os
import tokenize
import zipfile
import zlib
from typing import Any

import numpy as np

from .._atomic import atomic_open
from .._validation import as_path

#: A member may declare at most this many bytes per compressed byte (deflate
#: reaches about 1032), plus _SLACK: more is a zip bomb or corrupt.
_MAX_RATIO = 2048
_SLACK = 1 << 16

# (numpy's .npy header parser lets tokenize.TokenError out of some corrupt headers)
_READ_ERRORS = (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error,
                KeyError, NotImplementedError, RuntimeError, OverflowError,
                tokenize.TokenError)


def write_npz(path: Any, format_name: str, version: int, class_name: str,
              params: dict, arrays: dict[str, np.ndarray]) -> None:
    """Write the archive at `path` exactly (no ``.npz`` suffix is added), atomically:
    the previous file stays intact if the write fails."""
    path = os.fspath(as_path(path))
    members: dict[str, Any] = {
        "format": np.array(format_name), "version": np.array(version, dtype=np.int64),
        "class": np.array(class_name), "params": np.array(json_text(params))}
    members.update(arrays)
    with atomic_open(path) as f:
        np.savez_compressed(f, **members)


def json_text(value: Any) -> str:
    """`value` as JSON text (NaN and inf refused)."""
    return json.dumps(value, allow_nan=False)


def _reject_constant(name: str):
    raise ValueError(f"non-finite number {name}")


def parse_json(text: str, what: str, source: str) -> Any:
    """JSON `text` (NaN and inf refused) or a ValueError naming `what` in `source`."""
    try:
        return json.loads(text, parse_constant=_reject_constant)
    except (ValueError, RecursionError) as exc:
        raise ValueError(f"{source}: corrupt {what}: not valid JSON ({exc})") from None


def _check_shape(shape: tuple, template: tuple, sizes: dict, key: str, source: str) -> None:
    ok = len(shape) == len(template)
    if ok:
        for got, want in zip(shape, template):
            if isinstance(want, str):
                if sizes.setdefault(want, got) != got:
                    ok = False
            elif got != want:
                ok = False
    if not ok:
        want = "(" + ", ".join(str(sizes.get(w, w)) if isinstance(w, str) else str(w)
                               for w in template) + ("," if len(template) == 1 else "") + ")"
        raise ValueError(f"{source}: array {key!r} must have shape {want}, got {shape}")


def read_npz(path: Any, format_name: str, versions: tuple[int, ...],
             classes: tuple[str, ...], spec: dict[str, tuple],
             optional: tuple[str, ...] = ()) -> tuple[str, int, dict, dict]:
    """Read and check an archive written by :func:`write_npz`.

    `spec` maps each key to ``(dtype, shape template)``; a template holds ints
    and names (``("n", 3)``), a name taking the same size in every array.
    Keys in `optional` may be absent. Returns ``(class, version, params,
    arrays)``, the arrays in native byte order.
    """
    path = os.fspath(as_path(path))
    if not os.path.exists(path):
        raise FileNotFoundError(f"no such file: {path!r}")
    if not os.path.isfile(path):
        raise IsADirectoryError(f"{path!r} is not a file") if os.path.isdir(path) \
            else OSError(f"{path!r} is not a regular file")
    what = f"an {format_name} .npz file"
    with open(path, "rb") as f:
        magic = f.read(6)
    if magic == b"\x93NUMPY":
        raise ValueError(f"{path}: not {what} (a single .npy array, not an .npz archive)")
    if magic[:4] not in (b"PK\x03\x04", b"PK\x05\x06"):    # a zip archive's first bytes
        raise ValueError(f"{path}: not {what} (not a zip archive: it starts with "
                         f"{magic[:4]!r})")
    try:
        npz = np.load(path, allow_pickle=False)
    except (PermissionError, IsADirectoryError, FileNotFoundError):
        raise
    except _READ_ERRORS as exc:
        raise ValueError(f"{path}: not {what} (not a readable .npz archive: "
                         f"{type(exc).__name__}: {exc})") from None
    if not isinstance(npz, np.lib.npyio.NpzFile):
        raise ValueError(f"{path}: not {what} (a single .npy array, not an .npz archive)")
    with npz:
        return _read_members(npz, path, what, format_name, versions, classes, spec,
                             optional)


def read_npy_header(f) -> tuple:
    """``(shape, fortran_order, dtype)`` from the ``.npy`` stream `f`, left at its data.

    ValueError for a ``.npy`` format version other than 1.0 and 2.0.
    """
    version = np.lib.format.read_magic(f)
    if version == (1, 0):
        return np.lib.format.read_array_header_1_0(f)
    if version == (2, 0):
        return np.lib.format.read_array_header_2_0(f)
    raise ValueError(f"unsupported .npy version {version}")


def _header(npz, key: str, source: str):
    """(zip info, shape, dtype, header bytes) of member `key`, its data unread."""
    try:
        info = npz.zip.getinfo(key + ".npy")
        with npz.zip.open(info) as f:
            shape, _, dtype = read_npy_header(f)
            header = f.tell()
    except _READ_ERRORS as exc:
        raise ValueError(f"{source}: corrupt array {key!r} ({type(exc).__name__}: "
                         f"{exc})") from None
    return info, tuple(shape), dtype, header


def _data(npz, key: str, info, shape: tuple, dtype: np.dtype, header: int,
          source: str) -> np.ndarray:
    """Member `key`'s data, once its header's size agrees with the archive's."""
    nbytes = math.prod(shape) * dtype.itemsize
    if info.file_size != header + nbytes:
        raise ValueError(f"{source}: corrupt array {key!r}: its header announces "
                         f"{nbytes} bytes of data, the archive holds "
                         f"{info.file_size - header}")
    if info.file_size > _MAX_RATIO * info.compress_size + _SLACK:
        raise ValueError(f"{source}: corrupt array {key!r}: {info.file_size} bytes "
                         f"from {info.compress_size} compressed ones")
    try:
        return npz[key]
    except _READ_ERRORS as exc:
        raise ValueError(f"{source}: corrupt array {key!r} ({type(exc).__name__}: "
                         f"{exc})") from None


def _member(npz, key: str, dtype: np.dtype, template: tuple, sizes: dict,
            source: str) -> np.ndarray:
    """Member `key` of `dtype` (any byte order) and the shape `template`."""
    info, shape, got, header = _header(npz, key, source)
    if got.hasobject or got.kind != dtype.kind or got.names is not None or \
            got.subdtype is not None or (dtype.kind != "U" and got.itemsize != dtype.itemsize):
        want = "str" if dtype.kind == "U" else str(dtype)
        raise ValueError(f"{source}: array {key!r} must have dtype {want}, got {got}")
    _check_shape(shape, template, sizes, key, source)
    arr = _data(npz, key, info, shape, got, header, source)
    if dtype.kind == "U":
        return arr
    return np.asarray(arr, dtype=dtype.newbyteorder("="), order="C")


def _string(npz, key: str, source: str, what: str) -> str:
    """The 0-d str member `key`."""
    if key + ".npy" not in npz.zip.namelist():
        raise ValueError(f"{source}: not {what} (no {key!r} entry)")
    info, shape, got, header = _header(npz, key, source)
    if got.kind != "U" or shape != ():
        raise ValueError(f"{source}: not {what} ({key!r} must be a 0-d str array, got "
                         f"dtype {got}, shape {shape})")
    return str(_data(npz, key, info, shape, got, header, source)[()])


def _read_members(npz, source, what, format_name, versions, classes, spec, optional):
    names = set(npz.zip.namelist())
    fmt = _string(npz, "format", source, what)
    if fmt != format_name:
        raise ValueError(f"{source}: not {what} (its format is {fmt[:80]!r}, expected "
                         f"{format_name!r})")
    if "version.npy" not in names:
        raise ValueError(f"{source}: not {what} (no 'version' entry)")
    ver_arr = _member(npz, "version", np.dtype(np.int64), (), {}, source)
    version = int(ver_arr[()])
    if version not in versions:
        raise ValueError(f"{source}: {format_name} format version {version} is not "
                         f"supported (this occgp reads versions "
                         f"{', '.join(map(str, versions))}); a newer occgp may read it")
    cls = _string(npz, "class", source, what)
    if cls not in classes:
        raise ValueError(f"{source}: holds a {cls[:80]!r}, expected "
                         f"{' or '.join(map(repr, classes))}")
    params = parse_json(_string(npz, "params", source, what), "'params' entry", source)
    if not isinstance(params, dict):
        raise ValueError(f"{source}: corrupt 'params' entry: expected a JSON object, got "
                         f"{type(params).__name__}")
    known = {k + ".npy" for k in (*spec, "format", "version", "class", "params")}
    extra = sorted(names - known)
    if extra:
        raise ValueError(f"{source}: unexpected entries {extra[:5]} in {what}")
    arrays, sizes = {}, {}
    for key, (dtype, template) in spec.items():
        if key + ".npy" not in names:
            if key in optional:
                continue
            raise ValueError(f"{source}: array {key!r} is missing")
        arrays[key] = _member(npz, key, np.dtype(dtype), template, sizes, source)
    return cls, version, params, arrays


def check_finite(arrays: dict, keys, source: str, nonnegative: bool = False) -> None:
    """ValueError naming `source` unless each of `keys` in `arrays` is finite (and >= 0)."""
    for key in keys:
        if key not in arrays:
            continue
        arr = arrays[key]
        if not np.isfinite(arr).all():
            raise ValueError(f"{source}: array {key!r} holds NaN or inf")
        if nonnegative and (arr < 0).any():
            raise ValueError(f"{source}: array {key!r} holds negative values")


def encode_value(value: Any, classes: dict | None = None) -> Any:
    """`value` as JSON-ready data: dicts, lists, str, int, float, bool and None as
    they are; tuples, numeric arrays, numpy Generators and RandomStates, and
    objects of `classes` (name -> class, rebuilt from ``get_params()``) as
    one-key marker objects (``{"__tuple__": [...]}``, ...). TypeError on
    anything else."""
    classes = classes or {}
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, (int, np.integer)) and not isinstance(value, np.bool_):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value)
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, dict):
        if not all(isinstance(k, str) for k in value):
            raise TypeError(f"cannot save a dict with keys other than str: {value!r}")
        return {k: encode_value(v, classes) for k, v in value.items()}
    if isinstance(value, list):
        return [encode_value(v, classes) for v in value]
    if isinstance(value, tuple):
        return {"__tuple__": [encode_value(v, classes) for v in value]}
    if isinstance(value, np.ndarray) and value.dtype.kind in "biuf":
        return {"__ndarray__": value.dtype.str, "shape": list(value.shape),
                "data": value.ravel().tolist()}
    if isinstance(value, np.random.Generator):
        return {"__generator__": encode_value(value.bit_generator.state)}
    if isinstance(value, np.random.RandomState):
        return {"__random_state__": encode_value(value.get_state(legacy=False))}
    name = type(value).__name__
    if classes.get(name) is type(value):
        return {"__object__": name, "params": encode_value(value.get_params(), classes)}
    raise TypeError(f"cannot save a value of type {name} ({value!r:.80})")


#: For the random states' arrays, which predate encode_value's "shape".
encode_rng_state = encode_value

_BIT_GENERATORS = ("PCG64", "PCG64DXSM", "MT19937", "Philox", "SFC64")
_DECODE_ERRORS = (ValueError, TypeError, KeyError, OverflowError, IndexError)


def _decode_array(value: dict) -> np.ndarray:
    dtype = np.dtype(value["__ndarray__"]) if isinstance(value["__ndarray__"], str) else None
    if dtype is None or dtype.kind not in "biuf" or not isinstance(value["data"], list):
        raise ValueError(f"unexpected array {str(value['__ndarray__'])[:40]!r}")
    arr = np.array(value["data"], dtype=dtype)
    if "shape" in value:
        shape = value["shape"]
        if not (isinstance(shape, list) and all(isinstance(n, int) and n >= 0 for n in shape)):
            raise ValueError(f"bad array shape {str(shape)[:40]}")
        arr = arr.reshape(shape)
    return arr


def decode_value(value: Any, source: str, classes: dict | None = None,
                 what: str = "'params' entry") -> Any:
    """The inverse of :func:`encode_value`; ValueError naming `source` and `what`."""
    classes = classes or {}
    try:
        return _decode_value(value, source, classes)
    except RecursionError:
        raise ValueError(f"{source}: corrupt {what}: nested too deeply") from None
    except _DECODE_ERRORS as exc:
        raise ValueError(f"{source}: corrupt {what} ({type(exc).__name__}: {exc})") from None


def _decode_value(value, source, classes):
    if isinstance(value, list):
        return [_decode_value(v, source, classes) for v in value]
    if not isinstance(value, dict):
        return value
    if "__ndarray__" in value:
        return _decode_array(value)
    if set(value) == {"__tuple__"}:
        if not isinstance(value["__tuple__"], list):
            raise ValueError("a tuple must be a list")
        return tuple(_decode_value(v, source, classes) for v in value["__tuple__"])
    if set(value) == {"__generator__"}:
        return decode_rng(value["__generator__"], source)
    if set(value) == {"__random_state__"}:
        state = _decode_value(value["__random_state__"], source, classes)
        rs = np.random.RandomState()
        rs.set_state(state)
        return rs
    if set(value) == {"__object__", "params"}:
        cls = classes.get(value["__object__"]) if isinstance(value["__object__"], str) \
            else None
        if cls is None:
            raise ValueError(f"unknown class {str(value['__object__'])[:80]!r} (expected one "
                             f"of {sorted(classes)})")
        params = _decode_value(value["params"], source, classes)
        if not isinstance(params, dict):
            raise ValueError(f"the parameters of a {cls.__name__} must be an object")
        return cls(**params)
    return {k: _decode_value(v, source, classes) for k, v in value.items()}


def decode_rng(state: Any, source: str) -> np.random.Generator:
    """A Generator in the state :func:`encode_rng_state` encoded; ValueError otherwise."""
    name = state.get("bit_generator") if isinstance(state, dict) else None
    if name not in _BIT_GENERATORS:
        raise ValueError(f"{source}: corrupt random state: expected a bit generator among "
                         f"{_BIT_GENERATORS}, got {str(name)[:80]!r}")
    try:
        bit = getattr(np.random, name)()
        bit.state = _decode_value(state, source, {})
    except _DECODE_ERRORS as exc:
        raise ValueError(f"{source}: corrupt random state of its {name} "
                         f"({type(exc).__name__}: {exc})") from None
    return np.random.Generator(bit)
