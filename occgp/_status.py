"""The outcome codes of occgp's compiled core, and the one place that turns them into errors.

The compiled core (``ext/_status.h``) reports each failure as a :class:`Status`
code instead of raising; :func:`check_status` raises its exception, with a
message built from what the caller knows (the rows at fault, the map's limits).
"""

from __future__ import annotations

import enum

__all__ = ["Status", "check_status"]


class Status(enum.IntEnum):
    """A code of the compiled core (the values of ``occgp::Status`` in ``ext/_status.h``)."""

    OK = 0
    OUT_OF_RANGE = 1            # a point or ray end (after truncation) has no valid key
    RAY_TOO_SHORT = 2           # a ray crosses a cell border but is too short to walk
    TOO_MANY_CELLS = 3          # a scan reaches more cells than its limit
    TRUNCATED_DATA = 4          # a tree's data block ends before its last node
    CORRUPT_DEPTH = 5           # a node of a data block lies deeper than 16 levels
    CORRUPT_VALUE = 6           # a node of a data block holds a non-finite log-odds
    UNREADABLE_DATA = 7         # liboctomap could not read a data block
    WEIGHTS_LENGTH = 8          # ray weights do not match the scan's rays
    WEIGHTS_WITH_SUPERRAYS = 9  # ray weights were given with super rays

    @property
    def label(self) -> str:
        """The code's name in words, e.g. ``"too many cells"``."""
        return self.name.lower().replace("_", " ")


# messages by code; str.format fields come from check_status's context
_MESSAGES = {
    Status.OUT_OF_RANGE: (
        "{n_bad} of {n_total} {name}{what} lie outside the {kind}'s key range "
        "[{lo:g}, {hi:g}) m on some axis at resolution {resolution:g} "
        "(first: row {first}); the map is unchanged"),
    Status.RAY_TOO_SHORT: (
        "{n_bad} of {n_total} rays from origin to points are shorter than "
        "{shortest:.2g} m yet cross a cell border (first: row {first}): "
        "liboctomap's single-precision traversal cannot walk them; the map is unchanged"),
    Status.TOO_MANY_CELLS: (
        "the scan's {n_rays} rays reach more than MAX_SCAN_CELLS={max_scan_cells} cells "
        "at resolution {resolution:g} m; use a coarser resolution, max_range or fewer "
        "points, or raise MAX_SCAN_CELLS; the map is unchanged"),
    Status.TRUNCATED_DATA: "truncated data: the tree needs more than the {n_bytes} bytes given",
    Status.CORRUPT_DEPTH: "corrupt data: a node lies deeper than the 16 levels of an OcTree",
    Status.CORRUPT_VALUE: "corrupt data: a node holds a non-finite log-odds value",
    Status.UNREADABLE_DATA: "liboctomap could not read the tree data",
    Status.WEIGHTS_LENGTH: "weights must have length {expected}, got {got}",
    Status.WEIGHTS_WITH_SUPERRAYS: "weights and super rays do not combine",
}


def check_status(status: int, **context: object) -> None:
    """Raise the error a compiled core's `status` stands for; return for ``Status.OK``.

    Parameters
    ----------
    status : int or Status
        A code of the compiled core.
    **context
        The fields of the code's message: ``n_bad, n_total, name, what, kind, lo,
        hi, resolution, first`` (OUT_OF_RANGE), ``n_bad, n_total, shortest,
        first`` (RAY_TOO_SHORT), ``n_rays, max_scan_cells, resolution``
        (TOO_MANY_CELLS), ``n_bytes`` (TRUNCATED_DATA), ``expected, got``
        (WEIGHTS_LENGTH).

    Raises
    ------
    ValueError
        For every code but ``Status.OK``, with the code's message.
    """
    status = Status(status)
    if status is Status.OK:
        return
    raise ValueError(_MESSAGES[status].format(**context))
