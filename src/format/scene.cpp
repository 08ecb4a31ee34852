#include "format/scene.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>

#include <fmt/format.h>

#include "format/byte_io.h"
#include "format/checksum.h"
#include "format/directory.h"

namespace tessera::detail {

namespace {

void storeBox(uint8_t* p, const SceneBox& box) {
  for (int a = 0; a < 3; ++a) {
    storeF32(p + 4 * a, box.min[a]);
    storeF32(p + 12 + 4 * a, box.max[a]);
  }
}
SceneBox loadBox(const uint8_t* p) {
  SceneBox box;
  for (int a = 0; a < 3; ++a) {
    box.min[a] = loadF32(p + 4 * a);
    box.max[a] = loadF32(p + 12 + 4 * a);
  }
  return box;
}

Result<void> checkBox(const SceneBox& box, const std::string& what) {
  for (int a = 0; a < 3; ++a) {
    if (!std::isfinite(box.min[a]) || !std::isfinite(box.max[a]) || box.min[a] > box.max[a])
      return fail(ErrorCode::kCorrupt, what + ": bounds not finite or min above max");
  }
  return {};
}

// A block that must lie inside [begin, end) (a node's body), or be absent.
Result<void> checkInside(const BlockRef& block, uint64_t begin, uint64_t end,
                         const std::string& what) {
  if (block.length_bytes == 0) {
    if (block.offset_bytes != 0 || block.checksum != 0)
      return fail(ErrorCode::kCorrupt, what + ": empty block with non-zero offset or checksum");
    return {};
  }
  if (block.offset_bytes < begin || block.offset_bytes > end ||
      block.length_bytes > end - block.offset_bytes)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: block [{}, +{}) outside its node's body [{}, {})", what,
                            block.offset_bytes, block.length_bytes, begin, end));
  return {};
}

Result<void> checkRange(uint32_t first, uint32_t count, uint32_t total, const std::string& what) {
  if (first > total || count > total - first)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: range [{}, +{}) outside 0..{}", what, first, count, total));
  return {};
}

void storeImageInfo(uint8_t* p, const ImageInfo& info) {
  storeU32(p, info.width_px);
  storeU32(p + 4, info.height_px);
  p[8] = uint8_t(info.channels);
  p[9] = uint8_t(std::countr_zero(info.tile_size_px));
  p[10] = uint8_t(info.border_px);
  p[11] = uint8_t(info.level_count);
  p[12] = uint8_t(info.default_codec);
  p[13] = uint8_t(info.page_tiles_log2);
  p[14] = info.srgb_downsample ? 1 : 0;
}

// The 16-byte geometry shared by texture records and node texture records: the image record's
// fields (docs/format.md, "Root directory") with the level count checked against the size and
// every level on one directory page.
Result<ImageInfo> loadImageInfo(const uint8_t* p, bool known_minor, const std::string& what) {
  if (known_minor && (p[15] || (p[14] & ~1u)))
    return fail(ErrorCode::kCorrupt, what + ": reserved fields are not zero");
  ImageInfo info;
  info.width_px = loadU32(p);
  info.height_px = loadU32(p + 4);
  info.channels = p[8];
  if (p[9] > 11)
    return fail(ErrorCode::kCorrupt, fmt::format("{}: tile size 2^{} out of bounds", what, p[9]));
  info.tile_size_px = 1u << p[9];
  info.border_px = p[10];
  info.level_count = p[11];
  info.default_codec = Codec(p[12]);
  info.page_tiles_log2 = p[13];
  info.srgb_downsample = p[14] & 1;
  TESSERA_TRY(validateImageInfo(info, what));
  if (info.level_count != levelCountFor(info.width_px, info.height_px, info.tile_size_px))
    return fail(ErrorCode::kCorrupt, what + ": level count does not match the geometry");
  if (!fitsOnePagePerLevel(info))
    return fail(ErrorCode::kCorrupt, what + ": a level needs more than one directory page");
  return info;
}

}  // namespace

