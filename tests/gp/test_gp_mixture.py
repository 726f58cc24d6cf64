"""Tests of the mixture of GP experts (occgp.gp.GPMixture)."""

import pickle

import joblib
import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from sklearn.base import BaseEstimator, clone
from sklearn.exceptions import NotFittedError
from threadpoolctl import threadpool_limits

from occgp.datasets import room_2d
from occgp.gp import (COMBINE_RULES, GPOMIK, GPMixture, SquaredExponential,
                      observations_from_scans, predict_grid)


class Halves(BaseEstimator):
    """Hits clustered by the sign of x - `split` (a hand-checkable clustering)."""

    def __init__(self, split=0.0):
        self.split = split

    def fit_predict(self, hits, origins):
        self.labels_ = (np.asarray(hits)[:, 0] > self.split).astype(np.int64)
        self.n_clusters_ = int(self.labels_.max()) + 1
        return self.labels_

    def partial_fit(self, hits, origins):
        labels = (np.asarray(hits)[:, 0] > self.split).astype(np.int64)
        self.labels_ = np.r_[self.labels_, labels]
        self.n_clusters_ = max(self.n_clusters_, int(labels.max()) + 1)
        return labels


class One(Halves):
    """Every hit in one cluster."""

    def __init__(self, split=np.inf):
        super().__init__(split)


@pytest.fixture(scope="module")
def data():
    return observations_from_scans(room_2d().scan(n_poses=8))


@pytest.fixture(scope="module")
def queries():
    return np.random.default_rng(0).uniform([-11, -9], [11, 9], (600, 2))


FIXED = GPOMIK(SquaredExponential(1.7, 0.6), noise=1e-3, optimizer=False)


@pytest.fixture(scope="module")
def fitted(data):
    return GPMixture(FIXED, random_state=0).fit(*data)


def test_fit_assigns_every_observation_to_an_expert(fitted, data):
    hits, starts, _ = data
    assert fitted.labels_.shape == (len(hits) + len(starts),)
    assert fitted.n_experts_ == len(fitted.experts_) > 1
    assert set(np.unique(fitted.labels_)) == set(range(fitted.n_experts_))
    sizes = np.bincount(fitted.labels_)
    assert sizes.sum() == len(fitted.labels_)
    for e, gp in enumerate(fitted.experts_):
        assert gp.cells_[0].size == sizes[e]
        n_hits = int((gp.cells_[0].obs.labels > 0).sum())
        assert n_hits >= fitted.min_hits and n_hits < sizes[e]  # both classes
    assert fitted.n_clusters_ >= fitted.n_experts_ - 1


@pytest.mark.slow
@pytest.mark.parametrize("rule", ["bcm", "tresp", "gpoe"])
@pytest.mark.parametrize("hyperparameters", ["own", "shared"])
def test_one_expert_is_gpomik(data, queries, rule, hyperparameters):
    template = GPOMIK(n_restarts=0, random_state=0)
    with threadpool_limits(1):  # the mixture's BLAS threads: the same rounding
        single = clone(template).fit(*data)
        m0, v0 = single.predict(queries, return_var=True)
    mix = GPMixture(template, clustering=One(), combine=rule, hyperparameters=hyperparameters,
                    prior_tol=0.0, random_state=0).fit(*data)
    assert mix.n_experts_ == 1
    assert mix.experts_[0].kernel_ == single.kernel_
    assert mix.experts_[0].noise_ == single.noise_
    mean, var = mix.predict(queries, return_var=True)
    # gPoE weighs an expert by its entropy change, 0 where its variance rounds to the
    # prior: there the committee gives the prior's mean, the expert a mean of ~1e-11
    assert_allclose(mean, m0, rtol=1e-12, atol=1e-10 if rule == "gpoe" else 1e-12)
    # the mixture's variance is prior - |L^-1 k|^2, GPOMIK's k^T K^-1 k on tiles: rounding
    assert_allclose(var, v0, rtol=1e-10, atol=1e-10 * float(mix.experts_[0].kernel_.variance))


