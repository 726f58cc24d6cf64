// Super rays: a scan's rays grouped into classes that traverse the same cells (Kwon,
// dissertation 2.3.1-2.3.4), for scan_updates (ext/_scan.h). Build without
// floating-point contraction (-ffp-contract=off), as the rest of the core.
#ifndef OCCGP_SUPERRAYS_H
#define OCCGP_SUPERRAYS_H

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <exception>
#include <vector>

#ifdef _OPENMP
#include <omp.h>
#endif

#include <octomap/OcTree.h>

#include "_keys.h"
#include "_keytable.h"

namespace occgp {

namespace scan_detail {

constexpr int kMaxVal = 32768;  // liboctomap's tree_max_val
constexpr uint32_t kMinParallelGroups = 256;  // fewer end cells to classify: one thread
// a group whose first kProbeRays rays (of more) fall into as many classes is not
// classified further: its rays rarely share classes, and classifying costs about what
// traversing does
constexpr ptrdiff_t kProbeRays = 8;
// costs in cell visits of the traversal (timed on geb079 at 0.2 and 1 m): a ray's start
// (RAY_VISITS of the compiled maps, which occgp/_superray_policy.py uses too), and a
// signature's crossing
constexpr long kRayVisits = 10;
constexpr double kCrossingVisits = 2.0;

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

// Classify the rays of groups g0 <= g < g1 of super_rays (group g: order[offsets[g - 1]]
// up to order[offsets[g]]), appending the rays to traverse and their weights.
static inline void classify_groups(double res, const double* oc, const octomap::OcTreeKey& ko,
                                   const std::vector<octomap::point3d>& ends,
                                   const std::vector<octomap::OcTreeKey>& end_keys,
                                   const std::vector<uint32_t>& offsets,
                                   const std::vector<uint32_t>& order, double eb, bool adaptive,
                                   ptrdiff_t g0, ptrdiff_t g1, std::vector<uint32_t>& rays,
                                   std::vector<uint32_t>& weights) {
  const double rf = 1.0 / res;
  double lo[3], hi[3], pc[3], dp[3], inv[3];
  std::vector<Crossing> crossings;
  std::vector<uint64_t> class_code;
  std::vector<uint32_t> class_ray;
  for (ptrdiff_t g = g0; g < g1; ++g) {
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
      // each crossing where the rays can take nk keys splits them nk ways, so at least
      // `segments` classes remain: when that leaves no ray to spare, grouping cannot
      // pay its cost; `adaptive`, nor when the rays that could be spared (each a start
      // and its cells) cost less to traverse than classifying every ray costs (a
      // signature's crossings)
      long segments = 1;
      for (const Crossing& c : crossings) segments += c.n_keys - 1;
      const ptrdiff_t n_rays = static_cast<ptrdiff_t>(offsets[g]) - first;
      if (segments >= n_rays) ok = false;
      if (ok && adaptive) {
        long cells = 1;  // a ray's cells from the origin's to the end cell
        for (int a = 0; a < 3; ++a)
          cells += std::abs(static_cast<int>(kv[a]) - static_cast<int>(ko[a]));
        const double spare =
            static_cast<double>(n_rays - segments) * static_cast<double>(kRayVisits + cells);
        const double cost = kCrossingVisits * static_cast<double>(n_rays) *
                            static_cast<double>(crossings.size() + 1);
        if (!(spare > cost)) ok = false;
      }
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
    const ptrdiff_t last = offsets[g];
    ptrdiff_t joined = 0;  // rays that joined a class of an earlier ray
    for (ptrdiff_t m = first; m < last; ++m) {
      if (adaptive && m - first == kProbeRays && joined == 0) {
        // the probe found no two rays alike: the rest go on their own
        for (; m < last; ++m) {
          rays.push_back(order[m]);
          weights.push_back(1);
        }
        break;
      }
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
          ++joined;
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

}  // namespace scan_detail

// Group the rays of a scan into super rays (Kwon, dissertation 2.3.1-2.3.4).
//
// Fills `rays` (indices of the rays to traverse, ascending) and `weights` (how many
// rays each stands for). Rays ending in a cell that holds at least `threshold` end
// points are classified by their *signature*: at every border a ray crosses between the
// origin's cell and its end cell, the keys of the other coordinates there; only the
// crossings where the rays into that end cell can differ ("critical", the mapping
// lines) are evaluated. Equal signatures mean the same traversed cells, so one ray of
// each class is traversed with the class size as weight. A group whose crossings alone
// split it into as many classes as rays is left plain; with `adaptive`, so are the
// groups whose classification would cost more than the traversal it could spare
// (kRayVisits, kCrossingVisits), and those whose first kProbeRays rays all differ. The
// end cells' groups are classified on up to `n_threads` OpenMP threads, in contiguous
// ranges whose rays are joined: the rays and weights are the same for every
// `n_threads`.
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
                       std::vector<uint32_t>& rays, std::vector<uint32_t>& weights,
                       int n_threads = 1, bool adaptive = false) {
  using namespace scan_detail;
  double oc[3];
  const ptrdiff_t n = static_cast<ptrdiff_t>(ends.size());
  uint32_t n_groups = 0;
  std::vector<uint32_t> group_of, offsets, order;
  oc[0] = o.x();
  oc[1] = o.y();
  oc[2] = o.z();
  const double eb = std::ldexp(res, -21);  // 4 x the single-precision offset of the borders
  // groups of rays by end cell, for the cells with at least `threshold` end points
  group_of.assign(n, 0);
  uint64_t last_key = KeyTable::kEmpty;  // consecutive points of a scan often share a cell
  KeyCounts* entry = nullptr;
  for (ptrdiff_t i = 0; i < n; ++i) {
    if (truncated[i]) continue;
    const uint64_t key = pack_key(end_keys[i]);
    if (key != last_key) {
      entry = table.find(key);
      last_key = key;
    }
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
  // the groups are classified in contiguous ranges (on the threads when they are many),
  // each range's rays appended in group order, so the rays come out in the same order
  // for every n_threads
  const int threads = n_groups >= kMinParallelGroups ? std::max(1, n_threads) : 1;
  const ptrdiff_t n_ranges = threads > 1 ? static_cast<ptrdiff_t>(threads) * 8 : 1;
  std::vector<std::vector<uint32_t>> part_rays(n_ranges), part_weights(n_ranges);
  std::exception_ptr error;
#pragma omp parallel for num_threads(threads) schedule(dynamic) if (threads > 1)
  for (ptrdiff_t part = 0; part < n_ranges; ++part) {
    try {
      classify_groups(res, oc, ko, ends, end_keys, offsets, order, eb, adaptive,
                      1 + part * n_groups / n_ranges, 1 + (part + 1) * n_groups / n_ranges,
                      part_rays[part], part_weights[part]);
    } catch (...) {
#pragma omp critical(occgp_superray_error)
      if (!error) error = std::current_exception();
    }
  }
  if (error) std::rethrow_exception(error);
  // the rays in the scan's order, where neighbouring rays cross neighbouring cells (the
  // groups come in the table's order); a ray is in `rays` once, so a weight per point
  // orders them
  std::vector<uint32_t>& weight_of = group_of;  // the groups are no longer needed
  std::fill(weight_of.begin(), weight_of.end(), 0u);
  for (size_t r = 0; r < rays.size(); ++r) weight_of[rays[r]] = weights[r];
  for (ptrdiff_t part = 0; part < n_ranges; ++part) {
    for (size_t r = 0; r < part_rays[part].size(); ++r)
      weight_of[part_rays[part][r]] = part_weights[part][r];
  }
  rays.clear();
  weights.clear();
  for (ptrdiff_t i = 0; i < n; ++i) {
    if (weight_of[i] == 0) continue;
    rays.push_back(static_cast<uint32_t>(i));
    weights.push_back(weight_of[i]);
  }
}

}  // namespace occgp

#endif  // OCCGP_SUPERRAYS_H
