"""The colour octree (occgp.octree.ColorOctree over liboctomap's ColorOcTree).

Occupancy is checked leaf for leaf against OccupancyOctree, colours against a
direct computation and against liboctomap's own call sequence (a small C++
program compiled here: insertPointCloud, averageNodeColor per point,
updateInnerOccupancy, write), and files against liboctomap's AbstractOcTree::read.
"""

import pickle
import shutil
import subprocess
import sys

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from occgp import OccupancyOctree
from occgp.io._export import pack_rgb, unpack_rgb
from occgp.octree import ColorLeaves, ColorOctree
from occgp.io import read_pcd

from _helpers import read_ply

ORIGIN = np.array([0.05, 0.05, 0.55])


def scans(seed=0, n_scans=3, n=300):
    """Coloured scans of a box's walls (2.4 x 2.4 x 1.2 m) from a few origins, with a
    2x2x2 block of end points (8 sibling cells, hit once each, so pruned)."""
    rng = np.random.default_rng(seed)
    out = []
    block = np.array([[x, y, z] for z in (0.025, 0.075) for y in (0.025, 0.075)
                      for x in (-0.775, -0.725)]) + [0.0, 0.4, 0.4]
    for s in range(n_scans):
        u, v = rng.uniform(-1.15, 1.15, n), rng.uniform(0.02, 1.18, n)
        side = rng.integers(0, 4, n)
        x = np.where(side == 0, -1.17, np.where(side == 1, 1.17, u))
        y = np.where(side == 2, -1.17, np.where(side == 3, 1.17, u))
        pts = np.vstack([np.column_stack([x, y, v]), block])
        colors = rng.integers(0, 256, (len(pts), 3)).astype(np.uint8)
        out.append((pts, ORIGIN + [0.1 * s, -0.07 * s, 0.0], colors))
    return out


def fill(tree, data, **kw):
    for pts, org, col in data:
        tree.insert_scan(pts, org, col, **kw)
    return tree


# --------------------------------------------------------------------------- #
# the C++ reference: liboctomap's own calls
# --------------------------------------------------------------------------- #
REFERENCE = r"""
// color_reference insert OUT.ot RES MAXRANGE SCAN.bin...  (float32: origin, then x y z r g b)
// color_reference read IN.ot                               (prints type, then every leaf)
#include <octomap/ColorOcTree.h>
#include <octomap/AbstractOcTree.h>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
#include <vector>
using namespace octomap;
int main(int argc, char** argv) {
  std::string mode = argv[1];
  if (mode == "insert") {
    ColorOcTree tree(std::atof(argv[3]));
    double maxrange = std::atof(argv[4]);
    for (int f = 5; f < argc; ++f) {
      std::ifstream g(argv[f], std::ios::binary | std::ios::ate);
      std::vector<float> d(g.tellg() / sizeof(float));
      g.seekg(0);
      g.read(reinterpret_cast<char*>(d.data()), d.size() * sizeof(float));
      point3d origin(d[0], d[1], d[2]);
      Pointcloud cloud;
      for (size_t i = 3; i < d.size(); i += 6) cloud.push_back(d[i], d[i + 1], d[i + 2]);
      tree.insertPointCloud(cloud, origin, maxrange, false, false);
      for (size_t i = 3; i < d.size(); i += 6) {
        point3d p(d[i], d[i + 1], d[i + 2]);
        if (maxrange < 0 || (p - origin).norm() <= maxrange)
          tree.averageNodeColor(p.x(), p.y(), p.z(), (uint8_t)d[i + 3], (uint8_t)d[i + 4],
                                (uint8_t)d[i + 5]);
      }
    }
    tree.updateInnerOccupancy();
    return tree.write(argv[2]) ? 0 : 1;
  }
  AbstractOcTree* t = AbstractOcTree::read(argv[2]);
  if (!t) return 2;
  std::printf("%s\n", t->getTreeType().c_str());
  ColorOcTree* tree = dynamic_cast<ColorOcTree*>(t);
  if (!tree) return 3;
  std::printf("%.17g\n", tree->getResolution());
  for (ColorOcTree::leaf_iterator it = tree->begin_leafs(), end = tree->end_leafs();
       it != end; ++it) {
    ColorOcTreeNode::Color c = it->getColor();
    std::printf("%d %d %d %u %.9g %d %d %d\n", it.getKey()[0], it.getKey()[1],
                it.getKey()[2], it.getDepth(), it->getLogOdds(), c.r, c.g, c.b);
  }
  delete t;
  return 0;
}
"""


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    cxx = shutil.which("g++") or shutil.which("c++")
    if cxx is None or shutil.which("pkg-config") is None:
        pytest.skip("no C++ compiler or pkg-config")
    flags = subprocess.run(["pkg-config", "--cflags", "--libs", "octomap"],
                           capture_output=True, text=True)
    if flags.returncode != 0:
        pytest.skip("liboctomap not found by pkg-config")
    d = tmp_path_factory.mktemp("color_reference")
    (d / "ref.cpp").write_text(REFERENCE)
    exe = d / "color_reference"
    # the flags occgp's extensions are built with (setup.py): no fused multiply-add
    subprocess.run([cxx, "-O2", "-ffp-contract=off", "-std=c++17", str(d / "ref.cpp"),
                    "-o", str(exe), *flags.stdout.split()], check=True)
    return exe


