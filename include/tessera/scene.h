#pragma once
/// \file
/// Reading scene archives (docs/format.md, "Scenes"; docs/scenes.md): a version 1.1 archive
/// whose textures are ordinary pyramids and which adds objects, meshes and an R-tree over the
/// objects' bounds with textures on its nodes (Zhou, Zhu & Zhang, seed 004). Nodes are
/// numbered depth-first, so a node's subtree is one node-table range and one byte range:
///
///   - open: one read of the first 16 KiB (header and scene directory);
///   - a node: its record (one read, or none when cached or inside the header region) and its
///     own block (one read): objects, meshes, texture directories, geometry and every texture
///     level but the coarsest;
///   - a subtree: the records' range and the byte range [offset, offset + subtree_bytes);
///   - the coarsest level of every texture: the coarse block, one read (or a slice of it).

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include <tessera/byte_source.h>
#include <tessera/codec_scratch.h>
#include <tessera/coverage_hints.h>
#include <tessera/format.h>
#include <tessera/result.h>

namespace tessera {

/// An axis-aligned box in world units.
struct Box3 {
  std::array<float, 3> min{0, 0, 0};
  std::array<float, 3> max{0, 0, 0};
  friend bool operator==(const Box3&, const Box3&) = default;
};

/// Material texture slots, in the order of SceneObject::textures.
enum class TextureSlot : uint8_t {
  kBaseColor = 0,
  kMetallicRoughness = 1,
  kNormal = 2,
  kOcclusion = 3,
  kEmissive = 4,
};
inline constexpr uint32_t kTextureSlotCount = 5;
/// A slot without a texture.
inline constexpr uint32_t kNoTexture = 0xFFFFFFFFu;

/// How mesh buffers are stored (docs/format.md, "Geometry").
enum class GeometryCodec : uint8_t {
  kRaw = 0,
  kZstd = 1,
  kMeshopt = 2,  ///< meshoptimizer's vertex and index codecs
};
/// "raw", "zstd", "meshopt".
const char* geometryCodecName(GeometryCodec codec);
bool parseGeometryCodecName(std::string_view name, GeometryCodec* codec);

/// Counts and shape of a scene, from the scene directory.
struct SceneSummary {
  uint32_t nodes = 0;
  uint32_t objects = 0;
  uint32_t meshes = 0;
  uint32_t textures = 0;
  uint32_t tree_depth = 0;  ///< levels of the tree; the root alone is 1
  uint32_t max_children = 0;
  uint32_t leaf_capacity = 0;
  Box3 bounds;
};

/// A byte range of the archive.
struct FileRange {
  uint64_t offset_bytes = 0;
  uint64_t length_bytes = 0;
};

/// One R-tree node (docs/format.md, "Node table").
struct SceneNode {
  uint32_t index = 0;          ///< depth-first pre-order; 0 is the root
  Box3 bounds;                 ///< contains its children's and its objects' boxes
  uint32_t subtree_nodes = 1;  ///< nodes [index, index + subtree_nodes) are its subtree
  uint32_t child_count = 0;    ///< 0 for a leaf; the first child is index + 1
  uint32_t depth = 0;
  uint32_t first_object = 0, object_count = 0;    ///< objects held here (leaves only)
  uint32_t first_texture = 0, texture_count = 0;  ///< textures stored here
  uint32_t first_mesh = 0, mesh_count = 0;        ///< meshes stored here
  FileRange own;            ///< the node's block: head, pages, geometry, texture levels
  uint32_t head_bytes = 0;  ///< the head is the first head_bytes of `own`
  FileRange subtree;        ///< own block and every descendant's; starts where `own` does
  bool isLeaf() const { return child_count == 0; }
};

/// One object: a mesh drawn with a transform and a material.
struct SceneObject {
  uint32_t index = 0;
  Box3 bounds;                        ///< world space
  std::array<float, 12> transform{};  ///< object to world, row-major 3x4
  uint32_t mesh = 0;
  uint32_t mesh_node = 0;  ///< the node storing the mesh: this object's leaf or an ancestor
  std::array<uint32_t, kTextureSlotCount> textures{};  ///< texture index or kNoTexture
  uint32_t base_color_rgba = 0xFFFFFFFFu;              ///< factor; R in the low byte
  uint32_t source_index = 0;                           ///< the importer's object number
};

/// A mesh's record: where its geometry is and how it is coded.
struct SceneMesh {
  uint32_t index = 0;
  uint32_t vertex_count = 0;
  uint32_t index_count = 0;
  bool has_normals = false;
  bool has_uv0 = false;
  GeometryCodec codec = GeometryCodec::kRaw;
  FileRange blob;                  ///< inside its node's own block
  uint64_t blob_checksum = 0;      ///< XXH3-64 of the blob
  uint32_t vertex_part_bytes = 0;  ///< the blob's first part; the indices follow
};

/// Decoded geometry: a triangle list.
struct MeshData {
  std::vector<float> positions;  ///< 3 per vertex
  std::vector<float> normals;    ///< 3 per vertex, or empty
  std::vector<float> uv0;        ///< 2 per vertex, or empty
  std::vector<uint32_t> indices;
};

/// One texture: an image pyramid of the archive stored at one node.
struct SceneTexture {
  uint32_t index = 0;
  uint32_t image = 0;  ///< the image index an Archive sees for it
  uint32_t node = 0;   ///< where it is stored: the lowest common ancestor of its users
  uint32_t users = 0;  ///< objects referencing it
  ImageInfo info;      ///< name excluded (metadata)
  TileEntry coarsest;  ///< the one tile of level info.level_count - 1, in the coarse block
};

/// A texture stored at a node, with every level's tile entries (level 0 first, each
/// row-major), read from the node's block.
struct NodeTexture {
  uint32_t texture = 0;
  ImageInfo info;  ///< name excluded
  std::vector<std::vector<TileEntry>> levels;
};

/// What a node's block holds once parsed.
struct NodeContents {
  std::vector<SceneObject> objects;
  std::vector<SceneMesh> meshes;
  std::vector<NodeTexture> textures;
};

/// An opened scene archive. Thread-safe: immutable after open except for caches of node and
/// texture records, each guarded by its own mutex. Every method may be called from any thread.
class SceneArchive {
 public:
  /// Reads the first min(16 KiB, size) bytes once and checks the header and scene directory.
  /// Fails naming the source: not an archive, a 1.0 archive without a scene (kNotFound),
  /// corrupt fields.
  [[nodiscard]] static Result<std::shared_ptr<SceneArchive>> open(
      std::shared_ptr<ByteSource> source);
  [[nodiscard]] static Result<std::shared_ptr<SceneArchive>> openFile(const std::string& path);

