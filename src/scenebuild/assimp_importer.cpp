// OBJ, COLLADA, AC3D (and whatever else Assimp reads) through Assimp.
#include <algorithm>
#include <cmath>
#include <filesystem>

#include <assimp/Importer.hpp>
#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <fmt/format.h>

#include "assimp_model.h"
#include "importers.h"

namespace tessera::detail {

namespace {

// Assimp's texture types for each of our slots, first match wins.
const std::vector<aiTextureType> kSlotTypes[kSceneTextureSlots] = {
    {aiTextureType_BASE_COLOR, aiTextureType_DIFFUSE},
    {aiTextureType_METALNESS, aiTextureType_DIFFUSE_ROUGHNESS},
    {aiTextureType_NORMALS, aiTextureType_NORMAL_CAMERA},
    {aiTextureType_AMBIENT_OCCLUSION, aiTextureType_LIGHTMAP},
    {aiTextureType_EMISSIVE, aiTextureType_EMISSION_COLOR}};

struct ModelContext {
  const aiScene& ai;
  const std::string& path;
  ImportedScene& scene;
  TextureIndex& textures;
  uint32_t first_mesh = 0;  ///< scene index of the model's mesh 0
  std::vector<bool> mesh_kept;
  std::vector<std::array<uint32_t, kSceneTextureSlots>> material_slots;
  std::vector<uint32_t> material_colour;
};

Result<uint32_t> textureFor(ModelContext& ctx, const std::string& reference, uint32_t material) {
  const std::string what = fmt::format("{}: material {}", ctx.path, material);
  if (const aiTexture* embedded = ctx.ai.GetEmbeddedTexture(reference.c_str())) {
    if (embedded->mHeight != 0)
      return fail(ErrorCode::kUnsupported,
                  fmt::format("{}: embedded texture {} is uncompressed texels; PNG and JPEG are "
                              "supported",
                              what, reference));
    TextureSource t;
    t.name = fmt::format("{}#{}", std::filesystem::path(ctx.path).filename().string(), reference);
    const auto* bytes = reinterpret_cast<const uint8_t*>(embedded->pcData);
    t.bytes.assign(bytes, bytes + embedded->mWidth);
    t.mime_type = embedded->achFormatHint;
    ctx.scene.textures.push_back(std::move(t));
    return uint32_t(ctx.scene.textures.size() - 1);
  }
  std::string relative = reference;
  std::replace(relative.begin(), relative.end(), '\\', '/');
  const std::filesystem::path resolved =
      (std::filesystem::path(ctx.path).parent_path() / relative).lexically_normal();
  const std::string key = resolved.string();
  if (auto it = ctx.textures.find(key); it != ctx.textures.end()) return it->second;
  TextureSource t;
  t.name = relative;
  t.path = key;
  ctx.scene.textures.push_back(std::move(t));
  const uint32_t index = uint32_t(ctx.scene.textures.size() - 1);
  ctx.textures.emplace(key, index);
  return index;
}

Result<void> loadMaterials(ModelContext& ctx) {
  for (uint32_t m = 0; m < ctx.ai.mNumMaterials; ++m) {
    const aiMaterial* material = ctx.ai.mMaterials[m];
    std::array<uint32_t, kSceneTextureSlots> slots;
    slots.fill(kNoSceneTexture);
    for (uint32_t s = 0; s < kSceneTextureSlots; ++s) {
      for (aiTextureType type : kSlotTypes[s]) {
        aiString reference;
        if (material->GetTexture(type, 0, &reference) != AI_SUCCESS || reference.length == 0)
          continue;
        TESSERA_ASSIGN_OR_RETURN(slots[s], textureFor(ctx, reference.C_Str(), m));
        break;
      }
    }
    aiColor4D diffuse(1, 1, 1, 1);
    material->Get(AI_MATKEY_COLOR_DIFFUSE, diffuse);
    uint32_t rgba = 0;
    const float channels[4] = {diffuse.r, diffuse.g, diffuse.b, diffuse.a};
    for (int c = 0; c < 4; ++c) {
      const float v = std::isfinite(channels[c]) ? std::clamp(channels[c], 0.0f, 1.0f) : 1.0f;
      rgba |= uint32_t(std::lround(v * 255)) << (8 * c);
    }
    ctx.material_slots.push_back(slots);
    ctx.material_colour.push_back(rgba);
  }
  return {};
}

void loadMeshes(ModelContext& ctx) {
  ctx.first_mesh = uint32_t(ctx.scene.meshes.size());
  for (uint32_t m = 0; m < ctx.ai.mNumMeshes; ++m) {
    const aiMesh* mesh = ctx.ai.mMeshes[m];
    ImportedMesh out;
    out.name = mesh->mName.C_Str();
    for (uint32_t v = 0; v < mesh->mNumVertices; ++v) {
      const aiVector3D& p = mesh->mVertices[v];
      out.positions.insert(out.positions.end(), {p.x, p.y, p.z});
      if (mesh->mNormals) {
        const aiVector3D& n = mesh->mNormals[v];
        out.normals.insert(out.normals.end(), {n.x, n.y, n.z});
      }
      if (mesh->mTextureCoords[0]) {
        const aiVector3D& t = mesh->mTextureCoords[0][v];
        out.uv0.insert(out.uv0.end(), {t.x, t.y});
      }
    }
    for (uint32_t f = 0; f < mesh->mNumFaces; ++f) {
      const aiFace& face = mesh->mFaces[f];
      if (face.mNumIndices == 3)
        out.indices.insert(out.indices.end(), face.mIndices, face.mIndices + 3);
    }
    // A mesh of points or lines has no triangles: kept as a placeholder, never instanced.
    ctx.mesh_kept.push_back(!out.indices.empty());
    ctx.scene.meshes.push_back(std::move(out));
  }
}

std::array<float, 12> toTransform(const aiMatrix4x4& m) {
  return {m.a1, m.a2, m.a3, m.a4, m.b1, m.b2, m.b3, m.b4, m.c1, m.c2, m.c3, m.c4};
}

Result<void> walkNodes(ModelContext& ctx, ModelTemplate& out) {
  struct Frame {
    const aiNode* node;
    std::array<float, 12> parent;
    uint32_t depth;
  };
  std::vector<Frame> stack{{ctx.ai.mRootNode, {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0}, 0}};
  while (!stack.empty()) {
    Frame f = stack.back();
    stack.pop_back();
    if (f.depth >= kMaxNodeGraphDepth)
      return fail(ErrorCode::kTooLarge, fmt::format("{}: node {} is nested over {} deep", ctx.path,
                                                    f.node->mName.C_Str(), kMaxNodeGraphDepth));
    const auto world = composeTransforms(f.parent, toTransform(f.node->mTransformation));
    for (uint32_t k = 0; k < f.node->mNumMeshes; ++k) {
      const uint32_t mesh = f.node->mMeshes[k];
      if (mesh >= ctx.ai.mNumMeshes || !ctx.mesh_kept[mesh]) continue;
      const uint32_t material = ctx.ai.mMeshes[mesh]->mMaterialIndex;
      ImportedObject object;
      object.mesh = ctx.first_mesh + mesh;
      object.transform = world;
      if (material < ctx.material_slots.size()) {
        object.textures = ctx.material_slots[material];
        object.base_color_rgba = ctx.material_colour[material];
      }
      if (out.objects.size() >= kMaxImportedObjects)
        return fail(ErrorCode::kTooLarge, ctx.path + ": too many object instances");
      out.objects.push_back(object);
    }
    for (uint32_t c = f.node->mNumChildren; c-- > 0;)
      stack.push_back({f.node->mChildren[c], world, f.depth + 1});
  }
  return {};
}

}  // namespace

Result<ModelTemplate> loadAssimpModel(const std::string& path, ImportedScene& scene,
                                      TextureIndex& textures) {
  TESSERA_TRY(requireRegularFile(path));
  Assimp::Importer importer;
  importer.SetPropertyInteger(AI_CONFIG_PP_SBP_REMOVE,
                              aiPrimitiveType_POINT | aiPrimitiveType_LINE);
  const aiScene* ai =
      importer.ReadFile(path, aiProcess_Triangulate | aiProcess_JoinIdenticalVertices |
                                  aiProcess_SortByPType | aiProcess_ValidateDataStructure);
  if (ai == nullptr || ai->mRootNode == nullptr || (ai->mFlags & AI_SCENE_FLAGS_INCOMPLETE))
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: Assimp cannot read it: {}", path, importer.GetErrorString()));
  ModelContext ctx{*ai, path, scene, textures};
  TESSERA_TRY(loadMaterials(ctx));
  loadMeshes(ctx);
  ModelTemplate out;
  TESSERA_TRY(walkNodes(ctx, out));
  return out;
}

Result<ImportedScene> importAssimp(const std::string& path) {
  ImportedScene scene;
  scene.source = path;
  scene.importer = "assimp";
  TextureIndex textures;
  TESSERA_ASSIGN_OR_RETURN(ModelTemplate model, loadAssimpModel(path, scene, textures));
  scene.objects = std::move(model.objects);
  return scene;
}

}  // namespace tessera::detail
