"""The file format of occgp.gp's models (``"occgp.gp_model"`` ``.npz`` archives).

:meth:`GPOMIK.save <occgp.gp.GPOMIK.save>` describes the format; every model
writes its parameters the same way and adds its own fitted arrays. This module
reads and checks what the models share, and GPOMIK's local models.
"""

from __future__ import annotations

import inspect
import os

import numpy as np

from ..io import _npz as _npz_io
from .._validation import check_real
from ._cells import Cell
from ._checks import check_at_least
from ._integral_kernel import check_kernel
from ._kernels import Matern32, SparseKernel, SquaredExponential
from ._observations import Observations
from ._quadrature import ClenshawCurtis, Rule, Simpson

__all__ = ["GP_FORMAT", "GP_VERSIONS", "GP_CLASSES", "gp_params", "gp_fitted", "write_gp",
           "read_gp", "check_gp_fitted", "fitted_scalars", "set_fitted_scalars", "gpomik_cells"]

#: Format of the GP models' files (see GPOMIK.save, GPOM.save).
GP_FORMAT = "occgp.gp_model"
GP_VERSIONS = (1,)
#: The objects a GP model's parameters may hold, rebuilt from their get_params().
GP_CLASSES = {c.__name__: c for c in (SquaredExponential, Matern32, SparseKernel,
                                      ClenshawCurtis, Simpson)}
#: Parameters added after the first files were written: a file without them gets
#: the constructor's default.
ADDED_PARAMS = frozenset({"occupancy_threshold", "hit_tolerance", "objective", "min_size"})


def gp_params(model, classes=None, params=None) -> dict:
    """JSON-ready constructor parameters of `model` (TypeError if one cannot be saved).

    `classes` (name -> class) extends :data:`GP_CLASSES`; `params` replaces
    ``model.get_params(deep=False)``.
    """
    try:
        return _npz_io.encode_value(model.get_params(deep=False) if params is None else params,
                                    {**GP_CLASSES, **(classes or {})})
    except TypeError as exc:
        raise TypeError(f"cannot save this {type(model).__name__}: a parameter holds an "
                        f"unsupported value: {exc}") from None


def gp_fitted(value: dict) -> np.ndarray:
    """The ``fitted`` entry: `value` as a 0-d str array of JSON."""
    return np.array(_npz_io.json_text(_npz_io.encode_value(value, GP_CLASSES)))


def write_gp(model, path, arrays: dict, params: dict | None = None):
    """Write `model`'s file at `path`: its `params` (default :func:`gp_params`) and `arrays`.

    Returns `model` (``save`` returns it).
    """
    params = gp_params(model) if params is None else params
    _npz_io.write_npz(path, GP_FORMAT, GP_VERSIONS[-1], type(model).__name__, params, arrays)
    return model


def read_gp(cls, path, spec, classes=None, optional=()):
    """(source, unfitted model of the saved parameters, arrays, fitted dict or None).

    `classes` (name -> class) extends :data:`GP_CLASSES` for the parameters;
    the arrays of `spec` named in `optional` may be absent from a fitted model.
    """
    source = os.fspath(_npz_io.as_path(path))
    spec = {"fitted": (np.str_, ()), **spec}
    _, _, raw, arrays = _npz_io.read_npz(source, GP_FORMAT, GP_VERSIONS, (cls.__name__,),
                                         spec, tuple(spec))
    name = cls.__name__
    params = _npz_io.decode_value(raw, source, {**GP_CLASSES, **(classes or {})})
    expected = [p for p in inspect.signature(cls.__init__).parameters if p != "self"]
    if not isinstance(params, dict) or set(params) - set(expected) \
            or set(expected) - set(params) - ADDED_PARAMS:
        got = sorted(params)[:20] if isinstance(params, dict) else params
        raise ValueError(f"{source}: the parameters of a {name} must be {sorted(expected)}, "
                         f"got {got}")
    try:
        model = cls(**params)
        model._check_params()
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{source}: bad parameters of a {name}: {exc}") from None
    needed = [k for k in spec if k not in optional]
    present = [k for k in needed if k in arrays]
    if present and len(present) != len(needed):
        raise ValueError(f"{source}: a fitted {name} needs all of {needed}, got only "
                         f"{present}")
    fitted = None
    if present:
        text = str(arrays.pop("fitted")[()])
        fitted = _npz_io.decode_value(_npz_io.parse_json(text, "'fitted' entry", source),
                                      source, GP_CLASSES, "'fitted' entry")
        if not isinstance(fitted, dict):
            raise ValueError(f"{source}: corrupt 'fitted' entry: expected a JSON object")
        _npz_io.check_finite(arrays, list(arrays), source)
    return source, model, arrays, fitted


