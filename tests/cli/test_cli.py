"""The occgp command: the demo's methods (the demo itself: test_demo.py), map builds a map
from scan files."""

import io
import re

import numpy as np
import pytest

from occgp import AKIMap, BGKMap, KNNMap, OccupancyOctree
from occgp.cli._demo import STEREO_HISTORY, STEREO_KNN, STEREO_OCTREE, STEREO_RANGE
from occgp.maps import make_map
from occgp.cli import main
from occgp.cli._main import map_scans, mapping_methods, noisy_mapping_methods
from occgp.datasets import structured_room
from occgp.io import read_scans, write_pcd

KERNEL_METHODS = {"BGK", "AKIMap", "AKIMap (published)"}
STEREO_METHODS = {"octree, stereo", "k-NN, stereo", f"k-NN {STEREO_HISTORY} scans, stereo"}


def _build(spec):
    """The map of a demo method spec and the options of its insert_scan."""
    params = {k: v for k, v in spec.items() if k not in ("map", "insert")}
    return make_map(spec["map"], **params), spec.get("insert", {})


def test_mapping_methods_include_the_kernel_maps():
    methods = mapping_methods(0.2)
    assert KERNEL_METHODS | {"k-NN"} <= set(methods)
    assert {"octree (scan)", "octree (ray)", "grid (scan)", "grid (ray)"} <= set(methods)
    for name, spec in methods.items():
        (first, options), (second, _) = _build(spec), _build(spec)
        assert first is not second and callable(first.insert_scan), name
        assert first.resolution == 0.2, name
        assert options == ({"mode": "ray"} if "(ray)" in name else {}), name
    assert isinstance(_build(methods["BGK"])[0], BGKMap)
    assert _build(methods["AKIMap"])[0].variant == "occgp"
    assert _build(methods["AKIMap (published)"])[0].variant == "published"
    knn = _build(methods["k-NN"])[0]
    assert isinstance(knn, KNNMap) and knn.max_range == 8.0


def test_stereo_methods_cut_rays_alike_with_the_chosen_parameters():
    """The stereo table's octree and k-NN maps both cut rays at 4 m and take the
    parameters chosen on the tuning data sets."""
    methods = noisy_mapping_methods(0.2)
    assert set(methods) == STEREO_METHODS
    (octree, options), (knn, _) = _build(methods["octree, stereo"]), \
        _build(methods["k-NN, stereo"])
    multi = _build(methods[f"k-NN {STEREO_HISTORY} scans, stereo"])[0]
    assert isinstance(knn, KNNMap) and knn.max_range == STEREO_RANGE == 4.0
    assert knn.resolution == 0.2 and knn.history == 0 and multi.history == STEREO_HISTORY
    assert {k: knn.get_params()[k] for k in STEREO_KNN} == STEREO_KNN
    assert type(octree) is not KNNMap and octree.resolution == 0.2
    assert {k: octree.get_params()[k] for k in STEREO_OCTREE} == STEREO_OCTREE
    far = np.array([[6.0, 0.05, 0.05]])        # a return 6 m away: free up to 4 m only
    expected = OccupancyOctree(0.2, **STEREO_OCTREE).insert_scan(far, [0.05, 0.05, 0.05],
                                                                  max_range=4.0)
    octree.insert_scan(far, [0.05, 0.05, 0.05], **options)
    assert octree.num_leaves == expected.num_leaves > 0
    assert np.isnan(octree.occupancy([[5.0, 0.05, 0.05]]))[0]
    knn.insert_scan(far, [0.05, 0.05, 0.05])
    assert np.isnan(knn.occupancy([[5.0, 0.05, 0.05]]))[0]
    assert knn.occupancy([[3.0, 0.05, 0.05]])[0] < 0.5


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
        # both get it as their max_range: the longer beams cut there
        expected = (BGKMap(0.1, max_range=3.0) if method == "bgk"
                    else AKIMap(0.1, max_range=3.0, random_state=0))
        for s in scans:
            expected.update(s.points.astype(np.float64), s.origin)
        got, want = OccupancyOctree.load(out).leaves(), expected.to_octree().leaves()
        assert len(got.centers) == len(want.centers) > 0
        np.testing.assert_array_equal(np.sort(got.log_odds), np.sort(want.log_odds))
    capsys.readouterr()


