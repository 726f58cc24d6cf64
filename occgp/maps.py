"""The one face every map shows, and the registry of map types.

Every map in occgp, whatever its method, answers the calls of
:class:`OccupancyMap` the same way, so that the command line, the demo and
the evaluation harness handle any map through it. The registry
(:func:`register`, :func:`available_maps`, :func:`make_map`) is the one list of
map types they read: a new map type is one module and one decorator.

Other packages add map types as plugins: a distribution that declares an entry
point in the ``occgp.maps`` group (:data:`ENTRY_POINT_GROUP`) has its maps
registered the first time the registry is read, beside the built-in ones
(see :func:`register` and the user guide's "Map types and plugins").

Examples
--------
>>> from occgp.maps import OccupancyMap, available_maps, make_map
>>> "octree" in available_maps()
True
>>> m = make_map("octree", resolution=0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0])
>>> isinstance(m, OccupancyMap)
True
>>> m.is_occupied([[1.0, 0, 0], [0.5, 0, 0]]).tolist()
[True, False]
"""

from __future__ import annotations

import importlib
import importlib.metadata
import inspect
import numbers
import os
import threading
import warnings
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from types import MappingProxyType, ModuleType
from typing import Any, Protocol, TypeVar, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._validation import check_resolution

__all__ = ["OccupancyMap", "MapType", "CAPABILITIES", "capabilities", "register",
           "available_maps", "map_type", "make_map", "OCTREE_FORMATS", "ENTRY_POINT_GROUP",
           "MapPluginWarning"]

#: The entry-point group of map plugins: each entry point names a module whose import
#: registers maps with :func:`register`, or a function (called without arguments) that
#: does.
ENTRY_POINT_GROUP = "occgp.maps"


class MapPluginWarning(UserWarning):
    """A map plugin (an entry point of :data:`ENTRY_POINT_GROUP`) failed to load: its
    maps are not registered; occgp and the other maps work as before."""


