"""The candidate selector: its candidates, an untrained model is the prior, labels, training."""

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from occgp.iln.models import (  # noqa: E402
    CANDIDATES,
    CandidateSelector,
    available_models,
    hard_queries,
    make,
    selector_labels,
)
from occgp.iln.models._candidates import candidates  # noqa: E402
from occgp.iln.training import load_checkpoint, sample_hard_queries, train  # noqa: E402
from occgp.iln.tuning import tune_checkpoint, tune_threshold  # noqa: E402

K = {name: k for k, name in enumerate(CANDIDATES)}


def _random_image(rows=6, cols=12, seed=0, holes=True):
    rng = np.random.default_rng(seed)
    img = rng.uniform(2.0, 40.0, (rows, cols)).astype(np.float32)
    if holes:
        img[rng.uniform(size=img.shape) < 0.15] = 0.0
        img[0, :3] = 0.0
    return img


def _queries(rows, cols, n=400, seed=1):
    rng = np.random.default_rng(seed)
    return np.stack([rng.uniform(0, rows, n), rng.uniform(0, cols, n)], -1).astype(np.float32)


def _cands(img, q, wrap=True, max_range=80.0):
    ranges, exists, px = candidates(torch.from_numpy(img)[None] / max_range,
                                    torch.from_numpy(q)[None], wrap)
    return ranges[0].numpy() * max_range, exists[0].numpy(), px[0].numpy() * max_range


@pytest.mark.parametrize("wrap", [True, False])
def test_prior_candidate_is_inverse_bilinear(wrap):
    img = _random_image()
    q = _queries(*img.shape)
    ranges, exists, _ = _cands(img, q, wrap)
    expected = make({"name": "inverse-bilinear", "args": {"wrap": wrap}}).predict(img, q)
    np.testing.assert_allclose(ranges[:, K["prior"]], expected, rtol=1e-5, atol=1e-5)
    assert exists[:, K["prior"]].all() and exists[:, K["no-return"]].all()
    assert (ranges[:, K["no-return"]] == 0).all()


def test_copies_and_extensions_on_linear_inverse_ranges():
    # 1 / r linear in the row and the column: every extension and the prior agree exactly,
    # the copies give their row's / column's own value
    rows, cols = 6, 10
    i = np.arange(rows)[:, None] + 0.5
    j = np.arange(cols)[None, :] + 0.5
    inv = 0.02 + 0.01 * i + 0.002 * j
    img = (1.0 / inv).astype(np.float32)
    q = np.array([[2.3, 4.6], [3.75, 5.2], [2.9, 3.7]], np.float32)
    ranges, exists, px = _cands(img, q, wrap=False)
    inv_q = 0.02 + 0.01 * q[:, 0] + 0.002 * q[:, 1]
    for name in ("prior", "ext-up", "ext-down", "ext-left", "ext-right"):
        assert exists[:, K[name]].all(), name
        np.testing.assert_allclose(1.0 / ranges[:, K[name]], inv_q, rtol=1e-4)
    row_up = np.floor(q[:, 0] - 0.5) + 0.5
    np.testing.assert_allclose(1.0 / ranges[:, K["up"]], 0.02 + 0.01 * row_up + 0.002 * q[:, 1],
                               rtol=1e-4)
    col_left = np.floor(q[:, 1] - 0.5) + 0.5
    np.testing.assert_allclose(1.0 / ranges[:, K["left"]], 0.02 + 0.01 * q[:, 0] + 0.002 * col_left,
                               rtol=1e-4)
    assert px.shape == (3, 4, 4)
    assert px[0, 1, 1] == pytest.approx(img[1, 4])  # query (2.3, 4.6): rows 1-2, columns 4-5


def test_candidates_at_the_border_and_in_no_returns():
    img = np.full((4, 8), 10.0, np.float32)
    img[:, 5:] = 0.0
    q = np.array([[0.2, 2.0], [3.9, 2.0], [2.0, 6.5]], np.float32)
    ranges, exists, _ = _cands(img, q, wrap=False)
    assert not exists[0, K["up"]] and not exists[0, K["ext-up"]]  # above row 0's center
    assert not exists[1, K["down"]] and not exists[1, K["ext-down"]]
    assert ranges[2, K["prior"]] == 0.0 and not exists[2, K["up"]]  # inside the no-returns
    assert (ranges[~exists] == 0).all()


