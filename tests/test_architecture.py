"""The shape of the package: no module reaches into another's private names, no module
grows past the size one reader can hold, no two modules share a name."""

import ast
import importlib.util
from collections import Counter
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "occgp"
# modules every method may import private names from: the shared argument checks
ALLOWED = {"occgp._validation"}
MAX_LINES = 700
# the compiled core's sources (ext/): not yet split to MAX_LINES (_octree.pyx, _scan.h)
MAX_EXT_LINES = 800


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _sources():
    return sorted(PACKAGE.rglob("*.py"))


def _is_compiled(name: str) -> bool:
    spec = importlib.util.find_spec(name)
    return spec is not None and spec.origin is not None and \
        not spec.origin.endswith((".py", ".pyc"))


def _is_module(name: str) -> bool:
    try:
        return importlib.util.find_spec(name) is not None
    except ModuleNotFoundError:
        return False


def _resolve(module: str, node: ast.ImportFrom) -> str:
    if not node.level:
        return node.module or ""
    base = module.split(".")
    # a package's __init__ is its own base; a module's base is its package
    return ".".join(base[:len(base) - node.level + (1 if _is_package(module) else 0)]
                    + ([node.module] if node.module else []))


def _is_package(module: str) -> bool:
    return (ROOT.joinpath(*module.split(".")) / "__init__.py").is_file()


def _private_imports():
    """(module, line, source module, name) of every import of another module's private
    name inside occgp."""
    found = []
    for path in _sources():
        module = _module_name(path)
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if not isinstance(node, ast.ImportFrom):
                continue
            source = _resolve(module, node)
            if not source.startswith("occgp") or source in ALLOWED or source == module:
                continue
            for alias in node.names:
                name = alias.name
                if not name.startswith("_") or name.startswith("__"):
                    continue
                if _is_module(f"{source}.{name}") or _is_compiled(source):
                    continue        # a private module, or the compiled core behind a class
                found.append((module, node.lineno, source, name))
    return found


def test_no_module_imports_another_modules_private_names():
    found = _private_imports()
    assert not found, "\n".join(f"{m}:{line} imports {name} from {src}"
                                for m, line, src, name in found)


@pytest.mark.slow
def test_the_private_import_check_can_fail(tmp_path, monkeypatch):
    # a module that does reach into a sibling's private name is found
    fake = PACKAGE / "_architecture_probe.py"
    assert not fake.exists()
    fake.write_text("from .knn import _log_odds  # noqa\n")
    try:
        found = _private_imports()
    finally:
        fake.unlink()
    assert ("occgp._architecture_probe", 1, "occgp.knn", "_log_odds") in found


@pytest.mark.parametrize("path", [p for p in _sources()] +
                         sorted((ROOT / "ext").glob("*.[ph]*")),
                         ids=lambda p: str(p.relative_to(ROOT)))
def test_modules_stay_small(path):
    n = len(path.read_text().splitlines())
    limit = MAX_EXT_LINES if path.parent.name == "ext" else MAX_LINES
    assert n <= limit, f"{path.relative_to(ROOT)} has {n} lines (at most {limit})"


def test_no_two_modules_share_a_name():
    names = [p.stem for p in _sources() if p.stem != "__init__"]
    names += [p.stem for p in (ROOT / "ext").glob("*.pyx")]
    clashes = {n: c for n, c in Counter(names).items() if c > 1 and n.startswith("_")}
    assert not clashes, f"modules sharing a name: {sorted(clashes)}"


def test_test_folders_mirror_the_package():
    """tests/<name>/ holds the tests of occgp.<name> (a package, or grid.py); the tests
    left at the top of tests/ are package-wide (the protocol, the docs, the layers)."""
    folders = [p.name for p in (ROOT / "tests").iterdir()
               if p.is_dir() and p.name not in ("reference", "__pycache__")]
    assert folders, "no test folders"
    for name in folders:
        assert ((ROOT / "occgp" / name / "__init__.py").exists()
                or (ROOT / "occgp" / f"{name}.py").exists()), name
        assert any((ROOT / "tests" / name).glob("test_*.py")), name