def reference_insert(exe, workdir, data, resolution, max_range=None):
    files = []
    for i, (pts, org, col) in enumerate(data):
        rows = np.column_stack([np.asarray(pts, np.float32), np.asarray(col, np.float32)])
        path = workdir / f"scan{i}.bin"
        np.concatenate([np.asarray(org, np.float32), rows.ravel()]).tofile(path)
        files.append(str(path))
    out = workdir / "ref.ot"
    subprocess.run([str(exe), "insert", str(out), repr(resolution),
                    repr(-1.0 if max_range is None else max_range), *files], check=True)
    return out.read_bytes()


def reference_read(exe, path):
    lines = subprocess.run([str(exe), "read", str(path)], check=True, capture_output=True,
                           text=True).stdout.splitlines()
    table = np.array([[float(v) for v in line.split()] for line in lines[2:]]).reshape(-1, 8)
    return lines[0], float(lines[1]), table


def body(data: bytes) -> bytes:
    return data[data.index(b"\ndata\n") + len(b"\ndata\n"):]


# --------------------------------------------------------------------------- #
# occupancy: identical to OccupancyOctree
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("max_range", [None, 1.0])
@pytest.mark.parametrize("method", ["plain", "auto"])
def test_occupancy_leaves_identical_to_occupancy_octree(max_range, method):
    data = scans()
    color = fill(ColorOctree(0.05), data, max_range=max_range)
    plain = OccupancyOctree(0.05)
    for pts, org, _ in data:
        plain.insert_scan(pts, org, max_range=max_range, method=method)
    a, b = color.leaves(), plain.leaves()
    assert color.num_leaves == plain.num_leaves == len(a.centers) > 1000
    assert color.num_nodes == plain.num_nodes
    assert_array_equal(a.centers, b.centers)
    assert_array_equal(a.sizes, b.sizes)
    assert_array_equal(a.log_odds, b.log_odds)
    assert (a.sizes > 0.05).any()                 # pruned leaves were compared too
    probe = np.vstack([data[0][0], a.centers, [[9.0, 9.0, 9.0]]])
    assert_array_equal(color.log_odds(probe), plain.log_odds(probe))
    assert_array_equal(color.occupancy(probe), plain.occupancy(probe))
    assert_array_equal(color.is_occupied(probe), plain.is_occupied(probe))
    for x, y in zip(color.bounds, plain.bounds):
        assert_array_equal(x, y)
    assert_array_equal(color.extract_points()[0], plain.extract_points()[0])
    assert_array_equal(color.extract_points(False)[1], plain.extract_points(False)[1])


def test_sensor_model_parameters_are_used_and_validated():
    params = dict(prob_hit=0.9, prob_miss=0.2, clamping_min=0.2, clamping_max=0.95,
                  occupancy_threshold=0.6)
    data = scans(n_scans=2, n=100)
    a = fill(ColorOctree(0.1, **params), data)
    b = OccupancyOctree(0.1, **params)
    for pts, org, _ in data:
        b.insert_scan(pts, org)
    assert_array_equal(a.leaves().log_odds, b.leaves().log_odds)
    assert a.get_params() == dict(resolution=0.1, **params)
    with pytest.raises(ValueError, match="prob_hit must lie in"):
        ColorOctree(0.1, prob_hit=0.4)
    with pytest.raises(ValueError, match="resolution must lie in"):
        ColorOctree(1e20)
    with pytest.raises(TypeError, match="resolution must be a real number"):
        ColorOctree("0.1")


