"""Sphinx configuration for occgp's docs (API reference and example gallery)."""

import os

import occgp

project = "occgp"
author = "the occgp developers"
copyright = "2026, the occgp developers"
release = occgp.__version__
version = ".".join(release.split(".")[:2])

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.intersphinx",
    "sphinx.ext.mathjax",
    "numpydoc",
    "sphinx_gallery.gen_gallery",
]

autosummary_generate = True
# every class page (docs/_templates/autosummary/class.rst) documents its public
# members, inherited ones included (but not those of tuple, for the named tuples),
# and lists them in Methods / Attributes tables
autodoc_default_options = {"members": True}
numpydoc_show_class_members = False
# signatures without type hints: the numpydoc Parameters sections give the types
autodoc_typehints = "none"
numpydoc_class_members_toctree = False

# Offline by default: intersphinx inventories are fetched only when asked for.
intersphinx_mapping = {}
if os.environ.get("OCCGP_DOCS_INTERSPHINX"):
    intersphinx_mapping = {
        "python": ("https://docs.python.org/3", None),
        "numpy": ("https://numpy.org/doc/stable", None),
        "scipy": ("https://docs.scipy.org/doc/scipy", None),
    }

sphinx_gallery_conf = {
    "examples_dirs": "../examples",
    "gallery_dirs": "auto_examples",
    "filename_pattern": "/plot_",
    "doc_module": ("occgp",),
    "backreferences_dir": "gen_modules/backreferences",
    "remove_config_comments": True,
}

templates_path = ["_templates"]
exclude_patterns = ["_build", "gen_modules/backreferences/*.examples",
                    "real_log_tables.rst"]   # included by which_map.rst
html_theme = "pydata_sphinx_theme"
html_title = f"occgp {release}"
# a table of contents in the left sidebar of every page (docs/_templates/sidebar-toc.html):
# the pages and their sections; the right sidebar lists the page's own sections
html_sidebars = {"**": ["sidebar-toc.html"]}
html_theme_options = {"show_toc_level": 2, "secondary_sidebar_items": ["page-toc"]}


def _skip_metadata_requests(app, what, name, obj, skip, options):
    """Skip scikit-learn's metadata-routing methods (``set_*_request``,
    ``get_metadata_routing``) and what occgp.iln's models inherit from
    ``torch.nn.Module``: other libraries' machinery, not occgp's API."""
    if is_metadata_routing(name) or is_torch_member(obj):
        return True
    return None


def is_torch_member(obj):
    """Whether `obj` (a class member) is defined by PyTorch, e.g. what occgp.iln's models
    inherit from ``torch.nn.Module`` (also used by tests/test_api_docs.py)."""
    module = getattr(obj, "__module__", None) or ""
    return module == "torch" or module.startswith("torch.")


try:  # the names occgp.iln's models inherit from torch.nn.Module, for the class template
    import torch

    _TORCH_MODULE_MEMBERS = sorted(n for n in dir(torch.nn.Module) if not n.startswith("_"))
except ImportError:
    _TORCH_MODULE_MEMBERS = []
autosummary_context = {"torch_module_members": _TORCH_MODULE_MEMBERS}


def is_metadata_routing(name):
    """Whether `name` is one of scikit-learn's metadata-routing methods (also used by
    tests/test_api_docs.py)."""
    return (name.startswith("set_") and name.endswith("_request")) or \
        name == "get_metadata_routing"


def setup(app):
    app.connect("autodoc-skip-member", _skip_metadata_requests)
