"""Independent references for the octree's exactness tests (and the benchmark).

* :func:`build_octomap_insert` compiles ``reference/octomap_insert.cpp``, a small
  program that calls liboctomap's ``insertPointCloud`` directly;
  :func:`octomap_insert` runs it and returns the tree's bytes (.ot).
* :func:`ray_mode_reference` is a slow pure-Python model of ``mode="ray"``: a port
  of liboctomap's ray traversal (``computeRayKeys``, with its float32/float64
  arithmetic) and the per-ray counting rule of DESIGN.md, one clamp per scan.
"""

from __future__ import annotations

import math
import shutil
import subprocess
from collections import defaultdict
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
SOURCE = HERE / "reference" / "octomap_insert.cpp"
MAX_VAL = 32768
f32 = np.float32


def build_octomap_insert(outdir: Path) -> Path | None:
    """Compile the C++ reference; None when no compiler or liboctomap is available."""
    cxx = shutil.which("g++") or shutil.which("c++")
    if cxx is None or shutil.which("pkg-config") is None:
        return None
    flags = subprocess.run(["pkg-config", "--cflags", "--libs", "octomap"],
                           capture_output=True, text=True)
    if flags.returncode != 0:
        return None
    exe = Path(outdir) / "octomap_insert"
    # -fno-devirtualize: the calls go through the vtable to liboctomap's own compiled
    # code instead of a copy the compiler instantiates from the headers
    subprocess.run([cxx, "-O2", "-DNDEBUG", "-fno-devirtualize", "-std=c++17", str(SOURCE),
                    "-o", str(exe),
                    *flags.stdout.split()], check=True)
    return exe


def write_scan_bin(path: Path, points, origin) -> Path:
    data = np.concatenate([np.asarray(origin, np.float32).ravel(),
                           np.asarray(points, np.float32).ravel()])
    data.astype(np.float32).tofile(path)
    return path


def octomap_insert(exe: Path, workdir: Path, scans, resolution, *, prob_hit=0.7,
                   prob_miss=0.4, clamping_min=0.1192, clamping_max=0.971,
                   max_range=None, discretize=False) -> bytes:
    """Insert `scans` ((points, origin) pairs) with liboctomap; return the .ot bytes."""
    workdir = Path(workdir)
    files = [str(write_scan_bin(workdir / f"scan{i}.bin", p, o))
             for i, (p, o) in enumerate(scans)]
    out = workdir / "reference.ot"
    subprocess.run([str(exe), str(out), repr(resolution), repr(prob_hit), repr(prob_miss),
                    repr(clamping_min), repr(clamping_max),
                    repr(-1.0 if max_range is None else max_range),
                    "1" if discretize else "0", *files], check=True)
    return out.read_bytes()


def time_octomap_insert(exe: Path, scan_file: Path, resolution, repeats=3,
                        max_range=None) -> float:
    """Best time (s) liboctomap takes to insert the scan in `scan_file` into a fresh tree."""
    out = subprocess.run([str(exe), "--time", str(repeats), repr(resolution),
                          repr(-1.0 if max_range is None else max_range), str(scan_file)],
                         check=True, capture_output=True, text=True)
    return float(out.stdout)


def time_octomap_sequence(exe: Path, scan_files, resolution, *, rays=False,
                          max_range=None) -> list[float]:
    """Seconds liboctomap takes for each scan, inserted in order into one tree
    (``insertPointCloud``, or ``insertPointCloudRays`` with `rays`)."""
    out = subprocess.run([str(exe), "--sequence", "rays" if rays else "cloud", repr(resolution),
                          repr(-1.0 if max_range is None else max_range),
                          *map(str, scan_files)], check=True, capture_output=True, text=True)
    return [float(v) for v in out.stdout.split()]


# ---------------------------------------------------------------------- mode="ray" model
def logodds32(p: float) -> np.float32:
    return f32(math.log(p / (1.0 - p)))


def _key(c: np.float32, rf: float) -> int | None:
    k = math.floor(rf * float(c)) + MAX_VAL
    return k if 0 <= k < 2 * MAX_VAL else None


def _norm(v) -> float:
    # Vector3::norm: float products and sums, returned as double, sqrt in double
    sq = f32(f32(v[0] * v[0]) + f32(v[1] * v[1]))
    sq = f32(sq + f32(v[2] * v[2]))
    return math.sqrt(float(sq))


def ray_keys(origin, end, resolution):
    """Port of liboctomap's OcTreeBaseImpl::computeRayKeys (cells strictly before `end`)."""
    rf = 1.0 / resolution
    ko = [_key(c, rf) for c in origin]
    ke = [_key(c, rf) for c in end]
    if ko == ke:
        return []
    ray = [tuple(ko)]
    direction = [f32(end[i] - origin[i]) for i in range(3)]
    length = f32(_norm(direction))
    direction = [f32(d / length) for d in direction]
    step, t_max, t_delta = [0] * 3, [0.0] * 3, [0.0] * 3
    for i in range(3):
        step[i] = 1 if direction[i] > 0 else (-1 if direction[i] < 0 else 0)
        if step[i]:
            border = (float(ko[i] - MAX_VAL) + 0.5) * resolution
            border += float(f32(step[i] * resolution * 0.5))
            t_max[i] = (border - float(origin[i])) / float(direction[i])
            t_delta[i] = resolution / abs(float(direction[i]))
        else:
            t_max[i] = t_delta[i] = np.finfo(np.float64).max
    current = list(ko)
    while True:
        if t_max[0] < t_max[1]:
            dim = 0 if t_max[0] < t_max[2] else 2
        else:
            dim = 1 if t_max[1] < t_max[2] else 2
        current[dim] += step[dim]
        t_max[dim] += t_delta[dim]
        if current == ke:
            return ray
        if min(t_max) > float(length):
            return ray
        ray.append(tuple(current))


