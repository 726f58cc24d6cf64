"""The 2D scene family (occgp.datasets.scene_family_2d) and its scoring protocol
(occgp.evaluation.evaluate_scene_set)."""

import math

import numpy as np
import pytest

from occgp.datasets import (
    FAMILY_KINDS, TEST_SEEDS, TUNING_SEEDS, FamilyScene2D, LaserScan2D, Scene2D,
    scene_family_2d,
)
from occgp.datasets._scene2d import Circle, Rect, path_samples
from occgp.evaluation import (
    PeakRSS, evaluate_scene_set, format_scene_set, fpr_at_tpr, summarize_scene_set,
)
from occgp.gp import OccupancyGrid, grid_points, observations_from_scans
from occgp.metrics import roc_curve

ALL_SEEDS = list(TUNING_SEEDS) + list(TEST_SEEDS)


@pytest.fixture(scope="module")
def cases():
    return {seed: scene_family_2d(seed) for seed in ALL_SEEDS}


def _same_scene(a, b):
    assert a.labels == b.labels
    np.testing.assert_array_equal(a.path, b.path)
    for s, t in zip(a.solids, b.solids):
        assert type(s) is type(t)
        np.testing.assert_array_equal(s.center, t.center)
        if isinstance(s, Rect):
            np.testing.assert_array_equal(s.half, t.half)
            np.testing.assert_array_equal(s.rotation, t.rotation)
        else:
            assert s.radius == t.radius


# ------------------------------------------------------------------------ the split
def test_split_is_disjoint_and_balanced():
    assert not set(TUNING_SEEDS) & set(TEST_SEEDS)
    for seeds in (TUNING_SEEDS, TEST_SEEDS):
        kinds = [FAMILY_KINDS[s % 4] for s in seeds]
        assert {k: kinds.count(k) for k in FAMILY_KINDS} == {k: 3 for k in FAMILY_KINDS}


@pytest.mark.slow
def test_every_kind_and_laser_in_each_split(cases):
    for seeds in (TUNING_SEEDS, TEST_SEEDS):
        assert [cases[s].kind for s in seeds[:4]] == list(FAMILY_KINDS)
        beams = [cases[s].sensor.n_beams for s in seeds]
        assert sorted(set(beams)) == [17, 61, 181, 361]
        assert all(beams.count(b) == 3 for b in set(beams))
        thickness = [cases[s].scene.wall_thickness for s in seeds]
        assert min(thickness) <= 0.1 and max(thickness) >= 0.3


def test_kinds_have_their_solids(cases):
    for case in cases.values():
        assert isinstance(case, FamilyScene2D) and isinstance(case.scene, Scene2D)
        assert all(isinstance(s, (Rect, Circle)) for s in case.scene.solids)
        labels = " ".join(case.scene.labels)
        expected = {"office": "room_", "warehouse": "rack_", "hall": "pillar_",
                    "cluttered": "piece_"}[case.kind]
        assert expected in labels
        w, h = case.size
        assert 12 <= w <= 40 and 10 <= h <= 30
        t = case.scene.wall_thickness
        assert 0.05 <= t <= 0.1 or 0.3 <= t <= 0.5


# -------------------------------------------------------------------- determinism
def test_same_seed_same_case(cases):
    for seed in (0, 1, 2, 3, 103):
        again = scene_family_2d(seed)
        _same_scene(again.scene, cases[seed].scene)
        assert again.sensor == cases[seed].sensor
        for a, b in zip(again.scans(), cases[seed].scans()):
            np.testing.assert_array_equal(a.ranges, b.ranges)
            np.testing.assert_array_equal(a.origin, b.origin)
            assert a.heading == b.heading


def test_other_seed_other_case(cases):
    assert cases[0].sensor != cases[4].sensor
    assert not np.array_equal(cases[1].scene.path, cases[5].scene.path)


def test_kind_override():
    case = scene_family_2d(0, "hall")
    assert case.kind == "hall" and "pillar_0" in case.scene.labels


