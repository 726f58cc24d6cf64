"""Range images of occgp.iln._range: the LidarModel, conversions and bad input."""

import dataclasses
import json

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from occgp.iln._range import (
    LidarModel,
    points_to_range_image,
    range_image_from_points,
    range_image_to_points,
)


def _random_image(model, rng, empty=0.3):
    image = rng.uniform(1.0, model.max_range, model.shape).astype(np.float32)
    image[rng.random(model.shape) < empty] = 0.0
    return image


# --------------------------------------------------------------------------- #
# the model
# --------------------------------------------------------------------------- #
def test_presets_and_with_size():
    m = LidarModel.carla()
    assert (m.rows, m.cols, m.vertical_fov, m.horizontal_fov, m.max_range) == \
        (16, 1024, (-15.0, 15.0), 360.0, 80.0)
    k = LidarModel.hdl64e()
    assert (k.rows, k.cols, k.vertical_fov, k.max_range) == (64, 1024, (-24.8, 2.0), 120.0)
    big = m.with_size(256, 4096)
    assert big.shape == (256, 4096) and big.vertical_fov == m.vertical_fov
    assert LidarModel.carla(64, 1024) == m.with_size(64, 1024)
    with pytest.raises(dataclasses.FrozenInstanceError):
        m.rows = 3


def test_angles_follow_the_conventions():
    m = LidarModel(4, 8, (-10.0, 10.0), 360.0, 50.0)
    assert_allclose(m.elevations(), [7.5, 2.5, -2.5, -7.5])
    assert_allclose(m.azimuths(), 180 - (np.arange(8) + 0.5) * 45)
    e, a = m.pixel_angles()
    assert e.shape == a.shape == (4, 8)
    assert_allclose(e[:, 0], m.elevations())
    assert_allclose(a[0], m.azimuths())
    v, u = m.angles_to_pixels(e, a)
    assert_allclose(v, np.arange(4)[:, None] + 0.5 + 0 * u)
    assert_allclose(u, np.arange(8)[None, :] + 0.5 + 0 * v)
    # +x forward is the middle of the image; +y (left) lies at smaller columns
    assert_allclose(m.angles_to_pixels(0.0, 0.0), (2.0, 4.0))
    assert m.angles_to_pixels(0.0, 90.0)[1] == 2.0
    # 360 degrees wrap
    assert_allclose(m.angles_to_pixels(0.0, 180.0)[1], 0.0)
    assert_allclose(m.angles_to_pixels(0.0, -179.999)[1], 8.0 - 0.001 / 45, atol=1e-9)
    ev, az = m.pixels_to_angles(v, u)
    assert_allclose(ev, e)
    assert_allclose((az - a + 180) % 360 - 180, 0.0, atol=1e-12)
    d = m.directions()
    assert d.shape == (4, 8, 3)
    assert_allclose(np.linalg.norm(d, axis=-1), 1.0)
    assert_allclose(np.degrees(np.arcsin(d[..., 2])), e)


def test_cropped_fov_leaves_u_outside():
    m = LidarModel(2, 4, (-10.0, 10.0), 90.0, 50.0)
    assert_allclose(m.azimuths(), [33.75, 11.25, -11.25, -33.75])
    assert m.angles_to_pixels(0.0, 60.0)[1] < 0
    assert m.angles_to_pixels(0.0, -60.0)[1] > 4
    assert m.angles_to_pixels(0.0, 330.0)[1] == m.angles_to_pixels(0.0, -30.0)[1]


def test_json_round_trip():
    m = LidarModel(8, 64, (-24.8, 2.0), 270.0, 120.0)
    text = m.to_json()
    assert set(json.loads(text)) == {"vertical_fov", "horizontal_fov", "max_range"}
    assert LidarModel.from_json(text, 8, 64) == m
    assert LidarModel.from_json(text, 16, 32) == m.with_size(16, 32)


