"""The k-NN inverse sensor model: KNNMap against a slow reference, replays, statistics."""

import math
import pickle

import numpy as np
import pytest
from scipy import stats

from occgp import KNNMap, OccupancyOctree
from occgp._octree import _welford
from occgp.knn import ScanReplay, check_knn_params, mean_knn_distances, point_log_odds
from octomap_reference import knn_reference, leaf_values, logodds32
from _helpers import room_sequence
from _helpers import KNN_PARAMS as PARAMS, noisy_scans, build_knn as build


# ---------------------------------------------------------------------- the model
def test_point_probability_is_the_normal_cdf_mapping():
    s = np.linspace(0.0, 0.5, 11)
    got = point_log_odds(s, 10, 0.2, 10 * 0.05 ** 2, 0.9, 0.3)
    p = 0.9 - 0.6 * stats.norm.cdf(s, loc=0.2, scale=0.05)
    np.testing.assert_allclose(got, np.log(p / (1 - p)), rtol=1e-12)
    # truncated at s = 0
    got = point_log_odds(s, 10, 0.05, 10 * 0.1 ** 2, 0.9, 0.3, cdf="truncated")
    f = stats.truncnorm.cdf(s, (0 - 0.05) / 0.1, np.inf, loc=0.05, scale=0.1)
    p = 0.9 - 0.6 * f
    np.testing.assert_allclose(got, np.log(p / (1 - p)), rtol=1e-10)


def test_point_probability_limits():
    # no spread: the step at the mean; no neighbours (inf): the lower probability
    got = point_log_odds(np.array([0.1, 0.2, 0.3, np.inf]), 3, 0.2, 0.0, 0.8, 0.4)
    p = np.array([0.8, 0.6, 0.4, 0.4])
    np.testing.assert_allclose(got, np.log(p / (1 - p)))


def test_welford_matches_numpy_on_streams():
    rng = np.random.default_rng(3)
    state = (0, 0.0, 0.0)
    seen = []
    for size in (1, 5, 100, 3, 1000):
        chunk = rng.gamma(2.0, 0.05, size) + 10.0     # an offset, to test stability
        state = _welford(chunk, *state)
        seen.append(chunk)
        allv = np.concatenate(seen)
        assert state[0] == len(allv)
        assert state[1] == pytest.approx(allv.mean(), rel=1e-14)
        assert math.sqrt(state[2] / state[0]) == pytest.approx(allv.std(), rel=1e-9)
    # non-finite scores are skipped
    assert _welford(np.array([np.inf, 1.0, np.nan]), 0, 0.0, 0.0) == (1, 1.0, 0.0)


def test_mean_knn_distances_brute_force():
    rng = np.random.default_rng(0)
    pts = rng.uniform(size=(50, 3))
    d = np.sort(np.linalg.norm(pts[:, None] - pts[None], axis=-1), axis=1)[:, 1:]
    got = mean_knn_distances(pts, [1, 4])
    np.testing.assert_allclose(got[:, 0], d[:, 0])
    np.testing.assert_allclose(got[:, 1], d[:, :4].mean(axis=1))
    assert np.isinf(mean_knn_distances(pts[:3], [3])).all()


# ---------------------------------------------------------------------- the map
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_map_matches_the_slow_reference_cell_for_cell(seed):
    scans = noisy_scans(np.random.default_rng(seed))
    m = build(scans)
    ref = knn_reference(scans, 0.2, max_range=3.0, **PARAMS)
    got = leaf_values(m)
    assert set(got) == set(ref)
    keys = sorted(ref)
    np.testing.assert_allclose([got[k] for k in keys], [ref[k] for k in keys],
                               rtol=0, atol=2e-6)


