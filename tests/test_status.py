"""The compiled core's status codes: one enum in C++ (ext/_status.h), the same in Python."""

import re
from pathlib import Path

import numpy as np
import pytest

from occgp import OccupancyOctree
from occgp._status import Status, check_status

ROOT = Path(__file__).resolve().parents[1]


def test_python_codes_match_the_cpp_enum():
    text = (ROOT / "ext" / "_status.h").read_text()
    body = re.search(r"enum class Status : uint8_t \{(.*?)\};", text, re.S).group(1)
    cpp = {name.upper(): int(value) for name, value in re.findall(r"(\w+) = (\d+),", body)}
    assert cpp == {s.name: s.value for s in Status}


def test_check_status_raises_the_code_message():
    check_status(Status.OK)
    with pytest.raises(ValueError, match="^weights must have length 3, got 2$"):
        check_status(Status.WEIGHTS_LENGTH, expected=3, got=2)
    with pytest.raises(ValueError, match="liboctomap could not read the tree data"):
        check_status(int(Status.UNREADABLE_DATA))


def test_a_code_is_an_int_with_a_label():
    assert Status.TOO_MANY_CELLS.label == "too many cells"
    assert Status.TOO_MANY_CELLS == 3 and Status.TOO_MANY_CELLS != "too many cells"
    assert {Status.OK: 1}[0] == 1


def test_core_returns_the_status_of_a_failed_scan():
    m = OccupancyOctree(0.1)
    pts = np.array([[1.0, 0.0, 0.0], [5000.0, 0.0, 0.0]], np.float32)
    org = np.zeros(3, np.float32)
    assert m._insert_batch(pts, org, -1.0, False, False) is Status.OUT_OF_RANGE
    assert m._insert_batch(pts[:1], org, -1.0, False, False, max_cells=2) is Status.TOO_MANY_CELLS
    assert m.num_nodes == 0
