"""Time stamps per cell and the decay of outdated cells, for dynamic scenes.

The functions are methods of :class:`occgp.OccupancyOctree`, which binds them in its
class body (``decay = _stamps.decay``), so their first argument is the map, named
``self``; the map's files carry the stamps through its ``_trailer`` and
``_read_trailer`` (:func:`stamps_block`, :func:`read_stamps_block`).

A stamp is a float (seconds, or any clock the caller keeps) kept per finest cell
beside liboctomap's tree: an update made with ``stamp=t`` (:meth:`insert_scan`,
:meth:`update_cells`, :meth:`set_cells`) sets the stamp of every cell it reaches
to ``t``. :func:`decay` then follows liboctomap's
``OcTreeStamped::degradeOutdatedNodes`` (one miss for each occupied cell older
than an age limit, per call) or lets log-odds fade with a half-life. The stamps
travel with the map in its files (a block after OctoMap's data, which OctoMap's
tools skip) and in pickles.
"""

from __future__ import annotations

import math
import struct
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._queries import pack_keys, unpack_keys
from .._validation import check_real

__all__ = ["Stamps", "stamps", "stamp_at", "clear_stamps", "decay", "STAMPS_MAGIC",
           "stamps_block", "read_stamps_block"]

#: The first bytes of the stamps block written after a stamped map's OctoMap data.
STAMPS_MAGIC = b"# occgp stamps v1\n"
_COUNT = struct.Struct("<Qd")


class Stamps(NamedTuple):
    """The stamped cells of a map (see :meth:`OccupancyOctree.stamps`)."""

    #: Keys of the finest cells, uint16, shape (n, 3), sorted.
    keys: NDArray[np.uint16]
    #: Their centers, metres, shape (n, 3).
    centers: NDArray[np.float64]
    #: The stamp of the last stamped update that reached each cell, shape (n,).
    stamps: NDArray[np.float64]


def _check_time(value: Any, name: str) -> float:
    return check_real(value, name, state_bounds=True)


def stamps(self) -> Stamps:
    """The stamped cells and their stamps.

    Returns
    -------
    stamps : Stamps
        Named tuple ``(keys, centers, stamps)``, sorted by key. Empty when
        no update was stamped. A cell deleted from the map keeps its stamp
        until the next :meth:`decay` drops it.

    Examples
    --------
    >>> from occgp import OccupancyOctree
    >>> m = OccupancyOctree(0.1).insert_scan([[0.35, 0.05, 0.05]], [0.05, 0.05, 0.05],
    ...                                      stamp=2.0)
    >>> s = m.stamps()
    >>> len(s.keys), s.stamps.tolist()
    (4, [2.0, 2.0, 2.0, 2.0])
    """
    packed, stamps = self._stamp_table()
    order = np.argsort(packed)
    keys = unpack_keys(packed[order])
    centers = self.key_to_coord(keys) if len(keys) else np.empty((0, 3))
    return Stamps(keys, centers, stamps[order])


def stamp_at(self, points: ArrayLike) -> NDArray[np.float64]:
    """The stamp of the finest cell holding each point.

    Parameters
    ----------
    points : array-like of shape (n_points, 3)
        Query points, metres, inside the key range.

    Returns
    -------
    stamps : ndarray of shape (n_points,)
        The cell's stamp, NaN where the cell has none.

    Examples
    --------
    >>> from occgp import OccupancyOctree
    >>> m = OccupancyOctree(0.1).update_cells([[0.05, 0.05, 0.05]], 1.0, stamp=5.0)
    >>> m.stamp_at([[0.05, 0.05, 0.05], [1.0, 1.0, 1.0]]).tolist()
    [5.0, nan]
    """
    query = pack_keys(self.coord_to_key(points))
    packed, stamps = self._stamp_table()
    order = np.argsort(packed)
    packed, stamps = packed[order], stamps[order]
    at = np.minimum(np.searchsorted(packed, query), max(len(packed) - 1, 0))
    out = np.full(len(query), np.nan)
    if len(packed):
        hit = packed[at] == query
        out[hit] = stamps[at[hit]]
    return out


def clear_stamps(self):
    """Forget every stamp (the cells keep their log-odds).

    Returns
    -------
    self
    """
    self._clear_stamps()
    self._half_life_at = math.nan
    return self


