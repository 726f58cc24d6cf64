"""The occgp command: demo writes its table and files, map builds a map from scan files."""

import io
import re

import numpy as np
import pytest

from occgp import AKIMap, BGKMap, KNNMap, OccupancyOctree
from occgp.cli import _noisy_scans, demo, main, map_scans, mapping_methods, noisy_mapping_methods
from occgp.datasets import Scan, read_scans, structured_room, write_pcd

KERNEL_METHODS = {"BGK", "AKIMap", "AKIMap (published)"}
NOISY_METHODS = {"octree (scan), noisy", "k-NN, noisy"}


def test_demo_prints_table_and_writes_files(tmp_path):
    out = io.StringIO()
    rows = demo(tmp_path, resolution=0.2, progress=False, out=out)
    text = out.getvalue()
    assert "octree (scan)" in text and "octree (ray)" in text and "AUC" in text
    assert [r.method for r in rows] == ["octree (scan)", "octree (ray)", "grid (scan)",
                                        "grid (ray)", "BGK", "AKIMap", "AKIMap (published)",
                                        "k-NN", "octree (scan), noisy", "k-NN, noisy"]
    assert all(name in text for name in KERNEL_METHODS | NOISY_METHODS | {"k-NN"})
    # the noisy rows are a second table, after the first, on the same test points
    assert text.index("noisy scans:") > text.index("k-NN ")
    assert text.index("noisy scans:") < text.index("octree (scan), noisy")
    assert len({r.n_test for r in rows}) == 1 and len({r.n_points for r in rows}) == 1
    by_name = {r.method: r for r in rows}   # the grid is the octree cell for cell
    assert by_name["grid (scan)"].auc == by_name["octree (scan)"].auc
    assert by_name["grid (ray)"].mse == by_name["octree (ray)"].mse
    assert all(0.5 < r.auc <= 1 and r.seconds > 0 for r in rows)
    for name in ("map.bt", "slice.png", "roc.png"):
        assert (tmp_path / name).stat().st_size > 1000
    assert (tmp_path / "slice.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    tree = OccupancyOctree.load(tmp_path / "map.bt")    # the scan-mode octree
    assert tree.resolution == 0.2 and tree.num_leaves > 100
    assert tree.num_leaves == OccupancyOctree.from_bytes(
        by_name["octree (scan)"].map.to_bytes("bt")).num_leaves


def test_mapping_methods_include_the_kernel_maps():
    methods = mapping_methods(0.2)
    assert KERNEL_METHODS | {"k-NN"} <= set(methods)
    assert {"octree (scan)", "octree (ray)", "grid (scan)", "grid (ray)"} <= set(methods)
    for name, factory in methods.items():
        first, second = factory(), factory()
        assert first is not second and callable(first.insert_scan), name
        assert first.resolution == 0.2, name
    assert isinstance(methods["BGK"](), BGKMap)
    assert methods["AKIMap"]().variant == "occgp"
    assert methods["AKIMap (published)"]().variant == "published"
    assert isinstance(methods["k-NN"](), KNNMap) and methods["k-NN"]().sensor_range == 8.0


def test_noisy_methods_cut_rays_alike():
    """The noisy table's octree and k-NN map both cut rays at the scanner's 8 m."""
    methods = noisy_mapping_methods(0.2)
    assert set(methods) == NOISY_METHODS
    octree, knn = methods["octree (scan), noisy"](), methods["k-NN, noisy"]()
    assert isinstance(knn, KNNMap) and knn.sensor_range == 8.0 and knn.resolution == 0.2
    assert type(octree) is not KNNMap and octree.resolution == 0.2
    far = np.array([[12.0, 0.05, 0.05]])        # a return 12 m away: free up to 8 m only
    expected = OccupancyOctree(0.2).insert_scan(far, [0.05, 0.05, 0.05], max_range=8.0)
    octree.insert_scan(far, [0.05, 0.05, 0.05])
    assert octree.num_leaves == expected.num_leaves > 0
    assert np.isnan(octree.occupancy([[10.0, 0.05, 0.05]]))[0]
    knn.insert_scan(far, [0.05, 0.05, 0.05])
    assert np.isnan(knn.occupancy([[10.0, 0.05, 0.05]]))[0]
    assert knn.occupancy([[7.0, 0.05, 0.05]])[0] < 0.5


def test_noisy_scans_move_points_along_their_rays():
    rng = np.random.default_rng(0)
    origin = np.array([0.5, -0.5, 1.0])
    scans = [Scan(origin + rng.uniform(2, 6, (4000, 3)), origin) for _ in range(2)]

    def scales(noisy):
        out = []
        for clean, moved in zip(scans, noisy):
            assert isinstance(moved, Scan) and moved.points.shape == (4000, 3)
            np.testing.assert_array_equal(moved.origin, clean.origin)
            ray, got = clean.points - origin, moved.points - origin
            scale = np.linalg.norm(got, axis=1) / np.linalg.norm(ray, axis=1)
            np.testing.assert_allclose(got, scale[:, None] * ray, atol=1e-9)   # on the ray
            out.append(scale)
        return np.concatenate(out)

    speckled = scales(_noisy_scans(scans, depth_noise=0.0, speckle=0.1, seed=3))
    moved = speckled != 1.0              # outliers: uniform between sensor and end point
    assert 0.085 < moved.mean() < 0.115 and (speckled[moved] < 1).all()
    assert abs(speckled[moved].mean() - 0.5) < 0.05
    noisy = _noisy_scans(scans, depth_noise=0.01, speckle=0.0, seed=3)
    dist = np.concatenate([np.linalg.norm(s.points - origin, axis=1) for s in scans])
    rel = (scales(noisy) - 1) / (0.01 * dist)     # range error / (0.01 d^2) ~ N(0, 1)
    assert abs(rel.mean()) < 0.1 and 0.9 < rel.std() < 1.1
    again = _noisy_scans(scans, depth_noise=0.01, speckle=0.0, seed=3)
    np.testing.assert_array_equal(again[1].points, noisy[1].points)        # seeded
    other = _noisy_scans(scans, depth_noise=0.01, speckle=0.0, seed=4)
    assert not np.array_equal(other[1].points, noisy[1].points)
    same = _noisy_scans(scans, depth_noise=0.0, speckle=0.0, seed=3)
    np.testing.assert_allclose(same[0].points, scans[0].points, rtol=0, atol=1e-12)


def test_map_command_builds_tree_from_pcd_files(tmp_path, capsys):
    scans = structured_room().scan(n_poses=1, scans_per_pose=2, n_points=500)
    paths = [tmp_path / f"s{i}.pcd" for i in range(len(scans))]
    for path, scan in zip(paths, scans):
        write_pcd(path, scan.points, scan.origin)
    out = tmp_path / "m.ot"
    assert main(["map", *map(str, paths), "-o", str(out), "--resolution", "0.1",
                 "--mode", "ray", "--no-progress"]) == 0
    assert "2 scans, 1,000 points" in capsys.readouterr().out
    expected = OccupancyOctree(0.1)
    for scan in scans:
        expected.insert_scan(scan.points.astype(np.float32), scan.origin, mode="ray")
    got = OccupancyOctree.load(out)
    assert got.num_leaves == expected.num_leaves
    np.testing.assert_array_equal(np.sort(got.leaves().log_odds),
                                  np.sort(expected.leaves().log_odds))


def _write_scans(tmp_path):
    scans = structured_room().scan(n_poses=1, scans_per_pose=2, n_points=500)
    paths = [tmp_path / f"s{i}.pcd" for i in range(len(scans))]
    for path, scan in zip(paths, scans):
        write_pcd(path, scan.points, scan.origin)
    return paths, [s for path in paths for s in read_scans(path)]


@pytest.mark.parametrize("method", ["bgk", "akimap"])
def test_map_command_writes_kernel_map_as_octree(tmp_path, capsys, method):
    paths, scans = _write_scans(tmp_path)
    out = tmp_path / "m.bt"
    assert main(["map", *map(str, paths), "-o", str(out), "--resolution", "0.1",
                 "--method", method, "--no-progress"]) == 0
    assert "2 scans, 1,000 points" in capsys.readouterr().out
    tree = OccupancyOctree.load(out)
    assert tree.resolution == 0.1
    occupied = tree.leaves(occupied_only=True)
    assert len(occupied.centers) > 0
    # most end points lie in occupied leaves; the sensor's cell is free
    ends = np.concatenate([s.points for s in scans]).astype(np.float64)
    half = occupied.sizes[:, None] / 2
    inside = ((ends[:, None] >= occupied.centers - half)
              & (ends[:, None] < occupied.centers + half)).all(axis=2).any(axis=1)
    assert inside.mean() > 0.6 and tree.is_occupied(ends).mean() > 0.6
    assert not tree.is_occupied(scans[0].origin[None])[0]


def test_map_command_max_range_for_kernel_maps(tmp_path, capsys):
    paths, scans = _write_scans(tmp_path)
    for method in ("bgk", "akimap"):
        out = tmp_path / f"{method}.ot"
        assert main(["map", *map(str, paths), "-o", str(out), "--method", method,
                     "--max-range", "3", "--no-progress"]) == 0
        if method == "bgk":
            expected = BGKMap(0.1, max_range=3.0)
        else:                       # akimap gets the end points within 3 m only
            expected = AKIMap(0.1, random_state=0)
        for s in scans:
            pts = s.points.astype(np.float64)
            if method == "akimap":
                pts = pts[np.linalg.norm(pts - s.origin, axis=1) <= 3.0]
            expected.update(pts, s.origin)
        got, want = OccupancyOctree.load(out).leaves(), expected.to_octree().leaves()
        assert len(got.centers) == len(want.centers) > 0
        np.testing.assert_array_equal(np.sort(got.log_odds), np.sort(want.log_odds))
    capsys.readouterr()


@pytest.mark.parametrize("args, message", [
    (["map", "missing.pcd", "-o", "m.bt"], "occgp map: error:"),
    (["map", "x.pcd", "-o", "m.png"], "output must end in .bt or .ot"),
    (["map", "x.pcd", "-o", "m.bt", "--method", "bgk", "--mode", "ray"],
     "mode applies to method='octree' only"),
    (["map", "x.pcd", "-o", "m.bt", "--method", "akimap", "--max-range", "0"],
     "max_range must lie in (0.0, inf), got 0.0"),
])
def test_map_command_reports_errors(tmp_path, capsys, monkeypatch, args, message):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "x.pcd").write_text("not a pcd")
    assert main(args) == 1
    assert message in capsys.readouterr().err


