"""Tests of the committee rules that merge GP experts (occgp.gp._committee)."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from occgp.gp import COMBINE_RULES, combine_predictions
from occgp.gp._committee import Committee

# two experts at one query: means, variances, priors
MU = np.array([[0.8], [-0.2]])
VAR = np.array([[0.2], [0.5]])
PRIOR = np.array([1.0, 2.0])


def hand(rule):
    """The two-expert example of MU, VAR, PRIOR worked out by hand."""
    m1, m2, v1, v2, p1, p2 = 0.8, -0.2, 0.2, 0.5, 1.0, 2.0
    prior = 1.0 / ((1 / p1 + 1 / p2) / 2)                      # 4/3
    if rule == "minvar":                                        # 0.2 / 1 < 0.5 / 2
        return m1, v1
    if rule == "bcm":                                           # Eq. 13
        prec, wmean = 1 / v1 + 1 / v2, m1 / v1 + m2 / v2
    elif rule == "tresp":
        prec = 1 / prior + (1 / v1 - 1 / p1) + (1 / v2 - 1 / p2)
        wmean = m1 / v1 + m2 / v2
    else:
        b1, b2 = 0.5 * np.log(p1 / v1), 0.5 * np.log(p2 / v2)
        if rule == "rbcm":
            prec = 1 / prior + b1 * (1 / v1 - 1 / p1) + b2 * (1 / v2 - 1 / p2)
            wmean = b1 * m1 / v1 + b2 * m2 / v2
        else:  # gpoe, weights normalised to one
            w1, w2 = b1 / (b1 + b2), b2 / (b1 + b2)
            prec, wmean = w1 / v1 + w2 / v2, w1 * m1 / v1 + w2 * m2 / v2
    return wmean / prec, 1 / prec


@pytest.mark.parametrize("rule", COMBINE_RULES)
def test_two_experts_against_hand_computed_values(rule):
    mean, var = combine_predictions(MU, VAR, PRIOR, rule)
    m, v = hand(rule)
    assert_allclose(mean, [m], rtol=1e-13)
    assert_allclose(var, [v], rtol=1e-13)


def test_hand_values_of_the_paper_rule():
    # Eq. 13: 1/var = 1/0.2 + 1/0.5 = 7, mean = var (0.8/0.2 - 0.2/0.5) = 3.6/7
    mean, var = combine_predictions(MU, VAR, PRIOR, "bcm")
    assert_allclose(var, [1 / 7], rtol=1e-14)
    assert_allclose(mean, [3.6 / 7], rtol=1e-14)


@pytest.mark.parametrize("rule", ["tresp", "rbcm", "gpoe"])
def test_an_expert_at_its_prior_adds_nothing(rule):
    with_prior = combine_predictions([[0.8], [0.0]], [[0.2], [2.0]], [1.0, 2.0], rule)
    alone = combine_predictions([[0.8]], [[0.2]], [1.0], rule)
    if rule in ("tresp", "rbcm"):  # the committee prior is 1 / mean(1 / prior) of the experts
        assert_allclose(1 / with_prior[1] - 1 / (4 / 3), 1 / alone[1] - 1, rtol=1e-13)
        assert_allclose(with_prior[0] / with_prior[1], alone[0] / alone[1], rtol=1e-13)
    else:
        assert_allclose(with_prior, alone, rtol=1e-13)


def test_the_paper_rule_shrinks_the_variance_far_from_data():
    # every expert at its prior: Eq. 13 gives prior / M, the others the prior
    M = 5
    means, variances = np.zeros((M, 1)), np.ones((M, 1))
    assert_allclose(combine_predictions(means, variances, np.ones(M), "bcm")[1], [1 / M])
    for rule in ("tresp", "rbcm", "gpoe"):
        assert_allclose(combine_predictions(means, variances, np.ones(M), rule), ([0.0], [1.0]))


@pytest.mark.parametrize("rule", COMBINE_RULES)
def test_committee_add_equals_combine_and_adding_the_prior_is_neutral(rule):
    rng = np.random.default_rng(0)
    mu = rng.normal(size=(3, 7))
    prior = np.array([1.0, 1.5, 0.7])
    var = prior[:, None] * rng.uniform(0.05, 1.0, (3, 7))
    expected = combine_predictions(mu, var, prior, rule)
    committee = Committee(rule, prior, 7)
    committee.add(np.arange(4), mu[0, :4], var[0, :4], prior[0])
    committee.add(np.arange(4, 7), mu[0, 4:], var[0, 4:], prior[0])
    for e in (1, 2):
        committee.add(np.arange(7), mu[e], var[e], prior[e])
    committee.add(np.arange(7), np.zeros(7), np.full(7, prior[1]), prior[1])  # neutral
    assert_allclose(committee.result(), expected, rtol=1e-12, atol=1e-15)


def test_one_expert_is_the_expert_for_exact_rules():
    for rule in ("bcm", "tresp", "gpoe", "minvar"):
        mean, var = combine_predictions([[0.3, -1.0]], [[0.4, 0.9]], [1.0], rule)
        assert_allclose(mean, [0.3, -1.0], rtol=1e-14)
        assert_allclose(var, [0.4, 0.9], rtol=1e-14)


@pytest.mark.parametrize("kwargs, exc, match", [
    (dict(means=[[0.0]], variances=[[1.0]], prior_variances=[1.0], rule="poe"), ValueError,
     "rule must be one of"),
    (dict(means=[[0.0]], variances=[[1.0]], prior_variances=[1.0], rule=3), ValueError,
     "rule must be one of"),
    (dict(means=[0.0], variances=[1.0], prior_variances=[1.0]), ValueError, "n_experts"),
    (dict(means=[[0.0]], variances=[[1.0, 2.0]], prior_variances=[1.0]), ValueError,
     "one shape"),
    (dict(means=[[0.0]], variances=[[1.0]], prior_variances=[1.0, 2.0]), ValueError,
     "prior_variances must have shape"),
    (dict(means=[[np.nan]], variances=[[1.0]], prior_variances=[1.0]), ValueError,
     "means must be finite"),
    (dict(means=[[0.0]], variances=[[0.0]], prior_variances=[1.0]), ValueError, "positive"),
    (dict(means=[["a"]], variances=[[1.0]], prior_variances=[1.0]), TypeError, "means"),
])
def test_bad_input(kwargs, exc, match):
    with pytest.raises(exc, match=match):
        combine_predictions(**kwargs)


def test_minvar_takes_the_most_confident_expert():
    means = np.array([[1.0, 2.0, 0.5], [3.0, -1.0, 0.7]])
    variances = np.array([[0.5, 0.2, 1.0], [0.4, 0.9, 2.0]])
    priors = np.array([1.0, 2.0])
    mean, var = combine_predictions(means, variances, priors, "minvar")
    # fractions of the prior: [0.5, 0.2, 1.0] and [0.2, 0.45, 1.0]
    assert mean.tolist() == [3.0, 2.0, 0.0]
    assert var.tolist() == [0.4, 0.2, 1.0 / np.mean(1.0 / priors)]
