// The encoder table: one row per codec, each codec's encode function from its own folder.
#include "codecs/encode.h"

#include <iterator>

#include <fmt/format.h>

#include <tessera/check.h>

#include "bc/bc.h"
#include "jpeg/jpeg.h"
#include "lz4/lz4.h"
#include "png/png.h"
#include "ptm/ptm.h"
#include "raw/raw.h"
#include "webp/webp.h"
#include "zdelta/zdelta.h"
#include "zstd/zstd.h"

namespace tessera::detail {

namespace {

// Indexed by Codec value; the static_assert below keeps index and value in step.
constexpr CodecEncoder kEncoders[] = {
    {Codec::kRaw, encodeRaw},          {Codec::kZstd, encodeZstd},     {Codec::kLz4, encodeLz4},
    {Codec::kJpeg, encodeJpeg},        {Codec::kPng, encodePng},       {Codec::kWebp, encodeWebp},
    {Codec::kPtm, encodePtmForEffort}, {Codec::kZdelta, encodeZdelta}, {Codec::kBc1, encodeBc1},
    {Codec::kBc7, encodeBc7},
};
constexpr bool tableMatchesCodecValues() {
  for (size_t i = 0; i < std::size(kEncoders); ++i)
    if (size_t(kEncoders[i].codec) != i) return false;
  return true;
}
static_assert(tableMatchesCodecValues(), "kEncoders must be indexed by Codec value");

}  // namespace

const CodecEncoder* findEncoder(Codec codec) {
  const size_t index = size_t(codec);
  return index < std::size(kEncoders) ? &kEncoders[index] : nullptr;
}

Result<std::vector<uint8_t>> encodeTile(Codec codec, const ImageView& tile,
                                        const EncodeOptions& options, const ParentTexels* parent,
                                        CodecScratch* scratch) {
  const CodecEncoder* encoder = findEncoder(codec);
  if (encoder == nullptr)
    return fail(ErrorCode::kUnsupported, fmt::format("codec {}: unknown codec", int(codec)));
  // A tile outside these bounds is a caller bug, not bad input: the archive and the builder
  // validate geometry before any codec sees it.
  TESSERA_CHECK(tile.data != nullptr && tile.width_px >= 1 && tile.height_px >= 1)
      << "encode: empty tile " << tile.width_px << "x" << tile.height_px;
  TESSERA_CHECK(tile.channels >= 1 && tile.channels <= 4)
      << "encode: " << tile.channels << " channels, 1..4 supported";
  TESSERA_CHECK(tile.stride_bytes >= size_t(tile.width_px) * tile.texelBytes())
      << "encode: stride " << tile.stride_bytes << " shorter than a row";
  if (!codecSupportsSampleType(codec, tile.sample_type))
    return fail(ErrorCode::kUnsupported,
                fmt::format("codec {} cannot store {} samples (raw, zstd, lz4 and zdelta can{})",
                            codecName(codec), sampleTypeName(tile.sample_type),
                            tile.sample_type == SampleType::kU16 ? ", and png" : ""));
  return encoder->encode(tile, options, parent, scratch);
}

}  // namespace tessera::detail
