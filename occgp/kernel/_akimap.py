"""AKIMap: adaptive anisotropic kernel inference on cells (Kwon et al.)."""

from __future__ import annotations

from numbers import Integral, Real
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..io import _npz as _npz_io
from .._docfill import fill_doc
from .._kernel import _akimap_bandwidths
from .._params import DEFAULT_RESOLUTION, Check, Interval, Options, deprecated_alias
from .._validation import as_point, as_points, check_real, n_threads
from ..maps import register
from ._kernel_map import KernelMapBase
from ._kernel_samples import (MAX_CELLS_PER_UPDATE, beam_chunks, check_free_count,
                              packed_keys, search_cell, split_range, voxel_first)
from ._kernel_utils import Bandwidths

_RANDOM_STATE = "random_state must be None, a non-negative int or a numpy.random.Generator"


def _check_random_state(value):
    if not (value is None or isinstance(value, np.random.Generator)
            or (isinstance(value, Integral) and not isinstance(value, bool))):
        raise TypeError(f"{_RANDOM_STATE}, got {value!r}")
    if isinstance(value, Integral) and value < 0:
        raise ValueError(f"{_RANDOM_STATE}, got {value!r}")
    return value


@register("akimap", formats=(".npz",),
          description="Adaptive anisotropic kernel inference on cells", random_state=0)