bool operator==(const TextureRecord& a, const TextureRecord& b) {
  auto entry_equal = [](const TileEntry& x, const TileEntry& y) {
    return x.kind == y.kind && x.codec == y.codec && x.offset_bytes == y.offset_bytes &&
           x.length_bytes == y.length_bytes && x.checksum == y.checksum &&
           x.uniform_rgba == y.uniform_rgba;
  };
  const ImageInfo &p = a.info, &q = b.info;
  return a.image == b.image && a.node == b.node && a.users == b.users && p.width_px == q.width_px &&
         p.height_px == q.height_px && p.channels == q.channels &&
         p.tile_size_px == q.tile_size_px && p.border_px == q.border_px &&
         p.level_count == q.level_count && p.page_tiles_log2 == q.page_tiles_log2 &&
         p.default_codec == q.default_codec && p.srgb_downsample == q.srgb_downsample &&
         entry_equal(a.coarsest, b.coarsest);
}

Result<BlockRef> decodeSceneRef(std::span<const SectionEntry> sections, const std::string& name) {
  const BlockRef scene = findSection(sections, SectionKind::kScene);
  if (scene.length_bytes != 0 && scene.length_bytes != kSceneDirectoryBytes)
    return fail(ErrorCode::kCorrupt, fmt::format("{}: scene directory of {} bytes, expected {}",
                                                 name, scene.length_bytes, kSceneDirectoryBytes));
  return scene;
}

std::vector<uint8_t> encodeSceneDirectory(const SceneDirectory& d) {
  std::vector<uint8_t> bytes(kSceneDirectoryBytes, 0);
  uint8_t* p = bytes.data();
  storeU32(p, d.node_count);
  storeU32(p + 4, d.object_count);
  storeU32(p + 8, d.mesh_count);
  storeU32(p + 12, d.texture_count);
  storeU16(p + 16, d.tree_depth);
  storeU16(p + 18, d.max_children);
  storeU16(p + 20, d.leaf_capacity);
  storeBox(p + 24, d.bounds);
  storeBlockRef(p + 48, d.node_table);
  storeBlockRef(p + 72, d.texture_table);
  storeBlockRef(p + 96, d.coarse);
  return bytes;
}

Result<SceneDirectory> decodeSceneDirectory(std::span<const uint8_t> bytes,
                                            const FileHeader& header, const std::string& name) {
  const std::string what = name + ": scene directory";
  if (bytes.size() != kSceneDirectoryBytes)
    return fail(ErrorCode::kCorrupt, fmt::format("{} of {} bytes, expected {}", what, bytes.size(),
                                                 kSceneDirectoryBytes));
  const uint8_t* p = bytes.data();
  SceneDirectory d;
  d.node_count = loadU32(p);
  d.object_count = loadU32(p + 4);
  d.mesh_count = loadU32(p + 8);
  d.texture_count = loadU32(p + 12);
  d.tree_depth = loadU16(p + 16);
  d.max_children = loadU16(p + 18);
  d.leaf_capacity = loadU16(p + 20);
  d.bounds = loadBox(p + 24);
  d.node_table = loadBlockRef(p + 48);
  d.texture_table = loadBlockRef(p + 72);
  d.coarse = loadBlockRef(p + 96);
  if (header.version_minor == kSceneVersionMinor && (p[22] || p[23] || !allZero(p + 120, 8)))
    return fail(ErrorCode::kCorrupt, what + ": reserved fields are not zero");
  if (d.node_count == 0 || d.node_count > kMaxSceneNodes)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: node count {} out of 1..{}", what, d.node_count, kMaxSceneNodes));
  if (d.object_count > kMaxSceneObjects || d.mesh_count > kMaxSceneMeshes ||
      d.texture_count > kMaxImages)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: {} objects, {} meshes or {} textures over the bounds", what,
                            d.object_count, d.mesh_count, d.texture_count));
  if (d.tree_depth == 0 || d.tree_depth > kMaxSceneDepth || d.tree_depth > d.node_count)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: tree depth {} out of bounds", what, d.tree_depth));
  if (d.max_children < 2 || d.max_children > 256 || d.leaf_capacity == 0)
    return fail(ErrorCode::kCorrupt, fmt::format("{}: fan-out {} or leaf capacity {} out of bounds",
                                                 what, d.max_children, d.leaf_capacity));
  TESSERA_TRY(checkBox(d.bounds, what));
  TESSERA_TRY(checkBlockInFile(d.node_table, header.file_bytes, what + " node table"));
  TESSERA_TRY(checkBlockInFile(d.texture_table, header.file_bytes, what + " texture table"));
  TESSERA_TRY(checkBlockInFile(d.coarse, header.file_bytes, what + " coarse block"));
  if (d.node_table.length_bytes != uint64_t(d.node_count) * kNodeRecordBytes)
    return fail(ErrorCode::kCorrupt, fmt::format("{}: node table of {} bytes for {} nodes", what,
                                                 d.node_table.length_bytes, d.node_count));
  if (d.texture_table.length_bytes != uint64_t(d.texture_count) * kTextureRecordBytes)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: texture table of {} bytes for {} textures", what,
                            d.texture_table.length_bytes, d.texture_count));
  return d;
}

