// liboctomap's discretize (OccupancyOcTreeBase::computeDiscreteUpdate): the center of
// each distinct cell that holds a point, the scan's rays then cast to those centers.
// Used by insert_scan(..., discretize=True) of the octree and the grid (ext/_octree.pyx,
// occgp/octree/_logodds.py), before occgp's own pipeline runs on the centers.
#ifndef OCCGP_DISCRETIZE_H
#define OCCGP_DISCRETIZE_H

#include <cstddef>
#include <cstdint>
#include <vector>

namespace occgp {

// The key of a coordinate as liboctomap's coordToKey computes it (the floor of the
// double product, plus 32768) on one axis; false outside the 16-bit key range.
static inline bool discrete_key(double inv_resolution, float c, uint64_t* key) {
  const double scaled = inv_resolution * static_cast<double>(c);
  if (!(scaled >= -32768.0 && scaled < 32768.0)) return false;
  const int64_t truncated = static_cast<int64_t>(scaled);  // floor, without std::floor
  *key = static_cast<uint64_t>(truncated - (truncated > scaled) + 32768);
  return true;
}

// Write to `centers` (3 floats a cell) the center of each distinct cell holding one of
// the `n` points (xyz float32), in the order of each cell's first point, as liboctomap's
// keyToCoord gives it: (key - 32768 + 0.5) * resolution in double, stored as float.
// Returns the index of the first point outside the key range, or -1 when none is (then
// `centers` is complete).
static inline ptrdiff_t discretize_points(const float* points, ptrdiff_t n, double resolution,
                                          std::vector<float>& centers) {
  const double inv = 1.0 / resolution;
  size_t capacity = 16;
  while (capacity < 2 * static_cast<size_t>(n)) capacity <<= 1;
  const uint64_t kEmpty = ~0ull;
  std::vector<uint64_t> table(capacity, kEmpty);  // open addressing on the packed keys
  const size_t mask = capacity - 1;
  centers.clear();
  for (ptrdiff_t i = 0; i < n; ++i) {
    uint64_t k[3];
    for (int a = 0; a < 3; ++a)
      if (!discrete_key(inv, points[3 * i + a], &k[a])) return i;
    const uint64_t packed = k[0] | k[1] << 16 | k[2] << 32;
    size_t slot = static_cast<size_t>((packed * 0x9E3779B97F4A7C15ull) >> 32) & mask;
    while (table[slot] != kEmpty && table[slot] != packed) slot = (slot + 1) & mask;
    if (table[slot] == packed) continue;
    table[slot] = packed;
    for (int a = 0; a < 3; ++a)
      centers.push_back(static_cast<float>(
          (static_cast<double>(static_cast<int64_t>(k[a]) - 32768) + 0.5) * resolution));
  }
  return -1;
}

}  // namespace occgp

#endif  // OCCGP_DISCRETIZE_H
