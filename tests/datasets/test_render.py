"""The rendered stereo pair (occgp.datasets.render_stereo): geometry, shading, textures,
sensor effects and bad input."""

import sys

import numpy as np
import pytest
from scipy.ndimage import binary_erosion, map_coordinates, uniform_filter

from occgp.datasets import (
    TEXTURES, StereoPair, StereoRig, render_stereo, scene_materials, structured_room,
    tetromino_scene, unstructured_room,
)

POSITION = np.array([4.0, 0.0, 1.5])
# effects off: what the cameras see, exactly
CLEAN = dict(blur=0.0, noise=0.0, gain=0.0, offset=0.0, motion_blur=0.0, rectification=0.0)


def small(**kw):
    """A 320 x 180 rig (the default one at half size)."""
    return StereoRig(**{"width": 320, "height": 180, "focal_length": 168.6, **kw})


def pixel_points(pair, rig):
    """World points of the left pixels (nan for the sky), from the depth and the pose."""
    f, cx, cy = rig.intrinsics
    v, u = np.mgrid[0:rig.height, 0:rig.width] + 0.5
    cam = np.stack([(u - cx) / f, (v - cy) / f, np.ones_like(u)], axis=-1)
    depth = np.where(np.isfinite(pair.depth), pair.depth, np.nan)
    return pair.position + depth[..., None] * (cam @ pair.rotation.T)


def project(points, pair, rig):
    """Pixel coordinates (col, row, as floats with centers at +0.5) and depth of world
    points in a camera of `pair`'s pose."""
    cam = (points - pair.position) @ pair.rotation
    f, cx, cy = rig.intrinsics
    return f * cam[..., 0] / cam[..., 2] + cx, f * cam[..., 1] / cam[..., 2] + cy, cam[..., 2]


@pytest.fixture(scope="module")
def textured():
    return tetromino_scene("T", texture=True)


@pytest.fixture(scope="module")
def clean_pair(textured):
    rig = small(**CLEAN)
    return rig, render_stereo(textured, POSITION, textured.target_center, rig, truth=True)


def box_mask(scene, solid):
    is_box = np.array([label.startswith("box") for label in scene.labels])
    return (solid >= 0) & is_box[solid]


# --------------------------------------------------------------------------- #
# geometry
# --------------------------------------------------------------------------- #
def test_pair_shapes_and_pose(clean_pair):
    rig, pair = clean_pair
    assert isinstance(pair, StereoPair)
    for image in (pair.left, pair.right):
        assert image.shape == (180, 320) and image.dtype == np.uint8
    assert pair.depth.shape == (180, 320) and pair.depth.dtype == np.float64
    assert pair.solid.dtype == np.int16
    R = pair.rotation
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    assert R[2, 1] < 0            # the image's y axis points down
    assert R[:, 2] @ (np.array([0, 0, 0.45]) - POSITION) > 0     # z toward look_at
    without = render_stereo(tetromino_scene("T"), POSITION, [0, 0, 0.45], small(**CLEAN))
    assert without.depth is None and without.solid is None
    np.testing.assert_array_equal(without.left, pair.left)


def test_right_image_is_the_left_image_of_a_camera_one_baseline_to_the_right(clean_pair,
                                                                             textured):
    rig, pair = clean_pair
    shift = rig.baseline * pair.rotation[:, 0]
    moved = render_stereo(textured, POSITION + shift, textured.target_center + shift, rig)
    np.testing.assert_array_equal(moved.left, pair.right)
    np.testing.assert_allclose(moved.rotation, pair.rotation, atol=1e-12)


def test_depth_and_solid_are_the_exact_first_hits(clean_pair, textured):
    rig, pair = clean_pair
    points = pixel_points(pair, rig)
    f, cx, cy = rig.intrinsics
    v, u = np.mgrid[0:rig.height, 0:rig.width] + 0.5
    dirs = np.stack([(u - cx) / f, (v - cy) / f, np.ones_like(u)], -1) @ pair.rotation.T
    dirs = dirs.reshape(-1, 3)
    dist, hit = textured.ray_cast(POSITION, dirs)
    cos = (dirs / np.linalg.norm(dirs, axis=1, keepdims=True)) @ pair.rotation[:, 2]
    depth = pair.depth.ravel()
    np.testing.assert_array_equal(np.isfinite(depth), hit)
    np.testing.assert_allclose(depth[hit], (dist * cos)[hit], rtol=1e-12)
    # the solid of each pixel is the one hit at that distance
    ids = pair.solid.ravel()
    assert (ids[~hit] == -1).all() and (ids[hit] >= 0).all()
    unit = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    per_solid = np.array([s.intersect(np.broadcast_to(POSITION, unit.shape), unit)
                          for s in textured.solids])
    np.testing.assert_allclose(per_solid[ids[hit], np.flatnonzero(hit)], dist[hit], rtol=1e-12)
    assert np.isnan(points[np.isinf(pair.depth)]).all()


