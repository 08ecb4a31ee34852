// SceneArchive: the scene section of a version 1.1 archive over any ByteSource
// (docs/format.md, "Scenes").
#include <tessera/scene.h>

#include <algorithm>
#include <cstring>
#include <mutex>
#include <unordered_map>

#include <fmt/format.h>

#include "codecs/decode.h"
#include "format/checksum.h"
#include "format/coverage_hints.h"
#include "format/directory.h"
#include "format/header.h"
#include "format/scene.h"
#include "format/sections.h"
#include "scene/geometry.h"

namespace tessera {

using namespace detail;

const char* geometryCodecName(GeometryCodec codec) {
  switch (codec) {
    case GeometryCodec::kRaw: return "raw";
    case GeometryCodec::kZstd: return "zstd";
    case GeometryCodec::kMeshopt: return "meshopt";
  }
  return "unknown";
}

bool parseGeometryCodecName(std::string_view name, GeometryCodec* codec) {
  for (GeometryCodec c : {GeometryCodec::kRaw, GeometryCodec::kZstd, GeometryCodec::kMeshopt}) {
    if (name == geometryCodecName(c)) {
      *codec = c;
      return true;
    }
  }
  return false;
}

namespace {

Box3 toBox(const SceneBox& box) {
  return {box.min, box.max};
}

SceneNode toNode(const NodeRecord& r, uint32_t index) {
  SceneNode n;
  n.index = index;
  n.bounds = toBox(r.bounds);
  n.subtree_nodes = r.subtree_nodes;
  n.child_count = r.child_count;
  n.depth = r.depth;
  n.first_object = r.first_object;
  n.object_count = r.object_count;
  n.first_texture = r.first_texture;
  n.texture_count = r.texture_count;
  n.first_mesh = r.first_mesh;
  n.mesh_count = r.mesh_count;
  n.own = {r.offset_bytes, r.own_bytes};
  n.head_bytes = r.head_bytes;
  n.subtree = {r.offset_bytes, r.subtree_bytes};
  return n;
}

SceneTexture toTexture(const TextureRecord& r, uint32_t index) {
  return {index, r.image, r.node, r.users, r.info, r.coarsest};
}

/// Node records kept after a read: they are 96 bytes, and a walk revisits the top of the tree.
/// Past this many the cache starts over, so a hostile or huge table cannot grow it unbounded.
constexpr size_t kMaxCachedRecords = 1u << 20;
/// A subtree's records are read in one go for children() when they are at most this many bytes.
constexpr uint64_t kChildrenReadBytes = 64 * 1024;

}  // namespace

struct SceneArchive::Impl {
  std::shared_ptr<ByteSource> source;
  std::string name;
  FileHeader header;
  SceneDirectory directory;
  BlockRef hints;  ///< the coverage hints section; length 0 when there is none
  SceneSummary summary;
  std::vector<uint8_t> header_region;
  /// Head checksums need the head's own record: they are kept with it.
  std::mutex node_mutex;  // guards node_cache
  std::unordered_map<uint32_t, NodeRecord> node_cache;
  std::mutex texture_mutex;  // guards texture_cache
  std::unordered_map<uint32_t, TextureRecord> texture_cache;

  // Bytes [offset, offset + length): from the header region when inside it, else one read.
  Result<std::vector<uint8_t>> readRange(uint64_t offset, uint64_t length) const {
    if (length > header.file_bytes || offset > header.file_bytes - length)
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: range [{}, +{}) outside the file", name, offset, length));
    std::vector<uint8_t> bytes(length);
    if (offset + length <= header_region.size()) {
      std::memcpy(bytes.data(), header_region.data() + offset, length);
      return bytes;
    }
    TESSERA_TRY(source->read(offset, bytes));
    return bytes;
  }

  Result<std::vector<uint8_t>> readVerified(const BlockRef& block, const std::string& what) const {
    TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> bytes,
                             readRange(block.offset_bytes, block.length_bytes));
    if (checksum64(bytes) != block.checksum)
      return fail(ErrorCode::kCorrupt, fmt::format("{}: {} checksum mismatch at offset {}", name,
                                                   what, block.offset_bytes));
    return bytes;
  }

