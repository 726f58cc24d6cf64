"""Tests of GPOM, the local-GP occupancy map of O'Callaghan, Ramos & Durrant-Whyte (2009)."""

import pickle

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from sklearn.base import clone
from sklearn.exceptions import NotFittedError

from _helpers import assert_prediction_shapes
from occgp.gp._gpom import GPOM
from occgp.gp._gpr import JITTER, log_marginal_likelihood
from occgp.gp._kernels import Matern32, SparseKernel, SquaredExponential
from occgp.gp._quadrature import ClenshawCurtis


@pytest.fixture
def wall():
    """A wall at x = 2 seen by 15 beams from the origin: hits, beam starts, beam ends."""
    y = 2.0 * np.tan(np.linspace(-0.6, 0.6, 15))
    hits = np.column_stack([np.full(15, 2.0), y])
    return hits, np.zeros_like(hits), hits.copy()


def _free(m):
    return m.X_train_[m.y_train_ < 0]


# ------------------------------------------------------------------ discretisation
def test_free_points_every_step_along_a_segment():
    m = GPOM(optimizer=False).fit([[5.0, 5.0]], [[0.0, 0.0]], [[3.0, 4.0]])   # length 5
    arc = np.arange(0.25, 5.0, 0.5)
    assert_allclose(_free(m), arc[:, None] * np.array([[0.6, 0.8]]), rtol=0, atol=1e-14)
    assert_array_equal(m.X_train_[0], [5.0, 5.0])
    assert_array_equal(m.y_train_, np.r_[1.0, -np.ones(10)])
    assert m.n_dims_ == 2


@pytest.mark.parametrize("length, expected", [(1.25, [0.25, 0.75]), (1.5, [0.25, 0.75, 1.25]),
                                              (1.3, [0.25, 0.75, 1.25])])
def test_free_points_lie_strictly_below_the_length(length, expected):
    m = GPOM(optimizer=False).fit([[9.0]], [[0.0]], [[length]])
    assert_allclose(_free(m).ravel(), expected, rtol=0, atol=1e-14)


def test_short_and_zero_length_segments_give_one_free_point():
    starts = [[0.0, 0.0], [1.0, 1.0], [2.0, 0.0], [0.0, 0.0]]
    ends = [[0.2, 0.0], [1.0, 1.0], [2.0, 0.25], [0.0, 0.6]]    # short, zero, = step/2, normal
    m = GPOM(optimizer=False).fit([[5.0, 5.0]], starts, ends)
    assert_allclose(_free(m), [[0.1, 0.0], [1.0, 1.0], [2.0, 0.125], [0.0, 0.25]], atol=1e-14)


# ------------------------------------------------------------------ predictions
@pytest.mark.slow
def test_wall_is_occupied_and_beams_are_free(wall):
    m = GPOM(random_state=0).fit(*wall)
    hits = wall[0]
    assert (m.predict_proba(hits) > 0.5).all()
    near = hits[::2] * np.array([[0.25], [0.4], [0.5], [0.3], [0.45], [0.35], [0.5], [0.25]])
    assert (m.predict_proba(near) < 0.5).all()


@pytest.mark.slow
def test_variance_grows_away_from_the_data(wall):
    m = GPOM(random_state=0).fit(*wall)
    _, var_near = m.predict(wall[0], return_var=True)
    _, var_far = m.predict([[10.0, 0.0], [-6.0, 5.0]], return_var=True)
    assert var_far.min() > 10 * var_near.max()
    assert_allclose(var_far, m.kernel_.variance, rtol=1e-6)
    assert (var_near >= 0).all()


@pytest.mark.parametrize("dim", [1, 2, 3])
def test_output_shapes(dim):
    rng = np.random.default_rng(0)
    hits = rng.uniform(1.0, 2.0, (6, dim))
    m = GPOM(optimizer=False).fit(hits, np.zeros_like(hits), hits)
    assert_prediction_shapes(m, rng.uniform(-1.0, 3.0, (5, dim)))


