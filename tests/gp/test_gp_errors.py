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


# ------------------------------------------------------- bad input at every entry
from pathlib import Path  # noqa: E402

from occgp.gp import (ClenshawCurtis as CC, Matern32, OccupancyGrid, Simpson,  # noqa: E402
                      clenshaw_curtis, fit_plsc, grid_points, integral_kernel, loo_predictions,
                      observations_from_scans, plsc_proba, predict_grid, simpson)

HITS, STARTS, ENDS = wall()


def _gpomik():
    return GPOMIK(optimizer=False).fit(HITS, STARTS, ENDS)


def _gpom():
    return GPOM(optimizer=False).fit(HITS, STARTS, ENDS)


BAD_CALLS = [
    # (id, call, exception, message regex)
    ("gpomik-ragged-hits", lambda: GPOMIK().fit([[1.0], [1.0, 2.0]], STARTS, ENDS), ValueError,
     r"hits must be a numeric array, could not convert it"),
    ("gpomik-str-hits", lambda: GPOMIK().fit([["a", "b"]], STARTS, ENDS), TypeError,
     r"hits must hold real numbers"),
    ("gpomik-path-starts", lambda: GPOMIK().fit(HITS, Path("/tmp"), ENDS), TypeError,
     r"segment_starts must hold real numbers"),
    ("gpomik-optimizer-str", lambda: GPOMIK(optimizer="yes").fit(HITS, STARTS, ENDS), TypeError,
     r"optimizer must be a bool, got str"),
    ("gpomik-random-state-str", lambda: GPOMIK(random_state="x").fit(HITS, STARTS, ENDS),
     TypeError, r"random_state must be None, a non-negative int or a numpy Generator"),
    ("gpomik-random-state-bool", lambda: GPOMIK(random_state=True).fit(HITS, STARTS, ENDS),
     TypeError, r"random_state must be None, an int or a numpy Generator, got bool"),
    ("gpomik-n-restarts-huge", lambda: GPOMIK(n_restarts=2**70).fit(HITS, STARTS, ENDS),
     ValueError, r"n_restarts must be at most 1000"),
    ("gpomik-n-jobs-bigint", lambda: GPOMIK(optimizer=False, n_jobs=2**70).fit(
        HITS, STARTS, ENDS).n_accepted_ == 10 or None, None, None),
    ("gpomik-return-var-str", lambda: _gpomik().predict(HITS, return_var="no"), TypeError,
     r"return_var must be a bool, got str"),
    ("gpom-return-var-none", lambda: _gpom().predict(HITS, return_var=None), TypeError,
     r"return_var must be a bool, got NoneType"),
    ("gpom-random-state-str", lambda: GPOM(random_state="x").fit(HITS, STARTS, ENDS),
     TypeError, r"random_state must be None, an int or a RandomState instance"),
    ("gpom-n-restarts-huge", lambda: GPOM(n_restarts=10**6).fit(HITS, STARTS, ENDS), ValueError,
     r"n_restarts must be at most 1000"),
    ("kernel-call-nan", lambda: SquaredExponential()([[np.nan, 0.0]]), ValueError,
     r"X must be finite"),
    ("kernel-call-str", lambda: SquaredExponential()("ab"), TypeError,
     r"X must hold real numbers"),
    ("kernel-call-y-inf", lambda: Matern32()(HITS, [[np.inf, 0.0]]), ValueError,
     r"Y must be finite"),
    ("kernel-call-3d", lambda: SquaredExponential()(np.zeros((1, 2, 2))), ValueError,
     r"X must have shape \(n_samples, n_features\), got \(1, 2, 2\)"),
    ("kernel-call-eval-gradient-str", lambda: SquaredExponential()(HITS, eval_gradient="y"),
     TypeError, r"eval_gradient must be a bool, got str"),
    ("kernel-call-huge", lambda: SquaredExponential()(np.zeros((100_000, 3))), ValueError,
     r"kernel matrix of 100000 x 100000 samples needs 373 GiB"),
    ("kernel-diag-ragged", lambda: SparseKernel().diag([[1.0], [1.0, 2.0]]), ValueError,
     r"X must be a numeric array, could not convert it"),
    ("kernel-with-theta-str", lambda: SquaredExponential().with_theta("ab"), TypeError,
     r"theta must hold real numbers"),
    ("kernel-profile-str", lambda: SquaredExponential().profile("a"), TypeError,
     r"s must hold real numbers"),
    ("integral-kernel-eval-gradient-str",
     lambda: integral_kernel(SquaredExponential(), HITS, HITS, eval_gradient="y"), TypeError,
     r"eval_gradient must be a bool, got str"),
    ("integral-kernel-1e30", lambda: integral_kernel(SquaredExponential(), [[0, 0]], [[1e30, 0]]),
     ValueError, r"observation_ends must lie within 1e\+10 length scales of the origin"),
    ("integral-kernel-long-segments",
     lambda: integral_kernel(Matern32(), [[0, 0], [0, 1]], [[2e4, 0], [2e4, 1]]), ValueError,
     r"observations must be at most 10000 length scales long"),
    ("integral-kernel-huge", lambda: integral_kernel(SquaredExponential(), np.zeros((200_000, 2)),
                                                     np.zeros((200_000, 2))), ValueError,
     r"kernel matrix needs 1 dense 200000 x 200000 matrices \(298 GiB\)"),
    ("integral-kernel-ragged", lambda: integral_kernel(SquaredExponential(), [[1.0], [1, 2]],
                                                       HITS), ValueError,
     r"observation_starts must be a numeric array"),
    ("order-for-inf", lambda: CC().order_for(SquaredExponential(), np.inf), ValueError,
     r"length must lie in \[0.0, inf\), got inf"),
    ("order-for-str", lambda: Simpson().order_for(SquaredExponential(), "1"), TypeError,
     r"length must be a real number, got str"),
    ("order-for-kernel", lambda: CC().order_for("se", 1.0), TypeError,
     r"kernel must be one of occgp.gp's kernels"),
    ("max-order-huge", lambda: CC(max_order=2**70).orders, ValueError,
     r"max_order must be at least 3 and at most 16385"),
    ("clenshaw-curtis-huge", lambda: clenshaw_curtis(10**9), ValueError,
     r"n must be at least 2 and at most 16385, got 1000000000"),
    ("simpson-huge", lambda: simpson(2**40 + 1), ValueError, r"n must be at least 3 and at most"),
    ("loo-not-square", lambda: loo_predictions([1.0, 2.0], [1.0, 2.0]), ValueError,
     r"L must be 2-D, got shape \(2,\)"),
    ("loo-mismatched", lambda: loo_predictions(np.eye(3), [1.0, 2.0]), ValueError,
     r"L must have shape \(n, n\) with n = len\(y\) = 2, got \(3, 3\)"),
    ("loo-singular", lambda: loo_predictions(np.zeros((2, 2)), [1.0, 2.0]), ValueError,
     r"L must be a lower Cholesky factor, with a positive diagonal"),
    ("loo-none", lambda: loo_predictions(None, [1.0]), TypeError, r"L must hold real numbers"),
    ("fit-plsc-nan", lambda: fit_plsc([np.nan, 1.0], [1.0, 1.0], [1, -1]), ValueError,
     r"mu must be finite"),
    ("fit-plsc-negative-var", lambda: fit_plsc([1.0, 1.0], [-5.0, 1.0], [1, -1]), ValueError,
     r"var must be non-negative, got a minimum of -5.0"),
    ("fit-plsc-platt-str", lambda: fit_plsc([1.0, -1.0], [1.0, 1.0], [1, -1],
                                            platt_targets="y"), TypeError,
     r"platt_targets must be a bool, got str"),
    ("plsc-proba-nan", lambda: plsc_proba([np.nan], [1.0], 1.0, 0.0), ValueError,
     r"mu must be finite"),
    ("plsc-proba-a-str", lambda: plsc_proba([0.0], [1.0], "1", 0.0), TypeError,
     r"a must be a real number, got str"),
    ("plsc-proba-b-inf", lambda: plsc_proba([0.0], [1.0], 1.0, np.inf), ValueError,
     r"b must lie in \(-inf, inf\), got inf"),
    ("plsc-proba-shapes", lambda: plsc_proba([0.0, 1.0], [1.0, 1.0, 1.0], 1.0, 0.0), ValueError,
     r"mu and var must broadcast together, got shapes \(2,\) and \(3,\)"),
    ("scans-int", lambda: observations_from_scans(5), TypeError,
     r"scans must be a list of scans, got int"),
    ("scans-str", lambda: observations_from_scans("ab"), TypeError,
     r"scans must be a list of scans, got str"),
    ("scans-item-int", lambda: observations_from_scans([5]), TypeError,
     r"scans\[0\] must be a LaserScan2D, a Scan or a \(points, origin\) pair, got int"),
    ("scans-ragged", lambda: observations_from_scans([([[1.0], [1.0, 2.0]], [0, 0])]),
     ValueError, r"scans\[0\].points must be a numeric array"),
    ("predict-grid-none-model", lambda: predict_grid(None, [0, 0], [1, 1], 0.5), TypeError,
     r"model must have a predict_proba\(\) method"),
    ("grid-points-huge", lambda: grid_points([0, 0], [1e6, 1e6], 1e-3), ValueError,
     r"has 1e\+18 cells, more than max_points=20000000"),
    ("occupancy-grid-1e30", lambda: OccupancyGrid().fit([[1e30, 0.0]], None, None), ValueError,
     r"hits must lie within 1e\+15 cells of the origin"),
]


