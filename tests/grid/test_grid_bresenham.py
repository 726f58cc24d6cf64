"""GridMap's Bresenham ray model (``ray_model="bresenham"``, ``ext/_bresenham.h``)
against an independent reference of its rules written here in plain Python: every
cell and its float32 log-odds, after several scans."""

import math

import numpy as np
import pytest

from occgp import GridMap


def _key(point, resolution):
    return tuple(int(math.floor(float(c) * (1.0 / resolution))) + 32768 for c in point)


def _line(a, b):
    """The cells of the integer line from cell a towards cell b: a and those before b."""
    if a == b:
        return []
    delta = [q - p for p, q in zip(a, b)]
    step = [1 if d >= 0 else -1 for d in delta]
    delta = [abs(d) for d in delta]
    longest = max(delta)
    cell, error, cells = list(a), [0, 0, 0], [tuple(a)]
    for _ in range(longest - 1):
        for axis in range(3):
            error[axis] += delta[axis]
            if 2 * error[axis] >= longest:
                cell[axis] += step[axis]
                error[axis] -= longest
        cells.append(tuple(cell))
    return cells


class Reference:
    """The rules: end cells first, in point order, each cell once a scan; a point at
    max_range or beyond is moved onto that sphere and its cell gets a miss; then one
    line per distinct end cell (hits, then misses), its cells a miss each."""

    def __init__(self, resolution, hit=0.7, miss=0.4, lo=0.1192, hi=0.971):
        f = np.float32
        self.resolution = resolution
        self.hit, self.miss = f(math.log(hit / (1 - hit))), f(math.log(miss / (1 - miss)))
        self.lo, self.hi = f(math.log(lo / (1 - lo))), f(math.log(hi / (1 - hi)))
        self.cells = {}

    def _update(self, key, change):
        value = self.cells.get(key)
        if value is not None and ((change >= 0 and value >= self.hi)
                                  or (change <= 0 and value <= self.lo)):
            return
        value = np.float32((value or np.float32(0)) + change)
        self.cells[key] = np.float32(min(max(value, self.lo), self.hi))

    def insert(self, points, origin, max_range=None):
        origin = [float(c) for c in origin]
        start = _key(origin, self.resolution)
        done, hits, misses = set(), [], []
        for point in points:
            point = [float(c) for c in point]
            v = [p - o for p, o in zip(point, origin)]
            squared = v[0] * v[0] + v[1] * v[1] + v[2] * v[2]
            is_miss = max_range is not None and squared >= max_range * max_range
            if is_miss:
                norm = math.sqrt(squared)
                point = [o + (d / norm) * max_range for o, d in zip(origin, v)]
            key = _key(point, self.resolution)
            if key in done:
                continue
            done.add(key)
            self._update(key, self.miss if is_miss else self.hit)
            (misses if is_miss else hits).append(key)
        for end in hits + misses:
            for key in _line(start, end):
                if key not in done:
                    done.add(key)
                    self._update(key, self.miss)


def _cells(grid):
    """Every cell of the grid as {key: float32 log-odds}."""
    cells = grid.cells()
    keys = np.floor(cells.centers / grid.resolution).astype(np.int64) + 32768
    return {tuple(int(k) for k in key): value for key, value in zip(keys, cells.log_odds)}