# ------------------------------------------------------------------------ the path
@pytest.mark.slow
def test_paths_keep_clearance_and_revisit(cases):
    for seed, case in cases.items():
        path = case.scene.path
        samples = path_samples(path, step=0.02)
        assert case.scene.signed_distance(samples).min() >= 0.5, seed
        # the path passes again within 0.3 m of where it was, after 5 m or more away
        seg = np.linalg.norm(np.diff(samples, axis=0), axis=1)
        arc = np.concatenate([[0.0], np.cumsum(seg)])
        sub = samples[::10]
        d = np.linalg.norm(sub[:, None] - sub[None], axis=2)
        apart = np.abs(arc[::10][:, None] - arc[::10][None]) > 5.0
        assert np.any((d < 0.3) & apart), seed


def test_poses_lie_on_the_path_in_free_space(cases):
    case = cases[2]
    origins, headings = case.poses()
    assert origins.shape == (case.sensor.n_poses, 2)
    assert not case.scene.occupancy(origins).any()
    assert case.scene.signed_distance(origins).min() >= 0.5


# ------------------------------------------------------------------------- sensors
def test_sensor_settings_within_their_ranges(cases):
    for case in cases.values():
        s = case.sensor
        assert (s.n_beams, round(math.degrees(s.fov))) in {(17, 180), (61, 180), (181, 270),
                                                         (361, 360)}
        assert 6.0 <= s.max_range <= 10.0
        assert 0.0 <= s.range_noise <= 0.05
        assert 0.0 <= s.position_noise <= 0.03 and 0.0 <= s.heading_noise <= 0.005
        assert 1200 <= case.n_observations <= 7000
    assert any(c.sensor.range_noise == 0 for c in cases.values())
    assert any(c.sensor.position_noise == 0 for c in cases.values())


def test_observation_count_matches_the_gp_data(cases):
    case = cases[1]
    hits, starts, ends = observations_from_scans(case.scans())
    assert len(hits) + len(starts) == case.n_observations
    assert len(starts) == case.sensor.n_poses * case.sensor.n_beams


def test_full_turn_has_no_repeated_beam(cases):
    case = next(c for c in cases.values() if c.sensor.n_beams == 361)
    angles = case.sensor.angles
    assert len(np.unique(np.round(np.mod(angles, 2 * np.pi), 9))) == 361


@pytest.mark.slow
def test_zero_noise_gives_exact_ranges(cases):
    case = cases[7]                            # range and pose noise in its setting
    assert case.sensor.range_noise > 0 and case.sensor.position_noise > 0
    quiet = case.sensor._replace(range_noise=0.0, position_noise=0.0, heading_noise=0.0)
    origins, headings = case.poses()
    for scan, o, h in zip(case.scans(quiet), origins, headings):
        assert isinstance(scan, LaserScan2D)
        np.testing.assert_array_equal(scan.origin, o)
        assert scan.heading == h
        world = h + scan.angles
        d, hit = case.scene.ray_cast(o, np.column_stack([np.cos(world), np.sin(world)]),
                                     scan.max_range)
        np.testing.assert_array_equal(scan.ranges, d)
        np.testing.assert_array_equal(scan.hit, hit)


def test_noise_is_applied_as_specified(cases):
    case = cases[7]
    s = case.sensor
    quiet = s._replace(range_noise=0.0, position_noise=0.0, heading_noise=0.0)
    exact, noisy = case.scans(quiet), case.scans()
    hit = np.concatenate([a.hit for a in exact])
    assert np.array_equal(hit, np.concatenate([b.hit for b in noisy]))
    dr = np.concatenate([b.ranges - a.ranges for a, b in zip(exact, noisy)])
    assert np.all(dr[~hit] == 0)                  # no return: max_range as before
    assert np.std(dr[hit]) == pytest.approx(s.range_noise, rel=0.25)
    dp = np.array([b.origin - a.origin for a, b in zip(exact, noisy)])
    dh = np.array([b.heading - a.heading for a, b in zip(exact, noisy)])
    assert np.std(dp) == pytest.approx(s.position_noise, rel=0.35)
    assert np.std(dh) == pytest.approx(s.heading_noise, rel=0.35)
    # only the reported pose moves: the angles and the beams' count stay
    assert all(np.array_equal(a.angles, b.angles) for a, b in zip(exact, noisy))
    # pose noise alone leaves the ranges exact
    posed = case.scans(quiet._replace(position_noise=0.01))
    assert all(np.array_equal(a.ranges, b.ranges) for a, b in zip(exact, posed))


