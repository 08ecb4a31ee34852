#pragma once
// Scene importers: each turns one input into an ImportedScene, naming the file and the item in
// every error (docs/scenes.md, "Importers"). Owned by the calling thread.

#include <cstdint>
#include <string>
#include <vector>

#include <tessera/result.h>

#include "scene_model.h"

namespace tessera::detail {

/// Node graphs deeper than this are refused: real scenes nest a few dozen levels, and a
/// bound turns a hostile chain into an error instead of a stack of millions.
inline constexpr uint32_t kMaxNodeGraphDepth = 256;
/// Object instances an importer may create (a DAG can multiply them).
inline constexpr uint64_t kMaxImportedObjects = uint64_t(1) << 26;

/// Fails naming `path` unless it is an existing regular file: a FIFO or device would block
/// or never end the read that follows.
[[nodiscard]] Result<void> requireRegularFile(const std::string& path);

/// glTF 2.0, .gltf (external or data-URI buffers and images) or .glb, through tinygltf.
[[nodiscard]] Result<ImportedScene> importGltf(const std::string& path);
/// OBJ, COLLADA, AC3D and the other formats Assimp reads.
[[nodiscard]] Result<ImportedScene> importAssimp(const std::string& path);
/// A FlightGear placement list: OBJECT_SHARED and OBJECT_STATIC lines placing .ac models (read
/// through Assimp, each once) at longitude, latitude, elevation and heading.
[[nodiscard]] Result<ImportedScene> importStg(const std::string& path);
/// "synthetic-scene:N_OBJECTS:N_TEXTURES[:seed]" (the part after the prefix in `spec`):
/// a deterministic city of boxes and towers; textures are crops of `sources` (image files),
/// or of the project's synthetic terrain images when `sources` is empty.
[[nodiscard]] Result<ImportedScene> generateSyntheticScene(const std::string& spec,
                                                           const std::vector<std::string>& sources);

/// The texture's file path when it has one, else the embedded bytes written to a temporary
/// file under `temp_dir` (removed by the caller); fails naming the texture for a missing file
/// or an image format other than PNG and JPEG.
[[nodiscard]] Result<std::string> textureFile(const TextureSource& texture,
                                              const std::string& scene_name,
                                              const std::string& temp_dir, uint32_t index);

}  // namespace tessera::detail
