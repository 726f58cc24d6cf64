"""ROS 1 / ROS 2 bag reader: ``sensor_msgs/PointCloud2`` scans posed by TF.

Bags are read through the `rosbags <https://gitlab.com/ternaris/rosbags>`_
package (pure Python, no ROS installation), an optional dependency: install
it with ``pip install 'occgp[ros]'``. It is imported only when a bag is read.
"""

import errno
import logging
import warnings

import numpy as np

from .._reading import check_regular
from .._validation import as_path, check_real
from ._scan import Scan

__all__ = ["read_rosbag", "RosbagScans"]

logger = logging.getLogger("occgp")

_POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"
_TF_TYPES = ("tf2_msgs/msg/TFMessage", "tf/msg/tfMessage")
_TF_TOPICS = ("/tf", "/tf_static")
# sensor_msgs/PointField datatypes
_PF_NAMES = {1: "INT8", 2: "UINT8", 3: "INT16", 4: "UINT16", 5: "INT32", 6: "UINT32",
             7: "FLOAT32", 8: "FLOAT64"}
_PF_FLOATS = {7: "f4", 8: "f8"}
_NORM_TOL = 1e-2  # |q|^2 - 1 beyond this: a broken quaternion (tf2's own check)
_STILL_M = 1e-3  # metres: origins closer than this to the first count as the same point
_MOTION_SAMPLES = 32  # cloud stamps at which the TF frames are checked for motion


def _rosbags():
    """Import ``rosbags.highlevel.AnyReader`` and a default typestore, lazily."""
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError as exc:
        raise ImportError(
            "reading ROS bags needs the optional 'rosbags' package: "
            "pip install 'occgp[ros]' (or pip install rosbags)"
        ) from exc
    return AnyReader, get_typestore(Stores.LATEST)


def _frame(name):
    """tf2's frame-id normalisation: no leading slash."""
    return name.lstrip("/")


def _stamp_ns(stamp):
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def _fmt_ns(ns):
    return f"{ns // 1_000_000_000}.{ns % 1_000_000_000:09d} s"


# --------------------------------------------------------------------------- #
# rigid transforms (R, t): p' = R p + t
# --------------------------------------------------------------------------- #
def _compose(a, b):
    """a ∘ b."""
    return a[0] @ b[0], a[0] @ b[1] + a[1]


def _inverse(a):
    rt = a[0].T
    return rt, -(rt @ a[1])


_IDENTITY = (np.eye(3), np.zeros(3))


# --------------------------------------------------------------------------- #
# TF buffer
# --------------------------------------------------------------------------- #
class _Edge:
    """The transform parent <- child: static, or a time series interpolated in time."""

    def __init__(self, parent, child, static, stamps, trans, quats, source):
        from scipy.spatial.transform import Rotation  # type: ignore[import-untyped]

        self.parent, self.child, self.static = parent, child, static
        what = f"{source}: TF transform '{parent}' -> '{child}'"
        bad = ~(np.isfinite(trans).all(axis=1) & np.isfinite(quats).all(axis=1))
        norm2 = np.einsum("ij,ij->i", quats, quats)
        bad |= ~(np.abs(norm2 - 1.0) <= _NORM_TOL)
        if bad.any():
            i = int(np.argmax(bad))
            raise ValueError(
                f"{what} at {_fmt_ns(int(stamps[i]))} is not a finite rigid transform "
                f"(translation {trans[i].tolist()}, quaternion xyzw {quats[i].tolist()}, "
                "expected a unit quaternion)"
            )
        if static:  # the latest one published wins
            self.stamps = stamps[-1:]
            self.trans, self.rot = trans[-1:], Rotation.from_quat(quats[-1:])
            return
        order = np.argsort(stamps, kind="stable")
        stamps, trans, quats = stamps[order], trans[order], quats[order]
        last = np.r_[stamps[1:] != stamps[:-1], True]  # duplicate stamps: keep the last
        self.stamps, self.trans = stamps[last], trans[last]
        self.rot = Rotation.from_quat(quats[last])

    def at(self, t, tolerance_ns, where):
        """(R, t) of parent <- child at stamp `t` (ns): linear translation, slerp rotation."""
        if self.static:
            return self.rot[0].as_matrix(), self.trans[0]
        s = self.stamps
        first, last = int(s[0]), int(s[-1])  # Python ints: no int64 overflow
        if t < first - tolerance_ns or t > last + tolerance_ns:
            raise ValueError(
                f"{where}: stamp {_fmt_ns(t)} lies outside the TF data of '{self.parent}' -> "
                f"'{self.child}' ({_fmt_ns(first)} to {_fmt_ns(last)}, "
                f"{s.size} transforms); TF is not extrapolated (tf_tolerance= allows a margin)"
            )
        if t <= first:
            return self.rot[0].as_matrix(), self.trans[0]
        if t >= last:
            return self.rot[-1].as_matrix(), self.trans[-1]
        i = int(np.searchsorted(s, t, side="right")) - 1
        alpha = (t - int(s[i])) / (int(s[i + 1]) - int(s[i]))
        trans = (1.0 - alpha) * self.trans[i] + alpha * self.trans[i + 1]
        r0 = self.rot[i]
        delta = (r0.inv() * self.rot[i + 1]).as_rotvec()  # shortest arc
        from scipy.spatial.transform import Rotation

        rot = r0 * Rotation.from_rotvec(alpha * delta)
        return rot.as_matrix(), trans


