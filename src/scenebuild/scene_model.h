#pragma once
// A scene as the importers and the generator hand it to the builder: meshes in their own
// space, objects placing them, textures by source. Plain data, owned by one thread.

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "format/scene.h"

namespace tessera::detail {

/// A triangle list. positions 3 floats per vertex; normals 3 and uv0 2 per vertex or empty.
struct ImportedMesh {
  std::string name;  ///< for messages: "mesh 3 (Wall)"
  std::vector<float> positions;
  std::vector<float> normals;
  std::vector<float> uv0;
  std::vector<uint32_t> indices;
  SceneBox bounds;  ///< of the positions; set by validateScene
  uint32_t vertexCount() const { return uint32_t(positions.size() / 3); }
};

/// Where a texture's texels come from: a file, bytes embedded in the scene file, or a crop of
/// one of the generator's source images.
struct TextureSource {
  std::string name;            ///< for messages and metadata: "image 2 (bricks.png)"
  std::string path;            ///< a file to read, or empty
  std::vector<uint8_t> bytes;  ///< embedded bytes (a .glb buffer view, a data URI), or empty
  std::string mime_type;       ///< of the embedded bytes, as the scene file declares it
  /// Generator crops: source image index (>= 0) and the rectangle in it.
  int32_t crop_source = -1;
  uint32_t crop_x = 0, crop_y = 0, crop_width = 0, crop_height = 0;
};

/// One drawn object.
struct ImportedObject {
  uint32_t mesh = 0;
  std::array<float, 12> transform{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
  std::array<uint32_t, kSceneTextureSlots> textures{
      kNoSceneTexture, kNoSceneTexture, kNoSceneTexture, kNoSceneTexture, kNoSceneTexture};
  uint32_t base_color_rgba = 0xFFFFFFFFu;
  SceneBox bounds;  ///< world space; set by validateScene
};

struct ImportedScene {
  std::string source;    ///< the input as given
  std::string importer;  ///< "gltf", "assimp", "stg", "synthetic"
  std::vector<ImportedMesh> meshes;
  std::vector<ImportedObject> objects;
  std::vector<TextureSource> textures;
  /// The generator's source images (paths, or "synthetic:WxH:seed" specs).
  std::vector<std::string> crop_sources;
};

/// Checks what the importers cannot check alone and fills the bounds: every vertex finite,
/// every index below its mesh's vertex count, index and vertex counts within the format's
/// bounds, every object's mesh and texture indices in range, finite transforms. Errors name
/// `scene.source` and the item.
[[nodiscard]] Result<void> validateScene(ImportedScene& scene);

/// Multiplies row-major 3x4 affine transforms: a * b.
std::array<float, 12> composeTransforms(const std::array<float, 12>& a,
                                        const std::array<float, 12>& b);

}  // namespace tessera::detail