@pytest.mark.parametrize("rule", COMBINE_RULES)
def test_skipping_experts_changes_predictions_by_less_than_the_tolerance(data, queries, rule):
    tol = 1e-3
    exact = GPMixture(FIXED, combine=rule, prior_tol=0.0, random_state=0).fit(*data)
    skip = GPMixture(FIXED, combine=rule, prior_tol=tol, random_state=0).fit(*data)
    X = np.vstack([queries, data[0]])
    m0, v0 = exact.predict(X, return_var=True)
    m1, v1 = skip.predict(X, return_var=True)
    prior = float(FIXED.kernel.variance)
    assert np.abs(m1 - m0).max() <= tol * np.sqrt(prior)
    assert np.abs(v1 - v0).max() <= tol * prior
    # the classifiers were fitted on skipped predictions too: compare through one of them
    a, b = exact.plsc_
    from occgp.gp import plsc_proba
    assert np.abs(plsc_proba(m1, v1, a, b) - plsc_proba(m0, v0, a, b)).max() <= tol
    # and skipping did skip: fewer expert evaluations than queries x experts within the cutoff
    eps = tol / skip.n_experts_
    pairs = [sum(len(r.queries(X, e)) for r in skip._reaches()) for e in (eps, 0.0)]
    assert pairs[0] < pairs[1]


@pytest.mark.slow
def test_n_jobs_and_backends_give_the_same_map(data, queries):
    models = [GPMixture(combine="tresp", random_state=0, n_jobs=n).fit(*data) for n in (1, 2)]
    with joblib.parallel_config(backend="loky"):
        models.append(GPMixture(combine="tresp", random_state=0, n_jobs=2).fit(*data))
    ref = models[0].predict(queries, return_var=True)
    for m in models[1:]:
        assert_array_equal(m.labels_, models[0].labels_)
        assert m.plsc_ == models[0].plsc_
        out = m.predict(queries, return_var=True)
        assert_array_equal(out[0], ref[0])
        assert_array_equal(out[1], ref[1])


def test_blas_threads_are_restored_after_parallel_experts(data):
    from threadpoolctl import threadpool_info
    before = [(i["internal_api"], i["num_threads"]) for i in threadpool_info()]
    GPMixture(FIXED, random_state=0, n_jobs=2).fit(*data).predict([[0.0, 0.0]])
    assert [(i["internal_api"], i["num_threads"]) for i in threadpool_info()] == before


@pytest.mark.slow
def test_dask_local_cluster_gives_the_same_map(data, queries):
    distributed = pytest.importorskip("distributed", reason="the dask extra is not installed")
    ref = GPMixture(combine="tresp", random_state=0).fit(*data)
    with distributed.LocalCluster(processes=False, n_workers=2, threads_per_worker=1,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster), joblib.parallel_config(backend="dask"):
        model = GPMixture(combine="tresp", random_state=0, n_jobs=2).fit(*data)
        out = model.predict(queries, return_var=True)
    assert_array_equal(model.labels_, ref.labels_)
    assert model.plsc_ == ref.plsc_
    expected = ref.predict(queries, return_var=True)
    assert_array_equal(out[0], expected[0])
    assert_array_equal(out[1], expected[1])


def split_scans(n_first=6, n_poses=10):
    scans = room_2d().scan(n_poses=n_poses)
    return (observations_from_scans(scans[:n_first]),
            observations_from_scans(scans[n_first:]))


@pytest.mark.parametrize("how", ["cholesky", "refit"])
def test_update_touches_only_the_experts_that_got_observations(how):
    first, second = split_scans()
    model = GPMixture(FIXED, update_experts=how, random_state=0).fit(*first)
    before = list(model.experts_)
    factors = [gp.cells_[0].L.copy() for gp in before]
    n_obs = len(model.labels_)
    model.update(*second)
    changed = set(model.updated_experts_.tolist())
    assert len(model.labels_) == n_obs + len(second[0]) + len(second[1])
    assert changed == set(np.unique(model.labels_[n_obs:]).tolist())
    assert changed and len(changed) < model.n_experts_
    for e, gp in enumerate(before):
        if e in changed:
            assert model.experts_[e] is not gp
            assert model.experts_[e].n_accepted_ > gp.n_accepted_ or how == "refit"
        else:
            assert model.experts_[e] is gp
            assert_array_equal(gp.cells_[0].L, factors[e])
    sizes = np.bincount(model.labels_)
    for e, gp in enumerate(model.experts_):
        assert sum(c.size for c in gp.cells_) == sizes[e]


