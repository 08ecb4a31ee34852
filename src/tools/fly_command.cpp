// `tessera fly`: flies a camera path headless at a fixed frame rate, in real time, and
// records what the runtime did each frame; without --render, uploads are accepted at once.
#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <thread>
#include <unordered_map>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <tessera/archive.h>
#include <tessera/open.h>
#include <tessera/picture_file.h>
#include <tessera/byte_source.h>
#include <tessera/gl.h>
#include <tessera/link.h>
#include <tessera/renderer.h>
#include <tessera/stream.h>

#include <tessera/codec_scratch.h>
#include "display_window_option.h"
#include "camera_path.h"
#include "fly_command.h"
#include "fly_render.h"
#include "scene_fly_command.h"
#include "cli.h"

namespace tessera::cli {

namespace {

using Clock = std::chrono::steady_clock;

/// Bounds of --duration and --still-after (a day), --speed and --threads.
constexpr double kMaxDurationS = 86400;
constexpr double kMaxSpeedPxS = 1e9;
constexpr uint32_t kMaxLoaderThreads = 1024;

/// A flight that took this much longer than its path is noted as slower than real time.
constexpr double kSlowdownNoted = 1.05;

/// Failed loads whose messages summary.json keeps.
constexpr size_t kFailuresKept = 10;

/// Without --render, what a renderer with room for everything answers: every upload accepted.
ApplyResult acceptEverything(const FrameUpdate& update) {
  ApplyResult result;
  for (const auto& tile : update.uploads) result.accepted.push_back(tile->id);
  return result;
}

/// Drops the archive's pages from the page cache (posix_fadvise DONTNEED: no root needed,
/// unlike /proc/sys/vm/drop_caches), so the next reads come from the disk.
void dropFromPageCache(const std::string& path) {
  int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return;
  ::fdatasync(fd);
  ::posix_fadvise(fd, 0, 0, POSIX_FADV_DONTNEED);
  ::close(fd);
}

double percentile(std::vector<double> values, double p) {
  if (values.empty()) return 0;
  std::sort(values.begin(), values.end());
  size_t index = std::min(values.size() - 1, size_t(p / 100 * (values.size() - 1) + 0.5));
  return values[index];
}

uint64_t peakRssBytes() {
  std::ifstream status("/proc/self/status");
  std::string key;
  while (status >> key) {
    if (key == "VmHWM:") {
      uint64_t kib = 0;
      status >> kib;
      return kib * 1024;
    }
  }
  return 0;
}

/// Per jump (and at the start): how long until the view was at full detail, and until the
/// whole clip region was loaded (Backes et al., Table 1).
struct JumpTiming {
  double at_s = 0;
  double full_detail_ms = -1;
  double clip_region_ms = -1;
  std::vector<TileId> uploaded;  ///< tiles uploaded until the next jump
  double decode_bound_ms = -1;   ///< --decode-bound: those tiles decoded on every thread
  double rest_psnr_db = -1;      ///< --render: the picture before the next jump against the
  uint32_t rest_max_abs = 0;     ///< reference of the same resident tiles
};

/// The decode part of the physical bound on a jump's load time: the tiles it uploaded,
/// decoded from memory by `threads` threads at once into buffers faulted in beforehand (as
/// the loader's prewarmed ones are), with nothing else to do: no reads, checksums, queue or
/// cache. Wall time in ms.
Result<double> decodeBoundMs(const Archive& archive, std::span<const TileId> tiles,
                             uint32_t threads) {
  struct Work {
    TileId id;
    TileEntry entry;
    std::vector<uint8_t> payload;
    Image out;
  };
  std::vector<Work> work(tiles.size());
  for (size_t i = 0; i < tiles.size(); ++i) {
    Work& w = work[i];
    w.id = tiles[i];
    Result<TileEntry> entry = archive.tileEntry(w.id);
    if (!entry) return forwardError(entry);
    w.entry = *entry;
    if (w.entry.hasPayload()) {
      Result<std::vector<uint8_t>> payload = archive.readPayload(w.id, w.entry);
      if (!payload) return forwardError(payload);
      w.payload = std::move(*payload);
    }
    w.out.texels.assign(archive.images()[w.id.image].storedTileBytes(), 1);
  }
  std::atomic<size_t> next{0};
  std::atomic<bool> failed{false};
  auto worker = [&] {
    CodecScratch scratch;
    for (size_t i; (i = next.fetch_add(1)) < work.size();)
      if (!archive.decodeTileInto(work[i].id, work[i].entry, work[i].payload, work[i].out,
                                  &scratch))
        failed = true;
  };
  const auto started = Clock::now();
  {
    std::vector<std::jthread> pool;
    for (uint32_t t = 1; t < threads; ++t) pool.emplace_back(worker);
    worker();
  }
  const double ms = std::chrono::duration<double, std::milli>(Clock::now() - started).count();
  if (failed) return fail(ErrorCode::kCorrupt, archive.name() + ": a tile failed to decode");
  return ms;
}

/// What a flight starts from: the checked arguments, the archive and the camera path.
struct FlightSetup {
  uint32_t viewport_w = 0;
  uint32_t viewport_h = 0;
  /// With --link, the simulated link every read of the archive crosses; else null.
  std::shared_ptr<ThrottledSource> link;
  std::shared_ptr<Archive> archive;
  double open_ms = 0;     ///< opening: part of a remote client's time to its first picture
  bool remote = false;    ///< reads cross a network, simulated or real
  bool adaptive = false;  ///< adaptive scheduling on
  ImageInfo info;         ///< the image flown over
  CameraPath path;
};

/// The bounds of the numeric options (NaN fails every comparison, so each is written to
/// reject it): a NaN speed made the pan's keyframe loop endless, a NaN or negative duration
/// flew one frame and reported success.
Result<void> checkFlyArgs(const FlyArgs& args) {
  if (!(args.fps > 0 && args.fps <= 1000))
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("--fps {}: must be in (0, 1000]", args.fps));
  if (!(args.speed_px_s > 0 && args.speed_px_s <= kMaxSpeedPxS))
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("--speed {}: must be in (0, {:g}] level-0 px/s", args.speed_px_s,
                            kMaxSpeedPxS));
  if (!(args.duration_s > 0 && args.duration_s <= kMaxDurationS))
    return fail(
        ErrorCode::kInvalidArgument,
        fmt::format("--duration {}: must be in (0, {:g}] seconds", args.duration_s, kMaxDurationS));
  if (!(args.still_after_s >= 0 && args.still_after_s <= kMaxDurationS))
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("--still-after {}: must be in [0, {:g}] seconds", args.still_after_s,
                            kMaxDurationS));
  if (args.upload_budget == 0)
    return fail(ErrorCode::kInvalidArgument,
                "--upload-budget 0: at least one tile a frame, or nothing is ever drawn");
  if (args.threads > kMaxLoaderThreads)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("--threads {}: at most {}", args.threads, kMaxLoaderThreads));
  return {};
}

