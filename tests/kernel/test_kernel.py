"""Kernel inference on cells: the sparse kernel, BGK's samples and its alpha / beta."""

import pickle

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from occgp import AKIMap, BGKMap
from occgp.kernel import sparse_kernel, voxel_centroids


def wall_scan(n=41, x=2.0):
    return np.column_stack([np.full(n, x), np.linspace(-1, 1, n), np.zeros(n)]), np.zeros(3)


# ---------------------------------------------------------------------- kernel
def test_sparse_kernel_values_and_support():
    r = np.linspace(0, 1.5, 151)
    k = sparse_kernel(r)
    assert k[0] == 1.0
    assert np.all(k[r >= 1] == 0)
    assert np.all(k[r < 1] > 0) and np.all(np.diff(k[r <= 1]) <= 0)     # decreasing
    assert np.all(sparse_kernel(np.linspace(0.999, 1.0, 1001)) >= 0)    # clamped at 0
    expected = (2 + np.cos(2 * np.pi * r)) * (1 - r) / 3 + np.sin(2 * np.pi * r) / (2 * np.pi)
    assert_allclose(k[r < 1], expected[r < 1], rtol=1e-14)
    assert_allclose(sparse_kernel(np.array([1 - 1e-9])), [0.0], atol=1e-15)  # continuous


def test_tabulated_kernel_is_within_3e_8_of_the_formula():
    from occgp._kernel import kernel_from_table
    r2 = np.concatenate([np.linspace(0, 1, 200_001)[:-1],
                         np.random.default_rng(0).uniform(0, 1, 100_000)])
    assert np.max(np.abs(kernel_from_table(r2) - sparse_kernel(np.sqrt(r2)))) < 3e-8
    assert np.all(kernel_from_table(r2) >= 0)


def test_voxel_centroids():
    pts = np.array([[0.01, 0.01, 0.01], [0.03, 0.05, 0.07], [0.25, 0.0, 0.0]])
    c = voxel_centroids(pts, 0.1)
    assert_allclose(c, [[0.02, 0.03, 0.04], [0.25, 0.0, 0.0]])
    assert voxel_centroids(np.empty((0, 3)), 0.1).shape == (0, 3)


# ---------------------------------------------------------------------- BGK
def test_bgk_training_data_follows_la3dm():
    """Hits reduced to centroids, free samples every free_resolution metres (d < length)
    along each beam, one more at length - free_resolution on beams longer than
    free_resolution, and the origin; beams longer than max_range dropped whole with
    far_beams="drop" (la3dm's get_training_data gives 0, 0.5, 0.73, 1.0 for this 1.23 m
    beam)."""
    m = BGKMap(0.1, free_resolution=0.5, max_range=3.0, far_beams="drop")
    points = np.array([[1.22, 0.0, 0.0], [1.24, 0.0, 0.0], [0.0, 5.0, 0.0]])
    samples, labels = m.training_data(points, [0.0, 0.0, 0.0])
    hits = samples[labels == 1]
    frees = samples[labels == 0]
    assert_allclose(hits, [[1.23, 0.0, 0.0]])                   # one centroid, long beam gone
    assert_allclose(np.sort(frees[:, 0]), [0.0, 0.5, 0.73, 1.0])  # origin, 0.5, 1.23 - 0.5, 1.0
    assert_allclose(frees[:, 1:], 0.0)


