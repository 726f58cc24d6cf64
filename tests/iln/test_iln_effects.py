"""Sensor effects on simulated range images, and the realistic shards of make_dataset."""

import json
import types
import zipfile

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from occgp.datasets import outdoor_scene
from occgp.datasets._geometry import Box
from occgp.iln import LidarModel, SensorEffects, apply_sensor_effects, kept_beams_model, \
    load_shards, make_dataset, simulate_range_image, solid_reflectivity
from occgp.iln import _effects, data

OFF = dict(range_noise=0.0, grazing_dropout=0.0, dark_dropout=0.0, range_dropout=0.0)
HEIGHT = 1.73


def _ground_image(model, height=HEIGHT):
    """The exact image of an endless flat ground (z = 0) from a level sensor."""
    scene = types.SimpleNamespace(solids=[Box([0.0, 0.0, -0.5], [500.0, 500.0, 0.5])])
    return simulate_range_image(scene, ([0.0, 0.0, height], 0.0), model)


@pytest.fixture(scope="module")
def street():
    scene = outdoor_scene(3, size=40)
    model = LidarModel.carla(16, 256)
    image, ids = simulate_range_image(scene, scene.random_poses(1, seed=2)[0], model,
                                      return_ids=True)
    return scene, model, image, ids


# --------------------------------------------------------------------------- #
# SensorEffects and apply_sensor_effects
# --------------------------------------------------------------------------- #
def test_defaults_and_dict_round_trip():
    e = SensorEffects()
    assert e.range_noise == 0.02 and 0 < e.grazing_dropout <= 1 and 0 < e.dark_dropout <= 1
    assert SensorEffects.from_dict(e.as_dict()) == e
    assert SensorEffects.from_dict({"range_noise": 0.01}) == SensorEffects(range_noise=0.01)
    assert json.loads(json.dumps(e.as_dict())) == e.as_dict()


def test_seeded_and_reproducible(street):
    _, model, image, _ = street
    a = apply_sensor_effects(image, model, SensorEffects(), 5)
    b = apply_sensor_effects(image, model, SensorEffects(), np.random.default_rng(5))
    c = apply_sensor_effects(image, model, SensorEffects(), 6)
    assert a.dtype == np.float32 and a.shape == image.shape
    assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    assert (a[image == 0] == 0).all()                 # no return stays no return
    assert (a <= np.float32(model.max_range)).all() and (a >= 0).all()


def test_effects_off_change_nothing(street):
    scene, model, image, ids = street
    out = apply_sensor_effects(image, model, SensorEffects(**OFF), 0,
                               reflectivity=solid_reflectivity(scene.labels)[ids])
    assert_array_equal(out, image)
    # return_ids does not change the image; ids mark the returns
    assert_array_equal(simulate_range_image(scene, scene.random_poses(1, seed=2)[0], model),
                       image)
    assert ((ids >= 0) == (image > 0)).all()


def test_ids_name_the_solid_hit(street):
    scene, model, image, ids = street
    pose = scene.random_poses(1, seed=2)[0]
    dirs = model.directions() @ pose[:3, :3].T
    for k in np.unique(ids[ids >= 0]):
        sel = ids == k
        t = scene.solids[k].intersect(pose[:3, 3][None], dirs[sel])
        np.testing.assert_allclose(t, image[sel], rtol=1e-6, atol=1e-5)


def test_range_noise_statistics_on_flat_ground():
    model = LidarModel.carla(16, 256)
    clean = _ground_image(model)
    hit = clean > 0
    assert hit.sum() > 1500
    diffs = [apply_sensor_effects(clean, model, SensorEffects(**{**OFF, "range_noise": 0.02}),
                                  seed)[hit] - clean[hit] for seed in range(4)]
    diffs = np.concatenate(diffs)
    assert abs(np.std(diffs) - 0.02) < 0.002          # within 10 % of 2 cm
    assert abs(np.mean(diffs)) < 0.002


def test_incidence_angles_of_the_flat_ground():
    model = LidarModel.carla(16, 256)
    clean = _ground_image(model).astype(np.float64)
    cos = _effects._incidence_cosines(clean, model)
    hit = clean > 0
    # the ground's normal is +z: cos = height / range
    np.testing.assert_allclose(cos[hit], HEIGHT / clean[hit], rtol=1e-6)
    assert (cos[~hit] == 1.0).all()


