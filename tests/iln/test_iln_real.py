"""Per-beam elevation tables, real frames as range images and real-frame scores (occgp.iln)."""

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from conftest import data_path
from occgp.iln import (
    LidarModel, format_real_table, frame_range_image, kept_beams_model, points_to_range_image,
    range_image_to_points, read_lidar_frame, real_frame_scores, scan_rings,
)
from occgp.iln._beam_tables import HDL64E_TABLE, OS1_64_TABLE

TABLE = (10.0, 7.0, 6.0, 2.0, -1.0, -1.5, -2.0, -8.0)   # made up, uneven pitches
FOV = (-10.0, 12.0)


def _table_model(cols=64):
    return LidarModel(len(TABLE), cols, FOV, 360.0, 80.0, TABLE)


# ---------------------------------------------------------------- the table in LidarModel
def test_table_rows_look_at_their_entries():
    m = _table_model()
    assert_array_equal(m.elevations(), TABLE)
    assert_array_equal(m.pixel_angles()[0][:, 0], TABLE)
    v, _ = m.angles_to_pixels(np.array(TABLE), 0.0)
    assert_allclose(v, np.arange(len(TABLE)) + 0.5, atol=1e-12)
    e = np.radians(np.array(TABLE))
    assert_allclose(m.directions()[:, 0, 2], np.sin(e))


def test_fractional_rows_interpolate_the_table_linearly():
    m = _table_model()
    e, _ = m.pixels_to_angles(np.array([0.0, 1.0, 1.25, 3.5, 8.0]), 0.0)
    assert_allclose(e, [12.0, 8.5, 7.75, 2.0, -10.0])
    # beyond the edges: the end segments extend
    e, _ = m.pixels_to_angles(np.array([-0.5, 8.5]), 0.0)
    assert_allclose(e, [14.0, -12.0])
    v, _ = m.angles_to_pixels(e, 0.0)
    assert_allclose(v, [-0.5, 8.5])
    vv = np.linspace(-1, 9, 101)
    assert_allclose(m.angles_to_pixels(m.pixels_to_angles(vv, 0.0)[0], 0.0)[0], vv, atol=1e-9)


def test_points_fall_in_the_row_of_the_nearest_beam():
    m = _table_model(cols=8)
    elev = np.array([9.0, 8.6, 8.4, -1.7, -1.8, -7.0])         # midpoints 8.5, -1.75
    e = np.radians(elev)
    pts = np.column_stack([10 * np.cos(e), np.zeros_like(e), 10 * np.sin(e)])
    rows = [np.flatnonzero(points_to_range_image(p[None], m).any(axis=1))[0] for p in pts]
    assert rows == [0, 0, 1, 5, 6, 7]


def test_uniform_table_matches_the_uniform_model():
    plain = LidarModel(16, 32, (-15.0, 15.0))
    table = LidarModel(16, 32, (-15.0, 15.0), beam_elevations=tuple(plain.elevations()))
    e = np.linspace(-20, 20, 57)
    assert_allclose(table.angles_to_pixels(e, 0.0)[0], plain.angles_to_pixels(e, 0.0)[0],
                    atol=1e-9)
    assert_allclose(table.with_size(64, 32).elevations(), plain.with_size(64, 32).elevations(),
                    atol=1e-9)


def test_with_size_and_json_keep_the_table():
    m = _table_model()
    assert m.with_size(8, 16).beam_elevations == TABLE
    big = m.with_size(16, 64)
    assert big.vertical_fov == FOV
    # new row k sits at fractional row (k + 0.5) / 2 of the old one
    assert_allclose(big.elevations()[[1, 2, 3]], m.pixels_to_angles(np.array([0.75, 1.25, 1.75]),
                                                                    0.0)[0])
    back = LidarModel.from_json(m.to_json(), 8, 64)
    assert back == m
    assert LidarModel.from_json(m.to_json(), 16, 64) == big
    assert "beam_elevations" not in LidarModel.carla().to_json()


