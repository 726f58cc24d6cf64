"""The registry of range-image models: names -> classes, and specs -> models.

A spec is ``{"name": ..., "args": {...}, "sd": state_dict}``: :func:`make` builds the model
registered under the name, and a model's ``spec()`` gives it back (the checkpoints of
``occgp iln train`` store it). Classes join the registry with :func:`register`.
"""

from __future__ import annotations

import copy
from typing import Callable

from torch import nn

__all__ = ["register", "available_models", "make"]

_MODELS: dict[str, type] = {}


def register(name: str) -> Callable[[type], type]:
    """Class decorator adding a model class to the registry under `name`.

    Parameters
    ----------
    name : str
        Registry name used in specs (``{"name": name, "args": {...}}``).

    Returns
    -------
    decorator : callable
        Registers the class and returns it unchanged.

    Raises
    ------
    TypeError
        If `name` is not a str.
    ValueError
        If `name` is empty or already registered to another class.
    """
    if not isinstance(name, str):
        raise TypeError(f"name must be a str, got {type(name).__name__}")
    if not name:
        raise ValueError("name must be a non-empty str")

    def decorator(cls: type) -> type:
        if name in _MODELS and _MODELS[name] is not cls:
            raise ValueError(f"model name {name!r} is already registered to {_MODELS[name].__name__}")
        _MODELS[name] = cls
        cls.registry_name = name
        return cls

    return decorator


def available_models() -> list[str]:
    """Names of the registered models, sorted.

    Returns
    -------
    names : list of str
        The names :func:`make` accepts as ``spec["name"]`` (``"bilinear"``,
        ``"edge-aware"``, ``"edsr-baseline"``, ``"iln"``, ``"inverse-bilinear"``,
        ``"liif"`` and any added with :func:`register`).
    """
    return sorted(_MODELS)


def make(spec: dict, load_sd: bool = False) -> nn.Module:
    """Build a model from its spec.

    Parameters
    ----------
    spec : dict
        ``{"name": str, "args": dict}``, optionally with ``"sd"`` (a state_dict), as written by
        :meth:`RangeModel.spec` and stored in training checkpoints.
    load_sd : bool, default=False
        Load ``spec["sd"]`` into the new model.

    Returns
    -------
    model : torch.nn.Module
        The model, on the CPU, in training mode.

    Raises
    ------
    TypeError
        If `spec` is not a dict, ``spec["args"]`` is not a dict, or an argument has the wrong type.
    ValueError
        If the name is unknown, an argument is unknown or out of range, or `load_sd` is true and
        the spec has no ``"sd"`` or one that does not fit the model.

    Examples
    --------
    >>> m = make({"name": "iln", "args": {"channels": 16, "n_resblocks": 1, "depth": 1}})
    >>> m2 = make(m.spec(), load_sd=True)
    >>> sorted(m.spec())
    ['args', 'name', 'sd']
    """
    if not isinstance(spec, dict):
        raise TypeError(f"spec must be a dict with keys 'name' and 'args', got {type(spec).__name__}")
    if "name" not in spec:
        raise ValueError("spec must have a 'name' key (one of %s)" % ", ".join(available_models()))
    name = spec["name"]
    if not isinstance(name, str) or name not in _MODELS:
        raise ValueError(f"spec['name'] must be one of {available_models()}, got {name!r}")
    args = spec.get("args", {}) or {}
    if not isinstance(args, dict):
        raise TypeError(f"spec['args'] must be a dict, got {type(args).__name__}")
    cls = _MODELS[name]
    allowed = getattr(cls, "arg_names", None)
    if allowed is not None:
        unknown = sorted(set(args) - set(allowed))
        if unknown:
            raise ValueError(
                f"spec['args'] has unknown argument(s) {unknown} for model {name!r}; "
                f"expected some of {list(allowed)}"
            )
    model = cls(**copy.deepcopy(args))
    if load_sd:
        if "sd" not in spec or spec["sd"] is None:
            raise ValueError("load_sd=True needs spec['sd'] (a state_dict), but the spec has none")
        sd = spec["sd"]
        if not isinstance(sd, dict):
            raise TypeError(f"spec['sd'] must be a state_dict (dict), got {type(sd).__name__}")
        try:
            model.load_state_dict(sd)
        except RuntimeError as exc:
            raise ValueError(f"spec['sd'] does not fit model {name!r} with args {args}: {exc}") from None
    return model