def check_gp_fitted(fitted: dict, keys, n_dims: int, source: str, name: str) -> dict:
    """The fitted scalars shared by the GP models, checked; ValueError naming `source`."""
    if sorted(fitted) != sorted(keys):
        raise ValueError(f"{source}: the fitted state of a {name} must hold {sorted(keys)}, "
                         f"got {sorted(fitted)[:20]}")
    try:
        kernel = check_kernel(fitted["kernel_"])
        kernel._checked()
        kernel.inverse_length_scales(n_dims)
        check_real(fitted["noise_"], "noise_", low=0.0)
        plsc = fitted["plsc_"]
        if not (isinstance(plsc, tuple) and len(plsc) == 2):
            raise ValueError(f"plsc_ must be a pair (a, b), got {plsc!r:.80}")
        for v in plsc:
            check_real(v, "plsc_")
        lml = fitted["log_marginal_likelihood_value_"]
        if lml is not None:
            check_real(lml, "log_marginal_likelihood_value_")
        dims = fitted["n_dims_"]
        if isinstance(dims, bool) or dims != n_dims:
            raise ValueError(f"n_dims_ must be {n_dims} (the arrays' width), got {dims!r:.40}")
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{source}: corrupt fitted state of a {name}: {exc}") from None
    fitted = dict(fitted)
    fitted["log_marginal_likelihood_value_"] = np.nan if lml is None else float(lml)
    return fitted


def fitted_scalars(model) -> dict:
    """The fitted scalars of :func:`check_gp_fitted` (GPOM's, GPOMIK's) of `model`, JSON-ready."""
    lml = float(model.log_marginal_likelihood_value_)
    return {"kernel_": model.kernel_, "noise_": float(model.noise_),
            "plsc_": tuple(float(v) for v in model.plsc_),
            "log_marginal_likelihood_value_": lml if np.isfinite(lml) else None,
            "n_dims_": int(model.n_dims_)}


def set_fitted_scalars(model, fitted: dict) -> None:
    """Give `model` the scalars of :func:`fitted_scalars` from a checked `fitted` entry."""
    model.kernel_, model.noise_ = fitted["kernel_"], float(fitted["noise_"])
    model.plsc_ = tuple(float(v) for v in fitted["plsc_"])
    model.log_marginal_likelihood_value_ = fitted["log_marginal_likelihood_value_"]
    model.n_dims_ = int(fitted["n_dims_"])


def gpomik_cells(arrays: dict, fitted: dict, source: str) -> list:
    """The local models of a GPOMIK file, after checking them against `fitted`.

    Raises ValueError naming `source` if the arrays or the fitted scalars
    (already checked by :func:`check_gp_fitted`) are not a valid GPOMIK.
    """
    n_obs, n_dims = arrays["starts"].shape
    bad = ""
    sizes = arrays["cell_sizes"]
    try:
        quadrature = fitted["quadrature_"]
        if not isinstance(quadrature, Rule):
            raise TypeError(f"quadrature_ must be a ClenshawCurtis or Simpson, got "
                            f"{quadrature!r:.80}")
        quadrature._checked()
        check_real(fitted["jitter_"], "jitter_", low=0.0, low_open=False)
        for key in ("n_accepted_", "n_rejected_"):
            check_at_least(fitted[key], key, 0)
    except (TypeError, ValueError) as exc:
        bad = str(exc)
    labels, y, lengths = arrays["labels"], arrays["y"], arrays["lengths"]
    hit = labels == 1
    if bad:
        pass
    elif not 1 <= n_dims <= 3:
        bad = f"the observations must have 1 to 3 dimensions, got {n_dims}"
    elif len(sizes) == 0 or (sizes < 1).any() or int(sizes.sum()) != n_obs:
        bad = f"'cell_sizes' must be positive and sum to {n_obs}"
    elif fitted["n_accepted_"] != n_obs:
        bad = f"n_accepted_ must be {n_obs} (the observations), got {fitted['n_accepted_']}"
    elif sum(int(n) * (int(n) + 1) // 2 for n in sizes) != len(arrays["L"]):
        bad = "'L' must hold the lower triangles of the cells' factors"
    elif not (hit | (labels == -1)).all():
        bad = "'labels' must be +1 (hit) or -1 (beam)"
    elif not (np.array_equal(y[hit], np.ones(hit.sum())) and
              np.array_equal(arrays["starts"][hit], arrays["ends"][hit]) and
              not lengths[hit].any()):
        bad = "the hits must be points with target 1 and length 0"
    elif not (np.array_equal(y[~hit], np.where(lengths[~hit] > 0, -lengths[~hit], -1.0))
              and (lengths >= 0).all()):
        bad = "the beams' targets must be minus their lengths (-1 for zero length)"
    if bad:
        raise ValueError(f"{source}: corrupt fitted state of a GPOMIK: {bad}")
    cells, start, pos = [], 0, 0
    for n, fortran in zip(sizes.tolist(), arrays["L_fortran"].tolist()):
        L = np.zeros((n, n), order="F" if fortran else "C")
        L[np.tril_indices(n)] = arrays["L"][pos:pos + n * (n + 1) // 2]
        if not (np.diag(L) > 0).all():
            raise ValueError(f"{source}: corrupt fitted state of a GPOMIK: the Cholesky "
                             f"factor of local model {len(cells)} has a diagonal entry "
                             f"<= 0")
        obs = Observations(*(arrays[f][start:start + n].copy()
                             for f in Observations._fields))
        cells.append(Cell(obs, L, arrays["alpha"][start:start + n].copy()))
        start, pos = start + n, pos + n * (n + 1) // 2
    return cells
