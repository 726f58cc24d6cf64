"""Tests of the log-odds grid baseline and the grid evaluation helpers (occgp.gp._occupancy_grid)."""

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy.special import logit
from sklearn.base import clone
from sklearn.exceptions import NotFittedError

from occgp.gp._grid_eval import grid_points, predict_grid
from occgp.gp._occupancy_grid import OccupancyGrid, _free_cells

L_HIT, L_MISS = logit(0.7), logit(0.4)


def cell_set(keys):
    return {tuple(int(v) for v in k) for k in keys}


def brute_force_cells(start, end, resolution, n=100_000):
    """Cells of n samples along the open segment, the end cell excepted."""
    t = (np.arange(n) + 0.5) / n
    keys = np.floor((start + t[:, None] * (end - start)) / resolution).astype(np.int64)
    change = np.r_[True, (np.diff(keys, axis=0) != 0).any(axis=1)]
    cells = cell_set(keys[change])
    cells.discard(tuple(np.floor(end / resolution).astype(np.int64).tolist()))
    return cells


def per_segment(starts, ends, resolution):
    """Cell set of each segment, traversed one at a time by the vectorised code."""
    return [cell_set(_free_cells(s[None], e[None], resolution)) for s, e in zip(starts, ends)]


@pytest.mark.parametrize("dim", [2, 3])
def test_traversal_matches_brute_force(dim):
    rng = np.random.default_rng(0)
    resolution = 0.25
    starts = rng.uniform(-1.0, 1.0, (40, dim))
    ends = starts + rng.normal(0.0, 0.6, (40, dim))
    ends[:5, 0] = starts[:5, 0]  # some axis-parallel segments, off the grid planes
    cells = per_segment(starts, ends, resolution)
    for s, e, got in zip(starts, ends, cells):
        assert got == brute_force_cells(s, e, resolution)
    # All segments at once: the same rows as one at a time.
    together = _free_cells(starts, ends, resolution)
    assert len(together) == sum(len(c) for c in cells)
    assert cell_set(together) == set().union(*cells)


@pytest.mark.parametrize("dim", [2, 3])
def test_traversal_through_corners_matches_brute_force(dim):
    # Endpoints at cell centers: many segments pass exactly through grid corners
    # and edges, which the samples never hit (their t has a denominator of 2e5).
    rng = np.random.default_rng(1)
    starts = rng.integers(-4, 4, (40, dim)) + 0.5
    ends = rng.integers(-4, 4, (40, dim)) + 0.5
    cells = per_segment(starts, ends, 1.0)
    for s, e, got in zip(starts, ends, cells):
        assert got == brute_force_cells(s, e, 1.0)
    # Scaled to a resolution that binary floats do not hold, the cells stay the same.
    assert per_segment(starts * 0.1, ends * 0.1, 0.1) == cells


@pytest.mark.parametrize(
    "start, end, expected",
    [
        ([0.5, 0.5], [3.5, 0.5], {(0, 0), (1, 0), (2, 0)}),              # along x
        ([3.5, 0.5], [0.5, 0.5], {(3, 0), (2, 0), (1, 0)}),              # backwards
        ([0.5, 3.5], [0.5, 0.5], {(0, 3), (0, 2), (0, 1)}),              # along -y
        ([0.5, 1.0], [2.5, 1.0], {(0, 1), (1, 1)}),                      # on a grid line
        ([3.0, 0.5], [0.5, 0.5], {(2, 0), (1, 0)}),                      # starts on a plane
        ([0.5, 0.5], [3.5, 3.5], {(0, 0), (1, 1), (2, 2)}),              # through corners
        ([3.5, 0.5], [0.5, 3.5], {(3, 0), (2, 1), (1, 2)}),              # anti-diagonal
        ([0.5, 0.25], [3.5, 1.75], {(0, 0), (1, 0), (2, 1)}),            # one corner at (2, 1)
        ([0.2, 0.3], [0.7, 0.9], set()),                                 # inside one cell
        ([0.5, 0.5], [0.5, 0.5], set()),                                 # zero length
        ([0.5, 0.5, 0.5], [2.5, 2.5, 2.5], {(0, 0, 0), (1, 1, 1)}),      # 3D corners
        ([0.5, 0.5, 0.5], [2.5, 2.5, 0.5], {(0, 0, 0), (1, 1, 0)}),      # 3D edge
        ([0.5, 0.5, 2.5], [0.5, 0.5, -0.5], {(0, 0, 2), (0, 0, 1), (0, 0, 0)}),
    ],
)
@pytest.mark.parametrize("resolution", [1.0, 0.1])
def test_traversal_explicit_cases(start, end, expected, resolution):
    start, end = np.array(start) * resolution, np.array(end) * resolution
    assert per_segment([start], [end], resolution)[0] == expected


