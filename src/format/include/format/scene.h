#pragma once
// The scene section of a version 1.1 archive (docs/format.md, "Scenes"): the scene directory,
// node table, texture table and node heads. Pure: bytes in, structs out. The R-tree and its
// depth-first layout follow Zhou, Zhu & Zhang, section 3 (seed 004): textures hang on nodes,
// shared ones at the lowest common ancestor of their users, and a node's subtree is one
// contiguous byte range.

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <tessera/format.h>
#include <tessera/result.h>

#include "format/header.h"
#include "format/sections.h"

namespace tessera::detail {

/// The minor version that adds scenes. Version 1.0 readers open such a file and see its
/// textures as ordinary images; the scene directory is the section of kind kScene in the
/// section table (format/sections.h) that header bytes they ignore point to.
inline constexpr uint16_t kSceneVersionMinor = 1;
inline constexpr uint32_t kSceneDirectoryBytes = 128;
inline constexpr uint32_t kNodeRecordBytes = 96;
inline constexpr uint32_t kTextureRecordBytes = 64;
inline constexpr uint32_t kNodeHeadPrefixBytes = 16;
inline constexpr uint32_t kObjectRecordBytes = 128;
inline constexpr uint32_t kMeshRecordBytes = 64;
inline constexpr uint32_t kNodeTextureRecordBytes = 64;

/// Texture slots of an object's material; base colour is the one renderers need first.
inline constexpr uint32_t kSceneTextureSlots = 5;
/// A texture reference that refers to nothing.
inline constexpr uint32_t kNoSceneTexture = 0xFFFFFFFFu;

/// Bounds that keep a hostile file from driving allocations: a node table of 2^24 records is
/// 1.5 GiB, far above any scene we build (100,000 objects make about 16,000 nodes).
inline constexpr uint32_t kMaxSceneNodes = 1u << 24;
inline constexpr uint32_t kMaxSceneObjects = 1u << 26;
inline constexpr uint32_t kMaxSceneMeshes = 1u << 26;
inline constexpr uint32_t kMaxSceneDepth = 64;
/// Per mesh: vertices and indices (2^28 indices of 4 bytes is 1 GiB).
inline constexpr uint32_t kMaxMeshVertices = 1u << 28;
inline constexpr uint32_t kMaxMeshIndices = 1u << 28;
/// Per node: objects, meshes and textures in one head (the head is then at most ~130 MiB).
inline constexpr uint32_t kMaxNodeItems = 1u << 20;

/// How a mesh's vertex and index buffers are stored (docs/format.md, "Geometry").
enum class GeometryCodecId : uint8_t {
  kRaw = 0,      ///< vertices then indices, little-endian
  kZstd = 1,     ///< one zstd frame of the raw vertices, one of the raw indices
  kMeshopt = 2,  ///< meshoptimizer vertex codec, then its index codec (format version 1)
};

/// Axis-aligned box; min <= max on every axis for any non-empty box.
struct SceneBox {
  std::array<float, 3> min{0, 0, 0};
  std::array<float, 3> max{0, 0, 0};
  friend bool operator==(const SceneBox&, const SceneBox&) = default;
};

/// The 128-byte scene directory the header points at.
struct SceneDirectory {
  uint32_t node_count = 0;     ///< 1..kMaxSceneNodes; node 0 is the root
  uint32_t object_count = 0;   ///< 0..kMaxSceneObjects
  uint32_t mesh_count = 0;     ///< 0..kMaxSceneMeshes
  uint32_t texture_count = 0;  ///< 0..kMaxImages; texture t is described by texture record t
  uint16_t tree_depth = 1;     ///< levels of the tree, 1..kMaxSceneDepth (a lone root is 1)
  uint16_t max_children = 2;   ///< the R-tree's fan-out bound, 2..256
  uint16_t leaf_capacity = 1;  ///< objects per leaf at most, 1..65535
  SceneBox bounds;             ///< the root's box
  BlockRef node_table;         ///< node_count records of kNodeRecordBytes
  BlockRef texture_table;      ///< texture_count records of kTextureRecordBytes
  BlockRef coarse;             ///< every texture's coarsest-level payloads, in texture order
  friend bool operator==(const SceneDirectory&, const SceneDirectory&) = default;
};

/// One R-tree node. Nodes are numbered in depth-first pre-order, so node i's subtree is nodes
/// [i, i + subtree_nodes), its first child is i + 1, and a child's next sibling follows its
/// subtree. Objects, meshes and textures are numbered in the same pre-order of the node that
/// holds them, so a subtree's items are contiguous index ranges too.
struct NodeRecord {
  SceneBox bounds;             ///< contains every child's box and every own object's box
  uint32_t subtree_nodes = 1;  ///< this node and its descendants, >= 1
  uint16_t child_count = 0;    ///< 0 for a leaf
  uint8_t depth = 0;           ///< 0 at the root
  uint32_t first_object = 0, object_count = 0;    ///< own objects (leaves only)
  uint32_t first_texture = 0, texture_count = 0;  ///< textures stored at this node
  uint32_t first_mesh = 0, mesh_count = 0;        ///< meshes stored at this node
  uint64_t offset_bytes = 0;   ///< where the node's own block and its subtree range start
  uint32_t head_bytes = 0;     ///< the node head at offset_bytes
  uint64_t head_checksum = 0;  ///< XXH3-64 of the head
  uint64_t own_bytes = 0;      ///< head + pages + geometry + texture payloads of this node
  uint64_t subtree_bytes = 0;  ///< own block followed by every child's subtree range, in order
  friend bool operator==(const NodeRecord&, const NodeRecord&) = default;
};

/// One texture: which image of the root directory holds it, which node stores it, and its
/// coarsest tile's entry so a reader gets every texture's coarsest level from the coarse block
/// without touching a node.
struct TextureRecord {
  uint32_t image = 0;  ///< index into the root directory's images
  uint32_t node = 0;   ///< the node that stores it: the lowest common ancestor of its users
  uint32_t users = 0;  ///< objects that reference it in any slot
  ImageInfo info;      ///< geometry, as in the image record (name excluded)
  TileEntry coarsest;  ///< the single tile of level info.level_count - 1
  friend bool operator==(const TextureRecord& a, const TextureRecord& b);
};

/// One object: a mesh drawn with a transform and a material.
struct ObjectRecord {
  SceneBox bounds;  ///< world space
  /// Object to world, row-major 3x4: world = M * (x, y, z, 1).
  std::array<float, 12> transform{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
  uint32_t mesh = 0;       ///< global mesh index
  uint32_t mesh_node = 0;  ///< node holding the mesh: this object's leaf or an ancestor
  /// Per slot (base colour, metallic-roughness, normal, occlusion, emissive): a texture index
  /// or kNoSceneTexture.
  std::array<uint32_t, kSceneTextureSlots> textures{
      kNoSceneTexture, kNoSceneTexture, kNoSceneTexture, kNoSceneTexture, kNoSceneTexture};
  uint32_t base_color_rgba = 0xFFFFFFFFu;  ///< factor, 8-bit sRGB channels, R in the low byte
  uint32_t source_index = 0;               ///< the importer's object number (diagnostics)
  friend bool operator==(const ObjectRecord&, const ObjectRecord&) = default;
};

/// Vertex attributes present in a mesh besides positions (three f32).
enum MeshAttributeBits : uint8_t {
  kMeshNormals = 1,  ///< three f32
  kMeshUv0 = 2,      ///< two f32
};

/// One mesh: triangle list geometry stored as one blob inside its node's block.
struct MeshRecord {
  uint32_t mesh = 0;  ///< global index; equals the node's first_mesh + position in the head
  uint32_t vertex_count = 0;
  uint32_t index_count = 0;  ///< a multiple of 3, every index below vertex_count
  uint8_t attributes = 0;    ///< MeshAttributeBits
  GeometryCodecId codec = GeometryCodecId::kRaw;
  uint32_t vertex_part_bytes = 0;  ///< the blob's first part (vertices); indices follow
  BlockRef blob;                   ///< inside the node's own block
  friend bool operator==(const MeshRecord&, const MeshRecord&) = default;
  /// Bytes per vertex: 12 + 12 (normals) + 8 (uv0).
  uint32_t vertexStrideBytes() const {
    return 12 + ((attributes & kMeshNormals) ? 12 : 0) + ((attributes & kMeshUv0) ? 8 : 0);
  }
};

/// A texture stored at a node: its directory pages, one per level (a scene texture's level
/// always fits one page), concatenated level 0 first, so one BlockRef covers them.
struct NodeTextureRecord {
  uint32_t texture = 0;  ///< global index; equals the node's first_texture + position
  BlockRef pages;        ///< texturePagesBytes(info): every level's page, level 0 first
  /// Geometry, as in the texture table, so that a node's block alone is enough to read its
  /// textures' tiles (one read per node).
  ImageInfo info;
};

/// A decoded node head.
struct NodeHead {
  std::vector<ObjectRecord> objects;
  std::vector<MeshRecord> meshes;
  std::vector<NodeTextureRecord> textures;
};

/// The scene directory's reference among a decoded section table's entries: length 0 when the
/// table has no scene section; otherwise checked to be exactly kSceneDirectoryBytes long.
Result<BlockRef> decodeSceneRef(std::span<const SectionEntry> sections, const std::string& name);

std::vector<uint8_t> encodeSceneDirectory(const SceneDirectory& directory);
/// Checks counts, depth, fan-out, bounds (finite, min <= max) and every block against the file.
Result<SceneDirectory> decodeSceneDirectory(std::span<const uint8_t> bytes,
                                            const FileHeader& header, const std::string& name);

std::vector<uint8_t> encodeNodeRecords(std::span<const NodeRecord> nodes);
/// Decodes records numbered first_index, first_index + 1, ...; checks each record alone: box,
/// ranges against the directory's counts, blocks inside the file, head_bytes <= own_bytes <=
/// subtree_bytes. How records fit together is validateNodeTable's job.
Result<std::vector<NodeRecord>> decodeNodeRecords(std::span<const uint8_t> bytes,
                                                  uint32_t first_index,
                                                  const SceneDirectory& directory,
                                                  const FileHeader& header,
                                                  const std::string& name);
/// Checks a whole node table: pre-order structure (child counts and subtree sizes agree,
/// depths increase by one), item ranges numbered in pre-order without gaps, every child's box
/// inside its parent's, each child's subtree range right after its predecessor's, and the
/// root's range holding every node.
Result<void> validateNodeTable(std::span<const NodeRecord> nodes, const SceneDirectory& directory,
                               const std::string& name);

std::vector<uint8_t> encodeTextureRecords(std::span<const TextureRecord> textures);
Result<std::vector<TextureRecord>> decodeTextureRecords(std::span<const uint8_t> bytes,
                                                        uint32_t first_index,
                                                        const SceneDirectory& directory,
                                                        const FileHeader& header,
                                                        const std::string& name);

/// Head bytes for the given item counts.
uint64_t nodeHeadBytes(uint64_t objects, uint64_t meshes, uint64_t textures);
std::vector<uint8_t> encodeNodeHead(const NodeHead& head);
/// Decodes the head of `node` and checks it against the record (counts, numbering), the
/// directory (indices in range) and the node's own block (every blob and page inside it,
/// after the head).
Result<NodeHead> decodeNodeHead(std::span<const uint8_t> bytes, const NodeRecord& node,
                                uint32_t node_index, const SceneDirectory& directory,
                                const FileHeader& header, const std::string& name);

/// Bytes of a texture's concatenated pages (all levels, one page each).
uint64_t texturePagesBytes(const ImageInfo& info);
/// True when every level of `info` is covered by one directory page.
bool fitsOnePagePerLevel(const ImageInfo& info);

/// Object bounds of a box transformed by a 3x4 row-major matrix (the 8 corners).
SceneBox transformBox(const SceneBox& box, const std::array<float, 12>& transform);
/// True when `outer` contains `inner` on every axis.
bool boxContains(const SceneBox& outer, const SceneBox& inner);

}  // namespace tessera::detail