  Result<std::vector<NodeRecord>> records(uint32_t first, uint32_t count) {
    if (first > directory.node_count || count > directory.node_count - first)
      return fail(ErrorCode::kInvalidArgument,
                  fmt::format("{}: nodes [{}, +{}) outside the {} nodes", name, first, count,
                              directory.node_count));
    std::vector<uint8_t> bytes;
    if (first == 0 && count == directory.node_count) {
      TESSERA_ASSIGN_OR_RETURN(bytes, readVerified(directory.node_table, "node table"));
    } else {
      TESSERA_ASSIGN_OR_RETURN(
          bytes, readRange(directory.node_table.offset_bytes + uint64_t(first) * kNodeRecordBytes,
                           uint64_t(count) * kNodeRecordBytes));
    }
    TESSERA_ASSIGN_OR_RETURN(std::vector<NodeRecord> decoded,
                             decodeNodeRecords(bytes, first, directory, header, name));
    std::lock_guard lock(node_mutex);
    if (node_cache.size() + decoded.size() > kMaxCachedRecords) node_cache.clear();
    for (uint32_t k = 0; k < decoded.size() && decoded.size() <= kMaxCachedRecords; ++k)
      node_cache.emplace(first + k, decoded[k]);
    return decoded;
  }

  Result<NodeRecord> record(uint32_t index) {
    {
      std::lock_guard lock(node_mutex);
      if (auto it = node_cache.find(index); it != node_cache.end()) return it->second;
    }
    TESSERA_ASSIGN_OR_RETURN(std::vector<NodeRecord> one, records(index, 1));
    return one[0];
  }

  Result<void> checkTileEntries(const NodeRecord& node, const NodeTextureRecord& texture,
                                const std::vector<std::vector<TileEntry>>& levels) const {
    const uint64_t own_end = node.offset_bytes + node.own_bytes;
    const BlockRef& coarse = directory.coarse;
    for (uint32_t level = 0; level < levels.size(); ++level) {
      const bool coarsest = level + 1 == levels.size();
      for (const TileEntry& e : levels[level]) {
        if (e.kind != TileKind::kEncoded) continue;
        const uint64_t begin = coarsest ? coarse.offset_bytes : node.offset_bytes + node.head_bytes;
        const uint64_t end = coarsest ? coarse.offset_bytes + coarse.length_bytes : own_end;
        if (e.offset_bytes < begin || e.offset_bytes + e.length_bytes > end)
          return fail(ErrorCode::kCorrupt,
                      fmt::format("{}: texture {} level {}: a payload at {} lies outside {}", name,
                                  texture.texture, level, e.offset_bytes,
                                  coarsest ? "the coarse block" : "its node's block"));
      }
    }
    return {};
  }
};

SceneArchive::SceneArchive(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
SceneArchive::~SceneArchive() = default;

Result<std::shared_ptr<SceneArchive>> SceneArchive::open(std::shared_ptr<ByteSource> source) {
  TESSERA_CHECK(source != nullptr) << "SceneArchive::open: null source";
  auto impl = std::make_unique<Impl>();
  impl->name = source->name();
  const uint64_t size = source->sizeBytes();
  impl->header_region.resize(std::min<uint64_t>(size, kHeaderRegionBytes));
  TESSERA_TRY(source->read(0, impl->header_region));
  TESSERA_ASSIGN_OR_RETURN(impl->header, decodeHeader(impl->header_region, impl->name));
  if (impl->header.file_bytes != size)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: header records {} bytes but the file has {} (truncated?)",
                            impl->name, impl->header.file_bytes, size));
  TESSERA_ASSIGN_OR_RETURN(const BlockRef table,
                           decodeSectionTableRef(impl->header_region, impl->header, impl->name));
  impl->source = std::move(source);
  std::vector<SectionEntry> sections;
  if (table.length_bytes != 0) {
    TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> table_bytes,
                             impl->readVerified(table, "section table"));
    TESSERA_ASSIGN_OR_RETURN(sections, decodeSectionTable(table_bytes, impl->header, impl->name));
  }
  TESSERA_ASSIGN_OR_RETURN(BlockRef scene, decodeSceneRef(sections, impl->name));
  if (scene.length_bytes == 0)
    return fail(ErrorCode::kNotFound,
                fmt::format("{}: a version {}.{} archive without a scene", impl->name,
                            impl->header.version_major, impl->header.version_minor));
  TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> bytes,
                           impl->readVerified(scene, "scene directory"));
  TESSERA_ASSIGN_OR_RETURN(impl->directory, decodeSceneDirectory(bytes, impl->header, impl->name));
  impl->hints = findSection(sections, SectionKind::kCoverageHints);
  const SceneDirectory& d = impl->directory;
  impl->summary = {d.node_count, d.object_count, d.mesh_count,    d.texture_count,
                   d.tree_depth, d.max_children, d.leaf_capacity, toBox(d.bounds)};
  return std::shared_ptr<SceneArchive>(new SceneArchive(std::move(impl)));
}

