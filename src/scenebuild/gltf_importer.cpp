// glTF 2.0 through tinygltf: meshes, the node graph's transforms, materials' texture slots and
// images as texture sources (decoded later by the builder's readers, not by tinygltf).
#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>

#include <fmt/format.h>
#include <tiny_gltf.h>

#include "importers.h"

namespace tessera::detail {

namespace {

// Keeps embedded image bytes as they are; external images are read later from their path.
bool keepImageBytes(tinygltf::Image* image, const int, std::string*, std::string*, int, int,
                    const unsigned char* bytes, int size, void*) {
  const bool external = !image->uri.empty() && image->uri.rfind("data:", 0) != 0;
  if (!external && size > 0) image->image.assign(bytes, bytes + size);
  image->as_is = true;
  return true;
}

// Percent-decoding of a URI path (glTF URIs are RFC 3986).
std::string decodeUri(const std::string& uri) {
  std::string out;
  for (size_t i = 0; i < uri.size(); ++i) {
    if (uri[i] == '%' && i + 2 < uri.size() && std::isxdigit(uint8_t(uri[i + 1])) &&
        std::isxdigit(uint8_t(uri[i + 2]))) {
      out.push_back(char(std::stoi(uri.substr(i + 1, 2), nullptr, 16)));
      i += 2;
    } else {
      out.push_back(uri[i]);
    }
  }
  return out;
}

struct GltfContext {
  const tinygltf::Model& model;
  std::string name;  ///< the file, for messages
  ImportedScene& scene;
  /// Per glTF mesh: the imported meshes of its triangle primitives and their materials.
  std::vector<std::vector<std::pair<uint32_t, int>>> primitives;
};

// Reads accessor element `i` component `c` as float (normalized integers scaled).
Result<std::vector<float>> readFloats(const GltfContext& ctx, int accessor_index, int components,
                                      const std::string& what) {
  const auto& model = ctx.model;
  if (accessor_index < 0 || size_t(accessor_index) >= model.accessors.size())
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: accessor {} out of range", what, accessor_index));
  const tinygltf::Accessor& a = model.accessors[accessor_index];
  if (a.bufferView < 0 || size_t(a.bufferView) >= model.bufferViews.size())
    return fail(ErrorCode::kCorrupt, what + ": accessor without a valid buffer view");
  if (tinygltf::GetNumComponentsInType(a.type) != components)
    return fail(ErrorCode::kUnsupported,
                fmt::format("{}: {} components, expected {}", what,
                            tinygltf::GetNumComponentsInType(a.type), components));
  const int component_bytes = tinygltf::GetComponentSizeInBytes(a.componentType);
  if (component_bytes <= 0 || (a.componentType != TINYGLTF_COMPONENT_TYPE_FLOAT && !a.normalized))
    return fail(ErrorCode::kUnsupported, what + ": not float or normalized integer data");
  if (a.count > kMaxMeshVertices)
    return fail(ErrorCode::kTooLarge,
                fmt::format("{}: {} elements exceed {}", what, a.count, kMaxMeshVertices));
  const tinygltf::BufferView& view = model.bufferViews[a.bufferView];
  if (view.buffer < 0 || size_t(view.buffer) >= model.buffers.size())
    return fail(ErrorCode::kCorrupt, what + ": buffer view without a valid buffer");
  const std::vector<unsigned char>& buffer = model.buffers[view.buffer].data;
  const size_t element = size_t(component_bytes) * components;
  const size_t stride = view.byteStride ? view.byteStride : element;
  const uint64_t begin = uint64_t(view.byteOffset) + a.byteOffset;
  const uint64_t need = a.count == 0 ? 0 : (uint64_t(a.count) - 1) * stride + element;
  if (view.byteOffset + view.byteLength > buffer.size() || a.byteOffset + need > view.byteLength)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: accessor {} reads past its buffer of {} bytes", what,
                            accessor_index, buffer.size()));
  std::vector<float> out(size_t(a.count) * components);
  for (size_t i = 0; i < a.count; ++i) {
    const unsigned char* p = buffer.data() + begin + i * stride;
    for (int c = 0; c < components; ++c) {
      const unsigned char* q = p + c * component_bytes;
      float v = 0;
      switch (a.componentType) {
        case TINYGLTF_COMPONENT_TYPE_FLOAT: std::memcpy(&v, q, 4); break;
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: v = q[0] / 255.0f; break;
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
          v = uint16_t(q[0] | q[1] << 8) / 65535.0f;
          break;
        case TINYGLTF_COMPONENT_TYPE_BYTE: v = std::max(int8_t(q[0]) / 127.0f, -1.0f); break;
        case TINYGLTF_COMPONENT_TYPE_SHORT:
          v = std::max(int16_t(q[0] | q[1] << 8) / 32767.0f, -1.0f);
          break;
        default: return fail(ErrorCode::kUnsupported, what + ": unsupported component type");
      }
      out[i * components + c] = v;
    }
  }
  return out;
}

