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
#include "fly_render.h"
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

/// A flight of the demo and what it showed.
struct DemoFlight {
  const char* path;
  double speed_px_s;
  const char* what;
  nlohmann::json summary;  ///< its summary.json, once flown
};

/// The flight's figures on one line, as demo.html shows them (headlineFigures).
void printFlightLine(const DemoFlight& flight) {
  std::string line = fmt::format("  {:<5} ", flight.path);
  int passed = 0, failed = 0;
  for (const HeadlineFigure& f : headlineFigures(flight.summary)) {
    const bool pass = f.verdict == HeadlineFigure::Verdict::kPass;
    const bool fail = f.verdict == HeadlineFigure::Verdict::kFail;
    passed += pass;
    failed += fail;
    line += fmt::format("{}{} {}{}", line.size() > 8 ? ", " : "", f.short_label, f.text,
                        fail ? fmt::format(" (FAIL, target {})", f.target) : "");
  }
  const nlohmann::json& s = flight.summary;
  if (s.contains("upload_budget"))
    line += fmt::format(
        "\n        upload budget {} {:.1f} MiB a frame (median); {} frames drawn, {} skipped "
        "while the GPU was busy",
        s["upload_budget"].value("mode", std::string()),
        s["upload_budget"].value("bytes_p50", 0.0) / 1048576.0, s.value("frames", 0),
        s.value("dropped_frames", 0));
  std::printf(
      "%s\n        %d pass, %d fail (targets: docs/demo.md)%s\n", line.c_str(), passed, failed,
      slowdownNote(flight.summary).empty()
          ? ""
          : fmt::format("; slower than real time: the {:.1f}-s path took {:.1f} s",
                        flight.summary.value("path_s", 0.0), flight.summary.value("wall_s", 0.0))
                .c_str());
}

/// out/demo.html: per flight a thumbnail, the headline figures against their targets, a note
/// when it ran slower than real time, and a link to its report.
Result<void> writeDemoPage(const DemoArgs& args, const std::string& archive,
                           const std::vector<DemoFlight>& flights) {
  std::string html = fmt::format(
      "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><meta name='viewport' "
      "content='width=device-width'><title>Tessera demo</title><style>{}</style></head><body>"
      "<h1>Tessera demo</h1><p>Three flights over a {} synthetic image ({}), each a {:g}-s "
      "camera path at 30 frames a second in a {} view, streamed from the archive and drawn "
      "headless by the {} renderer on {}.</p>",
      reportCss(), htmlEscape(args.size), htmlEscape(archive), args.seconds,
      htmlEscape(args.viewport), htmlEscape(args.renderer),
      htmlEscape(flights.front().summary.value("gl", std::string("a GPU"))));
  std::string slow;
  for (const DemoFlight& flight : flights)
    if (!slowdownNote(flight.summary).empty())
      slow += fmt::format("{}{} took {:.1f} s", slow.empty() ? "" : ", ", flight.path,
                          flight.summary.value("wall_s", 0.0));
  if (!slow.empty())
    html += fmt::format(
        "<p class='warning'>The flights ran slower than real time: {} for {:g} s of path. {}"
        "Every frame of each path was drawn, so the times on this page are wall-clock times "
        "and the cameras moved more slowly than their nominal speeds; each report says how "
        "much.</p>",
        slow, args.seconds,
        softwareRenderer(flights.front().summary)
            ? htmlEscape(flights.front().summary.value("gl", std::string())) +
                  " renders on the CPU, on the cores the loaders use too. "
            : std::string());
  html +=
      "<p>Each flight's headline figures stand against the targets of docs/demo.md (&ldquo;What "
      "good looks like&rdquo;): &#10003; pass, &#10007; fail, &ndash; not judged (a figure a GPU "
      "sets, measured on a software renderer). A flight's report has the jumps, the plots over "
      "time and the pictures at rest.</p>";
  for (const DemoFlight& flight : flights) {
    html += fmt::format(
        "<section class='flight' id='{0}'><h2><a href='demo/{0}/report.html'>{0}</a>: {1}</h2>"
        "<div class='card'><div>",
        flight.path, htmlEscape(flight.what));
    if (!slowdownNote(flight.summary).empty())
      html += fmt::format(
          "<p class='note'>Ran {:.1f} times slower than real time: the {:.1f}-s path took "
          "{:.1f} s.</p>",
          flight.summary.value("slowdown", 1.0), flight.summary.value("path_s", 0.0),
          flight.summary.value("wall_s", 0.0));
    html += figureTableHtml(headlineFigures(flight.summary));
    html += fmt::format(
        "</div><figure><a href='demo/{0}/report.html'><img src='demo/{0}/rest-0.png' alt='{0} "
        "at rest'></a><figcaption>At rest at its first spot; its report has every picture"
        "</figcaption></figure></div></section>",
        flight.path);
  }
  html += "</body></html>\n";
  const std::string index = args.dir + "/demo.html";
  std::ofstream out(index);
  out << html;
  if (!out) return fail(ErrorCode::kIo, index + ": cannot write");
  return {};
}

int runDemo(const DemoArgs& args) {
  std::error_code ec;
  std::filesystem::create_directories(args.dir, ec);
  if (ec)
    return reportError(
        {ErrorCode::kIo, fmt::format("{}: cannot create: {}", args.dir, ec.message())});
  Result<std::string> archive = sampleArchive(args);
  if (!archive) return reportError(archive.error());

  std::vector<DemoFlight> flights = {
      {"jump", 1000, "five jumps across the image, loading each spot from nothing", {}},
      {"pan", 20000, "a pan at 20,000 level-0 px/s at full detail", {}},
      {"zoom", 1000, "from the whole image to full detail and back", {}},
  };
  std::printf("demo: flying %s, %s, %s headless (%s renderer, %s)\n", flights[0].path,
              flights[1].path, flights[2].path, args.renderer.c_str(), args.viewport.c_str());
  int exit_code = kExitOk;
  for (DemoFlight& flight : flights) {
    FlyArgs fly;
    fly.archive = *archive;
    fly.path = flight.path;
    fly.speed_px_s = flight.speed_px_s;
    fly.duration_s = args.seconds;
    fly.viewport = args.viewport;
    fly.fps = 30;
    fly.render = args.renderer;
    fly.report = true;
    fly.quiet = true;
    fly.out_dir = args.dir + "/demo/" + flight.path;
    // Tiles that failed to load are in the flight's figures and report: the demo goes on and
    // exits with that code at the end.
    const int code = runFly(fly);
    if (code != kExitOk && code != kExitLoadFailures) return code;
    if (code != kExitOk) exit_code = code;
    std::ifstream in(fly.out_dir + "/summary.json");
    flight.summary = nlohmann::json::parse(in, nullptr, false);
    if (flight.summary.is_discarded())
      return reportError({ErrorCode::kIo, fly.out_dir + "/summary.json: unreadable"});
    printFlightLine(flight);
  }
  if (Result<void> written = writeDemoPage(args, *archive, flights); !written)
    return reportError(written.error());
  std::printf("demo: report %s\n", std::filesystem::absolute(args.dir + "/demo.html").c_str());
  if (args.view) {
    ViewArgs view;
    view.archive = *archive;
    view.renderer = args.renderer;
    const int code = runView(view);
    return code != kExitOk ? code : exit_code;
  }
  return exit_code;
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
