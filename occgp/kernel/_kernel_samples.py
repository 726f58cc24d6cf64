"""Samples, sizes and limits of the kernel maps' updates.

Key packing and cube sums for voxel down-sampling, free samples made in chunks,
and the up-front counts that guard an update's work (cells in the samples'
support boxes, neighbour-search pairs, kernel weights) before anything changes.
"""

from __future__ import annotations

from numbers import Integral

import numpy as np
from numpy.typing import NDArray

from .._kernel import _support_cells
from .._validation import check_real

#: Half the number of keys per axis (liboctomap's tree_max_val).
MAX_VAL = 32768

#: Most free samples one update draws along its beams before down-sampling; they are
#: made and reduced in chunks of FREE_CHUNK, so memory stays bounded.
MAX_FREE_SAMPLES = 1 << 26
FREE_CHUNK = 1 << 22
#: Default of `max_cells_per_update`: about 3 s of accumulation on one thread.
MAX_CELLS_PER_UPDATE = 1 << 30


def packed_keys(points: NDArray[np.float64], size: float, name: str = "size",
                low: NDArray[np.float64] | None = None) -> NDArray[np.int64]:
    """One int64 per cube of edge `size` (21 bits per axis, z major), counted from the
    cube of `low` (default: the points' lowest corner)."""
    q = np.floor(points / size)
    q0 = q.min(axis=0) if low is None else np.floor(low / size)
    span = q.max(axis=0) - q0
    if not np.all(span < 1 << 21):
        raise ValueError(f"{name}={size:g} is too small for this scan: the points span "
                         f"{float(span.max()):.3g} cubes of {size:g} m on an axis, more "
                         f"than 2^21")
    k = np.maximum(q - q0, 0).astype(np.int64)     # (rounding below `low`: its cube)
    return (k[:, 2] << 42) | (k[:, 1] << 21) | k[:, 0]


