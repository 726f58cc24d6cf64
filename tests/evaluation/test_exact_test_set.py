"""exact_test_set / cells_in_view: ground truth over the cells the scans could see."""

import numpy as np
import pytest

from occgp.datasets import LaserScan2D, Scan, room_2d, structured_room
from occgp.evaluation import TestSet, cell_labels, cells_in_view, exact_labels, exact_test_set


@pytest.fixture(scope="module")
def room():
    return room_2d()


def _one_beam_scan(origin, heading, fov=np.pi / 2, n_beams=9, max_range=8.0):
    angles = np.linspace(-fov / 2, fov / 2, n_beams)
    return LaserScan2D(np.asarray(origin, float), heading, angles, np.full(n_beams, max_range),
                       np.zeros(n_beams, dtype=bool), max_range)


def test_cells_in_view_need_range_field_of_view_and_line_of_sight(room):
    scan = _one_beam_scan([0.0, -0.5], 0.0)             # looking along +x from the corridor
    cells = np.array([
        [2.0, -0.5],     # ahead, 2 m: in view
        [-2.0, -0.5],    # behind the sensor: outside the 90-degree field of view
        [9.5, -0.5],     # ahead but 9.5 m away: beyond max_range
        [0.0, -0.5],     # the sensor's own cell
    ])
    assert cells_in_view(room, cells, 0.1, [scan], max_range=8.0).tolist() == [
        True, False, False, True]
    # the disc at (6, -0.5), radius 0.5: its near face is seen, its far side is not
    assert cells_in_view(room, [[5.55, -0.5], [6.45, -0.5], [7.0, -0.5]], 0.1, [scan],
                         max_range=8.0).tolist() == [True, False, False]


def test_cells_deep_in_a_wall_are_not_in_view(room):
    scan = _one_beam_scan([9.0, -0.5], 0.0)               # facing the +x wall, 2 m away
    # the wall is x in [11, 11.2]: the cell on its face is seen, the one inside is not
    got = cells_in_view(room, [[11.025, -0.5], [11.125, -0.5]], 0.05, [scan], max_range=8.0)
    assert got.tolist() == [True, False]


def test_exact_test_set_labels_by_the_closed_cell_rule_and_balances(room):
    scans = room.scan(n_poses=6)
    full = exact_test_set(room, 0.2, scans, max_range=8.0, balance=False)
    assert isinstance(full, TestSet) and full.points.shape[1] == 2
    assert 0 < full.labels.mean() < 0.5                  # free cells outnumber occupied ones
    lifted = np.column_stack([full.points, np.zeros(len(full.points))])

    class Lifted:
        def occupancy(self, p):
            return room.occupancy(p[:, :2])

    np.testing.assert_array_equal(full.labels, cell_labels(Lifted(), lifted, 0.2))
    assert cells_in_view(room, full.points, 0.2, scans, max_range=8.0).all()
    balanced = exact_test_set(room, 0.2, scans, max_range=8.0, seed=3)
    n_occ = int(full.labels.sum())
    assert balanced.labels.sum() == n_occ and len(balanced.labels) == 2 * n_occ
    # every occupied cell kept; the free ones a seeded subset of the full set's
    full_rows = {tuple(p) for p in full.points}
    assert all(tuple(p) in full_rows for p in balanced.points)
    again = exact_test_set(room, 0.2, scans, max_range=8.0, seed=3)
    np.testing.assert_array_equal(again.points, balanced.points)


def test_exact_test_set_in_3d_keeps_cells_of_the_scans_hits():
    scene = structured_room()
    scans = scene.scan(n_poses=1, scans_per_pose=3, n_points=300)
    test = exact_test_set(scene, 0.5, scans, max_range=8.0, balance=False)
    assert test.points.shape[1] == 3 and test.labels.any() and not test.labels.all()
    # the cell of every return is in view and occupied
    hits = np.vstack([s.points for s in scans])
    cells = (np.floor(hits / 0.5) + 0.5) * 0.5
    assert cells_in_view(scene, cells, 0.5, scans, max_range=8.0).all()
    # the floor below the scanners' lowest ray (elevation 0 from 0.1 m) is never seen
    assert not (test.points[:, 2] < 0).any()