def test_bgk_cut_beam_gives_the_free_samples_of_a_beam_to_max_range():
    """far_beams="cut" (the default): a beam longer than max_range gives no occupied
    sample, and the free samples of a beam ending at max_range (la3dm's beam_sample:
    every free_resolution metres, and one at max_range - free_resolution)."""
    near, far, cut_end = [[1.23, 0.0, 0.0]], [[0.0, 5.0, 0.0]], [[0.0, 3.0, 0.0]]
    m = BGKMap(0.1, free_resolution=0.5, max_range=3.0)
    assert m.far_beams == "cut"
    samples, labels = m.training_data(np.vstack([near, far]), np.zeros(3))
    assert_allclose(samples[labels == 1], near)             # no hit at 5 m, none at 3 m
    frees = samples[labels == 0]
    on_far = frees[frees[:, 1] > 0]
    assert_allclose(np.sort(on_far[:, 1]), [0.5, 1.0, 1.5, 2.0, 2.5])   # 2.5 twice, merged
    assert_allclose(on_far[:, [0, 2]], 0.0)
    # the same free samples as the scan whose far point lay at max_range
    ref, ref_labels = BGKMap(0.1, free_resolution=0.5).training_data(
        np.vstack([near, cut_end]), np.zeros(3))
    want = ref[ref_labels == 0]
    assert_allclose(frees[np.lexsort(frees.T)], want[np.lexsort(want.T)])


def test_bgk_last_beams_counts_the_kept_and_dropped_beams_of_an_accepted_update():
    m = BGKMap(0.1, max_range=3.0)
    assert m.last_beams_ == (0, 0)
    points = np.array([[1.22, 0.0, 0.0], [1.24, 0.0, 0.0], [0.0, 5.0, 0.0], [0.0, 0.0, 4.0]])
    m.training_data(points, [0.0, 0.0, 0.0])                # a dry run counts nothing
    assert m.last_beams_ == (0, 0)
    m.update(points, [0.0, 0.0, 0.0])
    assert m.last_beams_ == (1, 2)                          # two cubes merged, two far
    m.update(points[2:], [0.0, 0.0, 0.0])                   # every beam cut: free samples
    assert m.last_beams_ == (0, 2) and m.num_cells > 0
    with pytest.raises(ValueError, match="points"):
        m.update([[np.nan, 0.0, 0.0]], [0.0, 0.0, 0.0])
    assert m.last_beams_ == (0, 2)                          # a rejected update changes nothing
    m.update(np.empty((0, 3)), [0.0, 0.0, 0.0])
    assert m.last_beams_ == (0, 0)
    assert BGKMap(0.1, max_range=None).update(points, np.zeros(3)).last_beams_ == (3, 0)
    assert pickle.loads(pickle.dumps(m)).last_beams_ == (0, 0)


def test_bgk_extra_free_sample_only_on_beams_longer_than_free_resolution():
    """la3dm's beam_sample: no free sample on a beam of at most free_resolution; on a
    beam of exactly 2 free_resolution the extra sample falls on the step one (both
    weigh in the centroid of their cube)."""
    m = BGKMap(0.1, free_resolution=0.5, ds_resolution=1e-3)
    for length, expected in [(0.5, [0.0]), (0.3, [0.0]), (0.6, [0.0, 0.1, 0.5]),
                             (1.0, [0.0, 0.5]), (2.2, [0.0, 0.5, 1.0, 1.5, 1.7, 2.0])]:
        samples, labels = m.training_data([[0.0, length, 0.0]], [0.0, 0.0, 0.0])
        assert_allclose(np.sort(samples[labels == 0][:, 1]), expected, atol=1e-12)


def slow_bgk(samples, labels, resolution, ell, sf2=1.0):
    """Cell key -> (alpha, beta) by looping over every sample and cell in Python."""
    cells = {}
    for x, y in zip(samples, labels):
        lo = np.ceil((x - ell) / resolution - 0.5).astype(int)
        hi = np.floor((x + ell) / resolution - 0.5).astype(int)
        for kx in range(lo[0], hi[0] + 1):
            for ky in range(lo[1], hi[1] + 1):
                for kz in range(lo[2], hi[2] + 1):
                    c = (np.array([kx, ky, kz]) + 0.5) * resolution
                    r2 = np.sum((c - x) ** 2) / ell ** 2
                    if r2 >= 1:
                        continue
                    r = np.sqrt(r2)
                    k = sf2 * ((2 + np.cos(2 * np.pi * r)) * (1 - r) / 3
                               + np.sin(2 * np.pi * r) / (2 * np.pi))
                    if k <= 0:          # rounding where the kernel vanishes, as la3dm clamps
                        continue
                    a, b = cells.get((kx, ky, kz), (0.0, 0.0))
                    cells[(kx, ky, kz)] = (a + k * y, b + k * (1 - y))
    return cells


