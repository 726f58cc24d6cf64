"""insert_scan's scan filters: ``min_range`` and free-only rays (``free_points``).

``min_range`` must give, leaf for leaf, the map of the pre-filtered scan, for every
map, method and mode. Free-only rays (octomap_server's ground points) must give the
map of liboctomap's key-set rule with their cells in the free set only (scan mode),
or one more miss per crossed cell (ray mode), checked against an independent model
built on the port of liboctomap's ray traversal in ``octomap_reference.py``.
"""

from collections import defaultdict

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from occgp import AKIMap, BGKMap, ColorOctree, GridMap, KNNMap, OccupancyOctree
from octomap_reference import MAX_VAL, _key, _ray_end, leaf_values, logodds32, ray_keys
from _helpers import assert_same_leaves

f32 = np.float32
METHODS = ["plain", "culling", "superray", "superray+culling", "auto"]
MODES = ["scan", "ray"]
# insert_scan's keywords; "n_jobs" goes to the constructor (see split)
OPTIONS = [{}, {"max_range": 1.6}, {"bbox": [[-1.0, -0.9, -0.2], [1.3, 1.1, 1.5]]},
           {"n_jobs": 2}]


def split(options):
    """(the constructor's n_jobs, insert_scan's other keywords) of an OPTIONS entry."""
    return options.get("n_jobs"), {k: v for k, v in options.items() if k != "n_jobs"}


def room_scans(seed=0, n_scans=4, n_points=300, n_ground=150):
    """A 4 x 4 x 2 m room seen from nearby poses: wall points with dense clusters (for
    super rays), floor points (z = 0) and a few points near the sensor."""
    rng = np.random.default_rng(seed)
    scans = []
    for _ in range(n_scans):
        origin = np.array([0.05, -0.05, 0.45]) + rng.uniform(-0.1, 0.1, 3)
        d = rng.normal(size=(n_points, 3))
        d[:, 2] = np.abs(d[:, 2])
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        hi, lo = np.array([2.0, 2.0, 2.0]), np.array([-2.0, -2.0, 0.0])
        t = np.min(np.where(d > 0, (hi - origin) / np.where(d > 0, d, 1),
                            (lo - origin) / np.where(d < 0, d, -1)), axis=1)
        walls = origin + d * t[:, None]
        cluster = np.array([1.95, 0.3, 0.9]) + rng.uniform(-0.04, 0.04, (60, 3))
        u = rng.normal(size=(20, 3))
        near = origin + u / np.linalg.norm(u, axis=1, keepdims=True) * rng.uniform(
            0.25, 0.6, (20, 1))
        ground = np.column_stack([rng.uniform(-1.9, 1.9, (n_ground, 2)), np.zeros(n_ground)])
        scans.append((np.vstack([walls, cluster, near]), ground, origin))
    return scans


def free_reference(scans, resolution, mode, max_range=None, bbox=None):
    """Cell key -> float32 log-odds after inserting (points, free_points, origin) scans:
    liboctomap's key sets (scan mode) or per-ray counts (ray mode), the free rays adding
    their traversed cells as free and nothing at their end; with `bbox`, liboctomap's
    useBBXLimit rule (rays ending in the box within range; cells in its keys)."""
    l_hit, l_miss = logodds32(0.7), logodds32(0.4)
    lo, hi = logodds32(0.1192), logodds32(0.971)
    rf = 1.0 / resolution
    values = {}
    if bbox is not None:
        box = np.asarray(bbox, f32)
        kbox = np.array([[_key(c, rf) for c in row] for row in box])
    for points, free, origin in scans:
        o = [f32(c) for c in np.asarray(origin, f32)]
        n_free, n_hit = defaultdict(int), defaultdict(int)
        for rows, hit in ((points, True), (free, False)):
            for p in np.asarray(rows, f32):
                p = [f32(c) for c in p]
                end, truncated = _ray_end(o, p, max_range)
                if bbox is not None and (truncated or not (
                        (np.array(p) >= box[0]).all() and (np.array(p) <= box[1]).all())):
                    continue
                for key in ray_keys(o, end, resolution):
                    n_free[key] += 1
                if hit and not truncated:
                    n_hit[tuple(_key(c, rf) for c in p)] += 1
        for key in set(n_free) | set(n_hit):
            if bbox is not None and not ((kbox[0] <= key).all() and (key <= kbox[1]).all()):
                continue
            if mode == "scan":
                delta = l_hit if n_hit[key] else l_miss
            else:
                delta = f32(n_free[key] * float(l_miss) + n_hit[key] * float(l_hit))
            value = f32(values.get(key, f32(0.0)) + delta)
            values[key] = lo if value < lo else (hi if value > hi else value)
    return values


