"""BGKMap: Bayesian generalized kernel inference on cells (la3dm's BGKOctoMap)."""

from __future__ import annotations

from numbers import Real

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._docfill import fill_doc
from .._params import DEFAULT_RESOLUTION, Interval
from .._validation import check_real
from ..maps import register
from ._kernel_map import KernelMapBase
from ._kernel_samples import (MAX_CELLS_PER_UPDATE, beam_chunks, check_free_count,
                              cube_sums, merge_cube_sums, packed_keys, split_range)


@register("bgk", formats=(".npz",),
          description="Bayesian generalised kernel inference on cells (isotropic)")
@fill_doc()
class BGKMap(KernelMapBase):
    """Occupancy by Bayesian generalized kernel inference (Doherty et al., "BGKOctoMap").

    Each scan becomes occupied and free training samples; every cell within
    `ell` of a sample collects the sample's kernel-weighted label in a Beta
    posterior, whose mean is the cell's occupancy (la3dm's BGKOctoMap on a
    hashed grid of cells).

    Parameters
    ----------
    resolution : float, default=0.1
        Edge length of the cells, in metres.
    ell : float, default=None
        Kernel length scale (support radius), in metres; None means
        ``max(0.2, 2 * resolution)``: la3dm's 0.2 m, scaled with cells coarser
        than 0.1 m (see Notes).
    sf2 : float, default=1.0
        Kernel signal variance (scale of the kernel).
    free_resolution : float, default=None
        Spacing of the free samples along each beam, in metres (plus one sample
        this far before each end point); None means
        ``max(0.5, 5 * resolution)``: la3dm's 0.5 m, scaled with cells coarser
        than 0.1 m (see Notes).
    ds_resolution : float, default=None
        Edge of the cubes that reduce the samples to centroids; None means
        `resolution`.
    prior : float, default=0.001
        Prior alpha and beta of every cell.
    max_range : float, default=None
        The sensor's range limit, in metres: a beam longer than this is cut
        there, as the octree's and the grid's rays are (`far_beams`); None
        keeps every beam whole. la3dm's default is 8 m (its simulated 8 m
        sensor); on a real LiDAR sequence (``hku_mb``, Livox Avia, hits to
        349 m, held-out scans scored to 30 m by ``bench/bench_real.py``),
        measured with the beams beyond dropped (``far_beams="drop"``), 8 m
        leaves 42 % of the test points unknown (AUC 0.877), 15 m 8 %
        (0.980), 30 m, 60 m and no limit 0.1 % (0.993): no limit by default,
        as OctoMap has none, and a limit at the sensor's useful range saves
        time (there 60 m halved it at the same scores).
    far_beams : {"cut", "drop"}, default="cut"
        What a beam longer than `max_range` gives: "cut" (occgp's rule, the
        octree's) its free samples along the beam up to `max_range`, as a
        beam of that length, and no occupied sample; "drop" (la3dm's rule)
        nothing, the beam is dropped whole. Only read when `max_range` is
        set.
    n_jobs : int, default=None
        Threads for the accumulation: None means 1, -1 every core, never more
        than the cores. The map is the same for any number.
    max_cells_per_update : int, default=2**30
        Most cells one update's kernels may visit (the support boxes of its
        samples, about ``(2 ell / resolution + 1)^3`` cells each), a few
        seconds of work on one thread; an update that would visit more raises
        a ValueError and changes nothing.
    occupancy_threshold : float, default=0.5
        A point is occupied (:meth:`is_occupied`) when its cell's occupancy is
        at least this probability, in (0, 1).

    Attributes
    ----------
    num_cells : int
        Number of cells any kernel reached.
    last_beams_ : tuple of (int, int)
        ``(kept, beyond)`` of the last accepted :meth:`update`: its beams
        (end points reduced to one centroid per cube of `ds_resolution`)
        within `max_range`, and those beyond it (cut at `max_range`, or
        dropped whole with ``far_beams="drop"``). ``(0, 0)``
        before any update; not saved by :meth:`save` or pickled (a loaded map
        starts at ``(0, 0)``).

    See Also
    --------
    AKIMap : Anisotropic kernels adapted to each sample's neighbours.
    OccupancyOctree : Log-odds mapping of the same scans.

    Notes
    -----
    The samples of a scan are its end points within `max_range` (occupied,
    label 1) and points every `free_resolution` metres along each beam, one
    more at ``length - free_resolution`` on every beam longer than
    `free_resolution`, and the sensor origin (free, label 0; la3dm's
    ``beam_sample``), both reduced to one centroid per cube of edge
    `ds_resolution`. A beam (to such a centroid) longer than `max_range` is
    cut there: its free samples are those of a beam of length `max_range`
    (la3dm drops it whole: ``far_beams="drop"``). Every cell whose center
    lies within `ell` of a sample gets ``k(r) y`` added to alpha and
    ``k(r) (1 - y)`` to beta, with ``r = distance / ell`` and k the sparse
    kernel times `sf2`. The occupancy of a cell is the posterior mean
    ``alpha / (alpha + beta)`` with `prior` added to both.

    Why `ell` and `free_resolution` grow with coarse cells: the samples are
    reduced to one centroid per cell, so a cell weighs its hits against the
    free samples that the beams leave in it and its neighbours. la3dm's
    0.2 m and 0.5 m are 2 and 5 cells at its 0.1 m; kept in metres at
    coarser cells, a free sample every 2.5 cells of every beam puts free
    evidence in most cells on a surface that beams graze. On the ``hku_mb``
    LiDAR sequence at 0.2 m (a validation split of the benchmark's training
    scans only: of its first 205 training scans, every 10th held out), 0.2 /
    0.5 m labelled 75 % of the held-out hits occupied (accuracy at 0.5
    0.860, AUC 0.978; the octree 0.903, 0.951), 0.4 / 1.0 m 89 % (0.913,
    AUC 0.976). At 0.1 m and finer the defaults are la3dm's (the maps of
    ``bench/bench_kernel.py`` at 0.05 m are unchanged).

    Parameters are stored as given and checked by the constructor, by
    :meth:`set_params` and again by every update (so that attributes changed
    after construction are checked too).

    Limits of one update, each a ValueError that leaves the map unchanged:
    points and origin within the key range ``[-32768, 32768) * resolution``
    per axis; at most ``MAX_FREE_SAMPLES`` (2^26) free samples before
    down-sampling; at most `max_cells_per_update` cells visited; ``sf2``
    within ``[1e-30, 1e30]`` (the cells keep float32 evidence); the scan at
    most 2^21 cubes of `ds_resolution` across; ``ell`` at least 1e-150 m.

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
    >>> m.is_occupied([[2.0, 0.0, 0.0], [1.0, 0.0, 0.0]]).tolist()
    [True, False]
    """

    def __init__(
        self,
        resolution: float = DEFAULT_RESOLUTION,
        *,
        ell: float | None = None,
        sf2: float = 1.0,
        free_resolution: float | None = None,
        ds_resolution: float | None = None,
        prior: float = 0.001,
        max_range: float | None = None,
        far_beams: str = "cut",
        n_jobs: int | None = None,
        max_cells_per_update: int = MAX_CELLS_PER_UPDATE,
        occupancy_threshold: float = 0.5,
    ) -> None:
        self._resolution = resolution
        self.ell = ell
        self.sf2 = sf2
        self.free_resolution = free_resolution
        self.ds_resolution = ds_resolution
        self.prior = prior
        self.max_range = max_range
        self.far_beams = far_beams
        self.n_jobs = n_jobs
        self.max_cells_per_update = max_cells_per_update
        self.occupancy_threshold = occupancy_threshold
        self._build()
        self.last_beams_ = (0, 0)
        self._beams = (0, 0)

    _SUPPORT_HINT = "a smaller ell"
    _parameter_constraints = {
        **KernelMapBase._parameter_constraints,
        "ell": [None, Interval(Real, 0, None, closed="neither")],
        "sf2": [Interval(Real, 0, None, closed="neither")],
        "free_resolution": [None, Interval(Real, 0, None, closed="neither")],
        "ds_resolution": [None, Interval(Real, 0, None, closed="neither")],
    }

    def _accepted(self) -> None:
        self.last_beams_ = self._beams

    def _check_values(self, params: dict) -> dict:
        out = super()._check_values(params)
        ell = params["ell"]
        out["ell"] = None if ell is None else check_real(ell, "ell", low=0.0)
        fr = params["free_resolution"]
        out["free_resolution"] = None if fr is None else check_real(fr, "free_resolution",
                                                                    low=0.0)
        # derived: the length scale and the free-sample spacing in use
        res = out["resolution"]
        out["length"] = max(0.2, 2.0 * res) if ell is None else out["ell"]
        out["free_step"] = max(0.5, 5.0 * res) if fr is None else out["free_resolution"]
        if out["length"] < 1e-150:
            raise ValueError(f"ell must be at least 1e-150 m (its inverse square must be "
                             f"finite), got {out['length']!r}"
                             + ("" if ell is not None else " (max(0.2, 2 * resolution))"))
        out["sf2"] = check_real(params["sf2"], "sf2", low=0.0)
        ds = params["ds_resolution"]
        out["ds_resolution"] = None if ds is None else check_real(ds, "ds_resolution",
                                                                  low=0.0)
        return out

    def __repr__(self) -> str:
        return f"BGKMap(resolution={self.resolution!r}, ell={self.ell!r}, " \
               f"num_cells={self.num_cells})"

    def training_data(self, points: ArrayLike,
                      origin: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The samples and labels (1 occupied, 0 free) that :meth:`update` uses.

        Nothing in the map changes.

        {scan_parameters}

        {training_returns}

        Raises
        ------
        TypeError, ValueError
            As :meth:`update`.
        """
        _, samples, labels, _, _ = self._checked_training_data(points, origin)
        return samples, labels

    def _training_data(self, p, pts, org):
        ds = p.resolution if p.ds_resolution is None else p.ds_resolution
        self._beams = (0, 0)
        if len(pts) == 0:
            return np.empty((0, 3)), np.empty(0)
        _, sums, counts = cube_sums(pts, ds, "ds_resolution")
        hits = sums / counts[:, None]
        n_beams = len(hits)
        hits, cut = split_range(hits, org, p.max_range, p.far_beams)
        self._beams = (len(hits), n_beams - len(hits))
        # the beams: to the hits, then those beyond max_range cut there (no hit)
        ends = np.vstack([hits, cut])
        if len(ends) == 0:
            return np.empty((0, 3)), np.empty(0)
        # free samples every free_resolution metres along each beam (d < length), one
        # more at length - free_resolution on every beam longer than free_resolution,
        # and the origin once per beam (so it weighs in its cube's centroid), as la3dm's
        # beam_sample and get_training_data
        length = np.linalg.norm(ends - org, axis=1)
        fr = p.free_step
        with np.errstate(over="ignore"):
            n_step_f = np.maximum(np.ceil(length / fr) - 1, 0)
        n_free_f = n_step_f + (length > fr)
        check_free_count(n_free_f.sum(), "free_resolution", fr)
        n_step, n_free = n_step_f.astype(np.int64), n_free_f.astype(np.int64)
        unit = (ends - org) / np.where(length > 0, length, 1.0)[:, None]
        # centroids per cube of ds, the free samples made and reduced chunk by chunk
        low = np.minimum(ends.min(axis=0), org) - ds
        parts = []
        for beam, j in beam_chunks(n_free):
            dist = (j + 1) * fr
            last = j >= n_step[beam]                # the sample at length - fr
            dist[last] = length[beam[last]] - fr
            parts.append(cube_sums(org + unit[beam] * dist[:, None], ds, "ds_resolution",
                                   low))
        parts.append((packed_keys(org[None], ds, "ds_resolution", low),
                      org[None] * len(ends), np.array([len(ends)])))
        _, sums, counts = merge_cube_sums(parts)
        frees = sums / counts[:, None]
        samples = np.vstack([hits, frees])
        labels = np.concatenate([np.ones(len(hits)), np.zeros(len(frees))])
        return samples, labels

    def _kernels(self, p, samples, labels, org):
        n = len(samples)
        precision = np.broadcast_to(np.eye(3) / p.length ** 2, (n, 3, 3)).copy()
        return precision, np.full((n, 3), p.length), np.ones(n), p.sf2, None
