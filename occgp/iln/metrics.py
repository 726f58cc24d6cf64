"""Metrics of LiDAR super-resolution (dissertation §4.4.2): range MAE and voxel scores.

Both are plain numpy and need no torch:

* :func:`range_mae` -- the mean absolute error of predicted ranges over the
  pixels where the true image has a return;
* :func:`voxel_scores` -- IoU, precision, recall and F1 of a reconstructed
  point cloud against the true one, on the occupied voxels of a grid
  (0.1 m by default, as in Table 4.1);
* :func:`region_masks` -- the pixels of an up-sampled image split into
  planar ones, depth edges and no-return boundaries (the per-region scores
  of :func:`occgp.iln.evaluate.evaluate`).

:mod:`occgp.iln.evaluate` applies them to whole test sets, image by image,
and averages the per-image values (as the published evaluation does).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._validation import as_numeric, check_real

__all__ = ["range_mae", "voxel_keys", "voxel_scores", "region_masks", "REGIONS",
           "VOXEL_INDEX_LIMIT"]

#: Points must lie within this many voxels of the origin along every axis (each
#: voxel index is packed into 21 bits of one int64 key): 104.8 km at 0.1 m.
VOXEL_INDEX_LIMIT = 2 ** 20


def _as_ranges(x: ArrayLike, name: str) -> NDArray[np.float64]:
    arr = as_numeric(x, name)
    if arr.ndim < 1 or arr.size == 0:
        raise ValueError(f"{name} must be a non-empty range image, got shape {arr.shape}")
    arr = np.asarray(arr, dtype=np.float64)
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} must be finite (0.0 marks no return), found "
                         f"{int(np.count_nonzero(~np.isfinite(arr)))} NaN or inf values")
    if (arr < 0).any():
        raise ValueError(f"{name} must hold ranges >= 0 (0.0 marks no return), found "
                         f"{int(np.count_nonzero(arr < 0))} negative values (min {arr.min():g})")
    return arr


def range_mae(pred: ArrayLike, truth: ArrayLike) -> float:
    """Mean absolute error of predicted ranges where the truth has a return.

    The mean of ``|pred - truth|`` over the pixels whose true range is
    positive. **A predicted no-return (0.0) against a true return counts
    with its full error**, the true range (a model that drops a pixel is not
    rewarded for it); a predicted return where the truth has none (sky,
    beyond the maximum range) is left out of the MAE (it lowers the
    precision of :func:`voxel_scores` instead).

    Parameters
    ----------
    pred : array-like of shape (rows, cols) or (n_images, rows, cols)
        Predicted ranges in metres, >= 0; 0.0 means no return.
    truth : array-like of the same shape
        True ranges in metres, >= 0; 0.0 means no return.

    Returns
    -------
    mae : float
        Metres, over every true return of every image at once.

    Raises
    ------
    ValueError
        If the shapes differ, an array is empty, holds NaN, inf or a negative
        range, or `truth` holds no return.
    TypeError
        If an array does not hold real numbers.

    Examples
    --------
    >>> range_mae([[10.0, 0.0, 5.0]], [[11.0, 4.0, 0.0]])
    2.5
    """
    pred = _as_ranges(pred, "pred")
    truth = _as_ranges(truth, "truth")
    if pred.shape != truth.shape:
        raise ValueError(f"pred and truth must have the same shape, got {pred.shape} and "
                         f"{truth.shape}")
    hit = truth > 0
    n = int(np.count_nonzero(hit))
    if n == 0:
        raise ValueError("truth holds no return (every range is 0.0): the MAE is undefined")
    return float(np.abs(pred[hit] - truth[hit]).sum() / n)


def voxel_keys(points: ArrayLike, voxel_size: float = 0.1, *,
               name: str = "points") -> NDArray[np.int64]:
    """Sorted unique keys of the voxels that hold at least one of `points`.

    A point ``p`` lies in the voxel of index ``floor(p / voxel_size)`` (the
    grid aligned with the origin of the points' frame); the three indices are
    packed into one int64.

    Parameters
    ----------
    points : array-like of shape (n_points, 3)
        Finite, within ``VOXEL_INDEX_LIMIT * voxel_size`` of the origin on
        every axis (104.8 km at 0.1 m). May be empty.
    voxel_size : float, default=0.1
        Voxel edge in metres, > 0.
    name : str, default="points"
        The argument's name in error messages.

    Returns
    -------
    keys : ndarray of int64, shape (n_voxels,)

    Raises
    ------
    ValueError
        If `points` is not of shape (n_points, 3), not finite or too far from
        the origin, or `voxel_size` is not positive and finite.
    TypeError
        If `points` does not hold real numbers or `voxel_size` is not a real.
    """
    voxel_size = check_real(voxel_size, "voxel_size", low=0.0)
    arr = as_numeric(points, name)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name} must have shape (n_points, 3), got {arr.shape}")
    arr = np.asarray(arr, dtype=np.float64)
    if not np.isfinite(arr).all():
        bad = int(np.count_nonzero(~np.isfinite(arr).all(axis=1)))
        raise ValueError(f"{name} must be finite: {bad} of {len(arr)} rows hold NaN or inf")
    with np.errstate(over="ignore"):
        index = np.floor(arr / voxel_size)
    if index.size and not (np.abs(index) < VOXEL_INDEX_LIMIT).all():
        far = float(np.abs(arr).max())
        raise ValueError(f"{name} must lie within {VOXEL_INDEX_LIMIT} voxels of the origin "
                         f"({VOXEL_INDEX_LIMIT * voxel_size:g} m at voxel_size {voxel_size:g}), "
                         f"got a coordinate of {far:g} m")
    shifted = index.astype(np.int64) + VOXEL_INDEX_LIMIT        # in [1, 2**21)
    keys = (shifted[:, 0] << 42) | (shifted[:, 1] << 21) | shifted[:, 2]
    return np.unique(keys)


def voxel_scores(pred_points: ArrayLike, true_points: ArrayLike,
                 voxel_size: float = 0.1) -> dict[str, float]:
    """IoU, precision, recall and F1 of reconstructed points on a voxel grid.

    Each point set becomes the set of voxels (edge `voxel_size`, the grid
    aligned with the origin of the sensor frame) holding at least one of its
    points: ``P`` of `pred_points`, ``T`` of `true_points`. Then ``IoU =
    |P ∩ T| / |P ∪ T|``, ``precision = |P ∩ T| / |P|``, ``recall = |P ∩ T| /
    |T|`` and ``F1 = 2 precision recall / (precision + recall)``
    (dissertation §4.4.2, Table 4.1). An empty prediction scores 0 on all
    four.

    Parameters
    ----------
    pred_points : array-like of shape (n_pred, 3)
        Reconstructed points (no-return pixels already dropped), metres. May
        be empty.
    true_points : array-like of shape (n_true, 3)
        True points in the same frame, at least one.
    voxel_size : float, default=0.1
        Voxel edge in metres, > 0.

    Returns
    -------
    scores : dict
        ``{"iou", "precision", "recall", "f1"}``, each in [0, 1].

    Raises
    ------
    ValueError
        If a point array is not of shape (n, 3), not finite, or farther than
        ``VOXEL_INDEX_LIMIT`` voxels from the origin; `true_points` is empty;
        or `voxel_size` is not positive and finite.
    TypeError
        If an array does not hold real numbers or `voxel_size` is not a real.

    Examples
    --------
    >>> s = voxel_scores([[0.05, 0.05, 0.05], [1.05, 0.05, 0.05]],
    ...                  [[0.01, 0.02, 0.03], [0.55, 0.05, 0.05]])
    >>> s["iou"], s["precision"], s["recall"], s["f1"]
    (0.3333333333333333, 0.5, 0.5, 0.5)
    """
    voxel_size = check_real(voxel_size, "voxel_size", low=0.0)
    truth = voxel_keys(true_points, voxel_size, name="true_points")
    if truth.size == 0:
        raise ValueError("true_points must hold at least one point, got none")
    pred = voxel_keys(pred_points, voxel_size, name="pred_points")
    inter = int(np.intersect1d(pred, truth, assume_unique=True).size)
    union = pred.size + truth.size - inter
    precision = inter / pred.size if pred.size else 0.0
    recall = inter / truth.size
    f1 = 2 * precision * recall / (precision + recall) if inter else 0.0
    return {"iou": inter / union, "precision": precision, "recall": recall, "f1": f1}


def region_masks(truth: ArrayLike, prior: ArrayLike, near_no_return: ArrayLike, *,
                 edge_threshold: float = 0.5) -> dict[str, NDArray[np.bool_]]:
    """The pixels of an up-sampled image by region: planar, depth edge, no-return boundary.

    The three regions split every pixel, in this order of precedence:

    * ``"boundary"`` (no-return boundary): the true pixel has no return, or one of the
      input pixels it is interpolated from (`near_no_return`) has none;
    * ``"edge"`` (depth edge): the inverse bilinear prediction `prior` is off the true range by
      more than `edge_threshold`;
    * ``"planar"``: the rest -- true returns that inverse bilinear, exact on planes, already
      gets within `edge_threshold`.

    Parameters
    ----------
    truth : array-like of shape (rows, cols) or (n_images, rows, cols)
        True ranges in metres, >= 0; 0.0 means no return.
    prior : array-like of the same shape
        The inverse bilinear prediction of the same pixels
        (:class:`occgp.iln.models.InverseBilinear`), metres.
    near_no_return : array-like of bool, the same shape
        True where one of the input pixels around the pixel's query has no return.
    edge_threshold : float, default=0.5
        Error of `prior` in metres above which a pixel is a depth edge, > 0.

    Returns
    -------
    masks : dict
        ``{"planar", "edge", "boundary"}`` -> bool arrays of `truth`'s shape; every pixel lies
        in exactly one.

    Raises
    ------
    ValueError
        If the shapes differ, an array is empty, a range array holds NaN, inf or a negative
        range, or `edge_threshold` is not positive and finite.
    TypeError
        If an array does not hold real numbers (`near_no_return`: booleans) or
        `edge_threshold` is not a real.

    Examples
    --------
    >>> m = region_masks([[10.0, 10.0, 0.0, 10.0]], [[10.1, 12.0, 5.0, 10.0]],
    ...                  [[False, False, False, True]])
    >>> [m[k].nonzero()[1].tolist() for k in REGIONS]
    [[0], [1], [2, 3]]
    """
    edge_threshold = check_real(edge_threshold, "edge_threshold", low=0.0, state_bounds=True)
    truth = _as_ranges(truth, "truth")
    prior = _as_ranges(prior, "prior")
    near = np.asarray(near_no_return)
    if near.dtype != np.bool_:
        raise TypeError(f"near_no_return must hold booleans, got dtype {near.dtype}")
    if not (truth.shape == prior.shape == near.shape):
        raise ValueError(f"truth, prior and near_no_return must have the same shape, got "
                         f"{truth.shape}, {prior.shape} and {near.shape}")
    boundary = (truth <= 0) | near
    edge = ~boundary & (np.abs(prior - truth) > edge_threshold)
    return {"planar": ~boundary & ~edge, "edge": edge, "boundary": boundary}


#: The regions of :func:`region_masks`, in table order.
REGIONS = ("planar", "edge", "boundary")