def test_log_odds_of_beams_and_hit():
    starts = np.array([[0.5, 0.5], [0.5, 0.5], [0.5, 0.2]])
    ends = np.array([[3.5, 0.5], [2.5, 0.5], [3.5, 0.7]])
    grid = OccupancyGrid(resolution=1.0).fit([[1.5, 0.5]], starts, ends)
    assert_allclose(grid.log_odds([[1.5, 0.5]]), [3 * L_MISS + L_HIT])
    assert_allclose(grid.log_odds([[0.5, 0.5], [2.5, 0.5]]), [3 * L_MISS, 2 * L_MISS])
    assert_allclose(grid.log_odds([[3.5, 0.5]]), [np.nan])  # end cells are not marked
    assert grid.n_dims_ == 2 and grid.n_updates_ == 1
    assert grid.keys_.dtype == np.int64 and grid.keys_.shape == (3, 2)
    assert_array_equal(grid.keys_, np.unique(grid.keys_, axis=0))


def test_clamping():
    n = 10
    grid = OccupancyGrid(resolution=1.0).fit(
        np.full((n, 2), 5.5), np.tile([0.5, 0.5], (n, 1)), np.tile([3.5, 0.5], (n, 1)))
    assert_allclose(grid.log_odds([[1.5, 0.5], [5.5, 5.5]]), [logit(0.1192), logit(0.971)])
    grid = OccupancyGrid(resolution=1.0, clamping_min=0.01, clamping_max=0.999)
    grid.fit(np.full((n, 2), 5.5), np.tile([0.5, 0.5], (n, 1)), np.tile([3.5, 0.5], (n, 1)))
    assert_allclose(grid.log_odds([[1.5, 0.5], [5.5, 5.5]]), [n * L_MISS, logit(0.999)])


@pytest.mark.parametrize("dim", [2, 3])
def test_update_equals_fit_on_all_data(dim):
    rng = np.random.default_rng(0)
    hits = rng.uniform(-1, 1, (60, dim))
    starts = rng.uniform(-1, 1, (50, dim))
    ends = rng.uniform(-1, 1, (50, dim))
    params = dict(resolution=0.2, clamping_min=1e-6, clamping_max=1 - 1e-6)  # no clamping
    full = OccupancyGrid(**params).fit(hits, starts, ends)
    perm = rng.permutation(50)
    parts = OccupancyGrid(**params).fit(hits[:20], starts[perm[:30]], ends[perm[:30]])
    parts.update(hits=hits[20:])
    parts.update(segment_starts=starts[perm[30:]], segment_ends=ends[perm[30:]])
    assert parts.n_updates_ == 3
    assert_array_equal(parts.keys_, full.keys_)
    assert_allclose(parts.log_odds_, full.log_odds_, atol=1e-12)


def test_fit_resets_the_map():
    grid = OccupancyGrid(resolution=1.0).fit([[0.5, 0.5]], None, None)
    grid.update(hits=[[0.5, 0.5]])
    grid.fit([[2.5, 2.5, 2.5]], None, None)
    assert grid.n_dims_ == 3 and grid.n_updates_ == 1
    assert_array_equal(grid.keys_, [[2, 2, 2]])


def test_unknown_cells():
    grid = OccupancyGrid(resolution=1.0).fit([[0.5, 0.5]], [[0.5, 0.5]], [[2.5, 0.5]])
    X = np.array([[0.5, 0.5], [1.5, 0.5], [2.5, 0.5], [-3.0, 7.0]])
    assert_array_equal(grid.is_known(X), [True, True, False, False])
    assert_allclose(grid.log_odds(X), [L_MISS + L_HIT, L_MISS, np.nan, np.nan])
    assert_allclose(grid.predict_proba(X), [1 / (1 + np.exp(-(L_MISS + L_HIT))), 0.4, 0.5, 0.5])
    assert grid.predict_proba(X).shape == (4,)
    assert grid.predict_proba(np.empty((0, 2))).shape == (0,)