def _reference(m, X):
    """Mean and variance of the local GP, one numpy solve per query."""
    hits, free = m.X_train_[m.y_train_ > 0], m.X_train_[m.y_train_ < 0]
    n_hit, n_free = min(m.n_hit_neighbors, len(hits)), min(m.n_free_neighbors, len(free))
    variance = float(m.kernel_.variance)
    means, variances = [], []
    for x in X:
        near_hits = hits[np.argsort(np.linalg.norm(hits - x, axis=1))[:n_hit]]
        near_free = free[np.argsort(np.linalg.norm(free - x, axis=1))[:n_free]]
        local = np.vstack([near_hits, near_free])
        y = np.r_[np.ones(n_hit), -np.ones(n_free)]
        K = m.kernel_(local) + (m.noise_ + JITTER * variance) * np.eye(len(y))
        k_star = m.kernel_(x[None], local)[0]
        means.append(k_star @ np.linalg.solve(K, y))
        variances.append(max(variance - k_star @ np.linalg.solve(K, k_star), 0.0))
    return np.array(means), np.array(variances)


@pytest.mark.parametrize("kernel", [SquaredExponential(1.5, 0.7), Matern32(0.8, 1.1),
                                    SparseKernel(1.0, 2.5), SquaredExponential(1.0, [0.5, 1.2])])
@pytest.mark.parametrize("n_hit_neighbors", [4, 50])
def test_batched_prediction_matches_per_query_reference(wall, kernel, n_hit_neighbors):
    m = GPOM(kernel, optimizer=False, n_hit_neighbors=n_hit_neighbors, n_free_neighbors=12,
             batch_size=7).fit(*wall)
    X = np.random.default_rng(0).uniform([-1.0, -3.0], [4.0, 3.0], (20, 2))
    mean, var = m.predict(X, return_var=True)
    ref_mean, ref_var = _reference(m, X)
    assert_allclose(mean, ref_mean, rtol=0, atol=1e-10)
    assert_allclose(var, ref_var, rtol=0, atol=1e-10)


def test_batch_size_does_not_change_the_result(wall):
    X = np.random.default_rng(1).uniform([-1.0, -3.0], [4.0, 3.0], (50, 2))
    results = [GPOM(optimizer=False, batch_size=b).fit(*wall).predict(X, return_var=True)
               for b in (1, 7, 4096)]
    for mean, var in results[1:]:
        assert_allclose(mean, results[0][0], rtol=0, atol=1e-12)
        assert_allclose(var, results[0][1], rtol=0, atol=1e-12)


# ------------------------------------------------------------------ fitting
def test_random_state_makes_fits_reproducible(wall):
    params = dict(random_state=3, max_optimize=40, n_restarts=1)
    a, b = GPOM(**params).fit(*wall), GPOM(**params).fit(*wall)
    assert a.kernel_ == b.kernel_ and a.noise_ == b.noise_ and a.plsc_ == b.plsc_
    X = np.random.default_rng(2).uniform(-1.0, 3.0, (10, 2))
    assert_array_equal(a.predict_proba(X), b.predict_proba(X))


@pytest.mark.slow
def test_optimizer_false_keeps_hyperparameters_and_the_user_kernel(wall):
    kernel = SquaredExponential(2.0, 0.8)
    m = GPOM(kernel, noise=0.05, optimizer=False).fit(*wall)
    assert m.kernel_ == kernel and m.kernel_ is not kernel and m.noise_ == 0.05
    GPOM(kernel, random_state=0).fit(*wall)
    assert kernel == SquaredExponential(2.0, 0.8)            # never mutated by fit


