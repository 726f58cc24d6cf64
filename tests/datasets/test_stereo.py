"""The noisy stereo-camera simulator: scenes, error model, orbit, voxel filter, data sets."""

import numpy as np
import pytest
from scipy import ndimage
from numpy.testing import assert_allclose, assert_array_equal

from occgp.datasets import (
    Scene,
    StereoCamera,
    StereoDataset,
    TetrominoScene,
    simulate_stereo,
    stereo_datasets,
    tetromino_scene,
    voxel_filter,
)
from occgp.datasets._geometry import Box

TINY = dict(width=32, height=18)
EXACT = dict(depth_noise=0.0, speckle=0.0, missing=0.0)


def wall_scene(x):
    """A 40 x 40 m wall whose face is the plane x = `x`, seen from the origin."""
    return Scene([Box([x + 0.5, 0.0, 0.0], [0.5, 20.0, 20.0])], ["wall"],
                 ([-1.0, -1.0, -1.0], [x, 1.0, 1.0]), "wall", [[0.0, 0.0, 0.0]], 0.0)


@pytest.mark.parametrize("layout", ["I", "O", "T", "L", "S"])
def test_tetromino_scene_geometry(layout):
    scene = tetromino_scene(layout)
    assert isinstance(scene, TetrominoScene) and scene.layout == layout
    assert len(scene.targets) == 8                     # 4 cells, a pair of boxes each
    assert sum(label.startswith("building") for label in scene.labels) == 3
    bottoms = sorted(b.center[2] - b.half_extents[2] for b in scene.targets)
    tops = sorted(b.center[2] + b.half_extents[2] for b in scene.targets)
    assert_allclose(bottoms[:4], 0.0)                  # the lower boxes stand on the ground
    assert_allclose(tops[-4:], 0.9)
    assert_allclose(scene.target_center, [0.0, 0.0, 0.45])
    ring = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    orbit = np.column_stack([4 * np.cos(ring), 4 * np.sin(ring), np.full(40, 1.5)])
    assert not scene.occupancy(orbit).any()            # the default orbit is free
    assert tetromino_scene(layout, environment="open").labels[-1].startswith("box")


def test_tetromino_scene_buildings_are_seeded():
    a, b = tetromino_scene("L", seed=3), tetromino_scene("L", seed=3)
    assert_array_equal(a.solids[-1].center, b.solids[-1].center)
    assert not np.array_equal(a.solids[-1].center, tetromino_scene("L", seed=4).solids[-1].center)
    # near facades 5 to 7 m from the center
    for s in a.solids[-3:]:
        assert 5.0 - 1e-9 <= s.signed_distance(np.array([[0.0, 0.0, 2.0]]))[0] <= 7.0 + 1e-9


def test_simulate_is_deterministic_by_seed():
    scene, cam = tetromino_scene("T"), StereoCamera(**TINY)
    a = simulate_stereo(scene, cam, n_frames=3, seed=5)
    b = simulate_stereo(scene, cam, n_frames=3, seed=5)
    c = simulate_stereo(scene, cam, n_frames=3, seed=6)
    assert len(a) == 6
    for s, t in zip(a, b):
        assert_array_equal(s.points, t.points)
        assert_array_equal(s.origin, t.origin)
    assert not all(np.array_equal(s.points, t.points) for s, t in zip(a, c))


def test_orbit_circles_the_layout_twice_looking_at_it():
    scene = tetromino_scene("S")
    scans = simulate_stereo(scene, StereoCamera(**TINY), n_frames=4, orbits=2, radius=3.0,
                            height=1.2)
    origins = np.array([s.origin for s in scans])
    assert_allclose(np.linalg.norm(origins[:, :2] - scene.target_center[:2], axis=1), 3.0)
    assert_allclose(origins[:, 2], 1.2)
    az = np.degrees(np.arctan2(origins[:, 1], origins[:, 0])) % 360
    assert_allclose(az, [0, 90, 180, 270, 45, 135, 225, 315], atol=1e-9)


def test_noiseless_points_lie_on_surfaces():
    scene, cam = tetromino_scene("O"), StereoCamera(**TINY, **EXACT)
    raw = simulate_stereo(scene, cam, n_frames=2, voxel=None)
    for scan in raw:
        assert len(scan.points) > 300
        assert np.abs(scene.signed_distance(scan.points)).max() < 1e-9
    filtered = simulate_stereo(scene, cam, n_frames=2, voxel=0.1)
    for scan in filtered:
        # a centroid of surface points in a voxel lies within the voxel's diagonal
        assert np.abs(scene.signed_distance(scan.points)).max() <= 0.1 * np.sqrt(3)


def test_depth_noise_grows_with_depth_squared():
    cam = StereoCamera(width=40, height=30, depth_noise=0.01, speckle=0.0, missing=0.0)
    spread = {}
    for x in (1.5, 5.0):
        points = cam.capture(wall_scene(x), [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], seed=0)
        assert len(points) == cam.n_pixels
        spread[x] = np.std(points[:, 0] - x)   # the depth of a fronto-parallel wall
    assert_allclose(spread[1.5], 0.01 * 1.5 ** 2, rtol=0.1)
    assert_allclose(spread[5.0], 0.01 * 5.0 ** 2, rtol=0.1)


