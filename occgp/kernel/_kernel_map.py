"""What the kernel maps share: parameters, scan checks, updates, queries and cells.

Every cell keeps a Beta posterior whose parameters collect the kernel-weighted
labels of nearby samples; a map class says how a scan becomes samples
(``_training_data``) and what kernel each sample gets (``_kernels``), and
:class:`KernelMapBase` does the rest: the checks that leave the map unchanged
on bad input, the compiled accumulation, the queries and the protocol of
:class:`occgp.maps.OccupancyMap`.
"""

from __future__ import annotations

import warnings
from numbers import Integral, Real
from types import SimpleNamespace
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._docfill import fill_doc
from .._kernel import _KernelCells
from .._params import Check, Interval, Options, ParamsMixin
from .._validation import (as_point, as_points, check_bool, check_choice, check_n_jobs,
                           check_probability, check_real, n_threads)
from ..octree._tree import OccupancyOctree
from .._scan_input import prefilter
from ._kernel_io import KernelMapFiles
from ._kernel_samples import (FAR_BEAMS, MAX_VAL, MAX_WEIGHT, check_max_cells,
                              check_max_range, support_cells)
from ._kernel_utils import KernelCells

#: The Parameters section of the queries (see :func:`occgp._docs.fill_doc`).
_QUERY_POINTS = """\
Parameters
----------
points : array-like of shape (n_points, 3)
    Query points, in metres."""


