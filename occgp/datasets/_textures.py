"""Procedural textures of the stereo renderer: albedo at surface points, vectorised.

Every texture maps 2D surface coordinates ``uv`` (metres, measured from a
corner of the face they lie on) to an albedo in [0, 1]. Randomness comes from
a hash of integer lattice coordinates and a seed, never from a random stream:
the same surface point has the same albedo in every image, whichever pixels
are evaluated and in which order, so the two cameras of a stereo pair and
every frame of a sequence see one fixed texture.

Patterns with sharp edges (cell borders, mortar, paint, windows) are
box-filtered over each pixel's footprint on the surface (``footprint``, in
metres), and noise octaves finer than the footprint fade out, so that a point
sample per pixel does not alias much.

* ``"voronoi"``: cells of a jittered grid of sites (about 6 cm apart), each
  a random grey, with thin dark borders: the textured boxes.
* ``"cardboard"``: a uniform light brown-grey with a very faint
  low-frequency variation (under one grey level) and a faint tape strip:
  plain boxes, where a block matcher has almost nothing to match.
* ``"asphalt"``: fine grain (value noise, several octaves), large stains and
  white parking-lot lines.
* ``"facade"``: running-bond brick courses with mortar lines and a grid of
  dark windows (a repeated pattern).
* ``"sky"``: a constant bright grey.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.ndimage import map_coordinates
from scipy.spatial import cKDTree

__all__ = ["TEXTURES", "texture_albedo", "lattice_hash", "value_noise"]

#: Names of the procedural textures (materials) the renderer knows.
TEXTURES = ("voronoi", "cardboard", "asphalt", "facade", "sky")

_M1 = np.uint64(0x9E3779B97F4A7C15)
_M2 = np.uint64(0xC2B2AE3D27D4EB4F)
_M3 = np.uint64(0xFF51AFD7ED558CCD)
_M4 = np.uint64(0xC4CEB9FE1A85EC53)
_S33 = np.uint64(33)
_S11 = np.uint64(11)
_MASK = (1 << 64) - 1
NOISE_PERIOD = 512      # period of the value-noise lattice, cells

VORONOI_CELL = 0.06      # site spacing of the Voronoi texture, metres
VORONOI_BORDER = 0.004   # width of its dark borders, metres
BRICK = (0.24, 0.075)    # brick pitch (length, course height) with mortar, metres
MORTAR = 0.012           # mortar joint width, metres
BAY = (2.4, 3.0)         # window grid pitch (horizontal, floor height), metres
WINDOW = (1.2, 1.4, 0.9)  # window width, height, sill height above the floor, metres


def _seed_word(seed: int, salt: int) -> np.uint64:
    x = (int(seed) * 0x2545F4914F6CDD1D + int(salt) * 0x9E3779B97F4A7C15 + 0x632BE59BD9B4E019)
    x &= _MASK
    x ^= x >> 31
    return np.uint64((x * 0xBF58476D1CE4E5B9) & _MASK)


def lattice_hash(ix, iy, seed: int, salt: int = 0):
    """Uniform values in [0, 1) from integer lattice coordinates and a seed.

    A 64-bit mix (MurmurHash3's finaliser) of ``ix``, ``iy`` (int64 arrays of
    one shape) and ``(seed, salt)``; deterministic and order-independent.

    Parameters
    ----------
    ix, iy : ndarray of int64
        Lattice coordinates (broadcastable).
    seed : int
        Texture seed.
    salt : int, default=0
        Separates independent draws at the same lattice point.

    Returns
    -------
    values : ndarray of float64
        In [0, 1), of the broadcast shape.
    """
    ix = np.asarray(ix, dtype=np.int64).view(np.uint64)
    iy = np.asarray(iy, dtype=np.int64).view(np.uint64)
    with np.errstate(over="ignore"):    # multiplication modulo 2**64 is the point
        h = (ix * _M1) ^ (iy * _M2) ^ _seed_word(seed, salt)
        h ^= h >> _S33
        h *= _M3
        h ^= h >> _S33
        h *= _M4
        h ^= h >> _S33
    return (h >> _S11).astype(np.float64) * (1.0 / (1 << 53))


@lru_cache(maxsize=64)
def _noise_table(salt: int):
    """The periodic lattice of :func:`value_noise`: hashed values on a NOISE_PERIOD^2 grid."""
    i = np.arange(NOISE_PERIOD, dtype=np.int64)
    table = lattice_hash(i[:, None], i[None, :], 0, salt)
    table.flags.writeable = False
    return table


def value_noise(u, v, scale: float, seed: int, salt: int = 0):
    """Value noise in [0, 1): hashed lattice values, interpolated bilinearly.

    The lattice (spacing `scale`) holds :func:`lattice_hash` values of its
    integer coordinates, periodic over ``NOISE_PERIOD`` (512) cells; `seed`
    shifts the lattice by a hashed whole number of cells, so that faces with
    different seeds see different parts of it.

    Parameters
    ----------
    u, v : ndarray of float64
        Surface coordinates, metres.
    scale : float
        Lattice spacing, metres.
    seed : int
        Texture seed.
    salt : int, default=0
        Separates octaves (an independent lattice per salt).

    Returns
    -------
    noise : ndarray of float64
        Same shape as `u`; mean 0.5.
    """
    u = np.asarray(u, dtype=np.float64)
    shift = np.floor(lattice_hash(np.array([1, 2]), np.int64(seed), 0x5EED, salt)
                     * NOISE_PERIOD)
    coords = np.empty((2, u.size))
    np.multiply(u.ravel(), 1.0 / scale, out=coords[0])
    np.multiply(np.asarray(v, dtype=np.float64).ravel(), 1.0 / scale, out=coords[1])
    coords += shift[:, None]
    out = map_coordinates(_noise_table(salt), coords, order=1, mode="grid-wrap",
                          prefilter=False)
    return out.reshape(u.shape)


def _fbm(u, v, footprint, octaves, seed, salt):
    """Sum of zero-mean value-noise octaves ``(scale, amplitude)``, each faded out where
    the pixel footprint reaches its scale (it would alias), and evaluated only where it
    does not vanish."""
    out = np.zeros_like(u)
    for k, (scale, amp) in enumerate(octaves):
        fade = np.clip(scale / np.maximum(footprint, 1e-12) - 1.0, 0.0, 1.0)
        live = np.flatnonzero(fade)
        if not len(live):
            continue
        if len(live) < 0.8 * len(u):
            out[live] += amp * fade[live] * (
                2.0 * value_noise(u[live], v[live], scale, seed, salt + k) - 1.0)
        else:
            out += amp * fade * (2.0 * value_noise(u, v, scale, seed, salt + k) - 1.0)
    return out


def _band(x, lo, hi, footprint):
    """Share of a pixel of width `footprint` centered at `x` that lies in [lo, hi]."""
    half = 0.5 * np.maximum(footprint, 1e-12)
    return np.clip((np.minimum(x + half, hi) - np.maximum(x - half, lo)) / (2 * half), 0.0, 1.0)


def _periodic_band(x, period, lo, hi, footprint):
    """:func:`_band` of the periodic band ``[lo, hi] + k * period`` (``0 <= lo < hi <=
    period``): exact for footprints up to the gap between bands, the band's duty cycle
    beyond half a period."""
    center, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    d = np.abs(np.mod(x - center + 0.5 * period, period) - 0.5 * period)
    cover = _band(d, -half, half, footprint)
    wide = footprint > 0.5 * period
    if np.any(wide):
        cover = np.where(wide, 2 * half / period, cover)
    return cover


def _voronoi_sites(uv, cell):
    """Lattice cells (ix, iy) whose sites can be nearest to a point of `uv`: within two
    cells of the point's own (a site lies in its cell, so nearer ones are never farther)."""
    lo = np.floor(uv.min(axis=0) / cell).astype(np.int64) - 2
    hi = np.floor(uv.max(axis=0) / cell).astype(np.int64) + 3
    if np.prod((hi - lo).astype(np.float64)) <= 4 * len(uv) + 10_000:
        gx, gy = np.meshgrid(np.arange(lo[0], hi[0]), np.arange(lo[1], hi[1]), indexing="ij")
        return gx.ravel(), gy.ravel()
    own = np.unique(np.floor(uv / cell).astype(np.int64), axis=0)
    off = np.array(np.meshgrid(np.arange(-2, 3), np.arange(-2, 3))).reshape(2, -1).T
    near = np.unique((own[:, None, :] + off[None]).reshape(-1, 2), axis=0)
    return near[:, 0], near[:, 1]