def test_cells():
    grid = OccupancyGrid(resolution=0.5).fit([[1.2, -0.1]], [[0.1, 0.1]], [[1.2, 0.1]])
    centers, proba = grid.cells()
    assert_allclose(centers, [[0.25, 0.25], [0.75, 0.25], [1.25, -0.25]])
    assert_allclose(proba, [0.4, 0.4, 0.7])
    assert_allclose(grid.predict_proba(centers), proba)


def test_zero_length_and_single_cell_segments_mark_nothing():
    grid = OccupancyGrid(resolution=1.0).fit(
        [[5.5, 5.5]], [[0.5, 0.5], [1.2, 1.2]], [[0.5, 0.5], [1.7, 1.9]])
    assert_array_equal(grid.keys_, [[5, 5]])


def test_segments_only_map_may_be_empty():
    grid = OccupancyGrid(resolution=1.0).fit(None, [[0.2, 0.2]], [[0.7, 0.7]])
    assert grid.keys_.shape == (0, 2)
    assert_allclose(grid.predict_proba([[0.5, 0.5]]), [0.5])
    assert_array_equal(grid.is_known([[0.5, 0.5]]), [False])


def test_hits_only_and_segments_only():
    hits = OccupancyGrid(resolution=1.0).fit([[0.5, 0.5, 0.5]], np.empty((0, 3)), np.empty((0, 3)))
    assert_allclose(hits.log_odds_, [L_HIT])
    free = OccupancyGrid(resolution=1.0).fit(np.empty((0, 2)), [[0.5, 0.5]], [[2.5, 0.5]])
    assert_allclose(free.log_odds_, [L_MISS, L_MISS])


def test_init_stores_params_and_clones():
    grid = OccupancyGrid(resolution=-1, prob_hit="x")
    assert grid.get_params()["resolution"] == -1
    assert clone(grid).get_params() == grid.get_params()


@pytest.mark.parametrize(
    "params, match",
    [
        (dict(resolution=0.0), "resolution must lie in"),
        (dict(resolution=np.nan), "resolution must lie in"),
        (dict(resolution="1"), "resolution must be a real number"),
        (dict(prob_hit=0.4), "prob_hit must lie in"),
        (dict(prob_miss=0.6), "prob_miss must lie in"),
        (dict(clamping_min=0.0), "clamping_min must lie in"),
        (dict(clamping_max=1.0), "clamping_max must lie in"),
    ],
)
def test_bad_params_raise_at_fit(params, match):
    grid = OccupancyGrid(**params)
    with pytest.raises((ValueError, TypeError), match=match):
        grid.fit([[0.5, 0.5]], None, None)


@pytest.mark.parametrize(
    "args, error, match",
    [
        (([1.0, 2.0], None, None), ValueError, r"hits must have shape \(n_points, 2\) or"),
        ((np.zeros((3, 4)), None, None), ValueError, r"hits must have shape .* got \(3, 4\)"),
        ((np.zeros((3, 1)), None, None), ValueError, r"hits must have shape .* got \(3, 1\)"),
        ((np.zeros((2, 2, 1)), None, None), ValueError, r"got \(2, 2, 1\)"),
        ((np.zeros((2, 2)), np.zeros((2, 3)), np.zeros((2, 3))), ValueError,
         "same number of columns"),
        ((None, np.zeros((2, 2)), np.zeros((2, 3))), ValueError, "same number of columns"),
        ((None, np.zeros((2, 2)), np.zeros((3, 2))), ValueError, "same length, got 2 and 3"),
        ((None, np.zeros((2, 2)), None), ValueError, "both be given or both be None"),
        ((None, None, np.zeros((2, 2))), ValueError, "both be given or both be None"),
        ((None, None, None), ValueError, "no data"),
        ((np.empty((0, 2)), np.empty((0, 2)), np.empty((0, 2))), ValueError, "0 hits and 0 seg"),
        (([[0.0, np.nan]], None, None), ValueError, "hits must be finite"),
        ((None, [[0.0, 0.0]], [[np.inf, 0.0]]), ValueError, "segment_ends must be finite"),
        (([["a", "b"]], None, None), TypeError, "hits must hold real numbers"),
        ((None, [[0j, 1j]], [[0.0, 1.0]]), TypeError, "segment_starts must hold real"),
    ],
)
def test_fit_rejects_bad_data(args, error, match):
    with pytest.raises(error, match=match):
        OccupancyGrid(resolution=1.0).fit(*args)


