#pragma once
// Mesh blobs (docs/format.md, "Geometry"): interleaved vertices (position, then normal and
// uv0 when present, f32 little-endian) and u32 indices, each part stored raw, as one zstd
// frame, or with meshoptimizer's vertex and index codecs. The decode side lives here, with the
// reader; the encode side (scenebuild) links the encoders.

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <tessera/result.h>
#include <tessera/scene.h>

#include "format/scene.h"

namespace tessera::detail {

/// Interleaves a mesh's attributes into the stored vertex layout.
std::vector<uint8_t> interleaveVertices(const MeshData& mesh, uint8_t attributes);

/// Decodes a verified blob of `record` into separate attribute arrays. Bounds every size by
/// the record's counts before allocating, rejects truncated parts and trailing bytes, and
/// checks every index against the vertex count. `what` prefixes errors.
[[nodiscard]] Result<MeshData> decodeMeshBlob(const MeshRecord& record,
                                              std::span<const uint8_t> blob,
                                              const std::string& what);

}  // namespace tessera::detail
