"""Training of the ILN models: loss decreases, checkpoints, resume, DDP and bad configurations."""

import json
import os
import socket

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from occgp.iln.models import make  # noqa: E402
from occgp.iln.training import (  # noqa: E402
    load_checkpoint,
    masked_l1,
    sample_queries,
    train,
    train_from_yaml,
    _query_table,
    _step_generator,
)

LIDAR = {"vertical_fov": [-15.0, 15.0], "horizontal_fov": 360.0, "max_range": 80.0}
TINY_MODEL = {"name": "iln", "args": {"channels": 8, "n_resblocks": 1, "depth": 1}}


def _scene_images(n, seed=0):
    """Smooth-ish 8x32 targets with some no-returns; inputs take every other row's average."""
    rng = np.random.default_rng(seed)
    rows, cols = 8, 32
    base = rng.uniform(15, 60, (n, 1, 1))
    wave = 10 * np.sin(np.linspace(0, 2 * np.pi, cols))[None, None] * rng.uniform(0, 1, (n, 1, 1))
    slope = np.linspace(0, 20, rows)[None, :, None]
    hi = (base + wave + slope).astype(np.float32)
    hi[:, 0, : cols // 4] = 0.0  # sky
    lo = 0.5 * (hi[:, 0::2] + hi[:, 1::2])
    lo[(hi[:, 0::2] == 0) | (hi[:, 1::2] == 0)] = 0.0
    return lo.astype(np.float32), hi


def _write_shards(folder, n=6, per_shard=3, seed=0):
    folder.mkdir(parents=True, exist_ok=True)
    lo, hi = _scene_images(n, seed)
    for s in range(0, n, per_shard):
        np.savez_compressed(
            folder / f"shard-{s // per_shard:04d}.npz",
            r4x32=lo[s : s + per_shard], r8x32=hi[s : s + per_shard],
            lidar=np.array(json.dumps(LIDAR)), seeds=np.arange(s, s + per_shard, dtype=np.int64),
            poses=np.tile(np.eye(4), (min(per_shard, n - s), 1, 1)),
            format=np.array("occgp.iln.shard"), version=np.array(1),
        )
    return folder


@pytest.fixture
def shards(tmp_path):
    return _write_shards(tmp_path / "data" / "train")


def _config(folder, **train_kw):
    return {
        "seed": 0, "device": "cpu", "progress": False, "model": TINY_MODEL,
        "data": {"folder": str(folder), "input": "4x32", "target": "8x32"},
        "train": {"epochs": 2, "batch_size": 2, "queries_per_image": 64, "lr": 1e-3, **train_kw},
    }


def test_two_steps_lower_the_loss_on_a_fixed_batch():
    torch.manual_seed(0)
    lo, hi = _scene_images(2)
    model = make({"name": "iln", "args": {"channels": 8, "n_resblocks": 1, "depth": 1}})
    lm = type("M", (), {"vertical_fov": (-15.0, 15.0), "horizontal_fov": 360.0})
    lo_m, hi_m = lm(), lm()
    lo_m.rows, lo_m.cols, hi_m.rows, hi_m.cols = 4, 32, 8, 32
    x, y = torch.from_numpy(lo) / 80, torch.from_numpy(hi) / 80
    q, t = sample_queries(y, _query_table(lo_m, hi_m), 256, _step_generator(0, 0, 0))
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    losses = []
    for _ in range(3):
        loss = masked_l1(model(x, q), t)
        losses.append(float(loss.detach()))
        opt.zero_grad()
        loss.backward()
        opt.step()
    assert losses[2] < losses[1] < losses[0]


def test_query_table_maps_target_centers_to_input_pixels():
    lm = type("M", (), {"vertical_fov": (-15.0, 15.0), "horizontal_fov": 360.0})
    lo, hi = lm(), lm()
    lo.rows, lo.cols, hi.rows, hi.cols = 4, 32, 8, 64
    table = _query_table(lo, hi).numpy().reshape(8, 64, 2)
    np.testing.assert_allclose(table[3, 5], [(3 + 0.5) / 2, (5 + 0.5) / 2], atol=1e-5)


def test_masked_l1_ignores_no_return_targets():
    pred = torch.tensor([[0.5, 0.2, 0.9]])
    target = torch.tensor([[0.4, 0.0, 0.8]])
    assert float(masked_l1(pred, target)) == pytest.approx(0.1)
    assert float(masked_l1(pred, torch.zeros_like(pred))) == 0.0


def test_train_is_reproducible_and_writes_checkpoints(shards, tmp_path):
    cfg = _config(shards)
    cfg["output"] = {"dir": str(tmp_path / "run")}
    a = train(cfg)
    b = train(_config(shards))
    assert a["step"] == 6 and len(a["losses"]) == 6  # 6 images, batch 2, 2 epochs
    assert a["losses"] == b["losses"]
    ckpt = load_checkpoint(tmp_path / "run" / "last.pt")
    assert ckpt["step"] == 6 and ckpt["epoch"] == 2 and ckpt["config"]["seed"] == 0
    assert set(ckpt) >= {"model", "optimizer", "epoch", "step", "config"}
    assert ckpt["model"]["args"]["max_range"] == 80.0 and ckpt["model"]["args"]["wrap"] is True
    restored = make(ckpt["model"], load_sd=True)
    lo, _ = _scene_images(2, seed=5)
    q = np.random.default_rng(0).uniform([0, 0], [4, 32], (100, 2))
    np.testing.assert_array_equal(restored.predict(lo, q), a["model"].predict(lo, q))
    small = load_checkpoint(tmp_path / "run" / "model.pt")
    assert "optimizer" not in small
    assert 0 < small["train_seconds"] and ckpt["train_seconds"] <= small["train_seconds"]
    assert "torch " + torch.__version__ in small["hardware"] and "device cpu" in small["hardware"]
    np.testing.assert_array_equal(make(small["model"], load_sd=True).predict(lo, q), restored.predict(lo, q))


def test_resume_continues_like_an_uninterrupted_run(shards, tmp_path):
    full = train(_config(shards, epochs=2))
    part = _config(shards, epochs=2, max_steps=4)
    part["output"] = {"dir": str(tmp_path / "part")}
    first = train(part)
    rest = _config(shards, epochs=2)
    rest["resume"] = str(tmp_path / "part" / "last.pt")
    second = train(rest)
    assert first["losses"] + second["losses"] == full["losses"]
    assert second["step"] == 6
    for k, v in full["model"].state_dict().items():
        torch.testing.assert_close(second["model"].state_dict()[k], v, rtol=0, atol=0)


def test_train_from_yaml(shards, tmp_path):
    yaml = pytest.importorskip("yaml")
    path = tmp_path / "c.yaml"
    path.write_text(yaml.safe_dump(_config(shards, max_steps=1)))
    assert train_from_yaml(path)["step"] == 1


@pytest.mark.parametrize("name", ["small.yaml", "small_liif.yaml"])
def test_small_config_is_valid(name):
    yaml = pytest.importorskip("yaml")
    from pathlib import Path

    import occgp.iln

    path = Path(occgp.iln.__file__).parent / "configs" / name
    cfg = yaml.safe_load(path.read_text())
    from occgp.iln.training import _check_config, _merge

    chk = _check_config(_merge(cfg))
    assert chk["queries"] == 16384 and chk["lr"] == 1e-4
    make(cfg["model"])  # builds


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _ddp_worker(rank, world, port, cfg, out):
    os.environ.update({"MASTER_ADDR": "127.0.0.1", "MASTER_PORT": str(port), "RANK": str(rank),
                       "WORLD_SIZE": str(world), "LOCAL_RANK": str(rank)})
    torch.set_num_threads(1)
    result = train(cfg)
    torch.save({"losses": result["losses"], "sd": result["model"].state_dict()}, f"{out}-{rank}.pt")


@pytest.mark.slow
def test_ddp_two_processes_two_steps(shards, tmp_path):
    import torch.multiprocessing as mp

    cfg = _config(shards, epochs=2, max_steps=2)
    cfg["output"] = {"dir": str(tmp_path / "ddp")}
    out = str(tmp_path / "res")
    mp.spawn(_ddp_worker, args=(2, _free_port(), cfg, out), nprocs=2, join=True)
    r0, r1 = (torch.load(f"{out}-{r}.pt", weights_only=True) for r in (0, 1))
    assert len(r0["losses"]) == 2 and r0["losses"] == r1["losses"]  # averaged over processes
    for k in r0["sd"]:  # gradients were all-reduced: the replicas agree
        torch.testing.assert_close(r0["sd"][k], r1["sd"][k])
    ckpt = load_checkpoint(tmp_path / "ddp" / "last.pt")
    assert ckpt["step"] == 2 and ckpt["world_size"] == 2


# ---------------------------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    "change, exc, match",
    [
        ({"colour": 1}, ValueError, r"config has unknown key\(s\) \['colour'\]"),
        ({"train": {"batch": 2}}, ValueError, r"config\['train'\] has unknown key\(s\) \['batch'\]"),
        ({"train": {"batch_size": 0}}, ValueError, r"config\['train'\]\['batch_size'\] must be >= 1"),
        ({"train": {"batch_size": 2.5}}, TypeError, r"config\['train'\]\['batch_size'\] must be an int"),
        ({"train": {"lr": -1.0}}, ValueError, r"config\['train'\]\['lr'\] must be a finite number > 0"),
        ({"train": {"lr": float("nan")}}, ValueError, r"config\['train'\]\['lr'\] must be a finite"),
        ({"train": {"queries_per_image": 0}}, ValueError, r"queries_per_image'\] must be >= 1"),
        ({"train": "fast"}, TypeError, r"config\['train'\] must be a dict"),
        ({"data": {"input": "16by1024"}}, ValueError, r"config\['data'\]\['input'\] must be a size"),
        ({"data": {"target": "4x32"}}, ValueError, r"\['input'\] and \['target'\] must differ"),
        ({"data": {"folder": None}}, ValueError, r"config\['data'\]\['folder'\] must name the folder"),
        ({"data": {"input": "16x1024"}}, ValueError, r"lacks the entries \['r16x1024'\]"),
        ({"device": "tpu:0"}, ValueError, r"config\['device'\] must be 'cpu', 'cuda'"),
        ({"device": 3}, TypeError, r"config\['device'\] must be a str"),
        ({"model": {"name": "bilinear"}}, ValueError, r"config\['model'\] 'bilinear' has no parameters"),
        ({"model": {"name": "nope"}}, ValueError, r"spec\['name'\] must be one of"),
        ({"progress": "yes"}, TypeError, r"config\['progress'\] must be true, false or null"),
        ({"seed": -1}, ValueError, r"config\['seed'\] must be >= 0"),
        ({"seed": 2**40}, ValueError, r"config\['seed'\] must be <= 4294967295"),
        ({"train": {"queries_per_image": 10**12}}, ValueError, r"queries_per_image'\] must be <= 4194304"),
        ({"train": {"batch_size": 10**9}}, ValueError, r"batch_size'\] must be <= 4096"),
    ],
)
def test_train_rejects_bad_config(shards, change, exc, match):
    cfg = _config(shards)
    for k, v in change.items():
        cfg[k] = {**cfg[k], **v} if isinstance(v, dict) and isinstance(cfg.get(k), dict) and k != "model" else v
    with pytest.raises(exc, match=match):
        train(cfg)