def test_not_fitted():
    grid = OccupancyGrid()
    for call in (lambda: grid.predict_proba([[0.0, 0.0]]), lambda: grid.log_odds([[0.0, 0.0]]),
                 lambda: grid.is_known([[0.0, 0.0]]), grid.cells,
                 lambda: grid.update(hits=[[0.0, 0.0]])):
        with pytest.raises(NotFittedError):
            call()


@pytest.mark.parametrize(
    "kwargs, error, match",
    [
        (dict(hits=[[0.5, 0.5, 0.5]]), ValueError, r"hits must have shape \(n_points, 2\)"),
        (dict(hits=[[0.5, np.nan]]), ValueError, "hits must be finite"),
        (dict(hits=[[0.5, 0.5]], segment_starts=[[0.0, 0.0]]), ValueError, "both be given"),
        (dict(segment_starts=[[0.0, 0.0]], segment_ends=[[1.0, "x"]]), TypeError,
         "segment_ends must hold real numbers"),
        (dict(), ValueError, "no data"),
    ],
)
def test_rejected_update_leaves_map_unchanged(kwargs, error, match):
    grid = OccupancyGrid(resolution=1.0).fit([[0.5, 0.5]], [[0.5, 0.5]], [[2.5, 0.5]])
    keys, log_odds = grid.keys_.copy(), grid.log_odds_.copy()
    with pytest.raises(error, match=match):
        grid.update(**kwargs)
    assert_array_equal(grid.keys_, keys)
    assert_array_equal(grid.log_odds_, log_odds)
    assert grid.n_updates_ == 1


@pytest.mark.parametrize("X, match", [([[0.0, 0.0, 0.0]], r"X must have shape \(n_points, 2\)"),
                                      ([[0.0, np.inf]], "X must be finite")])
def test_queries_reject_bad_points(X, match):
    grid = OccupancyGrid(resolution=1.0).fit([[0.5, 0.5]], None, None)
    with pytest.raises(ValueError, match=match):
        grid.predict_proba(X)


def test_grid_points_shape_and_order():
    points, shape = grid_points([0.0, -1.0, 2.0], [0.3, 0.0, 2.1], 0.1)
    assert shape == (3, 10, 1)
    assert points.shape == (30, 3) and points.dtype == np.float64
    cube = points.reshape(shape + (3,))
    assert_allclose(cube[:, 0, 0, 0], [0.05, 0.15, 0.25])
    assert_allclose(cube[0, :, 0, 1], -1.0 + (np.arange(10) + 0.5) * 0.1)
    assert_allclose(cube[..., 2], 2.05)
    # The last cell covers a remainder.
    assert grid_points([0, 0], [1.05, 1.0], 0.5)[1] == (3, 2)


@pytest.mark.parametrize(
    "lower, upper, resolution, match",
    [
        ([0.0], [1.0], 0.1, r"lower must have shape \(2,\) or \(3,\), got \(1,\)"),
        ([0.0] * 4, [1.0] * 4, 0.1, r"lower must have shape \(2,\) or \(3,\), got \(4,\)"),
        (0.0, 1.0, 0.1, r"lower must have shape \(2,\) or \(3,\), got \(\)"),
        ([0.0, 0.0], [1.0, 1.0, 1.0], 0.1, r"upper must have shape \(2,\)"),
        ([0.0, 0.0], [1.0, 0.0], 0.1, "lower must be below upper"),
        ([0.0, np.nan], [1.0, 1.0], 0.1, "lower must be finite"),
        ([0.0, 0.0], [1.0, 1.0], 0.0, "resolution must lie in"),
    ],
)
def test_grid_points_rejects_bad_box(lower, upper, resolution, match):
    with pytest.raises(ValueError, match=match):
        grid_points(lower, upper, resolution)


def test_predict_grid_proba_matches_grid_points():
    rng = np.random.default_rng(0)
    grid = OccupancyGrid(resolution=0.25).fit(rng.uniform(0, 2, (30, 2)), None, None)
    lower, upper = [0.0, 0.0], [2.0, 1.5]
    points, shape = grid_points(lower, upper, 0.25)
    expected = grid.predict_proba(points).reshape(shape)
    for batch_size in (1, 7, 50_000):
        values = predict_grid(grid, lower, upper, 0.25, batch_size=batch_size)
        assert values.shape == (8, 6)
        assert_array_equal(values, expected)


