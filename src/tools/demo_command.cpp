// `tessera demo`: the README's main job. Builds a multi-gigapixel sample archive once, flies
// the standard paths headless with a GPU renderer (EGL; llvmpipe where there is no GPU), and
// writes one HTML page linking each flight's report, printing its path and the headline
// figures. `--view` then opens the viewer on the same archive.
#include <filesystem>
#include <fstream>
#include <sstream>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <tessera/build.h>

#include "cli.h"
#include "fly_command.h"
#include "view_command.h"

namespace tessera::cli {

namespace {

struct DemoArgs {
  std::string dir = "out";
  std::string size = "65536x65536";
  std::string viewport = "1280x720";
  std::string renderer = "tile-quads";
  double seconds = 5;
  bool view = false;
};

/// Builds the sample archive unless one built with the same options is already there (the
/// options are stamped beside it).
Result<std::string> sampleArchive(const DemoArgs& args) {
  const std::string archive = args.dir + "/synthetic-" + args.size + ".tess";
  const std::string stamp = archive + ".args";
  BuildOptions options;
  options.inputs = {"synthetic:" + args.size + ":2:3"};
  options.output = archive;
  options.tile_size_px = 256;
  options.border_px = 1;  // seamless bilinear filtering in the tile-quads renderer
  options.codec = Codec::kJpeg;
  options.quality = 85;
  const std::string wanted = fmt::format("{} tile 256 border 1 jpeg q85", options.inputs.front());
  std::error_code ec;
  if (std::filesystem::exists(archive, ec) && std::filesystem::exists(stamp, ec)) {
    std::ifstream in(stamp);
    std::string found;
    std::getline(in, found);
    if (found == wanted) {
      std::printf("demo: %s is up to date\n", archive.c_str());
      return archive;
    }
  }
  std::printf("demo: building %s from %s (once)\n", archive.c_str(),
              options.inputs.front().c_str());
  std::fflush(stdout);
  std::filesystem::remove(stamp, ec);
  Result<BuildReport> built = buildArchive(options);
  if (!built) return forwardError(built);
  std::printf("demo: %.1f gigapixels in %.1f s (%.0f MP/s), %.0f MiB\n",
              built->images.front().width_px * double(built->images.front().height_px) / 1e9,
              built->elapsed_s, built->megapixels_per_s, built->output_bytes / 1048576.0);
  std::ofstream(stamp) << wanted << "\n";
  return archive;
}

int runDemo(const DemoArgs& args) {
  std::error_code ec;
  std::filesystem::create_directories(args.dir, ec);
  if (ec)
    return reportError(
        {ErrorCode::kIo, fmt::format("{}: cannot create: {}", args.dir, ec.message())});
  Result<std::string> archive = sampleArchive(args);
  if (!archive) return reportError(archive.error());

  struct Flight {
    const char* path;
    double speed;
    const char* what;
  };
  const Flight flights[] = {
      {"jump", 1000, "five jumps across the image, loading each spot from nothing"},
      {"pan", 20000, "a pan at 20,000 level-0 px/s at full detail"},
      {"zoom", 1000, "from the whole image to full detail and back"},
  };
  std::string rows;
  std::printf("demo: flying %s, %s, %s headless (%s renderer, %s)\n", flights[0].path,
              flights[1].path, flights[2].path, args.renderer.c_str(), args.viewport.c_str());
  for (const Flight& flight : flights) {
    FlyArgs fly;
    fly.archive = *archive;
    fly.path = flight.path;
    fly.speed_px_s = flight.speed;
    fly.duration_s = args.seconds;
    fly.viewport = args.viewport;
    fly.fps = 30;
    fly.render = args.renderer;
    fly.report = true;
    fly.quiet = true;
    fly.out_dir = args.dir + "/demo/" + flight.path;
    if (int code = runFly(fly); code != kExitOk) return code;
    std::ifstream in(fly.out_dir + "/summary.json");
    const nlohmann::json s = nlohmann::json::parse(in, nullptr, false);
    if (s.is_discarded())
      return reportError({ErrorCode::kIo, fly.out_dir + "/summary.json: unreadable"});
    double psnr = 1e9;
    for (const auto& jump : s["jumps"])
      if (jump.contains("rest_psnr_db") && jump["rest_psnr_db"].is_number())
        psnr = std::min(psnr, jump["rest_psnr_db"].get<double>());
    const double first_full = s["jumps"][0]["full_detail_ms"].is_number()
                                  ? s["jumps"][0]["full_detail_ms"].get<double>()
                                  : -1;
    std::printf(
        "  %-5s %5.1f%% of frames at full detail, %5.1f%% covered; render thread p99 %.2f ms "
        "(streaming %.2f ms); GPU p99 %.2f ms; read %.1f MiB (amplification %.2f); first full "
        "detail after %.0f ms; at rest %.1f dB from the CPU reference\n",
        flight.path, s["frames_full_detail_pct"].get<double>(),
        s["frames_fully_covered_pct"].get<double>(), s["render_ms"]["p99"].get<double>(),
        s["update_ms"]["p99"].get<double>(), s["gpu_ms"]["p99"].get<double>(),
        s["bytes_read"].get<double>() / 1048576.0, s["read_amplification"].get<double>(),
        first_full, std::min(psnr, 99.0));
    rows += fmt::format(
        "<tr><td><a href='demo/{0}/report.html'>{0}</a></td><td>{1}</td><td>{2:.1f}%</td><td>"
        "{3:.1f}%</td><td>{4:.2f}</td><td>{5:.2f}</td><td>{6:.1f}</td></tr>",
        flight.path, flight.what, s["frames_full_detail_pct"].get<double>(),
        s["frames_fully_covered_pct"].get<double>(), s["render_ms"]["p99"].get<double>(),
        s["gpu_ms"]["p99"].get<double>(), std::min(psnr, 99.0));
  }
  const std::string index = args.dir + "/demo.html";
  {
    std::ofstream out(index);
    out << "<!DOCTYPE html><html><head><meta charset='utf-8'><title>Tessera demo</title><style>"
           "body{font-family:sans-serif;margin:24px}td,th{border:1px solid #ccc;padding:3px "
           "8px}table{border-collapse:collapse}</style></head><body><h1>Tessera demo</h1>"
        << fmt::format("<p>{} &mdash; viewport {}, {} renderer, 30 fps, {} s a flight</p>",
                       *archive, args.viewport, args.renderer, args.seconds)
        << "<table><tr><th>flight</th><th>what</th><th>frames at full detail</th><th>frames "
           "fully covered</th><th>render thread p99 ms</th><th>GPU p99 ms</th><th>PSNR at rest "
           "dB</th></tr>"
        << rows << "</table></body></html>\n";
    if (!out) return reportError({ErrorCode::kIo, index + ": cannot write"});
  }
  std::printf("demo: report %s\n", std::filesystem::absolute(index).c_str());
  if (args.view) {
    ViewArgs view;
    view.archive = *archive;
    view.renderer = args.renderer;
    return runView(view);
  }
  return kExitOk;
}

}  // namespace

void registerDemoCommand(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<DemoArgs>();
  CLI::App* cmd = app.add_subcommand(
      "demo", "Build a sample archive, fly it headless and write an HTML report (docs/demo.md)");
  cmd->add_option("--dir", args->dir, "Folder for the archive and the reports")
      ->capture_default_str();
  cmd->add_option("--size", args->size, "Synthetic image size WxH")->capture_default_str();
  cmd->add_option("--viewport", args->viewport, "Viewport WxH of the flights")
      ->capture_default_str();
  cmd->add_option("--renderer", args->renderer, "tile-quads or clipmap")
      ->check(CLI::IsMember({"tile-quads", "clipmap"}))
      ->capture_default_str();
  cmd->add_option("--seconds", args->seconds, "Length of each flight")
      ->check(CLI::Range(0.5, 600.0))
      ->capture_default_str();
  cmd->add_flag("--view", args->view, "Then open the viewer on the archive (needs a display)");
  cmd->callback([args, &exit_code] { exit_code = runDemo(*args); });
}

}  // namespace tessera::cli
