"""Ground truth of a scene's cells: :func:`occgp.evaluation.cell_labels`.

It lives beside the scenes, below the evaluation package, because the data sets score
their own scans with it too (``naive_fdr`` in ``_sgbm.py``); the evaluation
package re-exports it where it was.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._docfill import fill_doc
from .._params import renamed_keywords
from .._validation import as_points, check_int, check_real

__all__ = ["cell_labels", "CELL_SECTIONS"]

#: The parameter and return sections :func:`cell_labels` and
#: :func:`occgp.evaluation.exact_labels` share.
CELL_SECTIONS = """resolution : float
    Cell edge, metres, > 0.
samples : int, default=5
    Sample points per axis, in [1, 16]; 1 tests the center alone.

Returns
-------
labels : ndarray of bool, shape (n_cells,)"""


@fill_doc(cell_sections=CELL_SECTIONS)
@renamed_keywords(centres="centers")
def cell_labels(scene: Any, centers: ArrayLike, resolution: float, *,
                samples: int = 5) -> NDArray[np.bool_]:
    """Ground truth of octree cells: whether a solid of `scene` reaches into each cell.

    A cell (edge `resolution`, centered at a row of `centers`) is occupied when
    ``scene.occupancy`` holds at one of ``samples**3`` points of the closed
    cell: a grid over it that includes its faces, widened by a millionth of
    the cell. A cell that a surface crosses counts as occupied whichever
    side of the surface its center lies on, and a surface lying on a cell
    border (a ground plane at z = 0) makes both cells beside it occupied: a
    measured point on it may fall in either. Cells whose center is farther
    than half a cell diagonal from every surface (``scene.signed_distance``,
    when the scene has it) take the center's label without sampling.

    Parameters
    ----------
    scene : object
        With ``occupancy(points) -> bool array`` (closed solids); optionally
        ``signed_distance(points)``.
    centers : array-like of shape (n_cells, 3)
        Cell centers, metres (``centres`` before, a name deprecated for one release).
    {cell_sections}

    Raises
    ------
    ValueError
        If `centers` is not of shape (n_cells, 3) or not finite, `resolution`
        is not positive, `samples` is out of range, or ``scene.occupancy``
        answers with the wrong shape.
    TypeError
        If `samples` is not an integer.

    Examples
    --------
    >>> class Ground:
    ...     def occupancy(self, points):
    ...         return points[:, 2] <= 0.0
    >>> cell_labels(Ground(), [[0.05, 0.05, -0.05], [0.05, 0.05, 0.05],
    ...                        [0.05, 0.05, 0.15]], 0.1).tolist()
    [True, True, False]
    """
    centers = as_points(centers, "centers")
    resolution = check_real(resolution, "resolution", low=0.0)
    samples = check_int(samples, "samples", low=1, high=16)
    labels = np.asarray(scene.occupancy(centers), dtype=bool)
    if labels.shape != (len(centers),):
        raise ValueError(f"scene.occupancy(points) must return shape ({len(centers)},), "
                         f"got {labels.shape}")
    if samples == 1:
        return labels
    near = np.arange(len(centers))
    widen = 1.0 + 1e-6
    if hasattr(scene, "signed_distance"):
        sd = np.asarray(scene.signed_distance(centers), dtype=np.float64)
        near = np.flatnonzero(np.abs(sd) <= 0.5 * math.sqrt(3) * resolution * widen)
    offsets = np.linspace(-0.5, 0.5, samples) * widen
    grid = np.stack(np.meshgrid(offsets, offsets, offsets, indexing="ij"), -1).reshape(-1, 3)
    for start in range(0, len(near), 20_000):
        rows = near[start:start + 20_000]
        pts = (centers[rows, None, :] + resolution * grid[None]).reshape(-1, 3)
        hit = np.asarray(scene.occupancy(pts), dtype=bool).reshape(len(rows), -1)
        labels[rows] |= hit.any(axis=1)
    return labels
