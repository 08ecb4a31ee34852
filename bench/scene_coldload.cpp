// tessera-scene-coldload: issue 28's cold-load comparison (docs/scenes.md, "Cold load"), one
// measurement per run, driven by bench/scene_coldload.sh:
//
//   tessera-scene-coldload prepare --models DIR --work WORK
//   tessera-scene-coldload tessera --archive PATH|URL --view NAME [--drop FILE]...
//   tessera-scene-coldload perfile --stg PATH|URL --archive LOCAL.tess --placements TSV
//                                  (--view NAME | --all) [--drop-list FILE]
//
// `tessera` opens the scene archive and runs SceneStreamer's frame loop (60 Hz by default) on
// a still camera until the view is at full quality (see fullQuality); `perfile` loads the same
// view's models and textures from their own files as a viewer does (scene_coldload_perfile.cpp),
// or every file of the scene with --all. Both print one JSON line: seconds, reads or requests,
// bytes. Before timing, the files named by --drop/--drop-list leave the page cache.
#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <thread>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include <tessera/open.h>
#include <tessera/scene_stream.h>

#include "scene_coldload.h"

namespace coldload {

using tessera::ErrorCode;
using tessera::fail;
using tessera::Result;

namespace {

// A y-up world seen along `dir` from `eye`: PerspectiveView's forward is (sin yaw cos pitch,
// -cos yaw cos pitch, sin pitch) in world coordinates.
tessera::PerspectiveView lookAlong(double x, double y, double z, double dx, double dy, double dz) {
  const double norm = std::sqrt(dx * dx + dy * dy + dz * dz);
  tessera::PerspectiveView view;
  view.eye_x = x;
  view.eye_y = y;
  view.eye_z = z;
  view.pitch_rad = std::asin(dz / norm);
  view.yaw_rad = std::atan2(dx / norm, -dy / norm);
  view.fov_y_rad = 1.0;
  view.viewport_w = 1920;
  view.viewport_h = 1080;
  return view;
}

}  // namespace

std::vector<std::string> viewNames() {
  return {"street", "oblique", "overview"};
}

Result<tessera::PerspectiveView> viewByName(const std::string& name,
                                            const tessera::SceneSummary& summary) {
  const tessera::Box3& b = summary.bounds;
  const double cx = (b.min[0] + b.max[0]) / 2, cz = (b.min[2] + b.max[2]) / 2;
  const double ground = b.min[1];
  // street: 10 m up among the models, looking east along a row, slightly down.
  if (name == "street") return lookAlong(cx, ground + 10, cz, 1, -0.05, 0.02);
  // oblique: 150 m up over the south edge (z is south), looking north 0.25 rad down.
  if (name == "oblique") return lookAlong(cx, ground + 150, b.max[2], 0.05, -0.25, -1);
  // overview: 1500 m over the centre, looking mostly down.
  if (name == "overview") return lookAlong(cx, ground + 1500, cz, 0.1, -1, 0.3);
  return fail(ErrorCode::kInvalidArgument, "unknown view " + name);
}

Result<uint64_t> dropFromPageCache(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return fail(ErrorCode::kNotFound, path + ": cannot open to drop its pages");
  struct stat st {};
  uint64_t resident = 0;
  bool ok = ::fstat(fd, &st) == 0 && ::posix_fadvise(fd, 0, 0, POSIX_FADV_DONTNEED) == 0;
  if (ok && st.st_size > 0) {
    void* map = ::mmap(nullptr, size_t(st.st_size), PROT_READ, MAP_SHARED, fd, 0);
    const long page = ::sysconf(_SC_PAGESIZE);
    std::vector<unsigned char> pages((size_t(st.st_size) + page - 1) / page);
    ok = map != MAP_FAILED && ::mincore(map, size_t(st.st_size), pages.data()) == 0;
    for (unsigned char p : pages) resident += p & 1;
    if (map != MAP_FAILED) ::munmap(map, size_t(st.st_size));
  }
  ::close(fd);
  if (!ok) return fail(ErrorCode::kIo, path + ": posix_fadvise/mincore failed");
  return resident;
}

namespace {

// Counts the reads the archive reader and the streamer make (one per ByteSource::read).
class CountingSource final : public tessera::ByteSource {
 public:
  explicit CountingSource(std::shared_ptr<tessera::ByteSource> inner) : inner_(std::move(inner)) {}
  uint64_t sizeBytes() const override { return inner_->sizeBytes(); }
  const std::string& name() const override { return inner_->name(); }
  tessera::Result<void> read(uint64_t offset, std::span<uint8_t> out) const override {
    ++reads;
    bytes += out.size();
    return inner_->read(offset, out);
  }
  tessera::Result<void> readCancellable(uint64_t offset, std::span<uint8_t> out,
                                        const std::atomic<bool>& cancel) const override {
    ++reads;
    bytes += out.size();
    return inner_->readCancellable(offset, out, cancel);
  }
  uint64_t prefetch(std::span<const tessera::ByteRange> ranges) const override {
    return inner_->prefetch(ranges);
  }
  std::optional<tessera::LinkStats> linkStats() const override { return inner_->linkStats(); }

