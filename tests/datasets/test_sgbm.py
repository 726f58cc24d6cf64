"""Clouds from rendered stereo pairs matched by OpenCV's StereoSGBM (occgp.datasets._sgbm)."""

import numpy as np
import pytest

from occgp.datasets import (SGBM_DEFAULT, SGBM_GRID, PointErrors, Scan, StereoRig,
                            disparity_to_points, match_stereo, naive_fdr, point_errors,
                            rank_sgbm_sets, render_orbit, rendered_stereo_datasets,
                            sgbm_parameter_sets, stereo_scans, tetromino_scene)

cv2 = pytest.importorskip("cv2", reason="StereoSGBM needs the stereo extra (opencv-python-headless)")

SMALL = StereoRig(width=240, height=136, focal_length=126.45)


@pytest.fixture(scope="module")
def scene():
    return tetromino_scene("T", texture=True, environment="buildings")


@pytest.fixture(scope="module")
def pairs(scene):
    return render_orbit(scene, SMALL, n_frames=3, orbits=1, truth=True)


def test_parameter_grid_is_the_authors():
    sets = sgbm_parameter_sets()
    assert len(sets) == 1600 == np.prod([len(v) for v in SGBM_GRID.values()])
    assert len({tuple(s.values()) for s in sets}) == 1600
    assert SGBM_GRID["blockSize"] == (3, 7, 11, 15)
    assert SGBM_GRID["disp12MaxDiff"] == (0, 1)
    assert SGBM_GRID["uniquenessRatio"] == (5, 15, 25, 35)
    assert SGBM_GRID["speckleRange"] == (1, 2)
    assert min(SGBM_GRID["preFilterCap"]) == 10 and max(SGBM_GRID["preFilterCap"]) == 50
    assert SGBM_DEFAULT in sets
    sub = sgbm_parameter_sets(40, seed=3)
    assert len(sub) == 40 and all(s in sets for s in sub)
    assert sub == sgbm_parameter_sets(40, seed=3) != sgbm_parameter_sets(40, seed=4)
    # grid order kept
    idx = [sets.index(s) for s in sub]
    assert idx == sorted(idx)


def test_match_stereo_recovers_a_shift():
    rng = np.random.default_rng(0)
    left = rng.integers(0, 256, (60, 240), dtype=np.uint8)
    right = np.roll(left, -17, axis=1)
    d = match_stereo(left, right, {"blockSize": 5, "uniquenessRatio": 5})
    valid = np.isfinite(d)
    assert valid[:, 100:220].mean() > 0.9
    assert np.abs(d[valid][100:] - 17).max() < 1.0
    assert d.dtype == np.float32
    # the left border (no match possible within 80 disparities) has none
    assert not valid[:, :17].any()


def test_match_stereo_rejects_bad_input():
    img = np.zeros((20, 100), np.uint8)
    with pytest.raises(TypeError, match="left"):
        match_stereo(img.astype(np.float32), img)
    with pytest.raises(ValueError, match="one shape"):
        match_stereo(img, img[:, :90])
    with pytest.raises(ValueError, match="2D"):
        match_stereo(np.zeros((2, 3, 4), np.uint8), np.zeros((2, 3, 4), np.uint8))
    with pytest.raises(ValueError, match="unknown"):
        match_stereo(img, img, {"blocksize": 5})
    with pytest.raises(ValueError, match="odd"):
        match_stereo(img, img, {"blockSize": 4})
    with pytest.raises(TypeError, match="blockSize"):
        match_stereo(img, img, {"blockSize": 5.0})
    with pytest.raises(TypeError, match="params"):
        match_stereo(img, img, [("blockSize", 5)])


