"""The OctoMap-binding features of OccupancyOctree: deletion, queries and listings at a
depth, thresholds, ray intersections and sensor-model setters.

Each is checked against a direct computation from the leaves (the finest cells a
tree describes, an inner node's value being the largest of its children's, as
liboctomap keeps it) or against liboctomap's own arithmetic.
"""

import pickle

import numpy as np
import pytest

from occgp import KNNMap, OccupancyOctree
from occgp.octree import Nodes

RES = 0.1
DEPTH = 16
f32 = np.float32


# ---------------------------------------------------------------------- references
def _leaf_keys(tree):
    """(keys (n, 3) int64 of each leaf's lowest finest key, depths (n,), values (n,))."""
    leaves = tree.leaves()
    depth = np.rint(DEPTH - np.log2(leaves.sizes / tree.resolution)).astype(np.int64)
    span = 1 << (DEPTH - depth)
    low = leaves.centers - leaves.sizes[:, None] / 2
    keys = np.rint(low / tree.resolution).astype(np.int64) + 32768
    assert (keys % span[:, None] == 0).all()
    return keys, depth, leaves.log_odds


def finest(tree):
    """{(kx, ky, kz): log-odds} of every finest cell the tree's leaves cover."""
    keys, depth, values = _leaf_keys(tree)
    cells, vals = [], []
    for d in np.unique(depth):
        s = 1 << (DEPTH - int(d))
        off = np.stack(np.meshgrid(*[np.arange(s)] * 3, indexing="ij"), -1).reshape(-1, 3)
        at = depth == d
        cells.append((keys[at][:, None, :] + off[None]).reshape(-1, 3))
        vals.append(np.repeat(values[at], len(off)))
    if not cells:
        return {}
    return dict(zip(map(tuple, np.vstack(cells).tolist()), np.concatenate(vals).tolist()))


def expected_search(tree, points, depth):
    """liboctomap's search(key, depth) computed from the leaves: the leaf holding the
    depth-`depth` node's cube if one does, else the largest value of the leaves in it,
    else NaN."""
    keys, ldepth, values = _leaf_keys(tree)
    q = np.floor((1.0 / tree.resolution) * np.asarray(points, np.float32).astype(np.float64)) + 32768
    inside = ((q >= 0) & (q < 65536)).all(axis=1)
    out = np.full(len(q), np.nan)
    for i in np.flatnonzero(inside):
        k = q[i].astype(np.int64)
        common = np.minimum(ldepth, depth)
        shift = (DEPTH - common)[:, None]
        same = ((keys >> shift) == (k[None] >> shift)).all(axis=1)
        holding = same & (ldepth <= depth)
        if holding.any():
            out[i] = values[holding][0]
        elif same.any():
            out[i] = values[same].max()
    return out


def dfs_order(keys, depths):
    """The pre-order (child 0 first) of nodes given by lowest key and depth."""
    code = np.zeros(len(keys), dtype=np.uint64)
    for bit in range(DEPTH - 1, -1, -1):
        for axis in (2, 1, 0):
            code = (code << np.uint64(1)) | ((keys[:, axis] >> bit) & 1).astype(np.uint64)
    return np.lexsort((depths, code))


def node_keys(nodes, resolution):
    low = nodes.centers - nodes.sizes[:, None] / 2
    return np.rint(low / resolution).astype(np.int64) + 32768


def check_inner_nodes(tree):
    """Every inner node holds the largest log-odds of its children; num_nodes agrees."""
    nodes = tree.nodes()
    assert len(nodes.depths) == tree.num_nodes
    keys = node_keys(nodes, tree.resolution)
    index = {(int(d), *map(int, k)): i for i, (d, k) in enumerate(zip(nodes.depths, keys))}
    children_max = np.full(len(keys), -np.inf, dtype=np.float32)
    for i, (d, k) in enumerate(zip(nodes.depths, keys)):
        if d == 0:
            continue
        shift = DEPTH - (d - 1)
        parent = index[(int(d) - 1, *[int(c >> shift << shift) for c in k])]
        children_max[parent] = max(children_max[parent], nodes.log_odds[i])
    inner = ~nodes.is_leaf
    assert np.array_equal(children_max[inner], nodes.log_odds[inner])
    assert np.isinf(children_max[nodes.is_leaf]).all()     # leaves have no children
    return nodes


