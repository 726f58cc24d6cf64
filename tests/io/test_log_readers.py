"""The real-log readers: CARMEN laser logs (read_carmen) and posed scan sequences
(ScanSequence), on small files made here and on slices of the shared logs."""

import gzip
import pathlib

import numpy as np
import pytest
from scipy.spatial import cKDTree

from occgp.cli import main
from occgp.io import (
    FLASER_NO_RETURN,
    LaserLog,
    ScanSequence,
    apply_poses,
    read_carmen,
    read_pcd,
    read_poses,
    write_pcd,
)

DATA = pathlib.Path(__file__).resolve().parents[3] / "shared" / "data"
CARMEN = DATA / "carmen"
HKU = DATA / "lidar_seq" / "hku_mb"
needs_carmen = pytest.mark.skipif(not (CARMEN / "intel-corrected.log.gz").exists(),
                                  reason="the shared CARMEN logs (../shared/data/carmen) are "
                                  "absent")
needs_hku = pytest.mark.skipif(not (HKU / "optimized_poses.txt").exists(),
                               reason="the shared LiDAR sequence (../shared/data/lidar_seq/"
                               "hku_mb) is absent")


def flaser(ranges, pose, t=1.0):
    r = " ".join(map(str, ranges))
    p = " ".join(map(str, pose))
    return f"FLASER {len(ranges)} {r} {p} {p} {t} host {t}\n"


def robotlaser(ranges, pose, start=-1.0, step=0.5, max_range=20.0, remissions=(), t=2.0):
    r = " ".join(map(str, ranges))
    rem = " ".join(map(str, remissions))
    p = " ".join(map(str, pose))
    return (f"ROBOTLASER1 0 {start} 3.14 {step} {max_range} 0.01 0 {len(ranges)} {r} "
            f"{len(remissions)} {rem} {p} {p} 0 0 0.5 0.3 0 {t} host {t}\n")


# --------------------------------------------------------------------------- #
# CARMEN, made here
# --------------------------------------------------------------------------- #
def test_flaser_beams_follow_carmens_convention(tmp_path):
    """Beam i of n leaves at theta - 90 deg + i * 180 deg / n, counter-clockwise; the
    origin is the line's laser pose; other messages are skipped."""
    path = tmp_path / "log.txt"
    pose = (1.0, 2.0, np.pi / 2)
    path.write_text("# comment\nPARAM robot_x 0\nODOM 0 0 0 0 0 0 0 host 0\n"
                    + flaser([1.0, 2.0, 3.0, 4.0], pose, t=7.5))
    log = read_carmen(path)
    assert isinstance(log, LaserLog) and len(log) == 1
    scan = log[0]
    np.testing.assert_array_equal(scan.origin, [1.0, 2.0])
    assert scan.heading == np.pi / 2
    np.testing.assert_allclose(scan.angles, np.radians([-90, -45, 0, 45]))
    # heading +y: beam 0 looks along +x (the robot's right), beam 2 along +y
    np.testing.assert_allclose(scan.points, [[2.0, 2.0], [1.0 + np.sqrt(2), 2.0 + np.sqrt(2)],
                                             [1.0, 5.0], [1.0 - 2 * np.sqrt(2),
                                                          2.0 + 2 * np.sqrt(2)]], atol=1e-12)
    assert log.times.tolist() == [7.5]
    np.testing.assert_array_equal(log.poses, [pose])


def test_no_returns_are_never_hits(tmp_path):
    """Readings at or beyond 49.99 m are dropped by default, or kept as free beams of
    no_return_range; max_range cuts farther returns to free beams."""
    path = tmp_path / "log.gz"
    with gzip.open(path, "wt") as f:
        f.write(flaser([1.0, 81.83, FLASER_NO_RETURN, 30.0], (0, 0, 0)))
    log = read_carmen(path)
    assert log.n_no_return == 2 and log[0].hit.all()
    np.testing.assert_array_equal(log[0].ranges, [1.0, 30.0])
    kept = read_carmen(path, no_return_range=5.0)
    np.testing.assert_array_equal(kept[0].ranges, [1.0, 5.0, 5.0, 30.0])
    np.testing.assert_array_equal(kept[0].hit, [True, False, False, True])
    cut = read_carmen(path, no_return_range=5.0, max_range=10.0)
    np.testing.assert_array_equal(cut[0].ranges, [1.0, 5.0, 5.0, 10.0])
    np.testing.assert_array_equal(cut[0].hit, [True, False, False, False])
    assert cut.n_cut == 1 and cut[0].max_range == 5.0
    hits, starts, ends = cut.observations()
    assert hits.tolist() == [[1.0, 0.0]] or np.allclose(hits, [[0.0, -1.0]])
    assert len(starts) == len(ends) == 4


