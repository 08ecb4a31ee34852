// `tessera render`: the CPU reference picture of one orthographic view, as PNG. The web tests
// compare what browsers draw (Tessera's viewer, OpenSeadragon, Leaflet) against it.
#include <charconv>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <system_error>

#include <fmt/format.h>

#include <tessera/archive.h>
#include <tessera/picture_file.h>
#include <tessera/render.h>
#include <tessera/stream.h>

#include "cli.h"
#include "output/output_file.h"

namespace tessera::cli {

namespace {

struct RenderArgs {
  std::string archive;
  std::string output;
  uint32_t image = 0;
  std::vector<double> centre;  ///< x,y in level-0 texels
  double texels_per_pixel = 1;
  std::string viewport = "1280x720";
  double rotation_deg = 0;
};

int runRender(const RenderArgs& args) {
  uint32_t viewport_w = 0, viewport_h = 0;
  if (!parseViewport(args.viewport, viewport_w, viewport_h))
    return reportError({ErrorCode::kInvalidArgument,
                        fmt::format("--viewport '{}' must be WxH with each side 1..16384, e.g. "
                                    "1280x720",
                                    args.viewport)});
  if (!std::isfinite(args.texels_per_pixel) || args.texels_per_pixel <= 0)
    return reportError({ErrorCode::kInvalidArgument, "--texels-per-pixel must be above 0"});
  if (!std::isfinite(args.centre[0]) || !std::isfinite(args.centre[1]))
    return reportError({ErrorCode::kInvalidArgument, "--centre must be two finite numbers"});
  if (!std::isfinite(args.rotation_deg))
    return reportError({ErrorCode::kInvalidArgument, "--rotation must be a finite number"});
  // Before a picture of up to 16384 x 16384 px is drawn for nothing.
  if (Result<void> output = detail::checkOutputPath(args.output); !output)
    return reportError(output.error());
  Result<std::shared_ptr<Archive>> opened = Archive::openFile(args.archive);
  if (!opened) return reportError(opened.error());
  const Archive& archive = **opened;
  if (args.image >= archive.images().size())
    return reportError({ErrorCode::kInvalidArgument,
                        fmt::format("{}: --image {} but the archive has {} image(s)", args.archive,
                                    args.image, archive.images().size())});
  View view;
  view.kind = View::Kind::kOrtho;
  view.image = args.image;
  view.ortho.centre_x = args.centre[0];
  view.ortho.centre_y = args.centre[1];
  view.ortho.texels_per_pixel = args.texels_per_pixel;
  view.ortho.viewport_w = viewport_w;
  view.ortho.viewport_h = viewport_h;
  view.ortho.rotation_rad = args.rotation_deg * std::numbers::pi / 180.0;
  // Every tile counts as resident: the picture a renderer shows at rest, everything loaded.
  Result<Picture> picture = renderReference(archive, view);
  if (!picture) return reportError(picture.error());
  if (Result<void> written = writePng(*picture, args.output); !written)
    return reportError(written.error());
  const ImageInfo& info = archive.images()[args.image];
  std::printf("%s: %ux%u, level %u of %u\n", args.output.c_str(), picture->width, picture->height,
              desiredLevelFor(args.texels_per_pixel, info.level_count), info.level_count);
  return kExitOk;
}

}  // namespace

// Strict "WxH": digits only on both sides, each side 1..16384. sscanf's %u would take "-3".
bool parseViewport(const std::string& text, uint32_t& w, uint32_t& h) {
  size_t x = text.find('x');
  if (x == std::string::npos || x == 0 || x + 1 >= text.size()) return false;
  auto parse = [](const std::string& digits, uint32_t& out) {
    const auto [end, error] = std::from_chars(digits.data(), digits.data() + digits.size(), out);
    return error == std::errc() && end == digits.data() + digits.size() && out >= 1 && out <= 16384;
  };
  return parse(text.substr(0, x), w) && parse(text.substr(x + 1), h);
}

void registerRenderCommand(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<RenderArgs>();
  CLI::App* cmd = app.add_subcommand(
      "render", "Write the CPU reference picture of an orthographic view to PNG (RGBA)");
  cmd->add_option("archive", args->archive, "Archive file")->required();
  cmd->add_option("-o,--output", args->output, "PNG to write")->required();
  cmd->add_option("--image", args->image, "Image index")->capture_default_str();
  cmd->add_option("--centre,--center", args->centre, "View centre X,Y in level-0 texels")
      ->delimiter(',')
      ->expected(2)
      ->required();
  cmd->add_option("--texels-per-pixel", args->texels_per_pixel,
                  "Zoom: level-0 texels per screen pixel (below 1 magnifies)")
      ->capture_default_str();
  cmd->add_option("--viewport", args->viewport, "Picture size WxH")->capture_default_str();
  cmd->add_option("--rotation", args->rotation_deg,
                  "Screen rotation in degrees (positive turns screen x towards image y)")
      ->capture_default_str();
  cmd->callback([args, &exit_code] { exit_code = runRender(*args); });
}

}  // namespace tessera::cli
