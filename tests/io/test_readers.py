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

from occgp.datasets import Scan
from occgp.io import (
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

DATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "data"
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
        ({"COUNT": "COUNT 1 1 0"}, "'z' has COUNT 0, expected 1 to 1048576"),
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


@pytest.mark.parametrize(
    "reader", [read_pcd, read_kitti_bin, read_scan_graph, read_xyz, read_scan_log, read_scans,
               load_scan_folder],
)
@pytest.mark.parametrize("bad, name", [(3, "int"), (b"a.pcd", "bytes"), (None, "NoneType")])
def test_readers_reject_non_path(reader, bad, name):
    with pytest.raises(TypeError, match=f"path must be a str or os.PathLike, got {name}"):
        reader(bad)


def test_readers_reject_nul_in_path():
    with pytest.raises(ValueError, match="path must not contain a NUL character"):
        read_xyz("a\0b.xyz")


def test_writers_reject_bad_arguments(tmp_path):
    with pytest.raises(TypeError, match="path must be a str or os.PathLike, got int"):
        write_pcd(5, np.zeros((1, 3)))
    with pytest.raises(TypeError, match="data must be a str"):
        write_pcd(tmp_path / "a.pcd", np.zeros((1, 3)), data=1)
    with pytest.raises(TypeError, match="fields must be a dict"):
        write_pcd(tmp_path / "a.pcd", np.zeros((1, 3)), fields=[1, 2])
    with pytest.raises(ValueError, match="dtype must be float32 or float64, got 'float16x'"):
        write_pcd(tmp_path / "a.pcd", np.zeros((1, 3)), dtype="float16x")
    with pytest.raises(ValueError, match=r"origin must be finite"):
        write_pcd(tmp_path / "a.pcd", np.zeros((1, 3)), origin=[np.nan, 0, 0])
    with pytest.raises(TypeError, match="points must be an array of numbers, got str"):
        write_pcd(tmp_path / "a.pcd", "points")
    with pytest.raises(TypeError, match="scans must be a sequence .* got int"):
        write_scan_graph(tmp_path / "a.graph", 5)
    with pytest.raises(TypeError, match=r"scans\[0\] must be a Scan or a \(points, origin\) pair"):
        write_scan_graph(tmp_path / "a.graph", [5])
    with pytest.raises(ValueError, match=r"scans\[0\].origin must be finite"):
        write_scan_graph(tmp_path / "a.graph", [(np.zeros((1, 3)), [0, np.inf, 0])])
    with pytest.raises(ValueError, match=r"scans\[1\].points must be finite"):
        write_scan_graph(tmp_path / "a.graph", [(np.zeros((1, 3)), np.zeros(3)),
                                                (np.full((1, 3), np.nan), np.zeros(3))])
    assert not (tmp_path / "a.graph").exists()
    write_scan_graph(tmp_path / "g.graph", (Scan(np.ones((2, 3)), np.zeros(3)) for _ in range(2)))
    assert len(read_scan_graph(tmp_path / "g.graph")) == 2


@pytest.mark.parametrize("reader", [read_kitti_bin, read_xyz])
@pytest.mark.parametrize(
    "origin, exc, match",
    [([np.nan, 0, 0], ValueError, r"origin must be finite \(no NaN or inf\), got \[nan, 0.0, 0.0\]"),
     ([0, np.inf, 0], ValueError, r"origin must be finite"),
     ([0, 0], ValueError, r"origin must have shape \(3,\), got \(2,\)"),
     ("abc", TypeError, "origin must be an array of numbers, got str"),
     ({"x": 1}, TypeError, "origin must be an array of numbers, got dict"),
     ([[0, 0], [1]], ValueError, "origin must be an array of numbers")],
)
def test_readers_reject_bad_origin(tmp_path, reader, origin, exc, match):
    np.zeros((2, 4), np.float32).tofile(tmp_path / "s.bin")
    (tmp_path / "s.xyz").write_text("1 2 3\n")
    name = "s.bin" if reader is read_kitti_bin else "s.xyz"
    with pytest.raises(exc, match=match):
        reader(tmp_path / name, origin=origin)


def test_read_pcd_rejects_non_bool_return_fields(tmp_path):
    write_pcd(tmp_path / "a.pcd", np.zeros((1, 3)))
    with pytest.raises(TypeError, match="return_fields must be a bool, got str"):
        read_pcd(tmp_path / "a.pcd", return_fields="yes")


def test_load_scan_folder_rejects_bad_pattern(tmp_path):
    write_pcd(tmp_path / "a.pcd", np.zeros((1, 3)))
    with pytest.raises(TypeError, match="pattern must be a str or None, got int"):
        load_scan_folder(tmp_path, 5)
    with pytest.raises(ValueError, match="pattern must be a non-empty glob relative to the folder"):
        load_scan_folder(tmp_path, "")
    with pytest.raises(ValueError, match="pattern must be a non-empty glob relative to the folder"):
        load_scan_folder(tmp_path, "/etc/*.pcd")


def test_non_finite_points_are_dropped_and_logged(tmp_path, caplog):
    bad = np.array([[1, 2, 3, 0], [np.nan, 0, 0, 0], [0, np.inf, 0, 0], [4, 5, 6, 0]], np.float32)
    bad.tofile(tmp_path / "k.bin")
    (tmp_path / "t.xyz").write_text("1 2 3\nnan 1 1\n4 5 6\n1 1e999 1\n")
    (tmp_path / "l.log").write_text("NODE 0 0 0 0 0 0\n1 2 3\ninf 0 0\n4 5 6\n")
    write_scan_graph(tmp_path / "g.graph", [Scan(np.array([[1.0, 2, 3], [4, 5, 6]]), np.zeros(3))])
    raw = bytearray((tmp_path / "g.graph").read_bytes())
    raw[12:20] = struct.pack("<d", np.nan)  # x of the first point
    (tmp_path / "g.graph").write_bytes(bytes(raw))
    write_pcd(tmp_path / "p.pcd", np.array([[1.0, 2, 3], [np.nan, 0, 0], [4, 5, 6]]))
    expect = {"k.bin": 2, "t.xyz": 2, "l.log": 1, "g.graph": 1, "p.pcd": 1}
    for name, dropped in expect.items():
        caplog.clear()
        with caplog.at_level("WARNING", logger="occgp"):
            scan = read_scans(tmp_path / name)[0]
        assert np.isfinite(scan.points).all()
        assert len(scan.points) >= 1
        assert f"dropped {dropped} of" in caplog.text and name in caplog.text
    assert_array_equal(read_xyz(tmp_path / "t.xyz").points, [[1, 2, 3], [4, 5, 6]])
    assert_array_equal(read_kitti_bin(tmp_path / "k.bin").points, [[1, 2, 3], [4, 5, 6]])


def test_scan_graph_transform_overflow_is_dropped(tmp_path):
    raw = _graph_bytes([[1e308, 0, 0], [1.0, 0, 0]], [1e308, 0, 0], [1, 0, 0, 0])
    (tmp_path / "o.graph").write_bytes(raw)
    assert_array_equal(read_scan_graph(tmp_path / "o.graph")[0].points, [[1e308 + 1, 0, 0]])


def test_scan_graph_rejects_non_finite_pose(tmp_path):
    (tmp_path / "a.graph").write_bytes(_graph_bytes([[1.0, 0, 0]], [np.nan, 0, 0], [1, 0, 0, 0]))
    with pytest.raises(ValueError, match=r"a.graph: .*node 0 has a non-finite position"):
        read_scan_graph(tmp_path / "a.graph")
    (tmp_path / "b.graph").write_bytes(_graph_bytes([[1.0, 0, 0]], [0, 0, 0], [0, 0, 0, 0]))
    with pytest.raises(ValueError, match=r"b.graph: .*node 0 has quaternion \[0.0, 0.0, 0.0, 0.0\]"):
        read_scan_graph(tmp_path / "b.graph")
    (tmp_path / "c.graph").write_bytes(_graph_bytes([[1.0, 0, 0]], [0, 0, 0], [1e300, 0, 0, 1e300]))
    assert_allclose(read_scan_graph(tmp_path / "c.graph")[0].points, [[0, 1, 0]], atol=1e-12)


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
    with pytest.raises(ValueError, match=r"t.bin: size 795 bytes is not a multiple of 16, the "
                                         r"size of a record \(KITTI: float32 x y z reflectance\)"):
        read_kitti_bin(tmp_path / "t.bin")


def _nuscenes_records(n):
    rng = np.random.default_rng(0)
    rec = np.empty((n, 5), np.float32)
    rec[:, :3] = rng.uniform(-50, 50, (n, 3))
    rec[:, 3] = rng.uniform(0, 255, n)
    rec[:, 4] = np.arange(n) % 32
    return rec


def test_nuscenes_pcd_bin_is_read_by_its_name(tmp_path):
    rec = _nuscenes_records(34688)  # 693,760 bytes: a multiple of 16 and of 20
    assert rec.nbytes == 693760 and rec.nbytes % 16 == 0
    path = tmp_path / "n015-2018-07-24-11-22-45+0800__LIDAR_TOP__1532402927647951.pcd.bin"
    rec.tofile(path)
    for scans in ([read_kitti_bin(path)], read_scans(path), load_scan_folder(tmp_path, None),
                  load_scan_folder(tmp_path, "*.bin")):
        assert len(scans) == 1
        assert_array_equal(scans[0].points, rec[:, :3].astype(np.float64))
    # the same bytes read as KITTI would give 43,360 wrong points
    assert len(read_kitti_bin(path, fields="kitti").points) == 43360
    assert len(read_kitti_bin(path, fields=4).points) == 43360


def test_bin_fields_argument(tmp_path):
    rec = _nuscenes_records(7)
    rec.tofile(tmp_path / "a.bin")  # 140 bytes: a multiple of 20, not of 16
    with pytest.raises(ValueError, match=r"a.bin: size 140 bytes is not a multiple of 16.*"
                                         r"pass fields=5"):
        read_kitti_bin(tmp_path / "a.bin")
    with pytest.raises(ValueError, match="pass fields=5"):
        read_scans(tmp_path / "a.bin")
    for fields in (5, "nuscenes", "NuScenes", np.int64(5)):
        assert_array_equal(read_kitti_bin(tmp_path / "a.bin", fields=fields).points, rec[:, :3])
    assert_array_equal(read_scans(tmp_path / "a.bin", fields=5)[0].points, rec[:, :3])
    assert_array_equal(load_scan_folder(tmp_path, "*.bin", fields=5)[0].points, rec[:, :3])
    xyz = rec[:, :3].copy()
    xyz.tofile(tmp_path / "b.bin")
    assert_array_equal(read_kitti_bin(tmp_path / "b.bin", fields=3).points, xyz)
    layout = np.dtype([("t", "<u4"), ("x", "<f8"), ("y", "<f8"), ("z", "<f8")])
    table = np.zeros(3, layout)
    table["x"], table["y"], table["z"] = [1, 2, 3], [4, 5, 6], [7, 8, 9]
    table.tofile(tmp_path / "c.bin")
    assert_array_equal(read_kitti_bin(tmp_path / "c.bin", fields=layout).points,
                       [[1, 4, 7], [2, 5, 8], [3, 6, 9]])
    rec.tofile(tmp_path / "d.pcd.bin")
    (tmp_path / "d.pcd.bin").write_bytes((tmp_path / "d.pcd.bin").read_bytes()[:-12])
    with pytest.raises(ValueError, match=r"d.pcd.bin: size 128 bytes is not a multiple of 20.*"
                                         r"nuScenes.*pass fields=4"):
        read_kitti_bin(tmp_path / "d.pcd.bin")


@pytest.mark.parametrize(
    "fields, exc, match",
    [(2, ValueError, "fields must be between 3 and 1024 float32 fields per record.*got 2"),
     (10**9, ValueError, "fields must be between 3 and 1024"),
     ("velodyne", ValueError, r"fields must be .* one of \['kitti', 'nuscenes'\], got 'velodyne'"),
     (True, TypeError, "fields must be None, an int .* got bool"),
     (4.0, TypeError, "fields must be None, an int .* got float"),
     (np.dtype("<f4"), ValueError, "fields as a dtype must be a record dtype with fields x, y"),
     (np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "S4")]), ValueError,
      "the field 'z' must be a scalar number type")],
)
def test_bin_fields_rejects_bad_values(tmp_path, fields, exc, match):
    np.zeros((2, 4), np.float32).tofile(tmp_path / "s.bin")
    with pytest.raises(exc, match=match):
        read_kitti_bin(tmp_path / "s.bin", fields=fields)
    with pytest.raises(exc, match=match):
        read_scans(tmp_path / "s.bin", fields=fields)
    with pytest.raises(exc, match=match):
        load_scan_folder(tmp_path, "*.bin", fields=fields)


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


