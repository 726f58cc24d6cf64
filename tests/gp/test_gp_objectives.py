"""The leave-one-out objective of the GP hyper-parameter fit (R&W §5.4.2)."""

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.stats import norm

from _helpers import assert_gradient_matches
from occgp.gp import ClenshawCurtis, Matern32, SparseKernel, SquaredExponential, integral_kernel
from occgp.gp._gpr import loo_log_predictive, optimize_hyperparameters

KERNELS = {
    "se": lambda d: SquaredExponential(1.3, 0.9),
    "se-ard": lambda d: SquaredExponential(0.8, np.linspace(0.7, 1.4, d)),
    "matern32": lambda d: Matern32(1.1, 1.2),
    "sparse": lambda d: SparseKernel(1.0, 2.5),
}


def _data(dim, seed=0):
    rng = np.random.default_rng(seed)
    hits = rng.uniform(-1.0, 1.0, (5, dim))
    starts = rng.uniform(-1.0, 1.0, (6, dim))
    ends = starts + rng.normal(0.0, 0.8, (6, dim))
    y = np.r_[np.ones(5), -np.linalg.norm(ends - starts, axis=1)]
    return np.vstack([hits, starts]), np.vstack([hits, ends]), y


@pytest.mark.parametrize("name", ["se", "se-ard", "matern32", "sparse"])
@pytest.mark.parametrize("dim", [2, 3])
def test_loo_gradient(name, dim):
    kernel = KERNELS[name](dim)
    S, E, y = _data(dim)
    theta = np.r_[kernel.theta, np.log(0.05)]
    assert_gradient_matches(loo_log_predictive, theta, kernel, ClenshawCurtis(), S, E, y)


def test_loo_value_is_the_sum_of_left_out_predictions():
    """Against refitting the GP without each observation in turn."""
    kernel = KERNELS["se-ard"](2)
    S, E, y = _data(2, seed=3)
    noise = 0.05
    v, _ = loo_log_predictive(np.r_[kernel.theta, np.log(noise)], kernel, ClenshawCurtis(),
                              S, E, y)
    K = integral_kernel(kernel, S, E)
    C = K + (noise + 1e-10 * np.mean(np.diag(K))) * np.eye(len(y))
    total = 0.0
    for i in range(len(y)):
        rest = np.delete(np.arange(len(y)), i)
        w = np.linalg.solve(C[np.ix_(rest, rest)], C[rest, i])
        mean = w @ y[rest]
        var = C[i, i] - w @ C[rest, i]
        total += norm(mean, np.sqrt(var)).logpdf(y[i])
    assert_allclose(v, total, rtol=1e-9)


def test_loo_fit_raises_its_objective():
    S, E, y = _data(2, seed=1)
    kernel = SquaredExponential(1.0, 1.0)
    start = loo_log_predictive(np.r_[kernel.theta, np.log(0.01)], kernel, ClenshawCurtis(),
                               S, E, y)[0]
    fitted, noise, value = optimize_hyperparameters(
        kernel, 0.01, (1e-4, 1.0), S, E, y, ClenshawCurtis(), n_restarts=0, objective="loo")
    assert value > start
    again = loo_log_predictive(np.r_[fitted.theta, np.log(noise)], fitted, ClenshawCurtis(),
                               S, E, y)[0]
    assert_allclose(again, value, rtol=1e-10)


@pytest.mark.parametrize("cls", ["GPOMIK", pytest.param("GPOM", marks=pytest.mark.slow), "GPMixture"])
def test_estimators_take_the_objective(cls):
    from occgp.datasets import room_2d
    from occgp.gp import GPOM, GPOMIK, GPMixture, observations_from_scans
    data = observations_from_scans(room_2d().scan(n_poses=3))
    make = {"GPOMIK": lambda **kw: GPOMIK(n_restarts=0, random_state=0, **kw),
            "GPOM": lambda **kw: GPOM(random_state=0, **kw),
            "GPMixture": lambda **kw: GPMixture(GPOMIK(n_restarts=0, **kw), random_state=0)}[cls]
    lml, loo = make().fit(*data), make(objective="loo").fit(*data)
    assert not np.allclose(lml.kernel_.theta, loo.kernel_.theta)
    assert np.all(np.isfinite(loo.predict_proba(data[0])))
    middles = 0.5 * (data[1] + data[2])
    assert lml.predict_proba(data[0]).mean() > lml.predict_proba(middles).mean()
    with pytest.raises(ValueError, match="objective"):
        make(objective="likelihood").fit(*data)


def test_min_size_merges_small_clusters():
    from occgp.gp import merge_small_clusters
    labels = [0, 0, 0, 0, 1, 1, 1, 1, 1, 1, 1]
    points = np.array([[0, 0], [0, 1], [0, 2], [1, 1], [0, 4], [0, 5], [0, 6], [0, 7],
                       [0, 8], [1, 5], [1, 6]], dtype=float)
    is_hit = [True, True, True, False] + [True] * 5 + [False] * 2
    assert merge_small_clusters(labels, points, is_hit).tolist() == labels
    assert merge_small_clusters(labels, points, is_hit, min_size=5).tolist() == [0] * 11
    with pytest.raises(ValueError, match="min_size"):
        merge_small_clusters(labels, points, is_hit, min_size=0)


@pytest.mark.slow
def test_global_hyperparameters_are_a_gpomik_fit():
    """hyperparameters='global': the kernel and noise of GPOMIK on the same data, and its
    PLSC with calibration='subset-loo'."""
    from occgp.datasets import room_2d
    from occgp.gp import GPOMIK, GPMixture, observations_from_scans
    data = observations_from_scans(room_2d().scan(n_poses=4))
    mix = GPMixture(GPOMIK(n_restarts=0), hyperparameters="global", calibration="subset-loo",
                    random_state=0).fit(*data)
    gp = GPOMIK(n_restarts=0, max_cell_size=None, calibration="subset-loo").fit(*data)
    assert_allclose(mix.kernel_.theta, gp.kernel_.theta, rtol=1e-8)
    assert_allclose(mix.noise_, gp.noise_, rtol=1e-8)
    assert_allclose(mix.plsc_, gp.plsc_, rtol=1e-6)
    for expert in mix.experts_:
        assert_allclose(expert.kernel_.theta, gp.kernel_.theta, rtol=1e-8)
    # a subset of max_optimize observations when there are more
    small = GPMixture(GPOMIK(n_restarts=0, max_optimize=50), hyperparameters="global",
                      random_state=0).fit(*data)
    assert not np.allclose(small.kernel_.theta, gp.kernel_.theta)
    again = GPMixture(GPOMIK(n_restarts=0, max_optimize=50), hyperparameters="global",
                      random_state=0).fit(*data)
    assert_allclose(again.predict(data[0]), small.predict(data[0]), rtol=0, atol=0)