std::vector<uint8_t> encodeNodeRecords(std::span<const NodeRecord> nodes) {
  std::vector<uint8_t> bytes(nodes.size() * kNodeRecordBytes, 0);
  uint8_t* p = bytes.data();
  for (const NodeRecord& n : nodes) {
    storeBox(p, n.bounds);
    storeU32(p + 24, n.subtree_nodes);
    storeU16(p + 28, n.child_count);
    p[30] = n.depth;
    storeU32(p + 32, n.first_object);
    storeU32(p + 36, n.object_count);
    storeU32(p + 40, n.first_texture);
    storeU32(p + 44, n.texture_count);
    storeU32(p + 48, n.first_mesh);
    storeU32(p + 52, n.mesh_count);
    storeU64(p + 56, n.offset_bytes);
    storeU32(p + 64, n.head_bytes);
    storeU64(p + 72, n.head_checksum);
    storeU64(p + 80, n.own_bytes);
    storeU64(p + 88, n.subtree_bytes);
    p += kNodeRecordBytes;
  }
  return bytes;
}

Result<std::vector<NodeRecord>> decodeNodeRecords(std::span<const uint8_t> bytes,
                                                  uint32_t first_index,
                                                  const SceneDirectory& directory,
                                                  const FileHeader& header,
                                                  const std::string& name) {
  if (bytes.size() % kNodeRecordBytes != 0)
    return fail(
        ErrorCode::kCorrupt,
        fmt::format("{}: {} bytes is not a whole number of node records", name, bytes.size()));
  const uint64_t count = bytes.size() / kNodeRecordBytes;
  if (first_index > directory.node_count || count > directory.node_count - first_index)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: node records {}..{} past the {} nodes", name, first_index,
                            first_index + count, directory.node_count));
  std::vector<NodeRecord> nodes(count);
  for (uint64_t k = 0; k < count; ++k) {
    const uint8_t* p = bytes.data() + k * kNodeRecordBytes;
    const uint32_t index = uint32_t(first_index + k);
    const std::string what = fmt::format("{}: node {}", name, index);
    NodeRecord& n = nodes[k];
    n.bounds = loadBox(p);
    n.subtree_nodes = loadU32(p + 24);
    n.child_count = loadU16(p + 28);
    n.depth = p[30];
    n.first_object = loadU32(p + 32);
    n.object_count = loadU32(p + 36);
    n.first_texture = loadU32(p + 40);
    n.texture_count = loadU32(p + 44);
    n.first_mesh = loadU32(p + 48);
    n.mesh_count = loadU32(p + 52);
    n.offset_bytes = loadU64(p + 56);
    n.head_bytes = loadU32(p + 64);
    n.head_checksum = loadU64(p + 72);
    n.own_bytes = loadU64(p + 80);
    n.subtree_bytes = loadU64(p + 88);
    if (header.version_minor == kSceneVersionMinor && (p[31] || !allZero(p + 68, 4)))
      return fail(ErrorCode::kCorrupt, what + ": reserved fields are not zero");
    TESSERA_TRY(checkBox(n.bounds, what));
    if (n.subtree_nodes == 0 || n.subtree_nodes > directory.node_count - index)
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: subtree of {} nodes out of bounds", what, n.subtree_nodes));
    if (n.child_count > directory.max_children || n.child_count >= n.subtree_nodes ||
        (n.child_count == 0) != (n.subtree_nodes == 1))
      return fail(ErrorCode::kCorrupt, fmt::format("{}: {} children for a subtree of {} nodes",
                                                   what, n.child_count, n.subtree_nodes));
    if (n.depth >= directory.tree_depth)
      return fail(ErrorCode::kCorrupt, fmt::format("{}: depth {} not below the tree depth {}", what,
                                                   n.depth, directory.tree_depth));
    if (n.object_count > 0 && n.child_count > 0)
      return fail(ErrorCode::kCorrupt, what + ": an inner node holds objects");
    if (n.object_count > directory.leaf_capacity)
      return fail(ErrorCode::kCorrupt, fmt::format("{}: {} objects over the leaf capacity {}", what,
                                                   n.object_count, directory.leaf_capacity));
    TESSERA_TRY(
        checkRange(n.first_object, n.object_count, directory.object_count, what + " objects"));
    TESSERA_TRY(
        checkRange(n.first_texture, n.texture_count, directory.texture_count, what + " textures"));
    TESSERA_TRY(checkRange(n.first_mesh, n.mesh_count, directory.mesh_count, what + " meshes"));
    if (n.object_count > kMaxNodeItems || n.mesh_count > kMaxNodeItems ||
        n.texture_count > kMaxNodeItems)
      return fail(ErrorCode::kCorrupt, what + ": more items than a node may hold");
    if (n.head_bytes != nodeHeadBytes(n.object_count, n.mesh_count, n.texture_count))
      return fail(
          ErrorCode::kCorrupt,
          fmt::format("{}: head of {} bytes does not match its item counts", what, n.head_bytes));
    if (n.head_bytes > n.own_bytes || n.own_bytes > n.subtree_bytes ||
        (n.child_count == 0 && n.own_bytes != n.subtree_bytes))
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: head {}, own {} and subtree {} bytes are inconsistent", what,
                              n.head_bytes, n.own_bytes, n.subtree_bytes));
    if (n.offset_bytes < header.header_region_bytes || n.offset_bytes > header.file_bytes ||
        n.subtree_bytes > header.file_bytes - n.offset_bytes)
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: subtree range [{}, +{}) outside the payload area", what,
                              n.offset_bytes, n.subtree_bytes));
  }
  return nodes;
}

