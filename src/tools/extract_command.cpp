// `tessera extract`: a tile or a rectangle of a level to PNG.
#include <algorithm>
#include <cctype>
#include <cstdio>
#include <cstring>

#include <fmt/format.h>

#include <tessera/archive.h>
#include <tessera/picture_file.h>
#include <tessera/open.h>

#include "cli.h"
#include "output/output_file.h"

namespace tessera::cli {

namespace {

struct ExtractArgs {
  std::string archive;
  std::string output;
  uint32_t image = 0;
  uint32_t level = 0;
  std::vector<uint32_t> tile;  ///< x,y
  std::vector<int64_t> rect;   ///< x,y,w,h
  bool with_border = false;
  bool with_padding = false;
};

/// Level texels [x0, x1) x [y0, y1).
struct TexelWindow {
  int64_t x0 = 0, y0 = 0, x1 = 0, y1 = 0;
};

/// What --tile writes of a stored tile: its inner square, with the border when asked, and cut
/// at the level's edge unless the padding (Backes et al., eq. 1: an edge tile is filled out
/// with copies of the edge texels) is asked for too.
TexelWindow tileWindow(const ImageInfo& info, uint32_t level, uint32_t tx, uint32_t ty,
                       const ExtractArgs& args) {
  const int64_t t = info.tile_size_px, b = args.with_border ? info.border_px : 0;
  TexelWindow window{tx * t - b, ty * t - b, (tx + 1) * t + b, (ty + 1) * t + b};
  if (!args.with_padding) {
    window.x0 = std::max<int64_t>(window.x0, 0);
    window.y0 = std::max<int64_t>(window.y0, 0);
    window.x1 = std::min<int64_t>(window.x1, info.levelWidthPx(level));
    window.y1 = std::min<int64_t>(window.y1, info.levelHeightPx(level));
  }
  return window;
}

Result<Image> extractTile(const Archive& archive, const ExtractArgs& args) {
  const ImageInfo& info = archive.images()[args.image];
  if (args.tile[0] >= info.tilesX(args.level) || args.tile[1] >= info.tilesY(args.level))
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: --tile {},{} is outside level {}, which has {} x {} tiles",
                            args.archive, args.tile[0], args.tile[1], args.level,
                            info.tilesX(args.level), info.tilesY(args.level)));
  TESSERA_ASSIGN_OR_RETURN(Image stored,
                           archive.readTile({args.image, args.level, args.tile[0], args.tile[1]}));
  const TexelWindow window = tileWindow(info, args.level, args.tile[0], args.tile[1], args);
  // The stored tile's texel (0, 0) is level texel (tx t - b, ty t - b).
  const int64_t origin_x = int64_t(args.tile[0]) * info.tile_size_px - info.border_px;
  const int64_t origin_y = int64_t(args.tile[1]) * info.tile_size_px - info.border_px;
  Image out(uint32_t(window.x1 - window.x0), uint32_t(window.y1 - window.y0), info.channels,
            info.sample_type);
  for (uint32_t y = 0; y < out.height_px; ++y)
    std::memcpy(
        out.row(y),
        stored.row(uint32_t(window.y0 - origin_y + y)) + (window.x0 - origin_x) * info.texelBytes(),
        out.strideBytes());
  return out;
}

Result<Image> extractRect(const Archive& archive, const ExtractArgs& args) {
  const ImageInfo& info = archive.images()[args.image];
  if (args.rect[2] <= 0 || args.rect[3] <= 0 || args.rect[2] > UINT32_MAX ||
      args.rect[3] > UINT32_MAX)
    return fail(ErrorCode::kInvalidArgument, "--rect needs a positive width and height");
  const int64_t level_w = info.levelWidthPx(args.level), level_h = info.levelHeightPx(args.level);
  const bool inside = args.rect[0] >= 0 && args.rect[1] >= 0 &&
                      args.rect[0] + args.rect[2] <= level_w &&
                      args.rect[1] + args.rect[3] <= level_h;
  if (!inside && !args.with_padding)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: --rect {},{},{},{} is not inside level {} ({} x {} px); give "
                            "--with-padding to read the texels outside as zero",
                            args.archive, args.rect[0], args.rect[1], args.rect[2], args.rect[3],
                            args.level, level_w, level_h));
  return archive.readRegion(
      args.image, args.level,
      {args.rect[0], args.rect[1], uint32_t(args.rect[2]), uint32_t(args.rect[3])});
}