# ------------------------------------------------------------------------ the grid
def test_grid_matches_grid_points_and_truth_is_exact(cases):
    case = cases[2]
    points, truth, shape = case.grid()
    lo, hi = case.scene.bounds
    ref, ref_shape = grid_points(lo, hi, 0.1)
    assert shape == ref_shape
    np.testing.assert_array_equal(points, ref)
    np.testing.assert_array_equal(truth, case.scene.occupancy(points))
    # known cells: the outer walls are occupied, the path's start is free
    t = case.scene.wall_thickness
    (x0, y0), (x1, y1) = case.scene.interior_bounds
    wall = np.array([[x0 - t / 2, 0.0], [x1 + t / 2, 0.0], [0.0, y1 + t / 2]])
    assert case.scene.occupancy(wall).all()
    assert not case.scene.occupancy(case.scene.path[:1]).any()
    coarse, coarse_truth, coarse_shape = case.grid(0.5)
    assert coarse_shape == grid_points(lo, hi, 0.5)[1] and len(coarse_truth) == len(coarse)


def test_pillar_cells_are_occupied(cases):
    case = cases[2]                                # a hall
    pillar = case.scene.solids[case.scene.labels.index("pillar_0")]
    assert case.scene.occupancy([pillar.center])[0]


def test_large_office():
    case = scene_family_2d(0, "office", size=(60, 40))
    assert case.size == (60.0, 40.0)
    assert 1200 <= case.n_observations <= 7000


# ---------------------------------------------------------------------- bad input
@pytest.mark.parametrize("kwargs, error, name", [
    (dict(seed=1.5), TypeError, "seed"),
    (dict(seed=True), TypeError, "seed"),
    (dict(seed=-1), ValueError, "seed"),
    (dict(seed=0, kind=3), TypeError, "kind"),
    (dict(seed=0, kind="garage"), ValueError, "kind"),
    (dict(seed=0, size=50), TypeError, "size"),
    (dict(seed=0, size=(5, 20)), ValueError, "size width"),
    (dict(seed=0, kind="office", size=(20, 11)), ValueError, "size height"),
    (dict(seed=0, size=("a", 20)), TypeError, "size width"),
])
def test_bad_family_arguments(kwargs, error, name):
    with pytest.raises(error, match=name):
        scene_family_2d(**kwargs)


def test_bad_case_arguments(cases):
    case = cases[3]
    with pytest.raises(TypeError, match="sensor"):
        case.scans(sensor=(17, np.pi, 8.0, 0.0, 0.0, 0.0, 5))
    with pytest.raises(ValueError, match="sensor.range_noise"):
        case.scans(case.sensor._replace(range_noise=-0.1))
    with pytest.raises(ValueError, match="sensor.n_poses"):
        case.scans(case.sensor._replace(n_poses=0))
    with pytest.raises(ValueError, match="resolution"):
        case.grid(0.0)
    with pytest.raises(ValueError, match="resolution"):
        case.grid(1e-4)
    with pytest.raises(TypeError, match="n_poses"):
        case.poses(2.0)


# ------------------------------------------------------------------------ protocol
@pytest.fixture(scope="module")
def records():
    return evaluate_scene_set({"grid 0.2": lambda: OccupancyGrid(0.2),
                               "grid 0.5": lambda: OccupancyGrid(0.5)}, [2, 3])


