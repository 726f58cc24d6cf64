"""thin_observations: the GP maps' policy for observations past their budget."""

import numpy as np
import pytest

from occgp.gp import GPMixture, GPOMIK, thin_observations
from occgp.gp._limits import MAX_MODEL_BYTES


def scans(n_spots=30, per_spot=(1, 5, 40), seed=0):
    """Beams from the origin to hits on spots 0.5 m apart; spot i is seen by
    per_spot[i % 3] beams; plus 20 beams without a return."""
    rng = np.random.default_rng(seed)
    hits = []
    for i in range(n_spots):
        c = np.array([5.0, 0.5 * i])
        hits.append(c + rng.uniform(0, 0.09, (per_spot[i % len(per_spot)], 2)))
    hits = np.vstack(hits)
    free_ends = np.column_stack([np.full(20, -8.0), np.linspace(-3, 3, 20)])
    ends = np.vstack([hits, free_ends])
    starts = np.zeros_like(ends)
    return hits, starts, ends


def test_nothing_is_dropped_within_the_budget():
    hits, starts, ends = scans()
    kh, kb = thin_observations(hits, starts, ends, len(hits) + len(ends))
    assert kh.tolist() == list(range(len(hits))) and kb.tolist() == list(range(len(ends)))


def test_every_place_keeps_beams_and_each_beam_its_hit():
    hits, starts, ends = scans()
    n = len(hits) + len(ends)
    kh, kb = thin_observations(hits, starts, ends, n // 4)
    assert len(kh) + len(kb) <= n // 4
    returning = kb[kb < len(hits)]
    assert sorted(returning.tolist()) == kh.tolist()       # beam i ends on hit i
    spot = np.floor(hits[:, 1] / 0.5).astype(int)
    kept = np.bincount(spot[kh], minlength=30)
    seen = np.bincount(spot, minlength=30)
    assert (kept >= 1).all()                                # every place keeps a beam
    assert (kept[seen == 1] == 1).all()                     # rare places keep all
    assert kept.max() < seen.max()                          # crowded places are thinned
    silent = kb[kb >= len(hits)]
    rate = len(returning) / len(hits)
    assert abs(len(silent) - rate * 20) <= 1                # silent beams at the same rate


def test_cells_grow_when_one_beam_a_place_is_over_budget():
    hits, starts, ends = scans()
    kh, kb = thin_observations(hits, starts, ends, 12)
    assert 2 <= len(kh) + len(kb) <= 12


def test_the_draw_follows_the_seed():
    hits, starts, ends = scans()
    a = thin_observations(hits, starts, ends, 100, random_state=1)
    b = thin_observations(hits, starts, ends, 100, random_state=1)
    c = thin_observations(hits, starts, ends, 100, random_state=2)
    assert all(np.array_equal(x, y) for x, y in zip(a, b))
    assert not np.array_equal(a[0], c[0])


@pytest.mark.parametrize("kwargs, error, match", [
    (dict(max_observations=1), ValueError, "max_observations must be at least 2"),
    (dict(max_observations=2.5), TypeError, "max_observations must be an int"),
    (dict(max_observations=10, cell_size=0.0), ValueError, "cell_size must lie in"),
])
def test_bad_arguments(kwargs, error, match):
    hits, starts, ends = scans()
    with pytest.raises(error, match=match):
        thin_observations(hits, starts, ends, **kwargs)


@pytest.mark.slow
def test_gpomik_fits_the_observations_thinning_keeps():
    hits, starts, ends = scans()
    n = len(hits) + len(ends)
    budget = n // 3
    model = GPOMIK(optimizer=False, max_observations=budget, random_state=0).fit(
        hits, starts, ends)
    kh, kb = thin_observations(hits, starts, ends, budget,
                               random_state=np.random.default_rng(0))
    kept = np.vstack([c.obs.ends for c in model.cells_])
    assert model.n_accepted_ == len(kh) + len(kb) and model.n_rejected_ == n - model.n_accepted_
    np.testing.assert_array_equal(kept, np.vstack([hits[kh], ends[kb]]))
    # within the budget nothing changes: the same model as without one
    full = GPOMIK(optimizer=False, max_observations=None, random_state=0).fit(hits, starts, ends)
    same = GPOMIK(optimizer=False, max_observations=n, random_state=0).fit(hits, starts, ends)
    X = np.column_stack([np.linspace(0, 6, 50), np.linspace(-1, 15, 50)])
    np.testing.assert_array_equal(full.predict_proba(X), same.predict_proba(X))
    assert full.n_rejected_ == 0


@pytest.mark.slow
def test_mixture_clusters_the_observations_thinning_keeps():
    hits, starts, ends = scans()
    n = len(hits) + len(ends)
    model = GPMixture(max_observations=n // 3, random_state=0).fit(hits, starts, ends)
    assert len(model.labels_) <= n // 3
    assert sum(e.n_accepted_ for e in model.experts_) == len(model.labels_)
    p = model.predict_proba(hits[:5])
    assert np.isfinite(p).all()
    full = GPMixture(max_observations=None, random_state=0).fit(hits, starts, ends)
    assert len(full.labels_) == n


@pytest.mark.parametrize("make", [
    lambda: GPOMIK(optimizer=False, max_observations=None, max_cell_size=None),
    lambda: GPMixture(max_observations=None, max_cluster_size=10 ** 9)])
def test_models_past_the_size_limit_are_refused_before_any_work(make):
    n = int(np.sqrt(MAX_MODEL_BYTES / 8)) + 1                  # one model of n: just past it
    hits = np.column_stack([np.full(n, 5.0), np.linspace(0, 100, n)])
    with pytest.raises(ValueError, match="Cholesky factors.*set max_observations"):
        make().fit(hits, np.zeros_like(hits), hits)


@pytest.mark.parametrize("cls", [GPOMIK, GPMixture])
@pytest.mark.parametrize("bad, err", [(1, ValueError), (2.5, TypeError), ("10", TypeError)])
def test_max_observations_is_checked(cls, bad, err):
    hits, starts, ends = scans()
    with pytest.raises(err, match="max_observations"):
        cls(max_observations=bad).fit(hits, starts, ends)
