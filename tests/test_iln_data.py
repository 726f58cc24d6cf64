"""Training data of occgp.iln: simulated range images, shards, and the CLI."""

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

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
