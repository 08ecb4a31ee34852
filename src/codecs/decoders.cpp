// The decoder table: one row per codec, each codec's decode function from its own folder.
#include "codecs/decode.h"

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
constexpr CodecDecoder kDecoders[] = {
    {Codec::kRaw, decodeRaw},   {Codec::kZstd, decodeZstd},     {Codec::kLz4, decodeLz4},
    {Codec::kJpeg, decodeJpeg}, {Codec::kPng, decodePng},       {Codec::kWebp, decodeWebp},
    {Codec::kPtm, decodePtm},   {Codec::kZdelta, decodeZdelta}, {Codec::kBc1, decodeBc1},
    {Codec::kBc7, decodeBc7},
};
constexpr bool tableMatchesCodecValues() {
  for (size_t i = 0; i < std::size(kDecoders); ++i)
    if (size_t(kDecoders[i].codec) != i) return false;
  return true;
}
static_assert(tableMatchesCodecValues(), "kDecoders must be indexed by Codec value");

}  // namespace

const CodecDecoder* findDecoder(Codec codec) {
  const size_t index = size_t(codec);
  return index < std::size(kDecoders) ? &kDecoders[index] : nullptr;
}

Result<void> decodeTile(Codec codec, std::span<const uint8_t> payload, Image& out,
                        const ParentTexels* parent, CodecScratch* scratch) {
  const CodecDecoder* decoder = findDecoder(codec);
  if (decoder == nullptr)
    return fail(ErrorCode::kUnsupported, fmt::format("codec {}: unknown codec", int(codec)));
  // A caller bug, not bad input: the reader takes the geometry from a validated directory.
  TESSERA_CHECK(out.width_px >= 1 && out.height_px >= 1)
      << "decode: empty expected geometry " << out.width_px << "x" << out.height_px;
  TESSERA_CHECK(out.channels >= 1 && out.channels <= 4)
      << "decode: " << out.channels << " channels, 1..4 supported";
  if (!codecSupportsSampleType(codec, out.sample_type))
    return fail(ErrorCode::kUnsupported,
                fmt::format("{} payload: {} samples are not supported", codecName(codec),
                            sampleTypeName(out.sample_type)));
  out.texels.resize(size_t(out.width_px) * out.height_px * out.texelBytes());
  return decoder->decode(payload, out, parent, scratch);
}

}  // namespace tessera::detail
