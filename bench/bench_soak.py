"""Soak: insert >= 1,000 scans into one map and watch memory and time per scan.

A leak shows as resident memory that keeps growing once the map has stopped growing; a
slowdown as time per scan that drifts up. Scans come from the structured room (4 poses
x 3 headings per seed, 3500 returns each, range noise 2 cm), so the map saturates in
the first blocks and every later scan revisits known space.

Run: ``python bench/bench_soak.py [--scans 1200] [--block 100]`` (or ``make soak``).
Each map runs in a fresh process (so that one map's freed memory does not blur the
next one's figures) and prints, per block of scans: resident memory (RSS) above the
process's before the map, the map's own memory, and the mean time per scan; then the
growth of RSS from the end of the third block to the last and from the middle block to
the last, and the time per scan of block 2's scans inserted once more at the end (the
same data into the full map) over their time in block 2: drift, not content.
"""

from __future__ import annotations

import argparse
import gc
import resource
import subprocess
import sys
import time

MAPS = {
    "octree": "OccupancyOctree(0.05), method='auto' (culling region and super rays)",
    "plain": "OccupancyOctree(0.05), method='plain' (liboctomap's insertPointCloud)",
    "grid": "GridMap(0.05), method='auto'",
    "bgk": "BGKMap(0.05, max_range=8, far_beams='drop') (la3dm's defaults)",
}


def rss_mib() -> float:
    """Current resident set size, MiB (from /proc; ru_maxrss is only the peak)."""
    with open("/proc/self/statm") as f:
        pages = int(f.read().split()[1])
    return pages * resource.getpagesize() / 2**20


def scans(n_scans: int) -> list:
    from occgp.datasets import structured_room

    room = structured_room(seed=0)
    out: list = []
    seed = 0
    while len(out) < n_scans:
        out.extend(room.scan(seed=seed, noise=0.02)[: n_scans - len(out)])
        seed += 1
    return out


def make_map(kind: str):
    from occgp import BGKMap, GridMap, OccupancyOctree

    if kind == "bgk":
        m = BGKMap(0.05, max_range=8.0, far_beams="drop")
        return m, m.insert_scan, m.memory_usage
    m = GridMap(0.05) if kind == "grid" else OccupancyOctree(0.05)
    method = "plain" if kind == "plain" else "auto"
    return m, lambda p, o: m.insert_scan(p, o, method=method), m.memory_usage


def soak(kind: str, n_scans: int, block: int) -> None:
    data = scans(n_scans)
    _, insert, own_bytes = make_map(kind)
    gc.collect()
    base = rss_mib()
    print(f"\n== {MAPS[kind]}: {n_scans} scans of {len(data[0][0])} points, "
          f"blocks of {block} (process RSS before the map: {base:.0f} MiB) ==")
    print(f"{'scans':>6} {'RSS MiB':>9} {'map MiB':>9} {'ms/scan':>9}")
    rows = []
    t_block = 0.0
    for i, (points, origin) in enumerate(data, 1):
        t0 = time.perf_counter()
        insert(points, origin)
        t_block += time.perf_counter() - t0
        if i % block == 0:
            rows.append((i, rss_mib() - base, own_bytes() / 2**20, 1e3 * t_block / block))
            print("{:6d} {:9.1f} {:9.1f} {:9.2f}".format(*rows[-1]), flush=True)
            t_block = 0.0
    if len(rows) >= 6:
        # the scans of block 2 once more, into the full map: the same data, so a
        # difference in time is drift, not the scans' content
        t0 = time.perf_counter()
        for points, origin in data[block:2 * block]:
            insert(points, origin)
        again = 1e3 * (time.perf_counter() - t0) / block
        mid = len(rows) // 2 - 1
        print(f"RSS growth: block 3 -> last {rows[-1][1] - rows[2][1]:+.1f} MiB, "
              f"block {mid + 1} -> last {rows[-1][1] - rows[mid][1]:+.1f} MiB (map: "
              f"{rows[-1][2] - rows[2][2]:+.1f} / {rows[-1][2] - rows[mid][2]:+.1f} MiB); "
              f"block 2's scans again at the end: {again:.2f} ms/scan, "
              f"{again / rows[1][3]:.2f}x block 2's time")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scans", type=int, default=1200)
    parser.add_argument("--block", type=int, default=100)
    parser.add_argument("--map", choices=sorted(MAPS), help="run one map in this process")
    args = parser.parse_args(argv)
    if args.map:
        soak(args.map, args.scans, args.block)
        return
    for kind in MAPS:
        subprocess.run([sys.executable, __file__, "--map", kind, "--scans", str(args.scans),
                        "--block", str(args.block)], check=True)


if __name__ == "__main__":
    main()