@pytest.mark.parametrize("args, message", [
    (["map", "missing.pcd", "-o", "m.bt"], "occgp map: error:"),
    (["map", "x.pcd", "-o", "m.bt"], "occgp map: error: x.pcd"),
    (["map", "s.pcd", "-o", "nowhere/m.bt"],
     "occgp map: error: [Errno 2] output: no such folder for the map file: 'nowhere'"),
    (["map", "s.pcd", "-o", "m.bt", "--input-map", "missing.ot"],
     "occgp map: error: [Errno 2] No such file or directory: 'missing.ot'"),
    (["map", "s.pcd", "-o", "m.bt", "--poses", "x.pcd", "--poses-format", "kitti"],
     "occgp map: error: x.pcd: line 1: expected 12 numbers"),
    (["map", "s.pcd", "-o", "m.bt", "--poses", "binary.txt"],
     "occgp map: error: binary.txt: not a text file (invalid UTF-8)"),
])
def test_map_command_reports_errors(tmp_path, capsys, monkeypatch, args, message):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "x.pcd").write_text("not a pcd file of poses 1 2 3 4 5 6 7 8 9 10")
    (tmp_path / "binary.txt").write_bytes(b"\xff\xfe\x00")
    write_pcd(tmp_path / "s.pcd", [[1.0, 0.0, 0.0]], [0.0, 0.0, 0.0])
    assert main(args + ["--no-progress"]) == 1
    assert message in capsys.readouterr().err
    assert not (tmp_path / "m.bt").exists()


def test_map_command_builds_knn_map(tmp_path, capsys):
    paths, scans = _write_scans(tmp_path)
    out = tmp_path / "knn.ot"
    assert main(["map", *map(str, paths), "-o", str(out), "--method", "knn", "--k", "3",
                 "--max-range", "6", "--p-u", "0.9", "--p-m", "0.3",
                 "--occupancy-threshold", "0.6", "--cdf", "truncated", "--no-progress"]) == 0
    captured = capsys.readouterr()
    assert "2 scans, 1,000 points" in captured.out and "deprecated" not in captured.err
    params = dict(k=3, max_range=6.0, p_u=0.9, p_m=0.3, occupancy_threshold=0.6, cdf="truncated")
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
    ("--max-range", "0", r"argument --max-range: max_range must lie in \(0.0, "),
    ("--max-range", "nan", r"argument --max-range: max_range must lie in"),
    ("--max-range", "1e30", r"argument --max-range: max_range must lie in"),
    ("--p-u", "1.5", r"argument --p-u: p_u must lie in \(0.0, 1.0\), got 1.5"),
    ("--p-u", "0.3", r"argument --p-u/--p-l: .*must satisfy p_u >= p_l"),
    ("--p-l", "0.9", r"argument --p-u/--p-l: .*must satisfy p_u >= p_l"),
    ("--p-m", "0.4", r"argument --p-m-out/--p-m: .*must satisfy p_m_out >= p_m"),
    ("--p-m-out", "0.5", r"argument --p-m-out: p_m_out must be below 0.5"),
    ("--p-min", "0", r"argument --p-min: p_min must lie in \(0.0, 1.0\), got 0.0"),
    ("--p-min", "0.3", r"argument --p-m/--p-min: .*must satisfy p_m >= p_min"),
    ("--p-max", "0.4", r"argument --p-max/--occupancy-threshold: .*must satisfy "
     r"p_max >= occupancy_threshold"),
    ("--p-max", "1", r"argument --p-max: p_max must lie in \(0.0, 1.0\), got 1.0"),
    ("--occupancy-threshold", "inf", r"argument --occupancy-threshold: occupancy_threshold "
     r"must lie in \(0.0, 1.0\), got inf"),
    ("--cdf", "cauchy", r"argument --cdf: invalid choice: 'cauchy'"),
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
        main(["map", "x.pcd", "-o", "m.bt", "--method", method, "--k", "3",
              "--occupancy-threshold", "0.6"])
    assert exc.value.code == 2
    assert (f"argument --k/--occupancy-threshold: applies to --method knn only, got --method "
            f"{method}") in capsys.readouterr().err