# --------------------------------------------------------------------------- #
# colours: averageNodeColor point by point, or the mean per cell
# --------------------------------------------------------------------------- #
def wall_scan(seed=1, n=400):
    """Points on one wall one cell thick (x in [1.0, 1.1)): no occupied block prunes."""
    rng = np.random.default_rng(seed)
    pts = np.column_stack([rng.uniform(1.0, 1.1, n), rng.uniform(-0.3, 0.3, n),
                           rng.uniform(-0.3, 0.3, n)])
    return pts, np.zeros(3), rng.integers(0, 256, (n, 3))


def cells_of(points, resolution):
    return [tuple(k) for k in np.floor(np.asarray(points, np.float32).astype(np.float64)
                                       / resolution).astype(np.int64).tolist()]


def test_average_fusion_is_averagenodecolor_point_by_point():
    pts, org, col = wall_scan()
    m = ColorOctree(0.1)
    m.insert_scan(pts, org, col)
    m.insert_scan(pts[::-1], org, col[::-1])       # a second scan, other order
    expected = {}
    for key, c in zip(cells_of(pts, 0.1) + cells_of(pts[::-1], 0.1),
                      np.vstack([col, col[::-1]]).tolist()):
        prev = expected.get(key)
        # liboctomap: an unset (white) cell takes the colour, a set one the integer average
        expected[key] = c if prev is None or prev == [255, 255, 255] else \
            [(p + q) // 2 for p, q in zip(prev, c)]
    keys = list(expected)
    centers = (np.array(keys) + 0.5) * 0.1
    rgb, has = m.colors(centers)
    assert_array_equal(rgb, np.array([expected[k] for k in keys]))
    assert_array_equal(has, [expected[k] != [255, 255, 255] for k in keys])
    assert len(keys) > 20


def test_mean_fusion_is_the_rounded_mean_per_cell_then_averaged():
    pts, org, col = wall_scan()
    m = ColorOctree(0.1).insert_scan(pts, org, col, fusion="mean")
    keys = cells_of(pts, 0.1)
    groups = {}
    for key, c in zip(keys, col.tolist()):
        groups.setdefault(key, []).append(c)
    cells = sorted(groups)
    mean = np.array([np.floor(np.mean(groups[k], axis=0) + 0.5) for k in cells])
    assert_array_equal(m.colors((np.array(cells) + 0.5) * 0.1)[0], mean)
    # a second scan's means are averaged with the cells' colours (averageNodeColor)
    m.insert_scan(pts[:1], org, [[0, 0, 0]], fusion="mean")
    assert_array_equal(m.colors(pts[:1])[0][0], mean[cells.index(keys[0])].astype(int) // 2)


@pytest.mark.parametrize("fusion", ["average", "mean"])
def test_a_scan_without_colours_updates_occupancy_only(fusion):
    pts, org, col = wall_scan()
    m = ColorOctree(0.1).insert_scan(pts[:20], org, col[:20])
    before = m.colors(pts)
    # a plain scan (the one face's insert_scan(points, origin)): occupancy as the plain
    # octree's, colours as they were, new cells without colour
    m.insert_scan(pts, org, fusion=fusion)
    m.insert_scan([[0.05, 2.05, 0.05]], org, None, max_range=5.0, min_range=0.1)
    plain = OccupancyOctree(0.1).insert_scan(pts[:20], org).insert_scan(pts, org)
    plain.insert_scan([[0.05, 2.05, 0.05]], org, max_range=5.0, min_range=0.1)
    assert_array_equal(m.leaves().log_odds, plain.leaves().log_odds)
    assert_array_equal(m.colors(pts)[0], before[0])
    assert_array_equal(m.colors(pts)[1], before[1])
    assert not before[1].all() and before[1].any()      # some cells only the plain scan hit
    rgb, has = m.colors([[0.05, 2.05, 0.05]])
    assert_array_equal(rgb, [[255, 255, 255]]) and not has[0]
    assert m.is_occupied([[0.05, 2.05, 0.05]])[0]


def test_truncated_rays_and_unknown_points_take_no_colour():
    m = ColorOctree(0.1)
    m.insert_scan([[0.55, 0.05, 0.05], [3.05, 0.05, 0.05]], [0.05, 0.05, 0.05],
                  [[10, 20, 30], [40, 50, 60]], max_range=1.0)
    rgb, has = m.colors([[0.55, 0.05, 0.05], [1.0, 0.05, 0.05], [3.05, 0.05, 0.05]])
    assert_array_equal(rgb, [[10, 20, 30], [255, 255, 255], [255, 255, 255]])
    assert_array_equal(has, [True, False, False])
    assert not m.is_occupied([[1.0, 0.05, 0.05]])[0]      # the cut ray's last free cell
    m.update_colors([[7.0, 7.0, 7.0]], [[1, 2, 3]])         # unknown cell: skipped
    assert np.isnan(m.occupancy([[7.0, 7.0, 7.0]])[0])


def test_update_and_set_colors():
    m = ColorOctree(0.1).insert_scan([[0.55, 0.05, 0.05]], [0.05, 0.05, 0.05], [[10, 20, 30]])
    p = [[0.55, 0.05, 0.05]]
    before = m.leaves().log_odds.copy()
    m.update_colors(p, [[30, 40, 51]])
    assert m.colors(p)[0].tolist() == [[20, 30, 40]]
    m.set_colors(p, [[1.0, 0.0, 0.5]])
    assert m.colors(p)[0].tolist() == [[255, 0, 128]]
    m.set_colors(p, [[255, 255, 255]])                       # white: no colour
    assert m.colors(p)[1].tolist() == [False]
    m.update_colors(p * 2, [[100, 100, 100], [0, 50, 200]])  # in order
    assert m.colors(p)[0].tolist() == [[50, 75, 150]]
    assert_array_equal(m.leaves().log_odds, before)          # occupancy untouched


def test_float_and_integer_colours_agree():
    pts, org, col = wall_scan(n=50)
    a = ColorOctree(0.1).insert_scan(pts, org, col.astype(np.int64))
    b = ColorOctree(0.1).insert_scan(pts, org, col / 255.0)
    c = ColorOctree(0.1).insert_scan(pts, org, (col / 255.0).astype(np.float32))
    assert_array_equal(a.leaves().colors, b.leaves().colors)
    assert_array_equal(a.leaves().colors, c.leaves().colors)


def test_pruned_block_takes_its_childrens_colours():
    """Eight siblings hit once each prune into their parent at the eighth update (before
    the colours come): all eight points' colours are then averaged into the parent."""
    block = np.array([[x, y, z] for z in (0.05, 0.15) for y in (0.05, 0.15)
                      for x in (2.05, 2.15)])
    col = np.arange(24).reshape(8, 3) * 10
    m = ColorOctree(0.1).insert_scan(block, [-1.05, 0.1, 0.1], col)
    leaf = m.leaves(occupied_only=True)
    assert leaf.sizes.tolist() == [0.2]
    expected = col[0]
    for c in col[1:]:
        expected = (expected + c) // 2
    assert_array_equal(leaf.colors[0], expected)


# --------------------------------------------------------------------------- #
# against liboctomap
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("max_range", [None, 1.2])
def test_file_equals_liboctomaps_own_call_sequence(reference, tmp_path, max_range):
    data = scans()
    ours = fill(ColorOctree(0.05), data, max_range=max_range).to_bytes()
    theirs = reference_insert(reference, tmp_path, data, 0.05, max_range)
    assert b"id ColorOcTree\n" in theirs and b"id ColorOcTree\n" in ours
    assert body(ours) == body(theirs)              # every node: log-odds, colour, children
    loaded = ColorOctree.load(tmp_path / "ref.ot")  # liboctomap's own file reads back
    assert loaded.resolution == 0.05
    assert body(loaded.to_bytes()) == body(theirs)


def test_liboctomap_reads_our_file_as_a_color_octree(reference, tmp_path):
    m = fill(ColorOctree(0.05), scans(n_scans=2))
    m.save(tmp_path / "map.ot")
    kind, res, table = reference_read(reference, tmp_path / "map.ot")
    assert kind == "ColorOcTree" and res == 0.05
    leaves = m.leaves()
    depth = 16 - np.rint(np.log2(leaves.sizes / 0.05)).astype(int)
    assert_array_equal(table[:, 3], depth)
    keys = np.floor(leaves.centers / 0.05).astype(np.int64) + 32768
    # a pruned leaf's key is any key it holds: compare at its own depth
    shift = (16 - depth)[:, None]
    assert_array_equal(table[:, :3].astype(np.int64) >> shift, keys >> shift)
    assert_array_equal(table[:, 4].astype(np.float32), leaves.log_odds)
    assert_array_equal(table[:, 5:], leaves.colors)
    assert (leaves.colors != 255).any()


# --------------------------------------------------------------------------- #
# files and pickles
# --------------------------------------------------------------------------- #
def test_save_load_round_trip_is_exact(tmp_path):
    m = fill(ColorOctree(0.05, prob_hit=0.8), scans())
    m.save(tmp_path / "m.ot")
    back = ColorOctree.load(tmp_path / "m.ot", prob_hit=0.8)
    a, b = m.leaves(), back.leaves()
    for x, y in zip(a, b):
        assert_array_equal(x, y)
    assert back.to_bytes() == m.to_bytes() == (tmp_path / "m.ot").read_bytes()
    assert back.get_params() == m.get_params()
    # a loaded map updates as the original
    pts, org, col = wall_scan(n=30)
    assert back.insert_scan(pts, org, col).to_bytes() == m.insert_scan(pts, org, col).to_bytes()


def test_pickle_and_empty_map():
    m = fill(ColorOctree(0.1), scans(n_scans=1, n=50))
    back = pickle.loads(pickle.dumps(m))
    assert type(back) is ColorOctree and back.to_bytes() == m.to_bytes()
    empty = ColorOctree(0.1)
    assert empty.num_leaves == 0 and np.isnan(empty.bounds[0]).all()
    assert ColorOctree.from_bytes(empty.to_bytes()).num_nodes == 0
    assert isinstance(empty.leaves(), ColorLeaves) and empty.leaves().colors.shape == (0, 3)
    assert m.clear().num_leaves == 0 and "num_leaves=0" in repr(m)


def test_load_rejects_other_files(tmp_path):
    plain = OccupancyOctree(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0])
    plain.save(tmp_path / "plain.ot")
    plain.save(tmp_path / "plain.bt")
    with pytest.raises(ValueError, match=r"plain\.ot holds a 'OcTree' tree; ColorOctree"):
        ColorOctree.load(tmp_path / "plain.ot")
    with pytest.raises(ValueError, match=r"plain\.bt is a binary \(\.bt\) OctoMap file"):
        ColorOctree.load(tmp_path / "plain.bt")
    with pytest.raises(ValueError, match="is not an OctoMap file"):
        ColorOctree.from_bytes(b"hello\nworld\n")
    with pytest.raises(TypeError, match="data must be bytes"):
        ColorOctree.from_bytes("text")
    with pytest.raises(OSError):
        ColorOctree.load(tmp_path / "missing.ot")
    # and OccupancyOctree refuses a colour file with a clear message
    ColorOctree(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0], [[1, 2, 3]]).save(tmp_path / "c.ot")
    with pytest.raises(ValueError, match="holds a 'ColorOcTree' tree; only 'OcTree' "
                       ".*occgp.ColorOctree.load"):
        OccupancyOctree.load(tmp_path / "c.ot")