def test_grazing_dropout_rises_towards_90_degrees():
    model = LidarModel.carla(64, 1024)
    clean = _ground_image(model)
    effects = SensorEffects(**{**OFF, "grazing_dropout": 0.8, "grazing_angle": 80.0})
    out = apply_sensor_effects(clean, model, effects, 1)
    hit = clean > 0
    angle = np.degrees(np.arccos(np.clip(HEIGHT / np.where(hit, clean, 1.0), 0, 1)))
    lost = hit & (out == 0)
    steep = hit & (angle < 79.0)
    grazing = hit & (angle > 87.0)
    assert steep.sum() > 1000 and grazing.sum() > 1000
    assert lost[steep].sum() == 0                     # no dropout below the onset angle
    assert lost[grazing].mean() > 0.3
    # the probability follows grazing_dropout * s**2
    s = np.clip((angle - 80.0) / 10.0, 0, 1)
    expected = (0.8 * s * s)[hit].mean()
    assert abs(lost[hit].mean() - expected) < 0.02


def test_grazing_dropout_spares_a_wall_seen_face_on():
    model = LidarModel.carla(16, 256)
    scene = types.SimpleNamespace(solids=[Box([6.0, 0.0, 0.0], [0.5, 60.0, 50.0])])
    clean = simulate_range_image(scene, ([0.0, 0.0, 0.0], 0.0), model)
    out = apply_sensor_effects(clean, model, SensorEffects(**{**OFF, "grazing_dropout": 1.0,
                                                                 "grazing_angle": 75.0}), 0)
    facing = clean > 0
    angle = np.degrees(np.arccos(_effects._incidence_cosines(clean.astype(float), model)))
    near_normal = facing & (angle < 45)
    assert near_normal.sum() > 100 and (out[near_normal] > 0).all()
    edge_on = facing & (angle > 82)
    assert edge_on.sum() > 20 and (out[edge_on] == 0).mean() > 0.15   # the wall seen edge-on


def test_dark_surfaces_drop_more_and_more_so_far_away():
    model = LidarModel.carla(16, 256)
    image = np.full(model.shape, 60.0, dtype=np.float32)
    image[:, 128:] = 10.0
    rho = np.zeros(model.shape)
    rho[8:] = 0.5                                     # bright lower half
    effects = SensorEffects(**{**OFF, "dark_dropout": 1.0, "dark_reflectivity": 0.2})
    out = apply_sensor_effects(image, model, effects, 0, reflectivity=rho)
    lost = out == 0
    dark_far, dark_near = lost[:8, :128].mean(), lost[:8, 128:].mean()
    assert lost[8:].sum() == 0                        # bright: never lost
    assert abs(dark_far - 60.0 / 80.0) < 0.07 and abs(dark_near - 10.0 / 80.0) < 0.05
    # without a reflectivity, no dark dropouts
    assert (apply_sensor_effects(image, model, effects, 0) > 0).all()


def test_returns_near_max_range_fall_off():
    model = LidarModel.carla(16, 256)
    image = np.tile(np.linspace(1.0, 80.0, 256, dtype=np.float32), (16, 1))
    effects = SensorEffects(**{**OFF, "range_dropout": 1.0, "range_falloff": 0.5})
    lost = apply_sensor_effects(image, model, effects, 0) == 0
    assert lost[image < 40.0].sum() == 0
    assert lost[image > 78.0].mean() > 0.9
    assert 0.2 < lost[(image > 50) & (image < 70)].mean() < 0.6


def test_solid_reflectivity_by_kind():
    labels = ["ground", "car_cabin", "tree_crown", "unknown"] * 50
    rho = solid_reflectivity(labels, seed=3)
    assert_array_equal(rho, solid_reflectivity(labels, seed=3))
    assert not np.array_equal(rho, solid_reflectivity(labels, seed=4))
    for k, label in enumerate(labels[:4]):
        lo, hi = _effects.REFLECTIVITY.get(label, _effects.DEFAULT_REFLECTIVITY)
        assert ((rho[k::4] >= lo) & (rho[k::4] <= hi)).all()


@pytest.mark.parametrize("kwargs, exc, match", [
    ({"range_noise": -0.01}, ValueError, "range_noise"),
    ({"range_noise": float("nan")}, ValueError, "range_noise"),
    ({"grazing_dropout": 1.5}, ValueError, "grazing_dropout"),
    ({"dark_dropout": -0.1}, ValueError, "dark_dropout"),
    ({"range_dropout": float("nan")}, ValueError, "range_dropout"),
    ({"grazing_angle": 90.0}, ValueError, "grazing_angle"),
    ({"dark_reflectivity": 0.0}, ValueError, "dark_reflectivity"),
    ({"range_falloff": 1.0}, ValueError, "range_falloff"),
    ({"range_noise": "0.02"}, TypeError, "range_noise"),
    ({"grazing_dropout": True}, TypeError, "grazing_dropout"),
])
def test_sensor_effects_bad_input(kwargs, exc, match):
    with pytest.raises(exc, match=match):
        SensorEffects(**kwargs)


