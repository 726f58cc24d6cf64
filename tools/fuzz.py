#!/usr/bin/env python
"""Seeded mutation fuzzer of occgp's file readers and loaders.

Every reader gets valid seed files written by occgp's own writers (or built
here byte by byte), mutated by truncations, bit and byte flips, byte
insertions and deletions, and edits of header fields (sizes, counts, widths,
resolutions, node counts, the ``POINTS`` / ``WIDTH`` / ``DATA`` lines, ...).
The ROS map reader (``ros_map``: ``OccupancyGrid2D.load_ros_map``) gets a YAML
file and its PGM image per case, one or both mutated: YAML values replaced by
hostile ones (aliases, ``/dev/zero``, huge numbers, tags, flow collections),
the PGM header's fields edited; the stamped octree files (``stamps_ot``,
``stamps_bt``) are mutated mostly in their stamps block (its count, decay time,
keys and stamps).
Each parsed result is then *used*: checked (shapes, finiteness), written and
read back where a writer exists, inserted into an ``OccupancyOctree``,
queried with ``occupancy`` and ``cast_rays``; trees go through ``to_bytes`` /
``from_bytes``.

Each case ends as one of

* ``ok``: parsed and used without error;
* ``rejected``: a ``ValueError`` / ``TypeError`` / ``OSError`` whose message
  names the file (or the argument);
* ``unclear``: any other exception, an allowed type whose message names
  nothing, or a parsed result that is invalid (wrong shape, NaN, a round trip
  that changes it);
* ``crash``: the process died (a signal);
* ``hang``: the case ran past the per-case time limit.

Cases run in child processes (``python tools/fuzz.py --worker``), a batch per
child; the parent watches each case with a time limit, and when a child dies
or hangs it records the case it was running, replays that case alone in a
fresh child, saves its input under a temporary folder and goes on with the
rest of the batch in a new child. Cases are a pure function of
``(seed, reader, index)``, so any case can be regenerated.

Usage::

    python tools/fuzz.py --cases 10000 --jobs 2          # the long campaign
    python tools/fuzz.py --cases 200 --readers pcd_ascii,bt
    python tools/fuzz.py --replay pcd_binary 1234        # rerun one case in-process

With ``--atheris-runs N`` and atheris installed, each reader also gets a
coverage-guided atheris (libFuzzer) run of N inputs, from the same seeds and
with the same mutations mixed into libFuzzer's own; its unclear exceptions
are raised so that libFuzzer saves the input (``crash-*`` files in the work
folder).
"""

from __future__ import annotations

import argparse
import bz2
import gzip
import json
import lzma
import os
import queue
import select
import shutil
import struct
import subprocess
import sys
import tempfile
import threading
import time
import traceback
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

OUTCOMES = ("ok", "rejected", "unclear", "crash", "hang")

# --------------------------------------------------------------------------- #
# seeds
# --------------------------------------------------------------------------- #
_SEED_RNG = 12345


def _cloud(rng, n):
    return rng.uniform(-8, 8, (n, 3)), rng.uniform(-1, 1, 3)


def _pcd_seeds(data):
    from occgp.io import write_pcd

    rng = np.random.default_rng(_SEED_RNG)
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "s.pcd"
        for k, (n, dtype, extra) in enumerate([(40, "float32", True), (12, "float64", False),
                                               (25, "float32", False), (0, "float32", False),
                                               (0, "float64", True), (1, "float32", True)]):
            points, origin = _cloud(rng, n)
            fields = None
            if extra:
                fields = {"intensity": rng.uniform(0, 1, n).astype(np.float32),
                          "ring": (np.arange(n) % 16).astype(np.uint16),
                          "normal": rng.normal(size=(n, 3)),
                          "label": rng.integers(-5, 5, n).astype(np.int8)}
            write_pcd(path, points, origin, data=data, fields=fields, dtype=dtype)
            out.append(path.read_bytes())
    if data == "ascii":  # an old-style header with a padding field, no COUNT / WIDTH
        out.append(b"VERSION .5\nFIELDS x _ y z\nSIZE 4 4 4 4\nTYPE F F F F\nPOINTS 3\n"
                   b"DATA ascii\n1 0 2 3\n4 0 5 6\n-1 0 0.5 2\n")
    if data == "binary":  # organised cloud with NaN holes
        pts = np.random.default_rng(1).uniform(-3, 3, (20, 3)).astype(np.float32)
        pts[::3] = np.nan
        header = ("VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 5\n"
                  "HEIGHT 4\nVIEWPOINT 0 0 1 1 0 0 0\nPOINTS 20\nDATA binary\n")
        out.append(header.encode() + pts.tobytes())
    return out


def _bin_seeds(width):
    rng = np.random.default_rng(_SEED_RNG)
    out = []
    for n in (60, 7, 1, 0):
        rec = np.zeros((n, width), np.float32)
        rec[:, :3] = rng.uniform(-30, 30, (n, 3))
        rec[:, 3] = rng.uniform(0, 1, n)
        if width == 5:
            rec[:, 4] = np.arange(n) % 32
        out.append(rec.tobytes())
    return out


def _graph_seeds():
    from occgp.io import Scan, write_scan_graph

    rng = np.random.default_rng(_SEED_RNG)
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "s.graph"
        for scans in ([Scan(*_cloud(rng, 20))],
                      [Scan(*_cloud(rng, 8)), Scan(*_cloud(rng, 5)), Scan(*_cloud(rng, 0))],
                      []):
            write_scan_graph(path, scans)
            out.append(path.read_bytes())
    # a rotated node and one edge, built by hand (the writer writes identity poses, no edges)
    half = np.sqrt(0.5)
    pts = b"".join(struct.pack("<i3d", 3, *p) for p in [[1.0, 0, 0], [0, 2.0, 0], [1, 1, 1]])
    pose = struct.pack("<i3di4d", 3, 1.0, 2.0, 3.0, 4, half, 0, 0, half)
    edge = struct.pack("<II", 0, 0) + pose + struct.pack("<d", 1.0)
    out.append(struct.pack("<II", 1, 3) + pts + pose + struct.pack("<II", 0, 1) + edge)
    return out


def _xyz_texts():
    rng = np.random.default_rng(_SEED_RNG)
    a = "\n".join(" ".join(f"{v:.6g}" for v in row) for row in rng.uniform(-9, 9, (30, 3)))
    b = "# x y z intensity\n\n" + "\n".join(
        " ".join(f"{v:.17g}" for v in row) for row in rng.uniform(-2, 2, (10, 4)))
    return [a + "\n", b + "\n", "1 2 3\n", "# empty\n"]


def _log_texts():
    rng = np.random.default_rng(_SEED_RNG)
    out = []
    for poses in ([(1, 0, 0, 0, 0, 1.5707963267948966)],
                  [(0, 0, 0, 0.1, -0.2, 0.3), (1, 2, 0.5, 0, 0, -1.2), (0, 0, 0, 0, 0, 0)]):
        lines = ["# scan log"]
        for k, pose in enumerate(poses):
            lines.append("NODE " + " ".join(repr(float(v)) for v in pose))
            for row in rng.uniform(-5, 5, (max(0, 12 - 5 * k), 3)):
                lines.append(" ".join(f"{v:.9g}" for v in row))
        out.append("\n".join(lines) + "\n")
    return out