@pytest.fixture
def room():
    """A small map with free, occupied and pruned (coarse) leaves."""
    rng = np.random.default_rng(3)
    m = OccupancyOctree(RES)
    origin = np.array([0.05, 0.05, 0.05])
    for _ in range(3):
        pts = rng.uniform(-0.8, 0.8, (150, 3))
        m.insert_scan(pts, origin)
    # a saturated 0.4 m cube, pruned into one leaf
    g = np.stack(np.meshgrid(*[np.arange(4)] * 3, indexing="ij"), -1).reshape(-1, 3)
    m.set_cells(1.2 + RES * (g + 0.5), 4.0)      # clamped to logit(clamping_max)
    return m


# ---------------------------------------------------------------------- delete_cells
def test_room_has_pruned_leaves(room):
    assert room.leaves().sizes.max() >= 4 * RES - 1e-9
    check_inner_nodes(room)


@pytest.mark.parametrize("depth", [0, 16, 15, 13])
def test_delete_cells_matches_the_leaves_minus_the_deleted(room, depth):
    rng = np.random.default_rng(depth)
    before = finest(room)
    pts = np.vstack([rng.uniform(-0.8, 0.8, (40, 3)), [[1.3, 1.3, 1.3], [1.45, 1.55, 1.35]],
                     [[9.0, 9.0, 9.0]]])
    d = depth or 16
    shift = DEPTH - d
    target = room.coord_to_key(pts).astype(np.int64) >> shift
    gone = set(map(tuple, target.tolist()))
    expected = {k: v for k, v in before.items() if tuple(c >> shift for c in k) not in gone}
    # nodes deleted: the distinct target nodes that hold a known cell
    held = gone & {tuple(c >> shift for c in k) for k in before}
    n = room.delete_cells(pts, depth=depth)
    assert n == len(held)
    assert finest(room) == expected
    assert np.isnan(room.log_odds(pts)).all()
    check_inner_nodes(room)
    # the tree is well formed: it serialises and reads back to the same cells
    again = OccupancyOctree.from_bytes(room.to_bytes("ot"))
    assert finest(again) == expected and again.num_nodes == room.num_nodes


def test_delete_inside_a_pruned_leaf_expands_it():
    m = OccupancyOctree(RES)
    g = np.stack(np.meshgrid(*[np.arange(2)] * 3, indexing="ij"), -1).reshape(-1, 3)
    m.set_cells(RES * (g + 0.5), 2.0)
    assert m.num_leaves == 1 and m.leaves().sizes.tolist() == [2 * RES]
    assert m.delete_cells([[0.05, 0.05, 0.05]]) == 1
    leaves = m.leaves()
    assert len(leaves.sizes) == 7 and np.allclose(leaves.sizes, RES)
    assert (leaves.log_odds == f32(2.0)).all()
    assert np.isnan(m.log_odds([[0.05, 0.05, 0.05]]))[0]
    assert m.log_odds([[0.15, 0.15, 0.15]], depth=15)[0] == f32(2.0)
    check_inner_nodes(m)


def test_delete_a_coarse_node_and_everything():
    m = OccupancyOctree(RES).insert_scan([[0.55, 0.05, 0.05], [-0.55, 0.05, 0.05]],
                                         [0.05, 0.05, 0.05])
    assert m.delete_cells([[-0.3, 0.0, 0.0]], depth=1) == 1      # the x < 0 octant
    assert np.isnan(m.log_odds([[-0.55, 0.05, 0.05]]))[0]
    assert not np.isnan(m.log_odds([[0.55, 0.05, 0.05]]))[0]
    check_inner_nodes(m)
    assert m.delete_cells(m.leaves().centers) > 0
    assert m.num_nodes == 0 and m.num_leaves == 0
    assert np.isnan(m.bounds[0]).all() and len(m.nodes().depths) == 0
    assert m.delete_cells([[0.0, 0.0, 0.0]]) == 0
    m.insert_scan([[0.55, 0.05, 0.05]], [0.05, 0.05, 0.05])      # usable again
    assert m.is_occupied([[0.55, 0.05, 0.05]])[0]


def test_delete_is_not_recorded_by_change_detection():
    m = OccupancyOctree(RES).insert_scan([[0.35, 0.05, 0.05]], [0.05, 0.05, 0.05])
    m.track_changes = True
    m.delete_cells([[0.35, 0.05, 0.05]])
    assert len(m.changed_cells().keys) == 0
    m.update_cells([[0.35, 0.05, 0.05]], 1.0)                     # observed again: new
    changes = m.changed_cells()
    assert changes.keys.tolist() == m.coord_to_key([[0.35, 0.05, 0.05]]).tolist()
    assert changes.new.tolist() == [True]


