"""occgp's version, read from the installed package's metadata.

The one place the version is written is ``[project] version`` in pyproject.toml; pip
writes it into the installed distribution's metadata (a wheel, an sdist build or the
editable install of ``make test``), and ``occgp.__version__`` and ``occgp --version``
read it from there.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("occgp")
except PackageNotFoundError:  # imported from a source tree that pip never installed
    __version__ = "0+unknown"

__all__ = ["__version__"]
