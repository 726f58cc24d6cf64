"""Tests of the NCA feature weights (occgp.evaluation.nca_feature_weights)."""

import numpy as np
import pytest
from scipy.optimize import approx_fprime

from occgp.evaluation import MAX_NCA_BYTES, NCAResult, nca_feature_weights
from occgp.evaluation._nca import _loss_matrix, _objective


def _regression(n=150, seed=0):
    rng = np.random.default_rng(seed)
    X = rng.uniform(-1, 1, size=(n, 5))
    y = 2 * X[:, 0] - X[:, 1] + 0.05 * rng.normal(size=n)
    return X, y


def _classification(n=160, seed=1):
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(n, 5))
    y = np.where(X[:, 0] + X[:, 2] > 0, "in", "out")
    return X, y


def _pairs(X):
    return np.abs(X.T[:, :, None] - X.T[:, None, :])


@pytest.mark.parametrize("task, loss", [("regression", "squared"),
                                        ("regression", "absolute"),
                                        ("classification", "squared")])
def test_gradient_matches_finite_differences(task, loss):
    X, y = _regression(40) if task == "regression" else _classification(40)
    X = (X - X.mean(0)) / X.std(0)
    A = _pairs(X)
    L = _loss_matrix(y, len(y), task, loss, True)
    w = np.random.default_rng(3).uniform(0.3, 1.5, size=X.shape[1])
    for sigma, lam in [(1.0, 1 / 40), (0.5, 0.0), (2.0, 0.3)]:
        f, grad = _objective(w, A, L, sigma, lam)
        num = approx_fprime(w, lambda v: _objective(v, A, L, sigma, lam)[0], 1e-7)
        np.testing.assert_allclose(grad, num, rtol=1e-4, atol=1e-7)
        assert np.isfinite(f)


def test_classification_objective_is_one_minus_mean_p_i():
    X, y = _classification(30)
    A = _pairs(X)
    L = _loss_matrix(y, 30, "classification", "squared", False)
    w = np.full(5, 0.7)
    D = np.tensordot(w ** 2, A, axes=1)
    np.fill_diagonal(D, np.inf)
    P = np.exp(-D / 1.5)
    P /= P.sum(1, keepdims=True)
    p_i = (P * (y[:, None] == y[None, :])).sum(1)
    f, _ = _objective(w, A, L, 1.5, 0.1)
    assert f == pytest.approx(1 - p_i.mean() + 0.1 * (w ** 2).sum(), rel=1e-12)


@pytest.mark.parametrize("loss", ["squared", "absolute"])
def test_regression_irrelevant_features_get_zero_weight(loss):
    X, y = _regression()
    res = nca_feature_weights(X, y, loss=loss)
    assert isinstance(res, NCAResult) and res.converged
    assert np.argmax(res.normalized) == 0 and res.normalized[0] == 1.0
    assert res.normalized[1] > 0.3
    assert np.all(res.normalized[2:] < 0.05)
    np.testing.assert_allclose(res.normalized, res.weights / res.weights.max())


def test_classification_irrelevant_features_get_zero_weight():
    X, y = _classification()
    res = nca_feature_weights(X, y, task="classification")
    assert res.converged
    assert min(res.normalized[0], res.normalized[2]) > 0.5
    assert np.all(res.normalized[[1, 3, 4]] < 0.05)
    assert 0 < res.objective < 1


def test_deterministic():
    X, y = _regression()
    a = nca_feature_weights(X, y)
    b = nca_feature_weights(X, y, n_jobs=1)
    np.testing.assert_array_equal(a.weights, b.weights)
    assert (a.objective, a.n_iter) == (b.objective, b.n_iter)


def test_invariant_to_feature_scaling_when_standardized():
    X, y = _regression()
    scaled = X * np.array([1e3, 1e-3, 5.0, 1.0, 1e6]) + 7.0
    a = nca_feature_weights(X, y)
    b = nca_feature_weights(scaled, y * 10 + 3)
    np.testing.assert_allclose(a.weights, b.weights, rtol=1e-6, atol=1e-8)


def test_unstandardized_depends_on_units_and_lam_shrinks():
    X, y = _regression()
    a = nca_feature_weights(X, y, standardize=False)
    b = nca_feature_weights(X * np.array([10, 1, 1, 1, 1]), y, standardize=False)
    assert not np.allclose(a.weights, b.weights)
    big = nca_feature_weights(X, y, lam=10.0)
    assert np.all(big.weights < 1e-3)
    np.testing.assert_array_equal(big.normalized[big.weights == 0], 0)


def test_constant_feature_gets_zero_weight():
    X, y = _regression()
    X[:, 3] = 4.2
    res = nca_feature_weights(X, y)
    assert res.normalized[3] < 1e-3


