// `tessera fly SCENE.tess`: flies a 3D camera path in real time at a fixed frame rate, the
// streamer updated and the scene drawn headless every frame, then settles at the last pose and
// compares the picture at rest with the same renderer holding every texture whole.
#include "scene_fly_command.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <thread>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <tessera/gl.h>
#include <tessera/open.h>
#include <tessera/picture_file.h>
#include <tessera/scene.h>
#include <tessera/scene_render.h>
#include <tessera/scene_stream.h>

#include "cli.h"
#include "fly_render.h"
#include "scene_path.h"

namespace tessera::cli {

namespace {

constexpr uint64_t kSceneUploadBudgetMib = 16;

using Clock = std::chrono::steady_clock;

/// Frames the settling at the end may take before the rest picture is taken anyway.
constexpr int kMaxSettleFrames = 2000;

double msBetween(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

nlohmann::json percentiles(std::vector<double> values) {
  if (values.empty()) return {{"p50", 0}, {"p99", 0}, {"max", 0}};
  std::sort(values.begin(), values.end());
  auto at = [&](double p) { return values[size_t(p / 100 * double(values.size() - 1) + 0.5)]; };
  return {{"p50", at(50)}, {"p99", at(99)}, {"max", values.back()}};
}

struct SceneFlightSetup {
  std::shared_ptr<SceneArchive> archive;
  ScenePath path;
  uint32_t viewport_w = 0, viewport_h = 0;
};

Result<SceneFlightSetup> setUpSceneFlight(const FlyArgs& args) {
  SceneFlightSetup setup;
  if (!parseViewport(args.viewport, setup.viewport_w, setup.viewport_h))
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("--viewport '{}' must be WxH with each side 1..16384", args.viewport));
  if (!(args.fps > 0 && args.fps <= 1000))
    return fail(ErrorCode::kInvalidArgument, "--fps must be in (0, 1000]");
  if (!(args.duration_s > 0 && args.duration_s <= 86400))
    return fail(ErrorCode::kInvalidArgument, "--duration must be in (0, 86400] seconds");
  Result<std::shared_ptr<ByteSource>> source = openByteSource(args.archive);
  if (!source) return forwardError(source);
  Result<std::shared_ptr<SceneArchive>> archive = SceneArchive::open(*source);
  if (!archive) return forwardError(archive);
  setup.archive = *archive;
  if (args.path == "orbit" || args.path == "pan") {
    setup.path = orbitPath(setup.archive->summary(), args.duration_s);
  } else if (args.path == "zoom" || args.path == "jump" || args.path == "spiral") {
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("--path {}: a scene flies orbit or a scene keyframe file "
                            "(docs/fly.md, \"Scenes\")",
                            args.path));
  } else {
    Result<ScenePath> path = loadScenePathFile(args.path);
    if (!path) return forwardError(path);
    setup.path = std::move(*path);
  }
  return setup;
}

/// Full quality: every visible leaf arrived, every visible texture resident at the level the
/// streamer wants and sampled at it on the GPU.
bool fullQuality(const SceneFrameStats& frame, const SceneDrawStats& draw) {
  return frame.waiting_leaves == 0 && frame.missing_pixels == 0 && draw.textures_below_wanted == 0;
}

/// What a flight recorded; written out after it.
struct SceneFlightLog {
  std::vector<std::string> csv_rows;
  std::vector<double> update_ms, render_ms;
  std::vector<ReportFrame> report_frames;
  std::vector<ReportPicture> pictures;
  size_t frames = 0, late_frames = 0, full_quality_frames = 0;
  /// Frames after the first picture with a visible object not drawn with its texture.
  size_t untextured_frames = 0;
  int64_t first_picture_frame = -1;
  struct Stop {
    double at_s = 0;
    double full_quality_ms = -1;  ///< wall time from the stop's first frame; -1: not reached
    double started_wall_s = -1;
  };
  std::vector<Stop> stops;
  double wall_s = 0;
  uint64_t peak_texel_bytes = 0;  ///< budgeted and pinned, the most any frame held

