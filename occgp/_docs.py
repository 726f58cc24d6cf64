"""Docstring pieces that several classes share, filled in where ``{name}`` stands alone
on a line (:func:`fill_doc`), so that one text serves every class that documents it."""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import TypeVar

T = TypeVar("T")

#: The sensor model of the log-odds maps (liboctomap's), as numpydoc parameters.
SENSOR_MODEL = """\
prob_hit : float, default=0.7
    Probability that a cell is occupied given a ray ends in it; in (0.5, 1).
prob_miss : float, default=0.4
    Probability that a cell is occupied given a ray crosses it; in (0, 0.5).
clamping_min : float, default=0.1192
    Lower clamping bound (probability); in (0, 0.5).
clamping_max : float, default=0.971
    Upper clamping bound (probability); in (0.5, 1).
occupancy_threshold : float, default=0.5
    Cells at or above this probability count as occupied; in (0, 1)."""

#: The attributes every octree shows.
OCTREE_ATTRIBUTES = """\
resolution : float
    Edge length of the smallest cells.
num_leaves : int
    Number of leaves (known cells after pruning).
num_nodes : int
    Number of nodes, inner ones included.
bounds : tuple of ndarray of shape (3,)
    Minimum and maximum corner of the known space (NaN when empty)."""


def fill_doc(**pieces: str) -> Callable[[T], T]:
    """A decorator that replaces each line ``{name}`` of the docstring by the piece
    `name`, indented as that line.

    Parameters
    ----------
    **pieces : str
        The texts, by the names their placeholders use.

    Returns
    -------
    decorator : callable
        Fills the docstring of the class or function it decorates and returns it.
    """
    def decorate(obj: T) -> T:
        doc = obj.__doc__ or ""
        for name, text in pieces.items():
            doc = re.sub(r"^([ \t]*)\{" + re.escape(name) + r"\}[ \t]*$",
                         lambda m: "\n".join(m.group(1) + line if line else line
                                             for line in text.splitlines()),
                         doc, flags=re.MULTILINE)
        obj.__doc__ = doc
        return obj
    return decorate
