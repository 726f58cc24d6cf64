"""Tests of GPOMIK, the GP occupancy map with integral kernels (occgp.gp._gpomik)."""

import pickle

import numpy as np
import pytest
import scipy.linalg as sl
from numpy.testing import assert_allclose, assert_array_equal
from scipy.stats import multivariate_normal
from sklearn.base import clone
from sklearn.exceptions import NotFittedError
from sklearn.gaussian_process.kernels import RBF

from _helpers import assert_gradient_matches, assert_prediction_shapes
from occgp.gp import (GPOMIK, ClenshawCurtis, Matern32, Simpson, SparseKernel,
                      SquaredExponential, integral_kernel)
from occgp.gp._gpr import log_marginal_likelihood

KERNELS = {
    "se": lambda dim=2: SquaredExponential(1.0, 0.5),
    "se-ard": lambda dim=2: SquaredExponential(1.0, [0.5, 0.8, 0.6][:dim]),
    "matern32": lambda dim=2: Matern32(1.0, 0.5),
    "sparse": lambda dim=2: SparseKernel(1.0, 1.0),
}


def wall(n=6, x=2.0, origin=(0.0, 0.0), y_range=(-1.0, 1.0)):
    """A wall at `x` seen by `n` beams from `origin`: hits, beam starts, beam ends."""
    y = np.linspace(*y_range, n)
    hits = np.column_stack([np.full(n, x), y])
    return hits, np.tile(origin, (n, 1)).astype(float), hits.copy()


def wall_3d(n=3):
    """A wall at x = 2 seen from the origin in 3D, n x n beams."""
    y, z = np.meshgrid(np.linspace(-1, 1, n), np.linspace(-0.5, 0.5, n))
    hits = np.column_stack([np.full(n * n, 2.0), y.ravel(), z.ravel()])
    return hits, np.zeros_like(hits), hits.copy()


def stack(*scenes):
    return tuple(np.vstack(parts) for parts in zip(*scenes))


def dense_prediction(model, cell, X):
    """Latent mean and variance of one cell by dense linear algebra."""
    obs = cell.obs
    Ks = integral_kernel(model.kernel_, X, X, obs.starts, obs.ends)
    K = integral_kernel(model.kernel_, obs.starts, obs.ends)
    K[np.diag_indices_from(K)] += model.noise_ + model.jitter_
    solved = sl.solve(K, np.c_[obs.y, Ks.T], assume_a="pos")
    mean = Ks @ solved[:, 0]
    var = model.kernel_.variance - np.einsum("ij,ji->i", Ks, solved[:, 1:])
    return mean, var


# ----------------------------------------------------------------- regression
@pytest.mark.parametrize("name", list(KERNELS))
def test_interpolates_noiseless_training_data(name):
    hits, starts, ends = wall()
    m = GPOMIK(KERNELS[name](), noise=1e-6, optimizer=False).fit(hits, starts, ends)
    assert_allclose(m.predict(hits), 1.0, atol=1e-3)
    # the latent function integrates to -length along every beam
    obs = m.cells_[0].obs
    along = integral_kernel(m.kernel_, starts, ends, obs.starts, obs.ends) @ m.cells_[0].alpha
    assert_allclose(along, -np.linalg.norm(ends - starts, axis=1), rtol=1e-3)
    _, var = m.predict(hits, return_var=True)
    assert (var < 1e-3 * m.kernel_.variance).all()
    p_hits = m.predict_proba(hits)
    p_free = m.predict_proba(0.4 * hits)          # on the beams, near the sensor
    assert (p_hits > 0.5).all() and (p_free < 0.5).all()