Result<std::vector<uint32_t>> readIndices(const GltfContext& ctx, int accessor_index,
                                          const std::string& what) {
  const auto& model = ctx.model;
  if (accessor_index < 0 || size_t(accessor_index) >= model.accessors.size())
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: index accessor {} out of range", what, accessor_index));
  const tinygltf::Accessor& a = model.accessors[accessor_index];
  // Bounded before anything is allocated: a hostile count of 2^31 is an error, not 8 GiB.
  if (a.count > kMaxMeshIndices)
    return fail(ErrorCode::kTooLarge, fmt::format("{}: {} indices exceed the {} per mesh", what,
                                                  a.count, kMaxMeshIndices));
  if (a.bufferView < 0 || size_t(a.bufferView) >= model.bufferViews.size())
    return fail(ErrorCode::kCorrupt, what + ": index accessor without a valid buffer view");
  const int bytes = tinygltf::GetComponentSizeInBytes(a.componentType);
  if (a.type != TINYGLTF_TYPE_SCALAR || (bytes != 1 && bytes != 2 && bytes != 4) ||
      a.componentType == TINYGLTF_COMPONENT_TYPE_FLOAT)
    return fail(ErrorCode::kCorrupt, what + ": indices are not unsigned scalars");
  const tinygltf::BufferView& view = model.bufferViews[a.bufferView];
  if (view.buffer < 0 || size_t(view.buffer) >= model.buffers.size())
    return fail(ErrorCode::kCorrupt, what + ": buffer view without a valid buffer");
  const std::vector<unsigned char>& buffer = model.buffers[view.buffer].data;
  const size_t stride = view.byteStride ? view.byteStride : size_t(bytes);
  const uint64_t need = a.count == 0 ? 0 : (uint64_t(a.count) - 1) * stride + bytes;
  if (view.byteOffset + view.byteLength > buffer.size() || a.byteOffset + need > view.byteLength)
    return fail(ErrorCode::kCorrupt, fmt::format("{}: indices read past their buffer", what));
  std::vector<uint32_t> out(a.count);
  const unsigned char* base = buffer.data() + view.byteOffset + a.byteOffset;
  for (size_t i = 0; i < a.count; ++i) {
    const unsigned char* p = base + i * stride;
    out[i] = bytes == 1   ? p[0]
             : bytes == 2 ? uint32_t(p[0] | p[1] << 8)
                          : uint32_t(p[0] | p[1] << 8 | p[2] << 16 | p[3] << 24);
  }
  return out;
}

// Strips and fans become lists; points and lines have no surface and are skipped (nullopt).
std::vector<uint32_t> toTriangleList(int mode, const std::vector<uint32_t>& in) {
  if (mode == TINYGLTF_MODE_TRIANGLES) return in;
  std::vector<uint32_t> out;
  for (size_t i = 2; i < in.size(); ++i) {
    if (mode == TINYGLTF_MODE_TRIANGLE_STRIP) {
      if (i % 2 == 0)
        out.insert(out.end(), {in[i - 2], in[i - 1], in[i]});
      else
        out.insert(out.end(), {in[i - 1], in[i - 2], in[i]});
    } else {
      out.insert(out.end(), {in[0], in[i - 1], in[i]});
    }
  }
  return out;
}

