"""No import circle among occgp's modules (tools/import_graph.py: every import counts,
inside functions and through importlib too), so a circle fails even without
lint-imports."""

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
_spec = importlib.util.spec_from_file_location("import_graph", ROOT / "tools" / "import_graph.py")
import_graph = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(import_graph)


def test_no_import_circle():
    graph = import_graph.import_graph()
    found = import_graph.circles(graph)
    assert not found, "import circles:\n" + "\n".join(
        ", ".join(c) + "\n    " + "\n    ".join(import_graph.cycle_edges(graph, c))
        for c in found)


def test_the_circle_check_can_fail(tmp_path):
    pkg = tmp_path / "occgp"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("def f():\n    from . import b\n")
    (pkg / "b.py").write_text("import importlib\nimportlib.import_module('occgp.a')\n")
    (pkg / "sub" / "__init__.py").write_text("from .c import x\n")
    (pkg / "sub" / "c.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from . import x\nx = 1\n")
    found = import_graph.circles(import_graph.import_graph(tmp_path))
    assert found == [["occgp.a", "occgp.b"]]