@pytest.mark.parametrize("name", ["se", "se-ard", "matern32", "sparse"])
@pytest.mark.parametrize("dim", [2, 3])
def test_log_marginal_likelihood_gradient(name, dim):
    rng = np.random.default_rng(0)
    kernel = KERNELS[name](dim)
    hits = rng.uniform(-1.0, 1.0, (5, dim))
    starts = rng.uniform(-1.0, 1.0, (6, dim))
    ends = starts + rng.normal(0.0, 0.8, (6, dim))
    X_starts, X_ends = np.vstack([hits, starts]), np.vstack([hits, ends])
    y = np.r_[np.ones(5), -np.linalg.norm(ends - starts, axis=1)]
    theta = np.r_[kernel.theta, np.log(0.05)]
    value = assert_gradient_matches(log_marginal_likelihood, theta, kernel, ClenshawCurtis(),
                                    X_starts, X_ends, y)
    # the value: a Gaussian log density with K + (noise + jitter) I
    K = integral_kernel(kernel, X_starts, X_ends)
    cov = K + (0.05 + 1e-10 * np.mean(np.diag(K))) * np.eye(len(y))
    assert_allclose(value, multivariate_normal(np.zeros(len(y)), cov).logpdf(y), rtol=1e-10)


def test_fitted_log_marginal_likelihood_is_a_maximum():
    hits, starts, ends = wall(8)
    m = GPOMIK(random_state=0, n_restarts=0).fit(hits, starts, ends)
    value = m.log_marginal_likelihood_value_
    assert np.isfinite(value)
    obs = m.cells_[0].obs
    theta = np.r_[m.kernel_.theta, np.log(m.noise_)]
    at, grad = log_marginal_likelihood(theta, m.kernel_, ClenshawCurtis(), obs.starts, obs.ends,
                                       obs.y)
    assert_allclose(at, value, rtol=1e-8)
    bounds = np.vstack([m.kernel_.bounds, np.log(m.noise_bounds)])
    interior = (theta > bounds[:, 0] + 1e-6) & (theta < bounds[:, 1] - 1e-6)
    assert_allclose(grad[interior], 0.0, atol=1e-3 * max(1.0, abs(value)))
    # unoptimised models report no likelihood
    assert np.isnan(GPOMIK(optimizer=False).fit(hits, starts, ends).log_marginal_likelihood_value_)


# ------------------------------------------------------------ estimator basics
@pytest.mark.parametrize("dim", [1, 2, 3])
def test_fit_returns_self_and_output_shapes(dim):
    rng = np.random.default_rng(0)
    hits = rng.uniform(1.0, 2.0, (5, dim))
    m = GPOMIK(optimizer=False)
    assert m.fit(hits, np.zeros_like(hits), hits) is m
    assert m.n_dims_ == dim and m.n_accepted_ == 10 and m.n_rejected_ == 0
    var = assert_prediction_shapes(m, rng.uniform(-1.0, 3.0, (7, dim)))
    assert (var >= 0).all()
    assert len(m.plsc_) == 2 and m.plsc_[0] > 0
    assert m.update(hits + 0.5) is m and m.n_accepted_ == 15


def test_predict_before_fit_raises():
    m = GPOMIK()
    for call in (lambda: m.predict([[0.0, 0.0]]), lambda: m.predict_proba([[0.0, 0.0]]),
                 lambda: m.update([[0.0, 0.0]]), lambda: m.kl_divergence([[0.0, 0.0]])):
        with pytest.raises(NotFittedError, match="not fitted"):
            call()


def test_clone_pickle_and_kernel_left_untouched():
    kernel = SquaredExponential(1.0, 0.5)
    hits, starts, ends = wall()
    m = GPOMIK(kernel, random_state=0, n_restarts=0).fit(hits, starts, ends)
    assert kernel == SquaredExponential(1.0, 0.5)          # the optimiser works on a copy
    assert m.kernel_ != kernel
    assert clone(m).get_params()["kernel"] == kernel
    X = np.random.default_rng(0).uniform(-1.0, 3.0, (5, 2))
    assert_array_equal(pickle.loads(pickle.dumps(m)).predict_proba(X), m.predict_proba(X))