def _carmen_texts():
    rng = np.random.default_rng(_SEED_RNG)
    flaser, robot = ["# CARMEN log", "PARAM robot_x 0"], []
    for k in range(3):
        r = np.round(rng.uniform(0.1, 30.0, 12), 3)
        r[k] = 81.83                                   # a no-return code
        pose = " ".join(f"{v:.6g}" for v in rng.uniform(-5, 5, 3))
        flaser.append(f"FLASER 12 {' '.join(map(str, r))} {pose} {pose} {k + 0.5} host {k}")
        flaser.append(f"ODOM {pose} 0 0 0 {k} host {k}")
        robot.append(f"ROBOTLASER1 0 -1.5 3.0 0.25 20.0 0.01 0 12 {' '.join(map(str, r))} "
                     f"2 7 9 {pose} {pose} 0 0 0.5 0.3 0 {k + 0.5} host {k}")
    return ["\n".join(flaser) + "\n", "\n".join(robot) + "\n"]


def _tree_seeds(fmt):
    from occgp import OccupancyOctree

    rng = np.random.default_rng(_SEED_RNG)
    out = []
    for res, n in ((0.1, 30), (0.25, 8), (0.05, 3), (0.1, 0)):
        tree = OccupancyOctree(res)
        if n:
            tree.insert_scan(rng.uniform(-1, 1, (n, 3)), [0.0, 0.0, 0.0])
        out.append(tree.to_bytes(fmt))
    return out


#: Between a ROS map case's YAML file and its PGM image in one seed / atheris input.
_PAIR_SEP = b"\n#--occgp-fuzz-pgm--\n"


def _ros_map_seeds():
    """map_server pairs: occgp's own (8-bit P5), and hand-made P2, 16-bit, negated,
    commented and mode-less variants; each as YAML + _PAIR_SEP + PGM."""
    from occgp import OccupancyGrid2D

    rng = np.random.default_rng(_SEED_RNG)
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        for shape, res, origin in (((5, 4), 0.1, (0.0, 0.0)), ((1, 1), 0.05, (-3.5, 2.25)),
                                   ((12, 7), 1.0e-3, (1e3, -1e3))):
            states = rng.integers(-1, 2, shape)
            yaml_path, pgm = OccupancyGrid2D(states, origin, res).save_ros_map(
                Path(tmp) / "case.yaml")
            out.append(yaml_path.read_bytes() + _PAIR_SEP + pgm.read_bytes())
    keys = (b"resolution: 0.25\norigin: [-1.0, 0.5, 0.0]\noccupied_thresh: 0.65\n"
            b"free_thresh: 0.196\n")
    out.append(b"image: case.pgm\nmode: trinary\nnegate: 0\n" + keys + _PAIR_SEP
               + b"P2\n# plain\n3 2\n255\n0 254 205\n254 0 100\n")
    out.append(b"image: case.pgm\nnegate: 1\n" + keys + _PAIR_SEP
               + b"P5 2 2\n65535\n" + np.array([0, 65535, 30000, 9], ">u2").tobytes())
    out.append(b"# a comment\nimage: 'case.pgm'\nnegate: 0\n" + keys + _PAIR_SEP
               + b"P5\n# CREATOR: GIMP\n4 1\n# x\n255\n" + bytes([0, 254, 205, 17]))
    return out


def _split_pair(data):
    yaml_text, sep, pgm = data.partition(_PAIR_SEP)
    return yaml_text, pgm


def _stamp_seeds(fmt):
    """Trees with a stamps block (stamped updates; a half-life decay time)."""
    from occgp import OccupancyOctree

    rng = np.random.default_rng(_SEED_RNG)
    out = []
    for res, n, decay in ((0.1, 30, False), (0.25, 8, True), (0.05, 2, True), (0.1, 0, True)):
        tree = OccupancyOctree(res)
        if n:
            tree.insert_scan(rng.uniform(-1, 1, (n, 3)), [0.0, 0.0, 0.0], stamp=1.5)
            tree.update_cells(rng.uniform(-1, 1, (3, 3)), occupied=True, stamp=7.0)
        if decay:
            tree.decay(9.0, half_life=4.0)
        out.append(tree.to_bytes(fmt))
    return out


_COMPRESS = {".gz": lambda b: gzip.compress(b, mtime=0), ".bz2": bz2.compress,
             ".xz": lzma.compress}
_DECOMPRESS = {".gz": gzip.decompress, ".bz2": bz2.decompress, ".xz": lzma.decompress}

# --------------------------------------------------------------------------- #
# mutations
# --------------------------------------------------------------------------- #
_INTS = [0, 1, 2, 3, 4, 5, 7, 8, 16, 255, 256, 65535, 2**31 - 1, 2**31, 2**32 - 1, 2**32,
         2**53 + 1, 2**63 - 1, 2**64, 10**30, -1, -2, -(2**31)]
_FLOATS = ["0", "-0", "1", "-1", "0.5", "1e-25", "1e-300", "1e-400", "5e-324", "1e20", "1e30",
           "3.5e38", "1e39", "1e300", "1e400", "nan", "-nan", "inf", "-inf", "NaN", "1e-5",
           "65536", "32768.5", "2.5e-3"]
_WORDS = ["", "x", "-", "0x10", "1_0", "++1", "1e", ".", "ascii", "binary", "binary_compressed",
          "zipped", "DATA", "NODE", "data", "res", "size", "id", "OcTree", "#", "\x00", "\xff",
          "é", "9" * 60]


def _token(rng):
    k = rng.integers(3)
    if k == 0:
        return str(_INTS[rng.integers(len(_INTS))])
    if k == 1:
        return _FLOATS[rng.integers(len(_FLOATS))]
    return _WORDS[rng.integers(len(_WORDS))]


def _header_end(data, fmt):
    """Offset just past the header of a text-headed format (PCD: DATA line; .bt/.ot: data)."""
    marker = {"pcd": b"DATA", "octomap": b"\ndata\n"}.get(fmt)
    if marker is None:
        return len(data)
    i = data.find(marker)
    if i < 0:
        return len(data)
    j = data.find(b"\n", i + 1 if fmt == "pcd" else i + 1 + 4)
    return len(data) if j < 0 else j + 1


def _edit_text_field(rng, data, end):
    """Replace one whitespace-separated token of data[:end] (a header field value, a count)."""
    head = data[:end]
    spans, i, n = [], 0, len(head)
    while i < n:
        while i < n and head[i] in b" \t\r\n":
            i += 1
        j = i
        while j < n and head[j] not in b" \t\r\n":
            j += 1
        if j > i:
            spans.append((i, j))
        i = j
    if not spans:
        return data
    # prefer tokens that follow a keyword (values), but keywords may change too
    a, b = spans[rng.integers(len(spans))]
    new = _token(rng).encode("utf-8", "surrogateescape")
    return data[:a] + new + data[b:]


