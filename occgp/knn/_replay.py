"""The replay of a data set's k-NN and OctoMap maps for many parameter values.

:class:`ScanReplay` (public in :mod:`occgp.knn`) holds what every map of a data
set shares under every parameter value: the cells of each scan and their
classes, which point lies in which cell, the k-NN scores and their running
statistics. :func:`occgp.evaluation.grid_search` replays thousands of
parameter combinations from it as vectorised updates, each exactly the map
:class:`~occgp.KNNMap` or :class:`~occgp.OccupancyOctree` would build.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ._scores import history_knn_distances, logodds32, mean_knn_distances, point_log_odds
from .._octree import _welford
from .._status import Status
from .._validation import (
    check_choice, check_int, check_n_jobs, check_real, check_resolution, n_threads,
)
from ._map import (CDFS, MAX_HISTORY, MAX_K, MAX_RANGE, RENAMED, STATS, KNNMap,
                   check_knn_params)
from .._params import DEFAULT_RESOLUTION, check_renamed, deprecated_alias
from ..octree._tree import unpack_keys

__all__ = ["ScanReplay", "check_octomap_params"]


def check_octomap_params(params: dict[str, Any]) -> dict[str, float]:
    """OctoMap's ``prob_hit``, ``prob_miss``, ``clamping_min``, ``clamping_max`` checked
    as :class:`~occgp.OccupancyOctree` checks them, except that ``prob_hit = 0.5`` (a hit
    that carries no evidence, the first value of Miao et al.'s grid) is allowed."""
    from ..octree._logodds import check_params
    hit = check_real(params["prob_hit"], "prob_hit", low=0.5, high=1.0, low_open=False)
    q = check_params({"resolution": 1.0, "occupancy_threshold": 0.5, **params,
                      "prob_hit": 0.7})
    return {"prob_hit": hit, "prob_miss": q["prob_miss"], "clamping_min": q["clamping_min"],
            "clamping_max": q["clamping_max"]}



class ScanReplay:
    """What every map of a data set shares, for replaying many parameter values.

    The cells each scan updates and their classes (holding near points,
    crossed by rays to near points, crossed by cut rays only), which point
    lies in which cell, the k-NN scores of the points and their running
    Welford statistics do not depend on the probabilities: they are computed
    once here (without the culling region, whose cells depend on the map), and
    :meth:`knn_log_odds` / :meth:`octomap_log_odds` replay each scan as one
    vectorised, clamped float32 update per cell, in scan order, for a batch of
    parameter combinations. The result equals, cell for cell and bit for bit,
    the map that :class:`~occgp.KNNMap` (or :class:`~occgp.OccupancyOctree` with
    the same ``max_range``, liboctomap's ``insertPointCloud``) builds from
    the same scans.

    Parameters
    ----------
    scans : iterable of (points, origin)
        The data set, in insertion order.
    resolution : float, default=DEFAULT_RESOLUTION (0.1)
    max_range : float, default=4.0
        The sensor range s_c, metres: rays longer than this are cut there, as
        ``KNNMap(max_range=)`` and OctoMap's ``max_range`` cut them (the name
        ``sensor_range`` is deprecated).
    ks : sequence of int, default=(1,)
        The values of k to score points for.
    cdf : {"normal", "truncated"}, default="normal"
    stats : {"online", "dataset"}, default="online"
        μ and σ of the scores: Welford's running statistics, as
        :class:`~occgp.KNNMap` keeps them, or the whole data set's, fixed for the run
        (the final Welford statistics over every finite score of every scan,
        :meth:`score_stats`), as ``KNNMap(score_stats=replay.score_stats(k))``
        uses them.
    history : int, default=0
        The previous scans each point is scored against, as
        ``KNNMap(history=)`` takes them (0: its own scan, the paper's score),
        in [0, 64].
    n_jobs : int or None, default=None
        Threads for the k-NN queries and the rays' traversal (the replay is the
        same for every `n_jobs`).

    Attributes
    ----------
    keys : ndarray of uint64, shape (n_cells,)
        Every cell the scans update (packed keys, x in the low 16 bits), sorted.
    centers : ndarray of shape (n_cells, 3)
        Their centers, metres.
    n_scans : int
    n_points : int
        Points in the scans; ``n_near`` of them within range.
    """

    def __init__(self, scans: Iterable[Sequence[Any]],
                 resolution: float = DEFAULT_RESOLUTION, *, max_range: float = 4.0,
                 ks: Sequence[int] = (1,), cdf: str = "normal", stats: str = "online",
                 history: int = 0, n_jobs: int | None = None, **deprecated: Any) -> None:
        for name in deprecated:
            if name != "sensor_range":
                raise TypeError(f"ScanReplay.__init__() got an unexpected keyword argument "
                                f"{name!r}")
        if deprecated:
            max_range = check_renamed({"sensor_range": "max_range"},
                                      {"max_range": max_range, **deprecated},
                                      {"max_range": 4.0}, "ScanReplay")["max_range"]
        k_values = (ks,) if isinstance(ks, (int, np.integer)) else ks
        self.ks = tuple(check_int(k, "ks", low=1, high=MAX_K) for k in k_values)
        if not self.ks:
            raise ValueError("ks must hold at least one k")
        self.resolution = check_resolution(resolution)
        self.max_range = check_real(max_range, "max_range", low=0.0,
                                    high=MAX_RANGE, high_open=False)
        self.cdf = check_choice(cdf, "cdf", CDFS)
        self.stats = check_choice(stats, "stats", STATS)
        self.history = check_int(history, "history", low=0, high=MAX_HISTORY)
        workers = n_threads(check_n_jobs(n_jobs))
        probe = KNNMap(self.resolution, max_range=self.max_range)
        local = []
        self.n_points = self.n_near = 0
        running = [(0, 0.0, 0.0)] * len(self.ks)
        previous: list[NDArray[np.float64]] = []     # the last `history` near clouds
        for i, scan in enumerate(scans):
            try:
                points, origin = scan
            except (TypeError, ValueError):
                raise TypeError(f"scans[{i}] must be a (points, origin) pair") from None
            got = probe._validated_scan(points, origin, self.max_range, "scan",
                                        check_ends=False)
            if got is None:
                continue
            pts, org, rng, _ = got
            out = probe._knn_cells(pts, org, rng, False, 20, probe._max_scan_cells(),
                                   workers)
            if isinstance(out, Status):
                try:
                    probe._record_insert(out, pts, org, rng, "superray", 20)
                except ValueError as exc:
                    raise ValueError(f"scans[{i}]: {exc}") from None
                raise AssertionError("unreachable")
            near, keys, kinds, point_cell, _ = out
            cloud = near.astype(np.float64)
            s = (history_knn_distances(cloud, previous, self.ks, workers) if self.history
                 else mean_knn_distances(cloud, self.ks, workers))
            if self.history:
                previous = (previous + [cloud])[-self.history:]
            per_k = []
            for j in range(len(self.ks)):
                running[j] = _welford(np.ascontiguousarray(s[:, j]), *running[j])
                per_k.append(running[j])
            local.append((keys, kinds, point_cell, s, per_k))
            self.n_points += len(pts)
            self.n_near += len(s)
        self._final_stats = tuple(running)
        if self.stats == "dataset":
            local = [(keys, kinds, point_cell, s, list(self._final_stats))
                     for keys, kinds, point_cell, s, _ in local]
        self.n_scans = len(local)
        all_keys = np.concatenate([x[0] for x in local]) if local else np.empty(0, np.uint64)
        self.keys = np.unique(all_keys)
        self._scans = [(np.searchsorted(self.keys, keys).astype(np.int64), kinds, point_cell,
                        s, per_k) for keys, kinds, point_cell, s, per_k in local]
        self.centers = probe.key_to_coord(unpack_keys(self.keys))

    @property
    def num_cells(self) -> int:
        """Number of cells the scans update."""
        return len(self.keys)

    def score_stats(self, k: int) -> tuple[float, float]:
        """The data set's mean and standard deviation of the scores for `k`.

        Welford's statistics over every finite score of every scan (the values
        :attr:`occgp.KNNMap.score_mean_` and :attr:`occgp.KNNMap.score_std_` reach after
        the last scan); (0.0, 0.0) when there is none.

        Parameters
        ----------
        k : int
            One of :attr:`ks`.

        Returns
        -------
        mean, std : float

        Raises
        ------
        ValueError
            If `k` was not scored.
        """
        if k not in self.ks:
            raise ValueError(f"k={k!r} was not scored; this ScanReplay holds ks={self.ks}")
        count, mean, m2 = self._final_stats[self.ks.index(k)]
        return (mean, math.sqrt(m2 / count) if count > 0 else 0.0)

    sensor_range = deprecated_alias("max_range", "sensor_range")

    @property
    def centres(self) -> NDArray[np.float64]:
        """Deprecated name of :attr:`centers`."""
        warnings.warn("ScanReplay.centres is deprecated; use centers", DeprecationWarning,
                      stacklevel=2)
        return self.centers

    @property
    def n_cells(self) -> int:
        """Deprecated name of :attr:`num_cells`."""
        warnings.warn("ScanReplay.n_cells is deprecated; use num_cells", DeprecationWarning,
                      stacklevel=2)
        return self.num_cells

    def knn_log_odds(self, params: Sequence[dict[str, Any]]) -> NDArray[np.float32]:
        """Final log-odds of every cell of the KNNMap each parameter dict builds.

        Parameters
        ----------
        params : sequence of dict
            One dict per combination, holding ``k`` (one of :attr:`ks`),
            ``p_u``, ``p_l``, ``p_m``, ``p_m_out``, ``p_min`` and ``p_max``
            (checked as :func:`check_knn_params` checks them, with
            ``occupancy_threshold`` and ``max_range`` left out: the threshold
            does not change log-odds, the range is the replay's).

        Returns
        -------
        log_odds : ndarray of float32, shape (len(params), n_cells)
            Rows: the combinations; columns: the cells of :attr:`keys`. Equal,
            bit for bit, to the maps :class:`~occgp.KNNMap` builds from the scans.

        Raises
        ------
        TypeError, ValueError
            If a parameter is of the wrong type (TypeError), or a dict lacks
            one or one is out of range (ValueError); the message names the
            dict's index (``params[i]``).
        """
        checked = [self._check_knn(p, i) for i, p in enumerate(params)]
        kidx = np.array([self.ks.index(p["k"]) for p in checked])
        l_in = np.array([logodds32(p["p_m"]) for p in checked], dtype=np.float32)
        l_out = np.array([logodds32(p["p_m_out"]) for p in checked], dtype=np.float32)
        triples = sorted({(int(kidx[b]), p["p_u"], p["p_l"]) for b, p in enumerate(checked)})
        which = {t: i for i, t in enumerate(triples)}
        rows = np.array([which[(int(kidx[b]), p["p_u"], p["p_l"])]
                         for b, p in enumerate(checked)])

        def updates(scan):
            _, kinds, point_cell, s, per_k = scan
            free = np.where(kinds[None, :] == 1, l_in[:, None], l_out[:, None])
            held = np.flatnonzero(kinds == 0)
            sums = np.empty((len(triples), len(held)), dtype=np.float32)
            for i, (j, p_u, p_l) in enumerate(triples):
                values = point_log_odds(s[:, j], *per_k[j], p_u, p_l, self.cdf)
                sums[i] = np.bincount(point_cell, values, minlength=len(kinds))[held]
            free[:, held] = sums[rows]
            return free

        return self._replay(checked, updates)

    def octomap_log_odds(self, params: Sequence[dict[str, Any]]) -> NDArray[np.float32]:
        """Like :meth:`knn_log_odds`, for OctoMap.

        liboctomap's ``insertPointCloud`` with the replay's ``max_range``: one
        update per cell and scan (a hit wins), clamped per scan.

        Parameters
        ----------
        params : sequence of dict
            One dict per combination, holding ``prob_hit``, ``prob_miss``,
            ``clamping_min`` and ``clamping_max`` (checked as
            :func:`check_octomap_params` checks them).

        Returns
        -------
        log_odds : ndarray of float32, shape (len(params), n_cells)
            Rows: the combinations; columns: the cells of :attr:`keys`.

        Raises
        ------
        TypeError, ValueError
            As :meth:`knn_log_odds`.
        """
        checked = []
        for i, p in enumerate(params):
            try:
                q = check_octomap_params(p)
            except KeyError as exc:
                raise ValueError(f"params[{i}] lacks the OctoMap parameter {exc}") from None
            except (TypeError, ValueError) as exc:
                raise type(exc)(f"params[{i}]: {exc}") from None
            checked.append({"p_min": q["clamping_min"], "p_max": q["clamping_max"],
                            "l_hit": logodds32(q["prob_hit"]),
                            "l_miss": logodds32(q["prob_miss"])})
        l_hit = np.array([p["l_hit"] for p in checked], dtype=np.float32)
        l_miss = np.array([p["l_miss"] for p in checked], dtype=np.float32)

        def updates(scan):
            kinds = scan[1]
            return np.where(kinds[None, :] == 0, l_hit[:, None], l_miss[:, None])

        return self._replay(checked, updates)

    def _check_knn(self, p: dict[str, Any], i: int) -> dict[str, Any]:
        try:
            p = check_renamed(RENAMED, p, owner="ScanReplay", stacklevel=4)
            q = check_knn_params({"occupancy_threshold": p.get("p_min", 0.5),
                                  "max_range": self.max_range, **p})
        except KeyError as exc:
            raise ValueError(f"params[{i}] lacks the k-NN parameter {exc}") from None
        except (TypeError, ValueError) as exc:
            raise type(exc)(f"params[{i}]: {exc}") from None
        if q["k"] not in self.ks:
            raise ValueError(f"params[{i}]: k={q['k']} was not scored; this ScanReplay "
                             f"holds ks={self.ks}")
        return q

    def _replay(self, checked, updates) -> NDArray[np.float32]:
        lo = np.array([logodds32(p["p_min"]) for p in checked], dtype=np.float32)[:, None]
        hi = np.array([logodds32(p["p_max"]) for p in checked], dtype=np.float32)[:, None]
        values = np.zeros((len(checked), self.num_cells), dtype=np.float32)
        for scan in self._scans:
            cells = scan[0]
            u = updates(scan).astype(np.float32, copy=False)
            values[:, cells] = np.minimum(np.maximum(values[:, cells] + u, lo), hi)
        return values