def test_robotlaser_lines(tmp_path):
    """ROBOTLASER1 beams start at the line's start angle and step by its resolution;
    readings at its maximum range are no-returns; remissions are skipped."""
    path = tmp_path / "log.log"
    path.write_text(robotlaser([1.0, 20.0, 2.0], (0.5, 0.0, 0.25), remissions=(3, 4)))
    log = read_carmen(path)
    np.testing.assert_allclose(log[0].angles, [-1.0, 0.0])
    np.testing.assert_allclose(log[0].points, [[0.5 + np.cos(-0.75), np.sin(-0.75)],
                                               [0.5 + 2 * np.cos(0.25), 2 * np.sin(0.25)]])
    assert log.n_no_return == 1 and log.times.tolist() == [2.0]


def test_one_message_kind_is_read(tmp_path):
    """A log that carries the same scans as FLASER and ROBOTLASER1 lines gives them once."""
    path = tmp_path / "log.txt"
    path.write_text(flaser([1.0, 1.0], (0, 0, 0)) + robotlaser([1.0, 1.0], (0, 0, 0)))
    assert len(read_carmen(path)) == 1
    assert read_carmen(path, message="ROBOTLASER1")[0].angles.tolist() == [-1.0, -0.5]


def test_flaser_angles_override(tmp_path):
    path = tmp_path / "log.txt"
    path.write_text(flaser([1.0, 1.0], (0, 0, 0)))
    log = read_carmen(path, flaser_angles=[0.0, 0.5])
    np.testing.assert_array_equal(log[0].angles, [0.0, 0.5])
    with pytest.raises(ValueError, match="flaser_angles holds 3 angles for a FLASER line of 2"):
        read_carmen(path, flaser_angles=[0.0, 0.5, 1.0])


@pytest.mark.parametrize("text, message", [
    ("", r"no FLASER or ROBOTLASER1 lines"),
    ("ODOM 0 0 0 0 0 0 0 host 0\n", r"no FLASER or ROBOTLASER1 lines"),
    ("FLASER 3 1.0 2.0\n", r"line 1: truncated FLASER line: expected at least 12 fields"),
    ("FLASER x 1.0\n", r"line 1: the FLASER beam count must be an integer, got 'x'"),
    ("FLASER -2 1.0\n", r"line 1: the FLASER beam count must lie in \[0, 100000\]"),
    ("# x\n" + "FLASER 2 1.0 abc 0 0 0 0 0 0 1 h 1\n", r"line 2: the ranges must be numbers, "
     r"got 'abc'"),
    ("FLASER 2 1.0 -1.0 0 0 0 0 0 0 1 h 1\n", r"line 1: ranges must be non-negative"),
    ("FLASER 2 1.0 nan 0 0 0 0 0 0 1 h 1\n", r"line 1: ranges must be non-negative"),
    ("FLASER 2 1.0 1.0 nan 0 0 0 0 0 1 h 1\n", r"line 1: the laser pose must be finite"),
    ("FLASER 2 1.0 1.0 1e30 0 0 0 0 0 1 h 1\n", r"line 1: the laser pose must be finite"),
    ("FLASER 2 1.0 1.0 0 0 0 0 0 0 inf h 1\n", r"line 1: the time stamp must be finite"),
    ("ROBOTLASER1 0 0 3 0.1 0 0.01 0 1 1.0 0 0 0 0 0 0 0 0 0 0 0 0 1 h 1\n",
     r"line 1: the laser configuration must be finite, with a maximum range in \(0, 1e6\]"),
    ("ROBOTLASER1 0 0 3 0.1 20 0.01 0 2 1.0 1.0 5 1\n",
     r"line 1: truncated ROBOTLASER1 line"),
])
def test_bad_logs_are_rejected_with_the_line(tmp_path, text, message):
    path = tmp_path / "bad.log"
    path.write_text(text)
    with pytest.raises(ValueError, match=message):
        read_carmen(path, message="ROBOTLASER1" if text.startswith("ROBOT") else None)