@pytest.mark.parametrize("call, exc, match", [
    (lambda m: m.delete_cells([[0.0, 0.0, 0.0]], depth=17), ValueError, r"depth must lie in \[0, 16\]"),
    (lambda m: m.delete_cells([[0.0, 0.0, 0.0]], depth=-1), ValueError, r"depth must lie"),
    (lambda m: m.delete_cells([[0.0, 0.0, 0.0]], depth=1.5), TypeError, r"depth must be"),
    (lambda m: m.delete_cells([[0.0, 0.0, 0.0]], depth=True), TypeError, r"depth must be"),
    (lambda m: m.delete_cells([[np.nan, 0.0, 0.0]]), ValueError, r"points must be finite"),
    (lambda m: m.delete_cells([[1e30, 0.0, 0.0]]), ValueError, r"outside the octree's key range"),
    (lambda m: m.delete_cells([0.0, 0.0, 0.0]), ValueError, r"points must have shape"),
    (lambda m: m.delete_cells([["a", "b", "c"]]), TypeError, r"points"),
])
def test_delete_cells_rejects_bad_input_and_changes_nothing(call, exc, match):
    m = OccupancyOctree(RES).insert_scan([[0.35, 0.05, 0.05]], [0.05, 0.05, 0.05])
    data = m.to_bytes()
    with pytest.raises(exc, match=match):
        call(m)
    assert m.to_bytes() == data


# ---------------------------------------------------------------------- search at a depth
@pytest.mark.parametrize("depth", [1, 8, 12, 13, 14, 15, 16])
def test_queries_at_a_depth_match_the_leaves(room, depth):
    rng = np.random.default_rng(depth)
    pts = np.vstack([rng.uniform(-1.0, 1.8, (300, 3)), [[1e30, 0, 0]]])
    want = expected_search(room, pts, depth)
    got = room.log_odds(pts, depth=depth)
    assert np.array_equal(np.isnan(got), np.isnan(want))
    assert np.array_equal(got[~np.isnan(got)], want[~np.isnan(want)])
    occ = room.occupancy(pts, depth=depth)
    assert np.allclose(occ, 1 / (1 + np.exp(-want)), equal_nan=True)
    threshold = f32(room._log_odds_thresholds()[2])
    is_occ, unknown = room.is_occupied(pts, depth=depth, return_unknown=True)
    assert np.array_equal(unknown, np.isnan(want))
    assert np.array_equal(is_occ, np.nan_to_num(want, nan=-np.inf) >= threshold)


def test_depth_zero_is_the_finest(room):
    pts = np.random.default_rng(0).uniform(-1, 1, (100, 3))
    for query in (room.log_odds, room.occupancy):
        assert np.array_equal(query(pts, depth=0), query(pts), equal_nan=True)
        assert np.array_equal(query(pts, depth=16), query(pts), equal_nan=True)
    assert np.array_equal(room.is_occupied(pts, depth=0), room.is_occupied(pts))
    assert room.tree_depth == 16


@pytest.mark.parametrize("depth", [1, 5, 13, 15, 16])
def test_coord_to_key_at_a_depth_is_liboctomaps(depth):
    m = OccupancyOctree(RES)
    rng = np.random.default_rng(depth)
    pts = np.vstack([rng.uniform(-3000, 3000, (200, 3)), [[0.0, -0.0, -1e-9]],
                     [[-3276.7, 3276.79, 0.05]]])
    keys = m.coord_to_key(pts, depth=depth)
    # liboctomap's coordToKey(coordinate, depth), in its signed int arithmetic
    keyval = np.floor((1.0 / RES) * pts.astype(np.float32).astype(np.float64)).astype(np.int64)
    diff = 16 - depth
    want = keyval + 32768 if diff == 0 else ((keyval >> diff) << diff) + (1 << (diff - 1)) + 32768
    assert np.array_equal(keys, want)
    # the key names the depth-d node holding the point: same center, same value
    assert np.array_equal(m.key_to_coord(keys, depth=depth),
                          m.key_to_coord(m.coord_to_key(pts), depth=depth))