/// Checks `args`, opens the archive (through the simulated link with --link, the header too,
/// as a remote client would read it) and builds the camera path.
Result<FlightSetup> setUpFlight(const FlyArgs& args) {
  FlightSetup setup;
  if (std::sscanf(args.viewport.c_str(), "%ux%u", &setup.viewport_w, &setup.viewport_h) != 2 ||
      setup.viewport_w == 0 || setup.viewport_h == 0 || setup.viewport_w > 16384 ||
      setup.viewport_h > 16384)
    return fail(ErrorCode::kInvalidArgument, "--viewport must be WxH, e.g. 1920x1080");
  TESSERA_TRY(checkFlyArgs(args));
  const auto open_start = Clock::now();
  Result<std::shared_ptr<Archive>> archive = fail(ErrorCode::kInternal, "not opened");
  if (!args.link.empty()) {
    Result<LinkModel> model = parseLinkModel(args.link);
    if (!model) return forwardError(model);
    Result<std::shared_ptr<ByteSource>> inner = openByteSource(args.archive);
    if (!inner) return forwardError(inner);
    setup.link = makeThrottledSource(*inner, *model);
    archive = Archive::open(setup.link);
  } else {
    archive = openArchive(args.archive);
  }
  if (!archive) return forwardError(archive);
  setup.archive = std::move(*archive);
  setup.open_ms = std::chrono::duration<double, std::milli>(Clock::now() - open_start).count();
  if (args.transcode != "none" && args.transcode != "bc1")
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("--transcode {}: must be none or bc1", args.transcode));
  // The display window maps --render's picture; without one it would be ignored unseen.
  if (args.render == "none" && (args.window != "auto" || args.gamma != "1"))
    return fail(
        ErrorCode::kInvalidArgument,
        fmt::format("{}: the display window applies to --render's picture; add --render "
                    "tile-quads or clipmap",
                    args.window != "auto" ? "--window " + args.window : "--gamma " + args.gamma));
  if (args.adaptive != "auto" && args.adaptive != "on" && args.adaptive != "off")
    return fail(ErrorCode::kInvalidArgument, "--adaptive must be auto, on or off");
  setup.remote = setup.link || isRemoteUri(args.archive);
  setup.adaptive = args.adaptive == "on" || (args.adaptive == "auto" && setup.remote);
  if (Result<EgressBudget> egress = parseEgressBudget(args.egress); !egress)
    return forwardError(egress);
  if (args.image >= setup.archive->images().size())
    return fail(ErrorCode::kInvalidArgument, fmt::format("no image {}", args.image));
  setup.info = setup.archive->images()[args.image];
  Result<CameraPath> path = std::filesystem::exists(args.path)
                                ? loadPathFile(args.path)
                                : builtinPath(args.path, setup.info, args.speed_px_s,
                                              args.duration_s, setup.viewport_w, setup.viewport_h);
  if (!path) return forwardError(path);
  setup.path = std::move(*path);
  return setup;
}

/// The streamer's options: the remote tuning first wherever reads cross a network, then what
/// the user set explicitly.
StreamerOptions flightStreamerOptions(const FlyArgs& args, const FlightSetup& setup) {
  StreamerOptions options;
  if (setup.remote) tuneForRemoteSource(options);
  options.cache_budget_bytes = args.cache_mib << 20;
  options.viewer_shift_eviction = args.eviction != "lru";
  if (args.threads != 0 || !setup.remote) options.loader_threads = args.threads;
  options.residency.upload_budget_tiles = args.upload_budget;
  if (args.upload_budget_mib) options.residency.upload_budget_bytes = *args.upload_budget_mib << 20;
  options.residency.adaptive_upload.enabled = !args.upload_budget_mib && args.render != "none";
  options.residency.adaptive_upload.frame_ms = 1000 / args.fps;
  if (args.merge_gap_kib) options.merge_gap_bytes = *args.merge_gap_kib << 10;
  if (!setup.remote || args.read_ahead_kib != FlyArgs{}.read_ahead_kib)
    options.read_ahead_bytes = args.read_ahead_kib << 10;
  options.loader_priority = args.loader_priority == "idle"   ? LoaderPriority::kIdle
                            : args.loader_priority == "nice" ? LoaderPriority::kNice
                                                             : LoaderPriority::kAuto;
  options.adaptive.enabled = setup.adaptive;
  options.adaptive.still_after_s = args.still_after_s;
  if (Result<EgressBudget> egress = parseEgressBudget(args.egress); egress)
    options.adaptive.egress = *egress;  // checked when the command line was parsed
  options.adaptive.egress.max_prefetch_bytes = args.prefetch_max_kib << 10;
  options.adaptive.egress.max_prefetch_requests = args.prefetch_max_requests;
  if (args.batch_gap_kib) options.batch_gap_bytes = *args.batch_gap_kib << 10;
  if (args.max_read_kib) options.max_merged_read_bytes = *args.max_read_kib << 10;
  return options;
}

/// What a flight recorded, frame by frame and per jump; written out after it.
struct FlightLog {
  std::vector<std::string> csv_rows;   ///< frames.csv up to render_ms
  std::vector<std::string> csv_tails;  ///< the columns after gpu_ms, known only at the end
  std::vector<double> update_ms;
  std::vector<double> render_ms;
  std::vector<ReportFrame> report_frames;
  std::vector<ReportPicture> report_pictures;
  std::vector<JumpTiming> jumps{{0}};
  size_t frames = 0;
  size_t frames_full_detail = 0;
  size_t frames_covered = 0;
  /// Frames before the first covered one are start-up (the coarsest tile is still loading):
  /// a viewer shows its first picture only then. Coverage is counted from that frame on.
  size_t startup_frames = 0;
  double startup_ms = -1;
  uint64_t uploaded_payload_bytes = 0;
  /// Bytes of the tiles handed to the renderer (texels, or bc blocks), declined ones again
  /// each time they are offered.
  uint64_t upload_bytes_offered = 0;
  FrameReport last{};
  /// Loads that failed, as the frames saw them: per tile whether it loaded on a later try,
  /// and the first kFailuresKept failures with their messages.
  uint64_t failures_seen = 0;
  std::unordered_map<TileId, bool, TileIdHash> failed_tiles;
  std::vector<LoadFailure> first_failures;
  /// Wall time from the first frame to the last, against the path's own length: the flight
  /// ran slower than real time when frames took longer than 1/fps.
  double wall_s = 0;
  size_t late_frames = 0;  ///< frames shown more than a frame interval after their time
  /// Frames of the path not drawn: their time had passed, or the GPU was still busy.
  size_t dropped_frames = 0;
  /// Frames whose streamer update recomputed the residency plan (FrameUpdate::replanned); the
  /// others held the view of the frame before and reused its plan.
  size_t replanned_frames = 0;
  double capture_s = 0;  ///< time the clock stood still for pictures at rest and screenshots
  std::vector<double> upload_budget_bytes;  ///< the budget each frame's uploads had