@pytest.mark.slow
def test_bgk_alpha_beta_equal_a_slow_reference():
    rng = np.random.default_rng(0)
    points = rng.uniform(-1, 1, (60, 3)) + [2.0, 0.0, 0.5]
    origin = np.array([0.1, -0.2, 0.3])
    m = BGKMap(0.1, ell=0.25, sf2=0.8).update(points, origin)
    samples, labels = m.training_data(points, origin)
    ref = slow_bgk(samples, labels, 0.1, 0.25, 0.8)
    cells = m.cells()
    keys = np.round(cells.centers / 0.1 - 0.5).astype(int)
    got = {tuple(k): (a - m.prior, b - m.prior) for k, a, b in zip(keys.tolist(), cells.alpha,
                                                                   cells.beta)}
    # the same cells (up to those the kernel reaches with under 1e-12, where rounding
    # decides), the same evidence up to the kernel table's 3e-8
    big = {k for k, (a, b) in ref.items() if a + b > 1e-12}
    assert big <= got.keys()
    assert {k for k, (a, b) in got.items() if a + b > 1e-12} <= ref.keys()
    assert len(big) > 1000
    for key in big:
        assert_allclose(got[key], ref[key], rtol=0, atol=1e-7 * 60)


@pytest.mark.parametrize("resolution, ell, free", [(0.05, 0.2, 0.5), (0.1, 0.2, 0.5),
                                                   (0.2, 0.4, 1.0), (0.25, 0.5, 1.25)])
def test_bgk_length_and_free_spacing_grow_with_coarse_cells(resolution, ell, free):
    """None means ell = max(0.2, 2 resolution) and free_resolution = max(0.5, 5
    resolution): la3dm's 0.2 m and 0.5 m up to 0.1 m cells, scaled beyond; the same
    map bit for bit as those values given."""
    wall, origin = wall60()
    wall = np.vstack([wall, wall * [1.5, 1.0, 1.0] + [0.0, 0.0, 0.3]])
    given = BGKMap(resolution, ell=ell, free_resolution=free)
    assert_same_cells(BGKMap(resolution).update(wall, origin), given.update(wall, origin))
    assert BGKMap(resolution).get_params()["ell"] is None
    # the spacing in use: samples every `free` metres along a beam of 4 m
    samples, labels = BGKMap(resolution, ds_resolution=1e-3).training_data(
        [[4.0, 0.0, 0.0]], origin)
    along = np.sort(samples[labels == 0][:, 0])
    assert_allclose(np.diff(along)[:2], free)


def test_bgk_map_marks_wall_occupied_and_free_space_free():
    points, origin = wall_scan()
    m = BGKMap(0.1).update(points, origin)
    # (beams a little longer than 2 m put a free sample just before the wall: BGK's blur)
    wall_p = m.occupancy(points)
    assert np.all(wall_p > 0.5) and np.mean(wall_p) > 0.8
    assert m.occupancy([[0.5, 0.0, 0.0]])[0] < 0.1
    assert np.isnan(m.occupancy([[5.0, 5.0, 5.0]])[0])                  # unknown
    assert m.is_occupied([[2.0, 0.0, 0.0], [0.5, 0, 0], [5, 5, 5]]).tolist() == [True, False,
                                                                             False]
    var = m.variance(points[20:21])[0]
    p = m.occupancy(points[20:21])[0]
    assert 0 < var < p * (1 - p)


def test_bgk_evidence_adds_up_over_scans():
    points, origin = wall_scan()
    once = BGKMap(0.1).update(points, origin)
    twice = BGKMap(0.1).update(points, origin).update(points, origin)
    a1, a2 = once.cells(), twice.cells()
    assert_array_equal(a1.centers, a2.centers)
    assert_allclose(a2.alpha - twice.prior, 2 * (a1.alpha - once.prior), rtol=1e-12)