def test_random_state_makes_fits_reproducible():
    hits, starts, ends = stack(wall(8), wall(5, x=2.5, y_range=(1.5, 2.5)))
    X = np.random.default_rng(0).uniform(-1.0, 3.0, (6, 2))
    fits = [GPOMIK(random_state=3, n_restarts=1, max_optimize=12).fit(hits, starts, ends)
            for _ in range(2)]
    assert fits[0].kernel_ == fits[1].kernel_ and fits[0].noise_ == fits[1].noise_
    assert fits[0].plsc_ == fits[1].plsc_
    assert_array_equal(fits[0].predict_proba(X), fits[1].predict_proba(X))
    assert np.isfinite(fits[0].log_marginal_likelihood_value_)
    lo, hi = np.exp(fits[0].kernel_.bounds[1])
    assert lo <= fits[0].kernel_.length_scale <= hi
    assert 1e-4 <= fits[0].noise_ <= 1.0


def test_quadrature_choices_agree():
    hits, starts, ends = wall(4)
    X = np.random.default_rng(0).uniform(-1.0, 3.0, (6, 2))

    def predict(quadrature):
        m = GPOMIK(Matern32(1.0, 1.0), optimizer=False, quadrature=quadrature)
        return m.fit(hits, starts, ends).predict(X)

    ref = predict("clenshaw-curtis")
    assert_array_equal(predict(ClenshawCurtis()), ref)
    assert_array_equal(predict(None), ref)
    simpson = predict("simpson")
    assert_array_equal(predict(Simpson()), simpson)
    assert_allclose(simpson, ref, rtol=1e-6, atol=1e-8)
    assert not np.array_equal(simpson, ref)          # the rule is actually used


@pytest.mark.parametrize("kernel", [SquaredExponential(1.0, 0.3),
                                    SquaredExponential(1.0, [0.3, 0.7]),
                                    SparseKernel(1.0, 1.0)], ids=["se", "se-ard", "sparse"])
def test_tiled_prediction_matches_dense_algebra(kernel):
    # observations spread over many tiles and far beyond the kernel's cutoff
    scenes = [wall(4, x=2.0 + 12 * i, origin=(12.0 * i, 3.0 * i), y_range=(3 * i - 1, 3 * i + 1))
              for i in range(4)]
    hits, starts, ends = stack(*scenes)
    m = GPOMIK(kernel, optimizer=False, max_cell_size=None).fit(hits, starts, ends)
    rng = np.random.default_rng(0)
    X = np.vstack([rng.uniform([-2, -3], [42, 12], (40, 2)), hits, 0.5 * (starts + ends)])
    mean, var = m.predict(X, return_var=True)
    want_mean, want_var = dense_prediction(m, m.cells_[0], X)
    assert_allclose(mean, want_mean, rtol=1e-9, atol=1e-12)
    assert_allclose(var, np.maximum(want_var, 0.0), rtol=1e-7, atol=1e-10)
    assert_array_equal(GPOMIK(kernel, optimizer=False, max_cell_size=None, n_jobs=2).fit(
        hits, starts, ends).predict(X), mean)