class FakeGP:
    """Mean = x + 10 y (+ 100 z), variance = 2 * mean; counts its calls."""

    def __init__(self):
        self.calls = 0

    def predict(self, X, return_var=False):
        assert return_var
        self.calls += 1
        mean = np.asarray(X) @ [1.0, 10.0, 100.0][: np.shape(X)[1]]
        return mean, 2 * mean


@pytest.mark.parametrize("output, factor", [("mean", 1.0), ("var", 2.0)])
def test_predict_grid_mean_and_var(output, factor):
    model = FakeGP()
    values = predict_grid(model, [0.0, 0.0, 0.0], [1.0, 2.0, 0.5], 0.5, output=output,
                          batch_size=3)
    assert values.shape == (2, 4, 1) and model.calls == 3
    i, j = np.meshgrid(np.arange(2), np.arange(4), indexing="ij")
    expected = factor * ((i + 0.5) * 0.5 + 10 * (j + 0.5) * 0.5 + 100 * 0.25)
    assert_allclose(values[..., 0], expected)


@pytest.mark.parametrize("kwargs, error, match", [
    (dict(output="probability"), ValueError, "output must be one of .* got 'probability'"),
    (dict(batch_size=0), ValueError, "batch_size must be a positive integer, got 0"),
    (dict(batch_size=2.5), TypeError, "batch_size must be an integer"),
])
def test_predict_grid_rejects_bad_arguments(kwargs, error, match):
    with pytest.raises(error, match=match):
        predict_grid(FakeGP(), [0.0, 0.0], [1.0, 1.0], 0.5, **kwargs)


@pytest.mark.parametrize("far", [10.0, 1e15])  # cells spread beyond int64 mixed-radix codes
def test_lookup_near_and_far_cells(far):
    rng = np.random.default_rng(0)
    hits = np.vstack([rng.uniform(-2, 2, (50, 3)), [[-far, 0.5, 0.5], [far, -far, far]]])
    grid = OccupancyGrid(resolution=1.0).fit(hits, None, None)
    centers, _ = grid.cells()
    assert_array_equal(grid.is_known(centers), True)
    assert_array_equal(grid.is_known(hits), True)
    misses = centers + [[0.0, 0.0, 3 * far]]
    assert_array_equal(grid.is_known(np.vstack([misses, [[far, far, far]]])), False)


# ----------------------------------------------------------- size and range limits
@pytest.mark.parametrize("lower, upper, resolution", [
    ([0, 0], [1e6, 1e6], 1e-3),                     # 1e18 cells (7.5 GiB of float64 per 1e9)
    ([0, 0, 0], [1e4, 1e4, 1e4], 1e-2),
    ([-1e308, 0], [1e308, 1], 1.0),                 # the extent overflows to inf
    ([0, 0], [1, 1], 1e-300),
])
def test_grid_points_rejects_too_many_cells(lower, upper, resolution):
    with pytest.raises(ValueError, match=r"cells, more than max_points=20000000"):
        grid_points(lower, upper, resolution)
    with pytest.raises(ValueError, match=r"cells, more than max_points=20000000"):
        predict_grid(FakeGP(), lower, upper, resolution, output="mean")


def test_grid_points_max_points_is_a_parameter():
    assert grid_points([0, 0], [10, 10], 1.0, max_points=100)[1] == (10, 10)
    with pytest.raises(ValueError, match=r"has 100 cells, more than max_points=99"):
        grid_points([0, 0], [10, 10], 1.0, max_points=99)
    with pytest.raises(ValueError, match=r"has 100 cells, more than max_points=99"):
        predict_grid(FakeGP(), [0, 0], [10, 10], 1.0, output="mean", max_points=99)
    with pytest.raises(TypeError, match="max_points must be an integer, got float"):
        grid_points([0, 0], [1, 1], 0.5, max_points=1e8)
    with pytest.raises(ValueError, match="max_points must be a positive integer, got 0"):
        grid_points([0, 0], [1, 1], 0.5, max_points=0)


def test_grid_points_thin_box_has_one_cell():
    assert grid_points([0, 0], [1e-12, 1.0], 0.5)[1] == (1, 2)


class RecordingGP(FakeGP):
    """FakeGP that keeps every batch of query points it is given."""

    def __init__(self):
        super().__init__()
        self.batches = []

    def predict(self, X, return_var=False):
        self.batches.append(np.array(X, copy=True))
        return super().predict(X, return_var)


