#pragma once
// The layout pass of a scene build (docs/format.md, "Scenes"): the coarse block, then every
// node's block in depth-first pre-order (head, directory pages, geometry, texture payloads
// coarse to fine), so each subtree is one byte range; then the tables, the 1.0 page indexes,
// root directory and metadata (in the header region while they fit); the header last.

#include <cstdint>
#include <vector>

#include <nlohmann/json.hpp>

#include <tessera/coverage_hints.h>
#include <tessera/result.h>

#include "format/scene.h"
#include "output/output_file.h"
#include "scene_model.h"
#include "scene_tree.h"
#include "texture_spool.h"

namespace tessera::detail {

/// A scene ready to lay out: every item numbered in the pre-order of the node holding it.
struct SceneLayoutInput {
  const ImportedScene* scene = nullptr;
  const SceneTree* tree = nullptr;
  std::vector<uint32_t> object_order;    ///< final object -> imported object
  std::vector<uint32_t> mesh_order;      ///< final mesh -> imported mesh
  std::vector<uint32_t> mesh_node;       ///< final mesh -> holding node
  std::vector<uint32_t> texture_order;   ///< final texture -> imported texture
  std::vector<uint32_t> texture_node;    ///< final texture -> holding node
  std::vector<uint32_t> texture_users;   ///< final texture -> objects using it
  std::vector<SpooledTexture> textures;  ///< final texture -> its encoded pyramid (spool offsets)
  const TempFile* spool = nullptr;
  uint64_t spool_bytes = 0;
  GeometryCodecId geometry_codec = GeometryCodecId::kMeshopt;
  uint32_t leaf_capacity = 16;
  uint32_t max_children = 8;
  nlohmann::json metadata;
  /// Average coverage hints in the final texture numbering, or null for none.
  const CoverageHints* hints = nullptr;
};

struct SceneLayoutResult {
  uint64_t file_bytes = 0;
  uint64_t texture_payload_bytes = 0;
  uint64_t coarse_bytes = 0;
  uint64_t geometry_raw_bytes = 0;
  uint64_t geometry_stored_bytes = 0;
  uint64_t hint_bytes = 0;  ///< the coverage hints block; 0 without
};

/// Writes the archive into `out` (not committed). Errors name the output file.
[[nodiscard]] Result<SceneLayoutResult> writeSceneArchive(const SceneLayoutInput& input,
                                                          const TempFile& out);

}  // namespace tessera::detail