def decay(self, now: float, max_age: float | None = None, *,
          half_life: float | None = None) -> int:
    """Let cells that were not observed lately fade (dynamic scenes).

    With `max_age`, liboctomap's ``OcTreeStamped::degradeOutdatedNodes``:
    each stamped cell that is occupied and older than `max_age`
    (``now - stamp > max_age``) gets one miss (the log-odds of
    ``prob_miss``, clamped), once per call; its stamp is kept, so a cell
    left by a moving object fades by one miss per call until a ray clears
    or a hit refreshes it. Free and unknown cells are left alone.

    With `half_life`, every stamped cell's log-odds decays exponentially
    towards 0 (probability 0.5): it is multiplied by
    ``0.5 ** (dt / half_life)``, where `dt` is the time since the cell's
    stamp or since the previous half-life call, whichever is later (so
    calls compose: two calls at ``t1 < t2`` decay as one call at ``t2``).

    Stamps are kept per finest cell: the cells of a pruned leaf decay
    one by one, as the expanded tree's leaves would, and the tree is
    pruned again where they stay equal. Cells never stamped never decay;
    stamps of cells no longer in the map are dropped.

    Parameters
    ----------
    now : float
        The current time, on the clock of the stamps.
    max_age : float, default=None
        Age limit (≥ 0) of :meth:`degradeOutdatedNodes`-style decay.
    half_life : float, default=None
        Half-life (> 0) of the exponential decay. Give exactly one of
        `max_age` and `half_life`.

    Returns
    -------
    n_cells : int
        How many cells were changed.

    Raises
    ------
    TypeError
        If an argument is not a real number.
    ValueError
        If `now` is not finite, `max_age` negative or not finite,
        `half_life` not positive and finite, or neither or both of them
        are given. The map is then unchanged.

    Examples
    --------
    >>> from occgp import OccupancyOctree
    >>> m = OccupancyOctree(0.1).update_cells([[0.05, 0.05, 0.05]], 0.6, stamp=0.0)
    >>> m.decay(now=10.0, max_age=5.0)
    1
    >>> round(float(m.log_odds([[0.05, 0.05, 0.05]])[0]), 3)   # 0.6 - 0.405
    0.195
    """
    now = _check_time(now, "now")
    if (max_age is None) == (half_life is None):
        raise ValueError("give exactly one of max_age and half_life")
    if max_age is not None:
        limit = check_real(max_age, "max_age", low=0.0, low_open=False, state_bounds=True)
    else:
        life = check_real(half_life, "half_life", low=0.0, state_bounds=True)
    packed, stamps = self._stamp_table()
    if max_age is not None:
        old = now - stamps > limit
    else:
        since = np.fmax(stamps, self._half_life_at)
        old = now - since > 0
    packed, stamps = packed[old], stamps[old]
    if len(packed) == 0:
        if half_life is not None:
            self._half_life_at = now
        return 0
    order = np.argsort(packed)
    packed = packed[order]
    centers = self.key_to_coord(unpack_keys(packed))
    occupied, unknown = self.is_occupied(centers, return_unknown=True)
    if unknown.any():       # deleted cells: their stamps go
        self._set_stamps(np.ascontiguousarray(packed[unknown]),
                         np.full(int(unknown.sum()), np.nan))
    if max_age is not None:
        take = occupied & ~unknown
        if take.any():
            self.update_cells(centers[take], occupied=False)
        return int(take.sum())
    take = ~unknown
    since = np.fmax(stamps[order], self._half_life_at)[take]
    values = self.log_odds(centers[take]) * 0.5 ** ((now - since) / life)
    if take.any():
        self.set_cells(centers[take], values)
    self._half_life_at = now
    return int(take.sum())


def stamped(self, stamp: Any):
    """A context that stamps the updates made in it with `stamp` (None: none)."""
    return _Stamping(self, None if stamp is None else _check_time(stamp, "stamp"))


class _Stamping:
    """Turns stamping on around one update (see :func:`stamped`)."""

    def __init__(self, tree: Any, stamp: float | None) -> None:
        self.tree, self.stamp = tree, stamp

    def __enter__(self) -> None:
        if self.stamp is not None:
            self.tree._set_stamping(True, self.stamp)

    def __exit__(self, *exc: Any) -> None:
        if self.stamp is not None:
            self.tree._set_stamping(False, 0.0)


def stamps_block(tree: Any) -> bytes:
    """The stamps block written after a map's OctoMap data (empty without stamps)."""
    packed, stamps = tree._stamp_table()
    if len(packed) == 0 and math.isnan(tree._half_life_at):
        return b""
    order = np.argsort(packed)
    return (STAMPS_MAGIC + _COUNT.pack(len(packed), tree._half_life_at)
            + packed[order].astype("<u8").tobytes() + stamps[order].astype("<f8").tobytes())


def read_stamps_block(tree: Any, data: bytes, offset: int, source: str) -> None:
    """Give `tree` the stamps of the block at `offset` of `data`, if one is there
    (other trailing bytes are ignored, as liboctomap ignores them)."""
    if not data.startswith(STAMPS_MAGIC, offset):
        return
    at = offset + len(STAMPS_MAGIC)
    if len(data) < at + _COUNT.size:
        raise ValueError(f"{source}: truncated stamps block")
    n, half_life_at = _COUNT.unpack_from(data, at)
    at += _COUNT.size
    if len(data) != at + 16 * n:
        raise ValueError(f"{source}: corrupt stamps block: {n} stamps announced, "
                         f"{len(data) - at} bytes follow (expected {16 * n})")
    packed = np.frombuffer(data, dtype="<u8", count=n, offset=at).astype(np.uint64)
    stamps = np.frombuffer(data, dtype="<f8", count=n, offset=at + 8 * n).astype(np.float64)
    if (packed >> np.uint64(48)).any() or not np.isfinite(stamps).all():
        raise ValueError(f"{source}: corrupt stamps block: a key out of range or a "
                         f"non-finite stamp")
    if not (math.isnan(half_life_at) or math.isfinite(half_life_at)):
        raise ValueError(f"{source}: corrupt stamps block: non-finite decay time")
    tree._set_stamps(np.ascontiguousarray(packed), np.ascontiguousarray(stamps))
    tree._half_life_at = half_life_at