  mutable std::atomic<uint64_t> reads{0}, bytes{0};

 private:
  std::shared_ptr<tessera::ByteSource> inner_;
};

// Full quality at rest: every visible leaf has arrived (no leaf waits), every visible object
// is drawable (geometry and every texture's coarsest level resident), and every texture of
// every visible object has its wanted level resident (residentLevel <= wantedLevel; the
// wanted level is the finest any visible user needs, SceneStreamer's per-object level).
bool fullQuality(const tessera::SceneStreamer& streamer, const tessera::SceneFrameStats& stats) {
  if (stats.waiting_leaves > 0 || streamer.drawableObjects().size() != stats.visible_objects) {
    return false;
  }
  for (uint32_t o : streamer.drawableObjects()) {
    for (uint32_t t : streamer.object(o)->textures) {
      if (t != tessera::kNoTexture && streamer.residentLevel(t) > streamer.wantedLevel(t)) {
        return false;
      }
    }
  }
  return true;
}

struct StreamRun {
  double open_s = 0, complete_s = -1, full_s = -1;
  uint32_t frames = 0;
  tessera::SceneFrameStats last;
};

// The frame loop: update every `frame_s` (a renderer's frame), never waiting on reads, until
// full quality or `timeout_s`; `step` instead waits for the reads between frames (untimed use).
Result<StreamRun> streamToFullQuality(tessera::SceneStreamer& streamer,
                                      const tessera::ByteSource* link_source,
                                      const tessera::PerspectiveView& camera, double frame_s,
                                      bool step, std::chrono::steady_clock::time_point start) {
  using Clock = std::chrono::steady_clock;
  StreamRun run;
  auto next = Clock::now();
  // TESSERA_COLDLOAD_TRACE=1: one line per frame that started or finished reads (stderr).
  static const bool trace = std::getenv("TESSERA_COLDLOAD_TRACE") != nullptr;
  const double timeout_s = 600;
  for (;;) {
    run.last = streamer.update(camera);
    ++run.frames;
    const double now = std::chrono::duration<double>(Clock::now() - start).count();
    if (trace && run.last.reads_started > 0) {
      const tessera::LinkCost cost = tessera::measureLinkCost(*link_source);
      std::fprintf(stderr, "link: %.1f ms, %.2f MB/s\n", cost.latency_s * 1e3,
                   cost.bandwidth_bytes_per_s / 1e6);
    }
    if (trace && (run.last.reads_started > 0 || run.last.results_applied > 0)) {
      std::fprintf(stderr,
                   "%.3f s frame %u: %u reads started, %u results, %u waiting leaves, %llu reads "
                   "(%llu bytes) so far\n",
                   now, run.frames, run.last.reads_started, run.last.results_applied,
                   run.last.waiting_leaves, (unsigned long long)streamer.totals().reads,
                   (unsigned long long)streamer.totals().bytes_read);
    }
    if (run.complete_s < 0 && run.last.waiting_leaves == 0 &&
        streamer.drawableObjects().size() == run.last.visible_objects) {
      run.complete_s = now;
    }
    if (fullQuality(streamer, run.last)) {
      run.full_s = now;
      return run;
    }
    if (streamer.totals().read_errors > 0) return fail(ErrorCode::kIo, "a scene read failed");
    if (now > timeout_s) return fail(ErrorCode::kIo, "no full quality after 600 s");
    if (step) {
      streamer.waitForReads();
    } else {
      next += std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(frame_s));
      std::this_thread::sleep_until(next);
    }
  }
}

Result<uint64_t> dropAll(const std::vector<std::string>& files) {
  uint64_t resident = 0;
  for (const std::string& file : files) {
    TESSERA_ASSIGN_OR_RETURN(uint64_t left, dropFromPageCache(file));
    resident += left;
  }
  return resident;
}

int runTessera(const std::string& uri, const std::string& view, double frame_s, uint32_t workers,
               const std::vector<std::string>& drops) {
  Result<uint64_t> resident = dropAll(drops);
  if (!resident) return std::fprintf(stderr, "%s\n", resident.error().message.c_str()), 1;
  const auto start = std::chrono::steady_clock::now();
  auto inner = tessera::openByteSource(uri);
  if (!inner) return std::fprintf(stderr, "%s\n", inner.error().message.c_str()), 1;
  auto source = std::make_shared<CountingSource>(*inner);
  auto archive = tessera::SceneArchive::open(source);
  if (!archive) return std::fprintf(stderr, "%s\n", archive.error().message.c_str()), 1;
  Result<tessera::PerspectiveView> camera = viewByName(view, (*archive)->summary());
  if (!camera) return std::fprintf(stderr, "%s\n", camera.error().message.c_str()), 1;
  tessera::SceneStreamOptions options;
  options.worker_threads = workers;
  auto streamer = tessera::SceneStreamer::open(*archive, options);
  if (!streamer) return std::fprintf(stderr, "%s\n", streamer.error().message.c_str()), 1;
  const double open_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  Result<StreamRun> run =
      streamToFullQuality(**streamer, source.get(), *camera, frame_s, false, start);
  if (!run) return std::fprintf(stderr, "%s: %s\n", uri.c_str(), run.error().message.c_str()), 1;
  const tessera::SceneStreamTotals& totals = (*streamer)->totals();
  const std::optional<tessera::LinkStats> link = source->linkStats();
  // Visible textures, and those wanted at full resolution (level 0).
  std::set<uint32_t> textures;
  uint32_t level0 = 0;
  for (uint32_t o : (*streamer)->drawableObjects()) {
    for (uint32_t t : (*streamer)->object(o)->textures) {
      if (t == tessera::kNoTexture || !textures.insert(t).second) continue;
      level0 += (*streamer)->wantedLevel(t) == 0;
    }
  }
  std::printf(
      "{\"side\": \"tessera\", \"uri\": \"%s\", \"view\": \"%s\", \"seconds\": %.4f, "
      "\"open_seconds\": %.4f, \"complete_seconds\": %.4f, \"frames\": %u, \"reads\": %llu, "
      "\"bytes\": %llu, \"requests\": %llu, \"streamer_reads\": [%llu, %llu, %llu], "
      "\"visible_objects\": %u, \"visible_textures\": %zu, \"textures_at_level0\": %u, "
      "\"resident_pages_after_drop\": %llu, \"prefetch_hit_bytes\": %llu}\n",
      uri.c_str(), view.c_str(), run->full_s, open_s, run->complete_s, run->frames,
      (unsigned long long)source->reads.load(), (unsigned long long)source->bytes.load(),
      (unsigned long long)(link ? link->requests : source->reads.load()),
      (unsigned long long)totals.reads_by_granularity[0],
      (unsigned long long)totals.reads_by_granularity[1],
      (unsigned long long)totals.reads_by_granularity[2], run->last.visible_objects,
      textures.size(), level0, (unsigned long long)*resident,
      (unsigned long long)(link ? link->prefetch_hit_bytes : 0));
  return 0;
}

// The .stg lines whose placements have an object in `view` at full quality: the streamer's
// own visible set, found on the local archive (untimed, before the caches are dropped).
Result<std::set<uint32_t>> visiblePlacements(const std::string& archive_path,
                                             const std::string& placements_path,
                                             const std::string& view) {
  TESSERA_ASSIGN_OR_RETURN(std::vector<Placement> placements, readPlacements(placements_path));
  TESSERA_ASSIGN_OR_RETURN(auto archive, tessera::SceneArchive::openFile(archive_path));
  TESSERA_ASSIGN_OR_RETURN(tessera::PerspectiveView camera, viewByName(view, archive->summary()));
  TESSERA_ASSIGN_OR_RETURN(auto streamer, tessera::SceneStreamer::open(archive));
  TESSERA_TRY(streamToFullQuality(*streamer, &archive->source(), camera, 0, true,
                                  std::chrono::steady_clock::now()));
  std::set<uint32_t> lines;
  for (uint32_t o : streamer->drawableObjects()) {
    const uint32_t source_index = streamer->object(o)->source_index;
    auto it =
        std::upper_bound(placements.begin(), placements.end(), source_index,
                         [](uint32_t index, const Placement& p) { return index < p.first_object; });
    if (it == placements.begin() ||
        source_index >= (it - 1)->first_object + (it - 1)->object_count) {
      return fail(ErrorCode::kCorrupt,
                  fmt::format("object {} is in no placement of {}", source_index, placements_path));
    }
    lines.insert((it - 1)->line);
  }
  return lines;
}

int runPerFile(const std::string& stg, const std::string& archive, const std::string& placements,
               const std::string& view, uint32_t threads, bool parse_models,
               const std::string& drop_list) {
  std::set<uint32_t> lines;
  if (!view.empty()) {
    Result<std::set<uint32_t>> visible = visiblePlacements(archive, placements, view);
    if (!visible) return std::fprintf(stderr, "%s\n", visible.error().message.c_str()), 1;
    lines = std::move(*visible);
  }
  std::vector<std::string> drops;
  if (!drop_list.empty()) {
    std::ifstream in(drop_list);
    for (std::string file; std::getline(in, file);)
      if (!file.empty()) drops.push_back(file);
    if (drops.empty()) return std::fprintf(stderr, "%s: no files to drop\n", drop_list.c_str()), 1;
  }
  Result<uint64_t> resident = dropAll(drops);
  if (!resident) return std::fprintf(stderr, "%s\n", resident.error().message.c_str()), 1;
  Result<PerFileReport> report = loadPerFile(stg, lines, threads, parse_models);
  if (!report) return std::fprintf(stderr, "%s\n", report.error().message.c_str()), 1;
  std::printf(
      "{\"side\": \"%s\", \"uri\": \"%s\", \"view\": \"%s\", \"seconds\": %.4f, "
      "\"reads\": %llu, \"bytes\": %llu, \"requests\": %llu, \"placements\": %zu, "
      "\"models\": %u, \"textures\": %u, \"texels\": %llu, \"resident_pages_after_drop\": %llu}\n",
      parse_models ? "perfile" : "perfile-noparse", stg.c_str(),
      view.empty() ? "all" : view.c_str(), report->seconds, (unsigned long long)report->files,
      (unsigned long long)report->bytes, (unsigned long long)report->files, lines.size(),
      report->models, report->textures, (unsigned long long)report->texels,
      (unsigned long long)*resident);
  return 0;
}

}  // namespace
}  // namespace coldload

