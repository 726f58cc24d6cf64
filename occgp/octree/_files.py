"""OctoMap files of the occupancy octree: ``.bt`` and ``.ot`` bytes and files.

The functions are methods of :class:`occgp.OccupancyOctree`, which binds them in its
class body (``save = _files.save``, ``load = classmethod(_files.load)``), so their
first argument is the map (``self``) or its class (``cls``). What follows OctoMap's
data in a file is the class's ``_trailer()`` (read back by ``_read_trailer``): the
octree's stamps block (``_stamps.py``)."""

from __future__ import annotations

import os
from typing import TYPE_CHECKING, TypeVar

import numpy as np

from ..io import _octomap_format as fmt
from .._atomic import write_bytes
from .._octree import _check_binary_data, _check_full_data
from .._reading import read_regular
from .._validation import as_path, check_choice, check_resolution

__all__ = ["to_bytes", "from_bytes", "save", "load", "check_format"]

if TYPE_CHECKING:
    from ._tree import OccupancyOctree

T = TypeVar("T", bound="OccupancyOctree")


def to_bytes(self: OccupancyOctree, format: str = "ot") -> bytes:
    """Serialise the map in an OctoMap file format.

    Parameters
    ----------
    format : {"ot", "bt"}, default="ot"
        ``"ot"`` keeps every log-odds value. ``"bt"`` is OctoMap's compact
        binary format: it keeps only whether each leaf is free or occupied
        (reading it back gives clamped values). The map itself is unchanged.

    Returns
    -------
    data : bytes
        The contents of a file that OctoMap's tools (octovis, ...) read.
    """
    binary = check_format(format) == "bt"
    if binary:
        # liboctomap's .bt writer stores the max-likelihood tree: build it on a copy
        tree = type(self).from_bytes(self.to_bytes("ot"), **self._sensor_params())
        tree._to_max_likelihood()
        body = tree._write_data(True)
        size = tree.num_nodes
    else:
        body = self._write_data(False)
        size = self.num_nodes
    return fmt.write_header(binary, size, self.resolution) + body + self._trailer()


def from_bytes(cls: type[OccupancyOctree], data: bytes, **params) -> OccupancyOctree:
    """Build a map from the contents of a ``.bt`` or ``.ot`` file.

    Parameters
    ----------
    data : bytes
        File contents; the format is read from the header.
    **params
        Sensor-model parameters (``prob_hit``, ``clamping_min``, ...); the
        files store only the resolution. The clamping bounds give the
        values of ``.bt`` leaves.

    Returns
    -------
    tree : OccupancyOctree
        A map of the class this is called on.

    Raises
    ------
    ValueError
        If the data is not an OcTree file, is truncated or corrupt.
    """
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise TypeError(f"data must be bytes, got {type(data).__name__}")
    return cls._from_data(bytes(data), "data", params)


def save(self: T, path: str | os.PathLike, format: str | None = None) -> T:
    """Write the map to an OctoMap file (see :meth:`to_bytes`).

    The file is written atomically: a temporary file beside `path` replaces
    it once complete, so the previous file stays intact if the write fails.

    Parameters
    ----------
    path : str or path-like
        Destination. Its suffix (``.bt`` or ``.ot``) gives the format unless
        `format` is set.
    format : {"ot", "bt"}, default=None

    Returns
    -------
    self : OccupancyOctree
    """
    path = os.fspath(as_path(path))
    if format is None:
        format = os.path.splitext(path)[1].lstrip(".").lower()
        if format not in fmt.FORMATS:
            raise ValueError(f"path must end in .bt or .ot (or pass format=), got {path!r}")
    write_bytes(path, self.to_bytes(format))
    return self


def load(cls: type[OccupancyOctree], path: str | os.PathLike, **params) -> OccupancyOctree:
    """Read a map from an OctoMap ``.bt`` or ``.ot`` file.

    Parameters
    ----------
    path : str or path-like
    **params
        Sensor-model parameters, as for :meth:`from_bytes`.

    Returns
    -------
    tree : OccupancyOctree
        A map of the class this is called on.

    Raises
    ------
    OSError
        If the file cannot be read, or is not a regular file (a named pipe,
        a device such as ``/dev/zero``: refused before it is opened).
    ValueError
        If it is not an OcTree file, or is truncated or corrupt.
    """
    path = os.fspath(as_path(path))
    data = read_regular(path, what="an OctoMap file")
    return cls._from_data(data, path, params)


def _from_data(cls: type[OccupancyOctree], data: bytes, source: str,
               params: dict) -> OccupancyOctree:
    header = fmt.parse_header(data, source)
    if header.tree_type != "OcTree":
        hint = (" (read ColorOcTree files with occgp.ColorOctree.load)"
                if header.tree_type == "ColorOcTree" else "")
        raise ValueError(f"{source} holds a {header.tree_type!r} tree; only 'OcTree' "
                         f"(occupancy) files can be read{hint}")
    try:
        check_resolution(header.resolution)
    except ValueError as exc:
        raise ValueError(f"{source}: the header's {exc}") from None
    tree = cls(header.resolution, **params)
    if header.size == 0:
        tree._read_trailer(data, header.data_offset, source)
        return tree
    check = _check_binary_data if header.binary else _check_full_data
    buf = np.frombuffer(data, dtype=np.uint8)
    try:
        nodes, end = check(buf, header.data_offset)
    except ValueError as exc:
        raise ValueError(f"{source}: {exc}") from None
    if nodes != header.size:
        raise ValueError(f"{source}: corrupt data: the header announces {header.size} "
                         f"nodes, the data holds {nodes}")
    tree._read_data(data[header.data_offset:end], header.binary, header.resolution)
    tree._read_trailer(data, end, source)
    return tree


def check_format(format: str) -> str:
    """`format` checked: "bt" or "ot"."""
    return check_choice(format, "format", fmt.FORMATS)