def test_apply_sensor_effects_bad_input(street):
    _, model, image, _ = street
    e = SensorEffects()
    with pytest.raises(TypeError, match="effects"):
        apply_sensor_effects(image, model, {"range_noise": 0.02}, 0)
    with pytest.raises(TypeError, match="model"):
        apply_sensor_effects(image, "carla", e, 0)
    with pytest.raises(TypeError, match="rng"):
        apply_sensor_effects(image, model, e, 0.5)
    with pytest.raises(ValueError, match="rng"):
        apply_sensor_effects(image, model, e, -1)
    with pytest.raises(ValueError, match="image must have shape"):
        apply_sensor_effects(image[:, :10], model, e, 0)
    bad = image.copy()
    bad[0, 0] = np.nan
    with pytest.raises(ValueError, match="image must be finite"):
        apply_sensor_effects(bad, model, e, 0)
    bad[0, 0] = -1.0
    with pytest.raises(ValueError, match="image must lie in"):
        apply_sensor_effects(bad, model, e, 0)
    with pytest.raises(ValueError, match="reflectivity must lie in"):
        apply_sensor_effects(image, model, e, 0, reflectivity=np.full(model.shape, 1.5))
    with pytest.raises(ValueError, match="reflectivity must have shape"):
        apply_sensor_effects(image, model, e, 0, reflectivity=np.zeros(3))
    with pytest.raises(ValueError, match="unknown SensorEffects fields"):
        SensorEffects.from_dict({"noise": 0.1})
    with pytest.raises(TypeError, match="fields"):
        SensorEffects.from_dict([("range_noise", 0.1)])
    with pytest.raises(TypeError, match="labels"):
        solid_reflectivity("ground")


def test_simulate_return_ids_bad_input(street):
    scene, model, _, _ = street
    pose = scene.random_poses(1, seed=2)[0]
    with pytest.raises(TypeError, match="return_ids"):
        simulate_range_image(scene, pose, model, return_ids=1)

    class RayCastOnly:
        def ray_cast(self, origin, dirs, max_range):
            return np.zeros(len(dirs)), np.zeros(len(dirs), dtype=bool)
    with pytest.raises(ValueError, match="return_ids"):
        simulate_range_image(RayCastOnly(), pose, model, return_ids=True)


# --------------------------------------------------------------------------- #
# make_dataset and load_shards
# --------------------------------------------------------------------------- #
def test_default_shards_are_exact_and_have_no_record(tmp_path):
    make_dataset(tmp_path, 1, 0, sizes=["16x1024"], images_per_scene=2, progress=False)
    (shard,) = sorted((tmp_path / "train").glob("*.npz"))
    with zipfile.ZipFile(shard) as zf:
        assert "simulation.npy" not in zf.namelist()
    images, meta = load_shards(tmp_path / "train", ["16x1024"], return_meta=True)
    assert meta["effects"] is None and meta["vegetation"] is False
    scene = outdoor_scene(0)
    for image, pose in zip(images["16x1024"], meta["poses"]):
        assert_array_equal(image, simulate_range_image(scene, pose, meta["model"]))


def test_shards_record_effects_and_vegetation(tmp_path):
    effects = SensorEffects(range_noise=0.03)
    make_dataset(tmp_path, 0, 1, sizes=["16x1024", "64x1024"], images_per_scene=2,
                 progress=False, effects=effects, vegetation=True, scene_size=40.0)
    images, meta = load_shards(tmp_path / "test", ["16x1024", "64x1024"], return_meta=True)
    assert meta["effects"] == effects and meta["vegetation"] is True
    assert meta["seeds"].tolist() == [100000, 100000]
    scene = outdoor_scene(100000, size=40.0, vegetation=True)
    clean = simulate_range_image(scene, meta["poses"][0], LidarModel.carla(64, 1024))
    noisy = images["64x1024"][0]
    both = (clean > 0) & (noisy > 0)
    assert 0.02 < np.std(noisy[both] - clean[both]) < 0.04
    assert ((noisy == 0) & (clean > 0)).any() and not ((noisy > 0) & (clean == 0)).any()
    # the same run again gives the same images (seeded per image)
    make_dataset(tmp_path / "again", 0, 1, sizes=["16x1024", "64x1024"], images_per_scene=2,
                 progress=False, effects=effects, vegetation=True, scene_size=40.0)
    again = load_shards(tmp_path / "again" / "test", ["16x1024", "64x1024"])
    assert_array_equal(again["64x1024"], images["64x1024"])


