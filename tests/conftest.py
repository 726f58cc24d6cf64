"""Shared fixtures: tiny synthetic rooms, the real data folder, the liboctomap reference."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data"

if importlib.util.find_spec("torch") is None:  # occgp.iln's torch modules need the extra
    collect_ignore = [str(Path(__file__).resolve().parents[1] / "occgp" / "iln" / name)
                      for name in ("models", "training.py")]


def data_path(*parts: str) -> Path:
    """Path of a file in ../shared/data; skip the test when it is absent."""
    path = DATA.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"real data {path} is absent (../shared/data beside the project root)")
    return path


def tiny_room_scan():
    """Wall points of a 2 m x 2 m x 1 m box seen from its center, and the origin."""
    rng = np.random.default_rng(0)
    n = 400
    u, z = rng.uniform(-1, 1, n), rng.uniform(0.05, 0.95, n)
    side = rng.integers(0, 4, n)
    x = np.where(side == 0, -1.0, np.where(side == 1, 1.0, u))
    y = np.where(side == 2, -1.0, np.where(side == 3, 1.0, u))
    return np.column_stack([x, y, z]), np.array([0.0, 0.0, 0.5])


@pytest.fixture
def tiny_room():
    """:func:`tiny_room_scan`."""
    return tiny_room_scan()


@pytest.fixture(scope="session")
def octomap_insert_exe(tmp_path_factory):
    """liboctomap's insertPointCloud as a separate program (skip without a compiler)."""
    from octomap_reference import build_octomap_insert

    exe = build_octomap_insert(tmp_path_factory.mktemp("octomap_reference"))
    if exe is None:
        pytest.skip("no C++ compiler or liboctomap pkg-config file to build the reference")
    return exe
