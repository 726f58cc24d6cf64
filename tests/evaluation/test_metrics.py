import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from sklearn import metrics as skm

from occgp import metrics

from occgp.metrics import (
    accuracy,
    mse,
    roc_auc,
    roc_curve,
    score_all,
    tpr_fdr_auc,
    tpr_fdr_curve,
)

ALL = [roc_curve, roc_auc, mse, accuracy, tpr_fdr_curve, tpr_fdr_auc, score_all]


@pytest.fixture
def noisy():
    """Labels and noisy, tied and partly unknown probabilities."""
    rng = np.random.default_rng(0)
    y = rng.random(300) < 0.3
    p = np.clip(0.5 + 0.3 * (y - 0.5) + rng.normal(0, 0.25, 300), 0, 1)
    p = np.round(p, 1)  # many ties
    p[rng.random(300) < 0.1] = np.nan
    return y, p


# --------------------------------------------------------------------- ROC
def test_roc_auc_hand_computed():
    # pairs (occ, free): (0.4 vs 0.1) win, (0.4 vs 0.6) loss, 0.9 wins both
    assert roc_auc([0, 0, 1, 1], [0.1, 0.6, 0.4, 0.9]) == pytest.approx(0.75)
    # a tie counts one half
    assert roc_auc([0, 1], [0.3, 0.3]) == pytest.approx(0.5)


@pytest.mark.parametrize("kind, expected", [("perfect", 1.0), ("inverted", 0.0)])
def test_roc_auc_perfect_and_inverted(kind, expected):
    rng = np.random.default_rng(0)
    y = rng.random(200) < 0.4
    p = np.where(y, rng.uniform(0.6, 1, 200), rng.uniform(0, 0.4, 200))
    if kind == "inverted":
        p = 1 - p
    assert roc_auc(y, p) == pytest.approx(expected)


def test_roc_auc_random_is_about_half():
    rng = np.random.default_rng(0)
    y = rng.random(4000) < 0.5
    assert roc_auc(y, rng.random(4000)) == pytest.approx(0.5, abs=0.03)


def test_roc_matches_sklearn_with_nan_as_half(noisy):
    y, p = noisy
    filled = np.where(np.isnan(p), 0.5, p)
    assert roc_auc(y, p) == pytest.approx(skm.roc_auc_score(y, filled))
    fpr, tpr, thr = roc_curve(y, p)
    ref = skm.roc_curve(y, filled)
    for got, want in zip((fpr, tpr, thr), ref):
        assert_allclose(got, want)
    assert np.trapezoid(tpr, fpr) == pytest.approx(roc_auc(y, p))


def test_roc_curve_keeps_every_threshold_on_request():
    y, p = [0, 0, 1, 1, 1], [0.1, 0.2, 0.3, 0.4, 0.5]
    fpr, tpr, thr = roc_curve(y, p, drop_intermediate=False)
    assert len(thr) == 6 and np.isinf(thr[0])
    assert np.all(np.diff(fpr) >= 0) and np.all(np.diff(tpr) >= 0)


def test_labels_may_be_bool_int_or_float():
    p = [0.2, 0.8, 0.4]
    for y in ([False, True, False], [0, 1, 0], [0.0, 1.0, 0.0]):
        assert roc_auc(y, p) == 1.0


# --------------------------------------------------------------- MSE / acc
def test_mse_hand_computed_and_unknown_costs_quarter():
    assert mse([1, 0, 1], [1.0, 0.0, 0.5]) == pytest.approx(0.25 / 3)
    assert mse([1, 0], [np.nan, np.nan]) == pytest.approx(0.25)
    assert mse([True, False], [0.9, 0.3]) == pytest.approx((0.01 + 0.09) / 2)


def test_accuracy_hand_computed():
    y = [1, 1, 1, 0, 0]
    p = [0.9, 0.6, 0.2, 0.1, 0.7]
    acc_occ, acc_free = accuracy(y, p)
    assert acc_occ == pytest.approx(2 / 3)
    assert acc_free == pytest.approx(1 / 2)


def test_accuracy_is_strict_at_threshold_and_unknown_is_wrong_for_both():
    y = [1, 0, 1, 0]
    p = [0.5, 0.5, np.nan, np.nan]
    assert accuracy(y, p) == (0.0, 0.0)
    # just off the threshold is right again
    assert accuracy(y, [0.5 + 1e-9, 0.5 - 1e-9, 1, 0]) == (1.0, 1.0)


