"""Maps out: PLY / PCD / Open3D exports and the distance field (occgp.io._export)."""

import struct
import sys

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from occgp import GridMap, OccupancyOctree
from occgp.io import _octomap_format as fmt
from occgp.nav._distance import distance_field
from occgp.io._export import (_CUBE_TRIANGLES, _finest_cells, leaf_cells, save_pcd, save_ply,
                              to_open3d)
from occgp.io import read_pcd
from _helpers import read_ply


# --------------------------------------------------------------------------- #
# fixtures and a tiny independent PLY reader
# --------------------------------------------------------------------------- #
@pytest.fixture
def small_map():
    """Three occupied single cells, one pruned occupied block of 2x2x2, two free cells."""
    m = OccupancyOctree(0.5)
    block = np.array([[x, y, z] for x in (4.25, 4.75) for y in (0.25, 0.75)
                      for z in (0.25, 0.75)])
    points = np.vstack([[[0.25, 0.25, 0.25], [1.25, 0.25, 2.75], [-1.75, 3.25, 0.75]],
                        block, [[2.25, 2.25, 0.25], [2.75, 2.25, 0.25]]])
    values = np.r_[1.0, 2.0, 3.0, np.full(8, 1.5), -1.0, -0.5]
    return m.set_cells(points, values).prune()


# --------------------------------------------------------------------------- #
# PLY
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("binary", [True, False])
def test_ply_points_hold_leaf_centers_sizes_and_probabilities(small_map, tmp_path, binary):
    path = tmp_path / "map.ply"
    save_ply(small_map, path, binary=binary)
    data, comments = read_ply(path)
    v = data["vertex"]
    centers, sizes, log_odds = small_map.leaves(occupied_only=True)
    assert len(v) == len(centers) == 4
    xyz = np.column_stack([v["x"], v["y"], v["z"]])
    assert_array_equal(xyz, centers.astype(np.float32))
    assert_array_equal(v["size"], sizes.astype(np.float32))
    assert sorted(v["size"].tolist()) == [0.5, 0.5, 0.5, 1.0]        # the pruned block
    assert_array_equal(v["probability"], small_map.occupancy(centers).astype(np.float32))
    assert "resolution 0.5" in comments[0]
    # height colours: lowest cell at viridis' start, highest at its end
    rgb = np.column_stack([v["red"], v["green"], v["blue"]])
    assert rgb[np.argmin(v["z"])].tolist() == [68, 1, 84]
    assert rgb[np.argmax(v["z"])].tolist() == [253, 231, 37]


def test_ply_binary_and_ascii_agree(small_map, tmp_path):
    save_ply(small_map, tmp_path / "b.ply", cubes=True)
    save_ply(small_map, tmp_path / "a.ply", cubes=True, binary=False)
    b, a = read_ply(tmp_path / "b.ply")[0], read_ply(tmp_path / "a.ply")[0]
    for name in ("vertex", "face"):
        for field in b[name].dtype.names:
            assert_array_equal(a[name][field], b[name][field])


def test_ply_free_cells_and_no_colour(small_map, tmp_path):
    save_ply(small_map, tmp_path / "free.ply", occupied=False, color=False)
    v = read_ply(tmp_path / "free.ply")[0]["vertex"]
    assert v.dtype.names == ("x", "y", "z", "size", "probability")
    assert sorted(v["x"].tolist()) == [2.25, 2.75]
    assert (v["probability"] < 0.5).all()


