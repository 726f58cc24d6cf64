"""OctoMap's file formats: the text header of ``.bt`` and ``.ot`` files.

A file is a text header, ending with the line ``data``, followed by the tree's
data block. ``.bt`` (binary, maximum likelihood) stores two bits per child;
``.ot`` (full) stores every node's float log-odds and a child mask. The data
blocks are written and read by liboctomap; this module writes the header the way
liboctomap does (but with the resolution's full precision) and parses it
strictly, so that a malformed file is refused with a clear message before
liboctomap sees it.
"""

from __future__ import annotations

import math
import re
from typing import NamedTuple

BINARY_HEADER = "# Octomap OcTree binary file"
FULL_HEADER = "# Octomap OcTree file"
_COMMENT = "# (feel free to add / change comments, but leave the first line as it is!)\n#\n"
FORMATS = ("bt", "ot")


class Header(NamedTuple):
    """What a file's header says."""

    binary: bool
    tree_type: str
    size: int
    resolution: float
    data_offset: int


def write_header(binary: bool, size: int, resolution: float) -> bytes:
    """Return the header liboctomap writes before the data block."""
    first = BINARY_HEADER if binary else FULL_HEADER
    return (
        f"{first}\n{_COMMENT}id OcTree\nsize {size}\nres {resolution!r}\ndata\n"
    ).encode("ascii")


def parse_header(data: bytes, source: str = "data") -> Header:
    """Parse the header at the start of `data`.

    Raises
    ------
    ValueError
        If the first line is not an OctoMap header, a field is missing or
        malformed (``size`` not a non-negative integer, ``res`` not a
        positive finite number), the ``data`` line never comes, or the
        node count is more than the data block can hold.
    """
    first_end = data.find(b"\n")
    first = data[: first_end if first_end >= 0 else 64].decode("ascii", "replace").rstrip("\r")
    if first.startswith(BINARY_HEADER):
        binary = True
    elif first.startswith(FULL_HEADER):
        binary = False
    else:
        raise ValueError(
            f"{source} is not an OctoMap file: its first line should start with "
            f"{BINARY_HEADER!r} (.bt) or {FULL_HEADER!r} (.ot), got {first[:60]!r}"
        )
    fields: dict[str, str] = {}
    pos = first_end + 1
    while True:
        end = data.find(b"\n", pos)
        if end < 0:
            raise ValueError(f"{source}: truncated header (no 'data' line)")
        line = data[pos:end].decode("ascii", "replace").strip()
        pos = end + 1
        if not line or line.startswith("#"):
            continue
        if line == "data":
            break
        key, _, value = line.partition(" ")
        if key in ("id", "size", "res"):  # liboctomap skips unknown keywords too
            fields[key] = value.strip()
    missing = [k for k in ("id", "size", "res") if k not in fields]
    if missing:
        raise ValueError(f"{source}: header lacks the field(s) {', '.join(missing)}")
    if not re.fullmatch(r"[0-9]{1,20}", fields["size"]):
        raise ValueError(
            f"{source}: malformed header: size must be a node count (a non-negative integer), "
            f"got {fields['size'][:40]!r}"
        )
    size = int(fields["size"])
    try:
        resolution = float(fields["res"])
    except ValueError:
        raise ValueError(
            f"{source}: malformed header: res must be a number, got {fields['res'][:40]!r}"
        ) from None
    if not 0 < resolution < math.inf:
        raise ValueError(
            f"{source}: header resolution must be positive and finite, got {resolution}"
        )
    # a .bt block spends 2 bytes on each node with children (8 children at most);
    # a .ot block 5 bytes on every node
    n_bytes = len(data) - pos
    most = 1 + 4 * n_bytes if binary else n_bytes // 5
    if size > most:
        raise ValueError(
            f"{source}: corrupt header: it announces {size} nodes, but the {n_bytes} data "
            f"bytes hold at most {most}"
        )
    return Header(binary, fields["id"], size, resolution, pos)