def _voronoi(uv, footprint, seed, size):
    cell = VORONOI_CELL
    gx, gy = _voronoi_sites(uv, cell)
    sites = np.column_stack([(gx + lattice_hash(gx, gy, seed, 1)) * cell,
                             (gy + lattice_hash(gx, gy, seed, 2)) * cell])
    grey = 0.08 + 0.84 * lattice_hash(gx, gy, seed, 3)
    dist, idx = cKDTree(sites).query(uv, k=2)
    s1, s2 = sites[idx[:, 0]], sites[idx[:, 1]]
    gap = np.maximum(np.linalg.norm(s2 - s1, axis=1), 1e-12)
    # distance to the bisector of the two nearest sites: the cell's border
    edge = (dist[:, 1] ** 2 - dist[:, 0] ** 2) / (2.0 * gap)
    half = 0.5 * np.maximum(footprint, 1e-12)
    other = np.clip((half - edge) / (2 * half), 0.0, 0.5)     # share across the border
    albedo = (1 - other) * grey[idx[:, 0]] + other * grey[idx[:, 1]]
    border = _band(edge, -VORONOI_BORDER / 2, VORONOI_BORDER / 2, footprint)
    return albedo + (0.04 - albedo) * border


def _cardboard(uv, footprint, seed, size):
    base = 0.56 + 0.02 * (lattice_hash(np.int64(0), np.int64(0), seed, 7) - 0.5)
    # under a grey level of variation in full light (0.002 * 255 = 0.5)
    faint = _fbm(uv[:, 0], uv[:, 1], footprint, ((0.35, 0.0015), (0.15, 0.0008)), seed, 10)
    tape = _band(uv[:, 0], size[0] / 2 - 0.024, size[0] / 2 + 0.024, footprint)
    return base + faint - 0.012 * tape


