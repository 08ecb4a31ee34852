#pragma once
// Variable I/O granularity (Zhou, Zhu & Zhang, seed 004, section 4): which reads fetch the
// node blocks and pieces a frame wants, one object, one node or one whole subtree per read,
// chosen by a cost model of the source. Pure arithmetic over a depth-first node list; no I/O.

#include <cstdint>
#include <vector>

#include <tessera/scene.h>
#include <tessera/scene_stream.h>

namespace tessera::detail {

/// One node as the planner sees it, in depth-first pre-order (SceneNode's numbering), so
/// that node i's subtree is [i, i + subtree_nodes) and its bytes [own.offset, + subtree).
struct PlanNode {
  uint32_t subtree_nodes = 1;
  FileRange own;      ///< the node's block
  FileRange subtree;  ///< starts where `own` does and holds every descendant's block
  /// The node's block is wanted (its objects, meshes or texture levels are needed).
  bool wanted = false;
  /// The byte ranges inside `own` that are enough for what is wanted (mesh blobs, texture
  /// tiles once the node's head is known; the head and directory pages of a large node not yet
  /// read), read at object granularity, neighbours joined (mergePieces). Empty: only a node or
  /// subtree read can serve the node.
  std::vector<FileRange> pieces;
};

/// `pieces` sorted and joined into the reads of least total cost: two neighbours become one
/// read (gap included) exactly when the gap costs less than a round trip (gap / bandwidth <
/// latency); overlapping pieces always join.
std::vector<FileRange> mergePieces(std::vector<FileRange> pieces, const LinkCost& link);

/// Cost of one read of `bytes` bytes: latency + bytes / bandwidth (seconds).
double readCost(const LinkCost& link, uint64_t bytes);

/// The reads of least total cost (sum of readCost) that cover every wanted node: its block
/// by a read of the node or of a subtree containing it, or all its pieces by object reads
/// (joined by mergePieces).
/// Exact, by dynamic programming over the tree (cost(n) = min(subtree read, own part +
/// children's costs)): O(nodes + pieces). Reads are returned in file order; a subtree read
/// stands for every wanted node in it. `nodes` must be a whole tree or a forest of whole
/// subtrees in pre-order.
std::vector<PlannedRead> planReads(const std::vector<PlanNode>& nodes, const LinkCost& link);

/// Reads of a plan joined where they are neighbours in the file: one source read of `range`
/// (the hull of its parts), counted at the coarsest granularity among them.
struct JoinedRead {
  PlannedRead read;
  std::vector<PlannedRead> parts;  ///< in file order; what each part was planned for
};

/// Joins file-ordered `reads` of different nodes as mergePieces joins one node's pieces: two
/// neighbours become one read exactly when the gap between them costs less than a round trip
/// (a subtree read and the next sibling's, a node's pieces and the next node's block).
std::vector<JoinedRead> joinReads(const std::vector<PlannedRead>& reads, const LinkCost& link);

/// Total cost of `reads` under `link`.
double planCost(const std::vector<PlannedRead>& reads, const LinkCost& link);

}  // namespace tessera::detail
