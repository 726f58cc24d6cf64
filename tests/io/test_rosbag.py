"""Tests of occgp.io's ROS bag reader (PointCloud2 scans posed by TF)."""

import sys
import warnings

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from conftest import data_path

rosbags = pytest.importorskip("rosbags", reason="the ros extra (rosbags) is not installed")

from rosbags.rosbag1 import Writer as Writer1  # noqa: E402
from rosbags.rosbag2 import StoragePlugin, Writer as Writer2  # noqa: E402
from rosbags.typesys import Stores, get_types_from_msg, get_typestore  # noqa: E402

from occgp.io import Scan  # noqa: E402
from occgp.io import read_rosbag  # noqa: E402

TS1 = get_typestore(Stores.ROS1_NOETIC)
TS1.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms",
                                "tf2_msgs/msg/TFMessage"))
TS2 = get_typestore(Stores.ROS2_HUMBLE)
PC2, TFM = "sensor_msgs/msg/PointCloud2", "tf2_msgs/msg/TFMessage"
S = 1_000_000_000  # ns per second


# --------------------------------------------------------------------------- #
# writing small bags
# --------------------------------------------------------------------------- #
def _header(ts, stamp, frame):
    T = ts.types
    time = T["builtin_interfaces/msg/Time"](sec=stamp // S, nanosec=stamp % S)
    extra = {"seq": 0} if "seq" in T["std_msgs/msg/Header"].__dataclass_fields__ else {}
    return T["std_msgs/msg/Header"](stamp=time, frame_id=frame, **extra)


def cloud(ts, stamp, frame, data, fields, point_step, width, height=1, row_step=None,
          bigendian=False, dense=True):
    """A PointCloud2; `fields` is [(name, offset, datatype)]."""
    PF = ts.types["sensor_msgs/msg/PointField"]
    return ts.types[PC2](
        header=_header(ts, stamp, frame), height=height, width=width,
        fields=[PF(name=n, offset=o, datatype=d, count=1) for n, o, d in fields],
        is_bigendian=bigendian, point_step=point_step,
        row_step=width * point_step if row_step is None else row_step,
        data=np.frombuffer(bytes(data), dtype=np.uint8), is_dense=dense)


def xyz32(points, frame="lidar", stamp=2 * S, ts=TS1):
    """A plain little-endian float32 x y z cloud."""
    data = np.asarray(points, dtype="<f4").tobytes()
    return cloud(ts, stamp, frame, data, [("x", 0, 7), ("y", 4, 7), ("z", 8, 7)], 12,
                 len(points))


def tf_msg(ts, transforms):
    """TFMessage of [(stamp, parent, child, (tx, ty, tz), (qx, qy, qz, qw))]."""
    T = ts.types
    out = []
    for stamp, parent, child, t, q in transforms:
        out.append(T["geometry_msgs/msg/TransformStamped"](
            header=_header(ts, stamp, parent), child_frame_id=child,
            transform=T["geometry_msgs/msg/Transform"](
                translation=T["geometry_msgs/msg/Vector3"](x=t[0], y=t[1], z=t[2]),
                rotation=T["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]))))
    return T[TFM](transforms=out)


def write_bag(path, messages, ros=1):
    """Write [(topic, msgtype, message)] (bag time = index) as a ROS 1 or ROS 2 bag."""
    ts = TS1 if ros == 1 else TS2
    if ros == 1:
        writer = Writer1(path)
    else:
        plugin = StoragePlugin.MCAP if ros == "mcap" else StoragePlugin.SQLITE3
        writer = Writer2(path, version=9, storage_plugin=plugin)
    cons = {}
    with writer:
        for i, (topic, msgtype, msg) in enumerate(messages):
            if topic not in cons:
                cons[topic] = writer.add_connection(topic, msgtype, typestore=ts)
            raw = ts.serialize_ros1(msg, msgtype) if ros == 1 else ts.serialize_cdr(msg, msgtype)
            writer.write(cons[topic], i + 1, raw)
    return path


def yaw_q(angle):
    return (0.0, 0.0, np.sin(angle / 2), np.cos(angle / 2))


def rz(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def chain_bag(path, ros=1, stamps=(2 * S,), points=((1.0, 0.0, 0.0),)):
    """odom -(dynamic)-> base_link -(static)-> lidar, and clouds in lidar."""
    ts = TS1 if ros == 1 else TS2
    msgs = [
        ("/tf_static", TFM, tf_msg(ts, [(0, "base_link", "lidar", (0, 0, 1), yaw_q(np.pi / 2))])),
        ("/tf", TFM, tf_msg(ts, [(1 * S, "odom", "base_link", (0, 0, 0), yaw_q(0.0))])),
        ("/tf", TFM, tf_msg(ts, [(3 * S, "odom", "base_link", (2, 0, 0), yaw_q(np.pi / 2))])),
    ]
    msgs += [("/points", PC2, xyz32(points, "lidar", s, ts)) for s in stamps]
    return write_bag(path, msgs, ros)


# --------------------------------------------------------------------------- #
# the akimap sample bag
# --------------------------------------------------------------------------- #
def test_akimap_sample_bag_has_73_posed_clouds():
    bag = data_path("akimap_sample", "sample.bag")
    scans = read_rosbag(bag, fixed_frame="map", sensor_frame="camera")
    assert (scans.topic, scans.fixed_frame, scans.sensor_frame) == ("/pointcloud_in", "map",
                                                                     "camera")
    assert len(scans) == 73
    listed = list(scans)
    assert len(listed) == 73 and all(isinstance(s, Scan) for s in listed)
    sizes = [s.points.shape[0] for s in listed]
    assert min(sizes) == 1193 and max(sizes) == 2058
    assert scans.n_points == sum(sizes) and scans.n_dropped == 0
    assert all(np.isfinite(s.points).all() for s in listed)
    origins = np.array([s.origin for s in listed])
    # LOAM odometry: the camera drives about 5 m along map x
    assert np.linalg.norm(origins[-1] - origins[0]) > 4.5
    assert np.all(np.linalg.norm(np.diff(origins, axis=0), axis=1) < 0.5)  # no jumps
    # the sensor lies inside its own scan's bounding box (x, y)
    for s in listed[::12]:
        lo, hi = s.points.min(axis=0), s.points.max(axis=0)
        assert np.all(lo[:2] < s.origin[:2]) and np.all(s.origin[:2] < hi[:2])


def test_akimap_sample_bag_default_frames_and_hand_decoding():
    bag = data_path("akimap_sample", "sample.bag")
    scans = read_rosbag(bag)  # the only PointCloud2 topic, the root of its TF tree
    assert scans.fixed_frame == "map" and scans.sensor_frame is None
    first = next(iter(scans))
    assert_array_equal(first.origin, 0.0)  # map -> camera_init has no translation
    # by hand: x y z float32 at offsets 0, 4, 8 of a 32-byte point, then map <- camera_init
    from rosbags.highlevel import AnyReader
    from scipy.spatial.transform import Rotation

    with AnyReader([bag]) as reader:
        con = next(c for c in reader.connections if c.topic == "/pointcloud_in")
        _, _, raw = next(reader.messages(connections=[con]))
        msg = reader.deserialize(raw, con.msgtype)
    raw_xyz = np.frombuffer(msg.data.tobytes(), dtype="<f4").reshape(-1, 8)[:, :3]
    rot = Rotation.from_quat([0.4999999999995599, 0.4999993366025517, 0.4999999999995599,
                              0.5000006633974483]).as_matrix()
    assert_allclose(first.points, raw_xyz.astype(np.float64) @ rot.T, atol=1e-12)


def test_akimap_sample_bag_frames():
    bag = data_path("akimap_sample", "sample.bag")
    with pytest.raises(ValueError, match=r"fixed_frame 'world' is not a frame of the TF tree.*"
                       r"\['base_link', 'camera', 'camera_init', 'map'\]"):
        read_rosbag(bag, fixed_frame="world")
    with pytest.raises(ValueError, match=r"topic '/tf' is not PointCloud2.*\['/pointcloud_in'\]"):
        read_rosbag(bag, topic="/tf")
    # leading slashes are ignored, as tf2 does
    assert read_rosbag(bag, fixed_frame="/camera_init").fixed_frame == "camera_init"


# --------------------------------------------------------------------------- #
# field layouts
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("ros", [1, 2])
def test_float64_fields(tmp_path, ros):
    ts = TS1 if ros == 1 else TS2
    pts = np.array([[1.0 + 1e-12, 2.0, 3.0], [-4.0, 5.5, 1e-300]])
    msg = cloud(ts, S, "lidar", pts.astype("<f8").tobytes(),
                [("x", 0, 8), ("y", 8, 8), ("z", 16, 8)], 24, 2)
    bag = write_bag(tmp_path / ("b.bag" if ros == 1 else "b"), [("/p", PC2, msg)], ros)
    with pytest.warns(UserWarning, match="no TF"):
        [scan] = read_rosbag(bag)
    assert_array_equal(scan.points, pts)  # float64 exactly
    assert_array_equal(scan.origin, 0.0)


def test_big_endian_with_a_leading_field_and_padding(tmp_path):
    pts = np.array([[1.5, -2.0, 3.25], [0.0, 7.0, -8.5], [9.0, 10.0, 11.0]], dtype=np.float32)
    rec = np.dtype({"names": ["intensity", "x", "y", "z"], "formats": [">f4"] * 4,
                    "offsets": [0, 4, 8, 12], "itemsize": 20})
    arr = np.zeros(3, dtype=rec)
    arr["intensity"] = 99.0
    arr["x"], arr["y"], arr["z"] = pts.T
    msg = cloud(TS1, S, "lidar", arr.tobytes(),
                [("intensity", 0, 7), ("x", 4, 7), ("y", 8, 7), ("z", 12, 7)], 20, 3,
                bigendian=True)
    bag = write_bag(tmp_path / "b.bag", [("/p", PC2, msg)])
    with pytest.warns(UserWarning):
        [scan] = read_rosbag(bag, topic="/p")
    assert_array_equal(scan.points, pts.astype(np.float64))


def test_organised_cloud_with_row_padding_and_extra_fields(tmp_path):
    # 2 x 3 organised cloud, z y x order, a uint16 ring, 16-byte points, 8 pad bytes per row
    rec = np.dtype({"names": ["z", "y", "x", "ring"], "formats": ["<f4", "<f4", "<f4", "<u2"],
                    "offsets": [0, 4, 8, 12], "itemsize": 16})
    rows = []
    expect = []
    for r in range(2):
        arr = np.zeros(3, dtype=rec)
        arr["x"] = np.arange(3) + 10 * r
        arr["y"] = -np.arange(3)
        arr["z"] = 0.5 * r
        arr["ring"] = 7
        rows.append(arr.tobytes() + b"\xee" * 8)
        expect.append(np.column_stack([arr["x"], arr["y"], arr["z"]]))
    msg = cloud(TS2, S, "lidar", b"".join(rows),
                [("z", 0, 7), ("y", 4, 7), ("x", 8, 7), ("ring", 12, 4)], 16, 3, height=2,
                row_step=56)
    bag = write_bag(tmp_path / "b", [("/p", PC2, msg)], ros=2)
    with pytest.warns(UserWarning):
        [scan] = read_rosbag(bag)
    assert_array_equal(scan.points, np.vstack(expect))


def test_non_dense_cloud_drops_and_counts_nan_and_inf(tmp_path, caplog):
    pts = [[1, 2, 3], [np.nan, 0, 0], [4, 5, 6], [0, np.inf, 0], [7, 8, 9]]
    msg = xyz32(pts)
    msg.is_dense = False
    bag = write_bag(tmp_path / "b.bag", [("/p", PC2, msg)] * 2)
    scans = read_rosbag(bag, fixed_frame="lidar")  # the cloud frame: no TF needed
    with caplog.at_level("WARNING", logger="occgp"):
        listed = list(scans)
    assert len(listed) == 2
    assert_array_equal(listed[0].points, [[1, 2, 3], [4, 5, 6], [7, 8, 9]])
    assert (scans.n_points, scans.n_dropped) == (10, 4)
    assert "dropped 4 of 10 points" in caplog.text


def test_empty_cloud(tmp_path):
    bag = write_bag(tmp_path / "b.bag", [("/p", PC2, xyz32(np.zeros((0, 3))))])
    [scan] = read_rosbag(bag, fixed_frame="lidar")
    assert scan.points.shape == (0, 3)


# --------------------------------------------------------------------------- #
# TF
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("ros, storage_file", [(1, None), (2, None), (2, "*.db3"),
                                               ("mcap", None), ("mcap", "*.mcap")])
def test_two_level_chain_static_and_dynamic_interpolated(tmp_path, ros, storage_file):
    name = "b.bag" if ros == 1 else "b"
    bag = chain_bag(tmp_path / name, ros, stamps=(2 * S, 1 * S + S // 2, 3 * S))
    if storage_file:  # a ROS 2 storage file read on its own
        bag = next(bag.glob(storage_file))
    scans = read_rosbag(bag, "/points")
    assert scans.fixed_frame == "odom"
    got = list(scans)
    for scan, alpha in zip(got, (0.5, 0.25, 1.0)):
        # by hand: odom <- base_link at alpha is (2 alpha, 0, 0) and yaw alpha * 90 deg;
        # base_link <- lidar is (0, 0, 1) and yaw 90 deg
        yaw = alpha * np.pi / 2
        origin = rz(yaw) @ [0.0, 0.0, 1.0] + [2 * alpha, 0.0, 0.0]
        point = rz(yaw) @ rz(np.pi / 2) @ [1.0, 0.0, 0.0] + origin
        assert_allclose(scan.origin, origin, atol=1e-12)
        assert_allclose(scan.points, [point], atol=1e-12)
    assert_allclose(got[0].points, [[1 - np.sqrt(0.5), np.sqrt(0.5), 1.0]], atol=1e-12)


def test_sensor_frame_and_fixed_frame_inside_the_chain(tmp_path):
    bag = chain_bag(tmp_path / "b.bag")
    [scan] = read_rosbag(bag, fixed_frame="base_link")  # static edge only
    assert_allclose(scan.points, [[0.0, 1.0, 1.0]], atol=1e-12)
    assert_allclose(scan.origin, [0.0, 0.0, 1.0])
    [scan] = read_rosbag(bag, fixed_frame="odom", sensor_frame="base_link")
    assert_allclose(scan.origin, [1.0, 0.0, 0.0], atol=1e-12)
    # fixed frame below the cloud frame: the inverse chain
    bag2 = write_bag(tmp_path / "c.bag", [
        ("/tf_static", TFM, tf_msg(TS1, [(0, "lidar", "cam", (1, 0, 0), yaw_q(0))])),
        ("/p", PC2, xyz32([[0.0, 0.0, 0.0]]))])
    [scan] = read_rosbag(bag2, fixed_frame="cam")
    assert_allclose(scan.points, [[-1.0, 0.0, 0.0]])


def test_stamp_outside_the_tf_data(tmp_path):
    bag = chain_bag(tmp_path / "b.bag", stamps=(4 * S,))
    scans = read_rosbag(bag)
    with pytest.raises(ValueError, match=r"stamp 4.000000000 s lies outside the TF data of "
                       r"'odom' -> 'base_link' \(1.000000000 s to 3.000000000 s"):
        list(scans)
    [scan] = read_rosbag(bag, tf_tolerance=1.5)  # the last transform, not extrapolated
    assert_allclose(scan.origin, [2.0, 0.0, 1.0], atol=1e-12)


def test_frames_not_connected_or_unknown(tmp_path):
    bag = write_bag(tmp_path / "b.bag", [
        ("/tf_static", TFM, tf_msg(TS1, [(0, "base", "lidar", (0, 0, 0), yaw_q(0)),
                                         (0, "map", "other", (0, 0, 0), yaw_q(0))])),
        ("/p", PC2, xyz32([[1.0, 0.0, 0.0]]))])
    with pytest.raises(ValueError, match=r"fixed_frame 'map' and the cloud frame 'lidar' are "
                       r"not connected"):
        read_rosbag(bag, fixed_frame="map")
    with pytest.raises(ValueError, match=r"sensor_frame 'nope' is not a frame"):
        read_rosbag(bag, fixed_frame="base", sensor_frame="nope")
    with pytest.raises(ValueError, match=r"fixed_frame 'nope' is not a frame"):
        read_rosbag(bag, fixed_frame="nope")


def test_bag_without_tf_warns_once_and_rejects_frames(tmp_path):
    bag = write_bag(tmp_path / "b.bag", [("/p", PC2, xyz32([[1.0, 2.0, 3.0]]))] * 3)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scans = list(read_rosbag(bag))
    assert [str(w.message) for w in caught if w.category is UserWarning] == [
        f"{bag}: the bag has no TF (/tf, /tf_static): points stay in the sensor frame 'lidar' "
        "and every scan's origin is (0, 0, 0)"]
    assert len(scans) == 3
    assert_array_equal(scans[2].points, [[1.0, 2.0, 3.0]])
    assert_array_equal(scans[2].origin, 0.0)
    with pytest.raises(ValueError, match=r"no /tf or /tf_static transforms.*fixed_frame 'odom'"):
        read_rosbag(bag, fixed_frame="odom")


# --------------------------------------------------------------------------- #
# a sensor origin that never moves while TF does (registered clouds)
# --------------------------------------------------------------------------- #
def _user_warnings(fn):
    """fn()'s result and the messages of the UserWarnings it emitted."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = fn()
    return out, [str(w.message) for w in caught if issubclass(w.category, UserWarning)]


def registered_bag(path, edge_moves=True, stamps=(S, 2 * S, 3 * S)):
    """Clouds already in odom (as LOAM publishes them); odom -> base_link on /tf (moving
    or not), base_link -> lidar static."""
    end = (2, 0, 0) if edge_moves else (0, 0, 0)
    msgs = [
        ("/tf_static", TFM, tf_msg(TS1, [(0, "base_link", "lidar", (0, 0, 1), yaw_q(0.0))])),
        ("/tf", TFM, tf_msg(TS1, [(1 * S, "odom", "base_link", (0, 0, 0), yaw_q(0.0))])),
        ("/tf", TFM, tf_msg(TS1, [(3 * S, "odom", "base_link", end, yaw_q(0.0))])),
    ]
    msgs += [("/points", PC2, xyz32([[5.0, 0.0, 0.0]], "odom", s)) for s in stamps]
    return write_bag(path, msgs)


@pytest.mark.slow
def test_akimap_sample_bag_warns_that_the_sensor_never_moves():
    bag = data_path("akimap_sample", "sample.bag")
    scans, messages = _user_warnings(lambda: list(read_rosbag(bag)))
    assert len(scans) == 73
    assert_array_equal([s.origin for s in scans], 0.0)
    assert messages == [
        f"{bag}: the sensor origin is the same point [0.0, 0.0, 0.0] in all 73 clouds of "
        "/pointcloud_in: the origin of their frame 'camera_init' (the default sensor frame), "
        "fixed in 'map', while TF frame(s) 'camera', 'base_link' move in 'map'. Clouds "
        "published already registered (in an odometry frame, as LOAM's are) need the "
        "sensor's own frame: pass it as sensor_frame= (occgp map --sensor-frame), e.g. "
        "'camera'"]
    _, messages = _user_warnings(lambda: list(read_rosbag(bag, sensor_frame="camera")))
    assert messages == []
    # a partial read cannot tell: no warning
    _, messages = _user_warnings(lambda: next(iter(read_rosbag(bag))))
    assert messages == []


def test_registered_clouds_warn_without_sensor_frame(tmp_path):
    bag = registered_bag(tmp_path / "r.bag")
    scans, messages = _user_warnings(lambda: list(read_rosbag(bag)))
    assert_array_equal([s.origin for s in scans], 0.0)
    [message] = messages
    assert "in all 3 clouds of /points: the origin of their frame 'odom'" in message
    assert "TF frame(s) 'base_link', 'lidar' move in 'odom'" in message
    assert "sensor_frame= (occgp map --sensor-frame), e.g. 'base_link'" in message
    scans, messages = _user_warnings(lambda: list(read_rosbag(bag, sensor_frame="lidar")))
    assert messages == []
    assert_allclose([s.origin for s in scans], [[0, 0, 1], [1, 0, 1], [2, 0, 1]], atol=1e-12)
    # a sensor frame given on purpose is taken as it is, moving or not
    _, messages = _user_warnings(lambda: list(read_rosbag(bag, sensor_frame="odom")))
    assert messages == []


@pytest.mark.parametrize("case", ["constant-tf", "static-sensor", "moving-cloud-frame",
                                  "one-cloud"])
def test_no_warning_when_the_sensor_is_fixed_or_moves(tmp_path, case):
    path = tmp_path / "b.bag"
    if case == "constant-tf":  # odom -> base_link on /tf, never moving
        bag = registered_bag(path, edge_moves=False)
    elif case == "static-sensor":
        bag = write_bag(path, [
            ("/tf_static", TFM, tf_msg(TS1, [(0, "map", "lidar", (1, 2, 3), yaw_q(0.5))]))]
            + [("/points", PC2, xyz32([[5.0, 0.0, 0.0]], "lidar", s)) for s in (S, 2 * S)])
    elif case == "moving-cloud-frame":
        bag = chain_bag(path, stamps=(S, 2 * S, 3 * S))
    else:  # a registered cloud, but only one: nothing to compare
        bag = registered_bag(path, stamps=(2 * S,))
    scans, messages = _user_warnings(lambda: list(read_rosbag(bag)))
    assert len(scans) == (1 if case == "one-cloud" else 2 if case == "static-sensor" else 3)
    assert messages == []


def test_map_command_surfaces_the_warning(tmp_path):
    from occgp.cli import main

    bag = registered_bag(tmp_path / "r.bag")
    with pytest.warns(UserWarning, match=r"pass it as sensor_frame= \(occgp map "
                      r"--sensor-frame\), e.g. 'base_link'"):
        assert main(["map", str(bag), "-o", str(tmp_path / "a.bt"), "--no-progress"]) == 0
    _, messages = _user_warnings(lambda: main(
        ["map", str(bag), "-o", str(tmp_path / "b.bt"), "--no-progress",
         "--sensor-frame", "lidar"]))
    assert messages == []


@pytest.mark.parametrize("q, match", [
    ((0.0, 0.0, 0.0, 0.0), "not a finite rigid transform"),
    ((0.0, 0.0, 0.0, 2.0), "expected a unit quaternion"),
    ((np.nan, 0.0, 0.0, 1.0), "not a finite rigid transform"),
])
def test_bad_tf_quaternion(tmp_path, q, match):
    bag = write_bag(tmp_path / "b.bag", [
        ("/tf", TFM, tf_msg(TS1, [(S, "odom", "lidar", (0, 0, 0), q)])),
        ("/p", PC2, xyz32([[1.0, 0.0, 0.0]], stamp=S))])
    with pytest.raises(ValueError, match=match):
        read_rosbag(bag)


def test_tf_frame_with_two_parents(tmp_path):
    bag = write_bag(tmp_path / "b.bag", [
        ("/tf", TFM, tf_msg(TS1, [(S, "odom", "lidar", (0, 0, 0), yaw_q(0)),
                                  (S, "map", "lidar", (0, 0, 0), yaw_q(0))])),
        ("/p", PC2, xyz32([[1.0, 0.0, 0.0]], stamp=S))])
    with pytest.raises(ValueError, match=r"frame 'lidar' has two parents: 'odom'.*'map'"):
        read_rosbag(bag)


# --------------------------------------------------------------------------- #
# topics and bad input
# --------------------------------------------------------------------------- #
def test_topic_choice(tmp_path):
    bag = write_bag(tmp_path / "b.bag", [("/a", PC2, xyz32([[1.0, 0, 0]])),
                                         ("/b", PC2, xyz32([[2.0, 0, 0]]))])
    with pytest.raises(ValueError, match=r"exactly one PointCloud2 topic; the bag has 2: "
                       r"\['/a', '/b'\]; pass topic="):
        read_rosbag(bag)
    with pytest.raises(ValueError, match=r"topic '/c' is not in the bag; its PointCloud2 "
                       r"topics: \['/a', '/b'\]"):
        read_rosbag(bag, topic="/c")
    with pytest.warns(UserWarning):
        [scan] = read_rosbag(bag, topic="/b")
    assert_array_equal(scan.points, [[2.0, 0, 0]])


def _bad_cloud(**changes):
    base = dict(data=np.zeros((2, 3), "<f4").tobytes(),
                fields=[("x", 0, 7), ("y", 4, 7), ("z", 8, 7)], point_step=12, width=2)
    base.update(changes)
    return cloud(TS1, S, "lidar", **base)


@pytest.mark.parametrize("changes, match", [
    (dict(fields=[("x", 0, 3), ("y", 4, 7), ("z", 8, 7)]),
     r"field 'x' is INT16; expected FLOAT32 \(7\) or FLOAT64 \(8\)"),
    (dict(fields=[("x", 0, 7), ("y", 4, 7), ("z", 8, 42)]), r"'z' is unknown datatype 42"),
    (dict(fields=[("x", 0, 7), ("y", 4, 7)]), r"lacks field\(s\) \['z'\]; its fields: "
                                              r"\['x', 'y'\]"),
    (dict(fields=[("x", 0, 7), ("y", 4, 7), ("z", 10, 7)]),
     r"field 'z' \(offset 10, 4 bytes\) does not fit in point_step 12"),
    (dict(fields=[("x", 0, 7), ("x", 4, 7), ("z", 8, 7)]), r"field 'x' twice"),
    (dict(point_step=0), r"point_step must be positive, got 0"),
    (dict(width=3), r"data has 24 bytes; height 1, width 3, point_step 12, row_step 36 "
                    r"need 36"),
    (dict(height=4 * 10**9), r"data has 24 bytes; height 4000000000"),
    (dict(row_step=11), r"row_step 11 is smaller than width 2 x point_step 12"),
])
def test_malformed_cloud(tmp_path, changes, match):
    bag = write_bag(tmp_path / "b.bag", [("/p", PC2, _bad_cloud(**changes))])
    scans = read_rosbag(bag, fixed_frame="lidar")
    with pytest.raises(ValueError, match=r"/p message 0: PointCloud2 .*" + match):
        list(scans)


def test_missing_and_wrong_paths(tmp_path):
    with pytest.raises(FileNotFoundError, match="no such ROS bag"):
        read_rosbag(tmp_path / "nope.bag")
    (tmp_path / "x.txt").write_text("hello")
    with pytest.raises(ValueError, match=r"x.txt: not a ROS bag; expected a ROS 1 .bag file"):
        read_rosbag(tmp_path / "x.txt")
    (tmp_path / "dir").mkdir()
    with pytest.raises(FileNotFoundError, match="not a ROS bag"):
        read_rosbag(tmp_path / "dir")
    with pytest.raises(TypeError, match="path must be a str or os.PathLike, got int"):
        read_rosbag(3)


def test_wrong_argument_types(tmp_path):
    bag = chain_bag(tmp_path / "b.bag")
    with pytest.raises(TypeError, match="topic must be a str or None, got int"):
        read_rosbag(bag, topic=1)
    with pytest.raises(TypeError, match="fixed_frame must be a str"):
        read_rosbag(bag, fixed_frame=1)
    with pytest.raises(ValueError, match="sensor_frame must be a non-empty TF frame id"):
        read_rosbag(bag, sensor_frame="/")
    with pytest.raises(ValueError, match=r"tf_tolerance must lie in \[0.0, 1000000000.0\)"):
        read_rosbag(bag, tf_tolerance=-1.0)


@pytest.mark.filterwarnings("ignore::UserWarning")
@pytest.mark.parametrize("ros", [1, 2])
def test_corrupt_and_truncated_bags(tmp_path, ros):
    name = "b.bag" if ros == 1 else "b"
    bag = chain_bag(tmp_path / name, ros, stamps=[2 * S] * 6,
                    points=np.random.default_rng(0).normal(size=(20, 3)))
    data_file = bag if ros == 1 else next(bag.glob("*.db3"))
    raw = data_file.read_bytes()
    rng = np.random.default_rng(0)
    outcomes = set()
    for cut in (0, 5, 13, 100, len(raw) // 3, len(raw) // 2, len(raw) - 200, len(raw) - 1):
        data_file.write_bytes(raw[:cut])
        try:
            list(read_rosbag(bag))
        except (ValueError, OSError) as exc:
            outcomes.add(type(exc).__name__)
            assert str(data_file.name) in str(exc) or str(bag) in str(exc)
        else:
            outcomes.add("read")
    for _ in range(4):  # flipped bytes in the middle
        bad = bytearray(raw)
        for pos in rng.integers(len(raw) // 4, len(raw), size=8):
            bad[pos] = int(rng.integers(0, 256))
        data_file.write_bytes(bytes(bad))
        try:
            list(read_rosbag(bag))
        except (ValueError, OSError):
            pass
    assert "ValueError" in outcomes


def test_garbage_bag_and_bad_metadata(tmp_path):
    (tmp_path / "g.bag").write_bytes(b"#ROSBAG V2.0\n" + b"\x00\xff" * 100)
    with pytest.raises(ValueError, match=r"g.bag: not a readable ROS bag, corrupt or truncated"):
        read_rosbag(tmp_path / "g.bag")
    bag = chain_bag(tmp_path / "r2", ros=2)
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: [unclosed\n")
    with pytest.raises(ValueError, match=r"r2: not a readable ROS bag"):
        read_rosbag(bag)


def test_missing_rosbags_names_the_extra(tmp_path, monkeypatch):
    bag = chain_bag(tmp_path / "b.bag")
    monkeypatch.setitem(sys.modules, "rosbags.highlevel", None)
    with pytest.raises(ImportError, match=r"pip install 'occgp\[ros\]'"):
        read_rosbag(bag)