def test_protocol_records(records, cases):
    assert [(r["method"], r["seed"]) for r in records] == [
        ("grid 0.2", 2), ("grid 0.5", 2), ("grid 0.2", 3), ("grid 0.5", 3)]
    for r in records:
        case = cases[r["seed"]]
        assert r["kind"] == case.kind
        assert r["n_observations"] == case.n_observations
        assert r["n_cells"] == int(case.view().sum())
        assert 0.5 < r["auc"] <= 1.0
        assert 0.0 <= r["fpr"] <= 1.0
        assert r["fit_seconds"] >= 0 and r["predict_seconds"] >= 0
        assert r["seconds"] == pytest.approx(r["fit_seconds"] + r["predict_seconds"])
        assert r["peak_memory_mb"] >= 0 or np.isnan(r["peak_memory_mb"])


def test_protocol_scores_against_exact_truth(records, cases):
    case = cases[2]
    points, truth, _ = case.grid()
    grid = OccupancyGrid(0.2).fit(*observations_from_scans(case.scans()))
    prob = grid.predict_proba(points)
    from occgp.metrics import roc_auc
    seen = case.view()
    assert records[0]["auc"] == roc_auc(truth[seen], prob[seen])
    assert records[0]["fpr"] == fpr_at_tpr(truth[seen], prob[seen])
    assert records[0]["auc_grid"] == roc_auc(truth, prob)
    assert records[0]["fpr_grid"] == fpr_at_tpr(truth, prob)


@pytest.mark.parametrize("seed", [1, 3, 5])
def test_view_holds_the_hits_and_the_beams(seed):
    """Every cell a beam crossed, and every hit's cell, is in view; no cell out of range is."""
    case = scene_family_2d(seed)
    points, truth, shape = case.grid()
    seen = case.view()
    assert seen.shape == truth.shape and seen.dtype == bool
    assert np.array_equal(seen, case.view())
    lo = np.asarray(case.scene.bounds[0])
    exact = case.scans(case.sensor._replace(range_noise=0.0, position_noise=0.0,
                                            heading_noise=0.0))
    hits, starts, ends = observations_from_scans(exact)
    # points along the beams (short of their ends by a margin past rounding) and the hits
    u = np.linspace(0.0, 1.0, 50)[:, None, None]
    along = (starts + u * (ends - starts) * 0.999).reshape(-1, 2)
    for p in (along, hits):
        ij = np.floor((p - lo) / 0.1).astype(int)
        ok = (ij >= 0).all(axis=1) & (ij < shape).all(axis=1)
        assert seen[ij[ok, 0] * shape[1] + ij[ok, 1]].all()
    origins, _ = case.poses()
    far = np.min(np.linalg.norm(points[:, None] - origins[None], axis=2), axis=1) \
        > case.sensor.max_range + 0.2
    assert not (seen & far).any()
    assert 0.0 < truth[seen].mean() < truth.mean() + 1e-12


def test_protocol_region_grid_scores_every_cell(cases):
    records = evaluate_scene_set({"grid": lambda: OccupancyGrid(0.2)}, [2], region="grid")
    assert records[0]["n_cells"] == len(cases[2].grid()[0])
    assert records[0]["auc"] == records[0]["auc_grid"]
    with pytest.raises(ValueError, match="region"):
        evaluate_scene_set({"grid": lambda: OccupancyGrid(0.2)}, [2], region="seen")


def test_summary_and_table(records):
    summary = summarize_scene_set(records)
    assert [s["method"] for s in summary] == ["grid 0.2", "grid 0.5"]
    for s in summary:
        aucs = [r["auc"] for r in records if r["method"] == s["method"]]
        assert s["n_scenes"] == 2 and s["kind"] == "all"
        assert s["auc_mean"] == pytest.approx(np.mean(aucs))
        assert s["auc_std"] == pytest.approx(np.std(aucs))
        assert s["auc_worst"] == min(aucs)
    by_kind = summarize_scene_set(records, by_kind=True)
    assert {(s["method"], s["kind"]) for s in by_kind} == {
        (m, k) for m in ("grid 0.2", "grid 0.5") for k in ("hall", "cluttered")}
    text = format_scene_set(records, by_kind=True)
    assert "grid 0.2" in text and "cluttered" in text
    assert len(text.splitlines()) == 2 + 4


