#pragma once
// The encode side of mesh blobs (scene/geometry.h has the layout and the decoder).

#include <cstdint>
#include <vector>

#include <tessera/scene.h>

#include "format/scene.h"
#include "scene_model.h"

namespace tessera::detail {

struct EncodedMesh {
  std::vector<uint8_t> blob;  ///< vertex part, then index part
  uint32_t vertex_part_bytes = 0;
  uint8_t attributes = 0;  ///< MeshAttributeBits present in the source mesh
  uint64_t raw_bytes = 0;  ///< interleaved vertices + u32 indices before coding
};

/// Encodes a validated mesh with `codec`. meshoptimizer's vertex codec is lossless on the
/// f32 attributes; its index codec needs a triangle list, which validateScene guarantees.
EncodedMesh encodeMesh(const ImportedMesh& mesh, GeometryCodecId codec);

}  // namespace tessera::detail
