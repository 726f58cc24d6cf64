"""The ``occgp`` command: ``occgp demo``, ``occgp map`` and ``occgp iln``.

``_main.py`` holds the parser and :func:`main`, ``_map_command.py`` the
``map`` sub-command and ``_demo.py`` the ``demo`` sub-command.
"""

from ._main import main

__all__ = ["main"]