# ------------------------------------------------------------------- updates
@pytest.mark.parametrize("name", ["se", "matern32"])
def test_update_equals_full_refactorisation(name):
    kernel = KERNELS[name]()
    hits, starts, ends = wall(4)
    # 4 hits and 5 beams, then 3 and 3
    A = (hits, np.vstack([starts, [[0.0, 0.0]]]), np.vstack([ends, [[2.6, 2.2]]]))
    B = wall(3, x=2.5, y_range=(0.5, 1.5))
    m = GPOMIK(kernel, optimizer=False, max_cell_size=None).fit(*A)
    assert m.update(*B) is m
    assert len(m.cells_) == 1 and m.n_accepted_ == 15 and m.cells_[0].size == 15
    # the reference: hits of A, beams of A, hits of B, beams of B, same noise and jitter
    starts = np.vstack([A[0], A[1], B[0], B[1]])
    ends = np.vstack([A[0], A[2], B[0], B[2]])
    y = np.r_[np.ones(4), -np.linalg.norm(A[2] - A[1], axis=1),
              np.ones(3), -np.linalg.norm(B[2] - B[1], axis=1)]
    cell = m.cells_[0]
    assert_array_equal(cell.obs.starts, starts)
    assert_array_equal(cell.obs.ends, ends)
    assert_allclose(cell.obs.y, y, rtol=1e-15)
    K = integral_kernel(m.kernel_, starts, ends)
    K[np.diag_indices_from(K)] += m.noise_ + m.jitter_
    L = sl.cholesky(K, lower=True)
    assert_allclose(cell.L, L, rtol=0, atol=1e-9 * np.abs(L).max())
    alpha = sl.cho_solve((L, True), y)
    assert_allclose(cell.alpha, alpha, rtol=0, atol=1e-9 * np.abs(alpha).max())
    X = np.random.default_rng(0).uniform(-1.0, 3.0, (10, 2))
    mean, var = m.predict(X, return_var=True)
    Ks = integral_kernel(m.kernel_, X, X, starts, ends)
    assert_allclose(mean, Ks @ alpha, rtol=1e-9, atol=1e-12)
    v = sl.solve_triangular(L, Ks.T, lower=True)
    assert_allclose(var, m.kernel_.variance - (v * v).sum(axis=0), rtol=1e-8, atol=1e-12)
    # a model fitted on A and B at once (same hyper-parameters; its jitter comes from
    # all of the data, hence the looser tolerance) predicts the same
    full = GPOMIK(kernel, optimizer=False, max_cell_size=None).fit(*stack(A, B))
    assert_allclose(full.predict(X), mean, rtol=1e-6, atol=1e-9)


def test_update_then_predict_uses_the_new_factor():
    # predict with variance caches K^-1 per cell: an update must not reuse a stale one
    hits, starts, ends = wall()
    m = GPOMIK(optimizer=False, max_cell_size=None).fit(hits, starts, ends)
    X = np.array([[3.5, 0.0], [2.0, 2.5]])
    before = m.predict(X, return_var=True)
    m.update([[3.5, 0.0]], [[0.0, 0.0]], [[3.0, 2.5]])
    mean, var = m.predict(X, return_var=True)
    want_mean, want_var = dense_prediction(m, m.cells_[0], X)
    assert_allclose(mean, want_mean, rtol=1e-9)
    assert_allclose(var, want_var, rtol=1e-7, atol=1e-12)
    assert var[0] < 0.1 * before[1][0]


def test_kl_active_sampling_rejects_a_duplicate_and_accepts_a_new_hit():
    hits, starts, ends = wall()
    m = GPOMIK(optimizer=False, kl_threshold=0.5, max_cell_size=None).fit(hits, starts, ends)
    kl = m.kl_divergence(hits[:1])
    assert kl.shape == (1,) and 0 <= kl[0] < 0.5
    m.update(hits[2:3])                                 # an exact duplicate
    assert m.n_rejected_ == 1 and m.n_accepted_ == 12 and m.cells_[0].size == 12
    m.update([[6.0, 5.0]])                              # far from the data
    assert m.n_rejected_ == 1 and m.n_accepted_ == 13 and m.cells_[0].size == 13
    assert m.predict_proba([[6.0, 5.0]])[0] > 0.5
    # the KL of a duplicate is well below that of the new hit
    assert m.kl_divergence(hits[:1])[0] < 0.1 * m.kl_divergence([[-4.0, 4.0]])[0]
    # a mixed batch: only the informative observation is kept
    m.update([[2.0, 0.2], [-5.0, -5.0]])
    assert m.n_rejected_ == 2 and m.n_accepted_ == 14