@pytest.mark.parametrize("call, exc, match", [
    (lambda m: m.log_odds([[0, 0, 0]], depth=17), ValueError, r"depth must lie in \[0, 16\]"),
    (lambda m: m.occupancy([[0, 0, 0]], depth="1"), TypeError, r"depth must be"),
    (lambda m: m.is_occupied([[0, 0, 0]], depth=-2), ValueError, r"depth must lie"),
    (lambda m: m.log_odds([[np.nan, 0, 0]], depth=3), ValueError, r"points must be finite"),
    (lambda m: m.occupancy([0, 0, 0], depth=3), ValueError, r"points must have shape"),
    (lambda m: m.coord_to_key([[0, 0, 0]], depth=0), ValueError, r"depth must lie in \[1, 16\]"),
    (lambda m: m.coord_to_key([[0, 0, 0]], depth=np.float64(3)), TypeError, r"depth must be"),
    (lambda m: m.coord_to_key([[1e30, 0, 0]], depth=3), ValueError, r"key range"),
    (lambda m: m.is_at_threshold([[0, 0, 0]], depth=99), ValueError, r"depth must lie"),
    (lambda m: m.is_at_threshold([[np.inf, 0, 0]]), ValueError, r"points must be finite"),
])
def test_depth_queries_reject_bad_input(call, exc, match):
    m = OccupancyOctree(RES).insert_scan([[0.35, 0.05, 0.05]], [0.05, 0.05, 0.05])
    with pytest.raises(exc, match=match):
        call(m)


def test_far_points_are_unknown_at_every_depth(room):
    far = [[1e30, 0, 0], [0, -1e30, 0], [4000.0, 0, 0]]
    assert np.isnan(room.log_odds(far, depth=3)).all()
    assert not room.is_at_threshold(far).any()


# ---------------------------------------------------------------------- leaves and nodes
def test_nodes_are_every_node_in_liboctomaps_order(room):
    nodes = check_inner_nodes(room)
    assert isinstance(nodes, Nodes)
    keys = node_keys(nodes, RES)
    assert nodes.depths[0] == 0 and np.allclose(nodes.centers[0], 0)
    assert nodes.sizes[0] == pytest.approx(RES * 2**16)
    assert np.array_equal(dfs_order(keys, nodes.depths), np.arange(len(keys)))
    assert np.allclose(nodes.sizes, RES * 2.0 ** (16 - nodes.depths.astype(float)))
    # the leaves are liboctomap's leaves, in its leaf iterator's order
    leaves = room.leaves()
    assert np.array_equal(nodes.centers[nodes.is_leaf], leaves.centers)
    assert np.array_equal(nodes.log_odds[nodes.is_leaf], leaves.log_odds)
    # and every node is an ancestor of a leaf (or a leaf)
    lk, ld, _ = _leaf_keys(room)
    for d in range(17):
        at = nodes.depths == d
        shift = 16 - d
        want = {tuple(k >> shift) for k, dd in zip(lk, ld) if dd >= d}
        assert {tuple(k >> shift) for k in keys[at]} == want


def test_own_leaf_walk_is_liboctomaps_leaf_iterator(room):
    c, s, d, v, leaf = room._nodes(16, True, False)
    leaves = room.leaves()
    assert np.array_equal(c, leaves.centers) and np.array_equal(v, leaves.log_odds)
    assert np.array_equal(s, leaves.sizes) and leaf.all()
    box = np.array([[-0.33, 0.02, -0.5], [0.41, 0.77, 1.3]])
    key_box = room._leaves_key_box(box)
    c, s, d, v, leaf = room._nodes(16, True, True, key_box)
    leaves = room.leaves(bbox=box, occupied_only=True)
    assert len(c) > 0
    assert np.array_equal(c, leaves.centers) and np.array_equal(v, leaves.log_odds)


@pytest.mark.parametrize("max_depth", [1, 10, 13, 14, 15])
def test_leaves_at_max_depth_are_begin_leafs(room, max_depth):
    lk, ld, lv = _leaf_keys(room)
    shift = 16 - np.minimum(ld, max_depth)
    top = lk >> shift[:, None] << shift[:, None]
    node_depth = np.minimum(ld, max_depth)
    groups = {}
    for k, d, v in zip(top, node_depth, lv):
        key = (int(d), *map(int, k))
        groups[key] = max(groups.get(key, -np.inf), v)
    want_keys = np.array([k[1:] for k in groups])
    want_depth = np.array([k[0] for k in groups])
    order = dfs_order(want_keys, want_depth)
    want_values = np.array(list(groups.values()), dtype=np.float32)[order]
    leaves = room.leaves(max_depth=max_depth)
    assert np.array_equal(leaves.log_odds, want_values)
    assert np.allclose(leaves.sizes, RES * 2.0 ** (16 - want_depth[order]))
    got_keys = np.rint((leaves.centers - leaves.sizes[:, None] / 2) / RES).astype(int) + 32768
    assert np.array_equal(got_keys, want_keys[order])
    # the same as the nodes listed down to max_depth, leaves flagged
    nodes = room.nodes(max_depth=max_depth)
    assert nodes.depths.max() == max_depth
    assert np.array_equal(nodes.log_odds[nodes.is_leaf], leaves.log_odds)
    # occupied_only tests the listed value
    occ = room.leaves(max_depth=max_depth, occupied_only=True)
    keep = leaves.log_odds >= f32(room._log_odds_thresholds()[2])
    assert np.array_equal(occ.centers, leaves.centers[keep])


