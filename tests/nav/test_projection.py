"""2D projection of a height band (``project_2d``) and the map_server / Nav2 files of
:class:`occgp.OccupancyGrid2D`: every cell against a brute-force reference on the
map's finest cells (pruned leaves expanded), files read back with Pillow and PyYAML."""

import numpy as np
import pytest
import yaml
from numpy.testing import assert_array_equal, assert_allclose
from PIL import Image

from conftest import tiny_room_scan as room_scan
from occgp import ColorOctree, GridMap, OccupancyGrid2D, OccupancyOctree


# --------------------------------------------------------------------------- #
# scenes and the reference
# --------------------------------------------------------------------------- #


def grid_with(cells, values, resolution=0.1):
    """A GridMap holding exactly `cells` (finest indices (n, 3)) with `values`; GridMap
    has no public cell setter, so this uses its compiled core's."""
    g = GridMap(resolution)
    keys = (np.asarray(cells, dtype=np.int64) + 32768).astype(np.uint16)
    g._set_cells(np.ascontiguousarray(keys), np.asarray(values, dtype=np.float32))
    return g


def random_octree():
    """A room scan, two pruned free blocks (16^3 and 8^3 cells), a pruned occupied block
    and scattered random cells: leaves of several sizes, some straddling the bands."""
    pts, org = room_scan()
    m = OccupancyOctree(0.1).insert_scan(pts, org)
    ar = np.arange(16) * 0.1 + 0.05
    block = np.stack(np.meshgrid(ar + 1.6, ar - 1.6, ar - 0.8, indexing="ij"), -1).reshape(-1, 3)
    m.set_cells(block, np.full(len(block), -2.0))
    ar8 = np.arange(8) * 0.1 + 0.05
    occ = np.stack(np.meshgrid(ar8 - 2.4, ar8 + 0.8, ar8, indexing="ij"), -1).reshape(-1, 3)
    m.set_cells(occ, np.full(len(occ), 3.5))
    rng = np.random.default_rng(1)
    scattered = (rng.integers(-30, 30, size=(300, 3)) + 0.5) * 0.1
    m.set_cells(scattered, rng.choice([-1.0, 1.0], size=300))
    return m


def make_map(kind):
    if kind == "octree":
        return random_octree()
    pts, org = room_scan()
    if kind == "color":
        return ColorOctree(0.1).insert_scan(pts, org, colors=np.ones((len(pts), 3)))
    m = random_octree()   # the same cells in a grid
    centers, states = finest_cells(m)
    values = np.where(states == 1, 2.0, -2.0)
    return grid_with(np.floor(centers / 0.1).astype(np.int64), values)


def finest_cells(m):
    """(centers (n, 3), state (n,): 1 occupied, 0 free) of every finest cell the map's
    leaves cover, each state read back through ``is_occupied``."""
    table = m.leaves() if hasattr(m, "leaves") else m.cells()
    centers, sizes = table[0], table[1]
    res = m.resolution
    out = []
    for size in np.unique(sizes):
        side = int(round(size / res))
        rows = centers[sizes == size]
        off = (np.arange(side) - (side - 1) / 2.0) * res
        cube = np.stack(np.meshgrid(off, off, off, indexing="ij"), -1).reshape(-1, 3)
        out.append((rows[:, None, :] + cube[None]).reshape(-1, 3))
    c = np.concatenate(out) if out else np.empty((0, 3))
    occ, unknown = m.is_occupied(c, return_unknown=True)
    assert not unknown.any()
    return c, occ.astype(np.int8)


