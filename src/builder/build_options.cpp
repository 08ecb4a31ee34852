// validateBuildOptions: every option of a build that can be judged without its inputs.
#include <tessera/build.h>

#include <bit>
#include <filesystem>

#include <fmt/format.h>

#include "codecs/encode.h"

namespace tessera {

namespace {

/// The efforts a codec accepts, as docs/codecs.md defines them; 0 is always its default.
struct EffortRange {
  int low = 0;
  int high = 0;
  const char* meaning = "";  ///< what the effort is for this codec; "" when it has none
};

EffortRange effortRange(Codec codec) {
  switch (codec) {
    case Codec::kZstd:
    case Codec::kZdelta: return {-100, 22, "the zstd level, negative for the fast levels"};
    case Codec::kPng: return {0, 9, "the zlib level"};
    case Codec::kWebp: return {0, 9, "the lossless preset"};
    case Codec::kPtm: return {0, 4, "the mode (docs/codecs.md)"};
    case Codec::kBc1: return {0, 3, "1 range fit, 2 cluster fit, 3 iterative cluster fit"};
    case Codec::kBc7: return {0, 4, "the endpoint refinement passes"};
    default: return {};
  }
}

Result<void> validateEffort(Codec codec, int effort) {
  const EffortRange range = effortRange(codec);
  if (effort >= range.low && effort <= range.high) return {};
  if (range.high == 0)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("effort {}: codec {} has no effort setting (give 0, or leave it out)",
                            effort, codecName(codec)));
  return fail(ErrorCode::kInvalidArgument,
              fmt::format("effort {} out of {}..{} for codec {} ({}; 0 = its default)", effort,
                          range.low, range.high, codecName(codec), range.meaning));
}

Result<void> validateGeometry(const BuildOptions& options) {
  if (options.tile_size_px < kMinTileSizePx || options.tile_size_px > kMaxTileSizePx ||
      !std::has_single_bit(options.tile_size_px))
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("tile size {} is not a power of two in {}..{}", options.tile_size_px,
                            kMinTileSizePx, kMaxTileSizePx));
  if (options.border_px > kMaxBorderPx)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("border {} out of 0..{}", options.border_px, kMaxBorderPx));
  if (options.page_tiles_log2 < 3 || options.page_tiles_log2 > 8)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("directory page side 2^{} out of 2^3..2^8", options.page_tiles_log2));
  return {};
}

}  // namespace

Result<void> validateBuildOptions(const BuildOptions& options) {
  if (options.inputs.empty() && options.row_sources.empty())
    return fail(ErrorCode::kInvalidArgument, "no input given");
  if (options.output.empty()) return fail(ErrorCode::kInvalidArgument, "no output path given");
  if (options.quality < 1 || options.quality > 100)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("quality {} out of 1..100", options.quality));
  if (!detail::findEncoder(options.codec))
    return fail(ErrorCode::kUnsupported,
                fmt::format("codec {} is not available in this build", codecName(options.codec)));
  TESSERA_TRY(validateEffort(options.codec, options.effort));
  TESSERA_TRY(validateGeometry(options));
  if (options.threads > kMaxBuildThreads)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{} threads out of 0..{} (0 = one per core)", options.threads,
                            kMaxBuildThreads));
  if (options.codec == Codec::kPtm && options.srgb_downsample)
    return fail(ErrorCode::kInvalidArgument,
                "codec ptm stores the integer floor-average pyramid of Marvie & Bouatouch; it "
                "cannot average in linear light (--srgb)");
  if (options.image_names.size() > options.inputs.size() + options.row_sources.size())
    return fail(ErrorCode::kInvalidArgument, "more image names than inputs");
  for (const RowSource& source : options.row_sources) {
    if (!source.read_rows)
      return fail(ErrorCode::kInvalidArgument, source.name + ": row source without a callback");
    if (source.channels < 1 || source.channels > 4)
      return fail(ErrorCode::kInvalidArgument,
                  fmt::format("{}: {} channels out of 1..4", source.name, source.channels));
    if (uint8_t(source.sample_type) > uint8_t(SampleType::kF32))
      return fail(ErrorCode::kInvalidArgument,
                  fmt::format("{}: unknown sample type {}", source.name, int(source.sample_type)));
  }
  for (const std::string& input : options.inputs) {
    if (std::filesystem::path(input).lexically_normal() ==
        std::filesystem::path(options.output).lexically_normal())
      return fail(ErrorCode::kInvalidArgument, input + ": output would overwrite the input");
  }
  return {};
}

}  // namespace tessera
