"""Stamps per cell and decay (dynamic scenes): ``insert_scan(stamp=)``, ``decay``."""

import pickle

import numpy as np
import pytest

from occgp import OccupancyOctree

RES = 0.1


def box_scan(boxes, *, n_az=160, n_el=90, origin=(0.0, 0.0, 0.0)):
    """Rays from `origin` over a sphere patch to the nearest hit on the inside of a
    6 x 6 x 3 m room (centered on the origin) or on the outside of axis-aligned `boxes`."""
    origin = np.asarray(origin, dtype=float)
    az, el = np.meshgrid(np.linspace(-np.pi, np.pi, n_az, endpoint=False),
                         np.linspace(-1.2, 1.2, n_el))
    d = np.column_stack([(np.cos(el) * np.cos(az)).ravel(), (np.cos(el) * np.sin(az)).ravel(),
                         np.sin(el).ravel()])
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d
        # inside of the room: the nearest exit
        room = np.array([[-3.0, -3.0, -1.5], [3.0, 3.0, 1.5]]) - 1e-3
        t = np.min(np.maximum((room[0] - origin) * inv, (room[1] - origin) * inv), axis=1)
        for lo, hi in boxes:
            t0 = (np.asarray(lo) - origin) * inv
            t1 = (np.asarray(hi) - origin) * inv
            near = np.max(np.minimum(t0, t1), axis=1)
            far = np.min(np.maximum(t0, t1), axis=1)
            hit = (near <= far) & (near > 0)
            t = np.where(hit & (near < t), near + 1e-3, t)
    return origin + d * t[:, None]


