// The deterministic scene generator: "synthetic-scene:N_OBJECTS:N_TEXTURES[:seed]". A city of
// boxes on a jittered grid; textures are crops of real images. Textures have spatial locality
// (most are used by a run of neighbouring objects, as facade textures are on a street) and a
// few are used everywhere (as seed 004's tree textures are), so promotion has work at every
// depth of the tree.
#include <algorithm>
#include <cmath>
#include <cstring>

#include <fmt/format.h>

#include "importers.h"

namespace tessera::detail {

namespace {

/// Distinct meshes: boxes whose UVs repeat 1..4 times across a face, shared by many objects.
constexpr uint32_t kMeshVariants = 16;
/// The share of texture references that go to the global textures.
constexpr uint32_t kGlobalPercent = 10;
/// Default sources: the project's synthetic terrain images (RGB), when no images are given.
constexpr uint32_t kDefaultSources = 8;
/// Objects stand on a grid of this spacing, in metres.
constexpr float kSpacingM = 25;

// splitmix64: a small, well-mixed, reproducible generator.
struct Random {
  uint64_t state;
  uint64_t next() {
    uint64_t z = (state += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  float uniform() { return float(next() >> 40) / float(1 << 24); }
  uint32_t below(uint32_t n) { return uint32_t(next() % n); }
};

ImportedMesh boxMesh(uint32_t variant) {
  ImportedMesh mesh;
  mesh.name = fmt::format("box{}", variant);
  const float repeat = float(1 + variant % 4);
  // Six faces, four vertices each: normal axis, sign.
  for (int axis = 0; axis < 3; ++axis) {
    for (int sign = -1; sign <= 1; sign += 2) {
      const int u = (axis + 1) % 3, v = (axis + 2) % 3;
      const uint32_t base = mesh.vertexCount();
      for (int corner = 0; corner < 4; ++corner) {
        float p[3], n[3] = {0, 0, 0};
        p[axis] = 0.5f * sign;
        p[u] = (corner & 1) ? 0.5f : -0.5f;
        p[v] = (corner & 2) ? 0.5f : -0.5f;
        n[axis] = float(sign);
        mesh.positions.insert(mesh.positions.end(), {p[0], p[1] + 0.5f, p[2]});
        mesh.normals.insert(mesh.normals.end(), {n[0], n[1], n[2]});
        mesh.uv0.insert(mesh.uv0.end(), {(corner & 1) * repeat, float((corner >> 1) & 1)});
      }
      if (sign > 0)
        mesh.indices.insert(mesh.indices.end(),
                            {base, base + 1, base + 3, base, base + 3, base + 2});
      else
        mesh.indices.insert(mesh.indices.end(),
                            {base, base + 3, base + 1, base, base + 2, base + 3});
    }
  }
  return mesh;
}

// Interleaves the bits of x and y (Morton order), so consecutive indices are spatial neighbours.
uint64_t morton(uint32_t x, uint32_t y) {
  uint64_t out = 0;
  for (int b = 0; b < 32; ++b)
    out |= (uint64_t((x >> b) & 1) << (2 * b)) | (uint64_t((y >> b) & 1) << (2 * b + 1));
  return out;
}

Result<std::array<uint64_t, 3>> parseSpec(const std::string& spec) {
  std::array<uint64_t, 3> values{0, 0, 1};
  size_t pos = 0;
  for (int i = 0; i < 3 && pos <= spec.size(); ++i) {
    size_t end = spec.find(':', pos);
    std::string part = spec.substr(pos, end == std::string::npos ? std::string::npos : end - pos);
    if (part.empty() || part.find_first_not_of("0123456789") != std::string::npos ||
        part.size() > 12)
      return fail(ErrorCode::kInvalidArgument,
                  fmt::format("synthetic-scene:{}: expected N_OBJECTS:N_TEXTURES[:seed]", spec));
    values[i] = std::stoull(part);
    if (end == std::string::npos) {
      if (i < 1)
        return fail(ErrorCode::kInvalidArgument,
                    fmt::format("synthetic-scene:{}: expected N_OBJECTS:N_TEXTURES[:seed]", spec));
      break;
    }
    pos = end + 1;
  }
  return values;
}

}  // namespace

Result<ImportedScene> generateSyntheticScene(const std::string& spec,
                                             const std::vector<std::string>& sources) {
  TESSERA_ASSIGN_OR_RETURN(auto values, parseSpec(spec));
  const uint64_t objects = values[0], textures = values[1], seed = values[2];
  const std::string name = "synthetic-scene:" + spec;
  if (objects == 0 || objects > kMaxImportedObjects)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: {} objects out of 1..{}", name, objects, kMaxImportedObjects));
  if (textures == 0 || textures > kMaxImages || textures > objects)
    return fail(
        ErrorCode::kInvalidArgument,
        fmt::format("{}: {} textures out of 1..min(objects, {})", name, textures, kMaxImages));
  ImportedScene scene;
  scene.source = name;
  scene.importer = "synthetic";
  scene.crop_sources = sources;
  if (scene.crop_sources.empty())
    for (uint32_t k = 0; k < kDefaultSources; ++k)
      scene.crop_sources.push_back(fmt::format("synthetic:1024x1024:{}:3", seed * 131 + k));
  for (uint32_t v = 0; v < kMeshVariants; ++v) scene.meshes.push_back(boxMesh(v));

  Random random{seed};
  const uint32_t global = std::max<uint32_t>(1, uint32_t(textures / 100));
  const uint32_t local = uint32_t(textures) > global ? uint32_t(textures) - global : 1;
  const uint32_t global_first = uint32_t(textures) > global ? local : 0;
  for (uint64_t t = 0; t < textures; ++t) {
    TextureSource texture;
    texture.name = fmt::format("texture {}", t);
    texture.crop_source = int32_t(random.below(uint32_t(scene.crop_sources.size())));
    const uint32_t side = 64u << random.below(3);  // 64, 128 or 256 px
    texture.crop_width = side << random.below(2);
    texture.crop_height = side;
    texture.crop_x = random.below(1 << 16);  // fractions of the free width and height
    texture.crop_y = random.below(1 << 16);
    scene.textures.push_back(std::move(texture));
  }

  // Objects on a jittered grid, generated in Morton order so that consecutive objects are
  // neighbours; object k's local texture is k * local / objects (a run of neighbours).
  const uint32_t side = uint32_t(std::ceil(std::sqrt(double(objects))));
  std::vector<std::pair<uint64_t, uint32_t>> cells;
  cells.reserve(size_t(side) * side);
  for (uint32_t y = 0; y < side; ++y)
    for (uint32_t x = 0; x < side; ++x) cells.push_back({morton(x, y), y * side + x});
  std::sort(cells.begin(), cells.end());
  scene.objects.reserve(objects);
  for (uint64_t k = 0; k < objects; ++k) {
    const uint32_t cell = cells[k].second;
    ImportedObject object;
    object.mesh = random.below(kMeshVariants);
    const float width = 6 + 12 * random.uniform(), depth = 6 + 12 * random.uniform();
    const float height = 4 + 60 * random.uniform() * random.uniform();
    const float angle = 6.2831853f * random.uniform();
    const float c = std::cos(angle), s = std::sin(angle);
    const float x = (cell % side + 0.3f * random.uniform()) * kSpacingM;
    const float z = (cell / side + 0.3f * random.uniform()) * kSpacingM;
    object.transform = {c * width, 0, s * depth, x, 0, height, 0, 0, -s * width, 0, c * depth, z};
    const bool use_global = random.below(100) < kGlobalPercent;
    object.textures[0] =
        use_global ? global_first + random.below(global) : uint32_t(k * local / objects);
    object.base_color_rgba = 0xFFFFFFFFu;
    scene.objects.push_back(object);
  }
  // Every global texture used at least once, whatever the draw.
  for (uint32_t g = 0; g < global && g < objects; ++g)
    scene.objects[size_t(g) * objects / global].textures[0] = global_first + g;
  return scene;
}

}  // namespace tessera::detail
