#pragma once
/// \file
/// Building scene archives (docs/scenes.md): a glTF 2.0 file (.gltf, .glb), a file Assimp
/// reads (OBJ, COLLADA, AC3D), a FlightGear placement list (.stg) or the deterministic
/// generator "synthetic-scene:N_OBJECTS:N_TEXTURES[:seed]" becomes one archive: an R-tree over
/// the objects (Zhou, Zhu & Zhang, seed 004), each texture an ordinary pyramid stored once at
/// the lowest common ancestor of its users, geometry beside it, and every subtree one
/// contiguous byte range.

#include <atomic>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <tessera/format.h>
#include <tessera/result.h>
#include <tessera/scene.h>

namespace tessera {

/// Everything `tessera build` sets for a scene. Defaults are the CLI's.
struct SceneBuildOptions {
  std::string input;   ///< a scene file or "synthetic-scene:N_OBJECTS:N_TEXTURES[:seed]"
  std::string output;  ///< the archive path; written atomically
  /// Images the generator cuts its textures from (PNG, JPEG, TIFF); empty: the project's
  /// synthetic terrain images. Ignored for scene files.
  std::vector<std::string> texture_sources;
  uint32_t tile_size_px = 128;  ///< power of two, 64..2048
  Codec codec = Codec::kJpeg;   ///< any codec but ptm
  int quality = 85;
  int effort = 0;
  GeometryCodec geometry_codec = GeometryCodec::kMeshopt;
  uint32_t leaf_capacity = 16;  ///< objects per R-tree leaf, 1..65535
  uint32_t max_children = 8;    ///< R-tree fan-out, 2..256
  uint32_t threads = 0;         ///< texture encoders; 0 = all cores
  /// Largest texture side accepted; larger textures are refused (kTooLarge) naming the file.
  uint32_t max_texture_side_px = 16384;
  /// Average coverage hints (Marvie & Bouatouch, seed 003 part II; docs/scenes.md, "Coverage
  /// hints"): computed and stored when true. Off by default: they cost 3 to 17 times the
  /// rest of the build in CPU time (docs/scenes.md has the figures).
  bool coverage_hints = false;
  double hint_cell_size = 0;         ///< world units; 0: the longer ground side / 16
  uint32_t hint_resolution_px = 64;  ///< per cube face, 1..4096
};

/// Progress, from the building thread.
struct SceneBuildProgress {
  uint64_t textures_done = 0;
  uint64_t textures_total = 0;
  double elapsed_s = 0;
};

/// How promotion of shared textures went (seed 004, Table 4).
struct PromotionStats {
  uint64_t texture_references = 0;  ///< (object, slot) pairs naming a texture
  uint64_t leaf_copies = 0;         ///< distinct (leaf, texture) pairs: copies without promotion
  uint64_t stored = 0;              ///< textures stored, each once
  uint64_t copies_avoided = 0;      ///< leaf_copies - stored
  uint64_t shared = 0;              ///< textures used by objects in more than one leaf
  std::vector<uint64_t> stored_at_depth;  ///< textures stored per tree depth (0 = root)
};

/// What a finished scene build reports.
struct SceneBuildReport {
  SceneSummary summary;
  PromotionStats promotion;
  uint64_t output_bytes = 0;
  uint64_t texture_payload_bytes = 0;
  uint64_t geometry_raw_bytes = 0;     ///< vertex and index buffers before coding
  uint64_t geometry_stored_bytes = 0;  ///< as stored with the chosen codec
  uint64_t tiles_encoded = 0;
  std::string importer;  ///< "gltf", "assimp", "stg", "synthetic"
  double elapsed_s = 0;
  /// Coverage hints: cells, (cell, texture) entries, bytes stored, seconds spent (all 0
  /// without hints).
  uint64_t hint_cells = 0;
  uint64_t hint_entries = 0;
  uint64_t hint_bytes = 0;
  double hint_seconds = 0;
};

/// Builds a scene archive. On failure or cancel nothing is left at `options.output` (a file
/// already there is untouched). Errors name the input file and the item: a missing or
/// unsupported texture, a texture index out of range, a cyclic or too deep node graph,
/// non-finite vertices, indices out of range or beyond 2^28 per mesh, a truncated .glb.
/// Blocking; owned by the caller's thread.
[[nodiscard]] Result<SceneBuildReport> buildScene(
    const SceneBuildOptions& options,
    const std::function<void(const SceneBuildProgress&)>& on_progress = {},
    const std::atomic<bool>* cancel = nullptr);

/// True when `input` names something buildScene reads rather than an image: a .gltf, .glb,
/// .obj, .dae, .ac or .stg path (by extension) or "synthetic-scene:...".
bool isSceneInput(const std::string& input);

}  // namespace tessera