Result<void> validateNodeTable(std::span<const NodeRecord> nodes, const SceneDirectory& directory,
                               const std::string& name) {
  if (nodes.size() != directory.node_count)
    return fail(ErrorCode::kCorrupt, fmt::format("{}: {} node records for {} nodes", name,
                                                 nodes.size(), directory.node_count));
  const NodeRecord& root = nodes[0];
  if (root.subtree_nodes != directory.node_count || root.depth != 0)
    return fail(ErrorCode::kCorrupt, name + ": node 0 is not the root of every node");
  uint32_t next_object = 0, next_texture = 0, next_mesh = 0, deepest = 0;
  for (uint32_t i = 0; i < nodes.size(); ++i) {
    const NodeRecord& n = nodes[i];
    const std::string what = fmt::format("{}: node {}", name, i);
    if (n.first_object != next_object || n.first_texture != next_texture ||
        n.first_mesh != next_mesh)
      return fail(ErrorCode::kCorrupt, what + ": items not numbered in depth-first order");
    next_object += n.object_count;
    next_texture += n.texture_count;
    next_mesh += n.mesh_count;
    deepest = std::max<uint32_t>(deepest, n.depth);
    // Children: i + 1, then each next sibling after the previous child's subtree.
    uint64_t child = i + 1;
    uint64_t expected_offset = n.offset_bytes + n.own_bytes;
    for (uint32_t c = 0; c < n.child_count; ++c) {
      if (child >= uint64_t(i) + n.subtree_nodes)
        return fail(ErrorCode::kCorrupt, what + ": children overrun its subtree");
      const NodeRecord& k = nodes[child];
      if (k.depth != n.depth + 1)
        return fail(ErrorCode::kCorrupt,
                    fmt::format("{}: child {} at depth {}", what, child, k.depth));
      if (!boxContains(n.bounds, k.bounds))
        return fail(ErrorCode::kCorrupt, fmt::format("{}: child {}'s box is outside", what, child));
      if (k.offset_bytes != expected_offset)
        return fail(ErrorCode::kCorrupt,
                    fmt::format("{}: child {}'s subtree starts at {}, expected {} (subtrees "
                                "must be contiguous, depth-first)",
                                what, child, k.offset_bytes, expected_offset));
      expected_offset += k.subtree_bytes;
      child += k.subtree_nodes;
    }
    if (child != uint64_t(i) + n.subtree_nodes)
      return fail(ErrorCode::kCorrupt, what + ": children do not fill its subtree");
    if (expected_offset != n.offset_bytes + n.subtree_bytes)
      return fail(ErrorCode::kCorrupt, what + ": subtree bytes are not its children's sum");
  }
  if (next_object != directory.object_count || next_texture != directory.texture_count ||
      next_mesh != directory.mesh_count)
    return fail(ErrorCode::kCorrupt, name + ": nodes do not hold every object, mesh and texture");
  if (deepest + 1 != directory.tree_depth)
    return fail(ErrorCode::kCorrupt, name + ": tree depth does not match the nodes");
  if (!boxContains(directory.bounds, root.bounds))
    return fail(ErrorCode::kCorrupt, name + ": root box outside the scene bounds");
  return {};
}

