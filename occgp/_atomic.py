"""Atomic file writes: the one way occgp writes a file.

Every writer in occgp (maps, models, exports, ROS map pairs, figures, ILN
shards and checkpoints) writes a temporary file in the destination's folder,
flushes it to disk (``os.fsync``), then renames it onto the destination with
``os.replace`` and syncs the folder. A reader therefore sees either the old
file or the complete new one, never a truncated file; when the write fails
(disk full, file size limit, an exception or ``KeyboardInterrupt`` in the
writer) the temporary file is removed and the previous file stays intact.

* :func:`atomic_open` gives a file object (``open()``'s `mode` and `encoding`),
  for writers that take one (``numpy.savez_compressed``, ``torch.save``,
  matplotlib's ``savefig``, ``write``).
* :func:`atomic_path` gives the temporary file's name, for writers that only
  take a path.
* :func:`write_bytes` writes bytes.
* :func:`atomic_group` writes several files and replaces them in a given order
  (a ROS map's image, then its YAML file), putting back the files it already
  replaced when a later replacement fails.

The new file gets the destination's permission bits when it exists, else the
umask's default (``0o666 & ~umask``) as a plain ``open()`` gives. A destination
that is a symbolic link is written through: its target is replaced.
"""

from __future__ import annotations

import contextlib
import errno
import os
import secrets
import shutil
import stat
from collections.abc import Iterator
from typing import IO, Any

from ._validation import as_path

__all__ = ["atomic_open", "atomic_path", "atomic_group", "write_bytes"]

_FLAGS = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0) \
    | getattr(os, "O_BINARY", 0)


class _Pending:
    """One destination and its temporary file beside it (created, empty).

    A destination that exists but is not a regular file (``/dev/null``, a FIFO)
    cannot be replaced: it is written directly (``tmp`` is the destination).
    """

    def __init__(self, path: Any, name: str = "path"):
        dest = os.fspath(as_path(path, name))
        if os.path.islink(dest):
            dest = os.path.realpath(dest)
        self.dest = dest
        folder, base = os.path.split(os.path.abspath(dest))
        self.folder = folder
        try:
            st = os.stat(dest)
        except OSError:
            st = None
        self.mode = None if st is None else stat.S_IMODE(st.st_mode)
        self.direct = st is not None and not stat.S_ISREG(st.st_mode)
        if st is not None and self.direct:
            if stat.S_ISDIR(st.st_mode):
                raise IsADirectoryError(errno.EISDIR, "cannot write a file over a folder", dest)
            self.tmp = dest
            return
        if st is not None and not os.access(dest, os.W_OK):
            # open() refuses a read-only file; a rename would not
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), dest)
        while len(os.fsencode(base)) > 200:          # room for the prefix and suffix
            base = base[:-1]
        for _ in range(100):
            tmp = os.path.join(folder, f".{base}.{secrets.token_hex(4)}.tmp")
            try:
                fd = os.open(tmp, _FLAGS, 0o666)
            except FileExistsError:
                continue
            except OSError as exc:
                if isinstance(exc, FileNotFoundError) and not os.path.isdir(folder):
                    raise FileNotFoundError(errno.ENOENT, "cannot write the file: its folder "
                                            f"{folder!r} does not exist", dest) from None
                raise _naming(dest, exc) from None
            break
        else:  # pragma: no cover - 100 collisions of 32 random bits
            raise FileExistsError(errno.EEXIST, "no free temporary name", dest)
        self.tmp = tmp
        os.close(fd)

    def sync(self) -> None:
        """Flush the temporary file to disk and give it its permission bits."""
        if self.direct:
            return
        fd = os.open(self.tmp, os.O_RDONLY | getattr(os, "O_BINARY", 0))
        try:
            if self.mode is not None and hasattr(os, "fchmod"):
                os.fchmod(fd, self.mode)
            os.fsync(fd)
        finally:
            os.close(fd)
        if self.mode is not None and not hasattr(os, "fchmod"):  # pragma: no cover - Windows
            os.chmod(self.tmp, self.mode)

    def discard(self) -> None:
        if self.direct:
            return
        with contextlib.suppress(OSError):
            os.unlink(self.tmp)


def _naming(dest: str, exc: BaseException) -> BaseException:
    """`exc` (an OSError) again, naming the destination rather than the temporary file."""
    if not isinstance(exc, OSError) or exc.errno is None:
        return exc
    try:
        return type(exc)(exc.errno, exc.strerror, dest)
    except TypeError:  # pragma: no cover - an OSError subclass of another signature
        return exc


