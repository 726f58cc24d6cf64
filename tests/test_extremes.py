"""Extreme input to the log-odds maps: resolutions, coordinates and rays at the edges of
single precision. Each case gives a clear error or the map the method's rules define;
the cases that used to crash or hang run in a child process with a time limit, so that
a regression is reported as a failure of that case."""

import subprocess
import sys
import textwrap

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from occgp import GridMap, OccupancyOctree
from occgp._validation import RESOLUTION_RANGE
from _helpers import assert_same_leaves

ALL_METHODS = ["plain", "auto", "culling", "superray", "superray+culling"]


def run_isolated(code: str, timeout: float = 60.0) -> str:
    """Run `code` in a fresh interpreter; fail on a crash, a hang or a non-zero exit."""
    try:
        proc = subprocess.run([sys.executable, "-c", textwrap.dedent(code)],
                              capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        pytest.fail(f"hung (> {timeout} s):\n{code}")
    if proc.returncode != 0:
        pytest.fail(f"exit code {proc.returncode} (negative: killed by that signal):\n"
                    f"{code}\n{proc.stderr[-2000:]}")
    return proc.stdout


@pytest.mark.parametrize("cls", [OccupancyOctree, GridMap])
@pytest.mark.parametrize("resolution", [1e20, 1e15, 1e-16, 1e-25, 1e300])
def test_resolution_outside_the_sound_range_is_rejected(cls, resolution):
    with pytest.raises(ValueError, match=r"resolution must lie in \[1e-15, 1e\+14\] m"):
        cls(resolution)


@pytest.mark.parametrize("resolution", [1e20, 1e-25])
def test_file_header_resolution_outside_the_sound_range_is_rejected(resolution):
    data = OccupancyOctree(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0]).to_bytes("bt")
    data = data.replace(b"res 0.1", b"res " + repr(resolution).encode())
    with pytest.raises(ValueError, match=r"data: the header's resolution must lie in"):
        OccupancyOctree.from_bytes(data)


@pytest.mark.slow
def test_former_segfault_and_hangs_now_raise():
    """liboctomap's traversal overflowed its key buffer (segfault) or never ended."""
    out = run_isolated("""
        from occgp import GridMap, OccupancyOctree
        for build in (lambda: OccupancyOctree(1e20).insert_scan(
                          [[3e20, 5e19, 5e19]], [5e19] * 3, method="plain"),
                      lambda: OccupancyOctree(1e20).insert_scan([[3e20, 5e19, 5e19]], [5e19] * 3),
                      lambda: GridMap(1e20).insert_scan([[3e20, 5e19, 5e19]], [5e19] * 3),
                      lambda: OccupancyOctree(1e-25).insert_scan(
                          [[3e-25, 5e-26, 5e-26]], [5e-26] * 3, method="plain")):
            try:
                build()
            except ValueError as exc:
                print("rejected:", exc)
    """)
    assert out.count("rejected: resolution must lie in") == 4


@pytest.mark.parametrize("cls", [pytest.param(OccupancyOctree, marks=pytest.mark.slow), GridMap])
@pytest.mark.parametrize("resolution", RESOLUTION_RANGE)
def test_rays_across_the_whole_key_range_at_the_resolution_bounds(cls, resolution):
    """At both ends of the range every ray in the key range is walked, by every method."""
    lo, hi = (np.array([-1, 1]) * (32768 * resolution * (1 - 1e-5)))
    points = np.array([[lo, lo, lo], [hi, hi, hi], [lo, hi, lo], [hi, lo, 0.0]])
    origin = np.array([hi, lo, hi])
    methods = ALL_METHODS if cls is OccupancyOctree else ["plain", "auto"]
    maps = [cls(resolution).insert_scan(points, origin, method=m) for m in methods]
    cells = maps[0].leaves() if cls is OccupancyOctree else maps[0].cells()
    assert len(cells.sizes) > 3 * 65536          # the diagonal rays crossed the key range
    for other in maps[1:]:
        if cls is OccupancyOctree:
            assert_same_leaves(other, maps[0])
        else:
            assert_array_equal(other.cells().log_odds, maps[0].cells().log_odds)


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["scan", "ray"])
def test_ray_longer_than_liboctomaps_key_buffer(mode):
    """insertPointCloud's KeyRay holds 100000 keys and is not checked (a segfault): such a
    ray goes through occgp's traversal, which gives the same cells."""
    points = [[3276.0, 3276.0, 3276.0], [1.0, 2.0, 0.5]]
    origin = [-3276.0, -3276.0, -3276.0]
    maps = [OccupancyOctree(0.1).insert_scan(points, origin, mode=mode, method=m)
            for m in ALL_METHODS]
    assert maps[0].num_leaves > 196000
    for other in maps[1:]:
        assert_same_leaves(other, maps[0])
    # discretize=True too: liboctomap's rule (one ray per end cell, to its center)
    d = OccupancyOctree(0.1).insert_scan(points + points, origin, discretize=True)
    centers = (np.floor(np.array(points) / 0.1) + 0.5) * 0.1
    assert_same_leaves(d, OccupancyOctree(0.1).insert_scan(centers, origin, method="auto"))


