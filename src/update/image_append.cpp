// appendImage: a new image encoded in memory, its payloads in clustering order, its pages and
// page indexes, all appended and committed by the header (docs/update.md, "Append").
#include <fmt/format.h>

#include "archive_tail.h"
#include "builder/texture_pyramid.h"
#include "format/tile_order.h"
#include "level_pages.h"
#include "update/archive_update.h"

namespace tessera::detail {

namespace {

/// Appended images are held whole: 32768 px a side is 4 GiB of RGBA at most.
constexpr uint32_t kMaxAppendSidePx = 32768;

}  // namespace

Result<UpdateReport> appendImage(const std::string& path, BuildOptions options) {
  if (options.inputs.size() != 1)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: append takes one image, {} given", path, options.inputs.size()));
  options.output = path;  // the build rules ask for one; nothing is written there but the append
  TESSERA_TRY(validateBuildOptions(options));
  if (codecNeedsParent(options.codec))
    return fail(ErrorCode::kUnsupported,
                fmt::format("{}: append encodes with {}, whose tiles depend on their parents; "
                            "choose another codec with --codec",
                            path, codecName(options.codec)));
  TESSERA_ASSIGN_OR_RETURN(ArchiveTail tail, ArchiveTail::open(path));
  if (tail.header().image_count >= kMaxImages)
    return fail(ErrorCode::kTooLarge, fmt::format("{}: already holds {} images", path, kMaxImages));
  const std::string& input = options.inputs[0];
  TESSERA_ASSIGN_OR_RETURN(Image image, readImageFile(input, kMaxAppendSidePx));
  if (image.sample_type != SampleType::kU8)
    return fail(ErrorCode::kUnsupported,
                fmt::format("{}: {} has {} samples; append adds 8-bit images (build wider ones "
                            "into an archive of their own)",
                            path, input, sampleTypeName(image.sample_type)));
  ImageInfo info;
  info.width_px = image.width_px;
  info.height_px = image.height_px;
  info.channels = image.channels;
  info.tile_size_px = options.tile_size_px;
  info.border_px = options.border_px;
  info.page_tiles_log2 = options.page_tiles_log2;
  info.srgb_downsample = options.srgb_downsample;
  EncodeOptions encode{options.quality, options.effort, options.chroma_subsampling};
  CodecScratch scratch;
  TESSERA_ASSIGN_OR_RETURN(EncodedPyramid pyramid,
                           encodePyramid(image, info, options.codec, encode, &scratch, input));
  // From the whole image (in memory anyway): from_level_width says which level it describes.
  const nlohmann::json statistics = levelStatistics(image);
  image = Image();
  const uint32_t index = tail.header().image_count;
  const ImageInfo& built = pyramid.info;
  tail.records().push_back({built, std::vector<LevelRecord>(built.level_count)});
  for (const TileId& tile : tileOrder(built, index, options.order)) {
    const size_t slot = size_t(tile.y) * built.tilesX(tile.level) + tile.x;
    TileEntry& entry = pyramid.entries[tile.level][slot];
    if (!entry.hasPayload()) continue;
    TESSERA_ASSIGN_OR_RETURN(BlockRef block, tail.append(pyramid.payloads[tile.level][slot]));
    entry.offset_bytes = block.offset_bytes;
    entry.checksum = block.checksum;
  }
  uint64_t tiles = 0;
  for (uint32_t level = 0; level < built.level_count; ++level) {
    LevelChanges changes;
    for (size_t slot = 0; slot < pyramid.entries[level].size(); ++slot)
      changes[slot] = pyramid.entries[level][slot];
    tiles += changes.size();
    TESSERA_TRY(rewriteLevel(tail, index, level, changes));
  }
  nlohmann::json& images = tail.metadata()["images"];
  if (!images.is_array()) images = nlohmann::json::array();
  std::string name = options.image_names.empty() ? std::string() : options.image_names[0];
  images.push_back({{"name", name},
                    {"source", input},
                    {"width", built.width_px},
                    {"height", built.height_px},
                    {"channels", built.channels},
                    {"codec", codecName(options.codec)},
                    {"statistics", statistics}});
  TESSERA_ASSIGN_OR_RETURN(UpdateReport report, tail.commit());
  report.tiles_rewritten = tiles;
  return report;
}

}  // namespace tessera::detail
