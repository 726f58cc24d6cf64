"""Up-sampling scans for maps, Table 4.1's evaluation and the mapping experiment (small cases)."""

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

torch = pytest.importorskip("torch")

from occgp.iln._range import LidarModel, range_image_to_points  # noqa: E402
from occgp.iln.evaluate import evaluate, format_table  # noqa: E402
from occgp.iln.metrics import range_mae, voxel_scores  # noqa: E402
from occgp.iln.models import make  # noqa: E402
from occgp.iln.upsample import (MAX_OUTPUT_PIXELS, resolve_model, upsample,  # noqa: E402
                                upsample_range_image)

LOW = LidarModel.carla(4, 64)


def _image(seed=0, shape=(4, 64), holes=0.2):
    rng = np.random.default_rng(seed)
    image = rng.uniform(2.0, 30.0, shape).astype(np.float32)
    image[rng.random(shape) < holes] = 0.0
    return image


def _tiny_iln():
    torch.manual_seed(0)
    return make({"name": "iln", "args": {"channels": 8, "n_resblocks": 1, "depth": 1}})


# ----------------------------------------------------------------------------- upsample
def test_upsample_constant_image_gives_points_at_that_range():
    points, image = upsample(np.full((4, 64), 12.5, np.float32), rows=16, cols=128,
                             return_image=True)
    assert image.shape == (16, 128) and image.dtype == np.float32
    assert points.shape == (16 * 128, 3)
    assert_allclose(np.linalg.norm(points, axis=1), 12.5, rtol=1e-6)
    assert_allclose(points, range_image_to_points(image, LOW.with_size(16, 128)))


def test_bilinear_upsample_at_the_input_size_gives_the_input_points_back():
    image = _image()
    points = upsample(image, rows=4, cols=64, lidar=LOW)
    assert_allclose(points, range_image_to_points(image, LOW), rtol=1e-5, atol=1e-5)


def test_upsample_with_a_model_object():
    points, image = upsample(_image(), rows=8, cols=128, model=_tiny_iln(), return_image=True)
    assert image.shape == (8, 128) and len(points) == np.count_nonzero(image) > 0


def test_upsample_points_and_image_inputs_agree():
    image = _image(1, holes=0.0)
    points = range_image_to_points(image, LOW)
    a = upsample(points, rows=8, cols=128, lidar=LOW)
    b = upsample(image, rows=8, cols=128, lidar=LOW)
    assert_allclose(a, b, rtol=1e-6, atol=1e-6)


def test_upsample_default_lidar_for_points_is_the_16_beam_carla_sensor():
    points = range_image_to_points(np.full((16, 1024), 9.0, np.float32), LidarModel.carla())
    out, image = upsample(points, rows=32, cols=1024, return_image=True)
    assert image.shape == (32, 1024) and len(out) == 32 * 1024


def test_upsample_drops_no_return_pixels():
    image = np.zeros((4, 64), np.float32)
    assert upsample(image, rows=8, cols=64).shape == (0, 3)
    image[:2] = 7.0                                  # the top half only
    points, out = upsample(image, rows=8, cols=64, return_image=True)
    assert 0 < len(points) == np.count_nonzero(out) < 8 * 64
    assert_array_equal(out[-2:], 0.0)               # below the returns: no return


def test_upsample_range_image_cuts_ranges_at_max_range():
    net = make({"name": "liif", "args": {"channels": 8, "n_resblocks": 1, "hidden": [8]}})
    with torch.no_grad():
        for p in net.parameters():
            p.fill_(1.0)                              # huge, positive predictions
    out = upsample_range_image(np.full((4, 64), 70.0, np.float32), rows=8, cols=64,
                               model=net)
    assert out.max() <= LOW.max_range


def test_resolve_model_names_and_models():
    assert resolve_model("bilinear").registry_name == "bilinear"
    assert resolve_model("inverse-bilinear").registry_name == "inverse-bilinear"
    assert resolve_model("edge-aware").registry_name == "edge-aware"
    net = _tiny_iln()
    assert resolve_model(net) is net
    with pytest.raises(ValueError, match=r"model must be one of \('bilinear', 'inverse-bilinear', 'edge-aware', "
                       r"'pretrained'\)"):
        resolve_model("cubic")
    with pytest.raises(TypeError, match="model must be one of .* got int"):
        resolve_model(3)


