"""Dense occupancy from sparse scans by Bayesian kernel inference on cells.

:class:`AKIMap` (Kwon et al.) gives every sample its own anisotropic kernel,
shaped by the covariance of its same-label neighbours and scaled against the
others; :class:`BGKMap` is its isotropic baseline, Doherty et al.'s Bayesian
generalized kernel inference ("BGKOctoMap"). In both every cell keeps a Beta
posterior whose parameters collect the kernel-weighted labels of nearby
samples; the bandwidths and the accumulation are compiled (``ext/_kernel.pyx``).
"""

from __future__ import annotations

import inspect
import os
from numbers import Integral
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._kernel import _akimap_bandwidths, _KernelCells
from ._kernel import sparse_kernel as _sparse_kernel
from ._kernel_samples import (  # noqa: F401 (MAX_FREE_SAMPLES: the documented limit)
    _MAX_VAL, MAX_CELLS_PER_UPDATE, MAX_FREE_SAMPLES, MAX_WEIGHT, _beam_chunks,
    _candidate_pairs, _check_free_count, _check_max_cells, _cube_sums, _merge_cube_sums,
    _packed_keys, _search_cell, _support_cells, voxel_first,
)
from . import _npz_io
from .maps import register
from .octree import OccupancyOctree
from ._validation import as_point, as_points, check_n_jobs, check_real, n_threads

__all__ = ["AKIMap", "BGKMap", "KernelCells", "Bandwidths", "sparse_kernel",
           "voxel_centroids"]


class KernelCells(NamedTuple):
    """The cells of a kernel map, as arrays (one row per cell)."""

    #: Cell centres, shape (n_cells, 3), in metres.
    centers: NDArray[np.float64]
    #: Occupied evidence alpha (prior included), shape (n_cells,).
    alpha: NDArray[np.float64]
    #: Free evidence beta (prior included), shape (n_cells,).
    beta: NDArray[np.float64]


#: Most free samples one update draws along its beams before down-sampling; they are
#: made and reduced in chunks of _FREE_CHUNK, so memory stays bounded.
def sparse_kernel(r: ArrayLike) -> NDArray[np.float64]:
    """The sparse kernel ``((2 + cos 2 pi r)(1 - r)) / 3 + sin(2 pi r) / (2 pi)`` for
    ``|r| < 1``, 0 beyond (Melkumyan and Ramos, 2009), element-wise; NaN where `r`
    is NaN.

    Parameters
    ----------
    r : array-like of real numbers, any shape
        Normalised distances.

    Returns
    -------
    ndarray of the shape of `r`

    Raises
    ------
    TypeError
        If `r` does not hold real numbers.
    """
    arr = np.asarray(r)
    if arr.dtype.kind not in "biuf":
        raise TypeError(f"r must hold real numbers, got dtype {arr.dtype}")
    flat = np.ascontiguousarray(arr, dtype=np.float64).ravel()
    out = _sparse_kernel(flat)
    out[np.isnan(flat)] = np.nan
    return out.reshape(arr.shape)


def voxel_centroids(points: ArrayLike, size: float) -> NDArray[np.float64]:
    """The centroid of the points in each cube of edge `size` that holds any (PCL's
    ``VoxelGrid``), ordered by cube.

    Raises
    ------
    TypeError, ValueError
        If `points` is not a finite array of shape (n_points, 3), `size` not a
        positive real, or the points span more than 2^21 cubes on an axis.
    """
    points = as_points(points, "points")
    size = check_real(size, "size", low=0.0)
    if len(points) == 0:
        return np.empty((0, 3))
    _, sums, counts = _cube_sums(points, size)
    return sums / counts[:, None]


class Bandwidths(NamedTuple):
    """Per-sample kernels of an :class:`AKIMap` update (see :meth:`AKIMap.bandwidths`)."""

    #: Inverse bandwidth matrices H^-1, shape (n_samples, 3, 3).
    precision: NDArray[np.float64]
    #: Half-size of each support's bounding box per axis, shape (n_samples, 3), metres.
    extent: NDArray[np.float64]
    #: Kernel weights |H|^-1/2, shape (n_samples,).
    weight: NDArray[np.float64]
    #: Length-scale factor c of H = c^2 Sigma (1 for the isotropic fallback).
    scale: NDArray[np.float64]
    #: Same-label samples in each search ball, the sample itself included.
    n_same: NDArray[np.int64]