def cube_sums(points, size, name="size", low=None):
    """(cube keys, coordinate sums (n, 3), counts) of the points in each cube."""
    keys, inverse, counts = np.unique(packed_keys(points, size, name, low),
                                      return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    sums = np.zeros((len(counts), 3))
    for a in range(3):
        sums[:, a] = np.bincount(inverse, weights=points[:, a], minlength=len(counts))
    return keys, sums, counts


def merge_cube_sums(parts):
    """The (keys, sums, counts) of the union of several (keys, sums, counts)."""
    if len(parts) == 1:
        return parts[0]
    keys = np.concatenate([p[0] for p in parts])
    sums = np.concatenate([p[1] for p in parts])
    counts = np.concatenate([p[2] for p in parts])
    ukeys, inverse = np.unique(keys, return_inverse=True)
    inverse = inverse.ravel()
    out = np.zeros((len(ukeys), 3))
    for a in range(3):
        out[:, a] = np.bincount(inverse, weights=sums[:, a], minlength=len(ukeys))
    return ukeys, out, np.bincount(inverse, weights=counts, minlength=len(ukeys))


def beam_chunks(counts):
    """(beam index, index along the beam from 0) of every sample of beams holding
    `counts` samples each, in chunks of at most FREE_CHUNK samples."""
    ends = np.cumsum(counts)
    starts = ends - counts
    total = int(ends[-1]) if len(ends) else 0
    for a in range(0, total, FREE_CHUNK):
        idx = np.arange(a, min(a + FREE_CHUNK, total), dtype=np.int64)
        beam = np.searchsorted(ends, idx, side="right")
        yield beam, idx - starts[beam]


def check_free_count(total, name, value):
    if total > MAX_FREE_SAMPLES:
        raise ValueError(
            f"{name}={value:g} would make {float(total):.3g} free samples along this "
            f"scan's beams, more than the {MAX_FREE_SAMPLES} an update takes; use a "
            f"larger {name} (or split the scan); the map is unchanged")


def voxel_first(points: NDArray[np.float64], size: float) -> NDArray[np.int64]:
    """Indices of the first point (in order) in each cube of edge `size` that holds any,
    in increasing order."""
    if len(points) == 0:
        return np.empty(0, dtype=np.int64)
    _, first = np.unique(packed_keys(points, size), return_index=True)
    return np.sort(first)


def check_max_range(value) -> float | None:
    """A kernel map's `max_range`: None (no limit) or a positive finite float."""
    return None if value is None else check_real(value, "max_range", low=0.0)


#: How a kernel map meets a beam longer than its `max_range` (see `far_beams`).
FAR_BEAMS = ("cut", "drop")


def split_range(points: NDArray[np.float64], origin: NDArray[np.float64],
                max_range: float | None, far_beams: str = "cut"
                ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(the end points at most `max_range` from `origin`, the ends of the longer beams
    cut at `max_range`): every point and no cut end when `max_range` is None; no cut
    end with ``far_beams="drop"`` (la3dm's rule: such beams are dropped whole)."""
    if max_range is None:
        return points, points[:0]
    length = np.linalg.norm(points - origin, axis=1)
    near = length <= max_range
    if far_beams == "drop":
        return points[near], points[:0]
    far = ~near
    cut = origin + (points[far] - origin) * (max_range / length[far])[:, None]
    return points[near], cut


def check_max_cells(value) -> int:
    if isinstance(value, bool) or not isinstance(value, Integral):
        raise TypeError(f"max_cells_per_update must be a positive int, got "
                        f"{type(value).__name__}")
    if value < 1:
        raise ValueError(f"max_cells_per_update must be a positive int, got {value!r}")
    return int(value)


def support_cells(samples, extent, res) -> float:
    """Cells in the support boxes of the samples (as the accumulation visits them:
    cell centers within `extent` of each sample, keys clamped to the key range),
    counted by the compiled core in one pass."""
    return float(_support_cells(np.ascontiguousarray(samples, dtype=np.float64),
                                np.ascontiguousarray(extent, dtype=np.float64),
                                float(res)))


def search_cell(xs, radius) -> float:
    """Edge of the cubes AKIMap's neighbour search buckets the samples in: the largest
    search radius, widened where the samples would span more than 2^20 cubes."""
    if len(xs) == 0:
        return radius
    lo, hi = xs.min(axis=0), xs.max(axis=0)
    span = float(np.max(hi - lo))
    largest = float(max(np.max(np.abs(lo)), np.max(np.abs(hi))))
    return max(radius, span / (1 << 20), largest / (1 << 52))


def candidate_pairs(xs, cell) -> float:
    """(sample, candidate) pairs AKIMap's neighbour search examines: for each sample,
    the samples in the 3 x 3 x 3 cubes of edge `cell` around its own."""
    if len(xs) == 0:
        return 0.0
    ck = np.floor(xs / cell).astype(np.int64)
    ck -= ck.min(axis=0) - 1                      # a cube of padding each side
    d0, d1 = int(ck[:, 0].max()) + 2, int(ck[:, 1].max()) + 2
    flat = (ck[:, 2] * d1 + ck[:, 1]) * d0 + ck[:, 0]
    d2 = int(ck[:, 2].max()) + 2
    if d0 * d1 * d2 <= 8 * len(xs) + (1 << 16):
        # few cubes: count them densely and sum each one's 3 x 3 x 3 neighbourhood by
        # shifted slices (the padding keeps every neighbour inside), in integers
        grid = np.bincount(flat, minlength=d0 * d1 * d2).reshape(d2, d1, d0)
        box = grid[:, :, :-2] + grid[:, :, 1:-1] + grid[:, :, 2:]
        box = box[:, :-2] + box[:, 1:-1] + box[:, 2:]
        box = box[:-2] + box[1:-1] + box[2:]
        return float(np.sum(grid[1:-1, 1:-1, 1:-1] * box))
    keys, counts = np.unique(flat, return_counts=True)
    near = np.zeros(len(keys))
    for dz in (-1, 0, 1):
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                q = keys + (dz * d1 + dy) * d0 + dx
                idx = np.minimum(np.searchsorted(keys, q), len(keys) - 1)
                hit = keys[idx] == q
                near[hit] += counts[idx[hit]]
    return float(np.dot(counts, near))


#: Largest kernel weight times sf2 an update may carry (and 1 / MAX_WEIGHT the
#: smallest): the cells keep float32 evidence (3.4e38 at most, 1.2e-38 at least in
#: full precision), so this leaves room for 3e8 contributions to one cell.
MAX_WEIGHT = 1e30
