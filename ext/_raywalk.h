// liboctomap's ray traversal, one cell at a time (used from ext/_scan.pxd).
//
// RayWalker visits exactly the cells that OcTreeBaseImpl::computeRayKeys
// (liboctomap 1.9) writes into a KeyRay, in the same order, with the same
// single/double precision arithmetic -- but inline, without storing the keys,
// and choosing the axis of each step without a branch (the branch on the
// smallest tMax is mispredicted about every other step in liboctomap's loop).
// Build without floating-point contraction (-ffp-contract=off) so that the
// arithmetic stays that of liboctomap's own build.
#ifndef OCCGP_RAYWALK_H
#define OCCGP_RAYWALK_H

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include <octomap/OcTreeKey.h>
#include <octomap/octomap_types.h>

#include "_keys.h"
#include "_keytable.h"

namespace occgp {

class RayWalker {
 public:
  // Start the walk of the ray from `origin` (in the cell `key_origin`) to `end`
  // (in the cell `key_end`); `resolution` is the tree's. Returns false when the
  // ray has no cells to walk (both ends in one cell, where computeRayKeys
  // returns an empty ray); otherwise key() is the origin's cell.
  bool start(double resolution, const octomap::point3d& origin,
             const octomap::OcTreeKey& key_origin, const octomap::point3d& end,
             const octomap::OcTreeKey& key_end) {
    if (key_origin == key_end) return false;
    octomap::point3d direction = end - origin;
    length_ = static_cast<float>(direction.norm());
    direction /= length_;
    int step[3];
    double t_max[3], t_delta[3];
    for (int i = 0; i < 3; ++i) {
      if (direction(i) > 0.0) step[i] = 1;
      else if (direction(i) < 0.0) step[i] = -1;
      else step[i] = 0;
      if (step[i] != 0) {
        // keyToCoord(key) of the origin's cell, then its border in the ray's direction
        double border = (static_cast<double>(static_cast<int>(key_origin[i]) - kMaxVal) + 0.5) *
                        resolution;
        border += static_cast<float>(step[i] * resolution * 0.5);
        t_max[i] = (border - origin(i)) / direction(i);
        t_delta[i] = resolution / std::fabs(direction(i));
      } else {
        t_max[i] = std::numeric_limits<double>::max();
        t_delta[i] = std::numeric_limits<double>::max();
      }
    }
    // scalars rather than arrays, so that the loop state stays in registers
    k0_ = key_origin[0], k1_ = key_origin[1], k2_ = key_origin[2];
    e0_ = key_end[0], e1_ = key_end[1], e2_ = key_end[2];
    s0_ = step[0], s1_ = step[1], s2_ = step[2];
    t0_ = t_max[0], t1_ = t_max[1], t2_ = t_max[2];
    d0_ = t_delta[0], d1_ = t_delta[1], d2_ = t_delta[2];
    return true;
  }

  // Step to the next cell of the ray; false when the ray has no more cells.
  bool next() {
    return advance(k0_, k1_, k2_, t0_, t1_, t2_, s0_, s1_, s2_, d0_, d1_, d2_, e0_, e1_, e2_,
                   length_);
  }

  // Visit the current cell and every later one of the ray, `visit(k0, k1, k2)` with
  // the keys of each (next() one cell at a time, the walk's state in registers rather
  // than in this object); returns how many cells were visited. The walker is spent
  // afterwards.
  template <class Visit>
  long visit_rest(Visit&& visit) const {
    int k0 = k0_, k1 = k1_, k2 = k2_;
    double t0 = t0_, t1 = t1_, t2 = t2_;
    long n = 0;
    do {
      visit(k0 & 0xFFFF, k1 & 0xFFFF, k2 & 0xFFFF);
      ++n;
    } while (advance(k0, k1, k2, t0, t1, t2, s0_, s1_, s2_, d0_, d1_, d2_, e0_, e1_, e2_,
                     length_));
    return n;
  }

  // The current cell's key on `axis`.
  int key(int axis) const { return (axis == 0 ? k0_ : axis == 1 ? k1_ : k2_) & 0xFFFF; }