class _KernelMap(_KernelCells):
    """What the kernel maps share: cells, Beta posteriors and queries."""

    def _init_cells(self, resolution: float, prior: float) -> None:
        self._resolution = check_real(resolution, "resolution", low=0.0)
        self.prior = check_real(prior, "prior", low=0.0)
        self._setup(self._resolution)

    @property
    def resolution(self) -> float:
        """Edge length of the cells, in metres (fixed when the map is made)."""
        return self._resolution

    def _check_params(self) -> None:
        """Check the parameters (also when changed after construction) and store them
        as plain floats / ints; raises before anything changes."""
        self.prior = check_real(self.prior, "prior", low=0.0)
        self.n_jobs = check_n_jobs(self.n_jobs)
        self.max_cells_per_update = _check_max_cells(self.max_cells_per_update)

    _SUPPORT_HINT = ""

    def _check_cells(self, samples, extent, weights, sf2) -> None:
        """Refuse an update whose kernels would visit more than max_cells_per_update
        cells, or whose weights would overflow the float32 cells, before anything
        changes."""
        top = float(np.max(weights)) * sf2
        bottom = float(np.min(weights)) * sf2
        if not top <= MAX_WEIGHT:
            raise ValueError(
                f"the kernel weights of this update reach {top:.3g} (sf2 times the weight "
                f"|H|^-1/2, which scales as resolution^-3 for AKIMap), more than "
                f"{MAX_WEIGHT:g}: the cells' float32 evidence would overflow; use a "
                f"smaller sf2 or a coarser resolution; the map is unchanged")
        if not bottom >= 1.0 / MAX_WEIGHT:
            raise ValueError(
                f"the kernel weights of this update fall to {bottom:.3g} (sf2 times the "
                f"weight |H|^-1/2, which scales as resolution^-3 for AKIMap), under "
                f"{1.0 / MAX_WEIGHT:g}: the cells' float32 evidence would underflow; use "
                f"a larger sf2 or a finer resolution; the map is unchanged")
        total = _support_cells(samples, extent, self.resolution)
        if total > self.max_cells_per_update:
            raise ValueError(
                f"this update would visit {total:.3g} cells (the support boxes of its "
                f"{len(samples)} samples at resolution {self.resolution:g} m), more than "
                f"max_cells_per_update={self.max_cells_per_update}; raise "
                f"max_cells_per_update, or use a coarser resolution or "
                f"{self._SUPPORT_HINT}; the map is unchanged")

    def _rng_state(self):
        return None

    def _set_rng_state(self, state) -> None:
        pass

    def _keep(self, extra) -> None:
        """Keep what an accepted update's kernels leave (AKIMap: its bandwidths)."""

    def _accepted(self) -> None:
        """Called once an update is accepted (also one that added no sample)."""

    def _validated_scan(self, points: ArrayLike, origin: ArrayLike):
        pts = as_points(points, "points")
        org = as_point(origin, "origin")
        limit = _MAX_VAL * self.resolution
        for name, arr in (("points", pts), ("origin", org[None])):
            bad = ~np.all((arr >= -limit) & (arr < limit), axis=1)
            if bad.any():
                raise ValueError(
                    f"{int(bad.sum())} of {len(arr)} {name} lie outside the map's key range "
                    f"[{-limit:g}, {limit:g}) m at resolution {self.resolution:g} "
                    f"(first: row {int(np.flatnonzero(bad)[0])}); the map is unchanged")
        return pts, org

    n_jobs: int | None
    max_cells_per_update: int

    def _training_data(self, pts, org):
        """(samples (n, 3), labels (n,)) of a validated scan."""
        raise NotImplementedError

    def _kernels(self, samples, labels, org):
        """(precision (n, 3, 3), extent (n, 3), weights (n,), sf2, extra) of the
        samples; `extra` goes to :meth:`_keep` once the update is accepted."""
        raise NotImplementedError

    def _checked_training_data(self, points, origin):
        self._check_params()
        pts, org = self._validated_scan(points, origin)
        state = self._rng_state()
        try:
            return (*self._training_data(pts, org), org, state)
        except BaseException:
            self._set_rng_state(state)
            raise

    def update(self, points: ArrayLike, origin: ArrayLike):
        """Add one scan's evidence; return self.

        Parameters
        ----------
        points : array-like of shape (n_points, 3)
            End points of the beams in the world frame, in metres. An empty scan
            changes nothing.
        origin : array-like of shape (3,)
            Sensor position, in metres.

        Returns
        -------
        self
            The updated map.

        Raises
        ------
        TypeError
            If `points` or `origin` does not hold real numbers, or a parameter
            changed after construction has the wrong type.
        ValueError
            If their shapes are wrong, they hold NaN or inf, or lie outside the
            key range (``[-32768 resolution, 32768 resolution)`` per axis); if
            the scan would make more than ``MAX_FREE_SAMPLES`` (2^26) free
            samples before down-sampling; if the samples' kernels would visit
            more than `max_cells_per_update` cells (or, for AKIMap, its
            bandwidths examine more sample pairs); or if a parameter changed
            after construction is out of range. The map (and AKIMap's random
            stream) is then unchanged.
        """
        samples, labels, org, state = self._checked_training_data(points, origin)
        if not len(samples):
            self._accepted()
            return self
        try:
            precision, extent, weights, sf2, extra = self._kernels(samples, labels, org)
            self._check_cells(samples, extent, weights, sf2)
        except BaseException:
            self._set_rng_state(state)
            raise
        self._keep(extra)
        self._accumulate(np.ascontiguousarray(samples), labels, precision, extent,
                         weights, sf2, n_threads(self.n_jobs))
        self._accepted()
        return self

    # evaluation harness protocol: maps take scans through insert_scan
    def insert_scan(self, points: ArrayLike, origin: ArrayLike):
        """Alias of :meth:`update`, for :mod:`occgp.evaluation`.

        Parameters
        ----------
        points : array-like of shape (n_points, 3)
            End points of the beams in the world frame, in metres.
        origin : array-like of shape (3,)
            Sensor position, in metres.

        Returns
        -------
        self
            The updated map.

        Raises
        ------
        TypeError, ValueError
            As :meth:`update`; the map is then unchanged.
        """
        return self.update(points, origin)

    # ------------------------------------------------------------------ queries
    def occupancy(self, points: ArrayLike) -> NDArray[np.float64]:
        """Posterior mean of occupancy, alpha / (alpha + beta), at each point's cell.

        Parameters
        ----------
        points : array-like of shape (n_points, 3)
            Query points, in metres.

        Returns
        -------
        p : ndarray of shape (n_points,)
            The posterior mean (`prior` added to alpha and beta); NaN where no
            sample's kernel ever reached the cell (unknown), or the point lies
            outside the key range.

        Raises
        ------
        TypeError
            If `points` does not hold real numbers.
        ValueError
            If `points` is not of shape (n_points, 3) or holds NaN or inf.
        """
        pts = as_points(points, "points")
        return self._query(pts, check_real(self.prior, "prior", low=0.0), 0)

    def variance(self, points: ArrayLike) -> NDArray[np.float64]:
        """Posterior variance of occupancy, ab / ((a + b)^2 (a + b + 1)), at each point's cell.

        ``a`` and ``b`` are the cell's alpha and beta with `prior` added (the
        variance of the Beta posterior).

        Parameters
        ----------
        points : array-like of shape (n_points, 3)
            Query points, in metres.

        Returns
        -------
        var : ndarray of shape (n_points,)
            The posterior variance; NaN where unknown (as :meth:`occupancy`).

        Raises
        ------
        TypeError, ValueError
            As :meth:`occupancy`.
        """
        pts = as_points(points, "points")
        return self._query(pts, check_real(self.prior, "prior", low=0.0), 1)

    def is_occupied(self, points: ArrayLike, threshold: float = 0.5) -> NDArray[np.bool_]:
        """Whether each point's cell has occupancy above `threshold`.

        Parameters
        ----------
        points : array-like of shape (n_points, 3)
            Query points, in metres.
        threshold : float, default=0.5
            Probability in [0, 1]; a cell is occupied when its posterior mean
            (:meth:`occupancy`) is strictly above it.

        Returns
        -------
        occupied : ndarray of bool, shape (n_points,)
            False where unknown.

        Raises
        ------
        TypeError
            If `points` does not hold real numbers or `threshold` is not a real
            number.
        ValueError
            If `points` is malformed (as :meth:`occupancy`) or `threshold` is
            outside [0, 1].
        """
        threshold = check_real(threshold, "threshold", low=0.0, high=1.0)
        p = self.occupancy(points)
        return np.where(np.isnan(p), False, p > threshold)

    def cells(self) -> KernelCells:
        """Every cell any kernel reached, ordered by key (z, then y, then x).

        Returns
        -------
        cells : KernelCells
            Named tuple ``(centers, alpha, beta)``: the cells' centres, shape
            (n_cells, 3), and their evidence with `prior` added, shape (n_cells,).
        """
        keys, alpha, beta = self._cells_arrays()
        order = np.lexsort(keys.T)
        keys, alpha, beta = keys[order], alpha[order], beta[order]
        centers = (keys.astype(np.float64) - _MAX_VAL + 0.5) * self.resolution
        prior = check_real(self.prior, "prior", low=0.0)
        return KernelCells(centers, alpha + prior, beta + prior)

    @property
    def num_cells(self) -> int:
        """Number of cells any kernel reached."""
        return int(self._num_cells())

    @property
    def memory_bytes(self) -> int:
        """Bytes the cells take: blocks of 4 x 4 x 4 cells (float32 alpha and beta and
        a mask of the reached cells, 520 bytes) and their hash index."""
        return int(self._memory_bytes())

    def to_octree(self, *, clamping_min: float = 0.001,
                  clamping_max: float = 0.999) -> OccupancyOctree:
        """The map as an :class:`~occgp.OccupancyOctree` of the same resolution.

        Each cell's posterior mean becomes its log-odds (float32, clamped to
        the bounds given), and the tree is pruned, so that ``.bt`` / ``.ot``
        export and OctoMap's viewers work. Cells no kernel reached stay
        unknown.

        Parameters
        ----------
        clamping_min, clamping_max : float, default=0.001 and 0.999
            The octree's clamping bounds, probabilities in (0, 0.5) and (0.5, 1),
            as :class:`~occgp.OccupancyOctree`'s.

        Returns
        -------
        tree : OccupancyOctree
            With the default sensor model otherwise.

        Raises
        ------
        TypeError, ValueError
            If the clamping bounds are rejected by :class:`~occgp.OccupancyOctree`.
        """
        tree = OccupancyOctree(self.resolution, clamping_min=clamping_min,
                               clamping_max=clamping_max)
        keys, alpha, beta = self._cells_arrays()
        if len(keys):
            prior = check_real(self.prior, "prior", low=0.0)
            p = (alpha + prior) / (alpha + beta + 2 * prior)
            log_odds = np.log(p) - np.log1p(-p)
            tree._set_values(np.ascontiguousarray(keys), log_odds.astype(np.float32))
        return tree

    def _extra_state(self) -> dict:
        return {}

    # ------------------------------------------------------------------ files
    _FORMAT = "occgp.kernel_map"
    _VERSIONS = (1,)
    _CELL_SPEC = {"keys": (np.uint16, ("n_cells", 3)), "alpha": (np.float32, ("n_cells",)),
                  "beta": (np.float32, ("n_cells",))}
    _EXTRA_SPEC: dict = {}
    _EXTRA_OPTIONAL: tuple = ()

    def get_params(self) -> dict:
        """The constructor's parameters.

        Returns
        -------
        params : dict
            Parameter name to value, as passed to the constructor (``cls(**params)``
            builds an empty map of the same kind).
        """
        raise NotImplementedError

    def _io_params(self) -> dict:
        return self.get_params()

    def _io_arrays(self) -> dict:
        return {}

    @classmethod
    def _io_extra(cls, params: dict, arrays: dict, source: str) -> dict:
        """Attributes to set on the loaded map (beyond its cells), from `arrays`;
        may rewrite `params` in place."""
        return {}

    def save(self, path: str | os.PathLike) -> "_KernelMap":
        """Write the map, its parameters and all its evidence to an ``.npz`` file.

        The file is a NumPy ``.npz`` archive (``numpy.savez_compressed``) of
        plain arrays, no pickled objects, written at `path` exactly (no
        suffix is added); :meth:`load` reads it back into a map that
        predicts, and goes on updating, exactly as this one. Its entries:

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

        Parameters
        ----------
        path : str or path-like
            Destination file (overwritten).

        Returns
        -------
        self
            The map.

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
        """
        self._check_params()
        keys, alpha, beta = self._cells_arrays()
        order = np.lexsort(keys.T)
        arrays = {"keys": keys[order], "alpha": alpha[order].astype(np.float32),
                  "beta": beta[order].astype(np.float32), **self._io_arrays()}
        _npz_io.write_npz(path, self._FORMAT, self._VERSIONS[-1], type(self).__name__,
                          _npz_io.encode_value(self._io_params()), arrays)
        return self

    @classmethod
    def load(cls, path: str | os.PathLike):
        """Read a map written by :meth:`save` (the format is described there).

        The file is read with ``numpy.load(..., allow_pickle=False)``; every
        entry's dtype, shape and size is checked before its data is read.

        Parameters
        ----------
        path : str or path-like
            A file written by ``save`` of this class.

        Returns
        -------
        map
            A map with the saved parameters, cells and (AKIMap) random stream
            and ``last_bandwidths_``.

        Raises
        ------
        TypeError
            If `path` is not a str or path-like.
        OSError
            If the file does not exist, is not a regular file or cannot be read.
        ValueError
            If it is not an ``.npz`` archive, is truncated or corrupt, is of
            another format, format version or class, lacks an entry or has an
            unexpected one, or an entry has the wrong dtype or shape; if the
            parameters are not those of the class or out of range; if the
            evidence holds NaN, inf or negative values, or a cell key twice.
        """
        name = cls.__name__
        source, _, params, arrays = _read_kernel_file(cls, path)
        expected = [p for p in inspect.signature(cls.__init__).parameters if p != "self"]
        if sorted(params) != sorted(expected):
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
        return _restore, (type(self), self.get_params(), keys, alpha, beta,
                          self._extra_state())