def _edit_lines(rng, data, end):
    """Delete, duplicate, swap or replace one line of data[:end]."""
    head, tail = data[:end], data[end:]
    lines = head.split(b"\n")
    if len(lines) < 2:
        return data
    k = int(rng.integers(len(lines) - 1))
    op = rng.integers(4)
    if op == 0:
        del lines[k]
    elif op == 1:
        lines.insert(k, lines[k])
    elif op == 2:
        m = int(rng.integers(len(lines) - 1))
        lines[k], lines[m] = lines[m], lines[k]
    else:
        key = lines[k].split(b" ", 1)[0]
        lines[k] = key + b" " + b" ".join(_token(rng).encode("utf-8", "surrogateescape")
                                         for _ in range(int(rng.integers(0, 4))))
    return b"\n".join(lines) + tail


def _overwrite_number(rng, data, start=0):
    """Overwrite 4 or 8 bytes with an interesting integer or float."""
    if len(data) - start < 4:
        return data
    width = 8 if rng.random() < 0.5 and len(data) - start >= 8 else 4
    pos = int(rng.integers(start, len(data) - width + 1))
    if rng.random() < 0.5:
        v = _INTS[rng.integers(len(_INTS))] % (2 ** (8 * width))
        raw = v.to_bytes(width, "little")
    else:
        v = float(_FLOATS[rng.integers(len(_FLOATS))].replace("-nan", "nan"))
        raw = struct.pack("<d" if width == 8 else "<f", v) if width == 8 or abs(v) < 3.4e38 \
            or not np.isfinite(v) else struct.pack("<f", np.inf)
    return data[:pos] + raw + data[pos + width:]


def _mutate_bytes(rng, data, fmt="raw"):
    """One random mutation of `data` (bytes)."""
    n = len(data)
    end = _header_end(data, fmt)
    ops = ["truncate", "bitflip", "byte", "insert", "delete", "duplicate", "number"]
    if fmt in ("pcd", "octomap", "text"):
        ops += ["field", "field", "field", "lines"]
    if fmt == "graph":
        ops += ["count", "count"]
    op = ops[rng.integers(len(ops))]
    if op == "truncate":
        if n == 0:
            return data
        # half of the cuts land in the header (or the first bytes)
        cut = int(rng.integers(0, max(1, min(end, n)) + 1)) if rng.random() < 0.5 else \
            int(rng.integers(0, n))
        return data[:cut]
    if op == "bitflip" and n:
        buf = bytearray(data)
        for _ in range(int(rng.integers(1, 9))):
            i = int(rng.integers(n))
            buf[i] ^= 1 << int(rng.integers(8))
        return bytes(buf)
    if op == "byte" and n:
        buf = bytearray(data)
        for _ in range(int(rng.integers(1, 4))):
            i = int(rng.integers(n))
            buf[i] = [0, 0xFF, 0x7F, 0x80, 0x20, 0x0A, 0x30 + int(rng.integers(10)),
                      int(rng.integers(256))][rng.integers(8)]
        return bytes(buf)
    if op == "insert":
        i = int(rng.integers(n + 1))
        k = int(rng.integers(1, 17))
        blob = bytes(rng.integers(0, 256, k, dtype=np.uint8)) if rng.random() < 0.5 else \
            data[i:i + k] or b"\n"
        return data[:i] + blob + data[i:]
    if op == "delete" and n:
        i = int(rng.integers(n))
        return data[:i] + data[i + int(rng.integers(1, 33)):]
    if op == "duplicate" and n:
        i = int(rng.integers(n))
        k = int(rng.integers(1, 65))
        return data[:i] + data[i:i + k] * int(rng.integers(2, 4)) + data[i + k:]
    if op == "number":
        return _overwrite_number(rng, data, end if fmt in ("pcd", "octomap") else 0)
    if op == "field":
        return _edit_text_field(rng, data, end)
    if op == "lines":
        return _edit_lines(rng, data, end)
    if op == "count" and n >= 4:
        # a ScanGraph count: the node count, a point count, the edge count (or anywhere)
        where = [0, 4, n - 4, int(rng.integers(0, n - 3))][rng.integers(4)]
        v = _INTS[rng.integers(len(_INTS))] % 2**32
        return data[:where] + struct.pack("<I", v) + data[where + 4:]
    return data


_YAML_TOKENS = ["*a", "&a x", "[*a, *a]", "/dev/zero", "/dev/stdin", ".", "..", "''", '""',
                "[", "{", "]", "!!binary AA==", "!!python/object:os.system", "!!set {a}", ".nan",
                ".inf", "-.inf", "0x10", "0o17", "1_000", "~", "null", "true", "yes", "[0, 0]",
                "[0.0, 0.0, 0.0, 0.0]", "[0, 0, 1e400]", "{a: 1}", "1" * 400, "9" * 5000,
                "1e-320", "-1", "2", "case.pgm", "case.pgm/", "\"case\\0.pgm\"", "é.pgm",
                "\"\\U0001F600.pgm\"", "|\n  x", ">-\n  y"]


def _mutate_yaml(rng, data):
    """Replace the value of one ``key: value`` line of a YAML file (or add a key)."""
    lines = data.split(b"\n")
    keyed = [k for k, line in enumerate(lines) if b":" in line]
    value = _YAML_TOKENS[rng.integers(len(_YAML_TOKENS))] if rng.random() < 0.7 \
        else _token(rng)
    value = value.encode("utf-8", "surrogateescape")
    if not keyed or rng.random() < 0.1:
        key = [b"image", b"mode", b"resolution", b"origin", b"negate", b"x"][rng.integers(6)]
        lines.insert(int(rng.integers(len(lines) + 1)), key + b": " + value)
    else:
        k = keyed[rng.integers(len(keyed))]
        lines[k] = lines[k].split(b":", 1)[0] + b": " + value
    if rng.random() < 0.1:  # an anchor defined before its aliases
        lines.insert(0, b"a: &a [1, 2, 3]")
    return b"\n".join(lines)


def _pgm_header_end(data):
    """Offset just past a PGM header (its magic, width, height and maxval)."""
    pos, fields = 2, 0
    while fields < 3 and pos < len(data):
        while pos < len(data) and (data[pos:pos + 1].isspace() or data[pos:pos + 1] == b"#"):
            if data[pos:pos + 1] == b"#":
                end = data.find(b"\n", pos)
                pos = len(data) if end < 0 else end + 1
            else:
                pos += 1
        while pos < len(data) and data[pos:pos + 1].isdigit():
            pos += 1
        fields += 1
    return min(len(data), pos + 1)


def mutate_ros_map(rng, data):
    """1 to 3 mutations of the YAML file (its values, its text) or of the PGM image
    (its header fields, its bytes) of a ROS map case."""
    yaml_text, pgm = _split_pair(data)
    for _ in range(min(3, int(rng.geometric(0.55)))):
        r = rng.random()
        if r < 0.35:
            yaml_text = _mutate_yaml(rng, yaml_text)
        elif r < 0.5:
            yaml_text = _mutate_bytes(rng, yaml_text, "text")
        elif r < 0.75:
            pgm = _edit_text_field(rng, pgm, _pgm_header_end(pgm))
        else:
            pgm = _mutate_bytes(rng, pgm)
    return yaml_text + _PAIR_SEP + pgm


