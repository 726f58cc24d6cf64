"""bench/bench_peers.py: its occgp worker, comparison and table, on a tiny room (no peers, no network)."""

import importlib.util
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parents[1] / "bench" / "bench_peers.py"


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("bench_peers", BENCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture
def occgp_run(bench, tiny_room, tmp_path):
    """The occgp worker run in its own process on the tiny room, as the bench runs it."""
    points, origin = tiny_room
    queries = bench.make_queries(points, 300, np.random.default_rng(0))
    job = dict(package="occgp", resolutions=[0.1, 0.2], repeats=1, query_repeats=1,
               n_jobs=[2], out=str(tmp_path),
               datasets=[bench.write_dataset(tmp_path, "room", points, origin, queries)])
    result = bench.launch_worker(sys.executable, job, tmp_path, env=bench.occgp_env(),
                                 timeout=300)
    return result, tmp_path


@pytest.mark.slow
def test_occgp_worker_writes_timings_maps_and_answers(occgp_run):
    result, out = occgp_run
    assert result["package"] == "occgp"
    assert [(r["dataset"], r["resolution"]) for r in result["runs"]] == [("room", 0.1),
                                                                         ("room", 0.2)]
    for run in result["runs"]:
        assert run["n_points"] == 400 and run["n_queries"] == 300
        for key in ("insert_s", "insert_n_jobs_2_s", "occupancy_s", "labels_s", "insert_grid_s",
                    "insert_discretize_s", "insert_grid_discretize_s", "insert_grid_bresenham_s"):
            assert run[key] > 0
        free, occupied = run["bresenham_jaccard"]
        assert 0 < free <= 1 and 0 < occupied <= 1
        stem = out / f"occgp_room_{run['resolution']}"
        for suffix in (".bt", ".ot", "_n_jobs_2.ot", "_grid.ot", "_discretize.ot",
                       "_grid_discretize.ot"):
            assert Path(f"{stem}{suffix}").stat().st_size > 0
        occupancy = np.load(f"{stem}_occupancy.npy")
        labels = np.load(f"{stem}_labels.npy")
        assert occupancy.shape == labels.shape == (300,)
        np.testing.assert_array_equal(np.isnan(occupancy), labels == -1)
        np.testing.assert_array_equal(occupancy[labels >= 0] >= 0.5, labels[labels >= 0] == 1)
        assert (labels == 1).any() and (labels == 0).any() and (labels == -1).any()


@pytest.mark.slow
def test_comparison_accepts_equal_results_and_flags_different_ones(bench, occgp_run):
    result, out = occgp_run
    assert bench.check_identical({"occgp": result}, out, [2]) == []
    # the grid's map is the octree's, its discretized map the discretized octree's
    shutil.copy(out / "occgp_room_0.2_discretize.ot", out / "occgp_room_0.2_grid.ot")
    assert bench.check_identical({"occgp": result}, out, [2]) == [
        "occgp grid .ot map differs (room, 0.2 m)"]
    shutil.copy(out / "occgp_room_0.2.ot", out / "occgp_room_0.2_grid.ot")
    # a peer whose files are occgp's own passes; change one answer and one map and it fails
    for path in out.glob("occgp_room_*"):
        shutil.copy(path, out / path.name.replace("occgp_", "pyoctomap_"))
    peer = dict(result, package="pyoctomap", version="0")
    results = {"pyoctomap": peer, "occgp": result}
    assert bench.check_identical(results, out, [2]) == []
    labels = np.load(out / "pyoctomap_room_0.1_labels.npy")
    np.save(out / "pyoctomap_room_0.1_labels.npy", -labels)
    shutil.copy(out / "occgp_room_0.2.ot", out / "pyoctomap_room_0.1.ot")
    shutil.copy(out / "occgp_room_0.1.ot", out / "pyoctomap_room_0.2_discretize.ot")
    problems = bench.check_identical(results, out, [2])
    assert problems == ["pyoctomap labels answers differ (room, 0.1 m)",
                        "pyoctomap .ot map differs (room, 0.1 m)",
                        "pyoctomap discretize .ot map differs (room, 0.2 m)"]


def test_table_has_a_row_per_operation_and_names_missing_peers(bench, occgp_run):
    result, _ = occgp_run
    peer = dict(result, package="pyoctomap", version="9.9")
    table, notes = bench.markdown_table({"pyoctomap": peer, "occgp": result},
                                        {"octomap-python": "pip install failed"}, [2])
    lines = table.splitlines()
    assert lines[0].startswith("| data | res. (m) | operation | pyoctomap 9.9 | occgp ")
    assert lines[0].endswith("| occgp / pyoctomap |")
    assert len(lines) == 2 + 2 * 8              # 2 resolutions x 8 operations
    assert "| room (400 pts) | 0.1 | insert, occgp n_jobs=2 | (1 thread) |" in table
    assert "| room (400 pts) | 0.1 | insert, occgp grid | (as above) |" in table
    assert "| room (400 pts) | 0.1 | insert discretize, occgp grid | (as above) |" in table
    assert "| insert discretize, occgp octree | " in table
    assert "insert, occgp grid bresenham (another map)" in table
    assert "occupancy, 300 queries" in table
    assert notes[0] == "octomap-python: not measured (pip install failed)"
    assert len(notes) == 3 and "occgp grid bresenham vs the discretized 3D-DDA map" in notes[1]
    assert "cores" in bench.hardware_line()
