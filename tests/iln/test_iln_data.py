"""Training data of occgp.iln: simulated range images, shards, and the CLI."""

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from occgp.datasets import outdoor_scene, structured_room
from occgp.datasets._geometry import rotation_matrix
from occgp.iln._range import LidarModel, points_to_range_image, range_image_to_points
from occgp.iln.data import simulate_range_image


@pytest.fixture(scope="module")
def scene():
    return outdoor_scene(seed=2, size=50)


def _reference(scene, pose, model):
    dirs = (model.directions() @ pose[:3, :3].T).reshape(-1, 3)
    d, hit = scene.ray_cast(pose[:3, 3], dirs, model.max_range)
    return np.where(hit, d, 0.0).reshape(model.shape).astype(np.float32)


def _tilted(origin, yaw, pitch=0.15, roll=-0.1):
    pose = np.eye(4)
    pose[:3, :3] = rotation_matrix(yaw, pitch, roll)
    pose[:3, 3] = origin
    return pose


# --------------------------------------------------------------------------- #
# ray casting
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("model", [
    LidarModel.carla(8, 64), LidarModel.hdl64e(16, 96),
    LidarModel(8, 48, (-30.0, 20.0), 120.0, 40.0),      # cropped, looking along +x
    LidarModel(6, 40, (-20.0, 10.0), 300.0, 60.0),      # cropped, wrapping behind
])
@pytest.mark.parametrize("which", [0, 1, 2])
def test_simulate_equals_ray_cast(scene, model, which):
    poses = [scene.trajectory(5)[1], _tilted([2.0, -1.0, 2.5], 2.5),
             _tilted([scene.cross_x, 10.0, 1.7], -1.2, 0.0, 0.0)]
    pose = poses[which]
    image = simulate_range_image(scene, pose, model)
    assert image.dtype == np.float32 and image.shape == model.shape
    assert_array_equal(image, _reference(scene, pose, model))
    assert image.any()


def test_simulate_origin_heading_and_other_scenes(scene):
    model = LidarModel.carla(8, 64)
    pose = np.eye(4)
    pose[:2, :2] = [[np.cos(0.4), -np.sin(0.4)], [np.sin(0.4), np.cos(0.4)]]
    pose[:3, 3] = [1.0, -1.5, 1.7]
    assert_array_equal(simulate_range_image(scene, ([1.0, -1.5, 1.7], 0.4), model),
                       simulate_range_image(scene, pose, model))
    # the ground is seen all around in the bottom row, the sky above the open road
    image = simulate_range_image(scene, pose, model)
    assert (image[-1] > 0).all()
    flat = 1.7 / np.sin(np.radians(15 - 30 / 16))             # the road, where nothing stands
    assert np.mean(np.isclose(image[-1], flat, rtol=1e-6)) > 0.8 and image[-1].max() <= np.float32(flat)
    # rooms work too (their solids), and any object with ray_cast
    room = structured_room()
    room_pose = ([0.0, 0.0, 1.0], 0.0)
    image = simulate_range_image(room, room_pose, model)
    assert_array_equal(image, _reference(room, _tilted([0.0, 0.0, 1.0], 0.0, 0.0, 0.0), model))

    class Caster:
        def ray_cast(self, origin, dirs, max_range):
            return np.full(len(dirs), 5.0), dirs[:, 2] < 0

    image = simulate_range_image(Caster(), room_pose, model)
    assert_array_equal(image, np.where(model.pixel_angles()[0] < 0, 5.0, 0.0))
    # the image's points lie on the scene's surfaces
    img = simulate_range_image(scene, pose, LidarModel.carla(16, 128))
    points = range_image_to_points(img, LidarModel.carla(16, 128)) @ pose[:3, :3].T + pose[:3, 3]
    assert np.abs(scene.signed_distance(points)).max() < 1e-6
    assert_array_equal(points_to_range_image(
        (points - pose[:3, 3]) @ pose[:3, :3], LidarModel.carla(16, 128)), img)


def test_simulate_beyond_max_range_is_no_return(scene):
    near = LidarModel(8, 64, (-15.0, 15.0), 360.0, 5.0)
    image = simulate_range_image(scene, scene.trajectory(3)[1], near)
    assert image.max() <= 5.0 and (image == 0).any()
    far = simulate_range_image(scene, scene.trajectory(3)[1],
                               LidarModel(8, 64, (-15.0, 15.0), 360.0, 80.0))
    assert_array_equal(image, np.where(far <= 5.0, far, 0.0))


