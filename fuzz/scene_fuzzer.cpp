// Fuzzes the scene reader (src/scene): a scene archive file opened from memory, every node
// record, node block and mesh read and decoded (at most kMaxNodes nodes). Checks that nothing
// crashes, hangs or reads out of range.
#include <tessera/scene.h>

#include "format_fuzz_input.h"

namespace {

constexpr uint32_t kMaxNodes = 64;

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace tessera;
  Result<std::shared_ptr<SceneArchive>> opened =
      SceneArchive::open(makeMemorySource(std::vector<uint8_t>(data, data + size), "fuzz.tess"));
  if (!opened) return 0;
  const SceneArchive& scene = **opened;
  (void)scene.readMetadata();
  Result<std::vector<SceneNode>> nodes = scene.allNodes();
  if (!nodes) return 0;
  uint32_t visited = 0;
  for (const SceneNode& node : *nodes) {
    if (++visited > kMaxNodes) break;
    (void)scene.children(node);
    Result<NodeContents> contents = scene.readNode(node);
    if (!contents) continue;
    for (const SceneMesh& mesh : contents->meshes) (void)scene.readMesh(mesh);
  }
  return 0;
}
