"""The docs' table of octomap-python / pyoctomap equivalents stays true to the code.

``docs/octomap_bindings.rst`` names, for each method of the Python OctoMap
bindings, occgp's equivalent. These tests parse its list-table, check that every
occgp name it cites exists, and check the recipes its notes give.
"""

import importlib
import re
from pathlib import Path

import numpy as np
import pytest

import occgp
from occgp import OccupancyOctree

PAGE = Path(__file__).resolve().parent.parent / "docs" / "octomap_bindings.rst"
ROLE = re.compile(r":(?:meth|attr|class|func|data|mod|obj):`~?(occgp(?:\.\w+)+)`")


def _rows(text: str) -> list[list[str]]:
    """The rows of the page's list-tables, each a list of cell texts."""
    rows: list[list[str]] = []
    in_table = False
    for line in text.splitlines():
        if line.startswith(".. list-table::"):
            in_table = True
            continue
        if not in_table:
            continue
        if line and not line.startswith(" "):
            in_table = False
        elif line.startswith("   * - "):
            rows.append([line[len("   * - "):]])
        elif line.startswith("     - ") or line.rstrip() == "     -":
            rows[-1].append(line[len("     - "):])
        elif line.startswith("       ") and rows:
            rows[-1][-1] += " " + line.strip()
    return rows


def _resolve(name: str):
    """The object a dotted ``occgp....`` name refers to (AttributeError if none)."""
    parts = name.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        for attr in parts[i:]:
            obj = getattr(obj, attr)
        return obj
    raise AttributeError(name)


def _logit(p: float) -> np.float32:
    return np.float32(np.log(p / (1 - p)))


@pytest.fixture(scope="module")
def rows():
    return _rows(PAGE.read_text(encoding="utf-8"))


def test_table_has_three_columns_and_the_header(rows):
    assert rows[0] == ["octomap-python / pyoctomap", "occgp", "notes"]
    assert len(rows) > 40
    bad = [r[0] for r in rows if len(r) != 3]
    assert bad == []


def test_every_cited_occgp_name_exists():
    names = sorted(set(ROLE.findall(PAGE.read_text(encoding="utf-8"))))
    assert "occgp.OccupancyOctree.update_cells" in names
    missing = []
    for name in names:
        try:
            _resolve(name)
        except AttributeError:
            missing.append(name)
    assert missing == []


def test_rows_naming_an_equivalent_cite_it(rows):
    # the occgp column either cites occgp by a cross-reference or says why not
    plain = ("Not available", "Not needed", "``uint16`` arrays")
    for binding, ours, _ in rows[1:]:
        assert ROLE.search(ours) or ours.startswith(plain), binding


@pytest.mark.parametrize("method", [
    "search", "isNodeOccupied", "isNodeAtThreshold", "getLabels", "castRay",
    "getRayIntersection", "coordToKey", "keyToCoord", "begin_leafs", "begin_tree",
    "begin_leafs_bbx", "maxDepth", "getMetricMin", "getMetricMax", "getMetricSize",
    "calcNumNodes", "size()", "getNumLeafNodes", "memoryUsage", "getResolution",
    "insertPointCloud", "updateNode", "updateNodes", "toMaxLikelihood", "prune",
    "expand", "writeBinary", "readBinary", "write(", "read(", "useBBXLimit",
    "setBBXMin", "enableChangeDetection", "resetChangeDetection", "extractPointCloud",
    "dynamicEDT_generate", "ColorOcTree", "averageNodeColor", "deleteNode",
    "adjustKeyAtDepth", "getTreeDepth", "setProbHit", "setOccupancyThres",
])
def test_binding_method_has_a_row(rows, method):
    assert any(method in r[0] for r in rows[1:]), method