@pytest.mark.parametrize("make, position, look_at", [
    (structured_room, [-4.0, 2.5, 1.0], [0.0, 0.0, 0.5]),        # walls behind the camera
    (unstructured_room, [-3.0, -0.5, 0.5], [3.0, 0.5, 0.8]),    # ellipsoids and cones
    (lambda: tetromino_scene("O"), [0.4, 0.9, 0.3], [5.0, 0.9, 0.3]),   # a box half behind
])
def test_culling_gives_the_brute_force_hits(make, position, look_at):
    scene = make()
    rig = StereoRig(width=96, height=54, focal_length=50.0, **CLEAN)
    pair = render_stereo(scene, position, look_at, rig, truth=True)
    f, cx, cy = rig.intrinsics
    v, u = np.mgrid[0:rig.height, 0:rig.width] + 0.5
    dirs = (np.stack([(u - cx) / f, (v - cy) / f, np.ones_like(u)], -1)
            @ pair.rotation.T).reshape(-1, 3)
    dist, hit = scene.ray_cast(position, dirs)
    assert hit.mean() > 0.3
    cos = (dirs / np.linalg.norm(dirs, axis=1, keepdims=True)) @ pair.rotation[:, 2]
    np.testing.assert_allclose(pair.depth.ravel()[hit], (dist * cos)[hit], rtol=1e-12)
    assert np.isinf(pair.depth.ravel()[~hit]).all()
    assert pair.left.std() > 5


def _warp_errors(pair, right_truth, rig, sign=1.0, mask=None):
    """|left - right sampled at (u - sign * d, v)| on pixels both cameras see."""
    d = rig.focal_length * rig.baseline / pair.depth
    rows, cols = np.mgrid[0:rig.height, 0:rig.width].astype(float)
    x = cols - sign * d
    ok = np.isfinite(pair.depth) & (x >= 0) & (x <= rig.width - 1)
    if mask is not None:
        ok &= mask
    warped = map_coordinates(pair.right.astype(float), [rows[ok], x[ok]], order=1)
    # occluded in the right camera: its own depth there disagrees
    seen = map_coordinates(right_truth.depth, [rows[ok], np.round(x[ok])], order=0)
    both = np.abs(seen - pair.depth[ok]) < 0.01 * pair.depth[ok]
    return np.abs(warped - pair.left[ok])[both], both.mean()


def test_right_image_warped_by_the_true_disparity_reproduces_the_left(clean_pair, textured):
    rig, pair = clean_pair
    shift = rig.baseline * pair.rotation[:, 0]
    right = render_stereo(textured, POSITION + shift, textured.target_center + shift, rig,
                          truth=True)
    err, visible = _warp_errors(pair, right, rig)
    assert visible > 0.95 and len(err) > 20_000
    assert np.median(err) < 1.0 and np.percentile(err, 95) < 12
    boxes = box_mask(textured, pair.solid)
    box_err, _ = _warp_errors(pair, right, rig, mask=boxes)
    # the Voronoi cells are 2-3 pixels wide here: resampling them costs a few levels
    assert np.median(box_err) < 5.0 and np.percentile(box_err, 95) < 30
    # a broken rig fails: the baseline's sign flipped, or no baseline at all (measured:
    # medians 3 right, 37 and 39 broken)
    wrong, _ = _warp_errors(pair, right, rig, sign=-1.0, mask=boxes)
    assert np.median(wrong) > 5 * np.median(box_err)
    assert np.percentile(wrong, 95) > 3 * np.percentile(box_err, 95)
    same, _ = _warp_errors(pair, right, rig, sign=0.0, mask=boxes)
    assert np.median(same) > 5 * np.median(box_err)


