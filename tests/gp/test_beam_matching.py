"""match_beams (issue 40): the same answer as testing every hit against every beam,
in memory bounded whatever the tolerance."""

import tracemalloc

import numpy as np
import pytest
from numpy.testing import assert_array_equal
from scipy.spatial import cKDTree

from occgp.gp import _beams
from occgp.gp._beams import match_beams

#: match_beams' stated bound on its working memory beyond arrays of the input's size
#: (its docstring): 2**18 pairs at a time, under 48 MB.
BOUND = 48e6


def reference(hits, starts, ends, tolerance):
    """The documented rule, beam by beam and hit by hit: the first hit equal to the
    end; else, among the hits no beam ends on exactly, the one on the ray (off it by
    at most slack) from slack before the end to tolerance + slack beyond it, nearest
    along the ray, then the lowest index; a zero-length beam matches only exactly."""
    out = np.full(len(ends), -1, dtype=np.int64)
    taken = np.array([(ends == h).all(axis=1).any() for h in hits], dtype=bool)
    for b in range(len(ends)):
        same = np.flatnonzero((hits == ends[b]).all(axis=1))
        if len(same):
            out[b] = same[0]
            continue
        delta = ends[b] - starts[b]
        length = np.linalg.norm(delta)
        if length == 0:
            continue
        u = delta / length
        scale = 1.0 + max(np.abs(starts[b]).max(), np.abs(ends[b]).max()) + length
        slack = 1e-6 * (scale + tolerance)
        best = None
        for h in np.flatnonzero(~taken):
            w = hits[h] - ends[b]
            t = w[0] * u[0]
            for a in range(1, len(w)):
                t += w[a] * u[a]
            off = np.linalg.norm(w - t * u)
            if off <= slack and -slack <= t <= tolerance + slack and (best is None or t < best):
                best, out[b] = t, h
    return out


def random_case(seed, dim, n_beams=120):
    """Beams from random origins: some ending on their hits (exactly), some stopping
    short of them by up to 1.5 m, some without a return; extra hits on and near the
    rays (coinciding hits, hits a rounding off the ray, or just beyond the slack),
    and zero-length beams."""
    rng = np.random.default_rng(seed)
    starts = rng.uniform(-2.0, 2.0, (n_beams, dim))
    d = rng.normal(size=(n_beams, dim))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = rng.uniform(0.5, 4.0, n_beams)
    hits = starts + d * r[:, None]
    kind = rng.integers(0, 4, n_beams)          # 0 exact, 1-2 short, 3 no return
    short = np.where(kind == 1, rng.uniform(0.0, 0.15, n_beams), rng.uniform(0.0, 1.5, n_beams))
    ends = np.where((kind == 0)[:, None], hits, starts + d * np.maximum(r - short, 0.0)[:, None])
    ends[kind == 3] = starts[kind == 3] + d[kind == 3] * 6.0
    extra = [hits[kind != 3]]
    pick = rng.choice(n_beams, 40)
    extra.append(hits[pick])                                  # coinciding hits
    along = starts[pick] + d[pick] * rng.uniform(0.0, 6.0, (40, 1))
    extra.append(along)                                       # more hits on the rays
    normal = rng.normal(size=(40, dim))
    normal -= (normal * d[pick]).sum(axis=1, keepdims=True) * d[pick]
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    off = rng.choice([0.3e-6, 3e-6, 3e-5], (40, 1)) * (1 + 6.0 + np.abs(along).max(axis=1,
                                                                              keepdims=True))
    extra.append(along + normal * off)                        # a rounding (or more) off
    hits = np.concatenate(extra)
    order = rng.permutation(len(hits))
    hits = hits[order]
    zero = rng.choice(n_beams, 5)
    ends[zero] = starts[zero]                                 # zero-length beams
    return hits, starts, ends