Result<std::shared_ptr<SceneArchive>> SceneArchive::openFile(const std::string& path) {
  TESSERA_ASSIGN_OR_RETURN(std::shared_ptr<ByteSource> source, openFileSource(path));
  return open(std::move(source));
}

const std::string& SceneArchive::name() const {
  return impl_->name;
}
const SceneSummary& SceneArchive::summary() const {
  return impl_->summary;
}
uint64_t SceneArchive::fileBytes() const {
  return impl_->header.file_bytes;
}
const ByteSource& SceneArchive::source() const {
  return *impl_->source;
}
Result<std::string> SceneArchive::readMetadata() const {
  const BlockRef& block = impl_->header.metadata;
  if (block.length_bytes == 0) return std::string("{}");
  TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> bytes, impl_->readVerified(block, "metadata"));
  return std::string(bytes.begin(), bytes.end());
}

FileRange SceneArchive::nodeTableRange() const {
  return {impl_->directory.node_table.offset_bytes, impl_->directory.node_table.length_bytes};
}
FileRange SceneArchive::coarseRange() const {
  return {impl_->directory.coarse.offset_bytes, impl_->directory.coarse.length_bytes};
}
FileRange SceneArchive::coverageHintsRange() const {
  return {impl_->hints.offset_bytes, impl_->hints.length_bytes};
}

Result<CoverageHints> SceneArchive::readCoverageHints() const {
  const BlockRef& block = impl_->hints;
  if (block.length_bytes == 0)
    return fail(ErrorCode::kNotFound, impl_->name + ": no coverage hints");
  if (block.length_bytes > kMaxCoverageHintsBytes)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: coverage hints of {} bytes exceed {}", impl_->name,
                            block.length_bytes, kMaxCoverageHintsBytes));
  TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> bytes,
                           impl_->readVerified(block, "coverage hints"));
  return decodeCoverageHints(bytes, impl_->directory.texture_count, impl_->name);
}

Result<SceneNode> SceneArchive::node(uint32_t index) const {
  TESSERA_ASSIGN_OR_RETURN(NodeRecord r, impl_->record(index));
  return toNode(r, index);
}

Result<std::vector<SceneNode>> SceneArchive::nodes(uint32_t first, uint32_t count) const {
  TESSERA_ASSIGN_OR_RETURN(std::vector<NodeRecord> records, impl_->records(first, count));
  std::vector<SceneNode> out;
  out.reserve(records.size());
  for (uint32_t k = 0; k < records.size(); ++k) out.push_back(toNode(records[k], first + k));
  return out;
}

Result<std::vector<SceneNode>> SceneArchive::allNodes() const {
  const uint32_t count = impl_->directory.node_count;
  TESSERA_ASSIGN_OR_RETURN(std::vector<NodeRecord> records, impl_->records(0, count));
  TESSERA_TRY(validateNodeTable(records, impl_->directory, impl_->name));
  std::vector<SceneNode> out;
  out.reserve(records.size());
  for (uint32_t k = 0; k < records.size(); ++k) out.push_back(toNode(records[k], k));
  return out;
}

Result<std::vector<SceneNode>> SceneArchive::children(const SceneNode& parent) const {
  std::vector<SceneNode> out;
  if (parent.child_count == 0) return out;
  const uint32_t descendants = parent.subtree_nodes - 1;
  if (uint64_t(descendants) * kNodeRecordBytes <= kChildrenReadBytes) {
    TESSERA_ASSIGN_OR_RETURN(std::vector<SceneNode> all, nodes(parent.index + 1, descendants));
    for (uint32_t k = 0; k < all.size(); k += all[k].subtree_nodes) out.push_back(all[k]);
  } else {
    for (uint32_t child = parent.index + 1; child < parent.index + parent.subtree_nodes;) {
      TESSERA_ASSIGN_OR_RETURN(SceneNode n, node(child));
      out.push_back(n);
      child += n.subtree_nodes;
    }
  }
  if (out.size() != parent.child_count)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: node {} records {} children, has {}", impl_->name, parent.index,
                            parent.child_count, out.size()));
  return out;
}

