"""grid_search: replayed parameter grids scored by the TPR–FDR AUC."""

import warnings

import joblib
import numpy as np
import pytest

from occgp import KNNMap, OccupancyOctree
from occgp.evaluation import (
    KNN_GRID, OCTOMAP_GRID, THRESHOLDS, cell_labels, grid_search,
)
from occgp.knn import ScanReplay
from occgp.metrics import tpr_fdr_auc
from test_knn import noisy_scans


class Wall:
    """Solid for x >= 1.95: the wall of `noisy_scans`, give or take its noise."""

    def occupancy(self, points):
        return np.asarray(points)[:, 0] >= 1.95


@pytest.fixture(scope="module")
def replay():
    scans = noisy_scans(np.random.default_rng(21), n_scans=4, n_wall=120)
    return scans, ScanReplay(scans, 0.2, sensor_range=3.0, ks=(1, 3))


def curve_of(m, centres, labels, thresholds):
    """TPR and FDR of a built map at each threshold, from its own is_occupied."""
    tpr, fdr = [], []
    for t in thresholds:
        occ = type(m).from_bytes(m.to_bytes(), **{**m._sensor_params(),
                                                   **({"p_t": t} if isinstance(m, KNNMap)
                                                      else {"occupancy_threshold": t})}
                                 ).is_occupied(centres)
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
        m = KNNMap(0.2, sensor_range=3.0, **{k: row[k] for k in grid})
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
    a = grid_search(scans, Wall(), grid, resolution=0.2, sensor_range=3.0)
    b = grid_search(rep, labels, grid)
    assert [r["auc"] for r in a.results] == [r["auc"] for r in b.results]


def test_the_search_uses_no_deprecated_name(replay):
    scans, rep = replay
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        grid_search(scans, Wall(), {"p_u": [0.9]}, resolution=0.2, sensor_range=3.0)
        grid_search(rep, Wall(), {"p_u": [0.9]})
        with pytest.raises(ValueError, match="truth must have shape"):
            grid_search(rep, [True], {"p_u": [0.9]})


def test_cell_labels_mark_cells_a_surface_crosses():
    centres = np.array([[1.9, 0, 0], [2.1, 0, 0], [1.7, 0, 0]])
    # the wall starts at 1.95: the cell [1.8, 2.0) holds it, its centre does not
    assert cell_labels(Wall(), centres, 0.2).tolist() == [True, True, False]
    assert cell_labels(Wall(), centres, 0.2, samples=1).tolist() == [False, True, False]
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
