"""Every file occgp writes is written atomically (occgp._atomic): a save that fails half
way (here: the file size limit RLIMIT_FSIZE, as a full disk would) raises OSError and
leaves the previous file byte for byte, loadable, with no temporary file beside it."""

import contextlib
import errno
import inspect
import os
import resource
import select
import signal
import stat
import subprocess
import sys

import numpy as np
import pytest

import occgp
from occgp import OccupancyGrid2D, OccupancyOctree
from occgp._atomic import atomic_group, atomic_open, atomic_path, write_bytes
from occgp.io import read_pcd, read_scan_graph, write_pcd, write_scan_graph
from occgp.maps import available_maps, make_map, map_type

# map parameters that keep the fits of the GP maps tiny and fast
FAST = {"gpom": {"optimizer": False}, "gpomik": {"optimizer": False}}


def _in_child(fn, limit=None):
    """Run `fn()` in a forked child (files limited to `limit` bytes); what it gave:
    ``"ok"`` (it returned), ``"OSError <errno> <message>"``, ``"exit <code>"``
    (SystemExit) or ``"<exception type> <message>"``."""
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child
        msg = "nothing"
        try:
            os.close(r)
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # EFBIG instead of death
            if limit is not None:
                resource.setrlimit(resource.RLIMIT_FSIZE,
                                   (limit, resource.getrlimit(resource.RLIMIT_FSIZE)[1]))
            fn()
            msg = "ok"
        except OSError as exc:
            msg = f"OSError {exc.errno} {exc}"
        except SystemExit as exc:
            msg = f"exit {exc.code}"
        except BaseException as exc:
            msg = f"{type(exc).__name__} {exc}"
        finally:
            os.write(w, msg.encode("utf-8", "replace")[:4000])
            os._exit(0)
    os.close(w)
    chunks = []
    try:
        while select.select([r], [], [], 60)[0] and (chunk := os.read(r, 4096)):
            chunks.append(chunk)
    finally:
        os.close(r)
        if not chunks:                      # hung (or died without a word): end it
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
    return b"".join(chunks).decode()


def _check_failed_save_keeps_old(folder, name, save_old, save_new, load):
    """Save the old file; measure the new one elsewhere; then save the new one over the
    old with a size limit one byte short of it, in a child: OSError EFBIG, the old file
    unchanged and loadable, nothing else in the folder."""
    path = folder / name
    save_old(path)
    old = path.read_bytes()
    before = load(path)
    (folder / "ref").mkdir()
    save_new(folder / "ref" / name)
    size = (folder / "ref" / name).stat().st_size
    assert size > len(old), "the new file must be larger than the old one"
    got = _in_child(lambda: save_new(path), limit=size - 1)
    assert got.startswith(f"OSError {errno.EFBIG}"), got
    assert path.read_bytes() == old
    assert sorted(os.listdir(folder)) == sorted([name, "ref"])
    assert str(path) in got                               # the message names the file
    return before, load(path)


def _scan(dims, n, seed):
    rng = np.random.default_rng(seed)
    if dims == 2:
        return np.column_stack([np.full(n, 2.0), rng.uniform(-1.5, 1.5, n)]), np.zeros(2)
    return np.column_stack([np.full(n, 2.0), rng.uniform(-1, 1, (n, 2))]), np.zeros(3)


def _map_cases():
    cases = []
    for name in available_maps():
        for suffix in map_type(name).formats:
            cases.append((name, suffix))
    return cases


@pytest.mark.parametrize("name, suffix", _map_cases())
def test_failed_map_save_keeps_the_old_file(name, suffix, tmp_path):
    entry = map_type(name)
    dims = 3 if 3 in entry.dims else 2

    def build(n, seed):
        points, origin = _scan(dims, n, seed)
        extra = {}
        if "colors" in inspect.signature(entry.cls.insert_scan).parameters:
            extra["colors"] = np.full((n, 3), 200, dtype=np.uint8)
        return make_map(name, **FAST.get(name, {})).insert_scan(points, origin, **extra)

    small, large = build(10, 0), build(60, 1)
    before, after = _check_failed_save_keeps_old(
        tmp_path, "m" + suffix, small.save, large.save, entry.cls.load)
    assert after.num_cells == before.num_cells == small.num_cells > 0