def test_map_command_reads_the_deprecated_knn_options_with_a_note(tmp_path, capsys):
    paths, _ = _write_scans(tmp_path)
    new, old = tmp_path / "new.bt", tmp_path / "old.bt"
    assert main(["map", *map(str, paths), "-o", str(new), "--method", "knn",
                 "--max-range", "6", "--occupancy-threshold", "0.6", "--no-progress"]) == 0
    assert "deprecated" not in capsys.readouterr().err
    assert main(["map", *map(str, paths), "-o", str(old), "--method", "knn",
                 "--sensor-range", "6", "--p-t", "0.6", "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert ("occgp map: note: --sensor-range is deprecated and will be removed in the next "
            "release; use --max-range") in err
    assert "occgp map: note: --p-t is deprecated and will be removed in the next release; " \
        "use --occupancy-threshold" in err
    assert old.read_bytes() == new.read_bytes()


@pytest.mark.parametrize("args, message", [
    (["--method", "knn", "--sensor-range", "6", "--max-range", "5"],
     "argument --sensor-range: not with --max-range; give --max-range only"),
    (["--method", "knn", "--p-t", "0.6", "--occupancy-threshold", "0.6"],
     "argument --p-t: not with --occupancy-threshold; give --occupancy-threshold only"),
    (["--method", "bgk", "--sensor-range", "6"],
     "argument --sensor-range: applies to --method knn only (the range limit of every map is "
     "--max-range), got --method bgk"),
    (["--method", "knn", "--sensor-range", "0"],
     "argument --max-range: max_range must lie in (0.0, "),
])
def test_map_command_rejects_bad_deprecated_knn_options(tmp_path, capsys, monkeypatch,
                                                      args, message):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exc:
        main(["map", "x.pcd", "-o", "m.bt", *args])
    assert exc.value.code == 2
    assert message in capsys.readouterr().err


@pytest.mark.parametrize("kwargs, exc, message", [
    (dict(method="octree", knn_params={"k": 3}), ValueError,
     r"knn_params applies to method='knn' only, got method='octree'"),
    (dict(method="knn", max_range=3.0, knn_params={"max_range": 5.0}), ValueError,
     r"max_range is given twice: as max_range= and in knn_params"),
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


@pytest.mark.parametrize("method", ["gpom", "gp", "BGK"])
def test_map_command_rejects_unknown_method(tmp_path, capsys, monkeypatch, method):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exc:
        main(["map", "x.pcd", "-o", "m.bt", "--method", method])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "argument --method: invalid choice" in err and "octree" in err


# --------------------------------------------------------------------------- #
# occgp map: bags, poses, outputs, continuing a map, options
# --------------------------------------------------------------------------- #
def _leaves(tree):
    """(centers, log-odds) of a tree's leaves, sorted by center."""
    leaves = tree.leaves()
    order = np.lexsort(leaves.centers.T)
    return leaves.centers[order], leaves.log_odds[order]


def _assert_same_tree(got, want):
    assert got.num_leaves == want.num_leaves > 0
    for a, b in zip(_leaves(got), _leaves(want)):
        np.testing.assert_array_equal(a, b)


def _ros1_bag(path, clouds, translation):
    """A ROS 1 bag: /tf_static map -> lidar (a translation) and PointCloud2 clouds of
    float32 x y z in lidar on /points (header stamps 1 s, 2 s, ...)."""
    pytest.importorskip("rosbags", reason="the ros extra (rosbags) is not installed")
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms",
                                   "tf2_msgs/msg/TFMessage"))
    T = ts.types

    def header(sec, frame):
        return T["std_msgs/msg/Header"](seq=0, stamp=T["builtin_interfaces/msg/Time"](
            sec=sec, nanosec=0), frame_id=frame)

    tf = T["tf2_msgs/msg/TFMessage"](transforms=[T["geometry_msgs/msg/TransformStamped"](
        header=header(0, "map"), child_frame_id="lidar",
        transform=T["geometry_msgs/msg/Transform"](
            translation=T["geometry_msgs/msg/Vector3"](x=translation[0], y=translation[1],
                                                       z=translation[2]),
            rotation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)))])
    PF = T["sensor_msgs/msg/PointField"]
    with Writer(path) as writer:
        con_tf = writer.add_connection("/tf_static", "tf2_msgs/msg/TFMessage", typestore=ts)
        con_pc = writer.add_connection("/points", "sensor_msgs/msg/PointCloud2", typestore=ts)
        writer.write(con_tf, 1, ts.serialize_ros1(tf, "tf2_msgs/msg/TFMessage"))
        for i, points in enumerate(clouds, start=1):
            data = np.asarray(points, dtype="<f4").tobytes()
            msg = T["sensor_msgs/msg/PointCloud2"](
                header=header(i, "lidar"), height=1, width=len(points),
                fields=[PF(name=c, offset=4 * j, datatype=7, count=1)
                        for j, c in enumerate("xyz")],
                is_bigendian=False, point_step=12, row_step=12 * len(points),
                data=np.frombuffer(data, dtype=np.uint8), is_dense=False)
            writer.write(con_pc, i + 1, ts.serialize_ros1(msg, "sensor_msgs/msg/PointCloud2"))
    return path


