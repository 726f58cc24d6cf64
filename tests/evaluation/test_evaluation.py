import logging
import time
from typing import NamedTuple

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

import occgp.maps
from occgp import BGKMap, KNNMap
from occgp.evaluation import _protocols
from occgp.evaluation import (
    MapResult,
    TestSet,
    compare_methods,
    equal_time_comparison,
    evaluate_map,
    format_table,
    grid_test_set,
    held_out_split,
    rows_to_records,
    run_method,
)
from occgp.maps import available_maps, make_map


class FakeGridMap:
    """Bounded voxel grid counting hits (+1) and misses (-1) per cell.

    Misses are sampled along each ray at half-cell steps, so a cell is
    unknown (NaN) until a ray touches it.
    """

    def __init__(self, lo=(-2.0, -2.0, -1.0), hi=(2.0, 2.0, 2.0), resolution=0.2):
        self.lo, self.res = np.asarray(lo), resolution
        self.shape = tuple(np.ceil((np.asarray(hi) - self.lo) / resolution).astype(int))
        self.hits = np.zeros(self.shape)
        self.misses = np.zeros(self.shape)
        self.n_inserted = 0

    def _index(self, points):
        idx = np.floor((np.asarray(points) - self.lo) / self.res).astype(int)
        inside = np.all((idx >= 0) & (idx < self.shape), axis=1)
        return idx, inside

    def insert_scan(self, points, origin):
        points = np.asarray(points)
        self.n_inserted += len(points)
        t = np.arange(0.0, 1.0, 0.5 * self.res / 4.0)  # rays are at most ~4 m here
        along = origin + t[None, :, None] * (points - origin)[:, None, :]
        idx, inside = self._index(along.reshape(-1, 3))
        np.add.at(self.misses, tuple(idx[inside].T), 1)
        idx, inside = self._index(points)
        np.add.at(self.hits, tuple(idx[inside].T), 1)
        return self

    def occupancy(self, points):
        idx, inside = self._index(points)
        out = np.full(len(idx), np.nan)
        h = self.hits[tuple(idx[inside].T)]
        m = self.misses[tuple(idx[inside].T)]
        p = 1 / (1 + np.exp(np.clip(0.5 * m - 2.0 * h, -50, 50)))
        out[inside] = np.where(h + m > 0, p, np.nan)
        return out


class FakeClock:
    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now


class CostlyMap(FakeGridMap):
    """Advances a fake clock by `cost` per inserted point."""

    def __init__(self, clock, cost):
        super().__init__()
        self.clock, self.cost = clock, cost

    def insert_scan(self, points, origin):
        self.clock.now += self.cost * len(points)
        return super().insert_scan(points, origin)


class MyScan(NamedTuple):
    points: np.ndarray
    origin: np.ndarray


def room_scans(n_scans=3, n=100, seed=0):
    """Wall points of a 2 m x 2 m x 1 m box seen from near its center."""
    rng = np.random.default_rng(seed)
    scans = []
    for _ in range(n_scans):
        u, z = rng.uniform(-1, 1, n), rng.uniform(0.05, 0.95, n)
        side = rng.integers(0, 4, n)
        x = np.where(side == 0, -1.0, np.where(side == 1, 1.0, u))
        y = np.where(side == 2, -1.0, np.where(side == 3, 1.0, u))
        origin = np.r_[rng.uniform(-0.2, 0.2, 2), 0.5]
        scans.append((np.column_stack([x, y, z]), origin))
    return scans


def sort_rows(a):
    return a[np.lexsort(a.T[::-1])]


# ----------------------------------------------------------- held-out split
def test_held_out_split_fractions_and_partition():
    scans = room_scans(n_scans=2, n=100)
    train, test = held_out_split(scans, fraction=0.2, seed=0)
    assert [len(p) for p, _ in train] == [80, 80]
    occ = test.points[test.labels]
    assert len(occ) == 40 and test.labels.dtype == bool
    for i, ((points, origin), (tp, to)) in enumerate(zip(scans, train)):
        assert_array_equal(to, origin)
        held = occ[20 * i: 20 * (i + 1)]
        assert_array_equal(sort_rows(np.vstack([tp, held])), sort_rows(points))


