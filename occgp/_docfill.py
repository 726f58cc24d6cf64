"""Docstring sections written once and filled into the docstrings that share them.

A docstring names a shared fragment on a line of its own, ``{name}``; :func:`fill_doc`
replaces that line by the fragment, indented like the line, so that the rendered
``__doc__`` is complete numpydoc (what Sphinx, ``help()`` and the docstring tests read).
"""

from __future__ import annotations

import re
import textwrap
from typing import Any, Callable

__all__ = ["fill_doc", "fill_text"]

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


def fill_doc(**fragments: str) -> Callable[[Any], Any]:
    """Decorator: fill the named fragments into a function's or class's docstring.

    Parameters
    ----------
    **fragments : str
        Fragment name to its text (see :func:`fill_text`).

    Returns
    -------
    decorate : callable
        Sets ``obj.__doc__`` to the filled docstring and returns `obj`.

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
    def decorate(obj: Any) -> Any:
        if obj.__doc__:
            obj.__doc__ = fill_text(obj.__doc__, fragments)
        return obj
    return decorate