def test_speckle_lowers_occupancy():
    rng = np.random.default_rng(5)
    wall = np.column_stack([np.full(400, 2.0), rng.uniform(-1, 1, (400, 2))])
    speckle = rng.uniform([0.5, -1, -1], [1.5, 1, 1], (6, 3))
    m = KNNMap(0.1, p_u=0.9, p_l=0.2).insert_scan(np.vstack([wall, speckle]), [0, 0, 0])
    assert (m.log_odds(speckle) < 0).all()
    assert m.is_occupied(wall).mean() > 0.75   # the sparsest wall points score low too


def test_l_in_wins_over_l_out_and_points_over_both():
    # one ray to a near point and one cut ray along the same line
    origin = np.array([0.05, 0.05, 0.05])
    m = KNNMap(0.1, k=1, p_m=0.2, p_m_out=0.4, max_range=4.0)
    m.insert_scan([[1.05, 0.05, 0.05], [10.05, 0.05, 0.05]], origin, method="plain")
    x = lambda v: [[v, 0.05, 0.05]]  # noqa: E731
    assert m.log_odds(x(0.55))[0] == logodds32(0.2)         # both rays: l_in
    assert m.log_odds(x(2.55))[0] == logodds32(0.4)         # the cut ray only: l_out
    # the near point's cell: a lone point has no neighbour, so p = p_l
    assert m.log_odds(x(1.05))[0] == np.float32(math.log(0.38 / 0.62))
    assert np.isnan(m.log_odds(x(4.55))[0])                 # past the cut


@pytest.mark.parametrize("method", ["culling", "superray", "superray+culling", "auto"])
def test_every_method_gives_the_plain_map(method):
    scans = room_sequence(np.random.default_rng(4), n_scans=8, n_points=500)
    params = dict(p_m=0.12, p_m_out=0.2, p_min=0.12)
    plain = KNNMap(0.1, max_range=2.0, **params)
    other = KNNMap(0.1, max_range=2.0, **params)
    regions = []
    for points, origin in scans:
        plain.insert_scan(points, origin, method="plain")
        other.insert_scan(points, origin, method=method)
        regions.append(other.last_insert_["region_cells"])
    assert leaf_values(plain) == leaf_values(other)
    assert plain.to_bytes() == other.to_bytes()
    if "culling" in method or method == "auto":
        assert max(regions) > 0          # the culling region did skip cells


def test_pickle_continues_the_statistics():
    scans = noisy_scans(np.random.default_rng(8), n_scans=4)
    whole = build(scans)
    half = build(scans[:2])
    copy = pickle.loads(pickle.dumps(half))
    assert (copy.n_scores_, copy.score_mean_, copy.score_std_) == (
        half.n_scores_, half.score_mean_, half.score_std_)
    assert copy.get_params() == half.get_params()
    for points, origin in scans[2:]:
        copy.insert_scan(points, origin, method="plain")
    assert copy.to_bytes() == whole.to_bytes()
    assert copy.score_mean_ == whole.score_mean_


def test_rejected_scan_changes_nothing():
    scans = noisy_scans(np.random.default_rng(9), n_scans=1)
    m = build(scans)
    before = (m.to_bytes(), m._scores)
    bad = scans[0][0].copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="points"):
        m.insert_scan(bad, scans[0][1])
    # cut at the sensor range, the ray still leaves the key range
    small = KNNMap(1e-4, max_range=4.0)
    for point in ([10.0, 0, 0], [3.5, 0, 0]):       # cut at 4 m, or within range
        with pytest.raises(ValueError, match="key range"):
            small.insert_scan([[1.0, 0, 0], point], [0, 0, 0])
    assert small.num_leaves == 0 and small.n_scores_ == 0
    assert (m.to_bytes(), m._scores) == before


def test_empty_scan_and_attributes():
    m = KNNMap(0.1)
    assert m.insert_scan(np.empty((0, 3)), [0, 0, 0]) is m
    assert m.num_leaves == 0 and math.isnan(m.score_mean_)
    assert (m.clamping_min, m.clamping_max, m.occupancy_threshold) == (0.02, 0.98, 0.5)
    with pytest.raises(AttributeError, match="prob_hit"):
        m.prob_hit
    assert "KNNMap" in repr(m)