def test_held_out_split_free_points_lie_on_their_rays():
    rng = np.random.default_rng(0)
    origin = np.array([0.5, -0.5, 0.2])
    # half the rays shorter than the margin: they give no free point
    dirs = rng.normal(size=(100, 3))
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    length = np.where(np.arange(100) % 2 == 0, rng.uniform(0.05, 0.29, 100),
                      rng.uniform(0.5, 3.0, 100))
    scan = (origin + dirs * length[:, None], origin)
    train, test = held_out_split([scan], fraction=0.5, free_margin=0.3, seed=1)
    occ, free = test.points[test.labels], test.points[~test.labels]
    long_ = np.linalg.norm(occ - origin, axis=1) > 0.3
    assert len(free) == long_.sum() > 0
    ends = occ[long_]
    ray, rel = ends - origin, free - origin
    t = np.einsum("ij,ij->i", rel, ray) / np.einsum("ij,ij->i", ray, ray)
    assert_allclose(np.cross(rel, ray), 0, atol=1e-12)  # on the line
    assert np.all(t >= 0)                               # not behind the origin
    assert np.all(np.linalg.norm(ends - free, axis=1) >= 0.3 - 1e-12)
    assert_array_equal(test.labels, np.r_[np.ones(len(occ)), np.zeros(len(free))] == 1)


def test_held_out_split_is_reproducible():
    scans = room_scans()
    a_train, a_test = held_out_split(scans, seed=3)
    b_train, b_test = held_out_split(scans, seed=3)
    c_train, c_test = held_out_split(scans, seed=4)
    assert_array_equal(a_test.points, b_test.points)
    for (pa, _), (pb, _) in zip(a_train, b_train):
        assert_array_equal(pa, pb)
    assert not np.array_equal(a_test.points, c_test.points)


def test_held_out_split_keeps_scan_types():
    points, origin = room_scans(n_scans=1)[0]
    train, _ = held_out_split([MyScan(points, origin), [points, origin]])
    assert type(train[0]) is MyScan
    assert type(train[1]) is tuple and len(train[1]) == 2


def test_held_out_split_keeps_a_training_point():
    train, test = held_out_split([(np.ones((1, 3)), np.zeros(3)),
                                  (np.ones((2, 3)), np.zeros(3))], fraction=0.9)
    assert [len(p) for p, _ in train] == [1, 1]
    assert test.labels.sum() == 1


@pytest.mark.parametrize("kwargs, match", [
    ({"fraction": 0.0}, r"fraction must lie in \(0.0, 1.0\), got 0.0"),
    ({"fraction": 1.0}, r"fraction must lie in \(0.0, 1.0\), got 1.0"),
    ({"free_margin": -0.1}, r"free_margin must lie in \[0.0, inf\), got -0.1"),
    ({"free_margin": np.nan}, "free_margin must lie in"),
])
def test_held_out_split_rejects_bad_parameters(kwargs, match):
    with pytest.raises(ValueError, match=match):
        held_out_split(room_scans(), **kwargs)


@pytest.mark.parametrize("scans, error, match", [
    ([], ValueError, "scans must hold at least one scan, got 0"),
    ([(np.zeros((5, 2)), np.zeros(3))], ValueError,
     r"scans\[0\].points must have shape \(n_points, 3\), got \(5, 2\)"),
    ([(np.zeros((0, 3)), np.zeros(3))], ValueError,
     r"scans\[0\].points must hold at least one point"),
    ([(np.ones((2, 3)), np.zeros(3)), (np.ones((2, 3)), np.zeros(2))], ValueError,
     r"scans\[1\].origin must have shape \(3,\), got \(2,\)"),
    ([(np.full((2, 3), np.nan), np.zeros(3))], ValueError, r"scans\[0\].points must be finite"),
    ([(np.ones((2, 3)), np.zeros(3), 5)], ValueError,
     r"scans\[0\] must be a \(points, origin\) pair, got a sequence of length 3"),
    ([5], TypeError, r"scans\[0\] must be a \(points, origin\) pair, got int"),
    (np.ones((4, 3)), TypeError, "scans must be a sequence of"),
])
def test_scans_are_validated(scans, error, match):
    with pytest.raises(error, match=match):
        held_out_split(scans)
    with pytest.raises(error, match=match):
        run_method("m", FakeGridMap, scans, TestSet(np.zeros((2, 3)), np.array([1, 0])))