def test_an_untrained_selector_is_inverse_bilinear():
    img = np.stack([_random_image(seed=s) for s in range(3)])
    q = _queries(6, 12, seed=5)
    sel = CandidateSelector()
    prior = make({"name": "inverse-bilinear"})
    np.testing.assert_array_equal(sel.predict(img, q), prior.predict(img, q))
    np.testing.assert_allclose(sel.weights(img, q), prior.weights(img, q), atol=1e-6)


def _forcing(name, threshold=0.5):
    """A selector whose head always prefers candidate `name` (where it exists)."""
    sel = CandidateSelector(threshold=threshold)
    with torch.no_grad():
        sel.net[-1].bias[K[name]] = 10.0
    return sel


def test_forced_choices_and_the_threshold():
    img = np.zeros((4, 8), np.float32)
    img[:2] = 10.0
    img[2:] = 30.0
    q = np.array([[2.25, 4.0], [1.8, 4.0]], np.float32)
    assert _forcing("up").predict(img, q).tolist() == [10.0, 10.0]
    assert _forcing("down").predict(img, q).tolist() == [30.0, 30.0]
    assert _forcing("no-return").predict(img, q).tolist() == [0.0, 0.0]
    prior = make({"name": "inverse-bilinear"}).predict(img, q)
    np.testing.assert_array_equal(_forcing("up", threshold=1.0).predict(img, q), prior)
    w = _forcing("down").weights(img, q)
    np.testing.assert_allclose(w, [[0, 0, 0.5, 0.5], [0, 0, 0.5, 0.5]], atol=1e-6)
    w = _forcing("ext-up").weights(img[None].repeat(2, 0), np.array([[[2.25, 4.0]]] * 2))
    assert w.shape == (2, 1, 4)


def test_weights_are_convex_or_zero():
    img = _random_image(seed=3)
    q = _queries(6, 12, seed=4)
    for name in CANDIDATES:
        w = _forcing(name).weights(img, q)
        total = w.sum(-1)
        assert ((np.abs(total - 1) < 1e-5) | (total == 0)).all()
        assert (w >= 0).all()


def test_labels_tie_to_the_prior():
    ranges = torch.tensor([[[10.0, 10.02, 12.0, 0, 0, 0, 0, 0, 0, 0]]]) / 80
    exists = torch.tensor([[[True, True, True] + [False] * 6 + [True]]])
    truth = torch.tensor([[10.015]]) / 80
    assert selector_labels(ranges, exists, truth, tie=0.02 / 80).item() == K["prior"]
    assert selector_labels(ranges, exists, truth, tie=0.0).item() == K["up"]
    truth = torch.tensor([[11.9]]) / 80
    assert selector_labels(ranges, exists, truth, tie=0.02 / 80).item() == K["down"]
    # no true return: the no-return candidate; a missing candidate is never the label
    assert selector_labels(ranges, exists, torch.zeros(1, 1), tie=0.0).item() == K["no-return"]
    exists[..., K["down"]] = False
    assert selector_labels(ranges, exists, torch.tensor([[11.9]]) / 80, 0.0).item() == K["up"]


def test_hard_queries_are_edges_and_no_return_neighbours():
    plane = (1.0 / (0.02 + 0.01 * (np.arange(8)[:, None] + 0.5)) * np.ones((1, 16))).astype(np.float32)
    step = plane.copy()
    step[4:] *= 2.0
    holes = plane.copy()
    holes[3, 7] = 0.0
    q = torch.tensor([[3.9, 7.6]])
    out = []
    for img in (plane, step, holes):
        r, e, px = candidates(torch.from_numpy(img)[None] / 80, q[None], True)
        out.append(bool(hard_queries(r, e, px)[0, 0]))
    assert out == [False, True, True]


