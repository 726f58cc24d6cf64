"""A Euclidean distance field stored in blocks, updated from a map's changed cells.

The map's fit, states, computation, updates and queries; the block store it
keeps its cells in is ``_distance_blocks.py``.
"""

from __future__ import annotations

import time
from itertools import product
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from ._distance import (
    DistanceField, MAX_DISTANCE_CELLS, UNKNOWN_CHOICES, cells_of, check_distance_map,
    closest_and_gradient, finish, grid_of_box, signed_transform,
)
from ._distance_blocks import (FREE as _FREE, KEY_HI as _KEY_HI, KEY_LO as _KEY_LO,
                              NONE as _NONE, OCCUPIED as _OCCUPIED, OUTSIDE as _OUTSIDE,
                              UNKNOWN as _UNKNOWN, BlockStore, cube_offsets as _cube_offsets,
                              pack as _pack, unpack as _unpack)
from .._validation import (as_points, check_bool, check_choice, check_int, check_real,
                          show_number)

if TYPE_CHECKING:  # annotations only: the maps sit above the navigation helpers
    from ..octree._logodds import LogOddsMap

__all__ = ["DistanceMap"]

#: Bytes stored per cell: the state (uint8), the distance (float64) and the
#: nearest cell's index (3 x int32).
CELL_BYTES = 1 + 8 + 12