def test_empty_scan_is_a_no_op_and_one_point_works():
    m = BGKMap(0.1)
    assert m.update(np.empty((0, 3)), [0, 0, 0]) is m and m.num_cells == 0
    m.update([[1.0, 0.0, 0.0]], [0, 0, 0])
    assert m.num_cells > 0 and m.occupancy([[1.0, 0.0, 0.0]])[0] > 0.5


def test_pickle_keeps_every_cell():
    points, origin = wall_scan()
    m = BGKMap(0.1, ell=0.3).update(points, origin)
    back = pickle.loads(pickle.dumps(m))
    assert back.get_params() == m.get_params()
    for a, b in zip(m.cells(), back.cells()):
        assert_array_equal(a, b)


@pytest.mark.parametrize("kwargs, exc, match", [
    (dict(resolution=0.0), ValueError, r"resolution must lie in \(0.0, inf\), got 0.0"),
    (dict(ell=-1.0), ValueError, "ell must lie in"),
    (dict(sf2="1"), TypeError, "sf2 must be a real number, got str"),
    (dict(free_resolution=np.nan), ValueError, "free_resolution must lie in"),
    (dict(prior=0.0), ValueError, "prior must lie in"),
    (dict(max_range=0.0), ValueError, "max_range must lie in"),
])
def test_bad_parameters_are_rejected(kwargs, exc, match):
    with pytest.raises(exc, match=match):
        BGKMap(**kwargs)


@pytest.mark.parametrize("points, origin, exc, match", [
    (np.zeros((3, 2)), [0, 0, 0], ValueError, r"points must have shape \(n_points, 3\)"),
    ([[np.nan, 0, 0]], [0, 0, 0], ValueError, "points must be finite"),
    ([[1.0, 0, 0]], [0, 0], ValueError, r"origin must have shape \(3,\)"),
    ([["a", "b", "c"]], [0, 0, 0], TypeError, "points must hold real numbers"),
    ([[1e6, 0, 0]], [0, 0, 0], ValueError, "1 of 1 points lie outside the map's key range"),
])
def test_bad_scans_leave_the_map_unchanged(points, origin, exc, match):
    wall, o = wall_scan()
    m = BGKMap(0.1).update(wall, o)
    before = m.cells()
    with pytest.raises(exc, match=match):
        m.update(points, origin)
    after = m.cells()
    assert_array_equal(before.alpha, after.alpha)


def test_to_octree_holds_the_posterior_means(tmp_path):
    points, origin = wall_scan()
    m = BGKMap(0.1).update(points, origin)
    tree = m.to_octree()
    cells = m.cells()
    p = cells.alpha / (cells.alpha + cells.beta)
    got = tree.occupancy(cells.centers)
    assert_allclose(got, np.clip(p, 0.001, 0.999), rtol=1e-5)
    assert np.isnan(tree.occupancy([[5.0, 5.0, 5.0]])[0])
    tree.save(tmp_path / "bgk.bt")                              # OctoMap's viewers read it
    from occgp import OccupancyOctree
    back = OccupancyOctree.load(tmp_path / "bgk.bt")
    assert_array_equal(back.is_occupied(cells.centers), tree.is_occupied(cells.centers))


# ---------------------------------------------------------------------- max_range
KERNEL_MAPS = {"bgk": lambda **kw: BGKMap(0.1, **kw),
               "akimap": lambda **kw: AKIMap(0.1, random_state=0, **kw)}


def wall_and_far_point():
    """A wall 2 m ahead (+x) of the origin and one end point 6 m to its side (+y)."""
    y, z = np.meshgrid(np.linspace(-1, 1, 21), np.linspace(-0.5, 0.5, 11))
    wall = np.column_stack([np.full(y.size, 2.0), y.ravel(), z.ravel()])
    return np.vstack([wall, [[0.0, 6.0, 0.0]]]), np.zeros(3)


