// verifyScene: the scene half of `tessera verify` (docs/scenes.md).
#include <tessera/scene.h>

#include <fmt/format.h>

namespace tessera {
namespace {

constexpr size_t kMaxFaultsKept = 100;

class Faults {
 public:
  explicit Faults(SceneVerifyReport& report) : report_(report) {}
  void add(std::string fault) {
    ++report_.fault_count;
    if (report_.faults.size() < kMaxFaultsKept) report_.faults.push_back(std::move(fault));
  }

 private:
  SceneVerifyReport& report_;
};

bool inside(const FileRange& inner, const FileRange& outer) {
  return inner.offset_bytes >= outer.offset_bytes &&
         inner.offset_bytes + inner.length_bytes <= outer.offset_bytes + outer.length_bytes;
}

bool sameGeometry(const ImageInfo& a, const ImageInfo& b) {
  return a.width_px == b.width_px && a.height_px == b.height_px && a.channels == b.channels &&
         a.tile_size_px == b.tile_size_px && a.level_count == b.level_count;
}

// Checks one node's block: head and pages (parseNode), its meshes, its objects' references.
void checkNode(const SceneArchive& scene, const std::vector<SceneNode>& nodes,
               const SceneNode& node, bool decode, std::vector<uint32_t>& stored_at,
               SceneVerifyReport& report, Faults& faults) {
  const std::string& name = scene.name();
  Result<NodeContents> contents = scene.readNode(node);
  if (!contents) {
    faults.add(contents.error().message);
    return;
  }
  ++report.nodes_checked;
  const SceneSummary& summary = scene.summary();
  for (const SceneMesh& mesh : contents->meshes) {
    ++report.meshes_checked;
    if (!inside(mesh.blob, node.own)) {
      faults.add(
          fmt::format("{}: mesh {} blob lies outside node {}", name, mesh.index, node.index));
      continue;
    }
    if (decode) {
      Result<MeshData> data = scene.readMesh(mesh);
      if (!data) faults.add(data.error().message);
    }
  }
  for (const SceneObject& object : contents->objects) {
    ++report.objects_checked;
    if (object.mesh >= summary.meshes) {
      faults.add(fmt::format("{}: object {} refers to mesh {} of {}", name, object.index,
                             object.mesh, summary.meshes));
    }
    const SceneNode* holder = object.mesh_node < nodes.size() ? &nodes[object.mesh_node] : nullptr;
    if (!holder || node.index < holder->index ||
        node.index >= holder->index + holder->subtree_nodes) {
      faults.add(fmt::format("{}: object {} in node {} has its mesh at node {}, not an ancestor",
                             name, object.index, node.index, object.mesh_node));
    }
    for (uint32_t t : object.textures) {
      if (t != kNoTexture && t >= summary.textures) {
        faults.add(fmt::format("{}: object {} refers to texture {} of {}", name, object.index, t,
                               summary.textures));
      }
    }
  }
  for (const NodeTexture& texture : contents->textures) {
    if (texture.texture >= stored_at.size()) {
      faults.add(fmt::format("{}: node {} stores texture {} of {}", name, node.index,
                             texture.texture, stored_at.size()));
    } else if (stored_at[texture.texture] != UINT32_MAX) {
      faults.add(fmt::format("{}: texture {} stored at nodes {} and {}", name, texture.texture,
                             stored_at[texture.texture], node.index));
    } else {
      stored_at[texture.texture] = node.index;
    }
  }
}

void checkTextures(const SceneArchive& scene, const std::vector<SceneTexture>& textures,
                   const std::vector<ImageInfo>& images, const std::vector<uint32_t>& stored_at,
                   SceneVerifyReport& report, Faults& faults) {
  const std::string& name = scene.name();
  const FileRange coarse = scene.coarseRange();
  for (const SceneTexture& texture : textures) {
    ++report.textures_checked;
    if (texture.image >= images.size() || !sameGeometry(texture.info, images[texture.image])) {
      faults.add(fmt::format("{}: texture {} does not match image record {} of {}", name,
                             texture.index, texture.image, images.size()));
    }
    if (stored_at[texture.index] == UINT32_MAX) {
      faults.add(fmt::format("{}: texture {} (recorded at node {}) is listed by no readable node",
                             name, texture.index, texture.node));
    } else if (stored_at[texture.index] != texture.node) {
      faults.add(fmt::format("{}: texture {} is recorded at node {} but stored at node {}", name,
                             texture.index, texture.node, stored_at[texture.index]));
    }
    if (texture.coarsest.kind == TileKind::kEncoded &&
        !inside({texture.coarsest.offset_bytes, texture.coarsest.length_bytes}, coarse)) {
      faults.add(fmt::format("{}: texture {} coarsest tile lies outside the coarse block", name,
                             texture.index));
    }
  }
}

}  // namespace

SceneVerifyReport verifyScene(const SceneArchive& scene, const std::vector<ImageInfo>& images,
                              bool decode) {
  SceneVerifyReport report;
  Faults faults(report);
  Result<std::vector<SceneNode>> nodes = scene.allNodes();
  if (!nodes) {
    faults.add(nodes.error().message);
    return report;
  }
  Result<std::vector<SceneTexture>> textures = scene.textures(0, scene.summary().textures);
  if (!textures) {
    faults.add(textures.error().message);
    return report;
  }
  std::vector<uint32_t> stored_at(textures->size(), UINT32_MAX);
  for (const SceneNode& node : *nodes) {
    checkNode(scene, *nodes, node, decode, stored_at, report, faults);
  }
  checkTextures(scene, *textures, images, stored_at, report, faults);
  // The coverage hints: checksum and every rule of the format (decodeCoverageHints).
  if (scene.coverageHintsRange().length_bytes != 0) {
    Result<CoverageHints> hints = scene.readCoverageHints();
    if (!hints) {
      faults.add(hints.error().message);
    } else {
      report.hint_cells_checked = hints->cellCount();
      report.hint_entries_checked = hints->entries.size();
    }
  }
  return report;
}

}  // namespace tessera