@pytest.mark.parametrize("table, match", [
    ((1.0, 2.0, 0.0, -1.0, -2.0, -3.0, -4.0, -5.0), "decrease strictly"),
    ((1.0, 0.0), r"one elevation per row"),
    ((20.0, 7.0, 6.0, 2.0, -1.0, -1.5, -2.0, -8.0), "strictly inside vertical_fov"),
    ((np.nan,) * 8, "finite"),
])
def test_bad_tables(table, match):
    with pytest.raises(ValueError, match=match):
        LidarModel(8, 8, FOV, beam_elevations=table)
    with pytest.raises(TypeError, match="beam_elevations"):
        LidarModel(8, 8, FOV, beam_elevations="abc")


def test_presets():
    assert LidarModel.hdl64e() == LidarModel(64, 1024, (-24.8, 2.0), 360.0, 120.0)
    m = LidarModel.hdl64e(table=True)
    d = -np.diff(m.elevations())
    assert_allclose(d[:31], 1 / 3, atol=1e-3)
    assert_allclose(d[32:], 0.5, atol=1e-6)
    assert m.elevations()[0] == 2.0 and m.elevations()[-1] == -24.33
    assert m.beam_elevations == HDL64E_TABLE
    h = LidarModel.hdl32e(table=True)
    assert_allclose(h.elevations()[[0, -1]], [10.67, -30.67])
    assert_allclose(-np.diff(h.elevations()), 41.34 / 31, atol=1e-3)
    assert LidarModel.hdl32e() == LidarModel(32, 1024, (-30.67, 10.67), 360.0, 100.0)
    assert_allclose(LidarModel.vlp16().elevations(), np.linspace(15, -15, 16))
    assert LidarModel.os1_64().beam_elevations == OS1_64_TABLE
    assert LidarModel.os1_64(16, 512).rows == 16


def test_from_points_by_clustering_and_by_ring():
    rng = np.random.default_rng(0)
    row = rng.integers(0, len(TABLE), 3000)
    e = np.radians(np.array(TABLE)[row] + rng.normal(0, 0.02, row.size))
    a = rng.uniform(-np.pi, np.pi, row.size)
    pts = 20 * np.column_stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
    for ring in (None, row * 7 + 3):
        m = LidarModel.from_points(pts, len(TABLE), 256, ring=ring)
        assert_allclose(m.elevations(), TABLE, atol=0.01)
    with pytest.raises(ValueError, match="rings"):
        LidarModel.from_points(pts, 9, ring=row)


# ---------------------------------------------------------------- frames from points
def test_scan_rings_and_frame_range_image():
    m = LidarModel(len(TABLE), 90, FOV, 360.0, 80.0, TABLE)
    truth = np.full(m.shape, 15.0, dtype=np.float32)
    truth[:, ::7] = 0.0
    pts = range_image_to_points(truth, m)            # row-major: beam by beam, azimuth falls
    ring = scan_rings(pts)
    assert ring.max() == len(TABLE) - 1
    assert_array_equal(np.bincount(ring), (truth > 0).sum(axis=1))
    image, lidar = frame_range_image(pts, len(TABLE), ring=ring, cols=90, max_range=80.0)
    assert_allclose(lidar.elevations(), TABLE, atol=1e-9)
    assert_allclose(image, truth, atol=1e-4)


# ---------------------------------------------------------------- scoring
def _ground(lidar, height=1.7):
    """Range image of a flat ground `height` below the sensor (no return above the horizon)."""
    e = np.radians(lidar.pixel_angles()[0])
    with np.errstate(divide="ignore"):
        r = np.where(e < -0.01, height / np.sin(-np.clip(e, None, -1e-9)), 0.0)
    return np.where(r <= lidar.max_range, r, 0.0).astype(np.float32)


def test_kept_beams_model():
    m, kept = kept_beams_model(_table_model(), 2)
    assert kept.tolist() == [0, 2, 4, 6]
    assert m.beam_elevations == TABLE[::2] and m.vertical_fov == FOV
    with pytest.raises(ValueError, match="keep_every"):
        kept_beams_model(_table_model(), 1)


