#include "scene_model.h"

#include <cmath>
#include <limits>

#include <fmt/format.h>

namespace tessera::detail {

namespace {

Result<void> validateMesh(ImportedMesh& mesh, const std::string& what) {
  const size_t vertices = mesh.positions.size() / 3;
  if (mesh.positions.size() % 3 != 0 || vertices == 0)
    return fail(ErrorCode::kCorrupt, what + ": no vertices");
  if (vertices > kMaxMeshVertices)
    return fail(ErrorCode::kTooLarge, fmt::format("{}: {} vertices exceed the {} per mesh", what,
                                                  vertices, kMaxMeshVertices));
  if (mesh.indices.size() > kMaxMeshIndices)
    return fail(ErrorCode::kTooLarge, fmt::format("{}: {} indices exceed the {} per mesh", what,
                                                  mesh.indices.size(), kMaxMeshIndices));
  if (mesh.indices.empty() || mesh.indices.size() % 3 != 0)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: {} indices is not a triangle list", what, mesh.indices.size()));
  if ((!mesh.normals.empty() && mesh.normals.size() != vertices * 3) ||
      (!mesh.uv0.empty() && mesh.uv0.size() != vertices * 2))
    return fail(ErrorCode::kCorrupt, what + ": attribute counts differ from the vertex count");
  SceneBox box;
  box.min.fill(std::numeric_limits<float>::max());
  box.max.fill(std::numeric_limits<float>::lowest());
  for (size_t v = 0; v < vertices; ++v) {
    for (int a = 0; a < 3; ++a) {
      const float x = mesh.positions[3 * v + a];
      if (!std::isfinite(x))
        return fail(ErrorCode::kCorrupt,
                    fmt::format("{}: vertex {} has a non-finite position", what, v));
      box.min[a] = std::min(box.min[a], x);
      box.max[a] = std::max(box.max[a], x);
    }
  }
  for (float x : mesh.normals)
    if (!std::isfinite(x)) return fail(ErrorCode::kCorrupt, what + ": non-finite normal");
  for (float x : mesh.uv0)
    if (!std::isfinite(x)) return fail(ErrorCode::kCorrupt, what + ": non-finite uv");
  for (size_t i = 0; i < mesh.indices.size(); ++i)
    if (mesh.indices[i] >= vertices)
      return fail(ErrorCode::kCorrupt, fmt::format("{}: index {} is {}, past its {} vertices", what,
                                                   i, mesh.indices[i], vertices));
  mesh.bounds = box;
  return {};
}

}  // namespace

Result<void> validateScene(ImportedScene& scene) {
  if (scene.objects.empty())
    return fail(ErrorCode::kInvalidArgument, scene.source + ": the scene has no objects");
  if (scene.objects.size() > kMaxSceneObjects)
    return fail(ErrorCode::kTooLarge, fmt::format("{}: {} objects exceed {}", scene.source,
                                                  scene.objects.size(), kMaxSceneObjects));
  if (scene.textures.size() > kMaxImages)
    return fail(ErrorCode::kTooLarge, fmt::format("{}: {} textures exceed {}", scene.source,
                                                  scene.textures.size(), kMaxImages));
  for (size_t m = 0; m < scene.meshes.size(); ++m) {
    ImportedMesh& mesh = scene.meshes[m];
    std::string what = mesh.name.empty()
                           ? fmt::format("{}: mesh {}", scene.source, m)
                           : fmt::format("{}: mesh {} ({})", scene.source, m, mesh.name);
    TESSERA_TRY(validateMesh(mesh, what));
  }
  for (size_t o = 0; o < scene.objects.size(); ++o) {
    ImportedObject& object = scene.objects[o];
    const std::string what = fmt::format("{}: object {}", scene.source, o);
    if (object.mesh >= scene.meshes.size())
      return fail(ErrorCode::kCorrupt, fmt::format("{}: mesh {} out of range (the scene has {})",
                                                   what, object.mesh, scene.meshes.size()));
    for (uint32_t s = 0; s < kSceneTextureSlots; ++s) {
      uint32_t t = object.textures[s];
      if (t != kNoSceneTexture && t >= scene.textures.size())
        return fail(ErrorCode::kCorrupt,
                    fmt::format("{}: texture {} out of range (the scene has {})", what, t,
                                scene.textures.size()));
    }
    for (float x : object.transform)
      if (!std::isfinite(x)) return fail(ErrorCode::kCorrupt, what + ": non-finite transform");
    object.bounds = transformBox(scene.meshes[object.mesh].bounds, object.transform);
    for (int a = 0; a < 3; ++a)
      if (!std::isfinite(object.bounds.min[a]) || !std::isfinite(object.bounds.max[a]))
        return fail(ErrorCode::kCorrupt, what + ": bounds overflow a float");
  }
  return {};
}

std::array<float, 12> composeTransforms(const std::array<float, 12>& a,
                                        const std::array<float, 12>& b) {
  std::array<float, 12> out{};
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 4; ++c) {
      float v = c == 3 ? a[4 * r + 3] : 0.0f;
      for (int k = 0; k < 3; ++k) v += a[4 * r + k] * b[4 * k + c];
      out[4 * r + c] = v;
    }
  }
  return out;
}

}  // namespace tessera::detail
