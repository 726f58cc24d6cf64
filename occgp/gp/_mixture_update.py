"""GPMixture's incremental side: new observations clustered into the experts they reach,
which are Cholesky-updated or refitted (:meth:`GPMixture.update`), as a mixin of
:class:`occgp.gp.GPMixture`."""

from __future__ import annotations

import copy

import numpy as np
from joblib import delayed
from numpy.typing import ArrayLike
from scipy.spatial import cKDTree
from sklearn.utils.validation import check_is_fitted
from threadpoolctl import threadpool_limits

from .._docfill import fill_doc
from ._beams import match_call
from ._cells import spatial_groups
from ._experts import concat_observations, fit_expert, hits_first, one_cell, split_observations
from ._observations import make_observations

__all__ = ["GPMixtureUpdates"]


@fill_doc()
class GPMixtureUpdates:
    """The update methods of :class:`~occgp.gp.GPMixture` (a mixin; it holds no state)."""

    # --------------------------------------------------------------- update
    def update(self, hits: ArrayLike | None = None, segment_starts: ArrayLike | None = None,
               segment_ends: ArrayLike | None = None, *,
               beam_hits: ArrayLike | None = None) -> "GPMixture":
        """Add observations: cluster them and update only the experts they reach.

        New hits are clustered incrementally (``clustering_.partial_fit``:
        they join existing clusters or open new ones); beams follow as in
        :meth:`fit`, with the returning beams of earlier calls as candidates.
        A new cluster with fewer than `min_hits` hits or `min_size`
        observations (or no beam) joins the
        expert nearest to it; a new cluster of its own gets a new expert. An
        existing expert that received observations is Cholesky-updated
        (``update_experts="cholesky"``, its hyper-parameters as fitted) or
        refitted on all its observations (``"refit"``); every other expert
        is left untouched (the same object, unchanged). The PLSC stays as
        fitted. :attr:`updated_experts_` lists the experts changed or created.
        Beams end at their hits or stop short of them, as in :meth:`fit`;
        without `beam_hits` their hits are sought among the hits of every
        call so far.

        {update_parameters}
        beam_hits : array-like of int of shape (n_beams,), default=None
            Each new beam's hit, as an index into this call's `hits`, or -1
            for a beam without a return; replaces the matching.

        Returns
        -------
        self : GPMixture

        Raises
        ------
        ValueError, TypeError
            As :meth:`fit`; the model is then unchanged.
        """
        check_is_fitted(self, "experts_")
        with threadpool_limits(1):
            return self._update(hits, segment_starts, segment_ends, beam_hits=beam_hits)

    def _update(self, hits, segment_starts, segment_ends, beam_hits=None, matched=None):
        self._check_params()
        template = self._expert_template
        new = make_observations(hits, segment_starts, segment_ends, dim=self.n_dims_)
        n_hits = int(np.count_nonzero(new.labels > 0))
        matched = match_call(new, n_hits, beam_hits, matched, self._observations,
                             self._beam_hits, self.hit_tolerance)
        if not len(new.y):
            return self
        clustering = copy.deepcopy(self.clustering_)  # the fitted one stays as it is on failure
        hit_labels, beam_labels, where = self._cluster_labels(clustering, new, n_hits,
                                                              partial=True, matched=matched)
        clusters = np.r_[hit_labels, beam_labels]
        expert_of = np.empty(len(new.y), dtype=np.int64)
        experts, next_id = list(self.experts_), len(self.experts_)
        old_tree = cKDTree(self._observations.anchors)
        old_labels = self.labels_
        cluster_experts = {c: set(s) for c, s in self._cluster_experts.items()}
        new_groups = {}
        for c in np.unique(clusters):
            idx = np.flatnonzero(clusters == c)
            known = cluster_experts.get(int(c))
            if known:
                cand = sorted(known)
                if len(cand) == 1:
                    expert_of[idx] = cand[0]
                else:  # a split cluster: the expert with the nearest observation
                    _, near = old_tree.query(new.anchors[idx])
                    owner = old_labels[near]
                    expert_of[idx] = np.where(np.isin(owner, cand), owner, cand[0])
                continue
            n_c_hits = int(np.count_nonzero(new.labels[idx] > 0))
            if n_c_hits < self.min_hits or n_c_hits == len(idx) or len(idx) < self.min_size:
                _, near = old_tree.query(new.anchors[idx])
                dist = np.linalg.norm(new.anchors[idx] - self._observations.anchors[near],
                                      axis=1)
                target = int(old_labels[near[int(np.argmin(dist))]])
                expert_of[idx] = target
                cluster_experts[int(c)] = {target}
                continue
            cluster_experts[int(c)] = set()
            for part in sorted(spatial_groups(where[idx], self.max_cluster_size,
                                              new.labels[idx] > 0),
                               key=lambda p: int(p.min())):
                expert_of[idx[part]] = next_id
                cluster_experts[int(c)].add(next_id)
                new_groups[next_id] = np.sort(idx[part])
                next_id += 1
        changed = np.unique(expert_of)
        old_changed = changed[changed < len(self.experts_)]
        fresh = [int(e) for e in changed if e >= len(self.experts_)]
        all_obs = concat_observations(self._observations, new)
        all_labels = np.r_[self.labels_, expert_of]

        def grow(e):
            gp = self.experts_[e]
            if self.update_experts == "refit":
                return fit_expert(template, hits_first(all_obs.take(all_labels == e)),
                                   self._expert_seed(e))
            return copy.deepcopy(gp).update(*split_observations(new.take(expert_of == e)))

        grown = self._parallel()(delayed(grow)(int(e)) for e in old_changed)
        made = self._parallel()(
            delayed(fit_expert)(one_cell(template, len(new_groups[e])),
                                hits_first(new.take(new_groups[e])), self._expert_seed(e))
            for e in fresh)
        # every step that can fail is done: now change the model
        for e, gp in zip(old_changed, grown):
            experts[int(e)] = gp
        experts += list(made)
        self.experts_ = experts
        self.clustering_ = clustering
        stale = set(changed.tolist())
        self._reach = [None if i in stale else r for i, r in enumerate(self._reach)]
        self._reach += [None] * len(made)
        self.labels_ = all_labels
        self._observations = all_obs
        self._calls = self._calls + [len(new.y)]
        self._hit_clusters = np.r_[self._hit_clusters, hit_labels]
        self._beam_hits = np.r_[self._beam_hits, matched]
        self._cluster_experts = cluster_experts
        self.n_clusters_ = int(getattr(self.clustering_, "n_clusters_", self.n_clusters_))
        self.updated_experts_ = changed
        return self