  /// Notes the frame's failed loads, and the uploads of tiles that had failed before.
  void noteLoads(const FrameUpdate& update) {
    for (const LoadFailure& failure : update.failures) {
      ++failures_seen;
      failed_tiles.try_emplace(failure.id, false).first->second = false;
      if (first_failures.size() < kFailuresKept) first_failures.push_back(failure);
    }
    if (failed_tiles.empty()) return;
    for (const auto& tile : update.uploads)
      if (auto it = failed_tiles.find(tile->id); it != failed_tiles.end()) it->second = true;
  }

  /// Records frame `k`, seen `now_s` after `start`.
  void record(uint64_t k, double now_s, Clock::time_point start, const View& view,
              const FrameReport& r, double frame_render_ms, double fps) {
    last = r;
    update_ms.push_back(r.update_ms);
    upload_budget_bytes.push_back(double(r.upload_budget_bytes));
    wall_s = now_s;
    late_frames += now_s > double(k + 1) / fps;
    ++frames;
    frames_full_detail += r.coverage_desired >= 1.0;
    if (startup_ms < 0 && r.fully_covered) startup_ms = now_s * 1000;
    if (startup_ms < 0) ++startup_frames;
    frames_covered += r.fully_covered;
    uploaded_payload_bytes = r.payload_bytes_total;
    upload_bytes_offered += r.upload_bytes;
    JumpTiming& jump = jumps.back();
    double since_ms = std::max(0.0, (now_s - jump.at_s) * 1000);
    if (jump.full_detail_ms < 0 && r.coverage_desired >= 1.0) jump.full_detail_ms = since_ms;
    // Loading ended when the loader ran dry, which may be up to a frame before this one saw
    // it: the loader's own time stamp, not the frame's, so the figure does not depend on fps.
    if (jump.clip_region_ms < 0 && r.queue_length == 0 && r.in_flight == 0) {
      double idle_s = std::chrono::duration<double>(r.loader_idle_since - start).count();
      jump.clip_region_ms = std::clamp((idle_s - jump.at_s) * 1000, 0.0, since_ms);
    }
    csv_rows.push_back(fmt::format(
        "{},{:.2f},{:.1f},{:.1f},{:.4f},{},{},{:.4f},{},{},{},{},{},{},{},{},{:.4f},{:.4f}", k,
        now_s * 1000, view.ortho.centre_x, view.ortho.centre_y, view.ortho.texels_per_pixel,
        r.desired_level, r.finest_full_level, r.coverage_desired, r.fully_covered ? 1 : 0,
        r.queue_length, r.in_flight, r.uploads, r.upload_bytes, r.bytes_read_total,
        r.tiles_loaded_total, r.load_failures_total, r.update_ms, frame_render_ms));
    csv_tails.push_back(fmt::format(
        "{:.0f},{:.2f},{:.2f},{},{},{},{},{},{},{},{},{},{}", r.link_bytes_per_s, r.link_latency_ms,
        r.queue_wait_ms, r.adaptive ? 1 : 0, r.view_still ? 1 : 0, r.requested_level,
        r.budget_bytes == UINT64_MAX ? int64_t(-1) : int64_t(r.budget_bytes), r.memory_bytes,
        r.requested_bytes, r.deferred_tiles, r.cancelled_total, r.reads_cancelled_total,
        r.upload_budget_bytes));
    report_frames.push_back({now_s * 1000, r.update_ms, frame_render_ms, -1, r.coverage_desired,
                             r.fully_covered, r.bytes_read_total, r.link_bytes_per_s,
                             r.desired_level, r.requested_level, r.finest_full_level});
  }
};

/// A picture of the GPU's last frame to a PNG in the output folder, kept for the report.
Result<void> saveFlightPicture(const FlyArgs& args, FlightLog& log, const Picture& picture,
                               const std::string& name, const std::string& caption) {
  return writeReportPicture(picture, args.out_dir + "/" + name, caption,
                            args.report ? &log.report_pictures : nullptr);
}

/// With --render, after frame `k` at `t_s`: the screenshots asked for, and at rest (the last
/// frame before the next jump, or the end) the picture against the reference of the tiles
/// resident then, with its level overlay.
Result<void> captureFlightPictures(const FlyArgs& args, const FlightSetup& setup, FlyRenderer& gpu,
                                   const View& view, uint64_t k, double t_s, FlightLog& log) {
  if (std::find(args.screenshot_frames.begin(), args.screenshot_frames.end(), k) !=
      args.screenshot_frames.end())
    TESSERA_TRY(saveFlightPicture(args, log, gpu.renderer().readPixels(),
                                  fmt::format("frame-{}.png", k),
                                  fmt::format("frame {} ({:.2f} s)", k, t_s)));
  const double next_t = (k + 1) / args.fps;
  if (next_t <= setup.path.durationS() && !setup.path.jumpsBetween(t_s, next_t)) return {};
  const size_t index = log.jumps.size() - 1;
  Picture picture = gpu.renderer().readPixels();
  if (setup.info.sample_type != SampleType::kU8)  // the reference draws 8-bit images only
    return saveFlightPicture(args, log, picture, fmt::format("rest-{}.png", index),
                             "At rest (a wide image: no CPU reference to compare with)");
  ReferenceOptions reference_options;
  reference_options.available = [&](const TileId& id) { return gpu.renderer().resident(id); };
  Result<Picture> reference = renderReference(*setup.archive, view, reference_options);
  if (!reference) return forwardError(reference);
  Result<PictureDifference> difference = comparePictures(picture, *reference);
  if (!difference) return forwardError(difference);
  // Identical pictures have an infinite PSNR: shown, stored and compared as kIdenticalPsnrDb.
  const double psnr_db = std::min(difference->psnr_db, kIdenticalPsnrDb);
  log.jumps.back().rest_psnr_db = psnr_db;
  log.jumps.back().rest_max_abs = difference->max_abs;
  const std::string when = next_t > setup.path.durationS()
                               ? std::string("at the end of the flight")
                               : fmt::format("before jump {}", index + 1);
  TESSERA_TRY(saveFlightPicture(
      args, log, picture, fmt::format("rest-{}.png", index),
      fmt::format("At rest {}: {} against the CPU reference", when, formatPsnr(psnr_db))));
  Result<Picture> tinted = levelOverlay(picture, *setup.archive, view, reference_options.available);
  if (!tinted) return forwardError(tinted);
  TESSERA_TRY(saveFlightPicture(args, log, *tinted, fmt::format("rest-{}-levels.png", index),
                                "The same, each pixel tinted by the level that draws it"));
  if (args.report) log.report_pictures.back().levels = true;
  return {};
}