@pytest.mark.parametrize("cls", [OccupancyOctree, GridMap])
@pytest.mark.parametrize("far", [[5.0, 0, 0], [1e20, 0, 0], [1e39, 0, 0], [1e300, 0, 0]])
def test_max_range_cuts_rays_to_far_points(cls, far):
    """A point beyond float range, or so far that its float squared distance overflows,
    still gives a ray cut at max_range: the same map as a point at 5 m."""
    origin = [0.05, 0.05, 0.05]
    methods = ALL_METHODS if cls is OccupancyOctree else ["plain", "auto", "superray"]
    for method in methods:
        m = cls(0.1).insert_scan([far], origin, max_range=2.0, method=method)
        ref = cls(0.1).insert_scan([[5.0, 0, 0]], origin, max_range=2.0, method=method)
        n = m.num_leaves if cls is OccupancyOctree else m.num_cells
        assert n == 20
        got = m.leaves() if cls is OccupancyOctree else m.cells()
        want = ref.leaves() if cls is OccupancyOctree else ref.cells()
        assert_array_equal(got.centers, want.centers)
        assert_array_equal(got.log_odds, want.log_odds)


@pytest.mark.slow
def test_float32_overflowing_point_used_to_hang_with_max_range():
    out = run_isolated("""
        from occgp import GridMap, OccupancyOctree
        for cls in (OccupancyOctree, GridMap):
            for p in ([1e39, 0, 0], [5, 0, 0]):
                m = cls(0.1).insert_scan([p], [1, 0, 0], max_range=1.0)
                print(m.num_leaves if cls is OccupancyOctree else m.num_cells)
    """)
    assert out.split() == ["9"] * 4


@pytest.mark.parametrize("method", ALL_METHODS)
def test_far_point_without_max_range_is_out_of_range_for_every_method(method):
    m = OccupancyOctree(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0])
    before = m.to_bytes()
    for far in ([1e20, 0, 0], [1e39, 0, 0]):
        with pytest.raises(ValueError, match="1 of 1 points lie outside the octree's key range"):
            m.insert_scan([far], [0, 0, 0], method=method)
    assert m.to_bytes() == before


@pytest.mark.parametrize("cls", [OccupancyOctree, GridMap])
@pytest.mark.parametrize("method", ["plain", "auto", "culling"])
def test_ray_too_short_to_walk_is_rejected(cls, method):
    """Across a border on two axes, 2.8e-30 m long: its float squared length is 0 and the
    traversal would never end (liboctomap: buffer overflow)."""
    m = cls(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0])
    n = m.num_leaves if cls is OccupancyOctree else m.num_cells
    with pytest.raises(ValueError, match=r"1 of 1 rays .* shorter than 1.1e-19 m yet cross a "
                                         r"cell border \(first: row 0\)"):
        m.insert_scan([[1e-30, 1e-30, 0.0]], [-1e-30, -1e-30, 0.0], method=method)
    assert (m.num_leaves if cls is OccupancyOctree else m.num_cells) == n
    # within one cell, a ray of any length is fine (nothing to walk)
    m.insert_scan([[1e-30, 1e-30, 0.0]], [2e-30, 2e-30, 0.0], method=method)


def test_cast_rays_normalises_extreme_directions():
    m = OccupancyOctree(0.1).insert_scan([[1.02, 0.05, 0.05]], [0.05, 0.05, 0.05])
    ends, hits = m.cast_rays([0.05, 0.05, 0.05], [[1.0, 0, 0], [1e39, 0, 0], [1e-40, 0, 0],
                                                  [1e300, 1e-300, 0]])
    assert hits.tolist() == [True] * 4
    assert_array_equal(ends, np.repeat(ends[:1], 4, axis=0))


