"""The culling region: every method gives the map of the plain method, bit for bit."""

import numpy as np
import pytest

from occgp import GridMap, OccupancyOctree
from conftest import data_path
from _helpers import random_scans
from _helpers import assert_same_leaves
from _helpers import room_sequence, build_octree as build


@pytest.mark.parametrize("mode", ["scan", "ray"])
@pytest.mark.parametrize("resolution", [0.1, 0.2])
def test_culling_equals_plain_on_a_revisited_room(mode, resolution):
    scans = room_sequence(np.random.default_rng(0))
    plain = build(scans, resolution, mode=mode)
    culled = build(scans, resolution, mode=mode, method="culling")
    assert_same_leaves(culled, plain)


@pytest.mark.parametrize("mode", ["scan", "ray"])
def test_culling_region_is_used_and_skips_cells(mode):
    scans = room_sequence(np.random.default_rng(1))
    m = build(scans[:-1], 0.1, mode=mode)
    points, origin = scans[-1]
    stats = m._insert_batch(points.astype(np.float32), origin.astype(np.float32), -1.0,
                            mode == "ray", True)
    assert stats[0] > 100                      # region cells
    plain = build(scans[:-1], 0.1, mode=mode)
    full = plain._insert_batch(points.astype(np.float32), origin.astype(np.float32), -1.0,
                               mode == "ray", False)
    assert full[0] == -1 and stats[1] < full[1]   # fewer cells updated
    assert_same_leaves(m, plain)


@pytest.mark.parametrize("max_range", [None, 1.0])
@pytest.mark.parametrize("mode", ["scan", "ray"])
def test_culling_equals_plain_on_random_scans(mode, max_range):
    rng = np.random.default_rng(2)
    scans = random_scans(rng, n_scans=3, n_points=300) * 3     # revisits saturate space
    plain = build(scans, 0.1, mode=mode, max_range=max_range)
    culled = build(scans, 0.1, mode=mode, max_range=max_range, method="culling")
    assert_same_leaves(culled, plain)


def test_batch_scan_update_equals_liboctomap():
    """occgp's own key table in scan mode gives liboctomap's insertPointCloud tree."""
    scans = room_sequence(np.random.default_rng(3), n_scans=4)
    ref = build(scans, 0.1)
    m = OccupancyOctree(0.1)
    for points, origin in scans:
        m._insert_batch(points.astype(np.float32), origin.astype(np.float32), -1.0, False, False)
    assert_same_leaves(m, ref)


def test_culling_keeps_end_points_out_of_the_region():
    """An end point in saturated free space must get its hit (DESIGN's exactness rule)."""
    origin = np.array([0.05, 0.05, 0.05])
    wall = np.column_stack([np.full(50, 2.05), np.linspace(-0.5, 0.5, 50), np.zeros(50) + 0.05])
    for method in ("plain", "culling"):
        m = OccupancyOctree(0.1)
        for _ in range(6):
            m.insert_scan(wall, origin, mode="ray", method=method)
        m.insert_scan(np.vstack([wall, [[1.05, 0.05, 0.05]]]), origin, mode="ray", method=method)
        if method == "plain":
            expected = m.log_odds([[1.05, 0.05, 0.05]])
        else:
            assert m.log_odds([[1.05, 0.05, 0.05]]) == expected


def test_discretize_needs_scan_mode():
    with pytest.raises(ValueError, match="discretize=True is only defined"):
        OccupancyOctree(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0], method="culling",
                                         discretize=True, mode="ray")
    with pytest.raises(ValueError, match=r"method must be one of \('auto', 'plain', 'culling', "):
        OccupancyOctree(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0], method="fast")


@pytest.mark.parametrize("seed", range(6))
def test_batch_update_with_end_points_on_cell_corners(seed):
    """End points on corners: liboctomap's traversal can step past the end cell."""
    rng = np.random.default_rng(seed)
    res = 0.2
    origin = np.round(rng.uniform(-1, 1, 3) / res) * res          # origin on a corner too
    points = np.round(rng.uniform(-3, 3, (2000, 3)) / res) * res
    points[::3] += rng.uniform(0, res, (len(points[::3]), 3)) * (rng.uniform(size=3) < 0.5)
    for mode in ("scan", "ray"):
        plain = build([(points, origin)] * 3, res, mode=mode)
        for method in ("culling", "superray", "superray+culling"):
            got = build([(points, origin)] * 3, res, mode=mode, method=method,
                        superray_threshold=2)
            assert_same_leaves(got, plain)


