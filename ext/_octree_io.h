// Checks of the data blocks of liboctomap's tree files (used from ext/_octree.pyx).
//
// liboctomap trusts the data it reads: a truncated block or one that describes a node
// deeper than the 16 levels of a tree makes it read past its input or recurse past its
// keys. These walks go through a block without building anything, so that liboctomap
// only ever reads valid data.
#ifndef OCCGP_OCTREE_IO_H
#define OCCGP_OCTREE_IO_H

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <vector>

#include "_status.h"

namespace occgp {

constexpr unsigned kFileDepth = 16;  // the levels of a tree with 16-bit keys

// Walk the .bt data block of `n` bytes from `offset` (per inner node two bytes: a
// 2-bit code per child, 3 for a child with children; children with children follow
// depth-first in child order). Sets `nodes` and `end` (the offset after the block).
// Returns Status::truncated_data or Status::corrupt_depth, or Status::ok.
inline Status check_binary_data(const uint8_t* data, ptrdiff_t n, ptrdiff_t offset,
                                ptrdiff_t* nodes, ptrdiff_t* end) {
  ptrdiff_t pos = offset, count = 1;
  std::vector<uint8_t> stack;  // depth of each inner node still to read
  stack.push_back(0);
  while (!stack.empty()) {
    const uint8_t depth = stack.back();
    stack.pop_back();
    if (pos + 2 > n) return Status::truncated_data;
    const unsigned bits = data[pos] | (static_cast<unsigned>(data[pos + 1]) << 8);
    pos += 2;
    // children with children are read depth-first in child order: push in reverse
    for (int i = 7; i >= 0; --i) {
      const unsigned code = (bits >> (2 * i)) & 3;
      if (code != 0) ++count;
      if (code == 3) {
        if (depth + 1u >= kFileDepth) return Status::corrupt_depth;
        stack.push_back(static_cast<uint8_t>(depth + 1));
      }
    }
  }
  *nodes = count;
  *end = pos;
  return Status::ok;
}

// As check_binary_data for a .ot data block: per node a float log-odds, then
// `node_bytes` - 5 bytes of payload (3 for a ColorOcTree's r, g, b), then the child
// mask. Also returns Status::corrupt_value for a non-finite log-odds.
inline Status check_full_data(const uint8_t* data, ptrdiff_t n, ptrdiff_t offset,
                              int node_bytes, ptrdiff_t* nodes, ptrdiff_t* end) {
  ptrdiff_t pos = offset, count = 0;
  std::vector<uint8_t> stack;
  stack.push_back(0);
  while (!stack.empty()) {
    const uint8_t depth = stack.back();
    stack.pop_back();
    if (pos + node_bytes > n) return Status::truncated_data;
    float value;
    std::memcpy(&value, data + pos, sizeof(float));
    const uint8_t mask = data[pos + node_bytes - 1];
    pos += node_bytes;
    ++count;
    if (!std::isfinite(value)) return Status::corrupt_value;
    if (mask != 0 && depth + 1u > kFileDepth) return Status::corrupt_depth;
    for (int i = 7; i >= 0; --i) {
      if ((mask >> i) & 1) stack.push_back(static_cast<uint8_t>(depth + 1));
    }
  }
  *nodes = count;
  *end = pos;
  return Status::ok;
}

}  // namespace occgp

#endif  // OCCGP_OCTREE_IO_H
