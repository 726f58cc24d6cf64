"""Small file helpers shared by the readers: path checks, whole-file reads."""

import bz2
import errno
import gzip
import lzma
import zlib
from pathlib import Path

from .._reading import read_regular
from .._validation import as_path

__all__ = ["as_path", "read_bytes", "read_maybe_compressed", "read_text", "READER_SECTIONS"]

#: Docstring sections the file readers share (fragments for :func:`occgp._docfill.fill_doc`).
READER_SECTIONS = {
    "raises_oserror": """Raises
------
OSError
    If the file is missing or unreadable, or is not a regular file (a named
    pipe, a device such as ``/dev/zero``).""",
    "path_type_error": """TypeError
    If `path` is not a str or os.PathLike.""",
    "unwritable": """OSError
    If the file cannot be written.""",
    "path_to_scans": """Parameters
----------
path : str or os.PathLike

Returns
-------
scans : list of Scan""",
}


def _check_file(path: Path) -> None:
    if not path.exists():
        raise FileNotFoundError(errno.ENOENT, "no such file", str(path))
    if path.is_dir():
        raise IsADirectoryError(errno.EISDIR, "expected a file, got a directory", str(path))


def read_bytes(path) -> bytes:
    """Read a whole regular file; OSError (FileNotFoundError, ...) naming the path.

    A named pipe, a device (``/dev/zero``) or a socket is refused before it is
    opened (:func:`occgp._reading.open_regular`), so a reader never hangs on a
    pipe nor reads an endless device."""
    path = as_path(path)
    _check_file(path)
    return read_regular(path)


def read_maybe_compressed(path) -> bytes:
    """Read a file, decompressing ``.bz2``, ``.gz`` and ``.xz`` by suffix.

    A corrupt or truncated compressed stream raises ValueError naming the file.
    """
    path = as_path(path)
    raw = read_bytes(path)
    suffix = path.suffix.lower()
    openers = {".bz2": bz2.decompress, ".gz": gzip.decompress, ".xz": lzma.decompress}
    if suffix not in openers:
        return raw
    try:
        return openers[suffix](raw)
    except (OSError, EOFError, ValueError, zlib.error, lzma.LZMAError) as exc:
        raise ValueError(f"{path}: corrupt or truncated {suffix[1:]} stream ({exc})") from None


def read_text(path) -> str:
    """:func:`read_maybe_compressed` decoded as UTF-8; ValueError naming the file if it is not."""
    raw = read_maybe_compressed(path)
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not a text file (invalid UTF-8)") from None