std::vector<uint8_t> encodeTextureRecords(std::span<const TextureRecord> textures) {
  std::vector<uint8_t> bytes(textures.size() * kTextureRecordBytes, 0);
  uint8_t* p = bytes.data();
  for (const TextureRecord& t : textures) {
    storeU32(p, t.image);
    storeU32(p + 4, t.node);
    storeU32(p + 8, t.users);
    storeImageInfo(p + 16, t.info);
    std::vector<uint8_t> entry = encodeTileEntries({&t.coarsest, 1});
    std::memcpy(p + 32, entry.data(), kTileEntryBytes);
    p += kTextureRecordBytes;
  }
  return bytes;
}

Result<std::vector<TextureRecord>> decodeTextureRecords(std::span<const uint8_t> bytes,
                                                        uint32_t first_index,
                                                        const SceneDirectory& directory,
                                                        const FileHeader& header,
                                                        const std::string& name) {
  if (bytes.size() % kTextureRecordBytes != 0)
    return fail(
        ErrorCode::kCorrupt,
        fmt::format("{}: {} bytes is not a whole number of texture records", name, bytes.size()));
  const uint64_t count = bytes.size() / kTextureRecordBytes;
  if (first_index > directory.texture_count || count > directory.texture_count - first_index)
    return fail(ErrorCode::kCorrupt, fmt::format("{}: texture records past the {} textures", name,
                                                 directory.texture_count));
  std::vector<TextureRecord> textures(count);
  for (uint64_t k = 0; k < count; ++k) {
    const uint8_t* p = bytes.data() + k * kTextureRecordBytes;
    const std::string what = fmt::format("{}: texture {}", name, first_index + k);
    TextureRecord& t = textures[k];
    t.image = loadU32(p);
    t.node = loadU32(p + 4);
    t.users = loadU32(p + 8);
    const bool known_minor = header.version_minor == kSceneVersionMinor;
    if (known_minor && (!allZero(p + 12, 4) || !allZero(p + 56, 8)))
      return fail(ErrorCode::kCorrupt, what + ": reserved fields are not zero");
    if (t.image >= header.image_count || t.node >= directory.node_count)
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: image {} or node {} out of range", what, t.image, t.node));
    TESSERA_ASSIGN_OR_RETURN(t.info, loadImageInfo(p + 16, known_minor, what));
    TESSERA_ASSIGN_OR_RETURN(
        std::vector<TileEntry> entry,
        decodeTileEntries({p + 32, kTileEntryBytes}, t.info, header, what + " coarsest tile"));
    t.coarsest = entry[0];
  }
  return textures;
}

uint64_t nodeHeadBytes(uint64_t objects, uint64_t meshes, uint64_t textures) {
  return kNodeHeadPrefixBytes + objects * kObjectRecordBytes + meshes * kMeshRecordBytes +
         textures * kNodeTextureRecordBytes;
}

std::vector<uint8_t> encodeNodeHead(const NodeHead& head) {
  std::vector<uint8_t> bytes(
      nodeHeadBytes(head.objects.size(), head.meshes.size(), head.textures.size()), 0);
  uint8_t* p = bytes.data();
  storeU32(p, uint32_t(head.objects.size()));
  storeU32(p + 4, uint32_t(head.meshes.size()));
  storeU32(p + 8, uint32_t(head.textures.size()));
  p += kNodeHeadPrefixBytes;
  for (const ObjectRecord& o : head.objects) {
    storeBox(p, o.bounds);
    for (int i = 0; i < 12; ++i) storeF32(p + 24 + 4 * i, o.transform[i]);
    storeU32(p + 72, o.mesh);
    storeU32(p + 76, o.mesh_node);
    for (uint32_t s = 0; s < kSceneTextureSlots; ++s) storeU32(p + 80 + 4 * s, o.textures[s]);
    storeU32(p + 100, o.base_color_rgba);
    storeU32(p + 104, o.source_index);
    p += kObjectRecordBytes;
  }
  for (const MeshRecord& m : head.meshes) {
    storeU32(p, m.mesh);
    storeU32(p + 4, m.vertex_count);
    storeU32(p + 8, m.index_count);
    p[12] = m.attributes;
    p[13] = uint8_t(m.codec);
    storeU32(p + 16, m.vertex_part_bytes);
    storeBlockRef(p + 24, m.blob);
    p += kMeshRecordBytes;
  }
  for (const NodeTextureRecord& t : head.textures) {
    storeU32(p, t.texture);
    storeBlockRef(p + 8, t.pages);
    storeImageInfo(p + 32, t.info);
    p += kNodeTextureRecordBytes;
  }
  return bytes;
}

