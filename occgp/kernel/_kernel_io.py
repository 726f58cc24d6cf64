"""The kernel maps' files and pickles.

Files are NumPy ``.npz`` archives of plain arrays in the ``occgp.kernel_map``
format (described in :meth:`KernelMapFiles.save`), written and checked by
:mod:`occgp.io._npz`; files written before ``occupancy_threshold`` existed lack
that parameter and read with its default; files written before ``far_beams``
existed read with ``far_beams="drop"`` where they set ``max_range`` (the rule
their maps were built with; the default, "cut", otherwise); parameters renamed
since a file was written (AKIMap's ``sensor_range``, now ``schedule_range``)
read under their new names. Pickles of earlier versions read the same way.
Pickles rebuild a map from its
parameters and cells through :func:`restore_kernel_map`.
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING, Any

import numpy as np

from ..io import _npz as _npz_io
from .._docfill import fill_doc
from .._validation import as_path

#: The format's name and the versions this code reads (it writes the last).
FORMAT = "occgp.kernel_map"
VERSIONS = (1,)
CELL_SPEC = {"keys": (np.uint16, ("n_cells", 3)), "alpha": (np.float32, ("n_cells",)),
             "beta": (np.float32, ("n_cells",))}


@fill_doc()
class KernelMapFiles:
    """Save, load and pickle for the kernel maps (mixed into their base class).

    A class provides ``get_params()``, ``_validated_params()`` (raising on a bad
    parameter), the compiled ``_cells_arrays()`` and ``_set_cells()``, and may
    extend ``_EXTRA_SPEC`` / ``_EXTRA_OPTIONAL`` (its further file entries),
    ``_io_params``, ``_io_arrays``, ``_io_extra`` and ``_extra_state``.
    """

    if TYPE_CHECKING:  # provided by the class this is mixed into
        def get_params(self, deep: bool = True) -> dict: ...
        @classmethod
        def _get_param_names(cls) -> list[str]: ...
        def _validated_params(self, params: dict | None = None) -> Any: ...
        def _cells_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...
        def _set_cells(self, keys: np.ndarray, alpha: np.ndarray,
                       beta: np.ndarray) -> None: ...

    _EXTRA_SPEC: dict = {}
    _EXTRA_OPTIONAL: tuple = ()
    #: Constructor parameters added after version 1 of the format: a file may lack them.
    _PARAMS_ADDED: tuple = ("occupancy_threshold", "far_beams")

    def _io_params(self) -> dict:
        return self.get_params()

    def _io_arrays(self) -> dict:
        return {}

    @classmethod
    def _io_extra(cls, params: dict, arrays: dict, source: str) -> dict:
        """Attributes to set on the loaded map (beyond its cells), from `arrays`;
        may rewrite `params` in place."""
        return {}

    def _extra_state(self) -> dict:
        return {}

    def save(self, path: str | os.PathLike):
        """Write the map, its parameters and all its evidence to an ``.npz`` file.

        :meth:`load` reads it back into a map that predicts, and goes on
        updating, exactly as this one.

        {save_parameters}

        {map_returns}

        Raises
        ------
        TypeError
            If `path` is not a str or path-like, or a parameter changed after
            construction has the wrong type.
        ValueError
            If a parameter changed after construction is out of range; nothing
            is written.
        OSError
            If the file cannot be written.

        Notes
        -----
        The file is a NumPy ``.npz`` archive (``numpy.savez_compressed``) of
        plain arrays, no pickled objects. Its entries:

        ``format``, ``version``, ``class``
            0-d arrays: ``"occgp.kernel_map"``, 1, and ``"BGKMap"`` or
            ``"AKIMap"``.
        ``params``
            0-d str: the constructor's parameters (:meth:`get_params`) as a
            JSON object; for an AKIMap made with a ``numpy.random.Generator``
            as `random_state`, that entry is ``"Generator"``.
        ``keys``
            uint16 (n_cells, 3): the key of every cell any kernel reached,
            ``floor(x / resolution) + 32768`` per axis, ordered by z, y, x.
        ``alpha``, ``beta``
            float32 (n_cells,): each cell's occupied and free evidence, the
            prior not included (the compiled cells keep float32).
        ``rng`` (AKIMap)
            0-d str: the state of the random generator of the free samples
            (``bit_generator.state``, arrays as lists) as JSON.
        ``bw_precision``, ``bw_extent``, ``bw_weight``, ``bw_scale``, ``bw_n_same`` (AKIMap)
            float64 (m, 3, 3), (m, 3), (m,), (m,) and int64 (m,): the fields
            of ``last_bandwidths_``; absent while it is None.
        """
        self._validated_params()
        keys, alpha, beta = self._cells_arrays()
        order = np.lexsort(keys.T)
        arrays = {"keys": keys[order], "alpha": alpha[order].astype(np.float32),
                  "beta": beta[order].astype(np.float32), **self._io_arrays()}
        _npz_io.write_npz(path, FORMAT, VERSIONS[-1], type(self).__name__,
                          _npz_io.encode_value(self._io_params()), arrays)
        return self

    @classmethod
    def load(cls, path: str | os.PathLike):
        """Read a map written by :meth:`save` (the format is described there).

        The file is read with ``numpy.load(..., allow_pickle=False)``; every
        entry's dtype, shape and size is checked before its data is read.

        {load_parameters}

        Returns
        -------
        map
            A map with the saved parameters, cells and (AKIMap) random stream
            and ``last_bandwidths_``.

        {load_raises}
            Also if the parameters are not those of the class or out of range;
            if the evidence holds NaN, inf or negative values, or a cell key
            twice.
        """
        name = cls.__name__
        source, _, params, arrays = read_kernel_file(cls, path)
        params = older_params(cls, params)
        expected = cls._get_param_names()
        missing = set(expected) - set(params)
        if set(params) - set(expected) or missing - set(cls._PARAMS_ADDED):
            raise ValueError(f"{source}: the parameters of a {name} must be "
                             f"{sorted(expected)}, got {sorted(params)[:20]}")
        extra = cls._io_extra(params, arrays, source)
        _npz_io.check_finite(arrays, ("alpha", "beta"), source, nonnegative=True)
        keys = arrays["keys"]
        packed = (keys[:, 0].astype(np.uint64) | keys[:, 1].astype(np.uint64) << 16 |
                  keys[:, 2].astype(np.uint64) << 32)
        if len(np.unique(packed)) != len(packed):
            raise ValueError(f"{source}: array 'keys' holds a cell more than once")
        try:
            m = cls(**params)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{source}: bad parameters of a {name}: {exc}") from None
        m._set_cells(keys, arrays["alpha"].astype(np.float64),
                     arrays["beta"].astype(np.float64))
        for attr, value in extra.items():
            setattr(m, attr, value)
        return m

    def __reduce__(self):
        keys, alpha, beta = self._cells_arrays()
        return restore_kernel_map, (type(self), self.get_params(), keys, alpha, beta,
                                    self._extra_state())


def restore_kernel_map(cls, params, keys, alpha, beta, extra=None):
    """The kernel map a pickle holds: `cls` built from `params`, with these cells.

    ``occgp.kernel._restore`` names it in the pickles of earlier versions.
    """
    if not (isinstance(cls, type) and issubclass(cls, KernelMapFiles)) or \
            not isinstance(params, dict) or not (extra is None or isinstance(extra, dict)):
        raise ValueError("corrupt pickle of a kernel map: expected a kernel map class, "
                         "its parameters (a dict) and its cells")
    keys = np.asarray(keys)
    alpha = np.asarray(alpha)
    beta = np.asarray(beta)
    n = len(keys) if keys.ndim == 2 else -1
    if keys.dtype != np.uint16 or keys.shape != (n, 3) or alpha.shape != (n,) or \
            beta.shape != (n,) or alpha.dtype.kind != "f" or beta.dtype.kind != "f":
        raise ValueError(f"corrupt pickle of a {cls.__name__}: expected cell keys uint16 "
                         f"(n, 3) and float alpha, beta (n,), got {keys.dtype} "
                         f"{keys.shape}, {alpha.dtype} {alpha.shape}, {beta.dtype} "
                         f"{beta.shape}")
    if not (np.isfinite(alpha).all() and np.isfinite(beta).all()):
        raise ValueError(f"corrupt pickle of a {cls.__name__}: alpha and beta must be finite")
    m = cls(**older_params(cls, params))
    m._set_cells(np.ascontiguousarray(keys), np.ascontiguousarray(alpha, dtype=np.float64),
                 np.ascontiguousarray(beta, dtype=np.float64))
    for name, value in (extra or {}).items():
        setattr(m, name, value)
    return m


def renamed_params(cls, params: dict) -> dict:
    """`params` of a file or pickle of `cls` with the parameters renamed since it was
    written (``_deprecated_params``) under their new names, without a warning: the
    files and pickles of earlier versions stay readable."""
    renames = getattr(cls, "_deprecated_params", {})
    return {renames.get(name, name): value for name, value in params.items()}


def older_params(cls, params: dict) -> dict:
    """`params` of a file or pickle of `cls`, read as written: renamed parameters under
    their new names (:func:`renamed_params`), and ``far_beams="drop"`` where one written
    before ``far_beams`` existed sets ``max_range`` (those maps dropped the beams beyond
    it whole)."""
    params = renamed_params(cls, params)
    if "far_beams" not in params and params.get("max_range") is not None:
        params["far_beams"] = "drop"
    return params


def read_kernel_file(cls, path):
    """(path, format version, params, arrays) of a kernel map file of class `cls`."""
    path = os.fspath(as_path(path))
    spec = {**CELL_SPEC, **cls._EXTRA_SPEC}
    _, version, params, arrays = _npz_io.read_npz(
        path, FORMAT, VERSIONS, (cls.__name__,), spec, cls._EXTRA_OPTIONAL)
    return path, version, params, arrays