  void record(uint64_t k, double now_s, double fps, const ScenePose& pose, const SceneFrameStats& f,
              const SceneDrawStats& d, double update, double render,
              const SceneStreamTotals& totals) {
    ++frames;
    wall_s = now_s;
    late_frames += now_s > double(k + 1) / fps;
    update_ms.push_back(update);
    render_ms.push_back(render);
    const uint32_t untextured = f.untextured_objects + d.untextured_objects;
    if (first_picture_frame < 0 && d.objects_drawn > 0) first_picture_frame = int64_t(k);
    if (first_picture_frame >= 0 && untextured > 0) ++untextured_frames;
    const bool full = fullQuality(f, d);
    full_quality_frames += full;
    peak_texel_bytes = std::max(peak_texel_bytes, f.texel_bytes + f.pinned_texel_bytes);
    const double t_s = double(k) / fps;
    for (Stop& stop : stops) {
      if (t_s < stop.at_s || stop.full_quality_ms >= 0) continue;
      if (stop.started_wall_s < 0) stop.started_wall_s = now_s;
      if (full) stop.full_quality_ms = (now_s - stop.started_wall_s) * 1000;
    }
    csv_rows.push_back(fmt::format(
        "{},{:.2f},{:.3f},{:.3f},{:.3f},{:.2f},{:.2f},{},{},{},{},{},{},{},{},{},{},{},{:.4f},{:."
        "4f}",
        k, now_s * 1000, pose.x, pose.y, pose.z, pose.yaw_rad * 180 / std::numbers::pi,
        pose.pitch_rad * 180 / std::numbers::pi, f.visible_objects, d.objects_drawn, untextured,
        f.waiting_leaves, f.missing_pixels, f.texel_bytes, f.pinned_texel_bytes, totals.reads,
        totals.bytes_read, d.levels_uploaded, d.bytes_uploaded, update, render));
    report_frames.push_back({now_s * 1000, update, render, -1,
                             f.visible_objects ? double(d.objects_drawn) / f.visible_objects : 1.0,
                             untextured == 0, totals.bytes_read, 0, 0, 0, 0});
  }
};

/// A picture to a PNG in the output folder, kept for the report.
Result<void> savePicture(const FlyArgs& args, SceneFlightLog& log, const Picture& picture,
                         const std::string& name, const std::string& caption) {
  return writeReportPicture(picture, args.out_dir + "/" + name, caption,
                            args.report ? &log.pictures : nullptr);
}

/// Flies the path in real time: frame k is shown at k / fps after the start, or as soon as
/// the one before it is done when the flight runs late (it never skips a frame).
Result<void> flySceneFrames(const FlyArgs& args, const SceneFlightSetup& setup,
                            SceneStreamer& streamer, SceneRenderer& renderer, SceneFlightLog& log) {
  for (const SceneStop& stop : setup.path.stops()) log.stops.push_back({stop.from_s});
  const uint64_t frames = uint64_t(std::floor(setup.path.durationS() * args.fps)) + 1;
  const auto start = Clock::now();
  for (uint64_t k = 0; k < frames; ++k) {
    const double t_s = double(k) / args.fps;
    std::this_thread::sleep_until(
        start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(t_s)));
    const ScenePose pose = setup.path.at(t_s);
    const PerspectiveView camera =
        perspectiveOf(pose, kSceneFovYRad, setup.viewport_w, setup.viewport_h);
    const auto before = Clock::now();
    const SceneFrameStats frame = streamer.update(camera);
    const double update_ms = msBetween(before, Clock::now());
    const SceneDrawStats draw = renderer.draw(streamer, camera);
    const double now_s = msBetween(start, Clock::now()) / 1000;
    log.record(k, now_s, args.fps, pose, frame, draw, update_ms, draw.render_ms, streamer.totals());
    if (std::find(args.screenshot_frames.begin(), args.screenshot_frames.end(), k) !=
        args.screenshot_frames.end())
      TESSERA_TRY(savePicture(args, log, renderer.readPixels(), fmt::format("frame-{}.png", k),
                              fmt::format("frame {} ({:.2f} s)", k, t_s)));
  }
  return {};
}