namespace {

Result<ObjectRecord> decodeObject(const uint8_t* p, bool known_minor,
                                  const SceneDirectory& directory, const std::string& what) {
  ObjectRecord o;
  o.bounds = loadBox(p);
  TESSERA_TRY(checkBox(o.bounds, what));
  for (int i = 0; i < 12; ++i) {
    o.transform[i] = loadF32(p + 24 + 4 * i);
    if (!std::isfinite(o.transform[i]))
      return fail(ErrorCode::kCorrupt, what + ": transform is not finite");
  }
  o.mesh = loadU32(p + 72);
  o.mesh_node = loadU32(p + 76);
  for (uint32_t s = 0; s < kSceneTextureSlots; ++s) {
    o.textures[s] = loadU32(p + 80 + 4 * s);
    if (o.textures[s] != kNoSceneTexture && o.textures[s] >= directory.texture_count)
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: texture {} in slot {} out of range", what, o.textures[s], s));
  }
  o.base_color_rgba = loadU32(p + 100);
  o.source_index = loadU32(p + 104);
  if (known_minor && !allZero(p + 108, 20))
    return fail(ErrorCode::kCorrupt, what + ": reserved fields are not zero");
  if (o.mesh >= directory.mesh_count || o.mesh_node >= directory.node_count)
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: mesh {} or its node {} out of range", what, o.mesh, o.mesh_node));
  return o;
}

Result<MeshRecord> decodeMesh(const uint8_t* p, bool known_minor, uint64_t body_begin,
                              uint64_t body_end, const std::string& what) {
  MeshRecord m;
  m.mesh = loadU32(p);
  m.vertex_count = loadU32(p + 4);
  m.index_count = loadU32(p + 8);
  m.attributes = p[12];
  m.codec = GeometryCodecId(p[13]);
  m.vertex_part_bytes = loadU32(p + 16);
  m.blob = loadBlockRef(p + 24);
  if (known_minor && (p[14] || p[15] || !allZero(p + 20, 4) || !allZero(p + 48, 16)))
    return fail(ErrorCode::kCorrupt, what + ": reserved fields are not zero");
  if (m.attributes & ~uint8_t(kMeshNormals | kMeshUv0))
    return fail(ErrorCode::kCorrupt,
                fmt::format("{}: unknown attributes {:#x}", what, m.attributes));
  if (uint8_t(m.codec) > uint8_t(GeometryCodecId::kMeshopt))
    return fail(ErrorCode::kUnsupported,
                fmt::format("{}: geometry codec {} unknown", what, int(m.codec)));
  if (m.vertex_count == 0 || m.vertex_count > kMaxMeshVertices || m.index_count == 0 ||
      m.index_count > kMaxMeshIndices || m.index_count % 3 != 0)
    return fail(ErrorCode::kCorrupt, fmt::format("{}: {} vertices and {} indices out of bounds",
                                                 what, m.vertex_count, m.index_count));
  if (m.blob.length_bytes == 0 || m.vertex_part_bytes > m.blob.length_bytes)
    return fail(ErrorCode::kCorrupt, what + ": geometry blob missing or shorter than its parts");
  TESSERA_TRY(checkInside(m.blob, body_begin, body_end, what + " geometry"));
  return m;
}

}  // namespace