def grid_values(grid):
    centers, _, values = grid.cells()
    keys = np.floor(centers / grid.resolution).astype(np.int64) + MAX_VAL
    return {tuple(k): v for k, v in zip(keys.tolist(), values)}


def prefiltered(points, origin, min_range):
    d = np.asarray(points, np.float64) - np.asarray(origin, np.float64)
    return np.asarray(points)[np.sqrt((d * d).sum(axis=1)) >= min_range]


# ---------------------------------------------------------------------- min_range
@pytest.mark.parametrize("cls", [OccupancyOctree, GridMap])
@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("method", METHODS)
def test_min_range_equals_the_prefiltered_scan(cls, mode, method):
    scans = room_scans(1, n_scans=3)
    for options in OPTIONS:
        if cls is GridMap and "bbox" in options:
            continue
        n_jobs, kwargs = split(options)
        a, b = cls(0.2, n_jobs=n_jobs), cls(0.2, n_jobs=n_jobs)
        for points, ground, origin in scans:
            cloud = np.vstack([points, ground])
            a.insert_scan(cloud, origin, mode=mode, method=method, min_range=0.45,
                          superray_threshold=3, **kwargs)
            b.insert_scan(prefiltered(cloud, origin, 0.45), origin, mode=mode,
                          method=method, superray_threshold=3, **kwargs)
        if cls is GridMap:
            assert grid_values(a) == grid_values(b)
        else:
            assert_same_leaves(a, b)


def test_min_range_with_free_points_filters_both():
    points, ground, origin = room_scans(2, n_scans=1)[0]
    a = OccupancyOctree(0.1).insert_scan(points, origin, min_range=0.5, free_points=ground)
    b = OccupancyOctree(0.1).insert_scan(prefiltered(points, origin, 0.5), origin,
                                         free_points=prefiltered(ground, origin, 0.5))
    assert_same_leaves(a, b)


def test_min_range_on_the_color_octree():
    points, _, origin = room_scans(3, n_scans=1)[0]
    rgb = np.random.default_rng(0).integers(0, 255, (len(points), 3))
    d = np.linalg.norm(points - origin, axis=1)
    a = ColorOctree(0.1).insert_scan(points, origin, rgb, min_range=0.5, max_range=3.0)
    b = ColorOctree(0.1).insert_scan(points[d >= 0.5], origin, rgb[d >= 0.5], max_range=3.0)
    la, lb = a.leaves(), b.leaves()
    for x, y in zip(la, lb):
        assert_array_equal(x, y)


def test_min_range_on_the_knn_map():
    scans = room_scans(4, n_scans=2)
    a, b = KNNMap(0.2, k=3), KNNMap(0.2, k=3)
    for points, _, origin in scans:
        a.insert_scan(points, origin, min_range=0.4)
        b.insert_scan(prefiltered(points, origin, 0.4), origin)
    assert_same_leaves(a, b)
    assert a.n_scores_ == b.n_scores_ and a.score_mean_ == b.score_mean_


@pytest.mark.parametrize("cls", [BGKMap, AKIMap])
def test_min_range_on_the_kernel_maps(cls):
    points, _, origin = room_scans(5, n_scans=1, n_points=120)[0]
    params = {"random_state": 0} if cls is AKIMap else {}
    a = cls(0.2, **params).insert_scan(points, origin, min_range=0.4)
    b = cls(0.2, **params).insert_scan(prefiltered(points, origin, 0.4), origin)
    assert_array_equal(a.occupancy(points), b.occupancy(points))


