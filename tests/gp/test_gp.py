"""Tests of occgp.gp's quadrature rules, PLSC and range observations.

The kernels and integral kernels are tested in test_gp_kernels.py, GPOMIK in test_gpomik.py.
"""

import warnings

import numpy as np
import pytest
import scipy.linalg as sl
from numpy.testing import assert_allclose, assert_array_equal
from scipy.special import erf
from scipy.stats import norm

from occgp.datasets import Scan, room_2d
from occgp.gp import (ClenshawCurtis, Matern32, Simpson, SparseKernel, SquaredExponential,
                      clenshaw_curtis, fit_plsc, loo_predictions, observations_from_scans,
                      plsc_proba, simpson)

KERNEL_CLASSES = [SquaredExponential, Matern32, SparseKernel]


# ------------------------------------------------------------------ quadrature
@pytest.mark.parametrize("n", list(range(2, 18)) + [33, 65, 129, 257])
def test_clenshaw_curtis_is_exact_below_degree_n(n):
    x, w = clenshaw_curtis(n)
    assert x.shape == w.shape == (n,)
    assert x[0] == 0.0 and x[-1] == 1.0 and (np.diff(x) > 0).all()
    assert (w > 0).all()
    assert_allclose(w.sum(), 1.0, rtol=1e-14)
    degrees = np.arange(n)
    assert_allclose((w * x[None, :] ** degrees[:, None]).sum(axis=1), 1.0 / (degrees + 1),
                    rtol=3e-14, atol=1e-16)
    # symmetric about 1/2
    assert_allclose(x + x[::-1], 1.0, atol=1e-15)
    assert_allclose(w, w[::-1], rtol=1e-13)


def test_clenshaw_curtis_is_not_exact_beyond_its_degree():
    x, w = clenshaw_curtis(4)       # exact to degree 3, not 4
    assert abs(w @ x ** 4 - 0.2) > 1e-4
    x, w = clenshaw_curtis(2)       # the trapezoidal rule
    assert_allclose(w, [0.5, 0.5])


@pytest.mark.parametrize("n", [3, 5, 7, 9, 17, 4097])
def test_simpson_is_exact_to_degree_three(n):
    x, w = simpson(n)
    assert x.shape == w.shape == (n,)
    assert_allclose(x, np.linspace(0.0, 1.0, n))
    assert_allclose(w.sum(), 1.0, rtol=1e-14)
    for degree in range(4):
        assert_allclose(w @ x ** degree, 1.0 / (degree + 1), rtol=1e-13)
    if n <= 17:   # its known error on x^4: (b - a) h^4 f''''/ 180
        assert_allclose(w @ x ** 4 - 0.2, 24 * (1.0 / (n - 1)) ** 4 / 180, rtol=1e-8)


@pytest.mark.parametrize("call, error, match", [
    (lambda: clenshaw_curtis(1), ValueError, "n must be at least 2"),
    (lambda: clenshaw_curtis(3.0), TypeError, "n must be an int"),
    (lambda: clenshaw_curtis(True), TypeError, "n must be an int"),
    (lambda: simpson(4), ValueError, "n must be odd"),
    (lambda: simpson(1), ValueError, "n must be at least 3"),
    (lambda: ClenshawCurtis(tol=0.0).orders, ValueError, r"tol must be a number in \[1e-15, 1\)"),
    (lambda: Simpson(tol=1.0).orders, ValueError, "tol must be a number"),
    (lambda: ClenshawCurtis(max_order=2).orders, ValueError, "max_order must be at least 3"),
    (lambda: ClenshawCurtis(max_order=9.0).orders, TypeError, "max_order must be an int"),
    (lambda: ClenshawCurtis(tol=1e-15, max_order=3).reach(SquaredExponential()), ValueError,
     "cannot reach tol"),
])
def test_quadrature_rejects_bad_parameters(call, error, match):
    with pytest.raises(error, match=match):
        call()


def test_quadrature_orders():
    assert ClenshawCurtis().orders == [3, 5, 9, 17, 33, 65, 129, 257]
    assert Simpson().orders[-1] == 4097
    assert ClenshawCurtis(max_order=20).orders == [3, 5, 9, 17]
    x, w = ClenshawCurtis().nodes(9)
    assert_array_equal(x, clenshaw_curtis(9)[0])


@pytest.mark.slow
@pytest.mark.parametrize("cls", KERNEL_CLASSES)
@pytest.mark.parametrize("rule", [ClenshawCurtis, Simpson])
def test_order_grows_with_the_length(rule, cls):
    quadrature, kernel = rule(), cls()
    reach = quadrature.reach(kernel)
    assert reach.shape == (len(quadrature.orders),)
    assert (np.diff(reach) >= 0).all() and reach[-1] > 0
    lengths = np.geomspace(1e-3, 500.0, 60)
    chosen = [quadrature.order_for(kernel, L) for L in lengths]
    nodes = [order * panels for order, panels in chosen]
    assert (np.diff(nodes) >= 0).all()                     # never fewer nodes for longer pieces
    assert all(order in quadrature.orders for order, _ in chosen)
    assert nodes[-1] > nodes[0]
    assert quadrature.order_for(kernel, 10.0)[0] > quadrature.order_for(kernel, 0.05)[0]
    # beyond the reach of the highest order: panels of it
    order, panels = quadrature.order_for(kernel, 4 * reach[-1])
    assert order == quadrature.orders[-1] and panels >= 4


