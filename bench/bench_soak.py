"""Soak: insert >= 1,000 scans into one map and watch memory and time per scan.

A leak shows as resident memory that grows beyond the map's own growth, a slowdown as
time per scan that drifts up once the map has stopped growing. Scans come from the
structured room (4 poses x 3 headings per seed, 3500 returns each, range noise 2 cm),
so the map saturates within the first blocks and later scans revisit known space.

Run: ``python bench/bench_soak.py [--scans 1200] [--block 100]`` (or ``make soak``).
Prints, per block of scans and per map: resident memory (RSS), the map's own memory,
RSS minus the map's memory, and the mean time per scan; then the growth of "RSS − map"
from the second block to the last and the ratio of the last block's time per scan to
the second block's (the first block includes the map's growth and warm-up).
"""

from __future__ import annotations

import argparse
import gc
import resource
import time

import numpy as np

from occgp import BGKMap, GridMap, OccupancyOctree
from occgp.datasets import structured_room


def rss_mib() -> float:
    """Current resident set size, MiB (from /proc; ru_maxrss is only the peak)."""
    with open("/proc/self/statm") as f:
        pages = int(f.read().split()[1])
    return pages * resource.getpagesize() / 2**20


def scans(n_scans: int):
    room = structured_room(seed=0)
    k = 0
    seed = 0
    while k < n_scans:
        for points, origin in room.scan(seed=seed, noise=0.02):
            if k == n_scans:
                return
            yield points, origin
            k += 1
        seed += 1


def map_bytes(m) -> int:
    return m.memory_usage() if hasattr(m, "memory_usage") else m.memory_bytes()


def soak(name: str, m, n_scans: int, block: int, data: list) -> None:
    print(f"\n== {name}: {n_scans} scans in blocks of {block} ==")
    print(f"{'scans':>6} {'RSS MiB':>9} {'map MiB':>9} {'RSS-map':>9} {'ms/scan':>9}")
    gc.collect()
    base = rss_mib()
    rows = []
    t_block = 0.0
    for i, (points, origin) in enumerate(data[:n_scans], 1):
        t0 = time.perf_counter()
        m.insert_scan(points, origin)
        t_block += time.perf_counter() - t0
        if i % block == 0:
            rss = rss_mib() - base
            own = map_bytes(m) / 2**20
            rows.append((i, rss, own, rss - own, 1e3 * t_block / block))
            print(f"{i:6d} {rss:9.1f} {own:9.1f} {rss - own:9.1f} {rows[-1][4]:9.2f}", flush=True)
            t_block = 0.0
    if len(rows) >= 3:
        growth = rows[-1][3] - rows[1][3]
        drift = rows[-1][4] / rows[1][4]
        print(f"RSS - map from block 2 to the last: {growth:+.1f} MiB; "
              f"time per scan, last block / block 2: {drift:.2f}x")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scans", type=int, default=1200)
    parser.add_argument("--block", type=int, default=100)
    args = parser.parse_args(argv)
    t0 = time.perf_counter()
    data = list(scans(args.scans))
    print(f"{len(data)} scans of {len(data[0][0])} points simulated in "
          f"{time.perf_counter() - t0:.1f} s; RSS before the maps {rss_mib():.0f} MiB")
    soak("OccupancyOctree(0.05), method='auto'", OccupancyOctree(0.05), args.scans,
         args.block, data)
    soak("OccupancyOctree(0.05), method='plain' (liboctomap's insertPointCloud)",
         _Plain(OccupancyOctree(0.05)), args.scans, args.block, data)
    soak("GridMap(0.05)", GridMap(0.05), args.scans, args.block, data)
    soak("BGKMap(0.05)", BGKMap(0.05), args.scans, args.block, data)


class _Plain:
    """An octree that inserts with method='plain'."""

    def __init__(self, tree):
        self.tree = tree

    def insert_scan(self, points, origin):
        self.tree.insert_scan(points, origin, method="plain")

    def memory_usage(self):
        return self.tree.memory_usage()


if __name__ == "__main__":
    main()
