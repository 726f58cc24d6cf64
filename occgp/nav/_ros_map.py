"""map_server / Nav2 map files: a PGM image and its YAML description.

The pair ROS's ``map_saver`` (ROS 1 and Nav2) writes in ``mode: trinary``: a
binary PGM (P5) whose top row is the map's largest y, with 0 for occupied, 254
for free and 205 for unknown cells, and a YAML file giving ``image``,
``resolution``, ``origin`` (x, y, yaw of the lower-left corner), ``negate``,
``occupied_thresh`` and ``free_thresh``. PGM files are written and read by occgp
itself (no image library); YAML is read with PyYAML's safe loader, refusing
aliases, from a file of at most 1 MiB (:mod:`occgp._reading`).
"""

from __future__ import annotations

import math
import numbers
import os
import pathlib
import re

import numpy as np
from numpy.typing import NDArray

from .._atomic import atomic_group
from .._reading import load_yaml_mapping, open_regular, read_limited
from .._validation import as_float, show_number

__all__ = ["write_ros_map", "read_ros_map", "read_pgm", "OCCUPIED", "FREE", "UNKNOWN",
           "OCCUPIED_THRESH", "FREE_THRESH", "MAX_PGM_PIXELS", "MAX_PGM_HEADER",
           "MAX_PGM_DIGITS"]

#: The grey levels map_saver writes in trinary mode.
OCCUPIED, FREE, UNKNOWN = 0, 254, 205
#: The thresholds map_saver writes with trinary images (ROS 1's map_saver; Nav2's since
#: it fixed them): they read 0 back as occupied ((255 - 0) / 255 > 0.65), 254 as free
#: (1 / 255 < 0.196) and 205 as unknown (50 / 255 = 0.19608 lies between them).
OCCUPIED_THRESH, FREE_THRESH = 0.65, 0.196
_REQUIRED = ("image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh")
#: The most pixels :func:`read_pgm` reads (16384 x 16384, 2 GiB as int64): a larger
#: image is refused before its pixels are read.
MAX_PGM_PIXELS = 1 << 28
#: The PGM header (magic, comments, width, height, maxval) is parsed from at most
#: this many bytes, each number at most MAX_PGM_DIGITS digits long.
MAX_PGM_HEADER = 1 << 16
MAX_PGM_DIGITS = 12
_PLAIN_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.\-/]*\Z")


def _yaml_float(x: float) -> str:
    """`x` as a YAML float that YAML 1.1 readers (PyYAML) also read as a float:
    ``1e-05`` would be a string there, ``1.0e-05`` is a float."""
    text = repr(float(x))
    if "e" in text and "." not in text.split("e")[0]:
        mantissa, exponent = text.split("e")
        text = f"{mantissa}.0e{exponent}"
    return text


def _yaml_string(text: str) -> str:
    """`text` as a double-quoted YAML scalar: printable characters as they are (the file
    is UTF-8), the others and YAML's line breaks U+2028 and U+2029 escaped. (JSON's
    escapes are not YAML's: JSON writes a character beyond the BMP as a surrogate pair,
    which YAML reads as two characters.)"""
    out = ['"']
    for ch in text:
        o = ord(ch)
        if ch in '"\\':
            out.append("\\" + ch)
        elif (0x20 <= o <= 0x7E or (0xA0 <= o <= 0xD7FF and o not in (0x2028, 0x2029))
              or (0xE000 <= o <= 0xFFFD and o != 0xFEFF) or o >= 0x10000):
            out.append(ch)
        elif o <= 0xFF:
            out.append(f"\\x{o:02x}")
        else:
            out.append(f"\\u{o:04x}")
    return "".join(out) + '"'


def write_ros_map(path: pathlib.Path, image: NDArray[np.uint8], resolution: float,
                  origin: NDArray[np.float64]) -> tuple[pathlib.Path, pathlib.Path]:
    """Write `image` (rows from the largest y down) as ``<stem>.pgm`` beside the YAML
    file `path`, and the YAML file; return both paths.

    Both files are written to temporary files first (see :mod:`occgp._atomic`);
    then the image replaces ``<stem>.pgm`` and only after it the YAML file
    replaces `path`, so that the YAML file never names a missing or half-written
    image. If a write or the first replacement fails, both old files stay; if
    replacing the YAML file fails, the old image is put back.
    """
    pgm = path.with_suffix(".pgm")
    height, width = image.shape
    header = f"P5\n# CREATOR: occgp {resolution:.3f} m/pix\n{width} {height}\n255\n"
    name = pgm.name if _PLAIN_NAME.match(pgm.name) else _yaml_string(pgm.name)
    text = (f"image: {name}\n"
            "mode: trinary\n"
            f"resolution: {_yaml_float(resolution)}\n"
            f"origin: [{_yaml_float(origin[0])}, {_yaml_float(origin[1])}, 0.0]\n"
            "negate: 0\n"
            f"occupied_thresh: {OCCUPIED_THRESH}\n"
            f"free_thresh: {FREE_THRESH}\n")
    # image first, then the YAML file that names it
    with atomic_group(pgm, path) as (pgm_tmp, yaml_tmp):
        with open(pgm_tmp, "wb") as fh:
            fh.write(header.encode("ascii"))
            fh.write(np.ascontiguousarray(image, dtype=np.uint8).tobytes())
        with open(yaml_tmp, "w", encoding="utf-8") as fh:
            fh.write(text)
    return path, pgm


