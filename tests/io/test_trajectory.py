"""Tests of the trajectory readers (KITTI poses, TUM) and apply_poses."""

import bz2

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy.spatial.transform import Rotation

from occgp.datasets import Scan
from occgp.io import apply_poses, read_kitti_poses, read_tum_trajectory


def _poses(n=3, seed=0):
    rng = np.random.default_rng(seed)
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, :3, :3] = Rotation.random(n, random_state=seed).as_matrix()
    poses[:, :3, 3] = rng.normal(scale=10.0, size=(n, 3))
    return poses


def _kitti_text(poses):
    return "".join(" ".join(f"{v:.12e}" for v in p[:3].ravel()) + "\n" for p in poses)


def test_read_kitti_poses(tmp_path):
    poses = _poses()
    path = tmp_path / "00.txt"
    path.write_text(_kitti_text(poses) + "\n")  # a trailing blank line
    got = read_kitti_poses(path)
    assert got.shape == (3, 4, 4)
    assert_allclose(got, poses, rtol=1e-11, atol=1e-11)
    assert_array_equal(got[:, 3], [[0, 0, 0, 1]] * 3)
    bz = tmp_path / "00.txt.bz2"
    bz.write_bytes(bz2.compress(path.read_bytes()))
    assert_array_equal(read_kitti_poses(bz), got)


def test_read_kitti_poses_accepts_printed_precision(tmp_path):
    # KITTI prints about seven significant digits
    path = tmp_path / "p.txt"
    path.write_text(_kitti_text(np.round(_poses(5), 6)))
    assert read_kitti_poses(path).shape == (5, 4, 4)


@pytest.mark.parametrize("text, match", [
    ("1 0 0 0 0 1 0 0 0 0 1\n", r"line 1: expected 12 numbers .*, got 11"),
    ("1 0 0 0 0 1 0 0 0 0 1 0\n\n1 0 0 0 0 1 0 0 0 0 1 0 5\n", r"line 3: .*got 13"),
    ("1 0 0 0 0 1 0 0 0 0 1 zero\n", r"line 1: expected 12 numbers .*, got 'zero'"),
    ("1 0 0 0 0 1 0 0 0 0 1 nan\n", r"line 1: values must be finite"),
    ("1 0 0 0 0 1 0 0 0 0 1 0\n2 0 0 0 0 1 0 0 0 0 1 0\n",
     r"line 2: the rotation part is not orthonormal with det \+1 \(max \|R R\^T - I\| = 3"),
    ("-1 0 0 0 0 1 0 0 0 0 1 0\n", r"line 1: the rotation part is not orthonormal with det"),
    ("1 0 0 0 0 1.01 0 0 0 0 1 0\n", r"line 1: .*not orthonormal"),
    ("# only a comment\n\n", r"no poses in the file"),
])
def test_read_kitti_poses_rejects_bad_lines(tmp_path, text, match):
    path = tmp_path / "p.txt"
    path.write_text(text)
    with pytest.raises(ValueError, match=match):
        read_kitti_poses(path)


def test_read_kitti_poses_tolerance_and_files(tmp_path):
    path = tmp_path / "p.txt"
    path.write_text("1 0 0 0 0 1.01 0 0 0 0 1 0\n")
    assert read_kitti_poses(path, tol=0.05)[0, 1, 1] == 1.01
    with pytest.raises(ValueError, match=r"tol must lie in \[0.0, 1.0\)"):
        read_kitti_poses(path, tol=-1)
    with pytest.raises(FileNotFoundError):
        read_kitti_poses(tmp_path / "nope.txt")
    (tmp_path / "bin.txt").write_bytes(b"\xff\xfe\x00")
    with pytest.raises(ValueError, match="not a text file"):
        read_kitti_poses(tmp_path / "bin.txt")


def test_read_tum_trajectory(tmp_path):
    rot = Rotation.from_euler("xyz", [[0.1, 0.2, 0.3], [0.0, 0.0, np.pi / 2]])
    q = rot.as_quat()  # x y z w
    lines = ["# ground truth trajectory", "# timestamp tx ty tz qx qy qz qw"]
    for t, pos, qq in zip([1305031102.175304, 1305031102.2], [[1, 2, 3], [4, 5, 6]], q):
        lines.append(f"{t:.6f} " + " ".join(map(str, pos)) + " " + " ".join(map(str, qq)))
    path = tmp_path / "groundtruth.txt"
    path.write_text("\n".join(lines) + "\n")
    t, poses = read_tum_trajectory(path)
    assert_allclose(t, [1305031102.175304, 1305031102.2])
    assert poses.shape == (2, 4, 4)
    assert_allclose(poses[:, :3, :3], rot.as_matrix(), atol=1e-12)
    assert_array_equal(poses[:, :3, 3], [[1, 2, 3], [4, 5, 6]])
    assert_allclose(poses[1, :3, :3] @ [1, 0, 0], [0, 1, 0], atol=1e-12)


