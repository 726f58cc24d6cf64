"""grid_search: replayed parameter grids scored by the TPR–FDR AUC."""

import warnings

import joblib
import numpy as np
import pytest

from occgp import KNNMap, OccupancyOctree
from occgp.evaluation import (
    KNN_GRID, OCTOMAP_GRID, THRESHOLDS, cell_labels, grid_search, matched_counts,
)
from occgp.knn import ScanReplay
from occgp.metrics import tpr_fdr_auc
from _helpers import noisy_scans


class Wall:
    """Solid for x >= 1.95: the wall of `noisy_scans`, give or take its noise."""

    def occupancy(self, points):
        return np.asarray(points)[:, 0] >= 1.95


@pytest.fixture(scope="module")
def replay():
    scans = noisy_scans(np.random.default_rng(21), n_scans=4, n_wall=120)
    return scans, ScanReplay(scans, 0.2, max_range=3.0, ks=(1, 3))


def curve_of(m, centers, labels, thresholds):
    """TPR and FDR of a built map at each threshold, from its own is_occupied."""
    tpr, fdr = [], []
    for t in thresholds:
        occ = type(m).from_bytes(m.to_bytes(), **{**m._sensor_params(),
                                                   "occupancy_threshold": t}
                                 ).is_occupied(centers)
        if occ.any():
            tpr.append((occ & labels).sum() / labels.sum())
            fdr.append((occ & ~labels).sum() / occ.sum())
    return tpr, fdr


def test_scores_are_those_of_the_built_maps(replay):
    scans, rep = replay
    labels = cell_labels(Wall(), rep.centers, 0.2)
    grid = {"k": [3], "p_u": [0.9, 0.7], "p_l": [0.3], "p_m": [0.2], "p_m_out": [0.4],
            "p_min": [0.05], "p_max": [0.95]}
    res = grid_search(rep, labels, grid)
    assert len(res.results) == 2 and res.n_rejected == 0
    for row in res.results:
        m = KNNMap(0.2, max_range=3.0, **{k: row[k] for k in grid})
        for points, origin in scans:
            m.insert_scan(points, origin)
        ts = [t for t in sorted(THRESHOLDS, reverse=True) if 0.05 <= t <= 0.95]
        tpr, fdr = curve_of(m, rep.centers, labels, ts)
        assert row["tpr"] == pytest.approx(tpr) and row["fdr"] == pytest.approx(fdr)
        x, y = np.r_[0, fdr, 1], np.r_[0, tpr, 1]
        assert row["auc"] == pytest.approx(np.trapezoid(y, x))
    assert res.best_score == max(r["auc"] for r in res.results)
    # every threshold: the metric of occgp.metrics on the map's probabilities
    full = grid_search(rep, labels, grid, thresholds=None)
    probs = 1 / (1 + np.exp(-rep.knn_log_odds([full.best_params])[0].astype(float)))
    assert full.best_score == pytest.approx(tpr_fdr_auc(labels, probs))


def test_octomap_search_matches_liboctomap(replay):
    scans, rep = replay
    labels = cell_labels(Wall(), rep.centers, 0.2)
    res = grid_search(rep, labels, {"prob_hit": [0.74], "prob_miss": [0.26],
                                    "clamping_min": [0.02], "clamping_max": [0.98]},
                      method="octomap")
    m = OccupancyOctree(0.2, prob_hit=0.74, prob_miss=0.26, clamping_min=0.02,
                        clamping_max=0.98)
    for points, origin in scans:
        m.insert_scan(points, origin, max_range=3.0, method="plain")
    tpr, fdr = curve_of(m, rep.centers, labels, sorted(THRESHOLDS, reverse=True))
    assert res.results[0]["tpr"] == pytest.approx(tpr)
    assert res.results[0]["fdr"] == pytest.approx(fdr)