class _TFBuffer:
    """The TF tree of a bag: child -> parent edges, static and dynamic."""

    def __init__(self, records, source):
        # records: (static, stamp_ns, parent, child, (tx, ty, tz), (qx, qy, qz, qw))
        self.source = source
        groups = {}
        parents = {}
        for static, stamp, parent, child, t, q in records:
            if not parent or not child:
                raise ValueError(f"{source}: TF transform with an empty frame id "
                                 f"(frame_id {parent!r}, child_frame_id {child!r})")
            if parent == child:
                raise ValueError(f"{source}: TF transform from frame '{child}' to itself")
            known = parents.setdefault(child, (parent, static))
            if known != (parent, static):
                kind = lambda s: "/tf_static" if s else "/tf"  # noqa: E731
                raise ValueError(
                    f"{source}: TF frame '{child}' has two parents: '{known[0]}' on "
                    f"{kind(known[1])} and '{parent}' on {kind(static)}; a TF tree "
                    "gives each frame one parent"
                )
            groups.setdefault(child, []).append((stamp, t, q))
        self.edges = {}
        for child, rows in groups.items():
            parent, static = parents[child]
            stamps = np.array([r[0] for r in rows], dtype=np.int64)
            trans = np.array([r[1] for r in rows], dtype=np.float64).reshape(-1, 3)
            quats = np.array([r[2] for r in rows], dtype=np.float64).reshape(-1, 4)
            self.edges[child] = _Edge(parent, child, static, stamps, trans, quats, source)
        self.frames = sorted(set(self.edges) | {e.parent for e in self.edges.values()})

    def __bool__(self):
        return bool(self.edges)

    def chain(self, frame):
        """[frame, parent, grandparent, ..., root]."""
        out, seen = [frame], {frame}
        while out[-1] in self.edges:
            parent = self.edges[out[-1]].parent
            if parent in seen:
                raise ValueError(f"{self.source}: the TF tree has a cycle through "
                                 f"'{parent}' ({' -> '.join(out)} -> {parent})")
            out.append(parent)
            seen.add(parent)
        return out

    def root(self, frame):
        return self.chain(frame)[-1]

    def check_connected(self, target, source_frame, what):
        """ValueError unless `target` and `source_frame` share a tree."""
        for name, f in ((what[0], target), (what[1], source_frame)):
            if f not in self.frames:
                raise ValueError(f"{name} '{f}' is not a frame of the TF tree of "
                                 f"{self.source}; its frames: {self.frames}")
        if self.root(target) != self.root(source_frame):
            raise ValueError(
                f"{what[0]} '{target}' and {what[1]} '{source_frame}' are not connected in the "
                f"TF tree of {self.source} (roots '{self.root(target)}' and "
                f"'{self.root(source_frame)}')"
            )

    def lookup(self, target, frame, t, tolerance_ns, where):
        """(R, t) mapping points of `frame` into `target` at stamp `t` (ns)."""
        if target == frame:
            return _IDENTITY
        up_t, up_f = self.chain(target), self.chain(frame)
        common = next((f for f in up_f if f in set(up_t)), None)
        if common is None:
            raise ValueError(f"{where}: frames '{target}' and '{frame}' are not connected "
                             f"in the TF tree of {self.source}")

        def to_common(chain):
            tr = _IDENTITY
            for child in chain[:chain.index(common)]:  # common <- ... <- chain[0]
                tr = _compose(self.edges[child].at(t, tolerance_ns, where), tr)
            return tr

        return _compose(_inverse(to_common(up_t)), to_common(up_f))