Result<void> importMeshes(GltfContext& ctx) {
  const auto& model = ctx.model;
  ctx.primitives.resize(model.meshes.size());
  for (size_t m = 0; m < model.meshes.size(); ++m) {
    const tinygltf::Mesh& mesh = model.meshes[m];
    for (size_t p = 0; p < mesh.primitives.size(); ++p) {
      const tinygltf::Primitive& prim = mesh.primitives[p];
      const std::string what =
          fmt::format("{}: mesh {} ({}) primitive {}", ctx.name, m, mesh.name, p);
      const int mode = prim.mode < 0 ? TINYGLTF_MODE_TRIANGLES : prim.mode;
      if (mode != TINYGLTF_MODE_TRIANGLES && mode != TINYGLTF_MODE_TRIANGLE_STRIP &&
          mode != TINYGLTF_MODE_TRIANGLE_FAN)
        continue;
      auto position = prim.attributes.find("POSITION");
      if (position == prim.attributes.end())
        return fail(ErrorCode::kCorrupt, what + ": no POSITION attribute");
      ImportedMesh out;
      out.name = fmt::format("{}/{}", mesh.name, p);
      TESSERA_ASSIGN_OR_RETURN(out.positions,
                               readFloats(ctx, position->second, 3, what + " POSITION"));
      if (auto n = prim.attributes.find("NORMAL"); n != prim.attributes.end()) {
        TESSERA_ASSIGN_OR_RETURN(out.normals, readFloats(ctx, n->second, 3, what + " NORMAL"));
      }
      if (auto uv = prim.attributes.find("TEXCOORD_0"); uv != prim.attributes.end()) {
        TESSERA_ASSIGN_OR_RETURN(out.uv0, readFloats(ctx, uv->second, 2, what + " TEXCOORD_0"));
      }
      std::vector<uint32_t> indices;
      if (prim.indices >= 0) {
        TESSERA_ASSIGN_OR_RETURN(indices, readIndices(ctx, prim.indices, what));
      } else {
        indices.resize(out.positions.size() / 3);
        for (size_t i = 0; i < indices.size(); ++i) indices[i] = uint32_t(i);
      }
      out.indices = toTriangleList(mode, indices);
      if (out.indices.empty()) continue;
      ctx.primitives[m].push_back({uint32_t(ctx.scene.meshes.size()), prim.material});
      ctx.scene.meshes.push_back(std::move(out));
    }
  }
  return {};
}

// One material's slots as image indices (texture sharing is by image: two glTF textures with
// the same source are one texture here).
Result<std::array<uint32_t, kSceneTextureSlots>> materialSlots(const GltfContext& ctx, int material,
                                                               uint32_t* colour) {
  std::array<uint32_t, kSceneTextureSlots> slots;
  slots.fill(kNoSceneTexture);
  *colour = 0xFFFFFFFFu;
  if (material < 0) return slots;
  const auto& model = ctx.model;
  if (size_t(material) >= model.materials.size())
    return fail(ErrorCode::kCorrupt, fmt::format("{}: material {} out of range ({} materials)",
                                                 ctx.name, material, model.materials.size()));
  const tinygltf::Material& m = model.materials[material];
  const int textures[kSceneTextureSlots] = {m.pbrMetallicRoughness.baseColorTexture.index,
                                            m.pbrMetallicRoughness.metallicRoughnessTexture.index,
                                            m.normalTexture.index, m.occlusionTexture.index,
                                            m.emissiveTexture.index};
  const char* names[kSceneTextureSlots] = {"baseColorTexture", "metallicRoughnessTexture",
                                           "normalTexture", "occlusionTexture", "emissiveTexture"};
  for (uint32_t s = 0; s < kSceneTextureSlots; ++s) {
    const int t = textures[s];
    if (t < 0) continue;
    if (size_t(t) >= model.textures.size())
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: material {} ({}): {} refers to texture {}, out of range ({} "
                              "textures)",
                              ctx.name, material, m.name, names[s], t, model.textures.size()));
    const int source = model.textures[t].source;
    if (source < 0 || size_t(source) >= model.images.size())
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: texture {} refers to image {}, out of range ({} images)",
                              ctx.name, t, source, model.images.size()));
    slots[s] = uint32_t(source);
  }
  uint32_t rgba = 0;
  const auto& factor = m.pbrMetallicRoughness.baseColorFactor;
  for (size_t c = 0; c < 4 && c < factor.size(); ++c)
    rgba |= uint32_t(std::lround(std::clamp(factor[c], 0.0, 1.0) * 255)) << (8 * c);
  *colour = factor.size() == 4 ? rgba : 0xFFFFFFFFu;
  return slots;
}

std::array<float, 12> nodeTransform(const tinygltf::Node& node) {
  std::array<float, 12> m{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
  if (node.matrix.size() == 16) {  // column-major 4x4
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) m[4 * r + c] = float(node.matrix[4 * c + r]);
    return m;
  }
  double t[3] = {0, 0, 0}, q[4] = {0, 0, 0, 1}, s[3] = {1, 1, 1};
  for (size_t i = 0; i < 3 && i < node.translation.size(); ++i) t[i] = node.translation[i];
  for (size_t i = 0; i < 4 && i < node.rotation.size(); ++i) q[i] = node.rotation[i];
  for (size_t i = 0; i < 3 && i < node.scale.size(); ++i) s[i] = node.scale[i];
  const double x = q[0], y = q[1], z = q[2], w = q[3];
  const double r[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)},
                          {2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)},
                          {2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)}};
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) m[4 * i + j] = float(r[i][j] * s[j]);
    m[4 * i + 3] = float(t[i]);
  }
  return m;
}