def test_pretrained_up_samples_with_the_shipped_model_and_says_when_it_is_missing(
        monkeypatch, tmp_path):
    import occgp.iln as iln
    from occgp.iln import _weights
    image = np.full((16, 1024), 10.0, dtype=np.float32)
    got = upsample(image, rows=64, cols=1024, model="pretrained", return_image=True)[1]
    want = upsample(image, rows=64, cols=1024, model=iln.pretrained(), return_image=True)[1]
    np.testing.assert_array_equal(got, want)
    np.testing.assert_allclose(got[got > 0], 10.0, rtol=1e-6)   # convex: a flat wall stays
    monkeypatch.setattr(_weights, "FOLDER", tmp_path)
    with pytest.raises(OSError, match="the shipped weights .*selector.pt are missing"):
        upsample(image, model="pretrained")


@pytest.mark.parametrize("data, kwargs, match", [
    (np.ones((4, 64, 1)), {}, r"points_or_range_image must be points of shape \(n_points, 3\) "
                              r"or a range image"),
    (np.ones((0, 3)), {}, r"non-empty, got shape \(0, 3\)"),
    (np.ones(5), {}, r"got shape \(5,\)"),
    (np.full((4, 64), np.nan), {}, "points_or_range_image must be finite"),
    (-np.ones((4, 64)), {}, r"ranges must lie in \[0, lidar.max_range = 80\] m"),
    (np.full((4, 64), 81.0), {}, r"ranges must lie in \[0, lidar.max_range = 80\] m"),
    (np.ones((4, 64)), {"lidar": LidarModel.carla(8, 64)},
     r"a range image must have lidar's shape \(8, 64\), got \(4, 64\)"),
    (np.array([[np.nan, 0.0, 1.0]]), {}, "points must be finite"),
    (np.array([[1e30, 0.0, 1.0]]), {}, "1e15"),
    (np.ones((4, 64)), {"rows": 0}, "rows must be a positive int, got 0"),
    (np.ones((4, 64)), {"cols": -3}, "cols must be a positive int, got -3"),
    (np.ones((4, 64)), {"rows": 4096, "cols": 4096},
     r"rows \* cols must be at most 4194304 pixels, got 4096 x 4096"),
    (np.ones((4, 64)), {"model": "nearest"}, "model must be one of"),
])
def test_upsample_rejects_bad_input(data, kwargs, match):
    with pytest.raises(ValueError, match=match):
        upsample(data, **kwargs)


@pytest.mark.parametrize("data, kwargs, match", [
    (np.array([["a", "b", "c"]]), {}, "points_or_range_image must hold real numbers"),
    (np.ones((4, 64)), {"rows": 2.5}, "rows must be a positive int, got float"),
    (np.ones((4, 64)), {"lidar": "carla"}, "lidar must be a LidarModel"),
    (np.ones((4, 64)), {"return_image": 1}, "return_image must be a bool"),
    (np.ones((4, 64)), {"model": object()}, "model must be one of"),
])
def test_upsample_rejects_bad_types(data, kwargs, match):
    with pytest.raises(TypeError, match=match):
        upsample(data, **kwargs)


def test_upsample_range_image_rejects_points_and_mismatched_lidar():
    with pytest.raises(ValueError, match=r"range_image must have shape \(rows, cols\)"):
        upsample_range_image(np.ones((2, 2, 2)))
    with pytest.raises(ValueError, match=r"range_image must have lidar's shape \(4, 64\)"):
        upsample_range_image(np.ones((10, 3)), lidar=LOW)
    assert MAX_OUTPUT_PIXELS >= 256 * 4096


# ----------------------------------------------------------------------------- evaluate
def _test_set(n=2):
    low = np.stack([_image(s) for s in range(n)])
    mid = np.stack([upsample_range_image(im, rows=8, cols=64) for im in low])
    high = np.stack([_image(10 + s, (16, 128), holes=0.1) for s in range(n)])
    return {"4x64": low, (8, 64): mid, "r16x128": high}