def test_train_rejects_bad_data(tmp_path):
    with pytest.raises(OSError, match="is not a folder"):
        train(_config(tmp_path / "missing"))
    (tmp_path / "empty").mkdir()
    with pytest.raises(OSError, match=r"no \.npz shards in"):
        train(_config(tmp_path / "empty"))
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "x.npz").write_bytes(b"not a zip")
    with pytest.raises(OSError, match="cannot read shard"):
        train(_config(bad))
    wrong = _write_shards(tmp_path / "wrong")
    with np.load(wrong / "shard-0000.npz") as z:
        d = dict(z)
    d["r8x32"] = d["r8x32"].astype(np.float64)
    np.savez(wrong / "shard-0000.npz", **d)
    with pytest.raises(ValueError, match=r"entry 'r8x32' must be float32 \(n, 8, 32\)"):
        train(_config(wrong))
    nan = _write_shards(tmp_path / "nan")
    with np.load(nan / "shard-0000.npz") as z:
        d = dict(z)
    d["r4x32"][0, 0, 0] = np.nan
    np.savez(nan / "shard-0000.npz", **d)
    with pytest.raises(ValueError, match="input images of the shards .* must be finite"):
        train(_config(nan))


def test_resume_and_yaml_errors(shards, tmp_path):
    cfg = _config(shards)
    cfg["resume"] = str(tmp_path / "nope.pt")
    with pytest.raises(OSError, match="checkpoint .*nope.pt' does not exist"):
        train(cfg)
    (tmp_path / "junk.pt").write_bytes(b"junk")
    cfg["resume"] = str(tmp_path / "junk.pt")
    with pytest.raises(OSError, match="cannot read checkpoint"):
        train(cfg)
    torch.save({"format": "other"}, tmp_path / "other.pt")
    cfg["resume"] = str(tmp_path / "other.pt")
    with pytest.raises(ValueError, match="is not an occgp.iln checkpoint"):
        train(cfg)
    run = _config(shards, max_steps=1)
    run["output"] = {"dir": str(tmp_path / "r")}
    train(run)
    cfg = _config(shards, batch_size=3)
    cfg["resume"] = str(tmp_path / "r" / "last.pt")
    with pytest.raises(ValueError, match="steps per epoch"):
        train(cfg)
    with pytest.raises(OSError, match="cannot read the configuration"):
        train_from_yaml(tmp_path / "none.yaml")
    (tmp_path / "list.yaml").write_text("- 1\n- 2\n")
    with pytest.raises(ValueError, match="must be a YAML mapping"):
        train_from_yaml(tmp_path / "list.yaml")
    (tmp_path / "broken.yaml").write_text("a: [1, 2\n")
    with pytest.raises(ValueError, match="is not valid YAML"):
        train_from_yaml(tmp_path / "broken.yaml")
    with pytest.raises(TypeError, match="config must be a dict"):
        train("config.yaml")


def test_train_from_yaml_rejects_a_binary_file(tmp_path):
    path = tmp_path / "config.yaml"
    path.write_bytes(b"\xff\xfe\x00binary")
    with pytest.raises(ValueError, match="is not UTF-8 text"):
        train_from_yaml(path)


def test_package_train_is_the_function_even_after_the_module_is_imported():
    import importlib

    import occgp.iln
    importlib.import_module("occgp.iln.training")
    assert callable(occgp.iln.train) and occgp.iln.train is train
    assert occgp.iln.load_checkpoint is load_checkpoint
