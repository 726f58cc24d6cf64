"""``occgp map``'s robot options: ``--project-2d`` (map_server / Nav2 files) and the scan
filters, each against the library call it stands for."""

import numpy as np
import pytest

from occgp import GridMap, OccupancyGrid2D, OccupancyOctree
from occgp.cli import main
from occgp.datasets import structured_room
from occgp.io import read_scans, write_pcd


def _write_scans(tmp_path, n_points=800):
    scans = structured_room().scan(n_poses=1, scans_per_pose=2, n_points=n_points)
    paths = [tmp_path / f"s{i}.pcd" for i in range(len(scans))]
    for path, scan in zip(paths, scans):
        write_pcd(path, scan.points, scan.origin)
    return paths, [s for path in paths for s in read_scans(path)]


@pytest.mark.parametrize("method, cls", [("octree", OccupancyOctree), ("grid", GridMap)])
def test_project_2d_writes_the_projection_of_the_map(tmp_path, capsys, method, cls):
    paths, scans = _write_scans(tmp_path)
    out = tmp_path / "floor.yaml"
    assert main(["map", *map(str, paths), "-o", str(out), "--method", method,
                 "--project-2d", "0.1", "1.5", "--no-progress"]) == 0
    assert "floor.pgm" in capsys.readouterr().out
    expected = cls(0.1)
    for s in scans:
        expected.insert_scan(s.points, s.origin)
    want = expected.project_2d(0.1, 1.5)
    got = OccupancyGrid2D.load_ros_map(out)
    assert np.array_equal(got.states, want.states)
    assert np.allclose(got.origin, want.origin) and got.resolution == want.resolution
    assert (got.states == 1).sum() > 100 and (got.states == 0).sum() > 100


@pytest.mark.parametrize("args, message", [
    (["-o", "m.yaml"], "a .yaml output is a 2D map: give project_2d"),
    (["-o", "m.bt", "--project-2d", "0", "1"], "output must end in .yaml or .yml"),
    (["-o", "m.yaml", "--project-2d", "1", "0"], "z_min <= z_max"),
    (["-o", "m.yaml", "--project-2d", "nan", "1"], "z_min must be a finite number"),
])
def test_project_2d_is_checked_before_reading(tmp_path, capsys, monkeypatch, args, message):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exc:
        main(["map", "missing.pcd", *args, "--no-progress"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert message in err and ("--project-2d" in err or "-o/--output" in err)


def test_filter_options_give_the_map_of_the_filtered_scans(tmp_path, capsys):
    from occgp.filters import ScanFilter
    paths, scans = _write_scans(tmp_path, n_points=1500)
    out = tmp_path / "m.ot"
    assert main(["map", *map(str, paths), "-o", str(out), "--min-range", "0.8",
                 "--z-max", "1.8", "--self-box", "-0.3", "-0.3", "-0.5", "0.3", "0.3", "0.2",
                 "--ground", "free", "--no-progress"]) == 0
    text = capsys.readouterr().out
    f = ScanFilter(min_range=0.8, z_max=1.8, self_box=[[-0.3, -0.3, -0.5], [0.3, 0.3, 0.2]],
                   ground="free", random_state=0)
    expected, n_free = OccupancyOctree(0.1), 0
    for s in scans:
        points, free = f.apply(s.points, s.origin)
        n_free += len(free)
        expected.insert_scan(points, s.origin, free_points=free)
    assert n_free > 50 and f"({n_free:,} ground points inserted as free)" in text
    got = OccupancyOctree.load(out)
    assert got.to_bytes() == expected.to_bytes()


@pytest.mark.parametrize("args, message", [
    (["--method", "akimap", "--ground", "free"], "ground='free' needs a map whose insert_scan"),
    (["--min-range", "-1"], "min_range"),
    (["--z-min", "2", "--z-max", "1"], "z_min"),
    (["--ground", "drop", "--ground-angle", "3"], "angle"),
])
def test_filter_options_are_checked_before_reading(tmp_path, capsys, monkeypatch, args,
                                                   message):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exc:
        main(["map", "missing.pcd", "-o", "m.bt", *args, "--no-progress"])
    assert exc.value.code == 2
    assert message in capsys.readouterr().err
