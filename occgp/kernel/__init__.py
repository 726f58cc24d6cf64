"""Dense occupancy from sparse scans by Bayesian kernel inference on cells.

:class:`AKIMap` (Kwon et al.) gives every sample its own anisotropic kernel,
shaped by the covariance of its same-label neighbours and scaled against the
others; :class:`BGKMap` is its isotropic baseline, Doherty et al.'s Bayesian
generalized kernel inference ("BGKOctoMap"). In both every cell keeps a Beta
posterior whose parameters collect the kernel-weighted labels of nearby
samples; the bandwidths and the accumulation are compiled (``ext/_kernel.pyx``).
Both answer :class:`occgp.maps.OccupancyMap`.
"""

from __future__ import annotations

# BGKMap first: the map registry lists the map types in the order they register
from ._bgk import BGKMap  # isort: skip
from ._akimap import AKIMap  # isort: skip
from ._kernel_map import KernelMapBase
from ._kernel_io import restore_kernel_map
# the update limits (MAX_FREE_SAMPLES is documented) and voxel_first, importable here as before
from ._kernel_samples import (  # noqa: F401
    MAX_CELLS_PER_UPDATE, MAX_FREE_SAMPLES, MAX_WEIGHT, voxel_first,
)
from ._kernel_utils import Bandwidths, KernelCells, sparse_kernel, voxel_centroids

__all__ = ["AKIMap", "BGKMap", "KernelCells", "Bandwidths", "sparse_kernel",
           "voxel_centroids"]

# the names earlier versions defined here: pickles of kernel maps name _restore
_restore = restore_kernel_map
_KernelMap = KernelMapBase