def test_load_rejects_truncated_and_corrupt_data():
    data = fill(ColorOctree(0.1), scans(n_scans=1, n=60)).to_bytes()
    start = data.index(b"\ndata\n") + 6
    with pytest.raises(ValueError, match="truncated data"):
        ColorOctree.from_bytes(data[:-5])
    nan = bytearray(data)
    nan[start:start + 4] = np.float32(np.nan).tobytes()
    with pytest.raises(ValueError, match="non-finite log-odds"):
        ColorOctree.from_bytes(bytes(nan))
    with pytest.raises(ValueError, match="announces"):
        ColorOctree.from_bytes(data.replace(b"\nsize ", b"\nsize 1", 1))
    extra = data + b"\x00" * 8
    assert ColorOctree.from_bytes(extra).to_bytes() == data
    header = data[:start].decode()
    size_line = next(line for line in header.splitlines() if line.startswith("size "))
    deep = header.replace(size_line, "size 19").encode()
    for _ in range(18):                              # a chain of 19 nodes, each one child
        deep += np.float32(0.0).tobytes() + b"\x00\x00\x00\x01"
    deep += np.float32(0.0).tobytes() + b"\x00\x00\x00\x00"
    with pytest.raises(ValueError, match="deeper than the 16 levels"):
        ColorOctree.from_bytes(deep)