def test_the_papers_grids_have_the_papers_counts(replay):
    _, rep = replay
    labels = cell_labels(Wall(), rep.centers, 0.2)
    knn = grid_search(rep, labels, KNN_GRID)
    assert len(knn.results) == 450 and knn.n_rejected == 4 * 4 * 81 - 450
    octo = grid_search(rep, labels, OCTOMAP_GRID, method="octomap")
    assert len(octo.results) == 20
    # 9 thresholds each (the map-wide ones defined): 4,050 and 180 operating points
    assert len(THRESHOLDS) == 9
    assert len(knn.operating_points()) <= 4050 and len(octo.operating_points()) <= 180
    assert sum(sum(r["p_min"] <= t <= r["p_max"] for t in THRESHOLDS)
               for r in knn.results) == 4050
    best = knn.results[knn.best_index]
    assert knn.best_params == {k: best[k] for k in KNN_GRID}


@pytest.mark.slow
def test_parallel_and_dask_give_the_same_table(replay):
    _, rep = replay
    labels = cell_labels(Wall(), rep.centers, 0.2)
    grid = {"p_u": [0.98, 0.74], "p_l": [0.26, 0.5], "p_m": [0.14, 0.26]}
    ref = grid_search(rep, labels, grid)
    two = grid_search(rep, labels, grid, n_jobs=2)
    assert two.results == ref.results
    distributed = pytest.importorskip("distributed", reason="the dask extra is not installed")
    with distributed.LocalCluster(processes=False, n_workers=2, threads_per_worker=1,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster), joblib.parallel_config(backend="dask"):
        out = grid_search(rep, labels, grid, n_jobs=2)
    assert out.results == ref.results


def test_scans_are_replayed_on_the_fly(replay):
    scans, rep = replay
    labels = cell_labels(Wall(), rep.centers, 0.2)
    grid = {"k": [1, 3], "p_u": [0.9]}
    a = grid_search(scans, Wall(), grid, resolution=0.2, max_range=3.0)
    b = grid_search(rep, labels, grid)
    assert [r["auc"] for r in a.results] == [r["auc"] for r in b.results]


def test_the_search_uses_no_deprecated_name(replay):
    scans, rep = replay
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        grid_search(scans, Wall(), {"p_u": [0.9]}, resolution=0.2, max_range=3.0)
        grid_search(rep, Wall(), {"p_u": [0.9]})
        with pytest.raises(ValueError, match="truth must have shape"):
            grid_search(rep, [True], {"p_u": [0.9]})


def test_cell_labels_mark_cells_a_surface_crosses():
    centers = np.array([[1.9, 0, 0], [2.1, 0, 0], [1.7, 0, 0]])
    # the wall starts at 1.95: the cell [1.8, 2.0) holds it, its center does not
    assert cell_labels(Wall(), centers, 0.2).tolist() == [True, True, False]
    assert cell_labels(Wall(), centers, 0.2, samples=1).tolist() == [False, True, False]
    # a surface on a cell border: both cells beside it
    from occgp.datasets import tetromino_scene
    scene = tetromino_scene("I")
    z = np.array([[10.05, 10.05, -0.05], [10.05, 10.05, 0.05], [10.05, 10.05, 0.15]])
    assert cell_labels(scene, z, 0.1).tolist() == [True, True, False]


@pytest.mark.parametrize("kwargs, exc, match", [
    (dict(param_grid={"q": [1]}), ValueError, "unknown parameters"),
    (dict(param_grid={"p_u": []}), ValueError, "empty"),
    (dict(param_grid=[]), ValueError, "param_grid"),
    (dict(param_grid={"p_u": [0.1], "p_l": [0.5]}), ValueError, "no combination"),
    (dict(method="gp"), ValueError, "method"),
    (dict(thresholds=[]), ValueError, "thresholds"),
    (dict(thresholds=[1.5]), ValueError, "thresholds"),
    (dict(batch_size=0), ValueError, "batch_size"),
    (dict(truth=np.zeros(3, bool)), ValueError, "shape"),
    (dict(truth="wall"), TypeError, "truth"),
    (dict(n_jobs=0), ValueError, "n_jobs"),
])
def test_bad_input(replay, kwargs, exc, match):
    _, rep = replay
    args = dict(truth=cell_labels(Wall(), rep.centers, 0.2), param_grid={"p_u": [0.9]})
    args.update(kwargs)
    with pytest.raises(exc, match=match):
        grid_search(rep, args.pop("truth"), args.pop("param_grid"), **args)


def test_no_occupied_cell(replay):
    _, rep = replay
    with pytest.raises(ValueError, match="no occupied cell"):
        grid_search(rep, np.zeros(rep.num_cells, bool), {"p_u": [0.9]})