bool endsWithTiff(const std::string& path) {
  std::string lower = path;
  std::transform(lower.begin(), lower.end(), lower.begin(),
                 [](unsigned char c) { return char(std::tolower(c)); });
  return lower.ends_with(".tif") || lower.ends_with(".tiff");
}

// The output's extension picks the format; samples are written as stored, never scaled.
Result<void> writeExtract(const Image& image, const std::string& path) {
  if (endsWithTiff(path)) return writeTiff(image, path);
  if (image.sample_type == SampleType::kF32)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: PNG cannot hold f32 samples; name a .tif output to get them "
                            "as float TIFF",
                            path));
  return writePng(image, path);
}

int runExtract(const ExtractArgs& args) {
  if (args.tile.empty() == args.rect.empty())
    return reportError(
        {ErrorCode::kInvalidArgument, "give exactly one of --tile X,Y or --rect X,Y,W,H"});
  if (Result<void> output = detail::checkOutputPath(args.output); !output)
    return reportError(output.error());
  Result<std::shared_ptr<Archive>> opened = openArchive(args.archive);
  if (!opened) return reportError(opened.error());
  const Archive& archive = **opened;
  if (args.image >= archive.images().size())
    return reportError({ErrorCode::kInvalidArgument,
                        fmt::format("{}: --image {} but the archive has {} image(s)", args.archive,
                                    args.image, archive.images().size())});
  if (args.level >= archive.images()[args.image].level_count)
    return reportError(
        {ErrorCode::kInvalidArgument,
         fmt::format("{}: --level {} but image {} has levels 0..{}", args.archive, args.level,
                     args.image, archive.images()[args.image].level_count - 1)});
  Result<Image> image = args.tile.empty() ? extractRect(archive, args) : extractTile(archive, args);
  if (!image) return reportError(image.error());
  if (Result<void> written = writeExtract(*image, args.output); !written)
    return reportError(written.error());
  std::printf("%s: %ux%u, %u channel(s), %s\n", args.output.c_str(), image->width_px,
              image->height_px, image->channels, sampleTypeName(image->sample_type));
  return kExitOk;
}

}  // namespace

void registerExtractCommand(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<ExtractArgs>();
  CLI::App* cmd = app.add_subcommand(
      "extract", "Write a tile or a rectangle of a level to PNG, or TIFF (-o NAME.tif)");
  cmd->add_option("archive", args->archive, kArchiveArgumentHelp)->required();
  cmd->add_option("-o,--output", args->output,
                  "PNG or, ending .tif/.tiff, TIFF to write (16-bit: either; float: TIFF)")
      ->required();
  cmd->add_option("--image", args->image, "Image index")->capture_default_str();
  cmd->add_option("--level", args->level, "Level (0 = full resolution)")->capture_default_str();
  cmd->add_option("--tile", args->tile, "Tile column,row")->delimiter(',')->expected(2);
  cmd->add_option("--rect", args->rect, "Rectangle x,y,width,height in level pixels")
      ->delimiter(',')
      ->expected(4);
  cmd->add_flag("--with-border", args->with_border, "Keep the tile's border texels");
  cmd->add_flag("--with-padding", args->with_padding,
                "Keep what lies past the level's edge: an edge tile's padding (copies of the edge "
                "texels), a rectangle's texels outside the level (as zero)");
  cmd->callback([args, &exit_code] { exit_code = runExtract(*args); });
}

}  // namespace tessera::cli
