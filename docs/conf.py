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
autodoc_default_options = {"members": True, "inherited-members": False}
numpydoc_show_class_members = False
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

templates_path = []
exclude_patterns = ["_build", "gen_modules/backreferences/*.examples"]
html_theme = "pydata_sphinx_theme"
html_title = f"occgp {release}"


def _skip_metadata_requests(app, what, name, obj, skip, options):
    """Skip scikit-learn's generated ``set_*_request`` methods (metadata routing)."""
    if name.startswith("set_") and name.endswith("_request"):
        return True
    return None


def setup(app):
    app.connect("autodoc-skip-member", _skip_metadata_requests)