def _near_borders(rng, points, res):
    """Half of `points` moved onto their cells' borders, edges and corners, and next
    to them (the float32 values around each, and points 1e-7 to 1e-5 of a cell inside)."""
    on = np.round(points / res) * res
    pick = (rng.uniform(size=points.shape) < 0.5) & (rng.uniform(size=(len(points), 1)) < 0.5)
    moved = np.where(pick, on, points).astype(np.float32)
    ulp = rng.integers(-2, 3, points.shape).astype(np.float32)
    moved = np.where(rng.uniform(size=points.shape) < 0.3,
                     np.nextafter(moved, moved + ulp), moved)
    inside = rng.choice([1e-7, 1e-6, 1e-5], points.shape) * res * rng.choice([-1, 1], points.shape)
    return np.where(rng.uniform(size=points.shape) < 0.2, moved + inside, moved)


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("cls", [OccupancyOctree, GridMap])
def test_rays_culled_whole_give_plain_maps_near_cell_borders(cls, seed):
    """A ray whose end cell's neighbours toward the sensor are in the region is not
    walked (``culled_rays``): exact even for end points on and next to cell borders,
    once the region has grown (the scans repeat until space saturates)."""
    rng = np.random.default_rng(seed)
    res = 0.2
    scans = room_sequence(rng, n_scans=3, n_points=20000)
    shift = np.array([0.037, -0.051, 0.023])                    # walls off the borders
    scans = [(_near_borders(rng, p + shift, res), o + shift if seed % 2 else
              np.round(o / res) * res) for p, o in scans]
    scans = scans * 4                                           # free space saturates
    for mode in ("scan", "ray"):
        plain = cls(res)
        for points, origin in scans:
            plain.insert_scan(points, origin, mode=mode, method="plain")
        for method in ("culling", "superray+culling"):
            m = cls(res)
            culled = 0
            for points, origin in scans:
                m.insert_scan(points, origin, mode=mode, method=method, superray_threshold=2)
                culled += m.last_insert_["culled_rays"]
            assert culled > 0
            if cls is GridMap:
                assert_array_equal_cells(m.cells(), plain.cells())
            else:
                assert_same_leaves(m, plain)


def test_scan_mode_region_holds_end_cells():
    """In scan mode a cell an end point lies in gets ``l_hit`` whatever crosses it, so
    the culling region takes it (and grows past it); ray counting keeps it out."""
    scans = room_sequence(np.random.default_rng(4), n_scans=7)
    regions = {}
    for mode in ("scan", "ray"):
        m = build(scans[:-1], 0.1, mode="scan")
        points, origin = scans[-1]
        regions[mode] = m._insert_batch(points.astype(np.float32), origin.astype(np.float32),
                                        -1.0, mode == "ray", True)[0]
        plain = build(scans[:-1], 0.1, mode="scan")
        plain._insert_batch(points.astype(np.float32), origin.astype(np.float32), -1.0,
                            mode == "ray", False)
        assert_same_leaves(m, plain)
    assert regions["scan"] > regions["ray"] > 100


@pytest.mark.parametrize("cls", [OccupancyOctree, GridMap])
def test_scan_mode_region_starts_at_a_sensor_cell_not_yet_free(cls):
    """Every ray that leaves the sensor's cell crosses it, so in scan mode the region
    starts there whatever its state (the cell is collected once, not walked); ray
    counting needs the cell fully free."""
    scans = room_sequence(np.random.default_rng(5), n_scans=7)[:-1]
    origin = scans[-1][1]
    points = scans[0][0]
    for mode in ("scan", "ray"):
        maps = {}
        for method in ("plain", "culling"):
            m = cls(0.1)
            for p, o in scans:
                m.insert_scan(p, o, mode=mode, method=method)
            m.insert_scan([origin], scans[0][1], mode=mode)   # the sensor's cell: hit
            m.insert_scan(points, origin, mode=mode, method=method)
            maps[method] = m
        region = maps["culling"].last_insert_["region_cells"]
        assert region > 100 if mode == "scan" else region == 0
        if cls is GridMap:
            assert_array_equal_cells(maps["culling"].cells(), maps["plain"].cells())
        else:
            assert_same_leaves(maps["culling"], maps["plain"])
        assert maps["culling"].log_odds([origin]) == maps["plain"].log_odds([origin])