def test_textures_are_fixed_on_the_surfaces_across_frames(clean_pair, textured):
    rig, pair = clean_pair
    other_position = np.array([2.8, 2.8, 1.3])
    other = render_stereo(textured, other_position, textured.target_center, rig, truth=True)
    points = pixel_points(pair, rig)
    mask = box_mask(textured, pair.solid)
    col, row, z = project(points[mask], other, rig)
    inside = (col > 1) & (col < rig.width - 2) & (row > 1) & (row < rig.height - 2)
    col, row, z = col[inside], row[inside], z[inside]
    seen = map_coordinates(other.depth, [row - 0.5, col - 0.5], order=0)
    visible = np.abs(seen - z) < 0.005 * z
    assert visible.sum() > 500
    # Lambertian and the same sun: a surface point has one grey level in both frames
    got = map_coordinates(other.left.astype(float), [row[visible] - 0.5, col[visible] - 0.5],
                          order=1)
    mine = pair.left[mask][inside][visible].astype(float)
    err = np.abs(got - mine)
    # sampling at 2-3 pixels per Voronoi cell costs some levels (measured: median 8.8 here,
    # 1.6 at 1280 x 720); another pattern in each frame would give unrelated grey levels
    unrelated = np.abs(got - np.random.default_rng(0).permutation(mine))
    assert np.median(err) < 12 and np.median(err) < 0.4 * np.median(unrelated)


# --------------------------------------------------------------------------- #
# shading
# --------------------------------------------------------------------------- #
def test_cast_shadows_darken_the_ground_to_the_ambient_light():
    scene = tetromino_scene("T", environment="open")
    rig = small(sun_azimuth=60.0, sun_elevation=30.0, ambient=0.3, **CLEAN)
    # a constant-albedo ground: its grey level tells the light
    pair = render_stereo(scene, POSITION, scene.target_center, rig, truth=True,
                         materials={"ground": "sky"})
    ground = pair.solid == 0
    points = pixel_points(pair, rig)[ground]
    _, blocked = scene.ray_cast(points + [0, 0, 1e-6], np.broadcast_to(rig.sun, points.shape))
    grey = pair.left[ground].astype(float)
    albedo = 0.92
    lit = 255 * albedo * (rig.ambient + (1 - rig.ambient) * rig.sun[2])
    dark = 255 * albedo * rig.ambient
    assert 0.02 < blocked.mean() < 0.5
    assert np.median(np.abs(grey[blocked] - dark)) < 2.5
    assert np.median(np.abs(grey[~blocked] - lit)) < 2.5
    assert np.mean(np.abs(grey[blocked] - dark) < 5) > 0.95
    # overhead sun: no shadow beside the boxes, every ground pixel fully lit
    noon = render_stereo(scene, POSITION, scene.target_center,
                         small(sun_elevation=90.0, ambient=0.3, **CLEAN),
                         materials={"ground": "sky"})
    assert np.median(np.abs(noon.left[ground] - 255 * albedo)) < 2.5


def test_sky_is_bright_and_identical_in_both_images(clean_pair, textured):
    rig, pair = clean_pair
    sky = np.isinf(pair.depth)
    assert sky.mean() > 0.1
    assert 200 <= pair.left[sky].min() and pair.left[sky].max() <= 245
    assert pair.left[sky][:10].mean() < pair.left[sky][-10:].mean()   # brighter downward
    # sky at infinity: no disparity, where the right camera sees the sky too
    shift = rig.baseline * pair.rotation[:, 0]
    right = render_stereo(textured, POSITION + shift, textured.target_center + shift, rig,
                          truth=True)
    both = sky & np.isinf(right.depth)
    assert both.sum() > 0.95 * sky.sum()
    np.testing.assert_array_equal(pair.left[both], pair.right[both])


def test_plain_boxes_are_nearly_textureless():
    rig = small(**CLEAN)

    def local_std(texture):
        scene = tetromino_scene("T", texture=texture)
        pair = render_stereo(scene, POSITION, scene.target_center, rig, truth=True)
        img = pair.left.astype(float)
        std = np.sqrt(np.maximum(uniform_filter(img ** 2, 5) - uniform_filter(img, 5) ** 2, 0))
        inner = np.zeros_like(pair.solid, dtype=bool)
        for k in np.unique(pair.solid[box_mask(scene, pair.solid)]):
            inner |= binary_erosion(pair.solid == k, iterations=3)
        assert inner.sum() > 1000
        return np.median(std[inner])

    plain, textured = local_std(False), local_std(True)
    assert plain < 1.0 and textured > 8.0