def test_accuracy_custom_threshold_and_missing_class():
    assert accuracy([1, 0], [0.75, 0.65], threshold=0.7) == (1.0, 1.0)
    acc_occ, acc_free = accuracy([0, 0], [0.2, 0.6])
    assert np.isnan(acc_occ) and acc_free == 0.5


# ----------------------------------------------------------------- TPR-FDR
def test_tpr_fdr_curve_hand_computed():
    fdr, tpr, thr = tpr_fdr_curve([1, 0, 1, 0], [0.9, 0.7, 0.6, 0.1])
    assert_allclose(fdr, [0, 0, 1 / 2, 1 / 3, 1 / 2])
    assert_allclose(tpr, [0, 0.5, 0.5, 1, 1])
    assert_array_equal(thr, [np.inf, 0.9, 0.7, 0.6, 0.1])


def test_tpr_fdr_curve_ties_move_together():
    fdr, tpr, thr = tpr_fdr_curve([1, 0, 1, 1], [0.8, 0.8, 0.8, 0.3])
    assert_allclose(fdr, [0, 1 / 3, 1 / 4])
    assert_allclose(tpr, [0, 2 / 3, 1])
    assert_array_equal(thr, [np.inf, 0.8, 0.3])


def test_tpr_fdr_auc_perfect_is_one_and_monotone_in_quality():
    y = np.array([1, 1, 1, 0, 0, 0, 0, 0])
    perfect = np.array([0.9, 0.8, 0.7, 0.4, 0.3, 0.2, 0.1, 0.05])
    assert tpr_fdr_auc(y, perfect) == pytest.approx(1.0)
    # swapping an occupied point below more and more free points only hurts
    aucs = []
    for k in range(4):
        p = perfect.copy()
        p[2] = [0.7, 0.35, 0.25, 0.01][k]
        aucs.append(tpr_fdr_auc(y, p))
    assert np.all(np.diff(aucs) < 0)
    assert all(0 <= a <= 1 for a in aucs)


def test_tpr_fdr_auc_hand_computed():
    # path (0,0) (0,.5) (.5,.5) (1/3,1) (.5,1) + (1,1); the fold counts with sign
    expected = 0.5 * 0.5 + (1 / 3 - 0.5) * 0.75 + (0.5 - 1 / 3) + 0.5
    assert tpr_fdr_auc([1, 0, 1, 0], [0.9, 0.7, 0.6, 0.1]) == pytest.approx(expected)


def test_tpr_fdr_auc_equals_trapezoidal_precision_recall_area(noisy):
    y, p = noisy
    precision, recall, _ = skm.precision_recall_curve(y, np.where(np.isnan(p), 0.5, p))
    assert tpr_fdr_auc(y, p) == pytest.approx(skm.auc(recall, precision))


def test_tpr_fdr_auc_random_is_about_the_occupied_fraction():
    rng = np.random.default_rng(0)
    y = rng.random(4000) < 0.2
    assert tpr_fdr_auc(y, rng.random(4000)) == pytest.approx(y.mean(), abs=0.03)


def test_tpr_fdr_only_occupied_points_is_defined():
    assert tpr_fdr_auc([1, 1], [0.2, 0.9]) == pytest.approx(1.0)


# ---------------------------------------------------------------- score_all
def test_score_all_agrees_with_single_metrics(noisy):
    y, p = noisy
    s = score_all(y, p)
    assert set(s) == {"auc", "mse", "acc_occupied", "acc_free", "tpr_fdr_auc",
                      "n_test", "unknown_fraction"}
    assert s["auc"] == pytest.approx(roc_auc(y, p))
    assert s["mse"] == pytest.approx(mse(y, p))
    assert (s["acc_occupied"], s["acc_free"]) == accuracy(y, p)
    assert s["tpr_fdr_auc"] == pytest.approx(tpr_fdr_auc(y, p))
    assert s["n_test"] == 300
    assert s["unknown_fraction"] == pytest.approx(np.isnan(p).mean())


def test_score_all_threshold():
    s = score_all([1, 0], [0.4, 0.2], threshold=0.3)
    assert (s["acc_occupied"], s["acc_free"]) == (1.0, 1.0)


# ---------------------------------------------------------------- bad input
@pytest.mark.parametrize("func", ALL)
def test_length_mismatch(func):
    with pytest.raises(ValueError, match="same length, got 3 and 2"):
        func([0, 1, 1], [0.1, 0.2])


@pytest.mark.parametrize("func", ALL)
@pytest.mark.parametrize("bad", [1.5, -0.1, np.inf])
def test_probabilities_outside_unit_interval(func, bad):
    with pytest.raises(ValueError, match=r"y_prob must be probabilities in \[0, 1\]"):
        func([0, 1, 1], [0.1, bad, 0.2])