def test_kl_sampling_sees_earlier_observations_of_the_same_batch():
    hits, starts, ends = wall()
    m = GPOMIK(optimizer=False, kl_threshold=0.5, max_cell_size=None).fit(hits, starts, ends)
    kl = m.kl_divergence([[6.0, 5.0], [6.0, 5.0]])
    assert kl[0] > 0.5 > kl[1]                          # the second copy adds nothing
    m.update([[6.0, 5.0], [6.0, 5.0], [-5.0, 5.0]])
    assert m.n_rejected_ == 1 and m.cells_[0].size == 14
    # the sequential predictions equal those of a model that took the earlier ones
    m2 = GPOMIK(optimizer=False, max_cell_size=None).fit(hits, starts, ends)
    m2.update([[6.0, 5.0]])
    both = GPOMIK(optimizer=False, max_cell_size=None).fit(hits, starts, ends)
    seq = both.kl_divergence([[6.0, 5.0], [4.0, 4.0]])[1]
    assert_allclose(seq, m2.kl_divergence([[4.0, 4.0]])[0], rtol=1e-8)


def test_kl_sampling_asks_older_cells_too():
    hits, starts, ends = wall()
    far_hits = hits + [20.0, 0.0]
    m = GPOMIK(optimizer=False, kl_threshold=0.5, max_cell_size=12)
    m.fit(np.vstack([hits, far_hits]), np.vstack([starts, starts + [20.0, 0.0]]),
          np.vstack([ends, ends + [20.0, 0.0]]))
    assert len(m.cells_) >= 2
    # each half of the data is known to one cell: duplicates anywhere are rejected
    assert (m.kl_divergence(np.vstack([hits[:2], far_hits[:2]])) < 0.5).all()


def test_kl_divergence_is_non_negative():
    rng = np.random.default_rng(0)
    hits, starts, ends = wall()
    m = GPOMIK(optimizer=False).fit(hits, starts, ends)
    new_hits = rng.uniform(-2.0, 4.0, (15, 2))
    new_starts = rng.uniform(-2.0, 4.0, (10, 2))
    new_ends = new_starts + rng.normal(0.0, 1.0, (10, 2))
    kl = m.kl_divergence(new_hits, new_starts, new_ends)
    assert kl.shape == (25,)
    assert (kl >= 0).all() and np.isfinite(kl).all()
    assert_allclose(m.kl_divergence(new_hits[:3]), kl[:3], rtol=1e-12)   # hits first


def test_rejected_update_leaves_the_model_unchanged():
    hits, starts, ends = wall()
    m = GPOMIK(optimizer=False, kl_threshold=0.5).fit(hits, starts, ends)
    X = np.random.default_rng(0).uniform(-1.0, 3.0, (8, 2))
    before = m.predict(X, return_var=True)
    state = (len(m.cells_), m.cells_[0].size, m.n_accepted_, m.n_rejected_)
    for bad in [dict(hits=[[np.nan, 0.0]]), dict(hits=[[0.0, 0.0, 0.0]]),
                dict(hits=[[0.0, 0.0]], segment_starts=[[0.0, 0.0]]),
                dict(segment_starts=[[0.0, 0.0]], segment_ends=[[1.0, np.inf]])]:
        with pytest.raises(ValueError):
            m.update(**bad)
        assert (len(m.cells_), m.cells_[0].size, m.n_accepted_, m.n_rejected_) == state
    m.update(hits[:2])                                  # rejected by KL
    assert m.n_rejected_ == 2 and m.cells_[0].size == state[1]
    after = m.predict(X, return_var=True)
    assert_array_equal(after[0], before[0])
    assert_array_equal(after[1], before[1])


