#include "analysis/storage_choice.h"

#include <algorithm>
#include <limits>
#include <map>
#include <queue>

namespace tessera::detail {

namespace {

/// Dinic's maximum flow on a small graph of int64 capacities.
class MaxFlow {
 public:
  explicit MaxFlow(size_t nodes) : adjacency_(nodes), level_(nodes), next_(nodes) {}

  void addEdge(size_t from, size_t to, int64_t capacity) {
    adjacency_[from].push_back(edges_.size());
    edges_.push_back({to, capacity});
    adjacency_[to].push_back(edges_.size());
    edges_.push_back({from, 0});
  }

  int64_t run(size_t source, size_t sink) {
    int64_t flow = 0;
    while (buildLevels(source, sink)) {
      std::fill(next_.begin(), next_.end(), 0);
      while (int64_t pushed = push(source, sink, std::numeric_limits<int64_t>::max()))
        flow += pushed;
    }
    return flow;
  }

  /// After run: the nodes reachable from the source in the residual graph (the cut's side).
  std::vector<bool> sourceSide(size_t source) const {
    std::vector<bool> seen(adjacency_.size(), false);
    std::vector<size_t> stack = {source};
    seen[source] = true;
    while (!stack.empty()) {
      size_t node = stack.back();
      stack.pop_back();
      for (size_t e : adjacency_[node]) {
        if (edges_[e].capacity > 0 && !seen[edges_[e].to]) {
          seen[edges_[e].to] = true;
          stack.push_back(edges_[e].to);
        }
      }
    }
    return seen;
  }

 private:
  struct Edge {
    size_t to;
    int64_t capacity;
  };

  bool buildLevels(size_t source, size_t sink) {
    std::fill(level_.begin(), level_.end(), -1);
    std::queue<size_t> queue;
    level_[source] = 0;
    queue.push(source);
    while (!queue.empty()) {
      size_t node = queue.front();
      queue.pop();
      for (size_t e : adjacency_[node]) {
        if (edges_[e].capacity > 0 && level_[edges_[e].to] < 0) {
          level_[edges_[e].to] = level_[node] + 1;
          queue.push(edges_[e].to);
        }
      }
    }
    return level_[sink] >= 0;
  }

  // Iterative depth-first augmenting path along increasing levels.
  int64_t push(size_t source, size_t sink, int64_t limit) {
    std::vector<size_t> path_edges;
    size_t node = source;
    while (true) {
      if (node == sink) {
        int64_t amount = limit;
        for (size_t e : path_edges) amount = std::min(amount, edges_[e].capacity);
        for (size_t e : path_edges) {
          edges_[e].capacity -= amount;
          edges_[e ^ 1].capacity += amount;
        }
        return amount;
      }
      bool advanced = false;
      for (size_t& i = next_[node]; i < adjacency_[node].size(); ++i) {
        size_t e = adjacency_[node][i];
        if (edges_[e].capacity > 0 && level_[edges_[e].to] == level_[node] + 1) {
          path_edges.push_back(e);
          node = edges_[e].to;
          advanced = true;
          break;
        }
      }
      if (advanced) continue;
      if (node == source) return 0;
      level_[node] = -1;  // dead end: never visit again in this phase
      size_t back = path_edges.back();
      path_edges.pop_back();
      node = edges_[back ^ 1].to;
      ++next_[node];
    }
  }

  std::vector<Edge> edges_;
  std::vector<std::vector<size_t>> adjacency_;
  std::vector<int> level_;
  std::vector<size_t> next_;
};

int64_t saving(const StorageTile& tile) {
  if (!tile.eligible || tile.procedural_bytes >= tile.baked_bytes) return 0;
  return int64_t(tile.baked_bytes - tile.procedural_bytes);
}

}  // namespace

uint64_t storageCost(const StorageProblem& problem, const std::vector<bool>& procedural) {
  uint64_t total = 0;
  std::vector<bool> used(problem.resource_bytes.size(), false);
  for (size_t t = 0; t < problem.tiles.size(); ++t) {
    const StorageTile& tile = problem.tiles[t];
    if (procedural[t]) {
      total += tile.procedural_bytes;
      for (uint32_t r : tile.resources) used[r] = true;
    } else {
      total += tile.baked_bytes;
    }
  }
  for (size_t r = 0; r < used.size(); ++r)
    if (used[r]) total += problem.resource_bytes[r];
  return total;
}

StorageChoice chooseStorage(const StorageProblem& problem) {
  // Tiles that need the same resources stand or fall together: one node per distinct set.
  std::map<std::vector<uint32_t>, size_t> group_of;
  std::vector<int64_t> group_saving;
  std::vector<const std::vector<uint32_t>*> group_resources;
  for (const StorageTile& tile : problem.tiles) {
    int64_t s = saving(tile);
    if (s == 0) continue;
    auto [it, added] = group_of.emplace(tile.resources, group_saving.size());
    if (added) {
      group_saving.push_back(0);
      group_resources.push_back(&it->first);
    }
    group_saving[it->second] += s;
  }
  const size_t groups = group_saving.size(), resources = problem.resource_bytes.size();
  const size_t source = groups + resources, sink = source + 1;
  MaxFlow flow(sink + 1);
  constexpr int64_t kInfinite = std::numeric_limits<int64_t>::max() / 4;
  for (size_t g = 0; g < groups; ++g) {
    flow.addEdge(source, g, group_saving[g]);
    for (uint32_t r : *group_resources[g]) flow.addEdge(g, groups + r, kInfinite);
  }
  for (size_t r = 0; r < resources; ++r)
    flow.addEdge(groups + r, sink, int64_t(problem.resource_bytes[r]));
  flow.run(source, sink);
  const std::vector<bool> chosen = flow.sourceSide(source);

  StorageChoice choice;
  choice.procedural.assign(problem.tiles.size(), false);
  for (size_t t = 0; t < problem.tiles.size(); ++t) {
    const StorageTile& tile = problem.tiles[t];
    if (saving(tile) == 0) continue;
    choice.procedural[t] = chosen[group_of.at(tile.resources)];
  }
  choice.resource_stored.assign(resources, false);
  for (size_t t = 0; t < problem.tiles.size(); ++t)
    if (choice.procedural[t])
      for (uint32_t r : problem.tiles[t].resources) choice.resource_stored[r] = true;
  choice.total_bytes = storageCost(problem, choice.procedural);
  return choice;
}

}  // namespace tessera::detail
