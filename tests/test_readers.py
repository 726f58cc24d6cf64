"""Tests of the scan readers and writers in occgp.datasets."""

import bz2
import gzip
import shutil
import struct
import subprocess
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from occgp.datasets import (
    Scan,
    load_scan_folder,
    lzf_decompress,
    read_kitti_bin,
    read_pcd,
    read_scan_graph,
    read_scan_log,
    read_scans,
    read_xyz,
    write_pcd,
    write_scan_graph,
)

DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data"
LA3DM = DATA / "la3dm_sim_structured"
OCTOMAP = DATA / "octomap"


def _need(path):
    if not path.exists():
        pytest.skip(f"real data not available: {path} is absent (see shared/data/README.md)")
    return path


def _lzf_compress(data):
    """Greedy LZF encoder (tests only): real back references, overlapping too."""
    out, lit, table, i, n = bytearray(), bytearray(), {}, 0, len(data)

    def flush():
        for k in range(0, len(lit), 32):
            chunk = lit[k:k + 32]
            out.append(len(chunk) - 1)
            out.extend(chunk)
        lit.clear()

    while i < n:
        key = data[i:i + 3]
        ref = table.get(key) if len(key) == 3 else None
        if len(key) == 3:
            table[key] = i
        if ref is not None and i - ref - 1 < 8192:
            length, limit = 3, min(264, n - i)
            while length < limit and data[ref + length] == data[i + length]:
                length += 1
            flush()
            code, off = length - 2, i - ref - 1
            if code < 7:
                out.append((code << 5) | (off >> 8))
            else:
                out += bytes([(7 << 5) | (off >> 8), code - 7])
            out.append(off & 0xFF)
            i += length
        else:
            lit.append(data[i])
            i += 1
    flush()
    return bytes(out)


@pytest.fixture
def cloud():
    rng = np.random.default_rng(0)
    return rng.uniform(-5, 5, (50, 3)), np.array([0.5, -1.0, 0.25])


# --------------------------------------------------------------------------- #
# real data
# --------------------------------------------------------------------------- #
def test_la3dm_pcd_files():
    folder = _need(LA3DM)
    for path in sorted(folder.glob("*.pcd")):
        scan, fields = read_pcd(path, return_fields=True)
        assert scan.points.shape == (3500, 3) and scan.points.dtype == np.float64
        assert set(fields) == {"x", "y", "z", "intensity"}
        assert fields["intensity"].dtype == np.float32
        header = path.read_bytes()[:400].decode("ascii", "replace")
        viewpoint = next(ln for ln in header.splitlines() if ln.startswith("VIEWPOINT"))
        assert_allclose(scan.origin, [float(v) for v in viewpoint.split()[1:4]])


def test_la3dm_folder_is_in_numeric_order():
    scans = load_scan_folder(_need(LA3DM))
    assert len(scans) == 12
    poses = np.array([s.origin[:2] for s in scans])
    expected = np.repeat([[1, 1], [4, 2], [5, 5], [3, 8]], 3, axis=0)
    assert_allclose(poses, expected, atol=1e-3)
    assert len(read_scans(LA3DM)) == 12


def test_octomap_scan_dat_bz2():
    scan = read_xyz(_need(OCTOMAP / "scan.dat.bz2"))
    assert scan.points.shape == (88206, 3)
    assert_array_equal(scan.origin, [0, 0, 0])
    assert_allclose(scan.points[0], [-0.0434742, -4.82982, 0.499645])
    assert len(read_scans(OCTOMAP / "scan.dat.bz2")) == 1


def test_octomap_spherical_scan_graph():
    scans = read_scan_graph(_need(OCTOMAP / "spherical_scan.graph"))
    assert len(scans) == 1
    scan = scans[0]
    assert scan.points.shape == (10201, 3)
    assert_allclose(scan.origin, [1.0, 0.0, -0.5])
    r = np.linalg.norm(scan.points - scan.origin, axis=1)
    assert_allclose(r, r[0], atol=1e-5)  # a sphere patch about the sensor