def _shards(folder, n=4, rows=16, cols=1024, seed=0):
    """Streets of steps: inputs every 4th row of the 4x taller targets."""
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    r = np.arange(rows * 4)[:, None] + 0.5
    hi = np.empty((n, rows * 4, cols), np.float32)
    for k in range(n):
        inv = 0.02 + 0.004 * r + 0.0 * np.arange(cols)[None]
        img = 1.0 / inv
        for _ in range(6):  # boxes in front
            c0 = rng.integers(0, cols - 64)
            r0 = rng.integers(0, rows * 4 - 8)
            img[r0:r0 + 8, c0:c0 + 64] = rng.uniform(3, 8)
        hi[k] = img
    lo = hi[:, 1::4]
    lidar = {"vertical_fov": [-15.0, 15.0], "horizontal_fov": 360.0, "max_range": 80.0}
    key_lo, key_hi = f"r{rows}x{cols}", f"r{rows * 4}x{cols}"
    np.savez_compressed(folder / "shard_00000.npz", **{key_lo: np.ascontiguousarray(lo),
                        key_hi: hi}, lidar=np.array(json.dumps(lidar)),
                        seeds=np.arange(n, dtype=np.int64), poses=np.tile(np.eye(4), (n, 1, 1)),
                        format=np.array("occgp.iln.shard"), version=np.array(1))
    return folder, key_lo[1:], key_hi[1:]


@pytest.fixture(scope="module")
def street(tmp_path_factory):
    """Two simulated street scenes, 2 poses each, at 16x1024 and 64x1024."""
    from occgp.iln.data import make_dataset

    folder = tmp_path_factory.mktemp("street")
    make_dataset(folder, 2, 0, sizes=["16x1024", "64x1024"], images_per_scene=2, seed=0,
                 progress=False)
    return folder


def _street_config(folder, out, steps=150):
    return {"seed": 0, "progress": False,
            "model": {"name": "selector", "args": {"hidden": 32}},
            "data": {"folder": str(folder), "input": "16x1024", "target": ["64x1024"]},
            "train": {"epochs": 1000, "batch_size": 2, "queries_per_image": 2048, "lr": 1e-2,
                      "schedule": "cosine", "warmup": 5, "hard_fraction": 0.5,
                      "max_steps": steps},
            "output": {"dir": None if out is None else str(out)}}


@pytest.mark.slow
def test_selector_training_learns_the_edges(street, tmp_path):
    from occgp.iln.data import load_shards
    from occgp.iln.evaluate import evaluate

    result = train(_street_config(street, tmp_path / "run"))
    losses = result["losses"]
    assert np.mean(losses[-10:]) < 0.7 * np.mean(losses[:5])
    again = train(_street_config(street, None, steps=20))
    first = train(_street_config(street, None, steps=20))
    for a, b in zip(first["model"].state_dict().values(), again["model"].state_dict().values()):
        assert torch.equal(a, b)
    # on the images it saw, the trained selector beats its prior, inverse bilinear
    images = load_shards(street / "train", ["16x1024", "64x1024"])
    rows = evaluate({"prior": "inverse-bilinear", "selector": result["model"]}, images,
                    out_sizes=["64x1024"], progress=False)
    prior, sel = rows
    assert sel["mae"] < 0.95 * prior["mae"] and sel["iou"] > prior["iou"] + 0.02
    # the thresholds are tuned on images after the first and written into a copy
    record = tune_checkpoint(tmp_path / "run" / "model.pt", street, tmp_path / "t.pt",
                             thresholds=[0.5, 1.0], no_return_thresholds=[0.9, 1.0],
                             out_sizes=["64x1024"], skip=1, progress=False)
    assert record["threshold"] == 0.5 and record["no_return_threshold"] in (0.9, 1.0)
    assert record["images"] == 3 and record["skip"] == 1 and len(record["rows"]) == 5
    tuned = load_checkpoint(tmp_path / "t.pt")
    assert tuned["threshold_tuning"] == record
    again = make(tuned["model"], load_sd=True)
    assert (again.threshold, again.no_return_threshold) == (0.5, record["no_return_threshold"])
    with pytest.raises(ValueError, match="no image is left"):
        tune_checkpoint(tmp_path / "run" / "model.pt", street, tmp_path / "u.pt",
                        out_sizes=["64x1024"], skip=4)
    with pytest.raises(ValueError, match="not a selector"):
        ckpt = load_checkpoint(tmp_path / "run" / "model.pt")
        ckpt["model"] = make({"name": "inverse-bilinear"}).spec()
        torch.save(ckpt, tmp_path / "bil.pt")
        tune_checkpoint(tmp_path / "bil.pt", street, tmp_path / "v.pt", out_sizes=["64x1024"])