# --------------------------------------------------------------------- cells
def test_cells_split_fit_and_update():
    room_a = wall(6, x=2.0)
    room_b = wall(6, x=12.0, origin=(10.0, 0.0))
    hits, starts, ends = stack(room_a, room_b)
    m = GPOMIK(SquaredExponential(1.0, 0.5), optimizer=False, max_cell_size=8).fit(
        hits, starts, ends)
    sizes = [c.size for c in m.cells_]
    assert len(sizes) >= 2 and max(sizes) <= 8 and sum(sizes) == 24
    for cell in m.cells_:
        occupied = cell.obs.starts[cell.obs.labels > 0]
        free = cell.obs.anchors[cell.obs.labels < 0]
        origin = cell.obs.starts[cell.obs.labels < 0]
        near_sensor = origin + 0.3 * (cell.obs.ends[cell.obs.labels < 0] - origin)
        if len(occupied):
            assert (m.predict_proba(occupied) > 0.5).all()
        if len(free):
            assert (m.predict_proba(near_sensor) < 0.5).all()
    # far from every cell: the prior
    mean, var = m.predict([[50.0, 50.0]], return_var=True)
    assert mean[0] == 0.0 and var[0] == m.kernel_.variance
    # updates fill the newest cell, then start new ones, never past the limit
    n_cells = len(m.cells_)
    m.update(*wall(6, x=-3.0, origin=(0.0, 0.0), y_range=(2.0, 3.0)))
    sizes = [c.size for c in m.cells_]
    assert len(sizes) > n_cells and max(sizes) <= 8 and sum(sizes) == 36
    assert m.n_accepted_ == 36
    new_hits = wall(6, x=-3.0, y_range=(2.0, 3.0))[0]
    assert (m.predict_proba(new_hits) > 0.5).all()


def test_max_cell_size_none_keeps_one_cell():
    hits, starts, ends = stack(wall(6), wall(6, x=12.0, origin=(10.0, 0.0)))
    m = GPOMIK(optimizer=False, max_cell_size=None).fit(hits, starts, ends)
    m.update(*wall(5, x=-3.0))
    assert len(m.cells_) == 1 and m.cells_[0].size == 34


# -------------------------------------------------------------------- inputs
def test_zero_length_beams_are_free_points():
    hits, starts, ends = wall()
    starts = np.vstack([starts, [[1.0, 0.0]]])
    ends = np.vstack([ends, [[1.0, 0.0]]])                 # a beam of length 0
    m = GPOMIK(optimizer=False).fit(hits, starts, ends)
    obs = m.cells_[0].obs
    assert obs.y[-1] == -1.0 and obs.labels[-1] == -1.0 and obs.lengths[-1] == 0.0
    assert m.predict([[1.0, 0.0]])[0] < 0
    m.update(None, [[1.0, 0.5]], [[1.0, 0.5]])
    assert m.cells_[0].obs.y[-1] == -1.0


def test_three_dimensional_scene():
    hits, starts, ends = wall_3d()
    m = GPOMIK(SquaredExponential(1.0, 0.5), optimizer=False).fit(hits, starts, ends)
    assert m.n_dims_ == 3
    assert (m.predict_proba(hits) > 0.5).all()
    assert (m.predict_proba(0.4 * hits) < 0.5).all()


@pytest.mark.parametrize("kwargs, match", [
    (dict(hits=[[np.nan, 0.0]]), "hits must be finite"),
    (dict(segment_starts=np.full((6, 2), np.nan)), "segment_starts must be finite"),
    (dict(segment_ends=np.full((6, 2), np.inf)), "segment_ends must be finite"),
    (dict(hits=np.zeros(6)), r"hits must have shape \(n_points, 2\)"),
    (dict(segment_starts=np.zeros((5, 2))),
     "segment_starts and segment_ends must have the same shape"),
    (dict(segment_ends=np.zeros((6, 3))), r"segment_ends must have shape \(n_points, 2\)"),
    (dict(hits=np.zeros((6, 3))), r"segment_starts must have shape \(n_points, 3\)"),
    (dict(hits=np.zeros((6, 4)), segment_starts=None, segment_ends=None),
     r"hits and segment_starts must have shape \(n, D\) with D in 1..3"),
    (dict(segment_ends=None), "segment_starts and segment_ends must be given together"),
    (dict(hits=None, segment_starts=None, segment_ends=None), "no observations"),
    (dict(segment_starts=None, segment_ends=None), "needs both hits and beams"),
    (dict(hits=None), "needs both hits and beams"),
    (dict(hits=np.empty((0, 2))), "needs both hits and beams"),
])
def test_fit_rejects_bad_observations(kwargs, match):
    hits, starts, ends = wall()
    args = dict(hits=hits, segment_starts=starts, segment_ends=ends)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        GPOMIK(optimizer=False).fit(**args)