@pytest.mark.parametrize("make", KERNEL_MAPS.values(), ids=KERNEL_MAPS.keys())
def test_max_range_cuts_a_far_beam_free_up_to_it_and_none_beyond(make):
    points, origin = wall_and_far_point()
    m = make(max_range=4.0).update(points, origin)
    assert m.far_beams == "cut"
    c = m.cells()
    on_beam = (np.abs(c.centers[:, 0]) < 0.3) & (np.abs(c.centers[:, 2]) < 0.3) \
        & (c.centers[:, 1] > 1.5)                      # away from the beams to the wall
    y = c.centers[on_beam, 1]
    occupancy = c.alpha[on_beam] / (c.alpha[on_beam] + c.beta[on_beam])
    assert len(y) and y.max() > 3.3                    # free evidence up to max_range
    assert y.max() < 4.0 + 0.25                        # and none beyond (a kernel's reach)
    assert np.all(occupancy < 0.5)                     # free only: no occupied cut end
    assert not m.is_occupied([[0.0, 4.0, 0.0], [0.0, 3.95, 0.0]]).any()
    assert np.isnan(m.occupancy([[0.0, 6.0, 0.0], [0.0, 5.0, 0.0]])).all()
    # without a limit the far point is occupied; la3dm's rule drops its beam whole
    assert make().update(points, origin).is_occupied([[0.0, 6.0, 0.0]])[0]
    dropped = make(max_range=4.0, far_beams="drop").update(points, origin).cells()
    assert not np.any((np.abs(dropped.centers[:, 0]) < 0.3)
                      & (np.abs(dropped.centers[:, 2]) < 0.3) & (dropped.centers[:, 1] > 1.5))


@pytest.mark.parametrize("make", KERNEL_MAPS.values(), ids=KERNEL_MAPS.keys())
def test_far_beams_changes_nothing_without_max_range_or_far_beams(make):
    """The map of max_range=None is the one either rule gives, and a limit beyond every
    beam gives it too (the map of a scan whose beams all lie within max_range)."""
    points, origin = wall_and_far_point()
    want = make().update(points, origin).update(points + 0.03, origin)
    for kw in (dict(far_beams="cut"), dict(far_beams="drop"), dict(max_range=1e30),
               dict(max_range=6.5, far_beams="drop")):
        m = make(**kw).update(points, origin).update(points + 0.03, origin)
        assert_same_cells(m, want)


@pytest.mark.parametrize("make", KERNEL_MAPS.values(), ids=KERNEL_MAPS.keys())
def test_every_beam_cut_gives_free_evidence_only(make):
    points, origin = wall_and_far_point()
    m = make(max_range=1.0).update(points, origin)
    assert m.num_cells > 0 and not m.is_occupied(m.cells().centers).any()
    assert make(max_range=1.0, far_beams="drop").update(points, origin).num_cells == 0


@pytest.mark.parametrize("value, exc", [("keep", ValueError), (None, ValueError),
                                        ("CUT", ValueError), (1, ValueError)])
def test_bad_far_beams(value, exc):
    for make in KERNEL_MAPS.values():
        with pytest.raises(exc, match=r"far_beams must be one of \('cut', 'drop'\)"):
            make(far_beams=value)
        m = make(max_range=1.0)
        m.far_beams = value                            # set as an attribute: checked on use
        with pytest.raises(exc, match="far_beams must be one of"):
            m.update(*wall_and_far_point())
        assert m.num_cells == 0


# ---------------------------------------------------------------------- limits and bad input
def wall60():
    return np.column_stack([np.full(60, 2.0), np.linspace(-1, 1, 60), np.zeros(60)]), \
        np.zeros(3)


def assert_same_cells(a, b):
    for x, y in zip(a.cells(), b.cells()):
        assert_array_equal(x, y)


