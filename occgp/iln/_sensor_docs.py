"""Docstrings of :class:`occgp.iln.LidarModel`'s size arguments and presets."""

from __future__ import annotations

from .._docfill import fill_text

__all__ = ["SIZE_SECTIONS", "preset"]

#: Docstring sections of the methods that take an image size (see :func:`occgp._docfill.fill_doc`).
SIZE_SECTIONS = {
    "size_params": """rows : int
    Beams (image rows), 1 to 65536.
cols : int
    Image columns, 1 to 65536; ``rows * cols`` at most
    ``MAX_PIXELS`` (2**24).""",
    "size_errors": """TypeError
    If `rows` or `cols` is not an int.
ValueError
    If `rows` or `cols` is outside [1, 65536], or ``rows * cols``
    exceeds ``MAX_PIXELS`` (2**24).""",
}

_PRESET_DOC = """{summary}

        Parameters
        ----------
        rows : int, default={rows}
            Beams (image rows), 1 to 65536.
        cols : int, default=1024
            Firings per revolution (image columns), 1 to 65536; ``rows * cols``
            at most ``MAX_PIXELS`` (2**24).{extra}

        Returns
        -------
        LidarModel

        Raises
        ------
        {{size_errors}}
        """


_TABLE_PARAM = """
        table : bool, default=False
            Use the sensor's per-beam elevation table (``beam_elevations``,
            resampled linearly when `rows` differs from its beams) instead of
            uniform rows over the field of view."""


def preset(summary: str, rows: int, table: bool = False):
    """Give a preset constructor of :class:`LidarModel` its docstring."""
    def decorate(fn):
        extra = _TABLE_PARAM if table else ""
        fn.__doc__ = fill_text(_PRESET_DOC.format(summary=summary, rows=rows, extra=extra),
                               SIZE_SECTIONS)
        return fn
    return decorate
