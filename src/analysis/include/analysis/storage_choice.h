#pragma once
// Baked or procedural, per tile, at the least total storage (Demeulemeester et al., section
// 2.3: "search for an optimal selection of procedural tiles to minimise the storage size"). A
// procedural tile needs every brush it draws stored once in the archive; the choice is a
// maximum-weight closure (Picard, 1976): groups of tiles that need the same brushes save
// bytes, brushes cost bytes, and a minimum cut finds the exact optimum.

#include <cstdint>
#include <vector>

namespace tessera::detail {

/// One tile's two costs and what being procedural needs.
struct StorageTile {
  uint64_t baked_bytes = 0;         ///< payload if stored as texels (0 for uniform and empty)
  uint64_t procedural_bytes = 0;    ///< its instance page
  bool eligible = false;            ///< within the time budget and the page bounds
  std::vector<uint32_t> resources;  ///< sorted ids of the brushes (and layer) it needs
};

struct StorageProblem {
  std::vector<StorageTile> tiles;
  std::vector<uint64_t> resource_bytes;  ///< stored size of each resource, indexed by id
};

struct StorageChoice {
  std::vector<bool> procedural;       ///< per tile
  std::vector<bool> resource_stored;  ///< per resource: needed by some procedural tile
  uint64_t total_bytes = 0;           ///< tiles' chosen costs plus stored resources
};

/// The exact minimum of total storage. Deterministic. O(max-flow) on one node per distinct
/// resource set, so millions of tiles cost little beyond grouping them.
StorageChoice chooseStorage(const StorageProblem& problem);

/// Total bytes of a given assignment: each tile's chosen cost, plus every resource that some
/// procedural tile needs (counted once).
uint64_t storageCost(const StorageProblem& problem, const std::vector<bool>& procedural);

}  // namespace tessera::detail