@pytest.mark.parametrize("bad, match", [
    (dict(k=0), "k"), (dict(k=1.5), "k"), (dict(p_u=0.3, p_l=0.5), "p_u >= p_l"),
    (dict(p_m=0.01), "p_m >= p_min"), (dict(p_m=0.3, p_m_out=0.2), "p_m_out >= p_m"),
    (dict(p_m_out=0.5), "p_m_out"), (dict(occupancy_threshold=0.01), "occupancy_threshold >= p_min"),
    (dict(occupancy_threshold=0.99), "p_max >= occupancy_threshold"), (dict(p_max=1.0), "p_max"), (dict(p_u=1.0), "p_u"),
    (dict(p_min=0.0), "p_min"), (dict(max_range=0.0), "max_range"),
    (dict(max_range=1e30), "max_range"), (dict(cdf="gev"), "cdf"),
    (dict(n_jobs=0), "n_jobs"),
])
def test_bad_parameters(bad, match):
    with pytest.raises((ValueError, TypeError), match=match):
        KNNMap(0.1, **bad)


def test_parameter_type_errors():
    with pytest.raises(TypeError, match="p_u"):
        KNNMap(0.1, p_u="high")
    with pytest.raises(TypeError, match="k"):
        check_knn_params(dict(PARAMS, k="3", occupancy_threshold=0.5, max_range=4.0))


# ---------------------------------------------------------------------- replay
def test_replay_equals_building_the_maps():
    scans = noisy_scans(np.random.default_rng(11), n_scans=4, n_wall=80)
    rep = ScanReplay(scans, 0.2, max_range=3.0, ks=(1, 3))
    combos = [dict(PARAMS), dict(PARAMS, k=1, p_u=0.62, p_l=0.62, p_m=0.05, p_m_out=0.05),
              dict(PARAMS, k=1, p_min=0.3, p_max=0.6, p_m=0.3, p_m_out=0.45)]
    values = rep.knn_log_odds(combos)
    keys = [tuple(int((key >> np.uint64(16 * a)) & np.uint64(0xFFFF)) for a in range(3))
            for key in rep.keys]
    for row, params in zip(values, combos):
        got = leaf_values(build(scans, **params))
        assert set(got) == set(keys)
        assert [got[k] for k in keys] == row.tolist()


def test_octomap_replay_equals_liboctomap():
    scans = noisy_scans(np.random.default_rng(12), n_scans=4, n_wall=80)
    rep = ScanReplay(scans, 0.2, max_range=3.0)
    combos = [dict(prob_hit=0.7, prob_miss=0.4, clamping_min=0.12, clamping_max=0.97),
              dict(prob_hit=0.86, prob_miss=0.26, clamping_min=0.3, clamping_max=0.6)]
    values = rep.octomap_log_odds(combos)
    keys = [tuple(int((key >> np.uint64(16 * a)) & np.uint64(0xFFFF)) for a in range(3))
            for key in rep.keys]
    for row, params in zip(values, combos):
        m = OccupancyOctree(0.2, **params)
        for points, origin in scans:
            m.insert_scan(points, origin, max_range=3.0, method="plain")
        got = leaf_values(m)
        assert set(got) == set(keys)
        assert [got[k] for k in keys] == row.tolist()
    np.testing.assert_allclose(rep.centers, (np.array(keys) - 32768 + 0.5) * 0.2)


def test_replay_rejects_bad_input():
    scans = noisy_scans(np.random.default_rng(1), n_scans=1)
    with pytest.raises(ValueError, match="ks"):
        ScanReplay(scans, 0.2, ks=())
    with pytest.raises(TypeError, match=r"scans\[0\]"):
        ScanReplay([np.zeros(3)], 0.2)
    rep = ScanReplay(scans, 0.2, ks=(1,))
    with pytest.raises(ValueError, match="k=3 was not scored"):
        rep.knn_log_odds([PARAMS])
    with pytest.raises(ValueError, match="lacks the k-NN parameter"):
        rep.knn_log_odds([{"k": 1}])
    with pytest.raises(ValueError, match=r"params\[0\].*p_u >= p_l"):
        rep.knn_log_odds([dict(PARAMS, k=1, p_u=0.2, p_l=0.3)])