# --------------------------------------------------------------------------- #
# PointCloud2 decoding
# --------------------------------------------------------------------------- #
def _decode_cloud(msg, where):
    """x, y, z of a PointCloud2 as float64 (n, 3), before dropping non-finite points."""
    height, width = int(msg.height), int(msg.width)
    step, row_step = int(msg.point_step), int(msg.row_step)
    data = msg.data
    n_bytes = len(data)
    if height * width == 0:
        return np.empty((0, 3))
    fields = {}
    for f in msg.fields:
        if f.name in fields:
            raise ValueError(f"{where}: PointCloud2 has field {f.name!r} twice")
        fields[f.name] = f
    missing = [c for c in "xyz" if c not in fields]
    if missing:
        raise ValueError(f"{where}: PointCloud2 lacks field(s) {missing}; its fields: "
                         f"{list(fields)}")
    if step <= 0:
        raise ValueError(f"{where}: PointCloud2 point_step must be positive, got {step}")
    order = ">" if msg.is_bigendian else "<"
    formats, offsets = [], []
    for c in "xyz":
        f = fields[c]
        if f.datatype not in _PF_FLOATS:
            kind = _PF_NAMES.get(f.datatype, f"unknown datatype {f.datatype}")
            raise ValueError(f"{where}: PointCloud2 field {c!r} is {kind}; expected FLOAT32 "
                             "(7) or FLOAT64 (8)")
        size = 4 if f.datatype == 7 else 8
        if f.offset < 0 or f.offset + size > step:
            raise ValueError(f"{where}: PointCloud2 field {c!r} (offset {f.offset}, {size} "
                             f"bytes) does not fit in point_step {step}")
        formats.append(order + _PF_FLOATS[f.datatype])
        offsets.append(int(f.offset))
    if row_step < width * step:
        raise ValueError(f"{where}: PointCloud2 row_step {row_step} is smaller than width "
                         f"{width} x point_step {step}")
    needed = (height - 1) * row_step + width * step
    if n_bytes < needed:
        raise ValueError(f"{where}: PointCloud2 data has {n_bytes} bytes; height {height}, "
                         f"width {width}, point_step {step}, row_step {row_step} need {needed}")
    rec = np.dtype({"names": ["x", "y", "z"], "formats": formats, "offsets": offsets,
                    "itemsize": step})
    buf = np.frombuffer(data, dtype=np.uint8)
    arr = np.ndarray(shape=(height, width), dtype=rec, buffer=buf, strides=(row_step, step))
    out = np.empty((height * width, 3))
    for j, c in enumerate("xyz"):
        out[:, j] = arr[c].reshape(-1)
    return out


# --------------------------------------------------------------------------- #
# bag access
# --------------------------------------------------------------------------- #
def _check_bag_path(path):
    path = as_path(path)
    if not path.exists():
        raise FileNotFoundError(errno.ENOENT, "no such ROS bag", str(path))
    if not path.is_dir() and path.suffix.lower() not in (".bag", ".db3", ".mcap"):
        raise ValueError(f"{path}: not a ROS bag; expected a ROS 1 .bag file, a ROS 2 bag "
                         "directory (metadata.yaml) or a ROS 2 .db3 / .mcap file")
    if not path.is_dir():   # a named pipe or a device would block or never end
        check_regular(path, "a ROS bag file")
    return path