@pytest.mark.parametrize("dim", [1, 2, 3])
@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("tolerance", [0.0, 0.1, 0.7, 5.0])
@pytest.mark.parametrize("budget", [None, 7])
def test_match_beams_equals_the_rule_beam_by_beam(dim, seed, tolerance, budget, monkeypatch):
    if budget is not None:                   # tiny chunks: many of them, and single
        monkeypatch.setattr(_beams, "_PAIR_BUDGET", budget)   # centers above the budget
        monkeypatch.setattr(_beams, "_SECTION", 0.03)
    hits, starts, ends = random_case(seed + 10 * dim, dim)
    got = match_beams(hits, starts, ends, hit_tolerance=tolerance)
    expected = reference(hits, starts, ends, tolerance)
    assert_array_equal(got, expected)
    if tolerance >= 0.7:                     # the case matches many stopped-short beams
        assert (got >= 0).sum() > (expected >= 0).sum() // 2 > 20


def test_match_beams_takes_the_nearest_hit_then_the_lowest_index(monkeypatch):
    monkeypatch.setattr(_beams, "_SECTION", 0.1)
    # one beam along x ending at 1; hits beyond at 3.0 (twice), 2.5 (twice) and 1.95
    hits = np.array([[3.0, 0.0], [2.5, 0.0], [2.5, 0.0], [3.0, 0.0], [1.95, 0.0]])
    starts, ends = np.zeros((1, 2)), np.array([[1.0, 0.0]])
    assert match_beams(hits, starts, ends, hit_tolerance=5.0).tolist() == [4]
    assert match_beams(hits[:4], starts, ends, hit_tolerance=5.0).tolist() == [1]
    assert match_beams(hits[:4], starts, ends, hit_tolerance=1.49).tolist() == [-1]
    assert match_beams(hits[[0, 3]], starts, ends, hit_tolerance=2.0).tolist() == [0]


def traced_peak(fn):
    tracemalloc.start()
    try:
        fn()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_large_tolerance_on_many_beams_stays_within_the_stated_bound():
    """The issue's case, scaled down: 6000 beams from the origin, half stopping 5 cm
    short of hits 3 to 4 m away, half without a return, hit_tolerance=5. Matching
    every end with every hit within the tolerance held 5 million pairs (at 24 bytes
    a pair for the table alone 125 MB, about 800 MB in all)."""
    rng = np.random.default_rng(0)
    n = 6000
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = rng.uniform(3.0, 4.0, n)
    ends = d * (r - 0.05)[:, None]
    none = rng.random(n) < 0.5
    ends[none] = d[none] * 8.0
    hits, starts = (d * r[:, None])[~none], np.zeros((n, 3))
    pairs = cKDTree(ends).count_neighbors(cKDTree(hits), 5.0)
    assert pairs * 24 > 2 * BOUND                     # what the old search held, at least
    out = np.empty(0)

    def run():
        nonlocal out
        out = match_beams(hits, starts, ends, hit_tolerance=5.0)

    peak = traced_peak(run)
    assert peak < BOUND
    expected = np.full(n, -1)
    expected[~none] = np.arange(len(hits))
    assert_array_equal(out, expected)


def test_memory_follows_the_pair_budget_where_every_pair_is_a_candidate(monkeypatch):
    """1500 beams along one line through 1500 hits within 1 mm of each other: every
    (beam, hit) pair lies in the beam's capsule and must be examined (2.25 million
    pairs, 54 MB for a table of them), in chunks of the budget."""
    monkeypatch.setattr(_beams, "_PAIR_BUDGET", 2**14)
    rng = np.random.default_rng(1)
    n = 1500
    hits = np.zeros((n, 3))
    hits[:, 0] = rng.uniform(1.0, 1.001, n)
    starts = np.zeros((n, 3))
    starts[:, 0] = -rng.uniform(0.0, 1.0, n)
    ends = np.zeros((n, 3))
    ends[:, 0] = rng.uniform(0.5, 0.9, n)
    out = np.empty(0)

    def run():
        nonlocal out
        out = match_beams(hits, starts, ends, hit_tolerance=3.0)

    peak = traced_peak(run)
    assert peak < 2**14 * 200 + 1e6                  # the budget's pairs, and the input
    assert_array_equal(out, np.full(n, np.argmin(hits[:, 0])))