@pytest.fixture(scope="module")
def trees():
    small = OccupancyOctree(0.1).insert_scan(*_scan(3, 20, 0))
    large = OccupancyOctree(0.1).insert_scan(*_scan(3, 200, 1))
    return small, large


@pytest.mark.parametrize("binary", [True, False])
def test_failed_save_ply_keeps_the_old_file(trees, binary, tmp_path):
    small, large = trees
    _check_failed_save_keeps_old(
        tmp_path, "m.ply", lambda p: small.save_ply(p, binary=binary),
        lambda p: large.save_ply(p, binary=binary), lambda p: p.read_bytes()[:3] == b"ply")


def test_failed_save_pcd_keeps_the_old_file(trees, tmp_path):
    small, large = trees
    before, after = _check_failed_save_keeps_old(tmp_path, "m.pcd", small.save_pcd,
                                                 large.save_pcd, read_pcd)
    np.testing.assert_array_equal(after.points, before.points)
    assert 0 < len(after.points) < len(read_pcd(tmp_path / "ref" / "m.pcd").points)


def test_failed_write_scan_graph_keeps_the_old_file(tmp_path):
    before, after = _check_failed_save_keeps_old(
        tmp_path, "s.graph", lambda p: write_scan_graph(p, [_scan(3, 5, 0)]),
        lambda p: write_scan_graph(p, [_scan(3, 50, 1)]), read_scan_graph)
    np.testing.assert_array_equal(after[0].points, before[0].points)
    assert len(after[0].points) == 5


def _grid(n):
    return OccupancyGrid2D(np.indices((n, n)).sum(axis=0) % 3 - 1, [-1.0, 2.0], 0.5)


def _ros_files(folder):
    return {name: (folder / name).read_bytes() for name in ("map.yaml", "map.pgm")}


def test_failed_save_ros_map_keeps_the_old_pair(tmp_path):
    small, large = _grid(4), _grid(40)
    small.save_ros_map(tmp_path / "map.yaml")
    old = _ros_files(tmp_path)
    (tmp_path / "ref").mkdir()
    large.save_ros_map(tmp_path / "ref" / "map.yaml")
    size = (tmp_path / "ref" / "map.pgm").stat().st_size
    got = _in_child(lambda: large.save_ros_map(tmp_path / "map.yaml"), limit=size - 1)
    assert got.startswith(f"OSError {errno.EFBIG}"), got
    assert _ros_files(tmp_path) == old
    assert sorted(os.listdir(tmp_path)) == ["map.pgm", "map.yaml", "ref"]
    np.testing.assert_array_equal(OccupancyGrid2D.load_ros_map(tmp_path / "map.yaml").states,
                                  small.states)


class _FailingReplace:
    """os.replace that raises on its `fail_on`-th call (counting from 1)."""

    def __init__(self, fail_on, real=os.replace):
        self.calls, self.fail_on, self.real = [], fail_on, real

    def __call__(self, src, dst, **kw):
        self.calls.append(os.path.basename(dst))
        if len(self.calls) == self.fail_on:
            raise OSError(errno.EIO, "simulated failure", dst)
        return self.real(src, dst, **kw)


def test_ros_map_replaces_the_image_then_the_yaml(tmp_path, monkeypatch):
    fake = _FailingReplace(fail_on=0)
    monkeypatch.setattr(os, "replace", fake)
    _grid(4).save_ros_map(tmp_path / "map.yaml")
    assert fake.calls == ["map.pgm", "map.yaml"]


