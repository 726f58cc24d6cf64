"""The models that ship with occgp.iln (occgp/iln/weights/)."""

import numpy as np
import pytest

torch = pytest.importorskip("torch")

import occgp.iln as iln  # noqa: E402
from occgp.datasets import outdoor_scene  # noqa: E402
from occgp.iln._weights import FOLDER, WEIGHTS  # noqa: E402


@pytest.mark.parametrize("name", sorted(WEIGHTS))
def test_shipped_model_loads_and_up_samples_a_simulated_scan(name):
    path = FOLDER / WEIGHTS[name]
    if not path.is_file():
        pytest.fail(f"{path} is missing: the package ships it")
    assert path.stat().st_size <= 5 * 2**20
    model = iln.pretrained(name)
    assert not model.training and model.spec()["name"] == name
    scene = outdoor_scene(100_003, size=40)
    lidar = iln.LidarModel.carla(16, 1024)
    image = iln.simulate_range_image(scene, scene.trajectory(1)[0], lidar)
    queries = np.random.default_rng(0).uniform([0, 0], [16, 1024], (500, 2))
    out = model.predict(image, queries)
    assert out.shape == (500,) and np.isfinite(out).all() and (out >= 0).all()
    assert (out <= lidar.max_range).all()
    if name == "iln":                  # weights over the 4 neighbours: within their ranges
        v = np.clip(np.floor(queries[:, 0] - 0.5).astype(int), 0, 15)
        u = np.floor(queries[:, 1] - 0.5).astype(int) % 1024
        near = np.stack([image[v, u], image[np.minimum(v + 1, 15), u],
                         image[v, (u + 1) % 1024], image[np.minimum(v + 1, 15), (u + 1) % 1024]])
        returns = np.where(near > 0, near, np.nan)
        has = np.isfinite(returns).any(axis=0)
        lo, hi = np.nanmin(returns[:, has], axis=0), np.nanmax(returns[:, has], axis=0)
        assert (out[has] >= lo - 1e-4).all() and (out[has] <= hi + 1e-4).all()


def test_the_default_shipped_model_is_the_tuned_selector():
    from occgp.iln.training import load_checkpoint

    model = iln.pretrained()
    assert isinstance(model, iln.CandidateSelector)
    ckpt = load_checkpoint(FOLDER / WEIGHTS["selector"])
    tuning = ckpt["threshold_tuning"]
    assert model.threshold == tuning["threshold"]
    assert model.no_return_threshold == tuning["no_return_threshold"]
    assert tuning["scene_seeds"][0] >= ckpt["config"]["data"]["max_images"] // 4
    assert ckpt["train_seconds"] <= 30 * 60 and "cores" in ckpt["hardware"]


def test_pretrained_rejects_an_unknown_name():
    with pytest.raises(ValueError,
                       match=r"name must be one of \['iln', 'liif', 'selector'\], got 'edsr'"):
        iln.pretrained("edsr")
