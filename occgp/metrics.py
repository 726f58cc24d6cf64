"""Scores of occupancy predictions against labelled test points.

The import path of :mod:`occgp.evaluation.metrics`, which defines every name
here (ROC curve and AUC, MSE, accuracies, the TPR–FDR curve and its area, and
:func:`score_all`); unknown points (NaN) count as p = 0.5 throughout.
"""

from .evaluation.metrics import (
    accuracy, mse, roc_auc, roc_curve, score_all, tpr_fdr_auc, tpr_fdr_curve,
)

__all__ = ["roc_curve", "roc_auc", "mse", "accuracy", "tpr_fdr_curve", "tpr_fdr_auc",
           "score_all"]
