// Bonxai's ray model on the block grid (ext/_block_grid.h): GridMap.insert_scan with
// ray_model="bresenham".
//
// A different map from OctoMap's, for speed (the rules are Bonxai's ProbabilisticMap):
//
// * a point's cell is floor(coordinate / resolution) on each axis, in double precision,
//   as OctoMap's key; a point at `max_range` or farther from the origin is moved onto
//   the sphere of that radius and its cell is updated as free (a miss) instead of
//   occupied (a hit);
// * the points are taken in order and each cell is updated once a scan: a point whose
//   cell was already updated in this scan changes nothing and casts no ray, so one ray
//   goes to each distinct end cell;
// * then each end cell (those of hits first, then those of misses, in the order they
//   were first updated) casts one integer Bresenham line from the origin's cell: the
//   origin's cell and the cells up to, not including, the end cell, visited by an error
//   term per axis (a step where twice the error reaches the longest axis' length); a
//   ray whose end cell is the origin's visits nothing. Each visited cell not updated
//   yet in this scan gets a miss.
//
// The updates are OctoMap's sensor model on float32 log-odds with its clamping (Bonxai
// stores fixed-point integers). The per-scan marks are the blocks' epoch marks, so a
// cell is skipped only when this scan updated it (Bonxai's 3-valued marker also skips a
// cell last updated exactly 3, 6, ... scans earlier).
#ifndef OCCGP_BRESENHAM_H
#define OCCGP_BRESENHAM_H

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <vector>

#include "_block_grid.h"
#include "_keys.h"
#include "_grid_apply.h"
#include "_status.h"

namespace occgp {

struct BresenhamStats {
  uint64_t rays;      // distinct end cells, each one ray
  uint64_t visits;    // cells visited by the rays
  uint64_t updated;   // cells updated (end cells and free cells)
  int64_t first_bad;  // with out_of_range: the first point whose end cell has no key
};

// The key of a coordinate in double precision (OctoMap's floor(c / resolution) + 2^15,
// scaled_key), or -1 outside the 16-bit key range.
static inline int64_t bresenham_key(double c, double inv_resolution) {
  int64_t key;
  return scaled_key(c * inv_resolution, &key) ? key : -1;
}

// Walk the Bresenham line from `from` to `to` (keys): f(packed key) for the start cell
// and the cells before `to`.
template <class F>
static inline uint64_t bresenham_walk(const int64_t from[3], const int64_t to[3], F f) {
  if (from[0] == to[0] && from[1] == to[1] && from[2] == to[2]) return 0;
  int64_t coord[3] = {from[0], from[1], from[2]};
  int64_t delta[3], step[3], error[3] = {0, 0, 0};
  for (int a = 0; a < 3; ++a) {
    const int64_t d = to[a] - from[a];
    step[a] = d < 0 ? -1 : 1;
    delta[a] = d < 0 ? -d : d;
  }
  const int64_t longest = std::max(std::max(delta[0], delta[1]), delta[2]);
  f(pack_keys(coord[0], coord[1], coord[2]));
  for (int64_t i = 0; i < longest - 1; ++i) {
    for (int a = 0; a < 3; ++a) {  // without branches: the steps of two axes are erratic
      error[a] += delta[a];
      const int64_t go = -static_cast<int64_t>((error[a] << 1) >= longest);  // 0 or all ones
      coord[a] += step[a] & go;
      error[a] -= longest & go;
    }
    f(pack_keys(coord[0], coord[1], coord[2]));
  }
  return static_cast<uint64_t>(longest);
}

// Insert one scan (n points, xyz float32) seen from `origin`. `max_range` < 0: no limit.
// Nothing changes unless every end cell and the origin's have keys (else out_of_range).
static inline Status bresenham_scan(BlockGrid& grid, const float* points, ptrdiff_t n,
                                    const float origin[3], double resolution,
                                    double max_range, float hit, float miss, float lo,
                                    float hi, BresenhamStats* stats) {
  const double inv = 1.0 / resolution;
  const double o[3] = {origin[0], origin[1], origin[2]};
  int64_t ko[3];
  stats->first_bad = -1;
  for (int a = 0; a < 3; ++a)
    if ((ko[a] = bresenham_key(o[a], inv)) < 0) return Status::out_of_range;
  const double max_sq = max_range < 0 ? INFINITY : max_range * max_range;
  // the end cells, checked before anything changes; the top bit flags a miss
  std::vector<uint64_t> ends(static_cast<size_t>(n));
  const uint64_t kMiss = 1ull << 63;
  for (ptrdiff_t i = 0; i < n; ++i) {
    double p[3] = {points[3 * i], points[3 * i + 1], points[3 * i + 2]};
    const double v[3] = {p[0] - o[0], p[1] - o[1], p[2] - o[2]};
    const double sq = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
    const bool is_miss = sq >= max_sq;
    if (is_miss) {
      const double norm = std::sqrt(sq);  // Bonxai's arithmetic: o + (v / |v|) * max_range
      for (int a = 0; a < 3; ++a) p[a] = o[a] + (v[a] / norm) * max_range;
    }
    int64_t k[3];
    for (int a = 0; a < 3; ++a) {
      if ((k[a] = bresenham_key(p[a], inv)) < 0) {
        stats->first_bad = i;
        return Status::out_of_range;
      }
    }
    ends[i] = pack_keys(k[0], k[1], k[2]) | (is_miss ? kMiss : 0);
  }
  grid.begin_scan();
  BlockAccessor cache(&grid);
  std::vector<uint64_t> hits, misses;  // distinct end cells, in first-update order
  uint64_t updated = 0;
  for (ptrdiff_t i = 0; i < n; ++i) {
    const uint64_t key = ends[i] & ~kMiss;
    GridBlock* block = cache.block(key);
    if (!grid.mark(block, key)) continue;
    const std::pair<float*, bool> cell = grid.emplace_in(block, key);
    const bool is_miss = ends[i] & kMiss;
    apply_update(cell.first, cell.second, is_miss ? miss : hit, lo, hi);
    (is_miss ? misses : hits).push_back(key);
    ++updated;
  }
  uint64_t visits = 0;
  auto clear = [&](uint64_t key) {
    GridBlock* block = cache.block(key);
    if (!grid.mark(block, key)) return;
    const std::pair<float*, bool> cell = grid.emplace_in(block, key);
    apply_update(cell.first, cell.second, miss, lo, hi);
    ++updated;
  };
  for (const std::vector<uint64_t>* list : {&hits, &misses}) {
    for (uint64_t key : *list) {
      const int64_t end[3] = {static_cast<int64_t>(key & 0xFFFF),
                              static_cast<int64_t>((key >> 16) & 0xFFFF),
                              static_cast<int64_t>((key >> 32) & 0xFFFF)};
      visits += bresenham_walk(ko, end, clear);
    }
  }
  stats->rays = hits.size() + misses.size();
  stats->visits = visits;
  stats->updated = updated;
  return Status::ok;
}

}  // namespace occgp

#endif  // OCCGP_BRESENHAM_H