  // Whether the ray from `origin` (in the cell `key_origin`) to `end` (in the cell
  // `key_end`, the ray's last) has no cell outside `region` -- told without start()'s
  // divisions and walk. `region` is closed under a step toward the origin on any axis
  // (walk_back), and its box holds the box of the two cells. The ray's cells then all
  // lie in `region` when computeRayKeys's walk (walkable, keys in range) reaches the
  // end cell without leaving that box, from a neighbour of the end cell that
  // `region` holds: the walk steps toward the end on each axis, so the cells before
  // lie between the origin's cell and that neighbour.
  //
  // The walk leaves the box only by crossing out of one of the end cell's slabs before
  // it has crossed into all of them, and it comes from the neighbour across the slab
  // it crosses into last. Its crossings on each axis lie at t0 + j d (start()),
  // within (count + 3) 2^-52 |t| of the exact values (walk_back), and those values
  // are the crossings of the segment from `origin` along the float direction d for the
  // float length L, whose end origin + L d lies within 2^-23 |end - origin| of `end`
  // on each axis (d = (end - origin) / L, both rounded once); start()'s cell borders
  // lie within 2^-25 of the resolution of the cells' (its half resolution is a
  // float). So when `end` lies further than all of this (`delta`, several times over)
  // from the faces of its cell the walk could leave it by (those away from the
  // origin; both on an axis where the keys agree), the walk crosses into the end
  // cell's slabs before it crosses out of any; and when the segment from `origin` to
  // `end` crosses into one of them later than into the others by more than all of this
  // in the segment's fraction (the margins below, several times over), the walk comes
  // from the neighbour across it. Where that is not certain, every neighbour of the
  // end cell toward the origin must be in `region`. (The walk may stop at L before it
  // reaches the end cell when `end` lies next to the face it enters by; its cells then
  // lie before that neighbour all the same.)
  static bool hidden(const CellBox& region, double resolution, double inv_resolution,
                     const octomap::point3d& origin, const octomap::OcTreeKey& key_origin,
                     const octomap::point3d& end, const octomap::OcTreeKey& key_end) {
    // the end cell's neighbours toward the origin (on the axes where the keys differ),
    // and those of them in the region
    int steps[3], toward = 0, in = 0;
    for (int i = 0; i < 3; ++i) {
      steps[i] = static_cast<int>(key_end[i]) - static_cast<int>(key_origin[i]);
      if (steps[i] == 0) continue;
      int cell[3] = {key_end[0], key_end[1], key_end[2]};
      cell[i] -= steps[i] > 0 ? 1 : -1;
      toward |= 1 << i;
      if (region.test(cell[0], cell[1], cell[2])) in |= 1 << i;
    }
    if (toward == 0) return true;  // one cell: no cells to walk
    if (in == 0) return false;
    double length[3], span = 0;  // per axis |end - origin|, and their sum
    for (int i = 0; i < 3; ++i) {
      length[i] = std::fabs(static_cast<double>(end(i)) - origin(i));
      span += length[i];
    }
    const double delta = 1e-6 * (resolution + span) + 1e-15 * (span * inv_resolution + 4) * span;
    double low[3];  // the end cell's lower faces
    for (int i = 0; i < 3; ++i) {
      low[i] = (static_cast<double>(key_end[i]) - kMaxVal) * resolution;
      const double inside = static_cast<double>(end(i)) - low[i];
      // the faces the walk could leave the end cell by: the far ones
      if (!((steps[i] > 0 || inside >= delta) && (steps[i] < 0 || inside <= resolution - delta)))
        return false;
    }
    if (in == toward) return true;
    // the slab the segment enters last: the largest reach / length (reach: from the
    // origin to the face toward it), compared as products; certain when it leads each
    // other one by margin_a + margin_b, margin_i = 1e-6 (1 + resolution / length_i) + c
    // (times length_a length_b, as products too)
    double reach[3];
    for (int i = 0; i < 3; ++i)
      reach[i] = std::fabs((steps[i] > 0 ? low[i] : low[i] + resolution) - origin(i));
    const double c = 4e-15 * (span * inv_resolution + 4);
    int last = -1;
    for (int i = 0; i < 3; ++i) {
      if (!(toward >> i & 1)) continue;
      if (last < 0 || reach[i] * length[last] > reach[last] * length[i]) last = i;
    }
    for (int i = 0; i < 3; ++i) {
      if (i == last || !(toward >> i & 1)) continue;
      const double both = length[last] * length[i];
      if (!(reach[last] * length[i] - reach[i] * length[last] >
            1e-6 * (2 * both + resolution * (length[last] + length[i])) + 2 * c * both))
        return false;
    }
    return in >> last & 1;
  }