// Walks the node graph from the scene's roots, depth-first with an explicit stack, refusing
// cycles and graphs deeper than kMaxNodeGraphDepth.
Result<void> importNodes(GltfContext& ctx) {
  const auto& model = ctx.model;
  std::vector<int> roots;
  if (!model.scenes.empty()) {
    const int s = model.defaultScene >= 0 && size_t(model.defaultScene) < model.scenes.size()
                      ? model.defaultScene
                      : 0;
    roots = model.scenes[s].nodes;
  }
  struct Frame {
    int node;
    std::array<float, 12> parent;
    uint32_t depth;
    size_t path_length;  ///< ancestors on `path` when this frame was pushed
  };
  std::vector<int> path;  // the ancestors of the node being visited, for cycle detection
  std::vector<Frame> stack;
  for (size_t r = roots.size(); r-- > 0;)
    stack.push_back({roots[r], {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0}, 0, 0});
  while (!stack.empty()) {
    Frame f = stack.back();
    stack.pop_back();
    if (f.node < 0 || size_t(f.node) >= model.nodes.size())
      return fail(ErrorCode::kCorrupt, fmt::format("{}: node {} out of range ({} nodes)", ctx.name,
                                                   f.node, model.nodes.size()));
    path.resize(f.path_length);
    if (std::find(path.begin(), path.end(), f.node) != path.end())
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: node {} is its own ancestor (a cycle in the node graph)",
                              ctx.name, f.node));
    if (f.depth >= kMaxNodeGraphDepth)
      return fail(ErrorCode::kTooLarge, fmt::format("{}: node {} is nested {} deep, over {}",
                                                    ctx.name, f.node, f.depth, kMaxNodeGraphDepth));
    path.push_back(f.node);
    const tinygltf::Node& node = model.nodes[f.node];
    const auto world = composeTransforms(f.parent, nodeTransform(node));
    if (node.mesh >= 0) {
      if (size_t(node.mesh) >= model.meshes.size())
        return fail(ErrorCode::kCorrupt, fmt::format("{}: node {} refers to mesh {}, out of range",
                                                     ctx.name, f.node, node.mesh));
      for (const auto& [mesh, material] : ctx.primitives[node.mesh]) {
        if (ctx.scene.objects.size() >= kMaxImportedObjects)
          return fail(ErrorCode::kTooLarge, ctx.name + ": too many object instances");
        ImportedObject object;
        object.mesh = mesh;
        object.transform = world;
        TESSERA_ASSIGN_OR_RETURN(object.textures,
                                 materialSlots(ctx, material, &object.base_color_rgba));
        ctx.scene.objects.push_back(object);
      }
    }
    for (size_t c = node.children.size(); c-- > 0;)
      stack.push_back({node.children[c], world, f.depth + 1, path.size()});
  }
  return {};
}

}  // namespace

Result<void> requireRegularFile(const std::string& path) {
  std::error_code ec;
  const std::filesystem::file_status status = std::filesystem::status(path, ec);
  if (!std::filesystem::exists(status)) return fail(ErrorCode::kNotFound, path + ": no such file");
  if (!std::filesystem::is_regular_file(status))
    return fail(ErrorCode::kIo, path + ": not a regular file");
  return {};
}

Result<ImportedScene> importGltf(const std::string& path) {
  TESSERA_TRY(requireRegularFile(path));
  tinygltf::TinyGLTF loader;
  loader.SetImageLoader(keepImageBytes, nullptr);
  tinygltf::Model model;
  std::string err, warn;
  const bool binary = std::filesystem::path(path).extension() == ".glb";
  const bool ok = binary ? loader.LoadBinaryFromFile(&model, &err, &warn, path)
                         : loader.LoadASCIIFromFile(&model, &err, &warn, path);
  if (!ok) {
    while (!err.empty() && err.back() == '\n') err.pop_back();
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: not a readable glTF{} file: {}", path, binary ? " binary" : "",
                            err.empty() ? "parse error" : err));
  }
  ImportedScene scene;
  scene.source = path;
  scene.importer = "gltf";
  const std::filesystem::path base = std::filesystem::path(path).parent_path();
  for (size_t i = 0; i < model.images.size(); ++i) {
    tinygltf::Image& image = model.images[i];
    TextureSource texture;
    const std::string label = image.name.empty() ? image.uri.substr(0, 64) : image.name;
    texture.name = fmt::format("image {} ({})", i, label);
    if (!image.uri.empty() && image.uri.rfind("data:", 0) != 0) {
      texture.path = (base / decodeUri(image.uri)).string();
    } else {
      texture.bytes = std::move(image.image);
      texture.mime_type = image.mimeType;
    }
    scene.textures.push_back(std::move(texture));
  }
  GltfContext ctx{model, path, scene, {}};
  TESSERA_TRY(importMeshes(ctx));
  TESSERA_TRY(importNodes(ctx));
  return scene;
}

}  // namespace tessera::detail