def test_effects_do_not_depend_on_the_chunking():
    models = [LidarModel.carla(16, 256)]
    whole, _ = data._chunk_images(0, 0, 3, 3, 0, [(16, 256)], models, 40.0, SensorEffects())
    a, _ = data._chunk_images(0, 0, 1, 3, 0, [(16, 256)], models, 40.0, SensorEffects())
    b, _ = data._chunk_images(0, 1, 3, 3, 0, [(16, 256)], models, 40.0, SensorEffects())
    assert_array_equal(whole["r16x256"], np.concatenate([a["r16x256"], b["r16x256"]]))


def test_table_sensor_keeps_every_4th_beam(tmp_path):
    lidar = LidarModel.hdl64e(table=True)
    make_dataset(tmp_path, 1, 0, sizes=["16x1024", "64x1024"], images_per_scene=1,
                 progress=False, model=lidar)
    images, meta = load_shards(tmp_path / "train", ["16x1024", "64x1024"], return_meta=True)
    assert_array_equal(images["16x1024"], images["64x1024"][:, ::4])
    kept, _ = kept_beams_model(lidar.with_size(64, 1024), 4)
    assert meta["models"][(16, 1024)] == kept == meta["model"]
    assert meta["models"][(64, 1024)] == lidar.with_size(64, 1024)
    with pytest.raises(ValueError, match="sizes: 128x2048 does not fit"):
        make_dataset(tmp_path / "bad", 1, 0, sizes=["128x2048"], model=lidar, progress=False)


def test_shards_of_different_simulations_or_bad_records_are_refused(tmp_path):
    make_dataset(tmp_path / "a", 1, 0, sizes=["16x1024"], images_per_scene=1, progress=False)
    make_dataset(tmp_path / "b", 1, 0, sizes=["16x1024"], images_per_scene=1, progress=False,
                 effects=SensorEffects())
    mixed = tmp_path / "mixed"
    mixed.mkdir()
    (mixed / "shard_00000.npz").write_bytes((tmp_path / "a/train/shard_00000.npz").read_bytes())
    (mixed / "shard_00001.npz").write_bytes((tmp_path / "b/train/shard_00000.npz").read_bytes())
    with pytest.raises(ValueError, match="simulation"):
        load_shards(mixed, ["16x1024"])
    with np.load(tmp_path / "b/train/shard_00000.npz") as z:
        entries = dict(z)
    for bad in ('{"effects": {"range_noise": -1}, "vegetation": false}', '[1]',
                '{"effects": null, "vegetation": 1}', '{"effects": null}', 'not json',
                '{"effects": null, "vegetation": false, "beams": {"16x1024": [0]}}'):
        entries["simulation"] = np.array(bad)
        folder = tmp_path / "bad"
        folder.mkdir(exist_ok=True)
        np.savez_compressed(folder / "shard_00000.npz", **entries)
        with pytest.raises(ValueError, match="not a valid occgp.iln shard: simulation"):
            load_shards(folder, ["16x1024"])


@pytest.mark.parametrize("kwargs, exc, match", [
    ({"effects": "yes"}, TypeError, "effects"),
    ({"effects": {"range_noise": 0.02}}, TypeError, "effects"),
    ({"vegetation": 1}, TypeError, "vegetation"),
])
def test_make_dataset_bad_effects(tmp_path, kwargs, exc, match):
    with pytest.raises(exc, match=match):
        make_dataset(tmp_path, 1, 0, sizes=["16x1024"], progress=False, **kwargs)


@pytest.mark.slow
def test_cli_realistic_dataset(tmp_path, capsys):
    from occgp.iln.cli import main

    status = main(["make-dataset", str(tmp_path), "--n-train", "1", "--n-test", "0",
                   "--images-per-scene", "1", "--effects", "--vegetation", "--sensor", "hdl64e",
                   "--no-progress"])
    assert status == 0 and "wrote 1 train" in capsys.readouterr().out
    images, meta = load_shards(tmp_path / "train", ["16x1024", "64x1024"], return_meta=True)
    assert meta["effects"] == SensorEffects() and meta["vegetation"] is True
    assert meta["models"][(64, 1024)].beam_elevations == \
        LidarModel.hdl64e(table=True).beam_elevations
    assert images["16x1024"].shape == (1, 16, 1024)
