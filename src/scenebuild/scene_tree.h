#pragma once
// The R-tree over object bounds and the promotion of shared items (Zhou, Zhu & Zhang, seed
// 004, section 3): leaves from the objects' bounding boxes, bulk-loaded by Sort-Tile-Recursive
// (Leutenegger et al. 1997) so every leaf is at the same depth and siblings are spatially
// close; a texture or mesh used by several leaves is stored once, at their lowest common
// ancestor.

#include <cstdint>
#include <span>
#include <vector>

#include "format/scene.h"

namespace tessera::detail {

inline constexpr uint32_t kNoNode = 0xFFFFFFFFu;

struct TreeNode {
  SceneBox bounds;                 ///< union of its children's or objects' boxes
  uint32_t parent = kNoNode;       ///< kNoNode at the root
  uint32_t depth = 0;              ///< 0 at the root
  uint32_t subtree_nodes = 1;      ///< this node and its descendants
  std::vector<uint32_t> children;  ///< node indices, in order
  std::vector<uint32_t> objects;   ///< input object indices (leaves only)
};

/// Nodes in depth-first pre-order (node 0 the root, a subtree a contiguous index range).
struct SceneTree {
  std::vector<TreeNode> nodes;
  std::vector<uint32_t> leaf_of;  ///< per input object, the leaf that holds it
  uint32_t depth = 1;             ///< levels; every leaf is at depth - 1
};

/// Bulk-loads the tree. Requires at least one box, leaf_capacity >= 1 and max_children >= 2.
/// Deterministic: ties are broken by object index.
SceneTree buildSceneTree(std::span<const SceneBox> boxes, uint32_t leaf_capacity,
                         uint32_t max_children);

/// The lowest common ancestor of two nodes.
uint32_t commonAncestor(const SceneTree& tree, uint32_t a, uint32_t b);

/// Per item, the node that stores it: the lowest common ancestor of the leaves of the objects
/// in users[item]; kNoNode for an item nobody uses.
std::vector<uint32_t> promoteItems(const SceneTree& tree,
                                   std::span<const std::vector<uint32_t>> users);

/// The union of two boxes.
SceneBox unionBox(const SceneBox& a, const SceneBox& b);

}  // namespace tessera::detail