# ------------------------------------------------------------ scoring options
GRID2 = {"k": [3], "p_u": [0.9, 0.7], "p_l": [0.3], "p_m": [0.2], "p_m_out": [0.4],
         "p_min": [0.05], "p_max": [0.95]}


def test_the_strict_protocol_is_the_default(replay):
    _, rep = replay
    labels = cell_labels(Wall(), rep.centers, 0.2)
    res = grid_search(rep, labels, GRID2)
    assert res.scoring == "exact" and not res.masked
    assert all("auc_exact" not in r for r in res.results)
    full = grid_search(rep, labels, GRID2, mask=np.ones(rep.num_cells, bool))
    assert full.masked
    for a, b in zip(res.results, full.results):
        assert b["auc"] == b["auc_exact"] == a["auc"] and b["tpr"] == a["tpr"]


def test_mask_scores_only_its_cells(replay):
    _, rep = replay
    labels = cell_labels(Wall(), rep.centers, 0.2)
    mask = rep.centers[:, 1] > 0
    res = grid_search(rep, labels, GRID2, mask=mask)
    plain = grid_search(rep, labels, GRID2)
    values = rep.knn_log_odds([{k: r[k] for k in GRID2} for r in res.results])
    ts = [t for t in sorted(THRESHOLDS, reverse=True) if 0.05 <= t <= 0.95]
    for row, v, strict in zip(res.results, values, plain.results):
        tpr, fdr = [], []
        for t in ts:
            occ = (v >= np.float32(np.log(t / (1 - t)))) & mask
            if occ.any():
                tpr.append((occ & labels).sum() / (labels & mask).sum())
                fdr.append((occ & ~labels).sum() / occ.sum())
        assert row["tpr"] == pytest.approx(tpr) and row["fdr"] == pytest.approx(fdr)
        assert row["auc"] == pytest.approx(np.trapezoid(np.r_[0, tpr, 1], np.r_[0, fdr, 1]))
        assert row["auc_exact"] == strict["auc"]
    # every threshold: the metric on the masked cells
    full = grid_search(rep, labels, GRID2, mask=mask, thresholds=None)
    probs = 1 / (1 + np.exp(-values.astype(float)))
    assert [r["auc"] for r in full.results] == pytest.approx(
        [tpr_fdr_auc(labels[mask], p[mask]) for p in probs])


def test_authors_scoring_is_matched_counts_and_the_unanchored_area(replay):
    _, rep = replay
    labels = cell_labels(Wall(), rep.centers, 0.2)
    mask = rep.centers[:, 2] < 0.5
    res = grid_search(rep, labels, GRID2, mask=mask, scoring="authors")
    assert res.scoring == "authors" and res.masked
    strict = grid_search(rep, labels, GRID2)
    values = rep.knn_log_odds([{k: r[k] for k in GRID2} for r in res.results])
    ts = [t for t in sorted(THRESHOLDS, reverse=True) if 0.05 <= t <= 0.95]
    for row, v, s in zip(res.results, values, strict.results):
        tpr, fdr = [], []
        for t in ts:
            occ = v >= np.float32(np.log(t / (1 - t)))
            if (occ & mask).any():
                c = matched_counts(rep.keys[occ], rep.keys[labels], rep.keys[mask])
                tpr.append(c.tpr)
                fdr.append(c.fdr)
        assert row["tpr"] == pytest.approx(tpr) and row["fdr"] == pytest.approx(fdr)
        assert row["auc"] == pytest.approx(np.trapezoid(tpr, fdr))
        assert row["auc_exact"] == s["auc"]
    # the ±1 rule only adds true positives
    nomask = grid_search(rep, labels, GRID2, scoring="authors")
    for a, s in zip(nomask.results, strict.results):
        assert all(x >= y - 1e-12 for x, y in zip(a["tpr"], s["tpr"]))
        assert all(x <= y + 1e-12 for x, y in zip(a["fdr"], s["fdr"]))


