"""Frontiers of the log-odds maps and of OccupancyGrid2D: scenes whose frontier is known
by construction (a walled free box with openings), and a brute-force reference."""

import itertools

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from occgp import ColorOctree, Frontiers, GridMap, OccupancyGrid2D, OccupancyOctree

N = 8   # the free box: cells 0..7 on every axis (one pruned 8 m leaf at 1 m)


def grid_with(cells, values, resolution=1.0):
    """A GridMap holding exactly `cells` (finest indices) with `values`; GridMap has no
    public cell setter, so this uses its compiled core's."""
    g = GridMap(resolution)
    keys = (np.asarray(cells, dtype=np.int64) + 32768).astype(np.uint16)
    g._set_cells(np.ascontiguousarray(keys), np.asarray(values, dtype=np.float32))
    return g


def walled_box(windows=None):
    """Finest cell indices and log-odds: a free 8^3 box with occupied walls on five sides
    (x = -1, y = -1, y = 8, z = -1, z = 8); the side x = 8 is open, or, with `windows`
    (a list of (j, k) cells), walled except at those cells."""
    ar = np.arange(N)
    free = np.array(list(itertools.product(ar, ar, ar)))
    span = np.arange(-1, N + 1)
    walls = {(i, j, k) for i in span for j in span for k in span
             if i < N and (i == -1 or j in (-1, N) or k in (-1, N))}
    if windows is not None:
        walls |= {(N, j, k) for j in ar for k in ar if (j, k) not in windows}
    walls = np.array(sorted(walls))
    cells = np.concatenate([free, walls])
    values = np.concatenate([np.full(len(free), -2.0), np.full(len(walls), 2.0)])
    return cells, values


def build(kind, cells, values):
    if kind == "grid":
        return grid_with(cells, values)
    m = OccupancyOctree(1.0).set_cells(cells + 0.5, values)
    return m


def as_set(points):
    return {tuple(p) for p in np.asarray(points).round(6).tolist()}


@pytest.mark.parametrize("kind", ["octree", "grid"])
def test_open_side_is_the_frontier(kind):
    m = build(kind, *walled_box())
    if kind == "octree":
        assert (m.leaves().sizes == N).sum() == 1       # the free box is one pruned leaf
    f = m.frontiers()
    assert isinstance(f, Frontiers) and f.n_clusters == 1
    expected = {(N - 0.5, j + 0.5, k + 0.5) for j in range(N) for k in range(N)}
    assert as_set(f.cells) == expected and len(f.cells) == N * N
    assert f.sizes.tolist() == [N * N] and f.labels.tolist() == [0] * (N * N)
    assert_allclose(f.centroids, [[N - 0.5, N / 2, N / 2]])
    assert as_set(f.cluster(0)) == expected


@pytest.mark.parametrize("kind", ["octree", "grid"])
def test_two_windows_give_two_clusters(kind):
    a = [(1, 1), (2, 1)]
    b = [(5, 5), (6, 5), (7, 5), (5, 6), (6, 6), (7, 6)]
    m = build(kind, *walled_box(windows=a + b))
    f = m.frontiers()
    assert f.sizes.tolist() == [6, 2]                  # largest first
    assert_allclose(f.centroids, [[N - 0.5, 6.5, 6.0], [N - 0.5, 2.0, 1.5]])
    assert as_set(f.cluster(0)) == {(N - 0.5, j + 0.5, k + 0.5) for j, k in b}
    assert as_set(f.cluster(1)) == {(N - 0.5, j + 0.5, k + 0.5) for j, k in a}
    assert_array_equal(f.labels, [0] * 6 + [1] * 2)   # cells grouped by cluster
    assert f.cells.shape == (8, 3) and f.labels.dtype == np.int64
    big = m.frontiers(min_size=3)
    assert big.sizes.tolist() == [6] and len(big.cells) == 6
    assert m.frontiers(min_size=7).n_clusters == 0


def test_clusters_use_26_connectivity():
    """Two windows touching only at a corner (or an edge in the frontier plane) make one
    cluster."""
    m = build("octree", *walled_box(windows=[(1, 1), (2, 2), (4, 4)]))
    f = m.frontiers()
    assert f.sizes.tolist() == [2, 1]
    assert as_set(f.cluster(1)) == {(N - 0.5, 4.5, 4.5)}


def test_a_closed_box_has_no_frontier_and_a_box_sees_outside_states():
    closed = build("octree", *walled_box(windows=[]))
    assert closed.frontiers().n_clusters == 0
    open_box = build("octree", *walled_box())
    # a box inside the free space: its edge cells' neighbours are free (outside the box)
    assert open_box.frontiers(bbox=[[1, 1, 1], [7, 7, 7]]).n_clusters == 0
    # a box cutting the frontier: the frontier cells inside it, exactly
    f = open_box.frontiers(bbox=[[5.0, 2.0, 3.0], [8.0, 4.0, 3.5]])
    assert as_set(f.cells) == {(7.5, 2.5, 3.5), (7.5, 3.5, 3.5)}