def test_fit_rejects_non_numeric_observations():
    hits, starts, ends = wall()
    with pytest.raises(TypeError, match="hits must hold real numbers"):
        GPOMIK(optimizer=False).fit([["a", "b"]], starts, ends)


def test_predict_rejects_bad_queries():
    m = GPOMIK(optimizer=False).fit(*wall())
    with pytest.raises(ValueError, match=r"X must have shape \(n_points, 2\)"):
        m.predict(np.zeros((3, 3)))
    with pytest.raises(ValueError, match=r"X must have shape \(n_points, 2\)"):
        m.predict_proba(np.zeros(2))
    with pytest.raises(ValueError, match="X must be finite"):
        m.predict([[np.nan, 0.0]])
    with pytest.raises(TypeError, match="X must hold real numbers"):
        m.predict([["a", "b"]])
    with pytest.raises(ValueError, match=r"hits must have shape \(n_points, 2\)"):
        m.update(np.zeros((2, 3)))
    with pytest.raises(ValueError, match=r"hits must have shape \(n_points, 2\)"):
        m.kl_divergence(np.zeros((2, 3)))


@pytest.mark.parametrize("params, error, match", [
    (dict(noise=0.0), ValueError, r"noise must lie in \(0.0, inf\)"),
    (dict(noise=-1.0), ValueError, "noise must lie in"),
    (dict(noise="a"), TypeError, "noise must be a real number"),
    (dict(noise_bounds=(1.0, 0.1)), ValueError, "noise_bounds must satisfy low < high"),
    (dict(noise_bounds=(0.0, 0.1)), ValueError, "noise_bounds must lie in"),
    (dict(max_cell_size=0), ValueError, "max_cell_size must be an int >= 1, got 0"),
    (dict(kl_threshold=-0.1), ValueError, r"kl_threshold must lie in \[0.0, inf\)"),
    (dict(quadrature="gauss"), ValueError, "quadrature must be 'clenshaw-curtis', 'simpson'"),
    (dict(n_restarts=-1), ValueError, "n_restarts must be an int >= 0, got -1"),
    (dict(max_optimize=1), ValueError, "max_optimize must be an int >= 2, got 1"),
    (dict(n_jobs=0), ValueError, "n_jobs must be"),
    (dict(kernel=RBF()), TypeError, "kernel must be one of occgp.gp's kernels"),
    (dict(kernel=SquaredExponential), TypeError, "kernel must be one of occgp.gp's kernels"),
    (dict(kernel=SquaredExponential(-1.0)), ValueError, "variance must be positive"),
    (dict(kernel=SquaredExponential(1.0, [1.0, 1.0, 1.0])), ValueError,
     "length_scale has 3 entries but the inputs have 2 dimensions"),
])
def test_fit_rejects_bad_parameters(params, error, match):
    with pytest.raises(error, match=match):
        GPOMIK(optimizer=False, **params).fit(*wall())


@pytest.mark.parametrize("params, error, match", [
    (dict(max_cell_size=2.5), TypeError, "max_cell_size must be"),
    (dict(n_restarts=1.5), TypeError, "n_restarts must be"),
    (dict(max_optimize="10"), TypeError, "max_optimize must be"),
    (dict(noise_bounds=(1e-4, 1e-2, 1.0)), ValueError, "noise_bounds must"),
    (dict(noise_bounds=None), TypeError, "noise_bounds must"),
])
def test_fit_rejects_parameters_of_the_wrong_type(params, error, match):
    with pytest.raises(error, match=match):
        GPOMIK(optimizer=False, **params).fit(*wall())


