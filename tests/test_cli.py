"""The occgp command: demo writes its table and files, map builds a tree from scan files."""

import io

import numpy as np
import pytest

from occgp import OccupancyOctree
from occgp.cli import demo, main
from occgp.datasets import structured_room, write_pcd


def test_demo_prints_table_and_writes_files(tmp_path):
    out = io.StringIO()
    rows = demo(tmp_path, resolution=0.2, progress=False, out=out)
    text = out.getvalue()
    assert "octree (scan)" in text and "octree (ray)" in text and "AUC" in text
    assert {r.method for r in rows} == {"octree (scan)", "octree (ray)", "grid (scan)",
                                        "grid (ray)"}
    by_name = {r.method: r for r in rows}   # the grid is the octree cell for cell
    assert by_name["grid (scan)"].auc == by_name["octree (scan)"].auc
    assert by_name["grid (ray)"].mse == by_name["octree (ray)"].mse
    assert all(0.5 < r.auc <= 1 and r.seconds > 0 for r in rows)
    for name in ("map.bt", "slice.png", "roc.png"):
        assert (tmp_path / name).stat().st_size > 1000
    assert (tmp_path / "slice.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    tree = OccupancyOctree.load(tmp_path / "map.bt")
    assert tree.resolution == 0.2 and tree.num_leaves > 100


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


@pytest.mark.parametrize("args, message", [
    (["map", "missing.pcd", "-o", "m.bt"], "occgp map: error:"),
    (["map", "x.pcd", "-o", "m.png"], "output must end in .bt or .ot"),
])
def test_map_command_reports_errors(tmp_path, capsys, monkeypatch, args, message):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "x.pcd").write_text("not a pcd")
    assert main(args) == 1
    assert message in capsys.readouterr().err