def test_bad_arguments(tmp_path):
    path = tmp_path / "log.txt"
    path.write_text(flaser([1.0], (0, 0, 0)))
    with pytest.raises(ValueError, match="message must be one of"):
        read_carmen(path, message="RLASER")
    with pytest.raises(ValueError, match=r"no_return_range must lie in \(0.0, 1000000.0\]"):
        read_carmen(path, no_return_range=0.0)
    with pytest.raises(TypeError, match="max_range must be a real number"):
        read_carmen(path, max_range="far")
    with pytest.raises(TypeError, match="path must be a str or os.PathLike"):
        read_carmen(3)
    with pytest.raises(FileNotFoundError):
        read_carmen(tmp_path / "missing.log")
    (tmp_path / "bad.gz").write_bytes(b"\x1f\x8b\x08\x00garbage")
    with pytest.raises(ValueError, match="corrupt or truncated gz stream"):
        read_carmen(tmp_path / "bad.gz")


def test_map_command_takes_a_carmen_log(tmp_path, capsys):
    """occgp map reads a CARMEN log as planar scans at z = 0: the cells of a wall seen by
    two scans are occupied, the beams' cells free, and no-returns insert nothing."""
    path = tmp_path / "log.gz"
    angles = np.radians(np.arange(180) - 90.0)
    ranges = np.where(np.abs(angles) < 1.0, 3.0 / np.cos(angles), 81.83)
    with gzip.open(path, "wt") as f:
        f.write(flaser(list(ranges), (0, 0, 0)))
        f.write(flaser(list(np.where(ranges < 80, ranges - 0.2 / np.cos(angles), ranges)),
                       (0.2, 0, 0)))
    out = tmp_path / "m.bt"
    assert main(["map", str(path), "-o", str(out), "--resolution", "0.1",
                 "--no-progress"]) == 0
    n = int((np.abs(angles) < 1.0).sum())
    assert f"2 scans, {2 * n} points" in capsys.readouterr().out
    from occgp import OccupancyOctree
    tree = OccupancyOctree.load(out)
    assert tree.occupancy([[3.05, 0.0, 0.0]])[0] > 0.5
    assert tree.occupancy([[1.5, 0.0, 0.0]])[0] < 0.5
    assert np.isnan(tree.occupancy([[0.0, 2.0, 0.0]])[0])       # a no-return beam


# --------------------------------------------------------------------------- #
# CARMEN, the shared logs
# --------------------------------------------------------------------------- #
@needs_carmen
@pytest.mark.parametrize("name, n_scans, n_beams, no_return, hit_range", [
    ("intel", 910, 180, 0.025, (0.23, 25.4)),
    ("freiburg-079", 4791, 360, 0.021, (0.12, 36.6)),
])
def test_shared_logs_read_as_their_readme_states(name, n_scans, n_beams, no_return,
                                                 hit_range):
    log = read_carmen(CARMEN / f"{name}-corrected.log.gz")
    assert len(log) == n_scans
    total = n_scans * n_beams
    assert log.n_no_return / total == pytest.approx(no_return, abs=0.001)
    ranges = np.concatenate([s.ranges for s in log])
    assert len(ranges) == total - log.n_no_return
    assert ranges.min() == pytest.approx(hit_range[0], abs=0.01)
    assert ranges.max() == pytest.approx(hit_range[1], abs=0.05)
    assert all(s.hit.all() for s in log)


@needs_carmen
@pytest.mark.parametrize("a", [100, 500])
def test_intel_scans_agree_where_they_overlap(a):
    """The beam convention, checked on the data: the end points of a scan and of the next
    one taken >= 1 m or 15 degrees away lie 2-3 cm (median) from each other; with the
    beams reversed, 0.7 m or more."""
    log = read_carmen(CARMEN / "intel-corrected.log.gz")
    poses = log.poses
    b = next(j for j in range(a + 1, len(log))
             if np.linalg.norm(poses[j, :2] - poses[a, :2]) >= 1.0
             or abs((poses[j, 2] - poses[a, 2] + np.pi) % (2 * np.pi) - np.pi)
             >= np.radians(15))
    other = cKDTree(log[b].points)
    assert np.median(other.query(log[a].points)[0]) < 0.04
    flipped = log[a]._replace(angles=log[a].angles[::-1])
    assert np.median(other.query(flipped.points)[0]) > 0.5


# --------------------------------------------------------------------------- #
# scan sequences
# --------------------------------------------------------------------------- #
def _sequence_files(tmp_path, n=4):
    """n PCD scans in tmp_path / "scans" and their KITTI poses in tmp_path / "poses.txt"."""
    rng = np.random.default_rng(0)
    folder = tmp_path / "scans"
    folder.mkdir()
    scans = [rng.normal(size=(20, 3)) for _ in range(n)]
    for i, pts in enumerate(scans):
        write_pcd(folder / f"scan_{i}.pcd", pts)
    poses = np.tile(np.eye(4), (n, 1, 1))
    for i in range(n):
        c, s = np.cos(0.3 * i), np.sin(0.3 * i)
        poses[i, :2, :2] = [[c, -s], [s, c]]
        poses[i, :3, 3] = [i, 2.0 * i, 0.5]
    lines = [" ".join(f"{v:.17g}" for v in p[:3].ravel()) for p in poses]
    (tmp_path / "poses.txt").write_text("\n".join(lines) + "\n")
    return scans, poses


