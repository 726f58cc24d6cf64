"""Per-beam elevation tables of real spinning LiDARs (numpy only).

A real sensor's beams are not always evenly spaced: the Velodyne HDL-64E has
two laser blocks of different pitches, and every unit is calibrated beam by
beam. A :class:`~occgp.iln.LidarModel` with ``beam_elevations`` puts row ``i``'s
center at the table's entry ``i`` (degrees, top beam first, strictly
decreasing) instead of a uniform bin. Between rows, a fractional row
coordinate ``v`` (pixel units, row ``i``'s center at ``i + 0.5``) maps to an
elevation **linearly between the neighbouring table entries**; the knots are
``(0, high)``, ``(i + 0.5, table[i])`` for every row and ``(rows, low)``, with
``(low, high)`` the model's ``vertical_fov`` (its edges), and beyond them the
end segments extend linearly. A row boundary (integer ``v``) thus lies midway
between two beams, so binning a point by its elevation gives it the nearest
beam. Resizing a model (``with_size``) samples this piecewise-linear map at
the new row centers ``(k + 0.5) * rows / new_rows``.

This module holds the arithmetic of the tables, the tables of the presets and
the estimation of a table from a real frame; :mod:`occgp.iln._range` uses it.
"""

from __future__ import annotations

import numpy as np

from .._validation import as_numeric

__all__ = ["HDL64E_TABLE", "HDL32E_TABLE", "VLP16_TABLE", "OS1_64_TABLE", "check_table",
           "table_fov", "elevation_at", "row_at", "resample_table", "scan_rings",
           "ring_table", "cluster_table", "estimate_table"]

#: Velodyne HDL-64E (nominal): upper block 32 beams from +2.0 to -8.33 degrees at a
#: 1/3 degree pitch, lower block 32 beams from -8.83 to -24.33 degrees at 1/2 degree.
HDL64E_TABLE = tuple(np.round(np.concatenate([2.0 - np.arange(32) / 3.0,
                                              -8.83 - 0.5 * np.arange(32)]), 4).tolist())
#: Velodyne HDL-32E: 32 beams from +10.67 to -30.67 degrees, 4/3 degree apart.
HDL32E_TABLE = tuple(np.round(np.linspace(10.67, -30.67, 32), 4).tolist())
#: Velodyne VLP-16: 16 beams from +15 to -15 degrees, 2 degrees apart.
VLP16_TABLE = tuple(np.linspace(15.0, -15.0, 16).tolist())
#: Ouster OS1-64 of the RELLIS-3D frame (``os1_64_full.bin``): the per-beam
#: elevations measured in it (every return of a beam has the same elevation to
#: 0.01 degree), beam 0 at the top.
OS1_64_TABLE = (
    17.02, 16.4, 15.84, 15.28, 14.82, 14.23, 13.67, 13.12, 12.67, 12.1, 11.54, 11.0, 10.55,
    9.98, 9.43, 8.88, 8.45, 7.89, 7.34, 6.79, 6.36, 5.79, 5.25, 4.7, 4.26, 3.71, 3.16, 2.61,
    2.17, 1.62, 1.07, 0.52, 0.08, -0.47, -1.02, -1.57, -2.02, -2.56, -3.11, -3.66, -4.11,
    -4.66, -5.2, -5.76, -6.21, -6.76, -7.31, -7.86, -8.31, -8.85, -9.4, -9.98, -10.42,
    -10.96, -11.52, -12.09, -12.55, -13.1, -13.66, -14.24, -14.71, -15.27, -15.84, -16.44)


def check_table(table, rows, name="beam_elevations"):
    """`table` as a tuple of `rows` finite floats in [-90, 90], strictly decreasing."""
    if isinstance(table, (str, bytes)) or not hasattr(table, "__len__"):
        raise TypeError(f"{name} must be a sequence of elevations (degrees), got "
                        f"{type(table).__name__}")
    arr = np.asarray(as_numeric(table, name), dtype=np.float64)
    if arr.shape != (rows,):
        raise ValueError(f"{name} must hold one elevation per row, shape ({rows},), "
                         f"got {arr.shape}")
    if not np.isfinite(arr).all() or (np.abs(arr) > 90.0).any():
        raise ValueError(f"{name} must hold finite elevations in [-90, 90] degrees")
    if (np.diff(arr) >= 0).any():
        raise ValueError(f"{name} must decrease strictly (row 0 is the top beam)")
    return tuple(arr.tolist())


def table_fov(table):
    """``(low, high)``: the table's ends extended by half the end pitches, within [-90, 90]."""
    t = np.asarray(table, dtype=np.float64)
    top = (t[0] - t[1]) / 2 if len(t) > 1 else 0.5
    bottom = (t[-2] - t[-1]) / 2 if len(t) > 1 else 0.5
    return max(float(t[-1] - bottom), -90.0), min(float(t[0] + top), 90.0)


def _knots(table, fov):
    """Row coordinates (increasing) and elevations (decreasing) of the piecewise-linear map."""
    t = np.asarray(table, dtype=np.float64)
    v = np.concatenate([[0.0], np.arange(len(t)) + 0.5, [float(len(t))]])
    e = np.concatenate([[fov[1]], t, [fov[0]]])
    return v, e