def _scans(rng, n_scans, n_points, spread=3.0):
    scans = []
    for _ in range(n_scans):
        origin = rng.uniform(-1, 1, 3).astype(np.float32)
        points = (origin + rng.normal(0, spread, (n_points, 3))).astype(np.float32)
        points[: n_points // 10] = points[n_points // 10: n_points // 5]  # shared end cells
        scans.append((points, origin))
    return scans


@pytest.mark.parametrize("resolution", [0.05, 0.1, 0.37])
@pytest.mark.parametrize("max_range", [None, 4.0])
def test_every_cell_is_the_reference(resolution, max_range):
    rng = np.random.default_rng(int(resolution * 100) + (max_range is None))
    grid, ref = GridMap(resolution), Reference(resolution)
    for points, origin in _scans(rng, 4, 300):
        grid.insert_scan(points, origin, max_range=max_range, ray_model="bresenham")
        ref.insert(points, origin, max_range)
    got = _cells(grid)
    assert len(got) > 500 and got.keys() == ref.cells.keys()
    assert all(got[k] == ref.cells[k] for k in got)


def test_line_rules():
    """Hand-checked lines: the origin's cell, then one step on the longest axis per
    cell, the others stepping when twice their error reaches it; never the end cell."""
    assert _line((0, 0, 0), (0, 0, 0)) == []
    assert _line((0, 0, 0), (3, 0, 0)) == [(0, 0, 0), (1, 0, 0), (2, 0, 0)]
    assert _line((0, 0, 0), (4, 2, 0)) == [(0, 0, 0), (1, 1, 0), (2, 1, 0), (3, 2, 0)]
    assert _line((5, 5, 5), (2, 5, 4)) == [(5, 5, 5), (4, 5, 5), (3, 5, 4)]
    grid = GridMap(1.0).insert_scan([[4.5, 2.5, 0.5]], [0.5, 0.5, 0.5], ray_model="bresenham")
    free = grid.cells().centers[grid.cells().log_odds < 0]
    assert sorted(map(tuple, (free - 0.5).astype(int).tolist())) == [(0, 0, 0), (1, 1, 0),
                                                                     (2, 1, 0), (3, 2, 0)]


def test_a_cell_is_updated_once_a_scan_and_in_every_scan():
    """Two points in one cell: one hit; the same cell over 12 scans: 12 hits (clamped),
    with no scan skipped (Bonxai's three-valued marker would skip every third)."""
    grid = GridMap(0.1)
    hit = np.float32(np.log(0.7 / 0.3))
    grid.insert_scan([[1.01, 0, 0], [1.02, 0, 0]], [0, 0, 0], ray_model="bresenham")
    assert grid.log_odds([[1.01, 0, 0]])[0] == pytest.approx(hit)
    assert grid.last_insert_["rays"] == 1
    for _ in range(2):
        grid.insert_scan([[1.01, 0, 0]], [0, 0, 0], ray_model="bresenham")
    assert grid.log_odds([[1.01, 0, 0]])[0] == pytest.approx(3 * hit, rel=1e-6)
    for _ in range(9):
        grid.insert_scan([[1.01, 0, 0]], [0, 0, 0], ray_model="bresenham")
    assert grid.log_odds([[1.01, 0, 0]])[0] == pytest.approx(np.log(0.971 / 0.029), rel=1e-6)


def test_far_points_are_moved_to_max_range_and_clear():
    grid = GridMap(0.1).insert_scan([[10.0, 0, 0]], [0, 0, 0], max_range=2.0,
                                    ray_model="bresenham")
    assert grid.is_occupied([[1.95, 0, 0]], return_unknown=True)[1].tolist() == [False]
    assert not grid.is_occupied([[1.95, 0, 0]])[0]       # the moved end: a miss
    assert np.isnan(grid.occupancy([[2.5, 0, 0]])[0])     # beyond: never seen


def test_free_space_mostly_agrees_with_the_octomap_model():
    rng = np.random.default_rng(3)
    exact, fast = GridMap(0.1), GridMap(0.1)
    for points, origin in _scans(rng, 3, 2000, spread=2.0):
        exact.insert_scan(points, origin, discretize=True)
        fast.insert_scan(points, origin, ray_model="bresenham")
    free_a = set(map(tuple, exact.cells().centers[exact.cells().log_odds < 0].round(3)))
    free_b = set(map(tuple, fast.cells().centers[fast.cells().log_odds < 0].round(3)))
    assert len(free_a & free_b) / len(free_a | free_b) > 0.6


@pytest.mark.parametrize("kwargs, error, match", [
    (dict(mode="ray"), ValueError, "only defined for mode='scan'"),
    (dict(method="plain"), ValueError, "takes no method, discretize or free_points"),
    (dict(discretize=True), ValueError, "takes no method, discretize or free_points"),
    (dict(free_points=[[0, 1.0, 0]]), ValueError, "takes no method"),
    (dict(max_range=-1.0), ValueError, "max_range"),
])
def test_bad_calls_change_nothing(kwargs, error, match):
    grid = GridMap(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0])
    before = _cells(grid)
    with pytest.raises(error, match=match):
        grid.insert_scan([[0, 1.0, 0]], [0, 0, 0], ray_model="bresenham", **kwargs)
    assert _cells(grid) == before


def test_points_without_a_key_change_nothing():
    grid = GridMap(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0])
    before = _cells(grid)
    with pytest.raises(ValueError, match="outside"):
        grid.insert_scan([[0, 1.0, 0], [1e5, 0, 0]], [0, 0, 0], ray_model="bresenham")
    assert _cells(grid) == before


def test_the_octree_takes_no_bresenham():
    from occgp import OccupancyOctree
    with pytest.raises(ValueError, match="ray_model"):
        OccupancyOctree(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0], ray_model="bresenham")