  ~SceneArchive();
  SceneArchive(const SceneArchive&) = delete;
  SceneArchive& operator=(const SceneArchive&) = delete;

  const std::string& name() const;
  const SceneSummary& summary() const;
  uint64_t fileBytes() const;
  const ByteSource& source() const;
  /// The archive's JSON metadata (docs/format.md, "Metadata"; a scene's build statistics are
  /// under "scene"): one verified read, "{}" when there is none.
  [[nodiscard]] Result<std::string> readMetadata() const;
  /// The range holding every node record; reading it (nodes()) costs one read.
  FileRange nodeTableRange() const;
  /// The coarse block: every texture's coarsest-level payload, in texture order.
  FileRange coarseRange() const;
  /// The coverage hints block (docs/format.md, "Coverage hints"); length 0 when the archive
  /// has none (built with --no-coverage-hints, or by an older writer).
  FileRange coverageHintsRange() const;
  /// Reads (one verified read, none when inside the header region) and decodes the coverage
  /// hints. kNotFound when there are none; kCorrupt (naming the archive and the field) for a
  /// block over 64 MiB, a checksum mismatch or a broken rule; kUnsupported for a newer version.
  [[nodiscard]] Result<CoverageHints> readCoverageHints() const;

  /// A node record: from the cache or the header region, else one read of 96 bytes.
  [[nodiscard]] Result<SceneNode> node(uint32_t index) const;
  /// Records [first, first + count) in one read; a subtree's are [i, i + subtree_nodes).
  [[nodiscard]] Result<std::vector<SceneNode>> nodes(uint32_t first, uint32_t count) const;
  /// Every record, and checks that they form the tree the format requires (validateNodeTable).
  [[nodiscard]] Result<std::vector<SceneNode>> allNodes() const;
  /// The children of a node, in order (reads the subtree's records at most once).
  [[nodiscard]] Result<std::vector<SceneNode>> children(const SceneNode& node) const;