@runtime_checkable
class OccupancyMap(Protocol):
    """The calls every map answers, whatever its method.

    A map integrates range scans (:meth:`insert_scan`) and answers queries
    at points (:meth:`occupancy`, :meth:`is_occupied`). Every map class in
    occgp satisfies this protocol; ``isinstance(m, OccupancyMap)`` checks that
    an object has each call (not their signatures).

    The one threshold rule: a point is occupied when its cell's log-odds is
    at least the map's threshold (OctoMap's rule), i.e. its probability is at
    least ``occupancy_threshold``; cells the map knows nothing about are
    unknown, reported as not occupied and, with ``return_unknown=True``, in a
    second mask.

    Parameters follow scikit-learn's convention: ``get_params()`` returns
    the constructor's arguments, ``set_params(**params)`` changes those a
    map can change (a rejected call changes nothing), and
    :func:`sklearn.base.clone` builds an empty map with the same parameters.

    Optional capabilities (:data:`CAPABILITIES`) are further methods a map
    may have; :func:`capabilities` lists those of a map.
    """

    def insert_scan(self, points: ArrayLike, origin: ArrayLike, **options: Any) -> Any:
        """Integrate one scan: rays from `origin` to each end point.

        Parameters
        ----------
        points : array-like of shape (n_points, n_dims)
            End points in the world frame, metres.
        origin : array-like of shape (n_dims,)
            Sensor position, metres.
        **options
            Options of the map's own update (e.g. the octree's ``max_range``).

        Returns
        -------
        self
            The updated map; a rejected scan changes nothing.
        """

    def occupancy(self, points: ArrayLike) -> NDArray[np.float64]:
        """Probability of occupancy at each point.

        Parameters
        ----------
        points : array-like of shape (n_points, n_dims)

        Returns
        -------
        p : ndarray of shape (n_points,)
            NaN where the map holds no evidence.
        """

    def is_occupied(self, points: ArrayLike, *, return_unknown: bool = False) -> Any:
        """Whether each point is occupied: its probability is at least the threshold.

        Parameters
        ----------
        points : array-like of shape (n_points, n_dims)
        return_unknown : bool, default=False
            Also return the mask of points without evidence.

        Returns
        -------
        occupied : ndarray of bool of shape (n_points,)
        unknown : ndarray of bool of shape (n_points,)
            Only when `return_unknown` is True.
        """

    @property
    def bounds(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(min corner, max corner) of the known space; NaN when the map is empty."""

    @property
    def num_cells(self) -> int:
        """Number of cells holding evidence."""

    def memory_usage(self) -> int:
        """Bytes the map's cells use.

        Returns
        -------
        nbytes : int
        """

    def get_params(self, deep: bool = True) -> dict:
        """The constructor's parameters.

        Parameters
        ----------
        deep : bool, default=True
            scikit-learn's flag (nested estimators' parameters too).

        Returns
        -------
        params : dict
        """

    def set_params(self, **params: Any) -> Any:
        """Change parameters.

        Parameters
        ----------
        **params
            The parameters to change, by name.

        Returns
        -------
        self
            The map; unchanged when a value is rejected.
        """

    def save(self, path: str | os.PathLike) -> Any:
        """Write the map with its evidence.

        The file is written atomically: a temporary file beside `path` replaces
        it once complete, so the previous file stays intact if the write fails.

        Parameters
        ----------
        path : str or path-like
            Destination, in one of the map type's formats.

        Returns
        -------
        self
        """

    @classmethod
    def load(cls, path: str | os.PathLike) -> Any:
        """Read a map written by :meth:`save`.

        Parameters
        ----------
        path : str or path-like

        Returns
        -------
        map
            A map of the class this is called on.
        """

    def to_octree(self) -> Any:
        """The map as an :class:`occgp.OccupancyOctree` (OctoMap's files).

        Returns
        -------
        tree : OccupancyOctree
        """


#: Optional capabilities a map may have: name -> what the method gives.
CAPABILITIES = MappingProxyType({
    "variance": "variance(points): the predictive variance at each point",
    "changed_cells": "changed_cells(): the cells changed since the last reset_changes()",
    "distance_field": "distance_field(bbox, ...): Euclidean distances to the occupied cells",
    "colors": "colors(points): the colour of each point's cell",
    "decay": "decay(now, max_age=...): cells stamped by insert_scan(stamp=) fade when outdated",
    "merge": "merge(other, transform=None): another map's log-odds added cell by cell",
    "project_2d": "project_2d(z_min, z_max, ...): a height band as a 2D occupancy grid",
    "frontiers": "frontiers(...): free cells next to unknown space, in clusters",
})

#: The OctoMap files (and the point clouds of occupied cells) every map writes through
#: its ``to_octree()``.
OCTREE_FORMATS = (".bt", ".ot", ".ply", ".pcd")


def capabilities(map: Any) -> frozenset[str]:
    """The optional capabilities of a map or map class.

    Parameters
    ----------
    map : object or type
        A map, or its class.

    Returns
    -------
    names : frozenset of str
        The names of :data:`CAPABILITIES` that `map` has as a callable.

    Examples
    --------
    >>> from occgp import OccupancyOctree, BGKMap
    >>> from occgp.maps import capabilities
    >>> sorted(capabilities(OccupancyOctree))
    ['changed_cells', 'decay', 'distance_field', 'frontiers', 'merge', 'project_2d']
    >>> sorted(capabilities(BGKMap))
    ['variance']
    """
    cls = map if isinstance(map, type) else type(map)
    return frozenset(name for name in CAPABILITIES
                     if callable(inspect.getattr_static(cls, name, None)))


@dataclass(frozen=True)
class MapType:
    """One registered map type (see :func:`register`)."""

    #: The name :func:`make_map`, ``occgp map --method`` and the demo use.
    name: str
    #: The map class (or a callable building a map from keyword parameters).
    cls: Callable[..., Any]
    #: The dimensions of the points the map takes (3, or 2 for the 2D GP maps).
    dims: tuple[int, ...]
    #: The file suffixes the class's ``save`` writes and ``load`` reads.
    formats: tuple[str, ...]
    #: One line that says what the map is.
    description: str
    #: Parameters :func:`make_map` passes before the caller's (which override them).
    defaults: Mapping[str, Any] = field(default_factory=dict)
    #: The plugin that registered the map: ``"NAME = VALUE (DISTRIBUTION)"`` of its
    #: entry point; None for occgp's maps and those registered by code run in-process.
    plugin: str | None = None

    @property
    def outputs(self) -> tuple[str, ...]:
        """Every suffix a map of this type can be written to: its own formats, then
        OctoMap's files and point clouds through ``to_octree()``."""
        return self.formats + tuple(s for s in OCTREE_FORMATS if s not in self.formats)

    @property
    def capabilities(self) -> frozenset[str]:
        """The optional capabilities of the class (see :func:`capabilities`)."""
        return capabilities(self.cls)

    def parameters(self) -> tuple[str, ...]:
        """The names of the class's constructor parameters."""
        return _init_parameters(self.cls)

    def check_params(self, params: Mapping[str, Any]) -> None:
        """Check that the constructor takes every name of `params` and that `params`
        with the registered defaults gives it every parameter it needs.

        Parameters
        ----------
        params : mapping
            Constructor parameters by name (their values are the class's to check).

        Raises
        ------
        ValueError
            If the constructor takes no parameter of a name, or lacks one it needs.
        """
        known = self.parameters()
        unknown = [p for p in params if p not in known]
        # a constructor whose **keywords only take deprecated names (occgp._params)
        renamed = getattr(self.cls, "_deprecated_params", None)
        if renamed is not None:
            unknown = [p for p in unknown if p not in renamed]
        if unknown and ("**" not in known or renamed is not None):
            raise ValueError(f"the {self.name!r} map takes no parameter {unknown[0]!r}; it "
                             f"takes {', '.join(k for k in known if k != '**') or 'none'}")
        try:
            sig = inspect.signature(self.cls)
        except (TypeError, ValueError):
            return                  # no signature to check: the class will tell
        missing = [p.name for p in sig.parameters.values()
                   if p.default is p.empty and p.kind in (p.POSITIONAL_OR_KEYWORD,
                                                          p.KEYWORD_ONLY)
                   and p.name not in params and p.name not in self.defaults]
        if missing:
            raise ValueError(f"the {self.name!r} map needs the parameters {missing}")


_REGISTRY: dict[str, MapType] = {}
# the modules whose import registers the built-in map types (the 2D GP maps live in a
# subpackage that `import occgp` does not load)
_BUILTIN_MODULES = ("occgp", "occgp.gp")
_loaded = False
# the plugins (entry points of ENTRY_POINT_GROUP): loaded once, after the built-in maps
_plugins_loaded = False
_plugin_lock = threading.RLock()
# the plugin being loaded (its label), which register() records and names in errors
_loading_plugin: str | None = None

C = TypeVar("C", bound=Callable[..., Any])


def register(name: str, *, dims: tuple[int, ...] | int = 3,
             formats: tuple[str, ...] = (".npz",), description: str | None = None,
             **defaults: Any) -> Callable[[C], C]:
    """Register a map class under `name`: a class decorator.

    A plugin (a separate distribution) calls it from the module its
    ``occgp.maps`` entry point names (see :data:`ENTRY_POINT_GROUP`).

    Parameters
    ----------
    name : str
        The map type's name: lower case letters, digits, ``-`` and ``_``,
        starting with a letter. Registering another class under a name that is
        taken raises (a plugin cannot replace a built-in map or another
        plugin's); registering the same class again replaces its entry.
    dims : int or tuple of int, default=3
        The dimensions of the points the map takes.
    formats : tuple of str, default=(".npz",)
        The file suffixes the class's ``save`` writes and ``load`` reads.
    description : str, default=None
        One line that says what the map is; None takes the first line of the
        class's docstring.
    **defaults
        Parameters :func:`make_map` passes unless the caller gives them.

    Returns
    -------
    decorator : callable
        Takes the class, registers it and returns it unchanged.

    Raises
    ------
    ValueError
        If `name` is malformed or taken by another class, `dims` holds
        other than 2 and 3, or a format does not start with a dot.
    TypeError
        If `name` or `description` is not a string, `dims` is not an int or a
        tuple of ints (a bool or a float such as ``3.0`` is not), or `formats`
        is not a tuple of strings.

    Examples
    --------
    >>> from occgp.maps import register, make_map
    >>> from occgp import OccupancyOctree
    >>> @register("coarse-octree", description="An octree of 0.5 m cells", resolution=0.5)
    ... class CoarseOctree(OccupancyOctree):
    ...     pass
    >>> make_map("coarse-octree").resolution
    0.5
    """
    if not isinstance(name, str):
        raise TypeError(f"name must be a str, got {type(name).__name__}")
    if not name or not name[0].isalpha() or not name.isascii() or name != name.lower() \
            or not name.replace("-", "").replace("_", "").isalnum():
        raise ValueError(f"name must be lower-case letters, digits, '-' and '_', starting "
                         f"with a letter, got {name!r}")
    dims = _check_dims(dims)
    if isinstance(formats, (str, bytes)) or not isinstance(formats, (tuple, list)) \
            or not all(isinstance(s, str) for s in formats):
        raise TypeError(f"formats must be a tuple of file suffixes such as ('.npz',), got "
                        f"{formats!r}")
    formats = tuple(formats)
    if any(not s.startswith(".") for s in formats):
        raise ValueError(f"formats must be file suffixes such as '.npz', got {formats!r}")
    if description is not None and not isinstance(description, str):
        raise TypeError(f"description must be a str or None, got {type(description).__name__}")

    def decorator(cls: C) -> C:
        old = _REGISTRY.get(name)
        if old is not None and _qualname(old.cls) != _qualname(cls):
            owner = f"the plugin {old.plugin}" if old.plugin else (
                "occgp's built-in map" if _qualname(old.cls).startswith("occgp.") else
                "a map registered in-process")
            by = f" by the plugin {_loading_plugin}" if _loading_plugin else ""
            raise ValueError(f"map type {name!r} is taken by {_qualname(old.cls)} ({owner}); "
                             f"{_qualname(cls)} cannot be registered under it{by}: choose "
                             f"another name")
        doc = (inspect.getdoc(cls) or "").strip().splitlines()
        _REGISTRY[name] = MapType(name, cls, dims, formats,
                                  description if description is not None else
                                  (doc[0] if doc else name),
                                  MappingProxyType(dict(defaults)),
                                  old.plugin if old is not None else _loading_plugin)
        return cls
    return decorator


def _is_int(value: Any) -> bool:
    return isinstance(value, (numbers.Integral, np.integer)) and not isinstance(
        value, (bool, np.bool_))


def _check_dims(dims: Any) -> tuple[int, ...]:
    """register's `dims` as a tuple of ints, each 2 or 3."""
    if _is_int(dims):
        dims = (dims,)
    elif not isinstance(dims, (tuple, list)) or not all(_is_int(d) for d in dims):
        what = type(dims).__name__ if not isinstance(dims, (tuple, list)) else repr(dims)
        raise TypeError(f"dims must be an int or a tuple of ints (2 or 3), got {what}")
    dims = tuple(int(d) for d in dims)
    if not dims or any(d not in (2, 3) for d in dims):
        raise ValueError(f"dims must be 2, 3 or a tuple of them, got {dims!r}")
    return dims


def _qualname(cls: Any) -> str:
    return f"{getattr(cls, '__module__', '?')}.{getattr(cls, '__qualname__', repr(cls))}"


def _load_builtins() -> None:
    """Register the built-in map types, then the plugins' (once each)."""
    global _loaded
    if not _loaded:
        for module in _BUILTIN_MODULES:
            importlib.import_module(module)
        _loaded = True
    if not _plugins_loaded:
        _load_plugins()


def _plugin_label(ep: importlib.metadata.EntryPoint) -> str:
    """``name = value (distribution)`` of an entry point, as messages name a plugin."""
    dist = getattr(ep, "dist", None)
    dist_name = getattr(dist, "name", None) if dist is not None else None
    return f"{ep.name} = {ep.value}" + (f" (distribution {dist_name})" if dist_name else "")


@contextmanager
def _registering(label: str) -> Iterator[None]:
    global _loading_plugin
    outer, _loading_plugin = _loading_plugin, label
    try:
        yield
    finally:
        _loading_plugin = outer


def _load_plugins() -> None:
    """Load every entry point of ENTRY_POINT_GROUP, once, in the entry points' order.

    A plugin that fails (its import raises, its function raises, or it registers a name
    that is taken) is reported with a MapPluginWarning naming it; the maps it registered
    before failing are removed, and the other plugins load as usual."""
    global _plugins_loaded
    with _plugin_lock:
        if _plugins_loaded:
            return
        _plugins_loaded = True          # set first: a plugin may read the registry
        try:
            eps = importlib.metadata.entry_points(group=ENTRY_POINT_GROUP)
        except Exception as exc:        # a broken metadata folder on sys.path
            warnings.warn(f"occgp.maps: the {ENTRY_POINT_GROUP!r} entry points could not "
                          f"be read ({type(exc).__name__}: {exc}); no map plugin is loaded",
                          MapPluginWarning, stacklevel=3)
            return
        seen = set()
        for ep in eps:
            key = (ep.name, ep.value)
            if key in seen:             # one distribution seen twice on sys.path
                continue
            seen.add(key)
            label = _plugin_label(ep)
            before = set(_REGISTRY)
            try:
                with _registering(label):
                    obj = ep.load()
                    if callable(obj) and not isinstance(obj, (type, ModuleType)):
                        obj()
            except Exception as exc:
                for name in set(_REGISTRY) - before:
                    del _REGISTRY[name]
                warnings.warn(f"occgp.maps: the map plugin {label} failed to load and is "
                              f"skipped: {type(exc).__name__}: {exc}", MapPluginWarning,
                              stacklevel=3)


def available_maps(*, dims: int | None = None) -> list[str]:
    """The names of the registered map types, in registration order.

    The built-in maps come first, then those of the plugins (the entry points
    of :data:`ENTRY_POINT_GROUP`, loaded on the first call of this function,
    :func:`map_type` or :func:`make_map`; a plugin that fails to load is
    skipped with a :class:`MapPluginWarning`).

    Parameters
    ----------
    dims : {2, 3}, default=None
        Only the maps that take points of this dimension; None lists all.

    Returns
    -------
    names : list of str

    Raises
    ------
    ValueError
        If `dims` is not None, 2 or 3.

    Examples
    --------
    >>> from occgp.maps import available_maps
    >>> {"octree", "bgk", "akimap", "knn"} <= set(available_maps(dims=3))
    True
    """
    if dims is not None and dims not in (2, 3):
        raise ValueError(f"dims must be 2, 3 or None, got {dims!r}")
    _load_builtins()
    return [name for name, t in _REGISTRY.items() if dims is None or dims in t.dims]


def map_type(name: str) -> MapType:
    """The registry entry of a map type.

    Parameters
    ----------
    name : str
        A name of :func:`available_maps`.

    Returns
    -------
    entry : MapType

    Raises
    ------
    ValueError
        If no map type has that name (the message lists those there are).
    """
    _load_builtins()
    try:
        return _REGISTRY[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown map type {name!r}; available: "
                         f"{', '.join(available_maps())}") from None


def make_map(name: str, **params: Any) -> Any:
    """Build an empty map of a registered type.

    Parameters
    ----------
    name : str
        A name of :func:`available_maps`.
    **params
        Constructor parameters; they override the type's registered defaults.

    Returns
    -------
    map : OccupancyMap

    Raises
    ------
    ValueError
        If `name` is not registered, a parameter is not one the class takes or
        one it needs is missing, a ``resolution`` lies outside
        :data:`~occgp._validation.RESOLUTION_RANGE` (``[1e-15, 1e14]`` m, for
        every map type), or the class rejects a value.
    TypeError
        If a ``resolution`` is not a real number, or the class rejects a
        value's type.

    Examples
    --------
    >>> from occgp.maps import make_map
    >>> make_map("bgk", resolution=0.2).resolution
    0.2
    """
    entry = map_type(name)
    entry.check_params(params)
    params = {**entry.defaults, **params}
    if params.get("resolution") is not None:
        # one range for every map type: beyond it single-precision geometry fails
        check_resolution(params["resolution"])
    return entry.cls(**params)


def _init_parameters(cls: Callable[..., Any]) -> tuple[str, ...]:
    """The keyword parameters of `cls`'s constructor ('**' when it takes any)."""
    try:
        sig = inspect.signature(cls)
    except (TypeError, ValueError):
        return ("**",)
    names = []
    for p in sig.parameters.values():
        if p.kind is p.VAR_KEYWORD:
            names.append("**")
        elif p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY):
            names.append(p.name)
    return tuple(names)