# --------------------------------------------------------------------------- #
# reading
# --------------------------------------------------------------------------- #
def _real(doc: dict, key: str, where: str) -> float:
    value = doc[key]
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{where}: {key} must be a number, got {_show(value)}")
    number = as_float(value)
    if not math.isfinite(number):
        raise ValueError(f"{where}: {key} must be finite, got {show_number(value)}")
    return number


def _read_yaml(path: pathlib.Path) -> dict:
    doc = load_yaml_mapping(path, "map's YAML file")
    missing = [k for k in _REQUIRED if k not in doc]
    if missing:
        raise ValueError(f"{path}: the map's YAML file lacks {', '.join(missing)}")
    return doc


def _show(value: object, n: int = 80) -> str:
    """A short repr of a value read from a file (a hostile one may be huge)."""
    text = repr(value)
    return text if len(text) <= n else f"{text[:n - 3]}... ({len(text)} characters)"


def read_ros_map(path: pathlib.Path) -> tuple[NDArray[np.int8], NDArray[np.float64], float]:
    """Read a map_server YAML file and its PGM image; return (states (nx, ny) indexed
    along x, y with 1 occupied, 0 free, -1 unknown; origin (2,); resolution)."""
    doc = _read_yaml(path)
    where = str(path)
    mode = doc.get("mode", "trinary")
    if mode != "trinary":
        raise ValueError(f"{where}: mode must be 'trinary' (the only mode read), "
                         f"got {_show(mode)}")
    resolution = _real(doc, "resolution", where)
    if resolution <= 0:
        raise ValueError(f"{where}: resolution must be > 0, got {resolution!r}")
    origin = doc["origin"]
    if not isinstance(origin, list) or len(origin) != 3:
        raise ValueError(f"{where}: origin must be a list [x, y, yaw], got {_show(origin)}")
    xyz = [_real({"origin": v}, "origin", where) for v in origin]
    if xyz[2] != 0.0:
        raise ValueError(f"{where}: origin's yaw must be 0 (rotated maps are not read), "
                         f"got {xyz[2]!r}")
    negate = doc["negate"]
    if isinstance(negate, bool) or negate not in (0, 1):
        raise ValueError(f"{where}: negate must be 0 or 1, got {_show(negate)}")
    occ_th = _real(doc, "occupied_thresh", where)
    free_th = _real(doc, "free_thresh", where)
    if not 0.0 <= free_th < occ_th <= 1.0:
        raise ValueError(f"{where}: the thresholds must satisfy 0 <= free_thresh < "
                         f"occupied_thresh <= 1, got {free_th!r} and {occ_th!r}")
    image = doc["image"]
    if not isinstance(image, str) or not image or "\0" in image:
        raise ValueError(f"{where}: image must be a file name, got {_show(image)}")
    pixels, maxval = read_pgm(path.parent / image, f"the image of {path.name}")
    shade = pixels.astype(np.float64) / maxval
    occ = shade if negate else 1.0 - shade
    # map_server's trinary rule (ROS 1's image_loader, Nav2's map_io)
    states = np.where(occ > occ_th, 1, np.where(occ < free_th, 0, -1)).astype(np.int8)
    return np.ascontiguousarray(states[::-1].T), np.array(xyz[:2]), resolution