  /// Texture records [first, first + count) in one read (cached).
  [[nodiscard]] Result<std::vector<SceneTexture>> textures(uint32_t first, uint32_t count) const;

  /// Reads the node's own block (one read) and parses it with parseNode.
  [[nodiscard]] Result<NodeContents> readNode(const SceneNode& node) const;
  /// Parses a node's own block from bytes the caller read, e.g. within a subtree read:
  /// `block` is node.own or a prefix of it holding at least the head (head_bytes) and, when
  /// `with_textures`, every texture's directory pages (kInvalidArgument naming the texture
  /// otherwise); mesh blobs and payloads past the prefix are the caller's to read. Verifies
  /// the head and page checksums.
  [[nodiscard]] Result<NodeContents> parseNode(const SceneNode& node,
                                               std::span<const uint8_t> block,
                                               bool with_textures = true) const;
  /// Verifies and decodes a mesh's geometry blob; `blob` holds mesh.blob's bytes.
  [[nodiscard]] Result<MeshData> decodeMesh(const SceneMesh& mesh,
                                            std::span<const uint8_t> blob) const;
  /// Reads (one read) and decodes a mesh's blob.
  [[nodiscard]] Result<MeshData> readMesh(const SceneMesh& mesh) const;

  /// Verifies a tile payload (empty for uniform and empty tiles) against its entry and decodes
  /// it to a stored tile (borders included) of `info`'s geometry. Codecs coded against a parent
  /// (ptm) are not used by scene builds and are rejected here (kUnsupported). Errors name the
  /// texture and the tile (level, x, y).
  [[nodiscard]] Result<Image> decodeTile(uint32_t texture, const ImageInfo& info, uint32_t level,
                                         uint32_t x, uint32_t y, const TileEntry& entry,
                                         std::span<const uint8_t> payload,
                                         CodecScratch* scratch = nullptr) const;
  /// The coarsest level of a texture as a stored tile: one read of its payload (or none for a
  /// uniform tile).
  [[nodiscard]] Result<Image> readCoarsest(const SceneTexture& texture,
                                           CodecScratch* scratch = nullptr) const;

  struct Impl;

 private:
  explicit SceneArchive(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// What verifyScene found.
struct SceneVerifyReport {
  uint64_t nodes_checked = 0;   ///< node heads and pages read and checksummed
  uint64_t meshes_checked = 0;  ///< mesh blobs checksummed (and decoded when asked)
  uint64_t objects_checked = 0;
  uint64_t textures_checked = 0;      ///< texture records matched against the image records
  uint64_t hint_cells_checked = 0;    ///< coverage hint cells decoded and checked (0: none)
  uint64_t hint_entries_checked = 0;  ///< their (texture, coverage) entries
  uint64_t fault_count = 0;
  std::vector<std::string> faults;  ///< the first 100, each naming the archive and the item
  bool ok() const { return fault_count == 0; }
};

/// Walks the scene of a scene archive: the node table (validateNodeTable), every node's head
/// and pages, every mesh blob (checksum; decoded when `decode`), every object's mesh and
/// texture references and its holders (an ancestor of its leaf), and the texture table
/// against the image records a 1.0 reader sees (`images`: size, channels, tile size, levels;
/// each texture stored at exactly the node that lists it, its coarsest tile inside the coarse
/// block), and the coverage hints when present (checksum and every rule of the format).
/// Texture payloads are Archive::verify's. Blocking; thread-safe like the archive.
SceneVerifyReport verifyScene(const SceneArchive& scene, const std::vector<ImageInfo>& images,
                              bool decode);

}  // namespace tessera