@pytest.mark.parametrize("bad, exc, match", [
    ("5", TypeError, "max_range must be a real number or an array of them, got str"),
    (True, TypeError, "max_range must be a real number, got bool"),
    (np.array(["5"]), TypeError, "max_range must be a real number or an array of them"),
    (np.array([True]), TypeError, "max_range must be a real number or an array .* bool"),
    ([[1.0, 2.0], [3.0]], TypeError, "max_range must be a real number or an array of them"),
    ([1.0, 2.0], ValueError, r"max_range must be a scalar or of shape \(1,\)"),
    (0.0, ValueError, r"max_range must lie in \(0.0, inf\)"),
])
def test_cast_rays_checks_max_range(bad, exc, match):
    m = OccupancyOctree(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0])
    with pytest.raises(exc, match=match):
        m.cast_rays([0, 0, 0], [[1.0, 0, 0]], max_range=bad)


@pytest.mark.parametrize("call, exc, match", [
    (lambda m: m.cast_rays([0, 0, 0], [[0.0, 0, 0]]), ValueError,
     r"directions must be non-zero, got 1 zero vectors \(first: row 0\)"),
    (lambda m: m.cast_rays([0, 0, 0], [[1.0, 0, 0]], ignore_unknown="yes"), TypeError,
     "ignore_unknown must be a bool, got str"),
    (lambda m: m.leaves(occupied_only=1), TypeError, "occupied_only must be a bool, got int"),
    (lambda m: m.leaves(bbox=[["a"] * 3] * 2), TypeError, "bbox must hold real numbers"),
    (lambda m: m.is_occupied([[0, 0, 0]], return_unknown=np.ones(2)), TypeError,
     "return_unknown must be a bool, got ndarray"),
    (lambda m: m.insert_scan([[1.0, 0, 0]], [0, 0, 0], mode=np.ones(2)), ValueError,
     r"mode must be one of \('scan', 'ray'\), got array"),
    (lambda m: m.insert_scan([[1.0, 0, 0]], [0, 0, 0], method=["plain"]), ValueError,
     r"method must be one of .*, got \['plain'\]"),
    (lambda m: m.to_bytes(np.ones(2)), ValueError, "format must be one of"),
    (lambda m: m.save(5), TypeError, "path must be a str or os.PathLike, got int"),
    (lambda m: OccupancyOctree.load(None), TypeError,
     "path must be a str or os.PathLike, got NoneType"),
    (lambda m: m.insert_scan([[1.0, 0, 0]], [0, 0, 0], discretize=True, max_range=0.5,
                             method="plain") and m.insert_scan(
        [[1e5, 0, 0]], [0, 0, 0], discretize=True, max_range=0.5), ValueError,
     r"1 of 1 points \(with discretize=True, before truncation\) lie outside"),
])
def test_octree_arguments_are_checked(call, exc, match):
    m = OccupancyOctree(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0])
    with pytest.raises(exc, match=match):
        call(m)


def test_grid_cells_checks_its_flag():
    with pytest.raises(TypeError, match="occupied_only must be a bool, got str"):
        GridMap(0.1).cells(occupied_only="no")


@pytest.mark.parametrize("cls", [OccupancyOctree, GridMap])
def test_scan_reaching_more_than_max_scan_cells_is_rejected(cls):
    """A scan's cells are counted as they are collected: past MAX_SCAN_CELLS (set low on
    the map here) the scan changes nothing, with every method."""
    points = [[5.0, 0, 0]] * 3 + [[0, 5.0, 0]] * 3      # 99 distinct cells
    methods = ALL_METHODS if cls is OccupancyOctree else ["plain", "auto", "superray"]
    for method in methods:
        m = cls(0.1).insert_scan([[0, 0, 1.0]], [0, 0, 0])
        before = m.cells() if cls is GridMap else m.leaves()
        m.MAX_SCAN_CELLS = 50
        with pytest.raises(ValueError, match=r"the scan's 6 rays reach more than "
                                             r"MAX_SCAN_CELLS=50 cells .* unchanged"):
            m.insert_scan(points, [0, 0, 0], method=method)
        after = m.cells() if cls is GridMap else m.leaves()
        assert_array_equal(after.log_odds, before.log_odds)
        m.MAX_SCAN_CELLS = 110                  # 306 cell visits, 99 distinct cells
        m.insert_scan(points, [0, 0, 0], method=method)
        ref = cls(0.1).insert_scan([[0, 0, 1.0]], [0, 0, 0]).insert_scan(points, [0, 0, 0])
        if cls is OccupancyOctree:
            assert_same_leaves(m, ref)           # the plain method's own map
        else:
            assert_array_equal(m.cells().log_odds, ref.cells().log_odds)


def test_max_scan_cells_is_checked():
    m = OccupancyOctree(0.1)
    m.MAX_SCAN_CELLS = 0
    with pytest.raises(ValueError, match=r"MAX_SCAN_CELLS must lie in \[1, 4611686018427387904\], got 0"):
        m.insert_scan([[1.0, 0, 0]], [0, 0, 0])
