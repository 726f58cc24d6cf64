"""One parameter mechanism for occgp's classes: a table of constraints per class.

A class lists what each constructor parameter may be in ``_parameter_constraints``
(scikit-learn's convention, ``sklearn.utils._param_validation``)::

    class BGKMap(ParamsMixin, ...):
        _parameter_constraints = {
            **KernelMapBase._parameter_constraints,
            "ell": [Interval(Real, 0, None, closed="neither")],
            "free_resolution": [None, Interval(Real, 0, None, closed="neither")],
        }

and inherits :meth:`ParamsMixin.get_params` and :meth:`ParamsMixin.set_params`
instead of writing its own. A parameter's value is accepted when one of its
constraints accepts it:

* ``None``: the value None;
* a type (``str``, ``numbers.Real``, ...): an instance of it;
* ``"boolean"``: a bool (Python's or numpy's);
* :class:`Interval`: a real or an int in an interval (checked by
  :func:`occgp._validation.check_real` / :func:`~occgp._validation.check_int`,
  whose messages name the parameter);
* :class:`Options`: one of a set of strings;
* :class:`Check`, or any other callable ``f(value, name)``: a checker of
  :mod:`occgp._validation` (or the class's own) that raises TypeError /
  ValueError naming the parameter.

A parameter missing from the table is not checked one by one. Rules that tie
parameters together go in ``_check_params_together``; renamed parameters in
``_deprecated_params`` (old name to new name), which keep the old name working
with a :class:`DeprecationWarning` for one release. A function's renamed keyword
argument gets the same through :func:`renamed_keywords`.

:data:`DEFAULT_RESOLUTION` is the one default cell edge of the maps.
"""

from __future__ import annotations

import functools
import inspect
import numbers
import warnings
from collections.abc import Callable, Iterable
from typing import Any, ClassVar, Protocol, TypeVar

from ._validation import check_bool, check_choice, check_int, check_real

__all__ = ["DEFAULT_RESOLUTION", "Interval", "Options", "Check", "ParamsMixin",
           "validate_params", "check_renamed", "deprecated_alias", "renamed_keywords",
           "param_names"]

#: The default edge length (metres) of the cells of every map that has cells.
DEFAULT_RESOLUTION = 0.1


class Interval:
    """A real number (``numbers.Real``) or an int (``numbers.Integral``) in an interval.

    Parameters
    ----------
    type : numbers.Real or numbers.Integral
    left, right : float or None
        The bounds; None: unbounded.
    closed : {"left", "right", "both", "neither"}, default="neither"
        Which bounds belong to the interval (an int's are always closed).
    """

    def __init__(self, type: type, left: float | None, right: float | None, *,
                 closed: str = "neither") -> None:
        if type not in (numbers.Real, numbers.Integral):
            raise TypeError(f"Interval's type must be numbers.Real or numbers.Integral, "
                            f"got {type!r}")
        check_choice(closed, "closed", ("left", "right", "both", "neither"))
        self.type, self.left, self.right, self.closed = type, left, right, closed

    def __call__(self, value: object, name: str) -> Any:
        if self.type is numbers.Integral:
            return check_int(value, name, low=self.left,  # type: ignore[arg-type]
                             high=self.right)  # type: ignore[arg-type]
        return check_real(value, name,
                          low=None if self.left is None else float(self.left),
                          high=None if self.right is None else float(self.right),
                          low_open=self.closed not in ("left", "both"),
                          high_open=self.closed not in ("right", "both"))

    def __str__(self) -> str:
        if self.type is numbers.Integral:
            lo = "-inf" if self.left is None else self.left
            hi = "inf" if self.right is None else self.right
            return f"an int in [{lo}, {hi}]"
        lo = "-inf" if self.left is None else repr(float(self.left))
        hi = "inf" if self.right is None else repr(float(self.right))
        return (f"a real number in {'[' if self.closed in ('left', 'both') else '('}{lo}, "
                f"{hi}{']' if self.closed in ('right', 'both') else ')'}")

    def __repr__(self) -> str:
        return (f"Interval({self.type.__name__}, {self.left!r}, {self.right!r}, "
                f"closed={self.closed!r})")


