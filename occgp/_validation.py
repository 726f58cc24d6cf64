"""Input checks shared by occgp's public classes.

Every message names the argument, what was expected and what came, so that bad
input never reaches compiled code (whose own buffer errors are cryptic).
"""

from __future__ import annotations

import math
import numbers
import os
import pathlib
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["as_numeric", "as_float", "show_number", "as_points", "as_point", "check_real",
           "check_probability", "check_resolution",
           "check_int", "check_bool", "check_choice", "as_path", "check_seed",
           "check_n_jobs", "n_threads", "RESOLUTION_RANGE"]

#: The resolutions (metres) at which liboctomap's single-precision ray traversal is
#: sound. ``computeRayKeys`` normalises each ray by its length computed from float
#: squares: across the key range (``2 * 32768 * sqrt(3)`` cells) that squared length
#: must stay below ``FLT_MAX`` (resolution < 1.6e14), and a ray of one cell must keep a
#: normal (not denormal) squared length (resolution > 1.1e-19). Outside these bounds a
#: ray's direction becomes zero or infinite and the traversal never ends. The range
#: keeps a margin of ~1.6 below the first bound and 1e4 above the second.
RESOLUTION_RANGE = (1e-15, 1e14)


def as_numeric(x: ArrayLike, name: str, kinds: str = "iuf") -> np.ndarray:
    """Return `x` as a numpy array of real numbers (any shape), or raise naming `name`.

    `kinds` are the accepted dtype kinds (add ``"b"`` to accept booleans).
    """
    try:
        arr = np.asarray(x)
    except (ValueError, TypeError) as exc:
        raise ValueError(f"{name} must be a numeric array, could not convert it: {exc}") from None
    if arr.dtype.kind not in kinds:
        what = "real numbers or booleans" if "b" in kinds else "real numbers"
        raise TypeError(f"{name} must hold {what}, got dtype {arr.dtype}")
    return arr


def as_points(x: ArrayLike, name: str = "points", dim: int = 3) -> NDArray[np.float64]:
    """Return `x` as a C-contiguous float64 array of shape (n_points, dim).

    Raises
    ------
    TypeError
        If `x` does not hold real numbers.
    ValueError
        If `x` is not of shape (n_points, dim) or holds NaN or inf.
    """
    arr = as_numeric(x, name)
    if arr.ndim != 2 or arr.shape[1] != dim:
        raise ValueError(f"{name} must have shape (n_points, {dim}), got {arr.shape}")
    arr = np.ascontiguousarray(arr, dtype=np.float64)
    if np.isfinite(arr).all():
        return arr
    finite = np.isfinite(arr).all(axis=1)
    if not finite.all():
        bad = int(np.count_nonzero(~finite))
        first = int(np.flatnonzero(~finite)[0])
        raise ValueError(
            f"{name} must be finite: {bad} of {len(arr)} rows hold NaN or inf (first: row {first})"
        )
    return arr


def as_point(x: ArrayLike, name: str = "origin", dim: int = 3) -> NDArray[np.float64]:
    """Return `x` as a float64 array of shape (dim,), finite."""
    arr = as_numeric(x, name)
    if arr.shape != (dim,):
        raise ValueError(f"{name} must have shape ({dim},), got {arr.shape}")
    arr = np.ascontiguousarray(arr, dtype=np.float64)
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} must be finite, got {arr.tolist()}")
    return arr


def show_number(value: object) -> str:
    """``repr(value)``, shortened for an int of more than 40 digits (whose ``repr`` may
    be long, or refused past Python's int-to-text limit)."""
    if isinstance(value, (numbers.Integral, np.integer)) and not isinstance(value, bool):
        v = int(value)
        bits = v.bit_length()
        if bits > 132:                   # > 40 digits: 2**132 has 40
            digits = int(bits * math.log10(2)) + 1
            what = f"{'a negative' if v < 0 else 'an'} int of about {digits} digits"
            return what + " (beyond a float's range)" if bits > 1024 else what
    return repr(value)


def _is_real(value: object) -> bool:
    """Whether `value` is a real number (Python's or numpy's, not a bool)."""
    return not isinstance(value, (bool, np.bool_)) and isinstance(
        value, (numbers.Real, np.floating, np.integer))


def as_float(value: object) -> float:
    """``float(value)`` for a real number, with ints too large for a float as +-inf (so
    that a range check refuses them by value rather than ``float`` by OverflowError)."""
    try:
        return float(value)  # type: ignore[arg-type]
    except OverflowError:
        return math.inf if value > 0 else -math.inf  # type: ignore[operator]


def check_real(value: object, name: str, *, low: float | None = None,
               high: float | None = None, low_open: bool = True,
               high_open: bool = True, state_bounds: bool = False) -> float:
    """Return `value` as a float after checking it is a finite real in the given interval.

    Any real number is taken: Python's and numpy's ints and floats (an int too large
    for a float counts as infinite, so it fails the check with a ValueError, never
    OverflowError). A bool or any other type raises TypeError. The error names the
    interval (``"x must lie in (0.0, inf), got 0.0"``), or with `state_bounds` the
    bounds (``"x must be a finite number > 0, got 0.0"``).
    """
    if not _is_real(value):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__}")
    v = as_float(value)
    lo_ok = low is None or (v > low if low_open else v >= low)
    hi_ok = high is None or (v < high if high_open else v <= high)
    if not np.isfinite(v) or not lo_ok or not hi_ok:
        if state_bounds:
            bounds = " and ".join(f"{op} {bound:g}" for op, bound in
                                  ((">" if low_open else ">=", low),
                                   ("<" if high_open else "<=", high)) if bound is not None)
            raise ValueError(f"{name} must be a finite number {bounds}".rstrip()
                             + f", got {show_number(value) if math.isinf(v) else v}")
        lo = "-inf" if low is None else repr(low)
        hi = "inf" if high is None else repr(high)
        interval = f"{'(' if low_open else '['}{lo}, {hi}{')' if high_open else ']'}"
        raise ValueError(f"{name} must lie in {interval}, got {show_number(value)}")
    return v


