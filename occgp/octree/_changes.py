"""Change detection of the occupancy octree (liboctomap's ``enableChangeDetection``):
which cells an update made new or flipped.

The functions are methods of :class:`occgp.OccupancyOctree`, which binds them in its
class body (``changed_cells = _changes.changed_cells``; ``track_changes =
property(_changes.track_changes, _changes.set_track_changes)``), so their first
argument is the map, named ``self``.
"""

from __future__ import annotations

import warnings
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
from numpy.typing import NDArray

from ._queries import unpack_keys
from .._validation import check_bool

if TYPE_CHECKING:
    from ._tree import OccupancyOctree

__all__ = ["Changes", "track_changes", "set_track_changes", "changed_cells",
           "reset_changes"]


class Changes(NamedTuple):
    """The cells a map recorded as changed (see :attr:`OccupancyOctree.track_changes`)."""

    #: Keys of the finest cells, uint16, shape (n, 3), sorted.
    keys: NDArray[np.uint16]
    #: Their centers, metres, shape (n, 3).
    centers: NDArray[np.float64]
    #: True where the cell was new (unknown before), False where its state flipped.
    new: NDArray[np.bool_]

    @property
    def centres(self) -> NDArray[np.float64]:
        """Deprecated name of :attr:`centers` (the spelling of :class:`Nodes` and
        :class:`Leaves`)."""
        warnings.warn("Changes.centres is deprecated; use Changes.centers",
                      DeprecationWarning, stacklevel=2)
        return self.centers


def track_changes(self: OccupancyOctree) -> bool:
    """Whether the map records which cells change (liboctomap's change detection).

    Set it to True to start recording: from then on, every update
    (:meth:`insert_scan` by any method, :meth:`update_cells`,
    :meth:`set_cells`) records, per finest cell, what liboctomap's
    ``enableChangeDetection`` records: a cell the map did not know is
    recorded as new; a known cell whose state (occupied or free) flips is
    recorded, and removed again when it flips back. Read them with
    :meth:`changed_cells`, clear them with :meth:`reset_changes`. The
    record is not saved in files or pickles.

    Examples
    --------
    >>> from occgp import OccupancyOctree
    >>> m = OccupancyOctree(0.1)
    >>> m.track_changes = True
    >>> m = m.insert_scan([[0.35, 0.05, 0.05]], [0.05, 0.05, 0.05])
    >>> changes = m.changed_cells()
    >>> len(changes.keys), bool(changes.new.all())     # 3 free cells, 1 occupied
    (4, True)
    """
    return bool(self._is_tracking())


def set_track_changes(self: OccupancyOctree, value: bool) -> None:
    self._set_tracking(check_bool(value, "track_changes"))


def changed_cells(self: OccupancyOctree) -> "Changes":
    """The cells recorded since tracking began or :meth:`reset_changes`.

    Returns
    -------
    changes : Changes
        Named tuple ``(keys, centers, new)``: the finest cells' keys
        (uint16, shape (n, 3), sorted), their centers and whether each
        was new (unknown before) rather than flipped. Empty when
        :attr:`track_changes` was never set.
    """
    packed, new = self._changed()
    order = np.argsort(packed, kind="stable")
    packed, new = packed[order], new[order]
    keys = unpack_keys(packed)
    centers = self.key_to_coord(keys) if len(keys) else np.empty((0, 3))
    return Changes(keys, centers, new)


def reset_changes(self: OccupancyOctree) -> "OccupancyOctree":
    """Forget the recorded changes (tracking stays as it is).

    Returns
    -------
    self
        The map.
    """
    self._reset_changes()
    return self
