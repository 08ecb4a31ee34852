#pragma once
// The scene streamer's loads (issue 28, item 4): one planned read (object, node or subtree;
// io_plan.h) per job, run on a fixed pool of worker threads, which parses the node blocks it
// holds, decodes their geometry and the texture levels the job's camera wants from the same
// bytes (seed 004: geometry and textures arrive together), and hands the result back for the
// render thread to pick up without waiting.

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include <tessera/scene.h>
#include <tessera/scene_stream.h>
#include <tessera/view.h>

#include "scene_residency.h"

namespace tessera::detail {

/// A refinement: every tile of one level of one texture, all inside the job's range.
struct LevelJob {
  uint32_t texture = 0;
  uint32_t level = 0;
  FileRange hull;  ///< the bytes of its encoded tiles (empty at the node's block when none)
  ImageInfo info;
  std::vector<TileEntry> tiles;  ///< row-major, tilesX(level) * tilesY(level)
};

/// Shared, immutable while the streamer lives: what workers need besides their job.
struct LoaderContext {
  std::shared_ptr<const SceneArchive> archive;
  std::vector<SceneTexture> textures;  ///< the whole texture table
  std::vector<uint8_t> coarse_block;   ///< every texture's coarsest payload (coarseRange)
  uint64_t coarse_offset_bytes = 0;
};

/// One read and what to make of it.
struct ReadJob {
  PlannedRead read;
  std::vector<SceneNode> parse;  ///< nodes whose blocks lie in read.range and are unknown
  std::vector<LevelJob> levels;
  std::vector<SceneMesh> meshes;  ///< blobs inside read.range to decode (object reads)
  PerspectiveView camera;         ///< the frame that asked: picks the levels of newly read textures
  double lod_bias = 0;
};

struct DecodedMesh {
  uint32_t mesh = 0;
  MeshData data;
};
struct DecodedLevel {
  uint32_t texture = 0;
  uint32_t level = 0;
  std::vector<Image> tiles;  ///< row-major
};
struct DecodedCoarsest {
  uint32_t texture = 0;
  Image tile;
};
struct ParsedNode {
  uint32_t node = 0;
  NodeContents contents;
};

/// What a job produced. On error the job's nodes and levels are named in `job` so the
/// streamer can release them; `error` names the archive and the failing read.
struct ReadResult {
  ReadJob job;
  std::string error;  ///< empty on success
  uint64_t bytes_read = 0;
  std::vector<ParsedNode> nodes;
  std::vector<DecodedMesh> meshes;
  std::vector<DecodedCoarsest> coarsest;  ///< of every texture the parsed objects use
  std::vector<DecodedLevel> levels;       ///< coarse to fine per texture
};

/// Runs one job: exactly one ByteSource::read of job.read.range. Thread-safe (scratch is the
/// caller's).
ReadResult runReadJob(const LoaderContext& context, ReadJob job, CodecScratch* scratch);

/// A fixed pool of worker threads running ReadJobs. submit and drain are for the render
/// thread and hold the queue or results mutex only to move a vector: they never wait on a read.
/// Thread-safe.
class SceneLoaderPool {
 public:
  SceneLoaderPool(std::shared_ptr<const LoaderContext> context, uint32_t threads);
  ~SceneLoaderPool();  ///< drops queued jobs, joins the workers
  void submit(ReadJob job);
  /// Finished results, without waiting.
  std::vector<ReadResult> drain();
  /// Jobs queued or running.
  uint32_t pending() const;
  /// Blocks until no job is queued or running (tests and frame-stepping tools only).
  void waitIdle();

 private:
  void work();

  std::shared_ptr<const LoaderContext> context_;
  mutable std::mutex mutex_;      // guards queue_, stop_, running_; taken before results_mutex_
  std::condition_variable wake_;  // a job was queued or the pool stops
  std::condition_variable idle_;  // a job finished
  std::deque<ReadJob> queue_;
  uint32_t running_ = 0;
  bool stop_ = false;
  std::mutex results_mutex_;  // guards results_
  std::vector<ReadResult> results_;
  std::vector<std::thread> threads_;
};

}  // namespace tessera::detail
