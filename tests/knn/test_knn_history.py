"""The k-NN score over scans (``KNNMap(history=W)``): the score against brute force, the
view-dependent error it isolates, its state, and the replay that equals the maps."""

import copy
import pickle

import numpy as np
import pytest

from occgp import KNNMap
from occgp._octree import _welford
from occgp.evaluation import cell_labels, grid_search
from occgp.knn import ScanReplay, history_knn_distances, mean_knn_distances
from octomap_reference import leaf_values
from _helpers import KNN_PARAMS as PARAMS, build_knn as build, noisy_scans


def brute_scores(points, history, k):
    """Mean distance to the k nearest points of the history clouds (inf if fewer)."""
    pool = np.concatenate(history) if history else np.empty((0, 3))
    if len(pool) < k:
        return np.full(len(points), np.inf)
    d = np.sort(np.linalg.norm(points[:, None] - pool[None], axis=-1), axis=1)
    return d[:, :k].mean(axis=1)


def cell_keys(rep):
    return [tuple(int((key >> np.uint64(16 * a)) & np.uint64(0xFFFF)) for a in range(3))
            for key in rep.keys]


# ---------------------------------------------------------------------- the score
def test_history_distances_brute_force():
    rng = np.random.default_rng(0)
    clouds = [rng.uniform(size=(n, 3)) for n in (7, 0, 12)]
    pts = rng.uniform(size=(20, 3))
    got = history_knn_distances(pts, clouds, [1, 4, 19, 20], workers=2)
    for j, k in enumerate((1, 4, 19, 20)):
        np.testing.assert_allclose(got[:, j], brute_scores(pts, clouds, k), rtol=1e-12)
    assert np.isfinite(got[:, 2]).all() and np.isinf(got[:, 3]).all()   # 19 history points
    # one k alone gives the same values as among others
    assert np.array_equal(history_knn_distances(pts, clouds, [4])[:, 0], got[:, 1])
    # no history point: the points' own cloud (the paper's score)
    assert np.array_equal(history_knn_distances(pts, [np.empty((0, 3))], [1, 3]),
                          mean_knn_distances(pts, [1, 3]))
    assert history_knn_distances(np.empty((0, 3)), clouds, [2]).shape == (0, 1)


@pytest.mark.parametrize("history, k", [(1, 1), (1, 2), (2, 2), (2, 3)])
def test_map_scores_three_scans_by_hand(history, k):
    # points on a 1/8 m lattice (exact in float32), every one within range
    scans = [
        (np.array([[1.0, 0.0, 0.0], [1.0, 0.25, 0.0], [1.0, 0.5, 0.125]]), [0.0, 0.0, 0.0]),
        (np.array([[1.125, 0.0, 0.0], [1.0, 0.75, 0.0]]), [0.0, 0.125, 0.0]),
        (np.array([[1.0, 0.125, 0.0], [1.5, 0.5, 0.5], [1.0, 0.625, 0.0],
                   [0.875, 0.25, 0.25]]), [0.0, 0.0, 0.125]),
    ]
    m = KNNMap(0.1, k=k, history=history)
    seen, state = [], (0, 0.0, 0.0)
    for i, (points, origin) in enumerate(scans):
        m.insert_scan(points, origin)
        # the first scan has no history: scored against itself, as the paper scores
        s = brute_scores(points, seen[-history:], k) if i else \
            mean_knn_distances(points, [k])[:, 0]
        if i:
            np.testing.assert_allclose(
                history_knn_distances(points, seen[-history:], [k])[:, 0], s, rtol=1e-15)
        state = _welford(s, *state)
        seen.append(points)
        assert m.n_scores_ == state[0]
        if state[0]:
            assert m.score_mean_ == pytest.approx(state[1], rel=1e-12)
            assert m.score_std_ == pytest.approx(np.sqrt(state[2] / state[0]), abs=1e-12)
        assert len(m._history) == min(i + 1, history)
        assert np.array_equal(m._history[-1], points)
    # by hand, k = 1 and one scan back: the third scan against the second
    if (history, k) == (1, 1):
        want = [0.125 * np.sqrt(2), 0.75, 0.125, 0.25 * np.sqrt(3)]
        np.testing.assert_allclose(brute_scores(scans[2][0], [scans[1][0]], 1), want)


def test_history_zero_is_the_papers_model():
    scans = noisy_scans(np.random.default_rng(3), n_scans=3)
    a, b = build(scans), build(scans, history=0)
    assert a.to_bytes() == b.to_bytes() and a._scores == b._scores
    assert b._history == [] and b.history == 0 and a.get_params()["history"] == 0
    c = build(scans, history=1)
    assert c.to_bytes() != a.to_bytes()