# --------------------------------------------------------------------------- #
# conversions
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("model", [LidarModel.carla(8, 64), LidarModel.hdl64e(16, 32),
                                   LidarModel(5, 7, (-30.0, 20.0), 120.0, 30.0)])
def test_round_trip_is_exact(model):
    image = _random_image(model, np.random.default_rng(0))
    points, pixels = range_image_to_points(image, model, return_pixels=True)
    assert points.shape == (np.count_nonzero(image), 3)
    assert_array_equal(pixels, np.argwhere(image > 0))
    assert_allclose(np.linalg.norm(points, axis=1), image[image > 0], rtol=1e-6)
    assert_array_equal(points_to_range_image(points, model), image)
    assert_array_equal(range_image_from_points(points, model), image)
    assert_array_equal(range_image_to_points(image, model), points)
    # float32 points too
    assert_array_equal(points_to_range_image(points.astype(np.float32), model)
                       > 0, image > 0)


def test_nearest_return_per_pixel_and_drops():
    m = LidarModel(4, 8, (-10.0, 10.0), 360.0, 50.0)
    d = m.directions()[1, 3]
    points = np.array([12.0 * d, 7.0 * d, 9.0 * d,          # one pixel, nearest kept
                       60.0 * m.directions()[2, 5],          # beyond max_range
                       [10.0, 0.0, 5.0],                     # above the field of view
                       [0.0, 0.0, 0.0]])                     # at the origin
    image = points_to_range_image(points, m)
    assert image.dtype == np.float32 and image.shape == (4, 8)
    expected = np.zeros((4, 8), np.float32)
    expected[1, 3] = 7.0
    assert_array_equal(image, expected)
    # the bottom edge belongs to the last row; the top edge to row 0
    low = [np.cos(np.radians(10.0)), 0.0, -np.sin(np.radians(10.0))]
    high = [np.cos(np.radians(10.0)), 0.0, np.sin(np.radians(10.0))]
    image = points_to_range_image(np.array([low, high]) * 5.0, m)
    assert image[3].any() and image[0].any()
    assert not points_to_range_image(np.empty((0, 3)), m).any()


def test_cropped_fov_drops_points_behind():
    m = LidarModel(2, 4, (-10.0, 10.0), 90.0, 50.0)
    image = points_to_range_image([[-10.0, 0.0, 0.0], [0.0, 10.0, 0.0], [10.0, 0.1, 0.0]], m)
    assert np.count_nonzero(image) == 1 and image[1, 1] == np.float32(np.hypot(10, 0.1))


def test_range_image_from_points_ring():
    m = LidarModel.hdl32e(rows=32, cols=16)
    rng = np.random.default_rng(0)
    n = 200
    ring = rng.integers(0, 32, n)
    az = rng.uniform(-np.pi, np.pi, n)
    r = rng.uniform(2, 50, n)
    el = np.radians(-30 + ring * 1.33)
    points = np.column_stack([r * np.cos(el) * np.cos(az), r * np.cos(el) * np.sin(az),
                              r * np.sin(el)])
    image = range_image_from_points(points, m, ring=ring.astype(np.float32))
    # bottom_up: ring 0 -> the last row; each pixel the nearest of its points
    rows = 31 - ring
    cols = np.floor(((180 - np.degrees(az)) % 360) / 360 * 16).astype(int)
    expected = np.zeros((32, 16))
    for i, j, rr in sorted(zip(rows, cols, r), key=lambda t: -t[2]):
        expected[i, j] = rr
    assert_allclose(image, expected.astype(np.float32))
    top = range_image_from_points(points, m, ring=ring, ring_order="top_down")
    assert_array_equal(top, image[::-1])