def mutate_stamps(rng, data):
    """1 to 4 mutations, most inside the stamps block after the OctoMap data: its
    count, its decay time, its keys and stamps, truncations and extra bytes."""
    from occgp.octree._stamps import STAMPS_MAGIC

    start = data.find(STAMPS_MAGIC)
    if start < 0:
        return mutate(rng, data, "octomap")
    head, block = data[:start], data[start:]
    at = len(STAMPS_MAGIC)
    for _ in range(min(4, int(rng.geometric(0.55)))):
        r = rng.random()
        if r < 0.3 and len(block) >= at + 16:      # the count or the decay time
            if rng.random() < 0.5:
                v = _INTS[rng.integers(len(_INTS))] % 2**64
                block = block[:at] + struct.pack("<Q", v) + block[at + 8:]
            else:
                v = float(_FLOATS[rng.integers(len(_FLOATS))].replace("-nan", "nan"))
                block = block[:at + 8] + struct.pack("<d", v) + block[at + 16:]
        elif r < 0.45:                             # the magic line
            block = _edit_text_field(rng, block, at)
        elif r < 0.9:
            block = _mutate_bytes(rng, block)
        else:
            head = _mutate_bytes(rng, head, "octomap")
    return head + block


def mutate(rng, data, fmt, compressed=None):
    """1 to 4 mutations; `compressed` (a suffix) mutates the text inside or the stream."""
    if compressed is not None and rng.random() < 0.6:
        text = _DECOMPRESS[compressed](data)
        for _ in range(min(4, int(rng.geometric(0.55)))):
            text = _mutate_bytes(rng, text, "text")
        data = _COMPRESS[compressed](text)
        if rng.random() < 0.2:
            data = _mutate_bytes(rng, data)
        return data
    for _ in range(min(4, int(rng.geometric(0.55)))):
        data = _mutate_bytes(rng, data, fmt)
    return data


# --------------------------------------------------------------------------- #
# using what a reader returned
# --------------------------------------------------------------------------- #
class BadResult(Exception):
    """A reader returned something invalid (a silently wrong result)."""


def _check(cond, what):
    if not cond:
        raise BadResult(what)


def _clean_insert_error(exc):
    msg = str(exc)
    return isinstance(exc, ValueError) and any(w in msg for w in ("points", "origin"))


def use_scans(scans, workdir, reader):
    """Check scans, round-trip them through a writer, insert them, query the map."""
    from occgp import OccupancyOctree
    from occgp.io import Scan, read_pcd, read_scan_graph, write_pcd, write_scan_graph

    _check(isinstance(scans, list), f"expected a list of scans, got {type(scans).__name__}")
    for k, scan in enumerate(scans[:4]):
        _check(isinstance(scan, Scan), f"scan {k} is a {type(scan).__name__}")
        p, o = scan
        _check(isinstance(p, np.ndarray) and p.dtype == np.float64 and p.ndim == 2
               and p.shape[1] == 3 and p.flags.c_contiguous,
               f"scan {k}: points {getattr(p, 'dtype', None)} {getattr(p, 'shape', None)}")
        _check(isinstance(o, np.ndarray) and o.dtype == np.float64 and o.shape == (3,),
               f"scan {k}: origin {getattr(o, 'shape', None)}")
        _check(np.isfinite(p).all(), f"scan {k}: non-finite points")
        _check(np.isfinite(o).all(), f"scan {k}: non-finite origin")
        # round trip through the PCD writer (float64: exact)
        rt = workdir / "rt.pcd"
        write_pcd(rt, p, o, dtype="float64", data=("binary", "ascii")[k % 2])
        back = read_pcd(rt)
        _check(np.array_equal(back.points, p) and np.array_equal(back.origin, o),
               f"scan {k}: PCD round trip changed the scan")
        sub = p[:150]
        # insert as read: bounded by max_range; out of the key range -> a clean ValueError
        tree = OccupancyOctree(0.5)
        try:
            tree.insert_scan(sub, o, max_range=25.0)
        except ValueError as exc:
            if not _clean_insert_error(exc):
                raise
            _check(tree.num_nodes == 0, "a rejected insert changed the map")
        # insert clipped to a sane box (and rounded to micrometres, so that no ray is
        # shorter than single precision can walk): must work
        box = 20.0
        oc, pc = np.round(np.clip(o, -box, box), 6), np.round(np.clip(sub, -box, box), 6)
        tree = OccupancyOctree(0.5).insert_scan(pc, oc)
        if len(pc):
            occ = tree.occupancy(pc[:40])
            _check(np.all(np.isnan(occ) | ((occ >= 0) & (occ <= 1))), "occupancy out of [0, 1]")
            dirs = pc[:20] - oc
            dirs = dirs[np.linalg.norm(dirs, axis=1) > 1e-3]
            if len(dirs):
                ends, hits = tree.cast_rays(oc, dirs, max_range=30.0)
                _check(ends.shape == dirs.shape and hits.shape == (len(dirs),),
                       "cast_rays shapes")
    if reader == "graph":
        rt = workdir / "rt.graph"
        write_scan_graph(rt, scans)
        back = read_scan_graph(rt)
        _check(len(back) == len(scans), "graph round trip changed the scan count")
        for a, b in zip(scans, back):
            _check(np.allclose(a.points, b.points, rtol=1e-9, atol=1e-6)
                   and np.array_equal(a.origin, b.origin), "graph round trip changed a scan")


def use_laser_log(log, workdir):
    """Check a LaserLog's scans and observations, fit the 2D log-odds grid on them."""
    from occgp.io import LaserLog
    from occgp.gp import OccupancyGrid

    _check(isinstance(log, LaserLog), f"got a {type(log).__name__}")
    for k, scan in enumerate(log):
        for name in ("origin", "angles", "ranges"):
            a = getattr(scan, name)
            _check(isinstance(a, np.ndarray) and np.isfinite(a).all(),
                   f"scan {k}: non-finite {name}")
        _check(np.isfinite(scan.heading) and (scan.ranges >= 0).all(), f"scan {k}: bad values")
        _check(scan.hit.dtype == bool and len(scan.hit) == len(scan.ranges),
               f"scan {k}: hit flags")
        _check(np.isfinite(scan.end_points).all(), f"scan {k}: non-finite end points")
    hits, starts, ends = log.observations()
    _check(len(starts) == len(ends) and np.isfinite(ends).all(), "observations")
    box = np.abs(np.vstack([starts, ends])).max() if len(ends) else 0.0
    if len(hits) and box < 1e3:
        OccupancyGrid(0.5).fit(hits, starts, ends)


