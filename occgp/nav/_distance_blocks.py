"""The block store of :class:`~occgp.nav.DistanceMap`: cubes of cells (state, distance,
nearest cell) allocated on demand in growing arrays, found by packed block coordinates."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["BlockStore", "FREE", "OCCUPIED", "UNKNOWN", "OUTSIDE", "KEY_LO", "KEY_HI", "NONE",
           "cube_offsets", "pack", "unpack"]

#: Cell states kept per block.
FREE, OCCUPIED, UNKNOWN, OUTSIDE = 0, 1, 2, 3
#: The key range, as cell indices (key - 32768).
KEY_LO, KEY_HI = -32768, 32768
#: Nearest-cell index of a cell without one (none within reach).
NONE = np.iinfo(np.int32).min


class BlockStore:
    """Allocation and lookup of a :class:`~occgp.nav.DistanceMap`'s blocks (a mixin; the
    map's ``_setup`` sets the block size and the domain it reads)."""

    # set by the map's ``_setup``: the block side in cells, the domain's cell bounds
    # [lo, hi) per axis, the slot of each allocated block and the released slots
    _B: int
    _domain: tuple[np.ndarray, np.ndarray]
    _slot: dict[tuple[int, ...], int]
    _free: list[int]

    def _alloc_arrays(self, capacity: int) -> None:
        B = self._B
        self._state = np.full((capacity, B, B, B), UNKNOWN, dtype=np.uint8)
        self._dist = np.full((capacity, B, B, B), np.nan)
        self._near = np.full((capacity, B, B, B, 3), NONE, dtype=np.int32)
        self._pad = np.zeros(capacity, dtype=np.int64)
        self._coords = np.zeros((capacity, 3), dtype=np.int64)
        self._lookup_keys = np.empty(0, dtype=np.int64)
        self._lookup_slots = np.empty(0, dtype=np.int64)

    def _grow(self, need: int) -> None:
        cap = len(self._state)
        if need <= cap:
            return
        new = max(need, 2 * cap, 8)
        B = self._B
        state = np.full((new, B, B, B), UNKNOWN, dtype=np.uint8)
        dist = np.full((new, B, B, B), np.nan)
        near = np.full((new, B, B, B, 3), NONE, dtype=np.int32)
        pad = np.zeros(new, dtype=np.int64)
        coords = np.zeros((new, 3), dtype=np.int64)
        state[:cap], dist[:cap], near[:cap] = self._state, self._dist, self._near
        pad[:cap], coords[:cap] = self._pad, self._coords
        self._state, self._dist, self._near, self._pad, self._coords = \
            state, dist, near, pad, coords

    def _allocate(self, blocks: np.ndarray) -> np.ndarray:
        """Slots for the block coordinates `blocks` (n, 3), new ones allocated with
        every cell unknown (outside the domain: outside)."""
        new = [tuple(int(v) for v in b) for b in blocks if tuple(int(v) for v in b)
               not in self._slot]
        reuse = min(len(new), len(self._free))
        fresh = len(new) - reuse
        first = len(self._slot) + len(self._free)
        self._grow(first + fresh)
        slots = [self._free.pop() for _ in range(reuse)] + list(range(first, first + fresh))
        B = self._B
        dlo, dhi = self._domain
        ar = np.arange(B)
        for b, s in zip(new, slots):
            self._slot[b] = s
            lo = np.array(b, dtype=np.int64) * B
            self._coords[s] = b
            self._state[s] = UNKNOWN
            self._dist[s] = np.nan
            self._near[s] = NONE
            if (lo < dlo).any() or (lo + B > dhi).any():
                ok = [((lo[a] + ar) >= dlo[a]) & ((lo[a] + ar) < dhi[a]) for a in range(3)]
                mask = ok[0][:, None, None] & ok[1][None, :, None] & ok[2][None, None, :]
                self._state[s][~mask] = OUTSIDE
        self._index()
        return np.array([self._slot[tuple(int(v) for v in b)] for b in blocks],
                        dtype=np.int64)

    def _release(self, slot: int) -> None:
        b = tuple(int(v) for v in self._coords[slot])
        del self._slot[b]
        self._free.append(slot)

    def _index(self) -> None:
        """Sorted packed block coordinates, for vectorised lookups."""
        if not self._slot:
            self._lookup_keys = np.empty(0, dtype=np.int64)
            self._lookup_slots = np.empty(0, dtype=np.int64)
            return
        coords = np.array(list(self._slot.keys()), dtype=np.int64)
        keys = pack(coords)
        order = np.argsort(keys)
        self._lookup_keys = keys[order]
        self._lookup_slots = np.array(list(self._slot.values()), dtype=np.int64)[order]

    def _slots_of(self, blocks: np.ndarray) -> np.ndarray:
        """Slot of each block coordinate (n, 3), -1 where not allocated."""
        keys = pack(blocks)
        pos = np.searchsorted(self._lookup_keys, keys)
        pos = np.minimum(pos, max(len(self._lookup_keys) - 1, 0))
        if len(self._lookup_keys) == 0:
            return np.full(len(keys), -1, dtype=np.int64)
        found = self._lookup_keys[pos] == keys
        return np.where(found, self._lookup_slots[pos], -1)


def cube_offsets(n: int) -> NDArray[np.int64]:
    """The (n**3, 3) integer offsets of an n x n x n cube of cells, x slowest."""
    ar = np.arange(n)
    return np.stack(np.meshgrid(ar, ar, ar, indexing="ij"), -1).reshape(-1, 3)


def pack(blocks: np.ndarray) -> NDArray[np.int64]:
    """One int64 per block coordinate (each in [-2**20, 2**20))."""
    b = blocks.astype(np.int64).reshape(-1, 3) + (1 << 20)
    return (b[:, 0] << 42) | (b[:, 1] << 21) | b[:, 2]


def unpack(keys: np.ndarray) -> NDArray[np.int64]:
    """The block coordinates (n, 3) of packed keys."""
    mask = (1 << 21) - 1
    return np.column_stack([(keys >> 42) & mask, (keys >> 21) & mask, keys & mask]) - (1 << 20)