def test_min_range_keeps_a_point_at_exactly_min_range_in_double_precision():
    origin = [0.05, 0.05, 0.05]
    # 1 + 1e-12 m away: dropped by min_range = 1 + 2e-12 (float64 distances), though
    # both round to the same float32
    p = [[1.05 + 1e-12, 0.05, 0.05]]
    m = OccupancyOctree(0.1).insert_scan(p, origin, min_range=1.0 + 2e-12)
    assert m.num_leaves == 0
    m = OccupancyOctree(0.1).insert_scan([[1.05, 0.05, 0.05]], origin, min_range=1.0)
    assert m.is_occupied([[1.05, 0.05, 0.05]])[0]


@pytest.mark.parametrize("cls", [OccupancyOctree, GridMap, ColorOctree, KNNMap, BGKMap])
@pytest.mark.parametrize("bad, match", [
    (-0.1, r"min_range must lie in \[0.0, inf\)"),
    (np.nan, "min_range must lie in"),
    (np.inf, "min_range must lie in"),
])
def test_bad_min_range_changes_nothing(cls, bad, match):
    points, _, origin = room_scans(6, n_scans=1, n_points=60)[0]
    extra = (np.zeros((len(points), 3), np.uint8),) if cls is ColorOctree else ()
    m = cls(0.2).insert_scan(points, origin, *extra)
    before = m.occupancy(points)
    with pytest.raises(ValueError, match=match):
        m.insert_scan(points + 0.3, origin, *extra, min_range=bad)
    assert_array_equal(m.occupancy(points), before)


@pytest.mark.parametrize("cls", [OccupancyOctree, GridMap, ColorOctree])
def test_min_range_must_be_less_than_max_range(cls):
    extra = (np.zeros((1, 3), np.uint8),) if cls is ColorOctree else ()
    with pytest.raises(ValueError, match=r"min_range must be less than max_range \(2.0\)"):
        cls(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0], *extra, min_range=2.0, max_range=2.0)
    with pytest.raises(TypeError, match="min_range must be a real number"):
        cls(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0], *extra, min_range="1")


def test_min_range_must_be_less_than_the_knn_max_range():
    with pytest.raises(ValueError, match=r"min_range must be less than max_range \(4.0\)"):
        KNNMap(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0], min_range=5.0)


# ---------------------------------------------------------------------- free_points
@pytest.mark.slow
@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("method", METHODS)
def test_free_points_give_liboctomaps_key_sets(mode, method):
    scans = room_scans(7, n_scans=6)
    # free points also ending in the hit clusters' cells: they must not join super rays
    scans = [(p, np.vstack([g, p[300:330]]), o) for p, g, o in scans]
    for options in OPTIONS + [{"n_jobs": 2, "max_range": 1.6}]:
        n_jobs, kwargs = split(options)
        m = OccupancyOctree(0.2, n_jobs=n_jobs)
        for points, free, origin in scans:
            m.insert_scan(points, origin, free_points=free, mode=mode, method=method,
                          superray_threshold=3, **kwargs)
        ref = free_reference(scans, 0.2, mode, options.get("max_range"),
                             options.get("bbox"))
        assert leaf_values(m) == ref, options
        if "culling" in method and "bbox" not in options:
            assert m.last_insert_["region_cells"] > 0


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("method", METHODS)
def test_free_points_on_the_grid_equal_the_octree(mode, method):
    scans = room_scans(8, n_scans=3)
    for options in ({}, {"max_range": 1.6, "n_jobs": 2}):
        n_jobs, kwargs = split(options)
        g, o = GridMap(0.2, n_jobs=n_jobs), OccupancyOctree(0.2, n_jobs=n_jobs)
        for points, free, origin in scans:
            g.insert_scan(points, origin, free_points=free, mode=mode, method=method,
                          superray_threshold=3, **kwargs)
            o.insert_scan(points, origin, free_points=free, mode=mode, method="plain",
                          **kwargs)
        assert grid_values(g) == leaf_values(o)


def test_culling_and_superrays_are_used_with_free_points():
    scans = room_scans(9, n_scans=6)
    for method in ("culling", "superray"):
        m = OccupancyOctree(0.2)
        for points, free, origin in scans:
            m.insert_scan(points, origin, free_points=free, method=method,
                          superray_threshold=3)
        stats = m.last_insert_
        if method == "culling":
            assert stats["region_cells"] > 0
        else:
            assert stats["superrays"]
            assert stats["rays"] < len(scans[-1][0]) + len(scans[-1][1]) - 40


