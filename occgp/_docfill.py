"""Docstring sections written once and filled into the docstrings that share them.

A docstring names a shared fragment on a line of its own, ``{name}``; :func:`fill_doc`
replaces that line by the fragment, indented like the line, so that the rendered
``__doc__`` is complete numpydoc (what Sphinx, ``help()`` and the docstring tests read).
"""

from __future__ import annotations

import inspect
import re
import textwrap
from typing import Any, Callable

__all__ = ["PIECES", "fill_doc", "fill_text"]

_PLACEHOLDER = re.compile(r"^([ \t]*)\{(\w+)\}[ \t]*$", re.MULTILINE)


def fill_text(doc: str, fragments: dict[str, str]) -> str:
    """`doc` with each line ``{name}`` replaced by ``fragments[name]``, indented alike.

    Parameters
    ----------
    doc : str
        A docstring.
    fragments : dict of str to str
        Fragment name to its text (dedented and stripped of blank edge lines first).

    Returns
    -------
    text : str
        The filled docstring.

    Raises
    ------
    KeyError
        If `doc` names a fragment that `fragments` lacks.

    Examples
    --------
    >>> fill_text("Sum.\\n\\n    {params}\\n", {"params": "a : int\\n    First."})
    'Sum.\\n\\n    a : int\\n        First.\\n'
    """
    def fill(match: re.Match) -> str:
        text = textwrap.dedent(fragments[match.group(2)]).strip("\n")
        return textwrap.indent(text, match.group(1), lambda line: bool(line.strip()))
    return _PLACEHOLDER.sub(fill, doc)


#: The shared pieces, by name; text flush left, numpydoc section headers included.
PIECES: dict[str, str] = {
    # ------------------------------------------------------------------ files
    "save_parameters": """\
Parameters
----------
path : str or path-like
    Destination file (overwritten; written at `path` exactly, no suffix is
    added). The file is written atomically: a temporary file beside `path`
    replaces it once complete, so the previous file stays intact if the
    write fails.""",
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
    "ray_scan_parameters": """\
Parameters
----------
points : array-like of shape (n_points, 3)
    Ray end points in the world frame, in metres. Must be finite. An
    empty scan (``n_points == 0``) changes nothing.
origin : array-like of shape (3,)
    Sensor position in the world frame, in metres.
max_range : float, default=None
    Rays longer than this are truncated: the cells up to `max_range`
    are marked free and the end cell is not marked occupied. None means
    no limit. Points may then lie beyond the key range, or beyond float
    range: their rays are cut at `max_range` all the same.""",
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


def fill_doc(**fragments: str) -> Callable[[Any], Any]:
    """Decorator: fill the ``{name}`` lines of a function's or class's docstrings.

    The fragments are :data:`PIECES` and those given here (which add to, or
    replace, them). On a class, the docstrings of the functions, class and static
    methods its body defines are filled too.

    Parameters
    ----------
    **fragments : str
        Fragment name to its text (see :func:`fill_text`).

    Returns
    -------
    decorate : callable
        Sets the ``__doc__`` of the object (and of a class's members), unless it
        has none (as under ``python -OO``), and returns the object itself.

    Raises
    ------
    KeyError
        If a docstring names a fragment that does not exist (when decorating).

    Examples
    --------
    >>> @fill_doc(returns="Returns\\n-------\\nn : int")
    ... def one():
    ...     '''One.
    ...
    ...     {returns}
    ...     '''
    ...     return 1
    >>> print(one.__doc__.strip())
    One.
    <BLANKLINE>
        Returns
        -------
        n : int
    """
    table = {**PIECES, **fragments}

    def fill(obj: Any) -> None:
        if obj.__doc__:
            obj.__doc__ = fill_text(obj.__doc__, table)

    def decorate(obj: Any) -> Any:
        fill(obj)
        if isinstance(obj, type):
            for member in vars(obj).values():
                if isinstance(member, (classmethod, staticmethod)):
                    fill(member.__func__)
                elif inspect.isfunction(member):
                    fill(member)
        return obj
    return decorate