/// The picture at rest at the path's last pose and its comparison with every texture whole.
struct RestFigures {
  int settle_frames = 0;
  SceneFrameStats frame;
  SceneDrawStats draw;
  PictureDifference difference;
  uint64_t full_texel_bytes = 0;         ///< every level of every texture, 4 bytes a texel
  uint64_t full_level0_texel_bytes = 0;  ///< level 0 of every texture
  uint32_t reference_read_failures = 0;
};

Result<RestFigures> restFigures(const FlyArgs& args, const SceneFlightSetup& setup,
                                SceneStreamer& streamer, SceneRenderer& renderer,
                                SceneFlightLog& log) {
  RestFigures rest;
  const PerspectiveView camera = perspectiveOf(setup.path.at(setup.path.durationS()), kSceneFovYRad,
                                               setup.viewport_w, setup.viewport_h);
  // Frame-stepping: waitForReads is for tools that step frames, as this settling does.
  for (; rest.settle_frames < kMaxSettleFrames; ++rest.settle_frames) {
    rest.frame = streamer.update(camera);
    rest.draw = renderer.draw(streamer, camera);
    if (rest.settle_frames > 0 && rest.frame.reads_started == 0 &&
        rest.frame.results_applied == 0 && rest.draw.bytes_uploaded == 0 &&
        fullQuality(rest.frame, rest.draw))
      break;
    streamer.waitForReads();
  }
  const Picture streamed = renderer.readPixels();
  TESSERA_TRY(savePicture(args, log, streamed, "rest.png", "at rest, streamed"));
  SceneRenderOptions whole;
  whole.all_levels_resident = true;
  Result<std::unique_ptr<SceneRenderer>> reference = SceneRenderer::create(setup.archive, whole);
  if (!reference) return forwardError(reference);
  (*reference)->draw(streamer, camera);
  rest.reference_read_failures = (*reference)->readFailures();
  if (rest.reference_read_failures)
    return fail(ErrorCode::kIo, fmt::format("{}: the reference could not read every texture: {}",
                                            args.archive, (*reference)->firstReadError()));
  const Picture expected = (*reference)->readPixels();
  TESSERA_TRY(savePicture(args, log, expected, "reference.png", "every texture resident"));
  Result<PictureDifference> difference = comparePictures(streamed, expected);
  if (!difference) return forwardError(difference);
  rest.difference = *difference;
  Result<std::vector<SceneTexture>> textures =
      setup.archive->textures(0, setup.archive->summary().textures);
  if (!textures) return forwardError(textures);
  for (const SceneTexture& texture : *textures) {
    for (uint32_t level = 0; level < texture.info.level_count; ++level)
      rest.full_texel_bytes +=
          uint64_t(texture.info.levelWidthPx(level)) * texture.info.levelHeightPx(level) * 4;
    rest.full_level0_texel_bytes += uint64_t(texture.info.width_px) * texture.info.height_px * 4;
  }
  return rest;
}