def test_free_points_only_clear():
    origin = [0.05, 0.05, 0.05]
    m = OccupancyOctree(0.1).insert_scan(np.empty((0, 3)), origin,
                                         free_points=[[0.75, 0.05, 0.05]])
    occ, unknown = m.is_occupied([[0.65, 0.05, 0.05], [0.75, 0.05, 0.05]],
                                 return_unknown=True)
    assert occ.tolist() == [False, False] and unknown.tolist() == [False, True]
    # a cell both free (a free ray crosses it) and occupied (a ray ends in it) is occupied
    m = OccupancyOctree(0.1).insert_scan([[0.45, 0.05, 0.05]], origin,
                                         free_points=[[0.95, 0.05, 0.05]])
    assert m.log_odds([[0.45, 0.05, 0.05]])[0] == logodds32(0.7)
    m = OccupancyOctree(0.1).insert_scan([[0.45, 0.05, 0.05]], origin, mode="ray",
                                         free_points=[[0.95, 0.05, 0.05]])
    assert m.log_odds([[0.45, 0.05, 0.05]])[0] == f32(float(logodds32(0.7))
                                                      + float(logodds32(0.4)))


def test_empty_free_points_change_nothing():
    points, _, origin = room_scans(10, n_scans=1)[0]
    a = OccupancyOctree(0.2).insert_scan(points, origin, free_points=np.empty((0, 3)))
    b = OccupancyOctree(0.2).insert_scan(points, origin)
    assert_same_leaves(a, b)


@pytest.mark.parametrize("fusion", ["average", "mean"])
def test_free_points_on_the_color_octree(fusion):
    scans = room_scans(11, n_scans=2)
    rng = np.random.default_rng(1)
    c, o = ColorOctree(0.2), OccupancyOctree(0.2)
    plain = ColorOctree(0.2)
    for points, free, origin in scans:
        rgb = rng.integers(0, 255, (len(points), 3))
        c.insert_scan(points, origin, rgb, free_points=free, fusion=fusion, max_range=2.5)
        plain.insert_scan(points, origin, rgb, fusion=fusion, max_range=2.5)
        o.insert_scan(points, origin, free_points=free, max_range=2.5)
    lc, lo = c.leaves(), o.leaves()
    for x, y in zip(lc[:3], lo):
        assert_array_equal(x, y)
    # colours come from the points alone
    pts = scans[-1][0]
    assert_array_equal(c.colors(pts)[0][c.is_occupied(pts)],
                       plain.colors(pts)[0][c.is_occupied(pts)])


@pytest.mark.parametrize("cls", [OccupancyOctree, GridMap, ColorOctree])
@pytest.mark.parametrize("bad, exc, match", [
    (np.zeros((3, 2)), ValueError, r"free_points must have shape \(n_points, 3\)"),
    ([[np.nan, 0, 0]], ValueError, "free_points must be finite"),
    ([[1e9, 0, 0]], ValueError, "free_points lie outside"),
    ([["a", 0, 0]], TypeError, "free_points must hold real numbers"),
])
def test_bad_free_points_change_nothing(cls, bad, exc, match):
    points, ground, origin = room_scans(12, n_scans=1, n_points=60)[0]
    extra = (np.zeros((len(points), 3), np.uint8),) if cls is ColorOctree else ()
    m = cls(0.2).insert_scan(points, origin, *extra)
    before = m.occupancy(ground)
    with pytest.raises(exc, match=match):
        m.insert_scan(points, origin, *extra, free_points=np.vstack([ground[:5], bad])
                      if exc is ValueError and np.asarray(bad).shape[-1] == 3 else bad)
    assert_array_equal(m.occupancy(ground), before)


def test_free_points_do_not_combine_with_discretize():
    with pytest.raises(ValueError, match="free_points do not combine with discretize"):
        OccupancyOctree(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0], discretize=True,
                                         free_points=[[0.0, 1.0, 0.0]])