def use_grid(grid, workdir):
    """Check a ROS map's grid, write it and read it back, find its frontiers."""
    from occgp import OccupancyGrid2D

    _check(isinstance(grid, OccupancyGrid2D), f"got a {type(grid).__name__}")
    st = grid.states
    _check(isinstance(st, np.ndarray) and st.dtype == np.int8 and st.ndim == 2 and st.size
           and np.isin(st, (-1, 0, 1)).all(), f"states {st.dtype} {st.shape}")
    _check(np.isfinite(grid.origin).all() and grid.origin.shape == (2,), "origin")
    _check(np.isfinite(grid.resolution) and grid.resolution > 0, "resolution")
    yaml_path, _ = grid.save_ros_map(workdir / "rt.yaml")
    back = OccupancyGrid2D.load_ros_map(yaml_path)
    _check(np.array_equal(back.states, st) and np.array_equal(back.origin, grid.origin)
           and back.resolution == grid.resolution, "ROS map round trip changed the grid")
    grid.frontiers()


def use_stamped_tree(tree):
    """use_tree, and the stamps: round trip through both formats, queries, a decay."""
    from occgp import OccupancyOctree

    stamps = tree.stamps()
    _check(np.isfinite(stamps.stamps).all() and len(stamps.keys) == len(stamps.stamps),
           "stamps")
    for fmt in ("ot", "bt"):
        again = OccupancyOctree.from_bytes(tree.to_bytes(fmt))
        s2 = again.stamps()
        _check(np.array_equal(s2.keys, stamps.keys) and np.array_equal(s2.stamps, stamps.stamps),
               f".{fmt} round trip changed the stamps")
    if len(stamps.keys):
        got = tree.stamp_at(stamps.centers[:20])
        _check(np.array_equal(got, stamps.stamps[:20]), "stamp_at disagrees with stamps()")
        now = float(np.max(stamps.stamps))
        if np.isfinite(now + 1.0):
            tree.decay(now + 1.0, max_age=0.5)
            tree.decay(now + 2.0, half_life=3.0)
    use_tree(tree)


def use_tree(tree):
    """Query a tree, round-trip it through both formats, insert a scan, cast rays."""
    from occgp import OccupancyOctree

    _check(isinstance(tree, OccupancyOctree), f"got a {type(tree).__name__}")
    res = tree.resolution
    _check(np.isfinite(res) and res > 0, f"resolution {res}")
    lo, hi = tree.bounds
    probes = np.array([[0.0, 0.0, 0.0], [res, -res, 2 * res]])
    if np.isfinite(lo).all():
        probes = np.vstack([probes, lo, hi, (lo + hi) / 2])
    occ = tree.occupancy(probes)
    _check(np.all(np.isnan(occ) | ((occ >= 0) & (occ <= 1))), "occupancy out of [0, 1]")
    ot = tree.to_bytes("ot")
    again = OccupancyOctree.from_bytes(ot)
    _check(again.num_nodes == tree.num_nodes and again.to_bytes("ot") == ot,
           ".ot round trip changed the tree")
    bt = tree.to_bytes("bt")
    OccupancyOctree.from_bytes(bt)
    scan = res * np.array([[6.0, 0, 0], [0, 5.0, 1], [3, 3, 3], [-4, 1, 0]])
    before = tree.num_nodes
    tree.insert_scan(scan, [0.0, 0.0, 0.0])
    _check(tree.num_nodes >= 1, f"an insert left {tree.num_nodes} nodes (had {before})")
    ends, hits = tree.cast_rays([0.0, 0.0, 0.0], scan, max_range=12 * res)
    _check(ends.shape == (4, 3) and hits.shape == (4,), "cast_rays shapes")


# --------------------------------------------------------------------------- #
# readers
# --------------------------------------------------------------------------- #
class Reader:
    """One fuzz target: seeds, how to mutate, how to call and use."""

    def __init__(self, name, suffix, seeds, fmt, call, use, compressed=None):
        self.name, self.suffix, self._seeds, self.fmt = name, suffix, seeds, fmt
        self.call, self.use, self.compressed = call, use, compressed
        self._cache = None

    def seeds(self):
        if self._cache is None:
            self._cache = self._seeds()
        return self._cache

    def case(self, seed, index):
        """The input of case `index`: a dict file name -> bytes (case 0..k-1: the seeds)."""
        seeds = self.seeds()
        rng = np.random.default_rng([seed, _READER_IDS[self.name], index])
        if index < len(seeds):
            return self.files(seeds[index], rng, mutated=False)
        data = seeds[int(rng.integers(len(seeds)))]
        return self.files(self.mutate(rng, data), rng)

    def mutate(self, rng, data):
        """One mutated input (bytes) from `data`."""
        return mutate(rng, data, self.fmt, self.compressed)

    def files(self, data, rng=None, mutated=True):
        return {"case" + self.suffix: data}


class FolderReader(Reader):
    """load_scan_folder over a folder of a few valid files and one mutated file."""

    def seeds(self):
        if self._cache is None:
            self._cache = [(name, data) for r in ("pcd_binary", "kitti_bin", "nuscenes_bin",
                                                  "xyz", "graph", "scan_log", "xyz_gz")
                           for name, data in [(READERS[r].suffix, READERS[r].seeds()[0])]]
        return self._cache

    def case(self, seed, index):
        seeds = self.seeds()
        rng = np.random.default_rng([seed, _READER_IDS[self.name], index])
        picks = rng.choice(len(seeds), size=3, replace=False)
        files = {}
        for j, k in enumerate(picks):
            suffix, data = seeds[k]
            if index > 0 and j == 0:
                fmt = {".pcd": "pcd", ".graph": "graph", ".xyz": "text", ".log": "text"}.get(
                    suffix, "raw")
                data = mutate(rng, data, fmt, ".gz" if suffix.endswith(".gz") else None)
            files[f"scan_{int(rng.integers(0, 30))}_{j}{suffix}"] = data
        return files


class PairReader(Reader):
    """OccupancyGrid2D.load_ros_map: a YAML file and the PGM image it names, one of
    them mutated (a seed is YAML + _PAIR_SEP + PGM, so atheris mutates one blob)."""

    def mutate(self, rng, data):
        return mutate_ros_map(rng, data)

    def files(self, data, rng=None, mutated=True):
        yaml_text, pgm = _split_pair(data)
        return {"case.yaml": yaml_text, "case.pgm": pgm}


class StampsReader(Reader):
    """OccupancyOctree.load of stamped maps, mutated mostly in the stamps block."""

    def mutate(self, rng, data):
        return mutate_stamps(rng, data)


def _read_pcd(paths):
    from occgp.io import read_pcd

    scan, fields = read_pcd(paths[0], return_fields=True)
    n = len(scan.points)
    for name, col in fields.items():
        _check(len(col) == n, f"field {name!r} has {len(col)} rows for {n} points")
    return [scan]


def _one(fn):
    def call(paths):
        return [fn(paths[0])]
    return call