@pytest.mark.parametrize("kwargs, match", [
    (dict(resolution=0.1, ell=100.0), r"would visit 7.2e\+11 cells .* max_cells_per_update="
                                      r"1073741824; .* a smaller ell; the map is unchanged"),
    (dict(resolution=1e-4, ell=0.2), r"would visit .* cells .*at resolution 0.0001 m\), "
                                     r"more than max_cells_per_update"),
    (dict(resolution=0.1, max_cells_per_update=1000), "max_cells_per_update=1000"),
    (dict(resolution=0.1, free_resolution=1e-9), r"free_resolution=1e-09 would make 4.39e\+10 "
                                                 r"free samples .* more than the 67108864"),
    (dict(resolution=0.1, ds_resolution=1e-9), r"ds_resolution=1e-09 is too small for this "
                                               r"scan: the points span 2e\+09 cubes"),
    (dict(resolution=0.1, sf2=1e35), r"kernel weights of this update reach 1e\+35 .* overflow"),
    (dict(resolution=0.1, sf2=1e-35), r"kernel weights of this update fall to 1e-35 .* "
                                      r"underflow"),
])
def test_too_large_or_degenerate_updates_are_refused_before_any_change(kwargs, match):
    """BGKMap(0.1, ell=100) or BGKMap(1e-4, ell=0.2) on a 60-point wall would take minutes:
    refused up front, and the map keeps what it had."""
    wall, origin = wall60()
    m = BGKMap(**kwargs)
    with pytest.raises(ValueError, match=match):
        m.update(wall, origin)
    assert m.num_cells == 0
    if kwargs["resolution"] == 0.1:             # a map that had cells keeps them
        full = BGKMap(0.1).update(wall + [0, 0, 1], origin)
        before = full.cells()
        for k, v in m.get_params().items():
            setattr(full, k, v) if k != "resolution" else None
        with pytest.raises(ValueError, match=match):
            full.update(wall, origin)
        for x, y in zip(before, full.cells()):
            assert_array_equal(x, y)


def test_max_cells_per_update_can_be_raised():
    wall, origin = wall60()
    with pytest.raises(ValueError, match="max_cells_per_update=100000"):
        BGKMap(0.1, ell=1.0, max_cells_per_update=100_000).update(wall, origin)
    m = BGKMap(0.1, ell=1.0, max_cells_per_update=10**7).update(wall, origin)
    assert_same_cells(m, BGKMap(0.1, ell=1.0).update(wall, origin))


@pytest.mark.parametrize("value, exc, match", [
    (1.5, TypeError, "max_cells_per_update must be a positive int, got float"),
    (True, TypeError, "max_cells_per_update must be a positive int, got bool"),
    (0, ValueError, "max_cells_per_update must be a positive int, got 0"),
    ("9", TypeError, "max_cells_per_update must be a positive int, got str"),
])
def test_bad_max_cells_per_update(value, exc, match):
    with pytest.raises(exc, match=match):
        BGKMap(0.1, max_cells_per_update=value)


def test_extreme_parameters_give_the_right_map():
    wall, origin = wall60()
    # cells of 1e20 m and ell in metres: no cell center within ell of any sample
    assert BGKMap(1e20, ell=0.2).update(wall, origin).num_cells == 0
    # free samples farther apart than every beam: only the origin is free
    samples, labels = BGKMap(0.1, free_resolution=1e30).training_data(wall, origin)
    assert_array_equal(samples[labels == 0], [[0.0, 0.0, 0.0]])
    # a max_range beyond every beam drops nothing
    assert_same_cells(BGKMap(0.1, max_range=1e30).update(wall, origin),
                      BGKMap(0.1, max_range=None).update(wall, origin))
    # cubes of 1e20 m: one hit centroid on each side of the face y = 0
    samples, labels = BGKMap(0.1, ds_resolution=1e20).training_data(wall, origin)
    assert labels.tolist().count(1) == 2
    with pytest.raises(ValueError, match=r"ell must be at least 1e-150 m .*got 1e-200"):
        BGKMap(0.1, ell=1e-200)


