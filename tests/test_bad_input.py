"""The docs' table of bad inputs (docs/bad_input.csv), kept true: every row's call raises
the exception it names, with a message matching its pattern, and a map the call would
have changed is left unchanged."""

import csv
import pathlib
import re

import numpy as np
import pytest

import occgp
import occgp.iln as iln
import occgp.io as io
from occgp import (
    AKIMap, BGKMap, GridMap, KNNMap, OccupancyOctree, datasets, evaluation, gp, metrics,
)

TABLE = pathlib.Path(__file__).resolve().parents[1] / "docs" / "bad_input.csv"


def rows():
    with open(TABLE, newline="") as f:
        reader = csv.reader(f)
        header = next(reader)
        assert header == ["entry point", "call", "raises", "message (regular expression)"]
        return [pytest.param(*row, id=f"{i + 2}:{row[0]}") for i, row in enumerate(reader)]


def namespace(tmp_path):
    """What the table's calls may use: occgp's public names, small maps, a folder."""
    ns = {"np": np, "occgp": occgp, "datasets": datasets, "io": io, "evaluation": evaluation,
          "metrics": metrics, "gp": gp, "iln": iln, "files": tmp_path}
    for module in (occgp, datasets, io, evaluation, metrics, gp):
        # (the readers' old occgp.datasets paths are deprecated: occgp.io's names)
        ns.update({name: getattr(module, name) for name in module.__all__
                   if module is not datasets or name not in io.__all__})
    ns["tree"] = OccupancyOctree(0.1).insert_scan([[1.0, 0, 0], [0, 1.0, 0]], [0, 0, 0])
    ns["grid"] = GridMap(0.1).insert_scan([[1.0, 0, 0], [0, 1.0, 0]], [0, 0, 0])
    ns["bgk"] = BGKMap(0.1).insert_scan([[1.0, 0, 0], [0, 1.0, 0]], [0, 0, 0])
    ns["akimap"] = AKIMap(0.1).insert_scan([[1.0, 0, 0], [0, 1.0, 0]], [0, 0, 0])
    ns["knn"] = KNNMap(0.1).insert_scan([[1.0, 0, 0], [0, 1.0, 0], [0, 1.1, 0]], [0, 0, 0])
    # a wall of 60 points 2 m in front of the origin
    ns["wall60"] = np.column_stack([np.full(60, 2.0), np.linspace(-1, 1, 60), np.zeros(60)])
    for name, content in make_files().items():
        (tmp_path / name).write_bytes(content)
    return ns


def make_files() -> dict[str, bytes]:
    """Small bad files for the readers' rows, by name."""
    good = np.arange(12, dtype=np.float32).reshape(3, 4)
    return {
        "odd.bin": good.tobytes()[:-3],                 # not a whole number of records
        "five.bin": np.ones((7, 5), np.float32).tobytes(),   # 140 bytes: 5-float records
        "corrupt.xyz.gz": b"\x1f\x8b\x08\x00garbage",
        "empty.pcd": b"",
        "truncated.log": b"#\nFLASER 2 1.0 2.0 0\n",            # CARMEN: no pose
        "negative.log": b"FLASER 2 1.0 -1.0 0 0 0 0 0 0 1.0 host 1.0\n",
        # a ROS map whose resolution is an int of 400 digits (YAML reads it as an int)
        "huge_resolution.yaml": b"image: huge_resolution.pgm\nresolution: " + b"1" * 400
        + b"\norigin: [0.0, 0.0, 0.0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n",
        "huge_resolution.pgm": b"P5 2 2 255\n" + bytes(4),
        # hostile ROS maps: nested aliases ("billion laughs"), a 5,000-digit width,
        # 10^10 pixels announced, an image name that is a list of 100,000 items
        "laughs.yaml": _laughs() + b"image: laughs.pgm\n" + _ROS_KEYS,
        "wide.yaml": b"image: wide.pgm\n" + _ROS_KEYS,
        "wide.pgm": b"P5 " + b"9" * 5000 + b" 2 255\n" + bytes(4),
        "many.yaml": b"image: many.pgm\n" + _ROS_KEYS,
        "many.pgm": b"P5 100000 100000 255\n" + bytes(4),
        "list.yaml": b"image: [" + b",".join([b"1"] * 100_000) + b"]\n" + _ROS_KEYS,
        # LiDAR frames: stray trailing bytes, empty, one point, no returns, one elevation,
        # an OS1-64 column with one beam's return
        "stray1.bin": _records(64) + b"\x00",
        "stray3.bin": _records(64) + b"\x00" * 3,
        "empty.bin": b"",
        "one.bin": _records(1),
        "zeros.bin": np.zeros((128, 4), np.float32).tobytes(),
        "flat.bin": _records(256, flat=True),
        "column.bin": np.r_[[[3.0, 1.0, 0.5, 1.0]], np.zeros((63, 4))].astype(np.float32)
        .tobytes(),
    }


