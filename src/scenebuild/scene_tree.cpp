#include "scene_tree.h"

#include <algorithm>
#include <cmath>
#include <numeric>

#include <tessera/check.h>

namespace tessera::detail {

namespace {

// A node while the tree is built bottom-up, before pre-order numbering.
struct BuildNode {
  SceneBox bounds;
  std::vector<uint32_t> children;  ///< indices into the build nodes
  std::vector<uint32_t> objects;
};

float centre(const SceneBox& box, int axis) {
  return 0.5f * (box.min[axis] + box.max[axis]);
}

// Sort-Tile-Recursive grouping in two axes (the scene's two longest): sort by the first,
// cut into slabs of about sqrt(groups) groups, sort each slab by the second, cut into groups.
std::vector<std::vector<uint32_t>> strGroups(std::span<const SceneBox> boxes,
                                             std::vector<uint32_t> items, uint32_t capacity,
                                             int axis_a, int axis_b) {
  const size_t groups = (items.size() + capacity - 1) / capacity;
  const size_t slabs = size_t(std::ceil(std::sqrt(double(groups))));
  const size_t slab_items = ((groups + slabs - 1) / slabs) * capacity;
  auto by_axis = [&](int axis) {
    return [&boxes, axis](uint32_t a, uint32_t b) {
      float ca = centre(boxes[a], axis), cb = centre(boxes[b], axis);
      return ca != cb ? ca < cb : a < b;
    };
  };
  std::sort(items.begin(), items.end(), by_axis(axis_a));
  std::vector<std::vector<uint32_t>> out;
  for (size_t begin = 0; begin < items.size(); begin += slab_items) {
    const size_t end = std::min(items.size(), begin + slab_items);
    std::sort(items.begin() + begin, items.begin() + end, by_axis(axis_b));
    for (size_t g = begin; g < end; g += capacity)
      out.emplace_back(items.begin() + g, items.begin() + std::min(end, g + capacity));
  }
  return out;
}

}  // namespace

SceneBox unionBox(const SceneBox& a, const SceneBox& b) {
  SceneBox out;
  for (int i = 0; i < 3; ++i) {
    out.min[i] = std::min(a.min[i], b.min[i]);
    out.max[i] = std::max(a.max[i], b.max[i]);
  }
  return out;
}

SceneTree buildSceneTree(std::span<const SceneBox> boxes, uint32_t leaf_capacity,
                         uint32_t max_children) {
  TESSERA_CHECK(!boxes.empty() && leaf_capacity >= 1 && max_children >= 2)
      << "buildSceneTree: no objects or a degenerate capacity";
  SceneBox all = boxes[0];
  for (const SceneBox& box : boxes) all = unionBox(all, box);
  int axes[3] = {0, 1, 2};
  std::sort(axes, axes + 3, [&](int a, int b) {
    float ea = all.max[a] - all.min[a], eb = all.max[b] - all.min[b];
    return ea != eb ? ea > eb : a < b;
  });

  // Leaves from the objects, then levels of inner nodes until one node is left.
  std::vector<BuildNode> build;
  std::vector<uint32_t> level;
  std::vector<uint32_t> objects(boxes.size());
  std::iota(objects.begin(), objects.end(), 0u);
  for (auto& group : strGroups(boxes, std::move(objects), leaf_capacity, axes[0], axes[1])) {
    BuildNode node;
    node.bounds = boxes[group[0]];
    for (uint32_t o : group) node.bounds = unionBox(node.bounds, boxes[o]);
    node.objects = std::move(group);
    level.push_back(uint32_t(build.size()));
    build.push_back(std::move(node));
  }
  while (level.size() > 1) {
    std::vector<SceneBox> level_boxes;
    for (uint32_t n : level) level_boxes.push_back(build[n].bounds);
    std::vector<uint32_t> positions(level.size());
    std::iota(positions.begin(), positions.end(), 0u);
    std::vector<uint32_t> next;
    for (auto& group : strGroups(level_boxes, positions, max_children, axes[0], axes[1])) {
      BuildNode node;
      node.bounds = level_boxes[group[0]];
      for (uint32_t p : group) {
        node.bounds = unionBox(node.bounds, level_boxes[p]);
        node.children.push_back(level[p]);
      }
      next.push_back(uint32_t(build.size()));
      build.push_back(std::move(node));
    }
    level = std::move(next);
  }

  // Pre-order numbering with an explicit stack.
  SceneTree tree;
  tree.leaf_of.assign(boxes.size(), kNoNode);
  struct Pending {
    uint32_t build_index, parent, depth;
  };
  std::vector<Pending> stack{{level[0], kNoNode, 0}};
  while (!stack.empty()) {
    Pending p = stack.back();
    stack.pop_back();
    const uint32_t index = uint32_t(tree.nodes.size());
    TreeNode node;
    node.bounds = build[p.build_index].bounds;
    node.parent = p.parent;
    node.depth = p.depth;
    node.objects = build[p.build_index].objects;
    for (uint32_t o : node.objects) tree.leaf_of[o] = index;
    if (p.parent != kNoNode) tree.nodes[p.parent].children.push_back(index);
    tree.depth = std::max(tree.depth, p.depth + 1);
    tree.nodes.push_back(std::move(node));
    const auto& children = build[p.build_index].children;
    for (size_t c = children.size(); c-- > 0;) stack.push_back({children[c], index, p.depth + 1});
  }
  for (size_t i = tree.nodes.size(); i-- > 1;)
    tree.nodes[tree.nodes[i].parent].subtree_nodes += tree.nodes[i].subtree_nodes;
  return tree;
}

uint32_t commonAncestor(const SceneTree& tree, uint32_t a, uint32_t b) {
  while (tree.nodes[a].depth > tree.nodes[b].depth) a = tree.nodes[a].parent;
  while (tree.nodes[b].depth > tree.nodes[a].depth) b = tree.nodes[b].parent;
  while (a != b) {
    a = tree.nodes[a].parent;
    b = tree.nodes[b].parent;
  }
  return a;
}

std::vector<uint32_t> promoteItems(const SceneTree& tree,
                                   std::span<const std::vector<uint32_t>> users) {
  std::vector<uint32_t> holder(users.size(), kNoNode);
  for (size_t item = 0; item < users.size(); ++item) {
    for (uint32_t object : users[item]) {
      const uint32_t leaf = tree.leaf_of[object];
      holder[item] = holder[item] == kNoNode ? leaf : commonAncestor(tree, holder[item], leaf);
    }
  }
  return holder;
}

}  // namespace tessera::detail