def test_disparity_to_points_inverts_the_projection():
    rig = StereoRig(width=40, height=20, focal_length=30.0, baseline=0.1)
    rotation = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])  # x fwd
    position = np.array([1.0, 2.0, 3.0])
    rng = np.random.default_rng(1)
    d = rng.uniform(0.5, 10.0, (20, 40))
    d[3, 4] = np.nan
    d[5, 6] = 0.0
    pts = disparity_to_points(d, rig, position, rotation, max_depth=100.0)
    assert len(pts) == 20 * 40 - 2
    cam = (pts - position) @ rotation           # back into the camera frame
    z = cam[:, 2]
    u = cam[:, 0] * rig.focal_length / z + rig.width / 2 - 0.5
    v = cam[:, 1] * rig.focal_length / z + rig.height / 2 - 0.5
    keep = np.isfinite(d) & (d > 0)
    vv, uu = np.nonzero(keep)
    np.testing.assert_allclose(u, uu, atol=1e-9)
    np.testing.assert_allclose(v, vv, atol=1e-9)
    np.testing.assert_allclose(z, rig.focal_length * rig.baseline / d[keep], rtol=1e-12)
    near = disparity_to_points(d, rig, position, rotation, max_depth=1.0)
    with np.errstate(divide="ignore"):
        depth = rig.focal_length * rig.baseline / d
    assert len(near) == np.sum(keep & (depth <= 1.0))
    with pytest.raises(ValueError, match="disparity"):
        disparity_to_points(d[:, :10], rig, position, rotation)
    with pytest.raises(ValueError, match="rotation"):
        disparity_to_points(d, rig, position, np.eye(2))
    with pytest.raises(TypeError, match="rig"):
        disparity_to_points(d, "rig", position, rotation)


def test_true_depth_through_the_pipeline_lies_on_the_surfaces(scene, pairs):
    p = pairs[0]
    with np.errstate(divide="ignore"):
        disparity = SMALL.focal_length * SMALL.baseline / p.depth
    pts = disparity_to_points(disparity, SMALL, p.position, p.rotation)
    assert len(pts) > 1000
    assert np.abs(scene.signed_distance(pts)).max() < 1e-6
    assert np.linalg.norm(pts - p.position, axis=1).max() < 8.0 * np.sqrt(3)


def test_stereo_scans_match_the_scene(scene, pairs):
    scans = stereo_scans(pairs, SMALL, SGBM_DEFAULT)
    assert len(scans) == len(pairs)
    for s, p in zip(scans, pairs):
        assert isinstance(s, Scan)
        np.testing.assert_array_equal(s.origin, p.position)
        keys = np.floor(s.points / 0.1)
        assert len(np.unique(keys, axis=0)) == len(keys)
    errors = point_errors(scene, scans)
    ranges = np.concatenate([np.linalg.norm(s.points - s.origin, axis=1) for s in scans])
    near = ranges < 4.0
    # textured boxes, asphalt and facades: most points within the k-NN range lie near a
    # surface (a mirrored or shifted triangulation puts them far off)
    assert near.sum() > 1000
    assert np.mean(errors.distance[near] < 0.3) > 0.8
    # the clouds are not the true surfaces: the matcher makes errors
    assert np.mean(errors.distance > 0.1) > 0.01
    again = stereo_scans(pairs, SMALL, SGBM_DEFAULT, n_jobs=2)
    for a, b in zip(scans, again):
        np.testing.assert_array_equal(a.points, b.points)


def test_pose_noise_moves_points_and_origins(pairs):
    clean = stereo_scans(pairs[:1], SMALL, voxel=None)
    moved = stereo_scans(pairs[:1], SMALL, voxel=None, pose_noise=(0.05, 1.0), seed=2)
    assert len(clean[0].points) == len(moved[0].points)
    shift = np.linalg.norm(moved[0].origin - clean[0].origin)
    assert 0 < shift < 0.5
    # a rigid motion: distances between points are kept
    a, b = clean[0].points, moved[0].points
    np.testing.assert_allclose(np.linalg.norm(a[1:] - a[:-1], axis=1),
                               np.linalg.norm(b[1:] - b[:-1], axis=1), rtol=1e-9, atol=1e-9)
    with pytest.raises(TypeError, match="pose_noise"):
        stereo_scans(pairs[:1], SMALL, pose_noise=0.1)
    with pytest.raises(ValueError, match=r"pose_noise\[1\]"):
        stereo_scans(pairs[:1], SMALL, pose_noise=(0.1, 100.0))