def test_nodes_at_max_depth_flag_the_cut_as_leaves(room):
    full = room.nodes()
    cut = room.nodes(max_depth=14)
    keep = full.depths <= 14
    assert np.array_equal(cut.centers, full.centers[keep])
    assert np.array_equal(cut.log_odds, full.log_odds[keep])
    assert np.array_equal(cut.is_leaf, full.is_leaf[keep] | (full.depths[keep] == 14))


def test_nodes_in_a_box(room):
    box = np.array([[0.12, -0.31, 0.0], [0.5, 0.2, 0.6]])
    full = room.nodes()
    kb = room._leaves_key_box(box).astype(np.int64)
    keys = node_keys(full, RES)
    span = (1 << (16 - full.depths.astype(np.int64)))[:, None] - 1
    meets = ((keys <= kb[1]) & (keys + span >= kb[0])).all(axis=1)
    boxed = room.nodes(bbox=box)
    assert 0 < len(boxed.depths) < len(full.depths)
    assert np.array_equal(boxed.centers, full.centers[meets])
    assert np.array_equal(boxed.is_leaf, full.is_leaf[meets])
    huge = room.nodes(bbox=[[-1e30] * 3, [1e30] * 3])
    assert np.array_equal(huge.centers, full.centers)


def test_inner_nodes_stay_consistent_through_every_update(room):
    rng = np.random.default_rng(9)
    room.update_cells(rng.uniform(-1, 1, (50, 3)), rng.normal(0, 2, 50))
    check_inner_nodes(room)
    room.insert_scan(rng.uniform(-1, 1, (100, 3)), [0, 0, 0], method="plain")
    check_inner_nodes(room)
    for fmt in ("ot", "bt"):
        check_inner_nodes(OccupancyOctree.from_bytes(room.to_bytes(fmt)))


@pytest.mark.parametrize("call, exc, match", [
    (lambda m: m.nodes(max_depth=17), ValueError, r"max_depth must lie in \[0, 16\]"),
    (lambda m: m.nodes(max_depth=2.0), TypeError, r"max_depth must be"),
    (lambda m: m.leaves(max_depth=-1), ValueError, r"max_depth must lie"),
    (lambda m: m.nodes(bbox=[[0, 0, 0]]), ValueError, r"bbox must have shape \(2, 3\)"),
    (lambda m: m.nodes(bbox=[[1, 0, 0], [0, 1, 1]]), ValueError, r"bbox must have min <= max"),
    (lambda m: m.leaves(max_depth=3, bbox=[[np.nan, 0, 0], [1, 1, 1]]), ValueError,
     r"bbox must have min <= max"),
    (lambda m: m.nodes(bbox="box"), TypeError, r"bbox"),
])
def test_listings_reject_bad_input(call, exc, match):
    m = OccupancyOctree(RES).insert_scan([[0.35, 0.05, 0.05]], [0.05, 0.05, 0.05])
    with pytest.raises(exc, match=match):
        call(m)


def test_empty_map_lists_nothing():
    m = OccupancyOctree(RES)
    assert len(m.nodes().depths) == 0 and len(m.leaves(max_depth=4).sizes) == 0
    assert m.nodes().centers.shape == (0, 3)