# ---------------------------------------------------------------------- what it is for
def _blob_and_wall(n_scans=5, seed=0):
    """A wall seen from each scan at the same place, and a dense blob of wrong depth
    that each scan sees somewhere else (beside the wall, off every other ray)."""
    rng = np.random.default_rng(seed)
    scans, blobs, walls = [], [], []
    for i in range(n_scans):
        origin = np.array([0.0, 0.2 * i, 0.0])
        wall = np.column_stack([2.0 + 0.01 * rng.standard_normal(800),
                                rng.uniform(-1, 1, (800, 2))])
        blob = np.array([1.5, 1.6 + 0.5 * i, 0.0]) + 0.04 * rng.standard_normal((40, 3))
        scans.append((np.vstack([wall, blob]), origin))
        blobs.append(blob)
        walls.append(wall)
    return scans, np.vstack(blobs[1:]), walls[-1]


@pytest.mark.parametrize("history", [1, 2, 4])
def test_history_isolates_a_view_dependent_blob(history):
    scans, blob, wall = _blob_and_wall()
    maps = {}
    for h in (0, history):
        m = KNNMap(0.1, k=3, history=h)
        for points, origin in scans:
            m.insert_scan(points, origin)
        maps[h] = m
    # one scan's score: the blob is as dense as the wall, so it is mapped as occupied
    paper = maps[0]
    assert paper.is_occupied(blob).mean() > 0.9 and paper.is_occupied(wall).mean() > 0.8
    assert np.nanmean(paper.occupancy(blob)) > np.nanmean(paper.occupancy(wall)) - 0.1
    # over scans: the blob is nowhere the earlier scans saw it, the wall is
    over = maps[history]
    assert over.is_occupied(blob).mean() < 0.05
    assert over.is_occupied(wall).mean() > 0.9
    assert np.nanmean(over.occupancy(blob)) < np.nanmean(over.occupancy(wall)) - 0.5


# ---------------------------------------------------------------------- state
def test_pickle_and_copies_keep_the_history():
    scans = noisy_scans(np.random.default_rng(8), n_scans=5)
    whole = build(scans, history=2)
    half = build(scans[:3], history=2)
    for again in (pickle.loads(pickle.dumps(half)), copy.deepcopy(half), copy.copy(half)):
        assert again.get_params() == half.get_params() and again.history == 2
        assert len(again._history) == 2
        assert all(np.array_equal(a, b) for a, b in zip(again._history, half._history))
        for points, origin in scans[3:]:
            again.insert_scan(points, origin, method="plain")
        assert again.to_bytes() == whole.to_bytes() and again._scores == whole._scores
    # without the history the continuation differs (the next scan scores against itself)
    bare = pickle.loads(pickle.dumps(half))
    bare._history = []
    for points, origin in scans[3:]:
        bare.insert_scan(points, origin, method="plain")
    assert bare.to_bytes() != whole.to_bytes()


def test_files_keep_only_the_tree(tmp_path):
    scans = noisy_scans(np.random.default_rng(2), n_scans=3)
    m = build(scans, history=2)
    m.save(tmp_path / "m.ot")
    back = KNNMap.load(tmp_path / "m.ot", **{k: v for k, v in m.get_params().items()
                                             if k != "resolution"})
    assert back.history == 2 and back._history == [] and back.n_scores_ == 0
    assert leaf_values(back) == leaf_values(m)
    # clear() removes the cells only: the statistics and the history stay
    m.clear()
    assert m.num_leaves == 0 and len(m._history) == 2 and m.n_scores_ > 0


def test_set_params_trims_or_grows_the_history():
    scans = noisy_scans(np.random.default_rng(5), n_scans=5, n_far=0)
    m = build(scans[:3], history=3)
    last = [c.copy() for c in m._history]
    assert len(last) == 3
    m.set_params(history=1)
    assert m.history == 1 and len(m._history) == 1 and np.array_equal(m._history[0], last[-1])
    # the next scan is scored against the one kept cloud
    before = m._scores
    points = scans[3][0].astype(np.float32).astype(np.float64)
    s = history_knn_distances(points, [last[-1]], [m.k])[:, 0]
    m.insert_scan(*scans[3], method="plain")
    assert m._scores == _welford(s, *before)
    m.set_params(history=4)
    assert len(m._history) == 1                      # fills up with the next scans
    m.insert_scan(*scans[4], method="plain")
    assert len(m._history) == 2
    m.set_params(history=0)
    assert m._history == [] and m.history == 0
    m.insert_scan(*scans[0], method="plain")
    assert m._history == []                          # nothing kept without a history


