"""Documented limits of the Gaussian-process maps, checked before any work is done.

* Coordinates: ``|x_d| <= MAX_SCALED_COORDINATE * length_scale_d`` (1e10 length
  scales from the origin). The kernels see differences of coordinates in
  length-scale units; float64 resolves them to ``1e10 * 2.2e-16 ~ 2e-6``
  length scales there, and not much beyond.
* Segments (beams): at most ``MAX_SCALED_SEGMENT`` (1e4) length scales long.
  The quadrature of a segment-segment covariance grows with the segments'
  lengths in length scales (quadratically for the Matérn and sparse kernels).
* Dense matrices: the matrices one step builds at once (``n x n`` float64 for
  ``n`` observations, several of them) stay below ``MAX_DENSE_BYTES`` (4 GiB).
* Models: the local models' Cholesky factors together (``n_i x n_i`` float64
  for a model of ``n_i`` observations) stay below ``MAX_MODEL_BYTES`` (8 GiB),
  checked before any is built.
* Threads: ``n_jobs`` above the number of cores counts as every core.
"""

from __future__ import annotations

import numpy as np
from threadpoolctl import ThreadpoolController

from .._validation import check_n_jobs, n_threads

__all__ = ["MAX_SCALED_COORDINATE", "MAX_SCALED_SEGMENT", "MAX_DENSE_BYTES",
           "MAX_MODEL_BYTES", "MAX_RESTARTS", "check_coordinates", "check_model_size", "check_segments", "check_dense", "threads",
           "generator", "one_blas_thread"]

MAX_SCALED_COORDINATE = 1e10
MAX_SCALED_SEGMENT = 1e4
MAX_DENSE_BYTES = 4 * 2 ** 30
MAX_MODEL_BYTES = 8 * 2 ** 30
#: Most extra starts of the hyper-parameter optimiser (``n_restarts``).
MAX_RESTARTS = 1000


def check_coordinates(arrays, inv_ls, *, fix="shift the data towards the origin"):
    """Reject coordinates beyond ``MAX_SCALED_COORDINATE`` length scales; `arrays` maps names."""
    for name, x in arrays.items():
        if not len(x):
            continue
        scaled = np.abs(x).max(axis=0) * inv_ls
        d = int(np.argmax(scaled))
        if scaled[d] > MAX_SCALED_COORDINATE:
            worst = float(np.abs(x[:, d]).max())
            raise ValueError(
                f"{name} must lie within {MAX_SCALED_COORDINATE:g} length scales of the origin "
                f"(|x| <= {MAX_SCALED_COORDINATE * float(1 / inv_ls[d]):.6g} on axis {d}, where "
                f"float64 still resolves the kernel), got a coordinate of {worst:.6g}; {fix}")


def check_segments(starts, ends, inv_ls, name="segment"):
    """Reject segments longer than ``MAX_SCALED_SEGMENT`` length scales."""
    if not len(starts):
        return
    scaled = np.linalg.norm((ends - starts) * inv_ls, axis=1)
    i = int(np.argmax(scaled))
    if scaled[i] > MAX_SCALED_SEGMENT:
        raise ValueError(
            f"{name}s must be at most {MAX_SCALED_SEGMENT:g} length scales long (the cost of "
            f"their integrals grows with it), got {name} {i} of {scaled[i]:.4g} length scales "
            f"(from {starts[i].tolist()} to {ends[i].tolist()}); split long beams, clip them at "
            f"a maximum range, or use a longer length scale")


def check_dense(n_rows, n_cols, n_matrices, what, fix):
    """Reject a step that would build `n_matrices` dense float64 arrays of n_rows x n_cols."""
    size = 8.0 * n_rows * n_cols * n_matrices
    if size > MAX_DENSE_BYTES:
        raise ValueError(
            f"{what} needs {n_matrices} dense {n_rows} x {n_cols} matrices "
            f"({size / 2 ** 30:.3g} GiB), more than the limit of "
            f"{MAX_DENSE_BYTES / 2 ** 30:g} GiB; {fix}")


def check_model_size(n_obs, cell_size, fix):
    """Reject `n_obs` observations in local models of at most `cell_size` (None: one)
    whose factors would pass ``MAX_MODEL_BYTES`` together."""
    cell = n_obs if cell_size is None else min(n_obs, cell_size)
    size = 8.0 * n_obs * cell
    if size > MAX_MODEL_BYTES:
        if cell == n_obs:
            most = f"one model holds at most {int(np.sqrt(MAX_MODEL_BYTES / 8)):,}"
        else:
            most = f"models of {cell:,} hold at most {int(MAX_MODEL_BYTES // (8 * cell)):,} together"
        raise ValueError(
            f"{n_obs:,} observations in local models of up to {cell:,} need about "
            f"{size / 2 ** 30:.3g} GiB for their Cholesky factors, more than the limit of "
            f"{MAX_MODEL_BYTES / 2 ** 30:g} GiB ({most}); {fix}")


def threads(n_jobs):
    """Threads for `n_jobs` (None: 1; -1: every core), at most the number of cores."""
    return n_threads(check_n_jobs(n_jobs))


_CONTROLLER: list = []


def one_blas_thread():
    """Context manager limiting BLAS and OpenMP to one thread.

    ``threadpoolctl.threadpool_limits(1)`` finds the loaded libraries anew on
    every call (a few milliseconds, which adds up over hundreds of experts);
    this reuses one controller, made on first use, when numpy's and scipy's
    libraries are loaded.
    """
    if not _CONTROLLER:
        _CONTROLLER.append(ThreadpoolController())
    return _CONTROLLER[0].limit(limits=1)


def generator(random_state, name="random_state"):
    """``numpy.random.default_rng(random_state)``, with an error naming the argument."""
    if isinstance(random_state, bool):
        raise TypeError(f"{name} must be None, an int or a numpy Generator, got bool")
    try:
        return np.random.default_rng(random_state)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be None, a non-negative int or a numpy Generator, got "
                        f"{random_state!r} ({exc})") from None