def reference(m, z_min, z_max, grid):
    """The projection's rule cell by cell on the finest cells, over `grid`'s cells."""
    c, state = finest_cells(m)
    res = m.resolution
    k = np.floor(c / res + 1e-6).astype(np.int64)       # finest indices (centers: +0.5)
    in_band = (k[:, 2] * res <= z_max) & ((k[:, 2] + 1) * res > z_min)
    f = int(round(grid.resolution / res))
    first = np.rint(grid.origin / grid.resolution).astype(np.int64)
    ij = k[:, :2] // f - first
    inside = in_band & (ij >= 0).all(1) & (ij < grid.shape).all(1)
    known = np.zeros(grid.shape, bool)
    occupied = np.zeros(grid.shape, bool)
    known[ij[inside, 0], ij[inside, 1]] = True
    sel = inside & (state == 1)
    occupied[ij[sel, 0], ij[sel, 1]] = True
    return np.where(occupied, 1, np.where(known, 0, -1)).astype(np.int8)


# --------------------------------------------------------------------------- #
# exactness
# --------------------------------------------------------------------------- #
@pytest.fixture(scope="module")
def maps():
    return {kind: make_map(kind) for kind in ("octree", "color", "grid")}


def test_scene_has_pruned_leaves(maps):
    m = maps["octree"]
    sizes = m.leaves().sizes
    assert (sizes >= 0.8 - 1e-9).any() and (sizes > 0.1 + 1e-9).sum() > 10


@pytest.mark.parametrize("kind", ["octree", "color", "grid"])
@pytest.mark.parametrize("band", [(0.05, 0.55), (-0.33, 0.07), (0.42, 0.42), (-3.0, 3.0)])
@pytest.mark.parametrize("factor", [1, 2, 3, 8])
def test_projection_matches_brute_force(maps, kind, band, factor):
    m = maps[kind]
    grid = m.project_2d(*band, resolution=None if factor == 1 else 0.1 * factor)
    assert grid.states.dtype == np.int8 and grid.resolution == pytest.approx(0.1 * factor)
    assert_array_equal(grid.states, reference(m, *band, grid))
    assert {-1, 0, 1} >= set(np.unique(grid.states).tolist())
    lo, hi = m.bounds
    # the default area: the map's bounds in x, y, extended to whole cells
    assert (grid.origin <= lo[:2] + 1e-9).all()
    assert (grid.origin + np.array(grid.shape) * grid.resolution >= hi[:2] - 1e-9).all()
    assert (grid.origin > lo[:2] - grid.resolution - 1e-9).all()


@pytest.mark.parametrize("kind", ["octree", "grid"])
@pytest.mark.parametrize("bbox, factor", [([[-0.73, 0.21], [2.04, 2.6]], 1),
                                          ([[-5.0, -5.0], [-1.0, 0.3]], 3),
                                          ([[0.0, 0.0], [0.8, 0.8]], 4)])
def test_projection_in_a_box(maps, kind, bbox, factor):
    m = maps[kind]
    grid = m.project_2d(0.05, 0.85, resolution=0.1 * factor, bbox=bbox)
    cell = 0.1 * factor
    assert_allclose(grid.origin, np.floor(np.array(bbox[0]) / cell + 1e-9) * cell)
    assert grid.shape == tuple(int(n) for n in np.ceil(np.array(bbox[1]) / cell - 1e-9)
                               - np.floor(np.array(bbox[0]) / cell + 1e-9))
    assert_array_equal(grid.states, reference(m, 0.05, 0.85, grid))


def test_band_edges_and_a_pruned_leaf():
    """One pruned 0.8 m free leaf and one occupied cell on top of it: the band's layers
    are those holding a point of [z_min, z_max] (a bound on a boundary belongs to the
    layer above it)."""
    ar = np.arange(8) * 0.1 + 0.05
    block = np.stack(np.meshgrid(ar, ar, ar, indexing="ij"), -1).reshape(-1, 3)
    m = OccupancyOctree(0.1).set_cells(block, np.full(len(block), -2.0))
    m.set_cells([[0.25, 0.35, 0.85]], [2.0])
    assert m.num_leaves == 2
    top = m.project_2d(0.8, 0.8)           # only the layer 0.8-0.9 m
    assert top.states[2, 3] == 1 and (top.states == -1).sum() == 63
    assert m.project_2d(0.0, 0.8).states[2, 3] == 1        # 0.8 is in the layer above
    below = m.project_2d(0.0, 0.8 - 1e-6).states
    assert (below == 0).all() and below.shape == (8, 8)
    assert m.project_2d(0.3, 0.3).states.tolist() == [[0] * 8] * 8
    assert (m.project_2d(5.0, 6.0).states == -1).all()    # a band above the map
    coarse = m.project_2d(0.7, 0.9, resolution=0.4)
    assert coarse.states.tolist() == [[1, 0], [0, 0]]


