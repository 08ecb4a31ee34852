#include "scene/scene_test_support.h"

#include <unistd.h>

#include <cstring>
#include <fstream>

#include <gtest/gtest.h>

#include <tessera/check.h>
#include <tessera/picture_file.h>
#include <tessera/scene_build.h>

namespace tessera::test {

std::string buildSyntheticCity(const ScratchDir& dir, const std::string& spec) {
  const SceneBuildOptions options = testCityOptions(dir, spec);
  Result<SceneBuildReport> report = buildScene(options);
  EXPECT_TRUE(report.has_value()) << report.error().message;
  return options.output;
}

ScratchDir::ScratchDir() {
  std::string pattern =
      (std::filesystem::temp_directory_path() / "tessera-scene-test-XXXXXX").string();
  TESSERA_CHECK(::mkdtemp(pattern.data()) != nullptr) << "mkdtemp failed";
  path_ = pattern;
}

ScratchDir::~ScratchDir() {
  std::error_code ec;
  std::filesystem::remove_all(path_, ec);
}

std::vector<std::string> ScratchDir::files() const {
  std::vector<std::string> out;
  for (const auto& entry : std::filesystem::directory_iterator(path_))
    out.push_back(entry.path().filename().string());
  return out;
}

void writeTestPng(const std::string& path, uint32_t width, uint32_t height, uint32_t seed) {
  Image image(width, height, 3);
  for (uint32_t y = 0; y < height; ++y)
    for (uint32_t x = 0; x < width; ++x)
      for (uint32_t c = 0; c < 3; ++c)
        image.row(y)[3 * x + c] =
            uint8_t((x * (c + 1) + y * (seed + 2) + seed * 37 + c * 50) & 255);
  TESSERA_CHECK(writePng(image, path).has_value()) << "writePng " << path;
}

GltfBuilder::GltfBuilder() {
  doc = {{"asset", {{"version", "2.0"}}},
         {"buffers", nlohmann::json::array()},
         {"bufferViews", nlohmann::json::array()},
         {"accessors", nlohmann::json::array()},
         {"meshes", nlohmann::json::array()},
         {"materials", nlohmann::json::array()},
         {"textures", nlohmann::json::array()},
         {"images", nlohmann::json::array()},
         {"nodes", nlohmann::json::array()},
         {"scenes", nlohmann::json::array({{{"nodes", nlohmann::json::array()}}})},
         {"scene", 0}};
}

int GltfBuilder::addView(const void* data, size_t bytes) {
  while (bin.size() % 4) bin.push_back(0);
  const size_t offset = bin.size();
  const auto* p = static_cast<const uint8_t*>(data);
  bin.insert(bin.end(), p, p + bytes);
  doc["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", offset}, {"byteLength", bytes}});
  return int(doc["bufferViews"].size() - 1);
}

int GltfBuilder::addQuadMesh(int material) {
  const float positions[] = {0, 0, 0, 1, 0, 0, 1, 0, 1, 0, 0, 1};
  const float uvs[] = {0, 0, 1, 0, 1, 1, 0, 1};
  const uint16_t indices[] = {0, 2, 1, 0, 3, 2};
  int pv = addView(positions, sizeof(positions));
  int uv = addView(uvs, sizeof(uvs));
  int iv = addView(indices, sizeof(indices));
  auto& acc = doc["accessors"];
  acc.push_back({{"bufferView", pv},
                 {"componentType", 5126},
                 {"count", 4},
                 {"type", "VEC3"},
                 {"min", {0, 0, 0}},
                 {"max", {1, 0, 1}}});
  acc.push_back({{"bufferView", uv}, {"componentType", 5126}, {"count", 4}, {"type", "VEC2"}});
  acc.push_back({{"bufferView", iv}, {"componentType", 5123}, {"count", 6}, {"type", "SCALAR"}});
  const int first = int(acc.size()) - 3;
  nlohmann::json prim = {{"attributes", {{"POSITION", first}, {"TEXCOORD_0", first + 1}}},
                         {"indices", first + 2}};
  if (material >= 0) prim["material"] = material;
  doc["meshes"].push_back({{"primitives", nlohmann::json::array({prim})}});
  return int(doc["meshes"].size() - 1);
}