nlohmann::json sceneFlightSummary(const FlyArgs& args, const SceneFlightSetup& setup,
                                  const SceneFlightLog& log, const RestFigures& rest,
                                  const SceneStreamer& streamer, const std::string& gl) {
  const SceneStreamTotals& totals = streamer.totals();
  const SceneSummary& scene = setup.archive->summary();
  nlohmann::json stops = nlohmann::json::array();
  std::vector<double> reached;
  for (const SceneFlightLog::Stop& stop : log.stops) {
    stops.push_back(
        {{"at_s", stop.at_s},
         {"full_quality_ms",
          stop.full_quality_ms < 0 ? nlohmann::json() : nlohmann::json(stop.full_quality_ms)}});
    if (stop.full_quality_ms >= 0) reached.push_back(stop.full_quality_ms);
  }
  std::sort(reached.begin(), reached.end());
  const uint64_t rest_texel_bytes = rest.frame.texel_bytes + rest.frame.pinned_texel_bytes;
  const double psnr =
      std::isinf(rest.difference.psnr_db) ? kIdenticalPsnrDb : rest.difference.psnr_db;
  return {
      {"archive", args.archive},
      {"path", setup.path.name},
      {"scene",
       {{"objects", scene.objects},
        {"textures", scene.textures},
        {"nodes", scene.nodes},
        {"bounds", {{"min", scene.bounds.min}, {"max", scene.bounds.max}}}}},
      {"viewport", args.viewport},
      {"fps", args.fps},
      {"renderer", "scene"},
      {"gl", gl},
      {"frames", log.frames},
      {"path_s", setup.path.durationS()},
      {"wall_s", log.wall_s},
      {"slowdown", setup.path.durationS() > 0 ? log.wall_s / setup.path.durationS() : 1.0},
      {"late_frames_pct", log.frames ? 100.0 * log.late_frames / log.frames : 0},
      {"update_ms", percentiles(log.update_ms)},
      {"render_ms", percentiles(log.render_ms)},
      {"reads", totals.reads},
      {"bytes_read", totals.bytes_read},
      {"reads_by_granularity",
       {{"object", totals.reads_by_granularity[0]},
        {"node", totals.reads_by_granularity[1]},
        {"subtree", totals.reads_by_granularity[2]}}},
      {"load_failures", totals.read_errors},
      {"first_picture_frame", log.first_picture_frame},
      {"untextured_frames", log.untextured_frames},
      {"frames_full_quality_pct", log.frames ? 100.0 * log.full_quality_frames / log.frames : 0},
      {"stops", std::move(stops)},
      {"full_quality_ms_median",
       reached.empty() ? nlohmann::json() : nlohmann::json(reached[reached.size() / 2])},
      {"peak_texel_bytes", log.peak_texel_bytes},
      {"upload_budget_mib", args.upload_budget_mib.value_or(kSceneUploadBudgetMib)},
      {"rest",
       {{"settle_frames", rest.settle_frames},
        {"psnr_db", psnr},
        {"max_abs", rest.difference.max_abs},
        {"objects_drawn", rest.draw.objects_drawn},
        {"texel_bytes", rest_texel_bytes},
        {"budgeted_texel_bytes", rest.frame.texel_bytes},
        {"pinned_texel_bytes", rest.frame.pinned_texel_bytes},
        {"gpu_sampled_texel_bytes", rest.draw.sampled_texel_bytes},
        {"full_texel_bytes", rest.full_texel_bytes},
        {"full_level0_texel_bytes", rest.full_level0_texel_bytes}}},
      {"scene_rest_psnr_db", psnr},
      {"rest_texel_memory_pct",
       rest.full_level0_texel_bytes ? 100.0 * rest_texel_bytes / rest.full_level0_texel_bytes : 0},
  };
}

void printSceneSummary(const nlohmann::json& s) {
  std::printf(
      "%s: %zu frames over %.1f s (%.2fx real time), %s\n"
      "  update p50 %.3f ms p99 %.3f ms; render thread p50 %.2f ms p99 %.2f ms (%s)\n"
      "  %s read in %llu reads; untextured frames after the first picture: %zu\n"
      "  at rest: PSNR %s against every texture resident; texel memory %s = %.1f %% of every "
      "texture at full resolution\n",
      s["archive"].get<std::string>().c_str(), s["frames"].get<size_t>(), s["path_s"].get<double>(),
      s["slowdown"].get<double>(), s["path"].get<std::string>().c_str(),
      s["update_ms"]["p50"].get<double>(), s["update_ms"]["p99"].get<double>(),
      s["render_ms"]["p50"].get<double>(), s["render_ms"]["p99"].get<double>(),
      s["gl"].get<std::string>().c_str(), formatBytes(s["bytes_read"].get<uint64_t>()).c_str(),
      static_cast<unsigned long long>(s["reads"].get<uint64_t>()),
      s["untextured_frames"].get<size_t>(),
      formatPsnr(s["scene_rest_psnr_db"].get<double>()).c_str(),
      formatBytes(s["rest"]["texel_bytes"].get<uint64_t>()).c_str(),
      s["rest_texel_memory_pct"].get<double>());
}