def test_map_command_builds_knn_map(tmp_path, capsys):
    paths, scans = _write_scans(tmp_path)
    out = tmp_path / "knn.ot"
    assert main(["map", *map(str, paths), "-o", str(out), "--method", "knn", "--k", "3",
                 "--sensor-range", "6", "--p-u", "0.9", "--p-m", "0.3", "--p-t", "0.6",
                 "--cdf", "truncated", "--no-progress"]) == 0
    assert "2 scans, 1,000 points" in capsys.readouterr().out
    params = dict(k=3, sensor_range=6.0, p_u=0.9, p_m=0.3, p_t=0.6, cdf="truncated")
    expected, default = KNNMap(0.1, **params), KNNMap(0.1)
    for s in scans:
        expected.insert_scan(s.points, s.origin)
        default.insert_scan(s.points, s.origin)
    got = KNNMap.load(out, **params)
    assert isinstance(got, KNNMap) and got.k == 3 and got.resolution == 0.1
    assert got.num_leaves == expected.num_leaves > 100
    want = np.sort(expected.leaves().log_odds)
    np.testing.assert_array_equal(np.sort(got.leaves().log_odds), want)
    assert got.num_leaves != default.num_leaves or \
        not np.array_equal(want, np.sort(default.leaves().log_odds))    # options applied
    # as a .bt file too, read by the plain octree
    assert main(["map", *map(str, paths), "-o", str(tmp_path / "knn.bt"), "--method", "knn",
                 "--no-progress"]) == 0
    tree = OccupancyOctree.load(tmp_path / "knn.bt")
    assert tree.num_leaves == OccupancyOctree.from_bytes(default.to_bytes("bt")).num_leaves
    ends = np.concatenate([s.points for s in scans])
    near = np.linalg.norm(ends - scans[0].origin, axis=1) <= 4.0
    assert tree.is_occupied(ends[near]).mean() > 0.5
    capsys.readouterr()