int GltfBuilder::addMaterial(int texture) {
  doc["materials"].push_back(
      {{"pbrMetallicRoughness", {{"baseColorTexture", {{"index", texture}}}}}});
  return int(doc["materials"].size() - 1);
}

int GltfBuilder::addTexture(int image) {
  doc["textures"].push_back({{"source", image}});
  return int(doc["textures"].size() - 1);
}

int GltfBuilder::addImageUri(const std::string& uri) {
  doc["images"].push_back({{"uri", uri}});
  return int(doc["images"].size() - 1);
}

int GltfBuilder::addImageBytes(const std::vector<uint8_t>& bytes, const std::string& mime) {
  int view = addView(bytes.data(), bytes.size());
  doc["images"].push_back({{"bufferView", view}, {"mimeType", mime}});
  return int(doc["images"].size() - 1);
}

int GltfBuilder::addNode(int mesh, float x, float z) {
  nlohmann::json node = {{"translation", {x, 0, z}}};
  if (mesh >= 0) node["mesh"] = mesh;
  doc["nodes"].push_back(node);
  return int(doc["nodes"].size() - 1);
}

void GltfBuilder::setRoots(const std::vector<int>& nodes) {
  doc["scenes"][0]["nodes"] = nodes;
}

std::string GltfBuilder::writeGltf(const ScratchDir& dir, const std::string& name) {
  nlohmann::json out = doc;
  out["buffers"] = nlohmann::json::array({{{"uri", name + ".bin"}, {"byteLength", bin.size()}}});
  writeFileBytes(dir.file(name + ".bin"), bin);
  const std::string text = out.dump(1);
  writeFileBytes(dir.file(name + ".gltf"), {text.begin(), text.end()});
  return dir.file(name + ".gltf");
}

std::string GltfBuilder::writeGlb(const ScratchDir& dir, const std::string& name) {
  nlohmann::json out = doc;
  std::vector<uint8_t> data = bin;
  while (data.size() % 4) data.push_back(0);
  out["buffers"] = nlohmann::json::array({{{"byteLength", data.size()}}});
  std::string json = out.dump();
  while (json.size() % 4) json.push_back(' ');
  std::vector<uint8_t> file;
  auto u32 = [&](uint32_t v) {
    for (int i = 0; i < 4; ++i) file.push_back(uint8_t(v >> (8 * i)));
  };
  u32(0x46546C67);  // "glTF"
  u32(2);
  u32(uint32_t(12 + 8 + json.size() + 8 + data.size()));
  u32(uint32_t(json.size()));
  u32(0x4E4F534A);  // JSON
  file.insert(file.end(), json.begin(), json.end());
  u32(uint32_t(data.size()));
  u32(0x004E4942);  // BIN
  file.insert(file.end(), data.begin(), data.end());
  writeFileBytes(dir.file(name + ".glb"), file);
  return dir.file(name + ".glb");
}

SceneBuildOptions testCityOptions(const ScratchDir& dir, const std::string& spec) {
  SceneBuildOptions options;
  options.input = "synthetic-scene:" + spec;
  options.output = dir.file("city.tess");
  options.tile_size_px = 64;
  options.threads = 2;
  options.leaf_capacity = 8;
  options.max_children = 4;
  return options;
}

PerspectiveView cameraAbove(const SceneSummary& summary, double height, double fov_y_rad) {
  PerspectiveView camera;
  camera.eye_x = (summary.bounds.min[0] + summary.bounds.max[0]) / 2;
  camera.eye_y = summary.bounds.max[1] + height;
  camera.eye_z = (summary.bounds.min[2] + summary.bounds.max[2]) / 2;
  camera.yaw_rad = 0;
  camera.pitch_rad = 0;
  camera.fov_y_rad = fov_y_rad;
  camera.viewport_w = 640;
  camera.viewport_h = 480;
  return camera;
}

}  // namespace tessera::test