# ---------------------------------------------------------------------- is_at_threshold
def test_is_at_threshold_is_liboctomaps_comparison(room):
    rng = np.random.default_rng(1)
    pts = np.vstack([rng.uniform(-1, 1.8, (300, 3)), [[50.0, 50.0, 50.0]]])
    lo, hi = room._log_odds_thresholds()[:2]
    for depth in (0, 14):
        l = room.log_odds(pts, depth=depth)
        want = (l >= f32(hi)) | (l <= f32(lo))         # NaN compares False: unknown
        got = room.is_at_threshold(pts, depth=depth)
        assert np.array_equal(got, want)
    assert room.is_at_threshold([[1.3, 1.3, 1.3]]).tolist() == [True]     # set above the clamp
    assert not room.is_at_threshold(pts[-1:])[0]
    ml = room.to_max_likelihood()
    known = ~np.isnan(ml.log_odds(pts))
    assert ml.is_at_threshold(pts)[known].all()


# ---------------------------------------------------------------------- ray intersections
def _ray_intersection_reference(origin, direction, center, resolution, delta):
    """liboctomap's getRayIntersection in its float / double arithmetic (numpy scalars),
    with the direction normalised as point3d::normalized does."""
    o = origin.astype(f32)
    d = direction.astype(f32)
    nsq = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
    d = d / f32(np.sqrt(np.float64(nsq)))
    c = center.astype(f32)
    half = f32(resolution / 2.0)
    lo = [c[a] - half for a in range(3)]
    hi = [c[a] + half for a in range(3)]
    out_d, found = np.finfo(np.float64).max, False
    for a in range(3):
        if np.float64(d[a]) == 0.0:
            continue
        others = [b for b in range(3) if b != a]
        for plane in (lo[a], hi[a]):
            dist = np.float64(plane - o[a]) / np.float64(d[a])
            p = d * f32(dist) + o
            if not any(np.float64(p[b]) < np.float64(lo[b]) - 1e-6
                       or np.float64(p[b]) > np.float64(hi[b]) + 1e-6 for b in others):
                out_d, found = min(out_d, dist), True
    if not found:
        return None
    return (d * f32(out_d + delta) + o).astype(np.float64)


def test_ray_intersections_old_keyword_centres_warns():
    m = OccupancyOctree(0.1).insert_scan([[1.0, 0.05, 0.05]], [0.05, 0.05, 0.05])
    new = m.ray_intersections([0.05, 0.05, 0.05], [[1.0, 0, 0]], centers=[[1.05, 0.05, 0.05]])
    with pytest.warns(DeprecationWarning, match="'centres' is deprecated.*'centers'"):
        old = m.ray_intersections([0.05, 0.05, 0.05], [[1.0, 0, 0]],
                                  centres=[[1.05, 0.05, 0.05]])
    np.testing.assert_array_equal(old[0], new[0])


@pytest.mark.parametrize("delta", [0.0, 0.01])
def test_ray_intersections_are_liboctomaps(delta):
    m = OccupancyOctree(RES)
    rng = np.random.default_rng(5)
    n = 300
    origins = rng.uniform(-2, 2, (n, 3))
    centers = (np.floor(rng.uniform(-2, 2, (n, 3)) / RES) + 0.5) * RES
    aim = centers + rng.uniform(-0.08, 0.08, (n, 3))       # most rays hit, some miss
    directions = aim - origins
    directions[:20, 1:] = 0.0                             # parallel to two axes
    points, found = m.ray_intersections(origins, directions, centers, delta=delta)
    assert 0 < found.sum() < n
    for i in range(n):
        want = _ray_intersection_reference(origins[i], directions[i], centers[i], RES, delta)
        if want is None:
            assert not found[i] and np.isnan(points[i]).all()
        else:
            assert found[i] and np.array_equal(points[i], want), i
    # with delta 0 the points lie on the cube's surface, on the ray
    if delta == 0:
        off = np.abs(points[found] - centers[found])
        assert np.allclose(off.max(axis=1), RES / 2, atol=1e-5)
        assert (off <= RES / 2 + 1e-5).all()


def test_ray_intersection_of_cast_rays_hits():
    m = OccupancyOctree(RES).insert_scan([[1.02, 0.33, 0.05]], [0.05, 0.05, 0.05])
    ends, hits = m.cast_rays([0.05, 0.05, 0.05], [[0.97, 0.28, 0.0]])
    assert hits.all()
    points, found = m.ray_intersections([0.05, 0.05, 0.05], [[0.97, 0.28, 0.0]], ends)
    assert found.all() and points[0, 0] == pytest.approx(1.0, abs=1e-6)
    # the shared origin and a per-ray origin agree; a center may be shared too
    p2, _ = m.ray_intersections([[0.05, 0.05, 0.05]], [[0.97, 0.28, 0.0]], ends[0])
    assert np.array_equal(points, p2)