def test_save_checks_the_path(tmp_path):
    m = ColorOctree(0.1)
    with pytest.raises(ValueError, match=r"path must end in \.ot"):
        m.save(tmp_path / "m.bt")
    with pytest.raises(TypeError, match="path must be a str or os.PathLike"):
        m.save(3)
    with pytest.raises(OSError):
        m.save(tmp_path / "no" / "such" / "m.ot")


# --------------------------------------------------------------------------- #
# exports
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("binary", [True, False])
def test_save_ply_writes_the_cells_colours(tmp_path, binary):
    m = fill(ColorOctree(0.1), scans(n_scans=2, n=80))
    m.save_ply(tmp_path / "m.ply", binary=binary)
    out = read_ply(tmp_path / "m.ply")
    v = out["vertex"] if isinstance(out, dict) else out[0]["vertex"]
    centers, sizes, colors = m.extract_points()
    assert_array_equal(np.column_stack([v["x"], v["y"], v["z"]]), centers.astype(np.float32))
    assert_array_equal(np.column_stack([v["red"], v["green"], v["blue"]]), colors)
    m.save_ply(tmp_path / "cubes.ply", cubes=True, binary=binary)
    cv = read_ply(tmp_path / "cubes.ply")
    cv = cv["vertex"] if isinstance(cv, dict) else cv[0]["vertex"]
    assert_array_equal(cv["red"], np.repeat(colors[:, 0], 8))


