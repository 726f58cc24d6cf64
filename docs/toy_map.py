"""A new map type in one module: the end-point counter of the architecture page.

Every cell holding end points is occupied with probability ``hits / (hits + 1)``
(one prior miss); cells no ray ended in are unknown. The class answers the
calls of :class:`occgp.maps.OccupancyMap`, and one decorator line registers it,
after which ``make_map("toy")``, ``occgp map --method toy`` and
``compare_methods(["toy"], ...)`` build it. ``tests/test_maps.py`` runs this
file.
"""

import numpy as np
from sklearn.base import BaseEstimator

from occgp import OccupancyOctree
from occgp.maps import register


@register("toy", formats=(".npz",), description="end points counted per cell")
class EndPointCounter(BaseEstimator):
    """Count the scans' end points per cell (no free space).

    Parameters
    ----------
    resolution : float, default=0.1
        Cell size in metres.
    occupancy_threshold : float, default=0.5
        Cells at or above this probability are occupied.
    """

    def __init__(self, resolution=0.1, occupancy_threshold=0.5):
        self.resolution = resolution                # scikit-learn: store, check later
        self.occupancy_threshold = occupancy_threshold

    # the protocol's calls
    def insert_scan(self, points, origin, **options):
        if not self.resolution > 0:
            raise ValueError(f"resolution must be positive, got {self.resolution!r}")
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        keys = np.floor(points / self.resolution).astype(np.int64)
        cells, counts = np.unique(keys, axis=0, return_counts=True)
        old = getattr(self, "hits_", {})
        self.hits_ = dict(old)
        for key, n in zip(map(tuple, cells), counts):
            self.hits_[key] = self.hits_.get(key, 0) + int(n)
        return self

    def occupancy(self, points):
        keys = np.floor(np.asarray(points, dtype=np.float64).reshape(-1, 3)
                        / self.resolution).astype(np.int64)
        hits = getattr(self, "hits_", {})
        n = np.array([hits.get(tuple(k), np.nan) for k in keys], dtype=np.float64)
        return n / (n + 1)                          # NaN where no ray ended

    def is_occupied(self, points, *, return_unknown=False):
        p = self.occupancy(points)
        occupied = ~np.isnan(p) & (p >= self.occupancy_threshold)
        return (occupied, np.isnan(p)) if return_unknown else occupied

    @property
    def num_cells(self):
        return len(getattr(self, "hits_", {}))

    @property
    def bounds(self):
        if not self.num_cells:
            return np.full(3, np.nan), np.full(3, np.nan)
        keys = np.array(list(self.hits_))
        return keys.min(axis=0) * self.resolution, (keys.max(axis=0) + 1) * self.resolution

    def memory_usage(self):
        return 32 * self.num_cells

    def save(self, path):
        keys = np.array(list(getattr(self, "hits_", {})), dtype=np.int64).reshape(-1, 3)
        np.savez(path, resolution=self.resolution, keys=keys,
                 hits=np.array(list(getattr(self, "hits_", {}).values()), dtype=np.int64))
        return self

    @classmethod
    def load(cls, path):
        with np.load(path) as f:
            m = cls(float(f["resolution"]))
            m.hits_ = {tuple(int(v) for v in k): int(n) for k, n in zip(f["keys"], f["hits"])}
        return m

    def to_octree(self):
        tree = OccupancyOctree(self.resolution)
        if self.num_cells:
            keys = np.array(list(self.hits_))
            hits = np.array(list(self.hits_.values()), dtype=np.float64)
            tree.set_cells((keys + 0.5) * self.resolution, np.log(hits))   # logit(n/(n+1))
        return tree
