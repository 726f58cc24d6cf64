"""Bad input and its limits in the Gaussian-process maps (occgp.gp): clear errors, no change."""

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from occgp.gp import GPOM, GPOMIK, SparseKernel, SquaredExponential
from occgp.gp._gpr import log_marginal_likelihood, optimize_hyperparameters, unique_observations
from occgp.gp._quadrature import ClenshawCurtis


def wall(n=5, x=2.0):
    hits = np.column_stack([np.full(n, x), np.linspace(-1.0, 1.0, n)])
    return hits, np.zeros_like(hits), hits.copy()


def fitted_state(model):
    """Every fitted attribute (``*_``), with the cells' arrays, as comparable values."""
    state = {}
    for name, value in vars(model).items():
        if not name.endswith("_") or name.startswith("_"):
            continue
        if name == "cells_":
            value = [(tuple(c.obs), c.L, c.alpha) for c in value]
        state[name] = value
    return state


def assert_same_state(a, b):
    assert a.keys() == b.keys()
    for name in a:
        if name == "cells_":
            assert len(a[name]) == len(b[name])
            for (obs_a, L_a, al_a), (obs_b, L_b, al_b) in zip(a[name], b[name]):
                for x, y in zip(obs_a, obs_b):
                    assert_array_equal(x, y)
                assert_array_equal(L_a, L_b)
                assert_array_equal(al_a, al_b)
        elif isinstance(a[name], np.ndarray):
            assert_array_equal(a[name], b[name])
        else:
            assert a[name] == b[name] or (a[name] != a[name] and b[name] != b[name]), name


# ----------------------------------------------------------- coordinate limits
@pytest.mark.parametrize("scale, offset", [(1e30, 0.0), (1e200, 0.0), (1.0, 1e30), (1e11, 0.0)])
def test_gpomik_fit_rejects_coordinates_beyond_the_limit(scale, offset):
    hits, starts, ends = (a * scale + offset for a in wall())
    with pytest.raises(ValueError, match=r"hits must lie within 1e\+10 length scales of the "
                                         r"origin \(\|x\| <= 1e\+10 on axis 0"):
        GPOMIK(optimizer=False).fit(hits, starts, ends)


def test_gpomik_coordinate_limit_scales_with_the_length_scale():
    hits, starts, ends = (a * 1e10 for a in wall())   # 2e10: within 1e10 length scales of 4
    m = GPOMIK(SquaredExponential(1.0, 4.0), optimizer=False)
    with pytest.raises(ValueError, match=r"segments must be at most 10000 length scales long"):
        m.fit(hits, starts, ends)
    with pytest.raises(ValueError, match=r"segment_starts must lie within .* 2e\+09"):
        GPOMIK(SquaredExponential(1.0, 0.2), optimizer=False).fit([[1.0, 0.0]], starts + 1e10,
                                                                  starts + 1e10 + 1.0)


def test_gpomik_rejects_beams_longer_than_the_limit():
    hits, starts, ends = wall()
    ends = ends * 6000.0                       # 12000 length scales
    with pytest.raises(ValueError, match=r"got segment 0 of 1\.342e\+04 length scales"):
        GPOMIK(optimizer=False).fit(hits, starts, ends)


def test_gpomik_far_queries_get_the_prior():
    m = GPOMIK(optimizer=False).fit(*wall())
    X = np.array([[1e300, -1e300], [1e30, 0.0], [-5e9, 3.0], [2.0, 0.0]])
    mean, var = m.predict(X, return_var=True)
    assert_array_equal(mean[:3], 0.0)
    assert_array_equal(var[:3], m.kernel_.variance)
    assert mean[3] > 0.5
    a, b = m.plsc_
    from scipy.special import ndtr
    assert_allclose(m.predict_proba(X[:3]), ndtr(b / np.sqrt(1 + a * a)), rtol=1e-15)


