#pragma once
// Loading one model file through Assimp into a scene being assembled: shared by the Assimp
// importer (one file is the scene) and the .stg importer (many placements of many models).

#include <map>
#include <string>
#include <vector>

#include <tessera/result.h>

#include "scene_model.h"

namespace tessera::detail {

/// A model's objects in the model's own space, its meshes and textures already appended to
/// the scene.
struct ModelTemplate {
  std::vector<ImportedObject> objects;
};

/// Textures already in the scene, by resolved file path: the same file is one texture however
/// many models use it (texture sharing kept across models).
using TextureIndex = std::map<std::string, uint32_t>;

/// Reads `path` with Assimp (triangulated, identical vertices joined, points and lines
/// dropped), appends its meshes and textures to `scene` and returns its objects.
[[nodiscard]] Result<ModelTemplate> loadAssimpModel(const std::string& path, ImportedScene& scene,
                                                    TextureIndex& textures);

}  // namespace tessera::detail
