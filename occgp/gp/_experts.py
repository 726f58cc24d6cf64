"""The experts of :class:`~occgp.gp.GPMixture`: fitting, dense prediction, reach, and
the leave-one-out downdate of the committee's classifier."""

from __future__ import annotations

import numpy as np
import scipy.linalg as sl
from scipy.spatial import cKDTree
from sklearn.base import clone

from ._beams import row_index
from ._cells import downdated_cell
from ._gpr import optimize_shared_hyperparameters
from ._integral_kernel import check_quadrature, covariance
from ._limits import one_blas_thread, threads
from ._observations import Observations, draw_subset

__all__ = ["Reach", "QueryIndex", "skip_tolerances", "evaluate_expert", "global_template",
           "shared_template", "hit_origins", "fit_expert", "one_cell", "predict_expert",
           "predict_dense", "split_observations", "hits_first", "concat_observations",
           "order_positions", "downdated"]

#: Spacing (in length scales) of the samples along an expert's beams that
#: bound the distance from a query to its observations.
_SAMPLE_STEP = 0.5
#: Experts of at most this many observations, or with at most as many queries as
#: observations, are evaluated densely (others on GPOMIK's tiles, which need K^-1 but
#: were faster for many queries on the Intel log); queries go in blocks of `_BLOCK`.
_DENSE_SIZE = 400
_BLOCK = 4096


def hit_origins(hits, segment_starts, segment_ends, beam_hits=None):
    """The sensor position of each hit: the start of its beam.

    Its beam is the first whose `beam_hits` entry (:func:`match_beams`: the
    hit of each beam, -1 for none) names it; without one (or without
    `beam_hits`), the first beam ending exactly on it. A hit with no beam is
    its own origin (a scan of one hit).
    """
    origins = hits.copy()
    beam = row_index(hits, segment_ends)
    if beam_hits is not None:
        named = np.flatnonzero(beam_hits >= 0)
        hit, first = np.unique(beam_hits[named], return_index=True)   # first beam per hit
        beam[hit] = named[first]
    origins[beam >= 0] = segment_starts[beam[beam >= 0]]
    return origins


class Reach:
    """Where one expert may differ from its prior by more than a tolerance.

    With ``C = K + noise I`` the expert's covariance, a query's variance
    reduction is ``k^T C^-1 k <= |k|^2 / noise`` and its mean
    ``|k^T C^-1 y| <= sqrt(k^T C^-1 k * y^T C^-1 y)`` (Cauchy–Schwarz in the
    ``C^-1`` inner product). Each entry of ``k`` is at most
    ``variance * w_i * f(d^2)``, with ``w_i`` the observation's length (1
    for a point), ``f`` the kernel's (decreasing) profile and ``d`` the
    distance in length scales from the query to the nearest observation.
    Beyond the radius where those bounds give a variance within
    ``eps * prior`` of the prior and a mean within ``eps * sqrt(prior)`` of 0
    the expert is at its prior up to the tolerance; beyond the kernel's
    cutoff it is exactly there. Distances are bounded below through samples
    every `_SAMPLE_STEP` length scales along the observations (a point of a
    segment is within half a step of a sample).
    """

    def __init__(self, gp):
        kernel = gp.kernel_
        self.kernel = kernel
        self.inv = kernel.inverse_length_scales(gp.n_dims_)
        self.prior = float(kernel.variance)
        cells = gp.cells_
        self.w2 = sum(float(np.sum(np.where(c.obs.lengths > 0, c.obs.lengths, 1.0) ** 2))
                      for c in cells)
        self.energy = max(max(float(c.obs.y @ c.alpha) for c in cells), 1e-300)
        self.noise = gp.noise_ + gp.jitter_
        starts = np.vstack([c.obs.starts for c in cells]) * self.inv
        ends = np.vstack([c.obs.ends for c in cells]) * self.inv
        n = np.ceil(np.linalg.norm(ends - starts, axis=1) / _SAMPLE_STEP).astype(np.intp) + 1
        owner = np.repeat(np.arange(len(n)), n)
        t = (np.arange(len(owner)) - np.repeat(np.cumsum(n) - n, n)) / np.maximum(n - 1, 1)[owner]
        samples = starts[owner] + t[:, None] * (ends - starts)[owner]
        self.lo, self.hi = samples.min(axis=0), samples.max(axis=0)
        self.tree = cKDTree(samples)
        self._radius = {}

    def radius(self, eps):
        """Distance (length scales) beyond which the expert is within `eps` of its prior."""
        if eps not in self._radius:
            r_max = eps * self.prior * min(1.0, eps / self.energy)
            bound = np.sqrt(r_max * self.noise / (self.w2 * self.prior ** 2)) if eps > 0 else 0.0
            profile = self.kernel.profile
            lo, hi = 0.0, float(type(self.kernel).cutoff2)
            if profile(np.array([hi]))[0] <= bound:
                for _ in range(60):  # smallest squared distance with f(s) <= bound
                    mid = 0.5 * (lo + hi)
                    lo, hi = (mid, hi) if profile(np.array([mid]))[0] > bound else (lo, mid)
            self._radius[eps] = float(np.sqrt(hi))
        return self._radius[eps]

    def box(self, eps):
        """(low, high) corners, in world coordinates, of the candidates of :meth:`queries`."""
        r = self.radius(eps) + _SAMPLE_STEP / 2
        return (self.lo - r) / self.inv, (self.hi + r) / self.inv

    def queries(self, X, eps):
        """Indices (ascending) of the queries within reach.

        `X`: the queries in world coordinates, or a :class:`QueryIndex` of
        them (faster when several experts look at the same queries).
        """
        index = X if isinstance(X, QueryIndex) else QueryIndex(X)
        r = self.radius(eps) + _SAMPLE_STEP / 2
        lo, hi = self.lo - r, self.hi + r
        # the world box, widened past rounding, picks a slice; the test in
        # length-scale units then decides as if every query were tested
        pad = 1e-9 * (1.0 + np.maximum(np.abs(lo), np.abs(hi)))
        cand = index.in_box((lo - pad) / self.inv, (hi + pad) / self.inv)
        Xs = index.X[cand] * self.inv
        cand = cand[np.all((Xs >= lo) & (Xs <= hi), axis=1)]
        if not len(cand):
            return cand
        d, _ = self.tree.query(index.X[cand] * self.inv, distance_upper_bound=r)
        return cand[np.isfinite(d)]


