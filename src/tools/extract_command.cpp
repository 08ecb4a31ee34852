// `tessera extract`: a tile or a rectangle of a level to PNG.
#include <cstdio>
#include <cstring>

#include <fmt/format.h>

#include <tessera/archive.h>
#include <tessera/picture_file.h>
#include <tessera/open.h>

#include "cli.h"

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
};

int runExtract(const ExtractArgs& args) {
  if (args.tile.empty() == args.rect.empty())
    return reportError(
        {ErrorCode::kInvalidArgument, "give exactly one of --tile X,Y or --rect X,Y,W,H"});
  Result<std::shared_ptr<Archive>> opened = openArchive(args.archive);
  if (!opened) return reportError(opened.error());
  const Archive& archive = **opened;
  Result<Image> image = Unexpected(ErrorCode::kInternal, "unset");
  if (!args.tile.empty()) {
    TileId id{args.image, args.level, args.tile[0], args.tile[1]};
    image = archive.readTile(id);
    if (image && !args.with_border && archive.images()[args.image].border_px > 0) {
      const ImageInfo& info = archive.images()[args.image];
      Image inner(info.tile_size_px, info.tile_size_px, info.channels);
      for (uint32_t y = 0; y < inner.height_px; ++y)
        std::memcpy(inner.row(y), image->row(y + info.border_px) + info.border_px * info.channels,
                    inner.strideBytes());
      image = std::move(inner);
    }
  } else {
    if (args.rect[2] <= 0 || args.rect[3] <= 0 || args.rect[2] > UINT32_MAX ||
        args.rect[3] > UINT32_MAX)
      return reportError({ErrorCode::kInvalidArgument, "--rect needs a positive width and height"});
    image = archive.readRegion(
        args.image, args.level,
        {args.rect[0], args.rect[1], uint32_t(args.rect[2]), uint32_t(args.rect[3])});
  }
  if (!image) return reportError(image.error());
  if (Result<void> written = writePng(*image, args.output); !written)
    return reportError(written.error());
  std::printf("%s: %ux%u, %u channel(s)\n", args.output.c_str(), image->width_px, image->height_px,
              image->channels);
  return kExitOk;
}

}  // namespace

void registerExtractCommand(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<ExtractArgs>();
  CLI::App* cmd = app.add_subcommand("extract", "Write a tile or a rectangle of a level to PNG");
  cmd->add_option("archive", args->archive, kArchiveArgumentHelp)->required();
  cmd->add_option("-o,--output", args->output, "PNG to write")->required();
  cmd->add_option("--image", args->image, "Image index")->capture_default_str();
  cmd->add_option("--level", args->level, "Level (0 = full resolution)")->capture_default_str();
  cmd->add_option("--tile", args->tile, "Tile column,row")->delimiter(',')->expected(2);
  cmd->add_option("--rect", args->rect, "Rectangle x,y,width,height in level pixels")
      ->delimiter(',')
      ->expected(4);
  cmd->add_flag("--with-border", args->with_border, "Keep the tile's border texels");
  cmd->callback([args, &exit_code] { exit_code = runExtract(*args); });
}

}  // namespace tessera::cli