# ----------------------------------------------------------------- real data, every method
METHODS = ("culling", "superray", "superray+culling")


@pytest.fixture(scope="module")
def geb079_trajectory():
    """Six dense scans (720 x 150 beams, about 100k points each) along a path in geb079."""
    from occgp.datasets import LidarSensor, free_path, simulate_scans
    env = OccupancyOctree.load(data_path("octomap", "geb079.bt"))
    poses = free_path(env, 6, step=1.0, seed=0)
    return simulate_scans(env, poses, LidarSensor(), seed=0, progress=False)


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["scan", "ray"])
@pytest.mark.parametrize("resolution", [0.1, 0.2, 0.4])
def test_every_method_equals_plain_on_a_geb079_trajectory(geb079_trajectory, mode, resolution):
    plain = build(geb079_trajectory, resolution, mode=mode)
    for method in METHODS:
        assert_same_leaves(build(geb079_trajectory, resolution, mode=mode, method=method), plain)


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["scan", "ray"])
def test_every_method_equals_plain_on_scan_dat_from_nearby_poses(mode):
    from occgp.io import read_xyz
    scan = read_xyz(data_path("octomap", "scan.dat.bz2"))
    rng = np.random.default_rng(0)
    shifts = np.vstack([np.zeros(3), rng.uniform(-0.5, 0.5, (3, 3)) * [1, 1, 0.2]])
    scans = [(scan.points + s, scan.origin + s) for s in shifts]
    plain = build(scans, 0.2, mode=mode, max_range=20.0)
    for method in METHODS:
        got = build(scans, 0.2, mode=mode, method=method, max_range=20.0)
        assert_same_leaves(got, plain)


@pytest.mark.slow
@pytest.mark.parametrize("expand", [False, True])
def test_updates_of_a_loaded_tree_equal_liboctomaps(expand):
    """Pruned, saturated nodes of a real map are expanded, updated and pruned again as
    liboctomap's updateNode does; on an expanded tree, cells whose update is a no-op
    leave their unpruned ancestors as they are."""
    path = data_path("octomap", "geb079.bt")
    rng = np.random.default_rng(4)
    origin = np.array([0.0, 0.0, 1.0])
    d = rng.normal(size=(20_000, 3))
    points = origin + 6 * d / np.linalg.norm(d, axis=1, keepdims=True) * rng.uniform(
        0.1, 1, (len(d), 1))
    maps = {}
    for method in ("reference", *METHODS):
        m = OccupancyOctree.load(path)
        if expand:
            m.expand()
        if method == "reference":   # liboctomap's insertPointCloud: updateNode per cell
            m._insert_point_cloud(points.astype(np.float32), origin.astype(np.float32),
                                  -1.0, False)
        else:
            m.insert_scan(points, origin, method=method)
        maps[method] = m
    for method in METHODS:
        assert_same_leaves(maps[method], maps["reference"])