@pytest.mark.parametrize("point", [[1e30, 0, 0], [1e39, 0, 0], [-1e30, 5, 5]])
def test_far_points_are_outside_the_key_range(point):
    with pytest.raises(ValueError, match=r"1 of 1 points lie outside the map's key range "
                                         r"\[-3276.8, 3276.8\) m"):
        BGKMap(0.1).update([point], [0, 0, 0])


@pytest.mark.parametrize("name, value, exc, match", [
    ("ell", "0.2", TypeError, "ell must be a real number, got str"),
    ("ell", -1.0, ValueError, "ell must lie in"),
    ("free_resolution", "0.5", TypeError, "free_resolution must be a real number"),
    ("max_range", np.inf, ValueError, "max_range must lie in"),
    ("prior", 0.0, ValueError, "prior must lie in"),
    ("n_jobs", 1.5, ValueError, "n_jobs must be None"),
    ("max_cells_per_update", 0.5, TypeError, "max_cells_per_update must be a positive int"),
])
def test_parameters_changed_after_construction_are_checked_on_update(name, value, exc, match):
    wall, origin = wall60()
    m = BGKMap(0.1).update(wall, origin)
    before = m._cells_arrays()
    setattr(m, name, value)
    with pytest.raises(exc, match=match):
        m.update(wall, origin)
    for x, y in zip(before, m._cells_arrays()):
        assert_array_equal(x, y)


def test_resolution_is_fixed():
    m = BGKMap(0.1)
    with pytest.raises(AttributeError):
        m.resolution = 0.2


def test_free_samples_in_chunks_equal_all_at_once(monkeypatch):
    import occgp.kernel._kernel_samples as _kernel_samples
    wall, origin = wall60()
    m = BGKMap(0.05, free_resolution=0.1, max_range=None)
    whole = m.training_data(wall, origin)
    monkeypatch.setattr(_kernel_samples, "FREE_CHUNK", 7)
    chunked = m.training_data(wall, origin)
    assert_array_equal(whole[1], chunked[1])
    assert_allclose(whole[0], chunked[0], rtol=0, atol=1e-12)


def test_far_apart_samples_in_a_wide_key_box():
    """Two samples 6 km apart: the update sums only the tiles their supports meet
    (not the key box between them), and gives the union of their maps."""
    a, b = [[1.0, 1.0, -3000.0]], [[30.0, 30.0, 3000.0]]
    kw = dict(free_resolution=1e6, max_range=None)
    both = BGKMap(0.1, **kw).update(a + b, [0.0, 0.0, 0.0])
    one = BGKMap(0.1, **kw).update(a, [0.0, 0.0, 0.0]).update(b, [0.0, 0.0, 0.0])
    x, y = both.cells(), one.cells()
    assert_array_equal(x.centers, y.centers)
    far = np.linalg.norm(x.centers, axis=1) > 1.0      # (two updates: the origin twice)
    assert_allclose(x.alpha, y.alpha, rtol=1e-6)
    assert_allclose(x.beta[far], y.beta[far], rtol=1e-6)
    assert far.sum() > 0 and (~far).sum() > 0
    assert both.occupancy([[30.0, 30.0, 3000.0]])[0] > 0.5


@pytest.mark.parametrize("make", [lambda: BGKMap(0.05, max_range=None),
                                  lambda: AKIMap(0.05, random_state=0)])
def test_cells_do_not_depend_on_where_the_tiles_cut(make):
    """An update sums its evidence in tiles of 64 cells a side counted from the lowest
    key it reaches; a point far behind the sensor moves every cut (on each axis, by
    a number of cells that is no multiple of 64), yet no cell of the wall (160 cells
    wide: cut twice) changes, not even in its last bit."""
    y, z = np.meshgrid(np.linspace(-4, 4, 41), np.linspace(-1, 1, 11))
    wall = np.column_stack([np.full(y.size, 3.0), y.ravel(), z.ravel()])
    origin = np.zeros(3)
    alone = make().update(wall, origin)
    behind = make().update(np.vstack([wall, [[-1.7, -5.3, -2.1]]]), origin)
    a, b = alone.cells(), behind.cells()
    near = a.centers[:, 0] > 1.5               # away from the origin and the far beam
    assert near.sum() > 10000
    idx = np.flatnonzero(np.isin(_keys(b.centers), _keys(a.centers[near])))
    assert_array_equal(b.centers[idx], a.centers[near])
    assert_array_equal(b.alpha[idx], a.alpha[near])
    assert_array_equal(b.beta[idx], a.beta[near])