_ROS_KEYS = (b"resolution: 0.1\norigin: [0.0, 0.0, 0.0]\nnegate: 0\noccupied_thresh: 0.65\n"
             b"free_thresh: 0.196\n")


def _laughs() -> bytes:
    """A YAML mapping of 9 levels of nested aliases (9**9 'lol's when expanded)."""
    lines = [b'a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]']
    for i in range(1, 9):
        prev, cur = chr(96 + i).encode(), chr(97 + i).encode()
        lines.append(cur + b": &" + cur + b" [" + b",".join([b"*" + prev] * 9) + b"]")
    return b"\n".join(lines) + b"\n"


def _records(n: int, flat: bool = False) -> bytes:
    """`n` KITTI records (x y z intensity): one sweep around the sensor, or if `flat`
    n / 4 sweeps of 4 points (as many scan-order rings), all at one elevation."""
    a = np.tile(np.linspace(-3, 3, 4), n // 4) if flat else np.linspace(-3, 3, n)
    z = np.zeros(len(a)) if flat else np.linspace(-1, 1, n)
    return np.c_[5 * np.cos(a), 5 * np.sin(a), z, np.ones(n)].astype("<f4").tobytes()


def state(value):
    """A fingerprint of a map's contents (None for other values)."""
    if isinstance(value, KNNMap):
        return value.to_bytes("ot"), value._scores
    if isinstance(value, OccupancyOctree):
        return value.to_bytes("ot")
    if isinstance(value, GridMap):
        return value.cells().log_odds.tobytes(), value.cells().centers.tobytes()
    if isinstance(value, (BGKMap, AKIMap)):
        return tuple(np.asarray(a).tobytes() for a in value.cells())
    return None


@pytest.mark.parametrize("entry, call, raises, message", rows())
def test_bad_input_table(entry, call, raises, message, tmp_path):
    ns = namespace(tmp_path)
    before = {k: state(v) for k, v in ns.items() if state(v) is not None}
    exc = {"ValueError": ValueError, "TypeError": TypeError, "OSError": OSError,
           "FileNotFoundError": FileNotFoundError, "NotFittedError": ValueError}[raises]
    with pytest.raises(exc) as info:
        eval(call, ns)  # noqa: S307 -- the table's own expressions
    assert type(info.value).__name__ == raises or raises in ("OSError", "NotFittedError")
    assert re.search(message, str(info.value)), (call, str(info.value))
    for k, fingerprint in before.items():
        assert state(ns[k]) == fingerprint, f"{call} changed {k}"


def test_table_covers_every_public_class():
    entries = {row.values[0].split(".")[0] for row in rows()}
    for name in ("OccupancyOctree", "GridMap", "metrics", "evaluation", "datasets", "io"):
        assert name in entries


def test_no_cell_reads_as_a_restructuredtext_reference():
    # the docs render the table as reStructuredText: "np.True_)" would be a link
    # to a missing target ("Unknown target name"), which fails the docs build
    pattern = re.compile(r"\w_(?=[\s)\].,:;!?'\"/>}-]|$)")
    bad = [(p.id, cell) for p in rows() for cell in p.values if pattern.search(cell)]
    assert not bad, bad