def test_speckle_points_lie_between_camera_and_surface():
    scene = tetromino_scene("I")
    position, look = np.array([4.0, 0.0, 1.5]), scene.target_center
    exact = StereoCamera(**TINY, **EXACT).capture(scene, position, look)
    cam = StereoCamera(**TINY, depth_noise=0.0, speckle=1.0, missing=0.0)
    points = cam.capture(scene, position, look, seed=1)
    assert len(points) == len(exact)
    rays = points - position
    rng = np.linalg.norm(rays, axis=1)
    surface, hit = scene.ray_cast(position, rays / rng[:, None], 50.0)
    assert hit.all() and (rng <= surface + 1e-9).all()
    assert np.mean(rng < surface - 1e-6) > 0.99          # strictly in front
    # a fraction `speckle` of the returns are outliers
    some = StereoCamera(width=64, height=36, depth_noise=0.0, speckle=0.3, missing=0.0)
    points = some.capture(scene, position, look, seed=2)
    off = np.abs(scene.signed_distance(points)) > 1e-6
    assert 0.25 < off.mean() < 0.35


def test_voxel_filter_keeps_one_point_per_voxel():
    scans = simulate_stereo(tetromino_scene("L"), StereoCamera(**TINY), n_frames=2, voxel=0.2)
    for scan in scans:
        keys = np.floor(scan.points / 0.2)
        assert len(np.unique(keys, axis=0)) == len(keys)
    rng = np.random.default_rng(0)
    points = rng.uniform(-1, 1, (2000, 3))
    out = voxel_filter(points, 0.5)
    assert len(out) == 64
    keys = np.floor(points / 0.5)
    assert_allclose(out[0], points[(keys == np.floor(out[0] / 0.5)).all(axis=1)].mean(axis=0))
    # a centroid that rounding pushes onto the next voxel is replaced by a point of the voxel
    edge = np.nextafter(0.3, 0)
    assert voxel_filter(np.full((3, 3), edge), 0.1).tolist() == [[edge] * 3]
    assert voxel_filter(np.empty((0, 3))).shape == (0, 3)


def test_weak_texture_loses_more_points():
    cam = StereoCamera(**TINY, missing=0.3)
    position = np.array([4.0, 0.0, 1.5])
    textured, plain = tetromino_scene("O"), tetromino_scene("O", texture=False)
    a = cam.capture(textured, position, textured.target_center, seed=3)
    b = cam.capture(plain, position, plain.target_center, seed=3)
    assert len(b) < len(a)
    # the same noise draws: the plain scene's points are the textured scene's, less some
    assert set(map(tuple, b)) <= set(map(tuple, a))
    lost = np.array(sorted(set(map(tuple, a)) - set(map(tuple, b))))
    dirs = (lost - position) / np.linalg.norm(lost - position, axis=1, keepdims=True)
    first, _ = plain.ray_cast(position, dirs, 50.0)
    origins = np.broadcast_to(position, dirs.shape)
    on_box = np.min([s.intersect(origins, dirs) for s in plain.targets], axis=0)
    assert_allclose(on_box, first)          # only pixels on the (plain) boxes are lost
    na = sum(len(s.points) for s in simulate_stereo(textured, cam, n_frames=2))
    nb = sum(len(s.points) for s in simulate_stereo(plain, cam, n_frames=2))
    assert nb < na


def test_missing_pixels_come_in_blobs_at_the_base_rate():
    cam = StereoCamera(width=80, height=45, depth_noise=0.0, speckle=0.0, missing=0.5)
    scene = wall_scene(2.0)
    points = cam.capture(scene, [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], seed=0)
    assert cam.n_pixels - len(points) == round(0.5 * 0.1 * cam.n_pixels)
    none = StereoCamera(width=80, height=45, **EXACT)
    every = none.capture(scene, [0.0, 0.0, 0.0], [1.0, 0.0, 0.0])
    assert len(every) == none.n_pixels
    kept = set(map(tuple, points))
    lost = np.array([tuple(p) not in kept for p in every]).reshape(45, 80)
    _, n_blobs = ndimage.label(lost)
    assert n_blobs <= lost.sum() / 8     # connected blobs (scattered pixels: ~170 components)


def test_stereo_datasets_listing():
    sets = stereo_datasets()
    assert len(sets) == 60 and all(isinstance(s, StereoDataset) for s in sets)
    assert len({(s.layout, s.texture, s.environment, s.depth_noise) for s in sets}) == 60
    assert len({s.seed for s in sets}) == 60
    assert {s.depth_noise for s in sets} == {0.005, 0.01, 0.02}
    # the same scene at every noise level
    by_combo = {}
    for s in sets:
        by_combo.setdefault((s.layout, s.texture, s.environment), set()).add(s.scene_seed)
    assert len(by_combo) == 20 and all(len(v) == 1 for v in by_combo.values())
    other = stereo_datasets((0.01,), seed=1)
    assert len(other) == 20 and not {s.seed for s in other} & {s.seed for s in sets[:20]}
    ds = sets[25]
    scene = ds.scene()
    assert (scene.layout, scene.texture, scene.environment) == (ds.layout, ds.texture,
                                                                ds.environment)
    assert ds.camera().depth_noise == ds.depth_noise
    scans = ds.scans(StereoCamera(**TINY), n_frames=1, orbits=1)
    assert_array_equal(scans[0].points, simulate_stereo(scene, StereoCamera(**TINY), n_frames=1,
                                                        orbits=1, seed=ds.seed)[0].points)