def read_pgm(path: pathlib.Path, what: str = "a PGM image") -> tuple[NDArray[np.int64], int]:
    """Read a PGM image (binary P5 or plain P2, 8 or 16 bits) strictly: (pixels of
    shape (height, width), maxval).

    The file must be a regular file (a FIFO or a device such as ``/dev/zero`` is
    refused before it is opened). The header is parsed from its first
    :data:`MAX_PGM_HEADER` bytes, each number at most :data:`MAX_PGM_DIGITS`
    digits long, and the image's pixel count (at most :data:`MAX_PGM_PIXELS`)
    and size are checked against the file's size before the pixels are read.
    Truncated data, trailing bytes, values above maxval and other formats raise
    ValueError naming the file."""
    with open_regular(path, what) as fh:
        file_size = os.fstat(fh.fileno()).st_size
        head = read_limited(fh, MAX_PGM_HEADER)
        magic, width, height, maxval, pos = _pgm_header(head, path)
        n = width * height
        if n > MAX_PGM_PIXELS:
            raise ValueError(f"{path}: the PGM image has {width} x {height} = {n} pixels, "
                             f"more than the {MAX_PGM_PIXELS} read")
        if magic == b"P5":
            size = 1 if maxval < 256 else 2
            if file_size - pos != n * size:
                got = file_size - pos
                what = "truncated" if got < n * size else "followed by extra bytes"
                raise ValueError(f"{path}: PGM data {what}: {width} x {height} pixels need "
                                 f"{n * size} bytes, got {got}")
            body = head[pos:] + read_limited(fh, n * size - (len(head) - pos) + 1)
            if len(body) != n * size:  # the file changed while read
                raise ValueError(f"{path}: PGM data of {len(body)} bytes, not the "
                                 f"{n * size} that {width} x {height} pixels need")
            pixels = np.frombuffer(body, dtype=np.uint8 if size == 1 else ">u2")
            pixels = pixels.astype(np.int64)
        else:
            # at most 5 digits and a little whitespace per value
            limit = 16 * n + 64
            if file_size - pos > limit:
                raise ValueError(f"{path}: plain PGM data of {file_size - pos} bytes is "
                                 f"too long for {width} x {height} pixels (at most {limit})")
            body = head[pos:] + read_limited(fh, limit + 1 - (len(head) - pos))
            if len(body) > limit:
                raise ValueError(f"{path}: plain PGM data is too long for {width} x "
                                 f"{height} pixels (at most {limit} bytes)")
            tokens = body.split()
            if len(tokens) != n or re.fullmatch(rb"[0-9\s]*", body) is None \
                    or any(len(t) > MAX_PGM_DIGITS for t in tokens):
                raise ValueError(f"{path}: plain PGM data must be {n} decimal numbers "
                                 f"({width} x {height}), got {len(tokens)} fields")
            pixels = np.array(tokens).astype(np.int64)
    if n and pixels.max() > maxval:
        raise ValueError(f"{path}: PGM pixel values must be <= maxval {maxval}, got "
                         f"{int(pixels.max())}")
    return pixels.reshape(height, width), maxval


def _pgm_header(data: bytes, path: object) -> tuple[bytes, int, int, int, int]:
    """(magic, width, height, maxval, offset of the pixels) from the header's bytes."""
    magic = data[:2]
    if magic not in (b"P5", b"P2"):
        raise ValueError(f"{path}: not a PGM image (P5 or P2); only PGM images are read "
                         f"(got a file starting with {data[:8]!r})")
    pos, separated = 2, False
    fields: list[int] = []
    names = ("width", "height", "maxval")
    while len(fields) < 3:
        if pos >= MAX_PGM_HEADER:
            raise ValueError(f"{path}: malformed PGM header: no {names[len(fields)]} in "
                             f"its first {MAX_PGM_HEADER} bytes")
        char = data[pos:pos + 1]
        if char.isspace():
            pos, separated = pos + 1, True
            continue
        if char == b"#":  # a comment runs to the end of its line
            end = data.find(b"\n", pos)
            pos, separated = (len(data) if end < 0 else end + 1), True
            continue
        start = pos
        while data[pos:pos + 1].isdigit() and pos - start <= MAX_PGM_DIGITS:
            pos += 1
        if pos - start > MAX_PGM_DIGITS:
            raise ValueError(f"{path}: malformed PGM header: the {names[len(fields)]} has "
                             f"more than {MAX_PGM_DIGITS} digits")
        if not separated or pos == start:
            raise ValueError(f"{path}: malformed PGM header: expected whitespace and the "
                             f"{names[len(fields)]}, got {data[start:start + 8]!r}")
        fields.append(int(data[start:pos]))
        separated = False
    width, height, maxval = fields
    if width < 1 or height < 1 or not 1 <= maxval <= 65535:
        raise ValueError(f"{path}: PGM width and height must be >= 1 and maxval in "
                         f"[1, 65535], got {width} x {height}, maxval {maxval}")
    if pos >= len(data) or not data[pos:pos + 1].isspace():
        raise ValueError(f"{path}: malformed PGM header (no whitespace after maxval)")
    return magic, width, height, maxval, pos + 1
