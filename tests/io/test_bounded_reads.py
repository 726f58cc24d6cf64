"""Readers bound their work before they allocate (issue 40, parts 4 and 6).

Every file reader refuses a named pipe (which would block the open forever)
and a device such as ``/dev/zero`` (which would be read until memory runs
out) with an error naming the file. Each case runs in a forked child with a
time limit (SIGALRM) and a memory limit, so that a regression fails here
instead of hanging or exhausting the test run.
"""

import os
import pathlib
import resource
import signal

import numpy as np
import pytest

import occgp
from occgp import ColorOctree, OccupancyGrid2D, OccupancyOctree, iln, io
from occgp._reading import load_yaml_mapping, open_regular, read_regular

pytestmark = pytest.mark.skipif(not hasattr(os, "fork") or not hasattr(os, "mkfifo"),
                                reason="needs fork and named pipes")

_HDR = (b"resolution: 0.1\norigin: [0.0, 0.0, 0.0]\nnegate: 0\noccupied_thresh: 0.65\n"
        b"free_thresh: 0.196\n")


def _in_child(fn, seconds=10, memory=2 << 30):
    """Run `fn()` in a forked child killed after `seconds` (SIGALRM) and limited to
    `memory` bytes of address space; ``"ok"``, ``"<type>: <message>"`` or
    ``"killed by signal <n>"`` / ``"exit <code>"``."""
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child
        os.close(r)
        msg = "ok"
        try:
            resource.setrlimit(resource.RLIMIT_AS, (memory, memory))
            signal.signal(signal.SIGALRM, signal.SIG_DFL)
            signal.alarm(seconds)
            fn()
        except BaseException as exc:  # noqa: BLE001
            msg = f"{type(exc).__name__}: {exc}"
        os.write(w, msg.encode("utf-8", "replace")[:4000])
        os._exit(0)
    os.close(w)
    chunks = []
    while chunk := os.read(r, 4096):
        chunks.append(chunk)
    os.close(r)
    _, status = os.waitpid(pid, 0)
    if os.WIFSIGNALED(status):
        return f"killed by signal {os.WTERMSIG(status)}"
    return b"".join(chunks).decode()


def _readers():
    """name -> (suffix, reader of a path)."""
    return {
        "read_pcd": (".pcd", io.read_pcd),
        "read_kitti_bin": (".bin", io.read_kitti_bin),
        "read_xyz": (".xyz", io.read_xyz),
        "read_xyz_gz": (".xyz.gz", io.read_xyz),
        "read_scan_log": (".log", io.read_scan_log),
        "read_scan_graph": (".graph", io.read_scan_graph),
        "read_carmen": (".clf", io.read_carmen),
        "read_kitti_poses": (".txt", io.read_kitti_poses),
        "read_poses": (".txt", io.read_poses),
        "OccupancyOctree.load": (".bt", OccupancyOctree.load),
        "ColorOctree.load": (".ot", ColorOctree.load),
        "OccupancyGrid2D.load_ros_map": (".yaml", OccupancyGrid2D.load_ros_map),
        "read_lidar_frame": (".bin", lambda p: iln.read_lidar_frame(p, "hdl64e")),
        "GridMap.load": (".npz", occgp.GridMap.load),
        "read_rosbag": (".bag", io.read_rosbag),
        "iln.train_from_yaml": (".yaml", iln.train_from_yaml),
    }


@pytest.mark.parametrize("reader", sorted(_readers()))
def test_readers_refuse_a_named_pipe(tmp_path, reader):
    suffix, read = _readers()[reader]
    fifo = tmp_path / f"pipe{suffix}"
    os.mkfifo(fifo)
    got = _in_child(lambda: read(fifo))
    assert got.startswith(("OSError", "IsADirectoryError")), got
    assert str(fifo) in got and "regular file" in got, got


@pytest.mark.parametrize("reader", sorted(_readers()))
def test_readers_refuse_dev_zero(tmp_path, reader):
    if not os.path.exists("/dev/zero"):
        pytest.skip("no /dev/zero")
    suffix, read = _readers()[reader]
    link = tmp_path / f"zero{suffix}"   # a link keeps the suffix the reader wants
    link.symlink_to("/dev/zero")
    got = _in_child(lambda: read(link))
    assert got.startswith("OSError"), got
    assert "zero" in got and "regular file" in got, got


@pytest.mark.parametrize("image", ["/dev/zero", "pipe.pgm"])
def test_ros_map_refuses_an_image_that_is_not_a_regular_file(tmp_path, image):
    os.mkfifo(tmp_path / "pipe.pgm")
    (tmp_path / "m.yaml").write_bytes(b"image: " + image.encode() + b"\n" + _HDR)
    got = _in_child(lambda: OccupancyGrid2D.load_ros_map(tmp_path / "m.yaml"))
    assert got.startswith("OSError"), got
    assert "the image of m.yaml must be a regular file" in got, got
    assert ("/dev/zero" if image == "/dev/zero" else str(tmp_path / "pipe.pgm")) in got


def test_a_billion_laughs_yaml_is_refused_quickly_with_a_short_message(tmp_path):
    """445 bytes of nested aliases once made a 527-million-character message."""
    lines = [b'a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]']
    for i in range(1, 9):
        prev, cur = chr(96 + i).encode(), chr(97 + i).encode()
        lines.append(cur + b": &" + cur + b" [" + b",".join([b"*" + prev] * 9) + b"]")
    path = tmp_path / "laughs.yaml"
    path.write_bytes(b"\n".join(lines) + b"\nimage: m.pgm\n" + _HDR)
    got = _in_child(lambda: OccupancyGrid2D.load_ros_map(path), memory=1 << 30)
    assert got.startswith("ValueError"), got
    assert str(path) in got and "aliases are not read" in got and len(got) < 1000, got