@pytest.mark.parametrize("option, value, message", [
    ("--k", "0", r"argument --k: k must lie in \[1, 1000\], got 0"),
    ("--k", "1.5", r"argument --k: invalid int value"),
    ("--k", "5000", r"argument --k: k must lie in \[1, 1000\], got 5000"),
    ("--sensor-range", "0", r"argument --sensor-range: sensor_range must lie in \(0.0, "),
    ("--sensor-range", "nan", r"argument --sensor-range: sensor_range must lie in"),
    ("--sensor-range", "1e30", r"argument --sensor-range: sensor_range must lie in"),
    ("--p-u", "1.5", r"argument --p-u: p_u must lie in \(0.0, 1.0\), got 1.5"),
    ("--p-u", "0.3", r"argument --p-u/--p-l: .*must satisfy p_u >= p_l"),
    ("--p-l", "0.9", r"argument --p-u/--p-l: .*must satisfy p_u >= p_l"),
    ("--p-m", "0.4", r"argument --p-m-out/--p-m: .*must satisfy p_m_out >= p_m"),
    ("--p-m-out", "0.5", r"argument --p-m-out: p_m_out must be below 0.5"),
    ("--p-min", "0", r"argument --p-min: p_min must lie in \(0.0, 1.0\), got 0.0"),
    ("--p-min", "0.3", r"argument --p-m/--p-min: .*must satisfy p_m >= p_min"),
    ("--p-max", "0.4", r"argument --p-max/--p-t: .*must satisfy p_max >= p_t"),
    ("--p-max", "1", r"argument --p-max: p_max must lie in \(0.0, 1.0\), got 1.0"),
    ("--p-t", "inf", r"argument --p-t: p_t must lie in \(0.0, 1.0\), got inf"),
    ("--cdf", "cauchy", r"argument --cdf: invalid choice: 'cauchy'"),
    ("--max-range", "3", r"argument --max-range: not with --method knn, whose range limit "
     r"is --sensor-range"),
])
def test_map_command_rejects_bad_knn_options(tmp_path, capsys, monkeypatch, option, value,
                                             message):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exc:
        main(["map", "missing.pcd", "-o", "m.bt", "--method", "knn", option, value])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("usage: occgp map") and "occgp map: error:" in err
    assert re.search(message, err), err
    assert not (tmp_path / "m.bt").exists()