def _interp(x, xp, fp):
    """np.interp with linear extension of the end segments (`xp` increasing)."""
    x = np.asarray(x, dtype=np.float64)
    y = np.interp(x, xp, fp)
    lo = x < xp[0]
    hi = x > xp[-1]
    if lo.any() or hi.any():
        s0 = (fp[1] - fp[0]) / (xp[1] - xp[0])
        s1 = (fp[-1] - fp[-2]) / (xp[-1] - xp[-2])
        y = np.where(lo, fp[0] + (x - xp[0]) * s0, y)
        y = np.where(hi, fp[-1] + (x - xp[-1]) * s1, y)
    return y


def elevation_at(v, table, fov):
    """Elevation (degrees) at fractional rows `v` of a table model."""
    kv, ke = _knots(table, fov)
    return _interp(v, kv, ke)


def row_at(elevation, table, fov):
    """Fractional row `v` of elevations (degrees) in a table model."""
    kv, ke = _knots(table, fov)
    return _interp(-np.asarray(elevation, dtype=np.float64), -ke, kv)


def resample_table(table, fov, rows):
    """The table of `rows` rows over the same map: elevations at ``(k + 0.5) * n / rows``."""
    n = len(table)
    v = (np.arange(rows) + 0.5) * (n / rows)
    out = elevation_at(v, table, fov)
    return tuple(float(x) for x in out)


def scan_rings(azimuth, jump=90.0):
    """Ring index of points in scan order: a new ring starts where the azimuth jumps by more
    than `jump` degrees (the sweep of one beam ends and the next beam's begins)."""
    azimuth = np.asarray(azimuth, dtype=np.float64)
    if azimuth.size == 0:       # no points, no rings
        return np.zeros(0, dtype=np.int64)
    starts = np.abs(np.diff(azimuth)) > jump
    return np.concatenate([[0], np.cumsum(starts)]).astype(np.int64)


def ring_table(elevation, ring, rows):
    """Table of `rows` beams from rings: each ring's median elevation; rings are merged
    (closest medians first) until `rows` remain. Returns ``(table, row of each point)``."""
    elevation = np.asarray(elevation, dtype=np.float64)
    ring = np.asarray(ring, dtype=np.int64)
    ids, inverse = np.unique(ring, return_inverse=True)
    if len(ids) < rows:
        raise ValueError(f"rows={rows} beams asked but the points hold only {len(ids)} rings")
    groups = [[k] for k in range(len(ids))]
    med = np.array([np.median(elevation[inverse == k]) for k in range(len(ids))])
    order = np.argsort(-med)
    groups = [groups[k] for k in order]
    meds = list(med[order])
    while len(groups) > rows:
        gaps = -np.diff(meds)
        k = int(np.argmin(gaps))
        groups[k] = groups[k] + groups.pop(k + 1)
        meds.pop(k + 1)
        members = np.isin(inverse, groups[k])
        meds[k] = float(np.median(elevation[members]))
    row_of_ring = np.empty(len(ids), dtype=np.int64)
    for row, g in enumerate(groups):
        row_of_ring[g] = row
    table = np.array([np.median(elevation[row_of_ring[inverse] == r]) for r in range(rows)])
    return table, row_of_ring[inverse]


def cluster_table(elevation, rows, iterations=50):
    """Table of `rows` beams from elevations alone: 1-D k-medians (Lloyd's iterations on the
    sorted elevations, started at evenly spaced quantiles). Returns ``(table, row of each point)``."""
    e = np.sort(np.asarray(elevation, dtype=np.float64))[::-1]
    centers = np.quantile(e, (np.arange(rows) + 0.5) / rows)[::-1].copy()
    for _ in range(iterations):
        bounds = (centers[:-1] + centers[1:]) / 2
        label = np.searchsorted(-bounds, -e, side="right")
        new = centers.copy()
        for r in range(rows):
            part = e[label == r]
            if len(part):
                new[r] = np.median(part)
        new = np.sort(new)[::-1]
        if np.allclose(new, centers):
            break
        centers = new
    bounds = (centers[:-1] + centers[1:]) / 2
    rows_of = np.searchsorted(-bounds, -np.asarray(elevation, dtype=np.float64), side="right")
    return centers, rows_of.astype(np.int64)


def estimate_table(elevation, rows, ring=None):
    """Checked, strictly decreasing table of `rows` beams from the elevations of a frame's points
    (NaN for points at the origin, ignored), by :func:`ring_table` with `ring`, else by
    :func:`cluster_table`."""
    elevation = np.asarray(elevation, dtype=np.float64)
    if rows < 2:
        raise ValueError(f"rows must be at least 2 to estimate a table, got {rows}")
    keep = np.isfinite(elevation)
    if ring is None:
        if len(np.unique(elevation[keep])) < rows:
            raise ValueError(f"points hold fewer distinct elevations than rows={rows}")
        table, _ = cluster_table(elevation[keep], rows)
    else:
        ring = as_numeric(ring, "ring")
        if ring.shape != elevation.shape:
            raise ValueError(f"ring must have shape (n_points,) = {elevation.shape}, "
                             f"got {ring.shape}")
        table, _ = ring_table(elevation[keep], ring[keep], rows)
    return check_table(np.sort(table)[::-1], rows)