def test_one_cell_fit_reuses_the_factor_of_its_optimisation_subset():
    # every observation in the subset and in one cell: the factor is built once, and is
    # the one a separate build of the cell gives, bit for bit
    rng = np.random.default_rng(0)
    hits = rng.uniform(-2, 2, (30, 2))
    starts = np.zeros((30, 2))
    m = GPOMIK(SquaredExponential(1.0, 0.8), noise=1e-2, optimizer=False).fit(hits, starts, hits)
    obs = m.cells_[0].obs
    again = m._make_cells(obs, m.kernel_, m.noise_, m.jitter_, m._quadrature, 1)
    assert len(m.cells_) == len(again) == 1
    assert_array_equal(m.cells_[0].L, again[0].L)
    assert_array_equal(m.cells_[0].alpha, again[0].alpha)


def _room_observations():
    from occgp.datasets import room_2d
    from occgp.gp import observations_from_scans
    return observations_from_scans(room_2d().scan(n_poses=3))


def test_model_loo_is_each_cells_prediction_without_the_observation():
    from occgp.gp._cells import predict_cell, spatial_groups
    from occgp.gp._integral_kernel import covariance
    from occgp.gp._observations import loo_sample, make_observations
    hits, starts, ends = _room_observations()
    m = GPOMIK(SquaredExponential(1.7, 0.6), noise=1e-2, optimizer=False, max_cell_size=30)
    m.fit(hits, starts, ends)
    assert len(m.cells_) > 2
    obs = make_observations(hits, starts, ends)
    groups = spatial_groups(obs.anchors, 30)     # the cells' observations, in order
    take, X = loo_sample(obs, 40, np.random.default_rng(0))
    mean, var = m._model_loo(m.cells_, groups, m.kernel_, m._quadrature, 1, take, X)
    prior = float(m.kernel_.variance)
    margin = 3.0 / m.kernel_.inverse_length_scales(2)
    for j, t in enumerate(take):
        best_m, best_v = 0.0, prior
        for c, (cell, idx) in enumerate(zip(m.cells_, groups)):
            lo, hi = cell.bounds(margin)
            if not np.all((X[j] >= lo) & (X[j] <= hi)):
                continue
            if t in idx:   # refit the cell without the observation
                o = cell.obs.take(np.flatnonzero(idx != t))
                K = covariance(m.kernel_, m._quadrature, o.starts, o.ends)
                K[np.diag_indices_from(K)] += m.noise_ + m.jitter_
                k = covariance(m.kernel_, m._quadrature, o.starts, o.ends, X[j:j + 1],
                               X[j:j + 1])[:, 0]
                mu, v = k @ np.linalg.solve(K, o.y), prior - k @ np.linalg.solve(K, k)
            else:
                mu, v = (a[0] for a in predict_cell(cell, X[j:j + 1], m.kernel_,
                                                      m._quadrature, 1, True))
            if v < best_v:
                best_m, best_v = mu, v
        assert_allclose(mean[j], best_m, rtol=1e-8, atol=1e-8)
        assert_allclose(var[j], best_v, rtol=1e-8, atol=1e-8 * prior)


def test_calibrations_share_the_model_and_differ_in_the_classifier():
    from occgp.gp import fit_plsc, loo_predictions
    from occgp.gp._observations import make_observations
    data = _room_observations()
    kw = dict(kernel=SquaredExponential(1.7, 0.6), noise=1e-2, optimizer=False, random_state=0)
    model = GPOMIK(**kw).fit(*data)      # the default: model-loo
    subset = GPOMIK(calibration="subset-loo", **kw).fit(*data)
    assert_array_equal(model.cells_[0].L, subset.cells_[0].L)
    assert model.plsc_ != subset.plsc_
    # subset-loo: leave-one-out over the (whole) subset, beams per unit length
    obs = make_observations(*data)
    mu, var = loo_predictions(subset.cells_[0].L, obs.y)
    scale = np.where(obs.lengths > 0, obs.lengths, 1.0)
    assert_allclose(subset.plsc_, fit_plsc(mu / scale, var / scale ** 2, obs.labels),
                    rtol=1e-6)
    with pytest.raises(ValueError, match="calibration must be one of"):
        GPOMIK(calibration="held-out", **kw).fit(*data)