@pytest.mark.parametrize("rule", [ClenshawCurtis, Simpson])
def test_chosen_order_meets_the_tolerance_on_a_kink_free_piece(rule):
    # squared exponential bump centered in a piece: the order picked for its length
    # integrates it to the tolerance relative to the half mass sqrt(pi / 2)
    quadrature, kernel = rule(), SquaredExponential()
    for L in [0.1, 0.7, 2.0, 6.0]:
        order, panels = quadrature.order_for(kernel, L)
        x, w = quadrature.nodes(order)
        t = (np.arange(panels)[:, None] + x[None, :]).ravel() / panels * L
        approx = L / panels * np.tile(w, panels) @ np.exp(-0.5 * (t - L / 2) ** 2)
        exact = np.sqrt(2 * np.pi) * erf(L / (2 * np.sqrt(2)))
        assert abs(approx - exact) <= 1e-10 * np.sqrt(np.pi / 2)


@pytest.mark.parametrize("cls", [Matern32, SparseKernel])
def test_calibration_emits_no_warnings(cls):
    # The first integral kernel of a Matérn or sparse kernel calibrates the rule's
    # reach against quad references at epsrel=1e-14 on pieces down to 0.02 length
    # scales, where quad warns of roundoff: an error under -W error.
    from occgp.gp._quadrature import _LENGTHS, _piece_pairs, _reference
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for L in _LENGTHS[:4]:
            for c, d in _piece_pairs(cls, L):
                _reference(cls(), L, c, d)


# ------------------------------------------------------------------------ PLSC
def _gp_covariance(rng, n, noise=0.1):
    X = np.sort(rng.uniform(0.0, 5.0, n))
    return np.exp(-0.5 * (X[:, None] - X[None, :]) ** 2) + noise * np.eye(n)


def test_loo_predictions_match_brute_force():
    rng = np.random.default_rng(0)
    n = 12
    K = _gp_covariance(rng, n)
    y = rng.normal(size=n)
    mu, var = loo_predictions(np.linalg.cholesky(K), y)
    assert mu.shape == var.shape == (n,)
    for i in range(n):
        rest = np.delete(np.arange(n), i)
        k = K[i, rest]
        solve = sl.solve(K[np.ix_(rest, rest)], np.c_[y[rest], k], assume_a="pos")
        assert_allclose(mu[i], k @ solve[:, 0], rtol=1e-10, atol=1e-12)
        assert_allclose(var[i], K[i, i] - k @ solve[:, 1], rtol=1e-10)


def _loo_log_prob(mu, var, labels, a, b):
    p = plsc_proba(mu, var, a, b)
    return np.sum(np.log(np.where(labels > 0, p, 1.0 - p)))


def _cross_entropy(mu, var, targets, a, b):
    p = plsc_proba(mu, var, a, b)
    return np.sum(targets * np.log(p) + (1.0 - targets) * np.log(1.0 - p))


def _plsc_sample(n, a, b, seed=0):
    rng = np.random.default_rng(seed)
    mu, var = rng.normal(0.0, 1.0, n), rng.uniform(0.05, 0.5, n)
    labels = np.where(rng.uniform(size=n) < plsc_proba(mu, var, a, b), 1.0, -1.0)
    return mu, var, labels


@pytest.mark.parametrize("platt_targets", [True, False])
def test_fit_plsc_recovers_its_parameters_and_improves_the_loo_probability(platt_targets):
    mu, var, labels = _plsc_sample(3000, 2.0, 0.5)
    a, b = fit_plsc(mu, var, labels, platt_targets=platt_targets)
    assert 0 < a and abs(a - 2.0) < 0.3 and abs(b - 0.5) < 0.15
    assert _loo_log_prob(mu, var, labels, a, b) > _loo_log_prob(mu, var, labels, 1.0, 0.0)


def test_fit_plsc_maximises_its_objective():
    mu, var, labels = _plsc_sample(200, 1.5, -0.3, seed=1)
    n_pos, n_neg = (labels > 0).sum(), (labels < 0).sum()
    platt = np.where(labels > 0, (n_pos + 1) / (n_pos + 2), 1 / (n_neg + 2))
    for targets, platt_targets in [((labels > 0).astype(float), False), (platt, True)]:
        a, b = fit_plsc(mu, var, labels, platt_targets=platt_targets)
        best = _cross_entropy(mu, var, targets, a, b)
        for da, db in [(0.02, 0), (-0.02, 0), (0, 0.02), (0, -0.02)]:
            assert best >= _cross_entropy(mu, var, targets, a + da, b + db)