def test_new_experts_of_an_update_share_the_fitted_hyperparameters():
    first, second = split_scans(3, 10)
    model = GPMixture(GPOMIK(n_restarts=0), random_state=0).fit(*first)
    n_before = model.n_experts_
    model.update(*second)
    assert model.n_experts_ > n_before
    for gp in model.experts_:
        assert gp.kernel_ == model.kernel_ and gp.noise_ == model.noise_


def test_cholesky_update_of_an_expert_equals_its_refit_with_fixed_hyperparameters(queries):
    first, second = split_scans()
    grown = GPMixture(FIXED, random_state=0).fit(*first).update(*second)
    refit = GPMixture(FIXED, update_experts="refit", random_state=0).fit(*first).update(*second)
    assert_array_equal(grown.labels_, refit.labels_)
    m0, v0 = grown.predict(queries, return_var=True)
    m1, v1 = refit.predict(queries, return_var=True)
    assert_allclose(m0, m1, atol=1e-8)
    assert_allclose(v0, v1, atol=1e-8)


def test_update_with_beams_only_grows_the_experts_of_similar_beams(data):
    hits, starts, ends = data
    model = GPMixture(FIXED, random_state=0).fit(hits, starts, ends)
    n_obs = len(model.labels_)
    far = starts[:3] + 0.5 * (ends[:3] - starts[:3])   # three short free beams
    model.update(None, starts[:3], far)
    assert len(model.labels_) == n_obs + 3
    assert set(model.updated_experts_.tolist()) == set(model.labels_[n_obs:].tolist())


def test_rejected_update_leaves_the_model_unchanged(data):
    model = GPMixture(FIXED, random_state=0).fit(*data)
    state = pickle.dumps(model)
    with pytest.raises(ValueError, match="hits"):
        model.update([[np.nan, 0.0]], [[0.0, 0.0]], [[1.0, 0.0]])
    with pytest.raises(ValueError, match="hits must have shape"):
        model.update([[0.0, 0.0, 0.0]], None, None)
    assert pickle.dumps(model) == state


class FirstHits(Halves):
    """The first `split` hits in cluster 1, the others in cluster 0."""

    def fit_predict(self, hits, origins):
        self.labels_ = (np.arange(len(hits)) < self.split).astype(np.int64)
        self.n_clusters_ = 2
        return self.labels_


def test_tiny_clusters_join_the_nearest_expert(data):
    model = GPMixture(FIXED, clustering=FirstHits(5), min_hits=6, random_state=0).fit(*data)
    assert model.n_clusters_ == 2 and model.n_experts_ == 1
    kept = GPMixture(FIXED, clustering=FirstHits(5), min_hits=5, random_state=0).fit(*data)
    assert kept.n_experts_ == 2
    assert (kept.labels_[:5] != kept.labels_[5]).all()


def test_works_with_predict_grid_pickle_and_clone(fitted):
    grid = predict_grid(fitted, [-2.0, -2.0], [2.0, 2.0], 0.5)
    assert grid.shape == (8, 8) and ((grid >= 0) & (grid <= 1)).all()
    again = pickle.loads(pickle.dumps(fitted))
    X = np.array([[0.0, 0.0], [3.0, -1.0]])
    assert_array_equal(again.predict_proba(X), fitted.predict_proba(X))
    assert clone(fitted).get_params()["combine"] == fitted.combine


def test_probabilities_separate_walls_from_free_space(fitted, data):
    hits, starts, ends = data
    free = starts + 0.5 * (ends - starts)
    assert fitted.predict_proba(hits).mean() > 0.6 > 0.4 > fitted.predict_proba(free).mean()


@pytest.mark.parametrize("params, exc, match", [
    (dict(clustering="kmeans"), ValueError, "clustering must be one of"),
    (dict(clustering=3), TypeError, "clustering must be"),
    (dict(combine="mean"), ValueError, "combine must be one of"),
    (dict(hyperparameters="all"), ValueError, "hyperparameters must be one of"),
    (dict(update_experts="never"), ValueError, "update_experts must be one of"),
    (dict(expert="gpomik"), TypeError, "expert must be a GPOMIK"),
    (dict(min_hits=0), ValueError, "min_hits"),
    (dict(max_cluster_size=1.5), TypeError, "max_cluster_size"),
    (dict(prior_tol=-1.0), ValueError, "prior_tol"),
    (dict(n_jobs="two"), ValueError, "n_jobs"),
    (dict(random_state="x"), TypeError, "random_state"),
])
def test_bad_parameters(data, params, exc, match):
    with pytest.raises(exc, match=match):
        GPMixture(**params).fit(*data)