def test_coarse_cell_mixing_free_and_unknown_is_free_and_unknown_column_unknown():
    g = grid_with([[0, 0, 0], [5, 0, 0]], [-2.0, 2.0])
    grid = g.project_2d(0.0, 0.05, resolution=0.3)
    assert grid.shape == (2, 1) and grid.states.tolist() == [[0], [1]]
    grid = g.project_2d(0.0, 0.05, bbox=[[0, 0], [0.6, 0.1]])
    assert grid.states[:, 0].tolist() == [0, -1, -1, -1, -1, 1]


def test_empty_map_and_far_box():
    m = OccupancyOctree(0.1)
    grid = m.project_2d(0.0, 1.0)
    assert grid.shape == (0, 0)
    grid = m.project_2d(0.0, 1.0, bbox=[[0, 0], [0.5, 0.3]])
    assert grid.shape == (5, 3) and (grid.states == -1).all()
    far = random_octree().project_2d(0.0, 1.0, bbox=[[1e9, 1e9], [1e9 + 1, 1e9 + 1]])
    assert (far.states == -1).all()


def test_projection_is_vectorised_over_big_leaves():
    """A map of a few huge pruned leaves projects fast (no per-cell expansion)."""
    ar = np.arange(8) * 0.1 + 0.05
    block = np.stack(np.meshgrid(ar, ar, ar, indexing="ij"), -1).reshape(-1, 3)
    m = OccupancyOctree(0.1)
    for level in range(6):   # set 8^3 cells at 0.1, let the tree prune to a 0.8 m leaf
        m.set_cells(block + 0.8 * level, np.full(len(block), -2.0))
    m.set_cells([[0.05, 0.05, 0.05]], [-2.0])
    assert m.num_leaves == 6
    grid = m.project_2d(0.0, 5.0)
    assert grid.shape == (48, 48) and (np.diag(grid.states[::8, ::8]) == 0).all()


@pytest.mark.parametrize("kwargs, exc, match", [
    (dict(z_min=1.0, z_max=0.0), ValueError, r"z_min must be <= z_max"),
    (dict(z_min=np.nan, z_max=1.0), ValueError, r"z_min must lie in"),
    (dict(z_min=0.0, z_max=np.inf), ValueError, r"z_max must lie in"),
    (dict(z_min="0", z_max=1.0), TypeError, r"z_min must be a real number"),
    (dict(z_min=0.0, z_max=1.0, resolution=0.15), ValueError,
     r"resolution must be a whole multiple .* of the map's resolution 0.1, got 0.15"),
    (dict(z_min=0.0, z_max=1.0, resolution=0.05), ValueError, r"resolution must be a whole"),
    (dict(z_min=0.0, z_max=1.0, resolution=-0.2), ValueError, r"resolution must lie in"),
    (dict(z_min=0.0, z_max=1.0, bbox=[0, 0, 1, 1]), ValueError, r"bbox must have shape \(2, 2\)"),
    (dict(z_min=0.0, z_max=1.0, bbox=[[0, 0, 0], [1, 1, 1]]), ValueError,
     r"bbox must have shape \(2, 2\)"),
    (dict(z_min=0.0, z_max=1.0, bbox=[[0, 1], [1, 0]]), ValueError, r"bbox must have min < max"),
    (dict(z_min=0.0, z_max=1.0, bbox=[[0, np.nan], [1, 1]]), ValueError, r"bbox must be finite"),
    (dict(z_min=0.0, z_max=1.0, bbox=[["a", "b"], ["c", "d"]]), TypeError, r"bbox must hold"),
    (dict(z_min=0.0, z_max=1.0, bbox=[[0, 0], [1e6, 1e6]]), ValueError,
     r"bbox .* needs 1e\+07 x 1e\+07 cells, more than max_cells=33554432"),
    (dict(z_min=0.0, z_max=1.0, bbox=[[0, 0], [1, 1]], max_cells=99), ValueError,
     r"more than max_cells=99"),
    (dict(z_min=0.0, z_max=1.0, max_cells=0), ValueError, r"max_cells"),
    (dict(z_min=0.0, z_max=1.0, max_cells=2.0), TypeError, r"max_cells"),
])
def test_project_2d_rejects_bad_input(kwargs, exc, match):
    m = OccupancyOctree(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0])
    with pytest.raises(exc, match=match):
        m.project_2d(**kwargs)