def test_fit_plsc_on_separated_labels():
    mu, var = np.array([1.0, 0.8, 1.2, -0.9, -1.1, -1.0]), np.full(6, 0.1)
    labels = np.array([1, 1, 1, -1, -1, -1])
    # the leave-one-out likelihood grows with a: the optimiser runs far out
    a_free, _ = fit_plsc(mu, var, labels, platt_targets=False)
    assert a_free > 10
    # Platt's targets keep it finite, and still on the right side of 1/2
    a, b = fit_plsc(mu, var, labels)
    assert 0 < a < a_free
    p = plsc_proba(mu, var, a, b)
    assert (p[labels > 0] > 0.5).all() and (p[labels < 0] < 0.5).all()


@pytest.mark.parametrize("args, match", [
    (([1.0, -1.0], [0.1, 0.1], [1, -1, 1]), "mu, var and labels must be 1-D of one length"),
    (([[1.0, -1.0]], [[0.1, 0.1]], [[1, -1]]), "must be 1-D"),
    (([1.0, -1.0], [0.1, 0.1], [1, 0]), r"labels must be -1 or \+1"),
    (([1.0, -1.0], [0.1, 0.1], [1, 1]), "PLSC needs both classes"),
])
def test_fit_plsc_rejects_bad_input(args, match):
    with pytest.raises(ValueError, match=match):
        fit_plsc(*args)


def test_plsc_proba_formula():
    rng = np.random.default_rng(0)
    mu, var = rng.normal(size=20), rng.uniform(0.0, 2.0, 20)
    a, b = 1.7, -0.3
    p = plsc_proba(mu, var, a, b)
    assert p.shape == (20,)
    assert_allclose(p, norm.cdf((a * mu + b) / np.sqrt(1 + a ** 2 * var)), rtol=1e-14)
    assert_allclose(plsc_proba(mu, 0.0 * var, 1.0, 0.0), norm.cdf(mu), rtol=1e-14)
    assert_allclose(p + plsc_proba(-mu, var, a, -b), 1.0, rtol=1e-14)
    # uncertainty pulls probabilities towards 1/2
    assert (np.abs(plsc_proba(mu, var + 5.0, a, b) - 0.5) <= np.abs(p - 0.5)).all()


# --------------------------------------------------------------- observations
def test_observations_from_scans_of_the_2d_room():
    scans = room_2d().scan(n_poses=3)
    hits, starts, ends = observations_from_scans(scans)
    n_beams = sum(len(s.ranges) for s in scans)
    hit = np.concatenate([s.hit for s in scans])
    assert starts.shape == ends.shape == (n_beams, 2)
    assert hits.shape == (hit.sum(), 2)
    assert (~hit).any() and hit.any()          # both kinds occur in these three scans
    # every beam starts at its scan's origin
    assert_array_equal(starts, np.vstack([np.tile(s.origin, (len(s.ranges), 1)) for s in scans]))
    lengths = np.linalg.norm(ends - starts, axis=1)
    max_range = np.concatenate([np.full(len(s.ranges), s.max_range) for s in scans])
    # beams without a return are free segments to the maximum range
    assert_allclose(lengths[~hit], max_range[~hit], rtol=1e-12)
    assert (lengths[hit] < max_range[hit]).all()
    # hits are the returning ends, in order
    assert_array_equal(hits, ends[hit])
    assert_allclose(hits, np.vstack([s.points for s in scans]), rtol=1e-12)


def test_observations_from_point_clouds():
    rng = np.random.default_rng(0)
    clouds = [Scan(rng.normal(size=(4, 3)), np.zeros(3)),       # a Scan, or a (points, origin) pair
              (rng.normal(size=(2, 3)), [1.0, 2.0, 3.0])]
    hits, starts, ends = observations_from_scans(clouds)
    assert hits.shape == starts.shape == ends.shape == (6, 3)
    assert_array_equal(hits, np.vstack([c[0] for c in clouds]))
    assert_array_equal(ends, hits)
    assert_array_equal(starts[4:], [[1.0, 2.0, 3.0]] * 2)


@pytest.mark.parametrize("scans, match", [
    ([], "scans must hold at least one scan"),
    ([(np.full((2, 3), np.nan), np.zeros(3))], r"scans\[0\].points must be finite"),
    ([(np.zeros((2, 3)), np.zeros(3)), (np.zeros(3), np.zeros(3))], r"scans\[1\].points"),
])
def test_observations_from_scans_rejects_bad_input(scans, match):
    with pytest.raises(ValueError, match=match):
        observations_from_scans(scans)


@pytest.mark.parametrize("origin", [[np.nan, 0.0, 0.0], [0.0, 0.0]])
def test_observations_from_scans_rejects_a_bad_origin(origin):
    with pytest.raises(ValueError, match=r"\borigin\b"):
        observations_from_scans([(np.zeros((2, 3)), origin)])


def test_observations_from_scans_rejects_four_dimensional_points():
    with pytest.raises(ValueError, match=r"scans\[0\].points"):
        observations_from_scans([(np.zeros((2, 4)), np.zeros(4))])