def test_predict_grid_batches_do_not_change_the_points():
    lower, upper = [0.0, -1.0, 2.0], [1.2, 0.0, 2.35]
    points, shape = grid_points(lower, upper, 0.1)
    expected = FakeGP().predict(points, return_var=True)[0].reshape(shape)
    for batch_size in (1, 5, 10**9):
        model = RecordingGP()
        values = predict_grid(model, lower, upper, 0.1, output="mean", batch_size=batch_size)
        # the points themselves are exact: the batches split grid_points' rows, in order
        assert_array_equal(np.concatenate(model.batches), points)
        # the model's matrix product goes through BLAS, whose kernels sum in an order
        # that depends on the batch's shape and the CPU (AVX2 and SSE kernels differ in
        # the last bits): equal to rounding
        assert_allclose(values, expected, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("kwargs, model, error, match", [
    (dict(output=None), FakeGP(), TypeError, "output must be one of .* got NoneType"),
    (dict(batch_size=True), FakeGP(), TypeError, "batch_size must be an integer, got bool"),
    (dict(), FakeGP(), TypeError, r"model must have a predict_proba\(\) method"),
    (dict(output="var"), object(), TypeError, r"model must have a predict\(\) method"),
])
def test_predict_grid_rejects_bad_types(kwargs, model, error, match):
    with pytest.raises(error, match=match):
        predict_grid(model, [0.0, 0.0], [1.0, 1.0], 0.5, **kwargs)


@pytest.mark.parametrize("data", [
    dict(hits=[[1e30, 0.0]], segment_starts=None, segment_ends=None),
    dict(hits=None, segment_starts=[[0.0, 0.0]], segment_ends=[[1e30, 0.0]]),
    dict(hits=[[2e14, 0.0]], segment_starts=None, segment_ends=None),   # 2e15 cells at 0.1
])
def test_occupancy_grid_rejects_far_coordinates(data):
    name = "hits" if data["hits"] is not None else "segment_ends"
    with pytest.raises(ValueError, match=rf"{name} must lie within 1e\+15 cells of the origin"):
        OccupancyGrid(resolution=0.1).fit(**data)


def test_occupancy_grid_update_far_data_leaves_the_map_unchanged():
    grid = OccupancyGrid(resolution=0.5).fit([[1.0, 1.0]], [[0.0, 0.0]], [[1.0, 1.0]])
    before = (grid.keys_.copy(), grid.log_odds_.copy(), grid.n_updates_)
    with pytest.raises(ValueError, match="segment_ends must lie within"):
        grid.update([[0.0, 0.0]], [[0.0, 0.0]], [[0.0, 1e300]])
    with pytest.raises(ValueError, match=r"crosses about 2e\+07 cells .* more than the limit"):
        grid.update(None, [[0.0, 0.0]], [[1e7, 0.0]])
    assert_array_equal(grid.keys_, before[0])
    assert_array_equal(grid.log_odds_, before[1])
    assert grid.n_updates_ == before[2]


def test_occupancy_grid_far_queries_are_unknown():
    grid = OccupancyGrid(resolution=0.1).fit([[0.05, 0.05]], None, None)
    X = [[1e30, 0.0], [1e300, -1e300], [0.05, 0.05], [-1e16, 0.0]]
    assert_array_equal(grid.is_known(X), [False, False, True, False])
    assert_array_equal(grid.predict_proba(X), [0.5, 0.5, 0.7, 0.5])


def test_occupancy_grid_chunked_traversal_matches_one_pass(monkeypatch):
    import occgp.gp._occupancy_grid as grid_module
    rng = np.random.default_rng(3)
    starts = rng.uniform(-3, 3, (60, 2))
    ends = starts + rng.uniform(-4, 4, (60, 2))
    hits = ends[:20]
    one = OccupancyGrid(resolution=0.2, clamping_min=1e-6, clamping_max=1 - 1e-6)
    one.fit(hits, starts, ends)
    monkeypatch.setattr(grid_module, "MAX_SEGMENT_CELLS", 70)   # several chunks
    chunked = clone(one).fit(hits, starts, ends)
    assert_array_equal(chunked.keys_, one.keys_)
    assert_allclose(chunked.log_odds_, one.log_odds_, rtol=0, atol=1e-12)
