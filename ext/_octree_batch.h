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

// The Morton code of a packed key (x in the low 16 bits, as ext/_keys.h packs them).
inline uint64_t morton_of_packed(uint64_t packed) {
  return morton_code(static_cast<unsigned>(packed & 0xFFFF),
                     static_cast<unsigned>((packed >> 16) & 0xFFFF),
                     static_cast<unsigned>((packed >> 32) & 0xFFFF));
}

inline octomap::OcTreeKey morton_key(uint64_t code) {
  return octomap::OcTreeKey(static_cast<octomap::key_type>(gather_bits3(code)),
                            static_cast<octomap::key_type>(gather_bits3(code >> 1)),
                            static_cast<octomap::key_type>(gather_bits3(code >> 2)));
}

// Keep the cells whose keys lie in [lo, hi] on every axis, in order; returns how many.
inline size_t keep_in_box(std::vector<CellUpdate>& cells, const int* lo, const int* hi) {
  size_t m = 0;
  for (const CellUpdate& cell : cells) {
    const octomap::OcTreeKey key = morton_key(cell.code);
    bool in = true;
    for (int axis = 0; axis < 3; ++axis) in = in && lo[axis] <= key[axis] && key[axis] <= hi[axis];
    if (in) cells[m++] = cell;
  }
  cells.resize(m);
  return m;
}

// Sort by code: least significant digit first, three passes of 16 bits (stable; the
// codes are distinct, so the order is the same for every `n_threads`). With threads,
// each pass counts and scatters contiguous chunks of the cells, one chunk a thread,
// each digit's rows of chunk t placed after those of the chunks before it.
inline void sort_by_code(std::vector<CellUpdate>& cells, std::vector<CellUpdate>& scratch,
                         int n_threads = 1) {
  constexpr size_t kBuckets = 1 << 16;
  const size_t n = cells.size();
  if (n < 256) {
    std::sort(cells.begin(), cells.end(),
              [](const CellUpdate& a, const CellUpdate& b) { return a.code < b.code; });
    return;
  }
  const int T = n < (1 << 16) ? 1 : std::max(1, n_threads);
  scratch.resize(n);
  std::vector<uint32_t> count(kBuckets * T);
  CellUpdate* src = cells.data();
  CellUpdate* dst = scratch.data();
  for (int shift = 0; shift < 48; shift += 16) {
    std::fill(count.begin(), count.end(), 0);
#pragma omp parallel for num_threads(T) schedule(static, 1) if (T > 1)
    for (int t = 0; t < T; ++t) {
      uint32_t* c = count.data() + kBuckets * t;
      for (size_t i = n * t / T; i < n * (t + 1) / T; ++i) ++c[(src[i].code >> shift) & 0xFFFF];
    }
    uint32_t sum = 0;  // digit-major, chunk-minor: the stable order
    for (size_t b = 0; b < kBuckets; ++b) {
      for (int t = 0; t < T; ++t) {
        uint32_t& c = count[kBuckets * t + b];
        const uint32_t k = c;
        c = sum;
        sum += k;
      }
    }
#pragma omp parallel for num_threads(T) schedule(static, 1) if (T > 1)
    for (int t = 0; t < T; ++t) {
      uint32_t* c = count.data() + kBuckets * t;
      for (size_t i = n * t / T; i < n * (t + 1) / T; ++i)
        dst[c[(src[i].code >> shift) & 0xFFFF]++] = src[i];
    }
    std::swap(src, dst);
  }
  if (src != cells.data()) std::copy(src, src + n, cells.data());
}