def test_empty_map_and_unknown_box():
    m = OccupancyOctree(0.1)
    f = m.frontiers()
    assert f.cells.shape == (0, 3) and f.centroids.shape == (0, 3) and f.n_clusters == 0
    assert m.frontiers(bbox=[[0, 0, 0], [1, 1, 1]]).n_clusters == 0
    with pytest.raises(ValueError, match=r"i: there are no frontier clusters"):
        f.cluster(0)


@pytest.mark.parametrize("kind", ["octree", "grid", "color"])
def test_empty_maps_and_cells_outside_the_box_have_no_frontier(kind):
    """Empty in, empty out (issue 40), on every log-odds map."""
    make = {"octree": OccupancyOctree, "grid": GridMap, "color": ColorOctree}[kind]
    empty = make(0.1)
    for f in (empty.frontiers(), empty.frontiers(bbox=[[0, 0, 0], [0.5, 0.5, 0.5]],
                                                min_size=3)):
        assert f.cells.shape == (0, 3) and f.labels.shape == (0,) and f.n_clusters == 0
    known = make(0.1)
    if kind == "color":
        known.insert_scan([[1.0, 0.05, 0.05]], [0.05, 0.05, 0.05], colors=[[1.0, 0, 0]])
    else:
        known.insert_scan([[1.0, 0.05, 0.05]], [0.05, 0.05, 0.05])
    assert known.frontiers().n_clusters > 0                  # the ray's free cells
    far = known.frontiers(bbox=[[5.0, 5.0, 5.0], [5.5, 5.5, 5.5]])
    assert far.cells.shape == (0, 3) and far.centroids.shape == (0, 3)


# --------------------------------------------------------------------------- #
# brute force on random maps
# --------------------------------------------------------------------------- #
def reference(cells, states, box_lo, box_hi, connectivity=26):
    """Frontier cells (as index tuples) and the clusters (frozensets) by explicit loops."""
    known = dict(zip(map(tuple, cells.tolist()), states.tolist()))
    faces = [d for d in itertools.product((-1, 0, 1), repeat=3) if sum(map(abs, d)) == 1]
    front = set()
    for c, s in known.items():
        if s == 0 and all(box_lo[a] <= c[a] < box_hi[a] for a in range(3)):
            if any(tuple(c[a] + d[a] for a in range(3)) not in known for d in faces):
                front.add(c)
    steps = [d for d in itertools.product((-1, 0, 1), repeat=3) if any(d)]
    clusters, seen = [], set()
    for c in front:
        if c in seen:
            continue
        todo, comp = [c], set()
        seen.add(c)
        while todo:
            x = todo.pop()
            comp.add(x)
            for d in steps:
                y = tuple(x[a] + d[a] for a in range(3))
                if y in front and y not in seen:
                    seen.add(y)
                    todo.append(y)
        clusters.append(frozenset(comp))
    return front, clusters


def random_map(kind):
    rng = np.random.default_rng(3)
    if kind == "color":
        pts = rng.uniform(-1.5, 1.5, size=(300, 3))
        return ColorOctree(0.25).insert_scan(pts, [0, 0, 0], colors=np.ones((300, 3)))
    cells = rng.integers(-6, 6, size=(700, 3))
    values = rng.choice([-2.0, -2.0, -2.0, 2.0], size=700)
    ar = np.arange(4)
    block = np.array(list(itertools.product(ar + 4, ar - 8, ar)))   # a pruned free leaf
    cells = np.concatenate([block, cells])
    values = np.concatenate([np.full(len(block), -2.0), values])
    if kind == "grid":
        u, first = np.unique(cells[::-1], axis=0, return_index=True)   # last value wins
        return grid_with(u, values[::-1][first], resolution=0.25)
    return OccupancyOctree(0.25).set_cells((cells + 0.5) * 0.25, values)


def finest(m):
    table = m.leaves() if hasattr(m, "leaves") else m.cells()
    res = m.resolution
    out = []
    for c, s in zip(table[0], table[1]):
        side = int(round(s / res))
        low = np.rint(c / res - side / 2).astype(np.int64)
        out.extend(tuple(low + np.array(o)) for o in itertools.product(range(side), repeat=3))
    idx = np.array(out)
    occ = m.is_occupied((idx + 0.5) * res)
    return idx, occ.astype(int)


@pytest.mark.parametrize("kind", ["octree", "grid", "color"])
@pytest.mark.parametrize("bbox", [None, [[-0.6, -1.1, -0.3], [1.05, 0.4, 1.2]]])
def test_frontiers_match_brute_force(kind, bbox):
    m = random_map(kind)
    idx, states = finest(m)
    res = m.resolution
    if bbox is None:
        lo, hi = idx.min(0), idx.max(0) + 1
    else:
        lo = np.floor(np.array(bbox[0]) / res + 1e-9).astype(int)
        hi = np.ceil(np.array(bbox[1]) / res - 1e-9).astype(int)
    front, clusters = reference(idx, states, lo, hi)
    f = m.frontiers(bbox=bbox)
    got = {tuple(v) for v in np.floor(f.cells / res).astype(int).tolist()}
    assert got == front and len(front) > 5
    got_clusters = {frozenset(tuple(v) for v in np.floor(f.cluster(i) / res).astype(int).tolist())
                    for i in range(f.n_clusters)}
    assert got_clusters == set(clusters)
    assert sorted(f.sizes.tolist(), reverse=True) == f.sizes.tolist()
    for i in range(f.n_clusters):
        assert_allclose(f.centroids[i], f.cluster(i).mean(axis=0))