@fill_doc(query_points=_QUERY_POINTS)
class KernelMapBase(ParamsMixin, KernelMapFiles, _KernelCells):
    """What the kernel maps share: cells, Beta posteriors, parameters and queries.

    A subclass's ``__init__`` stores its arguments as attributes of the same
    names (``resolution`` as ``_resolution``: it is read-only) and calls
    :meth:`_build`; it extends :meth:`_check_values` and provides
    ``_training_data(p, pts, org)`` and ``_kernels(p, samples, labels, org)``.
    """

    _SUPPORT_HINT = ""
    n_jobs: int | None
    max_range: float | None
    far_beams: str
    max_cells_per_update: int
    prior: float
    occupancy_threshold: float

    #: What each parameter may be (see :mod:`occgp._params`); a subclass extends it.
    _parameter_constraints: ClassVar[dict[str, list]] = {
        "resolution": [Interval(Real, 0, None, closed="neither")],
        "prior": [Interval(Real, 0, None, closed="neither")],
        "n_jobs": [Check(check_n_jobs, "None or a non-zero int")],
        "max_cells_per_update": [Interval(Integral, 1, None)],
        "occupancy_threshold": [Interval(Real, 0, 1, closed="neither")],
        "max_range": [None, Interval(Real, 0, None, closed="neither")],
        "far_beams": [Options(FAR_BEAMS)],
    }

    # ------------------------------------------------------------ parameters
    def _build(self) -> None:
        """Check the stored parameters and set up the (empty) cells."""
        p = self._validated_params()
        self._setup(p.resolution)
        self._cell_edge = p.resolution

    @property
    def resolution(self) -> float:
        """Edge length of the cells, in metres (fixed once the map holds cells)."""
        return self._resolution

    def _check_values(self, params: dict) -> dict:
        """The values of `params` (every parameter, by name) checked and made plain
        floats / ints; raises TypeError / ValueError naming the first bad one."""
        return dict(
            resolution=check_real(params["resolution"], "resolution", low=0.0),
            prior=check_real(params["prior"], "prior", low=0.0),
            n_jobs=check_n_jobs(params["n_jobs"]),
            max_cells_per_update=check_max_cells(params["max_cells_per_update"]),
            occupancy_threshold=check_probability(params["occupancy_threshold"],
                                                  "occupancy_threshold"),
            max_range=check_max_range(params["max_range"]),
            far_beams=check_choice(params["far_beams"], "far_beams", FAR_BEAMS))

    def _validated_params(self, params: dict | None = None) -> SimpleNamespace:
        """The checked parameters (the map's own by default) as attributes."""
        return SimpleNamespace(**self._check_values(self.get_params(deep=False)
                                                    if params is None else params))

    def _check_params_together(self, params: dict) -> dict:
        """Every parameter checked (:meth:`_check_values`); `resolution` changes only
        while the map holds no cell."""
        checked = self._check_values(params)
        if checked["resolution"] != self._cell_edge and self.num_cells:
            raise ValueError(f"resolution cannot change while the map holds cells (it is "
                             f"{self.resolution!r}, got {params['resolution']!r}); the map "
                             f"is unchanged")
        return checked

    def set_params(self, **params: Any):
        """Change parameters (scikit-learn's convention).

        Every parameter is checked as the constructor checks it before any
        changes; new values apply to later updates and queries, the cells keep
        their evidence. ``resolution`` can change only while the map holds no
        cell.

        Parameters
        ----------
        **params
            Constructor parameters, by name.

        {map_returns}

        Raises
        ------
        TypeError
            If a value has the wrong type.
        ValueError
            If a name is not a parameter of the map, a value is out of range,
            or `resolution` changes while the map holds cells. The map is then
            unchanged.

        Examples
        --------
        >>> from occgp import BGKMap
        >>> m = BGKMap(0.1).set_params(ell=0.3, occupancy_threshold=0.7)
        >>> m.get_params()["ell"], m.occupancy_threshold
        (0.3, 0.7)
        """
        return super().set_params(**params)

    def _set_checked_params(self, params: dict, checked: dict) -> None:
        """Store `params`, as given (all of them checked, as `checked`)."""
        for name, value in params.items():
            if name == "resolution":
                self._resolution = value
                if checked["resolution"] != self._cell_edge:
                    self._setup(checked["resolution"])
                    self._cell_edge = checked["resolution"]
            else:
                setattr(self, name, value)

    # ------------------------------------------------------------ updates
    def _check_cells(self, p, samples, extent, weights, sf2) -> None:
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
        total = support_cells(samples, extent, p.resolution)
        if total > p.max_cells_per_update:
            raise ValueError(
                f"this update would visit {total:.3g} cells (the support boxes of its "
                f"{len(samples)} samples at resolution {p.resolution:g} m), more than "
                f"max_cells_per_update={p.max_cells_per_update}; raise "
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
        limit = MAX_VAL * self._cell_edge
        for name, arr in (("points", pts), ("origin", org[None])):
            bad = ~np.all((arr >= -limit) & (arr < limit), axis=1)
            if bad.any():
                raise ValueError(
                    f"{int(bad.sum())} of {len(arr)} {name} lie outside the map's key range "
                    f"[{-limit:g}, {limit:g}) m at resolution {self._cell_edge:g} "
                    f"(first: row {int(np.flatnonzero(bad)[0])}); the map is unchanged")
        return pts, org

    def _training_data(self, p, pts, org):
        """(samples (n, 3), labels (n,)) of a validated scan, with parameters `p`."""
        raise NotImplementedError

    def _kernels(self, p, samples, labels, org):
        """(precision (n, 3, 3), extent (n, 3), weights (n,), sf2, extra) of the
        samples; `extra` goes to :meth:`_keep` once the update is accepted."""
        raise NotImplementedError

    def _checked_training_data(self, points, origin):
        """(checked parameters, samples, labels, origin, random state before)."""
        p = self._validated_params()
        pts, org = self._validated_scan(points, origin)
        state = self._rng_state()
        try:
            return (p, *self._training_data(p, pts, org), org, state)
        except BaseException:
            self._set_rng_state(state)
            raise

    def update(self, points: ArrayLike, origin: ArrayLike):
        """Add one scan's evidence; return self.

        An empty scan changes nothing.

        {scan_parameters}

        {updated_map_returns}

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
        p, samples, labels, org, state = self._checked_training_data(points, origin)
        if not len(samples):
            self._accepted()
            return self
        try:
            precision, extent, weights, sf2, extra = self._kernels(p, samples, labels, org)
            self._check_cells(p, samples, extent, weights, sf2)
        except BaseException:
            self._set_rng_state(state)
            raise
        self._keep(extra)
        self._accumulate(np.ascontiguousarray(samples), labels, precision, extent,
                         weights, sf2, n_threads(p.n_jobs))
        self._accepted()
        return self

    def insert_scan(self, points: ArrayLike, origin: ArrayLike, *,
                    min_range: float | None = None, **options: Any):
        """Add one scan's evidence (:class:`occgp.maps.OccupancyMap`'s call); return self.

        The same as :meth:`update`, after dropping the points nearer to
        `origin` than `min_range`.

        {scan_parameters}
        min_range : float, default=None
            Points nearer to `origin` than this are dropped first: the map is
            the one :meth:`update` gives with the pre-filtered scan (distances
            in double precision, a point at exactly `min_range` kept; None: no
            filter). Must be finite and >= 0 (and less than the map's
            `max_range` when that is set).
        **options
            None: the kernel maps take no other per-scan option.

        {updated_map_returns}

        Raises
        ------
        TypeError
            If another option is given; as :meth:`update`.
        ValueError
            If `min_range` is invalid; as :meth:`update`. The map is then
            unchanged.
        """
        if options:
            raise TypeError(f"{type(self).__name__}.insert_scan takes no options, got "
                            f"{next(iter(options))!r} (only min_range)")
        if min_range is not None:
            points, _, _ = prefilter(points, origin, min_range, self.max_range)
        return self.update(points, origin)

    # ------------------------------------------------------------ queries
    def occupancy(self, points: ArrayLike) -> NDArray[np.float64]:
        """Posterior mean of occupancy, alpha / (alpha + beta), at each point's cell.

        {query_points}

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

        {query_points}

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

    def is_occupied(self, points: ArrayLike, threshold: float | None = None, *,
                    return_unknown: bool = False):
        """Whether each point's cell is occupied: its occupancy at least `occupancy_threshold`.

        Cells no kernel reached are unknown, reported as not occupied; ask for
        `return_unknown` to tell them apart from free ones.

        {query_points}
        threshold : float, default=None
            Deprecated: set the map's `occupancy_threshold` instead. A
            probability in (0, 1); when given, a cell is occupied when its
            occupancy is strictly above it (the former rule), with a
            DeprecationWarning.
        return_unknown : bool, default=False
            Also return the mask of points in unknown cells.

        Returns
        -------
        occupied : ndarray of bool, shape (n_points,)
            False where unknown.
        unknown : ndarray of bool, shape (n_points,)
            Only when `return_unknown` is True: where :meth:`occupancy` is NaN.

        Raises
        ------
        TypeError
            If `points` does not hold real numbers, `return_unknown` is not a
            bool, or `threshold` / `occupancy_threshold` is not a real number.
        ValueError
            If `points` is malformed (as :meth:`occupancy`), `threshold` or
            `occupancy_threshold` is outside (0, 1).

        Examples
        --------
        >>> from occgp import BGKMap
        >>> m = BGKMap(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0])
        >>> occ, unk = m.is_occupied([[1.0, 0, 0], [0.5, 0, 0], [9, 9, 9]],
        ...                          return_unknown=True)
        >>> occ.tolist(), unk.tolist()
        ([True, False, False], [False, False, True])
        """
        return_unknown = check_bool(return_unknown, "return_unknown")
        if threshold is None:
            level = check_probability(self.occupancy_threshold, "occupancy_threshold")
        else:
            warnings.warn("is_occupied(points, threshold) is deprecated: set the map's "
                          "occupancy_threshold (occupied at or above it) instead",
                          DeprecationWarning, stacklevel=2)
            level = check_real(threshold, "threshold", low=0.0, high=1.0)
        p = self.occupancy(points)
        unknown = np.isnan(p)
        with np.errstate(invalid="ignore"):
            occupied = p >= level if threshold is None else p > level
        occupied &= ~unknown
        return (occupied, unknown) if return_unknown else occupied

    # ------------------------------------------------------------ cells
    def cells(self) -> KernelCells:
        """Every cell any kernel reached, ordered by key (z, then y, then x).

        Returns
        -------
        cells : KernelCells
            Named tuple ``(centers, alpha, beta)``: the cells' centers, shape
            (n_cells, 3), and their evidence with `prior` added, shape (n_cells,).
        """
        keys, alpha, beta = self._cells_arrays()
        order = np.lexsort(keys.T)
        keys, alpha, beta = keys[order], alpha[order], beta[order]
        centers = (keys.astype(np.float64) - MAX_VAL + 0.5) * self._cell_edge
        prior = check_real(self.prior, "prior", low=0.0)
        return KernelCells(centers, alpha + prior, beta + prior)

    @property
    def num_cells(self) -> int:
        """Number of cells any kernel reached (0 for an empty map)."""
        return int(self._num_cells())

    @property
    def bounds(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(min corner, max corner) of the cells any kernel reached, in metres; NaN
        arrays when the map is empty."""
        keys = self._cells_arrays()[0]
        if not len(keys):
            return np.full(3, np.nan), np.full(3, np.nan)
        low = (keys.min(axis=0).astype(np.float64) - MAX_VAL) * self._cell_edge
        high = (keys.max(axis=0).astype(np.float64) - MAX_VAL + 1) * self._cell_edge
        return low, high

    def memory_usage(self) -> int:
        """Bytes the cells take.

        Returns
        -------
        nbytes : int
            Blocks of 4 x 4 x 4 cells (float32 alpha and beta and a mask of the
            reached cells, 520 bytes each) and their hash index.
        """
        return int(self._memory_bytes())

    @property
    def memory_bytes(self) -> int:
        """Deprecated alias of :meth:`memory_usage` (a DeprecationWarning)."""
        warnings.warn("memory_bytes is deprecated: call memory_usage() instead",
                      DeprecationWarning, stacklevel=2)
        return self.memory_usage()

    def to_octree(self, *, clamping_min: float = 0.001,
                  clamping_max: float = 0.999) -> OccupancyOctree:
        """The map as an :class:`~occgp.OccupancyOctree` of the same resolution.

        Each cell's posterior mean becomes its log-odds (float32, clamped to
        the bounds given), and the tree is pruned, so that ``.bt`` / ``.ot``
        export and OctoMap's viewers work. Cells no kernel reached stay
        unknown. The tree takes the map's `occupancy_threshold`.

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
        level = check_probability(self.occupancy_threshold, "occupancy_threshold")
        tree = OccupancyOctree(self._cell_edge, clamping_min=clamping_min,
                               clamping_max=clamping_max, occupancy_threshold=level)
        keys, alpha, beta = self._cells_arrays()
        if len(keys):
            prior = check_real(self.prior, "prior", low=0.0)
            p = (alpha + prior) / (alpha + beta + 2 * prior)
            log_odds = np.log(p) - np.log1p(-p)
            tree._set_values(np.ascontiguousarray(keys), log_odds.astype(np.float32))
        return tree