def _build_readers():
    from occgp import OccupancyGrid2D, OccupancyOctree
    from occgp.io import (
        load_scan_folder,
        read_carmen,
        read_kitti_bin,
        read_scan_graph,
        read_scan_log,
        read_xyz,
    )

    def use_s(name):
        return lambda result, workdir: use_scans(result, workdir, name)

    def use_t(result, workdir):
        use_tree(result)

    def tree_bytes():
        return _tree_seeds("bt") + _tree_seeds("ot")

    readers = [
        Reader("pcd_ascii", ".pcd", lambda: _pcd_seeds("ascii"), "pcd", _read_pcd,
               use_s("pcd")),
        Reader("pcd_binary", ".pcd", lambda: _pcd_seeds("binary"), "pcd", _read_pcd,
               use_s("pcd")),
        Reader("pcd_binary_compressed", ".pcd", lambda: _pcd_seeds("binary_compressed"), "pcd",
               _read_pcd, use_s("pcd")),
        Reader("kitti_bin", ".bin", lambda: _bin_seeds(4), "raw", _one(read_kitti_bin),
               use_s("bin")),
        Reader("nuscenes_bin", ".pcd.bin", lambda: _bin_seeds(5), "raw", _one(read_kitti_bin),
               use_s("bin")),
        Reader("graph", ".graph", _graph_seeds, "graph", lambda p: read_scan_graph(p[0]),
               use_s("graph")),
        Reader("xyz", ".xyz", lambda: [t.encode() for t in _xyz_texts()], "text",
               _one(read_xyz), use_s("xyz")),
    ]
    for suffix in (".gz", ".bz2", ".xz"):
        readers.append(Reader(
            "xyz" + suffix.replace(".", "_"), ".xyz" + suffix,
            lambda s=suffix: [_COMPRESS[s](t.encode()) for t in _xyz_texts()], "raw",
            _one(read_xyz), use_s("xyz"), compressed=suffix))
    readers += [
        Reader("scan_log", ".log", lambda: [t.encode() for t in _log_texts()], "text",
               lambda p: read_scan_log(p[0]), use_s("log")),
        Reader("bt", ".bt", lambda: _tree_seeds("bt"), "octomap",
               lambda p: OccupancyOctree.load(p[0]), use_t),
        Reader("ot", ".ot", lambda: _tree_seeds("ot"), "octomap",
               lambda p: OccupancyOctree.load(p[0]), use_t),
        Reader("from_bytes", ".bytes", tree_bytes, "octomap",
               lambda p: OccupancyOctree.from_bytes(Path(p[0]).read_bytes()), use_t),
        FolderReader("scan_folder", "", None, "raw",
                     lambda p: load_scan_folder(Path(p[0]).parent, None), use_s("folder")),
        Reader("carmen", ".log", lambda: [t.encode() for t in _carmen_texts()], "text",
               lambda p: read_carmen(p[0]), lambda result, workdir: use_laser_log(result,
                                                                                  workdir)),
        PairReader("ros_map", ".yaml", _ros_map_seeds, "text",
                   lambda p: OccupancyGrid2D.load_ros_map(p[0]), use_grid),
        StampsReader("stamps_ot", ".ot", lambda: _stamp_seeds("ot"), "octomap",
                     lambda p: OccupancyOctree.load(p[0]), lambda t, w: use_stamped_tree(t)),
        StampsReader("stamps_bt", ".bt", lambda: _stamp_seeds("bt"), "octomap",
                     lambda p: OccupancyOctree.load(p[0]), lambda t, w: use_stamped_tree(t)),
    ]
    return {r.name: r for r in readers}


_NAMES = ["pcd_ascii", "pcd_binary", "pcd_binary_compressed", "kitti_bin", "nuscenes_bin",
          "graph", "xyz", "xyz_gz", "xyz_bz2", "xyz_xz", "scan_log", "bt", "ot", "from_bytes",
          "scan_folder", "carmen", "ros_map", "stamps_ot", "stamps_bt"]
_READER_IDS = {name: k for k, name in enumerate(_NAMES)}
READERS: dict = {}


def readers():
    if not READERS:
        READERS.update(_build_readers())
    return READERS


# --------------------------------------------------------------------------- #
# one case
# --------------------------------------------------------------------------- #
def _names_something(msg, files, folder, reader):
    names = [Path(f).name for f in files] + [str(folder)]
    if reader == "from_bytes":
        names += ["data"]
    return any(n and n in msg for n in names)


def _where(exc):
    tb = traceback.extract_tb(exc.__traceback__)
    frame = tb[-1] if tb else None
    return f"{Path(frame.filename).name}:{frame.lineno}" if frame else "?"


def run_case(reader_name, files, workdir):
    """Write `files` into a fresh folder under `workdir`, read, use; return an outcome dict."""
    reader = readers()[reader_name]
    folder = workdir / "case"
    folder.mkdir(parents=True, exist_ok=True)
    for old in os.scandir(folder):  # cheaper than removing the folder
        if old.is_dir(follow_symlinks=False):
            shutil.rmtree(old.path)
        else:
            os.unlink(old.path)
    paths = []
    for name, data in files.items():
        (folder / name).write_bytes(data)
        paths.append(str(folder / name))
    if reader_name == "scan_folder":
        paths.sort()
    stage = "read"
    try:
        result = reader.call(paths)
        stage = "use"
        reader.use(result, workdir)
    except BadResult as exc:
        return {"outcome": "unclear", "type": "BadResult", "stage": stage, "msg": str(exc)[:300],
                "where": _where(exc)}
    except (ValueError, TypeError, OSError) as exc:
        msg = str(exc)
        if stage == "read" and _names_something(msg, files, folder, reader_name):
            return {"outcome": "rejected", "type": type(exc).__name__}
        return {"outcome": "unclear", "type": type(exc).__name__, "stage": stage,
                "msg": msg[:300], "where": _where(exc)}
    except Exception as exc:  # noqa: BLE001 - every other type is a finding
        return {"outcome": "unclear", "type": type(exc).__name__, "stage": stage,
                "msg": str(exc)[:300], "where": _where(exc)}
    return {"outcome": "ok"}


# --------------------------------------------------------------------------- #
# worker (child process)
# --------------------------------------------------------------------------- #
def _scratch():
    """A RAM-backed folder for the cases' files where there is one (/dev/shm)."""
    shm = "/dev/shm"
    return shm if os.path.isdir(shm) and os.access(shm, os.W_OK) else None


def _worker():
    import warnings

    warnings.simplefilter("ignore")  # numpy's overflow warnings etc. are not findings
    workdir = Path(tempfile.mkdtemp(prefix="occgp-fuzz-w-", dir=_scratch()))
    out = sys.stdout
    try:
        for line in sys.stdin:
            job = json.loads(line)
            name, seed = job["reader"], job["seed"]
            reader = readers()[name]
            for index in range(job["start"], job["stop"]):
                out.write(f"S {index}\n")
                out.flush()
                res = run_case(name, reader.case(seed, index), workdir)
                res["index"] = index
                out.write("R " + json.dumps(res) + "\n")
                out.flush()
            out.write("D\n")
            out.flush()
    finally:
        shutil.rmtree(workdir, ignore_errors=True)


def _limits():
    # AddressSanitizer reserves terabytes of shadow address space: no limit under it
    if os.environ.get("OCCGP_UNDER_SANITIZER"):
        return
    try:
        import resource

        limit = 6 * 2**30
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    except (ImportError, ValueError, OSError):
        pass


