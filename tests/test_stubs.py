"""The .pyi stubs of the compiled modules agree with what they export (mypy.stubtest)."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# a mypy run per compiled module, 6-10 s each: the whole module is in the slow set
pytestmark = pytest.mark.slow


@pytest.mark.parametrize("module", ["occgp._octree", "occgp._grid", "occgp._kernel", "occgp._integral",
                                    "occgp._linetrack", "occgp._color"])
def test_compiled_module_stubs_match_runtime(module):
    pytest.importorskip("mypy.stubtest")
    env = dict(os.environ, MYPYPATH=str(ROOT))
    result = subprocess.run(
        [sys.executable, "-m", "mypy.stubtest", module, "--ignore-missing-stub",
         "--mypy-config-file", str(ROOT / "pyproject.toml")],
        capture_output=True, text=True, cwd=ROOT, env=env)
    assert result.returncode == 0, result.stdout + result.stderr