def test_evaluate_scores_match_direct_computation():
    images = _test_set()
    rows = evaluate({"Bilinear": "bilinear", "ILN": _tiny_iln()}, images, in_size=(4, 64),
                    out_sizes=["8x64", (16, 128)], progress=False)
    assert [(r["resolution"], r["method"]) for r in rows] == [
        ("8x64", "Bilinear"), ("8x64", "ILN"), ("16x128", "Bilinear"), ("16x128", "ILN")]
    exact = rows[0]                  # the 8x64 truth is the bilinear up-sampling itself
    assert exact["mae"] == 0.0 and exact["iou"] == exact["f1"] == 1.0
    hi = LOW.with_size(16, 128)
    scores = []
    for k in range(2):
        pred = upsample_range_image(images["4x64"][k], rows=16, cols=128)
        truth = images["r16x128"][k]
        s = voxel_scores(range_image_to_points(pred, hi), range_image_to_points(truth, hi))
        scores.append([range_mae(pred, truth)] + [s[m] for m in
                                                  ("iou", "precision", "recall", "f1")])
    want = np.mean(scores, axis=0)
    got = [rows[2][m] for m in ("mae", "iou", "precision", "recall", "f1")]
    assert_allclose(got, want, rtol=1e-12)
    assert all(r["n_images"] == 2 and r["seconds_per_image"] >= 0 for r in rows)
    assert all(0 <= r[m] <= 1 for r in rows for m in ("iou", "precision", "recall", "f1"))


def test_evaluate_skips_images_without_returns_in_the_truth():
    images = _test_set()
    images["r16x128"][1] = 0.0
    rows = evaluate(["bilinear"], images, in_size="4x64", out_sizes="16x128", progress=False)
    assert rows[0]["n_images"] == 1


def test_format_table_layout():
    rows = [{"method": m, "resolution": res, "mae": 1.5, "iou": 0.25, "precision": 0.5,
             "recall": 0.375, "f1": 0.4, "seconds_per_image": 0.01}
            for res in ("64x1024", "128x2048") for m in ("Bilinear", "ILN")]
    assert format_table(rows) == "\n".join([
        "Method      MAE    IoU  Precision  Recall     F1",
        "Test resolution: 64x1024",
        "Bilinear  1.500  0.250      0.500   0.375  0.400",
        "ILN       1.500  0.250      0.500   0.375  0.400",
        "Test resolution: 128x2048",
        "Bilinear  1.500  0.250      0.500   0.375  0.400",
        "ILN       1.500  0.250      0.500   0.375  0.400"])
    assert format_table(rows[:1], with_time=True).splitlines()[0].endswith("time [s]")
    with pytest.raises(ValueError, match=r"rows\[0\] lacks \['f1'\]"):
        format_table([{k: v for k, v in rows[0].items() if k != "f1"}])
    with pytest.raises(TypeError, match=r"rows\[0\] must be a dict"):
        format_table([1])