# --------------------------------------------------------------------------- #
# the grid's own methods
# --------------------------------------------------------------------------- #
def test_grid_cells_and_ros_arrays():
    states = np.array([[1, 0, -1], [0, 0, 1]], dtype=np.int8)   # nx=2, ny=3
    grid = OccupancyGrid2D(states, origin=[-1.0, 2.0], resolution=0.5)
    centers = grid.cell_centers()
    assert centers.shape == (2, 3, 2)
    assert_allclose(centers[1, 2], [-0.25, 3.25])
    idx = grid.world_to_cell(centers.reshape(-1, 2))
    assert_array_equal(idx.reshape(2, 3, 2)[..., 0], [[0] * 3, [1] * 3])
    assert_array_equal(grid.world_to_cell([[-1.0, 2.0], [-1.01, 3.6]]), [[0, 0], [-1, 3]])
    ros = grid.to_ros_array()
    assert ros.dtype == np.int8 and ros.shape == (3, 2)
    assert ros.tolist() == [[100, 0], [0, 0], [-1, 100]]      # row j = y index j
    img = grid.occupancy_image()
    assert img.dtype == np.uint8 and img.shape == (3, 2)
    assert img.tolist() == [[205, 0], [254, 254], [0, 254]]   # top row = largest y


@pytest.mark.parametrize("args, exc, match", [
    (([[2, 0]], [0, 0], 0.1), ValueError, r"states must hold -1 \(unknown\), 0 \(free\)"),
    (([0, 1], [0, 0], 0.1), ValueError, r"states must have shape \(nx, ny\)"),
    (([[0.0, 1.0]], [0, 0], 0.1), TypeError, r"states must hold integers \(-1, 0 or 1\), got dtype float64"),
    (([[0, 1]], [0, 0, 0], 0.1), ValueError, r"origin must have shape \(2,\)"),
    (([[0, 1]], [0, np.inf], 0.1), ValueError, r"origin must be finite"),
    (([[0, 1]], [0, 0], 0.0), ValueError, r"resolution must lie in"),
])
def test_grid_rejects_bad_input(args, exc, match):
    with pytest.raises(exc, match=match):
        OccupancyGrid2D(*args)


def test_world_to_cell_rejects_bad_points():
    grid = OccupancyGrid2D([[0]], [0, 0], 1.0)
    with pytest.raises(ValueError, match=r"points must have shape \(n_points, 2\)"):
        grid.world_to_cell([[0, 0, 0]])
    with pytest.raises(ValueError, match=r"points must be finite"):
        grid.world_to_cell([[np.nan, 0]])
    with pytest.raises(ValueError, match=r"overflows int64"):
        grid.world_to_cell([[1e300, 0]])