# ------------------------------------------------------------ grid test set
class Cube:
    """Solid cube [0, 1]^3 inside a 2 m box."""

    bounds = (np.array([-0.5, -0.5, -0.5]), np.array([1.5, 1.5, 1.5]))

    def occupancy(self, points):
        return np.all((points >= 0) & (points <= 1), axis=1)


def test_grid_test_set_centers_and_labels():
    test = grid_test_set(Cube(), 0.5)
    assert test.points.shape == (64, 3)
    assert_allclose(np.unique(test.points[:, 0]), [-0.25, 0.25, 0.75, 1.25])
    assert test.labels.sum() == 8  # centers 0.25 and 0.75 on each axis
    assert_array_equal(test.labels, Cube().occupancy(test.points))


def test_grid_test_set_bbox_aligned_to_lattice_and_observed():
    test = grid_test_set(Cube(), 0.2, bbox=([0.05, 0.05, 0.0], [0.5, 0.3, 0.0]))
    assert_allclose(np.unique(test.points[:, 0]), [0.1, 0.3, 0.5])  # closed box
    test = grid_test_set(Cube(), 0.2, bbox=([0.05, 0.05, 0.0], [0.45, 0.25, 0.0]))
    assert_allclose(np.unique(test.points[:, 0]), [0.1, 0.3])
    assert_allclose(np.unique(test.points[:, 1]), [0.1])
    assert_allclose(np.unique(test.points[:, 2]), [0.0])        # thin axis: its middle
    test = grid_test_set(Cube(), 0.5, observed=lambda p: p[:, 2] > 0)
    assert len(test.points) == 48 and np.all(test.points[:, 2] > 0)


@pytest.mark.parametrize("kwargs, error, match", [
    ({"resolution": 0.0}, ValueError, r"resolution must lie in \(0.0, inf\)"),
    ({"resolution": "a"}, TypeError, "resolution must be a real number"),
    ({"resolution": 0.5, "bbox": ([0, 0, 0],)}, ValueError, r"bbox must be a \(min, max\) pair"),
    ({"resolution": 0.5, "bbox": ([1, 0, 0], [0, 1, 1])}, ValueError, "min <= max"),
    ({"resolution": 0.5, "bbox": ([0, 0], [1, 1])}, ValueError,
     r"bbox\[0\] must have shape \(3,\)"),
    ({"resolution": 1e-4}, ValueError, "the grid would hold"),
    ({"resolution": 0.5, "observed": lambda p: True}, ValueError,
     r"observed\(points\) must return shape \(64,\)"),
])
def test_grid_test_set_rejects_bad_input(kwargs, error, match):
    with pytest.raises(error, match=match):
        grid_test_set(Cube(), **kwargs)


def test_grid_test_set_checks_scene_answer():
    class Bad(Cube):
        def occupancy(self, points):
            return np.zeros(3, dtype=bool)

    with pytest.raises(ValueError, match=r"scene.occupancy\(points\) must return shape"):
        grid_test_set(Bad(), 0.5)


# ---------------------------------------------------------- scoring a map
@pytest.fixture
def room():
    return held_out_split(room_scans(n_scans=4, n=200), seed=0)