/// Frames a real-time flight draws even while the GPU is busy (without uploading): the first,
/// the first after a jump (its time is the jump's), the last before a jump or the end (the
/// picture at rest) and the screenshots asked for.
bool mustDraw(const FlyArgs& args, const FlightSetup& setup, uint64_t k) {
  const double t_s = k / args.fps, next_t = (k + 1) / args.fps;
  return k == 0 || next_t > setup.path.durationS() ||
         setup.path.jumpsBetween((k - 1) / args.fps, t_s) || setup.path.jumpsBetween(t_s, next_t) ||
         std::find(args.screenshot_frames.begin(), args.screenshot_frames.end(), k) !=
             args.screenshot_frames.end();
}

/// Flies the path in real time at args.fps, one streamer update (and with `gpu`, one apply and
/// draw) per frame, and records each frame in `log`. With `gpu` (unless --every-frame), a
/// frame whose time has passed or that comes while the GPU is still busy with the last one is
/// skipped, as a display drops it, so the flight keeps to the wall clock.
Result<void> flyFrames(const FlyArgs& args, const FlightSetup& setup, TileStreamer& streamer,
                       FlyRenderer* gpu, FlightLog& log) {
  if (args.cold && !isRemoteUri(args.archive)) dropFromPageCache(args.archive);
  auto start = Clock::now();
  const double duration = setup.path.durationS();
  const bool real_time = gpu && !args.every_frame;
  double last_t_s = 0;  // the path time of the last frame drawn
  for (uint64_t k = 0;; ++k) {
    double t_s = k / args.fps;
    if (t_s > duration) break;
    // Frame pacing: a real renderer presents at the display rate; this is that wait.
    std::this_thread::sleep_until(
        start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(t_s)));
    double now_s = std::chrono::duration<double>(Clock::now() - start).count();
    const bool must_draw = !real_time || mustDraw(args, setup, k);
    if (!must_draw && (now_s > (k + 1) / args.fps || gpu->busy())) {
      ++log.dropped_frames;
      continue;
    }
    if (k > 0 && setup.path.jumpsBetween(last_t_s, t_s)) {
      if (args.cold && !setup.remote) dropFromPageCache(args.archive);
      log.jumps.push_back({std::chrono::duration<double>(Clock::now() - start).count()});
    }
    View view;
    view.image = args.image;
    view.ortho = setup.path.at(t_s, setup.viewport_w, setup.viewport_h);
    const FrameUpdate& update = streamer.update(view);
    if (update.replanned) ++log.replanned_frames;
    if (args.decode_bound)
      for (const auto& tile : update.uploads) log.jumps.back().uploaded.push_back(tile->id);
    last_t_s = t_s;
    double frame_render_ms = -1;
    if (gpu) {
      // A frame drawn while the GPU is busy uploads nothing: on a software renderer a texture
      // update waits for the frames that read the texture.
      frame_render_ms = gpu->frame(k, view, update, streamer, !real_time || !gpu->busy());
      log.render_ms.push_back(frame_render_ms);
    } else {
      streamer.acknowledge(acceptEverything(update));  // no GPU: a renderer of infinite room
    }
    log.noteLoads(update);
    log.record(k, now_s, start, view, update.report, frame_render_ms, args.fps);
    if (gpu) {
      // The flight's clock stops while pictures are read back and compared with the CPU
      // reference: the harness's work, no viewer's, and up to a second a jump on llvmpipe,
      // which would otherwise come out of the next spot's time.
      const auto capture_started = Clock::now();
      TESSERA_TRY(captureFlightPictures(args, setup, *gpu, view, k, t_s, log));
      const auto spent = Clock::now() - capture_started;
      start += spent;
      log.capture_s += std::chrono::duration<double>(spent).count();
    }
  }
  return {};
}

/// frames.csv: the rows recorded, with the GPU times read back after the flight.
Result<void> writeFramesCsv(const FlyArgs& args, const FlightLog& log) {
  std::ofstream csv(args.out_dir + "/frames.csv", std::ios::app);
  for (size_t i = 0; i < log.csv_rows.size(); ++i)
    csv << log.csv_rows[i] << ","
        << (i < log.report_frames.size() && log.report_frames[i].gpu_ms >= 0
                ? fmt::format("{:.4f}", log.report_frames[i].gpu_ms)
                : std::string("-1"))
        << "," << log.csv_tails[i] << "\n";
  return {};
}

nlohmann::json flightPercentiles(const std::vector<double>& values) {
  return nlohmann::json{
      {"p50", percentile(values, 50)},
      {"p99", percentile(values, 99)},
      {"max", values.empty() ? 0 : *std::max_element(values.begin(), values.end())}};
}

/// summary.json's jumps: full detail and clip-region times, and what --render and
/// --decode-bound measured.
nlohmann::json flightJumps(const FlyArgs& args, const FlightLog& log, bool rendered,
                           uint32_t threads) {
  nlohmann::json jump_list = nlohmann::json::array();
  for (const JumpTiming& j : log.jumps) {
    nlohmann::json entry = {
        {"at_s", j.at_s},
        {"full_detail_ms",
         j.full_detail_ms < 0 ? nlohmann::json() : nlohmann::json(j.full_detail_ms)},
        {"clip_region_ms",
         j.clip_region_ms < 0 ? nlohmann::json() : nlohmann::json(j.clip_region_ms)}};
    if (rendered) {
      entry["rest_psnr_db"] =
          j.rest_psnr_db < 0 ? nlohmann::json() : nlohmann::json(j.rest_psnr_db);
      entry["rest_max_abs"] = j.rest_max_abs;
    }
    if (args.decode_bound) {
      entry["tiles_uploaded"] = j.uploaded.size();
      entry["decode_bound_ms"] = j.decode_bound_ms;
      entry["decode_bound_threads"] = threads;
    }
    jump_list.push_back(std::move(entry));
  }
  return jump_list;
}