@pytest.mark.parametrize("kwargs, exc, match", [
    ({"resolution": 0.0}, ValueError, "resolution"),
    ({"max_range": -1.0}, ValueError, "max_range"),
    ({"scans": []}, ValueError, "at least one scan"),
    ({"scans": [3.0]}, TypeError, r"scans\[0\] must be a \(points, origin\) pair"),
    ({"scans": [Scan(np.ones((4, 3)), np.zeros(3))]}, ValueError,
     r"scans\[0\]\.origin must have shape \(2,\)"),
    ({"scans": [(np.zeros((3, 2)), np.zeros(2))]}, ValueError, r"scans\[0\] holds no ray"),
    ({"balance": 1}, TypeError, "balance must be a bool, got int"),
    ({"resolution": 1e-6}, ValueError, "the grid would hold .* points"),
    ({"seed": -1}, ValueError, "seed must be a non-negative int"),
    ({"samples": 0}, ValueError, "samples"),
    ({"bbox": ([0.0, 0.0], [-1.0, 1.0])}, ValueError, "bbox must have min <= max"),
    ({"bbox": ([0.0, 0.0], [1.0, 1.0], [2.0, 2.0])}, ValueError,
     r"bbox must be a \(min, max\) pair, got length 3"),
    ({"bbox": ([0.0], [1.0])}, ValueError, "bbox must be 2D or 3D corners, got 1"),
])
def test_exact_test_set_rejects_bad_input(room, kwargs, exc, match):
    args = {"resolution": 0.2, "scans": room.scan(n_poses=2), "max_range": 8.0, **kwargs}
    with pytest.raises(exc, match=match):
        exact_test_set(room, args.pop("resolution"), args.pop("scans"), **args)


def test_exact_test_set_needs_both_classes(room):
    scan = _one_beam_scan([0.0, -0.5], 0.0, max_range=1.0)   # 1 m of free corridor
    with pytest.raises(ValueError, match="0 occupied .* a test set needs both"):
        exact_test_set(room, 0.2, [scan], max_range=1.0)


def test_exact_test_set_rejects_a_scene_without_ray_casting():
    class Flat:
        bounds = (np.zeros(2), np.ones(2))

        def occupancy(self, points):
            return np.zeros(len(points), dtype=bool)

    with pytest.raises(TypeError, match="scene must have occupancy, ray_cast, bounds .* "
                                        "Flat lacks ray_cast"):
        exact_test_set(Flat(), 0.2, room_2d().scan(n_poses=1), max_range=8.0)
    with pytest.raises(TypeError, match="Flat lacks ray_cast"):
        cells_in_view(Flat(), [[0.5, 0.5]], 0.2, room_2d().scan(n_poses=1), max_range=8.0)


def test_cells_in_view_of_far_cells_is_false(room):
    scans = room.scan(n_poses=1)
    with np.errstate(all="raise"):
        got = cells_in_view(room, [[1e30, 1e30], [-1e30, 0.0]], 0.1, scans, max_range=8.0)
    assert got.tolist() == [False, False]


def test_cells_in_view_rejects_bad_centers(room):
    with pytest.raises(ValueError, match=r"centers must have shape \(n_points, 3\)"):
        cells_in_view(room, np.zeros((4, 5)), 0.1, room.scan(n_poses=1), max_range=8.0)


def test_the_old_keyword_centres_still_works_with_a_warning(room):
    scans = room.scan(n_poses=1)
    cells = [scans[0].origin, [30.0, 0.0]]
    want = cells_in_view(room, cells, 0.1, scans, max_range=8.0)
    with pytest.warns(DeprecationWarning, match=r"cells_in_view: .*'centres' is deprecated"
                      r".*use 'centers'"):
        got = cells_in_view(room, centres=cells, resolution=0.1, scans=scans, max_range=8.0)
    assert got.tolist() == want.tolist()
    labels = exact_labels(room, cells, 0.1)
    with pytest.warns(DeprecationWarning, match="exact_labels: .*use 'centers'"):
        assert exact_labels(room, centres=cells, resolution=0.1).tolist() == labels.tolist()
    cells3 = [[0.05, 0.05, 0.05], [30.0, 0.0, 0.05]]
    with pytest.warns(DeprecationWarning, match="cell_labels: .*use 'centers'"):
        old = cell_labels(structured_room(), centres=cells3, resolution=0.1)
    assert old.tolist() == cell_labels(structured_room(), cells3, 0.1).tolist()
    with pytest.raises(TypeError, match="got both 'centres' .* and 'centers'"), \
            pytest.warns(DeprecationWarning):
        exact_labels(room, centers=cells, centres=cells, resolution=0.1)