@pytest.mark.slow
def test_tune_threshold_picks_from_the_grid(street):
    from occgp.iln.data import load_shards

    images = load_shards(street / "train", ["16x1024", "64x1024"])
    images = {k: v[:2] for k, v in images.items()}
    # a selector sure of copying the upper row everywhere errs more than the prior: no pair
    # qualifies and the prior (1, 1) is returned
    t, n, rows = tune_threshold(_forcing("up"), images, thresholds=[0.2, 0.5],
                                no_return_thresholds=[1.0], out_sizes=["64x1024"],
                                progress=False)
    assert (t, n) == (1.0, 1.0)
    assert [(r["threshold"], r["no_return_threshold"]) for r in rows] == \
        [(0.2, 1.0), (0.5, 1.0), (1.0, None)]
    prior = rows[-1]
    assert rows[0]["mae"] > prior["mae"]
    expected = evaluate_one("inverse-bilinear", images)
    assert prior["iou"] == pytest.approx(expected["iou"], abs=1e-6)
    assert prior["mae"] == pytest.approx(expected["mae"], rel=1e-5)
    # an untrained selector is the prior: no pair gains anything, the prior is returned
    t, n, rows = tune_threshold(CandidateSelector(), images, thresholds=[0.2, 0.5],
                                no_return_thresholds=[0.9], out_sizes=["64x1024"],
                                progress=False)
    assert (t, n) == (1.0, 1.0)
    assert rows[0]["iou"] == rows[-1]["iou"] and rows[0]["mae"] == rows[-1]["mae"]
    with pytest.raises(TypeError, match="CandidateSelector"):
        tune_threshold(make({"name": "inverse-bilinear"}), images, out_sizes=["64x1024"])
    with pytest.raises(ValueError, match="thresholds"):
        tune_threshold(_forcing("up"), images, thresholds=[1.5], out_sizes=["64x1024"])
    with pytest.raises(ValueError, match="no_return_thresholds"):
        tune_threshold(_forcing("up"), images, no_return_thresholds=[], out_sizes=["64x1024"])
    with pytest.raises(TypeError, match="thresholds"):
        tune_threshold(_forcing("up"), images, thresholds=["a"], out_sizes=["64x1024"])


def evaluate_one(name, images):
    from occgp.iln.evaluate import evaluate

    return evaluate([name], images, out_sizes=["64x1024"], progress=False)[0]


def test_choose_candidates_and_the_no_return_threshold():
    from occgp.iln.models import choose_candidates

    p = np.array([[0.3, 0.6, 0, 0, 0, 0, 0, 0, 0, 0.1],    # up is sure enough
                  [0.5, 0.4, 0, 0, 0, 0, 0, 0, 0, 0.1],    # not above the prior
                  [0.02, 0.03, 0, 0, 0, 0, 0, 0, 0, 0.95],  # no return, sure enough
                  [0.05, 0.1, 0, 0, 0, 0, 0, 0, 0, 0.85]], np.float32)  # no return, not sure
    assert choose_candidates(p, 0.3, 0.9).tolist() == [K["up"], K["prior"], K["no-return"],
                                                         K["prior"]]
    assert choose_candidates(p, 0.05, 0.9).tolist()[3] == K["up"]
    assert choose_candidates(torch.from_numpy(p), 1.0, 1.0).tolist() == [0, 0, 0, 0]


def test_candidate_table_matches_predict():
    img = _random_image(seed=11)
    q = _queries(6, 12, seed=12)
    sel = _forcing("ext-down")
    ranges, probs = sel.candidate_table(img, q)
    assert ranges.shape == probs.shape == (len(q), 10)
    np.testing.assert_allclose(probs.sum(-1), 1.0, rtol=1e-5)
    from occgp.iln.models import choose_candidates
    choice = choose_candidates(probs, sel.threshold, sel.no_return_threshold)
    np.testing.assert_allclose(np.take_along_axis(ranges, choice[:, None], 1)[:, 0],
                               sel.predict(img, q), rtol=1e-5)
    with pytest.raises(ValueError, match="one image"):
        sel.candidate_table(img[None], q)


