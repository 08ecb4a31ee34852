#include "scene/geometry.h"

#include <bit>
#include <cstring>

#include <fmt/format.h>
#include <meshoptimizer.h>
#include <zstd.h>

namespace tessera::detail {

static_assert(std::endian::native == std::endian::little,
              "mesh blobs are little-endian and copied as such");

namespace {

Result<std::vector<uint8_t>> decodePart(GeometryCodecId codec, std::span<const uint8_t> part,
                                        size_t expected_bytes, size_t count, size_t element_bytes,
                                        bool indices, const std::string& what) {
  std::vector<uint8_t> out;
  switch (codec) {
    case GeometryCodecId::kRaw:
      if (part.size() != expected_bytes)
        return fail(ErrorCode::kCorrupt,
                    fmt::format("{}: {} bytes, expected {}", what, part.size(), expected_bytes));
      out.assign(part.begin(), part.end());
      return out;
    case GeometryCodecId::kZstd: {
      const unsigned long long size = ZSTD_getFrameContentSize(part.data(), part.size());
      if (size != expected_bytes)
        return fail(ErrorCode::kCorrupt,
                    fmt::format("{}: zstd frame declares {} bytes, expected {}", what,
                                size == ZSTD_CONTENTSIZE_UNKNOWN ? 0ull : size, expected_bytes));
      const size_t frame = ZSTD_findFrameCompressedSize(part.data(), part.size());
      if (ZSTD_isError(frame) || frame != part.size())
        return fail(ErrorCode::kCorrupt, what + ": truncated zstd frame or trailing bytes");
      out.resize(expected_bytes);
      const size_t got = ZSTD_decompress(out.data(), out.size(), part.data(), part.size());
      if (ZSTD_isError(got) || got != expected_bytes)
        return fail(ErrorCode::kCorrupt,
                    fmt::format("{}: zstd: {}", what,
                                ZSTD_isError(got) ? ZSTD_getErrorName(got) : "short frame"));
      return out;
    }
    case GeometryCodecId::kMeshopt: {
      out.resize(expected_bytes);
      const int rc = indices ? meshopt_decodeIndexBuffer(out.data(), count, element_bytes,
                                                         part.data(), part.size())
                             : meshopt_decodeVertexBuffer(out.data(), count, element_bytes,
                                                          part.data(), part.size());
      if (rc != 0)
        return fail(ErrorCode::kCorrupt,
                    fmt::format("{}: meshoptimizer {} codec rejects the data ({})", what,
                                indices ? "index" : "vertex", rc));
      return out;
    }
  }
  return fail(ErrorCode::kUnsupported, what + ": unknown geometry codec");
}

}  // namespace

std::vector<uint8_t> interleaveVertices(const MeshData& mesh, uint8_t attributes) {
  MeshRecord shape;
  shape.attributes = attributes;
  const size_t stride = shape.vertexStrideBytes();
  const size_t vertices = mesh.positions.size() / 3;
  std::vector<uint8_t> out(vertices * stride);
  for (size_t v = 0; v < vertices; ++v) {
    uint8_t* p = out.data() + v * stride;
    std::memcpy(p, &mesh.positions[3 * v], 12);
    p += 12;
    if (attributes & kMeshNormals) {
      std::memcpy(p, &mesh.normals[3 * v], 12);
      p += 12;
    }
    if (attributes & kMeshUv0) std::memcpy(p, &mesh.uv0[2 * v], 8);
  }
  return out;
}

Result<MeshData> decodeMeshBlob(const MeshRecord& record, std::span<const uint8_t> blob,
                                const std::string& what) {
  if (record.vertex_count == 0 || record.vertex_count > kMaxMeshVertices ||
      record.index_count == 0 || record.index_count > kMaxMeshIndices ||
      record.index_count % 3 != 0 || record.vertex_part_bytes > blob.size())
    return fail(ErrorCode::kCorrupt, what + ": counts or parts out of bounds");
  const size_t stride = record.vertexStrideBytes();
  const size_t vertex_bytes = size_t(record.vertex_count) * stride;
  const size_t index_bytes = size_t(record.index_count) * 4;
  TESSERA_ASSIGN_OR_RETURN(
      std::vector<uint8_t> vertices,
      decodePart(record.codec, blob.first(record.vertex_part_bytes), vertex_bytes,
                 record.vertex_count, stride, false, what + " vertices"));
  TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> indices,
                           decodePart(record.codec, blob.subspan(record.vertex_part_bytes),
                                      index_bytes, record.index_count, 4, true, what + " indices"));
  MeshData mesh;
  mesh.positions.resize(size_t(record.vertex_count) * 3);
  if (record.attributes & kMeshNormals) mesh.normals.resize(size_t(record.vertex_count) * 3);
  if (record.attributes & kMeshUv0) mesh.uv0.resize(size_t(record.vertex_count) * 2);
  for (size_t v = 0; v < record.vertex_count; ++v) {
    const uint8_t* p = vertices.data() + v * stride;
    std::memcpy(&mesh.positions[3 * v], p, 12);
    p += 12;
    if (record.attributes & kMeshNormals) {
      std::memcpy(&mesh.normals[3 * v], p, 12);
      p += 12;
    }
    if (record.attributes & kMeshUv0) std::memcpy(&mesh.uv0[2 * v], p, 8);
  }
  mesh.indices.resize(record.index_count);
  std::memcpy(mesh.indices.data(), indices.data(), index_bytes);
  for (size_t i = 0; i < mesh.indices.size(); ++i)
    if (mesh.indices[i] >= record.vertex_count)
      return fail(ErrorCode::kCorrupt, fmt::format("{}: index {} is {}, past {} vertices", what, i,
                                                   mesh.indices[i], record.vertex_count));
  return mesh;
}

}  // namespace tessera::detail