def test_ros_map_failing_between_the_two_replacements_keeps_the_old_pair(tmp_path,
                                                                         monkeypatch):
    small, large = _grid(4), _grid(40)
    small.save_ros_map(tmp_path / "map.yaml")
    old = _ros_files(tmp_path)
    fake = _FailingReplace(fail_on=2)         # the image is replaced, the YAML is not
    monkeypatch.setattr(os, "replace", fake)
    with pytest.raises(OSError, match="simulated failure"):
        large.save_ros_map(tmp_path / "map.yaml")
    assert fake.calls[:2] == ["map.pgm", "map.yaml"]
    monkeypatch.undo()
    assert _ros_files(tmp_path) == old                  # the old image was put back
    assert sorted(os.listdir(tmp_path)) == ["map.pgm", "map.yaml"]
    back = OccupancyGrid2D.load_ros_map(tmp_path / "map.yaml")
    np.testing.assert_array_equal(back.states, small.states)


def test_ros_map_killed_between_the_replacements_never_names_a_missing_image(tmp_path):
    # a process killed after the first replacement: the image is there, the YAML file
    # (which would name it) is not yet: a YAML file never names a missing image
    def killed():
        real = os.replace
        calls = []

        def replace(src, dst):
            calls.append(dst)
            if len(calls) == 2:
                os._exit(0)
            real(src, dst)
        os.replace = replace
        _grid(4).save_ros_map(tmp_path / "map.yaml")
    _in_child(killed)
    assert (tmp_path / "map.pgm").is_file() and not (tmp_path / "map.yaml").exists()
    image = (tmp_path / "map.pgm").read_bytes()
    assert image.startswith(b"P5") and len(image) > 16      # complete, not truncated


def test_non_bmp_file_names_round_trip(tmp_path, trees):
    small, _ = trees
    small.save(tmp_path / "map😀.bt")
    assert OccupancyOctree.load(tmp_path / "map😀.bt").num_nodes > 0
    yaml_path, pgm = _grid(3).save_ros_map(str(tmp_path / "map😀.yaml"))
    assert pgm.name == "map😀.pgm"
    np.testing.assert_array_equal(OccupancyGrid2D.load_ros_map(yaml_path).states,
                                  _grid(3).states)
    assert sorted(os.listdir(tmp_path)) == ["map😀.bt", "map😀.pgm", "map😀.yaml"]


_CLI_CHILD = """
import resource, signal, sys
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)      # EFBIG instead of death
limit = int(sys.argv[1])
if limit >= 0:
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, resource.getrlimit(resource.RLIMIT_FSIZE)[1]))
from occgp.cli import main
sys.exit(main(["map", sys.argv[2], "-o", sys.argv[3], "--no-progress"]))
"""


@pytest.mark.slow
def test_cli_map_output_keeps_the_old_file_when_the_write_fails(tmp_path):
    # a fresh interpreter, not a fork: the command line's threads must not meet a
    # fork of this test process's

    small, large = tmp_path / "small.pcd", tmp_path / "large.pcd"
    write_pcd(small, _scan(3, 10, 0)[0])
    write_pcd(large, _scan(3, 200, 1)[0])
    out = tmp_path / "out"
    out.mkdir()

    def run(scans, output, limit=-1):
        return subprocess.run([sys.executable, "-c", _CLI_CHILD, str(limit), str(scans),
                               str(output)], capture_output=True, text=True, timeout=120)
    assert run(small, out / "m.bt").returncode == 0
    assert run(large, tmp_path / "m.bt").returncode == 0
    old = (out / "m.bt").read_bytes()
    limit = (tmp_path / "m.bt").stat().st_size - 1
    assert limit >= len(old)
    got = run(large, out / "m.bt", limit)
    assert got.returncode == 1, got.stderr              # the CLI failed ...
    assert "File too large" in got.stderr, got.stderr
    assert (out / "m.bt").read_bytes() == old           # ... and kept the old map
    assert os.listdir(out) == ["m.bt"]
    assert OccupancyOctree.load(out / "m.bt").num_nodes > 0


