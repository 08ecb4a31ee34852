#pragma once
// Helpers for the scene tests: small scene files written at test time (PNG textures, glTF and
// .glb files, OBJ), a byte source that counts reads, and a temporary folder.

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include <tessera/byte_source.h>
#include <tessera/format.h>
#include <tessera/scene.h>
#include <tessera/scene_build.h>
#include <tessera/view.h>

#include "support/test_images.h"  // readFileBytes, writeFileBytes, writePng of any depth

namespace tessera::test {

/// A fresh folder under the system temp folder, removed with its contents.
class ScratchDir {
 public:
  ScratchDir();
  ~ScratchDir();
  const std::filesystem::path& path() const { return path_; }
  std::string file(const std::string& name) const { return (path_ / name).string(); }
  /// Names of the files in the folder (to check that a failed build left nothing behind).
  std::vector<std::string> files() const;

 private:
  std::filesystem::path path_;
};

/// Builds `synthetic-scene:SPEC` into `dir`/city.tess with small tiles (64 px), leaves (8)
/// and fan-out (4), so that a few hundred objects make a tree of several levels; returns the
/// path (a failed build fails the test).
std::string buildSyntheticCity(const ScratchDir& dir, const std::string& spec);

/// Build options for a synthetic city made at test time: "synthetic-scene:" + spec into
/// `dir`/city.tess, 64-px tiles, 2 threads, leaves of 8, fan-out 4.
SceneBuildOptions testCityOptions(const ScratchDir& dir, const std::string& spec);

/// A y-up scene seen straight down from `height` above its top, centred (yaw 0 and pitch 0
/// look down -y), 640 x 480.
PerspectiveView cameraAbove(const SceneSummary& summary, double height, double fov_y_rad = 1.0);

/// Writes a w x h RGB PNG with a pattern that depends on `seed`.
void writeTestPng(const std::string& path, uint32_t width, uint32_t height, uint32_t seed);
/// Reads a file whole.

/// A glTF 2.0 document being assembled: one binary buffer, meshes, nodes, materials, images.
struct GltfBuilder {
  nlohmann::json doc;
  std::vector<uint8_t> bin;
  GltfBuilder();
  /// Appends bytes to the buffer (4-byte aligned) and returns a new buffer view index.
  int addView(const void* data, size_t bytes);
  /// A unit quad (4 vertices, 6 indices, uv0) with material `material` (-1 for none); returns
  /// the mesh index.
  int addQuadMesh(int material);
  /// A material whose base colour is texture `texture`.
  int addMaterial(int texture);
  /// A texture of image `image`.
  int addTexture(int image);
  int addImageUri(const std::string& uri);
  int addImageBytes(const std::vector<uint8_t>& bytes, const std::string& mime);
  /// A node with `mesh` (-1 for none) translated by (x, 0, z); returns its index.
  int addNode(int mesh, float x, float z);
  /// Lists `nodes` as the default scene's roots.
  void setRoots(const std::vector<int>& nodes);
  /// Writes `name`.gltf with the buffer in `name`.bin beside it.
  std::string writeGltf(const ScratchDir& dir, const std::string& name);
  /// Writes `name`.glb with the buffer as its BIN chunk.
  std::string writeGlb(const ScratchDir& dir, const std::string& name);
};

/// A source over another that counts reads (each range of readMany counts as one).
class CountingSource : public ByteSource {
 public:
  explicit CountingSource(std::shared_ptr<ByteSource> inner) : inner_(std::move(inner)) {}
  uint64_t sizeBytes() const override { return inner_->sizeBytes(); }
  const std::string& name() const override { return inner_->name(); }
  Result<void> read(uint64_t offset, std::span<uint8_t> out) const override {
    ++reads;
    uint64_t largest = largest_read_bytes.load();
    while (out.size() > largest && !largest_read_bytes.compare_exchange_weak(largest, out.size())) {
    }
    return inner_->read(offset, out);
  }
  mutable std::atomic<uint64_t> reads{0};
  mutable std::atomic<uint64_t> largest_read_bytes{0};  ///< the longest read; tests may reset it

 private:
  std::shared_ptr<ByteSource> inner_;
};

}  // namespace tessera::test