# --------------------------------------------------------------------------- #
# bad input
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("kwargs, exc, match", [
    (dict(rows=0, cols=8), ValueError, r"rows must lie in \[1, 65536\], got 0"),
    (dict(rows=8, cols=10**6), ValueError, r"cols must lie in \[1, 65536\]"),
    (dict(rows=65536, cols=65536), ValueError, r"rows \* cols must be at most"),
    (dict(rows=4097, cols=4096), ValueError, r"rows \* cols must be at most 16777216 pixels, "
                                             r"got 4097 x 4096"),
    (dict(rows=8.0, cols=8), TypeError, r"rows must be a positive int, got float"),
    (dict(rows=True, cols=8), TypeError, r"rows must be a positive int, got bool"),
    (dict(rows=8, cols=8, vertical_fov=(10, -10)), ValueError, r"vertical_fov must satisfy"),
    (dict(rows=8, cols=8, vertical_fov=(-100, 10)), ValueError, r"vertical_fov must satisfy"),
    (dict(rows=8, cols=8, vertical_fov=(np.nan, 10)), ValueError, r"vertical_fov must satisfy"),
    (dict(rows=8, cols=8, vertical_fov=15), TypeError, r"vertical_fov must be a pair"),
    (dict(rows=8, cols=8, vertical_fov=("a", 1)), TypeError, r"vertical_fov\[0\] must be a real"),
    (dict(rows=8, cols=8, horizontal_fov=0), ValueError, r"horizontal_fov must lie in \(0, 360\]"),
    (dict(rows=8, cols=8, horizontal_fov=400), ValueError, r"horizontal_fov must lie in"),
    (dict(rows=8, cols=8, max_range=-1), ValueError, r"max_range must lie in \(0, 100000\]"),
    (dict(rows=8, cols=8, max_range=np.inf), ValueError, r"max_range must lie in"),
    (dict(rows=8, cols=8, max_range=1e30), ValueError, r"max_range must lie in"),
    (dict(rows=8, cols=8, max_range="80"), TypeError, r"max_range must be a real number"),
])
def test_bad_model(kwargs, exc, match):
    with pytest.raises(exc, match=match):
        LidarModel(**kwargs)


def test_bad_json():
    with pytest.raises(ValueError, match="not valid JSON"):
        LidarModel.from_json("{", 8, 8)
    with pytest.raises(ValueError, match="keys"):
        LidarModel.from_json('{"max_range": 80}', 8, 8)
    with pytest.raises(TypeError, match="text must be a JSON str"):
        LidarModel.from_json(b"{}", 8, 8)


M = LidarModel.carla(8, 64)


@pytest.mark.parametrize("call, exc, match", [
    (lambda: points_to_range_image(np.zeros((5, 2)), M), ValueError,
     r"points must have shape \(n_points, 3\), got \(5, 2\)"),
    (lambda: points_to_range_image([[np.nan, 0, 0]], M), ValueError, r"points must be finite"),
    (lambda: points_to_range_image([[1e30, 0, 0]], M), ValueError, r"magnitude at most 1e15"),
    (lambda: points_to_range_image([["a", "b", "c"]], M), TypeError, r"points must hold real"),
    (lambda: points_to_range_image(np.zeros((1, 3)), (8, 64)), TypeError,
     r"model must be a LidarModel, got tuple"),
    (lambda: range_image_to_points(np.zeros((8, 32)), M), ValueError,
     r"image must have shape \(8, 64\).*got \(8, 32\)"),
    (lambda: range_image_to_points(np.zeros((0, 64)), M), ValueError, r"image must have shape"),
    (lambda: range_image_to_points(np.full((8, 64), np.nan), M), ValueError,
     r"image must be finite"),
    (lambda: range_image_to_points(np.full((8, 64), -1.0), M), ValueError,
     r"image must hold ranges >= 0"),
    (lambda: range_image_to_points(np.full((8, 64), 81.0), M), ValueError,
     r"beyond the model's max_range=80.0"),
    (lambda: range_image_to_points(np.zeros((8, 64)), M, return_pixels=1), TypeError,
     r"return_pixels must be a bool"),
    (lambda: range_image_to_points(np.zeros((8, 64), dtype=complex), M), TypeError,
     r"image must hold real numbers"),
    (lambda: range_image_from_points(np.ones((3, 3)), M, ring=[0, 1]), ValueError,
     r"ring must have shape \(n_points,\) = \(3,\), got \(2,\)"),
    (lambda: range_image_from_points(np.ones((2, 3)), M, ring=[0, 8]), ValueError,
     r"ring must lie in \[0, 8\)"),
    (lambda: range_image_from_points(np.ones((2, 3)), M, ring=[0, -1]), ValueError,
     r"ring must lie in \[0, 8\)"),
    (lambda: range_image_from_points(np.ones((2, 3)), M, ring=[0, 0.5]), ValueError,
     r"ring must hold integers"),
    (lambda: range_image_from_points(np.ones((2, 3)), M, ring=[0, np.nan]), ValueError,
     r"ring must be finite"),
    (lambda: range_image_from_points(np.ones((2, 3)), M, ring=["a", "b"]), TypeError,
     r"ring must hold real numbers"),
    (lambda: range_image_from_points(np.ones((2, 3)), M, ring_order="up"), ValueError,
     r"ring_order must be one of"),
    (lambda: M.angles_to_pixels(np.nan, 0.0), ValueError, r"elevation must be finite"),
    (lambda: M.angles_to_pixels([1.0, 2.0], [1.0, 2.0, 3.0]), ValueError, r"must broadcast"),
])
def test_bad_input(call, exc, match):
    with pytest.raises(exc, match=match):
        call()