def test_authors_scoring_on_a_hand_built_replay():
    # one scan, three points in a row along y at x = 2: three end cells, rays before them
    pts = np.array([[2.05, 0.05, 0.05], [2.05, 0.35, 0.05], [2.05, 0.65, 0.05]])
    rep = ScanReplay([(pts, [0.05, 0.05, 0.05])], 0.1, max_range=3.0)
    ends = np.isclose(rep.centers[:, 0], 2.05)
    assert ends.sum() == 3
    # the truth: the ray cell just before each end cell (x = 1.95), one cell off
    behind = np.isclose(rep.centers[:, 0], 1.95) & np.isin(
        np.round(rep.centers[:, 1], 2), [0.05, 0.35, 0.65])
    assert behind.sum() == 3
    grid = {"k": [1], "p_u": [0.9], "p_l": [0.9], "p_m": [0.2], "p_m_out": [0.2]}
    strict = grid_search(rep, behind, grid, thresholds=[0.5])
    authors = grid_search(rep, behind, grid, thresholds=[0.5], scoring="authors")
    # at occupancy_threshold = 0.5 the three end cells are occupied, everything else free: strictly
    # 3 FP, 3 FN; by the authors' rule each end cell matches the occupied cell next to
    # it (3 TP, no FP), while the three occupied cells predicted free stay FN
    assert strict.results[0]["tpr"] == (0.0,) and strict.results[0]["fdr"] == (1.0,)
    assert authors.results[0]["tpr"] == (0.5,) and authors.results[0]["fdr"] == (0.0,)
    assert authors.results[0]["auc"] == 0.0          # one point: no area
    assert authors.results[0]["auc_exact"] == strict.results[0]["auc"] == 0.0


def test_truncated_cdf_and_dataset_statistics(replay):
    scans, rep = replay
    labels = cell_labels(Wall(), rep.centers, 0.2)
    for cdf, stats in (("truncated", "online"), ("normal", "dataset"),
                       ("truncated", "dataset")):
        res = grid_search(scans, labels, GRID2, resolution=0.2, max_range=3.0, cdf=cdf,
                          stats=stats)
        other = ScanReplay(scans, 0.2, max_range=3.0, ks=(3,), cdf=cdf, stats=stats)
        assert res.results == grid_search(other, labels, GRID2, cdf=cdf, stats=stats).results
        values = other.knn_log_odds([{k: r[k] for k in GRID2} for r in res.results])
        assert not np.array_equal(values, rep.knn_log_odds(
            [{k: r[k] for k in GRID2} for r in res.results]))
    # the maps: those KNNMap builds with the same cdf and fixed statistics
    other = ScanReplay(scans, 0.2, max_range=3.0, ks=(3,), cdf="truncated", stats="dataset")
    params = {k: v[0] for k, v in GRID2.items()}
    m = KNNMap(0.2, max_range=3.0, cdf="truncated", score_stats=other.score_stats(3),
               **params)
    for points, origin in scans:
        m.insert_scan(points, origin)
    got = m.occupancy(other.centers)
    want = 1 / (1 + np.exp(-other.knn_log_odds([params])[0].astype(float)))
    np.testing.assert_allclose(got, want, rtol=1e-6)


@pytest.mark.parametrize("kwargs, exc, match", [
    (dict(scoring="loose"), ValueError, "scoring must be one of"),
    (dict(mask=np.ones(3, bool)), ValueError, r"mask must have shape"),
    (dict(mask="all"), TypeError, "mask must be booleans"),
    (dict(scoring="authors", thresholds=None), ValueError, "thresholds=None"),
    (dict(cdf="kde"), ValueError, "cdf must be one of"),
    (dict(stats="global"), ValueError, "stats must be one of"),
    (dict(cdf="truncated"), ValueError, "cdf='truncated' differs from the ScanReplay's"),
    (dict(stats="dataset"), ValueError, "stats='dataset' differs from the ScanReplay's"),
])
def test_bad_scoring_options(replay, kwargs, exc, match):
    _, rep = replay
    with pytest.raises(exc, match=match):
        grid_search(rep, cell_labels(Wall(), rep.centers, 0.2), {"p_u": [0.9]}, **kwargs)


def test_mask_without_an_occupied_cell(replay):
    _, rep = replay
    labels = cell_labels(Wall(), rep.centers, 0.2)
    with pytest.raises(ValueError, match="mask holds no occupied cell"):
        grid_search(rep, labels, {"p_u": [0.9]}, mask=~labels)
