#include "io_plan.h"

#include <algorithm>
#include <limits>

#include <tessera/check.h>

namespace tessera::detail {
namespace {

// The least-cost cover of one subtree and the reads that reach it.
struct SubtreePlan {
  double cost = 0;
  std::vector<PlannedRead> reads;
};

class Planner {
 public:
  Planner(const std::vector<PlanNode>& nodes, const LinkCost& link) : nodes_(nodes), link_(link) {}

  // Seed 004's choice at node i, exactly: either one read of the whole subtree, or the
  // node's own part (nothing, its block, or its pieces one read each) plus the best plan of
  // every child subtree. Children of i start at i + 1 and follow each other's subtrees.
  SubtreePlan plan(uint32_t i) {
    const PlanNode& node = nodes_[i];
    SubtreePlan split;
    bool any_wanted = node.wanted;
    if (node.wanted) addOwn(i, split);
    const uint32_t end = i + node.subtree_nodes;
    for (uint32_t child = i + 1; child < end; child += nodes_[child].subtree_nodes) {
      SubtreePlan sub = plan(child);
      if (!sub.reads.empty()) any_wanted = true;
      split.cost += sub.cost;
      split.reads.insert(split.reads.end(), sub.reads.begin(), sub.reads.end());
    }
    if (!any_wanted) return {};
    const double whole = readCost(link_, node.subtree.length_bytes);
    // A leaf's subtree is its block: call that read a node read. A tie (up to rounding: every
    // node below wanted) goes to the finer reads, which fetch nothing unwanted.
    if (node.subtree_nodes > 1 && whole < split.cost * (1 - 1e-12)) {
      return {whole, {{ReadGranularity::kSubtree, i, node.subtree}}};
    }
    return split;
  }

 private:
  void addOwn(uint32_t i, SubtreePlan& out) const {
    const PlanNode& node = nodes_[i];
    const double block = readCost(link_, node.own.length_bytes);
    const std::vector<FileRange> runs = mergePieces(node.pieces, link_);
    double pieces = runs.empty() ? std::numeric_limits<double>::infinity() : 0;
    for (const FileRange& run : runs) pieces += readCost(link_, run.length_bytes);
    if (pieces < block) {
      out.cost += pieces;
      for (const FileRange& run : runs) out.reads.push_back({ReadGranularity::kObject, i, run});
    } else {
      out.cost += block;
      out.reads.push_back({ReadGranularity::kNode, i, node.own});
    }
  }

  const std::vector<PlanNode>& nodes_;
  const LinkCost& link_;
};

}  // namespace

std::vector<FileRange> mergePieces(std::vector<FileRange> pieces, const LinkCost& link) {
  std::sort(pieces.begin(), pieces.end(),
            [](const FileRange& a, const FileRange& b) { return a.offset_bytes < b.offset_bytes; });
  // Reading a gap costs gap / bandwidth, a read of its own the latency: each gap is decided
  // alone, so joining exactly the gaps cheaper than a round trip is the least total cost.
  const double gap_limit_bytes = link.latency_s * link.bandwidth_bytes_per_s;
  std::vector<FileRange> runs;
  for (const FileRange& piece : pieces) {
    const uint64_t end = piece.offset_bytes + piece.length_bytes;
    if (!runs.empty()) {
      FileRange& last = runs.back();
      const uint64_t last_end = last.offset_bytes + last.length_bytes;
      if (piece.offset_bytes <= last_end ||
          double(piece.offset_bytes - last_end) < gap_limit_bytes) {
        last.length_bytes = std::max(last_end, end) - last.offset_bytes;
        continue;
      }
    }
    runs.push_back(piece);
  }
  return runs;
}

double readCost(const LinkCost& link, uint64_t bytes) {
  return link.latency_s + double(bytes) / link.bandwidth_bytes_per_s;
}

std::vector<PlannedRead> planReads(const std::vector<PlanNode>& nodes, const LinkCost& link) {
  TESSERA_CHECK(link.bandwidth_bytes_per_s > 0) << "planReads: bandwidth must be positive";
  Planner planner(nodes, link);
  std::vector<PlannedRead> reads;
  for (uint32_t root = 0; root < nodes.size(); root += nodes[root].subtree_nodes) {
    TESSERA_CHECK(nodes[root].subtree_nodes >= 1) << "planReads: node " << root << " empty";
    SubtreePlan sub = planner.plan(root);
    reads.insert(reads.end(), sub.reads.begin(), sub.reads.end());
  }
  std::sort(reads.begin(), reads.end(), [](const PlannedRead& a, const PlannedRead& b) {
    return a.range.offset_bytes < b.range.offset_bytes;
  });
  return reads;
}

std::vector<JoinedRead> joinReads(const std::vector<PlannedRead>& reads, const LinkCost& link) {
  std::vector<PlannedRead> sorted = reads;
  std::sort(sorted.begin(), sorted.end(), [](const PlannedRead& a, const PlannedRead& b) {
    return a.range.offset_bytes < b.range.offset_bytes;
  });
  const double gap_limit_bytes = link.latency_s * link.bandwidth_bytes_per_s;
  std::vector<JoinedRead> out;
  for (const PlannedRead& read : sorted) {
    const uint64_t end = read.range.offset_bytes + read.range.length_bytes;
    if (!out.empty()) {
      PlannedRead& last = out.back().read;
      const uint64_t last_end = last.range.offset_bytes + last.range.length_bytes;
      if (read.range.offset_bytes <= last_end ||
          double(read.range.offset_bytes - last_end) < gap_limit_bytes) {
        last.range.length_bytes = std::max(last_end, end) - last.range.offset_bytes;
        last.granularity = std::max(last.granularity, read.granularity);
        out.back().parts.push_back(read);
        continue;
      }
    }
    out.push_back({read, {read}});
  }
  return out;
}

double planCost(const std::vector<PlannedRead>& reads, const LinkCost& link) {
  double cost = 0;
  for (const PlannedRead& read : reads) cost += readCost(link, read.range.length_bytes);
  return cost;
}

}  // namespace tessera::detail