@pytest.mark.parametrize("change, kwargs, match", [
    (lambda d: d.pop("r16x128"), {}, r"test_images lacks size 16x128 \(has 4x64, 8x64\)"),
    (lambda d: d.update({"r16x128": d["r16x128"][:1]}), {},
     "as many images of every size, got 2 and 1"),
    (lambda d: d.update({"r16x128": d["r16x128"][:, :8]}), {},
     r"test_images\[16x128\] must have shape \(n_images, 16, 128\)"),
    (lambda d: d.update({"r16x128": d["r16x128"] * np.nan}), {}, r"test_images\[16x128\] must be finite"),
    (lambda d: d.update({"r16x128": -d["r16x128"]}), {}, r"must hold ranges >= 0"),
    (lambda d: d.update({"r16x128": d["r16x128"] + 100}), {}, "beyond lidar.max_range = 80"),
    (lambda d: d.update({"16by128": 0}), {}, "must be a \\(rows, cols\\) pair or a string"),
    (lambda d: d.update({"16x128": d["r16x128"]}), {}, "holds size 16x128 twice"),
    (lambda d: None, {"models": {}}, "models must name at least one model"),
    (lambda d: None, {"models": ["cubic"]}, "model must be one of"),
    (lambda d: None, {"out_sizes": []}, "out_sizes must hold at least one size"),
    (lambda d: None, {"out_sizes": [(0, 128)]}, r"out_sizes\[0\] must be positive"),
    (lambda d: None, {"out_sizes": ["16x128", (16, 128)]},
     r"out_sizes must not repeat a size, got \['16x128', '16x128'\]"),
    (lambda d: None, {"voxel_size": 0.0}, r"voxel_size must lie in \(0.0, inf\)"),
])
def test_evaluate_rejects_bad_input(change, kwargs, match):
    images = _test_set()
    change(images)
    args = {"models": ["bilinear"], "in_size": "4x64", "out_sizes": ["16x128"], **kwargs}
    with pytest.raises(ValueError, match=match):
        evaluate(args.pop("models"), images, progress=False, **args)


@pytest.mark.parametrize("models, images, kwargs, match", [
    ("bilinear", [1, 2], {}, "test_images must be a dict of size -> images"),
    ([make({"name": "bilinear"})], None, {}, "models given as a list must hold names"),
    (3, None, {}, "models must be a dict name -> model"),
    ({1: "bilinear"}, None, {}, "models keys must be str"),
    (["bilinear"], None, {"lidar": "carla"}, "lidar must be a LidarModel"),
    (["bilinear"], None, {"in_size": 16}, "in_size must be a \\(rows, cols\\) pair"),
    (["bilinear"], None, {"in_size": (4.0, 64)}, "in_size must hold two ints"),
    (["bilinear"], None, {"out_sizes": 5}, "out_sizes must be a sequence of sizes"),
])
def test_evaluate_rejects_bad_types(models, images, kwargs, match):
    images = _test_set() if images is None else images
    args = {"in_size": "4x64", "out_sizes": ["16x128"], **kwargs}
    with pytest.raises(TypeError, match=match):
        evaluate(models, images, progress=False, **args)


# ----------------------------------------------------------------------------- mapping
SMALL = dict(n_scans=2, in_size="8x256", sizes=["16x256"], truth_sizes=["16x256"],
             n_test_cells=3000, test_range=8.0, progress=False)


@pytest.fixture(scope="module")
def street():
    from occgp.datasets import outdoor_scene
    return outdoor_scene(1, size=40)


@pytest.fixture(scope="module")
def mapping_rows(street):
    from occgp.iln.experiment import mapping_experiment
    return mapping_experiment(["bilinear"], scene=street, keep_maps=True, **SMALL)


def test_mapping_experiment_rows(mapping_rows, street):
    from occgp import OccupancyOctree
    from occgp.evaluation import evaluate_map

    assert [r["method"] for r in mapping_rows] == ["8x256 (input)", "bilinear 16x256",
                                                   "16x256 (true)"]
    for r in mapping_rows:
        assert 0.5 < r["auc"] < 1 and 0 < r["known"] <= 1
        assert r["n_test"] > r["n_occupied"] > 0 and r["n_scans"] == 2
        assert r["total_seconds"] == pytest.approx(r["upsample_seconds"] + r["update_seconds"])
        assert isinstance(r["map"], OccupancyOctree) and r["map"].resolution == 0.2
    assert mapping_rows[0]["upsample_seconds"] == 0 == mapping_rows[2]["upsample_seconds"]
    # more points from the denser scans, and the true dense map knows more than the sparse
    assert mapping_rows[0]["n_points"] < mapping_rows[2]["n_points"]
    assert mapping_rows[0]["known"] < mapping_rows[2]["known"]


