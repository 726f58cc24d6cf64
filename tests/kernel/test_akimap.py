"""AKIMap: samples, bandwidths (covariance, fallback, Eq. 3.7 scale), evidence, API."""

import pickle

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from occgp import AKIMap, BGKMap
from occgp.kernel import sparse_kernel


def wall_scan(ny=21, nz=11, x=2.0):
    y, z = np.meshgrid(np.linspace(-1, 1, ny), np.linspace(-0.5, 0.5, nz))
    return np.column_stack([np.full(y.size, x), y.ravel(), z.ravel()]), np.zeros(3)


def neighbours(samples, labels, i, origin, res, big_r=0.5, schedule_range=8.0):
    """Indices of the samples within sample i's search radius (brute force; the
    reference code's 8 m schedule, which the tests give the maps)."""
    d = np.linalg.norm(samples[i] - origin)
    radius = min((big_r - res) / schedule_range * d + res, big_r)
    near = np.flatnonzero(np.sum((samples - samples[i]) ** 2, axis=1) <= radius ** 2)
    return near[labels[near] == labels[i]], near[labels[near] != labels[i]]


def loss(c, r2, target):
    """Eq. 3.7 up to the constant |Sigma|^-1/2 / 2, for H = c^2 Sigma."""
    k = sparse_kernel(np.sqrt(r2) / c)
    return np.sum((target - k) ** 2) / c ** 3


# ---------------------------------------------------------------------- samples
def test_training_data_follows_the_reference_sampling():
    """End points one per cell (the first), then one random free point in each
    free_sample_distance interval starting half a distance from the origin; cells
    already holding a sample take none."""
    m = AKIMap(0.1, random_state=0)
    points = np.array([[2.02, 0.0, 0.0], [2.04, 0.0, 0.0], [0.0, 1.3, 0.0]])
    samples, labels = m.training_data(points, [0.0, 0.0, 0.0])
    hits, frees = samples[labels == 1], samples[labels == 0]
    assert_array_equal(hits, points[[0, 2]])                    # first point of the cell
    assert_array_equal(frees[0], [0, 0, 0])                     # the origin
    along_x = frees[1:][frees[1:, 1] == 0][:, 0]
    along_y = frees[1:][frees[1:, 0] == 0][:, 1]
    # beam of 2.02 m: intervals [0.25, 0.75), [0.75, 1.25), [1.25, 1.75), [1.75, 2.25)
    assert len(along_x) in (3, 4) and np.all(along_x < 2.02)
    assert_array_equal(np.floor((along_x - 0.25) / 0.5), np.arange(len(along_x)))
    assert np.all((along_y >= 0.25) & (along_y < 1.3))
    keys = np.floor(samples / 0.1)
    assert len(np.unique(keys, axis=0)) == len(samples)        # one sample per cell


def test_origin_is_a_free_sample_even_in_the_cell_of_an_end_point():
    """As the reference code: the origin is always the first free sample, and free
    samples in its cell or an end point's are skipped."""
    m = AKIMap(0.1, random_state=0)
    points = np.array([[0.05, 0.0, 0.0], [1.4, 0.0, 0.0]])
    samples, labels = m.training_data(points, [0.01, 0.0, 0.0])
    assert_array_equal(samples[labels == 1], points)
    frees = samples[labels == 0]
    assert_array_equal(frees[0], [0.01, 0.0, 0.0])
    keys = np.floor(frees[1:] / 0.1)
    assert not np.any(np.all(keys == [0, 0, 0], axis=1))        # nothing else in that cell
    assert len(frees) >= 2


def test_random_state_makes_samples_and_maps_reproducible():
    points, origin = wall_scan()
    a = AKIMap(0.1, random_state=3).update(points, origin)
    b = AKIMap(0.1, random_state=3).update(points, origin)
    c = AKIMap(0.1, random_state=4).update(points, origin)
    for x, y in zip(a.cells(), b.cells()):
        assert_array_equal(x, y)
    assert not np.array_equal(a.cells().alpha, c.cells().alpha) or \
        a.num_cells != c.num_cells
    gen = AKIMap(0.1, random_state=np.random.default_rng(3)).update(points, origin)
    assert_array_equal(gen.cells().beta, a.cells().beta)


