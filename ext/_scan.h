// A scan's cell updates, shared by the compiled maps: rays, super rays and the culling
// region (declared for Cython in ext/_scan.pxd).
//
// scan_updates turns a scan into one update per cell, and each map applies them its
// own way (ext/_octree.pyx in one pass over the tree, ext/_grid.pyx in its hash map).
// The rays of a scan may be walked on several OpenMP threads, each into its own
// counts, merged (integer sums) before the cells are collected: the modules that use
// this are built with OpenMP (OPENMP_MODULES in setup.py). Keys, ray ends and the
// sensor model come from a liboctomap OcTree of the map's resolution, so every map
// finds the cells liboctomap finds. Build without floating-point contraction
// (-ffp-contract=off), as the rest of the core. The functions are static: each module
// gets its own copy, which the compiler specialises (its FreeTest, constant arguments).
#ifndef OCCGP_SCAN_H
#define OCCGP_SCAN_H

#include <time.h>

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <exception>
#include <vector>

#ifdef _OPENMP
#include <omp.h>
#endif

#include <octomap/OcTree.h>

#include "_keys.h"
#include "_keytable.h"
#include "_raywalk.h"
#include "_status.h"

namespace occgp {

namespace scan_detail {
constexpr int kMaxVal = 32768;                 // liboctomap's tree_max_val
constexpr uint64_t kMaxRegionCells = 1 << 28;  // larger scan key boxes are not culled
constexpr uint64_t kMaxDenseCells = 1 << 24;   // up to this, free counts live in arrays
constexpr ptrdiff_t kMinThreadRays = 64;       // fewer rays per thread: fewer threads
constexpr int kMaxThreads = 256;
constexpr ptrdiff_t kMinParallelCollect = 1 << 16;  // fewer cells: collected on one thread
constexpr int kChunksPerThread = 16;  // the rays are handed out in chunks, first come first served
}  // namespace scan_detail

// Whether the map's cell at a key is known and at the lower clamping bound.
typedef bool (*FreeTest)(void* map, const octomap::OcTreeKey& key);

struct ScanCell {
  uint64_t key;  // packed key (pack_key of ext/_keys.pxd)
  float update;  // the log-odds to add, as updateNode(key, update) adds it
};

struct ScanStats {
  long region_cells;     // cells in the culling region; -1 without culling
  long rays;             // rays traversed (super rays count once)
  long traversed_cells;  // cell visits that counted a ray
  long unnecessary;      // with `diagnose`: visits to cells whose update is a no-op
  timespec clock[5];     // start; end points, super rays, culling region, traversal done
};

// The statistics of a scan before (or without) its traversal, every clock now.
static inline void empty_stats(ScanStats* stats) {
  stats->region_cells = -1;
  stats->rays = 0;
  stats->traversed_cells = 0;
  stats->unnecessary = -1;
  for (int k = 0; k < 5; ++k) clock_gettime(CLOCK_MONOTONIC, &stats->clock[k]);
}

namespace scan_detail {

static inline bool in_box(const octomap::OcTreeKey& key, const int* lo, const uint64_t* dims) {
  return static_cast<uint64_t>(static_cast<int>(key[0]) - lo[0]) < dims[0] &&
         static_cast<uint64_t>(static_cast<int>(key[1]) - lo[1]) < dims[1] &&
         static_cast<uint64_t>(static_cast<int>(key[2]) - lo[2]) < dims[2];
}

static inline uint64_t box_index(const octomap::OcTreeKey& key, const int* lo, const uint64_t* dims) {
  return (static_cast<uint64_t>(key[2] - lo[2]) * dims[1] +
          static_cast<uint64_t>(key[1] - lo[1])) * dims[0] +
         static_cast<uint64_t>(key[0] - lo[0]);
}

static inline octomap::OcTreeKey box_key(uint64_t idx, const int* lo, const uint64_t* dims) {
  octomap::OcTreeKey key;
  key[0] = static_cast<octomap::key_type>(lo[0] + idx % dims[0]);
  idx /= dims[0];
  key[1] = static_cast<octomap::key_type>(lo[1] + idx % dims[1]);
  key[2] = static_cast<octomap::key_type>(lo[2] + idx / dims[1]);
  return key;
}

// Count `w` rays through the cell (kx, ky, kz) in `table`: cells outside the scan's
// dense box, off the hot path of count_free.
__attribute__((noinline, cold)) static void count_free_table(int kx, int ky, int kz, uint32_t w,
                                                             KeyTable* table) {
  octomap::OcTreeKey key;
  key[0] = static_cast<octomap::key_type>(kx);
  key[1] = static_cast<octomap::key_type>(ky);
  key[2] = static_cast<octomap::key_type>(kz);
  table->get(pack_key(key))->n_free += w;
}

// Count `w` rays through the cell (kx, ky, kz): in the scan's dense box (`free_counts`,
// new cells appended to `touched`), or the table.
static inline void count_free(int kx, int ky, int kz, uint32_t w, bool dense, const int* lo,
                              const uint64_t* dims, uint32_t* free_counts,
                              std::vector<uint64_t>* touched, KeyTable* table) {
  const uint64_t x = static_cast<uint64_t>(kx - lo[0]);
  const uint64_t y = static_cast<uint64_t>(ky - lo[1]);
  const uint64_t z = static_cast<uint64_t>(kz - lo[2]);
  // liboctomap's traversal may step past the end cell before its length test stops
  // it: such cells lie outside the box and go to the table
  if (dense && x < dims[0] && y < dims[1] && z < dims[2]) {
    const uint64_t idx = (z * dims[1] + y) * dims[0] + x;
    if (free_counts[idx] == 0) touched->push_back(idx);
    free_counts[idx] += w;
  } else {
    count_free_table(kx, ky, kz, w, table);
  }
}

// One cell's update of a scan: liboctomap's insertPointCloud rule, or ray counting.
static inline float update_value(uint32_t n_free, uint32_t n_hit, bool ray_mode, float l_hit,
                          float l_miss) {
  if (ray_mode) return static_cast<float>(n_free * static_cast<double>(l_miss) +
                                          n_hit * static_cast<double>(l_hit));
  return n_hit ? l_hit : l_miss;
}

// liboctomap's coordToKeyChecked on one axis, with its arithmetic (floor of the double
// product, plus 32768); the range is tested on the double first, where liboctomap
// would cast a huge value to int unchecked.
static inline bool key_checked(double resolution_factor, float coordinate, octomap::key_type* key) {
  const double scaled = std::floor(resolution_factor * static_cast<double>(coordinate));
  if (scaled < -kMaxVal || scaled >= kMaxVal) return false;
  key[0] = static_cast<octomap::key_type>(static_cast<int>(scaled) + kMaxVal);
  return true;
}

// The murmur3 finaliser: spreads the bits of a signature for hashing.
static inline uint64_t mix(uint64_t k) {
  k ^= k >> 33;
  k *= 0xff51afd7ed558ccdULL;
  k ^= k >> 33;
  return k;
}

static inline double dmin(double a, double b) { return a < b ? a : b; }
static inline double dmax(double a, double b) { return a > b ? a : b; }

struct Crossing {
  int axis;       // the axis whose border the rays of a group cross
  int other;      // the coordinate read at that border
  double border;  // the border's position on `axis`, in metres
  int key_lo;     // lowest key `other` may have there
  int n_keys;     // how many keys `other` may have there
  int key_min;    // the keys of `other` from the origin's cell to the end cell:
  int key_max;    // only the borders between them are crossed
};

}  // namespace scan_detail

// Group the rays of a scan into super rays (Kwon, dissertation 2.3.1-2.3.4).
//
// Fills `rays` (indices of the rays to traverse) and `weights` (how many rays each
// stands for). Rays ending in a cell that holds at least `threshold` end points are
// classified by their *signature*: at every border a ray crosses between the origin's
// cell and its end cell, the keys of the other coordinates there; only the crossings
// where the rays into that end cell can differ ("critical", the mapping lines) are
// evaluated. Equal signatures mean the same traversed cells, so one ray of each class
// is traversed with the class size as weight.
//
// Exactness against liboctomap's float traversal: a ray joins a class only when it is
// *certified* -- its end point clears the borders of its cell by more than `delta` =
// 2^-19 (length + resolution), 4 x the error of liboctomap's float direction, and at
// every crossing (critical or not) the other coordinate clears the borders of its cell
// that the ray crosses (those between the origin's cell and the end cell) by more than
// `delta` plus 2^-21 resolution times the slope |d_b / d_a|, for the single-precision
// half-cell offset of liboctomap's borders. Its float traversal then equals the exact
// one. Every other ray is traversed on its own. A crossing is skipped as non-critical
// only when every certified ray of the group clears the same borders there by that
// margin: the slopes are bounded over the end cell shrunk by `delta` (where the origin
// lies on the end cell's face, at t = 0 of the rays' first crossing, rays that end
// near that face are steep, and the half-cell offset moves their first crossing far
// along them), and the key ranges are computed in doubles, cut to the keys the rays
// can have.
static inline void super_rays(double res, const octomap::point3d& o, const octomap::OcTreeKey& ko,
                       const std::vector<octomap::point3d>& ends,
                       const std::vector<octomap::OcTreeKey>& end_keys,
                       const std::vector<uint8_t>& truncated, KeyTable& table, int threshold,
                       std::vector<uint32_t>& rays, std::vector<uint32_t>& weights) {
  using namespace scan_detail;
  const double rf = 1.0 / res;
  double oc[3], lo[3], hi[3], pc[3], dp[3], inv[3];
  const ptrdiff_t n = static_cast<ptrdiff_t>(ends.size());
  uint32_t n_groups = 0;
  std::vector<uint32_t> group_of, offsets, order;
  std::vector<Crossing> crossings;
  std::vector<uint64_t> class_code;
  std::vector<uint32_t> class_ray;
  oc[0] = o.x();
  oc[1] = o.y();
  oc[2] = o.z();
  const double eb = std::ldexp(res, -21);  // 4 x the single-precision offset of the borders
  // groups of rays by end cell, for the cells with at least `threshold` end points
  group_of.assign(n, 0);
  for (ptrdiff_t i = 0; i < n; ++i) {
    if (truncated[i]) continue;
    KeyCounts* entry = table.find(pack_key(end_keys[i]));
    if (entry == nullptr || entry->n_hit < static_cast<uint32_t>(threshold)) continue;
    if (entry->group == 0) {
      n_groups += 1;
      entry->group = n_groups;
    }
    group_of[i] = entry->group;
  }
  offsets.assign(n_groups + 2, 0);
  for (ptrdiff_t i = 0; i < n; ++i) {
    if (group_of[i]) {
      offsets[group_of[i] + 1] += 1;
    } else {
      rays.push_back(static_cast<uint32_t>(i));
      weights.push_back(1);
    }
  }
  for (ptrdiff_t g = 1; g < static_cast<ptrdiff_t>(n_groups) + 2; ++g) offsets[g] += offsets[g - 1];
  order.resize(offsets[n_groups + 1]);
  for (ptrdiff_t i = 0; i < n; ++i) {
    if (group_of[i]) {
      order[offsets[group_of[i]]] = static_cast<uint32_t>(i);
      offsets[group_of[i]] += 1;
    }
  }
  // offsets[g] now ends group g (1-based), i.e. starts group g + 1
  for (ptrdiff_t g = 1; g < static_cast<ptrdiff_t>(n_groups) + 1; ++g) {
    const ptrdiff_t first = offsets[g - 1];
    const octomap::OcTreeKey kv = end_keys[order[first]];
    double far2 = 0;
    for (int a = 0; a < 3; ++a) {
      lo[a] = (static_cast<double>(kv[a]) - kMaxVal) * res;
      hi[a] = (static_cast<double>(kv[a]) + 1 - kMaxVal) * res;
      far2 += dmax(std::pow(lo[a] - oc[a], 2.0), std::pow(hi[a] - oc[a], 2.0));
    }
    // 2^-19 (length + res): 4 x the error of liboctomap's float32 ray direction
    const double delta = std::ldexp(std::sqrt(far2) + res, -19);
    bool ok = true;
    crossings.clear();
    int code_bits = 0;
    for (int a = 0; ok && a < 3; ++a) {
      const int d_a = static_cast<int>(kv[a]) - static_cast<int>(ko[a]);
      if (d_a == 0) continue;
      const int step = d_a > 0 ? 1 : -1;
      for (int b = a + 1; b < 3; ++b) {
        if (kv[b] == ko[b]) continue;  // the rays stay in one b-slab: the end margins certify it
        // the slopes d_b / d_a of the rays into the end cell, extreme at the corners of
        // the cell shrunk by the end margin `delta` (every other ray is traversed on its
        // own): finite even where the origin lies on the end cell's a-face, and there as
        // steep as such rays may be
        double r_min = 1e300, r_max = -1e300;
        for (int i = 0; i < 4; ++i) {
          const double s = ((i & 1) ? hi[a] - delta : lo[a] + delta) - oc[a];
          if (!(s * step >= 0.5 * delta)) {
            ok = false;  // degenerate end cell: leave the group plain
            break;
          }
          const double r = (((i & 2) ? hi[b] : lo[b]) - oc[b]) / s;
          r_min = dmin(r_min, r);
          r_max = dmax(r_max, r);
        }
        if (!ok) break;
        const double slack = delta + eb * dmax(std::fabs(r_min), std::fabs(r_max));
        Crossing c;
        c.key_min = std::min(static_cast<int>(ko[b]), static_cast<int>(kv[b])) - kMaxVal;
        c.key_max = std::max(static_cast<int>(ko[b]), static_cast<int>(kv[b])) - kMaxVal;
        for (long jj = 1; jj < std::abs(d_a) + 1; ++jj) {
          const double border =
              (static_cast<double>(static_cast<int>(ko[a]) + (step > 0 ? jj : 1 - jj)) - kMaxVal) *
              res;
          const double s = border - oc[a];
          const double b1 = oc[b] + s * r_min;
          const double b2 = oc[b] + s * r_max;
          // the keys the rays may have there, in doubles (steep rays give far ends), cut
          // to the keys between the origin's and the end cell's: the borders outside
          // are never crossed
          const double k_first = dmax(std::floor((dmin(b1, b2) - slack) * rf), c.key_min);
          const double k_last = dmin(std::floor((dmax(b1, b2) + slack) * rf), c.key_max);
          if (!(k_first <= k_last)) {
            ok = false;  // no key left (rounding): leave the group plain
            break;
          }
          c.key_lo = static_cast<int>(k_first);
          const int nk = static_cast<int>(k_last) - c.key_lo + 1;
          if (nk == 1) continue;  // every ray of the group has the same key here
          code_bits += 64 - __builtin_clzll(static_cast<uint64_t>(nk - 1));
          if (code_bits > 62) {
            ok = false;
            break;
          }
          c.axis = a;
          c.other = b;
          c.border = border;
          c.n_keys = nk;
          crossings.push_back(c);
        }
        if (!ok) break;
      }
    }
    if (ok) {
      // each crossing where the rays can take nk keys splits them nk ways: when that
      // alone leaves fewer rays than classes, grouping cannot pay its cost
      long segments = 1;
      for (const Crossing& c : crossings) segments += c.n_keys - 1;
      if (segments >= static_cast<ptrdiff_t>(offsets[g]) - first) ok = false;
    }
    if (!ok) {
      for (ptrdiff_t m = first; m < static_cast<ptrdiff_t>(offsets[g]); ++m) {
        rays.push_back(order[m]);
        weights.push_back(1);
      }
      continue;
    }
    // the classes: equal signatures, found in a small hash table
    size_t cap = 16;
    while (cap < static_cast<size_t>(2 * (static_cast<ptrdiff_t>(offsets[g]) - first))) cap <<= 1;
    class_code.assign(cap, KeyTable::kEmpty);  // signatures have at most 62 bits
    class_ray.resize(cap);
    for (ptrdiff_t m = first; m < static_cast<ptrdiff_t>(offsets[g]); ++m) {
      const uint32_t idx = order[m];
      pc[0] = ends[idx].x();
      pc[1] = ends[idx].y();
      pc[2] = ends[idx].z();
      ok = true;
      for (int a = 0; a < 3; ++a) {
        if (dmin(pc[a] - lo[a], hi[a] - pc[a]) <= delta) ok = false;
        dp[a] = pc[a] - oc[a];
        // the rays of a group cross borders of axis a only when dp[a] != 0
        inv[a] = dp[a] != 0 ? 1.0 / dp[a] : 0.0;
      }
      uint64_t code = 0;
      for (size_t j = 0; ok && j < crossings.size(); ++j) {
        const Crossing& c = crossings[j];
        const double r_abs = std::fabs(dp[c.other] * inv[c.axis]);
        const double y = oc[c.other] + (c.border - oc[c.axis]) * inv[c.axis] * dp[c.other];
        const double kb = std::floor(y * rf);
        // the margin to the borders of that key the rays cross
        double margin = 1e300;
        if (kb > c.key_min) margin = y - kb * res;
        if (kb < c.key_max) margin = dmin(margin, (kb + 1) * res - y);
        if (!(margin > delta + eb * r_abs) || kb < c.key_lo || kb >= c.key_lo + c.n_keys) {
          ok = false;
        } else {
          code = code * static_cast<uint64_t>(c.n_keys) +
                 static_cast<uint64_t>(static_cast<int>(kb) - c.key_lo);
        }
      }
      if (ok) {
        size_t h = mix(code) & (cap - 1);
        while (class_code[h] != KeyTable::kEmpty && class_code[h] != code) h = (h + 1) & (cap - 1);
        if (class_code[h] == code) {
          weights[class_ray[h]] += 1;
        } else {
          class_code[h] = code;
          class_ray[h] = static_cast<uint32_t>(rays.size());
          rays.push_back(idx);
          weights.push_back(1);
        }
      } else {
        rays.push_back(idx);
        weights.push_back(1);
      }
    }
  }
}

// Grow the scan's culling region (Kwon, dissertation 2.3.5, Alg. 3).
//
// Breadth first over Manhattan levels from the sensor's cell, inside the key box of
// the scan: a cell joins when it is fully free (log-odds at the lower clamp), holds no
// end point of the scan (occgp's exactness rule), and each of its test cells (one step
// toward the origin on every axis where its key differs from the origin's) is already
// in. Returns the number of cells, or -1 when the box is too large (no culling).
static inline long build_region(FreeTest fully_free, void* map, const octomap::OcTreeKey& ko,
                         const int* lo, const int* hi, int max_level, const KeyTable& ends,
                         CellBox& region) {
  using namespace scan_detail;
  CellBox seen;
  std::vector<octomap::OcTreeKey> frontier, next_frontier;
  if (!region.reset(lo, hi, kMaxRegionCells) || !seen.reset(lo, hi, kMaxRegionCells)) return -1;
  if (!fully_free(map, ko) || ends.contains(pack_key(ko))) return 0;
  region.set(ko[0], ko[1], ko[2]);
  seen.set(ko[0], ko[1], ko[2]);
  frontier.push_back(ko);
  long count = 1;
  for (int level = 1; level < max_level + 1; ++level) {
    next_frontier.clear();
    for (size_t j = 0; j < frontier.size(); ++j) {
      const octomap::OcTreeKey c = frontier[j];
      for (int axis = 0; axis < 3; ++axis) {
        for (int d = 0; d < 2; ++d) {
          const int step = d == 0 ? 1 : -1;
          if (c[axis] != ko[axis] && (step > 0) != (c[axis] > ko[axis]))
            continue;  // only away from the origin
          octomap::OcTreeKey nb = c;
          nb[axis] = static_cast<octomap::key_type>(static_cast<int>(c[axis]) + step);
          if (!seen.inside(nb[0], nb[1], nb[2]) || seen.test(nb[0], nb[1], nb[2])) continue;
          seen.set(nb[0], nb[1], nb[2]);
          bool ok = true;
          for (int b = 0; b < 3; ++b) {  // test cells: one step back toward the origin
            if (nb[b] == ko[b]) continue;
            octomap::OcTreeKey t = nb;
            t[b] = static_cast<octomap::key_type>(static_cast<int>(nb[b]) +
                                                  (nb[b] > ko[b] ? -1 : 1));
            if (!(region.inside(t[0], t[1], t[2]) && region.test(t[0], t[1], t[2]))) {
              ok = false;
              break;
            }
          }
          if (!ok || ends.contains(pack_key(nb))) continue;
          if (!fully_free(map, nb)) continue;
          region.set(nb[0], nb[1], nb[2]);
          next_frontier.push_back(nb);
          count += 1;
        }
      }
    }
    if (next_frontier.empty()) break;
    frontier.swap(next_frontier);
  }
  return count;
}

namespace scan_detail {

// What the threads of one scan's traversal share, read only.
struct Rays {
  double res;
  const octomap::point3d* origin;
  const octomap::OcTreeKey* key_origin;
  const octomap::point3d* ends;  // per ray: its end after truncation
  const octomap::OcTreeKey* end_keys;
  const uint8_t* end_ok;
  const uint32_t* ray_ids;  // super rays: the rays to walk and their weights; nullptr
  const uint32_t* ray_weights;
  const uint32_t* weights;  // per ray, or nullptr
  const CellBox* region;    // the culling region over the scan's key box
  bool cull;                // the region holds cells
  bool dense;               // counts in box arrays (else in tables)
  const int* lo;            // the scan's key box
  const uint64_t* dims;
  uint64_t max_cells;  // 0: no limit
};

// Walk rays r0 <= r < r1 of a scan (of its super rays when it has them) into one
// thread's counts: cells of the scan's key box in `counts` (dense; new ones appended
// to `touched`), other cells in `table`'s n_free. Adds the cell visits to `traversed`;
// with `visits` (diagnose), counts every visit there too.
//
// With s.max_cells, stops (setting `stop`) once `touched` and the entries of `table`
// past its first `table_base` ones -- distinct cells of the scan, as no two of them
// are one -- outnumber it; stops when another thread set `stop`.
static inline void walk_rays(const Rays* s, ptrdiff_t r0, ptrdiff_t r1, uint32_t* counts,
                      std::vector<uint64_t>* touched, KeyTable* table, size_t table_base,
                      KeyTable* visits, long* traversed, StopFlag* stop) {
  uint32_t w = 1;
  RayWalker walker;
  std::vector<uint64_t> back;
  long n_visits = 0;
  const CellBox* region = s->region;
  for (ptrdiff_t r = r0; r < r1; ++r) {
    if (stop->get()) break;
    ptrdiff_t i;
    if (s->ray_ids != nullptr) {
      i = s->ray_ids[r];
      w = s->ray_weights[r];
    } else {
      i = r;
      if (s->weights != nullptr) w = s->weights[i];
    }
    if (!s->end_ok[i]) continue;  // computeRayKeys's out-of-range check
    bool more = walker.start(s->res, *s->origin, *s->key_origin, s->ends[i], s->end_keys[i]);
    if (more && s->cull) {
      back.clear();
      if (walker.walk_back(*region, back)) {
        // the region's box is the scan's key box, the one `counts` covers
        for (size_t j = 0; j < back.size(); ++j) {
          const uint64_t idx = back[j];
          if (s->dense) {
            if (counts[idx] == 0) touched->push_back(idx);
            counts[idx] += w;
          } else {
            table->get(pack_key(box_key(idx, s->lo, s->dims)))->n_free += w;
          }
          if (visits != nullptr) visits->get(pack_key(box_key(idx, s->lo, s->dims)))->n_free += 1;
        }
        n_visits += back.size();
        more = false;
      } else {
        // the region is closed under stepping toward the origin, so a ray's cells in
        // it form a prefix of its traversal
        while (more && region->inside(walker.key(0), walker.key(1), walker.key(2)) &&
               region->test(walker.key(0), walker.key(1), walker.key(2)))
          more = walker.next();
      }
    }
    while (more) {
      count_free(walker.key(0), walker.key(1), walker.key(2), w, s->dense, s->lo, s->dims,
                 counts, touched, table);
      if (visits != nullptr) {
        octomap::OcTreeKey key;
        key[0] = static_cast<octomap::key_type>(walker.key(0));
        key[1] = static_cast<octomap::key_type>(walker.key(1));
        key[2] = static_cast<octomap::key_type>(walker.key(2));
        visits->get(pack_key(key))->n_free += 1;
      }
      n_visits += 1;
      more = walker.next();
    }
    if (s->max_cells && touched->size() + (table->size() - table_base) > s->max_cells) {
      stop->set();
      break;
    }
  }
  *traversed += n_visits;
}

}  // namespace scan_detail

// Collect one update per cell for a scan of `n` points (rows of three floats, appended
// to `cells`, keys distinct).
//
// Every ray is traversed as liboctomap's computeRayKeys traverses it (RayWalker); the
// cells are collected with their counts (rays passing through, rays ending in) and
// each gets one update: in scan mode l_hit if any ray ends in it, else l_miss
// (liboctomap's insertPointCloud); in ray mode n_free*l_miss + n_hit*l_hit. With
// `culling`, the cells of the scan's culling region (build_region, using `fully_free`
// on `map`) are skipped: they are at the lower clamp and hold no end point, so their
// update is a no-op; rays are walked back from their end until they enter it. With
// `weights` (ray mode; nullptr: none), ray i counts weights[i] times. With
// `superray_threshold` > 0 the rays are first grouped into super rays (super_rays) and
// one ray per class is traversed. `counts` is the caller's scratch array, zero between
// calls unless `counts_dirty` (an exception left it dirty). With `diagnose` (slow),
// stats->unnecessary counts the visits of the walked rays to cells whose update changes
// nothing: fully free cells that no ray ends in (the dissertation's "unnecessary
// traversals", Table 2.3).
//
// Returns Status::out_of_range when a ray's end (after truncation) lies outside the key
// range, else Status::ray_too_short when a ray cannot be walked, collecting nothing
// (the caller finds and reports the rows). With `max_cells` > 0, a scan whose rays
// reach more than that many distinct cells collects nothing and returns
// Status::too_many_cells (a lower bound on them is checked after each ray, so memory
// stays within one ray per thread of it plus the end cells; the exact count decides).
//
// The rays are walked on up to `n_threads` OpenMP threads (fewer for small scans; one
// with `diagnose`), each into its own counts: a slice of `counts` over the scan's key
// box (no more threads than slices fit the dense limit), or, where the box alone
// exceeds the limit, a table of its own. The counts are merged (integer sums) before
// the cells are collected, so the cells, their updates and the statistics are the same
// for every `n_threads`; only the order of `cells` may differ.
//
// With `free_only` (nullptr: none), a ray i with free_only[i] != 0 only clears: it is
// handled as a ray truncated at `max_range` is (octomap_server's ground points) -- its
// cells up to its (possibly truncated) end count as free, its end cell gets nothing
// from it, it is never grouped into a super ray, and its end does not keep a cell out
// of the culling region -- so every method stays exact.
static inline Status scan_updates(const octomap::OcTree& keys, const float* points, ptrdiff_t n,
                           const octomap::point3d& o, double max_range, bool ray_mode,
                           bool culling, const uint32_t* weights, int superray_threshold,
                           FreeTest fully_free, void* map, std::vector<uint32_t>& counts,
                           bool& counts_dirty, std::vector<ScanCell>& cells, ScanStats* stats,
                           bool diagnose, uint64_t max_cells, int n_threads,
                           const uint8_t* free_only = nullptr) {
  using namespace scan_detail;
  using octomap::OcTreeKey;
  using octomap::point3d;
  const int collect_threads = diagnose ? 1 : std::max(1, std::min(n_threads, kMaxThreads));
  const bool weighted = weights != nullptr;
  std::vector<uint32_t> ray_ids, ray_weights;  // the rays to traverse, super rays
  ptrdiff_t n_trav = n;
  std::vector<point3d> ends;
  std::vector<uint8_t> truncated;
  KeyTable table;
  CellBox region;
  OcTreeKey ko, key;
  int lo[3], hi[3];
  int max_level = 0;
  const float l_hit = keys.getProbHitLog(), l_miss = keys.getProbMissLog();
  std::vector<uint64_t> touched;  // box indices with a nonzero count
  uint64_t dims[3];
  uint64_t box_cells = 1;
  std::vector<OcTreeKey> end_keys;
  std::vector<uint8_t> end_ok;
  KeyTable visits;  // with diagnose: walked visits per cell
  const double res = keys.getResolution(), rf = 1.0 / res;
  Rays rays;
  StopFlag stop;
  long out_of_range = 0, too_short = 0;
  empty_stats(stats);
  keys.coordToKeyChecked(o, ko);
  for (int axis = 0; axis < 3; ++axis) lo[axis] = hi[axis] = ko[axis];
  ends.resize(n);
  end_keys.resize(n);
  end_ok.resize(n);
  truncated.resize(n);
  table.reset(static_cast<size_t>(n) / 8);
  // end cells first: they bound the region and may never join it
  for (ptrdiff_t i = 0; i < n; ++i) {
    const float* p = points + 3 * i;
    truncated[i] = effective_end(o, point3d(p[0], p[1], p[2]), max_range, &ends[i]);
    if (free_only != nullptr && free_only[i]) truncated[i] = 1;  // clears only, as a cut ray
    end_ok[i] = key_checked(rf, ends[i].x(), &key[0]) && key_checked(rf, ends[i].y(), &key[1]) &&
                key_checked(rf, ends[i].z(), &key[2]);
    if (!end_ok[i]) {
      ++out_of_range;
      continue;
    }
    if (!(key == ko) && !walkable(o, ends[i])) {
      end_ok[i] = false;  // a ray too short to walk: the caller reports it
      ++too_short;
      continue;
    }
    end_keys[i] = key;
    int level = 0;
    for (int axis = 0; axis < 3; ++axis) {
      lo[axis] = std::min(lo[axis], static_cast<int>(key[axis]));
      hi[axis] = std::max(hi[axis], static_cast<int>(key[axis]));
      level += std::abs(static_cast<int>(key[axis]) - static_cast<int>(ko[axis]));
    }
    max_level = std::max(max_level, level);
    if (!truncated[i]) table.get(pack_key(key))->n_hit += weighted ? weights[i] : 1;
  }
  clock_gettime(CLOCK_MONOTONIC, &stats->clock[1]);
  // nothing changed: the caller reports the bad rows
  if (out_of_range) return Status::out_of_range;
  if (too_short) return Status::ray_too_short;
  if (superray_threshold > 0) {
    super_rays(res, o, ko, ends, end_keys, truncated, table, superray_threshold, ray_ids,
               ray_weights);
    n_trav = static_cast<ptrdiff_t>(ray_ids.size());
  }
  clock_gettime(CLOCK_MONOTONIC, &stats->clock[2]);
  if (culling)
    stats->region_cells = build_region(fully_free, map, ko, lo, hi, max_level, table, region);
  clock_gettime(CLOCK_MONOTONIC, &stats->clock[3]);
  for (int axis = 0; axis < 3; ++axis) {
    dims[axis] = static_cast<uint64_t>(hi[axis] - lo[axis] + 1);
    box_cells *= dims[axis];
  }
  // threads: one with `diagnose`, and at least kMinThreadRays rays each
  if (diagnose || n_threads < 1) n_threads = 1;
  n_threads = std::min(std::min(n_threads, kMaxThreads),
                       static_cast<int>(std::max<ptrdiff_t>(n_trav / kMinThreadRays, 1)));
  // each thread's counts get their own slice of `counts`, within the dense limit: no
  // more threads than slices fit (counting in tables instead is several times slower);
  // a box larger than the limit is counted in tables by every thread
  const bool dense = box_cells <= kMaxDenseCells;
  if (dense)
    n_threads = static_cast<int>(std::min<uint64_t>(n_threads, kMaxDenseCells / box_cells));
  if (dense && (counts_dirty || counts.size() < box_cells * n_threads))
    counts.assign(std::max<uint64_t>(box_cells * n_threads, counts.size()), 0);
  counts_dirty = true;
  rays.res = res;
  rays.origin = &o;
  rays.key_origin = &ko;
  rays.ends = ends.data();
  rays.end_keys = end_keys.data();
  rays.end_ok = end_ok.data();
  rays.ray_ids = superray_threshold > 0 ? ray_ids.data() : nullptr;
  rays.ray_weights = superray_threshold > 0 ? ray_weights.data() : nullptr;
  rays.weights = weighted ? weights : nullptr;
  rays.region = &region;
  rays.cull = stats->region_cells > 0;
  rays.dense = dense;
  rays.lo = lo;
  rays.dims = dims;
  rays.max_cells = max_cells;
  // thread 0 counts into the scan's own table (its first `hits` entries: the end
  // cells), the others into tables of their own
  const size_t hits = table.size();
  if (n_threads == 1) {
    walk_rays(&rays, 0, n_trav, dense ? counts.data() : nullptr, &touched, &table, hits,
              diagnose ? &visits : nullptr, &stats->traversed_cells, &stop);
  } else {
    std::vector<std::vector<uint64_t>> part_touched(n_threads);  // threads 1, 2, ...: new cells
    std::vector<KeyTable> part_tables(n_threads - 1);             // and their other cells
    std::vector<long> part_visits(n_threads, 0);
    const ptrdiff_t n_chunks =
        std::min<ptrdiff_t>(n_trav, static_cast<ptrdiff_t>(n_threads) * kChunksPerThread);
    std::exception_ptr error;
#pragma omp parallel for num_threads(n_threads) schedule(dynamic)
    for (ptrdiff_t c = 0; c < n_chunks; ++c) {
#ifdef _OPENMP
      const int t = omp_get_thread_num();
#else
      const int t = 0;
#endif
      try {
        walk_rays(&rays, c * n_trav / n_chunks, (c + 1) * n_trav / n_chunks,
                  dense ? counts.data() + static_cast<uint64_t>(t) * box_cells : nullptr,
                  t == 0 ? &touched : &part_touched[t], t == 0 ? &table : &part_tables[t - 1],
                  t == 0 ? hits : 0, nullptr, &part_visits[t], &stop);
      } catch (...) {
#pragma omp critical(occgp_scan_error)
        if (!error) error = std::current_exception();
        stop.set();
      }
    }
    if (error) std::rethrow_exception(error);
    // merge into thread 0's counts (integer sums: the order does not matter), leaving
    // the other slices zero
    stats->traversed_cells += part_visits[0];
    for (int t = 1; t < n_threads; ++t) {
      if (dense) {
        uint32_t* part = counts.data() + static_cast<uint64_t>(t) * box_cells;
        for (const uint64_t idx : part_touched[t]) {
          if (counts[idx] == 0) touched.push_back(idx);
          counts[idx] += part[idx];
          part[idx] = 0;
        }
      }
      if (!stop.get()) {
        const KeyTable& part_table = part_tables[t - 1];
        for (size_t slot = 0; slot < part_table.capacity(); ++slot) {
          if (part_table.slot(slot).key != KeyTable::kEmpty)
            table.get(part_table.slot(slot).key)->n_free += part_table.slot(slot).n_free;
        }
      }
      stats->traversed_cells += part_visits[t];
    }
  }
  clock_gettime(CLOCK_MONOTONIC, &stats->clock[4]);
  bool too_many = false;
  if (stop.get()) {
    too_many = true;
  } else if (max_cells) {
    // the distinct cells: those counted in the box, and the table's others
    uint64_t distinct = touched.size() + table.size();
    if (dense) {
      for (size_t slot = 0; slot < table.capacity(); ++slot) {
        if (table.slot(slot).key == KeyTable::kEmpty) continue;
        key = unpack_key(table.slot(slot).key);
        if (in_box(key, lo, dims) && counts[box_index(key, lo, dims)]) distinct -= 1;
      }
    }
    too_many = distinct > max_cells;
  }
  if (too_many) {
    for (const uint64_t idx : touched) counts[idx] = 0;
    counts_dirty = false;
    return Status::too_many_cells;  // nothing changed: the caller reports it
  }
  // one update per cell: the traversed cells (on the threads), then end cells no ray crossed
  const ptrdiff_t n_touched = static_cast<ptrdiff_t>(touched.size());
  cells.reserve(touched.size() + table.size());
  cells.resize(touched.size());
  const int ct = n_touched >= kMinParallelCollect ? collect_threads : 1;  // not the walk's
#pragma omp parallel for num_threads(ct) schedule(static) if (ct > 1)
  for (ptrdiff_t t = 0; t < n_touched; ++t) {
    const KeyCounts* entry = table.find(cells[t].key = pack_key(box_key(touched[t], lo, dims)));
    cells[t].update = update_value(counts[touched[t]], entry ? entry->n_hit : 0, ray_mode,
                                   l_hit, l_miss);
  }
  ScanCell cell;
  for (size_t slot = 0; slot < table.capacity(); ++slot) {
    if (table.slot(slot).key == KeyTable::kEmpty) continue;
    key = unpack_key(table.slot(slot).key);
    uint32_t n_free = table.slot(slot).n_free;
    if (dense && in_box(key, lo, dims)) {
      if (counts[box_index(key, lo, dims)]) continue;  // collected above
      n_free = 0;
    }
    cell.key = pack_key(key);
    cell.update = update_value(n_free, table.slot(slot).n_hit, ray_mode, l_hit, l_miss);
    cells.push_back(cell);
  }
#pragma omp parallel for num_threads(ct) schedule(static) if (ct > 1)
  for (ptrdiff_t t = 0; t < n_touched; ++t) counts[touched[t]] = 0;
  counts_dirty = false;
  stats->rays = n_trav;
  if (diagnose) {
    stats->unnecessary = 0;
    for (size_t slot = 0; slot < visits.capacity(); ++slot) {
      if (visits.slot(slot).key == KeyTable::kEmpty) continue;
      const KeyCounts* entry = table.find(visits.slot(slot).key);
      if ((entry == nullptr || entry->n_hit == 0) &&
          fully_free(map, unpack_key(visits.slot(slot).key)))
        stats->unnecessary += visits.slot(slot).n_free;
    }
  }
  return Status::ok;
}

}  // namespace occgp

#endif  // OCCGP_SCAN_H