class _Child:
    def __init__(self):
        env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1",
                   MKL_NUM_THREADS="1", PYTHONUNBUFFERED="1")
        self.proc = subprocess.Popen(
            [sys.executable, str(Path(__file__).resolve()), "--worker"], cwd=str(REPO),
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env,
            preexec_fn=_limits if os.name == "posix" else None, bufsize=0)
        self._buf = b""
        self._err = []
        self._err_thread = threading.Thread(target=self._drain, daemon=True)
        self._err_thread.start()

    def _drain(self):
        for line in self.proc.stderr:
            self._err.append(line)
            del self._err[:-40]

    def stderr_tail(self):
        return b"".join(self._err).decode("utf-8", "replace")[-2000:]

    def send(self, job):
        self.proc.stdin.write((json.dumps(job) + "\n").encode())
        self.proc.stdin.flush()

    def readline(self, timeout):
        """A line, None at EOF, or raise TimeoutError."""
        deadline = time.monotonic() + timeout
        fd = self.proc.stdout.fileno()
        while b"\n" not in self._buf:
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError
            ready, _, _ = select.select([fd], [], [], left)
            if not ready:
                continue
            chunk = os.read(fd, 65536)
            if not chunk:
                return None
            self._buf += chunk
        line, _, self._buf = self._buf.partition(b"\n")
        return line.decode()

    def kill(self):
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait()
        self._err_thread.join(timeout=5)

    def close(self):
        try:
            self.proc.stdin.close()
        except OSError:
            pass
        try:
            self.proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self.kill()


class _Runner:
    """Runs ranges of cases in a child process, kept across ranges until it dies or hangs."""

    def __init__(self, timeout, startup=120.0):
        self.timeout, self.startup, self.child = timeout, startup, None

    def run(self, reader, seed, start, stop):
        """Run cases [start, stop); yield outcome dicts (crashes and hangs included)."""
        index = start
        while index < stop:
            if self.child is None:
                self.child, self.fresh = _Child(), True
            child = self.child
            child.send({"reader": reader, "seed": seed, "start": index, "stop": stop})
            current = None
            while True:
                try:
                    line = child.readline(self.startup if self.fresh else self.timeout)
                except TimeoutError:
                    self.close(kill=True)
                    if current is None:
                        raise RuntimeError(f"fuzz worker for {reader} did not start") from None
                    yield {"index": current, "outcome": "hang", "type": "Timeout",
                           "msg": f"over {self.timeout:g} s"}
                    index = current + 1
                    break
                if line is None:  # the child died
                    self.close(kill=True)
                    if current is None:
                        raise RuntimeError(f"fuzz worker for {reader} died before its first "
                                           f"case:\n{child.stderr_tail()}")
                    yield {"index": current, "outcome": "crash",
                           "type": f"exit {child.proc.returncode}",
                           "msg": child.stderr_tail()[-600:]}
                    index = current + 1
                    break
                self.fresh = False
                if line.startswith("S "):
                    current = int(line[2:])
                elif line.startswith("R "):
                    res = json.loads(line[2:])
                    yield res
                    current = None
                elif line == "D":
                    index = stop
                    break

    def close(self, kill=False):
        if self.child is not None:
            if kill:
                self.child.kill()
            else:
                self.child.close()
            self.child = None


def replay_alone(reader, seed, index, timeout):
    """Rerun one case in a fresh child; return its outcome dict."""
    runner = _Runner(timeout)
    try:
        return next(runner.run(reader, seed, index, index + 1))
    finally:
        runner.close(kill=True)


def save_case(reader, seed, index, root):
    files = readers()[reader].case(seed, index)
    folder = Path(root) / f"{reader}-{index}"
    folder.mkdir(parents=True, exist_ok=True)
    for name, data in files.items():
        (folder / name).write_bytes(data)
    first = next(iter(files.values()), b"")
    return folder, first[:48].hex(" ")