# --------------------------------------------------------------------------- #
# PCD
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("data", ["ascii", "binary", "binary_compressed"])
@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_pcd_round_trip(tmp_path, cloud, data, dtype):
    points, origin = cloud
    extra = {
        "intensity": np.linspace(0, 1, 50).astype(np.float32),
        "ring": np.arange(50, dtype=np.uint16),
        "label": -np.arange(50, dtype=np.int64) * 10**12,
        "normal": np.arange(150, dtype=np.float64).reshape(50, 3) / 7,  # COUNT 3
        "flag": np.arange(50, dtype=np.int8) % 3,
    }
    path = tmp_path / "cloud.pcd"
    write_pcd(path, points, origin, data=data, fields=extra, dtype=dtype)
    scan, fields = read_pcd(path, return_fields=True)
    tol = 1e-6 if dtype == "float32" else 0
    assert_allclose(scan.points, points, rtol=tol, atol=tol)
    assert_array_equal(scan.origin, origin)
    for name, values in extra.items():
        assert fields[name].dtype == values.dtype
        if data == "ascii" and name == "label":
            assert_allclose(fields[name], values)  # ascii goes through float64
        else:
            assert_array_equal(fields[name], values)


def test_pcd_empty_cloud(tmp_path):
    for data in ("ascii", "binary", "binary_compressed"):
        write_pcd(tmp_path / f"e_{data}.pcd", np.empty((0, 3)), data=data)
        assert read_pcd(tmp_path / f"e_{data}.pcd").points.shape == (0, 3)


def test_pcd_nan_points_are_dropped(tmp_path):
    points = np.array([[1.0, 2, 3], [np.nan, np.nan, np.nan], [4.0, 5, 6]])
    for data in ("ascii", "binary"):
        write_pcd(tmp_path / "o.pcd", points, data=data, fields={"i": np.arange(3.0)})
        scan, fields = read_pcd(tmp_path / "o.pcd", return_fields=True)
        assert_array_equal(scan.points, [[1, 2, 3], [4, 5, 6]])
        assert_array_equal(fields["i"], [0, 2])


def test_pcd_old_header_and_padding_field(tmp_path):
    # v0.5-style: no COUNT / WIDTH / VIEWPOINT; padding field "_" between fields
    text = "VERSION .5\nFIELDS x _ y z\nSIZE 4 4 4 4\nTYPE F F F F\nPOINTS 2\nDATA ascii\n"
    text += "1 0 2 3\n4 0 5 6\n"
    (tmp_path / "old.pcd").write_text(text)
    scan, fields = read_pcd(tmp_path / "old.pcd", return_fields=True)
    assert_array_equal(scan.points, [[1, 2, 3], [4, 5, 6]])
    assert_array_equal(scan.origin, [0, 0, 0])
    assert "_" not in fields


def test_pcd_binary_with_trailing_bytes_and_viewpoint_rotation(tmp_path):
    # PCL pads binary files (the la3dm files end with zeros); a rotated VIEWPOINT
    # leaves the points as stored
    header = ("VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 2\n"
              "HEIGHT 1\nVIEWPOINT 1 2 3 0 0 0 1\nPOINTS 2\nDATA binary\n")
    body = np.array([[1, 2, 3], [4, 5, 6]], np.float32).tobytes() + bytes(100)
    (tmp_path / "p.pcd").write_bytes(header.encode() + body)
    scan = read_pcd(tmp_path / "p.pcd")
    assert_array_equal(scan.points, [[1, 2, 3], [4, 5, 6]])
    assert_array_equal(scan.origin, [1, 2, 3])


def test_pcd_binary_compressed_with_real_lzf(tmp_path):
    rng = np.random.default_rng(0)
    pts = np.round(rng.uniform(-1, 1, (300, 3)), 1).astype(np.float32)  # compressible
    pts[100:200] = 0.0  # long runs: overlapping back references
    soa = b"".join(np.ascontiguousarray(pts[:, k]).tobytes() for k in range(3))
    comp = _lzf_compress(soa)
    assert len(comp) < len(soa) / 2
    header = ("VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 300\n"
              "HEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 300\nDATA binary_compressed\n")
    path = tmp_path / "c.pcd"
    path.write_bytes(header.encode() + struct.pack("<II", len(comp), len(soa)) + comp)
    assert_array_equal(read_pcd(path).points, pts)