def test_run_method_scores_a_fake_map(room):
    train, test = room
    calls = []

    def factory():
        calls.append(1)
        return FakeGridMap()

    row = run_method("fake", factory, train, test, progress=False)
    assert len(calls) == 1
    assert isinstance(row, MapResult) and row.method == "fake"
    assert row.seconds > 0
    assert row.n_scans == 4 and row.n_points == 4 * 160 == row.map.n_inserted
    assert row.n_test == len(test.points) and row.data_fraction == 1.0
    assert row.auc > 0.8 and row.tpr_fdr_auc > 0.6
    assert 0 <= row.mse < 0.25
    assert 0 <= row.unknown_fraction < 0.5
    assert row.acc_free > 0.5
    assert evaluate_map(row.map, test)["auc"] == pytest.approx(row.auc)


def test_evaluate_map_counts_unknown_as_half():
    class Unknown:
        def occupancy(self, points):
            return np.full(len(points), np.nan)

    s = evaluate_map(Unknown(), (np.zeros((4, 3)), [1, 0, 1, 0]))
    assert (s["auc"], s["mse"], s["acc_occupied"], s["acc_free"]) == (0.5, 0.25, 0.0, 0.0)
    assert s["unknown_fraction"] == 1.0


def test_evaluate_map_rejects_bad_answers_and_test_sets():
    class Wrong:
        def occupancy(self, points):
            return np.zeros((len(points), 1))

    test = TestSet(np.zeros((2, 3)), np.array([True, False]))
    with pytest.raises(ValueError, match=r"map.occupancy\(points\) must return shape \(2,\)"):
        evaluate_map(Wrong(), test)
    with pytest.raises(ValueError, match=r"test_set.labels must have shape \(2,\)"):
        evaluate_map(Wrong(), (np.zeros((2, 3)), [True]))
    with pytest.raises(ValueError, match=r"test_set.points must have shape \(n_points, 3\)"):
        evaluate_map(Wrong(), (np.zeros((2, 2)), [True, False]))
    with pytest.raises(ValueError, match="pair, got a sequence of length 3"):
        evaluate_map(Wrong(), (1, 2, 3))
    with pytest.raises(TypeError, match="test_set must be a TestSet"):
        evaluate_map(Wrong(), None)


def test_run_method_rejects_non_callable_factory(room):
    with pytest.raises(TypeError, match="factory of method 'x' must be callable, got int"):
        run_method("x", 3, *room)


def test_compare_methods_keeps_order(room):
    train, test = room
    rows = compare_methods({"b": FakeGridMap, "a": lambda: FakeGridMap(resolution=0.4)},
                           train, test, progress=False)
    assert [r.method for r in rows] == ["b", "a"]
    assert all(r.n_points == 640 for r in rows)
    with pytest.raises(ValueError, match="methods must hold at least one method"):
        compare_methods({}, train, test)
    with pytest.raises(TypeError, match="methods must be a mapping"):
        compare_methods([FakeGridMap], train, test)


# ------------------------------------------------------ equal-time comparison
@pytest.fixture
def clock(monkeypatch):
    clock = FakeClock()
    monkeypatch.setattr(_protocols, "_clock", clock)
    return clock


@pytest.mark.parametrize("cost, expected", [(2.0, 0.5), (3.0, 0.3), (1.0, 1.0)])
def test_equal_time_reduces_slow_methods(room, clock, cost, expected):
    train, test = room
    rows = equal_time_comparison(
        {"fast": lambda: CostlyMap(clock, 1.0), "slow": lambda: CostlyMap(clock, cost)},
        train, test, progress=False)
    fast, slow = rows
    assert fast.data_fraction == 1.0 and fast.seconds == 640
    assert slow.data_fraction == pytest.approx(expected)
    assert slow.seconds <= fast.seconds
    assert slow.n_points == 4 * round(expected * 160) == slow.map.n_inserted