/// The median over the jumps (the start included) of the time to full detail, of those that
/// got there; null when none did.
nlohmann::json medianFullDetailMs(const FlightLog& log) {
  std::vector<double> times;
  for (const JumpTiming& jump : log.jumps)
    if (jump.full_detail_ms >= 0) times.push_back(jump.full_detail_ms);
  if (times.empty()) return nullptr;
  return percentile(times, 50);
}

/// summary.json's failures: the first ones, each naming its tile and the problem.
nlohmann::json flightFailures(const FlightLog& log) {
  nlohmann::json list = nlohmann::json::array();
  for (const LoadFailure& failure : log.first_failures)
    list.push_back({{"image", failure.id.image},
                    {"level", failure.id.level},
                    {"x", failure.id.x},
                    {"y", failure.id.y},
                    {"code", errorCodeName(failure.code)},
                    {"message", failure.message}});
  return list;
}

/// summary.json (docs/fly.md, "summary.json").
nlohmann::json flightSummary(const FlyArgs& args, const FlightSetup& setup,
                             const StreamerOptions& options, const FlightLog& log,
                             const CacheStats& cache, const std::string& policy_name,
                             nlohmann::json jumps) {
  const FrameReport& last = log.last;
  const size_t frames = log.frames;
  nlohmann::json summary = {
      {"archive", args.archive},
      {"composite", args.composite},
      {"path", setup.path.name},
      {"codec", codecName(setup.info.default_codec)},
      {"levels", setup.info.level_count},
      {"viewport", args.viewport},
      {"fps", args.fps},
      {"speed_px_s", args.speed_px_s},
      {"page_cache", setup.remote ? "remote (HTTP)"
                     : args.cold  ? "cold (posix_fadvise DONTNEED before each jump)"
                                  : "as found"},
      {"merge_gap_bytes", options.merge_gap_bytes},
      {"batch_gap_bytes", options.batch_gap_bytes},
      {"link_sized_reads", options.link_sized_reads},
      {"read_ahead_bytes", options.read_ahead_bytes},
      {"loader_threads", options.loader_threads},
      {"eviction", policy_name},
      {"cache_budget_bytes", options.cache_budget_bytes},
      {"frames", frames},
      {"path_s", setup.path.durationS()},
      {"wall_s", log.wall_s},
      {"slowdown", setup.path.durationS() > 0 ? log.wall_s / setup.path.durationS() : 1.0},
      {"late_frames_pct", frames ? 100.0 * log.late_frames / frames : 0},
      {"dropped_frames", log.dropped_frames},
      {"replanned_frames", log.replanned_frames},
      {"capture_s", log.capture_s},
      {"drawn_fps", log.wall_s > 0 ? double(frames) / log.wall_s : 0},
      {"pacing", args.render == "none" ? "every frame (no rendering)"
                 : args.every_frame    ? "every frame (--every-frame)"
                                       : "real time (frames skipped while the GPU is busy)"},
      {"upload_budget",
       {{"mode", options.residency.adaptive_upload.enabled ? "adaptive" : "fixed"},
        {"frame_ms", options.residency.adaptive_upload.frame_ms},
        {"share", options.residency.adaptive_upload.upload_share},
        {"bytes_p50", percentile(log.upload_budget_bytes, 50)},
        {"bytes_min", percentile(log.upload_budget_bytes, 0)},
        {"bytes_max", percentile(log.upload_budget_bytes, 100)},
        {"bytes_per_ms_last", last.upload_bytes_per_ms}}},
      {"frames_full_detail_pct", frames ? 100.0 * log.frames_full_detail / frames : 0},
      {"startup_frames", log.startup_frames},
      {"open_ms", setup.open_ms},
      {"startup_ms", log.startup_ms < 0 ? nlohmann::json() : nlohmann::json(log.startup_ms)},
      {"frames_fully_covered_pct",
       frames > log.startup_frames
           ? 100.0 * log.frames_covered / double(frames - log.startup_frames)
           : 0},
      {"update_ms", flightPercentiles(log.update_ms)},
      {"full_detail_ms_median", medianFullDetailMs(log)},
      {"jumps_at_full_detail",
       std::count_if(log.jumps.begin(), log.jumps.end(),
                     [](const JumpTiming& jump) { return jump.full_detail_ms >= 0; })},
      {"jumps", std::move(jumps)},
      {"bytes_read", last.bytes_read_total},
      {"reads", last.reads_total},
      {"hinted_bytes", last.hinted_bytes_total},
      {"payload_bytes_delivered", log.uploaded_payload_bytes},
      {"read_amplification",
       log.uploaded_payload_bytes ? double(last.bytes_read_total) / log.uploaded_payload_bytes : 0},
      {"tiles_loaded", last.tiles_loaded_total},
      {"load_failures", std::max(last.load_failures_total, log.failures_seen)},
      {"failed_tiles", log.failed_tiles.size()},
      {"failed_tiles_loaded_later", std::count_if(log.failed_tiles.begin(), log.failed_tiles.end(),
                                                  [](const auto& tile) { return tile.second; })},
      {"failures", flightFailures(log)},
      {"decode_ms_total", last.decode_ms_total},
      {"upload_bytes_offered", log.upload_bytes_offered},
      {"transcode",
       {{"requested", args.transcode},
        {"active", options.transcode_to_bc1},
        {"tiles", last.tiles_transcoded_total},
        {"ms_total", last.transcode_ms_total}}},
      {"cache",
       {{"hits", cache.hits},
        {"misses", cache.misses},
        {"hit_rate",
         cache.hits + cache.misses ? double(cache.hits) / (cache.hits + cache.misses) : 0},
        {"evictions", cache.evictions},
        {"peak_bytes", cache.peak_bytes}}},
      {"peak_rss_bytes", peakRssBytes()},
      {"adaptive", setup.adaptive ? "on" : "off"},
      {"simulated_link", setup.link ? args.link : "none"},
      {"link_bytes_per_s", last.link_bytes_per_s},
      {"link_latency_ms", last.link_latency_ms},
      {"requests_cancelled", last.cancelled_total},
      {"reads_cancelled", last.reads_cancelled_total},
      {"parents_queued", last.parents_queued_total},
      {"parent_fallbacks", last.parent_fallbacks_total},
      {"children_read_early", last.children_read_early_total},
      {"loader_priority", args.loader_priority},
      {"loader_rescues", last.loader_rescues_total},
      {"rescued_batches", last.rescued_batches_total}};
  if (setup.adaptive) {
    summary["still_after_s"] = args.still_after_s;
    // Egress against what the view needed (docs/remote.md, "Egress"): payload bytes and
    // tiles as the scheduler requested them, each once.
    summary["egress"] = {{"budget", args.egress},
                         {"view_bytes", last.view_bytes_total},
                         {"view_tiles", last.view_tiles_total},
                         {"beyond_view_bytes", last.prefetch_bytes_total},
                         {"beyond_view_tiles", last.prefetch_tiles_total},
                         {"held_back_tiles_last_frame", last.egress_deferred_tiles}};
  }
  return summary;
}