def test_lzf_decompress_round_trip_and_errors():
    rng = np.random.default_rng(0)
    raw = bytes(rng.integers(0, 4, 5000, dtype=np.uint8)) + bytes(700) + b"abc" * 300
    assert lzf_decompress(_lzf_compress(raw), len(raw)) == raw
    with pytest.raises(ValueError, match="literal run of 5 bytes .* passes the end"):
        lzf_decompress(b"\x04ab", 5)
    with pytest.raises(ValueError, match="back reference 3 bytes before the start"):
        lzf_decompress(b"\x00a\x20\x02", 4)
    with pytest.raises(ValueError, match="decompressed to 3 bytes, expected 4"):
        lzf_decompress(b"\x02abc", 4)
    with pytest.raises(ValueError, match="truncated back reference"):
        lzf_decompress(b"\x00a\x20", 4)


@pytest.mark.parametrize(
    "data, cut, match",
    [
        ("binary", 7, r"truncated PCD binary data: expected 600 bytes \(50 points x 12 bytes\)"),
        ("binary_compressed", 7, r"truncated PCD binary_compressed data: expected \d+ compressed"),
        ("ascii", 30, r"data row 50 has 1 values, expected 3 \(truncated or malformed file\)"),
    ],
)
def test_pcd_truncated(tmp_path, cloud, data, cut, match):
    path = tmp_path / "full.pcd"
    write_pcd(path, cloud[0], data=data)
    raw = path.read_bytes()
    (tmp_path / "cut.pcd").write_bytes(raw[:-cut])
    with pytest.raises(ValueError, match=match):
        read_pcd(tmp_path / "cut.pcd")


_GOOD = {
    "FIELDS": "FIELDS x y z", "SIZE": "SIZE 4 4 4", "TYPE": "TYPE F F F", "COUNT": "COUNT 1 1 1",
    "WIDTH": "WIDTH 1", "HEIGHT": "HEIGHT 1", "VIEWPOINT": "VIEWPOINT 0 0 0 1 0 0 0",
    "POINTS": "POINTS 1", "DATA": "DATA ascii",
}


@pytest.mark.parametrize(
    "change, match",
    [
        ({"SIZE": "SIZE 4 4"}, "SIZE has 2 values, expected 3"),
        ({"TYPE": "TYPE F F X"}, "unsupported TYPE X with SIZE 4"),
        ({"SIZE": "SIZE 4 4 3"}, "unsupported TYPE F with SIZE 3"),
        ({"FIELDS": "FIELDS x y w"}, "lack 'z'"),
        ({"POINTS": "POINTS 2"}, r"POINTS 2 differs from WIDTH x HEIGHT = 1 x 1"),
        ({"DATA": "DATA zipped"}, "DATA must be one of"),
        ({"VIEWPOINT": "VIEWPOINT 0 0 0"}, "VIEWPOINT must be 7 numbers"),
        ({"WIDTH": "WIDTH one"}, "WIDTH must hold integers"),
        ({"HEIGHT": "COLOR 1"}, "unknown PCD header entry 'COLOR'"),
        ({"DATA": ""}, "no DATA line"),
        ({"COUNT": "COUNT 1 1 2"}, "'z' must have COUNT 1"),
    ],
)
def test_pcd_malformed_header(tmp_path, change, match):
    lines = {**_GOOD, **change}
    body = "1 2 3\n" if lines["DATA"] else ""
    (tmp_path / "bad.pcd").write_text("\n".join(v for v in lines.values() if v) + "\n" + body)
    with pytest.raises(ValueError, match=match):
        read_pcd(tmp_path / "bad.pcd")


