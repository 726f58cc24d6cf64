"""Metrics of LiDAR super-resolution: range MAE and voxel IoU / precision / recall / F1."""

import itertools

import numpy as np
import pytest
from numpy.testing import assert_allclose

from occgp.iln.metrics import VOXEL_INDEX_LIMIT, range_mae, voxel_keys, voxel_scores


def _direct_mae(pred, truth):
    errs = [abs(p - t) for p, t in zip(np.ravel(pred), np.ravel(truth)) if t > 0]
    return sum(errs) / len(errs)


def _direct_voxels(points, size):
    return {tuple(int(np.floor(c / size)) for c in p) for p in points}


def _direct_scores(pred, truth, size):
    P, T = _direct_voxels(pred, size), _direct_voxels(truth, size)
    inter = len(P & T)
    precision = inter / len(P) if P else 0.0
    recall = inter / len(T)
    f1 = 2 * precision * recall / (precision + recall) if inter else 0.0
    return {"iou": inter / len(P | T), "precision": precision, "recall": recall, "f1": f1}


def test_mae_matches_direct_computation():
    rng = np.random.default_rng(0)
    truth = rng.uniform(1, 80, (2, 4, 16))
    truth[rng.random(truth.shape) < 0.3] = 0.0
    pred = truth + rng.normal(0, 1, truth.shape)
    pred = np.clip(pred, 0, None)
    pred[rng.random(truth.shape) < 0.1] = 0.0
    assert_allclose(range_mae(pred, truth), _direct_mae(pred, truth), rtol=1e-12)


def test_mae_counts_a_dropped_return_by_its_true_range_and_ignores_false_returns():
    truth = np.array([[10.0, 4.0, 0.0]])
    assert range_mae([[10.0, 0.0, 7.0]], truth) == 2.0        # (0 + 4) / 2
    assert range_mae(truth, truth) == 0.0
    assert range_mae(np.float32(truth), truth) == 0.0


@pytest.mark.parametrize("pred, truth, match", [
    (np.ones((2, 3)), np.ones((3, 2)), r"same shape, got \(2, 3\) and \(3, 2\)"),
    (np.ones((2, 3)), np.zeros((2, 3)), "truth holds no return"),
    (np.full((2, 2), np.nan), np.ones((2, 2)), "pred must be finite"),
    (np.ones((2, 2)), np.full((2, 2), np.inf), "truth must be finite"),
    (-np.ones((2, 2)), np.ones((2, 2)), r"pred must hold ranges >= 0"),
    (np.ones((0, 4)), np.ones((0, 4)), r"pred must be a non-empty range image"),
    (np.float64(1.0), np.float64(1.0), r"non-empty range image, got shape \(\)"),
])
def test_mae_rejects_bad_input(pred, truth, match):
    with pytest.raises(ValueError, match=match):
        range_mae(pred, truth)


def test_mae_rejects_non_numeric():
    with pytest.raises(TypeError, match="pred must hold real numbers"):
        range_mae(np.array([["a"]]), np.ones((1, 1)))


@pytest.mark.parametrize("size", [0.1, 0.25, 1.0])
def test_voxel_scores_match_direct_computation(size):
    rng = np.random.default_rng(0)
    truth = rng.uniform(-3, 3, (300, 3))
    pred = np.vstack([truth[:200] + rng.normal(0, 0.08, (200, 3)),
                      rng.uniform(-3, 3, (50, 3))])
    got = voxel_scores(pred, truth, size)
    want = _direct_scores(pred, truth, size)
    for key in want:
        assert_allclose(got[key], want[key], rtol=1e-12, err_msg=key)
    assert 0 < got["iou"] < got["f1"] < 1


def test_voxel_scores_exact_small_case():
    # voxels: pred {(0,0,0), (10,0,0), (-1,-1,-1)}, truth {(0,0,0), (-1,-1,-1), (0,0,5)}
    pred = [[0.05, 0.05, 0.05], [0.01, 0.09, 0.0], [1.05, 0.0, 0.0], [-0.01, -0.01, -0.01]]
    truth = [[0.02, 0.02, 0.02], [-0.05, -0.05, -0.05], [0.0, 0.0, 0.55]]
    s = voxel_scores(pred, truth)
    assert s == {"iou": 2 / 4, "precision": 2 / 3, "recall": 2 / 3, "f1": 2 / 3}


def test_voxel_scores_identical_disjoint_and_empty_prediction():
    truth = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])
    assert voxel_scores(truth, truth) == {"iou": 1.0, "precision": 1.0, "recall": 1.0,
                                          "f1": 1.0}
    assert voxel_scores(truth + 10, truth) == {"iou": 0.0, "precision": 0.0, "recall": 0.0,
                                               "f1": 0.0}
    assert voxel_scores(np.empty((0, 3)), truth) == {"iou": 0.0, "precision": 0.0,
                                                     "recall": 0.0, "f1": 0.0}