def test_bad_data(data):
    hits, starts, ends = data
    with pytest.raises(ValueError, match="needs both hits and beams"):
        GPMixture().fit(None, starts, ends)
    with pytest.raises(ValueError, match="needs both hits and beams"):
        GPMixture().fit(hits, None, None)
    with pytest.raises(ValueError, match="hits"):
        GPMixture().fit(np.full((3, 2), np.nan), starts, ends)
    with pytest.raises(ValueError, match="segment_ends"):
        GPMixture().fit(hits, starts, ends[:-1])
    with pytest.raises(ValueError, match="hits"):
        GPMixture(clustering="line").fit(np.c_[hits, hits[:, :1]], np.c_[starts, starts[:, :1]],
                                         np.c_[ends, ends[:, :1]])


def test_not_fitted():
    model = GPMixture()
    for call in (lambda: model.predict([[0.0, 0.0]]), lambda: model.predict_proba([[0.0, 0.0]]),
                 lambda: model.update([[0.0, 0.0]], None, None), lambda: model.n_experts_):
        with pytest.raises(NotFittedError):
            call()


def test_predict_checks_queries(fitted):
    with pytest.raises(ValueError, match="X must have shape"):
        fitted.predict([[0.0, 0.0, 0.0]])
    with pytest.raises(TypeError, match="return_var"):
        fitted.predict([[0.0, 0.0]], return_var="yes")


@pytest.mark.slow
def test_plane_clusters_in_3d():
    from occgp.datasets import LidarSensor, simulate_scans, structured_room
    scene = structured_room(0)
    lo, hi = scene.interior_bounds
    poses = np.array([[lo[0] + 2.5, lo[1] + 2.0, 1.0], [lo[0] + 7.5, lo[1] + 5.0, 1.0]])
    scans = simulate_scans(scene, poses, LidarSensor(n_horizontal=48, n_vertical=4,
                                                     max_range=8.0), seed=0, progress=False)
    first, second = (observations_from_scans([s]) for s in scans)
    model = GPMixture(FIXED, clustering="plane", random_state=0).fit(*first)
    assert model.n_experts_ > 1
    model.update(*second)
    X = np.random.default_rng(0).uniform(lo, hi, (200, 3))
    p = model.predict_proba(X)
    assert p.shape == (200,) and ((p > 0) & (p < 1)).all()
    hits = np.vstack([first[0], second[0]])
    assert model.predict_proba(hits).mean() > 0.5


def far_wall(x, n_hits=60, distance=8.0):
    """A 2 m wall at x = `x` (hits, then beams ending at them) seen from `distance` m to
    its left: its beams' midpoints lie 4 m from its hits, farther than its length."""
    y = np.linspace(-1.0, 1.0, n_hits)
    hits = np.column_stack([np.full(n_hits, x), y])
    origins = np.column_stack([np.full(n_hits, x - distance), np.resize([-0.5, 0.0, 0.5], n_hits)])
    return hits, origins, hits.copy()


def assert_beams_with_their_hits(model, hits, first=0):
    """Every expert has hits and beams, and each beam is in its hit's expert."""
    labels = model.labels_[first:]
    n = len(hits)
    assert_array_equal(labels[n:2 * n], labels[:n])   # beam i ends at hit i
    for e, gp in enumerate(model.experts_):
        cls = np.concatenate([c.obs.labels for c in gp.cells_])
        assert (cls > 0).any() and (cls < 0).any(), e


def test_split_of_a_large_cluster_keeps_beams_with_their_hits():
    # one cluster of 120 observations, split into experts of at most 40: a median cut of
    # the hits and the beams' midpoints (4 m apart, the wall 2 m long) put all the hits on
    # one side and all the beams on the other, and the experts could not fit
    hits, starts, ends = far_wall(0.0)
    model = GPMixture(FIXED, clustering=One(), max_cluster_size=40, random_state=0)
    model.fit(hits, starts, ends)
    assert model.n_clusters_ == 1 and model.n_experts_ == 4
    assert np.bincount(model.labels_).max() <= 40
    assert_beams_with_their_hits(model, hits)
    assert model.predict_proba(hits).min() > 0.5
    assert model.predict_proba(0.5 * (starts + ends)).max() < 0.5