# --------------------------------------------------------------------------- #
# nuScenes ring index (occgp.io.read_kitti_bin(..., return_fields=True))
# --------------------------------------------------------------------------- #
def test_read_nuscenes_ring_into_range_image(tmp_path):
    from occgp.io import read_kitti_bin

    m = LidarModel.hdl32e(rows=32, cols=64)
    rng = np.random.default_rng(1)
    n = 300
    ring = rng.integers(0, 32, n)
    az = rng.uniform(-np.pi, np.pi, n)
    r = rng.uniform(2, 60, n)
    el = np.radians(-30.67 + ring * 41.34 / 31)
    records = np.column_stack([r * np.cos(el) * np.cos(az), r * np.cos(el) * np.sin(az),
                               r * np.sin(el), rng.uniform(0, 255, n), ring]).astype(np.float32)
    records[5, 0] = np.nan                                  # dropped with its fields
    path = tmp_path / "n008__LIDAR_TOP__1.pcd.bin"
    records.tofile(path)
    scan, extra = read_kitti_bin(path, return_fields=True)
    assert sorted(extra) == ["intensity", "ring"]
    assert extra["ring"].dtype == np.int64 and extra["intensity"].dtype == np.float32
    keep = np.arange(n) != 5
    assert_array_equal(extra["ring"], ring[keep])
    assert_array_equal(extra["intensity"], records[keep, 3])
    assert len(scan.points) == n - 1
    image = range_image_from_points(scan.points, m, ring=extra["ring"])
    assert_array_equal(np.flatnonzero(image.any(axis=1)), np.unique(31 - ring[keep]))
    # KITTI names its fourth field; int layouts f3, f4, ...
    records[:, :4].copy().tofile(tmp_path / "k.bin")
    assert list(read_kitti_bin(tmp_path / "k.bin", return_fields=True)[1]) == ["reflectance"]
    assert list(read_kitti_bin(path, fields=5, return_fields=True)[1]) == ["f3", "f4"]
    assert isinstance(read_kitti_bin(path), type(scan))


def test_read_nuscenes_bad_ring(tmp_path):
    from occgp.io import read_kitti_bin

    path = tmp_path / "bad.pcd.bin"
    np.array([[1, 2, 3, 4, 2.5]], dtype=np.float32).tofile(path)
    with pytest.raises(ValueError, match=r"bad.pcd.bin: the ring field must hold integer laser "
                                         r"indices, found 2.5"):
        read_kitti_bin(path, return_fields=True)
    read_kitti_bin(path)                                       # points alone are fine
    with pytest.raises(TypeError, match="return_fields must be a bool, got str"):
        read_kitti_bin(path, return_fields="yes")