@pytest.mark.parametrize("pose, exc, match", [
    (np.eye(3), ValueError, r"pose must be a \(4, 4\) sensor-to-world matrix or an "
                            r"\(origin, heading\) pair, got shape \(3, 3\)"),
    (np.full((4, 4), np.nan), ValueError, r"pose must be finite"),
    (np.diag([2.0, 1.0, 1.0, 1.0]), ValueError, r"pose must be a rigid transform"),
    (np.diag([1.0, 1.0, -1.0, 1.0]), ValueError, r"pose must be a rigid transform"),
    (np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [1, 0, 0, 1.0]]), ValueError,
     r"pose must be a rigid transform"),
    (([1e30, 0, 0], 0.0), ValueError, r"pose translation must have coordinates of magnitude"),
    (([0, 0], 0.0), ValueError, r"pose origin must have shape \(3,\), got \(2,\)"),
    (([0, 0, 0], "north"), TypeError, r"pose heading must be a real number"),
    (([0, 0, 0], np.nan), ValueError, r"pose origin and heading must be finite"),
    ("pose", TypeError, r"pose must hold real numbers"),
])
def test_simulate_bad_pose(scene, pose, exc, match):
    with pytest.raises(exc, match=match):
        simulate_range_image(scene, pose, LidarModel.carla(8, 64))


def test_simulate_bad_scene_or_model(scene):
    with pytest.raises(TypeError, match="model must be a LidarModel, got tuple"):
        simulate_range_image(scene, np.eye(4), (8, 64))
    with pytest.raises(TypeError, match="scene must list analytic solids or have a ray_cast"):
        simulate_range_image(object(), np.eye(4), LidarModel.carla(8, 64))


# --------------------------------------------------------------------------- #
# shards
# --------------------------------------------------------------------------- #
import io  # noqa: E402
import json  # noqa: E402
import zipfile  # noqa: E402

from occgp.iln.cli import main  # noqa: E402
from occgp.iln.data import FORMAT, TEST_SEED_OFFSET, load_shards, make_dataset  # noqa: E402


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    folder = tmp_path_factory.mktemp("iln") / "data"
    counts = make_dataset(folder, 2, 1, ["16x1024", "64x1024"], images_per_scene=2,
                          images_per_shard=3, scene_size=30, progress=False)
    return folder, counts


def test_make_dataset_writes_and_reads_back(dataset):
    folder, counts = dataset
    assert counts == {"train": 4, "test": 2, "shards": 3}
    assert sorted(p.name for p in (folder / "train").iterdir()) == ["shard_00000.npz",
                                                                    "shard_00001.npz"]
    images, meta = load_shards(folder / "train", ["16x1024", (64, 1024)], return_meta=True)
    assert images[(16, 1024)].shape == (4, 16, 1024) and images["64x1024"].shape == (4, 64, 1024)
    assert images[(16, 1024)].dtype == np.float32
    assert_array_equal(meta["seeds"], [0, 0, 1, 1])
    assert meta["poses"].shape == (4, 4, 4)
    assert meta["model"] == LidarModel.carla(16, 1024)
    test_images, test_meta = load_shards(folder / "test", ["64x1024"], return_meta=True)
    assert_array_equal(test_meta["seeds"], [TEST_SEED_OFFSET] * 2)
    # each image is the simulation of its pose in its scene, the sizes share the pose
    scene = outdoor_scene(1, size=30)
    for size in [(16, 1024), (64, 1024)]:
        expected = simulate_range_image(scene, meta["poses"][3], LidarModel.carla(*size))
        assert_array_equal(images[size][3], expected)
    with np.load(folder / "train" / "shard_00000.npz") as z:
        assert sorted(z.files) == ["format", "lidar", "poses", "r16x1024", "r64x1024", "seeds",
                                   "version"]
        assert z["format"].item() == FORMAT and z["version"].item() == 1
        assert json.loads(z["lidar"].item()) == {"vertical_fov": [-15.0, 15.0],
                                                 "horizontal_fov": 360.0, "max_range": 80.0}
        assert zipfile.ZipFile(folder / "train" / "shard_00000.npz").infolist()[0].compress_type \
            == zipfile.ZIP_DEFLATED


def test_make_dataset_is_seeded_and_refuses_to_overwrite(dataset, tmp_path):
    folder, _ = dataset
    with pytest.raises(ValueError, match=r"already holds 2 shards; pass overwrite=True"):
        make_dataset(folder, 1, 0, ["16x1024"], images_per_scene=1, progress=False)
    make_dataset(tmp_path, 1, 0, ["16x1024"], images_per_scene=2, scene_size=30, progress=False)
    again = load_shards(tmp_path / "train", ["16x1024"])["16x1024"]
    assert_array_equal(again, load_shards(folder / "train", ["16x1024"])["16x1024"][:2])
    make_dataset(tmp_path, 1, 0, ["16x1024"], images_per_scene=2, scene_size=30, seed=1,
                 overwrite=True, progress=False)
    other = load_shards(tmp_path / "train", ["16x1024"])["16x1024"]
    assert other.shape == again.shape and not np.array_equal(other, again)
    # two workers write the same shards
    import joblib

    with joblib.parallel_config(backend="threading"):
        make_dataset(tmp_path, 2, 0, ["16x1024"], images_per_scene=1, scene_size=30, seed=1,
                     overwrite=True, n_jobs=2, progress=False)
    assert_array_equal(load_shards(tmp_path / "train", ["16x1024"])["16x1024"][:1], other[:1])