int main(int argc, char** argv) {
  CLI::App app{"issue 28's cold-load benchmark: SceneStreamer against per-file loading"};
  app.require_subcommand(1);
  std::string models, work, uri, view, stg, archive, placements, drop_list;
  std::vector<std::string> drops;
  double fps = 60;
  uint32_t threads = 2;
  bool all = false, no_model_parse = false;
  CLI::App* prepare = app.add_subcommand("prepare", "select the models, write the .stg, build");
  prepare->add_option("--models", models, "FlightGear Models folder")->required();
  prepare->add_option("--work", work, "work folder")->required();
  CLI::App* tessera = app.add_subcommand("tessera", "stream a view to full quality");
  tessera->add_option("--archive", uri, "scene archive path or URL")->required();
  tessera->add_option("--view", view, "street, oblique or overview")->required();
  tessera->add_option("--fps", fps, "frames a second of the render loop");
  tessera->add_option("--workers", threads, "SceneStreamer worker threads");
  tessera->add_option("--drop", drops, "files to drop from the page cache first");
  CLI::App* perfile = app.add_subcommand("perfile", "load a view's files as a viewer does");
  perfile->add_option("--stg", stg, ".stg path or URL")->required();
  perfile->add_option("--archive", archive, "the local scene archive (finds the view's objects)");
  perfile->add_option("--placements", placements, "placements.tsv of prepare");
  perfile->add_option("--view", view, "street, oblique or overview");
  perfile->add_flag("--all", all, "every file of the scene, whatever the view");
  perfile->add_flag("--no-model-parse", no_model_parse,
                    "read models without parsing their geometry (a lower bound)");
  perfile->add_option("--threads", threads, "files loaded at once");
  perfile->add_option("--drop-list", drop_list, "file listing files to drop from the cache");
  CLI11_PARSE(app, argc, argv);
  if (prepare->parsed()) {
    tessera::Result<void> done = coldload::prepare(models, work);
    if (!done) return std::fprintf(stderr, "%s\n", done.error().message.c_str()), 1;
    return 0;
  }
  if (tessera->parsed()) return coldload::runTessera(uri, view, 1 / fps, threads, drops);
  if (all == !view.empty() || (!all && (archive.empty() || placements.empty()))) {
    std::fprintf(stderr, "perfile: give --view with --archive and --placements, or --all\n");
    return 2;
  }
  return coldload::runPerFile(stg, archive, placements, view, threads, !no_model_parse, drop_list);
}