def dense_cells(tree, lo=(-3.0, -3.0, -1.5), hi=(3.0, 3.0, 1.5)):
    """The centers of every finest cell of the room."""
    axes = [np.arange(a + RES / 2, b, RES) for a, b in zip(lo, hi)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


BOX_A = ([1.95, -0.55, -0.55], [2.45, 0.55, 0.55])      # the box before it moves
BOX_B = ([1.25, -0.25, -0.3], [1.45, 0.25, 0.05])       # after: nearer, hiding part of A


def moving_box_maps(decay: bool):
    """Five scans of the room with box A, then fifteen with box B; with `decay`, a
    ``decay(now, max_age=2.5)`` after each scan."""
    tree = OccupancyOctree(RES)
    for t in range(20):
        scan = box_scan([BOX_A] if t < 5 else [BOX_B])
        tree.insert_scan(scan, [0.0, 0.0, 0.0], stamp=float(t))
        if decay:
            tree.decay(float(t), max_age=2.5)
    return tree


@pytest.mark.slow
def test_moving_box_clears_by_rays_and_by_decay_and_nothing_else_changes():
    kept, decayed = moving_box_maps(False), moving_box_maps(True)
    cells = dense_cells(kept)
    before = OccupancyOctree(RES)
    for t in range(5):
        before.insert_scan(box_scan([BOX_A]), [0.0, 0.0, 0.0])
    in_a = np.all((cells > np.add(BOX_A[0], -RES)) & (cells < np.add(BOX_A[1], RES)), axis=1)
    was_box = before.is_occupied(cells) & in_a
    assert was_box.sum() > 50
    l_kept, l_decayed = kept.log_odds(cells), decayed.log_odds(cells)
    occ_kept, unknown_kept = kept.is_occupied(cells, return_unknown=True)
    occ_dec, unknown_dec = decayed.is_occupied(cells, return_unknown=True)
    # every cell the box left is free in the decayed map ...
    assert not occ_dec[was_box].any() and not unknown_dec[was_box].any()
    # ... some by ray clearing (free without decay too), some only by decay (hidden by B)
    by_rays = was_box & ~occ_kept
    by_decay = was_box & occ_kept
    assert by_rays.sum() > 20 and by_decay.sum() > 20
    assert np.array_equal(l_kept[by_rays], l_decayed[by_rays])
    # nothing else changed: every other cell holds the same log-odds, bit for bit
    other = ~by_decay
    assert np.array_equal(unknown_kept, unknown_dec)
    assert np.array_equal(l_kept[other], l_decayed[other], equal_nan=True)
    # box B, observed in every scan since it appeared, stays occupied
    in_b = np.all((cells > np.add(BOX_B[0], -RES)) & (cells < np.add(BOX_B[1], RES)), axis=1)
    assert occ_dec[in_b].sum() == occ_kept[in_b].sum() > 10


def _leaves(tree):
    lv = tree.leaves()
    order = np.lexsort(lv.centers.T)
    return lv.centers[order], lv.sizes[order], lv.log_odds[order]


@pytest.mark.slow
@pytest.mark.parametrize("method", ["plain", "culling", "superray", "superray+culling", "auto"])
@pytest.mark.parametrize("mode", ["scan", "ray"])
def test_stamped_insert_gives_the_same_map_and_stamps_every_updated_cell(method, mode):
    scans = [box_scan([BOX_A], n_az=60, n_el=30), box_scan([BOX_B], n_az=60, n_el=30)]
    plain, tracked = OccupancyOctree(RES), OccupancyOctree(RES)
    stamped = OccupancyOctree(RES, n_jobs=2)
    tracked.track_changes = True
    for t, scan in enumerate(scans):
        plain.insert_scan(scan, [0, 0, 0], mode=mode, method=method)
        stamped.insert_scan(scan, [0, 0, 0], mode=mode, method=method, stamp=10.0 + t)
        if t == 0:   # on an empty map every updated cell is new: the changes are the cells
            tracked.insert_scan(scan, [0, 0, 0], mode=mode, method="plain")
            first = tracked.changed_cells().keys
    for a, b in zip(_leaves(plain), _leaves(stamped)):
        assert np.array_equal(a, b)
    s = stamped.stamps()
    second = OccupancyOctree(RES)
    second.track_changes = True
    second.insert_scan(scans[1], [0, 0, 0], mode=mode, method="plain")
    newest = {tuple(k) for k in second.changed_cells().keys}
    expected = {tuple(k): (11.0 if tuple(k) in newest else 10.0) for k in first}
    expected.update({k: 11.0 for k in newest})
    assert {tuple(k): v for k, v in zip(s.keys, s.stamps)} == expected
    assert np.array_equal(stamped.stamp_at(s.centers), s.stamps)


def test_decay_follows_degrade_outdated_nodes():
    m = OccupancyOctree(RES)
    occupied = [[0.05, 0.05, 0.05], [0.15, 0.05, 0.05]]
    m.set_cells(occupied, [3.0, 0.3], stamp=0.0)
    m.set_cells([[0.25, 0.05, 0.05]], [-1.0], stamp=0.0)      # free: left alone
    m.set_cells([[0.35, 0.05, 0.05]], [2.0], stamp=9.0)       # recent: left alone
    m.set_cells([[0.45, 0.05, 0.05]], [2.0])                  # never stamped: left alone
    pts = [[0.05, 0.05, 0.05], [0.15, 0.05, 0.05], [0.25, 0.05, 0.05],
           [0.35, 0.05, 0.05], [0.45, 0.05, 0.05]]
    miss = np.float32(np.log(0.4 / 0.6))
    assert m.decay(10.0, max_age=10.0) == 0                   # strictly older than max_age
    assert m.decay(10.0, max_age=5.0) == 2
    expected = np.float32([3.0 + miss, 0.3 + miss, -1.0, 2.0, 2.0])
    assert np.array_equal(m.log_odds(pts), expected.astype(np.float64))
    assert m.decay(10.0, max_age=5.0) == 1                    # the second is free now
    expected[0] = np.float32(expected[0] + miss)
    assert np.array_equal(m.log_odds(pts), expected.astype(np.float64))
    assert m.stamp_at(pts[:2]).tolist() == [0.0, 0.0]         # stamps are kept
    # a fresh observation refreshes the stamp and stops the decay
    m.update_cells(pts[:1], occupied=True, stamp=12.0)
    assert m.decay(14.0, max_age=5.0) == 0


def test_decay_clamps_and_reaches_free():
    m = OccupancyOctree(RES, clamping_min=0.3)
    m.set_cells([[0.05, 0.05, 0.05]], [3.5], stamp=0.0)
    for _ in range(30):
        m.decay(100.0, max_age=1.0)
    value = m.log_odds([[0.05, 0.05, 0.05]])[0]
    assert value < 0 and not m.is_occupied([[0.05, 0.05, 0.05]])[0]
    assert value >= np.float32(np.log(0.3 / 0.7)) - 1e-6


def test_half_life_decay_composes():
    pts = [[0.05, 0.05, 0.05], [0.15, 0.05, 0.05], [0.25, 0.05, 0.05]]
    once, twice = OccupancyOctree(RES), OccupancyOctree(RES)
    for m in (once, twice):
        m.set_cells(pts, [3.0, -1.5, 1.0], stamp=0.0)
        m.set_cells(pts[2:], [1.0], stamp=4.0)
    assert once.decay(6.0, half_life=2.0) == 3
    twice.decay(3.0, half_life=2.0)
    twice.decay(6.0, half_life=2.0)
    expected = [3.0 / 8, -1.5 / 8, 1.0 / 2]
    np.testing.assert_allclose(once.log_odds(pts), expected, rtol=1e-6)
    np.testing.assert_allclose(twice.log_odds(pts), expected, rtol=1e-6)
    assert once.decay(6.0, half_life=2.0) == 0                 # no time has passed


def test_deleted_cells_lose_their_stamps():
    m = OccupancyOctree(RES).set_cells([[0.05, 0.05, 0.05], [1.05, 0.05, 0.05]], 2.0, stamp=0.0)
    m.delete_cells([[1.05, 0.05, 0.05]])
    assert len(m.stamps().keys) == 2
    assert m.decay(5.0, max_age=1.0) == 1
    assert m.stamps().keys.tolist() == m.coord_to_key([[0.05, 0.05, 0.05]]).tolist()
    m.clear()
    assert len(m.stamps().keys) == 0


@pytest.mark.parametrize("format", ["ot", "bt"])
def test_stamps_travel_with_files_and_pickles(tmp_path, format):
    m = OccupancyOctree(RES).insert_scan(box_scan([BOX_A], n_az=40, n_el=20), [0, 0, 0],
                                         stamp=3.5)
    m.set_cells([[0.05, 0.05, 0.05]], 1.0, stamp=7.25)
    m.decay(8.0, half_life=10.0)
    path = tmp_path / f"map.{format}"
    m.save(path)
    for back in (OccupancyOctree.load(path), pickle.loads(pickle.dumps(m))):
        a, b = m.stamps(), back.stamps()
        assert np.array_equal(a.keys, b.keys) and np.array_equal(a.stamps, b.stamps)
        assert back._half_life_at == 8.0
    # liboctomap's part of the file is the map's own: without the block it reads the same
    data = path.read_bytes()
    cut = data.index(b"# occgp stamps v1\n")
    plain = OccupancyOctree.from_bytes(data[:cut])
    assert len(plain.stamps().keys) == 0
    assert plain.to_bytes(format) == m.clear_stamps().to_bytes(format)


def test_a_corrupt_stamps_block_is_refused():
    m = OccupancyOctree(RES).set_cells([[0.05, 0.05, 0.05]], 1.0, stamp=1.0)
    data = m.to_bytes()
    with pytest.raises(ValueError, match="corrupt stamps block"):
        OccupancyOctree.from_bytes(data[:-3])
    with pytest.raises(ValueError, match="truncated stamps block"):
        OccupancyOctree.from_bytes(data[:data.index(b"# occgp stamps v1\n") + 20])
    bad = bytearray(data)
    bad[-8:] = np.float64(np.inf).tobytes()
    with pytest.raises(ValueError, match="non-finite stamp"):
        OccupancyOctree.from_bytes(bytes(bad))


@pytest.mark.parametrize("call, match", [
    (lambda m: m.insert_scan([[1.0, 0, 0]], [0, 0, 0], stamp=np.nan), "stamp"),
    (lambda m: m.insert_scan([[1.0, 0, 0]], [0, 0, 0], stamp="1"), "stamp"),
    (lambda m: m.update_cells([[1.0, 0, 0]], 1.0, stamp=np.inf), "stamp"),
    (lambda m: m.decay(np.nan, max_age=1.0), "now"),
    (lambda m: m.decay(1.0), "exactly one of max_age and half_life"),
    (lambda m: m.decay(1.0, max_age=1.0, half_life=1.0), "exactly one"),
    (lambda m: m.decay(1.0, max_age=-1.0), "max_age"),
    (lambda m: m.decay(1.0, half_life=0.0), "half_life"),
])
def test_bad_stamps_change_nothing(call, match):
    m = OccupancyOctree(RES).insert_scan([[0.5, 0, 0]], [0, 0, 0], stamp=0.0)
    before, stamps = m.to_bytes(), m.stamps()
    with pytest.raises((ValueError, TypeError), match=match):
        call(m)
    assert m.to_bytes() == before
    assert np.array_equal(m.stamps().stamps, stamps.stamps)
