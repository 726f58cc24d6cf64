"""Deprecated import path of the colour octree: use :mod:`occgp.octree`.

``occgp.color.ColorOctree`` and ``occgp.color.ColorLeaves`` keep working for one
release with a :class:`DeprecationWarning`; ``occgp.ColorOctree`` and
``occgp.octree.ColorOctree`` are the import paths.
"""

import warnings

from .octree import _color_tree

__all__ = ["ColorOctree", "ColorLeaves", "FUSIONS"]


def __getattr__(name):
    if name in __all__:
        warnings.warn(f"occgp.color.{name} is deprecated; import it from occgp.octree "
                      "(occgp.color goes in the next release)", DeprecationWarning,
                      stacklevel=2)
        return getattr(_color_tree, name)
    raise AttributeError(f"module 'occgp.color' has no attribute {name!r}")
