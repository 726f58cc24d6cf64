"""Merging the predictions of Gaussian-process experts into one.

Each expert ``e`` gives a latent mean ``mu_e`` and variance ``var_e`` at a
query, and has its own prior variance ``prior_e`` there (its kernel's
variance: the experts have their own hyper-parameters). Every rule below is
written as the prior plus each expert's departure from its prior, so an
expert left at its prior (a query it saw no data near) adds nothing but a
term known in closed form, and need not be evaluated there:

``"bcm"``
    The mixture paper's Eq. 13 (Kim & Kim 2022; a product of experts):
    ``1/var = sum_e 1/var_e`` and ``mu/var = sum_e mu_e/var_e``, over every
    expert. Far from all data the merged variance is ``prior / M`` with M
    experts: over-confident, the known weakness of the product of experts.
``"tresp"``
    The Bayesian committee machine with its prior correction (Tresp 2000):
    ``1/var = 1/prior + sum_e (1/var_e - 1/prior_e)``. With one prior for all
    experts this is Tresp's ``sum_e 1/var_e - (M - 1)/prior``; far from data
    it falls back to the prior.
``"rbcm"``
    The robust BCM (Deisenroth & Ng 2015): each expert weighted by its
    differential-entropy reduction ``beta_e = log(prior_e / var_e) / 2``,
    ``1/var = 1/prior + sum_e beta_e (1/var_e - 1/prior_e)`` and
    ``mu/var = sum_e beta_e mu_e/var_e``.
``"gpoe"``
    The generalised product of experts (Cao & Fleet 2014) with the same
    entropy weights normalised to sum to one:
    ``1/var = sum_e w_e/var_e``, ``mu/var = sum_e w_e mu_e/var_e``,
    ``w_e = beta_e / sum_e beta_e``; the prior where no expert is informed.

``"minvar"``
    The most confident expert alone: at each query, the expert whose
    variance is the smallest fraction of its prior gives the mean and
    variance (ties: the first expert); the prior where no expert is below
    its prior. This is how :class:`~occgp.gp.GPOMIK` answers a query from its
    spatial cells.

``prior`` is the committee's prior variance, ``1 / mean_e(1 / prior_e)``
(the experts' common prior when they share one).

References
----------
S. Kim, J. Kim, "Efficient clustering for continuous occupancy mapping using
a mixture of Gaussian processes", Sensors 22 (2022) 6832, Eq. 13.
V. Tresp, "A Bayesian committee machine", Neural Computation 12 (2000).
M. P. Deisenroth, J. W. Ng, "Distributed Gaussian processes", ICML 2015.
Y. Cao, D. J. Fleet, "Generalized product of experts for automatic and
principled fusion of Gaussian process predictions", arXiv:1410.7827 (2014).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._validation import as_numeric, check_choice

__all__ = ["COMBINE_RULES", "Committee", "combine_predictions"]

#: The merging rules, by name.
COMBINE_RULES = ("bcm", "tresp", "rbcm", "gpoe", "minvar")

#: Variances are floored at this fraction of the prior (a zero variance would
#: give an infinite precision).
_VAR_FLOOR = 1e-12


class Committee:
    """Accumulates experts' predictions at ``n`` queries and merges them.

    Start from every expert at its prior (``prior_vars``: one prior variance
    per expert, or an array (n_experts, n) of them), :meth:`add` the experts'
    predictions where they were evaluated, and read :meth:`result`. Adding
    an expert's prior itself changes nothing, so experts that were not
    evaluated at a query count as their prior there.
    """

    def __init__(self, rule: str, prior_vars: ArrayLike, n: int):
        self.rule = check_choice(rule, "combine", COMBINE_RULES)
        inv = 1.0 / np.asarray(prior_vars, dtype=np.float64)
        self.n = n
        # one prior per expert (point queries): reduce over the experts once, not per query
        mean_inv = np.full(n, inv.mean()) if inv.ndim == 1 else inv.mean(axis=0)
        #: The committee's prior variance at each query.
        self.prior = 1.0 / mean_inv
        # precision and precision-weighted mean; entropy weights for gpoe
        if self.rule == "bcm":
            self._precision = np.full(n, inv.sum()) if inv.ndim == 1 else inv.sum(axis=0)
        elif self.rule == "gpoe":
            self._precision = np.zeros(n)
            self._weights = np.zeros(n)
        elif self.rule == "minvar":
            self._ratio = np.ones(n)
            self._mean = np.zeros(n)
            self._var = self.prior.copy()
            return
        else:
            self._precision = 1.0 / self.prior
        self._weighted_mean = np.zeros(n)

    def add(self, index: NDArray[np.intp], mean: NDArray[np.float64], var: NDArray[np.float64],
            prior_var) -> None:
        """Add one expert's latent `mean` and `var` at the distinct queries `index`.

        `prior_var` is that expert's prior variance there (a scalar or an
        array like `var`); `var` is clipped to ``[1e-12 prior, prior]``.
        """
        prior_var = np.broadcast_to(np.asarray(prior_var, dtype=np.float64), np.shape(var))
        var = np.clip(var, _VAR_FLOOR * prior_var, prior_var)
        if self.rule == "minvar":
            ratio = var / prior_var
            better = ratio < self._ratio[index]
            at = index[better]
            self._ratio[at], self._mean[at], self._var[at] = ratio[better], mean[better], \
                var[better]
            return
        gain = 1.0 / var - 1.0 / prior_var
        if self.rule in ("bcm", "tresp"):
            self._precision[index] += gain
            self._weighted_mean[index] += mean / var
            return
        beta = 0.5 * np.log(prior_var / var)
        if self.rule == "rbcm":
            self._precision[index] += beta * gain
            self._weighted_mean[index] += beta * mean / var
        else:  # gpoe: normalised in result()
            self._weights[index] += beta
            self._precision[index] += beta / var
            self._weighted_mean[index] += beta * mean / var

    def result(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The merged latent mean and variance at every query."""
        if self.rule == "minvar":
            return self._mean.copy(), self._var.copy()
        precision, weighted = self._precision, self._weighted_mean
        if self.rule == "gpoe":
            informed = self._weights > 0
            w = np.where(informed, self._weights, 1.0)
            precision = np.where(informed, precision / w, 1.0 / self.prior)
            weighted = np.where(informed, weighted / w, 0.0)
        var = 1.0 / precision
        return weighted * var, var