def test_make_dataset_chunks_scenes_across_shards(tmp_path):
    counts = make_dataset(tmp_path, 1, 0, ["16x1024"], images_per_scene=9, images_per_shard=5,
                          scene_size=30, seed=4, progress=False)
    assert counts == {"train": 9, "test": 0, "shards": 2}
    images, meta = load_shards(tmp_path / "train", ["16x1024"], return_meta=True)
    assert images["16x1024"].shape == (9, 16, 1024)
    from occgp.iln.data import _pose_seed

    scene = outdoor_scene(0, size=30)
    assert_array_equal(meta["poses"], scene.random_poses(9, seed=_pose_seed(4, 0)))
    assert_array_equal(images["16x1024"][8],
                       simulate_range_image(scene, meta["poses"][8], LidarModel.carla()))
    assert not (tmp_path / "test").exists() or not any((tmp_path / "test").iterdir())


def _shard_bytes(**changes):
    """A valid 1-image 16x1024 shard, with `changes` applied (None deletes a key)."""
    entries = {"r16x1024": np.zeros((1, 16, 1024), np.float32), "seeds": np.zeros(1, np.int64),
               "poses": np.eye(4)[None], "lidar": np.array(LidarModel.carla().to_json()),
               "format": np.array(FORMAT), "version": np.array(1, np.int64)}
    entries.update(changes)
    buf = io.BytesIO()
    np.savez_compressed(buf, **{k: v for k, v in entries.items() if v is not None})
    return buf.getvalue()


@pytest.mark.parametrize("content, match", [
    (b"hello", r"not a valid occgp.iln shard \(not a .npz / zip file\)"),
    (_shard_bytes()[:-40], r"not a valid occgp.iln shard"),
    (_shard_bytes(format=np.array("numpy.stuff")), r"format is 'numpy.stuff', expected"),
    (_shard_bytes(format=None), r"missing \['format'\]"),
    (_shard_bytes(version=np.array(2, np.int64)), r"shard version 2 is not supported"),
    (_shard_bytes(version=np.array(1.0)), r"version must have dtype int64, got float64"),
    (_shard_bytes(seeds=np.zeros(2, np.int64)), r"poses has a wrong shape \(1, 4, 4\)"),
    (_shard_bytes(seeds=np.zeros(1, np.int32)), r"seeds must be int64 of shape \(n,\)"),
    (_shard_bytes(r16x1024=np.zeros((1, 16, 1024))), r"r16x1024 must have dtype float32"),
    (_shard_bytes(r16x1024=np.zeros((1, 16, 512), np.float32)), r"r16x1024 has a wrong shape"),
    (_shard_bytes(r16x1024=np.full((1, 16, 1024), np.nan, np.float32)),
     r"16x1024 images must be finite ranges in \[0, 80.0\]"),
    (_shard_bytes(r16x1024=np.full((1, 16, 1024), -1, np.float32)), r"must be finite ranges"),
    (_shard_bytes(r16x1024=None, r64x1024=np.zeros((1, 64, 1024), np.float32)),
     r"the shard has no 16x1024 images \(it has 64x1024\)"),
    (_shard_bytes(poses=np.full((1, 4, 4), np.inf)), r"poses hold NaN or inf"),
    (_shard_bytes(lidar=np.array("{")), r"lidar: text is not valid JSON"),
    (_shard_bytes(lidar=np.array('{"max_range": 80}')), r"lidar: text must be a JSON object"),
    (_shard_bytes(lidar=np.array(3)), r"lidar must be a 0-d str"),
    (_shard_bytes(seeds=np.array([object()], dtype=object)), r"seeds must be int64"),
])
def test_load_shards_rejects_foreign_or_corrupt_files(tmp_path, content, match):
    (tmp_path / "shard_00000.npz").write_bytes(_shard_bytes())
    (tmp_path / "shard_00001.npz").write_bytes(content)
    with pytest.raises(ValueError, match=r"shard_00001.npz: .*" + match):
        load_shards(tmp_path, ["16x1024"])