@pytest.mark.parametrize("func", ALL)
def test_two_dimensional_input(func):
    with pytest.raises(ValueError, match=r"y_true must have shape \(n_points,\), got \(2, 1\)"):
        func([[0], [1]], [0.1, 0.2])
    with pytest.raises(ValueError, match=r"y_prob must have shape \(n_points,\), got \(1, 2\)"):
        func([0, 1], [[0.1, 0.2]])


@pytest.mark.parametrize("func", ALL)
def test_empty_input(func):
    with pytest.raises(ValueError, match="must not be empty"):
        func([], [])


@pytest.mark.parametrize("func", ALL)
def test_labels_not_binary(func):
    with pytest.raises(ValueError, match=r"y_true must hold only 0/1 or booleans, got \[2\]"):
        func([0, 1, 2], [0.1, 0.2, 0.3])
    with pytest.raises(ValueError, match="y_true must hold only 0/1"):
        func([0, 1, np.nan], [0.1, 0.2, 0.3])


@pytest.mark.parametrize("func", ALL)
def test_non_numeric_input(func):
    with pytest.raises(TypeError, match="y_true must hold real numbers or booleans"):
        func(["a", "b"], [0.1, 0.2])
    with pytest.raises(TypeError, match="y_prob must hold real numbers or booleans"):
        func([0, 1], ["x", "y"])


@pytest.mark.parametrize("func", [roc_curve, roc_auc, score_all])
@pytest.mark.parametrize("y, present", [([1, 1], "occupied"), ([0, 0], "free")])
def test_single_class_for_roc(func, y, present):
    with pytest.raises(ValueError, match=f"needs both occupied and free.*only {present}"):
        func(y, [0.2, 0.7])


@pytest.mark.parametrize("func", [tpr_fdr_curve, tpr_fdr_auc])
def test_tpr_fdr_needs_an_occupied_point(func):
    with pytest.raises(ValueError, match="at least one occupied test point"):
        func([0, 0], [0.2, 0.7])


@pytest.mark.parametrize("func", [accuracy, score_all])
def test_bad_threshold(func):
    with pytest.raises(ValueError, match=r"threshold must lie in \[0.0, 1.0\], got 1.5"):
        func([0, 1], [0.2, 0.7], threshold=1.5)
    with pytest.raises(TypeError, match="threshold must be a real number, got str"):
        func([0, 1], [0.2, 0.7], threshold="half")
    # a bool is no threshold (True would otherwise be taken as 1.0)
    with pytest.raises(TypeError, match="threshold must be a real number, got bool"):
        func([0, 1], [0.2, 0.7], threshold=True)


# ------------------------------------------------------------ anchored / unanchored area
def test_tpr_fdr_unanchored_curve_drops_the_origin():
    y, p = [1, 0, 1, 0], [0.9, 0.7, 0.6, 0.1]
    fdr, tpr, thr = metrics.tpr_fdr_curve(y, p, anchored=False)
    assert fdr.tolist() == [0.0, 0.5, 1 / 3, 0.5]
    assert tpr.tolist() == [0.5, 0.5, 1.0, 1.0]
    assert thr.tolist() == [0.9, 0.7, 0.6, 0.1]


def test_tpr_fdr_unanchored_area_by_hand():
    y, p = [1, 0, 1, 0], [0.9, 0.7, 0.6, 0.1]
    # points (0, .5), (.5, .5), (1/3, 1), (.5, 1): .25 - .125 + 1/6
    assert metrics.tpr_fdr_auc(y, p, anchored=False) == pytest.approx(0.25 - 0.125 + 1 / 6,
                                                                      abs=1e-15)
    # anchored: + the segment from (0, 0) to (0, .5) (area 0) and (.5, 1) -> (1, 1): .5
    assert metrics.tpr_fdr_auc(y, p) == pytest.approx(0.25 - 0.125 + 1 / 6 + 0.5, abs=1e-15)
    # one operating point: no area
    assert metrics.tpr_fdr_auc([1, 0], [0.5, 0.5], anchored=False) == 0.0


def test_tpr_fdr_anchored_must_be_bool():
    with pytest.raises(TypeError, match="anchored must be a bool"):
        metrics.tpr_fdr_auc([1, 0], [0.9, 0.1], anchored=1)
    with pytest.raises(TypeError, match="anchored must be a bool"):
        metrics.tpr_fdr_curve([1, 0], [0.9, 0.1], anchored="no")