/// Over a network: what the link did, and what the requests saw of it (the last ones).
void addFlightLinkSummary(const Archive& archive, nlohmann::json& summary) {
  std::optional<LinkStats> link_stats = archive.source().linkStats();
  if (!link_stats) return;
  std::vector<double> mib_s, first_byte_ms;
  for (const LinkSample& sample : link_stats->recent) {
    if (sample.seconds > 0) mib_s.push_back(double(sample.bytes) / sample.seconds / 1048576.0);
    first_byte_ms.push_back(sample.first_byte_seconds * 1000);
  }
  summary["link"] = {{"requests", link_stats->requests},
                     {"bytes_received", link_stats->bytes_received},
                     {"retries", link_stats->retries},
                     {"errors", link_stats->errors},
                     {"cancelled", link_stats->cancelled},
                     {"prefetched_bytes", link_stats->prefetched_bytes},
                     {"prefetch_hit_bytes", link_stats->prefetch_hit_bytes},
                     {"connections", link_stats->connections},
                     {"http1_connections", link_stats->http1_connections},
                     {"http2_connections", link_stats->http2_connections},
                     {"max_in_flight", link_stats->max_in_flight},
                     {"recent_requests", link_stats->recent.size()},
                     {"recent_mib_s_p50", percentile(mib_s, 50)},
                     {"recent_first_byte_ms_p50", percentile(first_byte_ms, 50)}};
  // The flight's cost on the wire per byte the view needed: what a metered link pays.
  if (summary.contains("egress")) {
    const auto view_bytes = summary["egress"]["view_bytes"].get<uint64_t>();
    summary["egress"]["requests"] = link_stats->requests;
    summary["egress"]["bytes_received"] = link_stats->bytes_received;
    summary["egress"]["bytes_per_view_byte"] =
        view_bytes ? double(link_stats->bytes_received) / double(view_bytes) : 0.0;
  }
}

/// With --render: the renderer, the driver, and the render thread's and GPU's time per frame.
void addFlightRenderSummary(const FlyArgs& args, const FlyRenderer& gpu, const FlightLog& log,
                            nlohmann::json& summary) {
  std::vector<double> gpu_ms;
  for (const ReportFrame& f : log.report_frames)
    if (f.gpu_ms >= 0) gpu_ms.push_back(f.gpu_ms);
  summary["renderer"] = args.render;
  summary["gl"] = gpu.description();
  summary["render_ms"] = flightPercentiles(log.render_ms);
  summary["render_setup_ms"] = gpu.setupMs();
  summary["render_storage_allocations"] = gpu.flightAllocations();
  summary["gpu_ms"] = flightPercentiles(gpu_ms);
  nlohmann::json psnr_min;  // null until a picture at rest was compared
  for (const JumpTiming& jump : log.jumps)
    if (jump.rest_psnr_db >= 0 && (psnr_min.is_null() || jump.rest_psnr_db < psnr_min))
      psnr_min = jump.rest_psnr_db;
  summary["rest_psnr_db_min"] = psnr_min;
  // What the tiles cost the GPU at the end of the flight (docs/rendering.md, "Block-compressed
  // tiles"): bc1/bc7 blocks as stored, or texels.
  const RenderStats& stats = gpu.renderer().stats();
  summary["texture"] = {{"stored_blocks", gpu.renderer().takesStoredBlocks()},
                        {"gpu_bytes", stats.gpu_bytes},
                        {"resident_tiles", stats.resident_tiles}};
}

/// The one or two lines `tessera fly` prints unless --json or --quiet.
void printFlightSummary(const FlyArgs& args, const FlightSetup& setup, const FlightLog& log,
                        const nlohmann::json& summary) {
  const FrameReport& last = log.last;
  const double first_full_ms = log.jumps[0].full_detail_ms;
  std::printf(
      "%s: %zu frames, %.1f%% at full detail, %.1f%% covered; update p50 %.3f ms p99 "
      "%.3f ms; read %s (amplification %.2f); %s; wrote %s/frames.csv and summary.json\n",
      args.archive.c_str(), log.frames, summary["frames_full_detail_pct"].get<double>(),
      summary["frames_fully_covered_pct"].get<double>(), percentile(log.update_ms, 50),
      percentile(log.update_ms, 99), formatBytes(last.bytes_read_total).c_str(),
      summary["read_amplification"].get<double>(),
      first_full_ms < 0 ? "never at full detail before the first jump"
                        : fmt::format("first full detail after {:.1f} ms", first_full_ms).c_str(),
      args.out_dir.c_str());
  if (const uint64_t failures = summary["load_failures"].get<uint64_t>(); failures > 0)
    std::printf("FAILED: %llu loads of %zu tiles failed (%lld loaded on a later try)\n",
                (unsigned long long)failures, log.failed_tiles.size(),
                (long long)summary["failed_tiles_loaded_later"].get<int64_t>());
  if (args.render != "none")
    std::printf(
        "upload budget %s: %s a frame (median; %s to %s)%s; %zu frames drawn, %zu "
        "skipped (%s)\n",
        summary["upload_budget"]["mode"].get<std::string>().c_str(),
        formatBytes(uint64_t(percentile(log.upload_budget_bytes, 50))).c_str(),
        formatBytes(uint64_t(percentile(log.upload_budget_bytes, 0))).c_str(),
        formatBytes(uint64_t(percentile(log.upload_budget_bytes, 100))).c_str(),
        last.upload_bytes_per_ms > 0
            ? fmt::format(", measured {}/ms", formatBytes(uint64_t(last.upload_bytes_per_ms)))
                  .c_str()
            : "",
        log.frames, log.dropped_frames, summary["pacing"].get<std::string>().c_str());
  if (const double slowdown = summary["slowdown"].get<double>(); slowdown > kSlowdownNoted)
    std::printf(
        "slower than real time: the %.1f-s path took %.1f s (%.0f%% of frames late); times "
        "to full detail are wall-clock times\n",
        summary["path_s"].get<double>(), summary["wall_s"].get<double>(),
        summary["late_frames_pct"].get<double>());
  if (setup.link)
    std::printf(
        "link %s: %s crossed it, %llu reads abandoned in flight; estimate %s/s, %.1f ms "
        "latency; adaptive scheduling %s\n",
        args.link.c_str(), formatBytes(setup.link->totals().bytes).c_str(),
        (unsigned long long)last.reads_cancelled_total,
        formatBytes(uint64_t(last.link_bytes_per_s)).c_str(), last.link_latency_ms,
        setup.adaptive ? "on" : "off");
}