def test_yaml_loader_refuses_every_alias_but_reads_anchors_alone(tmp_path):
    path = tmp_path / "a.yaml"
    path.write_text("x: &one 1\ny: 2\n")
    assert load_yaml_mapping(path) == {"x": 1, "y": 2}
    path.write_text("x: &one 1\ny: *one\n")
    with pytest.raises(ValueError, match=r"a\.yaml: not a valid YAML file \(found the alias "
                                         r"\*one; aliases are not read"):
        load_yaml_mapping(path)


def test_read_regular_refuses_a_file_over_its_limit(tmp_path):
    path = tmp_path / "f.bin"
    path.write_bytes(bytes(100))
    assert read_regular(path, limit=100) == bytes(100)
    with pytest.raises(ValueError, match=r"f\.bin: the file holds 100 bytes, more than the 99"):
        read_regular(path, limit=99)


def test_open_regular_names_missing_files_and_folders(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope"):
        open_regular(tmp_path / "nope")
    with pytest.raises(IsADirectoryError, match="must be a regular file, got a directory"):
        open_regular(tmp_path)
    with pytest.raises(TypeError, match="path must be a str or os.PathLike, got int"):
        open_regular(3)


def test_pgm_pixels_are_not_read_before_the_size_checks(tmp_path):
    """A header announcing 10^10 pixels, or more than the file holds, is refused from
    the header alone (the pixel data would be huge or absent)."""
    from occgp.nav import _ros_map as _ros_map
    (tmp_path / "m.yaml").write_bytes(b"image: m.pgm\n" + _HDR)
    (tmp_path / "m.pgm").write_bytes(b"P5 100000 100000 255\n" + bytes(4))
    with pytest.raises(ValueError, match=r"m\.pgm: the PGM image has 100000 x 100000 = "
                                         r"10000000000 pixels, more than the 268435456"):
        OccupancyGrid2D.load_ros_map(tmp_path / "m.yaml")
    assert _ros_map.MAX_PGM_PIXELS == 1 << 28
    (tmp_path / "m.pgm").write_bytes(b"P5\n#" + b"x" * (1 << 16) + b"\n2 2 255\n" + bytes(4))
    with pytest.raises(ValueError, match=r"m\.pgm: malformed PGM header: no width in its "
                                         r"first 65536 bytes"):
        OccupancyGrid2D.load_ros_map(tmp_path / "m.yaml")


@pytest.mark.parametrize("name", ["map😀.yaml", "m a p é.yaml", "-m\\a:p.yaml", "m'\"#.yaml"])
def test_ros_map_file_names_round_trip(tmp_path, name):
    grid = OccupancyGrid2D([[0, 1, -1], [1, 0, 0]], [0.5, -1.0], 0.25)
    yaml_path, _ = grid.save_ros_map(tmp_path / name)
    back = OccupancyGrid2D.load_ros_map(yaml_path)
    np.testing.assert_array_equal(back.states, grid.states)


def test_scan_rings_of_nothing_is_empty():
    for points in (np.zeros((0, 3)), []):
        ring = iln.scan_rings(np.reshape(points, (0, 3)))
        assert ring.shape == (0,) and ring.dtype == np.int64
    one = iln.scan_rings([[1.0, 0.0, 0.0]])
    assert one.tolist() == [0]


def _frame(path: pathlib.Path, records) -> pathlib.Path:
    np.asarray(records, dtype="<f4").reshape(-1, 4).tofile(path)
    return path


@pytest.mark.parametrize("stray", [1, 3, 15])
def test_read_lidar_frame_refuses_stray_trailing_bytes(tmp_path, stray):
    rng = np.random.default_rng(0)
    path = _frame(tmp_path / "f.bin", np.c_[rng.uniform(-9, 9, (640, 3)), np.ones(640)])
    with open(path, "ab") as fh:
        fh.write(b"\x01" * stray)
    for sensor in ("hdl64e", "os1-64"):
        with pytest.raises(ValueError, match=rf"f\.bin: .* got {640 * 16 + stray} bytes: "
                                             rf"640 records and {stray} stray bytes"):
            iln.read_lidar_frame(path, sensor)


@pytest.mark.slow
def test_ros_yaml_over_its_size_limit_or_too_deep_is_refused(tmp_path):
    from occgp._reading import MAX_YAML_BYTES

    path = tmp_path / "big.yaml"
    path.write_bytes(b"image: m.pgm\n" + _HDR + b"#" * MAX_YAML_BYTES)
    with pytest.raises(ValueError, match=r"big\.yaml: a map's YAML file holds \d+ bytes, more "
                                         r"than the 1048576 read"):
        OccupancyGrid2D.load_ros_map(path)
    path = tmp_path / "deep.yaml"
    path.write_bytes(b"image: m.pgm\n" + _HDR + b"x: " + b"[" * 5000 + b"]" * 5000 + b"\n")
    with pytest.raises(ValueError, match=r"deep\.yaml: not a map's YAML file: its YAML "
                                         r"nesting is too deep"):
        OccupancyGrid2D.load_ros_map(path)
