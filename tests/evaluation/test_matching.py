"""The authors' ±1-cell one-to-one true-positive rule (occgp.evaluation.matched_counts)."""


import numpy as np
import pytest

from occgp.evaluation import MatchedCounts, matched_counts
from occgp.octree._queries import pack_keys


def slow_counts(pred, ref, scored):
    """The rule of matched_counts, written out with sets and loops."""
    pred, ref, scored = ({tuple(map(int, k)) for k in a} for a in (pred, ref, scored))
    pred = pred & scored
    offsets = [(0, 0, 0)] + [(dx, dy, dz) for dz in (1, 0, -1) for dx in (1, 0, -1)
                             for dy in (1, 0, -1) if (dx, dy, dz) != (0, 0, 0)]
    sweep = sorted(pred)
    matched, taken = set(), set()
    for off in offsets:
        claims = {}
        for c in sweep:
            if c in matched:
                continue
            t = (c[0] + off[0], c[1] + off[1], c[2] + off[2])
            if t in ref and t not in taken and t not in claims:
                claims[t] = c
        for t, c in claims.items():
            matched.add(c)
            taken.add(t)
    tp = len(matched)
    fn = len((ref & scored) - pred)
    tn = len(scored - ref - pred)
    return tp, len(pred) - tp, fn, tn


def test_hand_built_neighbour_match():
    ref = [[10, 10, 10], [11, 10, 10]]
    got = matched_counts([[10, 10, 10], [10, 11, 10], [10, 12, 10]], ref)
    # (10,10,10) matches itself, (10,11,10) the diagonal (11,10,10), (10,12,10) nothing;
    # (11,10,10) is occupied and not predicted: an exact-cell false negative
    assert got == MatchedCounts(2, 1, 1, 0, 2 / 3, 1 / 3)


def test_one_to_one():
    # two predicted cells next to one reference cell: one true positive only
    got = matched_counts([[5, 5, 5], [5, 5, 6]], [[5, 5, 7]], scored=[[5, 5, 5], [5, 5, 6]])
    assert got[:4] == (1, 1, 0, 0)


def test_offsets_in_order():
    # (4, 4, 4) reaches (4, 4, 5) at dz=+1, (4, 4, 6) at dz=-1 (later): one match
    got = matched_counts([[4, 4, 4], [4, 4, 6]], [[4, 4, 5]])
    assert got[:2] == (1, 1)


def test_perfect_prediction_scores_every_cell():
    rng = np.random.default_rng(0)
    cells = np.unique(rng.integers(100, 110, (300, 3)), axis=0)
    got = matched_counts(cells, cells)
    assert got[:4] == (len(cells), 0, 0, 0) and got.tpr == 1.0 and got.fdr == 0.0


def test_scored_cells_and_true_negatives():
    scored = [[0, 0, 0], [3, 0, 0], [6, 0, 0], [9, 0, 0]]
    # predicted (0,0,0) matches the unscored reference cell (1,0,0); (6,0,0) is a FN,
    # (9,0,0) a TN, (3,0,0) a FP; the predicted cell (20,0,0) is not scored
    got = matched_counts([[0, 0, 0], [3, 0, 0], [20, 0, 0]], [[1, 0, 0], [6, 0, 0]], scored)
    assert got == MatchedCounts(1, 1, 1, 1, 0.5, 0.5)


def test_packed_keys_equal_unpacked():
    a = np.array([[1, 2, 3], [2, 2, 3], [7, 7, 7]])
    b = np.array([[1, 3, 3], [7, 8, 8]])
    assert matched_counts(pack_keys(a), pack_keys(b)) == matched_counts(a, b)


def test_key_range_edges():
    got = matched_counts([[0, 0, 0], [65535, 65535, 65535]], [[65535, 65534, 65535]])
    assert got[:2] == (1, 1)


@pytest.mark.parametrize("seed", range(6))
def test_against_slow_reference(seed):
    rng = np.random.default_rng(seed)
    box = rng.integers(0, 6, (400, 3))
    scored = np.unique(box[:200], axis=0)
    ref = box[rng.random(400) < 0.3]
    pred = box[rng.random(400) < 0.4]
    got = matched_counts(pred, ref, scored)
    assert got[:4] == slow_counts(pred, ref, scored)


def test_empty_inputs():
    got = matched_counts(np.empty((0, 3), int), [[1, 1, 1]])
    assert got[:4] == (0, 0, 1, 0) and np.isnan(got.fdr) and got.tpr == 0.0


@pytest.mark.parametrize("args, exc, msg", [
    (([[0.5, 0, 0]], [[0, 0, 0]]), TypeError, "predicted must hold integer keys"),
    (([[0, 0, 0]], [[0, 0]]), ValueError, "reference must be packed keys"),
    (([[0, 0, 0]], [[0, 0, 0]], [[-1, 0, 0]]), ValueError, r"scored keys must lie in"),
    (([1 << 50], [[0, 0, 0]]), ValueError, "predicted packed keys must fit"),
])
def test_bad_keys(args, exc, msg):
    with pytest.raises(exc, match=msg):
        matched_counts(*args)


