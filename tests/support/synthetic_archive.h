#pragma once
// Small synthetic archives for the streaming tests: built once per test process with the
// public builder from "synthetic:WxH:seed:channels" into a temp dir, then opened over memory
// (optionally behind a FaultSource).

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <tessera/archive.h>
#include <tessera/format.h>

namespace tessera::test {

struct SyntheticArchiveSpec {
  uint32_t width_px = 1024;
  uint32_t height_px = 768;
  uint32_t seed = 3;
  uint32_t channels = 3;
  uint32_t tile_size_px = 64;
  Codec codec = Codec::kZstd;
  uint32_t border_px = 0;
};

/// The bytes of the archive for `spec`, built on first use (thread-safe). Fails the test
/// (ADD_FAILURE) and returns empty bytes if the build fails.
const std::vector<uint8_t>& syntheticArchiveBytes(const SyntheticArchiveSpec& spec);

/// Opens `source` as an archive; fails the test and returns null on error.
std::shared_ptr<Archive> openArchiveOrFail(std::shared_ptr<ByteSource> source);

/// Reads every directory page (tileEntry of every tile) so later tile reads touch only
/// payloads: a gate or fault on the source then hits the loader, not the directory.
void warmDirectory(const Archive& archive);

/// Every tile of image 0, coarsest level first.
std::vector<TileId> allTiles(const Archive& archive);

}  // namespace tessera::test
