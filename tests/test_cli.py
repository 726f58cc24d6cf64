"""The occgp command: demo writes its table and files, map builds a map from scan files."""

import io

import numpy as np
import pytest

from occgp import AKIMap, BGKMap, OccupancyOctree
from occgp.cli import demo, main, mapping_methods
from occgp.datasets import read_scans, structured_room, write_pcd

KERNEL_METHODS = {"BGK", "AKIMap", "AKIMap (published)"}


def test_demo_prints_table_and_writes_files(tmp_path):
    out = io.StringIO()
    rows = demo(tmp_path, resolution=0.2, progress=False, out=out)
    text = out.getvalue()
    assert "octree (scan)" in text and "octree (ray)" in text and "AUC" in text
    assert {r.method for r in rows} == {"octree (scan)", "octree (ray)", "grid (scan)",
                                        "grid (ray)"} | KERNEL_METHODS
    assert all(name in text for name in KERNEL_METHODS)
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
    assert KERNEL_METHODS <= set(methods)
    assert {"octree (scan)", "octree (ray)", "grid (scan)", "grid (ray)"} <= set(methods)
    for name, factory in methods.items():
        first, second = factory(), factory()
        assert first is not second and callable(first.insert_scan), name
        assert first.resolution == 0.2, name
    assert isinstance(methods["BGK"](), BGKMap)
    assert methods["AKIMap"]().variant == "occgp"
    assert methods["AKIMap (published)"]().variant == "published"


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


@pytest.mark.parametrize("method", ["grid", "gp", "BGK"])
def test_map_command_rejects_unknown_method(tmp_path, capsys, monkeypatch, method):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exc:
        main(["map", "x.pcd", "-o", "m.bt", "--method", method])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "argument --method: invalid choice" in err and "octree" in err