def test_inverse_bilinear_is_near_exact_on_the_ground_at_true_elevations():
    pytest.importorskip("torch")
    from occgp.iln import make, upsample_image
    net = make({"name": "inverse-bilinear", "args": {"max_range": 120.0}})
    lidar = LidarModel.hdl64e(64, 256, table=True)
    truth = _ground(lidar)
    kept_lidar, kept = kept_beams_model(lidar, 4)
    held = np.setdiff1d(np.arange(lidar.rows), kept)
    pred = upsample_image(net, truth[kept], kept_lidar, lidar)     # queries at the true beams
    # the dropped beams between two kept ones that both see the ground
    ground = kept[(truth[kept] > 0).all(axis=1)]
    inner = held[(held > ground[0]) & (held < kept[-1])]
    assert len(inner) >= 30
    rel = np.abs(pred[inner] - truth[inner]) / truth[inner]
    assert rel.max() < 2e-3
    # the same input read as 16 uniform rows misplaces the beams of the two blocks
    uniform = LidarModel(16, 256, lidar.vertical_fov, 360.0, lidar.max_range)
    wrong = upsample_image(net, truth[kept], uniform, lidar)
    assert np.abs(wrong[inner] - truth[inner]).mean() > 20 * np.abs(pred[inner] -
                                                                     truth[inner]).mean()
    rows = real_frame_scores({"ib": "inverse-bilinear", "b": "bilinear"}, truth, lidar)
    assert rows[0]["model"] == "ib" and rows[0]["mae"] < rows[1]["mae"]
    assert set(rows[0]) == {"model", "mae", "iou", "precision", "recall", "f1", "seconds"}
    assert "IoU / base" in format_real_table(rows, baseline="b")


def test_real_frame_scores_bad_input():
    lidar = _table_model()
    with pytest.raises(ValueError, match="shape"):
        real_frame_scores("bilinear", np.zeros((3, 3)), lidar)
    with pytest.raises(ValueError, match="no return"):
        real_frame_scores("bilinear", np.zeros(lidar.shape), lidar)
    with pytest.raises(TypeError, match="lidar"):
        real_frame_scores("bilinear", np.zeros(lidar.shape), "carla")
    pytest.importorskip("torch")
    image = np.full(lidar.shape, 10.0)
    with pytest.raises(ValueError, match="registered"):
        real_frame_scores("nearest", image, lidar)


# ---------------------------------------------------------------- the real frames
def test_os1_frame_rows_are_its_beams():
    path = data_path("lidar_frames", "os1_64_full.bin")
    image, lidar = read_lidar_frame(path, "os1-64")
    assert image.shape == (64, 2048)
    assert_allclose(lidar.elevations(), OS1_64_TABLE, atol=0.006)
    raw = np.fromfile(path, np.float32).reshape(2048, 64, 4)
    returns = (np.abs(raw[..., :3]).sum(-1) > 0).sum(axis=0)
    # every beam's returns land in its own row (a few share a pixel)
    assert ((image > 0).sum(axis=1) >= 0.95 * returns).all()
    same, _ = read_lidar_frame(path, "os1-64", beams="table")
    assert_array_equal(same > 0, image > 0)


def test_kitti_frame_scan_order_beams():
    path = data_path("lidar_frames", "kitti_hdl64e_front.bin")
    pts = np.fromfile(path, np.float32).reshape(-1, 4)[:, :3]
    assert scan_rings(pts).max() == 64                      # 65 sweeps: one cut in two
    image, lidar = read_lidar_frame(path, "hdl64e")
    e = lidar.elevations()
    assert image.shape == (64, 2048) and (image > 0).any(axis=1).all()
    # the two blocks: about 1/3 degree apart above, 1/2 degree below
    assert abs(np.median(-np.diff(e[:32])) - 1 / 3) < 0.05
    assert abs(np.median(-np.diff(e[33:])) - 0.5) < 0.05
    assert 2.0 < e[0] < 2.6 and -24.0 < e[-1] < -23.3
    nominal, lid = read_lidar_frame(path, "hdl64e", beams="table")
    assert lid.beam_elevations == HDL64E_TABLE
    assert (image > 0).sum() > (nominal > 0).sum()


@pytest.mark.parametrize("name, sensor", [("kitti_hdl64e_front.bin", "hdl64e"),
                                          ("os1_64_full.bin", "os1-64")])
def test_real_frame_scores_on_real_frames(name, sensor):
    pytest.importorskip("torch")
    image, lidar = read_lidar_frame(data_path("lidar_frames", name), sensor)
    rows = real_frame_scores(["bilinear", "inverse-bilinear"], image, lidar)
    b, ib = rows
    assert 0.3 < ib["mae"] < b["mae"] < 2.0
    assert 0.05 < b["iou"] < ib["iou"] < 0.5