def test_equal_time_uses_nested_subsets_of_the_scans(room, clock):
    train, test = room
    inserted = []

    class Recording(CostlyMap):
        def insert_scan(self, points, origin):
            inserted.append(points.copy())
            return super().insert_scan(points, origin)

    rows = equal_time_comparison(
        {"fast": lambda: CostlyMap(clock, 1.0), "slow": lambda: Recording(clock, 1.5)},
        train, test, step=0.25, progress=False)
    assert rows[1].data_fraction == 0.5
    assert len(inserted) == 12                            # 100%, 75%, 50%

    def subset(a, b):
        return (a[:, None, :] == b[None]).all(-1).any(-1).all()

    for i in range(4):
        full, three_q, half = inserted[i], inserted[4 + i], inserted[8 + i]
        assert (len(three_q), len(half)) == (120, 80)
        assert subset(three_q, full) and subset(half, three_q)


def test_equal_time_max_rounds_warns(room, clock, caplog):
    train, test = room
    with caplog.at_level(logging.WARNING, logger="occgp"):
        rows = equal_time_comparison(
            {"fast": lambda: CostlyMap(clock, 1.0), "slow": lambda: CostlyMap(clock, 10.0)},
            train, test, max_rounds=2, progress=False)
    assert rows[1].data_fraction == pytest.approx(0.9)
    assert "still over the budget" in caplog.text


def test_equal_time_reuses_full_rows(room, clock):
    train, test = room
    calls = []

    def slow():
        calls.append(1)
        return CostlyMap(clock, 2.0)

    methods = {"fast": lambda: CostlyMap(clock, 1.0), "slow": slow}
    full = compare_methods(methods, train, test, progress=False)
    calls.clear()
    rows = equal_time_comparison(methods, train, test, full_rows=full, progress=False)
    assert len(calls) == 10  # 95% ... 50%, no second all-data run
    assert rows[1].data_fraction == 0.5
    with pytest.raises(ValueError, match=r"full_rows must hold a row for every method.*slow"):
        equal_time_comparison(methods, train, test, full_rows=full[:1])


def test_equal_time_with_real_clock():
    scans = room_scans(n_scans=2, n=40)
    train, test = held_out_split(scans, seed=0)

    class Sleepy(FakeGridMap):
        def insert_scan(self, points, origin):
            time.sleep(2e-5 * len(points))
            return super().insert_scan(points, origin)

    rows = equal_time_comparison({"fast": FakeGridMap, "slow": Sleepy}, train, test,
                                 step=0.25, progress=False)
    assert rows[0].data_fraction == 1.0 and rows[1].data_fraction < 1.0


@pytest.mark.parametrize("kwargs, error, match", [
    ({"step": 0.0}, ValueError, r"step must lie in \(0.0, 1.0\)"),
    ({"step": 1.2}, ValueError, r"step must lie in \(0.0, 1.0\)"),
    ({"max_rounds": -1}, ValueError, "max_rounds must be a non-negative integer"),
    ({"max_rounds": 1.5}, ValueError, "max_rounds must be a non-negative integer"),
])
def test_equal_time_rejects_bad_parameters(room, kwargs, error, match):
    with pytest.raises(error, match=match):
        equal_time_comparison({"a": FakeGridMap}, *room, **kwargs)


# ------------------------------------------------------------------- tables
def make_rows():
    return [
        MapResult("AKIMap", 0.912, 0.063, 0.678, 0.981, 0.8, 2.76, 12, 31500, 100, 0.1, 0.75),
        MapResult("BGKOctoMap-L", 0.892, 0.109, 0.476, 0.981, 0.7, 2.82, 12, 42000, 100, 0.2,
                  map=object()),
    ]


def test_format_table_aligns_columns():
    table = format_table(make_rows())
    lines = table.splitlines()
    assert len(lines) == 4
    assert "AKIMap" in lines[2] and "BGKOctoMap-L" in lines[3]
    assert "75%" in lines[2] and "100%" in lines[3]
    assert len({len(line) for line in lines}) == 1
    # every column boundary (two spaces in the rule) is blank on every line
    gaps = [i for i in range(1, len(lines[1])) if lines[1][i - 1:i + 1] == "  "]
    assert gaps and all(line[i] == " " for line in lines for i in gaps)
    assert lines[0].split()[:3] == ["method", "data", "AUC"]
    assert "object" not in table


