"""The real-log benchmark (occgp.evaluation.RealLogBenchmark): the split, the test points'
geometry, the scores on logs with a known answer, and real maps on small synthetic logs."""

import math

import numpy as np
import pytest

from occgp.datasets import room_2d, structured_room
from occgp.io import LaserLog
from occgp.evaluation import (
    NLL_EPS, LogTestSet, RealLogBenchmark, log_split, log_test_set, score_log,
)


def wall_log(n_scans=20, n_points=200, seed=0):
    """3D scans of a wall at x = 10 from sensors along the y axis at x = 0..2."""
    rng = np.random.default_rng(seed)
    scans = []
    for i in range(n_scans):
        origin = np.array([rng.uniform(0, 2), rng.uniform(-1, 1), 0.0])
        pts = np.column_stack([np.full(n_points, 10.0), rng.uniform(-3, 3, n_points),
                               rng.uniform(-1, 1, n_points)])
        scans.append((pts, origin))
    return scans


class HalfSpace:
    """Occupied beyond x = 9.9 with probability `p_occ`, free before with `p_free`; no
    evidence where x < `unknown_below`."""

    occupancy_threshold = 0.5

    def __init__(self, p_occ=0.9, p_free=0.2, unknown_below=-np.inf):
        self.p_occ, self.p_free, self.unknown_below = p_occ, p_free, unknown_below
        self.origins = []

    def insert_scan(self, points, origin):
        self.origins.append(np.asarray(origin).copy())
        return self

    def occupancy(self, points):
        x = np.asarray(points)[:, 0]
        p = np.where(x >= 9.9, self.p_occ, self.p_free)
        return np.where(x < self.unknown_below, np.nan, p)


def test_split_holds_out_every_tenth_scan_from_the_fifth():
    train, test = log_split(100)
    assert test.tolist() == list(range(5, 100, 10))
    assert sorted(np.r_[train, test].tolist()) == list(range(100))
    with pytest.raises(ValueError, match="holds out no scan"):
        log_split(5)
    with pytest.raises(ValueError, match=r"offset must lie in \[0, every\)"):
        log_split(100, every=4, offset=4)
    with pytest.raises(TypeError, match="n_scans must be an int"):
        log_split(10.0)


def test_test_points_lie_on_their_beams_within_the_cut_offs():
    scans = wall_log(5)
    # one scan with hits too near and too far: they are not scored
    near_far = np.array([[0.3, 0.0, 0.0], [40.0, 0.0, 0.0], [10.0, 0.0, 0.0]])
    scans.append((near_far, np.zeros(3)))
    test = log_test_set(scans, max_range=30.0, min_range=0.5, margin=0.2, near=1.0,
                        near_fraction=0.5, seed=1)
    n = int(test.labels.sum())
    assert n == 5 * 200 + 1 and len(test.labels) == 2 * n
    occ, free = test.points[:n], test.points[n:]
    origins = np.array([scans[i][1] for i in test.scan[:n]])
    assert (test.scan[:n] == test.scan[n:]).all()
    r = np.linalg.norm(occ - origins, axis=1)
    ray = (occ - origins) / r[:, None]
    s = np.einsum("ij,ij->i", free - origins, ray)
    np.testing.assert_allclose(free, origins + s[:, None] * ray, atol=1e-9)   # on the beam
    assert (s >= 0.5 - 1e-9).all() and (s <= r - 0.2 + 1e-9).all()
    near = test.near_surface[n:]
    assert (s[near] >= r[near] - 1.2 - 1e-9).all()
    assert abs(near.mean() - 0.5) < 0.05
    assert not test.near_surface[:n].any()


def test_test_set_is_a_function_of_the_seed():
    scans = wall_log(3)
    a, b = log_test_set(scans, seed=3), log_test_set(scans, seed=3)
    assert all(np.array_equal(x, y) for x, y in zip(a, b))
    c = log_test_set(scans, seed=4)
    assert not np.array_equal(a.points, c.points)
    sub = log_test_set(scans, max_points=50, seed=3)
    assert sub.labels.sum() == 50 and len(sub.labels) == 100