namespace batch_detail {

typedef octomap::OcTreeNode Node;
typedef octomap::OcTreeBaseImpl<octomap::OcTreeNode, octomap::AbstractOccupancyOcTree> Base;
constexpr int kDepth = 16;

// liboctomap keeps the node count (tree_size) and the extent flag (size_changed) of
// the tree, and each node's children array, protected. Threads that change disjoint
// subtrees must not touch the shared count: they allocate and free nodes as
// liboctomap does, count what they did, and the count is set once afterwards. The
// members are reached through pointers to members named in derived classes.
struct TreeAccess : octomap::OcTree {
  static size_t Base::*size_member() { return &TreeAccess::tree_size; }
  static bool Base::*changed_member() { return &TreeAccess::size_changed; }
};
struct NodeAccess : octomap::OcTreeNode {
  static octomap::AbstractOcTreeNode** octomap::OcTreeDataNode<float>::*children_member() {
    return &NodeAccess::children;
  }
};

// Node operations through liboctomap itself (one thread).
struct TreeOps {
  octomap::OcTree& tree;
  void create(Node* node, unsigned pos) { tree.createNodeChild(node, pos); }
  void expand(Node* node) { tree.expandNode(node); }
  bool prune(Node* node) { return tree.pruneNode(node); }
};

// The same operations on a subtree one thread owns: liboctomap's createNodeChild,
// expandNode and pruneNode without the shared count, whose change is kept in `delta`.
struct SubtreeOps {
  const octomap::OcTree& tree;
  long delta;
  void create(Node* node, unsigned pos) {
    octomap::AbstractOcTreeNode**& children = node->*NodeAccess::children_member();
    if (children == nullptr) {
      children = new octomap::AbstractOcTreeNode*[8];
      for (unsigned i = 0; i < 8; ++i) children[i] = nullptr;
    }
    children[pos] = new Node();
    ++delta;
  }
  void expand(Node* node) {
    for (unsigned k = 0; k < 8; ++k) {
      create(node, k);
      tree.getNodeChild(node, k)->copyData(*node);
    }
  }
  bool prune(Node* node) {
    if (!tree.isNodeCollapsible(node)) return false;
    node->copyData(*tree.getNodeChild(node, 0));
    octomap::AbstractOcTreeNode**& children = node->*NodeAccess::children_member();
    for (unsigned i = 0; i < 8; ++i) {
      delete static_cast<Node*>(children[i]);
      children[i] = nullptr;
      --delta;
    }
    delete[] children;
    children = nullptr;
    return true;
  }
};

inline unsigned child_index(uint64_t code, int depth) {
  return static_cast<unsigned>((code >> (3 * (kDepth - 1 - depth))) & 7);
}

// One step of liboctomap's updateNodeRecurs on the way down: to child `pos` of `node`,
// created where missing below a node just created (`created`), or after expanding
// `node` when it is a pruned leaf. Updates `created` for the child.
template <class Ops>
inline Node* step_down(const octomap::OcTree& tree, Ops& ops, Node* node, unsigned pos,
                       bool& created) {
  if (!tree.nodeChildExists(node, pos)) {
    if (!tree.nodeHasChildren(node) && !created) {
      ops.expand(node);  // a pruned leaf
    } else {
      ops.create(node, pos);
      created = true;
    }
  } else {
    created = false;
  }
  return tree.getNodeChild(node, pos);
}

// Whether the cell's update aborts early in liboctomap's updateNode: the deepest
// existing node on its path is a leaf already clamped in the update's direction.
inline bool aborts(const octomap::OcTree& tree, Node* root, uint64_t code, float update,
                   float clamp_min, float clamp_max) {
  const Node* node = root;
  int d = 0;
  while (d < kDepth) {
    const unsigned pos = child_index(code, d);
    if (!tree.nodeChildExists(node, pos)) break;
    node = tree.getNodeChild(node, pos);
    ++d;
  }
  if (d < kDepth && tree.nodeHasChildren(node)) return false;
  const float value = node->getLogOdds();
  return (update >= 0 && value >= clamp_max) || (update <= 0 && value <= clamp_min);
}

// The depth-first pass over cells[0, n) (sorted, distinct), all below stack[base]
// (stack[0..base] the path to it, which exists). `base_created`: stack[base] was just
// created on the way down (liboctomap's updateNodeRecurs then creates, rather than
// expands, below it). Finalises (prunes or re-evaluates) the dirty nodes at depths
// `base`..15; returns the number of cells not aborted early and, in *dirty_base,
// whether stack[base] had an updated cell below it.
template <class Ops>
size_t update_below(const octomap::OcTree& tree, const CellUpdate* cells, size_t n,
                    Node** stack, int base, bool base_created, Ops& ops, bool* dirty_base) {
  const float clamp_min = tree.getClampingThresMinLog();
  const float clamp_max = tree.getClampingThresMaxLog();
  size_t applied = 0;
  int top = base;      // stack[0..top] is the path of the last cell (as far as it went)
  int dirty = base - 1;  // stack[base..dirty] have an updated cell below them
  auto finalize = [&ops](Node* node) {
    if (!ops.prune(node)) node->updateOccupancyChildren();
  };
  for (size_t i = 0; i < n; ++i) {
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
    // a base just made for this cell stands for the inner node above it (no abort)
    const bool fresh = base_created && applied == 0 && d == base;
    if (!fresh && (d == kDepth || !tree.nodeHasChildren(node))) {  // a leaf: maybe abort
      const float value = node->getLogOdds();
      if ((update >= 0 && value >= clamp_max) || (update <= 0 && value <= clamp_min)) continue;
    }
    // liboctomap's updateNodeRecurs on the way down
    bool created = fresh;
    while (d < kDepth) {
      node = step_down(tree, ops, node, child_index(code, d), created);
      stack[++d] = node;
    }
    top = kDepth;
    tree.updateNodeLogOdds(node, update);
    dirty = kDepth;
    ++applied;
  }
  for (int d = top; d >= base; --d) {
    if (d <= dirty && d < kDepth) finalize(stack[d]);
  }
  *dirty_base = dirty >= base;
  return applied;
}

}  // namespace batch_detail

