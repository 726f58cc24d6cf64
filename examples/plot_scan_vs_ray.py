"""
===========================================
Scan sets or ray counts: two update rules
===========================================

``mode="scan"`` (OctoMap's ``insertPointCloud``) updates each cell at most once
per scan; ``mode="ray"`` adds one update per ray. Where many rays of a scan
end in or cross the same cell, ray counting reaches the clamping bounds in a
single scan. We score both on held-out test points with
:func:`occgp.evaluation.compare_methods`.
"""

# Author: the occgp developers
# License: BSD 3 clause

# %%
import matplotlib.pyplot as plt

from occgp import OccupancyOctree
from occgp.datasets import structured_room
from occgp.evaluation import compare_methods, format_table, held_out_split
from occgp.metrics import roc_curve

scans = structured_room(seed=0).scan(seed=0)
train, test = held_out_split(scans, fraction=0.2, seed=0)


class RayCounting(OccupancyOctree):
    def insert_scan(self, points, origin, **kwargs):
        return super().insert_scan(points, origin, mode="ray", **kwargs)


rows = compare_methods({"scan sets": lambda: OccupancyOctree(0.1),
                        "ray counts": lambda: RayCounting(0.1)}, train, test, progress=False)
print(format_table(rows))

# %%
# Log-odds histograms show the difference: ray counting saturates at the
# clamping bounds (-2.0 and 3.5).
fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(9, 3.5), layout="constrained")
for r in rows:
    ax0.hist(r.map.leaves().log_odds, bins=60, histtype="step", label=r.method)
    fpr, tpr, _ = roc_curve(test.labels, r.map.occupancy(test.points))
    ax1.plot(fpr, tpr, label=f"{r.method} (AUC {r.auc:.3f})")
ax0.set_xlabel("leaf log-odds")
ax0.legend()
ax1.set_xlabel("false positive rate")
ax1.set_ylabel("true positive rate")
ax1.legend()
plt.show()