def test_scores_of_a_map_with_a_known_answer():
    """A map that says 0.9 on the wall and 0.2 before it: every point right, the Brier
    score and NLL as computed by hand; where it knows nothing, p = 0.5 and wrong."""
    scans = wall_log()
    bench = RealLogBenchmark(scans)
    maps = []

    def factory():
        maps.append(HalfSpace())
        return maps[-1]

    row = bench.evaluate("half space", factory)
    assert row.auc == 1.0 and row.accuracy == 1.0 and row.unknown_fraction == 0.0
    assert row.brier == pytest.approx((0.1 ** 2 + 0.2 ** 2) / 2)
    assert row.nll == pytest.approx(-(math.log(0.9) + math.log(0.8)) / 2)
    assert row.n_train_scans == 18 and row.threshold == 0.5
    # the held-out scans (5 and 15) were never inserted
    inserted = np.array(maps[0].origins)
    for i in (5, 15):
        assert not (np.abs(inserted - scans[i][1]).sum(axis=1) == 0).any()
    assert len(inserted) == 18

    test = bench.test_set
    unknown = HalfSpace(unknown_below=5.0)
    s = score_log(test, unknown.occupancy(test.points))
    x = test.points[:, 0]
    assert s["unknown_fraction"] == pytest.approx(np.mean(x < 5.0))
    assert s["accuracy"] == pytest.approx(np.mean(x >= 5.0))
    assert s["acc_occupied"] == 1.0
    # an over-confident wrong map is clipped at NLL_EPS
    wrong = score_log(test, np.where(test.labels, 0.0, 1.0))
    assert wrong["accuracy"] == 0.0 and wrong["nll"] == pytest.approx(-math.log(NLL_EPS))


def test_accuracy_uses_the_maps_own_threshold():
    test = LogTestSet(np.zeros((2, 3)), np.array([True, False]), np.array([False, False]),
                      np.zeros(2, dtype=np.int64))
    assert score_log(test, [0.6, 0.4])["accuracy"] == 1.0
    assert score_log(test, [0.6, 0.4], threshold=0.7)["accuracy"] == 0.5
    assert score_log(test, [0.5, 0.2])["acc_occupied"] == 1.0     # p >= threshold
    with pytest.raises(ValueError, match="probabilities must have shape"):
        score_log(test, [0.5])
    with pytest.raises(ValueError, match=r"probabilities must lie in \[0, 1\]"):
        score_log(test, [1.5, 0.0])


def test_real_maps_on_small_synthetic_logs():
    """The 3D octree and BGK on a structured room's sparse scans (BGK fills the holes
    between the rays: fewer unknowns, a higher AUC) and the 2D log-odds grid on the 2D
    room's laser scans."""
    scans = structured_room(seed=0).scan(seed=0, n_points=800)
    bench = RealLogBenchmark(scans, every=4, offset=1, max_range=8.0)
    rows = bench.compare({"octree": {"map": "octree", "resolution": 0.1},
                          "bgk": {"map": "bgk", "resolution": 0.1}})
    assert [r.method for r in rows] == ["octree", "bgk"]
    assert all(r.auc > 0.75 and r.n_test == len(bench.test_set.labels) for r in rows)
    assert rows[1].auc > rows[0].auc and rows[1].unknown_fraction < rows[0].unknown_fraction
    log = LaserLog(room_2d().scan(n_poses=26), np.arange(26.0))
    bench2 = RealLogBenchmark(log, every=5, offset=2, max_range=8.0)
    row = bench2.evaluate("grid", {"map": "gp-grid", "resolution": 0.1})
    assert row.auc > 0.7 and row.build_seconds >= 0 and row.query_seconds >= 0
    assert bench2.test_set.points.shape[1] == 2


def test_bad_arguments():
    scans = wall_log(3)
    with pytest.raises(ValueError, match="min_range \\+ margin must be less than max_range"):
        log_test_set(scans, max_range=0.4, min_range=0.3, margin=0.2)
    with pytest.raises(ValueError, match="no held-out hit lies between"):
        log_test_set(scans, max_range=5.0)
    with pytest.raises(ValueError, match=r"near_fraction must lie in \[0.0, 1.0\]"):
        log_test_set(scans, near_fraction=2.0)
    with pytest.raises(TypeError, match="max_points must be an int or None"):
        log_test_set(scans, max_points=2.5)
    bench = RealLogBenchmark(wall_log())
    with pytest.raises(ValueError, match="the 'gpom' map takes points of 2 dimensions"):
        bench.evaluate("gpom", "gpom")
    with pytest.raises(TypeError, match="method must be a factory"):
        bench.evaluate("x", 3)
    with pytest.raises(TypeError, match="scans must be a LaserLog"):
        RealLogBenchmark(5)