def test_pcd_ascii_missing_rows(tmp_path, cloud):
    write_pcd(tmp_path / "full.pcd", cloud[0], data="ascii")
    text = (tmp_path / "full.pcd").read_text().splitlines(keepends=True)
    (tmp_path / "cut.pcd").write_text("".join(text[:-1]))
    with pytest.raises(ValueError, match="PCD ascii data has 49 rows of 3 values, expected 50"):
        read_pcd(tmp_path / "cut.pcd")


def test_pcd_malformed_ascii_values(tmp_path):
    text = "\n".join(_GOOD.values()) + "\n1 two 3\n"
    (tmp_path / "bad.pcd").write_text(text)
    with pytest.raises(ValueError, match="data row 1 holds a non-number: '1 two 3'"):
        read_pcd(tmp_path / "bad.pcd")


def test_write_pcd_rejects_bad_input(tmp_path):
    with pytest.raises(ValueError, match=r"points must have shape \(n_points, 3\)"):
        write_pcd(tmp_path / "x.pcd", np.zeros((3, 2)))
    with pytest.raises(ValueError, match="data must be one of"):
        write_pcd(tmp_path / "x.pcd", np.zeros((3, 3)), data="zip")
    with pytest.raises(ValueError, match=r"fields\['c'\] has unsupported dtype bool"):
        write_pcd(tmp_path / "x.pcd", np.zeros((3, 3)), fields={"c": np.ones(3, bool)})
    with pytest.raises(ValueError, match=r"fields\['c'\] must have shape \(3,\)"):
        write_pcd(tmp_path / "x.pcd", np.zeros((3, 3)), fields={"c": np.ones(4)})


# --------------------------------------------------------------------------- #
# missing files and dispatch
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize(
    "reader, name",
    [(read_pcd, "a.pcd"), (read_kitti_bin, "a.bin"), (read_scan_graph, "a.graph"),
     (read_xyz, "a.xyz"), (read_scan_log, "a.log"), (read_scans, "a.pcd"),
     (load_scan_folder, "folder")],
)
def test_missing_file_raises_oserror(tmp_path, reader, name):
    with pytest.raises(OSError, match="no such"):
        reader(tmp_path / name)


def test_readers_reject_non_path():
    with pytest.raises(TypeError, match="path must be a str or os.PathLike"):
        read_pcd(3)


def test_read_scans_dispatch(tmp_path, cloud):
    points, origin = cloud
    write_pcd(tmp_path / "a.pcd", points, origin)
    np.hstack([points, np.zeros((50, 1))]).astype(np.float32).tofile(tmp_path / "b.bin")
    write_scan_graph(tmp_path / "c.graph", [Scan(points, origin)] * 2)
    np.savetxt(tmp_path / "d.xyz", points)
    (tmp_path / "e.log").write_text("NODE 0 0 0 0 0 0\n1 2 3\nNODE 1 0 0 0 0 0\n1 2 3\n")
    counts = {p.name: len(read_scans(p)) for p in sorted(tmp_path.iterdir())}
    assert counts == {"a.pcd": 1, "b.bin": 1, "c.graph": 2, "d.xyz": 1, "e.log": 2}
    assert len(read_scans(tmp_path)) == 7
    (tmp_path / "f.ply").write_text("ply\n")
    with pytest.raises(ValueError, match="unsupported scan file suffix '.ply'"):
        read_scans(tmp_path / "f.ply")


def test_load_scan_folder_order_and_errors(tmp_path):
    for i in (10, 2, 1, 11):
        write_pcd(tmp_path / f"scan_{i}.pcd", [[float(i), 0.0, 0.0]])
    (tmp_path / "LICENSE").write_text("MIT\n")
    assert [s.points[0, 0] for s in load_scan_folder(tmp_path)] == [1, 2, 10, 11]
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(ValueError, match=r"no files matching '\*.pcd'"):
        load_scan_folder(empty)
    with pytest.raises(NotADirectoryError, match="expected a directory"):
        load_scan_folder(tmp_path / "scan_1.pcd")