def test_recipes_in_the_notes():
    m = OccupancyOctree(0.1)
    m.insert_scan([[1.0, 0.05, 0.05], [0.05, 1.0, 0.05]], [0.05, 0.05, 0.05])
    pts = np.array([[1.0, 0.05, 0.05], [0.5, 0.05, 0.05], [5.0, 5.0, 5.0]])

    # getLabels: 1 occupied, 0 free, -1 unknown
    occ, unk = m.is_occupied(pts, return_unknown=True)
    assert np.where(unk, -1, occ.astype(int)).tolist() == [1, 0, -1]

    # isNodeAtThreshold: False after one scan, True after toMaxLikelihood; the method
    # is the float32 comparison with the clamping bounds, False where unknown
    def at_threshold(tree):
        l = tree.log_odds(pts)
        return ((l >= _logit(tree.clamping_max)) | (l <= _logit(tree.clamping_min))).tolist()
    assert at_threshold(m) == m.is_at_threshold(pts).tolist() == [False, False, False]
    ml = OccupancyOctree.from_bytes(m.to_bytes()).to_max_likelihood()
    assert at_threshold(ml) == ml.is_at_threshold(pts).tolist() == [True, True, False]

    # search(point, depth): the node's value is the largest of its children's
    assert m.log_odds(pts[:1], depth=1)[0] == m.leaves().log_odds.max()
    assert np.isnan(m.log_odds(pts[2:], depth=14))[0]

    # begin_leafs(maxDepth), begin_tree: sizes and the root
    assert m.leaves(max_depth=12).sizes.tolist() == [1.6]
    nodes = m.nodes()
    assert nodes.depths[0] == 0 and len(nodes.depths) == m.num_nodes
    assert m.tree_depth == 16

    # getMetricMin/Max/Size and volume
    lo, hi = m.bounds
    assert np.allclose(lo, [0, 0, 0]) and np.allclose(hi, [1.1, 1.1, 0.1])
    assert np.isclose(np.prod(hi - lo), 1.1 * 1.1 * 0.1)
    assert np.isnan(OccupancyOctree(0.1).bounds[0]).all()

    # begin_leafs: depth from the leaf sizes
    leaves = m.leaves()
    depth = 16 - np.log2(leaves.sizes / m.resolution)
    assert depth.min() >= 0 and depth.max() == 16

    # deleteNode
    assert m.delete_cells(pts) == 2 and np.isnan(m.log_odds(pts)).all()

    # setProbHit ...: pickles keep them
    import pickle
    m.set_params(prob_hit=0.8)
    assert pickle.loads(pickle.dumps(m)).prob_hit == 0.8


@pytest.mark.parametrize("d", [1, 5, 15])
def test_adjust_key_at_depth_recipe(d):
    m = OccupancyOctree(0.1)
    rng = np.random.default_rng(d)
    keys = rng.integers(0, 65536, size=(50, 3)).astype(np.uint16)
    k = keys.astype(np.int64)
    adjusted = ((k >> (16 - d)) << (16 - d)) + (1 << (15 - d))
    # the adjusted key names the same depth-d node, and keys in one node agree
    assert np.array_equal(m.key_to_coord(adjusted, depth=d), m.key_to_coord(keys, depth=d))
    sibling = np.minimum(k | 1, 65535)
    same = ((sibling >> (16 - d)) << (16 - d)) + (1 << (15 - d))
    assert np.array_equal(same, adjusted)
    # coord_to_key(pts, depth=d) gives the adjusted key of the finest one
    pts = m.key_to_coord(keys)
    assert np.array_equal(m.coord_to_key(pts, depth=d), adjusted)


def test_key_to_coord_of_the_depth_recipe_is_the_node_center():
    m = OccupancyOctree(0.1)
    # the depth-15 node holding key 32768 spans [0, 0.2) on each axis
    center = m.key_to_coord([[32768, 32768, 32768]], depth=15)
    assert np.allclose(center, 0.1)


def test_module_names_resolve():
    assert _resolve("occgp.OccupancyOctree.leaves") is OccupancyOctree.leaves
    assert _resolve("occgp.Leaves") is occgp.Leaves
    with pytest.raises(AttributeError):
        _resolve("occgp.OccupancyOctree.search")


@pytest.mark.parametrize("binding, ours", [
    ("tree.search(point, depth)", "occgp.OccupancyOctree.log_odds"),
    ("tree.isNodeAtThreshold", "occgp.OccupancyOctree.is_at_threshold"),
    ("getRayIntersection", "occgp.OccupancyOctree.ray_intersections"),
    ("adjustKeyAtDepth", "occgp.OccupancyOctree.coord_to_key"),
    ("begin_leafs(maxDepth)", "occgp.OccupancyOctree.leaves"),
    ("begin_tree", "occgp.OccupancyOctree.nodes"),
    ("getTreeDepth", "occgp.OccupancyOctree.tree_depth"),
    ("setProbHit", "occgp.OccupancyOctree.set_params"),
    ("deleteNode", "occgp.OccupancyOctree.delete_cells"),
])
def test_rows_now_covered_cite_their_method(rows, binding, ours):
    row = next(r for r in rows[1:] if binding in r[0])
    assert ours in ROLE.findall(row[1])