@fill_doc()
class AKIMap(KernelMapBase):
    """Occupancy by adaptive anisotropic kernel inference (Kwon et al., AKIMap).

    Each scan becomes occupied and free samples, and each sample gets its own
    bandwidth matrix H, shaped by the covariance of its same-label neighbours
    and scaled against the others; every cell inside a sample's support
    collects the sample's kernel-weighted label in a Beta posterior, whose
    mean is the cell's occupancy.

    Parameters
    ----------
    resolution : float, default=0.1
        Edge length of the cells, in metres; also the isotropic fallback's
        bandwidth and the down-sampling cell of the samples.
    free_sample_distance : float, default=None
        One random free sample per this many metres of each beam; None means
        ``max(0.5, 5 * resolution)``: the reference code's 0.5 m, scaled with
        cells coarser than 0.1 m (see Notes).
    max_search_range : float, default=None
        R, the largest neighbour search radius, in metres; None means the
        free-sample distance in use (as the reference code).
    schedule_range : float, default=30.0
        The paper's sensor range in the bandwidth schedule ``r(d)``: the
        distance at which the search radius reaches R, in metres (it sets the
        bandwidths' schedule only: `max_range` limits the beams; called
        ``sensor_range`` before, a name deprecated for one release). The paper
        grows the radius "from the voxel size at the origin to R at max
        range": 30 m, the useful range of the LiDARs the defaults are chosen
        for, where the reference code has its simulated sensor's 8 m (use
        ``schedule_range=8`` for the la3dm scenes). On the ``hku_mb`` validation
        split (see Notes) 30 m against 8 m: accuracy at 0.5 0.933 -> 0.931,
        AUC 0.991 -> 0.991 at 0.1 m, 0.929 -> 0.931 and 0.978 -> 0.979 at
        0.2 m, in 30 % less time (fewer neighbours in the searches near the
        sensor).
    variant : {"occgp", "published"}, default="occgp"
        How the scale is chosen: "occgp" minimises Eq. 3.7 on a grid of 16
        log-spaced scales refined by golden-section search; "published" runs
        the reference code's gradient descent from c = 1 (step 0.01 / epoch,
        100 epochs, tolerance 0.001, the code's gradient as published).
    bandwidth_floor : float, default=None
        f, in metres: ``f^2 I`` is added to every bandwidth after its scale is
        chosen, so no kernel is thinner than about f (see Notes). None means,
        for ``variant="occgp"``, ``3 * resolution`` but at most 0.3 times the
        free-sample distance in use (so ``3 * resolution`` up to 0.05 m cells,
        0.15 m up to 0.1 m, ``1.5 * resolution`` beyond), and 0 (none, as
        published) for ``variant="published"``.
    prior : float, default=0.001
        Prior alpha and beta of every cell.
    max_range : float, default=None
        The sensor's range limit, in metres, as :class:`BGKMap`'s: a beam
        longer than this is cut there, as the octree's and the grid's rays
        are (`far_beams`); None keeps every beam whole.
    far_beams : {"cut", "drop"}, default="cut"
        What a beam longer than `max_range` gives: "cut" (occgp's rule, the
        octree's) no occupied sample and its free samples up to `max_range`,
        drawn as on a beam of that length (one beam per cell of the cut
        ends); "drop" (la3dm's rule) nothing: the map is the one of the scan
        without those points. Only read when `max_range` is set.
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
    occupancy_threshold : float, default=0.5
        A point is occupied (:meth:`is_occupied`) when its cell's occupancy is
        at least this probability, in (0, 1).

    Attributes
    ----------
    num_cells : int
        Number of cells any kernel reached.
    last_bandwidths_ : Bandwidths
        The kernels of the last update's samples.

    See Also
    --------
    BGKMap : The isotropic baseline.

    Notes
    -----
    The samples of a scan are its end points within `max_range` (occupied,
    label 1; the first point in each cell of edge `resolution`), the sensor
    origin (always, as the reference code) and one uniformly random point in each
    `free_sample_distance` interval of every beam (free, label 0; intervals
    start half a distance from the origin, cells already holding a sample
    are skipped). A beam longer than `max_range` is cut there and gives only
    free samples, drawn after those of the beams to the end points (with
    ``far_beams="drop"`` it gives none). Each sample gets its own bandwidth matrix H:

    * the same-label samples within ``r(d) = min((R - resolution) / schedule_range
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

    Every cell whose center lies inside a sample's support gets
    ``|H|^-1/2 k(r) y`` added to alpha and ``|H|^-1/2 k(r) (1 - y)`` to beta
    (Eq. 3.8-3.9), ``r^2 = (c_m - x)^T H^-1 (c_m - x)``; occupancy is
    ``alpha / (alpha + beta)`` with `prior` added to both.

    Why the floor: a covariance of samples on a surface is nearly flat, and
    its kernel then falls between cell centers; the floor gives such kernels
    the thickness of a few cells (AUC 0.938 -> 0.980 on the la3dm structured
    scene at 0.05 m with the default, 3 cells there). Beyond about a third of
    the spacing of the free samples it smooths free space into surfaces: of
    floors from 0.05 m to 0.3 m, 0.15 m scored best on the synthetic rooms
    against their exact occupancy at both 0.05 m and 0.1 m cells (at 0.1 m,
    AUC 0.810 -> 0.867 structured, 0.796 -> 0.864 unstructured, against the
    former ``3 * resolution``; the la3dm scene's held-out AUC 0.983 ->
    0.970), and on the ``hku_mb`` LiDAR sequence at 0.1 m (a validation
    split of the real-log benchmark's training scans only: of its first 205
    training scans, every 10th held out) accuracy at 0.5 0.912 -> 0.933,
    AUC 0.990 -> 0.991, in a third of the accumulation's time.

    Why the free-sample distance grows with coarse cells: a free sample
    every 0.5 m of every beam, 2.5 cells of 0.2 m, puts free evidence in
    most cells on a surface that beams graze, and their posterior mean
    falls below 0.5. On the same validation split at 0.2 m, 0.5 m (floor
    0.6 m) labelled 69 % of the held-out hits occupied (accuracy at 0.5
    0.831, AUC 0.972; the octree 0.903, 0.951), 1.0 m (floor 0.3 m) 93 %
    (accuracy 0.929, AUC 0.978).

    Parameters are stored as given and checked by the constructor, by
    :meth:`set_params` and again by every update (so that attributes changed
    after construction are checked too). Setting a new `random_state`
    through :meth:`set_params` restarts the stream of free samples.

    Limits of one update, each a ValueError that leaves the map (and its
    random stream) unchanged: points and origin within the key range
    ``[-32768, 32768) * resolution`` per axis; at most ``MAX_FREE_SAMPLES``
    (2^26) free samples; at most `max_cells_per_update` cells visited and
    sample pairs examined; kernel weights ``|H|^-1/2`` within
    ``[1e-30, 1e30]`` (the cells keep float32 evidence: with the default
    floor, resolutions from about 1e-10 m to 1e10 m).

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
    _parameter_constraints = {
        **KernelMapBase._parameter_constraints,
        "free_sample_distance": [None, Interval(Real, 0, None, closed="neither")],
        "max_search_range": [None, Interval(Real, 0, None, closed="neither")],
        "schedule_range": [Interval(Real, 0, None, closed="neither")],
        "variant": [Options(VARIANTS)],
        "bandwidth_floor": [None, Interval(Real, 0, None, closed="left")],
        "random_state": [Check(lambda value, name: _check_random_state(value),
                               "None, a non-negative int or a numpy.random.Generator")],
    }
    _deprecated_params = {"sensor_range": "schedule_range"}
    sensor_range = deprecated_alias("schedule_range", "sensor_range")

    def __init__(
        self,
        resolution: float = DEFAULT_RESOLUTION,
        *,
        free_sample_distance: float | None = None,
        max_search_range: float | None = None,
        schedule_range: float = 30.0,
        variant: str = "occgp",
        bandwidth_floor: float | None = None,
        prior: float = 0.001,
        max_range: float | None = None,
        far_beams: str = "cut",
        random_state: int | np.random.Generator | None = None,
        n_jobs: int | None = None,
        max_cells_per_update: int = MAX_CELLS_PER_UPDATE,
        occupancy_threshold: float = 0.5,
        **deprecated: Any,
    ) -> None:
        if deprecated:
            schedule_range = self._renamed(deprecated, schedule_range=schedule_range)[
                "schedule_range"]
        self._resolution = resolution
        self.free_sample_distance = free_sample_distance
        self.max_search_range = max_search_range
        self.schedule_range = schedule_range
        self.variant = variant
        self.bandwidth_floor = bandwidth_floor
        self.prior = prior
        self.max_range = max_range
        self.far_beams = far_beams
        self.random_state = random_state
        self.n_jobs = n_jobs
        self.max_cells_per_update = max_cells_per_update
        self.occupancy_threshold = occupancy_threshold
        self._build()
        self._rng = np.random.default_rng(random_state)
        self.last_bandwidths_: Bandwidths | None = None

    _SUPPORT_HINT = "a smaller bandwidth_floor or max_search_range"

    def _check_values(self, params: dict) -> dict:
        out = super()._check_values(params)
        d = params["free_sample_distance"]
        out["free_sample_distance"] = None if d is None else check_real(
            d, "free_sample_distance", low=0.0)
        r = params["max_search_range"]
        out["max_search_range"] = None if r is None else check_real(r, "max_search_range",
                                                                    low=0.0)
        out["schedule_range"] = check_real(params["schedule_range"], "schedule_range",
                                           low=0.0)
        variant = params["variant"]
        if not isinstance(variant, str) or variant not in self.VARIANTS:
            raise ValueError(f"variant must be one of {self.VARIANTS}, got {variant!r}")
        out["variant"] = variant
        f = params["bandwidth_floor"]
        out["bandwidth_floor"] = None if f is None else check_real(f, "bandwidth_floor",
                                                                   low=0.0, low_open=False)
        out["random_state"] = _check_random_state(params["random_state"])
        # derived: the free-sample distance, the neighbour search radius R and the
        # floor f in use
        out["free_step"] = (max(0.5, 5.0 * out["resolution"]) if d is None
                            else out["free_sample_distance"])
        out["search_range"] = out["free_step"] if r is None else out["max_search_range"]
        out["floor"] = (out["bandwidth_floor"] if f is not None else
                        min(3.0 * out["resolution"], 0.3 * out["free_step"])
                        if variant == "occgp" else 0.0)
        return out

    def _set_checked_params(self, params, p) -> None:
        old = self.random_state
        super()._set_checked_params(params, p)
        new = params.get("random_state", old)
        if not (new is old or (isinstance(new, Integral) and isinstance(old, Integral)
                               and new == old)):
            self._rng = np.random.default_rng(new)

    def _rng_state(self):
        return self._rng.bit_generator.state

    def _set_rng_state(self, state) -> None:
        self._rng.bit_generator.state = state

    def _keep(self, extra) -> None:
        self.last_bandwidths_ = extra

    def __repr__(self) -> str:
        return (f"AKIMap(resolution={self.resolution!r}, variant={self.variant!r}, "
                f"num_cells={self.num_cells})")

    # ------------------------------------------------------------ files
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
    _PARAMS_ADDED = KernelMapBase._PARAMS_ADDED + ("max_range",)

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

    # ------------------------------------------------------------ samples and kernels
    @property
    def floor_(self) -> float:
        """The bandwidth floor in use, in metres (see `bandwidth_floor`)."""
        return self._validated_params().floor

    def training_data(self, points: ArrayLike,
                      origin: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The samples and labels (1 occupied, 0 free) an update would use, drawn from
        the map's random generator (so this advances it).

        {scan_parameters}

        {training_returns}

        Raises
        ------
        TypeError, ValueError
            As :meth:`update` (the generator is then not advanced).
        """
        _, samples, labels, _, _ = self._checked_training_data(points, origin)
        return samples, labels

    def _training_data(self, p, pts, org):
        res, step = p.resolution, p.free_step
        pts, cut = split_range(pts, org, p.max_range, p.far_beams)
        hits = pts[voxel_first(pts, res)]
        # the beams: to the hits, then those beyond max_range cut there (no hit), one
        # per cell of its cut end
        ends = np.vstack([hits, cut[voxel_first(cut, res)]])
        if len(ends) == 0:
            return np.empty((0, 3)), np.empty(0)
        length = np.linalg.norm(ends - org, axis=1)
        # one random point in each interval [step/2 + j step, step/2 + (j+1) step)
        # that starts before the end point, kept when it falls before it
        with np.errstate(over="ignore"):
            n_free_f = np.maximum(np.ceil((length - 0.5 * step) / step), 0)
        check_free_count(n_free_f.sum(), "free_sample_distance", step)
        n_free = n_free_f.astype(np.int64)
        unit = (ends - org) / np.where(length > 0, length, 1.0)[:, None]
        # the origin is always a free sample (the reference code's first one, even in
        # the cell of an end point); a cell already holding a sample (end points, the
        # origin, then the free samples in order) takes no further free one. The free
        # samples are drawn chunk by chunk (the same stream as at once).
        low = np.minimum(ends.min(axis=0), org) - res
        # the cells taken, each once (the hits' are distinct: one hit a cell); a chunk's
        # new cells join them before the next chunk
        taken = packed_keys(np.vstack([hits, org[None]]), res, "resolution", low)
        if (taken[:-1] == taken[-1]).any():
            taken = taken[:-1]
        kept, new = [org[None]], None
        for beam, j in beam_chunks(n_free):
            if new is not None:
                taken = np.concatenate([taken, new])
            dist = step * (0.5 + j + self._rng.random(len(beam)))
            keep = dist < length[beam]
            beam, dist = beam[keep], dist[keep]
            frees = org + unit[beam] * dist[:, None]
            keys = packed_keys(frees, res, "resolution", low)
            _, first = np.unique(keys, return_index=True)
            first = np.sort(first[~np.isin(keys[first], taken, assume_unique=True)])
            kept.append(frees[first])
            new = keys[first]
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
        p = self._validated_params()
        xs = as_points(samples, "samples")
        org = as_point(origin, "origin")
        lab = np.asarray(labels)
        if lab.shape != (len(xs),):
            raise ValueError(f"labels must have shape ({len(xs)},), got {lab.shape}")
        if lab.dtype.kind not in "biuf":
            raise TypeError(f"labels must hold 0 or 1, got dtype {lab.dtype}")
        if not np.isin(lab, (0, 1)).all():
            raise ValueError("labels must be 0 (free) or 1 (occupied)")
        return self._bandwidths(p, xs, lab, org)

    def _bandwidths(self, p, xs, lab, org) -> Bandwidths:
        radius = p.search_range
        cell = search_cell(xs, radius)
        pairs, out = _akimap_bandwidths(np.ascontiguousarray(xs, dtype=np.float64),
                                        np.ascontiguousarray(lab, dtype=np.uint8), org,
                                        p.resolution, radius, p.schedule_range,
                                        p.variant == "published", p.floor,
                                        n_threads(p.n_jobs), cell,
                                        float(p.max_cells_per_update))
        if out is None:
            raise ValueError(
                f"the bandwidths of these {len(xs)} samples would examine {pairs:.3g} "
                f"sample pairs (those in the cubes of edge max_search_range="
                f"{radius:g} m around each), more than max_cells_per_update="
                f"{p.max_cells_per_update}; use a smaller max_search_range or raise "
                f"max_cells_per_update; the map is unchanged")
        return Bandwidths(*out)

    def _kernels(self, p, samples, labels, org):
        bw = self._bandwidths(p, samples, labels, org)
        return bw.precision, bw.extent, bw.weight, 1.0, bw
