"""Helpers that several test modules share (the fixtures are in conftest.py)."""

import threading

import numpy as np
from numpy.testing import assert_allclose, assert_array_equal
from scipy.optimize import approx_fprime

from occgp import KNNMap, OccupancyOctree
from octomap_reference import MAX_VAL


def share_between_threads(make_map, room, read, n_readers=3):
    """Insert 20 noisy copies of the scan `room` (points, origin) into one map from a
    thread while `n_readers` others call ``read(map, points)`` 50 times each; return
    that map, one built from the same scans in a single thread, and the exceptions
    the readers raised."""
    points, origin = room
    rng = np.random.default_rng(4)
    scans = [(points + rng.normal(0, 0.02, points.shape), origin) for _ in range(20)]
    shared, errors = make_map(), []

    def write():
        for p, o in scans:
            shared.insert_scan(p, o)

    def reader():
        try:
            for _ in range(50):
                read(shared, points)
        except Exception as exc:   # pragma: no cover - reported by the caller
            errors.append(exc)

    threads = [threading.Thread(target=write)]
    threads += [threading.Thread(target=reader) for _ in range(n_readers)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    sequential = make_map()
    for p, o in scans:
        sequential.insert_scan(p, o)
    return shared, sequential, errors


def random_scans(rng, n_scans=3, n_points=60, spread=2.0, *, origins=0.5, near=0.2):
    """`n_scans` scans of `n_points` random rays each, from origins drawn uniformly in
    ``[-origins, origins]^3``, of lengths uniform in ``[near, spread]``."""
    scans = []
    for _ in range(n_scans):
        origin = rng.uniform(-origins, origins, 3)
        direction = rng.normal(size=(n_points, 3))
        direction /= np.linalg.norm(direction, axis=1, keepdims=True)
        points = origin + direction * rng.uniform(near, spread, (n_points, 1))
        scans.append((points, origin))
    return scans


def assert_prediction_shapes(model, X):
    """A fitted occgp.gp model's ``predict`` (with and without `return_var`) and
    ``predict_proba`` at `X`: one value per row, the same mean both ways,
    probabilities in [0, 1], and an empty answer to an empty query. Returns the
    variance."""
    mean = model.predict(X)
    mean2, var = model.predict(X, return_var=True)
    proba = model.predict_proba(X)
    assert mean.shape == var.shape == proba.shape == (len(X),)
    assert_array_equal(mean, mean2)
    assert ((proba >= 0) & (proba <= 1)).all()
    assert model.predict(np.empty((0, X.shape[1]))).shape == (0,)
    return var


def assert_gradient_matches(objective, theta, *args):
    """`objective(theta, *args)` returns (value, gradient): the gradient has theta's
    shape and matches finite differences of the value. Returns the value."""
    value, grad = objective(theta, *args)
    assert grad.shape == theta.shape
    assert_allclose(grad, approx_fprime(theta, lambda t: objective(t, *args)[0], 1e-7),
                    rtol=1e-4, atol=1e-5)
    return value


_PLY_TYPES = {"float": "<f4", "double": "<f8", "uchar": "u1", "int": "<i4", "uint": "<u4"}


def read_ply(path):
    """Parse a PLY file (ascii or binary_little_endian, triangle lists) with numpy."""
    raw = open(path, "rb").read()
    end = raw.index(b"end_header\n") + len(b"end_header\n")
    lines = raw[:end].decode("ascii").splitlines()
    assert lines[0] == "ply"
    fmt = lines[1].split()[1]
    elements, comments = [], []
    for line in lines[2:-1]:
        words = line.split()
        if words[0] == "comment":
            comments.append(line[8:])
        elif words[0] == "element":
            elements.append((words[1], int(words[2]), []))
        elif words[0] == "property" and words[1] == "list":
            elements[-1][2].append(("n", _PLY_TYPES[words[2]]))
            elements[-1][2].append(("v", _PLY_TYPES[words[3]], (3,)))
        else:
            elements[-1][2].append((words[2], _PLY_TYPES[words[1]]))
    out, pos = {}, end
    text = raw[end:].decode("ascii").splitlines() if fmt == "ascii" else None
    for name, count, props in elements:
        dt = np.dtype(props)
        if fmt == "binary_little_endian":
            out[name] = np.frombuffer(raw, dtype=dt, count=count, offset=pos)
            pos += count * dt.itemsize
        else:
            assert fmt == "ascii"
            rows = np.array([[float(v) for v in t.split()] for t in text[:count]])
            text = text[count:]
            arr = np.zeros(count, dtype=dt)
            col = 0
            for p in props:
                width = p[2][0] if len(p) == 3 else 1
                arr[p[0]] = rows[:, col:col + width].reshape(arr[p[0]].shape)
                col += width
            out[name] = arr
    if fmt == "binary_little_endian":
        assert pos == len(raw), "trailing bytes after the last element"
    else:
        assert not text, "trailing rows after the last element"
    return out, comments


def grid_values(grid):
    """Cell key → float32 log-odds, keys computed from the centers as `leaf_values` does."""
    centers, sizes, values = grid.cells()
    assert np.all(sizes == grid.resolution)
    keys = np.floor(centers / grid.resolution).astype(np.int64) + MAX_VAL
    return {tuple(k): v for k, v in zip(keys.tolist(), values)}


def assert_same_cells(got, expected):
    assert got.keys() == expected.keys()
    keys = sorted(expected)
    assert_array_equal(np.array([got[k] for k in keys], np.float32).view(np.uint32),
                       np.array([expected[k] for k in keys], np.float32).view(np.uint32))


def rewrite_npz(src, dst, **changes):
    """Copy the .npz `src` to `dst` with entries replaced (None deletes one)."""
    with np.load(src, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    for k, v in changes.items():
        if v is None:
            arrays.pop(k)
        else:
            arrays[k] = v
    np.savez_compressed(dst, **arrays)
    return dst


def assert_same_leaves(a, b):
    """Every leaf of two trees: same center, size and log-odds."""
    la, lb = a.leaves(), b.leaves()
    order_a = np.lexsort((la.sizes, *la.centers.T))
    order_b = np.lexsort((lb.sizes, *lb.centers.T))
    assert len(la.sizes) == len(lb.sizes)
    assert_array_equal(la.centers[order_a], lb.centers[order_b])
    assert_array_equal(la.sizes[order_a], lb.sizes[order_b])
    assert_array_equal(la.log_odds[order_a], lb.log_odds[order_b])


def room_sequence(rng, n_scans=8, n_points=600):
    """A box room scanned from nearby poses, then a new obstacle in its free space."""
    scans = []
    for k in range(n_scans):
        origin = np.array([0.0, 0.0, 0.5]) + rng.uniform(-0.15, 0.15, 3)
        d = rng.normal(size=(n_points, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        # distance to the walls of a 4 x 4 x 2 m box around (0, 0, 1)
        t = np.min(np.where(d > 0, (np.array([2.0, 2.0, 2.0]) - origin) / np.where(d > 0, d, 1),
                            (np.array([-2.0, -2.0, 0.0]) - origin) / np.where(d < 0, d, -1)),
                   axis=1)
        points = origin + d * t[:, None]
        if k == n_scans - 1:            # something appears where space was free
            points[:80] = origin + d[:80] * rng.uniform(0.3, 1.0, (80, 1))
        scans.append((points, origin))
    return scans


def build_octree(scans, resolution, **kwargs):
    """Insert `scans` in order; the method is "plain" unless `kwargs` name one."""
    kwargs.setdefault("method", "plain")
    m = OccupancyOctree(resolution)
    for points, origin in scans:
        m.insert_scan(points, origin, **kwargs)
    return m


KNN_PARAMS = dict(k=3, p_u=0.9, p_l=0.3, p_m=0.2, p_m_out=0.4, p_min=0.05, p_max=0.95)


def noisy_scans(rng, n_scans=3, n_wall=40, n_speckle=8, n_far=8):
    """A wall at x = 2 with depth noise, speckle between sensor and wall, far points."""
    scans = []
    for _ in range(n_scans):
        origin = rng.uniform(-0.3, 0.3, 3)
        wall = np.column_stack([2.0 + 0.05 * rng.standard_normal(n_wall),
                                rng.uniform(-1, 1, (n_wall, 2))])
        speckle = origin + rng.uniform(0.2, 0.9, (n_speckle, 1)) * (wall[:n_speckle] - origin)
        far = origin + rng.normal(size=(n_far, 3)) * 0 + np.column_stack(
            [np.full(n_far, 6.0), rng.uniform(-2, 2, (n_far, 2))])
        scans.append((np.vstack([wall, speckle, far]), origin))
    return scans


def build_knn(scans, resolution=0.2, method="plain", **params):
    m = KNNMap(resolution, max_range=3.0, **{**KNN_PARAMS, **params})
    for points, origin in scans:
        m.insert_scan(points, origin, method=method)
    return m