def _open(path):
    """An open AnyReader; OSError / ValueError naming the file otherwise."""
    AnyReader, typestore = _rosbags()
    try:
        reader = AnyReader([path], default_typestore=typestore)
        reader.open()
    except (MemoryError, PermissionError, IsADirectoryError):
        raise
    except FileNotFoundError as exc:  # a ROS 2 directory without metadata.yaml
        raise FileNotFoundError(errno.ENOENT, f"not a ROS bag ({exc})", str(path)) from None
    except Exception as exc:  # rosbags raises many types on corrupt data
        raise ValueError(f"{path}: not a readable ROS bag, corrupt or truncated "
                         f"({type(exc).__name__}: {exc})") from None
    return reader


def _messages(reader, connections, path, what):
    """(index, connection, bag time, message) for `connections`; ValueError on corrupt data."""
    if not connections:  # rosbags reads every topic for an empty filter
        return
    it = reader.messages(connections=connections)
    i = 0
    while True:
        try:
            item = next(it)
        except StopIteration:
            return
        except MemoryError:
            raise
        except Exception as exc:
            raise ValueError(f"{path}: corrupt or truncated bag while reading {what} message "
                             f"{i} ({type(exc).__name__}: {exc})") from None
        con, t, raw = item
        try:
            msg = reader.deserialize(raw, con.msgtype)
        except MemoryError:
            raise
        except Exception as exc:
            raise ValueError(f"{path}: cannot decode {con.msgtype} message {i} on {con.topic} "
                             f"({type(exc).__name__}: {exc})") from None
        yield i, con, t, msg
        i += 1


def _read_tf(reader, path):
    cons = [c for c in reader.connections if c.topic in _TF_TOPICS and c.msgtype in _TF_TYPES]
    records = []
    for _, con, _, msg in _messages(reader, cons, path, "TF"):
        static = con.topic == "/tf_static"
        for tr in msg.transforms:
            v, q = tr.transform.translation, tr.transform.rotation
            records.append((static, _stamp_ns(tr.header.stamp), _frame(tr.header.frame_id),
                            _frame(tr.child_frame_id), (v.x, v.y, v.z), (q.x, q.y, q.z, q.w)))
    return _TFBuffer(records, path)


def _check_frame(value, name):
    if value is None:
        return None
    if not isinstance(value, str):
        raise TypeError(f"{name} must be a str (a TF frame id) or None, got "
                        f"{type(value).__name__}")
    if not _frame(value):
        raise ValueError(f"{name} must be a non-empty TF frame id, got {value!r}")
    return _frame(value)