Result<std::vector<SceneTexture>> SceneArchive::textures(uint32_t first, uint32_t count) const {
  const SceneDirectory& d = impl_->directory;
  if (first > d.texture_count || count > d.texture_count - first)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: textures [{}, +{}) outside the {} textures", impl_->name, first,
                            count, d.texture_count));
  std::vector<SceneTexture> out;
  {
    std::lock_guard lock(impl_->texture_mutex);
    for (uint32_t k = 0; k < count; ++k) {
      auto it = impl_->texture_cache.find(first + k);
      if (it == impl_->texture_cache.end()) break;
      out.push_back(toTexture(it->second, first + k));
    }
    if (out.size() == count) return out;
    out.clear();
  }
  std::vector<uint8_t> bytes;
  if (first == 0 && count == d.texture_count) {
    TESSERA_ASSIGN_OR_RETURN(bytes, impl_->readVerified(d.texture_table, "texture table"));
  } else {
    TESSERA_ASSIGN_OR_RETURN(bytes, impl_->readRange(d.texture_table.offset_bytes +
                                                         uint64_t(first) * kTextureRecordBytes,
                                                     uint64_t(count) * kTextureRecordBytes));
  }
  TESSERA_ASSIGN_OR_RETURN(std::vector<TextureRecord> records,
                           decodeTextureRecords(bytes, first, d, impl_->header, impl_->name));
  std::lock_guard lock(impl_->texture_mutex);
  if (impl_->texture_cache.size() + records.size() > kMaxCachedRecords)
    impl_->texture_cache.clear();
  for (uint32_t k = 0; k < records.size(); ++k) {
    if (records.size() <= kMaxCachedRecords) impl_->texture_cache.emplace(first + k, records[k]);
    out.push_back(toTexture(records[k], first + k));
  }
  return out;
}

Result<NodeContents> SceneArchive::readNode(const SceneNode& node) const {
  TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> block,
                           impl_->readRange(node.own.offset_bytes, node.own.length_bytes));
  return parseNode(node, block);
}

Result<NodeContents> SceneArchive::parseNode(const SceneNode& node, std::span<const uint8_t> block,
                                             bool with_textures) const {
  TESSERA_ASSIGN_OR_RETURN(NodeRecord record, impl_->record(node.index));
  const std::string what = fmt::format("{}: node {}", impl_->name, node.index);
  if (block.size() < record.head_bytes || block.size() > record.own_bytes)
    return fail(ErrorCode::kInvalidArgument, fmt::format("{}: {} bytes given, the block has {}",
                                                         what, block.size(), record.own_bytes));
  std::span<const uint8_t> head_bytes = block.first(record.head_bytes);
  if (checksum64(head_bytes) != record.head_checksum)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: head checksum mismatch at offset {}", what, record.offset_bytes));
  TESSERA_ASSIGN_OR_RETURN(
      NodeHead head,
      decodeNodeHead(head_bytes, record, node.index, impl_->directory, impl_->header, impl_->name));
  NodeContents out;
  for (uint32_t k = 0; k < head.objects.size(); ++k) {
    const ObjectRecord& o = head.objects[k];
    out.objects.push_back({record.first_object + k, toBox(o.bounds), o.transform, o.mesh,
                           o.mesh_node, o.textures, o.base_color_rgba, o.source_index});
  }
  for (const MeshRecord& m : head.meshes) {
    out.meshes.push_back({m.mesh, m.vertex_count, m.index_count, (m.attributes & kMeshNormals) != 0,
                          (m.attributes & kMeshUv0) != 0, GeometryCodec(m.codec),
                          FileRange{m.blob.offset_bytes, m.blob.length_bytes}, m.blob.checksum,
                          m.vertex_part_bytes});
  }
  if (!with_textures) return out;
  for (const NodeTextureRecord& t : head.textures) {
    const std::string texture_what = fmt::format("{} texture {}", what, t.texture);
    // A prefix of the block (a reader that skipped the payloads) must still hold the pages.
    if (t.pages.offset_bytes - record.offset_bytes + t.pages.length_bytes > block.size())
      return fail(
          ErrorCode::kInvalidArgument,
          fmt::format("{}: directory pages [{}, +{}) lie outside the {} bytes given", texture_what,
                      t.pages.offset_bytes, t.pages.length_bytes, block.size()));
    std::span<const uint8_t> pages =
        block.subspan(t.pages.offset_bytes - record.offset_bytes, t.pages.length_bytes);
    if (checksum64(pages) != t.pages.checksum)
      return fail(ErrorCode::kCorrupt, fmt::format("{}: directory pages checksum mismatch at "
                                                   "offset {}",
                                                   texture_what, t.pages.offset_bytes));
    NodeTexture texture{t.texture, t.info, {}};
    size_t pos = 0;
    for (uint32_t level = 0; level < t.info.level_count; ++level) {
      const size_t bytes = size_t(t.info.tilesX(level)) * t.info.tilesY(level) * kTileEntryBytes;
      TESSERA_ASSIGN_OR_RETURN(std::vector<TileEntry> entries,
                               decodeTileEntries(pages.subspan(pos, bytes), t.info, impl_->header,
                                                 fmt::format("{} level {}", texture_what, level)));
      texture.levels.push_back(std::move(entries));
      pos += bytes;
    }
    TESSERA_TRY(impl_->checkTileEntries(record, t, texture.levels));
    out.textures.push_back(std::move(texture));
  }
  return out;
}

