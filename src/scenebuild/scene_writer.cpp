#include "scene_writer.h"

#include <algorithm>
#include <cstring>

#include <fmt/format.h>

#include "format/checksum.h"
#include "format/coverage_hints.h"
#include "format/directory.h"
#include "format/header.h"
#include "format/sections.h"
#include "geometry_encode.h"
#include "output/file_appender.h"

namespace tessera::detail {

namespace {

struct LayoutState {
  const SceneLayoutInput& in;
  const TempFile& out;
  FileAppender appender;
  /// Final tile entries per texture, payload offsets in the output.
  std::vector<std::vector<std::vector<TileEntry>>> entries;
  std::vector<NodeRecord> nodes;
  std::vector<uint32_t> final_mesh;     ///< imported mesh -> final
  std::vector<uint32_t> final_texture;  ///< imported texture -> final
  std::vector<uint8_t> payload;         ///< copy buffer
  SceneLayoutResult result;
};

Result<uint64_t> copyFromSpool(LayoutState& s, const TileEntry& entry) {
  TESSERA_CHECK(entry.offset_bytes + entry.length_bytes <= s.in.spool_bytes)
      << "spool entry past the spool end";
  s.payload.resize(entry.length_bytes);
  TESSERA_TRY(s.in.spool->pread(entry.offset_bytes, s.payload));
  return s.appender.append(s.payload);
}

// Every texture's coarsest tile, in texture order: one read gives a reader all of them.
Result<BlockRef> writeCoarseBlock(LayoutState& s) {
  BlockRef block;
  block.offset_bytes = s.appender.end();
  uint64_t coarse_bytes = 0;
  std::vector<uint8_t> all;  // the coarse block is small: one tile per texture
  for (size_t t = 0; t < s.entries.size(); ++t) {
    TileEntry& entry = s.entries[t].back()[0];
    if (entry.kind != TileKind::kEncoded) continue;
    TESSERA_ASSIGN_OR_RETURN(entry.offset_bytes, copyFromSpool(s, entry));
    all.insert(all.end(), s.payload.begin(), s.payload.end());
    coarse_bytes += entry.length_bytes;
  }
  block.length_bytes = coarse_bytes;
  block.checksum = coarse_bytes ? checksum64(all) : 0;
  if (coarse_bytes == 0) block.offset_bytes = 0;
  s.result.coarse_bytes = coarse_bytes;
  return block;
}

Result<void> writeNode(LayoutState& s, uint32_t index) {
  NodeRecord& record = s.nodes[index];
  NodeHead head;
  for (uint32_t k = 0; k < record.object_count; ++k) {
    const ImportedObject& o = s.in.scene->objects[s.in.object_order[record.first_object + k]];
    ObjectRecord r;
    r.bounds = o.bounds;
    r.transform = o.transform;
    r.mesh = s.final_mesh[o.mesh];
    r.mesh_node = s.in.mesh_node[r.mesh];
    for (uint32_t slot = 0; slot < kSceneTextureSlots; ++slot)
      r.textures[slot] =
          o.textures[slot] == kNoSceneTexture ? kNoSceneTexture : s.final_texture[o.textures[slot]];
    r.base_color_rgba = o.base_color_rgba;
    r.source_index = s.in.object_order[record.first_object + k];
    head.objects.push_back(r);
  }
  uint64_t pages_bytes = 0;
  for (uint32_t k = 0; k < record.texture_count; ++k)
    pages_bytes += texturePagesBytes(s.in.textures[record.first_texture + k].info);
  record.head_bytes =
      uint32_t(nodeHeadBytes(record.object_count, record.mesh_count, record.texture_count));
  TESSERA_ASSIGN_OR_RETURN(record.offset_bytes, s.appender.skip(record.head_bytes + pages_bytes));

  for (uint32_t k = 0; k < record.mesh_count; ++k) {
    const uint32_t mesh = record.first_mesh + k;
    EncodedMesh encoded =
        encodeMesh(s.in.scene->meshes[s.in.mesh_order[mesh]], s.in.geometry_codec);
    MeshRecord m;
    m.mesh = mesh;
    m.vertex_count = s.in.scene->meshes[s.in.mesh_order[mesh]].vertexCount();
    m.index_count = uint32_t(s.in.scene->meshes[s.in.mesh_order[mesh]].indices.size());
    m.attributes = encoded.attributes;
    m.codec = s.in.geometry_codec;
    m.vertex_part_bytes = encoded.vertex_part_bytes;
    TESSERA_ASSIGN_OR_RETURN(m.blob.offset_bytes, s.appender.append(encoded.blob));
    m.blob.length_bytes = encoded.blob.size();
    m.blob.checksum = checksum64(encoded.blob);
    s.result.geometry_raw_bytes += encoded.raw_bytes;
    s.result.geometry_stored_bytes += encoded.blob.size();
    head.meshes.push_back(m);
  }

  // Texture levels coarse to fine across the node's textures: a prefix of the body holds the
  // geometry and every texture down to some level (the coarsest is in the coarse block).
  uint32_t max_levels = 0;
  for (uint32_t k = 0; k < record.texture_count; ++k)
    max_levels = std::max(max_levels, s.in.textures[record.first_texture + k].info.level_count);
  for (uint32_t level = max_levels; level-- > 0;) {
    for (uint32_t k = 0; k < record.texture_count; ++k) {
      auto& levels = s.entries[record.first_texture + k];
      if (level + 1 >= levels.size()) continue;
      for (TileEntry& entry : levels[level]) {
        if (entry.kind != TileKind::kEncoded) continue;
        TESSERA_ASSIGN_OR_RETURN(entry.offset_bytes, copyFromSpool(s, entry));
        s.result.texture_payload_bytes += entry.length_bytes;
      }
    }
  }

  // Head and pages into the hole left for them.
  std::vector<uint8_t> pages;
  uint64_t pages_offset = record.offset_bytes + record.head_bytes;
  for (uint32_t k = 0; k < record.texture_count; ++k) {
    const uint32_t texture = record.first_texture + k;
    std::vector<uint8_t> bytes;
    for (const auto& level : s.entries[texture]) {
      std::vector<uint8_t> page = encodeTileEntries(level);
      bytes.insert(bytes.end(), page.begin(), page.end());
    }
    NodeTextureRecord t;
    t.texture = texture;
    t.info = s.in.textures[texture].info;
    t.pages = {pages_offset + pages.size(), bytes.size(), checksum64(bytes)};
    pages.insert(pages.end(), bytes.begin(), bytes.end());
    head.textures.push_back(t);
  }
  std::vector<uint8_t> head_bytes = encodeNodeHead(head);
  TESSERA_CHECK(head_bytes.size() == record.head_bytes && pages.size() == pages_bytes)
      << "node head or pages size changed";
  record.head_checksum = checksum64(head_bytes);
  TESSERA_TRY(s.out.pwrite(record.offset_bytes, head_bytes));
  if (!pages.empty()) TESSERA_TRY(s.out.pwrite(pages_offset, pages));
  record.own_bytes = s.appender.end() - record.offset_bytes;
  return {};
}

// Numbering of items per node (pre-order), from the holders.
void numberNodes(LayoutState& s) {
  const SceneTree& tree = *s.in.tree;
  s.nodes.resize(tree.nodes.size());
  uint32_t object = 0, texture = 0, mesh = 0;
  for (uint32_t i = 0; i < tree.nodes.size(); ++i) {
    NodeRecord& r = s.nodes[i];
    const TreeNode& n = tree.nodes[i];
    r.bounds = n.bounds;
    r.subtree_nodes = n.subtree_nodes;
    r.child_count = uint16_t(n.children.size());
    r.depth = uint8_t(n.depth);
    r.first_object = object;
    r.object_count = uint32_t(n.objects.size());
    object += r.object_count;
    r.first_texture = texture;
    while (texture < s.in.texture_node.size() && s.in.texture_node[texture] == i) ++texture;
    r.texture_count = texture - r.first_texture;
    r.first_mesh = mesh;
    while (mesh < s.in.mesh_node.size() && s.in.mesh_node[mesh] == i) ++mesh;
    r.mesh_count = mesh - r.first_mesh;
  }
}

struct PlacedBlock {
  BlockRef ref;
  std::vector<uint8_t> bytes;
};

PlacedBlock makeBlock(std::vector<uint8_t> bytes) {
  PlacedBlock block;
  block.ref.length_bytes = bytes.size();
  block.ref.checksum = bytes.empty() ? 0 : checksum64(bytes);
  block.bytes = std::move(bytes);
  return block;
}

// The 1.0 structures that make the textures ordinary images: one page index per level (one
// page each) and the root directory.
std::vector<ImageRecord> imageRecords(LayoutState& s, std::vector<PlacedBlock>& page_indexes) {
  std::vector<ImageRecord> records;
  for (size_t t = 0; t < s.entries.size(); ++t) {
    ImageRecord record;
    record.info = s.in.textures[t].info;
    const NodeRecord& node = s.nodes[s.in.texture_node[t]];
    // Pages of texture t sit in its node's block, in texture order, level 0 first.
    uint64_t offset = node.offset_bytes + node.head_bytes;
    for (uint32_t k = node.first_texture; k < t; ++k)
      offset += texturePagesBytes(s.in.textures[k].info);
    for (const auto& level : s.entries[t]) {
      std::vector<uint8_t> page = encodeTileEntries(level);
      PageRef ref{offset, page.size(), checksum64(page)};
      offset += page.size();
      uint64_t payload = 0;
      bool any = false;
      for (const TileEntry& e : level) {
        payload += e.length_bytes;
        any |= e.kind != TileKind::kEmpty;
      }
      page_indexes.push_back(makeBlock(any ? encodePageIndex({&ref, 1}) : std::vector<uint8_t>{}));
      record.levels.push_back({{}, payload});
    }
    records.push_back(std::move(record));
  }
  return records;
}

}  // namespace

Result<SceneLayoutResult> writeSceneArchive(const SceneLayoutInput& in, const TempFile& out) {
  const std::string& name = out.finalPath();
  LayoutState s{in, out, FileAppender(out, kHeaderRegionBytes), {}, {}, {}, {}, {}, {}};
  s.final_mesh.assign(in.scene->meshes.size(), kNoNode);
  for (uint32_t m = 0; m < in.mesh_order.size(); ++m) s.final_mesh[in.mesh_order[m]] = m;
  s.final_texture.assign(in.scene->textures.size(), kNoSceneTexture);
  for (uint32_t t = 0; t < in.texture_order.size(); ++t) s.final_texture[in.texture_order[t]] = t;
  for (const SpooledTexture& t : in.textures) s.entries.push_back(t.entries);
  numberNodes(s);

  TESSERA_ASSIGN_OR_RETURN(BlockRef coarse, writeCoarseBlock(s));
  for (uint32_t i = 0; i < s.nodes.size(); ++i) TESSERA_TRY(writeNode(s, i));
  const uint64_t nodes_end = s.appender.end();
  for (uint32_t i = 0; i < s.nodes.size(); ++i) {
    const uint32_t after = i + s.nodes[i].subtree_nodes;
    const uint64_t end = after < s.nodes.size() ? s.nodes[after].offset_bytes : nodes_end;
    s.nodes[i].subtree_bytes = end - s.nodes[i].offset_bytes;
  }

  std::vector<TextureRecord> texture_records;
  for (uint32_t t = 0; t < s.entries.size(); ++t)
    texture_records.push_back(
        {t, in.texture_node[t], in.texture_users[t], in.textures[t].info, s.entries[t].back()[0]});
  std::vector<PlacedBlock> page_indexes;
  std::vector<ImageRecord> records = imageRecords(s, page_indexes);

  SceneDirectory directory;
  directory.node_count = uint32_t(s.nodes.size());
  directory.object_count = uint32_t(in.object_order.size());
  directory.mesh_count = uint32_t(in.mesh_order.size());
  directory.texture_count = uint32_t(s.entries.size());
  directory.tree_depth = uint16_t(in.tree->depth);
  directory.max_children = uint16_t(in.max_children);
  directory.leaf_capacity = uint16_t(in.leaf_capacity);
  directory.bounds = s.nodes[0].bounds;
  directory.coarse = coarse;

  // Tables and 1.0 structures: into the header region while they fit, else appended.
  std::vector<uint8_t> region(kHeaderRegionBytes, 0);
  uint64_t region_used = kHeaderBytes;
  auto place = [&](PlacedBlock& block) -> Result<void> {
    if (block.bytes.empty()) return {};
    if (region_used + block.bytes.size() <= kHeaderRegionBytes) {
      block.ref.offset_bytes = region_used;
      std::memcpy(region.data() + region_used, block.bytes.data(), block.bytes.size());
      region_used += block.bytes.size();
      return {};
    }
    TESSERA_ASSIGN_OR_RETURN(block.ref.offset_bytes, s.appender.append(block.bytes));
    return {};
  };
  // The scene directory and the section table that points at it (and at the hints) have
  // fixed sizes: reserve them first so they are always in the region (one read opens a scene).
  const uint64_t scene_offset = region_used;
  region_used += kSceneDirectoryBytes;
  const uint64_t sections_offset = region_used;
  const uint32_t section_count = in.hints ? 2 : 1;
  region_used += uint64_t(section_count) * kSectionEntryBytes;
  PlacedBlock node_table = makeBlock(encodeNodeRecords(s.nodes));
  PlacedBlock texture_table = makeBlock(encodeTextureRecords(texture_records));
  TESSERA_TRY(place(node_table));
  TESSERA_TRY(place(texture_table));
  for (PlacedBlock& block : page_indexes) TESSERA_TRY(place(block));
  size_t next_index = 0;
  for (ImageRecord& record : records)
    for (LevelRecord& level : record.levels) level.page_index = page_indexes[next_index++].ref;
  PlacedBlock root = makeBlock(encodeRootDirectory(records));
  TESSERA_TRY(place(root));
  nlohmann::json metadata_json = in.metadata;
  metadata_json["scene"]["bytes"] = {
      {"textures", s.result.texture_payload_bytes + s.result.coarse_bytes},
      {"coarse_block", s.result.coarse_bytes},
      {"geometry", s.result.geometry_stored_bytes},
      {"geometry_raw", s.result.geometry_raw_bytes}};
  const std::string metadata_text = metadata_json.dump();
  if (metadata_text.size() > kMaxMetadataBytes)
    return fail(ErrorCode::kTooLarge, name + ": metadata exceeds 16 MiB");
  PlacedBlock metadata = makeBlock({metadata_text.begin(), metadata_text.end()});
  TESSERA_TRY(place(metadata));
  // The hints last: the runtime reads them once at open, the tables come first in the region.
  PlacedBlock hints;
  if (in.hints) {
    hints = makeBlock(encodeCoverageHints(*in.hints));
    s.result.hint_bytes = hints.bytes.size();
    TESSERA_TRY(place(hints));
  }
  TESSERA_TRY(s.appender.flush());

  directory.node_table = node_table.ref;
  directory.texture_table = texture_table.ref;
  std::vector<uint8_t> directory_bytes = encodeSceneDirectory(directory);
  std::memcpy(region.data() + scene_offset, directory_bytes.data(), directory_bytes.size());
  const BlockRef scene{scene_offset, directory_bytes.size(), checksum64(directory_bytes)};
  std::vector<SectionEntry> sections = {{uint32_t(SectionKind::kScene), scene}};
  if (in.hints) sections.push_back({uint32_t(SectionKind::kCoverageHints), hints.ref});
  const std::vector<uint8_t> table_bytes = encodeSectionTable(sections);
  std::memcpy(region.data() + sections_offset, table_bytes.data(), table_bytes.size());
  const BlockRef table{sections_offset, table_bytes.size(), checksum64(table_bytes)};

  FileHeader header;
  header.version_minor = kSceneVersionMinor;
  header.file_bytes = std::max<uint64_t>(s.appender.end(), kHeaderRegionBytes);
  header.image_count = uint32_t(records.size());
  header.root = root.ref;
  header.metadata = metadata.ref;
  // The region without the header first, the header last (the commit marker).
  TESSERA_TRY(out.pwrite(kHeaderBytes, std::span(region).subspan(kHeaderBytes)));
  std::vector<uint8_t> header_bytes = encodeHeader(header);
  stampSectionTableRef(header_bytes, table);
  TESSERA_TRY(out.pwrite(0, header_bytes));
  s.result.file_bytes = header.file_bytes;
  return s.result;
}

}  // namespace tessera::detail