class QueryIndex:
    """Queries sorted along their first axis, for the experts' box look-ups.

    Parameters
    ----------
    X : ndarray of shape (n, D)
        Queries, world coordinates.
    """

    def __init__(self, X):
        self.X = X
        self._order = np.argsort(X[:, 0], kind="stable")
        self._first = X[self._order, 0]

    def in_box(self, lo, hi):
        """Indices (ascending) of the queries in the closed box ``[lo, hi]``."""
        a = np.searchsorted(self._first, lo[0], side="left")
        b = np.searchsorted(self._first, hi[0], side="right")
        idx = self._order[a:b]
        if self.X.shape[1] > 1 and len(idx):
            rest = self.X[idx, 1:]
            idx = idx[np.all((rest >= lo[1:]) & (rest <= hi[1:]), axis=1)]
        return np.sort(idx)


def skip_tolerances(reaches, prior_tol):
    """How far from its prior each expert may be where the committee skips it.

    Expert ``e`` gets ``prior_tol / m_e``, with ``m_e`` the number of experts
    (itself included) whose cutoff boxes (where they may differ from their
    prior at all) overlap its own. At any query, the experts not at their
    prior are some ``m`` experts whose boxes all hold the query, so they
    overlap each other's, and each of them has ``m_e >= m``: the skipped ones
    add up to at most `prior_tol`.
    """
    boxes = [reach.box(0.0) for reach in reaches]
    lo = np.array([b[0] for b in boxes])
    hi = np.array([b[1] for b in boxes])
    count = np.empty(len(boxes), dtype=np.int64)
    for a in range(0, len(boxes), 256):
        overlap = np.all((lo[a:a + 256, None] <= hi[None]) & (lo[None] <= hi[a:a + 256, None]),
                         axis=2)
        count[a:a + 256] = overlap.sum(axis=1)
    return prior_tol / count


def evaluate_expert(e, expert, idx, X):
    """Expert `e`'s latent mean and variance at its queries `X` (indices `idx`)."""
    mean, var = predict_expert(expert, X)
    return e, idx, mean, var


def global_template(template, obs, seed):
    """`template` with a GPOMIK's hyper-parameters fitted on a random subset, and its PLSC.

    The subset holds ``template.max_optimize`` observations of all of `obs`
    drawn at random (all of them when fewer; with hits and beams, see
    :func:`draw_subset`), so the GPOMIK fits both on the whole subset, as
    :meth:`GPOMIK.fit` would. Returns ``(template, (a, b))``.
    """
    take = draw_subset(obs.labels, template.max_optimize, np.random.default_rng(seed))
    gp = fit_expert(clone(template).set_params(max_cell_size=None), hits_first(obs.take(take)),
                    int(np.random.SeedSequence([seed, 0, 1]).generate_state(1)[0]))
    return (clone(template).set_params(kernel=gp.kernel_, noise=gp.noise_, optimizer=False),
            tuple(gp.plsc_))