def test_scene_materials_and_overrides(textured):
    plain = tetromino_scene("T", texture=False)
    assert scene_materials(textured)[:3] == ["asphalt", "voronoi", "voronoi"]
    assert scene_materials(plain)[1:9] == ["cardboard"] * 8
    assert scene_materials(textured)[-1] == "facade"
    room = scene_materials(structured_room())
    assert room[0] == "asphalt" and set(room) <= set(TEXTURES)
    rig = small(width=160, height=90, focal_length=84.3, **CLEAN)
    as_dict = render_stereo(textured, POSITION, textured.target_center, rig,
                            materials={"box_*": "cardboard"})
    as_list = render_stereo(plain, POSITION, plain.target_center, rig,
                            materials=scene_materials(plain))
    np.testing.assert_array_equal(as_dict.left, as_list.left)


# --------------------------------------------------------------------------- #
# sensor effects
# --------------------------------------------------------------------------- #
def test_seeded_noise_is_deterministic(textured):
    rig = small(width=160, height=90, focal_length=84.3)
    a = render_stereo(textured, POSITION, textured.target_center, rig, seed=3)
    b = render_stereo(textured, POSITION, textured.target_center, rig, seed=3)
    c = render_stereo(textured, POSITION, textured.target_center, rig, seed=4)
    np.testing.assert_array_equal(a.left, b.left)
    np.testing.assert_array_equal(a.right, b.right)
    assert (a.left != c.left).mean() > 0.3
    clean = render_stereo(textured, POSITION, textured.target_center,
                          small(width=160, height=90, focal_length=84.3, blur=0.5, gain=0.0,
                                offset=0.0, noise=0.0))
    noise = a.left.astype(float) - clean.left
    assert 1.5 < noise.std() < 2.5


def test_gain_offset_and_rectification_act_on_the_right_image(clean_pair, textured):
    rig, pair = clean_pair
    gained = render_stereo(textured, POSITION, textured.target_center,
                           small(**{**CLEAN, "gain": 0.1, "offset": 3.0}))
    np.testing.assert_array_equal(gained.left, pair.left)
    expect = np.clip(np.rint(pair.right * 1.1 + 3.0), 0, 255)
    assert np.abs(gained.right - expect).max() <= 1
    shifted = render_stereo(textured, POSITION, textured.target_center,
                            small(**{**CLEAN, "rectification": 2.0}))
    np.testing.assert_array_equal(shifted.right[2:], pair.right[:-2])
    np.testing.assert_array_equal(shifted.left, pair.left)


def test_blur_and_motion_blur_smooth_the_images(clean_pair, textured):
    rig, pair = clean_pair

    def energy(img, axis):
        return np.abs(np.diff(img.astype(float), axis=axis)).mean()

    blurred = render_stereo(textured, POSITION, textured.target_center,
                            small(**{**CLEAN, "blur": 1.5}))
    assert energy(blurred.left, 0) < 0.7 * energy(pair.left, 0)
    assert energy(blurred.left, 1) < 0.7 * energy(pair.left, 1)
    moving = render_stereo(textured, POSITION, textured.target_center,
                           small(**{**CLEAN, "motion_blur": 6.0}))
    across = energy(moving.left, 1) / energy(pair.left, 1)
    along = energy(moving.left, 0) / energy(pair.left, 0)
    assert across < 0.6 and across < along - 0.1      # horizontal: smoothed most


def test_jpeg_round_trip(clean_pair, textured):
    pytest.importorskip("cv2")
    rig, pair = clean_pair
    jpeg = render_stereo(textured, POSITION, textured.target_center,
                         small(**{**CLEAN, "jpeg": 50}))
    diff = np.abs(jpeg.left.astype(float) - pair.left)
    assert 0.2 < diff.mean() < 5


def test_jpeg_without_opencv_names_the_extra(textured, monkeypatch):
    monkeypatch.setitem(sys.modules, "cv2", None)
    with pytest.raises(ImportError, match=r"pip install occgp\[stereo\]"):
        render_stereo(textured, POSITION, textured.target_center,
                      StereoRig(width=32, height=18, focal_length=16.0, jpeg=90))


def test_zed_rig_and_intrinsics():
    zed = StereoRig.zed(noise=1.0)
    assert (zed.width, zed.height, zed.focal_length, zed.baseline) == (1280, 720, 674.31,
                                                                       0.11968)
    assert zed.noise == 1.0
    assert StereoRig().intrinsics == (337.2, 320.0, 180.0)
    np.testing.assert_allclose(StereoRig().camera_matrix,
                               [[337.2, 0, 320], [0, 337.2, 180], [0, 0, 1]])
    assert np.linalg.norm(StereoRig().sun) == pytest.approx(1.0)


