"""GPOMIK's incremental side: KL gains of new observations and the Cholesky updates
that add them (:meth:`GPOMIK.update`, :meth:`GPOMIK.kl_divergence`), as a mixin of
:class:`occgp.gp.GPOMIK`."""

from __future__ import annotations

import numpy as np
import scipy.linalg as sl
from numpy.typing import ArrayLike
from sklearn.utils.validation import check_is_fitted

from .._docfill import fill_doc
from ._cells import Cell, kl_gain
from ._gpr import cholesky, solve_lower
from ._integral_kernel import covariance
from ._limits import check_dense
from ._observations import Observations, check_beam_hits, make_observations

__all__ = ["GPOMIKUpdates"]


@fill_doc()
class GPOMIKUpdates:
    """The update methods of :class:`~occgp.gp.GPOMIK` (a mixin; it holds no state)."""

    # ---------------------------------------------------------------- update
    def _cross(self, obs_a, obs_b):
        return covariance(self.kernel_, self._quadrature, obs_a.starts, obs_a.ends,
                           obs_b.starts, obs_b.ends, n_threads=self._n_threads)

    def _extend(self, cell, new, K12=None, K22=None):
        """Cholesky update of Eq. 11–13: append `new` to `cell`.

        `K12` (cell x new) and `K22` (new x new, without noise) are computed
        unless given.
        """
        if K12 is None:
            K12 = self._cross(cell.obs, new)
        if K22 is None:
            K22 = covariance(self.kernel_, self._quadrature, new.starts, new.ends,
                              n_threads=self._n_threads)
        m = len(K22)
        K22 = K22 + (self.noise_ + self.jitter_) * np.eye(m)
        S12 = sl.solve_triangular(cell.L, K12, lower=True, check_finite=False)
        S22 = cholesky(K22 - S12.T @ S12, self.kernel_, self.noise_,
                       f"the {m} new observations given the newest local model")
        n = cell.size
        L = np.zeros((n + m, n + m))
        L[:n, :n] = cell.L
        L[n:, :n] = S12.T
        L[n:, n:] = S22
        obs = Observations(*(np.concatenate([a, b]) for a, b in zip(cell.obs, new)))
        # forward solution L^-1 y grows by one block; one backward solve gives alpha
        z_old = sl.solve_triangular(cell.L, cell.obs.y, lower=True, check_finite=False)
        z_new = sl.solve_triangular(S22, new.y - S12.T @ z_old, lower=True, check_finite=False)
        alpha = solve_lower(L, obs.y, np.r_[z_old, z_new])
        return Cell(obs, L, alpha)

    def kl_divergence(self, hits=None, segment_starts=None, segment_ends=None):
        """KL divergence that adding each observation would bring to the map.

        Observations are taken in order (hits first, then beams, each in
        input order). For observation ``j`` with latent prediction
        ``N(mu, var)`` given the map and the observations before it in this
        batch, and ``N(mu', var')`` after conditioning on its target with the
        noise variance: ``KL(after || before) = log(sqrt(var / var')) +
        (var' + (mu' - mu)**2) / (2 var) - 1/2``. For a beam, the latent is
        the integral along it. The newest cell conditions on the batch too
        (one Cholesky factor of the batch's predictive covariance gives every
        sequential prediction at once); an older cell whose box holds the
        observation gives its own divergence, and the smallest one counts.
        The model is not changed.

        {update_parameters}

        Returns
        -------
        kl : ndarray of shape (n_hits + n_beams,)
            One divergence per observation, hits first.

        Raises
        ------
        NotFittedError
            If called before :meth:`fit`.
        ValueError, TypeError
            As :meth:`update`, also when the batch's covariance with the
            largest cell would take more than 4 GiB.
        numpy.linalg.LinAlgError
            (a ValueError) If the batch's predictive covariance cannot be
            factorised.
        """
        new = self._new_observations(hits, segment_starts, segment_ends, kl=True)
        return self._kl(new)[0]

    def _new_observations(self, hits, segment_starts, segment_ends, kl):
        """Validated observations for :meth:`update` and :meth:`kl_divergence`."""
        check_is_fitted(self, "cells_")
        new = make_observations(hits, segment_starts, segment_ends, dim=self.n_dims_)
        self._check_observations(new, self.kernel_)
        if kl:  # the batch's covariance and its blocks against a cell
            m, n = len(new.y), max(cell.size for cell in self.cells_)
            check_dense(m, 3 * m + 2 * n, 1, f"the divergences of {m} new observations",
                        "pass fewer observations at a time")
        return new

    def _kl(self, new):
        """KL gains of `new`, and the newest cell's blocks K12 and K22 (no noise)."""
        noise = self.noise_ + self.jitter_
        K22 = covariance(self.kernel_, self._quadrature, new.starts, new.ends,
                          n_threads=self._n_threads)
        prior = np.diag(K22)
        margin = 3.0 / self.kernel_.inverse_length_scales(self.n_dims_)
        kl = np.full(len(new.y), np.inf)
        for i, cell in enumerate(self.cells_):
            newest = i == len(self.cells_) - 1
            if newest:
                take = np.arange(len(new.y))
            else:
                lo, hi = cell.bounds(margin)
                take = np.flatnonzero(np.all((new.anchors >= lo) & (new.anchors <= hi), axis=1))
                if not len(take):
                    continue
            sub = new.take(take)
            K12 = self._cross(cell.obs, sub)
            S12 = sl.solve_triangular(cell.L, K12, lower=True, check_finite=False)
            mu = K12.T @ cell.alpha
            if newest:  # y_j given the cell and y_<j: one factor of the batch's covariance
                K12_newest = K12
                C = K22 - S12.T @ S12
                C[np.diag_indices_from(C)] += noise
                Lc = cholesky(C, self.kernel_, self.noise_,
                              f"the {len(sub.y)} new observations given the newest local model")
                z = sl.solve_triangular(Lc, sub.y - mu, lower=True, check_finite=False)
                d = np.diag(Lc)
                mu, var = sub.y - d * z, d * d - noise
            else:
                var = prior[take] - np.einsum("ij,ij->j", S12, S12)
            kl[take] = np.minimum(kl[take], kl_gain(np.maximum(var, 1e-300), mu, sub.y, noise))
        return kl, K12_newest, K22

    def update(self, hits: ArrayLike | None = None, segment_starts: ArrayLike | None = None,
               segment_ends: ArrayLike | None = None, *,
               beam_hits: ArrayLike | None = None) -> "GPOMIK":
        """Add observations by Cholesky updates, with active sampling.

        With `kl_threshold` set, observations whose KL divergence (see
        :meth:`kl_divergence`: given the map and the earlier observations of
        this call) is below it are rejected. The accepted ones join the newest
        cell, its factor grown by Eq. 11–13 of the paper (``O(n^2)`` instead
        of ``O(n^3)``); past `max_cell_size` the rest start new cells (split
        spatially when more than one cell's worth). Hyper-parameters and PLSC
        stay as fitted. Beams may end at their hits or stop short of them,
        as in :meth:`fit`.

        {update_parameters}
        beam_hits : array-like of int of shape (n_beams,), default=None
            Each new beam's hit (an index into this call's `hits`), or -1;
            checked, otherwise unused (see :meth:`fit`).

        Returns
        -------
        self : GPOMIK

        Raises
        ------
        ValueError, TypeError
            As :meth:`fit`, also for observations beyond the limits of the
            fitted kernel (see the class docstring); the model is then
            unchanged (every fitted attribute).
        numpy.linalg.LinAlgError
            (a ValueError) If the grown covariance cannot be factorised; the
            model is then unchanged.
        """
        new = self._new_observations(hits, segment_starts, segment_ends,
                                     kl=self.kl_threshold is not None)
        if beam_hits is not None:
            n_hits = int(np.count_nonzero(new.labels > 0))
            check_beam_hits(beam_hits, len(new.y) - n_hits, n_hits)
        keep = np.arange(len(new.y))
        K12 = K22 = None
        if self.kl_threshold is not None and len(new.y):
            kl, K12, K22 = self._kl(new)  # the blocks serve the Cholesky update below
            keep = np.flatnonzero(kl >= float(self.kl_threshold))
        n_rejected = len(new.y) - len(keep)
        cells = list(self.cells_)
        if len(keep):
            room = len(keep) if self.max_cell_size is None \
                else self.max_cell_size - self.cells_[-1].size
            self._check_cell_size(min(max(room, 0), len(keep)), self.cells_[-1].size)
            rest = keep[max(room, 0):]
            if len(rest):
                self._check_cell_size(len(rest))
            if room > 0:
                head = keep[:room]
                cells[-1] = self._extend(
                    self.cells_[-1], new.take(head), None if K12 is None else K12[:, head],
                    None if K22 is None else K22[np.ix_(head, head)])
            if len(rest):
                cells += self._make_cells(new.take(rest), self.kernel_, self.noise_,
                                          self.jitter_, self._quadrature, self._n_threads)
        # every step that can fail is done: now change the model
        self.cells_[:] = cells
        self.n_accepted_ += len(keep)
        self.n_rejected_ += n_rejected
        return self