def test_max_iter_stops_early():
    X, y = _regression()
    res = nca_feature_weights(X, y, max_iter=1)
    assert res.n_iter == 1 and not res.converged


def test_memory_limit_is_checked_before_allocating():
    n = int((MAX_NCA_BYTES / 8 / 9) ** 0.5) + 1
    X = np.zeros((n, 9))
    X[:, 0] = np.arange(n)
    with pytest.raises(ValueError, match=r"GiB of pairwise differences.*subsample"):
        nca_feature_weights(X, np.arange(n, dtype=float))


X0, Y0 = _regression(10)


@pytest.mark.parametrize("kwargs, exc, match", [
    (dict(X=np.zeros(10), y=Y0), ValueError, r"X must have shape \(n_samples, n_features\)"),
    (dict(X=np.zeros((10, 0)), y=Y0), ValueError, r"X must have shape"),
    (dict(X=X0[:2], y=Y0[:2]), ValueError, r"X must hold at least 3 samples, got 2"),
    (dict(X=np.where(np.eye(10, 5) > 0, np.nan, X0), y=Y0), ValueError, r"X must be finite"),
    (dict(X=np.full((10, 5), np.inf), y=Y0), ValueError, r"X must be finite"),
    (dict(X=np.full((10, 5), "a"), y=Y0), TypeError, r"X must hold real numbers"),
    (dict(X=[[1, 2], [3]], y=Y0), ValueError, r"X must be a numeric array"),
    (dict(X=X0, y=Y0[:9]), ValueError, r"y must have shape \(n_samples,\) = \(10,\)"),
    (dict(X=X0, y=Y0[:, None]), ValueError, r"y must have shape"),
    (dict(X=X0, y=np.r_[np.nan, Y0[1:]]), ValueError, r"y must be finite"),
    (dict(X=X0, y=np.ones(10)), ValueError, r"y must not be constant"),
    (dict(X=X0, y=np.array(["a"] * 10)), TypeError, r"y must hold real numbers"),
    (dict(X=X0, y=np.zeros(10, int), task="classification"), ValueError,
     r"y must hold at least 2 classes, got 1"),
    (dict(X=X0, y=np.r_[0, 1e200, Y0[2:]], standardize=False), ValueError,
     r"y spans .* too wide for the squared loss"),
    (dict(X=np.r_[np.full((1, 5), -1e308), np.full((9, 5), 1e308)], y=Y0,
          standardize=False), ValueError, r"X's features span too wide a range"),
    (dict(X=X0, y=Y0, task="ranking"), ValueError, r"task must be one of"),
    (dict(X=X0, y=Y0, loss="huber"), ValueError, r"loss must be one of"),
    (dict(X=X0, y=Y0, sigma=0.0), ValueError, r"sigma must lie in \[1e-08, 100000000.0\]"),
    (dict(X=X0, y=Y0, sigma=-1.0), ValueError, r"sigma must lie in"),
    (dict(X=X0, y=Y0, sigma=1e9), ValueError, r"sigma must lie in"),
    (dict(X=X0, y=Y0, sigma=np.nan), ValueError, r"sigma must lie in"),
    (dict(X=X0, y=Y0, sigma="1"), TypeError, r"sigma must be a real number"),
    (dict(X=X0, y=Y0, lam=-0.1), ValueError, r"lam must lie in \[0.0, 10000000000.0\]"),
    (dict(X=X0, y=Y0, lam=np.inf), ValueError, r"lam must lie in"),
    (dict(X=X0, y=Y0, lam=[1.0]), TypeError, r"lam must be a real number"),
    (dict(X=X0, y=Y0, standardize=1), TypeError, r"standardize must be a bool"),
    (dict(X=X0, y=Y0, max_iter=0), ValueError, r"max_iter must be a positive int, got 0"),
    (dict(X=X0, y=Y0, max_iter=2.5), TypeError, r"max_iter must be a positive int"),
    (dict(X=X0, y=Y0, n_jobs=0), ValueError, r"n_jobs must be None, a positive int"),
])
def test_bad_input(kwargs, exc, match):
    with pytest.raises(exc, match=match):
        nca_feature_weights(**kwargs)


def test_extreme_values_are_fine_when_standardized():
    X, y = _regression()
    a = nca_feature_weights(X, y)
    b = nca_feature_weights(X * 1e300, y * 1e300)
    c = nca_feature_weights(X * 1e-300, y * 1e-300)
    np.testing.assert_allclose(b.weights, a.weights, rtol=1e-6, atol=1e-8)
    np.testing.assert_allclose(c.weights, a.weights, rtol=1e-6, atol=1e-8)