# --------------------------------------------------------------------------- #
# bad input
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("kwargs, exc, match", [
    (dict(width=0), ValueError, "width must be a positive int, got 0"),
    (dict(height=2.5), TypeError, "height must be a positive int, got float"),
    (dict(width=4000, height=4000), ValueError, r"width \* height must be at most"),
    (dict(focal_length=-1.0), ValueError, "focal_length must lie in"),
    (dict(baseline=0.0), ValueError, "baseline must lie in"),
    (dict(max_depth=np.inf), ValueError, "max_depth must lie in"),
    (dict(blur=-0.1), ValueError, "blur must lie in"),
    (dict(noise="2"), TypeError, "noise must be a real number, got str"),
    (dict(gain=1.0), ValueError, "gain must lie in"),
    (dict(rectification=np.nan), ValueError, "rectification must lie in"),
    (dict(jpeg=0), ValueError, r"jpeg must lie in \[1, 100\], got 0"),
    (dict(jpeg=90.0), TypeError, "jpeg must be a positive int, got float"),
    (dict(sun_elevation=0.0), ValueError, "sun_elevation must lie in"),
    (dict(ambient=1.5), ValueError, "ambient must lie in"),
    (dict(motion_blur=-1), ValueError, "motion_blur must lie in"),
])
def test_bad_rig_fields(kwargs, exc, match):
    with pytest.raises(exc, match=match):
        StereoRig(**kwargs)


@pytest.mark.parametrize("call, exc, match", [
    (lambda s, r: render_stereo("scene", POSITION, [0, 0, 0], r), TypeError,
     "scene must be a Scene, got str"),
    (lambda s, r: render_stereo(s, POSITION, [0, 0, 0], "rig"), TypeError,
     "rig must be a StereoRig, got str"),
    (lambda s, r: render_stereo(s, [0, 0], [0, 0, 0], r), ValueError,
     r"position must have shape \(3,\)"),
    (lambda s, r: render_stereo(s, POSITION, [0, 0, np.nan], r), ValueError,
     "look_at must be finite"),
    (lambda s, r: render_stereo(s, [0, 0, 0.3], [4, 0, 0.3], r), ValueError,
     "position .* lies inside a solid"),
    (lambda s, r: render_stereo(s, [0.0, 0.2, 0.3], [4, 0.2, 0.3], r), ValueError,
     "the right camera, at .* lies inside a solid"),
    (lambda s, r: render_stereo(s, POSITION, POSITION, r), ValueError,
     "look_at must differ from position"),
    (lambda s, r: render_stereo(s, POSITION, POSITION + [0, 0, 1], r), ValueError,
     "look_at must not lie straight above or below position"),
    (lambda s, r: render_stereo(s, POSITION, [0, 0, 0], r, seed=-1), ValueError,
     "seed must be a non-negative int"),
    (lambda s, r: render_stereo(s, POSITION, [0, 0, 0], r, truth=1), TypeError,
     "truth must be a bool"),
    (lambda s, r: render_stereo(s, POSITION, [0, 0, 0], r, materials={"ground": "grass"}),
     ValueError, r"materials\['ground'\] must be one of \('voronoi'"),
    (lambda s, r: render_stereo(s, POSITION, [0, 0, 0], r, materials={"tree*": "voronoi"}),
     ValueError, "materials: the pattern 'tree\\*' matches no label"),
    (lambda s, r: render_stereo(s, POSITION, [0, 0, 0], r, materials=["asphalt"]),
     ValueError, r"materials must name one material per solid \(12\), got 1"),
    (lambda s, r: render_stereo(s, POSITION, [0, 0, 0], r,
                                materials=["asphalt"] * 11 + ["marble"]),
     ValueError, r"materials\[11\] must be one of"),
    (lambda s, r: render_stereo(s, POSITION, [0, 0, 0], r, materials="voronoi"), TypeError,
     "materials must be a sequence of material names"),
    (lambda s, r: render_stereo(s, POSITION, [0, 0, 0], r, materials={1: "voronoi"}),
     TypeError, "materials keys must be label patterns"),
    (lambda s, r: scene_materials([1, 2]), TypeError, "scene must be a Scene, got list"),
])
def test_bad_render_input(call, exc, match):
    scene = tetromino_scene("T")
    with pytest.raises(exc, match=match):
        call(scene, StereoRig(width=32, height=18, focal_length=16.0))