@pytest.mark.parametrize("call, error, match", [c[1:] for c in BAD_CALLS],
                         ids=[c[0] for c in BAD_CALLS])
def test_bad_input_gives_a_clear_error(call, error, match):
    if error is None:       # accepted (and bounded)
        assert call() is not None
        return
    with pytest.raises(error, match=match):
        call()


def test_scans_hit_mask_must_match_the_points():
    from types import SimpleNamespace
    scan = SimpleNamespace(end_points=HITS, origin=np.zeros(2), hit=np.ones(3, dtype=bool))
    with pytest.raises(ValueError, match=r"scans\[0\].hit must be a bool array of shape \(5,\)"):
        observations_from_scans([scan])


def test_n_jobs_beyond_the_cores_counts_as_every_core():
    from occgp.gp._limits import threads
    from occgp._validation import n_threads
    assert threads(2**70) == threads(-1) == n_threads(-1)
    assert threads(None) == 1 and threads(1) == 1


def test_inverse_length_scales_and_take_reject_bad_arguments():
    from occgp.gp import Observations, SquaredExponential
    k = SquaredExponential(length_scale=[1.0, 2.0])
    np.testing.assert_array_equal(k.inverse_length_scales(2), [1.0, 0.5])
    with pytest.raises(TypeError, match="n_dims must be a non-negative int, got str"):
        k.inverse_length_scales("2")
    with pytest.raises(ValueError, match=r"n_dims must lie in \[0, 65536\], got -1"):
        k.inverse_length_scales(-1)
    obs = Observations(*(np.zeros((3, 2)), np.zeros((3, 2)), np.ones(3), np.ones(3),
                         np.zeros(3)))
    assert len(obs.take([0, 2]).y) == 2
    with pytest.raises(ValueError, match=r"index: index 5 is out of bounds .*3 observations"):
        obs.take(5)
    with pytest.raises(ValueError, match="index: boolean index did not match"):
        obs.take(np.ones(4, dtype=bool))