def test_voxel_keys_are_unique_and_distinguish_neighbours():
    offsets = np.array(list(itertools.product([-1, 0, 1], repeat=3)), dtype=float)
    keys = voxel_keys(offsets * 0.1 + 0.05)
    assert keys.size == 27 and np.all(np.diff(keys) > 0)
    edge = (VOXEL_INDEX_LIMIT - 1) * 0.1
    far = voxel_keys([[edge, -edge, edge], [-edge, edge, -edge]])
    assert far.size == 2


@pytest.mark.parametrize("pred, truth, size, match", [
    (np.zeros((2, 3)), np.zeros((0, 3)), 0.1, "true_points must hold at least one point"),
    (np.zeros((2, 2)), np.zeros((2, 3)), 0.1, r"pred_points must have shape \(n_points, 3\)"),
    (np.zeros((2, 3)), np.zeros(3), 0.1, r"true_points must have shape \(n_points, 3\), got \(3,\)"),
    (np.array([[np.nan, 0, 0]]), np.zeros((1, 3)), 0.1, "pred_points must be finite"),
    (np.array([[1e30, 0, 0]]), np.zeros((1, 3)), 0.1, "pred_points must lie within 1048576 voxels"),
    (np.zeros((1, 3)), np.array([[0, 0, 2e5]]), 0.1, "true_points must lie within"),
    (np.ones((1, 3)), np.ones((1, 3)), 1e-20, "true_points must lie within"),
    (np.zeros((1, 3)), np.zeros((1, 3)), 0.0, r"voxel_size must lie in \(0.0, inf\)"),
    (np.zeros((1, 3)), np.zeros((1, 3)), np.inf, r"voxel_size must lie in"),
    (np.zeros((1, 3)), np.zeros((1, 3)), np.nan, r"voxel_size must lie in"),
])
def test_voxel_scores_reject_bad_input(pred, truth, size, match):
    with pytest.raises(ValueError, match=match):
        voxel_scores(pred, truth, size)


def test_voxel_scores_reject_bad_types():
    with pytest.raises(TypeError, match="voxel_size must be a real number, got str"):
        voxel_scores(np.zeros((1, 3)), np.zeros((1, 3)), "0.1")
    with pytest.raises(TypeError, match="pred_points must hold real numbers"):
        voxel_scores(np.array([["a", "b", "c"]]), np.zeros((1, 3)))


# ------------------------------------------------------------------- without torch
@pytest.fixture
def no_torch(monkeypatch):
    """Hide torch (and drop the torch modules of occgp.iln) for one test."""
    import sys
    monkeypatch.setitem(sys.modules, "torch", None)
    for name in list(sys.modules):
        if name.startswith(("torch.", "occgp.iln.models.")) or name in ("occgp.iln.models",
                                                                        "occgp.iln.training"):
            monkeypatch.delitem(sys.modules, name)


def test_metrics_and_tables_work_without_torch(no_torch):
    from occgp.iln.evaluate import format_table
    from occgp.iln.experiment import format_mapping_table
    assert range_mae([[1.0]], [[2.0]]) == 1.0
    row = {"method": "m", "resolution": "64x1024", "mae": 1.0, "iou": 0.5, "precision": 0.5,
           "recall": 0.5, "f1": 0.5}
    assert "Test resolution: 64x1024" in format_table([row])
    row.update(n_points=1, auc=0.5, known=0.5, upsample_seconds=0.0, update_seconds=0.0,
               total_seconds=0.0)
    assert format_mapping_table([row]).startswith("Map from")


@pytest.mark.parametrize("call, name", [
    (lambda: __import__("occgp.iln.upsample", fromlist=["x"]).upsample(np.ones((4, 64))),
     "upsample"),
    (lambda: __import__("occgp.iln.upsample", fromlist=["x"]).resolve_model("bilinear"),
     "resolve_model"),
    (lambda: __import__("occgp.iln.evaluate", fromlist=["x"]).evaluate(
        ["bilinear"], {"4x64": np.ones((1, 4, 64)), "8x64": np.ones((1, 8, 64))},
        in_size="4x64", out_sizes="8x64", progress=False), "evaluate"),
])
def test_model_calls_without_torch_raise_a_clear_import_error(no_torch, call, name):
    with pytest.raises(ImportError, match=rf"occgp.iln.{name} needs PyTorch: pip install "
                                          r"'occgp\[iln\]'"):
        call()