def test_format_table_columns_floatfmt_and_dicts():
    rows = rows_to_records(make_rows())
    table = format_table(rows, columns=["method", "n_points", "mse"], floatfmt=".1f")
    assert table.splitlines()[2].split() == ["AKIMap", "31500", "0.1"]
    with pytest.raises(ValueError, match=r"columns \['nope'\] are not in rows\[0\]"):
        format_table(rows, columns=["method", "nope"])
    with pytest.raises(TypeError, match=r"rows\[0\] must be a MapResult or a dict, got int"):
        format_table([1])


def test_rows_to_records_drops_maps():
    records = rows_to_records(make_rows())
    assert all("map" not in r for r in records)
    assert records[0]["method"] == "AKIMap" and records[1]["data_fraction"] == 1.0
    assert set(records[0]) == set(MapResult._fields) - {"map"}


# ------------------------------------------------- methods from the map registry
@pytest.fixture
def registry(monkeypatch):
    """occgp.maps with a copy of its registry: map types registered in a test leave
    with it."""
    occgp.maps.available_maps()               # the built-in types, registered once
    monkeypatch.setattr(occgp.maps, "_REGISTRY", dict(occgp.maps._REGISTRY))
    return occgp.maps


def same_scores(a, b):
    keys = ("auc", "mse", "acc_occupied", "acc_free", "tpr_fdr_auc", "n_points", "n_test",
            "unknown_fraction")
    return all(getattr(a, k) == getattr(b, k) for k in keys)


def test_compare_methods_takes_registered_names(room):
    train, test = room
    rows = compare_methods(["knn", "bgk"], train, test, progress=False)
    assert [r.method for r in rows] == ["knn", "bgk"]
    assert isinstance(rows[0].map, KNNMap) and isinstance(rows[1].map, BGKMap)
    by_factory = compare_methods({"knn": lambda: make_map("knn"),
                                  "bgk": lambda: make_map("bgk")}, train, test,
                                 progress=False)
    assert all(same_scores(a, b) for a, b in zip(rows, by_factory))
    row = run_method("k", "knn", train, test, progress=False)
    assert row.method == "k" and same_scores(row, rows[0])


def test_compare_methods_takes_map_dicts_and_factories(room):
    train, test = room
    spec = {"map": "bgk", "resolution": 0.2}
    rows = compare_methods({"dict": spec, "factory": lambda: BGKMap(resolution=0.2),
                            "fake": FakeGridMap, "name": "knn"}, train, test, progress=False)
    assert [r.method for r in rows] == ["dict", "factory", "fake", "name"]
    assert isinstance(rows[0].map, BGKMap) and rows[0].map.resolution == 0.2
    assert same_scores(rows[0], rows[1])
    assert isinstance(rows[2].map, FakeGridMap) and isinstance(rows[3].map, KNNMap)
    assert spec == {"map": "bgk", "resolution": 0.2}          # left as given
    row = run_method("r", {"map": "knn", "resolution": 0.2, "k": 3}, train, test,
                     progress=False)
    assert (row.map.resolution, row.map.k) == (0.2, 3)


def test_map_dicts_pass_insert_options(room):
    train, test = room
    spec = {"map": "octree", "resolution": 0.2, "insert": {"mode": "ray"}}
    row, = compare_methods({"ray": spec}, train, test, progress=False)
    expected = make_map("octree", resolution=0.2)
    for points, origin in train:
        expected.insert_scan(points, origin, mode="ray")
    probe = np.asarray(test[0] if isinstance(test, tuple) else test.points)
    np.testing.assert_array_equal(row.map.log_odds(probe), expected.log_odds(probe))
    scan_mode, = compare_methods({"scan": {"map": "octree", "resolution": 0.2}}, train, test,
                                 progress=False)
    assert not np.array_equal(scan_mode.map.log_odds(probe), expected.log_odds(probe),
                              equal_nan=True)
    with pytest.raises(TypeError, match="the 'insert' of method 'x' must be a mapping"):
        compare_methods({"x": {"map": "octree", "insert": "ray"}}, train, test)
    assert spec["insert"] == {"mode": "ray"}                  # left as given


