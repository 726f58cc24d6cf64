"""Docstring sections shared by occgp's maps and models, and the decorator that fills them in.

A docstring names a shared piece by a line holding only ``{name}``; :func:`fill_doc`
replaces that line by the piece, each of its lines indented as the placeholder was.
The rendered ``__doc__`` is complete numpydoc (what Sphinx, ``help()`` and the
docstring tests read). On a class it fills the class's docstring and those of the
methods the class body defines::

    @fill_doc()
    class Model:
        @classmethod
        def load(cls, path):
            '''Read a model written by :meth:`save`.

            {load_parameters}
            ...
            '''
"""

from __future__ import annotations

import inspect
import re
from typing import Callable, TypeVar

__all__ = ["PIECES", "fill_doc"]

T = TypeVar("T")

#: A line holding only ``{name}`` (and white space).
_PLACEHOLDER = re.compile(r"^([ \t]*)\{(\w+)\}[ \t]*$", re.MULTILINE)

#: The shared pieces, by name; text flush left, numpydoc section headers included.
PIECES: dict[str, str] = {
    # ------------------------------------------------------------------ files
    "save_parameters": """\
Parameters
----------
path : str or path-like
    Destination file (overwritten; written at `path` exactly, no suffix is
    added).""",
    "gp_save_raises": """\
Raises
------
TypeError
    If `path` is not a str or path-like, or a parameter holds a value
    that cannot be saved (see :meth:`GPOMIK.save <occgp.gp.GPOMIK.save>`).
OSError
    If the file cannot be written.""",
    "load_parameters": """\
Parameters
----------
path : str or path-like
    A file written by ``save`` of this class.""",
    # the ValueError's description goes on in the docstring (its model's checks)
    "load_raises": """\
Raises
------
TypeError
    If `path` is not a str or path-like.
OSError
    If the file does not exist, is not a regular file or cannot be read.
ValueError
    If it is not an ``.npz`` archive, is truncated or corrupt, is of
    another format, version or class, lacks an entry or has an
    unexpected one, or an entry has the wrong dtype or shape.""",
    # ------------------------------------------------------- occgp.gp queries
    "predict_parameters": """\
Parameters
----------
X : array-like of shape (n_queries, D)
    Query points in the fitted model's dimension D. Must be finite.
return_var : bool, default=False
    Also return the latent variance.""",
    "predict_returns": """\
Returns
-------
mean : ndarray of shape (n_queries,)
var : ndarray of shape (n_queries,)
    Only with `return_var`.""",
    "predict_raises": """\
Raises
------
NotFittedError
    If called before :meth:`fit`.
ValueError
    If `X` is not of shape (n_queries, D) or holds NaN or inf.
TypeError
    If `X` does not hold real numbers, or `return_var` is not a bool.""",
    # ------------------------------------------------------- occgp.gp updates
    "update_parameters": """\
Parameters
----------
hits : array-like of shape (n_hits, D), default=None
    Laser returns, in the fitted model's dimension D.
segment_starts, segment_ends : array-like of shape (n_beams, D), default=None
    Beams, given together. `hits` or the beams may be None, not both.""",
    # ------------------------------------------------------ 3D scans of the maps
    "scan_parameters": """\
Parameters
----------
points : array-like of shape (n_points, 3)
    End points of the beams in the world frame, in metres.
origin : array-like of shape (3,)
    Sensor position, in metres.""",
    "training_returns": """\
Returns
-------
samples : ndarray of shape (n_samples, 3)
labels : ndarray of shape (n_samples,)""",
    "occupied_returns": """\
Returns
-------
occupied : ndarray of bool, shape (n_points,)
unknown : ndarray of bool, shape (n_points,)
    Only when `return_unknown` is True.""",
    "map_returns": """\
Returns
-------
self
    The map.""",
    "updated_map_returns": """\
Returns
-------
self
    The updated map.""",
}


def _indented(text: str, indent: str) -> str:
    return "\n".join(indent + line if line else "" for line in text.splitlines())


def fill_doc(**pieces: str) -> Callable[[T], T]:
    """Decorator: fill the ``{name}`` lines of a function's or class's docstrings.

    On a class, the docstrings of the functions, class and static methods its
    body defines are filled too.

    Parameters
    ----------
    **pieces : str
        Pieces of this docstring only (flush left), by name; they add to,
        or replace, :data:`PIECES`.

    Returns
    -------
    decorate : callable
        Sets the ``__doc__`` of the object (and of a class's members), unless
        it has none (as under ``python -OO``), and returns the object itself.

    Raises
    ------
    KeyError
        If the docstring names a piece that does not exist (when decorating).
    """
    table = {**PIECES, **pieces}

    def fill(obj: object) -> None:
        doc = obj.__doc__
        if doc:
            obj.__doc__ = _PLACEHOLDER.sub(
                lambda m: _indented(table[m.group(2)], m.group(1)), doc)

    def decorate(obj: T) -> T:
        fill(obj)
        if isinstance(obj, type):
            for member in vars(obj).values():
                if isinstance(member, (classmethod, staticmethod)):
                    fill(member.__func__)
                elif inspect.isfunction(member):
                    fill(member)
        return obj

    return decorate
