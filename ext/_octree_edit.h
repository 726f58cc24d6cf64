// Node deletion and node listing for occgp's OcTree (used from ext/_octree.pyx).
//
// liboctomap 1.9's OcTreeBaseImpl::deleteNode cannot be used: deleteNodeRecurs
// deletes an inner node through deleteNodeChild while its (possibly empty)
// array of children is still allocated, which the node's destructor asserts
// against (an abort), and it re-evaluates only the deepest surviving ancestor
// and leaves an emptied root behind as a stale leaf. delete_node keeps its
// semantics otherwise: a pruned leaf on the way down is expanded (its eight
// children take its value) and the search continues in the child; the node at
// the requested depth is removed with its whole subtree; an inner node left
// without children is removed too (it would otherwise read as a leaf with its
// old value), up to the root (then the tree is cleared); every ancestor left
// is re-evaluated as the max of its children (updateOccupancyChildren).
//
// Only liboctomap's public node API is used; a node's children array is freed
// the way pruneNode frees it (eight equal leaf children, then pruneNode).
//
// collect_nodes walks the tree depth-first in liboctomap's iterator order
// (pre-order, child 0 first), as begin_tree(maxDepth) or, with leaves_only,
// begin_leafs(maxDepth) do, skipping the subtrees that miss a key box.
#ifndef OCCGP_OCTREE_EDIT_H
#define OCCGP_OCTREE_EDIT_H
#include <cstdint>
#include <vector>
#include <octomap/OcTree.h>

namespace occgp {

constexpr unsigned kEditDepth = 16;

// liboctomap's computeChildIdx(key, 15 - depth): the child of a depth-`depth` node
// holding `key`.
inline unsigned edit_child_index(const octomap::OcTreeKey& key, unsigned depth) {
  const unsigned bit = kEditDepth - 1 - depth;
  return ((key[0] >> bit) & 1u) | (((key[1] >> bit) & 1u) << 1) | (((key[2] >> bit) & 1u) << 2);
}

// Free the children array of a node that has no children (the array may or may not
// be allocated): create eight equal leaf children and prune them, as pruneNode does.
inline void free_children(octomap::OcTree& tree, octomap::OcTreeNode* node) {
  for (unsigned i = 0; i < 8; ++i) {
    if (!tree.nodeChildExists(node, i)) tree.createNodeChild(node, i)->setLogOdds(0.0f);
  }
  tree.pruneNode(node);
}

// Delete child `pos` of `parent` (at depth `depth`) with its whole subtree.
inline void delete_subtree(octomap::OcTree& tree, octomap::OcTreeNode* parent, unsigned pos,
                           unsigned depth) {
  octomap::OcTreeNode* node = tree.getNodeChild(parent, pos);
  if (depth < kEditDepth) {
    for (unsigned i = 0; i < 8; ++i) {
      if (tree.nodeChildExists(node, i)) delete_subtree(tree, node, i, depth + 1);
    }
    free_children(tree, node);
  }
  tree.deleteNodeChild(parent, pos);
}

// Delete the node at `depth` (1..16) holding `key`; returns whether there was one.
inline bool delete_node(octomap::OcTree& tree, const octomap::OcTreeKey& key, unsigned depth) {
  typedef octomap::OcTreeNode Node;
  Node* path[kEditDepth + 1];
  unsigned pos[kEditDepth];
  path[0] = tree.getRoot();
  if (path[0] == nullptr) return false;
  for (unsigned d = 0; d < depth; ++d) {
    Node* node = path[d];
    pos[d] = edit_child_index(key, d);
    if (!tree.nodeChildExists(node, pos[d])) {
      if (tree.nodeHasChildren(node)) return false;  // no node holds the key
      tree.expandNode(node);                        // a pruned leaf: split it
    }
    path[d + 1] = tree.getNodeChild(node, pos[d]);
  }
  delete_subtree(tree, path[depth - 1], pos[depth - 1], depth);
  // remove the ancestors left without children, then re-evaluate the others
  int d = static_cast<int>(depth) - 1;
  while (d >= 0 && !tree.nodeHasChildren(path[d])) {
    if (d == 0) {
      tree.clear();
      return true;
    }
    free_children(tree, path[d]);
    tree.deleteNodeChild(path[d - 1], pos[d - 1]);
    --d;
  }
  for (; d >= 0; --d) path[d]->updateOccupancyChildren();
  return true;
}

struct NodeList {
  std::vector<double> centers;  // 3 per node
  std::vector<double> sizes;
  std::vector<uint8_t> depths;
  std::vector<float> values;
  std::vector<uint8_t> is_leaf;
};

// Append the nodes of the subtree at `node` (depth `depth`, key `key` with the bits
// below the node cleared) to `out`, pre-order, child 0 first.
inline void collect_nodes_rec(const octomap::OcTree& tree, const octomap::OcTreeNode* node,
                              const octomap::OcTreeKey& key, unsigned depth, unsigned max_depth,
                              bool leaves_only, bool occupied_only,
                              const octomap::OcTreeKey& kmin, const octomap::OcTreeKey& kmax,
                              NodeList& out) {
  const unsigned span = (1u << (kEditDepth - depth)) - 1;  // keys below the node's key
  for (unsigned a = 0; a < 3; ++a) {
    if (key[a] > kmax[a] || key[a] + span < kmin[a]) return;
  }
  const bool leaf = depth == max_depth || !tree.nodeHasChildren(node);
  if ((leaf || !leaves_only) && (!occupied_only || tree.isNodeOccupied(node))) {
    for (unsigned a = 0; a < 3; ++a) out.centers.push_back(tree.keyToCoord(key[a], depth));
    out.sizes.push_back(tree.getNodeSize(depth));
    out.depths.push_back(static_cast<uint8_t>(depth));
    out.values.push_back(node->getLogOdds());
    out.is_leaf.push_back(leaf);
  }
  if (leaf) return;
  const unsigned bit = kEditDepth - 1 - depth;
  for (unsigned i = 0; i < 8; ++i) {
    if (!tree.nodeChildExists(node, i)) continue;
    octomap::OcTreeKey child = key;
    if (i & 1) child[0] |= static_cast<octomap::key_type>(1u << bit);
    if (i & 2) child[1] |= static_cast<octomap::key_type>(1u << bit);
    if (i & 4) child[2] |= static_cast<octomap::key_type>(1u << bit);
    collect_nodes_rec(tree, tree.getNodeChild(node, i), child, depth + 1, max_depth, leaves_only,
                      occupied_only, kmin, kmax, out);
  }
}

// The nodes (or, with `leaves_only`, the leaves) down to `max_depth` (1..16) whose key
// range meets the box [kmin, kmax], in liboctomap's iterator order.
inline void collect_nodes(const octomap::OcTree& tree, unsigned max_depth, bool leaves_only,
                          bool occupied_only, const octomap::OcTreeKey& kmin,
                          const octomap::OcTreeKey& kmax, NodeList& out) {
  const octomap::OcTreeNode* root = tree.getRoot();
  if (root == nullptr) return;
  collect_nodes_rec(tree, root, octomap::OcTreeKey(0, 0, 0), 0, max_depth, leaves_only,
                    occupied_only, kmin, kmax, out);
}

}  // namespace occgp

#endif  // OCCGP_OCTREE_EDIT_H