def _keys(centers):
    k = np.round(centers / 0.05 - 0.5).astype(np.int64) + (1 << 20)
    return (k[:, 2] << 42) | (k[:, 1] << 21) | k[:, 0]


@pytest.mark.parametrize("n_threads", [1, 2])
def test_samples_in_chunks_of_tile_pairs_give_the_same_map(n_threads):
    """The accumulation takes the samples in chunks of at most `max_pairs` (tile,
    sample) pairs; every chunk size (1: one sample a chunk) gives the same cells, up
    to the float32 rounding of adding each chunk's sums to the cells."""
    points, origin = wall_scan(41, 6.0)
    m = BGKMap(0.05, ell=0.4, max_range=None)
    samples, labels = m.training_data(points, origin)
    precision, extent, weights, sf2, _ = m._kernels(m._validated_params(), samples,
                                                    labels, origin)
    args = (np.ascontiguousarray(samples), labels, precision, extent, weights, sf2)
    maps = []
    for max_pairs in (1 << 22, 50, 1):
        k = BGKMap(0.05)
        n = k._accumulate(*args, n_threads, max_pairs)
        maps.append((n, k.cells()))
    (n0, c0), rest = maps[0], maps[1:]
    assert n0 > 10000
    for n, c in rest:
        assert n == n0
        assert_array_equal(c.centers, c0.centers)
        assert_allclose(c.alpha, c0.alpha, rtol=1e-6)
        assert_allclose(c.beta, c0.beta, rtol=1e-6)


@pytest.mark.parametrize("bad, match", [
    (lambda k, a, b: (k.astype(np.int64), a, b), "expected cell keys uint16"),
    (lambda k, a, b: (k, a[:-1], b), "expected cell keys uint16"),
    (lambda k, a, b: (k, a, np.full_like(b, np.nan)), "alpha and beta must be finite"),
    (lambda k, a, b: (k[:, :2].copy(), a, b), "expected cell keys uint16"),
])
def test_corrupt_pickle_data_is_rejected(bad, match):
    from occgp.kernel import _restore
    wall, origin = wall60()
    m = BGKMap(0.1).update(wall, origin)
    fn, args = m.__reduce__()
    cls, params, keys, alpha, beta, extra = args
    with pytest.raises(ValueError, match=match):
        fn(cls, params, *bad(keys, alpha, beta), extra)
    with pytest.raises(ValueError, match="corrupt pickle of a kernel map"):
        _restore(dict, params, keys, alpha, beta, extra)


def test_sparse_kernel_and_voxel_centroids_check_their_input():
    assert_allclose(sparse_kernel([[0.0, 2.0], [-0.5, np.nan]]),
                    [[1.0, 0.0], [sparse_kernel([0.5])[0], np.nan]])
    assert sparse_kernel(np.array([0, 1])).tolist() == [1.0, 0.0]
    with pytest.raises(TypeError, match="r must hold real numbers, got dtype <U1"):
        sparse_kernel(["a"])
    with pytest.raises(ValueError, match=r"points must have shape \(n_points, 3\)"):
        voxel_centroids(np.zeros((2, 2)), 0.1)
    with pytest.raises(ValueError, match=r"size must lie in \(0.0, inf\)"):
        voxel_centroids(np.zeros((2, 3)), -1.0)
    with pytest.raises(ValueError, match="size=1e-09 is too small"):
        voxel_centroids([[0, 0, 0], [1, 0, 0]], 1e-9)
