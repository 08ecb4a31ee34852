// The R-tree (STR bulk load) and the promotion of shared items: invariants on random scenes,
// and promotion against a brute-force reference.
#include "scene_tree.h"

#include <random>
#include <set>

#include <gtest/gtest.h>

namespace tessera::detail {
namespace {

std::vector<SceneBox> randomBoxes(uint32_t count, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> pos(-1000, 1000), size(0.1f, 30);
  std::vector<SceneBox> boxes(count);
  for (SceneBox& box : boxes) {
    for (int a = 0; a < 3; ++a) {
      box.min[a] = pos(rng);
      box.max[a] = box.min[a] + size(rng);
    }
  }
  return boxes;
}

void expectTreeInvariants(const SceneTree& tree, std::span<const SceneBox> boxes,
                          uint32_t leaf_capacity, uint32_t max_children) {
  std::vector<int> seen(boxes.size(), 0);
  uint32_t leaf_depth = UINT32_MAX;
  for (uint32_t i = 0; i < tree.nodes.size(); ++i) {
    const TreeNode& n = tree.nodes[i];
    EXPECT_LE(n.children.size(), max_children);
    if (n.children.empty()) {
      EXPECT_GE(n.objects.size(), 1u);
      EXPECT_LE(n.objects.size(), leaf_capacity);
      if (leaf_depth == UINT32_MAX) leaf_depth = n.depth;
      EXPECT_EQ(n.depth, leaf_depth) << "leaves at different depths";
      EXPECT_EQ(n.subtree_nodes, 1u);
    } else {
      EXPECT_TRUE(n.objects.empty()) << "inner node " << i << " holds objects";
    }
    for (uint32_t o : n.objects) {
      ++seen[o];
      EXPECT_EQ(tree.leaf_of[o], i);
      EXPECT_TRUE(boxContains(n.bounds, boxes[o])) << "object " << o << " outside leaf " << i;
    }
    // Pre-order: children follow their parent, each after the previous child's subtree.
    uint32_t next = i + 1, total = 1;
    for (uint32_t c : n.children) {
      EXPECT_EQ(c, next);
      EXPECT_EQ(tree.nodes[c].parent, i);
      EXPECT_EQ(tree.nodes[c].depth, n.depth + 1);
      EXPECT_TRUE(boxContains(n.bounds, tree.nodes[c].bounds)) << "child " << c << " of " << i;
      next += tree.nodes[c].subtree_nodes;
      total += tree.nodes[c].subtree_nodes;
    }
    EXPECT_EQ(total, n.subtree_nodes);
  }
  for (size_t o = 0; o < seen.size(); ++o) EXPECT_EQ(seen[o], 1) << "object " << o;
  EXPECT_EQ(tree.depth, leaf_depth + 1);
  EXPECT_EQ(tree.nodes[0].subtree_nodes, tree.nodes.size());
}

TEST(SceneTree, EveryObjectInExactlyOneLeafAndBoundsNest) {
  for (uint32_t seed = 1; seed <= 20; ++seed) {
    const uint32_t count = 1 + seed * 97 % 3000;
    const uint32_t capacity = 1 + seed % 20, fan_out = 2 + seed % 15;
    auto boxes = randomBoxes(count, seed);
    SceneTree tree = buildSceneTree(boxes, capacity, fan_out);
    SCOPED_TRACE(testing::Message()
                 << count << " boxes, capacity " << capacity << ", fan-out " << fan_out);
    expectTreeInvariants(tree, boxes, capacity, fan_out);
  }
}

TEST(SceneTree, OneObjectIsARootLeaf) {
  auto boxes = randomBoxes(1, 3);
  SceneTree tree = buildSceneTree(boxes, 16, 8);
  ASSERT_EQ(tree.nodes.size(), 1u);
  EXPECT_EQ(tree.depth, 1u);
  EXPECT_EQ(tree.nodes[0].objects, std::vector<uint32_t>{0});
}

TEST(SceneTree, IsDeterministic) {
  auto boxes = randomBoxes(5000, 9);
  SceneTree a = buildSceneTree(boxes, 16, 8), b = buildSceneTree(boxes, 16, 8);
  ASSERT_EQ(a.nodes.size(), b.nodes.size());
  for (size_t i = 0; i < a.nodes.size(); ++i) EXPECT_EQ(a.nodes[i].objects, b.nodes[i].objects);
}

// The brute-force rule: an item is stored at the deepest node whose subtree holds every leaf
// of its users (seed 004, section 3: shared textures go up to the common father).
uint32_t bruteForceHolder(const SceneTree& tree, const std::vector<uint32_t>& users) {
  uint32_t best = kNoNode;
  for (uint32_t i = 0; i < tree.nodes.size(); ++i) {
    bool all = true;
    for (uint32_t o : users) {
      const uint32_t leaf = tree.leaf_of[o];
      all &= leaf >= i && leaf < i + tree.nodes[i].subtree_nodes;
    }
    if (all && (best == kNoNode || tree.nodes[i].depth > tree.nodes[best].depth)) best = i;
  }
  return best;
}

TEST(Promotion, MatchesBruteForceOnRandomScenes) {
  for (uint32_t seed = 1; seed <= 25; ++seed) {
    std::mt19937 rng(seed * 7919);
    const uint32_t objects = 50 + rng() % 800, items = 1 + rng() % 120;
    auto boxes = randomBoxes(objects, seed);
    SceneTree tree = buildSceneTree(boxes, 1 + rng() % 12, 2 + rng() % 8);
    std::vector<std::vector<uint32_t>> users(items);
    for (uint32_t o = 0; o < objects; ++o) {
      // Mostly one item per object, sometimes a few: local and global sharing both occur.
      const uint32_t refs = 1 + (rng() % 10 == 0 ? rng() % 4 : 0);
      for (uint32_t r = 0; r < refs; ++r) users[rng() % items].push_back(o);
    }
    users[0].clear();  // an unused item
    std::vector<uint32_t> holder = promoteItems(tree, users);
    for (uint32_t item = 0; item < items; ++item) {
      const uint32_t expected = users[item].empty() ? kNoNode : bruteForceHolder(tree, users[item]);
      EXPECT_EQ(holder[item], expected) << "seed " << seed << " item " << item;
    }
  }
}

TEST(Promotion, ItemOfOneLeafStaysInIt) {
  auto boxes = randomBoxes(400, 5);
  SceneTree tree = buildSceneTree(boxes, 8, 4);
  for (uint32_t o = 0; o < 400; o += 37) {
    std::vector<std::vector<uint32_t>> users = {{o}};
    EXPECT_EQ(promoteItems(tree, users)[0], tree.leaf_of[o]);
  }
}

TEST(Promotion, ItemOfEveryObjectGoesToTheRoot) {
  auto boxes = randomBoxes(400, 6);
  SceneTree tree = buildSceneTree(boxes, 8, 4);
  std::vector<std::vector<uint32_t>> users(1);
  for (uint32_t o = 0; o < 400; ++o) users[0].push_back(o);
  EXPECT_EQ(promoteItems(tree, users)[0], 0u);
}

}  // namespace
}  // namespace tessera::detail
