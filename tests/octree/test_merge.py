"""Merging maps: ``OccupancyOctree.merge`` against ``update_cells`` / ``set_cells`` by hand,
on every leaf."""

import numpy as np
import pytest

from occgp import GridMap, OccupancyOctree

RES = 0.1



def two_maps():
    rng = np.random.default_rng(3)
    a, b = OccupancyOctree(RES), OccupancyOctree(RES, prob_hit=0.8, clamping_max=0.99)
    for m, origin in ((a, [0.0, 0.0, 0.0]), (b, [0.6, -0.3, 0.2])):
        d = rng.normal(size=(3000, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        pts = np.asarray(origin) + d * rng.uniform(1.0, 2.5, size=(3000, 1))
        m.insert_scan(pts, origin)
    return a, b


def finest(tree):
    """Centers and log-odds of every finest cell a map knows (leaves expanded)."""
    lv = tree.leaves()
    out_c, out_v = [], []
    for c, s, v in zip(lv.centers, lv.sizes, lv.log_odds):
        n = int(round(s / RES))
        ar = (np.arange(n) - n / 2 + 0.5) * RES
        g = np.stack(np.meshgrid(ar, ar, ar, indexing="ij"), axis=-1).reshape(-1, 3) + c
        out_c.append(g)
        out_v.append(np.full(len(g), v, dtype=np.float32))
    return np.concatenate(out_c), np.concatenate(out_v)


def same_leaves(x, y):
    lx, ly = x.leaves(), y.leaves()
    ox, oy = np.lexsort(lx.centers.T), np.lexsort(ly.centers.T)
    return (np.array_equal(lx.centers[ox], ly.centers[oy])
            and np.array_equal(lx.sizes[ox], ly.sizes[oy])
            and np.array_equal(lx.log_odds[ox], ly.log_odds[oy]))


def copy(tree):
    return OccupancyOctree.from_bytes(tree.to_bytes(), **tree._sensor_params())


@pytest.mark.slow
def test_add_equals_update_cells_by_hand():
    a, b = two_maps()
    centers, values = finest(b)
    assert len(centers) > len(b.leaves().sizes)            # b has pruned leaves
    expected = copy(a).update_cells(centers, values)
    assert same_leaves(copy(a).merge(b), expected)


@pytest.mark.slow
def test_max_equals_set_cells_by_hand():
    a, b = two_maps()
    centers, values = finest(b)
    mine = a.log_odds(centers)
    take = np.isnan(mine) | (values > mine)
    expected = copy(a).set_cells(centers[take], values[take])
    merged = copy(a).merge(b, rule="max")
    assert same_leaves(merged, expected)
    assert np.all(merged.log_odds(centers) >= np.fmin(values, merged.clamping_max))


@pytest.mark.slow
def test_identity_and_whole_cell_transforms_are_exact():
    a, b = two_maps()
    assert same_leaves(copy(a).merge(b, np.eye(4)), copy(a).merge(b))
    # a quarter turn about z and a shift by whole cells map cells onto cells
    t = np.array([[0.0, -1.0, 0.0, 0.3], [1.0, 0.0, 0.0, -0.2], [0.0, 0.0, 1.0, 0.5],
                  [0.0, 0.0, 0.0, 1.0]])
    centers, values = finest(b)
    moved = centers @ t[:3, :3].T + t[:3, 3]
    expected = copy(a).update_cells(moved, values)
    assert same_leaves(copy(a).merge(b, t), expected)


ROTATION = np.array([[np.cos(0.3), -np.sin(0.3), 0.0, 1.234],
                     [np.sin(0.3), np.cos(0.3), 0.0, -0.5],
                     [0.0, 0.0, 1.0, 0.05], [0.0, 0.0, 0.0, 1.0]])


@pytest.mark.parametrize("rule", ["add", "max"])
@pytest.mark.parametrize("transform", [None, "shift", "rotation"], ids=str)
def test_merging_empty_maps(rule, transform):
    """Empty is a valid state (issue 40): an empty map merged into any map leaves it
    unchanged, and a map merged into an empty one gives the map's evidence."""
    t = {None: None, "shift": np.diag([1.0, 1.0, 1.0, 1.0]) + np.eye(4, k=3) * 0.3,
         "rotation": ROTATION}[transform]
    rng = np.random.default_rng(5)
    a = OccupancyOctree(RES).insert_scan(rng.uniform(-1.0, 1.0, (200, 3)), [0.0, 0.0, 0.0])
    for empty in (OccupancyOctree(RES), GridMap(RES)):
        merged = OccupancyOctree(RES).merge(empty, t, rule=rule)
        assert merged.num_leaves == 0 and np.isnan(merged.log_odds([[0.05] * 3])).all()
        assert copy(a).merge(empty, t, rule=rule).to_bytes("ot") == a.to_bytes("ot")
    # into an empty map: as into a map that knows nothing (a fresh copy of the
    # reference's parameters), the whole of a's evidence, nothing else
    fresh = OccupancyOctree(RES).merge(a, t, rule=rule)
    centers, values = finest(fresh)
    if t is None:
        assert same_leaves(fresh, a)
    else:
        pre = (centers - t[:3, 3]) @ t[:3, :3]
        assert np.array_equal(values.astype(np.float64), a.log_odds(pre))


@pytest.mark.slow
def test_any_rotation_resamples_every_cell_once():
    a, b = two_maps()
    angle = 0.3
    t = np.eye(4)
    t[:3, :3] = [[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0],
                 [0, 0, 1]]
    t[:3, 3] = [1.234, -0.5, 0.05]
    empty = OccupancyOctree(RES).merge(b, t)
    centers, values = finest(empty)
    # each cell holds the value of the cell of b at its center's preimage
    pre = (centers - t[:3, 3]) @ t[:3, :3]
    assert np.array_equal(values.astype(np.float64), b.log_odds(pre))
    # and no cell whose preimage b knows is left out: the cells around the merged ones
    around = (centers[:, None, :] + RES * np.array(
        [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]])).reshape(-1, 3)
    missing = np.isnan(empty.log_odds(around))
    assert np.isnan(b.log_odds((around[missing] - t[:3, 3]) @ t[:3, :3])).all()
    # the volume is kept up to resampling
    assert abs(len(centers) / len(finest(b)[0]) - 1) < 0.05


def test_merge_takes_grid_maps_and_tracks_changes():
    pts = np.array([[1.0, 0.2, 0.1], [0.3, 1.1, 0.0]])
    grid = GridMap(RES).insert_scan(pts, [0, 0, 0])
    tree = OccupancyOctree(RES)
    tree.track_changes = True
    tree.merge(grid)
    assert same_leaves(tree, OccupancyOctree(RES).insert_scan(pts, [0, 0, 0]))
    assert len(tree.changed_cells().keys) == len(finest(tree)[0])


@pytest.mark.parametrize("call, error, match", [
    (lambda a, b: a.merge(OccupancyOctree(0.2)), ValueError, "resolution"),
    (lambda a, b: a.merge("map"), TypeError, "other must be"),
    (lambda a, b: a.merge(b, np.eye(3)), ValueError, "4 x 4"),
    (lambda a, b: a.merge(b, 2 * np.eye(4)), ValueError, "last row|rotation"),
    (lambda a, b: a.merge(b, np.diag([1.0, 1.0, -1.0, 1.0])), ValueError, "rotation"),
    (lambda a, b: a.merge(b, np.full((4, 4), np.nan)), ValueError, "finite"),
    (lambda a, b: a.merge(b, rule="min"), ValueError, "rule"),
    (lambda a, b: a.merge(b, max_cells=10), ValueError, "max_cells"),
    (lambda a, b: a.merge(b, np.array([[1, 0, 0, 1e30], [0, 1, 0, 0], [0, 0, 1, 0],
                                       [0, 0, 0, 1.0]])), ValueError, "key range"),
    (lambda a, b: a.merge(b, np.array([[1, 0, 0, 3276.0], [0, 1, 0, 0], [0, 0, 1, 0],
                                       [0, 0, 0, 1.0]])), ValueError, "key range"),
])
def test_a_rejected_merge_changes_nothing(call, error, match):
    a, b = two_maps()
    before = a.to_bytes()
    with pytest.raises(error, match=match):
        call(a, b)
    assert a.to_bytes() == before