// Apply `cells` (distinct keys) to `tree` as updateNode(key, update, false) would.
// Sorts `cells`; `scratch` is working memory. Returns the number of cells not
// aborted early.
//
// With `n_threads` > 1 (and enough cells), the cells are split into the subtrees of
// one depth (the shallowest with at least 8 per thread); the paths down to them are
// made on one thread (as the first cell of each subtree that is not aborted would make
// them), the subtrees are updated on the threads, each owning its own, and the few
// shared nodes above them are finalised on one thread: the same tree, node for node,
// as on one thread.
inline size_t apply_updates(octomap::OcTree& tree, std::vector<CellUpdate>& cells,
                            std::vector<CellUpdate>& scratch, int n_threads = 1) {
  using namespace batch_detail;
  if (cells.empty()) return 0;
  sort_by_code(cells, scratch, n_threads);
  size_t first = 0, applied = 0;
  if (tree.getRoot() == nullptr) {  // liboctomap's updateNode creates the root
    tree.updateNode(morton_key(cells[0].code), cells[0].update, false);
    first = 1;
    applied = 1;
  }
  const CellUpdate* rest = cells.data() + first;
  const size_t n = cells.size() - first;
  Node* stack[kDepth + 1];
  stack[0] = tree.getRoot();
  bool dirty_root = false;
  constexpr size_t kMinParallelCells = 4096;
  if (n_threads <= 1 || n < kMinParallelCells) {
    TreeOps ops{tree};
    return applied + update_below(tree, rest, n, stack, 0, false, ops, &dirty_root);
  }
  // the split depth: the shallowest with at least 8 subtrees a thread (at most 12)
  int base = 1;
  std::vector<size_t> starts;
  for (; base <= 12; ++base) {
    const int shift = 3 * (kDepth - base);
    starts.clear();
    for (size_t i = 0; i < n; ++i)
      if (i == 0 || (rest[i].code >> shift) != (rest[i - 1].code >> shift)) starts.push_back(i);
    if (starts.size() >= static_cast<size_t>(64 * n_threads)) break;
  }
  base = std::min(base, 12);
  starts.push_back(n);
  const ptrdiff_t n_groups = static_cast<ptrdiff_t>(starts.size()) - 1;
  const float clamp_min = tree.getClampingThresMinLog();
  const float clamp_max = tree.getClampingThresMaxLog();
  // each subtree's first cell that is not aborted (n: none), found without changing the tree
  std::vector<size_t> lead(n_groups, n);
#pragma omp parallel for num_threads(n_threads) schedule(dynamic)
  for (ptrdiff_t g = 0; g < n_groups; ++g) {
    for (size_t i = starts[g]; i < starts[g + 1]; ++i) {
      if (!aborts(tree, stack[0], rest[i].code, rest[i].update, clamp_min, clamp_max)) {
        lead[g] = i;
        break;
      }
    }
  }
  // the paths down to the subtrees, made as that cell's updateNodeRecurs makes them
  std::vector<Node*> roots(n_groups, nullptr);
  std::vector<uint8_t> fresh(n_groups, 0);
  {
    TreeOps ops{tree};
    for (ptrdiff_t g = 0; g < n_groups; ++g) {
      if (lead[g] == n) continue;
      const uint64_t code = rest[lead[g]].code;
      Node* node = stack[0];
      int d = 0;
      while (d < base) {
        const unsigned pos = child_index(code, d);
        if (!tree.nodeChildExists(node, pos)) break;
        node = tree.getNodeChild(node, pos);
        ++d;
      }
      bool created = false;
      while (d < base) {
        node = step_down(tree, ops, node, child_index(code, d), created);
        ++d;
      }
      roots[g] = node;
      fresh[g] = created;
    }
  }
  // the subtrees, on the threads
  std::vector<size_t> done(n_groups, 0);
  std::vector<long> delta(n_groups, 0);
  std::exception_ptr error;
#pragma omp parallel for num_threads(n_threads) schedule(dynamic)
  for (ptrdiff_t g = 0; g < n_groups; ++g) {
    if (roots[g] == nullptr) continue;
    try {
      Node* sub[kDepth + 1];
      sub[base] = roots[g];
      SubtreeOps ops{tree, 0};
      bool dirty = false;
      done[g] = update_below(tree, rest + lead[g], starts[g + 1] - lead[g], sub, base,
                             fresh[g] != 0, ops, &dirty);
      delta[g] = ops.delta;
    } catch (...) {
#pragma omp critical(occgp_batch_error)
      if (!error) error = std::current_exception();
    }
  }
  long total = 0;
  for (ptrdiff_t g = 0; g < n_groups; ++g) {
    applied += done[g];
    total += delta[g];
  }
  if (total != 0) {
    tree.*TreeAccess::size_member() = static_cast<size_t>(static_cast<long>(tree.size()) + total);
    tree.*TreeAccess::changed_member() = true;
  }
  if (error) std::rethrow_exception(error);
  // the shared nodes above the subtrees, deepest first, each once
  TreeOps ops{tree};
  for (int d = base - 1; d >= 0; --d) {
    const int shift = 3 * (kDepth - d);
    uint64_t last = ~0ULL;
    for (ptrdiff_t g = 0; g < n_groups; ++g) {
      if (roots[g] == nullptr) continue;
      const uint64_t prefix = rest[starts[g]].code >> shift;
      if (prefix == last) continue;
      last = prefix;
      Node* node = stack[0];
      const uint64_t code = rest[starts[g]].code;
      for (int k = 0; k < d; ++k) node = tree.getNodeChild(node, child_index(code, k));
      if (!ops.prune(node)) node->updateOccupancyChildren();
    }
  }
  return applied;
}

}  // namespace occgp

#endif  // OCCGP_OCTREE_BATCH_H