@pytest.mark.parametrize("method", ["plain", "culling"])
def test_unnecessary_traversals_are_the_visits_of_no_op_cells(method):
    """The diagnostic count: visits of the walked rays to cells that are fully free
    before the scan and hold no end point, checked against the Python traversal."""
    from octomap_reference import logodds32, ray_keys
    scans = room_sequence(np.random.default_rng(8), n_scans=7, n_points=150)
    m = build(scans[:-1], 0.2, mode="ray")
    points, origin = (np.asarray(a, np.float32) for a in scans[-1])
    floor = logodds32(m.clamping_min)
    ends = {tuple(k) for k in (np.floor(points / 0.2).astype(int) + 32768).tolist()}
    expected = 0
    for p in points:
        for key in ray_keys(origin, p, 0.2):
            center = (np.array(key) - 32768 + 0.5) * 0.2
            value = m.log_odds([center])[0]
            if key not in ends and value <= floor:
                expected += 1
    stats = m._insert_batch(points, origin, -1.0, True, method == "culling", diagnose=True)
    if method == "plain":
        assert stats[5] == expected > 0
    else:       # the region spares some (a small one only hides rays: kMinWalkBackRegion)
        assert 0 < stats[0] < 128 and 0 <= stats[5] < expected


@pytest.mark.parametrize("cls", [OccupancyOctree, GridMap])
@pytest.mark.parametrize("mode, method", [("scan", "culling"), ("ray", "plain"),
                                          ("ray", "superray+culling"), ("scan", "superray")])
def test_ray_ends_out_of_range_leave_the_map_unchanged(cls, mode, method):
    """The compiled pipeline checks the key range of the ray ends before any update."""
    m = cls(0.1)
    m.insert_scan([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], [0, 0, 0], mode=mode, method=method)
    before = m.to_bytes("ot") if cls is OccupancyOctree else m.cells()
    bad = [[0.5, 0.5, 0.5], [5000.0, 0.0, 0.0], [0.2, 0.2, 0.2]]
    with pytest.raises(ValueError, match=r"1 of 3 points lie outside the .* key range "
                                         r".*\(first: row 1\); the map is unchanged"):
        m.insert_scan(bad, [0, 0, 0], mode=mode, method=method)
    after = m.to_bytes("ot") if cls is OccupancyOctree else m.cells()
    if cls is OccupancyOctree:
        assert after == before
    else:
        assert_array_equal_cells(after, before)
    # a long ray truncated at max_range is fine
    m.insert_scan(bad, [0, 0, 0], mode=mode, method=method, max_range=10.0)


def assert_array_equal_cells(a, b):
    np.testing.assert_array_equal(a.centers, b.centers)
    np.testing.assert_array_equal(a.log_odds, b.log_odds)


@pytest.mark.parametrize("cls", [OccupancyOctree, GridMap])
@pytest.mark.parametrize("mode", ["ray", "scan"])
@pytest.mark.parametrize("n_jobs", [1, 2])
@pytest.mark.parametrize("on_borders", [False, True])
def test_region_spared_cells_and_traversed_cells_add_up_to_the_walk_without_region(
        cls, mode, n_jobs, on_borders):
    """Scan by scan, the visits of the culled insertion and those its region spared
    (hidden rays, rays walked back, region prefixes walked past) are the visits of
    occgp's walk without a region: ray mode's "plain" method, and in scan mode super
    rays with a threshold no cell reaches (every ray walked on its own). With the
    room's walls on cell borders, a hidden ray whose walk would stop short of its end
    cell (its end point on the face it enters by) counts as reaching it: at most one
    visit too many a hidden ray; off the borders, exactly."""
    scans = room_sequence(np.random.default_rng(3))
    if not on_borders:
        shift = np.array([0.0123, 0.0371, 0.0217])
        scans = [(points + shift, origin + shift) for points, origin in scans]
    plain, culled = cls(0.1, n_jobs=n_jobs), cls(0.1, n_jobs=n_jobs)
    without = (dict(method="plain") if mode == "ray"
               else dict(method="superray", superray_threshold=2**31 - 1))
    spared = hidden = 0
    for points, origin in scans:
        plain.insert_scan(points, origin, mode=mode, **without)
        culled.insert_scan(points, origin, mode=mode, method="culling")
        a, b = plain.last_insert_, culled.last_insert_
        assert a["region_spared_cells"] == 0 and a["rays"] == b["rays"]
        extra = b["traversed_cells"] + b["region_spared_cells"] - a["traversed_cells"]
        assert 0 <= extra <= (b["culled_rays"] if on_borders else 0)
        spared += b["region_spared_cells"]
        hidden += b["culled_rays"]
    assert spared > 0 and hidden > 0