def combine_predictions(means: ArrayLike, variances: ArrayLike, prior_variances: ArrayLike,
                        rule: str = "rbcm") -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Merge the latent predictions of several experts at the same queries.

    Parameters
    ----------
    means, variances : array-like of shape (n_experts, n_queries)
        Each expert's latent mean and variance.
    prior_variances : array-like of shape (n_experts,) or (n_experts, n_queries)
        Each expert's prior variance (its kernel's variance at a point).
    rule : {"bcm", "tresp", "rbcm", "gpoe", "minvar"}, default="rbcm"
        The merging rule (see :mod:`occgp.gp._committee`): the mixture paper's
        Eq. 13, Tresp's BCM with the prior correction, the robust BCM, the
        generalised product of experts, or the most confident expert alone.

    Returns
    -------
    mean, var : ndarray of shape (n_queries,)

    Raises
    ------
    ValueError
        If the shapes disagree, a value is not finite, a variance is not
        positive, or the rule is unknown.
    TypeError
        On non-numeric input or a rule that is not a string.

    Examples
    --------
    Two experts with prior variance 1: one sure (variance 0.1, mean 1), one
    at its prior:

    >>> mean, var = combine_predictions([[1.0], [0.0]], [[0.1], [1.0]], [1.0, 1.0], "tresp")
    >>> mean.round(6).tolist(), var.round(6).tolist()
    ([1.0], [0.1])
    >>> mean, var = combine_predictions([[1.0], [0.0]], [[0.1], [1.0]], [1.0, 1.0], "bcm")
    >>> mean.round(6).tolist(), var.round(6).tolist()
    ([0.909091], [0.090909])
    """
    rule = check_choice(rule, "rule", COMBINE_RULES)
    arrays = {}
    for name, value in (("means", means), ("variances", variances),
                        ("prior_variances", prior_variances)):
        arr = as_numeric(value, name).astype(np.float64)
        if not np.isfinite(arr).all():
            raise ValueError(f"{name} must be finite (found NaN or inf)")
        arrays[name] = arr
    mu, var, prior = arrays["means"], arrays["variances"], arrays["prior_variances"]
    if mu.ndim != 2 or var.shape != mu.shape:
        raise ValueError(f"means and variances must have one shape (n_experts, n_queries), got "
                         f"{mu.shape} and {var.shape}")
    if prior.shape not in ((len(mu),), mu.shape):
        raise ValueError(f"prior_variances must have shape ({len(mu)},) or {mu.shape}, got "
                         f"{prior.shape}")
    if (var <= 0).any() or (prior <= 0).any():
        raise ValueError("variances and prior_variances must be positive")
    committee = Committee(rule, prior, mu.shape[1])
    index = np.arange(mu.shape[1])
    for e in range(len(mu)):
        committee.add(index, mu[e], var[e], prior[e] if prior.ndim == 1 else prior[e])
    return committee.result()