def _restore(cls, params, keys, alpha, beta, extra=None):
    if not (isinstance(cls, type) and issubclass(cls, _KernelMap)) or \
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
    m = cls(**params)
    m._set_cells(np.ascontiguousarray(keys), np.ascontiguousarray(alpha, dtype=np.float64),
                 np.ascontiguousarray(beta, dtype=np.float64))
    for name, value in (extra or {}).items():
        setattr(m, name, value)
    return m


def _read_kernel_file(cls, path):
    path = os.fspath(_npz_io.as_path(path))
    spec = {**_KernelMap._CELL_SPEC, **cls._EXTRA_SPEC}
    cls_name, version, params, arrays = _npz_io.read_npz(
        path, cls._FORMAT, cls._VERSIONS, (cls.__name__,), spec, cls._EXTRA_OPTIONAL)
    return path, version, params, arrays


@register("bgk", formats=(".npz",), description="Bayesian generalised kernel inference on cells (isotropic)")
class BGKMap(_KernelMap):
    """Occupancy by Bayesian generalized kernel inference (Doherty et al., "BGKOctoMap").

    Each scan becomes training samples: its end points within `max_range`
    (occupied, label 1) and points every `free_resolution` metres along each
    beam, one more at ``length - free_resolution`` on every beam longer than
    `free_resolution`, and the sensor origin (free, label 0; la3dm's
    ``beam_sample``), both reduced to one centroid per cube of edge
    `ds_resolution`. Every cell whose centre lies within `ell` of a
    sample gets ``k(r) y`` added to alpha and ``k(r) (1 - y)`` to beta, with
    ``r = distance / ell`` and k the sparse kernel times `sf2`. The occupancy of
    a cell is the posterior mean ``alpha / (alpha + beta)`` with `prior` added to
    both; this is la3dm's BGKOctoMap on a hashed grid of cells.

    Parameters
    ----------
    resolution : float, default=0.1
        Edge length of the cells, in metres.
    ell : float, default=0.2
        Kernel length scale (support radius), in metres.
    sf2 : float, default=1.0
        Kernel signal variance (scale of the kernel).
    free_resolution : float, default=0.5
        Spacing of the free samples along each beam, in metres (plus one sample
        this far before each end point).
    ds_resolution : float, default=None
        Edge of the cubes that reduce the samples to centroids; None means
        `resolution`.
    prior : float, default=0.001
        Prior alpha and beta of every cell.
    max_range : float, default=8.0
        Beams longer than this are dropped whole (la3dm's rule); None keeps all.
    n_jobs : int, default=None
        Threads for the accumulation: None means 1, -1 every core, never more
        than the cores. The map is the same for any number.
    max_cells_per_update : int, default=2**30
        Most cells one update's kernels may visit (the support boxes of its
        samples, about ``(2 ell / resolution + 1)^3`` cells each), a few
        seconds of work on one thread; an update that would visit more raises
        a ValueError and changes nothing.

    Notes
    -----
    Limits of one update, each a ValueError that leaves the map unchanged:
    points and origin within the key range ``[-32768, 32768) * resolution``
    per axis; at most ``MAX_FREE_SAMPLES`` (2^26) free samples before
    down-sampling; at most `max_cells_per_update` cells visited; ``sf2``
    within ``[1e-30, 1e30]`` (the cells keep float32 evidence); the scan at
    most 2^21 cubes of `ds_resolution` across; ``ell`` at least 1e-150 m.

    Attributes
    ----------
    num_cells : int
        Number of cells any kernel reached.
    last_beams_ : tuple of (int, int)
        ``(kept, dropped)`` of the last accepted :meth:`update`: its beams
        (end points reduced to one centroid per cube of `ds_resolution`)
        within `max_range`, and those beyond it, dropped whole. ``(0, 0)``
        before any update; not saved by :meth:`save` or pickled (a loaded map
        starts at ``(0, 0)``).

    See Also
    --------
    OccupancyOctree : Log-odds mapping of the same scans.

    References
    ----------
    .. [1] K. Doherty, J. Wang, B. Englot, "Bayesian generalized kernel inference
       for occupancy map prediction", ICRA 2017; la3dm's BGKOctoMap.

    Examples
    --------
    >>> import numpy as np
    >>> from occgp import BGKMap
    >>> wall = np.column_stack([np.full(21, 2.0), np.linspace(-1, 1, 21), np.zeros(21)])
    >>> m = BGKMap(0.1).update(wall, origin=[0.0, 0.0, 0.0])
    >>> bool(m.occupancy([[2.0, 0.0, 0.0]])[0] > 0.5), bool(m.occupancy([[1.0, 0, 0]])[0] < 0.5)
    (True, True)
    """

    def __init__(
        self,
        resolution: float = 0.1,
        *,
        ell: float = 0.2,
        sf2: float = 1.0,
        free_resolution: float = 0.5,
        ds_resolution: float | None = None,
        prior: float = 0.001,
        max_range: float | None = 8.0,
        n_jobs: int | None = None,
        max_cells_per_update: int = MAX_CELLS_PER_UPDATE,
    ) -> None:
        self._init_cells(resolution, prior)
        self.n_jobs = n_jobs
        self.ell = ell
        self.sf2 = sf2
        self.free_resolution = free_resolution
        self.ds_resolution = ds_resolution
        self.max_range = max_range
        self.max_cells_per_update = max_cells_per_update
        self._check_params()
        self.last_beams_ = (0, 0)
        self._beams = (0, 0)

    _SUPPORT_HINT = "a smaller ell"

    def _accepted(self) -> None:
        self.last_beams_ = self._beams

    def _check_params(self) -> None:
        super()._check_params()
        self.ell = check_real(self.ell, "ell", low=0.0)
        if self.ell < 1e-150:
            raise ValueError(f"ell must be at least 1e-150 m (its inverse square must be "
                             f"finite), got {self.ell!r}")
        self.sf2 = check_real(self.sf2, "sf2", low=0.0)
        self.free_resolution = check_real(self.free_resolution, "free_resolution", low=0.0)
        self.ds_resolution = (None if self.ds_resolution is None else
                              check_real(self.ds_resolution, "ds_resolution", low=0.0))
        self.max_range = (None if self.max_range is None else
                          check_real(self.max_range, "max_range", low=0.0))

    def get_params(self) -> dict:
        """The constructor's parameters.

        Returns
        -------
        params : dict
            Parameter name to value, as passed to the constructor (``cls(**params)``
            builds an empty map of the same kind).
        """
        return dict(resolution=self.resolution, ell=self.ell, sf2=self.sf2,
                    free_resolution=self.free_resolution, ds_resolution=self.ds_resolution,
                    prior=self.prior, max_range=self.max_range, n_jobs=self.n_jobs,
                    max_cells_per_update=self.max_cells_per_update)

    def __repr__(self) -> str:
        return f"BGKMap(resolution={self.resolution!r}, ell={self.ell!r}, " \
               f"num_cells={self.num_cells})"

    def training_data(self, points: ArrayLike,
                      origin: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The samples and labels (1 occupied, 0 free) that :meth:`update` uses.

        Nothing in the map changes.

        Parameters
        ----------
        points : array-like of shape (n_points, 3)
            End points of the beams in the world frame, in metres.
        origin : array-like of shape (3,)
            Sensor position, in metres.

        Returns
        -------
        samples : ndarray of shape (n_samples, 3)
        labels : ndarray of shape (n_samples,)

        Raises
        ------
        TypeError, ValueError
            As :meth:`update`.
        """
        samples, labels, _, _ = self._checked_training_data(points, origin)
        return samples, labels

    def _training_data(self, pts, org):
        ds = self.resolution if self.ds_resolution is None else self.ds_resolution
        self._beams = (0, 0)
        if len(pts) == 0:
            return np.empty((0, 3)), np.empty(0)
        _, sums, counts = _cube_sums(pts, ds, "ds_resolution")
        hits = sums / counts[:, None]
        n_beams = len(hits)
        if self.max_range is not None:
            hits = hits[np.linalg.norm(hits - org, axis=1) <= self.max_range]
        self._beams = (len(hits), n_beams - len(hits))
        if len(hits) == 0:
            return np.empty((0, 3)), np.empty(0)
        # free samples every free_resolution metres along each beam (d < length), one
        # more at length - free_resolution on every beam longer than free_resolution,
        # and the origin once per beam (so it weighs in its cube's centroid), as la3dm's
        # beam_sample and get_training_data
        length = np.linalg.norm(hits - org, axis=1)
        fr = self.free_resolution
        with np.errstate(over="ignore"):
            n_step_f = np.maximum(np.ceil(length / fr) - 1, 0)
        n_free_f = n_step_f + (length > fr)
        _check_free_count(n_free_f.sum(), "free_resolution", fr)
        n_step, n_free = n_step_f.astype(np.int64), n_free_f.astype(np.int64)
        unit = (hits - org) / np.where(length > 0, length, 1.0)[:, None]
        # centroids per cube of ds, the free samples made and reduced chunk by chunk
        low = np.minimum(hits.min(axis=0), org) - ds
        parts = []
        for beam, j in _beam_chunks(n_free):
            dist = (j + 1) * fr
            last = j >= n_step[beam]                # the sample at length - fr
            dist[last] = length[beam[last]] - fr
            parts.append(_cube_sums(org + unit[beam] * dist[:, None], ds, "ds_resolution",
                                    low))
        parts.append((_packed_keys(org[None], ds, "ds_resolution", low),
                      org[None] * len(hits), np.array([len(hits)])))
        _, sums, counts = _merge_cube_sums(parts)
        frees = sums / counts[:, None]
        samples = np.vstack([hits, frees])
        labels = np.concatenate([np.ones(len(hits)), np.zeros(len(frees))])
        return samples, labels

    def _kernels(self, samples, labels, org):
        n = len(samples)
        precision = np.broadcast_to(np.eye(3) / self.ell ** 2, (n, 3, 3)).copy()
        return precision, np.full((n, 3), self.ell), np.ones(n), self.sf2, None


@register("akimap", formats=(".npz",), description="Adaptive anisotropic kernel inference on cells", random_state=0)
class AKIMap(_KernelMap):
    """Occupancy by adaptive anisotropic kernel inference (Kwon et al., AKIMap).

    Each scan becomes samples: its end points (occupied, label 1; the first
    point in each cell of edge `resolution`), the sensor origin (always, as
    the reference code) and one uniformly random point in each
    `free_sample_distance` interval of every beam (free, label 0; intervals
    start half a distance from the origin, cells already holding a sample are
    skipped). Each sample gets its own
    bandwidth matrix H:

    * the same-label samples within ``r(d) = min((R - resolution) / sensor_range
      * d + resolution, R)`` of it (d its distance to the origin,
      ``R = max_search_range``) give the scatter about it, ``Sigma = S / (n - 2)
      + 0.001 I`` (n counts the sample itself); with ``n <= 2`` the kernel is
      isotropic, ``H = resolution^2 I``;
    * the length-scale factor c in ``[resolution / sqrt(lambda_max(Sigma)), 1]``
      minimises Eq. 3.7, ``|c^2 Sigma|^-1/2 / 2 * sum_j (t_j - k(r_j / c))^2``
      over the neighbours j inside the support of Sigma, with targets ``t_j =
      k(r_j)`` for same-label neighbours and 0 for the others (c = 1 when none
      of the others is inside); ``H = c^2 Sigma + f^2 I``, f the bandwidth
      floor.

    Every cell whose centre lies inside a sample's support gets
    ``|H|^-1/2 k(r) y`` added to alpha and ``|H|^-1/2 k(r) (1 - y)`` to beta
    (Eq. 3.8-3.9), ``r^2 = (c_m - x)^T H^-1 (c_m - x)``; occupancy is
    ``alpha / (alpha + beta)`` with `prior` added to both.

    Parameters
    ----------
    resolution : float, default=0.1
        Edge length of the cells, in metres; also the isotropic fallback's
        bandwidth and the down-sampling cell of the samples.
    free_sample_distance : float, default=0.5
        One random free sample per this many metres of each beam.
    max_search_range : float, default=None
        R, the largest neighbour search radius, in metres; None means
        `free_sample_distance` (as the reference code).
    sensor_range : float, default=8.0
        Distance at which the search radius reaches R, in metres.
    variant : {"occgp", "published"}, default="occgp"
        How the scale is chosen: "occgp" minimises Eq. 3.7 on a grid of 16
        log-spaced scales refined by golden-section search; "published" runs
        the reference code's gradient descent from c = 1 (step 0.01 / epoch,
        100 epochs, tolerance 0.001, the code's gradient as published).
    bandwidth_floor : float, default=None
        f, in metres: ``f^2 I`` is added to every bandwidth after its scale is
        chosen, so no kernel is thinner than about f. A covariance of samples
        on a surface is nearly flat, and its kernel then falls between cell
        centres; the floor gives such kernels the thickness of a few cells.
        None means ``3 * resolution`` for ``variant="occgp"`` (AUC 0.938 ->
        0.980 on the la3dm structured scene at 0.05 m) and 0 (none, as
        published) for ``variant="published"``.
    prior : float, default=0.001
        Prior alpha and beta of every cell.
    random_state : int, numpy.random.Generator or None, default=None
        Seed of the free samples; an int makes every run draw the same ones.
    n_jobs : int, default=None
        Threads for the bandwidths and the accumulation: None means 1, -1
        every core, never more than the cores. The map is the same for any
        number.
    max_cells_per_update : int, default=2**30
        Most cells one update's kernels may visit (the support boxes of its
        samples), and most (sample, candidate neighbour) pairs its bandwidths
        may examine (the samples in the search cubes around each sample);
        a few seconds of work on one thread each. An update that would exceed
        either raises a ValueError and changes nothing.

    Notes
    -----
    Limits of one update, each a ValueError that leaves the map (and its
    random stream) unchanged: points and origin within the key range
    ``[-32768, 32768) * resolution`` per axis; at most ``MAX_FREE_SAMPLES``
    (2^26) free samples; at most `max_cells_per_update` cells visited and
    sample pairs examined; kernel weights ``|H|^-1/2`` within
    ``[1e-30, 1e30]`` (the cells keep float32 evidence: with the default
    floor, resolutions from about 1e-10 m to 1e10 m).

    Attributes
    ----------
    num_cells : int
        Number of cells any kernel reached.
    last_bandwidths_ : Bandwidths
        The kernels of the last update's samples.

    See Also
    --------
    BGKMap : The isotropic baseline.

    References
    ----------
    .. [1] Y. Kwon, B. Moon, S.-E. Yoon, "Adaptive kernel inference for dense and
       sharp occupancy grids", IROS 2020; Y. Kwon, dissertation (KAIST), ch. 3.

    Examples
    --------
    >>> import numpy as np
    >>> from occgp import AKIMap
    >>> y, z = np.meshgrid(np.linspace(-1, 1, 21), np.linspace(-0.5, 0.5, 11))
    >>> wall = np.column_stack([np.full(y.size, 2.0), y.ravel(), z.ravel()])
    >>> m = AKIMap(0.1, random_state=0).update(wall, origin=[0.0, 0.0, 0.0])
    >>> bool(m.occupancy([[2.0, 0.0, 0.0]])[0] > 0.5), bool(m.occupancy([[1.0, 0, 0]])[0] < 0.5)
    (True, True)
    """

    VARIANTS = ("occgp", "published")

    def __init__(
        self,
        resolution: float = 0.1,
        *,
        free_sample_distance: float = 0.5,
        max_search_range: float | None = None,
        sensor_range: float = 8.0,
        variant: str = "occgp",
        bandwidth_floor: float | None = None,
        prior: float = 0.001,
        random_state: int | np.random.Generator | None = None,
        n_jobs: int | None = None,
        max_cells_per_update: int = MAX_CELLS_PER_UPDATE,
    ) -> None:
        self._init_cells(resolution, prior)
        self.free_sample_distance = free_sample_distance
        self.max_search_range = max_search_range
        self.sensor_range = sensor_range
        self.variant = variant
        self.bandwidth_floor = bandwidth_floor
        self.n_jobs = n_jobs
        self.max_cells_per_update = max_cells_per_update
        self._check_params()
        if not (random_state is None or isinstance(random_state, np.random.Generator)
                or (isinstance(random_state, Integral) and not isinstance(random_state, bool))):
            raise TypeError(f"random_state must be None, a non-negative int or a "
                            f"numpy.random.Generator, got {random_state!r}")
        if isinstance(random_state, Integral) and random_state < 0:
            raise ValueError(f"random_state must be None, a non-negative int or a "
                             f"numpy.random.Generator, got {random_state!r}")
        self.random_state = random_state
        self._rng = np.random.default_rng(random_state)
        self.last_bandwidths_: Bandwidths | None = None

    _SUPPORT_HINT = "a smaller bandwidth_floor or max_search_range"

    def _check_params(self) -> None:
        super()._check_params()
        self.free_sample_distance = check_real(self.free_sample_distance,
                                               "free_sample_distance", low=0.0)
        self.max_search_range = (None if self.max_search_range is None else
                                 check_real(self.max_search_range, "max_search_range",
                                            low=0.0))
        self.sensor_range = check_real(self.sensor_range, "sensor_range", low=0.0)
        if not isinstance(self.variant, str) or self.variant not in self.VARIANTS:
            raise ValueError(f"variant must be one of {self.VARIANTS}, got {self.variant!r}")
        self.bandwidth_floor = (None if self.bandwidth_floor is None else
                                check_real(self.bandwidth_floor, "bandwidth_floor",
                                           low=0.0, low_open=False))

    def _rng_state(self):
        return self._rng.bit_generator.state

    def _set_rng_state(self, state) -> None:
        self._rng.bit_generator.state = state

    def _keep(self, extra) -> None:
        self.last_bandwidths_ = extra

    def get_params(self) -> dict:
        """The constructor's parameters.

        Returns
        -------
        params : dict
            Parameter name to value, as passed to the constructor (``cls(**params)``
            builds an empty map of the same kind).
        """
        return dict(resolution=self.resolution,
                    free_sample_distance=self.free_sample_distance,
                    max_search_range=self.max_search_range, sensor_range=self.sensor_range,
                    variant=self.variant, bandwidth_floor=self.bandwidth_floor,
                    prior=self.prior, random_state=self.random_state,
                    n_jobs=self.n_jobs, max_cells_per_update=self.max_cells_per_update)

    def __repr__(self) -> str:
        return (f"AKIMap(resolution={self.resolution!r}, variant={self.variant!r}, "
                f"num_cells={self.num_cells})")

    def _extra_state(self) -> dict:
        # the generator where it stands, so a restored map draws what this one would
        return {"_rng": self._rng, "last_bandwidths_": self.last_bandwidths_}

    _BW_FIELDS = ("precision", "extent", "weight", "scale", "n_same")
    _EXTRA_SPEC = {"rng": (np.str_, ()),
                   "bw_precision": (np.float64, ("n_bw", 3, 3)),
                   "bw_extent": (np.float64, ("n_bw", 3)),
                   "bw_weight": (np.float64, ("n_bw",)),
                   "bw_scale": (np.float64, ("n_bw",)),
                   "bw_n_same": (np.int64, ("n_bw",))}
    _EXTRA_OPTIONAL = tuple("bw_" + f for f in _BW_FIELDS)

    def _io_params(self) -> dict:
        params = self.get_params()
        rs = params["random_state"]
        params["random_state"] = ("Generator" if isinstance(rs, np.random.Generator)
                                  else None if rs is None else int(rs))
        return params

    def _io_arrays(self) -> dict:
        state = _npz_io.encode_rng_state(self._rng.bit_generator.state)
        out = {"rng": np.array(_npz_io.json_text(state))}
        if self.last_bandwidths_ is not None:
            for f in self._BW_FIELDS:
                out["bw_" + f] = np.asarray(getattr(self.last_bandwidths_, f))
        return out

    @classmethod
    def _io_extra(cls, params: dict, arrays: dict, source: str) -> dict:
        state = _npz_io.parse_json(str(arrays["rng"][()]), "'rng' entry", source)
        rng = _npz_io.decode_rng(state, source)
        extra: dict = {"_rng": rng, "last_bandwidths_": None}
        if params.get("random_state") == "Generator":
            params["random_state"] = None
            extra["random_state"] = rng
        present = [k for k in cls._EXTRA_OPTIONAL if k in arrays]
        if present and len(present) != len(cls._EXTRA_OPTIONAL):
            raise ValueError(f"{source}: the last bandwidths need all of "
                             f"{list(cls._EXTRA_OPTIONAL)}, got only {present}")
        if present:
            _npz_io.check_finite(arrays, present, source)
            if (arrays["bw_n_same"] < 1).any():
                raise ValueError(f"{source}: array 'bw_n_same' holds counts under 1")
            extra["last_bandwidths_"] = Bandwidths(*(arrays["bw_" + f]
                                                     for f in cls._BW_FIELDS))
        return extra

    @property
    def floor_(self) -> float:
        """The bandwidth floor in use, in metres (see `bandwidth_floor`)."""
        if self.bandwidth_floor is not None:
            return self.bandwidth_floor
        return 3.0 * self.resolution if self.variant == "occgp" else 0.0

    @property
    def _search_range(self) -> float:
        return (self.free_sample_distance if self.max_search_range is None
                else self.max_search_range)

    def training_data(self, points: ArrayLike,
                      origin: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The samples and labels (1 occupied, 0 free) an update would use, drawn from
        the map's random generator (so this advances it).

        Parameters
        ----------
        points : array-like of shape (n_points, 3)
            End points of the beams in the world frame, in metres.
        origin : array-like of shape (3,)
            Sensor position, in metres.

        Returns
        -------
        samples : ndarray of shape (n_samples, 3)
        labels : ndarray of shape (n_samples,)

        Raises
        ------
        TypeError, ValueError
            As :meth:`update` (the generator is then not advanced).
        """
        samples, labels, _, _ = self._checked_training_data(points, origin)
        return samples, labels

    def _training_data(self, pts, org):
        res, step = self.resolution, self.free_sample_distance
        if len(pts) == 0:
            return np.empty((0, 3)), np.empty(0)
        hits = pts[voxel_first(pts, res)]
        length = np.linalg.norm(hits - org, axis=1)
        # one random point in each interval [step/2 + j step, step/2 + (j+1) step)
        # that starts before the end point, kept when it falls before it
        with np.errstate(over="ignore"):
            n_free_f = np.maximum(np.ceil((length - 0.5 * step) / step), 0)
        _check_free_count(n_free_f.sum(), "free_sample_distance", step)
        n_free = n_free_f.astype(np.int64)
        unit = (hits - org) / np.where(length > 0, length, 1.0)[:, None]
        # the origin is always a free sample (the reference code's first one, even in
        # the cell of an end point); a cell already holding a sample (end points, the
        # origin, then the free samples in order) takes no further free one. The free
        # samples are drawn chunk by chunk (the same stream as at once).
        low = np.minimum(hits.min(axis=0), org) - res
        taken = np.unique(_packed_keys(np.vstack([hits, org[None]]), res, "resolution", low))
        kept = [org[None]]
        for beam, j in _beam_chunks(n_free):
            dist = step * (0.5 + j + self._rng.random(len(beam)))
            keep = dist < length[beam]
            beam, dist = beam[keep], dist[keep]
            frees = org + unit[beam] * dist[:, None]
            keys = _packed_keys(frees, res, "resolution", low)
            _, first = np.unique(keys, return_index=True)
            first = np.sort(first[~np.isin(keys[first], taken, assume_unique=True)])
            kept.append(frees[first])
            taken = np.union1d(taken, keys[first])
        frees = np.vstack(kept)
        samples = np.vstack([frees, hits])
        labels = np.concatenate([np.zeros(len(frees)), np.ones(len(hits))])
        return samples, labels

    def bandwidths(self, samples: ArrayLike, labels: ArrayLike,
                   origin: ArrayLike) -> Bandwidths:
        """The kernel of each sample, as an update computes them.

        Parameters
        ----------
        samples : array-like of shape (n_samples, 3)
        labels : array-like of shape (n_samples,)
            1 (occupied) or 0 (free).
        origin : array-like of shape (3,)
            Sensor position (the search radius grows with the distance to it).

        Returns
        -------
        Bandwidths
            Precision, support extents, weights, scales and neighbour counts.

        Raises
        ------
        TypeError
            If `samples`, `labels` or `origin` does not hold real numbers.
        ValueError
            If their shapes are wrong, they hold NaN or inf, a label is not 0
            or 1, or the search would examine more than
            `max_cells_per_update` sample pairs.
        """
        self._check_params()
        xs = as_points(samples, "samples")
        org = as_point(origin, "origin")
        lab = np.asarray(labels)
        if lab.shape != (len(xs),):
            raise ValueError(f"labels must have shape ({len(xs)},), got {lab.shape}")
        if lab.dtype.kind not in "biuf":
            raise TypeError(f"labels must hold 0 or 1, got dtype {lab.dtype}")
        if not np.isin(lab, (0, 1)).all():
            raise ValueError("labels must be 0 (free) or 1 (occupied)")
        return self._bandwidths(xs, lab, org)

    def _bandwidths(self, xs, lab, org) -> Bandwidths:
        radius = self._search_range
        cell = _search_cell(xs, radius)
        pairs = _candidate_pairs(xs, cell)
        if pairs > self.max_cells_per_update:
            raise ValueError(
                f"the bandwidths of these {len(xs)} samples would examine {pairs:.3g} "
                f"sample pairs (those in the cubes of edge max_search_range="
                f"{radius:g} m around each), more than max_cells_per_update="
                f"{self.max_cells_per_update}; use a smaller max_search_range or raise "
                f"max_cells_per_update; the map is unchanged")
        out = _akimap_bandwidths(np.ascontiguousarray(xs, dtype=np.float64),
                                 np.ascontiguousarray(lab, dtype=np.uint8), org,
                                 self.resolution, radius, self.sensor_range,
                                 self.variant == "published", self.floor_,
                                 n_threads(self.n_jobs), cell)
        return Bandwidths(*out)

    def _kernels(self, samples, labels, org):
        bw = self._bandwidths(samples, labels, org)
        return bw.precision, bw.extent, bw.weight, 1.0, bw