def test_gpomik_prior_cut_matches_the_tiles_just_beyond_the_reach():
    m = GPOMIK(optimizer=False).fit(*wall())
    reach = np.sqrt(SquaredExponential.cutoff2)
    X = np.array([[2.0 + reach + 1e-6, 0.0], [2.0 + reach - 0.5, 0.0], [0.5, 1.0 + reach]])
    mean, var = m.predict(X, return_var=True)
    tiles = m._predict_cell(m.cells_[0], X[1:2], True)   # inside: the tiles answer
    assert_array_equal(mean[1], tiles[0][0])
    assert mean[0] == 0.0 and var[0] == 1.0
    assert abs(mean[1]) < 1e-12 and abs(var[1] - 1.0) < 1e-12


def test_gpom_far_queries_get_the_prior_and_far_data_is_rejected():
    hits, starts, ends = wall(9)
    m = GPOM(optimizer=False).fit(hits, starts, ends)
    mean, var = m.predict([[1e300, -1e300], [1e30, 0.0], [2.0, 0.0]], return_var=True)
    assert_array_equal(mean[:2], 0.0)
    assert_array_equal(var[:2], m.kernel_.variance)
    assert mean[2] > 0.5
    assert m.predict_proba([[1e300, -1e300]]).shape == (1,)
    with pytest.raises(ValueError, match=r"hits must lie within 1e\+10 length scales"):
        GPOM(optimizer=False).fit(hits * 1e30, starts, ends * 1e30)


def test_gpom_rejects_too_many_free_points():
    hits, starts, ends = wall()
    with pytest.raises(ValueError, match=r"would give 1\.\d+e\+0[78] free points at "
                                         r"free_step=1e-06, more than the limit of 10000000"):
        GPOM(optimizer=False, free_step=1e-6).fit(hits, starts, ends)


# ------------------------------------------------------------------ dense sizes
def test_gpomik_rejects_dense_matrices_beyond_the_limit():
    rng = np.random.default_rng(0)
    hits = rng.uniform(0.0, 100.0, (30_000, 2))
    starts, ends = np.zeros((1, 2)), np.ones((1, 2))
    with pytest.raises(ValueError, match=r"hyper-parameter optimisation needs 6 dense 30001 x "
                                         r"30001 matrices .* lower max_optimize"):
        GPOMIK(max_optimize=10**6).fit(hits, starts, ends)
    with pytest.raises(ValueError, match=r"a local model of 30001 observations needs 4 dense .* "
                                         r"lower max_cell_size"):
        GPOMIK(optimizer=False, max_cell_size=None).fit(hits, starts, ends)


def test_gpomik_kl_update_rejects_a_batch_beyond_the_limit():
    m = GPOMIK(optimizer=False, kl_threshold=0.1).fit(*wall())
    before = fitted_state(m)
    big = np.random.default_rng(0).uniform(0.0, 100.0, (20_000, 2))
    with pytest.raises(ValueError, match=r"the divergences of 20000 new observations needs .* "
                                         r"pass fewer observations at a time"):
        m.update(big)
    assert_same_state(before, fitted_state(m))


# ------------------------------------------------ rejected updates change nothing
@pytest.mark.parametrize("kl_threshold", [None, 1e-3])
def test_gpomik_update_at_1e30_leaves_every_fitted_attribute_unchanged(kl_threshold):
    m = GPOMIK(optimizer=False, kl_threshold=kl_threshold).fit(*wall())
    before = fitted_state(m)
    with pytest.raises(ValueError, match=r"hits must lie within 1e\+10 length scales"):
        m.update([[1e30, 0.0]], [[0.0, 0.0]], [[1e30, 0.0]])
    with pytest.raises(ValueError, match=r"segment_ends must lie within 1e\+10 length scales"):
        m.update(None, [[0.0, 0.0]], [[0.0, -1e12]])
    assert_same_state(before, fitted_state(m))
    assert m.n_accepted_ == 10 and m.n_rejected_ == 0