def shared_template(template, obs, groups, rng):
    """`template` with the hyper-parameters that maximise the experts' summed objective.

    They are fitted on whole experts (`groups`: indices into `obs`) in random
    order, as many as fit in `max_optimize` observations of the template (at
    least one).
    """
    kernel, noise, noise_bounds = template._check_params()
    if template.optimizer:
        order = rng.permutation(len(groups))
        sizes = np.array([len(groups[e]) for e in order])
        n_parts = max(1, int(np.searchsorted(np.cumsum(sizes), template.max_optimize,
                                             side="right")))
        parts = [(o.starts, o.ends, o.y) for o in
                 (obs.take(groups[e]) for e in np.sort(order[:n_parts]))]
        kernel, noise, _ = optimize_shared_hyperparameters(
            kernel, noise, noise_bounds, parts, check_quadrature(template.quadrature),
            n_restarts=template.n_restarts, rng=rng, objective=template.objective,
            n_threads=threads(template.n_jobs))
    return clone(template).set_params(kernel=kernel, noise=noise, optimizer=False)


def fit_expert(template, obs, seed):
    """A clone of `template` fitted on `obs`, with one BLAS thread (the same in any worker)."""
    expert = clone(template).set_params(random_state=seed)
    n_hits = int(np.count_nonzero(obs.labels > 0))
    with one_blas_thread():
        return expert.fit(obs.starts[:n_hits], obs.starts[n_hits:], obs.ends[n_hits:])


def one_cell(template, n_obs):
    """`template` for an expert of `n_obs` observations in one cell: its `max_cell_size`
    raised to `n_obs` where below it (a part of a cluster that no cut could split keeping
    hits and beams on both sides; the committee's leave-one-out downdate needs one cell)."""
    if template.max_cell_size is None or n_obs <= template.max_cell_size:
        return template
    return clone(template).set_params(max_cell_size=n_obs)


def predict_expert(expert, X):
    """Latent mean and variance of `expert` at `X`.

    A single-cell expert of at most `_DENSE_SIZE` observations, or asked at
    most as many queries as it has observations, is evaluated densely
    (:func:`predict_dense`): the same values as :meth:`GPOMIK.predict` up to
    rounding, without its tiles' bookkeeping. BLAS runs on one thread,
    so the values do not depend on the joblib backend.
    """
    with one_blas_thread():
        return predict_dense(expert, X)


def predict_dense(expert, X):
    """Latent mean and variance of a single-cell `expert` at `X`, densely where it has at
    most `_DENSE_SIZE` observations or `X` at most as many points (otherwise its predict).

    The cross-covariance ``k`` of a block of `_BLOCK` queries gives
    ``mean = k^T alpha`` and ``var = prior - |L^-1 k|^2`` (one triangular
    solve; ``K^-1`` is never formed). Agrees with :meth:`GPOMIK.predict`
    (``k^T K^-1 k`` on tiles) to rounding: tested to 1e-10 of the prior.
    """
    size = expert.cells_[0].size
    if len(expert.cells_) > 1 or size > max(_DENSE_SIZE, len(X)):
        return expert.predict(X, return_var=True)
    cell = expert.cells_[0]
    prior = float(expert.kernel_.variance)
    mean, var = np.empty(len(X)), np.empty(len(X))
    for i in range(0, len(X), _BLOCK):
        x = X[i:i + _BLOCK]
        k = covariance(expert.kernel_, expert._quadrature, cell.obs.starts, cell.obs.ends, x, x,
                        n_threads=expert._n_threads)
        v = sl.solve_triangular(cell.L, k, lower=True, check_finite=False)
        mean[i:i + _BLOCK] = k.T @ cell.alpha
        var[i:i + _BLOCK] = np.maximum(prior - np.einsum("ij,ij->j", v, v), 0.0)
    return mean, var


def split_observations(obs):
    """`obs` as GPOMIK's (hits, segment_starts, segment_ends)."""
    hit = obs.labels > 0
    return obs.starts[hit], obs.starts[~hit], obs.ends[~hit]


def hits_first(obs):
    """`obs` with its hits first (the order GPOMIK keeps)."""
    return obs.take(np.r_[np.flatnonzero(obs.labels > 0), np.flatnonzero(obs.labels < 0)])


def concat_observations(a: Observations, b: Observations) -> Observations:
    return Observations(*(np.concatenate([x, y]) for x, y in zip(a, b)))


def order_positions(is_hit):
    """Position of each observation within :func:`_order` of them (hits first)."""
    order = np.r_[np.flatnonzero(is_hit), np.flatnonzero(~is_hit)]
    pos = np.empty(len(order), dtype=np.intp)
    pos[order] = np.arange(len(order))
    return pos


def downdated(gp, X, pos):
    """Latent mean and variance of single-cell expert `gp` at X[j] without its observation
    pos[j] (:func:`~occgp.gp._cells.downdated_cell`)."""
    return downdated_cell(gp.cells_[0], gp.kernel_, gp._quadrature, gp._n_threads, X, pos)