def _wall_clouds(n=200, seed=0):
    """Two clouds of a wall 3 m ahead of the sensor (sensor frame), the first with two
    NaN points."""
    rng = np.random.default_rng(seed)
    clouds = []
    for x in (3.0, 3.2):
        pts = np.column_stack([np.full(n, x), rng.uniform(-1, 1, n), rng.uniform(-0.5, 0.5, n)])
        clouds.append(pts.astype(np.float32))
    clouds[0][[5, 17]] = np.nan
    return clouds


def test_map_command_maps_ros1_bag_posed_by_tf(tmp_path, capsys):
    clouds = _wall_clouds()
    bag = _ros1_bag(tmp_path / "s.bag", clouds, (1.0, 2.0, 0.5))
    out = tmp_path / "m.ot"
    assert main(["map", str(bag), "-o", str(out), "--fixed-frame", "map", "--topic",
                 "/points", "--sensor-frame", "lidar", "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert f"dropped 2 of 400 points of {bag} with a NaN or inf coordinate" in text
    assert "2 scans, 398 points → " in text and "wall time" in text
    expected = OccupancyOctree(0.1)
    for pts in clouds:
        pts = pts[np.isfinite(pts).all(axis=1)].astype(np.float64) + [1.0, 2.0, 0.5]
        expected.insert_scan(pts, [1.0, 2.0, 0.5])
    _assert_same_tree(OccupancyOctree.load(out), expected)
    # the default frames (the TF root, the cloud's frame) give the same map
    assert main(["map", str(bag), "-o", str(tmp_path / "d.ot"), "--no-progress"]) == 0
    _assert_same_tree(OccupancyOctree.load(tmp_path / "d.ot"), expected)
    capsys.readouterr()


def test_map_command_rejects_bad_bag_options(tmp_path, capsys):
    bag = _ros1_bag(tmp_path / "s.bag", _wall_clouds(), (0.0, 0.0, 0.0))
    assert main(["map", str(bag), "-o", str(tmp_path / "m.bt"), "--topic", "/nope",
                 "--no-progress"]) == 1
    assert re.search(r"occgp map: error: .*s\.bag: topic '/nope' is not in the bag",
                     capsys.readouterr().err)
    assert main(["map", str(bag), "-o", str(tmp_path / "m.bt"), "--fixed-frame", "world",
                 "--no-progress"]) == 1
    assert "world" in capsys.readouterr().err
    assert not (tmp_path / "m.bt").exists()


def _kitti_line(pose):
    return " ".join(f"{v:.17g}" for v in pose[:3].ravel())


def test_map_command_applies_kitti_and_tum_poses(tmp_path, capsys):
    """--poses moves each scan (given in the sensor frame) by its pose: the map's cells
    are those of the scans moved by hand, and not those of the unmoved scans."""
    clouds = [c[np.isfinite(c).all(axis=1)].astype(np.float64) for c in _wall_clouds()]
    paths = []
    for i, pts in enumerate(clouds):
        paths.append(tmp_path / f"s{i}.pcd")
        write_pcd(paths[-1], pts, np.zeros(3))
    yaw = np.pi / 2
    poses = np.array([np.eye(4), np.eye(4)])
    poses[0, :3, 3] = [5.0, 0.0, 0.0]
    poses[1, :3, :3] = [[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0],
                        [0, 0, 1]]
    poses[1, :3, 3] = [0.0, 4.0, 1.0]
    kitti = tmp_path / "poses.txt"
    kitti.write_text("\n".join(_kitti_line(p) for p in poses) + "\n")
    tum = tmp_path / "traj.txt"
    q = [(0, 0, 0, 1), (0, 0, np.sin(yaw / 2), np.cos(yaw / 2))]
    tum.write_text("# t x y z qx qy qz qw\n" + "".join(
        f"{i} {' '.join(map(repr, p[:3, 3].tolist()))} {' '.join(repr(float(v)) for v in qi)}\n"
        for i, (p, qi) in enumerate(zip(poses, q))))
    expected, unposed = OccupancyOctree(0.1), OccupancyOctree(0.1)
    for path, pose in zip(paths, poses):
        scan = read_scans(path)[0]
        pts = scan.points.astype(np.float64)
        expected.insert_scan(pts @ pose[:3, :3].T + pose[:3, 3], pose[:3, 3])
        unposed.insert_scan(pts, np.zeros(3))
    for poses_file, extra in ((kitti, []), (kitti, ["--poses-format", "kitti"]),
                              (tum, []), (tum, ["--poses-format", "tum"])):
        out = tmp_path / "m.ot"
        assert main(["map", *map(str, paths), "-o", str(out), "--poses", str(poses_file),
                     *extra, "--no-progress"]) == 0
        got = OccupancyOctree.load(out)
        if poses_file == tum:       # quaternion -> matrix rounding: same cells
            assert got.num_leaves == expected.num_leaves
            np.testing.assert_allclose(_leaves(got)[0], _leaves(expected)[0])
        else:
            _assert_same_tree(got, expected)
        assert not np.array_equal(_leaves(got)[0][:10], _leaves(unposed)[0][:10])
        # the wall of the first scan lies 8 m along x (5 m pose + 3 m ahead), not at 3 m
        assert got.is_occupied(clouds[0] + [5.0, 0.0, 0.0]).mean() > 0.9
        assert not got.is_occupied(clouds[0]).any()
    capsys.readouterr()


@pytest.mark.parametrize("method", ["octree", "bgk"])
def test_map_command_writes_ply_and_pcd(tmp_path, capsys, method):
    from occgp.io import read_pcd

    paths, scans = _write_scans(tmp_path)
    main(["map", *map(str, paths), "-o", str(tmp_path / "m.ot"), "--method", method,
          "--no-progress"])
    tree = OccupancyOctree.load(tmp_path / "m.ot")
    centers, _ = tree.extract_points(occupied=True)
    assert len(centers) > 50
    assert main(["map", *map(str, paths), "-o", str(tmp_path / "m.pcd"), "--method", method,
                 "--no-progress"]) == 0
    got = read_pcd(tmp_path / "m.pcd").points.astype(np.float64)
    np.testing.assert_allclose(got[np.lexsort(got.T)], centers[np.lexsort(centers.T)],
                               atol=1e-5)
    assert main(["map", *map(str, paths), "-o", str(tmp_path / "m.ply"), "--method", method,
                 "--no-progress"]) == 0
    data = (tmp_path / "m.ply").read_bytes()
    head = data[:data.index(b"end_header\n")].decode()
    assert head.startswith("ply\nformat binary_little_endian 1.0\n")
    assert f"element vertex {len(centers)}\n" in head
    assert "wrote " + str(tmp_path / "m.ply") in capsys.readouterr().out


def test_map_command_continues_input_map(tmp_path, capsys):
    paths, scans = _write_scans(tmp_path)
    first, both = tmp_path / "first.ot", tmp_path / "both.bt"
    assert main(["map", str(paths[0]), "-o", str(first), "--resolution", "0.2",
                 "--no-progress"]) == 0
    assert main(["map", str(paths[1]), "-o", str(both), "--input-map", str(first),
                 "--no-progress"]) == 0
    assert f"{first} + 1 scans, 500 points" in capsys.readouterr().out
    expected = OccupancyOctree(0.2)
    for s in scans:
        expected.insert_scan(s.points, s.origin)
    _assert_same_tree(OccupancyOctree.load(both),
                      OccupancyOctree.from_bytes(expected.to_bytes("bt")))
    # a kernel map continues from its .npz exactly (evidence and random stream)
    assert main(["map", str(paths[0]), "-o", str(tmp_path / "a.npz"), "--method", "akimap",
                 "--no-progress"]) == 0
    assert main(["map", str(paths[1]), "-o", str(tmp_path / "b.npz"), "--method", "akimap",
                 "--input-map", str(tmp_path / "a.npz"), "--no-progress"]) == 0
    want = AKIMap(0.1, random_state=0)
    for s in scans:
        want.update(s.points, s.origin)
    got = AKIMap.load(tmp_path / "b.npz")
    assert got.num_cells == want.num_cells > 0
    for a, b in zip(got.cells(), want.cells()):
        np.testing.assert_array_equal(a, b)
    # a BGK file is not an AKIMap: a clean error naming the input map
    assert main(["map", str(paths[1]), "-o", str(tmp_path / "c.bt"), "--method", "bgk",
                 "--input-map", str(tmp_path / "a.npz"), "--no-progress"]) == 1
    assert re.search(r"occgp map: error: input_map: cannot continue it as a bgk map: .*a\.npz",
                     capsys.readouterr().err)


def test_map_command_reports_beams_beyond_max_range(tmp_path, capsys):
    paths, scans = _write_scans(tmp_path)
    ends = np.concatenate([s.points.astype(np.float64) - s.origin for s in scans])
    far = int(np.count_nonzero(np.linalg.norm(ends, axis=1) > 3.0))
    assert 0 < far < len(ends)
    # BGK's beams: one per 0.1 m cube holding end points, to their centroid
    kept = dropped = 0
    for s in scans:
        pts = s.points.astype(np.float64)
        _, inverse, counts = np.unique(np.floor(pts / 0.1), axis=0, return_inverse=True,
                                       return_counts=True)
        sums = np.zeros((len(counts), 3))
        np.add.at(sums, inverse.ravel(), pts)
        beyond = np.linalg.norm(sums / counts[:, None] - s.origin, axis=1) > 3.0
        kept, dropped = kept + int((~beyond).sum()), dropped + int(beyond.sum())
    assert 0 < dropped < kept
    assert main(["map", *map(str, paths), "-o", str(tmp_path / "m.bt"), "--method", "bgk",
                 "--max-range", "3", "--n-jobs", "2", "--no-progress"]) == 0
    assert (f"{far:,} of 1,000 points lie beyond max_range 3 m: BGK cut {dropped:,} of "
            f"its {kept + dropped:,} beams (to the end points' centroids per cube of "
            f"ds_resolution) there (free space only)") in capsys.readouterr().out
    # la3dm's rule, asked for: the same beams dropped whole
    assert main(["map", *map(str, paths), "-o", str(tmp_path / "m.bt"), "--method", "bgk",
                 "--max-range", "3", "--param", "far_beams=drop", "--no-progress"]) == 0
    assert (f"{far:,} of 1,000 points lie beyond max_range 3 m: BGK dropped {dropped:,} of "
            f"its {kept + dropped:,} beams") in capsys.readouterr().out
    assert main(["map", *map(str, paths), "-o", str(tmp_path / "m.bt"), "--method", "akimap",
                 "--max-range", "3", "--no-progress"]) == 0
    assert (f"{far:,} of 1,000 points lie beyond max_range 3 m: AKIMap cut their beams "
            f"there (free space only)") in capsys.readouterr().out
    assert main(["map", *map(str, paths), "-o", str(tmp_path / "m.bt"), "--max-range", "3",
                 "--no-progress"]) == 0
    assert f"{far:,} of 1,000 points lie beyond max_range 3 m: their rays were cut" in \
        capsys.readouterr().out


def test_map_command_progress_bar_counts_every_step(tmp_path, capsys):
    paths, _ = _write_scans(tmp_path)
    out = io.StringIO()
    map_scans(paths, tmp_path / "m.ply", method="bgk", progress=True, out=out)
    err = capsys.readouterr().err
    # 2 files read + 2 scans + the conversion + the save
    assert "6/6" in err and "writing m.ply" in err
    assert "wall time" in out.getvalue()


def test_map_help_shows_every_default():
    from occgp.cli._main import _parser

    parser = _parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    for name in ("map", "demo"):
        for action in sub.choices[name]._actions:
            if action.option_strings and action.dest != "help":
                assert "default" in action.help, (name, action.option_strings)


@pytest.mark.parametrize("args, message", [
    (["-o", "m.png"], r"argument -o/--output: output must end in .bt, .ot, .ply or .pcd for "
     r"method='octree', got 'm.png'"),
    (["-o", "m.npz"], r"argument -o/--output: .* \(.npz: grid, bgk, akimap and gp-grid "
     r"only\), got 'm.npz'"),
    (["-o", "m.npz", "--method", "knn"], r"argument -o/--output: .*method='knn'"),
    (["-o", "m.bt", "--method", "bgk", "--mode", "ray"],
     r"argument --mode: mode applies to method='octree' or 'grid' only"),
    (["-o", "m.bt", "--method", "akimap", "--max-range", "0"],
     r"argument --max-range: max_range must lie in \(0.0, inf\), got 0.0"),
    (["-o", "m.bt", "--resolution", "0"], r"argument --resolution: resolution"),
    (["-o", "m.bt", "--resolution", "nan"], r"argument --resolution: resolution"),
    (["-o", "m.bt", "--n-jobs", "0"], r"argument --n-jobs: n_jobs must be None, a positive "
     r"int or a negative int"),
    (["-o", "m.bt", "--n-jobs", "x"], r"argument --n-jobs: invalid int value"),
    (["-o", "m.bt", "--poses-format", "kitti"],
     r"argument --poses-format: poses_format applies with poses only"),
    (["-o", "m.bt", "--poses", "p.txt", "--poses-format", "euroc"],
     r"argument --poses-format: invalid choice"),
    (["-o", "m.bt", "--poses", "bad.txt"], r"argument --poses: cannot tell the format of "
     r"poses file 'bad.txt': line 2 has 3 columns; expected 12 \(kitti"),
    (["-o", "m.bt", "--poses", "three.txt"], r"argument --poses: poses file 'three.txt' holds "
     r"3 poses for 1 scans; expected one pose per scan"),
    (["-o", "m.bt", "--topic", "/points"], r"argument --topic: topic applies to ROS bag "
     r"inputs only"),
    (["-o", "m.bt", "--fixed-frame", "map"], r"argument --fixed-frame: fixed_frame applies"),
    (["-o", "m.bt", "--tf-tolerance", "-1"], r"argument --tf-tolerance: tf_tolerance must"),
    (["-o", "m.bt", "--input-map", "m.npz"], r"argument --input-map: input_map must be a .bt "
     r"or .ot file to continue a octree map, got 'm.npz'"),
    (["-o", "m.bt", "--method", "bgk", "--input-map", "m.ot"],
     r"argument --input-map: input_map must be a .npz file to continue a bgk map"),
    (["-o", "m.bt", "--input-map", "in.ot", "--resolution", "0.3"],
     r"argument --resolution: resolution 0.3 differs from that of input_map 'in.ot' \(0.2\)"),
    (["-o", "m.bt", "--fields", "x:f4,y"], r"argument --fields: expected an int"),
    (["-o", "m.bt", "--fields", "x:q9"], r"argument --fields: expected an int"),
])
def test_map_command_rejects_bad_options(tmp_path, capsys, monkeypatch, args, message):
    monkeypatch.chdir(tmp_path)
    write_pcd("s.pcd", [[1.0, 0.0, 0.0], [2.0, 0.5, 0.0]], [0.0, 0.0, 0.0])
    (tmp_path / "bad.txt").write_text("# comment\n1 2 3\n")
    (tmp_path / "three.txt").write_text("1 0 0 0 0 1 0 0 0 0 1 0\n" * 3)
    OccupancyOctree(0.2).insert_scan([[1.0, 0, 0]], [0, 0, 0]).save("in.ot")
    with pytest.raises(SystemExit) as exc:
        main(["map", "s.pcd", *args, "--no-progress"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("usage: occgp map") and re.search(message, err), err
    assert not (tmp_path / "m.bt").exists() and not (tmp_path / "m.npz").exists()


@pytest.mark.parametrize("kwargs, exc, message", [
    (dict(output="m.txt"), ValueError, r"output must end in .bt, .ot, .ply or .pcd"),
    (dict(n_jobs=0), ValueError, r"n_jobs must be None"),
    (dict(poses_format="tum"), ValueError, r"poses_format applies with poses only"),
    (dict(topic="/x"), ValueError, r"topic applies to ROS bag inputs only"),
    (dict(tf_tolerance="1"), TypeError, r"tf_tolerance"),
    (dict(resolution=-1.0), ValueError, r"resolution"),
    (dict(input_map="m.bt", method="akimap"), ValueError, r"input_map must be a .npz file"),
])
def test_map_scans_checks_arguments_before_reading(tmp_path, kwargs, exc, message):
    kwargs = {"output": tmp_path / "m.bt", **kwargs}
    with pytest.raises(exc, match=message):
        map_scans([tmp_path / "missing.pcd"], **kwargs)
    assert not (tmp_path / "m.bt").exists()


@pytest.mark.parametrize("fields, records", [
    ("3", lambda p: p.astype("<f4")),
    ("x:<f8,y:<f8,z:<f8,t:<u4", lambda p: np.rec.fromarrays(
        [p[:, 0], p[:, 1], p[:, 2], np.arange(len(p), dtype="<u4")],
        dtype=[("x", "<f8"), ("y", "<f8"), ("z", "<f8"), ("t", "<u4")])),
])
def test_map_command_reads_bin_records_with_fields(tmp_path, capsys, fields, records):
    pts = _wall_clouds()[1].astype(np.float64)
    (tmp_path / "s.bin").write_bytes(records(pts).tobytes())
    assert main(["map", str(tmp_path / "s.bin"), "-o", str(tmp_path / "m.ot"), "--fields",
                 fields, "--no-progress"]) == 0
    assert "1 scans, 200 points" in capsys.readouterr().out
    expected = OccupancyOctree(0.1).insert_scan(
        pts.astype(np.float32) if fields == "3" else pts, np.zeros(3))
    _assert_same_tree(OccupancyOctree.load(tmp_path / "m.ot"), expected)


HUGE = "1" + "0" * 400


@pytest.mark.parametrize("args, message", [
    # a parameter with an option of its own is refused, not silently overwritten
    (["--param", "resolution=0.5"], r"argument --param: params names 'resolution' \(= 0\.5\), "
     r"which has its own option: give it there \(--resolution; map_scans' resolution=\)"),
    (["--param", "resolution=abc"], r"params names 'resolution' .*--resolution"),
    (["--method", "bgk", "--param", "n_jobs=0"], r"params names 'n_jobs' .*--n-jobs"),
    (["--method", "bgk", "--param", "max_range=5"], r"params names 'max_range' .*--max-range"),
    (["--method", "knn", "--param", "k=3"], r"params names 'k' .*\(--k; map_scans' knn_params\)"),
    # bad values: checked by the map before any scan is read
    (["--param", f"prob_hit={HUGE}"],
     r"argument --param: prob_hit must lie in \(0\.5, 1\.0\), got an int of about 401 digits"),
    (["--param", "prob_hit=abc"], r"argument --param: prob_hit must be a real number, got str"),
    (["--param", "prob_hit=True"], r"argument --param: prob_hit must be a real number, got bool"),
    (["--param", "nope=1"], r"argument --param: the 'octree' map takes no parameter 'nope'"),
    (["--method", "bgk", "--param", "ell=-1"], r"argument --param: ell must lie in \(0\.0, inf\)"),
    (["--method", "knn", "--param", "history=-1"], r"argument --param: history must"),
    # a map that checks its parameters at its first update (the GP grid): probed first
    (["--method", "gp-grid", "--param", "prob_hit=0.2"],
     r"argument --param: prob_hit must lie in \(0\.5, 1\.0\), got 0\.2"),
])
def test_map_command_refuses_bad_params_before_any_work(tmp_path, capsys, monkeypatch, args,
                                                        message):
    """--param: exit code 2 and one error line naming the parameter, never a traceback, and
    before any scan is read (the scan file does not exist)."""
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exc:
        main(["map", "missing.pcd", "-o", "m.bt", "--no-progress", *args])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert lines[0].startswith("usage: occgp map") and "Traceback" not in err
    assert lines[-1].startswith("occgp map: error: argument --param: ")
    assert re.search(message, lines[-1]), err
    assert not (tmp_path / "m.bt").exists()


def test_map_command_honours_good_params(tmp_path):
    paths, scans = _write_scans(tmp_path)
    out = tmp_path / "m.ot"          # log-odds (a .bt file keeps only the states)
    assert main(["map", *map(str, paths), "-o", str(out), "--resolution", "0.2", "--param",
                 "prob_hit=0.9", "--no-progress"]) == 0
    tree = OccupancyOctree.load(out)
    expected = OccupancyOctree(0.2, prob_hit=0.9)
    for scan in scans:
        expected.insert_scan(scan.points, scan.origin)
    hits = np.vstack([s.points for s in scans])
    assert tree.resolution == 0.2
    # two scans at the default prob_hit=0.7 reach at most p = 0.845
    assert tree.occupancy(hits).max() >= 0.9 - 1e-6
    np.testing.assert_allclose(tree.occupancy(hits), expected.occupancy(hits), atol=1e-6)


def test_map_scans_refuses_params_set_by_its_own_arguments(tmp_path):
    write_pcd(tmp_path / "s.pcd", [[1.0, 0.0, 0.0]], [0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match=r"params names 'resolution' \(= 0\.5\)"):
        map_scans([tmp_path / "s.pcd"], tmp_path / "m.bt", params={"resolution": 0.5})
    with pytest.raises(TypeError, match="prob_hit must be a real number, got str"):
        map_scans([tmp_path / "s.pcd"], tmp_path / "m.bt", params={"prob_hit": "0.7"})
    with pytest.raises(TypeError, match="params must be a mapping of constructor parameters"):
        map_scans([tmp_path / "s.pcd"], tmp_path / "m.bt", params=[("prob_hit", 0.7)])
    assert not (tmp_path / "m.bt").exists()