def test_failed_figure_save_keeps_the_old_file(tmp_path):
    pytest.importorskip("matplotlib", reason="the demo's figures need matplotlib")
    from matplotlib.figure import Figure

    from occgp.cli._demo import _save_figure

    def figure(n):
        fig = Figure(figsize=(2, 2))
        fig.subplots().imshow(np.random.default_rng(n).uniform(size=(n, n)))
        return fig
    _check_failed_save_keeps_old(tmp_path, "f.png", lambda p: _save_figure(figure(2), p),
                                 lambda p: _save_figure(figure(40), p),
                                 lambda p: p.read_bytes()[:4] == b"\x89PNG")


def test_failed_iln_checkpoint_save_keeps_the_old_file(tmp_path):
    torch = pytest.importorskip("torch", reason="ILN checkpoints need the iln extra (torch)")
    from occgp.iln.training import (CHECKPOINT_FORMAT, CHECKPOINT_VERSION, _save,
                                    load_checkpoint)

    def ckpt(n):
        return {"format": CHECKPOINT_FORMAT, "version": CHECKPOINT_VERSION, "step": n,
                "w": torch.arange(n, dtype=torch.float64)}
    before, after = _check_failed_save_keeps_old(
        tmp_path, "last.pt", lambda p: _save(p, ckpt(4)), lambda p: _save(p, ckpt(4000)),
        load_checkpoint)
    assert after["step"] == before["step"] == 4


def test_failed_iln_shard_save_keeps_the_old_file(tmp_path):
    from occgp.iln import LidarModel
    from occgp.iln.data import _write_shard, load_shards

    shards = tmp_path / "shards"
    shards.mkdir()
    model = LidarModel(16, 1024, (-15.0, 15.0), 360.0, 50.0)

    def shard(path, n):
        rng = np.random.default_rng(n)
        _write_shard(path, {"r16x1024": rng.uniform(1, 40, (n, 16, 1024)).astype(np.float32)},
                     np.zeros(n, np.int64), np.tile(np.eye(4), (n, 1, 1)), model)
    before, after = _check_failed_save_keeps_old(
        shards, "shard_00000.npz", lambda p: shard(p, 1), lambda p: shard(p, 3),
        lambda p: load_shards(p.parent, ["16x1024"]))
    np.testing.assert_array_equal(after["16x1024"], before["16x1024"])
    assert after["16x1024"].shape == (1, 16, 1024)


# ------------------------------------------------------------------ the helper itself
def test_an_exception_in_the_writer_keeps_the_old_file(tmp_path):
    path = tmp_path / "a.bin"
    write_bytes(path, b"old")
    for exc in (KeyboardInterrupt, ValueError):
        with pytest.raises(exc):
            with atomic_open(path) as fh:
                fh.write(b"new, half written")
                raise exc()
        assert path.read_bytes() == b"old"
        assert os.listdir(tmp_path) == ["a.bin"]
    with pytest.raises(RuntimeError):
        with atomic_path(path) as tmp:
            with open(tmp, "wb") as fh:
                fh.write(b"new")
            raise RuntimeError
    assert path.read_bytes() == b"old" and os.listdir(tmp_path) == ["a.bin"]


def test_a_missing_folder_is_an_oserror_naming_the_path(tmp_path):
    path = tmp_path / "no" / "such" / "map.bt"
    with pytest.raises(FileNotFoundError, match=r"folder .*no/such' does not exist.*map\.bt"):
        write_bytes(path, b"x")
    with pytest.raises(OSError, match=r"no/such/map\.bt"):
        OccupancyOctree(0.1).save(path)
    with pytest.raises(IsADirectoryError, match="over a folder"):
        write_bytes(tmp_path, b"x")