# --------------------------------------------------------------------------- #
# KITTI .bin
# --------------------------------------------------------------------------- #
def test_kitti_bin_round_trip_and_truncation(tmp_path, cloud):
    points, _ = cloud
    rec = np.hstack([points, np.ones((50, 1))]).astype(np.float32)
    rec.tofile(tmp_path / "s.bin")
    scan = read_kitti_bin(tmp_path / "s.bin", origin=(1, 2, 3))
    assert_allclose(scan.points, points, rtol=1e-6, atol=1e-6)
    assert_array_equal(scan.origin, [1, 2, 3])
    (tmp_path / "t.bin").write_bytes(rec.tobytes()[:-5])
    with pytest.raises(ValueError, match="795 bytes is not a multiple of 16"):
        read_kitti_bin(tmp_path / "t.bin")


# --------------------------------------------------------------------------- #
# OctoMap .graph
# --------------------------------------------------------------------------- #
def test_scan_graph_round_trip(tmp_path, cloud):
    points, origin = cloud
    scans = [Scan(points, origin), Scan(points[:7] * 2, origin + 1)]
    write_scan_graph(tmp_path / "g.graph", scans)
    back = read_scan_graph(tmp_path / "g.graph")
    assert len(back) == 2
    for a, b in zip(scans, back):
        assert_allclose(b.points, a.points, atol=1e-12)
        assert_array_equal(b.origin, a.origin)


def _graph_bytes(local, t, q):
    pts = b"".join(struct.pack("<i3d", 3, *p) for p in local)
    pose = struct.pack("<i3di4d", 3, *t, 4, *q)
    return struct.pack("<II", 1, len(local)) + pts + pose + struct.pack("<II", 0, 0)


def test_scan_graph_applies_the_node_pose(tmp_path):
    half = np.sqrt(0.5)  # 90 degrees about z: (w, x, y, z) = (cos 45, 0, 0, sin 45)
    raw = _graph_bytes([[1.0, 0, 0], [0, 2.0, 0]], [1.0, 2.0, 3.0], [half, 0, 0, half])
    (tmp_path / "r.graph").write_bytes(raw)
    scan = read_scan_graph(tmp_path / "r.graph")[0]
    assert_allclose(scan.points, [[1, 3, 3], [-1, 2, 3]], atol=1e-12)
    assert_array_equal(scan.origin, [1, 2, 3])


def test_scan_graph_truncated_and_malformed(tmp_path):
    raw = _graph_bytes([[1.0, 0, 0], [0, 2.0, 0]], [0, 0, 0], [1, 0, 0, 0])
    (tmp_path / "t.graph").write_bytes(raw[:40])
    with pytest.raises(ValueError, match=r"expected 56 bytes for the 2 points of node 0 .* 32"):
        read_scan_graph(tmp_path / "t.graph")
    (tmp_path / "t.graph").write_bytes(raw[:-2])
    with pytest.raises(ValueError, match="expected 4 bytes for the edge count .* found 2"):
        read_scan_graph(tmp_path / "t.graph")
    (tmp_path / "x.graph").write_bytes(raw + b"junk")
    with pytest.raises(ValueError, match="4 unexpected bytes after the 0 edges"):
        read_scan_graph(tmp_path / "x.graph")
    bad = bytearray(raw)
    bad[8:12] = struct.pack("<i", 7)
    (tmp_path / "b.graph").write_bytes(bytes(bad))
    with pytest.raises(ValueError, match="a point of node 0 is not tagged 3"):
        read_scan_graph(tmp_path / "b.graph")


@pytest.mark.skipif(shutil.which("graph2tree") is None, reason="OctoMap's graph2tree not installed")
def test_graph2tree_reads_written_graph(tmp_path, cloud):
    points, origin = cloud
    write_scan_graph(tmp_path / "w.graph", [Scan(points, origin)])
    out = subprocess.run(
        ["graph2tree", "-i", str(tmp_path / "w.graph"), "-o", str(tmp_path / "w.bt"),
         "-res", "0.5"],
        capture_output=True, text=True, timeout=60,
    )
    assert out.returncode == 0, out.stderr
    assert "Reading 50 points" in out.stdout + out.stderr
    assert (tmp_path / "w.bt").stat().st_size > 0


