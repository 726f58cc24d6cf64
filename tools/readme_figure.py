"""Print the README's text picture of the demo's maps.

``occgp demo`` draws a horizontal slice of every 3D map beside the ground truth
(``demo_out/slice.png``). This script builds two of them, the octree and BGK, as the
demo does (the structured room's 12 scans within 8 m, 0.1 m cells), takes the same
slice (the cell layer at the scanners' mean height) and prints it as text, one
character per 0.5 m x 0.5 m block of 25 cells, so that the README shows it without a
binary file:

* ``#``: a cell of the block is occupied (p >= 0.5; in the ground truth: a solid
  reaches into it, among the cells the scans could see),
* ``?``: none is, and at least half of the block's cells are unknown (in the ground
  truth: out of every scan's view),
* ``.``: none is, and most of the block's cells are known and free.

Run: ``python tools/readme_figure.py``.
"""

import numpy as np

from occgp import make_map
from occgp.datasets import structured_room
from occgp.evaluation import cells_in_view, exact_labels

RES = 0.1        # the demo's resolution
RANGE = 8.0      # the demo's scanner range
BLOCK = 5        # cells per character and axis
MAPS = {
    "octree": dict(map="octree"),
    "BGK": dict(map="bgk", n_jobs=-1),
}


def lattice(lo, hi, res):
    """The centers of the cells inside [lo, hi] on each axis (as the demo's slice)."""
    return [(np.arange(np.ceil(a / res - 0.5 - 1e-9), np.floor(b / res - 0.5 + 1e-9) + 1)
             + 0.5) * res for a, b in zip(lo, hi)]


def to_text(p):
    """One character per BLOCK x BLOCK cells of p (indexed [y, x], NaN: unknown);
    the top row is the largest y."""
    ny, nx = p.shape
    rows = []
    for y0 in range(0, ny, BLOCK):
        row = ""
        for x0 in range(0, nx, BLOCK):
            block = p[y0:y0 + BLOCK, x0:x0 + BLOCK]
            known = block[~np.isnan(block)]
            if (known >= 0.5).any():
                row += "#"
            else:
                row += "?" if 2 * known.size <= block.size else "."
        rows.append(row)
    return rows[::-1]


def main():
    scene = structured_room(seed=0)
    scans = scene.scan(max_range=RANGE, seed=0)
    lo, hi = (np.asarray(b, dtype=float) for b in scene.bounds)
    z = (np.floor(np.mean([s.origin[2] for s in scans]) / RES + 1e-9) + 0.5) * RES
    xs, ys = lattice(lo[:2], hi[:2], RES)
    gx, gy = np.meshgrid(xs, ys)
    q = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, z)])
    truth = exact_labels(scene, q, RES).astype(float)
    truth[~cells_in_view(scene, q, RES, scans, max_range=RANGE)] = np.nan
    panels = {"ground truth": truth.reshape(gx.shape)}
    for name, spec in MAPS.items():
        spec = dict(spec)
        m = make_map(spec.pop("map"), resolution=RES, **spec)
        for points, origin in scans:
            m.insert_scan(points, origin)
        panels[name] = m.occupancy(q).reshape(gx.shape)
    texts = {name: to_text(p) for name, p in panels.items()}
    width = len(next(iter(texts.values()))[0])
    print("  ".join(name.ljust(width) for name in texts).rstrip())
    for rows in zip(*texts.values()):
        print("  ".join(rows))
    print(f"slice at z = {z:.2f} m; # occupied, . free, ? unknown")


if __name__ == "__main__":
    main()