class _Unknown:
    """A map that knows nothing: every probability NaN."""

    def fit(self, hits, starts, ends):
        return self

    def predict_proba(self, X):
        return np.full(len(X), np.nan)


class _Broken(_Unknown):
    def fit(self, hits, starts, ends):
        raise RuntimeError("fit failed on purpose")


class _WithVariance(_Unknown):
    calls = []

    def predict(self, X, return_var=False):
        self.calls.append(return_var)
        return np.zeros(len(X)), np.ones(len(X))


def test_unknown_counts_one_half():
    r, = evaluate_scene_set({"unknown": _Unknown}, [3])
    assert r["auc"] == 0.5 and r["fpr"] == 1.0


def test_fit_errors_propagate():
    with pytest.raises(RuntimeError, match="on purpose"):
        evaluate_scene_set({"broken": _Broken}, [3])


def test_variance_is_timed_when_asked():
    _WithVariance.calls.clear()
    evaluate_scene_set({"v": _WithVariance}, [3])
    assert _WithVariance.calls == [True]
    _WithVariance.calls.clear()
    evaluate_scene_set({"v": _WithVariance}, [3], with_variance=False)
    assert _WithVariance.calls == []


def test_fpr_at_tpr_matches_the_curve():
    rng = np.random.default_rng(0)
    truth = rng.random(500) < 0.3
    prob = np.clip(truth * 0.3 + rng.random(500) * 0.7, 0, 1)
    fpr, tpr, _ = roc_curve(truth, prob, drop_intermediate=False)
    assert fpr_at_tpr(truth, prob, 0.9) == fpr[np.searchsorted(tpr, 0.9)]
    assert fpr_at_tpr(truth, prob, 1.0) == fpr[np.argmax(tpr >= 1.0)]


@pytest.mark.slow
def test_peak_rss_sees_an_allocation():
    with PeakRSS() as memory:
        block = np.ones(30_000_000)              # 229 MB
        block[::512] = 2.0
    if not np.isnan(memory.peak):
        assert memory.peak > 100


@pytest.mark.parametrize("call, error, name", [
    (lambda: evaluate_scene_set([], [0]), TypeError, "methods"),
    (lambda: evaluate_scene_set({}, [0]), TypeError, "methods"),
    (lambda: evaluate_scene_set({"m": 3}, [0]), TypeError, "methods"),
    (lambda: evaluate_scene_set({"m": lambda: 3}, [0]), TypeError, "methods"),
    (lambda: evaluate_scene_set({"m": _Unknown}, []), ValueError, "seeds"),
    (lambda: evaluate_scene_set({"m": _Unknown}, 3), TypeError, "seeds"),
    (lambda: evaluate_scene_set({"m": _Unknown}, [-1]), ValueError, "seed"),
    (lambda: evaluate_scene_set({"m": _Unknown}, [0], with_variance=1), TypeError,
     "with_variance"),
    (lambda: evaluate_scene_set({"m": _Unknown}, [0], tpr=1.5), ValueError, "tpr"),
    (lambda: evaluate_scene_set({"m": _Unknown}, [0], resolution=-1), ValueError,
     "resolution"),
    (lambda: summarize_scene_set([{"method": "m"}]), ValueError, "records"),
    (lambda: summarize_scene_set("abc"), TypeError, "records"),
    (lambda: summarize_scene_set([3]), TypeError, "records"),
    (lambda: PeakRSS(0), ValueError, "interval"),
])
def test_bad_protocol_arguments(call, error, name):
    with pytest.raises(error, match=name):
        call()