def check_probability(value: object, name: str) -> float:
    """Return `value` as a float after checking it lies in the open interval (0, 1)."""
    return check_real(value, name, low=0.0, high=1.0)


def check_resolution(value: object, name: str = "resolution") -> float:
    """Return `value` as a float after checking it lies in :data:`RESOLUTION_RANGE`.

    A value that is not a number > 0 (NaN included) gets check_real's message, one > 0
    (an infinite one, or an int too large for a float, included) the range's.
    """
    v = math.inf if _is_real(value) and as_float(value) == math.inf else \
        check_real(value, name, low=0.0)
    lo, hi = RESOLUTION_RANGE
    if not lo <= v <= hi:
        raise ValueError(f"{name} must lie in [{lo:g}, {hi:g}] m (the range where liboctomap's "
                         f"single-precision ray traversal is sound), got {show_number(value)}")
    return v


def check_int(value: object, name: str, *, low: int | None = None,
              high: int | None = None, state_bounds: bool = False) -> int:
    """Return `value` as an int after checking it is an integer (not a bool) in [low, high].

    The errors name the kind of int (``"n must be a positive int, got 0"``), or with
    `state_bounds` the bound that fails (``"n must be an int"``, ``"n must be >= 1, got 0"``).
    """
    kind = {0: "a non-negative int", 1: "a positive int"}.get(low, "an int") \
        if low is not None and not state_bounds else "an int"
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (numbers.Integral,
                                                                     np.integer)):
        raise TypeError(f"{name} must be {kind}, got {type(value).__name__}")
    v = int(value)
    if state_bounds:
        if low is not None and v < low:
            raise ValueError(f"{name} must be >= {low}, got {show_number(v)}")
        if high is not None and v > high:
            raise ValueError(f"{name} must be <= {high}, got {show_number(v)}")
        return v
    if (low is not None and v < low) or (high is not None and v > high):
        if high is None:
            raise ValueError(f"{name} must be {kind}, got {show_number(v)}")
        lo = "-inf" if low is None else str(low)
        raise ValueError(f"{name} must lie in [{lo}, {high}], got {show_number(v)}")
    return v



def check_bool(value: object, name: str) -> bool:
    """Return `value` as a bool after checking it is one (numpy's included)."""
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be a bool, got {type(value).__name__}")
    return bool(value)


def check_choice(value: object, name: str, choices: Sequence[str], *,
                 strict_type: bool = False) -> str:
    """Return `value` after checking it is one of the strings `choices`.

    A value that is not a str raises ValueError, or TypeError with `strict_type`.
    """
    if strict_type and not isinstance(value, str):
        raise TypeError(f"{name} must be one of {choices}, got {type(value).__name__}")
    if not isinstance(value, str) or value not in choices:
        raise ValueError(f"{name} must be one of {choices}, got {value!r}")
    return value


def as_path(path: Any, name: str = "path") -> pathlib.Path:
    """Return `path` as a :class:`pathlib.Path`; TypeError naming `name` otherwise."""
    try:
        path = os.fspath(path)
    except TypeError:
        raise TypeError(f"{name} must be a str or os.PathLike, "
                        f"got {type(path).__name__}") from None
    if not isinstance(path, str):
        raise TypeError(f"{name} must be a str or os.PathLike, got {type(path).__name__}")
    if "\0" in path:
        raise ValueError(f"{name} must not contain a NUL character, got {path!r}")
    return pathlib.Path(path)


def check_seed(seed: Any, name: str = "seed") -> np.random.Generator:
    """``numpy.random.default_rng(seed)``, with errors that name `name`."""
    if isinstance(seed, (bool, np.bool_)):
        raise TypeError(f"{name} must be an int, a numpy Generator or None, got bool")
    try:
        return np.random.default_rng(seed)
    except (TypeError, ValueError) as exc:
        raise (ValueError if isinstance(exc, ValueError) else TypeError)(
            f"{name} must be a non-negative int, a numpy Generator or None, got {seed!r}"
        ) from None


def check_n_jobs(n_jobs: Any, name: str = "n_jobs") -> int | None:
    """Return `n_jobs` (None, or a non-zero int as joblib counts them) after checking it."""
    if n_jobs is None:
        return None
    if isinstance(n_jobs, (bool, np.bool_)) or not isinstance(
            n_jobs, (numbers.Integral, np.integer)) or n_jobs == 0:
        raise ValueError(f"{name} must be None, a positive int or a negative int "
                         f"(-1: every core), got {n_jobs!r}")
    return int(n_jobs)


def n_threads(n_jobs: int | None) -> int:
    """Threads for a checked `n_jobs` as joblib counts them (None: 1; -1: every core), at
    most the number of cores (threads beyond them only cost memory)."""
    if n_jobs is None:
        return 1
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") \
        else (os.cpu_count() or 1)
    return min(n_jobs, cores) if n_jobs > 0 else max(cores + 1 + n_jobs, 1)