class DistanceMap(BlockStore):
    """A Euclidean distance field stored in blocks, updated incrementally.

    The field has the map's cells (edge ``tree.resolution``, on the map's key
    grid) and is stored in cubic blocks of ``block_size**3`` cells, allocated
    only where the map knows at least one cell (inside `bbox` when given):
    memory grows with the known space, not with a bounding box. Each cell holds
    the distance from its center to the nearest obstacle cell's center, as
    :meth:`occgp.OccupancyOctree.distance_field` defines it (obstacles: the
    occupied cells, and the unknown ones when ``unknown="occupied"``; with
    `signed`, obstacle cells hold minus the distance to the nearest
    non-obstacle cell), and the index of that nearest cell, from which
    :meth:`query` gives the closest cell's center and the gradient.

    Each block is computed on a window of cells around it: the block padded by
    ``p`` cells, starting at ``p = block_size // 2`` and doubling until every
    distance found in the block is at most ``p`` cells (then no cell outside
    the window can be nearer) or ``p`` reaches ``ceil(max_distance /
    resolution)`` (truncation: longer distances become `max_distance`) or the
    window covers every known cell. The distances equal those of a dense
    computation over the same space on every cell (bit for bit: both take
    ``sqrt`` of the same integer squared offset, times the resolution).

    :meth:`update` reads the map's recorded changes (``tree.changed_cells()``,
    with ``tree.track_changes = True``) and recomputes only the blocks whose
    window holds a cell whose obstacle state changed, plus the blocks whose
    window touched the edge of the known space when that edge moved. The
    result equals a new :meth:`fit` on the updated map exactly: same blocks,
    bit-identical distances and the same nearest cells (every block is always
    computed by the same steps on the same window).

    An empty map (or one that knows no cell inside `bbox`) is a valid start:
    the field then has no block, :meth:`query` answers NaN (unknown)
    everywhere and :meth:`dense` an empty grid; :meth:`update` allocates the
    blocks as the map learns cells, so "fit the empty map, update after each
    scan" gives exactly the field of a fit after the scans. Known space
    without any obstacle (only free cells, ``unknown="free"``) holds inf, or
    `max_distance` when truncated.

    Parameters
    ----------
    max_distance : float, default=None
        Truncation distance in metres (voxblox's truncation): distances beyond
        it are stored as `max_distance` (``-max_distance`` inside obstacles)
        with no nearest cell, and a block's window is at most
        ``ceil(max_distance / resolution)`` cells wide on each side. None:
        exact distances everywhere (blocks far from every obstacle then need
        windows as large as the known space, and are recomputed at every
        update that changes an obstacle).
    signed : bool, default=False
        Negative distances inside obstacles (minus the distance from the cell's
        center to the nearest non-obstacle cell's center), as voxblox's and
        nvblox's ESDF: a boundary obstacle cell holds ``-resolution`` and its
        free neighbour ``+resolution``; no cell holds 0.
    unknown : {"occupied", "free"}, default="occupied"
        How cells the map knows nothing about count: as obstacles or as free
        space.
    bbox : array-like of shape (2, 3), default=None
        Restrict the field to the map's cells in this box (snapped outwards
        to the cells, as in :meth:`~occgp.OccupancyOctree.distance_field`);
        obstacles outside it are not seen. None: the whole key range.
    block_size : int, default=16
        Edge of the blocks in cells, a power of 2 in [4, 128]. Each block
        holds ``21 * block_size**3`` bytes (86016 for 16: a uint8 state, a
        float64 distance and three int32 for the nearest cell per cell).

    Attributes
    ----------
    resolution_ : float
        Edge of the cells (the map's resolution).
    num_blocks_ : int
        Blocks allocated.
    last_update_ : dict
        Statistics of the last :meth:`fit` or :meth:`update`: ``changed_cells``
        (cells read), ``obstacle_changes`` (cells whose obstacle state
        flipped), ``blocks``, ``recomputed`` (blocks computed), ``seconds``.

    See Also
    --------
    occgp.OccupancyOctree.distance_field : The dense field over a box.

    Examples
    --------
    >>> from occgp import DistanceMap, OccupancyOctree
    >>> tree = OccupancyOctree(1.0).set_cells([[0.5, 0.5, 0.5], [5.5, 0.5, 0.5]], [2.0, -2.0])
    >>> tree.track_changes = True
    >>> field = DistanceMap(max_distance=3.0, unknown="free").fit(tree)
    >>> field.query([[2.5, 0.5, 0.5], [5.5, 0.5, 0.5]]).tolist()
    [2.0, 3.0]
    >>> tree = tree.set_cells([[6.5, 0.5, 0.5]], [2.0])       # a new obstacle
    >>> field.update(tree).query([[5.5, 0.5, 0.5]]).tolist()
    [1.0]
    >>> field.last_update_["recomputed"], field.num_blocks_
    (1, 1)
    >>> tree = tree.reset_changes()      # the caller resets the record
    """

    def __init__(self, max_distance: float | None = None, *, signed: bool = False,
                 unknown: str = "occupied", bbox: ArrayLike | None = None,
                 block_size: int = 16) -> None:
        self.max_distance = max_distance
        self.signed = signed
        self.unknown = unknown
        self.bbox = bbox
        self.block_size = block_size

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(max_distance={self.max_distance!r}, "
                f"signed={self.signed!r}, unknown={self.unknown!r}, "
                f"block_size={self.block_size!r})")

    # ------------------------------------------------------------------ fit
    def fit(self, tree: LogOddsMap) -> "DistanceMap":
        """Compute the whole field of `tree` (every block from scratch).

        Parameters
        ----------
        tree : OccupancyOctree or GridMap
            The map.

        Returns
        -------
        self : DistanceMap
            The computed field.

        Raises
        ------
        TypeError
            If `tree` is not a log-odds map, or a parameter has the wrong type.
        ValueError
            If `max_distance` is not positive and finite, `unknown` not one of
            the choices, `bbox` not a (2, 3) box with min < max, or
            `block_size` not a power of 2 in [4, 128].
        """
        start = time.perf_counter()
        check_distance_map(tree)
        self._setup(tree.resolution)
        table = getattr(tree, "leaves", None) or getattr(tree, "cells")
        centers, sizes = table()[:2]
        occupied = tree.is_occupied(centers) if len(centers) else np.empty(0, bool)
        side = np.rint(np.asarray(sizes) / self._res).astype(np.int64)
        low = np.rint(centers / self._res - side[:, None] / 2.0).astype(np.int64)
        dlo, dhi = self._domain
        inside = ((low < dhi) & (low + side[:, None] > dlo)).all(axis=1)
        low, side, occupied = low[inside], side[inside], occupied[inside]
        self._paint_leaves(low, side, occupied)
        self._region = self._known_region()
        slots = np.array(sorted(self._slot.values()), dtype=np.int64)
        for s in slots:
            self._compute(int(s))
        self.last_update_ = {"changed_cells": int(np.sum(side**3)), "obstacle_changes": 0,
                             "blocks": len(self._slot), "recomputed": len(slots),
                             "seconds": time.perf_counter() - start}
        return self

    def _setup(self, resolution: float) -> None:
        """Validate the parameters and clear the blocks."""
        self._max_d = None if self.max_distance is None else check_real(
            self.max_distance, "max_distance", low=0.0)
        self._signed = check_bool(self.signed, "signed")
        self._unknown_occ = check_choice(self.unknown, "unknown",
                                         UNKNOWN_CHOICES) == "occupied"
        b = check_int(self.block_size, "block_size", low=1)
        if b < 4 or b > 128 or b & (b - 1):
            raise ValueError(f"block_size must be a power of 2 in [4, 128], "
                             f"got {show_number(b)}")
        self._B, self._shift = b, b.bit_length() - 1
        self._res = float(resolution)
        if self.bbox is None:
            dlo, dhi = np.full(3, _KEY_LO), np.full(3, _KEY_HI)
        else:
            shape, first = grid_of_box(self.bbox, self._res, np.inf)
            dlo = np.clip(first.astype(np.int64), _KEY_LO, _KEY_HI)
            dhi = np.clip(first.astype(np.int64) + np.array(shape), _KEY_LO, _KEY_HI)
        self._domain = (dlo.astype(np.int64), dhi.astype(np.int64))
        self._pcap = None if self._max_d is None else int(np.ceil(self._max_d / self._res))
        self._slot: dict[tuple[int, ...], int] = {}
        self._new_slots = np.empty(0, dtype=np.int64)
        self._free: list[int] = []
        self._alloc_arrays(0)
        self.resolution_ = self._res

    # ------------------------------------------------------------------ states
    def _paint_leaves(self, low: np.ndarray, side: np.ndarray, occupied: np.ndarray) -> None:
        """Allocate the blocks the leaves touch inside the domain and write their states."""
        B, sh = self._B, self._shift
        dlo, dhi = self._domain
        small = side <= B
        blocks = [low[small] >> sh]
        big_levels = np.unique(side[~small])
        for s in big_levels:
            rows = np.flatnonzero(side == s)
            n = int(s) // B
            offs = _cube_offsets(n)
            blk = ((low[rows] >> sh)[:, None, :] + offs[None]).reshape(-1, 3)
            blocks.append(blk)
        allb = _unpack(np.unique(_pack(np.concatenate(blocks))))
        keep = ((allb * B < dhi) & (allb * B + B > dlo)).all(axis=1)
        self._allocate(allb[keep])
        flat = self._state.reshape(len(self._state), B**3)   # no blocks: shape (0, B**3)
        value = occupied.astype(np.uint8)
        for s in np.unique(side[small]):
            rows = np.flatnonzero(side == s)
            s = int(s)
            offs = _cube_offsets(s)
            slots = self._slots_of(low[rows] >> sh)
            ok = slots >= 0
            rows, slots = rows[ok], slots[ok]
            loc = (low[rows] & (B - 1))[:, None, :] + offs[None]
            pos = (loc[..., 0] * B + loc[..., 1]) * B + loc[..., 2]
            flat[slots[:, None], pos] = value[rows][:, None]
        for s in big_levels:
            rows = np.flatnonzero(side == s)
            n = int(s) // B
            offs = _cube_offsets(n)
            blk = ((low[rows] >> sh)[:, None, :] + offs[None]).reshape(-1, 3)
            slots = self._slots_of(blk)
            ok = slots >= 0
            flat[slots[ok]] = np.repeat(value[rows], n**3)[ok][:, None]
        # cells outside the domain in blocks that straddle its edge
        for b, s in self._slot.items():
            lo = np.array(b) * B
            if (lo < dlo).any() or (lo + B > dhi).any():
                ar = np.arange(B)
                ok3 = [((lo[a] + ar) >= dlo[a]) & ((lo[a] + ar) < dhi[a]) for a in range(3)]
                mask = ok3[0][:, None, None] & ok3[1][None, :, None] & ok3[2][None, None, :]
                self._state[s][~mask] = _OUTSIDE
        for b, s in list(self._slot.items()):
            if not (self._state[s] <= _OCCUPIED).any():
                self._release(s)
        self._index()

    def _known_region(self):
        """(lo, hi) cells: the box of the allocated blocks grown by one cell, inside the
        domain (no window needs to reach beyond it, see the class notes)."""
        dlo, dhi = self._domain
        if not self._slot:
            return dlo.copy(), dlo.copy()
        coords = np.array(list(self._slot.keys()), dtype=np.int64)
        lo = coords.min(axis=0) * self._B - 1
        hi = coords.max(axis=0) * self._B + self._B + 1
        return np.maximum(lo, dlo), np.minimum(hi, dhi)

    def _window(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """The states of the cells [lo, hi) (unknown where no block is allocated)."""
        B, sh = self._B, self._shift
        out = np.full(tuple(hi - lo), _UNKNOWN, dtype=np.uint8)
        blo, bhi = lo >> sh, (hi - 1) >> sh
        for b in product(*(range(int(blo[a]), int(bhi[a]) + 1) for a in range(3))):
            s = self._slot.get(b)
            if s is None:
                continue
            c0 = np.array(b, dtype=np.int64) * B
            a0, a1 = np.maximum(c0, lo), np.minimum(c0 + B, hi)
            out[a0[0] - lo[0]:a1[0] - lo[0], a0[1] - lo[1]:a1[1] - lo[1],
                a0[2] - lo[2]:a1[2] - lo[2]] = self._state[s][
                a0[0] - c0[0]:a1[0] - c0[0], a0[1] - c0[1]:a1[1] - c0[1],
                a0[2] - c0[2]:a1[2] - c0[2]]
        return out

    def _obstacle(self, states: np.ndarray) -> np.ndarray:
        return (states == _OCCUPIED) | ((states == _UNKNOWN) if self._unknown_occ else False)

    # ------------------------------------------------------------------ compute
    def _compute(self, slot: int) -> None:
        """Compute one block on windows of growing padding (see the class notes)."""
        B = self._B
        lo = self._coords[slot] * B
        hi = lo + B
        clo, chi = self._region
        rlo, rhi = np.maximum(lo, clo), np.minimum(hi, chi)    # the block's cells in the domain
        p = B // 2 if self._pcap is None else min(B // 2, self._pcap)
        while True:
            wlo, whi = np.maximum(lo - p, clo), np.minimum(hi + p, chi)
            covers = bool((wlo == clo).all() and (whi == chi).all())
            capped = self._pcap is not None and p >= self._pcap
            obstacle = self._obstacle(self._window(wlo, whi))
            region = tuple(slice(int(rlo[a] - wlo[a]), int(rhi[a] - wlo[a])) for a in range(3))
            d2, near = signed_transform(obstacle, self._signed, region)
            certified = bool((d2 >= 0).all() and (d2 <= p * p).all())
            if certified or capped or covers:
                break
            p = 2 * p if self._pcap is None else min(2 * p, self._pcap)
        inside = obstacle[region]
        dist, has = finish(d2, inside, self._signed, self._res, self._max_d)
        glob = np.moveaxis(near, 0, -1).astype(np.int64) + wlo
        glob[~has] = _NONE
        part = tuple(slice(int(rlo[a] - lo[a]), int(rhi[a] - lo[a])) for a in range(3))
        self._dist[slot] = np.nan
        self._near[slot] = _NONE
        self._dist[slot][part] = dist
        self._near[slot][part] = glob
        self._pad[slot] = p if (certified or capped) else -1

    # ------------------------------------------------------------------ update
    def update(self, tree: LogOddsMap, points: ArrayLike | None = None,
               depth: int = 0) -> "DistanceMap":
        """Bring the field up to date with the cells of `tree` that changed.

        Reads ``tree.changed_cells()`` (the map must record its changes:
        ``tree.track_changes = True`` before the updates since :meth:`fit`), plus
        the cells of `points`; re-reads their states; recomputes the blocks
        whose window holds a cell whose obstacle state changed (and new blocks;
        blocks left without a known cell are freed). The record is left as it
        is: call ``tree.reset_changes()`` once every field that follows the map
        is updated (cells recorded twice cost time, never exactness).

        Parameters
        ----------
        tree : OccupancyOctree or GridMap
            The map the field was fitted on, after its updates.
        points : array-like of shape (n_points, 3), default=None
            More changed cells, those the map does not record: the points given
            to ``tree.delete_cells`` (deletions are not recorded), or every
            change of a :class:`~occgp.GridMap` (which records none).
        depth : int, default=0
            Tree depth of the nodes `points` name, as in ``delete_cells``: 0 or
            16 the finest cells, ``d`` every cell of the depth-``d`` node (then
            only cells of allocated blocks are re-read: use it for deletions).

        Returns
        -------
        self : DistanceMap
            The updated field.

        Raises
        ------
        TypeError
            If `tree` is not a log-odds map, or `depth` not an int.
        ValueError
            If the field was not fitted, `tree`'s resolution differs, `tree`
            records no changes and no `points` are given, `points` is not of
            shape (n_points, 3) or not finite, or `depth` lies outside [0, 16].
        """
        start = time.perf_counter()
        self._check_fitted()
        check_distance_map(tree)
        if tree.resolution != self._res:
            raise ValueError(f"tree must have the field's resolution {self._res!r}, got "
                             f"{tree.resolution!r}")
        depth = check_int(depth, "depth", low=0, high=16)
        tracking = bool(getattr(tree, "track_changes", False))
        if not tracking and points is None:
            raise ValueError("tree records no changes (set tree.track_changes = True before "
                             "updating it) and no points were given")
        cells = [np.empty((0, 3), dtype=np.int64)]
        if tracking:
            record = getattr(tree, "changed_cells")()
            cells.append(record.keys.astype(np.int64) + _KEY_LO)
        boxes = None
        if points is not None:
            pts = as_points(points, "points")
            c = cells_of(pts, self._res)
            if depth in (0, 16):
                cells.append(c)
            else:
                s = 16 - depth
                blo = ((c - _KEY_LO) >> s << s) + _KEY_LO
                boxes = (blo, blo + (1 << s))
        read = np.unique(np.concatenate(cells), axis=0)
        dlo, dhi = self._domain
        read = read[((read >= dlo) & (read < dhi)).all(axis=1)]
        old_region = self._region
        flipped = self._reread_cells(tree, read)
        if boxes is not None:
            flipped = np.concatenate([flipped, self._reread_boxes(tree, *boxes)])
        new_slots = self._new_slots
        self._region = self._known_region()
        todo = self._affected(flipped, old_region)
        live = np.array(list(self._slot.values()), dtype=np.int64)
        todo = np.intersect1d(np.union1d(todo, new_slots), live).astype(np.int64)
        for s in todo:
            self._compute(int(s))
        self.last_update_ = {"changed_cells": len(read), "obstacle_changes": len(flipped),
                             "blocks": len(self._slot), "recomputed": len(todo),
                             "seconds": time.perf_counter() - start}
        return self

    def _write_states(self, cells: np.ndarray, new: np.ndarray) -> np.ndarray:
        """Write states of `cells` (in the domain); return the cells whose obstacle
        state flipped. Allocates and frees blocks as needed."""
        B, sh = self._B, self._shift
        blocks = cells >> sh
        slots = self._slots_of(blocks)
        old = np.full(len(cells), _UNKNOWN, dtype=np.uint8)
        have = slots >= 0
        loc = cells & (B - 1)
        old[have] = self._state[slots[have], loc[have, 0], loc[have, 1], loc[have, 2]]
        need = ~have & (new <= _OCCUPIED)
        if need.any():
            nb = np.unique(blocks[need], axis=0)
            created = self._allocate(nb)
            self._new_slots = np.union1d(self._new_slots, created)
            slots = self._slots_of(blocks)
        ok = slots >= 0
        self._state[slots[ok], loc[ok, 0], loc[ok, 1], loc[ok, 2]] = new[ok]
        touched = np.unique(slots[ok & (new == _UNKNOWN)])
        released = [int(s) for s in touched if not (self._state[s] <= _OCCUPIED).any()]
        for s in released:
            self._release(s)
        if released:
            self._index()
            self._new_slots = np.setdiff1d(self._new_slots, released)
        flip = self._obstacle(old) != self._obstacle(new)
        return cells[flip]

    def _reread_cells(self, tree: LogOddsMap, cells: np.ndarray) -> np.ndarray:
        self._new_slots = np.empty(0, dtype=np.int64)
        if len(cells) == 0:
            return np.empty((0, 3), dtype=np.int64)
        occ, unk = tree.is_occupied((cells + 0.5) * self._res, return_unknown=True)
        new = np.where(unk, _UNKNOWN, np.where(occ, _OCCUPIED, _FREE)).astype(np.uint8)
        return self._write_states(cells, new)

    def _reread_boxes(self, tree: LogOddsMap, blo: np.ndarray, bhi: np.ndarray) -> np.ndarray:
        """Re-read every cell of the allocated blocks that meet the boxes [blo, bhi)."""
        if not self._slot:
            return np.empty((0, 3), dtype=np.int64)
        B = self._B
        coords = np.array(list(self._slot.keys()), dtype=np.int64)
        lo = coords * B
        meet = np.zeros(len(coords), dtype=bool)
        for a, b in zip(blo, bhi):
            meet |= ((lo < b) & (lo + B > a)).all(axis=1)
        offs = _cube_offsets(B)
        out = [np.empty((0, 3), dtype=np.int64)]
        for c in coords[meet]:
            cells = c * B + offs
            s = self._slot.get(tuple(int(v) for v in c))
            if s is None:       # freed by an earlier block of this loop
                continue
            cells = cells[self._state[s].reshape(-1) != _OUTSIDE]
            occ, unk = tree.is_occupied((cells + 0.5) * self._res, return_unknown=True)
            new = np.where(unk, _UNKNOWN, np.where(occ, _OCCUPIED, _FREE)).astype(np.uint8)
            out.append(self._write_states(cells, new))
        return np.concatenate(out)

    def _affected(self, flipped: np.ndarray, old_region) -> np.ndarray:
        """Slots of the allocated blocks whose window holds a flipped cell, or whose
        window met the edge of the known region when it moved."""
        if not self._slot:
            return np.empty(0, dtype=np.int64)
        B, sh = self._B, self._shift
        slots = np.array(list(self._slot.values()), dtype=np.int64)
        lo = self._coords[slots] * B
        pad = self._pad[slots]
        hit = pad < 0 if len(flipped) else np.zeros(len(slots), dtype=bool)
        if len(flipped):
            # per changed block, the box of its flipped cells
            blk = flipped >> sh
            _, inv = np.unique(blk, axis=0, return_inverse=True)
            inv = inv.reshape(-1)
            n = inv.max() + 1
            flo = np.full((n, 3), np.iinfo(np.int64).max)
            fhi = np.full((n, 3), np.iinfo(np.int64).min)
            np.minimum.at(flo, inv, flipped)
            np.maximum.at(fhi, inv, flipped)
            step = max(1, 2**22 // max(n, 1))
            for i in range(0, len(slots), step):
                l, p = lo[i:i + step, None, :], pad[i:i + step, None]
                gap = np.maximum(np.maximum(l - fhi[None], flo[None] - (l + B - 1)), 0)
                hit[i:i + step] |= (gap.max(axis=2) <= p).any(axis=1)
        olo, ohi = old_region
        nlo, nhi = self._region
        if not (np.array_equal(olo, nlo) and np.array_equal(ohi, nhi)):
            ilo, ihi = np.maximum(olo, nlo), np.minimum(ohi, nhi)
            wlo, whi = lo - pad[:, None], lo + B + pad[:, None]
            hit |= (pad < 0) | ~((wlo >= ilo) & (whi <= ihi)).all(axis=1)
        return slots[hit]

    # ------------------------------------------------------------------ queries
    def _check_fitted(self) -> None:
        if not hasattr(self, "_slot"):
            raise ValueError("this DistanceMap is not fitted yet: call fit(tree) first")

    def _lookup(self, cells: np.ndarray, want_closest: bool, want_gradient: bool):
        B, sh = self._B, self._shift
        slots = self._slots_of(cells >> sh)
        loc = cells & (B - 1)
        ok = slots >= 0
        dist = np.full(len(cells), np.nan)
        near = np.full((len(cells), 3), _NONE, dtype=np.int64)
        dist[ok] = self._dist[slots[ok], loc[ok, 0], loc[ok, 1], loc[ok, 2]]
        near[ok] = self._near[slots[ok], loc[ok, 0], loc[ok, 1], loc[ok, 2]]
        if not (want_closest or want_gradient):
            return dist, []
        has = near[:, 0] != _NONE
        return dist, closest_and_gradient(cells, np.where(has[:, None], near, 0), has, dist,
                                          np.zeros(3), self._res, want_closest,
                                          want_gradient)

    def query(self, points: ArrayLike, *, return_closest: bool = False,
              return_gradient: bool = False):
        """The field at `points`, by the cell holding each point.

        Parameters
        ----------
        points : array-like of shape (n_points, 3)
            Points in metres, finite.
        return_closest : bool, default=False
            Also return the center of the cell each distance is measured to:
            the nearest obstacle cell (an obstacle cell's own center in an
            unsigned field), or in a signed field, for obstacle cells, the
            nearest non-obstacle cell.
        return_gradient : bool, default=False
            Also return the gradient of the distance: the unit vector
            ``(center - closest) / distance`` (away from the nearest obstacle;
            inside obstacles of a signed field, towards free space); zero in
            the obstacle cells of an unsigned field.

        Returns
        -------
        distances : ndarray of shape (n_points,)
            Metres; NaN outside the allocated blocks (or outside `bbox`).
        closest : ndarray of shape (n_points, 3)
            Only with `return_closest`; NaN where the distance has no nearest
            cell (NaN, inf or truncated).
        gradient : ndarray of shape (n_points, 3)
            Only with `return_gradient`; NaN where `closest` is.

        Raises
        ------
        TypeError
            If `points` does not hold numbers, or a flag is not a bool.
        ValueError
            If the field is not fitted, or `points` is not of shape (n_points, 3)
            or not finite.
        """
        self._check_fitted()
        pts = as_points(points, "points")
        want_c = check_bool(return_closest, "return_closest")
        want_g = check_bool(return_gradient, "return_gradient")
        cells = np.clip(cells_of(pts, self._res), _KEY_LO - 1, _KEY_HI)
        dist, extras = self._lookup(cells, want_c, want_g)
        return (dist, *extras) if extras else dist

    def dense(self, bbox: ArrayLike | None = None, *, return_closest: bool = False,
              return_gradient: bool = False, max_cells: int = MAX_DISTANCE_CELLS):
        """The field on a regular grid, as :meth:`~occgp.OccupancyOctree.distance_field`.

        Parameters
        ----------
        bbox : array-like of shape (2, 3), default=None
            Box of the grid (snapped outwards to the cells); None: the box of
            the allocated blocks (a grid of shape (0, 0, 0) when there are
            none).
        return_closest : bool, default=False
            Also return the closest cells' centers, shape (nx, ny, nz, 3)
            (see :meth:`query`).
        return_gradient : bool, default=False
            Also return the gradient, shape (nx, ny, nz, 3) (see :meth:`query`).
        max_cells : int, default=8388608
            The most cells the grid may have.

        Returns
        -------
        field : DistanceField
            NaN in the cells no block covers. With `return_closest` or
            `return_gradient`, a tuple ``(field, closest, gradient)`` of those
            asked for.

        Raises
        ------
        TypeError
            If a flag is not a bool, or `max_cells` not an int.
        ValueError
            If the field is not fitted, `bbox` is not a (2, 3) box with
            min < max, or the grid would have more than `max_cells` cells.
        """
        self._check_fitted()
        want_c = check_bool(return_closest, "return_closest")
        want_g = check_bool(return_gradient, "return_gradient")
        max_cells = check_int(max_cells, "max_cells", low=1)
        if bbox is None:
            if self._slot:
                coords = np.array(list(self._slot.keys()), dtype=np.int64)
                first = coords.min(axis=0) * self._B
                shape = tuple(int(v) for v in coords.max(axis=0) * self._B + self._B - first)
                dlo, dhi = self._domain
                first = np.maximum(first, dlo)
                shape = tuple(int(v) for v in np.minimum(first + shape, dhi) - first)
            else:                   # nothing known: an empty grid
                first, shape = np.zeros(3, dtype=np.int64), (0, 0, 0)
            if np.prod(np.array(shape, dtype=np.float64)) > max_cells:
                raise ValueError(f"the allocated blocks span {shape} cells, more than "
                                 f"max_cells={max_cells}; pass a smaller bbox")
        else:
            shape, first = grid_of_box(bbox, self._res, max_cells)
            first = first.astype(np.int64)
        axes = [first[a] + np.arange(n) for a, n in enumerate(shape)]
        cells = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        dist, extras = self._lookup(cells, want_c, want_g)
        field = DistanceField(dist.reshape(shape), first * self._res, self._res)
        if not extras:
            return field
        return (field, *[e.reshape(*shape, 3) for e in extras])

    @property
    def num_blocks_(self) -> int:
        """Blocks allocated."""
        self._check_fitted()
        return len(self._slot)

    def memory_usage(self) -> int:
        """Bytes held by the allocated blocks (``21 * block_size**3`` each).

        Returns
        -------
        nbytes : int
            Bytes of the arrays of the allocated blocks (the arrays are grown by
            doubling, so up to twice as much may be reserved).
        """
        self._check_fitted()
        return len(self._slot) * (CELL_BYTES * self._B**3 + 4 * 8)