/// frames.csv's header, written before the flight so that an unwritable folder fails first.
Result<void> startFramesCsv(const FlyArgs& args) {
  std::error_code ec;
  std::filesystem::create_directories(args.out_dir, ec);
  std::ofstream csv(args.out_dir + "/frames.csv");
  if (!csv) return fail(ErrorCode::kIo, args.out_dir + "/frames.csv: cannot write");
  csv << "frame,t_ms,centre_x,centre_y,texels_per_pixel,desired_level,finest_full_level,"
         "coverage_desired,fully_covered,queue,in_flight,uploads,upload_bytes,bytes_read,"
         "tiles_loaded,load_failures,update_ms,render_ms,gpu_ms,link_bytes_per_s,"
         "link_latency_ms,queue_wait_ms,adaptive,view_still,requested_level,budget_bytes,"
         "memory_bytes,requested_bytes,deferred_tiles,requests_cancelled,reads_cancelled,"
         "upload_budget_bytes\n";
  return {};
}

/// runFly after the archive is open: fly, then write what the flight recorded. Returns the
/// summary (summary.json).
Result<nlohmann::json> runFlight(const FlyArgs& args, const FlightSetup& setup) {
  if (args.composite == "gpu") {
    Result<std::shared_ptr<TileCompositor>> compositor = createGpuTileCompositor();
    if (!compositor) return forwardError(compositor);
    setup.archive->setTileCompositor(std::move(*compositor));
  }
  // The renderer first: whether it uploads bc1/bc7 blocks as stored decides what the loaders
  // hand it.
  StreamerOptions options = flightStreamerOptions(args, setup);
  std::unique_ptr<FlyRenderer> gpu;
  if (args.render != "none") {
    const std::optional<RendererKind> kind = rendererNamed(args.render);
    if (!kind)
      return fail(ErrorCode::kInvalidArgument,
                  fmt::format("--render {}: no such renderer", args.render));
    Result<DisplayWindow> display =
        displayWindowFromOptions(*setup.archive, args.image, args.window, args.gamma);
    if (!display) return forwardError(display);
    View first;
    first.image = args.image;
    first.ortho = setup.path.at(0, setup.viewport_w, setup.viewport_h);
    Result<std::unique_ptr<FlyRenderer>> created =
        FlyRenderer::create(*kind, setup.info, first, options.residency, args.transcode == "bc1");
    if (!created) return forwardError(created);
    gpu = std::move(*created);
    gpu->renderer().setDisplayWindow(*display);
  }
  options.keep_block_compressed = gpu && gpu->renderer().takesStoredBlocks();
  // Without a renderer the loaders still transcode (their cost is what such a run measures);
  // the clipmap keeps RGBA texels, so for it the tiles stay decoded.
  options.transcode_to_bc1 = args.transcode == "bc1" && (!gpu || options.keep_block_compressed);
  Result<std::unique_ptr<TileStreamer>> streamer = TileStreamer::create(setup.archive, options);
  if (!streamer) return forwardError(streamer);
  TESSERA_TRY(startFramesCsv(args));
  FlightLog log;
  TESSERA_TRY(flyFrames(args, setup, **streamer, gpu.get(), log));
  if (gpu) {
    std::vector<double> gpu_ms = gpu->finishGpuTimes();
    for (size_t i = 0; i < log.report_frames.size() && i < gpu_ms.size(); ++i)
      log.report_frames[i].gpu_ms = gpu_ms[i];
  }
  TESSERA_TRY(writeFramesCsv(args, log));
  const CacheStats cache = (*streamer)->cacheStats();
  const std::string policy_name = (*streamer)->cache().policyName();
  const uint32_t threads =
      args.threads ? args.threads : std::max(1u, std::thread::hardware_concurrency());
  if (args.decode_bound) {
    streamer->reset();  // its loader threads are gone before the bound is measured
    for (JumpTiming& jump : log.jumps) {
      Result<double> ms = decodeBoundMs(*setup.archive, jump.uploaded, threads);
      if (!ms) return forwardError(ms);
      jump.decode_bound_ms = *ms;
    }
  }
  nlohmann::json summary = flightSummary(args, setup, options, log, cache, policy_name,
                                         flightJumps(args, log, gpu != nullptr, threads));
  addFlightLinkSummary(*setup.archive, summary);
  if (gpu) addFlightRenderSummary(args, *gpu, log, summary);
  std::ofstream(args.out_dir + "/summary.json") << summary.dump(2) << "\n";
  if (args.report)
    TESSERA_TRY(writeFlyReport(args.out_dir + "/report.html", summary, log.report_frames,
                               log.report_pictures));
  if (args.json)
    std::printf("%s\n", summary.dump(2).c_str());
  else if (!args.quiet)
    printFlightSummary(args, setup, log, summary);
  return summary;
}

}  // namespace

int runFly(const FlyArgs& args) {
  if (isSceneArchive(args.archive)) return runSceneFly(args);
  Result<FlightSetup> setup = setUpFlight(args);
  if (!setup) return reportError(setup.error());
  Result<nlohmann::json> flown = runFlight(args, *setup);
  if (!flown) return reportError(flown.error());
  const nlohmann::json& summary = *flown;
  const uint64_t failures = summary["load_failures"].get<uint64_t>();
  if (failures == 0) return kExitOk;
  // The flight ran and wrote its outputs, but the picture missed tiles: not a success.
  const nlohmann::json& first = summary["failures"];
  const size_t tiles = summary["failed_tiles"].get<size_t>();
  std::fprintf(stderr, "tessera: %s: %s%s%s\n", args.archive.c_str(),
               tiles ? fmt::format("{} tiles failed to load ({} failures)", tiles, failures).c_str()
                     : fmt::format("{} loads failed", failures).c_str(),
               first.empty() ? "" : "; the first: ",
               first.empty() ? "" : first[0]["message"].get<std::string>().c_str());
  return kExitLoadFailures;
}