def test_update_splits_a_large_new_cluster_keeping_beams_with_their_hits():
    # the first wall fits one expert; the second (a new cluster, right of x = 5) is split
    model = GPMixture(FIXED, clustering=Halves(5.0), max_cluster_size=40, random_state=0)
    model.fit(*far_wall(0.0, n_hits=20))
    assert model.n_experts_ == 1
    hits, starts, ends = far_wall(20.0)
    model.update(hits, starts, ends)
    assert model.n_experts_ == 5
    assert_array_equal(model.updated_experts_, [1, 2, 3, 4])
    assert_beams_with_their_hits(model, hits, first=40)
    assert model.predict_proba(hits).min() > 0.5
    assert model.predict_proba(0.5 * (starts + ends)).max() < 0.5


def test_a_cluster_no_cut_can_split_keeping_both_classes_stays_one_expert():
    # 5 hits, each the end of 20 beams: every part needs a hit, so parts of at most 10
    # observations cannot be made; the experts are larger, one cell each (the committee's
    # leave-one-out classifier with hyperparameters="own" needs it)
    hits = np.column_stack([np.full(5, 5.0), np.arange(5.0)])
    starts = np.column_stack([np.zeros(100), np.linspace(-2.0, 6.0, 100)])
    ends = np.repeat(hits, 20, axis=0)
    model = GPMixture(FIXED, clustering=One(), max_cluster_size=10, hyperparameters="own",
                      random_state=0).fit(hits, starts, ends)
    sizes = np.bincount(model.labels_)
    assert model.n_experts_ > 1 and sizes.min() > 10
    assert_array_equal(model.labels_[5:], np.repeat(model.labels_[:5], 20))
    for gp, size in zip(model.experts_, sizes):
        assert len(gp.cells_) == 1 and gp.cells_[0].size == size
        n_hits = int((gp.cells_[0].obs.labels > 0).sum())
        assert 1 <= n_hits < size
    assert np.isfinite(model.plsc_).all()
    assert np.isfinite(model.predict_proba(hits)).all()


def test_beams_without_a_return_go_with_the_hit_of_their_most_similar_returning_beam():
    hits, starts, ends = far_wall(0.0)
    # six beams without a return, crossing in front of the wall and passing its ends
    # (y = +-1): three rising past its top, three falling past its bottom; their midpoints
    # lie in the middle (|y| <= 0.2), the returning beams most like them end near the ends
    miss_starts = np.array([[-8.0, -2.0], [-8.0, -2.2], [-8.0, -1.8],
                            [-8.0, 2.0], [-8.0, 2.2], [-8.0, 1.8]])
    miss_ends = np.array([[2.0, 2.0], [2.0, 2.0], [2.0, 2.2],
                          [2.0, -2.0], [2.0, -2.0], [2.0, -2.2]])
    model = GPMixture(FIXED, clustering=One(), max_cluster_size=70, random_state=0)
    model.fit(hits, np.vstack([starts, miss_starts]), np.vstack([ends, miss_ends]))
    assert model.n_experts_ == 2
    assert_beams_with_their_hits(model, hits)
    top, bottom = model.labels_[np.argmax(hits[:, 1])], model.labels_[np.argmin(hits[:, 1])]
    assert top != bottom
    assert_array_equal(model.labels_[-6:], [top] * 3 + [bottom] * 3)


@pytest.mark.parametrize("hyperparameters", ["global", "own"])
def test_random_subsets_of_the_classifiers_keep_both_classes(hyperparameters):
    # 5 hits among 105 observations: subsets of 10 (the global fit's, each expert's and,
    # with "own", the committee's) drawn at random would often hold no hit
    hits = np.column_stack([np.full(5, 5.0), np.arange(5.0)])
    starts = np.column_stack([np.zeros(100), np.linspace(-2.0, 6.0, 100)])
    ends = np.repeat(hits, 20, axis=0)
    expert = clone(FIXED).set_params(max_optimize=10)
    for seed in range(4):
        model = GPMixture(expert, clustering=One(), max_cluster_size=10, max_optimize=10,
                          hyperparameters=hyperparameters, random_state=seed)
        model.fit(hits, starts, ends)
        assert np.isfinite(model.plsc_).all()
        for gp in model.experts_:
            assert np.isfinite(gp.plsc_).all()