class RosbagScans:
    """The scans of one PointCloud2 topic of a bag, posed by TF (see :func:`read_rosbag`).

    Iterating reads the bag afresh, one message at a time, so the scans are
    never all in memory at once; ``len()`` is the number of messages.

    Attributes
    ----------
    path : pathlib.Path
        The bag.
    topic : str
        The PointCloud2 topic.
    fixed_frame : str or None
        The frame the points are expressed in (None: each cloud's own frame,
        no TF).
    sensor_frame : str or None
        The frame whose origin is the sensor position (None: the cloud's frame).
    n_points : int
        Points decoded by the last iteration (before dropping).
    n_dropped : int
        Points with a NaN or inf coordinate dropped by the last iteration.
    """

    def __init__(self, path, topic, n_messages, tf, fixed_frame, sensor_frame, tolerance_ns):
        self.path, self.topic = path, topic
        self.fixed_frame, self.sensor_frame = fixed_frame, sensor_frame
        self.n_points = self.n_dropped = 0
        self._n, self._tf, self._tol = n_messages, tf, tolerance_ns

    def __len__(self):
        return self._n

    def __repr__(self):
        return (f"RosbagScans({str(self.path)!r}, topic={self.topic!r}, {self._n} clouds, "
                f"fixed_frame={self.fixed_frame!r}, sensor_frame={self.sensor_frame!r})")

    def __iter__(self):
        self.n_points = self.n_dropped = 0
        # with the default sensor frame: each cloud's stamp and frame, and how far the
        # sensor origin strays from the first one (see _warn_if_sensor_still)
        watch = self.fixed_frame is not None and self.sensor_frame is None and bool(self._tf)
        stamps, frames, first, spread = [], set(), None, 0.0
        reader = _open(self.path)
        try:
            cons = [c for c in reader.connections
                    if c.topic == self.topic and c.msgtype == _POINTCLOUD2]
            for i, _, _, msg in _messages(reader, cons, self.path, self.topic):
                scan = self._scan(i, msg)
                if watch:
                    stamps.append(_stamp_ns(msg.header.stamp))
                    frames.add(_frame(msg.header.frame_id))
                    first = scan.origin if first is None else first
                    spread = max(spread, float(np.abs(scan.origin - first).max()))
                yield scan
        finally:
            reader.close()
        if self.n_dropped:
            logger.warning("%s: dropped %d of %d points of %s with a non-finite coordinate "
                           "(NaN or inf)", self.path, self.n_dropped, self.n_points, self.topic)
        if len(stamps) > 1 and spread <= _STILL_M:
            self._warn_if_sensor_still(stamps, frames, first)

    def _warn_if_sensor_still(self, stamps, frames, origin):
        """Warn that the sensor never moved while a TF frame does (registered clouds)."""
        picks = np.unique(np.linspace(0, len(stamps) - 1, _MOTION_SAMPLES).round().astype(int))
        root = self._tf.root(self.fixed_frame)
        moving = []
        for frame in self._tf.frames:
            if frame == self.fixed_frame or frame in frames or self._tf.root(frame) != root:
                continue
            seen = []
            for k in picks:
                try:
                    seen.append(self._tf.lookup(self.fixed_frame, frame, stamps[k], self._tol,
                                                "")[1])
                except ValueError:  # a stamp outside this frame's TF data
                    continue
            if seen and np.abs(np.array(seen) - seen[0]).max() > _STILL_M:
                moving.append(frame)
        if not moving:
            return
        moving.sort(key=lambda f: (len(self._tf.chain(f)), f))  # nearest the root first
        names = ", ".join(f"'{f}'" for f in moving)
        clouds = ", ".join(f"'{f}'" for f in sorted(frames))
        warnings.warn(
            f"{self.path}: the sensor origin is the same point {np.round(origin, 6).tolist()} "
            f"in all {len(stamps)} clouds of {self.topic}: the origin of their frame {clouds} "
            f"(the default sensor frame), fixed in '{self.fixed_frame}', while TF frame(s) "
            f"{names} move in '{self.fixed_frame}'. Clouds published already registered (in "
            f"an odometry frame, as LOAM's are) need the sensor's own frame: pass it as "
            f"sensor_frame= (occgp map --sensor-frame), e.g. '{moving[0]}'",
            UserWarning, stacklevel=3)

    def _scan(self, i, msg):
        where = f"{self.path}: {self.topic} message {i}"
        points = _decode_cloud(msg, where)
        keep = np.isfinite(points).all(axis=1)
        self.n_points += points.shape[0]
        if not keep.all():
            self.n_dropped += int(points.shape[0] - np.count_nonzero(keep))
            points = points[keep]
        if self.fixed_frame is None:
            return Scan(np.ascontiguousarray(points), np.zeros(3))
        frame = _frame(msg.header.frame_id)
        t = _stamp_ns(msg.header.stamp)
        if not frame:
            raise ValueError(f"{where}: empty header.frame_id; cannot pose it by TF")
        rot, trans = self._tf.lookup(self.fixed_frame, frame, t, self._tol, where)
        sensor = self.sensor_frame or frame
        origin = trans if sensor == frame else self._tf.lookup(
            self.fixed_frame, sensor, t, self._tol, where)[1]
        world = points @ rot.T + trans
        return Scan(np.ascontiguousarray(world), np.array(origin, dtype=np.float64))