@pytest.mark.parametrize("call", [
    lambda room: compare_methods({"x": "nope"}, *room),
    lambda room: compare_methods({"x": {"map": "nope", "resolution": 0.1}}, *room),
    lambda room: compare_methods(["knn", "nope"], *room),
    lambda room: run_method("x", "nope", *room),
    lambda room: equal_time_comparison(["nope"], *room),
])
def test_unknown_map_names_list_the_registered_ones(room, call):
    with pytest.raises(ValueError, match="unknown map type 'nope'; available: ") as err:
        call(room)
    assert all(name in str(err.value) for name in available_maps())


@pytest.mark.parametrize("methods, error, match", [
    ({"x": {"resolution": 0.2}}, ValueError, "the dict of method 'x' must hold the key 'map'"),
    ({"x": {"map": 3}}, TypeError, "the 'map' of method 'x' must be a registered map name"),
    ({"x": {"map": "knn", "bogus": 1}}, ValueError,
     "method 'x': the 'knn' map takes no parameter 'bogus'; it takes .*resolution"),
    ({"x": 3}, TypeError, "factory of method 'x' must be callable, got int"),
    (["knn", "bgk", "knn"], ValueError, r"must name each map type once, got \['knn'\]"),
    ("knn", TypeError, "methods must be a mapping .* got str"),
    (["knn", FakeGridMap], TypeError, "methods must be a mapping .* got list holding type"),
    (iter(["knn"]), TypeError, "methods must be a mapping"),
    ([], ValueError, "methods must hold at least one method"),
])
def test_compare_methods_rejects_bad_specs(room, methods, error, match):
    with pytest.raises(error, match=match):
        compare_methods(methods, *room)


def test_specs_are_checked_before_any_map_is_built(room):
    built = []

    def factory():
        built.append(1)
        return FakeGridMap()

    for bad in ({"map": "knn", "bogus": 1}, "nope", {"map": 3}):
        with pytest.raises((ValueError, TypeError)):
            compare_methods({"first": factory, "second": bad}, *room)
        with pytest.raises((ValueError, TypeError)):
            equal_time_comparison({"first": factory, "second": bad}, *room)
    assert not built


class Sized(FakeGridMap):
    """A fake map whose constructor needs a parameter."""

    def __init__(self, size, scale=1.0):
        super().__init__()
        self.size = size


def test_registered_names_need_3d_maps_and_their_parameters(room, registry):
    registry.register("test-flat", dims=2, description="A 2D map")(FakeGridMap)
    registry.register("test-sized")(Sized)
    with pytest.raises(ValueError, match="method 'test-flat': the 'test-flat' map takes "
                                         "points of 2 dimensions, the scans here are 3D; "
                                         "3D maps: ") as err:
        compare_methods(["test-flat"], *room)
    assert all(name in str(err.value) for name in available_maps(dims=3))
    with pytest.raises(ValueError, match=r"the 'test-sized' map needs the parameters "
                                         r"\['size'\]"):
        compare_methods(["test-sized"], *room)
    row = run_method("s", {"map": "test-sized", "size": 4}, *room, progress=False)
    assert isinstance(row.map, Sized) and row.map.size == 4


def test_equal_time_takes_registered_maps(room, clock, registry):
    registry.register("test-costly", description="A fake map on a fake clock")(CostlyMap)
    train, test = room
    rows = equal_time_comparison(
        {"fast": {"map": "test-costly", "clock": clock, "cost": 1.0},
         "slow": {"map": "test-costly", "clock": clock, "cost": 2.0}},
        train, test, progress=False)
    assert [(r.method, r.data_fraction) for r in rows] == [("fast", 1.0), ("slow", 0.5)]
    assert all(isinstance(r.map, CostlyMap) for r in rows)
    rows = equal_time_comparison(["knn"], train, test, max_rounds=1, progress=False)
    assert [(r.method, r.data_fraction) for r in rows] == [("knn", 1.0)]