@pytest.mark.parametrize("binary", [True, False])
def test_save_pcd_writes_packed_rgb(tmp_path, binary):
    m = fill(ColorOctree(0.1), scans(n_scans=2, n=80))
    m.save_pcd(tmp_path / "m.pcd", binary=binary)
    scan, fields = read_pcd(tmp_path / "m.pcd", return_fields=True)
    centers, _, colors = m.extract_points()
    assert_array_equal(scan.points, centers.astype(np.float32))
    assert fields["rgb"].dtype == np.uint32
    assert_array_equal(unpack_rgb(fields["rgb"]), colors)
    assert pack_rgb([[1, 2, 3]]).tolist() == [0x010203]
    assert unpack_rgb(np.array([0x010203], np.uint32).view(np.float32)).tolist() == [[1, 2, 3]]


def test_plain_map_exports_are_unchanged(tmp_path):
    m = OccupancyOctree(0.1).insert_scan([[1.0, 0.0, 0.0]], [0.0, 0.0, 0.0])
    m.save_pcd(tmp_path / "p.pcd")
    assert set(read_pcd(tmp_path / "p.pcd", return_fields=True)[1]) == {"x", "y", "z", "intensity"}
    m.save_ply(tmp_path / "p.ply", binary=False)
    assert (tmp_path / "p.ply").read_text().splitlines()[-1].endswith(" 33 145 140")


def test_to_open3d_uses_the_cells_colours():
    o3d = pytest.importorskip("open3d")
    m = fill(ColorOctree(0.1), scans(n_scans=1, n=60))
    cloud = m.to_open3d(kind="points")
    assert isinstance(cloud, o3d.geometry.PointCloud)
    assert_array_equal(np.rint(np.asarray(cloud.colors) * 255), m.extract_points()[2])


# --------------------------------------------------------------------------- #
# bad input: a clear error, the map unchanged
# --------------------------------------------------------------------------- #
P1 = [[1.05, 0.05, 0.05]]
O = [0.05, 0.05, 0.05]
BAD_INSERTS = [
    (dict(points=P1, origin=O, colors=[[1, 2]]), ValueError, r"colors must have shape \(1, 3\)"),
    (dict(points=P1, origin=O, colors=[[1, 2, 3], [4, 5, 6]]), ValueError,
     r"colors must have shape \(1, 3\)"),
    (dict(points=P1, origin=O, colors=[1, 2, 3]), ValueError, r"colors must have shape"),
    (dict(points=P1, origin=O, colors=[[256, 0, 0]]), ValueError,
     r"colors of an integer dtype must lie in \[0, 255\]"),
    (dict(points=P1, origin=O, colors=[[-1, 0, 0]]), ValueError, r"must lie in \[0, 255\]"),
    (dict(points=P1, origin=O, colors=[[1.5, 0.0, 0.0]]), ValueError,
     r"colors of a float dtype must lie in \[0, 1\]"),
    (dict(points=P1, origin=O, colors=[[np.nan, 0.0, 0.0]]), ValueError, r"hold NaN"),
    (dict(points=P1, origin=O, colors=[[True, False, True]]), TypeError,
     r"colors must hold integers in \[0, 255\] or floats"),
    (dict(points=P1, origin=O, colors=[["a", "b", "c"]]), TypeError, r"colors must hold"),
    (dict(points=P1, origin=O, colors=[[1, 2, 3], [4, 5]]), ValueError,
     r"colors must be a numeric array"),
    (dict(points=[[np.nan, 0, 0]], origin=O, colors=[[1, 2, 3]]), ValueError,
     r"points must be finite"),
    (dict(points=[[1e30, 0, 0]], origin=O, colors=[[1, 2, 3]]), ValueError,
     r"outside the octree's key range"),
    (dict(points=P1, origin=[1e30, 0, 0], colors=[[1, 2, 3]]), ValueError,
     r"origin .* lies outside the octree's key range"),
    (dict(points=[[1.0, 0.0]], origin=O, colors=[[1, 2, 3]]), ValueError,
     r"points must have shape \(n_points, 3\)"),
    (dict(points=P1, origin=O, colors=[[1, 2, 3]], fusion="median"), ValueError,
     r"fusion must be one of \('average', 'mean'\)"),
    (dict(points=P1, origin=O, colors=[[1, 2, 3]], max_range=-1.0), ValueError,
     r"max_range must lie in"),
    (dict(points=np.zeros((0, 3)), origin=O, colors=np.zeros((1, 3))), ValueError,
     r"colors must have shape \(0, 3\)"),
]