@pytest.mark.parametrize("call, exc, match", [
    (lambda m: m.ray_intersections([0, 0, 0], [[0, 0, 0]], [[1, 0, 0]]), ValueError,
     r"directions must be non-zero"),
    (lambda m: m.ray_intersections([0, 0, 0], [[1, 0, 0]], [[1, 0, 0], [2, 0, 0]]),
     ValueError, r"centers must have shape \(3,\) or \(1, 3\)"),
    (lambda m: m.ray_intersections([[0, 0, 0]] * 2, [[1, 0, 0]], [[1, 0, 0]]), ValueError,
     r"origins must have shape \(3,\) or \(1, 3\)"),
    (lambda m: m.ray_intersections([0, 0, 0], [[1, 0, 0]], [[1e30, 0, 0]]), ValueError,
     r"centers.*key range"),
    (lambda m: m.ray_intersections([1e30, 0, 0], [[1, 0, 0]], [[1, 0, 0]]), ValueError,
     r"origins.*key range"),
    (lambda m: m.ray_intersections([0, 0, 0], [[np.nan, 0, 0]], [[1, 0, 0]]), ValueError,
     r"directions must be finite"),
    (lambda m: m.ray_intersections([0, 0, 0], [[1, 0, 0]], [[1, 0, 0]], delta=1e30),
     ValueError, r"delta must lie in"),
    (lambda m: m.ray_intersections([0, 0, 0], [[1, 0, 0]], [[1, 0, 0]], delta=np.nan),
     ValueError, r"delta"),
    (lambda m: m.ray_intersections([0, 0, 0], [[1, 0, 0]], [[1, 0, 0]], delta="0"),
     TypeError, r"delta must be a real number"),
    (lambda m: m.ray_intersections([0, 0], [[1, 0, 0]], [[1, 0, 0]]), ValueError,
     r"origins must have shape"),
    (lambda m: m.ray_intersections([0, 0, 0], [1, 0, 0], [[1, 0, 0]]), ValueError,
     r"directions must have shape"),
])
def test_ray_intersections_reject_bad_input(call, exc, match):
    with pytest.raises(exc, match=match):
        call(OccupancyOctree(RES))


# ---------------------------------------------------------------------- set_params
NEW = dict(prob_hit=0.9, prob_miss=0.3, clamping_min=0.05, clamping_max=0.99,
           occupancy_threshold=0.6)


def test_set_params_then_updates_are_those_of_a_map_built_with_them():
    rng = np.random.default_rng(2)
    scans = [rng.uniform(-1, 1, (100, 3)) for _ in range(3)]
    a = OccupancyOctree(RES).set_params(**NEW)
    b = OccupancyOctree(RES, **NEW)
    for s in scans:
        a.insert_scan(s, [0, 0, 0])
        b.insert_scan(s, [0, 0, 0], method="plain")
    assert a.to_bytes() == b.to_bytes()
    assert a.get_params() == b.get_params()
    assert a.prob_hit == 0.9 and a.occupancy_threshold == 0.6
    assert a._log_odds_thresholds() == b._log_odds_thresholds()


def test_set_params_leaves_the_stored_values():
    m = OccupancyOctree(RES).update_cells([[0.05, 0.05, 0.05]], 3.0)
    data = m.to_bytes()
    m.set_params(clamping_max=0.8, occupancy_threshold=0.96)
    assert m.to_bytes() == data                                  # not re-clamped
    assert m.is_occupied([[0.05, 0.05, 0.05]]).tolist() == [False]   # 3.0 < logit(0.96)
    assert m.is_at_threshold([[0.05, 0.05, 0.05]]).tolist() == [True]
    # liboctomap's updateNode: an update towards a bound the cell is at or beyond is
    # skipped; any other update clamps to the new bounds
    m.update_cells([[0.05, 0.05, 0.05]], 0.1)
    assert m.log_odds([[0.05, 0.05, 0.05]])[0] == f32(3.0)
    m.update_cells([[0.05, 0.05, 0.05]], -0.1)
    assert m.log_odds([[0.05, 0.05, 0.05]])[0] == f32(np.log(0.8 / 0.2))