CLI::Validator egressSpecValidator() {
  return CLI::Validator(
      [](std::string& spec) {
        Result<EgressBudget> budget = parseEgressBudget(spec);
        return budget ? std::string() : budget.error().message;
      },
      "default|metered|unbounded|FACTOR", "egress budget");
}

void registerFlyCommand(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<FlyArgs>();
  CLI::App* cmd = app.add_subcommand(
      "fly", "Fly a camera path headless in real time and report streaming figures");
  cmd->add_option("archive", args->archive, kArchiveArgumentHelp)->required();
  cmd->add_option("--path", args->path, "pan, zoom, jump, spiral, or a keyframe file (docs/fly.md)")
      ->capture_default_str();
  cmd->add_option("--speed", args->speed_px_s, "Pan speed in level-0 pixels per second")
      ->capture_default_str();
  cmd->add_option("--duration", args->duration_s, "Seconds to fly (built-in paths)")
      ->capture_default_str();
  cmd->add_option("--viewport", args->viewport, "Viewport WxH, e.g. 1280x720, 1920x1080, 3840x2160")
      ->capture_default_str();
  cmd->add_option("--fps", args->fps, "Frames per second")->capture_default_str();
  cmd->add_option("--cache-mib", args->cache_mib, "Tile cache budget in MiB")
      ->capture_default_str();
  cmd->add_option("--eviction", args->eviction, "viewer-shift or lru")
      ->check(CLI::IsMember({"viewer-shift", "lru"}))
      ->capture_default_str();
  cmd->add_option("--threads", args->threads, "Loader threads (0 = all cores)")
      ->capture_default_str();
  cmd->add_option("--upload-budget", args->upload_budget, "Most tiles uploaded per frame")
      ->capture_default_str();
  cmd->add_option("--upload-budget-mib", args->upload_budget_mib,
                  "A fixed budget of texel MiB uploaded per frame (0 = no byte limit); "
                  "default: with --render, what the renderer's measured upload rate fits in a "
                  "quarter of a frame, else 16");
  cmd->add_flag("--every-frame", args->every_frame,
                "With --render, draw every frame of the path however long each takes, "
                "instead of skipping those that come while the GPU is busy");
  cmd->add_option("--loader-priority", args->loader_priority,
                  "auto (SCHED_IDLE, with normal-priority helpers while those starve), idle "
                  "(SCHED_IDLE only) or nice (niceness 5); docs/runtime.md")
      ->check(CLI::IsMember({"auto", "idle", "nice"}))
      ->capture_default_str();
  cmd->add_option("--merge-gap-kib", args->merge_gap_kib,
                  "Reads of tiles closer than this in the file are merged into one (default: 16, "
                  "for a file and a URL alike)");
  cmd->add_option("--batch-gap-kib", args->batch_gap_kib,
                  "Queued tiles whose payloads are closer than this are loaded as one batch "
                  "(StreamerOptions::batch_gap_bytes)");
  cmd->add_option(
      "--max-read-kib", args->max_read_kib,
      "Most bytes one batch spans in the file (StreamerOptions::max_merged_read_bytes)");
  cmd->add_option("--read-ahead-kib", args->read_ahead_kib,
                  "Payload bytes at the head of the loader's queue fetched ahead (0 = off)")
      ->capture_default_str();
  cmd->add_option("--image", args->image, "Image index")->capture_default_str();
  cmd->add_option("--window", args->window, kWindowOptionHelp)->capture_default_str();
  cmd->add_option("--gamma", args->gamma, kGammaOptionHelp)->capture_default_str();
  cmd->add_option("-o,--out", args->out_dir, "Folder for frames.csv and summary.json")
      ->capture_default_str();
  cmd->add_flag("--json", args->json, "Print the summary as JSON");
  cmd->add_flag("--cold", args->cold,
                "Drop the archive from the page cache at the start and before each jump");
  cmd->add_flag("--decode-bound", args->decode_bound,
                "After the flight, time decoding each jump's uploaded tiles on every thread "
                "from memory (the decode part of the physical bound)");
  cmd->add_option("--render", args->render,
                  "Draw every frame headless: tile-quads or clipmap (none: no GPU work)")
      ->check(CLI::IsMember({"none", "tile-quads", "clipmap"}))
      ->capture_default_str();
  cmd->add_option("--transcode", args->transcode,
                  "bc1: encode JPEG tiles to bc1 on the loader threads, drawn from a bc1 array "
                  "by tile-quads (none: tiles as stored)")
      ->check(CLI::IsMember({"none", "bc1"}))
      ->capture_default_str();
  cmd->add_option("--composite", args->composite,
                  "Where procedural tiles are composited: cpu (the loader threads) or gpu (a "
                  "headless OpenGL context of its own)")
      ->check(CLI::IsMember({"cpu", "gpu"}))
      ->capture_default_str();
  cmd->add_option("--screenshots", args->screenshot_frames,
                  "Frames to save as frame-N.png (with --render)")
      ->delimiter(',');
  cmd->add_flag("--report", args->report,
                "Write report.html: plots and pictures in one self-contained page");
  cmd->add_option("--link", args->link,
                  "Read the archive through a simulated network link RATE:RTT, e.g. 20mbit:40ms "
                  "or 2mbit:150ms (rate in bit/kbit/mbit/gbit per second, round trip in us/ms/s)");
  cmd->add_option(
         "--adaptive", args->adaptive,
         "Adaptive scheduling (request only what the measured link delivers within the "
         "time limits, refine when the view is still): auto (on with --link or a URL), on, off")
      ->check(CLI::IsMember({"auto", "on", "off"}))
      ->capture_default_str();
  cmd->add_option("--egress", args->egress,
                  "What adaptive scheduling fetches beyond the view over the flight: default "
                  "(at most 1.5x the view's bytes and requests), metered (only the view), "
                  "unbounded, or a factor such as 3")
      ->check(egressSpecValidator())
      ->capture_default_str();
  cmd->add_option("--prefetch-max-kib", args->prefetch_max_kib,
                  "Most KiB fetched beyond the view over the flight (0: no cap)");
  cmd->add_option("--prefetch-max-requests", args->prefetch_max_requests,
                  "Most tiles requested beyond the view over the flight (0: no cap)");
  cmd->add_option("--still-after", args->still_after_s,
                  "Seconds without a view change before the still budgets apply (adaptive)")
      ->capture_default_str();
  cmd->add_flag("-q,--quiet", args->quiet, "Print nothing");
  cmd->callback([args, &exit_code] { exit_code = runFly(*args); });
}

}  // namespace tessera::cli