def test_threads_give_the_same_map():
    points, origin = wall_scan(41, 21)
    one = AKIMap(0.05, random_state=1, n_jobs=1).update(points, origin)
    two = AKIMap(0.05, random_state=1, n_jobs=2).update(points, origin)
    for x, y in zip(one.cells(), two.cells()):
        assert_array_equal(x, y)
    bgk1 = BGKMap(0.05, n_jobs=1).update(points, origin)
    bgk2 = BGKMap(0.05, n_jobs=-1).update(points, origin)
    for x, y in zip(bgk1.cells(), bgk2.cells()):
        assert_array_equal(x, y)


# ---------------------------------------------------------------------- bandwidths
@pytest.mark.parametrize("variant", ["published", "occgp"])
def test_plane_covariance_has_the_normal_as_smallest_eigenvector(variant):
    rng = np.random.default_rng(0)
    normal = np.array([0.3, -0.2, 1.0])
    normal /= np.linalg.norm(normal)
    u = np.cross(normal, [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    ab = rng.uniform(-0.4, 0.4, (300, 2))
    samples = ab[:, :1] * u + ab[:, 1:] * v + [5.0, 0.0, 0.0]
    labels = np.ones(len(samples))
    m = AKIMap(0.05, variant=variant, schedule_range=8.0)
    bw = m.bandwidths(samples, labels, [0.0, 0.0, 0.0])
    central = np.flatnonzero(np.all(np.abs(ab) < 0.15, axis=1))
    assert len(central) > 20 and np.all(bw.n_same[central] > 10)
    for i in central:
        w, vec = np.linalg.eigh(np.linalg.inv(bw.precision[i]))
        assert abs(vec[:, 0] @ normal) > 0.99
        assert w[0] < 0.9 * w[1]


def test_isotropic_fallback_with_at_most_two_same_label_neighbours():
    samples = np.array([[2.0, 0.0, 0.0], [2.02, 0.0, 0.0], [4.0, 0.0, 0.0],
                        [4.01, 0.01, 0.0], [4.02, 0.0, 0.01], [3.0, 0.0, 0.0]])
    labels = np.array([1, 1, 1, 1, 1, 0])
    published = AKIMap(0.05, variant="published").bandwidths(samples, labels, [0, 0, 0])
    assert_array_equal(published.n_same, [2, 2, 3, 3, 3, 1])
    for i in (0, 1, 5):
        assert_allclose(published.precision[i], np.eye(3) / 0.05 ** 2)
        assert_allclose(published.extent[i], 0.05)
        assert_allclose(published.weight[i], 0.05 ** -3)
    assert not np.allclose(published.precision[2], np.eye(3) / 0.05 ** 2)
    floored = AKIMap(0.05).bandwidths(samples, labels, [0, 0, 0])       # f = 0.15
    h = 0.05 ** 2 + 0.15 ** 2
    assert_allclose(floored.precision[0], np.eye(3) / h)
    assert_allclose(floored.weight[0], h ** -1.5)


def scene_samples():
    """Occupied samples on a wall and free samples in front of it, as one scan gives."""
    points, origin = wall_scan(31, 16)
    m = AKIMap(0.05, random_state=0)
    samples, labels = m.training_data(points, origin)
    return samples, labels, origin


def test_search_radius_reaches_r_at_30_m_by_default():
    """schedule_range defaults to 30 m (a 30 m LiDAR; the reference code's 8 m for its
    simulated sensor): the neighbour counts are those of that schedule."""
    samples, labels, origin = scene_samples()
    assert AKIMap().schedule_range == 30.0
    bw = AKIMap(0.05).bandwidths(samples, labels, origin)
    eight = AKIMap(0.05, schedule_range=8.0).bandwidths(samples, labels, origin)
    for i in np.random.default_rng(3).choice(len(samples), 100, replace=False):
        same, _ = neighbours(samples, labels, i, origin, 0.05, schedule_range=30.0)
        assert bw.n_same[i] == len(same)
    assert np.mean(bw.n_same) < np.mean(eight.n_same)


@pytest.mark.parametrize("variant", ["published", "occgp"])
def test_covariance_and_scale_against_a_direct_computation(variant):
    """Sigma = scatter of the same-label neighbours about the sample / (n - 2) + 0.001 I;
    the scale lies in [res / sqrt(lambda_max), 1] and does not raise Eq. 3.7 above its
    value at 1."""
    samples, labels, origin = scene_samples()
    res = 0.05
    bw = AKIMap(res, variant=variant, bandwidth_floor=0.0,
                schedule_range=8.0).bandwidths(samples, labels, origin)
    rng = np.random.default_rng(1)
    checked = lowered = 0
    for i in rng.choice(len(samples), 300, replace=False):
        same, other = neighbours(samples, labels, i, origin, res)
        assert bw.n_same[i] == len(same)
        if len(same) <= 2:
            continue
        d = samples[same] - samples[i]
        sigma = d.T @ d / (len(same) - 2) + 0.001 * np.eye(3)
        c = bw.scale[i]
        inv = np.linalg.inv(sigma)
        assert_allclose(bw.precision[i] * c ** 2, inv, rtol=1e-9, atol=1e-12 * np.abs(inv).max())
        assert_allclose(bw.weight[i], np.linalg.det(sigma) ** -0.5 / c ** 3, rtol=1e-9)
        lo = res / np.sqrt(np.linalg.eigvalsh(sigma)[-1])
        assert min(lo, 1.0) * (1 - 1e-7) <= c <= 1.0
        inv = np.linalg.inv(sigma)
        both = np.concatenate([same, other])
        dd = samples[both] - samples[i]
        r2 = np.einsum("ni,ij,nj->n", dd, inv, dd)
        inside = r2 < 1
        target = np.where(np.arange(len(both)) < len(same), sparse_kernel(np.sqrt(r2)), 0.0)
        assert loss(c, r2[inside], target[inside]) <= loss(1.0, r2[inside],
                                                           target[inside]) * (1 + 1e-6)
        checked += 1
        lowered += c < 1
    assert checked > 100 and lowered > 5


@pytest.mark.slow
def test_occgp_minimiser_is_never_worse_than_a_fine_grid_by_much():
    samples, labels, origin = scene_samples()
    res = 0.05
    bw = AKIMap(res, bandwidth_floor=0.0, schedule_range=8.0).bandwidths(samples, labels,
                                                                       origin)
    for i in np.flatnonzero(bw.scale < 1)[:60]:
        same, other = neighbours(samples, labels, i, origin, res)
        d = samples[same] - samples[i]
        sigma = d.T @ d / (len(same) - 2) + 0.001 * np.eye(3)
        both = np.concatenate([same, other])
        dd = samples[both] - samples[i]
        r2 = np.einsum("ni,ij,nj->n", dd, np.linalg.inv(sigma), dd)
        inside = r2 < 1
        target = np.where(np.arange(len(both)) < len(same), sparse_kernel(np.sqrt(r2)), 0.0)
        lo = res / np.sqrt(np.linalg.eigvalsh(sigma)[-1])
        grid = np.geomspace(lo, 1.0, 2000)
        best = min(loss(c, r2[inside], target[inside]) for c in grid)
        assert loss(bw.scale[i], r2[inside], target[inside]) <= best * 1.02 + 1e-12


# ---------------------------------------------------------------------- evidence
def slow_akimap(samples, labels, origin, res, big_r=0.5, schedule_range=8.0):
    """The published AKIMap update in plain Python: neighbours, covariance, the reference
    code's gradient descent, and alpha / beta over every cell in each support box."""
    n = len(samples)
    precisions, weights = [], []
    for i in range(n):
        same, other = neighbours(samples, labels, i, origin, res, big_r, schedule_range)
        if len(same) <= 2:
            precisions.append(np.eye(3) / res ** 2)
            weights.append(res ** -3.0)
            continue
        d = samples[same] - samples[i]
        sigma = d.T @ d / (len(same) - 2) + 0.001 * np.eye(3)
        inv = np.linalg.inv(sigma)
        w0 = np.linalg.det(sigma) ** -0.5
        both = np.concatenate([other, same])
        dd = samples[both] - samples[i]
        r = np.sqrt(np.einsum("ni,ij,nj->n", dd, inv, dd))
        is_same = np.arange(len(both)) >= len(other)
        keep = r < 1
        r, is_same = r[keep], is_same[keep]
        c = 1.0
        lo = res / np.sqrt(np.linalg.eigvalsh(sigma)[-1])
        if (~is_same).any() and lo < 1:
            target = np.where(is_same, sparse_kernel(r), 0.0)
            for epoch in range(1, 101):
                rs = r / c
                rot = 2 * np.pi * rs
                k = np.maximum((2 + np.cos(rot)) * (1 - rs) / 3 + np.sin(rot) / (2 * np.pi), 0)
                kg = ((1 - rs) * rot * np.sin(rot) / (3 * c) + (np.cos(rot) + 2) * rs / (3 * c)
                      - rs * np.cos(rot) / c)
                err = target - k
                w = w0 / c ** 3
                grad = -1.5 * w / c * np.sum(err ** 2) - w * np.sum(err * kg)
                new_c = min(1.0, max(c - 0.01 * grad / epoch, lo))
                if abs(grad) < 1e-3 or abs(0.5 * w * np.sum(err ** 2)) < 1e-3 or \
                        abs(c - new_c) < 1e-3:
                    break
                c = new_c
        precisions.append(inv / c ** 2)
        weights.append(w0 / c ** 3)
    cells = {}
    for x, y, p, w in zip(samples, labels, precisions, weights):
        ext = np.sqrt(np.diag(np.linalg.inv(p)))
        lo = np.ceil((x - ext) / res - 0.5).astype(int)
        hi = np.floor((x + ext) / res - 0.5).astype(int)
        for kx in range(lo[0], hi[0] + 1):
            for ky in range(lo[1], hi[1] + 1):
                for kz in range(lo[2], hi[2] + 1):
                    dc = (np.array([kx, ky, kz]) + 0.5) * res - x
                    r2 = dc @ p @ dc
                    if r2 >= 1:
                        continue
                    k = w * sparse_kernel(np.array([np.sqrt(r2)]))[0]
                    if k <= 0:
                        continue
                    a, b = cells.get((kx, ky, kz), (0.0, 0.0))
                    cells[(kx, ky, kz)] = (a + k * y, b + k * (1 - y))
    return cells


def test_published_alpha_beta_equal_a_slow_reference():
    rng = np.random.default_rng(2)
    y, z = np.meshgrid(np.linspace(-0.3, 0.3, 7), np.linspace(-0.2, 0.2, 5))
    points = np.column_stack([np.full(y.size, 1.2), y.ravel(), z.ravel()])
    points += rng.normal(0, 0.01, points.shape)
    origin = np.array([0.0, 0.05, 0.0])
    m = AKIMap(0.1, variant="published", random_state=5, schedule_range=8.0)
    samples, labels = m.training_data(points, origin)
    m = AKIMap(0.1, variant="published", random_state=5, schedule_range=8.0).update(points,
                                                                                 origin)
    ref = slow_akimap(samples, labels, origin, 0.1)
    cells = m.cells()
    keys = np.round(cells.centers / 0.1 - 0.5).astype(int)
    got = {tuple(k): (a - m.prior, b - m.prior)
           for k, a, b in zip(keys.tolist(), cells.alpha, cells.beta)}
    scale = max(a + b for a, b in ref.values())
    big = {k for k, (a, b) in ref.items() if a + b > 1e-9 * scale}
    assert big <= got.keys() and len(big) > 50
    assert {k for k, (a, b) in got.items() if a + b > 1e-9 * scale} <= ref.keys()
    for key in big:
        assert_allclose(got[key], ref[key], rtol=2e-6, atol=1e-7 * scale)


def test_wall_is_occupied_and_the_space_before_it_free():
    points, origin = wall_scan(x=2.05)                          # on the cell centers
    for variant in AKIMap.VARIANTS:
        m = AKIMap(0.1, variant=variant, random_state=0).update(points, origin)
        assert np.mean(m.occupancy(points) > 0.5) > 0.9
        assert m.occupancy([[1.0, 0.0, 0.0]])[0] < 0.5
        assert np.isnan(m.occupancy([[5.0, 5.0, 5.0]])[0])
        assert m.memory_usage() / m.num_cells < 64


@pytest.mark.parametrize("resolution, step, floor", [(0.01, 0.5, 0.03), (0.05, 0.5, 0.15),
                                                      (0.1, 0.5, 0.15), (0.2, 1.0, 0.3),
                                                      (0.4, 2.0, 0.6)])
def test_free_sample_distance_and_floor_grow_with_coarse_cells(resolution, step, floor):
    """None means a free sample per max(0.5, 5 resolution) metres, R the same, and a
    floor of 3 resolution, at most 0.3 times that distance: the same map bit for bit
    as those values given."""
    points, origin = wall_scan(x=2.05)
    points = np.vstack([points, points * [1.6, 1.0, 1.0] + [0.0, 0.0, 0.4]])
    m = AKIMap(resolution, random_state=0)
    assert m.get_params()["free_sample_distance"] is None
    assert_allclose(m.floor_, floor, rtol=1e-15)
    given = AKIMap(resolution, free_sample_distance=step, max_search_range=step,
                   bandwidth_floor=floor, random_state=0)
    a, b = m.update(points, origin).cells(), given.update(points, origin).cells()
    for x, y in zip(a, b):
        assert_array_equal(x, y)
    # the published variant: the same free samples, no floor
    assert AKIMap(resolution, variant="published").floor_ == 0.0
    s1, l1 = AKIMap(resolution, variant="published", random_state=1).training_data(
        points, origin)
    s2, l2 = AKIMap(resolution, free_sample_distance=step,
                    random_state=1).training_data(points, origin)
    assert_array_equal(s1, s2)


def test_bandwidth_floor_keeps_a_flat_wall_between_cell_centers():
    """A wall on a cell boundary: the published flat kernels (thickness sqrt(0.001) m)
    miss the centers 5 cm away; the floor's do not."""
    points, origin = wall_scan(x=2.0)
    published = AKIMap(0.1, variant="published", random_state=0).update(points, origin)
    occgp = AKIMap(0.1, random_state=0).update(points, origin)
    assert np.mean(published.occupancy(points) > 0.5) < 0.2
    assert np.mean(occgp.occupancy(points) > 0.5) > 0.9


def test_empty_scan_is_a_no_op_and_one_point_works():
    m = AKIMap(0.1, random_state=0)
    assert m.update(np.empty((0, 3)), [0, 0, 0]) is m and m.num_cells == 0
    assert m.last_bandwidths_ is None
    m.update([[1.0, 0.0, 0.0]], [0, 0, 0])
    assert m.num_cells > 0 and m.occupancy([[1.0, 0.0, 0.0]])[0] > 0.5
    assert np.all(m.last_bandwidths_.n_same <= 2)           # every kernel isotropic


def test_pickle_keeps_cells_and_the_random_stream():
    points, origin = wall_scan()
    m = AKIMap(0.1, random_state=0).update(points, origin)
    back = pickle.loads(pickle.dumps(m))
    assert back.get_params() == m.get_params()
    for a, b in zip(m.cells(), back.cells()):
        assert_array_equal(a, b)
    m.update(points + [0.5, 0, 0], origin)
    back.update(points + [0.5, 0, 0], origin)
    for a, b in zip(m.cells(), back.cells()):
        assert_array_equal(a, b)


def test_to_octree_of_akimap(tmp_path):
    points, origin = wall_scan()
    m = AKIMap(0.1, random_state=0).update(points, origin)
    tree = m.to_octree()
    cells = m.cells()
    p = cells.alpha / (cells.alpha + cells.beta)
    assert_allclose(tree.occupancy(cells.centers), np.clip(p, 0.001, 0.999), rtol=1e-5)
    tree.save(tmp_path / "akimap.bt")


@pytest.mark.parametrize("kwargs, exc, match", [
    (dict(resolution=-0.1), ValueError, "resolution must lie in"),
    (dict(free_sample_distance=0.0), ValueError, "free_sample_distance must lie in"),
    (dict(max_search_range=np.inf), ValueError, "max_search_range must lie in"),
    (dict(schedule_range="8"), TypeError, "schedule_range must be a real number"),
    (dict(variant="paper"), ValueError, r"variant must be one of \('occgp', 'published'\)"),
    (dict(bandwidth_floor=-0.1), ValueError, "bandwidth_floor must lie in"),
    (dict(random_state=-1), ValueError, "random_state must be None, a non-negative int"),
    (dict(random_state=True), TypeError, "random_state must be None, a non-negative int"),
    (dict(random_state=1.5), TypeError, "random_state must be None"),
    (dict(n_jobs=0), ValueError, "n_jobs must be None, a positive int"),
    (dict(n_jobs=2.0), ValueError, "n_jobs must be None"),
])
def test_bad_parameters_are_rejected(kwargs, exc, match):
    with pytest.raises(exc, match=match):
        AKIMap(**kwargs)


@pytest.mark.parametrize("points, origin, exc, match", [
    (np.zeros((3, 2)), [0, 0, 0], ValueError, r"points must have shape \(n_points, 3\)"),
    ([[np.inf, 0, 0]], [0, 0, 0], ValueError, "points must be finite"),
    ([[1.0, 0, 0]], [0, 0, np.nan], ValueError, "origin must be finite"),
    ([["a", "b", "c"]], [0, 0, 0], TypeError, "points must hold real numbers"),
    ([[1.0, 0, 0]], [4000.0, 0, 0], ValueError, "1 of 1 origin lie outside the map's key"),
])
def test_bad_scans_leave_the_map_unchanged(points, origin, exc, match):
    wall, o = wall_scan()
    m = AKIMap(0.1, random_state=0).update(wall, o)
    before = m.cells()
    with pytest.raises(exc, match=match):
        m.update(points, origin)
    after = m.cells()
    assert_array_equal(before.alpha, after.alpha)
    assert_array_equal(before.beta, after.beta)


@pytest.mark.parametrize("samples, labels, match", [
    (np.zeros((2, 3)), [1, 2], "labels must be 0 .free. or 1 .occupied."),
    (np.zeros((2, 3)), [1], r"labels must have shape \(2,\)"),
])
def test_bad_bandwidth_input(samples, labels, match):
    with pytest.raises(ValueError, match=match):
        AKIMap(0.1).bandwidths(samples, labels, [0, 0, 0])


# ---------------------------------------------------------------------- limits and bad input
def wall60():
    return np.column_stack([np.full(60, 2.0), np.linspace(-1, 1, 60), np.zeros(60)]), \
        np.zeros(3)


@pytest.mark.parametrize("kwargs, match", [
    (dict(resolution=1e-4), r"would visit .* cells .* more than max_cells_per_update="
                            r"1073741824; .*bandwidth_floor or max_search_range"),
    (dict(resolution=0.1, bandwidth_floor=100.0), r"would visit 7.\d+e\+11 cells"),
    (dict(resolution=0.1, free_sample_distance=1e-9), r"free_sample_distance=1e-09 would "
                                                      r"make 4.39e\+10 free samples"),
    (dict(resolution=0.1, max_search_range=100.0, max_cells_per_update=1000),
     r"would examine .* sample pairs .*max_search_range=100 m"),
    (dict(resolution=1e20), r"kernel weights of this update fall to 1.71e-61 .* underflow"),
    (dict(resolution=1e-12), r"kernel weights of this update reach .* overflow"),
])
def test_too_large_or_degenerate_updates_change_nothing(kwargs, match):
    """Refused up front: no cells, no bandwidths kept, the random stream where it was."""
    wall, origin = wall60()
    if kwargs["resolution"] == 1e-12:
        wall, origin = wall * 1e-12, origin
    m = AKIMap(random_state=0, **kwargs)
    with pytest.raises(ValueError, match=match):
        m.update(wall, origin)
    assert m.num_cells == 0 and m.last_bandwidths_ is None
    fresh = AKIMap(random_state=0, **kwargs)
    assert_array_equal(m._rng.random(5), fresh._rng.random(5))


def test_far_points_and_tiny_resolutions_are_outside_the_key_range():
    with pytest.raises(ValueError, match="1 of 1 points lie outside the map's key range"):
        AKIMap(0.1).update([[1e39, 0, 0]], [0, 0, 0])
    with pytest.raises(ValueError, match=r"60 of 60 points lie outside .*resolution 1e-25"):
        AKIMap(1e-25).update(*wall60())


def test_extreme_search_parameters_give_the_right_bandwidths():
    wall, origin = wall60()
    m = AKIMap(0.1, random_state=0)
    samples, labels = m.training_data(wall, origin)
    # a search radius far below the sample spacing: every kernel isotropic
    bw = AKIMap(0.1, max_search_range=1e-300).bandwidths(samples, labels, origin)
    assert np.all(bw.n_same == 1)
    # a sensor range of 1e-320 m: the radius is R = 0.5 m everywhere (no 0 * inf)
    bw = AKIMap(0.1, schedule_range=1e-320).bandwidths(samples, labels, origin)
    want = [len(neighbours(samples, labels, i, origin, 0.1, 0.5, 1e-300)[0])
            for i in range(len(samples))]
    assert_array_equal(bw.n_same, want)
    # free samples farther apart than every beam: only the origin is free
    s, lab = AKIMap(0.1, free_sample_distance=1e30, random_state=0).training_data(wall, origin)
    assert_array_equal(s[lab == 0], [[0.0, 0.0, 0.0]])


def test_free_samples_in_chunks_equal_all_at_once(monkeypatch):
    import occgp.kernel._kernel_samples as _kernel_samples
    points, origin = wall_scan(11, 5)
    whole = AKIMap(0.05, free_sample_distance=0.1, random_state=2).training_data(points, origin)
    assert len(whole[0]) > 500
    monkeypatch.setattr(_kernel_samples, "FREE_CHUNK", 64)
    chunked = AKIMap(0.05, free_sample_distance=0.1, random_state=2).training_data(points,
                                                                                  origin)
    assert_array_equal(whole[0], chunked[0])
    assert_array_equal(whole[1], chunked[1])


@pytest.mark.parametrize("name, value, exc, match", [
    ("variant", "paper", ValueError, "variant must be one of"),
    ("variant", 3, ValueError, "variant must be one of"),
    ("bandwidth_floor", "0.1", TypeError, "bandwidth_floor must be a real number"),
    ("free_sample_distance", -0.5, ValueError, "free_sample_distance must lie in"),
    ("schedule_range", np.nan, ValueError, "schedule_range must lie in"),
    ("max_cells_per_update", 2.0**40, TypeError, "max_cells_per_update must be a positive"),
])
def test_parameters_changed_after_construction_are_checked_on_update(name, value, exc, match):
    points, origin = wall_scan()
    m = AKIMap(0.1, random_state=0).update(points, origin)
    before = m._cells_arrays()
    setattr(m, name, value)
    with pytest.raises(exc, match=match):
        m.update(points, origin)
    for x, y in zip(before, m._cells_arrays()):
        assert_array_equal(x, y)


def test_bandwidths_reject_bad_labels_and_origin():
    with pytest.raises(TypeError, match="labels must hold 0 or 1, got dtype <U1"):
        AKIMap(0.1).bandwidths(np.zeros((2, 3)), ["a", "b"], [0, 0, 0])
    with pytest.raises(ValueError, match=r"origin must have shape \(3,\)"):
        AKIMap(0.1).bandwidths(np.zeros((2, 3)), [0, 1], [0, 0])
    with pytest.raises(ValueError, match="samples must be finite"):
        AKIMap(0.1).bandwidths([[np.inf, 0, 0]], [0], [0, 0, 0])


def test_corrupt_pickle_data_is_rejected():
    points, origin = wall_scan()
    m = AKIMap(0.1, random_state=0).update(points, origin)
    fn, (cls, params, keys, alpha, beta, extra) = m.__reduce__()
    with pytest.raises(ValueError, match="corrupt pickle of a AKIMap: expected cell keys"):
        fn(cls, params, keys.astype(np.float64), alpha, beta, extra)
    with pytest.raises(ValueError, match="corrupt pickle of a kernel map"):
        fn(cls, params, keys, alpha, beta, [1, 2])


def test_huge_n_jobs_uses_the_cores():
    """n_jobs=2**40 neither overflows a C int nor allocates a scratch row per thread."""
    points, origin = wall_scan()
    a = AKIMap(0.1, random_state=0, n_jobs=2**40).update(points, origin)
    b = AKIMap(0.1, random_state=0, n_jobs=1).update(points, origin)
    for x, y in zip(a.cells(), b.cells()):
        assert_array_equal(x, y)
    c = BGKMap(0.1, n_jobs=-2**40).update(points, origin)
    for x, y in zip(c.cells(), BGKMap(0.1).update(points, origin).cells()):
        assert_array_equal(x, y)


@pytest.mark.parametrize("spread", [2.0, 2000.0])     # few cubes (dense count), many
def test_candidate_pairs_counts_the_neighbour_cubes_samples(spread):
    """The guard's count of the neighbour search's work: for each sample, the samples in
    the 3 x 3 x 3 cubes around its own, by brute force."""
    from occgp.kernel._kernel_samples import candidate_pairs
    rng = np.random.default_rng(3)
    xs = rng.normal(size=(400, 3)) * spread
    xs[7::7] = xs[1:-6:7]                            # repeated points share a cube
    cell = 0.75
    ck = np.floor(xs / cell)
    expected = (np.abs(ck[:, None, :] - ck[None, :, :]).max(axis=2) <= 1).sum()
    assert candidate_pairs(xs, cell) == float(expected)
    assert candidate_pairs(xs[:0], cell) == 0.0
    # the compiled search counts the same pairs (and does no work beyond a limit)
    from occgp._kernel import _akimap_bandwidths
    labels = (np.arange(len(xs)) % 2).astype(np.uint8)
    args = (xs, labels, np.zeros(3), 0.1, cell, 8.0, False, 0.3, 1, cell)
    pairs, out = _akimap_bandwidths(*args, float(expected))
    assert pairs == float(expected) and len(out[0]) == len(xs)
    assert _akimap_bandwidths(*args, float(expected) - 1) == (float(expected), None)


# ---------------------------------------------------------------------- max_range
def far_and_near_scan():
    """A wall 2 m away and a second one 6 m away, seen from the origin."""
    near, origin = wall_scan()
    far, _ = wall_scan(x=6.0)
    return np.vstack([near, far[:, [1, 0, 2]]]), origin


def test_far_beams_drop_drops_the_beams_beyond_max_range_whole():
    points, origin = far_and_near_scan()
    samples, labels = AKIMap(0.1, max_range=3.0, far_beams="drop",
                             random_state=0).training_data(points, origin)
    hits, frees = samples[labels == 1], samples[labels == 0]
    assert_array_equal(hits[:, 0], 2.0)                        # only the near wall's
    # no free sample on a beam to the far wall (those run along +y, x at most 1 / 6)
    assert np.all(np.linalg.norm(frees - origin, axis=1) < np.sqrt(2 ** 2 + 1 + 0.25))
    assert not np.any(frees[:, 1] > np.abs(frees[:, 0]) * 6.0 + 0.01)
    everything, lab = AKIMap(0.1, max_range=None, random_state=0).training_data(points,
                                                                               origin)
    assert (lab == 1).sum() == len(np.unique(np.floor(points / 0.1), axis=0))


def test_max_range_cuts_the_beams_beyond_it():
    """far_beams="cut" (the default): the far wall gives no occupied sample, and free
    samples on its beams up to max_range only, one beam per cell of the cut ends."""
    points, origin = far_and_near_scan()
    samples, labels = AKIMap(0.1, max_range=3.0, random_state=0).training_data(points,
                                                                              origin)
    hits, frees = samples[labels == 1], samples[labels == 0]
    assert_array_equal(hits[:, 0], 2.0)                        # only the near wall's
    on_far = frees[frees[:, 1] > np.abs(frees[:, 0]) * 6.0 + 0.01]
    assert len(on_far) and np.linalg.norm(on_far - origin, axis=1).max() < 3.0
    assert np.linalg.norm(on_far - origin, axis=1).max() > 2.5
    # the far beams are drawn after the near ones: those free samples are unchanged
    dropped, lab = AKIMap(0.1, max_range=3.0, far_beams="drop",
                          random_state=0).training_data(points, origin)
    assert_array_equal(dropped[lab == 0], frees[:int((lab == 0).sum())])


def test_far_beams_drop_is_the_map_of_the_pre_filtered_scan():
    points, origin = far_and_near_scan()
    origin = np.array([0.03, -0.02, 0.01])
    for limit in (3.0, 5.9, float(np.linalg.norm(points[-1] - origin))):
        kept = points[np.linalg.norm(points - origin, axis=1) <= limit]
        assert 0 < len(kept) <= len(points)
        got = AKIMap(0.1, max_range=limit, far_beams="drop", random_state=0, n_jobs=2)
        want = AKIMap(0.1, random_state=0)
        for _ in range(2):                                  # the random streams too
            got.update(points, origin)
            want.update(kept, origin)
        for x, y in zip(got.cells(), want.cells()):
            assert_array_equal(x, y)


def test_max_range_none_or_beyond_every_beam_keeps_all():
    points, origin = far_and_near_scan()
    default = AKIMap(0.1, random_state=0).update(points, origin)
    assert default.max_range is None
    for limit in (None, 1e30):
        m = AKIMap(0.1, max_range=limit, random_state=0).update(points, origin)
        for x, y in zip(m.cells(), default.cells()):
            assert_array_equal(x, y)
    # every beam dropped: the scan adds nothing (the origin alone is no sample)
    assert AKIMap(0.1, max_range=1.0, far_beams="drop",
                  random_state=0).update(points, origin).num_cells == 0


@pytest.mark.parametrize("value, exc, match", [
    (0.0, ValueError, r"max_range must lie in \(0.0, inf\), got 0.0"),
    (np.inf, ValueError, "max_range must lie in"),
    (-1.0, ValueError, "max_range must lie in"),
    ("30", TypeError, "max_range must be a real number, got str"),
    (True, TypeError, "max_range must be a real number"),
])
def test_bad_max_range(value, exc, match):
    with pytest.raises(exc, match=match):
        AKIMap(0.1, max_range=value)
    with pytest.raises(exc, match=match):
        BGKMap(0.1, max_range=value)
    m = AKIMap(0.1, random_state=0).update(*wall_scan())
    before = m.cells()
    m.max_range = value                                 # set as an attribute: checked on use
    with pytest.raises(exc, match=match):
        m.update(*wall_scan())
    for x, y in zip(m.cells(), before):
        assert_array_equal(x, y)


def test_min_range_must_stay_under_max_range():
    m = AKIMap(0.1, max_range=2.0, random_state=0)
    with pytest.raises(ValueError, match=r"min_range must be less than max_range \(2.0\)"):
        m.insert_scan(*wall_scan(), min_range=3.0)
    assert m.num_cells == 0
