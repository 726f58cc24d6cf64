"""Every public function and method documents its parameters and return value (numpydoc).

The API pages are numpydoc autosummary pages: a parameter missing from a
docstring's ``Parameters`` section is missing from the docs. This walks the
names each public module exports (``__all__``), and for classes their public
methods defined in occgp (inherited ones included; namedtuple builtins such
as ``count`` / ``index`` and properties are skipped), and reports

* parameters absent from the ``Parameters`` section (``*args`` and
  ``**kwargs`` excepted), and
* functions that return a value (a ``return`` with a value in their source,
  or, for compiled ones, a return annotation other than None) without a
  ``Returns`` section, and generators without ``Yields``.

``occgp.iln`` is checked with its torch parts (skipped without torch); members
defined by PyTorch (what its models inherit from ``torch.nn.Module``) are left
to torch's docs, as docs/conf.py's ``is_torch_member`` does.

Run ``python tests/test_docstrings.py`` to print the report for every module.
"""

from __future__ import annotations

import ast
import importlib
import importlib.util
import inspect
import textwrap

import pytest

numpydoc_docscrape = pytest.importorskip("numpydoc.docscrape")

MODULES = ["occgp", "occgp.gp", "occgp.datasets", "occgp.io", "occgp.evaluation", "occgp.metrics", "occgp.iln"]

#: Modules that need an optional dependency to import all of their API.
NEEDS = {"occgp.iln": "torch"}

#: Modules whose docstrings are still being completed; their test reports
#: what is missing as an expected failure. Empty this set once they are done.
#: occgp.iln: train_from_yaml and load_checkpoint (occgp/iln/training.py) lack
#: Parameters and Returns sections.
PENDING_MODULES: set = set()


def _is_torch_member(obj):
    """Whether `obj` is defined by PyTorch (docs/conf.py's ``is_torch_member``)."""
    module = getattr(obj, "__module__", None) or ""
    return module == "torch" or module.startswith("torch.")


def _defining_class(cls, name):
    for klass in inspect.getmro(cls):
        if name in vars(klass):
            return klass
    return None


def _public_callables(module):
    """``(qualified name, function)`` of each public function and method `module` exports."""
    for name in getattr(module, "__all__", [n for n in dir(module) if not n.startswith("_")]):
        obj = getattr(module, name, None)
        if inspect.isclass(obj):
            for attr in sorted(dir(obj)):
                if attr.startswith("_"):
                    continue
                owner = _defining_class(obj, attr)
                if owner is None or not owner.__module__.startswith("occgp"):
                    continue  # tuple.count, object builtins, third-party bases
                raw = vars(owner)[attr]
                if isinstance(raw, property) or inspect.isclass(raw):
                    continue
                member = getattr(obj, attr)
                if callable(member) and not _is_torch_member(member):
                    yield f"{module.__name__}.{name}.{attr}", member
        elif callable(obj) and not inspect.isclass(obj) and inspect.isroutine(obj):
            yield f"{module.__name__}.{name}", obj


def _returns_value(func):
    """``(returns, yields)`` of `func`: from its source, else from its return annotation."""
    func = inspect.unwrap(getattr(func, "__func__", func))
    try:
        source = textwrap.dedent(inspect.getsource(func))
        tree = ast.parse(source)
    except (OSError, TypeError, SyntaxError, IndentationError):
        try:
            ann = inspect.signature(func).return_annotation
        except (TypeError, ValueError):
            return False, False
        return ann not in (inspect.Signature.empty, None, "None"), False
    node = tree.body[0]
    if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
        return False, False
    returns = yields = False
    stack = list(node.body)
    while stack:
        sub = stack.pop()
        if isinstance(sub, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda, ast.ClassDef)):
            continue
        if isinstance(sub, ast.Return) and sub.value is not None and not (
                isinstance(sub.value, ast.Constant) and sub.value.value is None):
            returns = True
        if isinstance(sub, (ast.Yield, ast.YieldFrom)):
            yields = True
        stack.extend(ast.iter_child_nodes(sub))
    return returns, yields


def problems(func):
    """What the numpydoc docstring of `func` lacks, as a list of strings."""
    try:
        sig = inspect.signature(func)
    except (TypeError, ValueError):
        return []
    params = [name for name, p in sig.parameters.items()
              if name not in ("self", "cls") and not name.startswith("_")
              and p.kind not in (inspect.Parameter.VAR_POSITIONAL, inspect.Parameter.VAR_KEYWORD)]
    doc = numpydoc_docscrape.FunctionDoc(func) if func.__doc__ else None
    documented = set()
    if doc is not None:
        for p in doc["Parameters"]:
            documented.update(n.strip().lstrip("*") for n in p.name.split(","))
    out = []
    missing = [p for p in params if p not in documented]
    if missing:
        out.append(f"Parameters lacks {missing}")
    returns, yields = _returns_value(func)
    if returns and not (doc is not None and doc["Returns"]):
        out.append("no Returns section")
    if yields and not (doc is not None and (doc["Yields"] or doc["Returns"])):
        out.append("no Yields section")
    return out


def report(module_name):
    """``{qualified name: problems}`` over the public API of `module_name`."""
    module = importlib.import_module(module_name)
    found = {}
    for qualname, func in _public_callables(module):
        issues = problems(func)
        if issues:
            found[qualname] = issues
    return found


@pytest.mark.parametrize("module_name", MODULES)
def test_public_api_documents_parameters_and_returns(module_name):
    if module_name in NEEDS:
        pytest.importorskip(NEEDS[module_name])
    found = report(module_name)
    text = "\n".join(f"{name}: {'; '.join(issues)}" for name, issues in found.items())
    if found and module_name in PENDING_MODULES:
        pytest.xfail(f"docstrings of {module_name} pending:\n{text}")
    assert not found, f"incomplete docstrings in {module_name}:\n{text}"


def test_checker_flags_a_missing_parameter_and_return():
    def documented(a, b=1):
        """Sum.

        Parameters
        ----------
        a : int
        b : int, default=1

        Returns
        -------
        s : int
        """
        return a + b

    def undocumented(a, b=1):
        """Sum.

        Parameters
        ----------
        a : int
        """
        return a + b

    assert problems(documented) == []
    assert problems(undocumented) == ["Parameters lacks ['b']", "no Returns section"]


if __name__ == "__main__":
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # this checkout's occgp
    for name in MODULES:
        if name in NEEDS and importlib.util.find_spec(NEEDS[name]) is None:
            continue
        for qualname, issues in report(name).items():
            print(f"{qualname}: {'; '.join(issues)}")