@pytest.mark.parametrize("text, match", [
    ("0 1 2 3 0 0 0\n", r"line 1: expected 8 numbers \(timestamp tx ty tz qx qy qz qw\), got 7"),
    ("0 1 2 3 0 0 0 1\n1 a 2 3 0 0 0 1\n", r"line 2: .*got 'a'"),
    ("0 1 2 3 0 0 0 inf\n", r"line 1: values must be finite"),
    ("0 1 2 3 0 0 0 0\n", r"line 1: quaternion .* has norm 0; expected a unit quaternion"),
    ("# c\n0 1 2 3 0 0 0 1.1\n", r"line 2: quaternion .* has norm 1.1"),
    ("0 1 2 3 0 0 0 1e300\n", r"line 1: quaternion .* has norm 1e\+300"),
    ("2 1 2 3 0 0 0 1\n1 1 2 3 0 0 0 1\n", r"line 2: timestamp 1.0 is smaller than the "
                                          r"previous one 2.0"),
    ("", r"no poses in the file"),
])
def test_read_tum_trajectory_rejects_bad_lines(tmp_path, text, match):
    path = tmp_path / "t.txt"
    path.write_text(text)
    with pytest.raises(ValueError, match=match):
        read_tum_trajectory(path)


def test_apply_poses_moves_scans_to_the_world_frame():
    rng = np.random.default_rng(0)
    poses = _poses(3)
    scans = [Scan(rng.normal(size=(n, 3)), np.zeros(3)) for n in (4, 0, 7)]
    out = apply_poses(scans, poses)
    assert len(out) == 3 and all(isinstance(s, Scan) for s in out)
    for scan, world, pose in zip(scans, out, poses):
        expect = (pose @ np.c_[scan.points, np.ones(len(scan.points))].T).T[:, :3]
        assert_allclose(world.points, expect, atol=1e-12)
        assert_array_equal(world.origin, pose[:3, 3])  # origin = the sensor position
    # 3x4 poses, a generator of plain pairs, a sensor offset in the scan
    pairs = ((s.points, [1.0, 0.0, 0.0]) for s in scans)
    out34 = apply_poses(pairs, poses[:, :3])
    assert_allclose(out34[2].points, out[2].points, atol=1e-12)
    assert_allclose(out34[0].origin, poses[0, :3, :3] @ [1, 0, 0] + poses[0, :3, 3])
    assert_array_equal(scans[0].origin, 0.0)  # inputs untouched


def test_apply_poses_with_kitti_file(tmp_path):
    path = tmp_path / "poses.txt"
    path.write_text("1 0 0 10 0 1 0 0 0 0 1 0\n0 -1 0 0 1 0 0 5 0 0 1 0\n")
    scans = [Scan(np.array([[1.0, 0.0, 0.0]]), np.zeros(3))] * 2
    out = apply_poses(scans, read_kitti_poses(path))
    assert_allclose(out[0].points, [[11.0, 0.0, 0.0]])
    assert_allclose(out[1].points, [[0.0, 6.0, 0.0]])
    assert_array_equal(out[1].origin, [0.0, 5.0, 0.0])


def test_apply_poses_rejects_bad_poses():
    scans = [Scan(np.zeros((2, 3)), np.zeros(3))] * 2
    good = np.tile(np.eye(4), (2, 1, 1))
    with pytest.raises(ValueError, match=r"poses has 3 poses for 2 scans"):
        apply_poses(scans, np.tile(np.eye(4), (3, 1, 1)))
    with pytest.raises(ValueError, match=r"shape \(n_scans, 4, 4\) or \(n_scans, 3, 4\), got "
                       r"\(2, 4\)"):
        apply_poses(scans, np.eye(4)[:2])
    bad = good.copy()
    bad[1, 0, 0] = 1.5
    with pytest.raises(ValueError, match=r"poses\[1\]: the rotation part is not orthonormal"):
        apply_poses(scans, bad)
    bad = good.copy()
    bad[0, 2, 2] = -1.0  # a reflection
    with pytest.raises(ValueError, match=r"poses\[0\]: .*not orthonormal .*det -1"):
        apply_poses(scans, bad)
    bad = good.copy()
    bad[0, 3, 0] = 1.0
    with pytest.raises(ValueError, match=r"poses\[0\] must have last row \[0, 0, 0, 1\]"):
        apply_poses(scans, bad)
    bad = good.copy()
    bad[0, 0, 3] = np.nan
    with pytest.raises(ValueError, match=r"poses must be finite"):
        apply_poses(scans, bad)
    with pytest.raises(TypeError, match=r"got a pair \(read_tum_trajectory returns"):
        apply_poses(scans, (np.zeros(2), good))
    with pytest.raises(TypeError, match=r"poses must be an array of numbers"):
        apply_poses(scans, "poses")


def test_apply_poses_rejects_bad_scans():
    with pytest.raises(TypeError, match="got a single Scan"):
        apply_poses(Scan(np.zeros((1, 3)), np.zeros(3)), np.eye(4)[None])
    with pytest.raises(TypeError, match=r"scans must be an iterable of Scan, got int"):
        apply_poses(3, np.eye(4)[None])
    with pytest.raises(TypeError, match=r"scans\[0\] must be a Scan or a \(points, origin\) pair"):
        apply_poses([5], np.eye(4)[None])
    with pytest.raises(ValueError, match=r"scans\[0\].points must have shape \(n_points, 3\)"):
        apply_poses([(np.zeros((2, 2)), np.zeros(3))], np.eye(4)[None])
    with pytest.raises(ValueError, match=r"scans\[0\].origin must be finite"):
        apply_poses([(np.zeros((2, 3)), [np.nan, 0, 0])], np.eye(4)[None])