Result<NodeHead> decodeNodeHead(std::span<const uint8_t> bytes, const NodeRecord& node,
                                uint32_t node_index, const SceneDirectory& directory,
                                const FileHeader& header, const std::string& name) {
  const std::string what = fmt::format("{}: node {}", name, node_index);
  if (bytes.size() != node.head_bytes || bytes.size() < kNodeHeadPrefixBytes)
    return fail(ErrorCode::kCorrupt, fmt::format("{}: head of {} bytes, the record says {}", what,
                                                 bytes.size(), node.head_bytes));
  const uint8_t* p = bytes.data();
  if (loadU32(p) != node.object_count || loadU32(p + 4) != node.mesh_count ||
      loadU32(p + 8) != node.texture_count)
    return fail(ErrorCode::kCorrupt, what + ": head counts differ from the node record");
  const bool known_minor = header.version_minor == kSceneVersionMinor;
  if (known_minor && !allZero(p + 12, 4))
    return fail(ErrorCode::kCorrupt, what + ": reserved head fields are not zero");
  const uint64_t body_begin = node.offset_bytes + node.head_bytes;
  const uint64_t body_end = node.offset_bytes + node.own_bytes;
  NodeHead head;
  p += kNodeHeadPrefixBytes;
  for (uint32_t k = 0; k < node.object_count; ++k, p += kObjectRecordBytes) {
    TESSERA_ASSIGN_OR_RETURN(
        ObjectRecord o, decodeObject(p, known_minor, directory,
                                     fmt::format("{} object {}", what, node.first_object + k)));
    head.objects.push_back(o);
  }
  for (uint32_t k = 0; k < node.mesh_count; ++k, p += kMeshRecordBytes) {
    const std::string mesh_what = fmt::format("{} mesh {}", what, node.first_mesh + k);
    TESSERA_ASSIGN_OR_RETURN(MeshRecord m,
                             decodeMesh(p, known_minor, body_begin, body_end, mesh_what));
    if (m.mesh != node.first_mesh + k)
      return fail(ErrorCode::kCorrupt, mesh_what + ": numbered out of order");
    head.meshes.push_back(m);
  }
  for (uint32_t k = 0; k < node.texture_count; ++k, p += kNodeTextureRecordBytes) {
    const std::string texture_what = fmt::format("{} texture {}", what, node.first_texture + k);
    NodeTextureRecord t{loadU32(p), loadBlockRef(p + 8), {}};
    if (known_minor && (!allZero(p + 4, 4) || !allZero(p + 48, 16)))
      return fail(ErrorCode::kCorrupt, texture_what + ": reserved fields are not zero");
    TESSERA_ASSIGN_OR_RETURN(t.info, loadImageInfo(p + 32, known_minor, texture_what));
    if (t.pages.length_bytes != texturePagesBytes(t.info))
      return fail(ErrorCode::kCorrupt,
                  fmt::format("{}: pages of {} bytes, its levels need {}", texture_what,
                              t.pages.length_bytes, texturePagesBytes(t.info)));
    if (t.texture != node.first_texture + k)
      return fail(ErrorCode::kCorrupt, texture_what + ": numbered out of order");
    TESSERA_TRY(checkInside(t.pages, body_begin, body_end, texture_what + " pages"));
    head.textures.push_back(t);
  }
  return head;
}

uint64_t texturePagesBytes(const ImageInfo& info) {
  uint64_t tiles = 0;
  for (uint32_t level = 0; level < info.level_count; ++level)
    tiles += uint64_t(info.tilesX(level)) * info.tilesY(level);
  return tiles * kTileEntryBytes;
}

bool fitsOnePagePerLevel(const ImageInfo& info) {
  const uint32_t side = 1u << info.page_tiles_log2;
  return info.tilesX(0) <= side && info.tilesY(0) <= side;
}

SceneBox transformBox(const SceneBox& box, const std::array<float, 12>& m) {
  SceneBox out;
  for (int r = 0; r < 3; ++r) {
    // Arvo's method: each output axis is the translation plus, per input axis, the smaller or
    // larger of the two products.
    float lo = m[4 * r + 3], hi = m[4 * r + 3];
    for (int c = 0; c < 3; ++c) {
      float a = m[4 * r + c] * box.min[c], b = m[4 * r + c] * box.max[c];
      lo += std::min(a, b);
      hi += std::max(a, b);
    }
    out.min[r] = lo;
    out.max[r] = hi;
  }
  return out;
}

bool boxContains(const SceneBox& outer, const SceneBox& inner) {
  for (int a = 0; a < 3; ++a)
    if (inner.min[a] < outer.min[a] || inner.max[a] > outer.max[a]) return false;
  return true;
}

}  // namespace tessera::detail
