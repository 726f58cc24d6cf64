"""The options of ``occgp map``: the errors that name one (:class:`OptionError`), the
option of each :func:`~occgp.cli._map_command.map_scans` argument, the k-NN model's
options and their checks, and the parsing of option values (``--param``, ``--fields``)."""

from __future__ import annotations

import argparse
import ast
import inspect
import re
from collections.abc import Mapping
from typing import Any

import numpy as np

from .._params import check_renamed
from ..knn import CDFS, KNN_PARAMS, KNNMap, check_knn_params

__all__ = ["OptionError", "OptionTypeError", "option_error", "OWN_PARAMS", "OPTION_OF",
           "POSE_FORMATS", "KNN_OPTIONS", "KNN_DEFAULTS", "check_knn_options", "knn_error",
           "option_name", "parse_param", "parse_fields"]

# KNNMap's model parameters (those of `occgp map --method knn`) and their defaults,
# read from its signature
KNN_OPTIONS = KNN_PARAMS + ("cdf",)
KNN_DEFAULTS = {name: prm.default for name, prm in
                 inspect.signature(KNNMap.__init__).parameters.items() if name in KNN_OPTIONS}
def check_knn_options(knn_params) -> dict:
    """KNNMap's defaults updated by `knn_params`, checked (see :func:`map_scans`)."""
    if not isinstance(knn_params, Mapping):
        raise TypeError(f"knn_params must be a mapping of KNNMap parameters, "
                        f"got {type(knn_params).__name__}")
    unknown = sorted(set(knn_params) - set(KNN_OPTIONS) - set(KNNMap._deprecated_params),
                     key=str)
    if unknown:
        raise ValueError(f"knn_params holds {unknown}, which KNNMap does not take; it takes "
                         f"{list(KNN_OPTIONS)}")
    params = {**KNN_DEFAULTS, **check_renamed(KNNMap._deprecated_params, dict(knn_params),
                                              owner="knn_params", stacklevel=4)}
    cdf = params.pop("cdf")
    if not isinstance(cdf, str) or cdf not in CDFS:
        raise ValueError(f"cdf must be one of {CDFS}, got {cdf!r}")
    return {**check_knn_params(params), "cdf": cdf}

class OptionError(ValueError):
    """A ValueError about one argument of :func:`map_scans` (its name in `param`);
    ``occgp map`` reports it as a usage error of the matching option (exit code 2)."""

    def __init__(self, param: str, message: str) -> None:
        super().__init__(message)
        self.param = param


class OptionTypeError(TypeError):
    """The TypeError of :class:`OptionError`: a value of the wrong type for one argument."""

    def __init__(self, param: str, message: str) -> None:
        super().__init__(message)
        self.param = param


def option_error(param: str, exc: Exception) -> Exception:
    """`exc` (a ValueError or TypeError) as the option error of `param`, same kind."""
    return (OptionTypeError if isinstance(exc, TypeError) else OptionError)(param, str(exc))


#: The map parameters map_scans sets from its own arguments (the options of ``occgp
#: map``): `params` may not name them (one place for each value).
OWN_PARAMS = {"resolution": "--resolution", "n_jobs": "--n-jobs", "max_range": "--max-range"}


# the option of each map_scans argument an OptionError can name
OPTION_OF = {"output": "-o/--output", "method": "--method", "mode": "--mode",
              "resolution": "--resolution", "max_range": "--max-range", "n_jobs": "--n-jobs",
              "poses": "--poses", "poses_format": "--poses-format", "topic": "--topic",
              "fixed_frame": "--fixed-frame", "sensor_frame": "--sensor-frame",
              "project_2d": "--project-2d", "scan_filter": "scan filter options",
              "tf_tolerance": "--tf-tolerance", "input_map": "--input-map",
              "fields": "--fields", "paths": "scans", "params": "--param"}
POSE_FORMATS = ("kitti", "tum")


def option_name(name: str) -> str:
    """The command-line option of a KNNMap parameter: ``p_m_out`` → ``--p-m-out``,
    ``max_range`` → ``--max-range`` (the deprecated ``--sensor-range`` and ``--p-t``
    are read as ``--max-range`` and ``--occupancy-threshold``)."""
    return "--" + name.replace("_", "-")


def knn_error(parser: argparse.ArgumentParser, exc: Exception) -> None:
    """parser.error for a rejected k-NN option, naming the options the message names."""
    message = str(exc)
    named = sorted({m.start(): m.group(1) for m in re.finditer(
        r"(?<![\w-])(" + "|".join(sorted(KNN_OPTIONS, key=len, reverse=True)) + r")(?![\w-])",
        message)}.items())
    options = "/".join(dict.fromkeys(option_name(name) for _, name in named)) or "k-NN options"
    parser.error(f"argument {options}: {message}")


def parse_param(text: str) -> tuple[str, Any]:
    """--param NAME=VALUE: (name, the value as a Python literal, else the text)."""
    name, sep, value = text.partition("=")
    if not sep or not name.strip().isidentifier():
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE, got {text[:60]!r}")
    try:
        return name.strip(), ast.literal_eval(value.strip())
    except (ValueError, SyntaxError, TypeError, MemoryError, RecursionError):
        return name.strip(), value.strip()


_FIELD_NAMES = ("kitti", "nuscenes")


def parse_fields(text: str):
    """--fields: an int (float32 values per record), "kitti" / "nuscenes", or a record
    layout ``name:dtype,...`` (e.g. ``x:<f8,y:<f8,z:<f8,t:<u4``)."""
    text = text.strip()
    if text.isdigit():
        return int(text)
    if text in _FIELD_NAMES:
        return text
    try:
        items = [item.split(":") for item in text.split(",")]
        if not all(len(item) == 2 and item[0] for item in items):
            raise ValueError
        return np.dtype([(name.strip(), np.dtype(kind.strip())) for name, kind in items])
    except (TypeError, ValueError):
        raise argparse.ArgumentTypeError(
            f"expected an int (float32 values per record), kitti, nuscenes or name:dtype,... "
            f"(e.g. x:<f4,y:<f4,z:<f4,t:<u4), got {text[:60]!r}") from None