def test_gpomik_update_that_cannot_be_factorised_changes_nothing():
    hits, starts, ends = wall()
    m = GPOMIK(SparseKernel(1.0, 1.0), noise=1e-12, optimizer=False).fit(hits, starts, ends)
    before = fitted_state(m)
    X = np.random.default_rng(0).uniform(0.0, 1.0, (300, 2))
    with pytest.raises(np.linalg.LinAlgError, match=r"the 300 new observations given the "
                                                    r"newest local model .* raise noise"):
        m.update(X)
    assert_same_state(before, fitted_state(m))
    assert issubclass(np.linalg.LinAlgError, ValueError)


def test_gpomik_fit_that_cannot_be_factorised_names_the_cause():
    X = np.random.default_rng(0).uniform(0.0, 1.0, (300, 2))
    with pytest.raises(np.linalg.LinAlgError, match=r"optimisation subset \(305 x 305, kernel "
                                                    r"SparseKernel.*cannot be factorised"):
        GPOMIK(SparseKernel(1.0, 1.0), noise=1e-12, optimizer=False).fit(X, X[:5] * 0, X[:5])


def test_gpomik_failed_refit_keeps_the_earlier_fit():
    m = GPOMIK(optimizer=False).fit(*wall())
    before = fitted_state(m)
    with pytest.raises(ValueError, match="must lie within"):
        m.fit(*(a * 1e30 for a in wall()))
    assert_same_state(before, fitted_state(m))


# ---------------------------------------------------------- repeated observations
def test_repeated_observations_give_the_same_likelihood_and_gradient():
    rng = np.random.default_rng(0)
    S = rng.uniform(0, 2, (6, 2))
    E = S + rng.uniform(-1, 1, (6, 2))
    E[:2] = S[:2]
    y = np.where(np.arange(6) < 2, 1.0, -np.linalg.norm(E - S, axis=1))
    rep = [0, 0, 1, 2, 3, 3, 3, 4, 5, 5]
    S, E, y = S[rep], E[rep], y[rep]
    index, counts = unique_observations(S, E, y)
    assert index.tolist() == [0, 2, 3, 4, 7, 8] and counts.tolist() == [2, 1, 1, 3, 1, 2]
    k = SquaredExponential(1.3, 0.7)
    theta = np.r_[k.theta, np.log(0.02)]
    full = log_marginal_likelihood(theta, k, ClenshawCurtis(), S, E, y)
    merged = log_marginal_likelihood(theta, k, ClenshawCurtis(), S[index], E[index], y[index],
                                     counts=counts)
    assert_allclose(merged[0], full[0], rtol=1e-12)
    assert_allclose(merged[1], full[1], rtol=1e-9, atol=1e-12)


def test_hit_and_free_point_at_one_place_are_not_merged():
    P = np.array([[1.0, 2.0], [1.0, 2.0]])
    assert unique_observations(P, P, np.array([1.0, -1.0])) is None


def test_identical_beams_fit_like_their_merged_form():
    # 60 identical beams: the optimiser sees 2 distinct observations, the same optimum
    hits = np.tile([[2.0, 0.0]], (60, 1))
    starts = np.zeros_like(hits)
    k, noise, lml = optimize_hyperparameters(
        SquaredExponential(), 0.01, (1e-4, 1.0), np.vstack([hits, starts]),
        np.vstack([hits, hits]), np.r_[np.ones(60), -2.0 * np.ones(60)], ClenshawCurtis(),
        n_restarts=0, rng=np.random.default_rng(0))
    theta = np.r_[k.theta, np.log(noise)]
    full, _ = log_marginal_likelihood(theta, k, ClenshawCurtis(), np.vstack([hits, starts]),
                                      np.vstack([hits, hits]),
                                      np.r_[np.ones(60), -2.0 * np.ones(60)])
    assert_allclose(lml, full, rtol=1e-10)