def read_rosbag(path, topic=None, *, fixed_frame=None, sensor_frame=None,
                tf_tolerance=0.0):
    """Read the ``sensor_msgs/PointCloud2`` scans of a ROS 1 or ROS 2 bag.

    Each message of `topic` becomes one :class:`Scan`: its points
    expressed in `fixed_frame` and the sensor position (the origin of
    `sensor_frame`) in that frame, both from the bag's ``/tf`` and
    ``/tf_static`` (``tf2_msgs/TFMessage``) at the cloud's
    ``header.stamp``. The transform chain from `fixed_frame` to the cloud's
    ``header.frame_id`` is composed through the TF tree (any depth, static
    and dynamic edges); dynamic transforms are interpolated between their
    stamps (linear translation, quaternion slerp), never extrapolated.
    Frame ids are compared without a leading ``/`` (as tf2 does).

    Any point layout is decoded from the message's ``fields`` (offsets and
    FLOAT32 / FLOAT64 datatypes of x, y, z; other fields and padding
    skipped), ``point_step``, ``row_step``, ``height`` x ``width`` and
    ``is_bigendian``, vectorised. Points with a NaN or inf coordinate
    (``is_dense`` false, or a message that wrongly claims to be dense) are
    dropped; the number is kept in ``n_dropped`` and logged on the
    ``"occgp"`` logger at the end of an iteration.

    Bags are read with the optional ``rosbags`` package
    (``pip install 'occgp[ros]'``).

    Parameters
    ----------
    path : str or os.PathLike
        A ROS 1 ``.bag`` file, a ROS 2 bag directory (with its
        ``metadata.yaml``) or a ROS 2 ``.db3`` / ``.mcap`` file.
    topic : str, optional
        The PointCloud2 topic. Default: the bag's only PointCloud2 topic.
    fixed_frame : str, optional
        The world frame of the returned points. Default: the root of the
        TF tree that holds the first cloud's frame; if the bag has no TF,
        the points stay in each cloud's own frame with origin (0, 0, 0),
        and a :class:`UserWarning` says so.
    sensor_frame : str, optional
        The frame whose origin is the sensor position. Default: the cloud's
        ``header.frame_id``. Give it when the clouds are published already
        registered in an odometry frame (as LOAM's are: the akimap sample's
        clouds are in ``camera_init``, the sensor is ``camera``). Left at
        the default, an iteration that finds the sensor origin at the same
        point (within 1 mm) in every cloud while a frame of the TF tree moves
        in `fixed_frame` ends with a :class:`UserWarning` naming the moving
        frames.
    tf_tolerance : float, default=0.0
        Seconds a cloud stamp may lie before the first or after the last
        transform of a dynamic TF edge; that transform is then used as is.

    Returns
    -------
    scans : RosbagScans
        A re-iterable sequence of :class:`Scan` with ``len()`` (the number
        of messages) and attributes ``fixed_frame``, ``sensor_frame``,
        ``n_points`` and ``n_dropped``. ``list(scans)`` reads them all.

    Raises
    ------
    ImportError
        If the ``rosbags`` package is not installed.
    OSError
        If the bag does not exist or cannot be read, or a bag file is not a
        regular file (a named pipe, a device).
    ValueError
        If the file is not a readable bag (corrupt or truncated), the topic
        is missing or not PointCloud2 (the message lists the PointCloud2
        topics), a frame is not in the TF tree or not connected to the
        cloud's frame, `fixed_frame` / `sensor_frame` differ from the cloud
        frame in a bag without TF, a TF transform is not a finite rigid
        transform or the tree is not a tree. While iterating: a cloud stamp
        outside its TF data, a message whose x / y / z are not FLOAT32 or
        FLOAT64, whose fields do not fit ``point_step`` or whose data is
        shorter than its size says, or corrupt message data. Also if
        `tf_tolerance` is negative or not finite.
    TypeError
        If `path`, `topic`, `fixed_frame`, `sensor_frame` or `tf_tolerance` has a
        wrong type.

    Notes
    -----
    The cloud's ``header.stamp`` is used, not the bag's receive time. A
    frame with two parents, or published on both ``/tf`` and
    ``/tf_static``, is rejected rather than resolved by time.

    Examples
    --------
    >>> scans = read_rosbag("sample.bag", fixed_frame="map",
    ...                     sensor_frame="camera")  # doctest: +SKIP
    >>> len(scans)  # doctest: +SKIP
    73
    >>> points, origin = next(iter(scans))  # doctest: +SKIP
    """
    path = _check_bag_path(path)
    if topic is not None and not isinstance(topic, str):
        raise TypeError(f"topic must be a str or None, got {type(topic).__name__}")
    fixed_frame = _check_frame(fixed_frame, "fixed_frame")
    sensor_frame = _check_frame(sensor_frame, "sensor_frame")
    tol_ns = int(round(check_real(tf_tolerance, "tf_tolerance", low=0.0, high=1e9,
                                  low_open=False) * 1e9))
    reader = _open(path)
    try:
        clouds = sorted({c.topic for c in reader.connections if c.msgtype == _POINTCLOUD2})
        if topic is None:
            if len(clouds) != 1:
                raise ValueError(f"{path}: topic=None needs exactly one PointCloud2 topic; the "
                                 f"bag has {len(clouds)}: {clouds}; pass topic=")
            topic = clouds[0]
        elif topic not in clouds:
            others = sorted({c.topic for c in reader.connections})
            kind = "is not PointCloud2" if topic in others else "is not in the bag"
            raise ValueError(f"{path}: topic {topic!r} {kind}; its PointCloud2 topics: "
                             f"{clouds} (all topics: {others})")
        cons = [c for c in reader.connections if c.topic == topic and c.msgtype == _POINTCLOUD2]
        n = sum(int(c.msgcount) for c in cons)
        tf = _read_tf(reader, path)
        first = next(_messages(reader, cons, path, topic), None)
    finally:
        reader.close()
    if first is not None:
        frame = _frame(first[3].header.frame_id)
        fixed_frame, sensor_frame = _resolve_frames(path, tf, frame, fixed_frame, sensor_frame)
    return RosbagScans(path, topic, n, tf, fixed_frame, sensor_frame, tol_ns)