@pytest.mark.parametrize("method", ["octree", "bgk", "akimap"])
def test_map_command_rejects_knn_options_with_other_methods(tmp_path, capsys, monkeypatch,
                                                             method):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exc:
        main(["map", "x.pcd", "-o", "m.bt", "--method", method, "--k", "3", "--p-t", "0.6"])
    assert exc.value.code == 2
    assert f"argument --k/--p-t: applies to --method knn only, got --method {method}" in \
        capsys.readouterr().err


@pytest.mark.parametrize("kwargs, exc, message", [
    (dict(method="octree", knn_params={"k": 3}), ValueError,
     r"knn_params applies to method='knn' only, got method='octree'"),
    (dict(method="knn", max_range=3.0), ValueError,
     r"max_range does not apply to method='knn': its range limit is "
     r"knn_params\['sensor_range'\] \(default 4.0 m\)"),
    (dict(method="knn", knn_params={"kk": 3}), ValueError,
     r"knn_params holds \['kk'\], which KNNMap does not take"),
    (dict(method="knn", knn_params=[("k", 3)]), TypeError,
     r"knn_params must be a mapping of KNNMap parameters, got list"),
    (dict(method="knn", knn_params={"k": 2.5}), TypeError, r"k must be a positive int"),
    (dict(method="knn", knn_params={"p_u": 0.3}), ValueError, r"must satisfy p_u >= p_l"),
    (dict(method="knn", knn_params={"cdf": "cauchy"}), ValueError,
     r"cdf must be one of \('normal', 'truncated'\), got 'cauchy'"),
    (dict(method="knn", knn_params={"n_jobs": 2}), ValueError,
     r"knn_params holds \['n_jobs'\]"),
])
def test_map_scans_checks_knn_params_before_reading(tmp_path, kwargs, exc, message):
    with pytest.raises(exc, match=message):
        map_scans([tmp_path / "missing.pcd"], tmp_path / "m.bt", **kwargs)
    assert not (tmp_path / "m.bt").exists()


@pytest.mark.parametrize("method", ["grid", "gp", "BGK"])
def test_map_command_rejects_unknown_method(tmp_path, capsys, monkeypatch, method):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exc:
        main(["map", "x.pcd", "-o", "m.bt", "--method", method])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "argument --method: invalid choice" in err and "octree" in err