def test_scan_sequence_poses_every_scan(tmp_path):
    scans, poses = _sequence_files(tmp_path)
    seq = ScanSequence(tmp_path / "scans", tmp_path / "poses.txt", progress=False)
    assert len(seq) == 4 and seq.files[0].name == "scan_0.pcd"
    expected = apply_poses([read_pcd(f) for f in seq.files], poses)
    for got, want in zip(seq, expected):
        np.testing.assert_allclose(got.points, want.points, atol=1e-12)
        np.testing.assert_allclose(got.origin, want.origin, atol=1e-12)
    np.testing.assert_allclose(seq[-1].origin, poses[-1, :3, 3])
    sub = seq.subset([3, 1])
    np.testing.assert_allclose(sub[0].points, expected[3].points, atol=1e-12)
    np.testing.assert_allclose(read_poses(tmp_path / "poses.txt"), poses, atol=1e-15)


def test_scan_sequence_reads_lazily(tmp_path):
    """A malformed file is only an error when it is read, naming it."""
    _sequence_files(tmp_path)
    (tmp_path / "scans" / "scan_2.pcd").write_bytes(b"not a pcd")
    seq = ScanSequence(tmp_path / "scans")
    assert len(seq[0].points) == 20
    with pytest.raises(ValueError, match="scan_2.pcd"):
        seq[2]


def test_scan_sequence_rejects_bad_input(tmp_path):
    _sequence_files(tmp_path)
    with pytest.raises(ValueError, match=r"holds 4 poses for 5 scans"):
        write_pcd(tmp_path / "scans" / "scan_9.pcd", np.zeros((1, 3)))
        ScanSequence(tmp_path / "scans", tmp_path / "poses.txt")
    (tmp_path / "scans" / "scan_9.pcd").unlink()
    with pytest.raises(ValueError, match=r"poses has 1 poses for 4 scans"):
        ScanSequence(tmp_path / "scans", np.eye(4)[None])
    with pytest.raises(ValueError, match="poses_format must be one of"):
        ScanSequence(tmp_path / "scans", tmp_path / "poses.txt", poses_format="euroc")
    with pytest.raises(ValueError, match="poses_format applies to a pose file"):
        ScanSequence(tmp_path / "scans", np.tile(np.eye(4), (4, 1, 1)), poses_format="kitti")
    with pytest.raises(FileNotFoundError):
        ScanSequence(tmp_path / "nowhere")
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(ValueError, match="no supported scan files"):
        ScanSequence(empty)
    with pytest.raises(IndexError):
        ScanSequence(tmp_path / "scans")[4]
    with pytest.raises(TypeError, match="indices must be integers"):
        ScanSequence(tmp_path / "scans")[1:2]


def test_map_command_reads_the_same_sequence(tmp_path):
    """occgp map FOLDER --poses FILE and the API build the same map."""
    from occgp import OccupancyOctree
    _sequence_files(tmp_path)
    out = tmp_path / "m.ot"
    assert main(["map", str(tmp_path / "scans"), "--poses", str(tmp_path / "poses.txt"), "-o",
                 str(out), "--no-progress"]) == 0
    tree = OccupancyOctree(0.1)
    for scan in ScanSequence(tmp_path / "scans", tmp_path / "poses.txt"):
        tree.insert_scan(scan.points, scan.origin)
    assert OccupancyOctree.load(out).to_bytes("ot") == tree.to_bytes("ot")


@needs_hku
def test_hku_sequence_keyframes_agree_with_their_neighbours():
    """Posed by optimized_poses.txt, a keyframe's points lie about 6 cm (median) from the
    five keyframes before it; posed by the next keyframe's pose, far more."""
    seq = ScanSequence(HKU / "Scans", HKU / "optimized_poses.txt", progress=False)
    assert len(seq) == 457
    np.testing.assert_allclose(seq.poses[0], np.eye(4), atol=0.05)
    k = 50
    union = cKDTree(np.vstack([seq[i].points for i in range(k - 5, k)]))
    assert np.median(union.query(seq[k].points)[0]) < 0.1
    shifted = seq.with_poses(np.roll(seq.poses, -1, axis=0))
    assert np.median(union.query(shifted[k].points)[0]) > 0.12