def test_leave_one_out_downdate_equals_refitting_without_the_observation(data):
    from occgp.gp._experts import downdated, predict_dense
    from occgp.gp._integral_kernel import covariance
    hits, starts, ends = data
    gp = clone(FIXED).set_params(noise=1e-2, max_cell_size=None).fit(
        hits[:40], starts[:60], ends[:60])
    cell = gp.cells_[0]
    rng = np.random.default_rng(0)
    pos = np.r_[0, 17, 39, 40, 75, cell.size - 1]           # hits and beams
    u = rng.random(len(pos))
    X = cell.obs.starts[pos] + u[:, None] * (cell.obs.ends[pos] - cell.obs.starts[pos])
    mean, var = downdated(gp, X, pos)
    prior = float(gp.kernel_.variance)
    for j, p in enumerate(pos):
        keep = np.delete(np.arange(cell.size), p)
        o = cell.obs.take(keep)
        K = covariance(gp.kernel_, gp._quadrature, o.starts, o.ends)
        K[np.diag_indices_from(K)] += gp.noise_ + gp.jitter_
        k = covariance(gp.kernel_, gp._quadrature, o.starts, o.ends, X[j:j + 1], X[j:j + 1])
        assert_allclose(mean[j], (k.T @ np.linalg.solve(K, o.y))[0], rtol=1e-9, atol=1e-9)
        assert_allclose(var[j], prior - (k.T @ np.linalg.solve(K, k))[0, 0], rtol=1e-9,
                        atol=1e-9 * prior)
    # without the downdate: the expert's own prediction (which saw the observation)
    full, _ = predict_dense(gp, X)
    assert np.abs(full - mean).max() > 1e-3


def test_draw_balanced_takes_as_many_hits_as_beams():
    from occgp.gp._observations import draw_balanced
    labels = np.r_[np.ones(30), -np.ones(300)]
    take = draw_balanced(labels, 40, np.random.default_rng(0))
    assert_array_equal(take, np.unique(take))
    assert (labels[take] > 0).sum() == (labels[take] < 0).sum() == 20
    take = draw_balanced(labels, 100, np.random.default_rng(0))   # too few hits: all of them
    assert (labels[take] > 0).sum() == 30 and (labels[take] < 0).sum() == 70
    assert len(draw_balanced(labels, 1000, np.random.default_rng(0))) == len(labels)


def test_committee_calibration_is_fitted_on_a_balanced_leave_one_out_sample(data, monkeypatch):
    import occgp.gp._mixture as mixture_module
    seen = {}
    fit = mixture_module.fit_plsc

    def spy(mean, var, labels):
        seen["labels"] = np.asarray(labels)
        return fit(mean, var, labels)

    monkeypatch.setattr(mixture_module, "fit_plsc", spy)
    hits, starts, ends = data
    # three beams to a hit: a random draw would hold about three beams to a hit
    beams = np.repeat(np.arange(len(starts)), 3)
    model = GPMixture(FIXED, max_optimize=200, random_state=0).fit(hits, starts[beams],
                                                                    ends[beams])
    labels = seen["labels"]
    assert len(labels) == 200 and (labels > 0).sum() == (labels < 0).sum() == 100
    assert np.isfinite(model.plsc_).all()


@pytest.mark.slow
def test_subset_calibration_is_the_global_gpomiks_classifier(data):
    from occgp.gp._experts import global_template
    model = GPMixture(GPOMIK(n_restarts=0), calibration="subset-loo", random_state=0)
    model.fit(*data)
    default = GPMixture(GPOMIK(n_restarts=0), random_state=0).fit(*data)
    assert default.kernel_ == model.kernel_
    assert default.plsc_ != model.plsc_
    # the subset GPOMIK's classifier, seeded as the fit seeds it
    from occgp.gp._observations import make_observations
    _, plsc = global_template(model._check_params(), make_observations(*data), model._seed)
    assert model.plsc_ == plsc


@pytest.mark.parametrize("params, match", [
    (dict(calibration="held-out"), "calibration must be one of"),
    (dict(calibration="subset-loo", hyperparameters="own"), "calibration='subset-loo' needs"),
    (dict(calibration="subset-loo", hyperparameters="shared"), "calibration='subset-loo' needs"),
])
def test_bad_calibration(data, params, match):
    with pytest.raises(ValueError, match=match):
        GPMixture(FIXED, **params).fit(*data)