def test_mapping_experiment_maps_the_true_scans_like_a_direct_build(mapping_rows, street):
    from occgp import OccupancyOctree
    from occgp.iln.data import simulate_range_image

    lidar = LidarModel.carla(16, 256)
    tree = OccupancyOctree(0.2)
    for pose in street.trajectory(2):
        pts = range_image_to_points(simulate_range_image(street, pose, lidar), lidar)
        tree.insert_scan(pts @ pose[:3, :3].T + pose[:3, 3], pose[:3, 3])
    mine = mapping_rows[2]["map"]
    probe = np.random.default_rng(0).uniform([-15, -8, -0.2], [15, 5, 3], (2000, 3))
    assert_array_equal(mine.occupancy(probe), tree.occupancy(probe))


def test_mapping_experiment_is_seeded(mapping_rows, street):
    from occgp.iln.experiment import mapping_experiment
    again = mapping_experiment({}, scene=street, **SMALL)
    assert [r["method"] for r in again] == ["8x256 (input)", "16x256 (true)"]
    assert again[0]["auc"] == mapping_rows[0]["auc"] and again[1]["auc"] == mapping_rows[2]["auc"]


def test_format_mapping_table(mapping_rows):
    from occgp.iln.experiment import format_mapping_table
    lines = format_mapping_table(mapping_rows).splitlines()
    assert lines[0].split()[:4] == ["Map", "from", "points/scan", "AUC"]
    assert len(lines) == 5 and lines[3].startswith("bilinear 16x256")
    with pytest.raises(ValueError, match=r"rows\[0\] lacks \['auc'\]"):
        format_mapping_table([{k: v for k, v in mapping_rows[0].items() if k != "auc"}])
    with pytest.raises(TypeError, match=r"rows\[0\] must be a dict"):
        format_mapping_table(["x"])


@pytest.mark.parametrize("kwargs, match", [
    ({"n_scans": 0}, r"n_scans must lie in \[1, 1000\], got 0"),
    ({"truth_sizes": []}, "truth_sizes must hold at least one size"),
    ({"sizes": ["16x256", "16x256"]}, r"sizes must not repeat a size, got \['16x256', '16x256'\]"),
    ({"sizes": ["4096x4096"]}, r"rows \* cols must be at most 4194304 pixels"),
    ({"resolution": 0.0}, r"resolution must lie in \(0.0, 10.0\]"),
    ({"resolution": 1e-9}, r"resolution must lie in \[0.001, 10\] m"),
    ({"resolution": 1e20}, r"resolution must lie in \(0.0, 10.0\]"),
    ({"n_test_cells": 10**9}, r"n_test_cells must lie in \[1, 10000000\]"),
    ({"test_range": 100.0}, r"test_range must lie in \(0.0, 80.0\]"),
    ({"poses": np.zeros((2, 3, 3))}, r"poses must have shape \(n_scans, 4, 4\)"),
    ({"poses": np.full((1, 4, 4), np.nan)}, r"poses\[0\]: pose must be finite"),
    ({"poses": [[[1, 0, 0, 1e30], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]]},
     r"poses\[0\]: pose translation must have coordinates of magnitude at most 1e7 m"),
    ({"test_range": np.inf}, r"test_range must lie in"),
    ({"models": ["cubic"]}, "model must be one of"),
    ({"n_test_cells": 1}, "a test set needs both classes"),
])
def test_mapping_experiment_rejects_bad_input(street, kwargs, match):
    from occgp.iln.experiment import mapping_experiment
    args = {**SMALL, "models": ["bilinear"], **kwargs}
    with pytest.raises(ValueError, match=match):
        mapping_experiment(args.pop("models"), scene=street, **args)


@pytest.mark.parametrize("kwargs, match", [
    ({"scene": object()}, "scene must be a Scene of occgp.datasets"),
    ({"lidar": "carla"}, "lidar must be a LidarModel"),
    ({"keep_maps": "yes"}, "keep_maps must be a bool"),
    ({"sizes": 3}, "sizes must be a sequence of sizes"),
    ({"n_scans": 2.0}, "n_scans must be a positive int, got float"),
])
def test_mapping_experiment_rejects_bad_types(street, kwargs, match):
    from occgp.iln.experiment import mapping_experiment
    args = {**SMALL, "scene": street, **kwargs}
    with pytest.raises(TypeError, match=match):
        mapping_experiment(["bilinear"], **args)