def test_sample_hard_queries_draws_the_hard_share():
    folder_images = _random_image(rows=4, cols=32, seed=2, holes=False)
    step = np.repeat(folder_images, 4, axis=0)
    x = torch.from_numpy(folder_images)[None] / 80
    y = torch.from_numpy(step)[None] / 80
    from occgp.iln._range import LidarModel
    from occgp.iln.training import _query_table
    table = _query_table(LidarModel.carla(4, 32), LidarModel.carla(16, 32))
    gen = torch.Generator().manual_seed(0)
    q, t = sample_hard_queries(x, y, table, 200, 0.5, gen, True)
    assert q.shape == (1, 200, 2) and t.shape == (1, 200)
    r, e, px = candidates(x, q, True)
    hard = hard_queries(r, e, px)[0]
    assert hard[:100].float().mean() >= hard[100:].float().mean()
    q0, _ = sample_hard_queries(x, y, table, 50, 0.0, torch.Generator().manual_seed(0), True)
    assert q0.shape == (1, 50, 2)


@pytest.mark.parametrize("args, exc, match", [
    ({"hidden": 0}, ValueError, "hidden"),
    ({"threshold": 1.5}, ValueError, "threshold"),
    ({"threshold": "high"}, TypeError, "threshold"),
    ({"tie": -0.1}, ValueError, "tie"),
    ({"tie": float("nan")}, ValueError, "tie"),
    ({"no_return_threshold": -0.1}, ValueError, "no_return_threshold"),
])
def test_bad_arguments(args, exc, match):
    with pytest.raises(exc, match=match):
        make({"name": "selector", "args": args})


def test_registry_and_spec_round_trip():
    assert "selector" in available_models()
    sel = _forcing("left", threshold=0.7)
    again = make(sel.spec(), load_sd=True)
    img = _random_image(seed=9)
    q = _queries(6, 12, seed=9)
    np.testing.assert_array_equal(again.predict(img, q), sel.predict(img, q))
    assert again.threshold == 0.7


@pytest.mark.parametrize("change, match", [
    ({"train": {"hard_fraction": 1.5}}, "hard_fraction"),
    ({"train": {"schedule": "linear"}}, "schedule"),
    ({"train": {"warmup": -1}}, "warmup"),
    ({"data": {"target": ["64x1024", "64x1024"]}}, "repeat"),
    ({"data": {"target": ["16x1024"]}}, "differ"),
])
def test_bad_training_configuration(tmp_path, change, match):
    folder, lo, hi = _shards(tmp_path / "d" / "train", n=2)
    cfg = {"model": {"name": "selector"}, "progress": False,
           "data": {"folder": str(folder), "input": lo, "target": hi},
           "train": {"max_steps": 1, "queries_per_image": 64}}
    for key, value in change.items():
        cfg[key] = dict(cfg[key], **value)
    with pytest.raises(ValueError, match=match):
        train(cfg)


def test_shipped_selector_config_is_valid():
    yaml = pytest.importorskip("yaml")
    from pathlib import Path

    import occgp.iln
    from occgp.iln.training import _check_config, _merge

    path = Path(occgp.iln.__file__).parent / "configs" / "selector.yaml"
    cfg = yaml.safe_load(path.read_text())
    chk = _check_config(_merge(cfg))
    assert chk["targets"] == [(64, 1024), (128, 2048)] and chk["hard_fraction"] == 0.5
    assert chk["schedule"] == "cosine" and chk["max_images"] == 600
    assert isinstance(make(cfg["model"]), CandidateSelector)


def test_max_farther_never_lengthens_the_prior():
    img = np.zeros((4, 8), np.float32)
    img[:2] = 10.0
    img[2:] = 30.0
    q = np.array([[2.25, 4.0], [1.8, 4.0]], np.float32)
    prior = make({"name": "inverse-bilinear"}).predict(img, q)
    far = _forcing("down")
    assert far.predict(img, q).tolist() == [30.0, 30.0]
    far.max_farther = 0.02
    np.testing.assert_array_equal(far.predict(img, q), prior)  # the copy would lengthen it
    near = _forcing("up")
    near.max_farther = 0.02
    assert near.predict(img, q).tolist() == [10.0, 10.0]       # shortening stays allowed
    ranges, probs = far.candidate_table(img, q)
    assert (probs[ranges > prior[:, None] * 1.02] == 0).all()
    assert make(far.spec(), load_sd=True).max_farther == 0.02
    with pytest.raises(ValueError, match="max_farther"):
        CandidateSelector(max_farther=-1.0)