class Options:
    """One of a set of strings (scikit-learn's ``StrOptions``)."""

    def __init__(self, options: Iterable[str]) -> None:
        self.options = tuple(options)

    def __call__(self, value: object, name: str) -> str:
        return check_choice(value, name, self.options)

    def __str__(self) -> str:
        return f"one of {self.options}"

    def __repr__(self) -> str:
        return f"Options({self.options!r})"


class Check:
    """A checker ``f(value, name)`` of :mod:`occgp._validation`, with a description
    for the messages that list several constraints."""

    def __init__(self, func: Callable[[Any, str], Any], description: str) -> None:
        self.func, self.description = func, description

    def __call__(self, value: object, name: str) -> Any:
        return self.func(value, name)

    def __str__(self) -> str:
        return self.description

    def __repr__(self) -> str:
        return f"Check({getattr(self.func, '__name__', self.func)!r})"


def _describe(constraint: Any) -> str:
    if constraint is None:
        return "None"
    if constraint == "boolean":
        return "a bool"
    if isinstance(constraint, type):
        return f"an instance of {constraint.__name__}"
    return str(constraint) if isinstance(constraint, (Interval, Options, Check)) else \
        f"accepted by {getattr(constraint, '__name__', constraint)}"


def _check_one(constraint: Any, value: object, name: str) -> Any:
    """`value` if `constraint` accepts it (checked: an Interval gives a float / int);
    TypeError / ValueError otherwise."""
    if constraint is None:
        if value is None:
            return None
        raise TypeError(f"{name} must be None, got {type(value).__name__}")
    if constraint == "boolean":
        return check_bool(value, name)
    if isinstance(constraint, type):
        if isinstance(value, constraint):
            return value
        raise TypeError(f"{name} must be an instance of {constraint.__name__}, "
                        f"got {type(value).__name__}")
    if callable(constraint):
        return constraint(value, name)
    raise TypeError(f"unknown constraint {constraint!r} for parameter {name!r}")


def validate_params(constraints: dict[str, list], params: dict[str, Any],
                    owner: str = "") -> dict[str, Any]:
    """The values of `params` checked against their `constraints` (a
    ``_parameter_constraints`` table); names the table lacks pass unchecked.

    A value one constraint accepts is returned as that constraint makes it (an
    :class:`Interval` gives a float or an int). Otherwise TypeError or ValueError
    names the parameter: the error of its one constraint besides None, else a list
    of what it may be.
    """
    out = dict(params)
    for name, value in params.items():
        allowed = constraints.get(name)
        if allowed is None:
            continue
        errors: list[Exception] = []
        for constraint in allowed:
            try:
                out[name] = _check_one(constraint, value, name)
                break
            except (TypeError, ValueError) as exc:
                errors.append(exc)
        else:
            real = [c for c in allowed if c is not None]
            if len(real) == 1 and value is not None:
                raise errors[allowed.index(real[0])]
            kind = TypeError if all(isinstance(e, TypeError) for e in errors) else ValueError
            where = f" of {owner}" if owner else ""
            raise kind(f"{name}{where} must be "
                       f"{' or '.join(_describe(c) for c in allowed)}, got {value!r}")
    return out


def check_renamed(renames: dict[str, str], params: dict[str, Any],
                  defaults: dict[str, Any] | None = None, owner: str = "",
                  stacklevel: int = 3) -> dict[str, Any]:
    """`params` with each deprecated name of `renames` (old name to new name) turned
    into its new name, with a DeprecationWarning naming the new one.

    An old name given together with its new name raises TypeError; with `defaults`
    (the constructor's), a new name that holds its default counts as not given.
    """
    out = dict(params)
    for old, new in renames.items():
        if old not in out:
            continue
        value = out.pop(old)
        warnings.warn(f"{owner + ': ' if owner else ''}the parameter {old!r} is deprecated "
                      f"and will be removed in the next release; use {new!r} instead",
                      DeprecationWarning, stacklevel=stacklevel)
        if new in out and (defaults is None or out[new] is not defaults.get(new, object())):
            raise TypeError(f"got both {old!r} (deprecated) and {new!r}; pass only {new!r}")
        out[new] = value
    return out