@pytest.mark.slow
def test_optimizer_raises_the_log_marginal_likelihood(wall):
    fixed = GPOM(optimizer=False).fit(*wall)
    fitted = GPOM(random_state=0).fit(*wall)
    assert fitted.log_marginal_likelihood_value_ > fixed.log_marginal_likelihood_value_
    X = fitted.X_train_                                       # all points: below max_optimize
    theta = np.r_[fitted.kernel_.theta, np.log(fitted.noise_)]
    lml, _ = log_marginal_likelihood(theta, fitted.kernel_, ClenshawCurtis(), X, X,
                                     fitted.y_train_)
    assert_allclose(fitted.log_marginal_likelihood_value_, lml, rtol=1e-10)


@pytest.mark.slow
def test_subsample_keeps_both_classes(wall):
    m = GPOM(max_optimize=2, random_state=0).fit(*wall)
    assert np.isfinite(m.plsc_).all()


def test_sklearn_protocol(wall):
    m = GPOM(noise=-1.0, free_step="bad")                     # __init__ does no validation
    assert m.get_params()["noise"] == -1.0
    m = clone(GPOM(SquaredExponential(1.0, 0.5), optimizer=False)).fit(*wall)
    X = np.random.default_rng(3).uniform(-1.0, 3.0, (8, 2))
    assert_array_equal(pickle.loads(pickle.dumps(m)).predict_proba(X), m.predict_proba(X))


# ------------------------------------------------------------------ errors
def test_predict_before_fit_raises():
    for method in (GPOM().predict, GPOM().predict_proba):
        with pytest.raises(NotFittedError):
            method([[0.0, 0.0]])


@pytest.mark.parametrize("which, match", [(0, "hits must be finite"),
                                          (1, "segment_starts must be finite"),
                                          (2, "segment_ends must be finite")])
def test_fit_rejects_nan(wall, which, match):
    data = [a.copy() for a in wall]
    data[which][3, 1] = np.nan
    with pytest.raises(ValueError, match=match):
        GPOM(optimizer=False).fit(*data)


def test_predict_rejects_bad_queries(wall):
    m = GPOM(optimizer=False).fit(*wall)
    with pytest.raises(ValueError, match="X must be finite"):
        m.predict([[np.nan, 0.0]])
    with pytest.raises(ValueError, match=r"X must have shape \(n_points, 2\), got \(3, 3\)"):
        m.predict_proba(np.zeros((3, 3)))
    with pytest.raises(TypeError, match="X must hold real numbers"):
        m.predict([["a", "b"]])


@pytest.mark.parametrize("hits, starts, ends, match", [
    (np.zeros(4), np.zeros((2, 2)), np.ones((2, 2)), r"hits must have shape \(n_hits, D\)"),
    (np.zeros((4, 4)), np.zeros((2, 4)), np.ones((2, 4)), r"hits must have shape \(n_hits, D\)"),
    (np.zeros((4, 2)), np.zeros((2, 3)), np.ones((2, 3)), r"segment_starts must have shape"),
    (np.zeros((4, 2)), np.zeros((2, 2)), np.ones((2, 3)), r"segment_ends must have shape"),
    (np.zeros((4, 2)), np.zeros((2, 2)), np.ones((3, 2)), "must have the same shape"),
])
def test_fit_rejects_bad_shapes_and_mixed_dimensions(hits, starts, ends, match):
    with pytest.raises(ValueError, match=match):
        GPOM(optimizer=False).fit(hits + 3.0, starts, ends)


@pytest.mark.parametrize("hits, n_segments", [(np.zeros((0, 2)), 3), (np.ones((3, 2)), 0)])
def test_fit_needs_both_classes(hits, n_segments):
    with pytest.raises(ValueError, match="needs both occupied and free points"):
        GPOM(optimizer=False).fit(hits, np.zeros((n_segments, 2)), np.ones((n_segments, 2)))