Result<MeshData> SceneArchive::decodeMesh(const SceneMesh& mesh,
                                          std::span<const uint8_t> blob) const {
  const std::string what = fmt::format("{}: mesh {}", impl_->name, mesh.index);
  if (blob.size() != mesh.blob.length_bytes || checksum64(blob) != mesh.blob_checksum)
    return fail(ErrorCode::kCorrupt, fmt::format("{}: geometry checksum mismatch at offset {}",
                                                 what, mesh.blob.offset_bytes));
  MeshRecord record;
  record.mesh = mesh.index;
  record.vertex_count = mesh.vertex_count;
  record.index_count = mesh.index_count;
  record.attributes =
      uint8_t((mesh.has_normals ? kMeshNormals : 0) | (mesh.has_uv0 ? kMeshUv0 : 0));
  record.codec = GeometryCodecId(mesh.codec);
  record.vertex_part_bytes = mesh.vertex_part_bytes;
  return decodeMeshBlob(record, blob, what);
}

Result<MeshData> SceneArchive::readMesh(const SceneMesh& mesh) const {
  TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> blob,
                           impl_->readRange(mesh.blob.offset_bytes, mesh.blob.length_bytes));
  return decodeMesh(mesh, blob);
}

Result<Image> SceneArchive::decodeTile(uint32_t texture, const ImageInfo& info, uint32_t level,
                                       uint32_t x, uint32_t y, const TileEntry& entry,
                                       std::span<const uint8_t> payload,
                                       CodecScratch* scratch) const {
  const std::string what =
      fmt::format("{}: texture {} tile ({},{},{})", impl_->name, texture, level, x, y);
  Image out(info.storedTileSidePx(), info.storedTileSidePx(), info.channels);
  switch (entry.kind) {
    case TileKind::kEmpty: return out;
    case TileKind::kUniform:
      for (size_t i = 0; i < out.texels.size(); ++i)
        out.texels[i] = uint8_t(entry.uniform_rgba >> (8 * (i % info.channels)));
      return out;
    case TileKind::kEncoded: break;
    default: return fail(ErrorCode::kUnsupported, what + ": tile kind not supported");
  }
  if (payload.size() != entry.length_bytes || checksum64(payload) != entry.checksum)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: checksum mismatch at offset {}", what, entry.offset_bytes));
  if (codecNeedsParent(entry.codec))
    return fail(ErrorCode::kUnsupported,
                fmt::format("{}: codec {} is not used in scenes", what, codecName(entry.codec)));
  Result<void> decoded = detail::decodeTile(entry.codec, payload, out, nullptr, scratch);
  if (!decoded) return fail(decoded.error().code, what + ": " + decoded.error().message);
  return out;
}

Result<Image> SceneArchive::readCoarsest(const SceneTexture& texture, CodecScratch* scratch) const {
  const TileEntry& entry = texture.coarsest;
  std::vector<uint8_t> payload;
  if (entry.kind == TileKind::kEncoded) {
    TESSERA_ASSIGN_OR_RETURN(payload, impl_->readRange(entry.offset_bytes, entry.length_bytes));
  }
  return decodeTile(texture.index, texture.info, texture.info.level_count - 1, 0, 0, entry, payload,
                    scratch);
}

}  // namespace tessera