# ---------------------------------------------------------------------- data-set statistics
@pytest.mark.parametrize("seed", [0, 1])
def test_fixed_statistics_match_the_slow_reference(seed):
    scans = noisy_scans(np.random.default_rng(seed))
    fixed = (0.11, 0.04)
    m = build(scans, score_stats=fixed)
    ref = knn_reference(scans, 0.2, max_range=3.0, score_stats=fixed, **PARAMS)
    got = leaf_values(m)
    assert set(got) == set(ref)
    keys = sorted(ref)
    np.testing.assert_allclose([got[k] for k in keys], [ref[k] for k in keys],
                               rtol=0, atol=2e-6)
    # the fixed statistics change the map; Welford's are still kept
    online = build(scans)
    assert leaf_values(online) != got
    assert (m.n_scores_, m.score_mean_, m.score_std_) == (online.n_scores_,
                                                         online.score_mean_, online.score_std_)
    assert m.score_stats == fixed and online.score_stats is None


def test_fixed_statistics_pickle_and_zero_std():
    scans = noisy_scans(np.random.default_rng(4))
    m = build(scans[:2], score_stats=(0.1, 0.0))
    again = pickle.loads(pickle.dumps(m))
    assert again.score_stats == (0.1, 0.0)
    for mm in (m, again):
        mm.insert_scan(*scans[2], method="plain")
    assert leaf_values(m) == leaf_values(again)
    ref = knn_reference(scans, 0.2, max_range=3.0, score_stats=(0.1, 0.0), **PARAMS)
    got = leaf_values(m)
    np.testing.assert_allclose([got[k] for k in sorted(ref)], [ref[k] for k in sorted(ref)],
                               rtol=0, atol=2e-6)


def test_dataset_replay_equals_maps_with_the_dataset_statistics():
    scans = noisy_scans(np.random.default_rng(13), n_scans=4, n_wall=80)
    rep = ScanReplay(scans, 0.2, max_range=3.0, ks=(1, 3), stats="dataset")
    online = ScanReplay(scans, 0.2, max_range=3.0, ks=(1, 3))
    combos = [dict(PARAMS), dict(PARAMS, k=1, p_u=0.74, p_l=0.38)]
    keys = [tuple(int((key >> np.uint64(16 * a)) & np.uint64(0xFFFF)) for a in range(3))
            for key in rep.keys]
    for row, params in zip(rep.knn_log_odds(combos), combos):
        full = build(scans, **params)
        # the data set's statistics are those a map reaches after the last scan
        assert rep.score_stats(params["k"]) == (full.score_mean_, full.score_std_)
        got = leaf_values(build(scans, score_stats=rep.score_stats(params["k"]), **params))
        assert [got[k] for k in keys] == row.tolist()
    assert not np.array_equal(rep.knn_log_odds(combos), online.knn_log_odds(combos))
    assert online.score_stats(3) == rep.score_stats(3)


def test_score_stats_bad_input():
    with pytest.raises(TypeError, match="score_stats must be None or a"):
        KNNMap(0.1, score_stats=0.1)
    with pytest.raises(ValueError, match=r"score_stats\[1\] \(the std\) must lie in"):
        KNNMap(0.1, score_stats=(0.1, -1.0))
    with pytest.raises(ValueError, match=r"score_stats\[0\] \(the mean\) must lie in"):
        KNNMap(0.1, score_stats=(np.nan, 1.0))
    with pytest.raises(ValueError, match="stats must be one of"):
        ScanReplay([], 0.2, stats="global")
    with pytest.raises(ValueError, match="k=2 was not scored"):
        ScanReplay([], 0.2).score_stats(2)