def _resolve_frames(path, tf, frame, fixed_frame, sensor_frame):
    """Default and check the frames against the first cloud's `frame`."""
    if not tf:
        if fixed_frame not in (None, frame) or sensor_frame not in (None, frame):
            raise ValueError(
                f"{path}: the bag has no /tf or /tf_static transforms, so its clouds (frame "
                f"'{frame}') cannot be expressed in fixed_frame {fixed_frame!r} / "
                f"sensor_frame {sensor_frame!r}"
            )
        if fixed_frame is None:
            warnings.warn(
                f"{path}: the bag has no TF (/tf, /tf_static): points stay in the sensor frame "
                f"'{frame}' and every scan's origin is (0, 0, 0)", UserWarning, stacklevel=3)
            return None, None
        return fixed_frame, sensor_frame
    if not frame:
        raise ValueError(f"{path}: the first cloud has an empty header.frame_id")
    if fixed_frame is None:
        if frame not in tf.frames:
            warnings.warn(
                f"{path}: the cloud frame '{frame}' is not in the bag's TF tree (frames "
                f"{tf.frames}): points stay in '{frame}'", UserWarning, stacklevel=3)
        fixed_frame = tf.root(frame) if frame in tf.frames else frame
    if fixed_frame != frame:
        tf.check_connected(fixed_frame, frame, ("fixed_frame", "the cloud frame"))
    if sensor_frame is not None and sensor_frame != fixed_frame:
        tf.check_connected(fixed_frame, sensor_frame, ("fixed_frame", "sensor_frame"))
    return fixed_frame, sensor_frame