def _ray_end(origin, point, max_range):
    """The end liboctomap uses for a ray, and whether it was truncated."""
    d = [f32(point[i] - origin[i]) for i in range(3)]
    if max_range is None or _norm(d) <= max_range:
        return point, False
    n = f32(_norm(d))
    unit = [f32(c / n) for c in d]
    return [f32(origin[i] + f32(unit[i] * f32(max_range))) for i in range(3)], True


def ray_mode_reference(scans, resolution, *, prob_hit=0.7, prob_miss=0.4,
                       clamping_min=0.1192, clamping_max=0.971, max_range=None):
    """Cell key → float32 log-odds after inserting `scans` with per-ray counting."""
    l_hit, l_miss = logodds32(prob_hit), logodds32(prob_miss)
    lo, hi = logodds32(clamping_min), logodds32(clamping_max)
    rf = 1.0 / resolution
    values: dict[tuple, np.float32] = {}
    for points, origin in scans:
        o = [f32(c) for c in np.asarray(origin, np.float32)]
        counts = defaultdict(lambda: [0, 0])
        for p in np.asarray(points, np.float32):
            p = [f32(c) for c in p]
            end, truncated = _ray_end(o, p, max_range)
            for key in ray_keys(o, end, resolution):
                counts[key][0] += 1
            if not truncated:
                counts[tuple(_key(c, rf) for c in p)][1] += 1
        for key, (n_free, n_hit) in counts.items():
            delta = f32(n_free * float(l_miss) + n_hit * float(l_hit))
            value = f32(values.get(key, f32(0.0)) + delta)
            values[key] = lo if value < lo else (hi if value > hi else value)
    return values


def leaf_values(tree) -> dict[tuple, np.float32]:
    """Cell key → log-odds of every finest-level cell of `tree` (expanded on a copy)."""
    copy = type(tree).from_bytes(tree.to_bytes("ot"), **tree._sensor_params())
    centers, sizes, values = copy.expand().leaves()
    assert np.all(np.isclose(sizes, tree.resolution))
    keys = np.floor(centers / tree.resolution).astype(np.int64) + MAX_VAL
    return {tuple(k): v for k, v in zip(keys.tolist(), values)}


def knn_reference(scans, resolution, *, k, p_u, p_l, p_m, p_m_out, p_min, p_max,
                  max_range, score_stats=None):
    """Cell key → float32 log-odds after inserting `scans` with the k-NN inverse sensor
    model: brute-force neighbours, Welford one point at a time (or the fixed
    `score_stats` (mean, std)), the normal CDF from ``math.erfc``, the ray port above,
    one clamped update per cell and scan."""
    rf = 1.0 / resolution
    l_in, l_out = logodds32(p_m), logodds32(p_m_out)
    lo, hi = logodds32(p_min), logodds32(p_max)
    values: dict[tuple, np.float32] = {}
    count, mean, m2 = 0, 0.0, 0.0
    for points, origin in scans:
        o = [f32(c) for c in np.asarray(origin, np.float32)]
        near, cut = [], []
        for p in np.asarray(points, np.float32):
            p = [f32(c) for c in p]
            end, truncated = _ray_end(o, p, max_range)
            (cut if truncated else near).append(end)
        pts = np.array(near, dtype=np.float64).reshape(-1, 3)
        scores = []
        for i in range(len(pts)):
            d = sorted(math.dist(pts[i], pts[j]) for j in range(len(pts)) if j != i)
            scores.append(sum(d[:k]) / k if len(d) >= k else math.inf)
        for s in scores:
            if math.isfinite(s):
                count += 1
                delta = s - mean
                mean += delta / count
                m2 += delta * (s - mean)
        mu, std = (mean, math.sqrt(m2 / count) if count else 0.0) if score_stats is None \
            else score_stats
        point_sum: dict[tuple, float] = defaultdict(float)
        for p, s in zip(near, scores):
            if not math.isfinite(s):
                f = 1.0
            elif std > 0:
                f = 0.5 * math.erfc(-(s - mu) / (std * math.sqrt(2.0)))
            else:
                f = 1.0 if s > mu else (0.0 if s < mu else 0.5)
            prob = p_u - (p_u - p_l) * f
            point_sum[tuple(_key(c, rf) for c in p)] += math.log(prob / (1.0 - prob))
        update: dict[tuple, np.float32] = {key: f32(v) for key, v in point_sum.items()}
        for end in near:
            for key in ray_keys(o, end, resolution):
                update.setdefault(key, l_in)
        for end in cut:
            for key in ray_keys(o, end, resolution):
                update.setdefault(key, l_out)
        for key, delta in update.items():
            value = f32(values.get(key, f32(0.0)) + delta)
            values[key] = lo if value < lo else (hi if value > hi else value)
    return values