Result<nlohmann::json> runSceneFlight(const FlyArgs& args, const SceneFlightSetup& setup) {
  std::error_code ec;
  std::filesystem::create_directories(args.out_dir, ec);
  SceneStreamOptions stream_options;
  if (args.threads) stream_options.worker_threads = args.threads;
  Result<std::unique_ptr<SceneStreamer>> streamer =
      SceneStreamer::open(setup.archive, stream_options);
  if (!streamer) return forwardError(streamer);
  Result<std::unique_ptr<GlContext>> context = GlContext::createHeadless();
  if (!context) return forwardError(context);
  SceneRenderOptions render_options;
  // 0 is "no byte limit", as for image flights; the scene renderer's budget does not adapt
  // yet, so without --upload-budget-mib it is the image flights' former fixed 16 MiB.
  const uint64_t budget_mib = args.upload_budget_mib.value_or(kSceneUploadBudgetMib);
  render_options.upload_budget_bytes = budget_mib ? budget_mib << 20 : UINT64_MAX;
  Result<std::unique_ptr<SceneRenderer>> renderer =
      SceneRenderer::create(setup.archive, render_options);
  if (!renderer) return forwardError(renderer);
  SceneFlightLog log;
  TESSERA_TRY(flySceneFrames(args, setup, **streamer, **renderer, log));
  Result<RestFigures> rest = restFigures(args, setup, **streamer, **renderer, log);
  if (!rest) return forwardError(rest);
  nlohmann::json summary =
      sceneFlightSummary(args, setup, log, *rest, **streamer, (*context)->description());
  std::ofstream csv(args.out_dir + "/frames.csv");
  csv << "frame,t_ms,x,y,z,yaw_deg,pitch_deg,visible_objects,drawn_objects,untextured,"
         "waiting_leaves,missing_pixels,texel_bytes,pinned_texel_bytes,reads,bytes_read,"
         "levels_uploaded,upload_bytes,update_ms,render_ms\n";
  for (const std::string& row : log.csv_rows) csv << row << "\n";
  std::ofstream(args.out_dir + "/summary.json") << summary.dump(2) << "\n";
  if (!csv) return fail(ErrorCode::kIo, args.out_dir + "/frames.csv: cannot write");
  if (args.report)
    TESSERA_TRY(
        writeFlyReport(args.out_dir + "/report.html", summary, log.report_frames, log.pictures));
  if (args.json)
    std::printf("%s\n", summary.dump(2).c_str());
  else if (!args.quiet)
    printSceneSummary(summary);
  return summary;
}

}  // namespace

bool isSceneArchive(const std::string& path_or_url) {
  // A URL is not probed: the probe would cost the server a request of its own before the
  // image flight's open (a URL flies as images; docs/scenes.md, "Not done").
  if (isRemoteUri(path_or_url)) return false;
  Result<std::shared_ptr<SceneArchive>> scene = SceneArchive::openFile(path_or_url);
  return scene.has_value();
}

int runSceneFly(const FlyArgs& args) {
  Result<SceneFlightSetup> setup = setUpSceneFlight(args);
  if (!setup) return reportError(setup.error());
  Result<nlohmann::json> flown = runSceneFlight(args, *setup);
  if (!flown) return reportError(flown.error());
  const nlohmann::json& summary = *flown;
  const uint64_t failures = summary["load_failures"].get<uint64_t>();
  const size_t untextured = summary["untextured_frames"].get<size_t>();
  if (failures == 0 && untextured == 0) return kExitOk;
  // The flight ran and wrote its outputs, but the pictures missed data: not a success.
  std::fprintf(stderr,
               "tessera: %s: %llu reads failed; %zu frames showed a visible object "
               "untextured\n",
               args.archive.c_str(), static_cast<unsigned long long>(failures), untextured);
  return kExitLoadFailures;
}

}  // namespace tessera::cli
