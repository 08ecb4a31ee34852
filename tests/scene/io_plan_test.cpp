// Variable I/O granularity: the planner's reads against a brute-force minimum over every
// choice of object, node and subtree reads on small random trees.
#include "io_plan.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <random>

#include <gtest/gtest.h>

namespace tessera::detail {
namespace {

// A random tree of `count` nodes in pre-order with blocks laid out depth-first, as the scene
// writer does, so that every subtree is one contiguous range.
std::vector<PlanNode> randomTree(std::mt19937& rng, uint32_t count) {
  std::vector<uint32_t> parent(count, 0);
  for (uint32_t i = 1; i < count; ++i) {
    // Any earlier node on the rightmost path keeps pre-order valid; pick among ancestors of i-1.
    std::vector<uint32_t> path;
    for (uint32_t p = i - 1;; p = parent[p]) {
      path.push_back(p);
      if (p == 0) break;
    }
    parent[i] = path[rng() % path.size()];
  }
  std::vector<PlanNode> nodes(count);
  uint64_t offset = 0;
  for (uint32_t i = 0; i < count; ++i) {
    const uint64_t own = 1 + rng() % 100000;
    nodes[i].own = {offset, own};
    offset += own;
    if (rng() % 2) nodes[i].wanted = true;
    if (nodes[i].wanted && rng() % 2) {
      const uint32_t pieces = 1 + rng() % 3;
      for (uint32_t p = 0; p < pieces; ++p) {
        const uint64_t len = 1 + rng() % std::max<uint64_t>(1, own / 4);
        nodes[i].pieces.push_back({nodes[i].own.offset_bytes + rng() % (own - len + 1), len});
      }
    }
  }
  for (uint32_t i = count; i-- > 0;) {
    nodes[i].subtree = nodes[i].own;
    for (uint32_t j = i + 1; j < count; ++j) {
      uint32_t a = j;
      while (a != 0 && a != i) a = parent[a];
      if (a == i) {
        ++nodes[i].subtree_nodes;
        nodes[i].subtree.length_bytes += nodes[j].own.length_bytes;
      }
    }
  }
  return nodes;
}

// Every assignment of {none, object, node, subtree} to the nodes; a plan is valid when every
// wanted node is read by itself or lies inside a chosen subtree.
double bruteForceMinimum(const std::vector<PlanNode>& nodes, const LinkCost& link) {
  const uint32_t n = uint32_t(nodes.size());
  std::vector<int> choice(n, 0);
  double best = INFINITY;
  std::function<void(uint32_t)> visit = [&](uint32_t i) {
    if (i == n) {
      double cost = 0;
      for (uint32_t k = 0; k < n; ++k) {
        if (choice[k] == 1) {
          for (const FileRange& run : mergePieces(nodes[k].pieces, link))
            cost += readCost(link, run.length_bytes);
        }
        if (choice[k] == 2) cost += readCost(link, nodes[k].own.length_bytes);
        if (choice[k] == 3) cost += readCost(link, nodes[k].subtree.length_bytes);
      }
      for (uint32_t k = 0; k < n; ++k) {
        if (!nodes[k].wanted || choice[k] == 1 || choice[k] == 2) continue;
        bool covered = false;
        for (uint32_t a = 0; a <= k && !covered; ++a) {
          covered = choice[a] == 3 && k < a + nodes[a].subtree_nodes;
        }
        if (!covered) return;
      }
      best = std::min(best, cost);
      return;
    }
    for (int c = 0; c < 4; ++c) {
      if (c == 1 && nodes[i].pieces.empty()) continue;
      choice[i] = c;
      visit(i + 1);
    }
  };
  visit(0);
  return best == INFINITY ? 0 : best;
}

// Whether `reads` cover every wanted node (a node read, every piece inside its object reads,
// or a subtree).
bool coversEveryWantedNode(const std::vector<PlanNode>& nodes,
                           const std::vector<PlannedRead>& reads) {
  for (uint32_t k = 0; k < nodes.size(); ++k) {
    if (!nodes[k].wanted) continue;
    bool covered = false;
    for (const PlannedRead& read : reads) {
      if (read.granularity == ReadGranularity::kNode && read.node == k) covered = true;
      if (read.granularity == ReadGranularity::kSubtree && read.node <= k &&
          k < read.node + nodes[read.node].subtree_nodes) {
        covered = true;
      }
    }
    bool pieces = !nodes[k].pieces.empty();
    for (const FileRange& piece : nodes[k].pieces) {
      bool inside = false;
      for (const PlannedRead& read : reads) {
        inside = inside || (read.granularity == ReadGranularity::kObject && read.node == k &&
                            read.range.offset_bytes <= piece.offset_bytes &&
                            piece.offset_bytes + piece.length_bytes <=
                                read.range.offset_bytes + read.range.length_bytes);
      }
      pieces = pieces && inside;
    }
    if (!covered && !pieces) return false;
  }
  return true;
}

// Every split of sorted pieces into runs of neighbours, each run read as its hull.
double bestSplit(std::vector<FileRange> pieces, const LinkCost& link) {
  std::sort(pieces.begin(), pieces.end(),
            [](const FileRange& a, const FileRange& b) { return a.offset_bytes < b.offset_bytes; });
  double best = INFINITY;
  const uint32_t gaps = uint32_t(pieces.size()) - 1;
  for (uint32_t cut = 0; cut < (1u << gaps); ++cut) {
    double cost = 0;
    uint64_t begin = pieces[0].offset_bytes, end = begin + pieces[0].length_bytes;
    for (uint32_t p = 1; p <= pieces.size(); ++p) {
      if (p == pieces.size() || (cut >> (p - 1) & 1)) {
        cost += readCost(link, end - begin);
        if (p == pieces.size()) break;
        begin = pieces[p].offset_bytes;
        end = begin + pieces[p].length_bytes;
      } else {
        end = std::max(end, pieces[p].offset_bytes + pieces[p].length_bytes);
      }
    }
    best = std::min(best, cost);
  }
  return best;
}

TEST(IoPlan, JoinsExactlyTheGapsCheaperThanARoundTrip) {
  std::mt19937 rng(11);
  const LinkCost link{0.001, 1e6};  // a gap under 1000 bytes is cheaper than a read
  for (int round = 0; round < 300; ++round) {
    std::vector<FileRange> pieces(1 + rng() % 8);
    for (FileRange& piece : pieces) piece = {rng() % 20000, 1 + rng() % 1500};
    const std::vector<FileRange> runs = mergePieces(pieces, link);
    double cost = 0;
    for (const FileRange& run : runs) cost += readCost(link, run.length_bytes);
    EXPECT_NEAR(cost, bestSplit(pieces, link), 1e-9) << "round " << round;
    for (const FileRange& piece : pieces) {
      EXPECT_TRUE(std::any_of(runs.begin(), runs.end(), [&](const FileRange& run) {
        return run.offset_bytes <= piece.offset_bytes &&
               piece.offset_bytes + piece.length_bytes <= run.offset_bytes + run.length_bytes;
      }));
    }
  }
  // Two pieces 999 bytes apart join; 1001 bytes apart they stay two reads.
  EXPECT_EQ(mergePieces({{0, 10}, {1009, 10}}, link).size(), 1u);
  EXPECT_EQ(mergePieces({{0, 10}, {1011, 10}}, link).size(), 2u);
}

TEST(IoPlan, JoinsNeighbouringReadsOfDifferentNodes) {
  const LinkCost link{0.001, 1e6};  // gaps under 1000 bytes join
  std::mt19937 rng(5);
  for (int round = 0; round < 200; ++round) {
    std::vector<PlannedRead> reads;
    uint64_t offset = 0;
    for (uint32_t i = 0; i < 1 + rng() % 10; ++i) {
      offset += rng() % 2500;
      const uint64_t length = 1 + rng() % 3000;
      reads.push_back({ReadGranularity(rng() % 3), i, {offset, length}});
      offset += length;
    }
    std::shuffle(reads.begin(), reads.end(), rng);
    const std::vector<JoinedRead> joined = joinReads(reads, link);
    size_t parts = 0;
    for (size_t j = 0; j < joined.size(); ++j) {
      const FileRange& range = joined[j].read.range;
      parts += joined[j].parts.size();
      ReadGranularity coarsest = ReadGranularity::kObject;
      for (size_t p = 0; p < joined[j].parts.size(); ++p) {
        const FileRange& part = joined[j].parts[p].range;
        EXPECT_GE(part.offset_bytes, range.offset_bytes);
        EXPECT_LE(part.offset_bytes + part.length_bytes, range.offset_bytes + range.length_bytes);
        if (p > 0) {
          const FileRange& prev = joined[j].parts[p - 1].range;
          EXPECT_LT(part.offset_bytes - (prev.offset_bytes + prev.length_bytes), 1000u);
        }
        coarsest = std::max(coarsest, joined[j].parts[p].granularity);
      }
      EXPECT_EQ(joined[j].read.granularity, coarsest);
      if (j > 0) {
        const FileRange& prev = joined[j - 1].read.range;
        EXPECT_GE(range.offset_bytes - (prev.offset_bytes + prev.length_bytes), 1000u)
            << "a gap cheaper than a round trip would have joined";
      }
    }
    EXPECT_EQ(parts, reads.size());
  }
}

TEST(IoPlan, MatchesTheBruteForceMinimumOnRandomTrees) {
  std::mt19937 rng(28);
  // Latencies from a RAM disk to a slow link, so every granularity wins somewhere.
  const LinkCost links[] = {{0.0, 1e9}, {0.0001, 1e9}, {0.008, 100e6}, {0.04, 2.5e6}};
  uint32_t by_granularity[3] = {0, 0, 0};
  for (int trial = 0; trial < 400; ++trial) {
    const std::vector<PlanNode> nodes = randomTree(rng, 1 + rng() % 7);
    const LinkCost& link = links[trial % 4];
    const std::vector<PlannedRead> reads = planReads(nodes, link);
    ASSERT_TRUE(coversEveryWantedNode(nodes, reads)) << "trial " << trial;
    const double brute = bruteForceMinimum(nodes, link);
    EXPECT_NEAR(planCost(reads, link), brute, 1e-9 * std::max(1.0, brute)) << "trial " << trial;
    for (const PlannedRead& read : reads) ++by_granularity[int(read.granularity)];
  }
  EXPECT_GT(by_granularity[0], 0u) << "object reads chosen somewhere";
  EXPECT_GT(by_granularity[1], 0u) << "node reads chosen somewhere";
  EXPECT_GT(by_granularity[2], 0u) << "subtree reads chosen somewhere";
}

TEST(IoPlan, HighLatencyReadsTheSubtreeAndLowLatencyOnlyWhatIsWanted) {
  // Root with two leaves of 1 MB each; only the two leaves are wanted.
  std::vector<PlanNode> nodes(3);
  nodes[0] = {3, {0, 1000}, {0, 2001000}, false, {}};
  nodes[1] = {1, {1000, 1000000}, {1000, 1000000}, true, {}};
  nodes[2] = {1, {1001000, 1000000}, {1001000, 1000000}, true, {}};
  // 40 ms round trip: one read of 2.001 MB beats two reads of 1 MB (1 KB more bytes).
  std::vector<PlannedRead> slow = planReads(nodes, {0.04, 2.5e6});
  ASSERT_EQ(slow.size(), 1u);
  EXPECT_EQ(slow[0].granularity, ReadGranularity::kSubtree);
  EXPECT_EQ(slow[0].range.length_bytes, 2001000u);
  // No latency at all: reading the root's 1 KB for nothing costs more than a second read.
  std::vector<PlannedRead> fast = planReads(nodes, {0.0, 1e9});
  ASSERT_EQ(fast.size(), 2u);
  EXPECT_EQ(fast[0].granularity, ReadGranularity::kNode);
  EXPECT_EQ(fast[1].node, 2u);
  // A known head and one small wanted piece: object granularity.
  nodes[2].wanted = false;
  nodes[1].pieces = {{5000, 2000}};
  std::vector<PlannedRead> piece = planReads(nodes, {0.0001, 1e9});
  ASSERT_EQ(piece.size(), 1u);
  EXPECT_EQ(piece[0].granularity, ReadGranularity::kObject);
  EXPECT_EQ(piece[0].range.offset_bytes, 5000u);
}

TEST(IoPlan, NothingWantedReadsNothing) {
  std::vector<PlanNode> nodes(2);
  nodes[0] = {2, {0, 10}, {0, 30}, false, {}};
  nodes[1] = {1, {10, 20}, {10, 20}, false, {}};
  EXPECT_TRUE(planReads(nodes, {}).empty());
}

}  // namespace
}  // namespace tessera::detail