@pytest.mark.parametrize("suffix", [".gz", ".bz2", ".xz"])
@pytest.mark.parametrize("damage", ["flip", "truncate", "garbage"])
def test_corrupt_compressed_text_is_a_value_error(tmp_path, suffix, damage):
    import lzma
    compress = {".gz": gzip.compress, ".bz2": bz2.compress, ".xz": lzma.compress}[suffix]
    raw = bytearray(compress(b"1 2 3\n4 5 6\n" * 50))
    if damage == "flip":
        raw[len(raw) // 2] ^= 0xFF  # gzip: zlib.error "invalid ..." before the fix
        raw[len(raw) // 2 + 1] ^= 0x55
    elif damage == "truncate":
        raw = raw[: len(raw) // 2]
    else:
        raw = bytearray(b"this is not compressed")
    path = tmp_path / f"s.xyz{suffix}"
    path.write_bytes(bytes(raw))
    with pytest.raises(ValueError, match=rf"s.xyz{suffix}: corrupt or truncated {suffix[1:]}"):
        read_xyz(path)
    with pytest.raises(ValueError, match=rf"s.xyz{suffix}: corrupt or truncated"):
        read_scans(path)


def test_gzip_bad_deflate_block_was_zlib_error(tmp_path):
    raw = bytearray(gzip.compress(b"1 2 3\n" * 10))
    raw[10] = 0xFF  # first byte of the deflate stream: an invalid block type
    (tmp_path / "s.xyz.gz").write_bytes(bytes(raw))
    with pytest.raises(ValueError, match=r"s.xyz.gz: corrupt or truncated gz stream"):
        read_xyz(tmp_path / "s.xyz.gz")


def test_pcd_ascii_integer_out_of_range(tmp_path):
    text = ("FIELDS x y z ring\nSIZE 4 4 4 1\nTYPE F F F U\nCOUNT 1 1 1 1\nPOINTS 1\n"
            "DATA ascii\n1 2 3 300\n")
    (tmp_path / "r.pcd").write_text(text)
    with pytest.raises(ValueError, match=r"r.pcd: PCD ascii data holds a value outside \[0, 255\]"):
        read_pcd(tmp_path / "r.pcd")


# --------------------------------------------------------------------------- #
# OctoMap .bt / .ot headers
# --------------------------------------------------------------------------- #
def _tree_bytes(fmt):
    from occgp import OccupancyOctree

    tree = OccupancyOctree(0.1).insert_scan([[1.0, 0, 0], [0, 1.0, 0.5]], [0, 0, 0])
    return tree.to_bytes(fmt)


@pytest.mark.parametrize("fmt", ["bt", "ot"])
@pytest.mark.parametrize(
    "old, new, match",
    [(b"res 0.1", b"res nan", "header resolution must be positive and finite, got nan"),
     (b"res 0.1", b"res inf", "header resolution must be positive and finite, got inf"),
     (b"res 0.1", b"res -0.1", "header resolution must be positive and finite, got -0.1"),
     (b"res 0.1", b"res 1e-400", "header resolution must be positive and finite, got 0.0"),
     (b"res 0.1", b"res x", "res must be a number, got 'x'"),
     (b"size ", b"size -", r"size must be a node count \(a non-negative integer\), got '-\d+'"),
     (b"size ", b"size 1_", r"size must be a node count"),
     (b"size ", b"size 99999999999999", r"announces 99999999999999\d* nodes, but the \d+ data"),
     (b"size ", b"size 9" * 30, r"size must be a node count"),
     (b"res 0.1\n", b"", "header lacks the field"),
     (b"data\n", b"dat\n", r"truncated header \(no 'data' line\)"),
     (b"id OcTree", b"id ColorOcTree", "holds a 'ColorOcTree' tree")],
)
def test_octomap_header_rejects_bad_fields(fmt, old, new, match):
    from occgp import OccupancyOctree

    data = _tree_bytes(fmt)
    assert old in data
    with pytest.raises(ValueError, match=match):
        OccupancyOctree.from_bytes(data.replace(old, new, 1))


@pytest.mark.parametrize("fmt", ["bt", "ot"])
def test_octomap_truncated_header_and_data(fmt):
    from occgp import OccupancyOctree

    data = _tree_bytes(fmt)
    end = data.index(b"data\n") + 5
    for cut in (0, 10, 40, end - 3, end, end + 1, len(data) - 1):
        with pytest.raises(ValueError, match="data|header|not an OctoMap file"):
            OccupancyOctree.from_bytes(data[:cut])
    assert OccupancyOctree.from_bytes(data).num_nodes > 0


@pytest.mark.parametrize("data", ["ascii", "binary", "binary_compressed"])
@pytest.mark.parametrize("count", [2**20 + 1, 2**32, 10**20])
def test_pcd_absurd_count_of_an_empty_cloud(tmp_path, data, count):
    # numpy raised "invalid shape in fixed-type tuple" (naming nothing) for binary data
    header = (f"FIELDS x y z i\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 {count}\nWIDTH 0\n"
              f"HEIGHT 1\nPOINTS 0\nDATA {data}\n").encode()
    body = bytes(8) if data == "binary_compressed" else b""
    (tmp_path / "c.pcd").write_bytes(header + body)
    with pytest.raises(ValueError, match=rf"c.pcd: field 'i' has COUNT {count}, expected 1 to"):
        read_pcd(tmp_path / "c.pcd")


MOVED_TO_IO = ["read_pcd", "write_pcd", "lzf_decompress", "read_kitti_bin", "read_scan_graph",
               "write_scan_graph", "read_xyz", "read_scan_log", "load_scan_folder", "read_scans",
               "read_carmen", "LaserLog", "FLASER_NO_RETURN", "ScanSequence", "read_poses",
               "POSE_FORMATS", "read_kitti_poses", "read_tum_trajectory", "apply_poses",
               "read_rosbag", "RosbagScans"]


@pytest.mark.parametrize("name", MOVED_TO_IO)
def test_old_datasets_paths_warn_and_give_the_io_objects(name):
    import occgp.datasets
    import occgp.io

    with pytest.warns(DeprecationWarning,
                      match=rf"occgp\.datasets\.{name} is deprecated; import it from occgp\.io"):
        obj = getattr(occgp.datasets, name)
    assert obj is getattr(occgp.io, name)
    assert name not in occgp.datasets.__all__ and name in occgp.io.__all__


def test_from_import_of_an_old_path_warns():
    with pytest.warns(DeprecationWarning, match=r"occgp\.datasets\.read_pcd is deprecated"):
        from occgp.datasets import read_pcd as old
    assert old is read_pcd


def test_the_records_the_simulators_return_stay_in_datasets(recwarn):
    import warnings

    import occgp.datasets
    import occgp.io

    warnings.simplefilter("error", DeprecationWarning)
    assert occgp.datasets.Scan is occgp.io.Scan
    assert occgp.datasets.LaserScan2D is occgp.io.LaserScan2D
    with pytest.raises(AttributeError, match="has no attribute 'read_nothing'"):
        occgp.datasets.read_nothing
