// liboctomap's discretize (OccupancyOcTreeBase::computeDiscreteUpdate): the center of
// each distinct cell that holds a point, the scan's rays then cast to those centers.
// Used by insert_scan(..., discretize=True) of the octree and the grid (ext/_grid.pyx,
// occgp/octree/_logodds.py), before occgp's own pipeline runs on the centers.
#ifndef OCCGP_DISCRETIZE_H
#define OCCGP_DISCRETIZE_H

#include <cstddef>
#include <cstdint>
#include <vector>

#include "_keys.h"
#include "_keytable.h"

namespace occgp {

// Write to `centers` (3 floats a cell) the center of each distinct cell holding one of
// the `n` points (xyz float32), in the order of each cell's first point: the keys are
// liboctomap's coordToKey (key_checked), the centers its keyToCoord, (key - 32768 + 0.5)
// * resolution in double, stored as float. Returns the index of the first point
// outside the key range, or -1 when none is (then `centers` is complete).
static inline ptrdiff_t discretize_points(const float* points, ptrdiff_t n, double resolution,
                                          std::vector<float>& centers) {
  struct Seen {
    uint64_t key;
  };
  const double inv = 1.0 / resolution;
  KeyMap<Seen> seen;  // the end cells met so far
  seen.reset(static_cast<size_t>(n));
  centers.clear();
  for (ptrdiff_t i = 0; i < n; ++i) {
    octomap::key_type k[3];
    for (int a = 0; a < 3; ++a)
      if (!key_checked(inv, points[3 * i + a], &k[a])) return i;
    const size_t before = seen.size();
    seen.get(pack_key(octomap::OcTreeKey(k[0], k[1], k[2])));
    if (seen.size() == before) continue;  // a cell met before
    for (int a = 0; a < 3; ++a)
      centers.push_back(static_cast<float>(
          (static_cast<double>(static_cast<int>(k[a]) - 32768) + 0.5) * resolution));
  }
  return -1;
}

}  // namespace occgp

#endif  // OCCGP_DISCRETIZE_H