def _asphalt(uv, footprint, seed, size):
    u, v = uv[:, 0], uv[:, 1]
    grain = _fbm(u, v, footprint, ((0.012, 0.07), (0.03, 0.05), (0.08, 0.035)), seed, 20)
    stains = _fbm(u, v, footprint, ((1.3, 0.045),), seed, 30)
    albedo = 0.4 + grain + stains
    # parking rows: stripes 2.5 m apart, 5 m long, between two long lines, every 18 m
    stripe = (_periodic_band(u, 2.5, 1.2, 1.3, footprint)
              * _periodic_band(v, 18.0, 6.5, 11.5, footprint))
    line = np.maximum(_periodic_band(v, 18.0, 6.4, 6.52, footprint),
                      _periodic_band(v, 18.0, 11.48, 11.6, footprint))
    paint = np.maximum(stripe, line)
    return albedo + (0.78 + 0.3 * grain - albedo) * paint


def _facade(uv, footprint, seed, size):
    u, v = uv[:, 0], uv[:, 1]
    length, course = BRICK
    row = np.floor(v / course)
    us = u + 0.5 * length * np.mod(row, 2)
    col = np.floor(us / length)
    brick = 0.36 + 0.16 * lattice_hash(row.astype(np.int64), col.astype(np.int64), seed, 40)
    brick = brick + _fbm(u, v, footprint, ((0.02, 0.03),), seed, 41)
    in_brick = (_periodic_band(us, length, MORTAR / 2, length - MORTAR / 2, footprint)
                * _periodic_band(v, course, MORTAR / 2, course - MORTAR / 2, footprint))
    albedo = 0.68 + (brick - 0.68) * in_brick
    # windows: one per bay, on every floor, away from the face's edges and top
    bay_w, floor_h = BAY
    win_w, win_h, sill = WINDOW
    n_bays = max(int((size[0] - 0.6) // bay_w), 0)
    if n_bays and size[1] > floor_h:
        u0 = (size[0] - n_bays * bay_w) / 2
        across = _periodic_band(u - u0, bay_w, (bay_w - win_w) / 2, (bay_w + win_w) / 2,
                                footprint) * _band(u, u0, u0 + n_bays * bay_w, footprint)
        up = _periodic_band(v, floor_h, sill, sill + win_h, footprint) * \
            _band(v, 0.0, np.floor(size[1] / floor_h) * floor_h - 0.3, footprint)
        glass = 0.1 + 0.05 * lattice_hash(np.floor((u - u0) / bay_w).astype(np.int64),
                                          np.floor(v / floor_h).astype(np.int64), seed, 42)
        win = across * up
        albedo = albedo + (glass - albedo) * win
    return albedo


def _sky(uv, footprint, seed, size):
    return 0.92 + _fbm(uv[:, 0], uv[:, 1], footprint, ((5.0, 0.01),), seed, 50)


_TEXTURES = {"voronoi": _voronoi, "cardboard": _cardboard, "asphalt": _asphalt,
             "facade": _facade, "sky": _sky}


def texture_albedo(name: str, uv, footprint, *, seed: int, size=(np.inf, np.inf)):
    """Albedo of the texture `name` at surface coordinates `uv`.

    Parameters
    ----------
    name : str
        One of :data:`TEXTURES`.
    uv : ndarray of shape (n, 2)
        Coordinates on one face, metres, from a corner of the face.
    footprint : ndarray of shape (n,) or float
        Size of each pixel on the surface, metres (sharp patterns are averaged
        over it, noise finer than it fades out).
    seed : int
        Texture seed (one per face: the same seed gives the same pattern).
    size : tuple of two floats, default=(inf, inf)
        Extent of the face along u and v, metres (windows and tape strips are
        placed within it).

    Returns
    -------
    albedo : ndarray of shape (n,)
        In [0, 1].

    Raises
    ------
    ValueError
        For an unknown `name`.
    """
    if name not in _TEXTURES:
        raise ValueError(f"material must be one of {TEXTURES}, got {name!r}")
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    footprint = np.broadcast_to(np.asarray(footprint, dtype=np.float64), (len(uv),))
    if not len(uv):
        return np.zeros(0)
    out = _TEXTURES[name](uv, footprint, int(seed), tuple(float(s) for s in size))
    return np.clip(out, 0.0, 1.0)