_F = TypeVar("_F", bound=Callable[..., Any])


def renamed_keywords(**renames: str) -> Callable[[_F], _F]:
    """A decorator that keeps the old names (``old="new"``) of a function's renamed
    keyword arguments working for one release, with a DeprecationWarning naming the
    new one (:func:`check_renamed`; both names at once raise TypeError). Positional
    calls and the new names pass through untouched; the signature shown is the
    function's own.

    Examples
    --------
    >>> @renamed_keywords(centres="centers")
    ... def count(centers):
    ...     return len(centers)
    >>> count(centers=[1, 2])
    2
    """
    def decorate(func: _F) -> _F:
        @functools.wraps(func)
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            if not renames.keys() & kwargs.keys():
                return func(*args, **kwargs)
            return func(*args, **check_renamed(renames, kwargs, owner=func.__name__,
                                               stacklevel=3))
        return wrapper  # type: ignore[return-value]
    return decorate


def deprecated_alias(new: str, old: str) -> property:
    """A property `old` that reads and writes the attribute `new`, with a
    DeprecationWarning naming `new` (a renamed parameter's old attribute)."""
    message = (f"the attribute {old!r} is deprecated and will be removed in the next "
               f"release; use {new!r} instead")

    def fget(self):
        warnings.warn(message, DeprecationWarning, stacklevel=2)
        return getattr(self, new)

    def fset(self, value):
        warnings.warn(message, DeprecationWarning, stacklevel=2)
        setattr(self, new, value)

    return property(fget, fset, doc=f"Deprecated alias of :attr:`{new}`.")


def param_names(cls: type[object]) -> list[str]:
    """The constructor's parameters of `cls`, in the signature's order (``**kwargs``,
    where deprecated names arrive, left out): :class:`ParamsMixin`'s
    ``_get_param_names``, and that of a class that binds ``get_params`` in its class
    body instead of deriving from it (``_get_param_names = classmethod(param_names)``).

    Parameters
    ----------
    cls : type
        The class.

    Returns
    -------
    names : list of str
    """
    init = cls.__init__
    if init is object.__init__:
        return []
    names = []
    for p in inspect.signature(init).parameters.values():
        if p.name == "self" or p.kind == p.VAR_KEYWORD:
            continue
        if p.kind == p.VAR_POSITIONAL:
            raise RuntimeError(f"{cls.__name__}'s constructor must not take *args "
                               f"(scikit-learn's convention)")
        names.append(p.name)
    return names


class _ParamsSource(Protocol):
    """What :meth:`ParamsMixin.get_params` reads: a :class:`ParamsMixin`, or a class
    that binds ``get_params`` in its class body (``occgp.octree.LogOddsMap``)."""

    def _get_param_names(self) -> list[str]: ...
    def _get_param(self, name: str) -> Any: ...


