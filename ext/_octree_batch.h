// One pass over an OcTree for all the cell updates of a scan (used from ext/_octree.pyx).
//
// liboctomap updates a scan's cells one at a time: OccupancyOcTreeBase::updateNode
// searches the key from the root, descends again creating or expanding nodes,
// and on the way back up prunes or re-evaluates every ancestor -- 3 x 16 node
// visits per cell. apply_updates sorts the cells in Morton order (the octree's
// depth-first order) and walks the tree once: the ancestors shared by
// consecutive cells are visited once, and each inner node is pruned or
// re-evaluated once, after the last cell below it.
//
// The result is the tree that updateNode(key, update, false) called for each
// cell, in any order, leaves, for distinct cells: a cell's early abort (its
// leaf exists and is clamped in the update's direction) depends only on its
// own value, which no other cell's update changes; expanding a node and
// pruning it again restores it; and a node's final state is the prune-or-max
// of its children's final states, which one evaluation after the last cell
// below it computes. Aborted cells leave their ancestors untouched, as in
// liboctomap (which matters on trees that are not pruned).
#ifndef OCCGP_OCTREE_BATCH_H
#define OCCGP_OCTREE_BATCH_H

#include <algorithm>
#include <cstdint>
#include <vector>

#include <octomap/OcTree.h>

namespace occgp {

struct CellUpdate {
  uint64_t code;  // Morton code of the cell's key: the child indices from the root down
  float update;   // log-odds to add
};

// Bit i of the 16-bit `v` moved to bit 3i.
inline uint64_t spread_bits3(uint64_t v) {
  v &= 0xFFFF;
  v = (v | (v << 16)) & 0x0000FF0000FFULL;
  v = (v | (v << 8)) & 0x00F00F00F00FULL;
  v = (v | (v << 4)) & 0x0C30C30C30C3ULL;
  v = (v | (v << 2)) & 0x249249249249ULL;
  return v;
}

inline uint64_t gather_bits3(uint64_t v) {
  v &= 0x249249249249ULL;
  v = (v | (v >> 2)) & 0x0C30C30C30C3ULL;
  v = (v | (v >> 4)) & 0x00F00F00F00FULL;
  v = (v | (v >> 8)) & 0x0000FF0000FFULL;
  v = (v | (v >> 16)) & 0xFFFF;
  return v;
}

// Depth d's child index (liboctomap's computeChildIdx(key, 15 - d)) in bits 3(15-d)..3(15-d)+2.
inline uint64_t morton_code(unsigned x, unsigned y, unsigned z) {
  return spread_bits3(x) | (spread_bits3(y) << 1) | (spread_bits3(z) << 2);
}

inline octomap::OcTreeKey morton_key(uint64_t code) {
  return octomap::OcTreeKey(static_cast<octomap::key_type>(gather_bits3(code)),
                            static_cast<octomap::key_type>(gather_bits3(code >> 1)),
                            static_cast<octomap::key_type>(gather_bits3(code >> 2)));
}

// Sort by code: least significant digit first, three passes of 16 bits.
inline void sort_by_code(std::vector<CellUpdate>& cells, std::vector<CellUpdate>& scratch) {
  const size_t n = cells.size();
  if (n < 256) {
    std::sort(cells.begin(), cells.end(),
              [](const CellUpdate& a, const CellUpdate& b) { return a.code < b.code; });
    return;
  }
  scratch.resize(n);
  std::vector<uint32_t> count(1 << 16);
  CellUpdate* src = cells.data();
  CellUpdate* dst = scratch.data();
  for (int shift = 0; shift < 48; shift += 16) {
    std::fill(count.begin(), count.end(), 0);
    for (size_t i = 0; i < n; ++i) ++count[(src[i].code >> shift) & 0xFFFF];
    uint32_t sum = 0;
    for (uint32_t& c : count) {
      const uint32_t k = c;
      c = sum;
      sum += k;
    }
    for (size_t i = 0; i < n; ++i) dst[count[(src[i].code >> shift) & 0xFFFF]++] = src[i];
    std::swap(src, dst);
  }
  if (src != cells.data()) std::copy(src, src + n, cells.data());
}

// Apply `cells` (distinct keys) to `tree` as updateNode(key, update, false) would.
// Sorts `cells`; `scratch` is working memory. Returns the number of cells not
// aborted early.
inline size_t apply_updates(octomap::OcTree& tree, std::vector<CellUpdate>& cells,
                            std::vector<CellUpdate>& scratch) {
  typedef octomap::OcTreeNode Node;
  constexpr int kDepth = 16;
  if (cells.empty()) return 0;
  sort_by_code(cells, scratch);
  size_t first = 0, applied = 0;
  if (tree.getRoot() == nullptr) {  // liboctomap's updateNode creates the root
    tree.updateNode(morton_key(cells[0].code), cells[0].update, false);
    first = 1;
    applied = 1;
  }
  const float clamp_min = tree.getClampingThresMinLog();
  const float clamp_max = tree.getClampingThresMaxLog();
  Node* stack[kDepth + 1];
  stack[0] = tree.getRoot();
  int top = 0;     // stack[0..top] is the path of the last cell (as far as it went)
  int dirty = -1;  // stack[0..dirty] have an updated cell below them
  auto finalize = [&tree](Node* node) {
    if (!tree.pruneNode(node)) node->updateOccupancyChildren();
  };
  auto child_index = [](uint64_t code, int depth) {
    return static_cast<unsigned>((code >> (3 * (kDepth - 1 - depth))) & 7);
  };
  for (size_t i = first; i < cells.size(); ++i) {
    const uint64_t code = cells[i].code;
    const float update = cells[i].update;
    int common = top;
    if (i > 0) {
      const int group = (63 - __builtin_clzll(code ^ cells[i - 1].code)) / 3;
      common = std::min(top, kDepth - 1 - group);
    }
    for (int d = top; d > common; --d) {
      if (d <= dirty && d < kDepth) finalize(stack[d]);
    }
    dirty = std::min(dirty, common);
    // liboctomap's search(key): the deepest existing node on the key's path
    int d = common;
    Node* node = stack[d];
    while (d < kDepth) {
      const unsigned pos = child_index(code, d);
      if (!tree.nodeChildExists(node, pos)) break;
      node = tree.getNodeChild(node, pos);
      stack[++d] = node;
    }
    top = d;
    if (d == kDepth || !tree.nodeHasChildren(node)) {  // a leaf holds the cell: maybe abort
      const float value = node->getLogOdds();
      if ((update >= 0 && value >= clamp_max) || (update <= 0 && value <= clamp_min)) continue;
    }
    // liboctomap's updateNodeRecurs on the way down
    bool created = false;
    while (d < kDepth) {
      const unsigned pos = child_index(code, d);
      if (!tree.nodeChildExists(node, pos)) {
        if (!tree.nodeHasChildren(node) && !created) {
          tree.expandNode(node);  // a pruned leaf
        } else {
          tree.createNodeChild(node, pos);
          created = true;
        }
      } else {
        created = false;
      }
      node = tree.getNodeChild(node, pos);
      stack[++d] = node;
    }
    top = kDepth;
    tree.updateNodeLogOdds(node, update);
    dirty = kDepth;
    ++applied;
  }
  for (int d = top; d >= 0; --d) {
    if (d <= dirty && d < kDepth) finalize(stack[d]);
  }
  return applied;
}

}  // namespace occgp

#endif  // OCCGP_OCTREE_BATCH_H