@pytest.mark.parametrize("kwargs, exc, match", BAD_INSERTS)
def test_insert_scan_rejects_bad_input_and_changes_nothing(kwargs, exc, match):
    m = fill(ColorOctree(0.1), scans(n_scans=1, n=40))
    before = m.to_bytes()
    with pytest.raises(exc, match=match):
        m.insert_scan(**kwargs)
    assert m.to_bytes() == before


def test_too_long_rays_and_too_many_cells_are_refused():
    m = ColorOctree(1e-3)
    with pytest.raises(ValueError, match=r"1 of 2 rays cross more than 99990 cells \(first: row 1\)"):
        m.insert_scan([[-29.0, -30, -30], [30.0, 30, 30]], [-30, -30, -30], [[1, 2, 3]] * 2)
    m.MAX_SCAN_CELLS = 100
    with pytest.raises(ValueError, match="MAX_SCAN_CELLS=100"):
        m.insert_scan([[0.5, 0, 0]], [0, 0, 0], [[1, 2, 3]])
    assert m.num_nodes == 0


@pytest.mark.parametrize("method", ["update_colors", "set_colors"])
def test_colour_updates_reject_bad_input_and_change_nothing(method):
    m = fill(ColorOctree(0.1), scans(n_scans=1, n=40))
    before = m.to_bytes()
    f = getattr(m, method)
    with pytest.raises(ValueError, match="outside the octree's key range"):
        f([[1e30, 0, 0]], [[1, 2, 3]])
    with pytest.raises(ValueError, match="points must be finite"):
        f([[np.inf, 0, 0]], [[1, 2, 3]])
    with pytest.raises(ValueError, match=r"colors must have shape \(2, 3\)"):
        f(P1 * 2, [[1, 2, 3]])
    with pytest.raises(ValueError, match=r"must lie in \[0, 255\]"):
        f(P1, [[1, 2, 300]])
    assert m.to_bytes() == before


def test_queries_reject_bad_input():
    m = ColorOctree(0.1)
    with pytest.raises(ValueError, match=r"points must have shape \(n_points, 3\)"):
        m.colors([1.0, 2.0, 3.0])
    with pytest.raises(TypeError, match="points must hold real numbers"):
        m.colors([["a", "b", "c"]])
    with pytest.raises(TypeError, match="occupied_only must be a bool"):
        m.leaves(occupied_only=1)
    with pytest.raises(TypeError, match="occupied must be a bool"):
        m.extract_points(occupied="yes")
    rgb, has = m.colors([[1e30, 0.0, 0.0]])              # beyond the key range: unknown
    assert has.tolist() == [False] and rgb.tolist() == [[255, 255, 255]]
    assert np.isnan(m.occupancy([[1e30, 0.0, 0.0]])[0])


def test_compiled_core_refuses_an_uninitialised_tree():
    from occgp._color import _ColorOcTree
    with pytest.raises(ValueError, match="was not initialised"):
        _ColorOcTree()._num_nodes()


if __name__ == "__main__":
    sys.exit(pytest.main([__file__, "-q"]))