def test_ply_cubes_are_closed_outward_boxes(small_map, tmp_path):
    save_ply(small_map, tmp_path / "cubes.ply", cubes=True)
    data, _ = read_ply(tmp_path / "cubes.ply")
    v, f = data["vertex"], data["face"]
    centers, sizes, _ = small_map.leaves(occupied_only=True)
    n = len(centers)
    assert len(v) == 8 * n and len(f) == 12 * n
    assert (f["n"] == 3).all()
    xyz = np.column_stack([v["x"], v["y"], v["z"]]).astype(np.float64).reshape(n, 8, 3)
    assert_allclose(xyz.mean(axis=1), centers, atol=1e-6)
    assert_allclose(xyz.max(axis=1) - xyz.min(axis=1), np.repeat(sizes[:, None], 3, 1),
                    atol=1e-6)
    assert_array_equal(v["size"].reshape(n, 8), np.repeat(sizes[:, None], 8, 1))
    # each cube's triangles index only its own 8 vertices, cover 6 faces and face outwards
    tri = f["v"].reshape(n, 12, 3)
    assert_array_equal(tri // 8, np.arange(n)[:, None, None] * np.ones((1, 12, 3), int))
    flat = xyz.reshape(-1, 3)
    a, b, c = flat[f["v"][:, 0]], flat[f["v"][:, 1]], flat[f["v"][:, 2]]
    normal = np.cross(b - a, c - a)
    outward = (a + b + c) / 3 - np.repeat(centers, 12, axis=0)
    assert (np.einsum("ij,ij->i", normal, outward) > 0).all()
    area = 0.5 * np.linalg.norm(normal, axis=1).reshape(n, 12).sum(axis=1)
    assert_allclose(area, 6 * sizes**2, rtol=1e-6)


def test_cube_triangles_use_every_corner_twice_per_axis():
    counts = np.bincount(_CUBE_TRIANGLES.ravel(), minlength=8)
    assert counts.sum() == 36 and (counts >= 3).all()


def test_ply_of_an_empty_map_and_of_a_grid_map(tmp_path):
    save_ply(OccupancyOctree(0.1), tmp_path / "empty.ply", cubes=True)
    data, _ = read_ply(tmp_path / "empty.ply")
    assert len(data["vertex"]) == 0 and len(data["face"]) == 0
    g = GridMap(0.1).insert_scan([[1.0, 0.0, 0.0]], [0.0, 0.0, 0.0])
    save_ply(g, tmp_path / "grid.ply", binary=False)
    v = read_ply(tmp_path / "grid.ply")[0]["vertex"]
    assert_allclose(np.column_stack([v["x"], v["y"], v["z"]]), [[1.05, 0.05, 0.05]],
                    atol=1e-6)
    assert_allclose(v["probability"], [0.7], atol=1e-6)


# --------------------------------------------------------------------------- #
# PCD
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("binary", [True, False])
def test_pcd_round_trip(small_map, tmp_path, binary):
    path = tmp_path / "map.pcd"
    save_pcd(small_map, path, binary=binary)
    scan, fields = read_pcd(path, return_fields=True)
    centers, _, _ = small_map.leaves(occupied_only=True)
    assert_array_equal(scan.points, centers.astype(np.float32))
    assert_array_equal(scan.origin, [0.0, 0.0, 0.0])
    assert set(fields) == {"x", "y", "z", "intensity"}
    assert_array_equal(fields["intensity"], small_map.occupancy(centers).astype(np.float32))
    header = open(path, "rb").read(400)
    assert b"VERSION 0.7" in header
    assert (b"DATA binary" if binary else b"DATA ascii") in header
    save_pcd(small_map, tmp_path / "free.pcd", occupied=False)
    assert len(read_pcd(tmp_path / "free.pcd").points) == 2


# --------------------------------------------------------------------------- #
# finest cells and Open3D
# --------------------------------------------------------------------------- #
def test_finest_cells_are_the_expanded_maps_centers(small_map):
    expanded = OccupancyOctree.from_bytes(small_map.to_bytes()).expand()
    for occupied in (True, False):
        got = _finest_cells(small_map, occupied)
        want = expanded.extract_points(occupied)[0]
        assert got.shape == want.shape
        order_g = np.lexsort(got.T)
        order_w = np.lexsort(want.T)
        assert_array_equal(got[order_g], want[order_w])      # bit for bit (keyToCoord)
    assert len(_finest_cells(small_map)) == 3 + 8


def test_leaf_cells_takes_the_old_keyword_centres_with_a_warning(small_map):
    centers, sizes, _ = small_map.leaves()
    index, owner = leaf_cells(centers, sizes, 0.5)
    assert len(index) == len(owner) == (len(sizes) - 1) + 8      # one pruned 2x2x2 block
    with pytest.warns(DeprecationWarning, match="leaf_cells: .*'centres' .*use 'centers'"):
        old = leaf_cells(centres=centers, sizes=sizes, resolution=0.5)
    assert_array_equal(old[0], index)
    assert_array_equal(old[1], owner)


def test_finest_cells_cap_is_checked_before_allocating(small_map):
    assert len(_finest_cells(small_map, max_cells=11)) == 11
    with pytest.raises(ValueError, match=r"occupied leaves expand to 11 finest cells.*"
                                         r"max_cells=10"):
        _finest_cells(small_map, max_cells=10)
    # a map whose root is one free leaf: 2**48 finest cells, refused without allocating
    root_leaf = fmt.write_header(False, 1, 1.0) + struct.pack("<f", -2.0) + b"\x00"
    m = OccupancyOctree.from_bytes(root_leaf)
    assert m.leaves().sizes.tolist() == [65536.0]
    with pytest.raises(ValueError, match=r"free leaves expand to 281474976710656 finest"):
        _finest_cells(m, occupied=False)
    with pytest.raises(ValueError, match=r"281474976710656 .*max_voxels=4194304"):
        to_open3d(m, occupied=False)


def test_to_open3d_without_open3d_names_the_extra(small_map, monkeypatch):
    monkeypatch.setitem(sys.modules, "open3d", None)
    with pytest.raises(ImportError, match=r"occgp\[open3d\].*open3d-cpu"):
        to_open3d(small_map)


def test_to_open3d_rejects_bad_arguments(small_map):
    with pytest.raises(ValueError, match=r"kind must be one of \('voxels', 'points'\)"):
        to_open3d(small_map, kind="mesh")
    with pytest.raises(TypeError, match="occupied must be a bool"):
        to_open3d(small_map, occupied=1)
    with pytest.raises(TypeError, match="tree must be an OccupancyOctree or a GridMap"):
        to_open3d(np.zeros((3, 3)))


def test_to_open3d_geometries(small_map, tmp_path):
    o3d = pytest.importorskip("open3d")
    grid = to_open3d(small_map)
    assert isinstance(grid, o3d.geometry.VoxelGrid)
    assert grid.voxel_size == 0.5
    voxels = grid.get_voxels()
    assert len(voxels) == 11
    centers = np.array([grid.get_voxel_center_coordinate(v.grid_index) for v in voxels])
    want = _finest_cells(small_map)
    assert_allclose(centers[np.lexsort(centers.T)], want[np.lexsort(want.T)], atol=1e-9)
    cloud = to_open3d(small_map, kind="points", occupied=False)
    assert isinstance(cloud, o3d.geometry.PointCloud)
    assert_allclose(np.asarray(cloud.points), small_map.extract_points(False)[0])
    assert len(to_open3d(OccupancyOctree(0.1)).get_voxels()) == 0


def test_open3d_reads_the_ply_files(small_map, tmp_path):
    o3d = pytest.importorskip("open3d")
    for binary in (True, False):
        save_ply(small_map, tmp_path / "p.ply", binary=binary)
        cloud = o3d.io.read_point_cloud(str(tmp_path / "p.ply"))
        assert_allclose(np.asarray(cloud.points), small_map.extract_points()[0], atol=1e-6)
        assert cloud.has_colors()
        save_ply(small_map, tmp_path / "c.ply", binary=binary, cubes=True)
        mesh = o3d.io.read_triangle_mesh(str(tmp_path / "c.ply"))
        assert len(mesh.vertices) == 32 and len(mesh.triangles) == 48


# --------------------------------------------------------------------------- #
# bad input of the writers
# --------------------------------------------------------------------------- #
def test_writers_reject_bad_input(small_map, tmp_path):
    missing = tmp_path / "no" / "such" / "folder" / "map.ply"
    with pytest.raises(OSError, match=r"folder/map\.ply"):
        save_ply(small_map, missing)
    with pytest.raises(OSError, match=r"folder/map\.pcd"):
        save_pcd(small_map, missing.with_suffix(".pcd"))
    with pytest.raises(TypeError, match="tree must be an OccupancyOctree or a GridMap, got"):
        save_ply("map.bt", tmp_path / "x.ply")
    with pytest.raises(TypeError, match="path must be a str or os.PathLike, got int"):
        save_ply(small_map, 3)
    with pytest.raises(TypeError, match="binary must be a bool, got str"):
        save_ply(small_map, tmp_path / "x.ply", binary="yes")
    with pytest.raises(TypeError, match="cubes must be a bool"):
        save_ply(small_map, tmp_path / "x.ply", cubes=None)
    with pytest.raises(TypeError, match="occupied must be a bool"):
        save_pcd(small_map, tmp_path / "x.pcd", occupied="yes")
    with pytest.raises(TypeError, match="path must be a str or os.PathLike"):
        save_pcd(small_map, None)
    assert not (tmp_path / "x.ply").exists() and not (tmp_path / "x.pcd").exists()


# --------------------------------------------------------------------------- #
# distance field
# --------------------------------------------------------------------------- #
def test_distance_field_of_one_cell_is_the_distance_to_its_center():
    m = OccupancyOctree(0.25).set_cells([[0.6, -0.1, 1.1]], [2.0])
    c = m.key_to_coord(m.coord_to_key([[0.6, -0.1, 1.1]]))[0]
    field = distance_field(m, [[-0.4, -1.0, 0.3], [1.3, 0.9, 1.9]], unknown="free")
    assert field.resolution == 0.25
    assert_array_equal(field.origin, [-0.5, -1.0, 0.25])           # aligned to the cells
    assert field.distances.shape == (8, 8, 7)
    centers = field.centers()
    assert_allclose(field.distances, np.linalg.norm(centers - c, axis=-1),
                    rtol=1e-14, atol=1e-15)
    assert field.distances.min() == 0.0


def test_distance_field_unknown_as_occupied_or_free():
    m = OccupancyOctree(1.0)
    row = [[x + 0.5, 0.5, 0.5] for x in range(5)]
    m.set_cells(row, [-1.0, -1.0, -1.0, -1.0, 2.0])          # four free cells, then a wall
    box = [[0, 0, 0], [5, 2, 1]]                              # y = 1 row is unknown
    free = distance_field(m, box, unknown="free").distances
    occ = distance_field(m, box).distances
    assert_allclose(free[:, 0, 0], [4, 3, 2, 1, 0])
    assert_allclose(free[:, 1, 0], np.sqrt(np.arange(4, -1, -1) ** 2 + 1.0))
    assert_array_equal(occ[:, 0, 0], [1, 1, 1, 1, 0])        # the unknown row next door
    assert_array_equal(occ[:, 1, 0], 0)
    # with no obstacle at all: inf
    assert np.isinf(distance_field(m, [[0, 0, 0], [4, 1, 1]], unknown="free").distances).all()


def test_distance_field_grid_snaps_corners_on_multiples_of_the_resolution():
    m = OccupancyOctree(0.1)
    field = distance_field(m, [[0.3, -0.7, 0.0], [0.7, 0.1, 0.2]])
    assert field.distances.shape == (4, 8, 2)
    assert_allclose(field.origin, [0.3, -0.7, 0.0], atol=1e-15)
    assert (field.distances == 0).all()                      # all unknown: obstacles


def test_distance_field_at_another_resolution_and_on_a_grid_map():
    m = OccupancyOctree(1.0).set_cells([[0.5, 0.5, 0.5]], [2.0])
    field = distance_field(m, [[0, 0, 0], [2, 0.5, 0.5]], 0.5, unknown="free")
    assert field.distances.shape == (4, 1, 1)
    assert_allclose(field.distances[:, 0, 0], [0, 0, 0.5, 1.0])
    g = GridMap(1.0).insert_scan([[2.5, 0.5, 0.5]], [0.5, 0.5, 0.5])
    assert_allclose(distance_field(g, [[0, 0, 0], [3, 1, 1]]).distances[:, 0, 0], [2, 1, 0])


@pytest.mark.parametrize("bbox, kwargs, exc, match", [
    (np.zeros(3), {}, ValueError, r"bbox must have shape \(2, 3\).*got \(3,\)"),
    ([[0, 0], [1, 1]], {}, ValueError, r"bbox must have shape \(2, 3\)"),
    ([[0, 0, np.nan], [1, 1, 1]], {}, ValueError, "bbox must be finite"),
    ([[0, 0, 0], [1, 1, np.inf]], {}, ValueError, "bbox must be finite"),
    ([[0, 0, 0], [1, 0, 1]], {}, ValueError, "bbox must have min < max on every axis"),
    ([[0, 0, 2], [1, 1, 1]], {}, ValueError, "bbox must have min < max on every axis"),
    ([["a", "b", "c"], [1, 1, 1]], {}, TypeError, "bbox must hold real numbers"),
    ([[-1e30, 0, 0], [1e30, 1, 1]], {}, ValueError, r"cells, more than max_cells=8388608"),
    ([[0, 0, 0], [1, 1, 1]], {"resolution": 1e-300}, ValueError, "more than max_cells"),
    ([[0, 0, 0], [1, 1, 1]], {"resolution": 0.0}, ValueError, r"resolution must lie in \(0"),
    ([[0, 0, 0], [1, 1, 1]], {"resolution": np.nan}, ValueError, "resolution must lie in"),
    ([[0, 0, 0], [1, 1, 1]], {"resolution": "1"}, TypeError, "resolution must be a real"),
    ([[0, 0, 0], [1, 1, 1]], {"unknown": "maybe"}, ValueError, "unknown must be one of"),
    ([[0, 0, 0], [1, 1, 1]], {"max_cells": 0}, ValueError, "max_cells must be a positive"),
    ([[0, 0, 0], [1, 1, 1]], {"max_cells": 999}, ValueError, r"10 x 10 x 10 cells, more than"),
    ([[0, 0, 0], [1, 1, 1]], {"max_cells": 2.0}, TypeError, "max_cells must be"),
])
def test_distance_field_rejects_bad_input(bbox, kwargs, exc, match):
    m = OccupancyOctree(0.1)
    with pytest.raises(exc, match=match):
        distance_field(m, bbox, **kwargs)


def test_distance_field_at_the_cap_and_of_a_non_map():
    m = OccupancyOctree(0.1)
    assert distance_field(m, [[0, 0, 0], [1, 1, 1]], max_cells=1000).distances.shape == \
        (10, 10, 10)
    with pytest.raises(TypeError, match="tree must be an OccupancyOctree or a GridMap"):
        distance_field(None, [[0, 0, 0], [1, 1, 1]])