@pytest.mark.parametrize("call, exc, match", [
    (lambda: tetromino_scene("Z"), ValueError, r"layout must be one of .*'Z'"),
    (lambda: tetromino_scene(texture=1), TypeError, r"texture must be a bool, got int"),
    (lambda: tetromino_scene(environment="moon"), ValueError, r"environment must be one of"),
    (lambda: tetromino_scene(seed=-1), ValueError, r"seed must be a non-negative int, got -1"),
    (lambda: StereoCamera(width=0), ValueError, r"width must be a positive int, got 0"),
    (lambda: StereoCamera(height=2.5), TypeError, r"height must be a positive int, got float"),
    (lambda: StereoCamera(width=4000, height=4000), ValueError,
     r"width \* height must be at most 2073600"),
    (lambda: StereoCamera(fov=180), ValueError, r"fov must lie in \(0\.0, 180\.0\)"),
    (lambda: StereoCamera(max_depth=0), ValueError, r"max_depth must lie in \(0\.0, 1000\.0\]"),
    (lambda: StereoCamera(max_depth=1e30), ValueError, r"max_depth must lie in"),
    (lambda: StereoCamera(depth_noise=-0.1), ValueError, r"depth_noise must lie in \[0\.0, 1\.0\]"),
    (lambda: StereoCamera(speckle=np.nan), ValueError, r"speckle must lie in \[0\.0, 1\.0\]"),
    (lambda: StereoCamera(missing="x"), TypeError, r"missing must be a real number, got str"),
    (lambda: simulate_stereo("scene"), TypeError, r"scene must be a Scene, got str"),
    (lambda: simulate_stereo(tetromino_scene(), camera=3), TypeError,
     r"camera must be a StereoCamera, got int"),
    (lambda: simulate_stereo(tetromino_scene(), n_frames=0), ValueError,
     r"n_frames must lie in \[1, 10000\], got 0"),
    (lambda: simulate_stereo(tetromino_scene(), orbits=1.0), TypeError,
     r"orbits must be a positive int, got float"),
    (lambda: simulate_stereo(tetromino_scene(), radius=-1), ValueError, r"radius must lie in"),
    (lambda: simulate_stereo(tetromino_scene(), height=np.inf), ValueError, r"height must lie in"),
    (lambda: simulate_stereo(tetromino_scene(), voxel=1e-9), ValueError,
     r"voxel must lie in \[1e-06, 1000\.0\]"),
    (lambda: simulate_stereo(tetromino_scene(), seed=-3), ValueError,
     r"seed must be a non-negative int"),
    (lambda: simulate_stereo(tetromino_scene(), radius=0.3, height=0.3), ValueError,
     r"camera position of frame 0, .* lies inside a solid"),
    (lambda: simulate_stereo(tetromino_scene(), height=-0.05), ValueError,
     r"lies inside a solid"),
    (lambda: StereoCamera().capture(tetromino_scene(), [0, 0], [1, 0, 0]), ValueError,
     r"position must have shape \(3,\), got \(2,\)"),
    (lambda: StereoCamera().capture(tetromino_scene(), [4, 0, 1], [4, 0, 1]), ValueError,
     r"look_at must differ from position"),
    (lambda: StereoCamera().capture(tetromino_scene(), [4, 0, 1], [4, 0, 3]), ValueError,
     r"look_at must not lie straight above or below position"),
    (lambda: StereoCamera().capture(tetromino_scene(), [0.4, 0, 0.2], [4, 0, 1]), ValueError,
     r"position \[0\.4, 0\.0, 0\.2\] lies inside a solid"),
    (lambda: voxel_filter(np.zeros((4, 2))), ValueError,
     r"points must have shape \(n_points, 3\), got \(4, 2\)"),
    (lambda: voxel_filter([[1e30, 0, 0]], 0.1), ValueError, r"\|x\| / voxel < 2\*\*62"),
    (lambda: stereo_datasets(()), ValueError, r"noise_levels must hold at least one"),
    (lambda: stereo_datasets((0.01, 2.0)), ValueError,
     r"noise_levels\[1\] must lie in \[0\.0, 1\.0\], got 2\.0"),
    (lambda: stereo_datasets(0.01), TypeError, r"noise_levels must be a sequence"),
    (lambda: stereo_datasets(seed=0.5), TypeError, r"seed must be a non-negative int"),
])
def test_bad_parameters(call, exc, match):
    with pytest.raises(exc, match=match):
        call()