def test_set_params_survive_pickle_and_load(tmp_path):
    m = OccupancyOctree(RES).insert_scan([[0.55, 0.05, 0.05]], [0.05, 0.05, 0.05])
    m.set_params(**NEW)
    again = pickle.loads(pickle.dumps(m))
    assert again.get_params() == m.get_params()
    assert again._log_odds_thresholds() == m._log_odds_thresholds()
    path = tmp_path / "m.ot"
    m.save(path)
    params = {k: v for k, v in m.get_params().items() if k != "resolution"}
    loaded = OccupancyOctree.load(path, **params)
    assert loaded.get_params() == m.get_params() and loaded.to_bytes() == m.to_bytes()
    m.set_params(**m.get_params())                               # the round trip works


@pytest.mark.parametrize("params, exc, match", [
    (dict(prob_hit=0.4), ValueError, r"prob_hit"),
    (dict(prob_miss=0.6), ValueError, r"prob_miss"),
    (dict(clamping_min=0.0), ValueError, r"clamping_min"),
    (dict(clamping_max=1.0), ValueError, r"clamping_max"),
    (dict(occupancy_threshold=np.nan), ValueError, r"occupancy_threshold"),
    (dict(prob_hit="0.7"), TypeError, r"prob_hit must be a real number"),
    (dict(prob_hit=0.8, prob_miss=1e30), ValueError, r"prob_miss"),
    (dict(resolution=0.2), ValueError, r"resolution is fixed"),
    (dict(k=3), ValueError, r"'k' is not a parameter of OccupancyOctree"),
])
def test_set_params_rejects_and_changes_nothing(params, exc, match):
    m = OccupancyOctree(RES)
    before = (m.get_params(), m._log_odds_thresholds())
    with pytest.raises(exc, match=match):
        m.set_params(**params)
    assert (m.get_params(), m._log_odds_thresholds()) == before


def test_grid_and_colour_maps_set_params_as_if_built_with_them():
    from occgp import ColorOctree, GridMap
    rng = np.random.default_rng(3)
    scans = [rng.uniform(-1, 1, (100, 3)) for _ in range(3)]
    a, b = GridMap(RES).set_params(**NEW), GridMap(RES, **NEW)
    for s in scans:
        a.insert_scan(s, [0, 0, 0], mode="ray")
        b.insert_scan(s, [0, 0, 0], mode="ray")
    got, want = a.cells(), b.cells()
    assert a.get_params() == b.get_params() and len(got.centers) > 0
    np.testing.assert_array_equal(got.centers, want.centers)
    np.testing.assert_array_equal(got.log_odds, want.log_odds)
    np.testing.assert_array_equal(a.is_occupied(got.centers), b.is_occupied(got.centers))
    colours = rng.integers(0, 255, (100, 3))
    c, d = ColorOctree(RES).set_params(**NEW), ColorOctree(RES, **NEW)
    for s in scans:
        c.insert_scan(s, [0, 0, 0], colours)
        d.insert_scan(s, [0, 0, 0], colours)
    assert c.to_bytes() == d.to_bytes() and c.get_params() == d.get_params()
    for m in (a, c):
        before = m.get_params()
        with pytest.raises(ValueError, match="prob_miss"):
            m.set_params(prob_hit=0.8, prob_miss=0.7)
        assert m.get_params() == before


def test_knnmap_keeps_its_rules():
    m = KNNMap(RES)
    before = m.get_params()
    with pytest.raises(ValueError, match=r"'prob_hit' is not a parameter of KNNMap; "
                                         r"its parameters are resolution, k, "):
        m.set_params(prob_hit=0.8)
    with pytest.raises(ValueError, match=r"p_max >= occupancy_threshold"):
        m.set_params(k=3, occupancy_threshold=0.99)     # checked together: k is not set either
    with pytest.raises(AttributeError, match="no prob_hit"):
        m.prob_hit
    assert m.get_params() == before
    assert m.set_params() is m


def test_inner_nodes_after_expand_prune_and_max_likelihood(room):
    check_inner_nodes(room.expand())
    check_inner_nodes(room.prune())
    check_inner_nodes(room.to_max_likelihood())


def test_empty_calls_return_empty_arrays():
    m = OccupancyOctree(RES).insert_scan([[0.35, 0.05, 0.05]], [0.05, 0.05, 0.05])
    none = np.empty((0, 3))
    points, found = m.ray_intersections([0, 0, 0], none, none)
    assert points.shape == (0, 3) and found.shape == (0,)
    assert m.delete_cells(none) == 0 and m.log_odds(none, depth=3).shape == (0,)
    assert m.is_at_threshold(none).shape == (0,)
    assert m.coord_to_key(none, depth=4).shape == (0, 3)