# --------------------------------------------------------------------------- #
# 2D
# --------------------------------------------------------------------------- #
def test_frontiers_of_a_projected_grid():
    m = build("octree", *walled_box())
    grid = m.project_2d(0.0, N - 0.1)
    assert grid.shape == (N + 1, N + 2) and grid.origin.tolist() == [-1.0, -1.0]
    f = grid.frontiers()
    assert f.cells.shape == (N, 2)
    assert as_set(f.cells) == {(N - 0.5, j + 0.5) for j in range(N)}
    assert_allclose(f.centroids, [[N - 0.5, N / 2]])
    # a band through window A only: the wall's gap at y 1..3 is the frontier
    a = [(1, 1), (2, 1)]
    b = [(5, 5), (6, 5), (5, 6), (6, 6)]
    m = build("grid", *walled_box(windows=a + b))
    assert m.project_2d(0.0, N - 0.1).frontiers().n_clusters == 0
    f = m.project_2d(1.2, 1.7).frontiers()
    assert f.sizes.tolist() == [2] and as_set(f.cells) == {(N - 0.5, 1.5), (N - 0.5, 2.5)}
    f = m.project_2d(5.0, 6.5).frontiers()
    assert f.sizes.tolist() == [2] and as_set(f.cells) == {(N - 0.5, 5.5), (N - 0.5, 6.5)}


def test_grid_frontiers_by_hand():
    states = np.array([[0, 0, 0, 0, 0],
                       [0, 1, 1, 1, 0],
                       [0, 1, -1, 1, 0],
                       [0, 1, 0, 1, 0],
                       [0, 0, 0, 0, 0]])
    grid = OccupancyGrid2D(states, origin=[10.0, 20.0], resolution=2.0)
    f = grid.frontiers()
    # the border (neighbours beyond the grid are unknown): a ring of 16 cells, joined
    # by the cell beside the hole (8-connectivity)
    assert f.sizes.tolist() == [17]
    assert (17.0, 25.0) in as_set(f.cells) and (15.0, 25.0) not in as_set(f.cells)
    inner = OccupancyGrid2D(np.pad(states, 1, constant_values=1), [0, 0], 1.0).frontiers()
    assert inner.sizes.tolist() == [1] and as_set(inner.cells) == {(4.5, 3.5)}
    # diagonal neighbours cluster together (8-connectivity), not across a gap
    diag = OccupancyGrid2D([[1, 1, 1, 1], [1, 0, 1, 1], [1, 1, -1, 1], [1, 1, 1, 1]], [0, 0], 1.0)
    assert diag.frontiers().n_clusters == 0          # (1, 1)'s face neighbours are known
    diag = OccupancyGrid2D([[1, 1, 1, 1], [1, 0, -1, 1], [1, -1, 0, 1], [1, 1, 1, 1]],
                           [0, 0], 1.0).frontiers()
    assert diag.sizes.tolist() == [2]


@pytest.mark.parametrize("kwargs, exc, match", [
    (dict(bbox=[[0, 0], [1, 1]]), ValueError, r"bbox must have shape \(2, 3\)"),
    (dict(bbox=[[0, 0, 0], [1, 1, np.nan]]), ValueError, r"bbox must be finite"),
    (dict(bbox=[[0, 0, 0], [1, 0, 1]]), ValueError, r"bbox must have min < max"),
    (dict(min_size=0), ValueError, r"min_size"),
    (dict(min_size=1.5), TypeError, r"min_size"),
    (dict(bbox=[[0, 0, 0], [100, 100, 100]]), ValueError,
     r"bbox .* needs 1e\+03 x 1e\+03 x 1e\+03 cells, more than max_cells=16777216"),
    (dict(bbox=[[0, 0, 0], [1, 1, 1]], max_cells=999), ValueError, r"more than max_cells=999"),
])
def test_frontiers_reject_bad_input(kwargs, exc, match):
    m = OccupancyOctree(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0])
    with pytest.raises(exc, match=match):
        m.frontiers(**kwargs)


def test_cluster_and_grid_frontiers_reject_bad_input():
    f = OccupancyGrid2D([[0, -1]], [0, 0], 1.0).frontiers()
    with pytest.raises(ValueError, match=r"i must"):
        f.cluster(1)
    with pytest.raises(TypeError, match=r"i must be a non-negative int, got float"):
        f.cluster(0.0)
    with pytest.raises(ValueError, match=r"min_size"):
        OccupancyGrid2D([[0, -1]], [0, 0], 1.0).frontiers(min_size=-1)
