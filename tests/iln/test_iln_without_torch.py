"""occgp works without PyTorch: only occgp.iln's models and training need it."""

import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_occgp_imports_and_maps_without_torch():
    code = textwrap.dedent("""
        import importlib.abc, sys

        class HideTorch(importlib.abc.MetaPathFinder):
            def find_spec(self, name, path=None, target=None):
                if name == "torch" or name.startswith("torch."):
                    raise ModuleNotFoundError(f"No module named {name!r}")
                return None

        sys.meta_path.insert(0, HideTorch())
        import numpy as np
        import occgp, occgp.gp, occgp.datasets, occgp.evaluation, occgp.metrics, occgp.cli
        import occgp.iln
        assert "torch" not in sys.modules
        m = occgp.OccupancyOctree(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0])
        assert m.num_leaves > 0
        model = occgp.iln.LidarModel.carla(4, 32)
        image = occgp.iln.points_to_range_image([[10.0, 0.0, 0.0]], model)
        assert (image > 0).sum() == 1
        try:
            occgp.iln.make({"name": "bilinear"})
        except ImportError as exc:
            assert "occgp.iln.make needs PyTorch" in str(exc), exc
        else:
            raise AssertionError("occgp.iln.make worked without torch")
        assert occgp.cli.main(["iln", "train", "missing.yaml"]) == 1
        assert "torch" not in sys.modules
        print("ok")
    """)
    result = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                            text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip().endswith("ok")
