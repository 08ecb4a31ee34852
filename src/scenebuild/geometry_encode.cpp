#include "geometry_encode.h"

#include <cstring>

#include <meshoptimizer.h>
#include <zstd.h>

#include <tessera/check.h>

#include "scene/geometry.h"

namespace tessera::detail {

namespace {

// zstd level 19: geometry is written once and read many times; the level costs build time only.
constexpr int kZstdLevel = 19;

std::vector<uint8_t> zstdFrame(const std::vector<uint8_t>& bytes) {
  std::vector<uint8_t> out(ZSTD_compressBound(bytes.size()));
  const size_t n = ZSTD_compress(out.data(), out.size(), bytes.data(), bytes.size(), kZstdLevel);
  TESSERA_CHECK(!ZSTD_isError(n)) << "zstd: " << ZSTD_getErrorName(n);
  out.resize(n);
  return out;
}

}  // namespace

EncodedMesh encodeMesh(const ImportedMesh& mesh, GeometryCodecId codec) {
  EncodedMesh out;
  out.attributes =
      uint8_t((mesh.normals.empty() ? 0 : kMeshNormals) | (mesh.uv0.empty() ? 0 : kMeshUv0));
  MeshData data;
  data.positions = mesh.positions;
  data.normals = mesh.normals;
  data.uv0 = mesh.uv0;
  std::vector<uint8_t> vertices = interleaveVertices(data, out.attributes);
  std::vector<uint8_t> indices(mesh.indices.size() * 4);
  std::memcpy(indices.data(), mesh.indices.data(), indices.size());
  out.raw_bytes = vertices.size() + indices.size();
  std::vector<uint8_t> vertex_part, index_part;
  switch (codec) {
    case GeometryCodecId::kRaw:
      vertex_part = std::move(vertices);
      index_part = std::move(indices);
      break;
    case GeometryCodecId::kZstd:
      vertex_part = zstdFrame(vertices);
      index_part = zstdFrame(indices);
      break;
    case GeometryCodecId::kMeshopt: {
      const size_t count = mesh.vertexCount();
      MeshRecord shape;
      shape.attributes = out.attributes;
      const size_t stride = shape.vertexStrideBytes();
      meshopt_encodeVertexVersion(0);
      meshopt_encodeIndexVersion(1);
      vertex_part.resize(meshopt_encodeVertexBufferBound(count, stride));
      vertex_part.resize(meshopt_encodeVertexBuffer(vertex_part.data(), vertex_part.size(),
                                                    vertices.data(), count, stride));
      index_part.resize(meshopt_encodeIndexBufferBound(mesh.indices.size(), count));
      index_part.resize(meshopt_encodeIndexBuffer(index_part.data(), index_part.size(),
                                                  mesh.indices.data(), mesh.indices.size()));
      TESSERA_CHECK(!vertex_part.empty() && !index_part.empty()) << "meshoptimizer bound too small";
      break;
    }
  }
  out.vertex_part_bytes = uint32_t(vertex_part.size());
  out.blob = std::move(vertex_part);
  out.blob.insert(out.blob.end(), index_part.begin(), index_part.end());
  return out;
}

}  // namespace tessera::detail