def test_permissions_kept_or_from_the_umask(tmp_path):
    path = tmp_path / "a.bin"
    old_umask = os.umask(0o027)
    try:
        write_bytes(path, b"1")
        assert stat.S_IMODE(path.stat().st_mode) == 0o640       # 0o666 & ~0o027
        os.chmod(path, 0o604)
        write_bytes(path, b"2")
        assert stat.S_IMODE(path.stat().st_mode) == 0o604       # the old file's bits
    finally:
        os.umask(old_umask)
    assert path.read_bytes() == b"2"


def test_a_symbolic_link_is_written_through(tmp_path):
    target = tmp_path / "target.bin"
    write_bytes(target, b"old")
    link = tmp_path / "link.bin"
    link.symlink_to(target)
    write_bytes(link, b"new")
    assert link.is_symlink() and target.read_bytes() == b"new"
    assert sorted(os.listdir(tmp_path)) == ["link.bin", "target.bin"]


def test_a_group_restores_what_it_replaced(tmp_path, monkeypatch):
    a, b = tmp_path / "a", tmp_path / "b"           # b did not exist before
    write_bytes(a, b"old a")
    monkeypatch.setattr(os, "replace", _FailingReplace(fail_on=2))
    with pytest.raises(OSError, match="simulated failure"):
        with atomic_group(a, b) as (ta, tb):
            for t in (ta, tb):
                with open(t, "wb") as fh:
                    fh.write(b"new")
    monkeypatch.undo()
    assert a.read_bytes() == b"old a" and os.listdir(tmp_path) == ["a"]
    with atomic_group(b, a) as (tb, ta):
        for t in (tb, ta):
            with open(t, "wb") as fh:
                fh.write(b"new")
    assert a.read_bytes() == b.read_bytes() == b"new"
    assert sorted(os.listdir(tmp_path)) == ["a", "b"]


def test_every_writer_goes_through_the_atomic_helper():
    # no module of occgp opens a file for writing by itself
    import re
    from pathlib import Path

    root = Path(occgp.__file__).parent
    # open(NAME, "w...") but for the helper's temporary files (names ending in tmp),
    # Path.write_*, and savers given a path rather than the helper's file object
    pattern = re.compile(r"open\((?!\w*tmp\b)[^)]*[\"'][wax]b?[\"']|\.write_(bytes|text)\(|"
                         r"torch\.save\([^,]*,\s*(?!fh?\))\w|savefig\((?!fh?\b)|"
                         r"savez\w*\((?!fh?\b)|\.tofile\(|imwrite\(")
    found = [f"{p.relative_to(root)}:{n}" for p in sorted(root.rglob("*.py"))
             if p.name != "_atomic.py"
             for n, line in enumerate(p.read_text().splitlines(), 1)
             if pattern.search(line) and not line.lstrip().startswith((">>>", "..."))]
    assert not found, found


def test_a_special_file_is_written_directly_not_replaced(tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    reader = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)
    try:
        write_bytes(fifo, b"through the pipe")
        assert os.read(reader, 100) == b"through the pipe"
    finally:
        os.close(reader)
    assert stat.S_ISFIFO(os.stat(fifo).st_mode) and os.listdir(tmp_path) == ["pipe"]


def test_long_names_and_read_only_files(tmp_path):
    path = tmp_path / ("é" * 120 + ".bt")                   # 244 bytes: near NAME_MAX
    OccupancyOctree(0.1).insert_scan(*_scan(3, 5, 0)).save(path)
    assert OccupancyOctree.load(path).num_nodes > 0 and os.listdir(tmp_path) == [path.name]
    if os.geteuid() == 0:
        return                                  # root may write a read-only file anyway
    write_bytes(tmp_path / "ro", b"old")
    os.chmod(tmp_path / "ro", 0o444)
    with pytest.raises(PermissionError, match="ro"):
        write_bytes(tmp_path / "ro", b"new")
    assert (tmp_path / "ro").read_bytes() == b"old"