@pytest.mark.parametrize("params, error, match", [
    (dict(n_hit_neighbors=0), ValueError, "n_hit_neighbors must be an int >= 1, got 0"),
    (dict(n_free_neighbors=2.5), TypeError, "n_free_neighbors must be an int, got float"),
    (dict(free_step=0.0), ValueError, r"free_step must lie in \(0.0, inf\), got 0.0"),
    (dict(free_step=-1.0), ValueError, "free_step must lie in"),
    (dict(noise=0.0), ValueError, r"noise must lie in \(0.0, inf\), got 0.0"),
    (dict(noise_bounds=(1.0, 0.1)), ValueError, "noise_bounds must satisfy"),
    (dict(max_optimize=1), ValueError, "max_optimize must be an int >= 2"),
    (dict(batch_size=0), ValueError, "batch_size must be an int >= 1"),
    (dict(n_restarts=-1), ValueError, "n_restarts must be an int >= 0"),
    (dict(optimizer="yes"), TypeError, "optimizer must be a bool"),
    (dict(n_jobs=0), ValueError, "n_jobs must be None"),
    (dict(kernel="rbf"), TypeError, "kernel must be one of occgp.gp's kernels"),
    (dict(kernel=SquaredExponential(length_scale=[1.0, 1.0, 1.0])), ValueError,
     "length_scale has 3 entries but the inputs have 2 dimensions"),
])
def test_fit_rejects_bad_parameters(wall, params, error, match):
    with pytest.raises(error, match=match):
        GPOM(**{"optimizer": False, **params}).fit(*wall)


def test_local_loo_leaves_the_point_out(wall):
    """calibration='local-loo' predicts each calibration point with the local GP that
    predict() would use were the point not in the training set: for a hit, the same as a
    map fitted without it; for a free point, the same as a map without that free point
    (BLAS reductions: compared to 1e-12). The wall is jittered: no ties among the
    neighbour distances."""
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(1)
    hits, starts, ends = (a.copy() for a in wall)
    hits += rng.uniform(-0.05, 0.05, hits.shape)
    starts += rng.uniform(-0.05, 0.05, starts.shape)
    ends = hits.copy()
    m = GPOM(optimizer=False, random_state=0).fit(hits, starts, ends)
    n_hits = len(hits)
    for i in (0, 4, n_hits - 1):
        mu, var = m._local_loo(np.array([i]))
        rest = np.delete(hits, i, axis=0)
        m2 = GPOM(optimizer=False, random_state=0).fit(rest, starts, ends)
        mu2, var2 = m2.predict(hits[i:i + 1], return_var=True)
        assert_allclose([mu[0], var[0]], [mu2[0], var2[0]], rtol=1e-12, atol=1e-12)
    free = m.X_train_[n_hits:]
    for j in (0, 7, len(free) - 1):
        mu, var = m._local_loo(np.array([n_hits + j]))
        m._free_tree = cKDTree(np.delete(free, j, axis=0))
        mu2, var2 = m.predict(free[j:j + 1], return_var=True)
        m._free_tree = cKDTree(free)
        assert_allclose([mu[0], var[0]], [mu2[0], var2[0]], rtol=1e-12, atol=1e-12)


@pytest.mark.slow
def test_local_loo_calibration_labels_the_walls_of_a_laser_log():
    """On held-out scans of the 2D room, PLSC fitted on the local GPs' leave-one-out
    predictions (class-balanced) calls the walls occupied where the subset's classifier
    does not; the ranking (AUC) stays."""
    from occgp.datasets import room_2d
    from occgp.io import LaserLog
    from occgp.evaluation import RealLogBenchmark

    log = LaserLog(room_2d().scan(n_poses=26, n_beams=60), np.arange(26.0))
    bench = RealLogBenchmark(log, every=5, offset=2, max_range=8.0)
    rows = {cal: bench.evaluate(cal, {"map": "gpom", "calibration": cal, "random_state": 0})
            for cal in ("subset-loo", "local-loo")}
    new, old = rows["local-loo"], rows["subset-loo"]
    assert new.accuracy > old.accuracy and new.brier < old.brier
    assert new.acc_occupied > 0.8
    assert new.auc > old.auc - 0.01