class ParamsMixin:
    """``get_params`` / ``set_params`` from a table of constraints (scikit-learn's
    convention, and what :func:`sklearn.base.clone` needs).

    A class lists its constructor's parameters in ``_parameter_constraints``
    (see :mod:`occgp._params`; a subclass extends its base's with
    ``{**Base._parameter_constraints, ...}``) and ``_deprecated_params`` (old
    name to new name). It may override

    * ``_check_params_together(params)``: every parameter (the new values over
      the current ones, each checked by the table) checked together; returns the
      checked values or raises TypeError / ValueError naming a parameter;
    * ``_set_checked_params(params, checked)``: store the accepted `params`
      (default: ``setattr`` of each value as given, scikit-learn's convention);
    * ``_get_param(name)``: read a stored value (default: ``getattr``).
    """

    _parameter_constraints: ClassVar[dict[str, list]] = {}
    _deprecated_params: ClassVar[dict[str, str]] = {}

    @classmethod
    def _get_param_names(cls) -> list[str]:
        """The constructor's parameters, in the signature's order (``**kwargs``,
        where deprecated names arrive, left out): :func:`param_names`."""
        return param_names(cls)

    @classmethod
    def _renamed(cls, deprecated: dict[str, Any], **given: Any) -> dict[str, Any]:
        """The constructor's values `given` of renamed parameters, updated from its
        ``**deprecated`` keywords (old names, with a DeprecationWarning each); any
        other keyword raises TypeError, as Python does."""
        for name in deprecated:
            if name not in cls._deprecated_params:
                raise TypeError(f"{cls.__name__}.__init__() got an unexpected keyword "
                                f"argument {name!r}")
        defaults = {p.name: p.default
                    for p in inspect.signature(cls.__init__).parameters.values()}
        out = check_renamed(cls._deprecated_params, {**given, **deprecated}, defaults,
                            cls.__name__, stacklevel=4)
        return {name: out[name] for name in given}

    def get_params(self: _ParamsSource, deep: bool = True) -> dict[str, Any]:
        """The constructor's parameters (scikit-learn's ``get_params``).

        Parameters
        ----------
        deep : bool, default=True
            Also the parameters of the objects the parameters hold (a kernel's,
            as ``kernel__length_scale``).

        Returns
        -------
        params : dict
            Parameter name to value, as stored (``type(m)(**m.get_params(deep=False))``
            and :func:`sklearn.base.clone` build an empty object with the same
            parameters).
        """
        out: dict[str, Any] = {}
        for name in self._get_param_names():
            value = self._get_param(name)
            if deep and hasattr(value, "get_params") and not isinstance(value, type):
                out.update((f"{name}__{k}", v) for k, v in value.get_params(deep=True).items())
            out[name] = value
        return out

    def _get_param(self, name: str) -> Any:
        """The stored value of the parameter `name` (default: the attribute; a class
        that keeps its parameters in a dict reads them there)."""
        return getattr(self, name)

    def _check_params_together(self, params: dict[str, Any]) -> dict[str, Any]:
        return params

    def _set_checked_params(self, params: dict[str, Any], checked: dict[str, Any]) -> None:
        for name, value in params.items():
            setattr(self, name, value)

    def set_params(self, **params: Any):
        """Change parameters (scikit-learn's ``set_params``), all checked first.

        Parameters
        ----------
        **params
            Constructor parameters by name (``name__sub`` for a parameter of an
            object a parameter holds).

        Returns
        -------
        self
            The object.

        Raises
        ------
        TypeError
            If a value has the wrong type.
        ValueError
            If a name is not a parameter, or a value is out of range. Nothing
            has changed then.
        """
        if not params:
            return self
        cls = type(self)
        params = check_renamed(cls._deprecated_params, params, owner=cls.__name__)
        names = self._get_param_names()
        own: dict[str, Any] = {}
        nested: dict[str, dict[str, Any]] = {}
        for key, value in params.items():
            name, sep, sub = key.partition("__")
            if name not in names:
                raise ValueError(f"{name!r} is not a parameter of {cls.__name__}; its "
                                 f"parameters are {', '.join(names) or 'none'}")
            if sep:
                nested.setdefault(name, {})[sub] = value
            else:
                own[name] = value
        for name in nested:
            holder = own.get(name, self._get_param(name))
            if not hasattr(holder, "set_params"):
                raise ValueError(f"{name} of {cls.__name__} holds "
                                 f"{type(holder).__name__}, which has no parameters to set")
        current = self.get_params(deep=False)
        checked = validate_params(cls._parameter_constraints, own, cls.__name__)
        checked = self._check_params_together({**current, **checked})
        for name, sub_params in nested.items():  # each object's set_params checks its own
            own.get(name, self._get_param(name)).set_params(**sub_params)
        self._set_checked_params(own, checked)
        return self
