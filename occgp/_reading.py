"""Bounded file reads: the way occgp's readers open a file.

A reader must never hang on a named pipe, read a device such as
``/dev/zero`` until memory runs out, or allocate what a hostile header
announces before checking it. The readers therefore open files only through
this module:

* :func:`open_regular` opens a path only if it is a regular file (checked with
  ``os.stat`` before the open, and again with ``os.fstat`` on the descriptor,
  opened non-blocking so that a pipe swapped in between cannot block); a FIFO,
  a device, a socket or a folder raises an ``OSError`` naming the file.
* :func:`read_regular` reads a whole regular file, refusing one larger than a
  limit before reading it.
* :func:`read_limited` reads at most a given number of bytes from an open file
  (a header).
* :func:`load_yaml_mapping` reads a small YAML file of a mapping without
  aliases (``*name``): "billion laughs" documents, whose nested aliases expand
  to billions of nodes when printed or walked, are refused.

Every error names the file.
"""

from __future__ import annotations

import errno
import os
import stat
from typing import IO, Any

from ._validation import as_path

__all__ = ["check_regular", "open_regular", "read_regular", "read_limited", "load_yaml_mapping",
           "MAX_YAML_BYTES"]

#: The largest YAML description read (map_server's files hold a few hundred bytes).
MAX_YAML_BYTES = 1 << 20

_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a named pipe (FIFO)"),
          (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
          (stat.S_ISSOCK, "a socket"))
_FLAGS = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0) \
    | getattr(os, "O_BINARY", 0)


def _kind(mode: int) -> str:
    return next((name for test, name in _KINDS if test(mode)), "not a regular file")


def _not_regular(path: str, mode: int, what: str) -> OSError:
    code = errno.EISDIR if stat.S_ISDIR(mode) else errno.EINVAL
    exc_type = IsADirectoryError if stat.S_ISDIR(mode) else OSError
    return exc_type(code, f"{what} must be a regular file, got {_kind(mode)}", path)


def check_regular(path: Any, what: str = "the file", name: str = "path") -> None:
    """Raise unless `path` is a regular file (FileNotFoundError if missing, OSError
    naming the file and its kind otherwise), without opening it."""
    path = os.fspath(as_path(path, name))
    st = os.stat(path)
    if not stat.S_ISREG(st.st_mode):
        raise _not_regular(path, st.st_mode, what)


def open_regular(path: Any, what: str = "the file", name: str = "path") -> IO[bytes]:
    """Open `path` for binary reading if it is a regular file.

    Raises
    ------
    TypeError
        If `path` is not a str or os.PathLike (the message names `name`).
    FileNotFoundError, PermissionError, IsADirectoryError, OSError
        If the file is missing, unreadable, a folder, or another kind of file
        than a regular one (a FIFO, a device, a socket); the error's
        ``filename`` is the path.
    """
    path = os.fspath(as_path(path, name))
    st = os.stat(path)      # FileNotFoundError etc. name the path
    if not stat.S_ISREG(st.st_mode):
        raise _not_regular(path, st.st_mode, what)
    fd = os.open(path, _FLAGS)
    try:
        st = os.fstat(fd)   # the file opened, if it changed since the stat
        if not stat.S_ISREG(st.st_mode):
            raise _not_regular(path, st.st_mode, what)
        if _FLAGS & getattr(os, "O_NONBLOCK", 0):
            os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_limited(fh: IO[bytes], size: int) -> bytes:
    """At most `size` bytes from the open file `fh` (fewer at its end)."""
    chunks, left = [], size
    while left > 0:
        chunk = fh.read(left)
        if not chunk:
            break
        chunks.append(chunk)
        left -= len(chunk)
    return b"".join(chunks)


def read_regular(path: Any, *, limit: int | None = None, what: str = "the file",
                 name: str = "path") -> bytes:
    """The bytes of the regular file `path`, refused unread when larger than `limit`.

    Raises
    ------
    OSError
        As :func:`open_regular`.
    ValueError
        If the file holds more than `limit` bytes (checked before reading it, and
        again while reading, for a file that grows).
    """
    with open_regular(path, what, name) as fh:
        size = os.fstat(fh.fileno()).st_size
        if limit is not None and size > limit:
            raise ValueError(f"{os.fspath(path)}: {what} holds {size} bytes, more than "
                             f"the {limit} read")
        data = read_limited(fh, size + 1 if limit is None else limit + 1)
        if limit is not None and len(data) > limit:
            raise ValueError(f"{os.fspath(path)}: {what} holds more than the {limit} "
                             "bytes read (it grew while being read)")
        if limit is None and len(data) > size:   # grew while read: read the rest
            data += fh.read()
    return data


def load_yaml_mapping(path: Any, what: str = "YAML file", *,
                      limit: int = MAX_YAML_BYTES) -> dict:
    """The mapping in the UTF-8 YAML file `path` (at most `limit` bytes, no aliases).

    Raises
    ------
    OSError
        As :func:`open_regular`.
    ValueError
        If the file is larger than `limit`, not UTF-8, not valid YAML, holds
        an alias (``*name``) or nesting deeper than Python's recursion allows,
        or is not a mapping. The message names the file.
    """
    import yaml  # type: ignore[import-untyped]  # PyYAML

    data = read_regular(path, limit=limit, what=f"a {what}")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path}: a {what} must be UTF-8 text ({exc})") from None
    try:
        doc = yaml.load(text, Loader=_no_alias_loader())  # noqa: S506 - a SafeLoader
    except yaml.YAMLError as exc:
        raise ValueError(f"{path}: not a valid YAML file ({_short(str(exc), 400)})") from None
    except RecursionError:
        raise ValueError(f"{path}: not a {what}: its YAML nesting is too deep") from None
    except (ValueError, OverflowError) as exc:  # e.g. an int of more than 4300 digits
        raise ValueError(f"{path}: a value of the {what} cannot be read "
                         f"({_short(str(exc), 200)})") from None
    if not isinstance(doc, dict):
        raise ValueError(f"{path}: a {what} must hold a mapping of keys, got "
                         f"{type(doc).__name__}")
    return doc


def _short(text: str, n: int = 80) -> str:
    return text if len(text) <= n else text[:n - 3] + "..."


_LOADER: list = []


def _no_alias_loader() -> type:
    """PyYAML's SafeLoader refusing aliases (``*name``); built at first use."""
    if _LOADER:
        return _LOADER[0]
    import yaml  # type: ignore[import-untyped]

    class NoAliasLoader(yaml.SafeLoader):
        def compose_node(self, parent, index):  # type: ignore[no-untyped-def]
            if self.check_event(yaml.AliasEvent):
                event = self.peek_event()
                raise yaml.composer.ComposerError(
                    None, None, f"found the alias *{_short(str(event.anchor), 40)}; aliases "
                    "are not read", event.start_mark)
            return super().compose_node(parent, index)

    _LOADER.append(NoAliasLoader)
    return NoAliasLoader