@pytest.mark.skipif(shutil.which("log2graph") is None, reason="OctoMap's log2graph not installed")
def test_scan_log_matches_octomap_log2graph(tmp_path):
    log = tmp_path / "s.log"
    log.write_text("NODE 1 2 3 0.3 -0.2 0.7\n1 0 0\n0 1 0\n2.5 -1 0.25\n"
                   "NODE -1 0.5 0 0 0.4 -1.2\n1 1 1\n")
    subprocess.run(["log2graph", str(log), str(tmp_path / "s.graph")], check=True,
                   capture_output=True, timeout=60)
    ours, theirs = read_scan_log(log), read_scan_graph(tmp_path / "s.graph")
    assert len(ours) == len(theirs) == 2
    for a, b in zip(ours, theirs):
        assert_allclose(a.points, b.points, atol=1e-6)  # OctoMap stores floats
        assert_allclose(a.origin, b.origin, atol=1e-6)


# --------------------------------------------------------------------------- #
# text
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("suffix, opener", [("", open), (".bz2", bz2.open), (".gz", gzip.open)])
def test_xyz_round_trip_compressed(tmp_path, cloud, suffix, opener):
    points, _ = cloud
    path = tmp_path / f"scan.xyz{suffix}"
    with opener(path, "wt") as fh:
        fh.write("# x y z intensity\n\n")
        np.savetxt(fh, np.hstack([points, np.ones((50, 1))]), fmt="%.17g")
    scan = read_xyz(path, origin=[0, 0, 1])
    assert_array_equal(scan.points, points)
    assert_array_equal(scan.origin, [0, 0, 1])


def test_xyz_malformed_and_corrupt(tmp_path):
    (tmp_path / "a.xyz").write_text("1 2 3\n# c\n4 5\n")
    with pytest.raises(ValueError, match="line 3: expected 'x y z' numbers, got '4 5'"):
        read_xyz(tmp_path / "a.xyz")
    (tmp_path / "b.xyz").write_text("1 2 3\n4 x 6\n")
    with pytest.raises(ValueError, match="line 2"):
        read_xyz(tmp_path / "b.xyz")
    (tmp_path / "c.xyz").write_text("1 2 3\nnan 1 1\n")
    with pytest.raises(ValueError, match="point 1 .* not finite"):
        read_xyz(tmp_path / "c.xyz")
    raw = bz2.compress(b"1 2 3\n" * 100)
    (tmp_path / "d.xyz.bz2").write_bytes(raw[:-10])
    with pytest.raises(ValueError, match="corrupt or truncated bz2 stream"):
        read_xyz(tmp_path / "d.xyz.bz2")
    (tmp_path / "e.xyz").write_text("NODE 0 0 0 0 0 0\n1 2 3\n")
    with pytest.raises(ValueError, match="use read_scan_log|read it with read_scan_log"):
        read_xyz(tmp_path / "e.xyz")


def test_scan_log_poses_and_errors(tmp_path):
    path = tmp_path / "s.log"
    path.write_text("# log\nNODE 1 0 0 0 0 1.5707963267948966\n1 0 0\n0 1 0\n"
                    "NODE 0 0 2 0 0 0\n1 1 1\n")
    a, b = read_scan_log(path)
    assert_allclose(a.points, [[1, 1, 0], [0, 0, 0]], atol=1e-12)
    assert_array_equal(a.origin, [1, 0, 0])
    assert_allclose(b.points, [[1, 1, 3]])
    path.write_text("1 2 3\nNODE 0 0 0 0 0 0\n")
    with pytest.raises(ValueError, match="points before the first NODE line"):
        read_scan_log(path)
    path.write_text("NODE 0 0 0\n1 2 3\n")
    with pytest.raises(ValueError, match="line 1: expected 'NODE x y z roll pitch yaw'"):
        read_scan_log(path)
    path.write_text("NODE 0 0 0 0 0 0\n1 2\n")
    with pytest.raises(ValueError, match="line 2"):
        read_scan_log(path)
