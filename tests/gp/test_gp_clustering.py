"""Clustering of hits and beams for the mixture of GP experts (occgp.gp._clustering, _beams)."""

import warnings

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from occgp import _linetrack
from occgp.gp import Matern32, SquaredExponential, integral_kernel
from occgp.gp._beams import assign_beams, merge_small_clusters
from occgp.gp._clustering import DirichletProcessClustering, segment_distance
from occgp.gp._lines import LineTracking
from occgp.gp._planes import PlaneClustering


# ------------------------------------------------------------------ hand-made scans
def _cross(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def scan(walls, origin, n_beams=90, fov=2 * np.pi, heading=0.0, max_range=20.0):
    """Hits of a planar laser at `origin` on the segments `walls` (exact ray casting)."""
    origin = np.asarray(origin, dtype=float)
    angles = heading + np.linspace(-fov / 2, fov / 2, n_beams, endpoint=fov < 2 * np.pi)
    d = np.column_stack([np.cos(angles), np.sin(angles)])
    best = np.full(n_beams, np.inf)
    for p, q in walls:
        p, q = np.asarray(p, dtype=float), np.asarray(q, dtype=float)
        e, w = q - p, p - origin
        den = _cross(d, e[None])
        ok = np.abs(den) > 1e-12
        safe = np.where(ok, den, 1.0)
        t, s = _cross(w[None], e[None]) / safe, _cross(w[None], d) / safe
        hit = ok & (t > 0) & (s >= 0) & (s <= 1) & (t < best)
        best = np.where(hit, t, best)
    keep = best < max_range
    hits = origin + best[keep, None] * d[keep]
    return hits, np.repeat(origin[None], len(hits), axis=0)


def scans(walls, origins, **kw):
    parts = [scan(walls, o, **kw) for o in origins]
    return np.vstack([p[0] for p in parts]), np.vstack([p[1] for p in parts])


BOX = [((-1, -1), (1, -1)), ((1, -1), (1, 1)), ((1, 1), (-1, 1)), ((-1, 1), (-1, -1))]
CORNERS = [(-3, -3), (3, -3), (3, 3), (-3, 3)]


def _face(hits):
    """Face of the box of each hit: 0 bottom, 1 right, 2 top, 3 left (-1: a corner)."""
    x, y = hits.T
    face = np.select([np.isclose(y, -1), np.isclose(x, 1), np.isclose(y, 1), np.isclose(x, -1)],
                     [0, 1, 2, 3], -1)
    face[(np.abs(np.abs(x) - 1) < 0.15) & (np.abs(np.abs(y) - 1) < 0.15)] = -1
    return face


def _one_label_per_group(labels, groups):
    """Each group (>= 0) has one label, and different groups different labels."""
    pairs = {(g, l) for g, l in zip(groups, labels) if g >= 0}
    by_group = {}
    for g, l in pairs:
        by_group.setdefault(g, set()).add(l)
    assert all(len(v) == 1 for v in by_group.values()), by_group
    firsts = [next(iter(v)) for v in by_group.values()]
    assert len(set(firsts)) == len(firsts), by_group


# ======================================================================= line tracking
def test_compiled_line_tracking_splits_at_distance_and_gap():
    pts = np.array([[0.0, 0], [1, 0], [2, 0], [3, 0.5],   # off the line: new line
                    [3, 1.5], [3, 2.5], [3, 9.0],          # gap: new line
                    [5, 5], [6, 6]])                       # second scan
    line = np.empty(len(pts), dtype=np.intp)
    n = _linetrack.track_lines(pts, np.array([0, 7, 9], dtype=np.intp), 0.1, 2.0, line)
    assert n == 4
    assert_array_equal(line, [0, 0, 0, 1, 1, 1, 2, 3, 3])


def test_two_walls_at_right_angles_give_two_lines():
    hits, origins = scan([((-4, 2), (2, 2)), ((2, 2), (2, -4))], (0, 0), n_beams=60)
    lt = LineTracking().fit(hits, origins)
    assert lt.n_clusters_ == 2
    on_top = np.isclose(hits[:, 1], 2) & ~np.isclose(hits[:, 0], 2)
    on_side = np.isclose(hits[:, 0], 2) & ~np.isclose(hits[:, 1], 2)
    _one_label_per_group(lt.labels_, np.where(on_top, 0, np.where(on_side, 1, -1)))
    assert lt.labels_.dtype == np.int64 and lt.n_dims_ == 2
    d = lt.lines_.direction
    assert abs(d[0] @ d[1]) < np.sin(np.radians(2))


def test_box_seen_from_four_poses_gives_one_cluster_per_face():
    hits, origins = scans(BOX, CORNERS, n_beams=180)
    lt = LineTracking().fit(hits, origins)
    assert lt.n_lines_ >= 8            # two faces per pose, merged across poses
    assert lt.n_clusters_ == 4
    _one_label_per_group(lt.labels_, _face(hits))
    assert lt.lines_.n_points.sum() == len(hits)


def test_wall_seen_from_five_poses_is_one_cluster():
    hits, origins = scans([((-5, 2), (5, 2))], [(x, 0.0) for x in np.linspace(-4, 4, 5)],
                          n_beams=40)
    lt = LineTracking().fit(hits, origins)
    assert lt.n_clusters_ == 1 and lt.n_lines_ >= 5
    c, d, (t0, t1), n = (a[0] for a in lt.lines_)
    assert abs(d[1]) < 1e-12 and c[1] == pytest.approx(2.0)
    assert c[0] + t0 * d[0] == pytest.approx(hits[:, 0].min() if d[0] > 0 else hits[:, 0].max())
    assert n == len(hits)


def test_gap_bigger_than_gap_threshold_splits_a_wall():
    walls = [((-6, 2), (-1.5, 2)), ((1.5, 2), (6, 2))]       # a 3 m doorway
    hits, origins = scans(walls, [(-3, 0), (0, 0), (3, 0)], n_beams=120)
    assert LineTracking(gap_threshold=2.0).fit(hits, origins).n_clusters_ == 2
    assert LineTracking(gap_threshold=3.5).fit(hits, origins).n_clusters_ == 1


def test_scan_across_the_back_is_not_split():
    # a full turn whose wall lies behind the sensor, across the +-pi bearing
    hits, origins = scan([((-2, -3), (-2, 3))], (0, 0), n_beams=90)
    lt = LineTracking().fit(hits, origins)
    assert lt.n_clusters_ == 1 and lt.n_lines_ == 1


def test_lone_corner_hit_does_not_bridge_two_walls():
    walls = [((0, 0), (4, 0)), ((0, 0), (0, 4))]
    hits, origins = scans(walls, [(2, 2), (3, 1)], n_beams=60)
    corner = np.array([[0.0, 0.0]])
    hits = np.vstack([hits, corner])
    origins = np.vstack([origins, [[1.0, 1.0]]])
    lt = LineTracking().fit(hits, origins)
    assert lt.n_clusters_ == 2


@pytest.mark.parametrize("hits", [[[1.0, 1.0]], [[1.0, 1.0], [9.0, 9.0]]])
def test_line_tracking_lone_hits_are_clusters(hits):
    # a lone hit far from every line is a cluster of its own (the tiny-cluster rule
    # of merge_small_clusters deals with it later)
    lt = LineTracking().fit(hits, np.zeros((len(hits), 2)))
    assert_array_equal(lt.labels_, np.arange(len(hits)))


def test_line_tracking_lone_far_hit_beside_a_wall():
    hits, origins = scan([((-5, 2), (5, 2))], (0, 0), n_beams=40)
    hits = np.vstack([hits, [[0.0, -15.0]]])
    origins = np.vstack([origins, [[0.0, 0.0]]])
    labels = LineTracking().fit_predict(hits, origins)
    assert len(set(labels[:-1])) == 1 and labels[-1] != labels[0]
    lt = LineTracking().fit(hits[:-1], origins[:-1])
    assert_array_equal(lt.partial_fit(hits[-1:] + [[0.0, -1.0]], [[0.0, 0.0]]), [1])


def test_line_tracking_partial_fit_keeps_old_labels_and_opens_new_ones():
    wall, far = ((-5, 2), (5, 2)), ((8, -5), (8, 5))
    h1, o1 = scans([wall], [(-3, 0), (0, 0)], n_beams=40)
    h2, o2 = scans([wall, far], [(3, 0)], n_beams=60)
    lt = LineTracking()
    first = lt.partial_fit(h1, o1)
    assert_array_equal(first, LineTracking().fit_predict(h1, o1))
    before = lt.labels_.copy()
    new = lt.partial_fit(h2, o2)
    assert_array_equal(lt.labels_[:len(h1)], before)
    assert_array_equal(lt.labels_, np.r_[before, new])
    on_wall = np.isclose(h2[:, 1], 2)
    assert set(new[on_wall]) == {0}
    assert set(new[~on_wall]) == {1} and lt.n_clusters_ == 2
    assert lt.lines_.n_points.tolist() == [np.sum(lt.labels_ == 0), np.sum(~on_wall)]


def test_line_tracking_box_streamed_pose_by_pose():
    lt = LineTracking()
    parts = [scan(BOX, o, n_beams=180) for o in CORNERS]
    for hits, origins in parts:
        lt.partial_fit(hits, origins)
    assert lt.n_clusters_ == 4
    _one_label_per_group(lt.labels_, _face(np.vstack([p[0] for p in parts])))


def test_line_tracking_partial_fit_short_line_joins_a_new_cluster():
    wall, far = ((-5, 2), (5, 2)), ((8, -5), (8, 5))
    lt = LineTracking().fit(*scans([wall], [(-3, 0), (0, 0)], n_beams=40))
    hits, origins = scans([wall, far], [(3, 0)], n_beams=60)
    hits = np.vstack([hits, [[8.05, 6.0]]])           # a lone hit beyond the new wall's end
    new = lt.partial_fit(hits, np.vstack([origins, [[3.0, 0.0]]]))
    assert new[-1] == 1 and set(new[np.isclose(hits[:, 0], 8)]) == {1}


@pytest.mark.parametrize("hits, match", [
    (np.zeros((4, 3)), r"hits must have shape \(n_hits, 2\) for line tracking, got \(4, 3\)"),
    (np.zeros((0, 2)), "at least one hit"),
    (np.array([[0.0, np.nan]] * 2), "hits must be finite"),
    (np.full((2, 2), 1e30), "within 1e\\+10 m"),
])
def test_line_tracking_rejects_bad_hits(hits, match):
    with pytest.raises(ValueError, match=match):
        LineTracking().fit(hits, np.zeros_like(hits))


def test_clusterers_reject_mismatched_origins_and_non_numbers():
    with pytest.raises(ValueError, match=r"origins must have one row per hit"):
        LineTracking().fit(np.zeros((3, 2)), np.zeros((2, 2)))
    with pytest.raises(TypeError, match="hits must hold real numbers"):
        DirichletProcessClustering().fit([["a", "b"]], [[0, 0]])


@pytest.mark.parametrize("params, error, match", [
    (dict(distance_threshold=0.0), ValueError, "distance_threshold must lie in"),
    (dict(gap_threshold=np.inf), ValueError, "gap_threshold must lie in"),
    (dict(merge_angle=95.0), ValueError, r"merge_angle must lie in \[0.0, 90.0\]"),
    (dict(merge_distance="1"), TypeError, "merge_distance must be a real number"),
    (dict(min_points=1), ValueError, "min_points must be an int >= 2, got 1"),
    (dict(min_points=2.5), TypeError, "min_points must be"),
])
def test_line_tracking_rejects_bad_params(params, error, match):
    with pytest.raises(error, match=match):
        LineTracking(**params).fit(np.zeros((2, 2)), np.ones((2, 2)))


def test_rejected_partial_fit_leaves_the_clusterer_unchanged():
    hits, origins = scans([((-5, 2), (5, 2))], [(0, 0)], n_beams=40)
    lt = LineTracking().fit(hits, origins)
    state = {k: v.copy() if isinstance(v, np.ndarray) else v for k, v in vars(lt).items()}
    with pytest.raises(ValueError, match="hits must be finite"):
        lt.partial_fit(np.array([[0.0, np.nan]]), np.zeros((1, 2)))
    assert_array_equal(lt.labels_, state["labels_"])
    assert lt.n_clusters_ == state["n_clusters_"]


# =================================================================== Dirichlet process
def _blobs(rng, centers=((0, 0), (6, 0), (0, 6)), n=60, sd=0.3):
    return np.vstack([rng.normal(c, sd, (n, len(c))) for c in centers])


def test_dirichlet_process_finds_three_blobs():
    hits = _blobs(np.random.default_rng(0))
    dp = DirichletProcessClustering(random_state=0)
    labels = dp.fit_predict(hits, np.zeros_like(hits))
    assert dp.n_clusters_ == 3 and labels.dtype == np.int64
    _one_label_per_group(labels, np.repeat([0, 1, 2], 60))
    assert_array_equal(labels[[0, 60, 120]], [0, 1, 2])       # order of first appearance
    assert dp.converged_


def test_dirichlet_process_is_deterministic_for_a_seed():
    hits = _blobs(np.random.default_rng(1), centers=((0, 0), (2, 0), (1, 2)), n=30, sd=0.6)
    a = DirichletProcessClustering(max_clusters=10, random_state=3).fit_predict(hits, hits)
    b = DirichletProcessClustering(max_clusters=10, random_state=3).fit_predict(hits, hits)
    assert_array_equal(a, b)
    assert_array_equal(np.unique(a), np.arange(a.max() + 1))


@pytest.mark.parametrize("dim", [1, 3])
def test_dirichlet_process_in_one_and_three_dimensions(dim):
    centers = [(0,) * dim, (8,) * dim]
    hits = _blobs(np.random.default_rng(2), centers=centers, n=40)
    dp = DirichletProcessClustering(random_state=0).fit(hits, np.zeros_like(hits))
    assert dp.n_clusters_ == 2 and dp.n_dims_ == dim


def test_dirichlet_process_single_hit_and_no_convergence_warning():
    dp = DirichletProcessClustering().fit([[1.0, 2.0]], [[0.0, 0.0]])
    assert_array_equal(dp.labels_, [0])
    hits = _blobs(np.random.default_rng(3))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        dp = DirichletProcessClustering(max_iter=1, random_state=0).fit(hits, hits)
    assert not dp.converged_


def test_dirichlet_process_partial_fit_joins_known_blobs_and_opens_new_ones():
    rng = np.random.default_rng(4)
    old = _blobs(rng)
    dp = DirichletProcessClustering(random_state=0)
    dp.partial_fit(old, np.zeros_like(old))
    before = dp.labels_.copy()
    near = rng.normal((6, 0), 0.1, (10, 2))
    far = rng.normal((30, 30), 0.3, (20, 2))
    new = dp.partial_fit(np.vstack([near, far]), np.zeros((30, 2)))
    assert_array_equal(dp.labels_[:len(old)], before)
    assert set(new[:10]) == {before[60]}
    assert set(new[10:]) == {3} and dp.n_clusters_ == 4 and len(dp.mixtures_) == 2


@pytest.mark.parametrize("params, error, match", [
    (dict(concentration=0.0), ValueError, "concentration must lie in"),
    (dict(max_clusters=0), ValueError, r"max_clusters must lie in \[1, 1000\], got 0"),
    (dict(covariance_type="round"), ValueError, "covariance_type must be one of"),
    (dict(max_iter=True), TypeError, "max_iter must be"),
    (dict(random_state="a"), TypeError, "random_state must be None, an int"),
    (dict(random_state=-1), ValueError, r"random_state must lie in \[0, 2\*\*32 - 1\]"),
    (dict(covariance_prior=-1.0), ValueError, "covariance_prior must lie in"),
    (dict(max_clusters=10 ** 6), ValueError, r"max_clusters must lie in \[1, 1000\]"),
    (dict(max_iter=10 ** 9), ValueError, r"max_iter must lie in \[1, 100000\]"),
    (dict(n_init=1000), ValueError, r"n_init must lie in \[1, 100\]"),
])
def test_dirichlet_process_rejects_bad_params(params, error, match):
    with pytest.raises(error, match=match):
        DirichletProcessClustering(**params).fit(np.zeros((3, 2)), np.zeros((3, 2)))


def test_dirichlet_process_rejects_bad_dimensions():
    with pytest.raises(ValueError, match=r"hits must have shape \(n_hits, D\) with D in 1..3"):
        DirichletProcessClustering().fit(np.zeros((3, 4)), np.zeros((3, 4)))
    dp = DirichletProcessClustering(random_state=0).fit(np.eye(3)[:, :2], np.zeros((3, 2)))
    with pytest.raises(ValueError, match=r"hits must have shape \(n_hits, 2\) \(the "
                                         r"dimension of the first fit\), got \(2, 3\)"):
        dp.partial_fit(np.zeros((2, 3)), np.zeros((2, 3)))


def test_dirichlet_process_covariance_prior_is_in_square_metres():
    hits = np.random.default_rng(9).uniform(0, 10, (50, 2))
    prior = DirichletProcessClustering(covariance_prior=2.0, max_clusters=5, random_state=0)
    model = prior.fit(hits, hits).mixtures_[0]
    scale = hits.std(axis=0).max()              # the fit's frame: hits over their spread
    np.testing.assert_allclose(model.covariance_prior_, 2.0 / scale ** 2 * np.eye(2))


# ==================================================================== plane clustering
def _corner(n=8):
    u, v = np.meshgrid(np.linspace(0.1, 1.5, n), np.linspace(0.1, 1.5, n))
    u, v, o = u.ravel(), v.ravel(), np.zeros(n * n)
    return np.vstack([np.column_stack([u, v, o]), np.column_stack([u, o, v]),
                      np.column_stack([o, u, v])])


def test_plane_clustering_finds_the_three_faces_of_a_box_corner():
    hits = _corner()
    pc = PlaneClustering(random_state=0).fit(hits, np.ones_like(hits))
    assert pc.n_clusters_ == 3 and pc.n_planes_ == 3
    _one_label_per_group(pc.labels_, np.repeat([0, 1, 2], 64))
    normals = np.abs(pc.planes_.normal)
    assert_array_equal(np.argmax(normals, axis=1), [2, 1, 0])
    assert pc.planes_.is_plane.all()


def test_plane_clustering_falls_back_to_the_dirichlet_process():
    hits = _blobs(np.random.default_rng(5), centers=((0, 0, 0), (5, 5, 5)), n=40)
    pc = PlaneClustering(random_state=0).fit(hits, np.zeros_like(hits))
    assert pc.n_planes_ == 0 and pc.n_clusters_ == 2
    _one_label_per_group(pc.labels_, np.repeat([0, 1], 40))


@pytest.fixture(scope="module")
def room_scans():
    from occgp.datasets import LidarSensor, simulate_scans, structured_room

    scene = structured_room(0)
    lo, _ = scene.interior_bounds
    poses = np.array([[2.5, 2.0, 1.0], [7.5, 2.0, 1.0], [2.5, 5.0, 1.0], [7.5, 5.0, 1.0]]) \
        + np.r_[lo[0], lo[1], 0.0]
    sensor = LidarSensor(n_horizontal=64, n_vertical=4, max_range=8.0)
    out = simulate_scans(scene, poses, sensor, seed=0, progress=False)
    hits = np.vstack([s.points for s in out])
    origins = np.vstack([np.repeat(s.origin[None], len(s.points), 0) for s in out])
    distance = np.stack([np.abs(s.signed_distance(hits)) for s in scene.solids], axis=1)
    owner = np.array(scene.labels)[np.argmin(distance, axis=1)]
    return hits, origins, owner, [len(s.points) for s in out]


def test_plane_clustering_on_the_structured_room(room_scans):
    hits, origins, owner, _ = room_scans
    pc = PlaneClustering(random_state=0).fit(hits, origins)
    # 862 hits: the floor and four walls (and the partition and table top) are
    # planes; the furniture's few hits per face go to the DP fallback. 19 clusters
    # with 7 planes at the defaults; a range leaves room for the fallback's
    # variational fit.
    assert 5 <= pc.n_planes_ <= 10 and 10 <= pc.n_clusters_ <= 30
    for surface in ["floor", "wall_-x", "wall_+x", "wall_-y", "wall_+y"]:
        labels = pc.labels_[owner == surface]
        main = np.bincount(labels).argmax()
        assert pc.planes_.is_plane[main]
        assert np.mean(labels == main) >= 0.9, surface


def test_plane_clustering_partial_fit_grows_the_floor(room_scans):
    hits, origins, owner, sizes = room_scans
    n2 = sizes[0] + sizes[1]
    pc = PlaneClustering(random_state=0)
    pc.partial_fit(hits[:n2], origins[:n2])
    before, k = pc.labels_.copy(), pc.n_clusters_
    floor = np.bincount(before[owner[:n2] == "floor"]).argmax()
    new = pc.partial_fit(hits[n2:], origins[n2:])
    assert_array_equal(pc.labels_[:n2], before)
    assert np.mean(new[owner[n2:] == "floor"] == floor) >= 0.6
    assert new.max() >= k and pc.n_clusters_ == new.max() + 1
    assert pc.planes_.n_points.sum() == len(hits)


@pytest.mark.parametrize("params, error, match", [
    (dict(angle_threshold=-1.0), ValueError, "angle_threshold must lie in"),
    (dict(n_neighbors=1), ValueError, r"n_neighbors must be an int in \[2, 100\], got 1"),
    (dict(n_neighbors=10 ** 9), ValueError, r"n_neighbors must be an int in \[2, 100\]"),
    (dict(min_region_size=0), ValueError, "min_region_size must be a positive int"),
    (dict(concentration=-2.0), ValueError, "concentration must lie in"),
    (dict(n_jobs=0), ValueError, "n_jobs must be None"),
])
def test_plane_clustering_rejects_bad_params(params, error, match):
    with pytest.raises(error, match=match):
        PlaneClustering(**params).fit(_corner(3), np.zeros((27, 3)))


def test_plane_clustering_needs_3d_hits():
    with pytest.raises(ValueError, match=r"hits must have shape \(n_hits, 3\) for plane"):
        PlaneClustering().fit(np.zeros((5, 2)), np.zeros((5, 2)))


# ====================================================================== beam assignment
def _similarity(kernel, a0, a1, b0, b1):
    """The paper's Eq. 11 similarity, by the public integral kernel."""
    K = integral_kernel(kernel, a0, a1, b0, b1)
    la = np.linalg.norm(np.asarray(a1) - a0, axis=1)
    lb = np.linalg.norm(np.asarray(b1) - b0, axis=1)
    return K / (np.where(la > 0, la, 1.0)[:, None] * np.where(lb > 0, lb, 1.0)[None])


def test_assign_beams_hand_checked_three_beams():
    # a long returning beam crossing the free beam's start, and a short one along it:
    # the raw integral favours the long one, the normalised similarity the short one
    hits = np.array([[0.0, 4.0], [1.0, 0.0]])
    starts = np.array([[0.0, -4.0], [0.0, 0.0], [0.0, 0.0]])
    ends = np.array([[0.0, 4.0], [1.0, 0.0], [3.0, 0.0]])
    kernel = SquaredExponential(1.0, 1.0)
    raw = integral_kernel(kernel, starts[2:], ends[2:], starts[:2], ends[:2])[0]
    sim = _similarity(kernel, starts[2:], ends[2:], starts[:2], ends[:2])[0]
    assert raw[0] > raw[1] and sim[1] > sim[0]
    assert_array_equal(assign_beams([7, 3], hits, starts, ends), [7, 3, 3])


def test_assign_beams_every_beam_assigned_and_returns_take_their_hit():
    rng = np.random.default_rng(6)
    hits = rng.uniform(-5, 5, (30, 2))
    labels = rng.integers(0, 4, 30)
    origin = np.zeros((30, 2))
    free_ends = rng.uniform(-8, 8, (20, 2))
    starts = np.vstack([origin, np.zeros((20, 2))])
    ends = np.vstack([hits, free_ends])
    out = assign_beams(labels, hits, starts, ends)
    assert out.dtype == np.int64 and out.shape == (50,) and (out >= 0).all()
    assert_array_equal(out[:30], labels)
    assert set(out[30:]) <= set(labels)


def test_assign_beams_coinciding_hits_take_the_first_label():
    hits = np.array([[1.0, 0.0], [1.0, 0.0], [-0.0, 2.0]])
    out = assign_beams([4, 9, 1], hits, np.zeros((2, 2)), [[1.0, 0.0], [0.0, 2.0]])
    assert_array_equal(out, [4, 1])


def test_assign_beams_free_beam_takes_the_cluster_beside_it():
    # cluster 0: beams to a wall at y = 3 around x = -4; cluster 1: around x = +4
    xs = np.linspace(-5, -3, 5)
    hits = np.vstack([np.column_stack([xs, np.full(5, 3.0)]),
                      np.column_stack([-xs, np.full(5, 3.0)])])
    labels = np.repeat([0, 1], 5)
    starts = np.zeros((12, 2))
    ends = np.vstack([hits, [[-4.2, 8.0], [4.5, 8.0]]])
    out = assign_beams(labels, hits, starts, ends)
    assert_array_equal(out[10:], [0, 1])


@pytest.mark.parametrize("kernel, quadrature", [
    (SquaredExponential(1.0, 1.0), None),
    (SquaredExponential(2.0, [0.6, 1.7]), None),
    (Matern32(1.0, 2.0), None),
    (SquaredExponential(1.0, 1.0), "simpson"),
])
def test_assign_beams_equals_the_brute_force_argmax(kernel, quadrature):
    rng = np.random.default_rng(7)
    origins = rng.uniform(0, 6, (5, 2))
    starts = np.repeat(origins, 8, axis=0)
    ang = rng.uniform(0, 2 * np.pi, 40)
    ends = starts + rng.uniform(0.0, 4.0, (40, 1)) * np.column_stack([np.cos(ang), np.sin(ang)])
    ends[[0, 10]] = starts[[0, 10]]                        # zero-length beams (points)
    returning = rng.random(40) < 0.6
    hits = ends[returning]
    labels = np.arange(len(hits))
    out = assign_beams(labels, hits, starts, ends, kernel=kernel, quadrature=quadrature)
    sim = _similarity(kernel, starts[~returning], ends[~returning], starts[returning],
                      ends[returning])
    assert_array_equal(out[~returning], np.argmax(sim, axis=1))
    assert_array_equal(out[returning], labels)
    assert_array_equal(assign_beams(labels, hits, starts, ends, kernel=kernel,
                                    quadrature=quadrature, n_jobs=2), out)


def test_assign_beams_far_free_beam_takes_the_nearest_returning_beam():
    hits = np.array([[1.0, 0.0], [0.0, 1.0]])
    starts = np.array([[0.0, 0.0], [0.0, 0.0], [0.0, 40.0]])      # 39 m from beam 1
    ends = np.array([[1.0, 0.0], [0.0, 1.0], [0.0, 45.0]])
    assert_array_equal(assign_beams([0, 1], hits, starts, ends), [0, 1, 1])


@pytest.mark.parametrize("dim", [1, 3])
def test_assign_beams_in_one_and_three_dimensions(dim):
    hits = np.eye(dim)[:1] * 2.0
    starts = np.zeros((2, dim))
    ends = np.vstack([hits, -np.eye(dim)[:1] * 3.0])
    assert_array_equal(assign_beams([5], hits, starts, ends), [5, 5])


def test_assign_beams_without_beams_or_without_returns():
    assert assign_beams([0], [[1.0, 1.0]], np.zeros((0, 2)), np.zeros((0, 2))).shape == (0,)
    with pytest.raises(ValueError, match="2 beams have no return .* and no beam has one"):
        assign_beams([0], [[1.0, 1.0]], np.zeros((2, 2)), np.ones((2, 2)) * 5)
    with pytest.raises(ValueError, match="no beam has one"):
        assign_beams(np.zeros(0, int), np.zeros((0, 2)), np.zeros((1, 2)), np.ones((1, 2)))


@pytest.mark.parametrize("call, error, match", [
    (lambda: assign_beams([0, 1], [[1.0, 0]], [[0, 0]], [[1.0, 0]]), ValueError,
     r"hit_labels must have shape \(1,\)"),
    (lambda: assign_beams([-1], [[1.0, 0]], [[0, 0]], [[1.0, 0]]), ValueError,
     "hit_labels must be non-negative"),
    (lambda: assign_beams([0.5], [[1.0, 0]], [[0, 0]], [[1.0, 0]]), TypeError,
     "hit_labels must hold integers, got dtype float64"),
    (lambda: assign_beams(["a"], [[1.0, 0]], [[0, 0]], [[1.0, 0]]), TypeError,
     "hit_labels must hold real numbers"),
    (lambda: assign_beams([0], [[1.0, 0]], [[0, 0, 0]], [[1.0, 0, 0]]), ValueError,
     r"segment_starts must have shape \(n_points, 2\)"),
    (lambda: assign_beams([0], [[1.0, 0]], [[0, 0]], [[np.inf, 0]]), ValueError,
     "segment_ends must be finite"),
    (lambda: assign_beams([0], [[1.0, 0]], [[0, 0]], [[1e30, 0]]), ValueError,
     "within 1e\\+10 length scales"),
    (lambda: assign_beams([0], [[1.0, 0]], [[0, 0]], [[1.0, 0]], kernel="se"), TypeError,
     "kernel must be one of occgp.gp's kernels"),
    (lambda: assign_beams([0], [[1.0, 0]], [[0, 0]], [[1.0, 0]], quadrature="gauss"),
     ValueError, "quadrature must be"),
    (lambda: assign_beams([0], np.zeros((1, 4)), [[0, 0]], [[1.0, 0]]), ValueError,
     r"hits must have shape \(n_hits, D\) with D in 1..3"),
    (lambda: assign_beams([0], [[1.0, 0]], [[0, 0]], [[1.0, 0]], n_jobs=0), ValueError,
     "n_jobs must be None"),
])
def test_assign_beams_rejects_bad_input(call, error, match):
    with pytest.raises(error, match=match):
        call()


# ================================================================ tiny-cluster merging
POINTS = np.array([[0, 0], [0, 1], [0, 2], [1, 1], [0, 3.5],
                   [0, 8], [0, 9], [0, 10], [1, 9]], dtype=float)
IS_HIT = np.array([True, True, True, False, True, True, True, True, False])


def test_merge_small_clusters_merges_a_one_hit_cluster_into_the_nearest():
    out = merge_small_clusters([0, 0, 0, 0, 1, 2, 2, 2, 2], POINTS, IS_HIT)
    assert_array_equal(out, [0, 0, 0, 0, 0, 1, 1, 1, 1])


def test_merge_small_clusters_merges_hits_only_and_beams_only_clusters():
    # kept: 0 (three hits and a beam) and 2 (likewise); 1 is a beam only, next to 0;
    # 5 is three hits and no beam, next to 2
    labels = [0, 0, 0, 0, 1, 5, 5, 5, 2, 2, 2, 2]
    points = np.array([[0, 0], [0, 1], [0, 2], [1, 1], [1, 3], [0, 8], [0, 9], [0, 10],
                       [0, 12], [0, 13], [0, 14], [1, 13]], dtype=float)
    is_hit = np.array([1, 1, 1, 0, 0, 1, 1, 1, 1, 1, 1, 0], dtype=bool)
    out = merge_small_clusters(labels, points, is_hit)
    assert_array_equal(out, [0, 0, 0, 0, 0, 1, 1, 1, 1, 1, 1, 1])


def test_merge_small_clusters_relabels_in_old_label_order_and_returns_a_new_array():
    labels = np.array([5, 5, 5, 5, 2, 2, 2, 2])
    is_hit = np.array([True, True, True, False] * 2)
    out = merge_small_clusters(labels, np.arange(16.0).reshape(8, 2), is_hit)
    assert_array_equal(out, [1, 1, 1, 1, 0, 0, 0, 0])
    same = np.array([0, 0, 0, 0, 1, 1, 1, 1])
    out = merge_small_clusters(same, np.arange(16.0).reshape(8, 2), is_hit)
    assert_array_equal(out, same) and out is not same


def test_merge_small_clusters_with_no_cluster_kept_gives_one_cluster():
    out = merge_small_clusters([3, 4, 4], np.zeros((3, 2)), [True, False, True])
    assert_array_equal(out, [0, 0, 0])


@pytest.mark.parametrize("args, error, match", [
    (([0, 1], np.zeros((3, 2)), [True, False]), ValueError, r"points must have shape \(2, D\)"),
    (([0, 1], np.zeros((2, 2)), [1, 0]), TypeError, "is_hit must hold booleans, got dtype int"),
    (([0, 1], np.zeros((2, 2)), [True]), ValueError, r"is_hit must have shape \(2,\)"),
    (([0, -1], np.zeros((2, 2)), [True, False]), ValueError, "labels must be non-negative"),
    (([[0, 1]], np.zeros((2, 2)), [True, False]), ValueError, r"labels must have shape \(n,\)"),
    (([0.0, 1.0], np.zeros((2, 2)), [True, False]), TypeError, "labels must hold integers"),
    (([0, 1], [[0, 0], [np.nan, 0]], [True, False]), ValueError, "points must be finite"),
    (([0, 1], np.zeros((2, 2)), [True, False], 0), ValueError, "min_hits must be a positive"),
])
def test_merge_small_clusters_rejects_bad_input(args, error, match):
    with pytest.raises(error, match=match):
        merge_small_clusters(*args)


def test_segment_distance_against_sampling():
    rng = np.random.default_rng(8)
    p0, p1, q0, q1 = (rng.normal(size=(60, 3)) for _ in range(4))
    p1[:10] = p0[:10]
    q1[5:15] = q0[5:15]
    d = segment_distance(p0, p1, q0, q1)
    u = np.linspace(0, 1, 101)[:, None, None]
    a = p0 + u * (p1 - p0)
    b = q0 + u * (q1 - q0)
    sampled = np.linalg.norm(a[:, None] - b[None], axis=-1).min(axis=(0, 1))
    assert (d <= sampled + 1e-12).all() and np.allclose(d, sampled, atol=0.05)


@pytest.mark.parametrize("make", [LineTracking, lambda: DirichletProcessClustering(random_state=0),
                                  lambda: PlaneClustering(random_state=0)])
def test_clusterers_pickle_and_continue_alike(make):
    import pickle

    rng = np.random.default_rng(10)
    model = make()
    dim = 3 if isinstance(model, PlaneClustering) else 2
    if dim == 2:
        hits, origins = scans(BOX, CORNERS[:2], n_beams=90)
        new, new_origins = scan(BOX, CORNERS[2], n_beams=90)
    else:
        hits = _corner(6)
        origins = np.ones_like(hits)
        new = _corner(6) + rng.normal(0, 0.001, hits.shape)
        new_origins = np.ones_like(new)
    model.fit(hits, origins)
    copy = pickle.loads(pickle.dumps(model))
    assert_array_equal(copy.partial_fit(new, new_origins), model.partial_fit(new, new_origins))
    assert_array_equal(copy.labels_, model.labels_)