def test_load_shards_bad_folder_or_sizes(tmp_path, dataset):
    folder, _ = dataset
    with pytest.raises(ValueError, match=r"no .npz shards in the folder; read .*train or .*test"):
        load_shards(folder, ["16x1024"])
    with pytest.raises(FileNotFoundError, match="no such directory"):
        load_shards(tmp_path / "missing", ["16x1024"])
    (tmp_path / "f.npz").write_bytes(_shard_bytes())
    with pytest.raises(NotADirectoryError):
        load_shards(tmp_path / "f.npz", ["16x1024"])
    other = LidarModel.hdl64e().to_json()
    (tmp_path / "g.npz").write_bytes(_shard_bytes(lidar=np.array(other)))
    with pytest.raises(ValueError, match=r"g.npz: its sensor .* differs from that of .*f.npz"):
        load_shards(tmp_path, ["16x1024"])
    for sizes, exc, match in [
        (["16x512"], ValueError, r"size must be one of 16x1024, 64x1024, 128x2048, 256x4096"),
        (["big"], ValueError, r"size must look like '64x1024'"),
        ("16x1024", TypeError, r"sizes must be a sequence of sizes"),
        ([], ValueError, r"sizes must name at least one size"),
        (["16x1024", (16, 1024)], ValueError, r"sizes must not repeat a size"),
        ([16], TypeError, r"size must be a str like '64x1024' or a \(rows, cols\) pair"),
    ]:
        with pytest.raises(exc, match=match):
            load_shards(folder / "train", sizes)


@pytest.mark.parametrize("kwargs, exc, match", [
    (dict(n_train=-1), ValueError, r"n_train must lie in \[0, 100000\], got -1"),
    (dict(n_train=0, n_test=0), ValueError, r"n_train and n_test must not both be 0"),
    (dict(n_test=10**6), ValueError, r"n_test must lie in \[0, 100000\]"),
    (dict(n_train=1.5), TypeError, r"n_train must be a non-negative int, got float"),
    (dict(images_per_scene=0), ValueError, r"images_per_scene must lie in \[1, 10000\]"),
    (dict(images_per_shard=0), ValueError, r"images_per_shard must lie in \[1, 1000000\]"),
    (dict(seed=-3), ValueError, r"seed must be a non-negative int"),
    (dict(sizes=["8x64"]), ValueError, r"size must be one of"),
    (dict(model="carla"), TypeError, r"model must be a LidarModel or None, got str"),
    (dict(scene_size=1e30), ValueError, r"scene_size must lie in \[30.0, 400.0\]"),
    (dict(overwrite="yes"), TypeError, r"overwrite must be a bool"),
    (dict(progress="yes"), TypeError, r"progress must be a bool or None"),
    (dict(sizes=["256x4096", "16x1024"], images_per_shard=600), ValueError,
     r"images_per_shard=600 images of 4259840 bytes \(all sizes\) exceed 2147483648 bytes"),
    (dict(n_jobs=0), ValueError, r"n_jobs must be None, a positive int or a negative int"),
    (dict(folder=3), TypeError, r"folder must be a str or os.PathLike, got int"),
])
def test_make_dataset_bad_input(tmp_path, kwargs, exc, match):
    args = dict(folder=tmp_path, n_train=1, n_test=0, sizes=["16x1024"], progress=False)
    args.update(kwargs)
    with pytest.raises(exc, match=match):
        make_dataset(**args)
    assert not any(tmp_path.iterdir())                  # nothing written


def test_cli_make_dataset(tmp_path, capsys):
    rc = main(["make-dataset", str(tmp_path), "--n-train", "1", "--n-test", "1", "--sizes",
               "16x1024", "--images-per-scene", "1", "--seed", "2", "--no-progress"])
    assert rc == 0
    assert "wrote 1 train and 1 test images (2 shards)" in capsys.readouterr().out
    assert load_shards(tmp_path / "test", ["16x1024"])["16x1024"].shape == (1, 16, 1024)
    # a second run refuses to overwrite: status 1 and a message
    rc = main(["make-dataset", str(tmp_path), "--n-train", "1", "--n-test", "0", "--sizes",
               "16x1024", "--images-per-scene", "1", "--no-progress"])
    assert rc == 1 and "already holds 1 shards" in capsys.readouterr().err
    for argv, match in [
        (["make-dataset", str(tmp_path), "--n-train", "1", "--n-test", "1", "--sizes", "8x8"],
         "size must be one of"),
        (["make-dataset", str(tmp_path), "--n-train", "-1", "--n-test", "1"],
         "expected a non-negative int"),
        (["make-dataset", str(tmp_path), "--n-test", "1"], "--n-train"),
        ([], "COMMAND"),
    ]:
        with pytest.raises(SystemExit) as info:
            main(argv)
        assert info.value.code == 2 and match in capsys.readouterr().err