  // The culling region's shortcut (Kwon, dissertation 2.3.5): right after start(),
  // append to `cells` the cells of the ray that lie outside `region`, as indices
  // into the region's box (CellBox::index), or as packed keys (pack_key) with `Keys`,
  // found walking back from the end
  // cell, and return
  // true -- or return false, appending nothing, when that walk cannot be
  // certified to give the cells that next() gives; walk forward then.
  //
  // The walk back is exact: the j-th border crossing on axis i lies at
  // t0_i + j d_i, the values next() accumulates one addition at a time. Each
  // choice next() makes between two crossings is certified when the exact
  // values differ by more than both accumulations can err, (j + 3) 2^-52 |t|.
  // Where all choices after the ray's last cell in the region are certified,
  // next() takes the same cells there (a tie broken the other way inside the
  // region only swaps cells that are in the region too: it is closed under a
  // step toward the origin on any axis), and reaches the end cell.
  template <bool Keys = false>
  bool walk_back(const CellBox& region, std::vector<uint64_t>& cells) const {
    const int step[3] = {s0_, s1_, s2_};
    const double t0[3] = {t0_, t1_, t2_};
    const double dt[3] = {d0_, d1_, d2_};
    const int origin[3] = {k0_, k1_, k2_};
    int key[3] = {e0_, e1_, e2_};
    long count[3];   // crossings on each axis between the origin's cell and the current one
    double last[3];  // the crossing into the current cell's slab on each axis (-inf: none)
    double next[3];  // the crossing out of it (+inf: the ray is parallel to the slab)
    long most = 0;
    double largest = 0;
    for (int i = 0; i < 3; ++i) {
      count[i] = static_cast<long>(key[i] - origin[i]) * step[i];
      if (count[i] < 0 || (step[i] == 0 && key[i] != origin[i])) return false;
      if (step[i] == 0) {
        last[i] = -std::numeric_limits<double>::infinity();
        next[i] = std::numeric_limits<double>::infinity();
        continue;
      }
      next[i] = t0[i] + static_cast<double>(count[i]) * dt[i];
      last[i] = count[i] > 0 ? t0[i] + static_cast<double>(count[i] - 1) * dt[i]
                             : -std::numeric_limits<double>::infinity();
      most = std::max(most, count[i]);
      largest = std::max(largest, std::fabs(t0[i]) + static_cast<double>(count[i] + 1) * dt[i]);
    }
    // what the accumulated and the computed crossings can err, both together
    const double margin =
        2.0 * static_cast<double>(most + 3) * std::numeric_limits<double>::epsilon() * largest;
    // the ray's cells all lie in the box of its end cells, which the region's box holds
    const uint64_t stride[3] = {region.stride(0), region.stride(1), region.stride(2)};
    uint64_t index = region.index(key[0], key[1], key[2]);
    // the crossing into the end cell must come before the ray's end
    if (std::max(std::max(last[0], last[1]), last[2]) + margin >= static_cast<double>(length_))
      return false;
    const size_t first = cells.size();
    long remaining = count[0] + count[1] + count[2];
    bool at_end = true;
    while (remaining > 0) {
      // the crossing into the current cell: the latest of the three
      const bool c01 = last[0] >= last[1], c02 = last[0] >= last[2], c12 = last[1] >= last[2];
      const int dim = c01 ? (c02 ? 0 : 2) : (c12 ? 1 : 2);
      const double entry = last[dim];
      // next() took it as the earliest of the next crossings on the three axes
      const double other = std::min(next[dim == 0 ? 1 : 0], next[dim == 2 ? 1 : 2]);
      if (!(other - entry > margin)) {
        cells.resize(first);
        return false;
      }
      if (!at_end) {
        // the entry into a cell of the region is certified: the cells before it are in
        // the region, whichever way next() breaks their ties
        if (region.test_index(index)) return true;
        cells.push_back(Keys ? pack_keys(key[0], key[1], key[2]) : index);
      }
      at_end = false;
      --remaining;
      --count[dim];
      key[dim] -= step[dim];
      if (step[dim] > 0) index -= stride[dim];
      else index += stride[dim];
      next[dim] = entry;
      last[dim] = count[dim] > 0 ? t0[dim] + static_cast<double>(count[dim] - 1) * dt[dim]
                                 : -std::numeric_limits<double>::infinity();
    }
    // the origin's cell
    if (!region.test_index(index)) cells.push_back(Keys ? pack_keys(key[0], key[1], key[2]) : index);
    return true;
  }

 private:
  // One step of computeRayKeys's loop on the keys (k) and tMax values (t): along the
  // axis of the smallest tMax, ties resolved as computeRayKeys resolves them; false
  // when the end cell (keys e) is reached or the smallest tMax passes `length`.
  static inline bool advance(int& k0, int& k1, int& k2, double& t0, double& t1, double& t2,
                             int s0, int s1, int s2, double d0, double d1, double d2, int e0,
                             int e1, int e2, float length) {
    const bool c01 = t0 < t1, c02 = t0 < t2, c12 = t1 < t2;
    const bool m0 = c01 & c02;
    const bool m1 = !c01 & c12;
    const bool m2 = !(m0 | m1);
    k0 += m0 ? s0 : 0;
    k1 += m1 ? s1 : 0;
    k2 += m2 ? s2 : 0;
    t0 += m0 ? d0 : 0.0;  // adding +0.0 leaves every tMax value unchanged
    t1 += m1 ? d1 : 0.0;
    t2 += m2 ? d2 : 0.0;
    // keys are 16 bits: compare them modulo 2^16, as OcTreeKey does
    if ((((k0 ^ e0) | (k1 ^ e1) | (k2 ^ e2)) & 0xFFFF) == 0) return false;
    // the smallest tMax, by value (std::min's references would keep t0..t2 in memory)
    const double t01 = t0 < t1 ? t0 : t1;
    const double dist = t01 < t2 ? t01 : t2;
    return !(dist > length);
  }

  static constexpr int kMaxVal = 32768;  // liboctomap's tree_max_val
  int k0_ = 0, k1_ = 0, k2_ = 0;
  int e0_ = 0, e1_ = 0, e2_ = 0;
  int s0_ = 0, s1_ = 0, s2_ = 0;
  double t0_ = 0, t1_ = 0, t2_ = 0;
  double d0_ = 0, d1_ = 0, d2_ = 0;
  float length_ = 0;
};

}  // namespace occgp

#endif  // OCCGP_RAYWALK_H
