// Key arithmetic shared by the compiled maps (declared for Cython in ext/_keys.pxd):
// liboctomap's 16-bit keys packed into one integer, and the ends of its rays.
//
// The arithmetic is liboctomap's (single-precision points, double-precision keys), so
// every map that uses it finds the same cells as its OcTree. Build without
// floating-point contraction (-ffp-contract=off).
#ifndef OCCGP_KEYS_H
#define OCCGP_KEYS_H

#include <cfloat>
#include <cstdint>

#include <octomap/OcTreeKey.h>
#include <octomap/octomap_types.h>

namespace occgp {

// The three 16-bit keys in one integer (x in the low bits), for hash maps.
inline uint64_t pack_key(const octomap::OcTreeKey& key) {
  return static_cast<uint64_t>(key[0]) | (static_cast<uint64_t>(key[1]) << 16) |
         (static_cast<uint64_t>(key[2]) << 32);
}

// The same of three keys given as integers (each taken modulo 2^16, as OcTreeKey does).
inline uint64_t pack_keys(int64_t kx, int64_t ky, int64_t kz) {
  return static_cast<uint64_t>(kx & 0xFFFF) | static_cast<uint64_t>(ky & 0xFFFF) << 16 |
         static_cast<uint64_t>(kz & 0xFFFF) << 32;
}

inline octomap::OcTreeKey unpack_key(uint64_t packed) {
  return octomap::OcTreeKey(static_cast<octomap::key_type>(packed & 0xFFFF),
                            static_cast<octomap::key_type>((packed >> 16) & 0xFFFF),
                            static_cast<octomap::key_type>((packed >> 32) & 0xFFFF));
}

// The key of a scaled coordinate (coordinate / resolution, in double precision):
// floor(scaled) + 32768, as liboctomap's coordToKey; false outside the 16-bit key range,
// tested on the double first, where liboctomap would cast a huge value to int unchecked.
// In range, the floor is the truncation, less one below a negative non-integer
// (std::floor takes a dozen instructions on x86-64 without SSE4.1).
inline bool scaled_key(double scaled, int64_t* key) {
  if (!(scaled >= -32768.0 && scaled < 32768.0)) return false;
  const int64_t truncated = static_cast<int64_t>(scaled);
  *key = truncated - (truncated > scaled) + 32768;
  return true;
}

// liboctomap's coordToKeyChecked on one axis, with its arithmetic (the float coordinate
// times the double resolution factor).
inline bool key_checked(double resolution_factor, float coordinate, octomap::key_type* key) {
  int64_t k;
  if (!scaled_key(resolution_factor * static_cast<double>(coordinate), &k)) return false;
  *key = static_cast<octomap::key_type>(k);
  return true;
}

// Set `end` to the ray's end as liboctomap's computeUpdate does; true when truncated.
// `max_range` < 0 means no limit.
inline bool effective_end(const octomap::point3d& origin, const octomap::point3d& point,
                          double max_range, octomap::point3d* end) {
  const octomap::point3d direction = point - origin;
  if (max_range < 0 || direction.norm() <= max_range) {
    *end = point;
    return false;
  }
  *end = origin + direction.normalized() * static_cast<float>(max_range);
  return true;
}

// Whether liboctomap's traversal (computeRayKeys, RayWalker) of a ray between two
// different cells ends: it divides the direction by the length computed from float
// squares, which must be a normal, finite float (an infinite length leaves a zero
// direction, a zero one an infinite direction, and the walk then never stops).
inline bool walkable(const octomap::point3d& origin, const octomap::point3d& end) {
  const octomap::point3d d = end - origin;
  const float nsq = d.x() * d.x() + d.y() * d.y() + d.z() * d.z();
  return nsq >= FLT_MIN && nsq <= FLT_MAX;
}

}  // namespace occgp

#endif  // OCCGP_KEYS_H