# --------------------------------------------------------------------------- #
# campaign (parent)
# --------------------------------------------------------------------------- #
def run_campaign(names, cases, seed=0, jobs=1, timeout=10.0, batch=None, save_dir=None,
                 progress=False):
    """Fuzz `names` with `cases` cases each; return (table rows, findings).

    Findings are dicts with reader, index, outcome, type, message and, for
    crashes and hangs, whether the case reproduces alone; every finding's
    input is saved under `save_dir` (default: a new temporary folder).
    """
    readers()
    batch = batch or max(50, min(2000, cases // max(1, 4 * jobs // len(names) or 1)))
    work = queue.Queue()
    for name in names:
        for start in range(0, cases, batch):
            work.put((name, start, min(cases, start + batch)))
    counts = {name: dict.fromkeys(OUTCOMES, 0) for name in names}
    findings, lock, errors = [], threading.Lock(), []

    def run():
        runner = _Runner(timeout)
        try:
            _run(runner)
        finally:
            runner.close()

    def _run(runner):
        while True:
            try:
                name, start, stop = work.get_nowait()
            except queue.Empty:
                return
            try:
                for res in runner.run(name, seed, start, stop):
                    with lock:
                        counts[name][res["outcome"]] += 1
                        if res["outcome"] not in ("ok", "rejected"):
                            findings.append({"reader": name, **res})
            except Exception as exc:  # noqa: BLE001
                errors.append(exc)
                return
            if progress:
                with lock:
                    print(f"  {name} {stop}/{cases}", file=sys.stderr, flush=True)

    threads = [threading.Thread(target=run) for _ in range(max(1, jobs))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    if errors:
        raise errors[0]
    if findings:
        save_dir = Path(save_dir or tempfile.mkdtemp(prefix="occgp-fuzz-"))
        for f in findings:
            f["input"], f["hex"] = (str(x) for x in save_case(f["reader"], seed, f["index"],
                                                              save_dir))
            if f["outcome"] in ("crash", "hang"):
                alone = replay_alone(f["reader"], seed, f["index"], timeout)
                f["alone"] = alone["outcome"]
    rows = [(name, sum(counts[name].values()), *(counts[name][o] for o in OUTCOMES))
            for name in names]
    return rows, sorted(findings, key=lambda f: (f["reader"], f["index"]))


def format_table(rows):
    head = ("reader", "cases", "ok", "rejected", "unclear", "crashes", "hangs")
    total = ("total", *(sum(r[k] for r in rows) for k in range(1, len(head))))
    widths = [max(len(str(r[k])) for r in [head, *rows, total]) for k in range(len(head))]
    line = lambda r: "| " + " | ".join(str(v).ljust(w) if k == 0 else str(v).rjust(w)  # noqa
                                       for k, (v, w) in enumerate(zip(r, widths))) + " |"
    sep = "|" + "|".join("-" * (w + 2) for w in widths) + "|"
    return "\n".join([line(head), sep, *map(line, rows), sep, line(total)])


def format_finding(f, seed=0):
    alone = f" (alone: {f['alone']})" if "alone" in f else ""
    return (f"{f['reader']} case {f['index']} (seed {seed}): {f['outcome']}{alone}: "
            f"{f.get('type')} at {f.get('stage', '-')} {f.get('where', '')}: "
            f"{f.get('msg', '')[:300]}\n    input: {f.get('input')}\n    hex: {f.get('hex')}\n"
            f"    replay: python tools/fuzz.py --replay {f['reader']} {f['index']} --seed {seed}")


# --------------------------------------------------------------------------- #
# atheris (coverage-guided), where it installs
# --------------------------------------------------------------------------- #
def _atheris_main(name, runs, corpus, counts_path, timeout):
    import atheris

    import numpy  # noqa: F401 - imported (uninstrumented) first

    with atheris.instrument_imports(include=["occgp"]):
        import occgp  # noqa: F401
        import occgp.datasets  # noqa: F401
    import warnings

    warnings.simplefilter("ignore")
    reader = readers()[name]
    workdir = Path(tempfile.mkdtemp(prefix="occgp-fuzz-a-", dir=_scratch()))
    counts = dict.fromkeys(OUTCOMES, 0)
    fmt = reader.fmt

    def files_of(data):
        if isinstance(reader, FolderReader):
            seeds = reader.seeds()
            return {"scan_0.pcd": seeds[0][1], "scan_1.xyz": seeds[3][1], "scan_2.bin": data}
        return reader.files(data)

    def one_input(data):
        res = run_case(name, files_of(bytes(data)), workdir)
        counts[res["outcome"]] += 1
        total = sum(counts.values())
        if total % 500 == 0 or total >= runs:
            Path(counts_path).write_text(json.dumps(counts))
        if res["outcome"] == "unclear":
            raise RuntimeError(f"unclear outcome: {res}")

    def custom_mutator(data, max_size, seed):
        rng = np.random.default_rng(seed)
        if rng.random() < 0.5:
            out = atheris.Mutate(data, max_size)
        else:
            try:
                out = reader.mutate(rng, bytes(data))
            except Exception:  # noqa: BLE001 - a seed the inner mutator cannot open
                out = _mutate_bytes(rng, bytes(data), fmt)
        return out[:max_size]

    corpus = Path(corpus)
    corpus.mkdir(parents=True, exist_ok=True)
    seeds = readers()["kitti_bin"].seeds() if isinstance(reader, FolderReader) else reader.seeds()
    for k, data in enumerate(seeds):
        (corpus / f"seed{k}").write_bytes(data)
    args = [sys.argv[0], f"-runs={runs}", f"-timeout={int(timeout)}", "-rss_limit_mb=6144",
            "-max_len=65536", f"-artifact_prefix={corpus.parent}/", "-print_final_stats=0",
            str(corpus)]
    atheris.Setup(args, one_input, custom_mutator=custom_mutator)
    atheris.Fuzz()


def run_atheris(names, runs, timeout, jobs):
    """Run atheris per reader in its own process; return table rows and failing readers."""
    root = Path(tempfile.mkdtemp(prefix="occgp-fuzz-atheris-"))
    rows, failed = [], []
    pending = list(names)
    running = []
    while pending or running:
        while pending and len(running) < max(1, jobs):
            name = pending.pop(0)
            counts = root / f"{name}.json"
            log = open(root / f"{name}.log", "wb")
            proc = subprocess.Popen(
                [sys.executable, str(Path(__file__).resolve()), "--atheris-child", name,
                 "--atheris-runs", str(runs), "--timeout", str(timeout), "--corpus",
                 str(root / name / "corpus"), "--counts", str(counts)],
                cwd=str(REPO), stdout=log, stderr=subprocess.STDOUT,
                env=dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1"))
            running.append((name, proc, log, counts))
        time.sleep(0.5)
        for item in list(running):
            name, proc, log, counts = item
            if proc.poll() is None:
                continue
            running.remove(item)
            log.close()
            c = json.loads(counts.read_text()) if counts.exists() else dict.fromkeys(OUTCOMES, 0)
            text = (root / f"{name}.log").read_text("utf-8", "replace")
            hang = proc.returncode != 0 and "libFuzzer: timeout" in text
            unclear = proc.returncode != 0 and "unclear outcome" in text
            crash = proc.returncode != 0 and not hang and not unclear
            c["crash"] += int(crash)
            c["hang"] += int(hang)
            c["unclear"] += int(unclear)
            rows.append((f"atheris:{name}", sum(c.values()), *(c[o] for o in OUTCOMES)))
            if proc.returncode != 0:
                failed.append((name, root / f"{name}.log"))
    return rows, failed


def atheris_available():
    try:
        import atheris  # noqa: F401
    except ImportError:
        return False
    return True


# --------------------------------------------------------------------------- #
# command line
# --------------------------------------------------------------------------- #
def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", type=int, default=10000, help="cases per reader")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--jobs", type=int, default=1, help="child processes at a time")
    parser.add_argument("--timeout", type=float, default=10.0, help="seconds per case")
    parser.add_argument("--readers", default=",".join(_NAMES),
                        help=f"comma-separated subset of {','.join(_NAMES)}")
    parser.add_argument("--save-dir", default=None, help="where failing inputs are saved")
    parser.add_argument("--atheris-runs", type=int, default=0,
                        help="also run atheris with this many inputs per reader, if installed")
    parser.add_argument("--replay", nargs=2, metavar=("READER", "INDEX"))
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--atheris-child", default=None, help=argparse.SUPPRESS)
    parser.add_argument("--corpus", default=None, help=argparse.SUPPRESS)
    parser.add_argument("--counts", default=None, help=argparse.SUPPRESS)
    parser.add_argument("--progress", action="store_true")
    args = parser.parse_args(argv)
    if args.worker:
        _worker()
        return 0
    if args.atheris_child:
        _atheris_main(args.atheris_child, args.atheris_runs, args.corpus, args.counts,
                      args.timeout)
        return 0
    if args.replay:
        name, index = args.replay[0], int(args.replay[1])
        files = readers()[name].case(args.seed, index)
        for fname, data in files.items():
            print(f"{fname}: {len(data)} bytes: {data[:64].hex(' ')}")
        work = Path(tempfile.mkdtemp(prefix="occgp-fuzz-r-"))
        print(run_case(name, files, work))
        print(f"files in {work / 'case'}")
        return 0
    names = [n.strip() for n in args.readers.split(",") if n.strip()]
    unknown = [n for n in names if n not in _READER_IDS]
    if unknown:
        parser.error(f"unknown readers {unknown}; choose among {_NAMES}")
    t0 = time.perf_counter()
    rows, findings = run_campaign(names, args.cases, args.seed, args.jobs, args.timeout,
                                  save_dir=args.save_dir, progress=args.progress)
    print(f"seeded mutation fuzz: {args.cases} cases per reader, seed {args.seed}, "
          f"{time.perf_counter() - t0:.0f} s")
    print(format_table(rows))
    bad = bool(findings)
    for f in findings:
        print(format_finding(f, args.seed))
    if args.atheris_runs:
        if atheris_available():
            t0 = time.perf_counter()
            arows, failed = run_atheris(names, args.atheris_runs, args.timeout, args.jobs)
            print(f"\natheris (coverage-guided): {args.atheris_runs} runs per reader, "
                  f"{time.perf_counter() - t0:.0f} s")
            print(format_table(arows))
            for name, log in failed:
                print(f"atheris {name} failed: see {log}")
            bad = bad or bool(failed)
        else:
            print("\natheris is not installed: the seeded generator above ran alone")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