def _sync_folder(folder: str) -> None:
    """fsync a folder so that a rename in it survives a crash (where the OS can)."""
    if not hasattr(os, "O_DIRECTORY"):  # pragma: no cover - Windows
        return
    try:
        fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass                                    # some file systems refuse it
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_group(*paths: Any, name: str = "path") -> Iterator[list[str]]:
    """Write several files: yields their temporary paths; replaces them in order.

    On leaving the block without an exception each temporary file is synced,
    then the destinations are replaced in the order of `paths`. An exception in
    the block removes the temporary files and changes no destination. When a
    replacement fails, the destinations already replaced are put back as they
    were (restored from hard links, or copies, made before the first
    replacement; removed if they did not exist). A process killed between two
    replacements leaves the earlier files new and the later ones old.
    """
    pending: list[_Pending] = []
    try:
        for path in paths:
            pending.append(_Pending(path, name))
        yield [p.tmp for p in pending]
        for p in pending:
            p.sync()
    except BaseException as exc:
        for p in pending:
            p.discard()
        if isinstance(exc, OSError):
            # a write error names the temporary file, or no file: name the destination
            named = [p.dest for p in pending if exc.filename == p.tmp]
            if not named and exc.filename is None and len(paths) == 1 and pending:
                named = [pending[0].dest]
            if named:
                raise _naming(named[0], exc) from exc
        raise
    backups = _backups(pending) if len(pending) > 1 else [None] * len(pending)
    done = 0
    try:
        for p in pending:
            if not p.direct:
                os.replace(p.tmp, p.dest)
            done += 1
    except BaseException as exc:
        for p, backup in zip(pending[:done], backups):
            if p.direct:
                continue
            with contextlib.suppress(OSError):
                if backup is None:
                    os.unlink(p.dest)
                else:
                    os.replace(backup, p.dest)
        for p in pending[done:]:
            p.discard()
        for backup in backups:
            if backup is not None:
                with contextlib.suppress(OSError):
                    os.unlink(backup)
        if isinstance(exc, OSError) and done < len(pending):
            raise _naming(pending[done].dest, exc) from exc
        raise
    for backup in backups:
        if backup is not None:
            with contextlib.suppress(OSError):
                os.unlink(backup)
    for folder in dict.fromkeys(p.folder for p in pending):
        _sync_folder(folder)


def _backups(pending: list[_Pending]) -> list[str | None]:
    """A hard link (or a copy) of each existing destination, beside it; None where
    there is none."""
    out: list[str | None] = []
    try:
        for p in pending:
            if p.direct or not os.path.exists(p.dest):
                out.append(None)
                continue
            spare = _Pending(p.dest).tmp     # a fresh free name in the same folder
            try:
                os.unlink(spare)
                os.link(p.dest, spare)
            except OSError:                   # no hard links here: a copy
                try:
                    shutil.copy2(p.dest, spare)
                except BaseException:
                    with contextlib.suppress(OSError):
                        os.unlink(spare)
                    raise
            out.append(spare)
    except BaseException:
        for backup in out:
            if backup is not None:
                with contextlib.suppress(OSError):
                    os.unlink(backup)
        for p in pending:
            p.discard()
        raise
    return out


@contextlib.contextmanager
def atomic_path(path: Any, name: str = "path") -> Iterator[str]:
    """Yield the name of a new, empty temporary file beside `path`; on a clean
    exit it is synced and renamed onto `path`, on any exception removed.

    For writers that take a file name (the file may be reopened and truncated).
    """
    with atomic_group(path, name=name) as (tmp,):
        yield tmp


@contextlib.contextmanager
def atomic_open(path: Any, mode: str = "wb", *, encoding: str | None = None,
                name: str = "path") -> Iterator[IO[Any]]:
    """``open(path, mode)`` for writing, made atomic (see the module's docstring).

    `mode` is ``"wb"`` or ``"w"`` (text, with `encoding`). The file object
    writes the temporary file; leaving the block without an exception puts the
    complete file at `path`, an exception leaves `path` as it was.

    Examples
    --------
    >>> import os, tempfile
    >>> path = os.path.join(tempfile.mkdtemp(), "a.txt")
    >>> with atomic_open(path, "w", encoding="utf-8") as fh:
    ...     _ = fh.write("new")
    >>> open(path).read()
    'new'
    """
    if mode not in ("wb", "w"):
        raise ValueError(f"mode must be 'wb' or 'w', got {mode!r}")
    with atomic_path(path, name) as tmp:
        with open(tmp, mode, encoding=encoding) as fh:
            yield fh
            fh.flush()


def write_bytes(path: Any, data: bytes, name: str = "path") -> None:
    """Write `data` to `path` atomically."""
    with atomic_open(path, "wb", name=name) as fh:
        fh.write(data)