# --------------------------------------------------------------------------- #
# map_server / Nav2 files
# --------------------------------------------------------------------------- #
def test_ros_files_read_back_with_pillow_and_yaml(maps, tmp_path):
    grid = maps["octree"].project_2d(0.05, 0.85, resolution=0.2)
    yaml_path, pgm = grid.save_ros_map(tmp_path / "level0.yaml")
    assert (yaml_path, pgm) == (tmp_path / "level0.yaml", tmp_path / "level0.pgm")
    doc = yaml.safe_load(yaml_path.read_text())
    assert doc["image"] == "level0.pgm" and doc["mode"] == "trinary"
    assert doc["resolution"] == grid.resolution and doc["negate"] == 0
    assert doc["origin"] == [float(grid.origin[0]), float(grid.origin[1]), 0.0]
    assert (doc["occupied_thresh"], doc["free_thresh"]) == (0.65, 0.196)
    with Image.open(pgm) as im:
        assert im.format == "PPM" and im.mode == "L"
        assert im.size == grid.shape            # (width, height) = (nx, ny)
        pixels = np.array(im)
    assert set(np.unique(pixels).tolist()) <= {0, 205, 254}
    nx, ny = grid.shape
    for i, j in [(0, 0), (nx - 1, ny - 1), (nx // 2, ny // 3)] + \
            [tuple(int(v) for v in np.argwhere(grid.states == 1)[0])]:
        expected = {1: 0, 0: 254, -1: 205}[int(grid.states[i, j])]
        assert pixels[ny - 1 - j, i] == expected         # top row = max y
    # map_server's trinary rule on the written values and thresholds gives the states
    occ = (255 - pixels) / 255.0
    states = np.where(occ > doc["occupied_thresh"], 1,
                      np.where(occ < doc["free_thresh"], 0, -1))
    assert_array_equal(states[::-1].T, grid.states)


def test_round_trip_and_path_forms(maps, tmp_path):
    grid = maps["grid"].project_2d(-0.33, 0.07, resolution=0.3)
    for name in ("a", "b.yaml", "c.yml"):
        yaml_path, pgm = grid.save_ros_map(str(tmp_path / name))
        back = OccupancyGrid2D.load_ros_map(yaml_path)
        assert_array_equal(back.states, grid.states)
        assert_array_equal(back.origin, grid.origin)      # full precision
        assert back.resolution == grid.resolution
    assert (tmp_path / "a.yaml").exists() and (tmp_path / "c.pgm").exists()
    odd = OccupancyGrid2D([[1, 0]], [1e-5, -3.25e-7], 1e-5)
    odd.save_ros_map(tmp_path / "odd name.yaml")
    back = OccupancyGrid2D.load_ros_map(tmp_path / "odd name.yaml")
    assert_array_equal(back.origin, odd.origin) and back.resolution == 1e-5


def test_loads_map_saver_style_files(tmp_path):
    """A map written as map_saver writes it (comment in the header, 6-digit numbers),
    a plain (P2) image with negate, and an image Pillow wrote."""
    pixels = np.array([[0, 205], [254, 254], [205, 0]], dtype=np.uint8)   # 2 wide, 3 high
    (tmp_path / "m.pgm").write_bytes(b"P5\n# CREATOR: map_saver.cpp 0.050 m/pix\n2 3\n255\n"
                                     + pixels.tobytes())
    (tmp_path / "m.yaml").write_text("image: m.pgm\nresolution: 0.050000\n"
                                     "origin: [-10.000000, -5.500000, 0.000000]\nnegate: 0\n"
                                     "occupied_thresh: 0.65\nfree_thresh: 0.196\n\n")
    grid = OccupancyGrid2D.load_ros_map(tmp_path / "m.yaml")
    assert grid.states.tolist() == [[-1, 0, 1], [1, 0, -1]]
    assert grid.origin.tolist() == [-10.0, -5.5] and grid.resolution == 0.05
    inverted = 255 - pixels
    (tmp_path / "n.pgm").write_bytes(b"P2 2 # plain\n3 255\n" + " ".join(
        str(v) for v in inverted.ravel()).encode() + b"\n")
    (tmp_path / "n.yaml").write_text("image: n.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n"
                                     "negate: 1\noccupied_thresh: 0.65\nfree_thresh: 0.196\n"
                                     "mode: trinary\n")
    assert OccupancyGrid2D.load_ros_map(tmp_path / "n.yaml").states.tolist() == \
        [[-1, 0, 1], [1, 0, -1]]
    Image.fromarray(pixels).save(tmp_path / "p.pgm")
    (tmp_path / "p.yaml").write_text(f"image: {tmp_path / 'p.pgm'}\nresolution: 1\n"
                                     "origin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\n"
                                     "free_thresh: 0.196\n")
    assert OccupancyGrid2D.load_ros_map(tmp_path / "p.yaml").states.tolist() == \
        [[-1, 0, 1], [1, 0, -1]]


GOOD_YAML = ("image: m.pgm\nresolution: 0.1\norigin: [0.0, 0.0, 0.0]\nnegate: 0\n"
             "occupied_thresh: 0.65\nfree_thresh: 0.196\n")
GOOD_PGM = b"P5\n2 2\n255\n\x00\xfe\xcd\x00"


@pytest.mark.parametrize("yaml_text, pgm, match", [
    ("image: [unclosed\n", GOOD_PGM, r"not a valid YAML file"),
    ("- just\n- a list\n", GOOD_PGM, r"must hold a mapping of keys, got list"),
    (GOOD_YAML.replace("negate: 0\n", ""), GOOD_PGM, r"lacks negate"),
    (GOOD_YAML.replace("resolution: 0.1", "resolution: fine"), GOOD_PGM,
     r"resolution must be a number, got 'fine'"),
    (GOOD_YAML.replace("resolution: 0.1", "resolution: -0.1"), GOOD_PGM,
     r"resolution must be > 0"),
    (GOOD_YAML.replace("resolution: 0.1", "resolution: .nan"), GOOD_PGM,
     r"resolution must be finite"),
    (GOOD_YAML.replace("[0.0, 0.0, 0.0]", "[0.0, 0.0]"), GOOD_PGM, r"origin must be a list"),
    (GOOD_YAML.replace("[0.0, 0.0, 0.0]", "[0.0, 0.0, 0.5]"), GOOD_PGM, r"yaw must be 0"),
    (GOOD_YAML.replace("[0.0, 0.0, 0.0]", "[0.0, x, 0.0]"), GOOD_PGM,
     r"origin must be a number"),
    (GOOD_YAML.replace("negate: 0", "negate: 2"), GOOD_PGM, r"negate must be 0 or 1"),
    (GOOD_YAML + "mode: scale\n", GOOD_PGM, r"mode must be 'trinary'"),
    (GOOD_YAML.replace("free_thresh: 0.196", "free_thresh: 0.7"), GOOD_PGM,
     r"0 <= free_thresh < occupied_thresh <= 1"),
    (GOOD_YAML.replace("image: m.pgm", "image: 5"), GOOD_PGM, r"image must be a file name"),
    (GOOD_YAML, b"\x89PNG\r\n\x1a\n....", r"not a PGM image"),
    (GOOD_YAML, GOOD_PGM[:-1], r"PGM data truncated: 2 x 2 pixels need 4 bytes, got 3"),
    (GOOD_YAML, GOOD_PGM + b"\n", r"PGM data followed by extra bytes"),
    (GOOD_YAML, b"P5\n2 2\n", r"malformed PGM header: expected whitespace and the maxval"),
    (GOOD_YAML, b"P5\n2 x2\n255\n\x00\x00\x00\x00", r"expected whitespace and the height"),
    (GOOD_YAML, b"P5\n0 2\n255\n", r"width and height must be >= 1"),
    (GOOD_YAML, b"P5\n2 2\n70000\n" + bytes(8), r"maxval in \[1, 65535\]"),
    (GOOD_YAML, b"P5\n2 2\n100\n\x00\xfe\xcd\x00", r"pixel values must be <= maxval 100"),
    (GOOD_YAML, b"P2\n2 2\n255\n0 1 2\n", r"plain PGM data must be 4 decimal numbers"),
    (GOOD_YAML, b"P2\n2 2\n255\n0 1 2 -3\n", r"plain PGM data must be 4 decimal numbers"),
])
def test_load_ros_map_rejects_malformed_files(tmp_path, yaml_text, pgm, match):
    (tmp_path / "m.yaml").write_text(yaml_text)
    (tmp_path / "m.pgm").write_bytes(pgm)
    with pytest.raises(ValueError, match=match) as info:
        OccupancyGrid2D.load_ros_map(tmp_path / "m.yaml")
    assert "m.yaml" in str(info.value) or "m.pgm" in str(info.value)


def test_load_ros_map_missing_files_and_bad_paths(tmp_path):
    with pytest.raises(FileNotFoundError):
        OccupancyGrid2D.load_ros_map(tmp_path / "none.yaml")
    (tmp_path / "m.yaml").write_text(GOOD_YAML)
    with pytest.raises(FileNotFoundError, match="m.pgm"):
        OccupancyGrid2D.load_ros_map(tmp_path / "m.yaml")
    with pytest.raises(TypeError, match="path must be a str or os.PathLike, got int"):
        OccupancyGrid2D.load_ros_map(3)


def test_save_ros_map_rejects_bad_paths_and_empty_grids(tmp_path):
    grid = OccupancyGrid2D([[0, 1]], [0, 0], 0.1)
    with pytest.raises(ValueError, match=r"path must end in .yaml or .yml"):
        grid.save_ros_map(tmp_path / "map.pgm")
    with pytest.raises(TypeError, match=r"path must be a str or os.PathLike"):
        grid.save_ros_map(None)
    with pytest.raises(FileNotFoundError):
        grid.save_ros_map(tmp_path / "no" / "such" / "map.yaml")
    with pytest.raises(ValueError, match=r"cannot write an empty grid"):
        OccupancyOctree(0.1).project_2d(0, 1).save_ros_map(tmp_path / "e.yaml")


EMPTY_KINDS = {
    "octree": lambda: OccupancyOctree(0.1),
    "grid": lambda: GridMap(0.1),
    "color": lambda: ColorOctree(0.1),
}


@pytest.mark.parametrize("kind", list(EMPTY_KINDS))
def test_empty_maps_project_to_empty_or_unknown_grids(kind):
    """Empty in, empty out (issue 40): no bbox gives a (0, 0) grid whose every view
    is empty; a bbox gives its cells, all unknown."""
    m = EMPTY_KINDS[kind]()
    grid = m.project_2d(0.0, 1.0)
    assert grid.shape == (0, 0) and grid.states.dtype == np.int8
    assert grid.to_ros_array().shape == (0, 0) and grid.occupancy_image().shape == (0, 0)
    assert grid.cell_centers().shape == (0, 0, 2)
    assert grid.frontiers().cells.shape == (0, 2) and grid.frontiers().n_clusters == 0
    boxed = m.project_2d(0.0, 1.0, resolution=0.2, bbox=[[-0.3, 0.0], [0.3, 0.2]])
    assert boxed.shape == (4, 1) and (boxed.states == -1).all()
    assert (boxed.to_ros_array() == -1).all()
    assert boxed.frontiers().n_clusters == 0


def test_known_cells_outside_the_box_or_band_project_to_unknown():
    m = OccupancyOctree(0.1).insert_scan([[1.0, 0.05, 0.05]], [0.05, 0.05, 0.05])
    outside = m.project_2d(0.0, 1.0, bbox=[[5.0, 5.0], [5.5, 5.3]])
    assert outside.shape == (5, 3) and (outside.states == -1).all()
    above = m.project_2d(3.0, 4.0)      # the map's x-y bounds, no cell in the band
    assert above.shape[0] > 0 and (above.states == -1).all()
    assert above.frontiers().n_clusters == 0