def test_stereo_scans_reject_bad_input(pairs):
    with pytest.raises(TypeError, match="pairs"):
        stereo_scans(pairs[0], SMALL)
    with pytest.raises(TypeError, match=r"pairs\[1\]"):
        stereo_scans([pairs[0], "x"], SMALL)
    with pytest.raises(ValueError, match="voxel"):
        stereo_scans(pairs, SMALL, voxel=0.0)
    with pytest.raises(ValueError, match="n_jobs"):
        stereo_scans(pairs, SMALL, n_jobs=0)


def test_naive_fdr_counts_free_cells(scene):
    on_box = np.array([[0.0, 0.0, 0.45], [0.0, 0.0, 1.05]])      # in a box, in the air
    inside = scene.occupancy(on_box)
    assert inside.tolist() == [True, False]
    fdr = naive_fdr([Scan(on_box, np.zeros(3))], scene)
    assert fdr == pytest.approx(0.5)
    assert naive_fdr([Scan(on_box[:1], np.zeros(3))] * 3, scene) == 0.0
    assert np.isnan(naive_fdr([Scan(np.empty((0, 3)), np.zeros(3))], scene))


@pytest.mark.slow
def test_rank_orders_by_naive_fdr(scene, pairs):
    sets = sgbm_parameter_sets(6, seed=5)
    order, fdr = rank_sgbm_sets(pairs[:2], SMALL, scene, sets)
    assert sorted(order.tolist()) == list(range(6))
    assert np.all(np.diff(fdr[order]) >= 0)
    for i in (0, 3):
        expect = naive_fdr(stereo_scans(pairs[:2], SMALL, sets[i], voxel=None), scene)
        assert fdr[i] == expect
    with pytest.raises(ValueError, match="at least one"):
        rank_sgbm_sets(pairs, SMALL, scene, [])


def test_point_errors_front_and_behind(scene):
    origin = np.array([4.0, 0.0, 0.25])          # facing the lower box at x = 0.8
    t = scene.ray_cast(origin, [[-1.0, 0.0, 0.0]])[0][0]
    pts = origin + np.array([[-(t - 0.5), 0, 0], [-(t + 0.2), 0, 0], [-t, 0, 0]])
    e = point_errors(scene, [Scan(pts, origin)])
    assert isinstance(e, PointErrors)
    np.testing.assert_allclose(e.along, [-0.5, 0.2, 0.0], atol=1e-9)
    assert e.surface.tolist() == ["box"] * 3
    assert e.distance[2] == pytest.approx(0.0, abs=1e-9)
    rows = {r["surface"]: r for r in e.table((0.1,))}
    assert rows["all"]["points"] == 3
    assert rows["box"][">0.1"] == pytest.approx(2 / 3)
    assert rows["box"][">0.1 front"] == pytest.approx(1 / 3)
    assert rows["box"][">0.1 behind"] == pytest.approx(1 / 3)
    sky = point_errors(scene, [Scan(np.array([[4.0, 0.0, 30.0]]), np.array([4.0, 0.0, 1.0]))])
    assert sky.surface.tolist() == ["none"] and np.isnan(sky.along[0])


def test_rendered_datasets_split_in_balanced_halves():
    sets = rendered_stereo_datasets()
    assert len(sets) == 20 and len({d.name for d in sets}) == 20
    tune = [d for d in sets if d.half == "tune"]
    assert len(tune) == 10
    for layout in "IOTLS":
        assert sum(d.layout == layout for d in tune) == 2
    assert sum(d.texture for d in tune) == 5
    assert sum(d.environment == "open" for d in tune) == 5
    assert [d.seed for d in rendered_stereo_datasets(1)] == list(range(20, 40))
    d = sets[3]
    assert d.scene().name == f"tetromino_{d.layout}_{'textured' if d.texture else 'plain'}_" \
                             f"{d.environment}"
    scans = d.scans(rig=StereoRig(width=160, height=90, focal_length=84.3), n_frames=1, orbits=1)
    assert len(scans) == 1 and len(scans[0].points) > 0
    with pytest.raises(TypeError, match="not used"):
        d.scans(pairs=[], n_frames=3)