@pytest.mark.parametrize("value, exc, match", [
    (1.5, TypeError, "history must be a non-negative int, got float"),
    ("2", TypeError, "history must be a non-negative int, got str"),
    (True, TypeError, "history must be a non-negative int, got bool"),
    (-1, ValueError, r"history must lie in \[0, 64\], got -1"),
    (65, ValueError, r"history must lie in \[0, 64\], got 65"),
])
def test_bad_history(value, exc, match):
    with pytest.raises(exc, match=match):
        KNNMap(0.1, history=value)
    m = build(noisy_scans(np.random.default_rng(1), n_scans=2), history=2)
    before = (m.get_params(), [c.copy() for c in m._history])
    with pytest.raises(exc, match=match):
        m.set_params(history=value, k=2)
    assert m.get_params() == before[0]
    assert all(np.array_equal(a, b) for a, b in zip(m._history, before[1]))
    with pytest.raises(exc, match=match):
        ScanReplay([], 0.2, history=value)
    assert KNNMap(0.1, history=np.int64(64)).history == 64


def test_rejected_scan_keeps_the_history():
    scans = noisy_scans(np.random.default_rng(9), n_scans=3)
    m = build(scans[:2], history=1)
    before = (m.to_bytes(), m._scores, [c.copy() for c in m._history])
    bad = scans[2][0].copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="points"):
        m.insert_scan(bad, scans[2][1])
    with pytest.raises(ValueError, match="method"):
        m.insert_scan(*scans[2], method="fast")
    assert (m.to_bytes(), m._scores) == before[:2]
    assert len(m._history) == 1 and np.array_equal(m._history[0], before[2][0])


# ---------------------------------------------------------------------- replay
@pytest.mark.parametrize("history", [1, 3])
@pytest.mark.parametrize("cdf", ["normal", "truncated"])
@pytest.mark.parametrize("stats", ["online", "dataset"])
def test_replay_equals_the_maps_with_history(history, cdf, stats):
    scans = noisy_scans(np.random.default_rng(11 + history), n_scans=5, n_wall=80)
    # a scan with no near point: an empty cloud in the history, then the own-scan score
    scans.insert(2, (np.array([[6.0, 0.0, 0.0], [6.0, 1.0, 0.5]]), np.zeros(3)))
    rep = ScanReplay(scans, 0.2, max_range=3.0, ks=(1, 3), cdf=cdf, stats=stats,
                     history=history)
    assert rep.history == history
    combos = [dict(PARAMS), dict(PARAMS, k=1, p_u=0.62, p_l=0.62, p_m=0.05, p_m_out=0.05),
              dict(PARAMS, k=1, p_u=0.74, p_l=0.38, p_min=0.3, p_max=0.6, p_m=0.3,
                   p_m_out=0.45)]
    keys = cell_keys(rep)
    for row, params in zip(rep.knn_log_odds(combos), combos):
        online = build(scans, cdf=cdf, history=history, **params)
        if stats == "dataset":
            # the data set's statistics: those the map reaches after the last scan
            assert rep.score_stats(params["k"]) == (online.score_mean_, online.score_std_)
            m = build(scans, cdf=cdf, history=history,
                      score_stats=rep.score_stats(params["k"]), **params)
        else:
            m = online
        got = leaf_values(m)
        assert set(got) == set(keys)
        assert [got[k] for k in keys] == row.tolist()
    paper = ScanReplay(scans, 0.2, max_range=3.0, ks=(1, 3), cdf=cdf, stats=stats)
    assert not np.array_equal(paper.knn_log_odds(combos), rep.knn_log_odds(combos))


GRID2 = {"k": [3], "p_u": [0.9, 0.7], "p_l": [0.3], "p_m": [0.2], "p_m_out": [0.4],
         "p_min": [0.05], "p_max": [0.95]}


class Wall:
    def occupancy(self, points):
        return np.asarray(points)[:, 0] >= 1.95


def test_grid_search_with_history():
    scans = noisy_scans(np.random.default_rng(21), n_scans=4, n_wall=120)
    rep = ScanReplay(scans, 0.2, max_range=3.0, ks=(3,), history=2)
    labels = cell_labels(Wall(), rep.centers, 0.2)
    res = grid_search(scans, labels, GRID2, resolution=0.2, max_range=3.0, history=2)
    assert res.results == grid_search(rep, labels, GRID2).results
    assert res.results == grid_search(rep, labels, GRID2, history=2).results
    paper = grid_search(scans, labels, GRID2, resolution=0.2, max_range=3.0)
    assert paper.results == grid_search(scans, labels, GRID2, resolution=0.2,
                                        max_range=3.0, history=0).results
    assert [r["auc"] for r in paper.results] != [r["auc"] for r in res.results]
    with pytest.raises(ValueError, match="history=0 differs from the ScanReplay's"):
        grid_search(rep, labels, GRID2, history=0)
    with pytest.raises(TypeError, match="history must be a non-negative int"):
        grid_search(rep, labels, GRID2, history=1.0)
    with pytest.raises(ValueError, match=r"history must lie in \[0, 64\]"):
        grid_search(scans, labels, GRID2, history=100)
