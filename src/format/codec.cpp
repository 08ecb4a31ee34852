#include "codec.h"

#include <algorithm>
#include <cstring>
#include <iterator>

#include <fmt/format.h>
#include <turbojpeg.h>
#include <zstd.h>

#include "codec_internal.h"

namespace tessera::detail {

CodecScratch::State::~State() {
  ZSTD_freeCCtx(zstd_cctx);
  ZSTD_freeDCtx(zstd_dctx);
  if (jpeg_compressor != nullptr) tjDestroy(jpeg_compressor);
  if (jpeg_decompressor != nullptr) tjDestroy(jpeg_decompressor);
  tjFree(jpeg_buffer);
}

CodecScratch::CodecScratch() : state_(new State) {}
CodecScratch::~CodecScratch() {
  delete state_;
}

namespace {

// A tile outside these bounds is a caller bug, not bad input: the archive and the builder
// validate geometry before any codec sees it.
void checkTile(const ImageView& tile) {
  TESSERA_CHECK(tile.data != nullptr && tile.width_px >= 1 && tile.height_px >= 1)
      << "encode: empty tile " << tile.width_px << "x" << tile.height_px;
  TESSERA_CHECK(tile.channels >= 1 && tile.channels <= 4)
      << "encode: " << tile.channels << " channels, 1..4 supported";
  TESSERA_CHECK(tile.stride_bytes >= size_t(tile.width_px) * tile.channels)
      << "encode: stride " << tile.stride_bytes << " shorter than a row";
}

// Sizes `out` to its geometry so every decoder can write width*height*channels bytes.
void prepareOut(Image& out) {
  TESSERA_CHECK(out.width_px >= 1 && out.height_px >= 1)
      << "decode: empty expected geometry " << out.width_px << "x" << out.height_px;
  TESSERA_CHECK(out.channels >= 1 && out.channels <= 4)
      << "decode: " << out.channels << " channels, 1..4 supported";
  out.texels.resize(size_t(out.width_px) * out.height_px * out.channels);
}

// Adapters from the table's signatures to the codecs', which take no parent (only ptm needs
// one) and can rely on the geometry checks done here.
template <EncodeFn encode>
Result<std::vector<uint8_t>> encodeChecked(const ImageView& tile, const EncodeOptions& options,
                                           const ParentTexels* /*parent*/, CodecScratch* scratch) {
  checkTile(tile);
  return encode(tile, options, scratch);
}

template <DecodeFn decode>
Result<void> decodeChecked(std::span<const uint8_t> payload, Image& out,
                           const ParentTexels* /*parent*/, CodecScratch* scratch) {
  prepareOut(out);
  return decode(payload, out, scratch);
}

template <EncodeFn encode, DecodeFn decode>
constexpr CodecFunctions makeEntry(Codec codec, bool lossless) {
  return {codec, /*needs_parent=*/false, lossless, &encodeChecked<encode>, &decodeChecked<decode>};
}

Result<std::vector<uint8_t>> encodePtmChecked(const ImageView& tile, const EncodeOptions& options,
                                              const ParentTexels* parent, CodecScratch* scratch) {
  checkTile(tile);
  return encodePtmForEffort(tile, options, parent, scratch);
}

Result<void> decodePtmChecked(std::span<const uint8_t> payload, Image& out,
                              const ParentTexels* parent, CodecScratch* scratch) {
  prepareOut(out);
  return decodePtm(payload, out, parent, scratch);
}

// Indexed by Codec value; the static_asserts below keep index and value in step.
constexpr CodecFunctions kCodecTable[] = {
    makeEntry<encodeRaw, decodeRaw>(Codec::kRaw, true),
    makeEntry<encodeZstd, decodeZstd>(Codec::kZstd, true),
    makeEntry<encodeLz4, decodeLz4>(Codec::kLz4, true),
    makeEntry<encodeJpeg, decodeJpeg>(Codec::kJpeg, false),
    makeEntry<encodePng, decodePng>(Codec::kPng, true),
    makeEntry<encodeWebp, decodeWebp>(Codec::kWebp, true),
    {Codec::kPtm, /*needs_parent=*/true, /*lossless=*/true, &encodePtmChecked, &decodePtmChecked},
};
constexpr bool tableMatchesCodecValues() {
  for (size_t i = 0; i < std::size(kCodecTable); ++i)
    if (size_t(kCodecTable[i].codec) != i) return false;
  return true;
}
static_assert(tableMatchesCodecValues(), "kCodecTable must be indexed by Codec value");
static_assert(std::size(kCodecTable) == size_t(Codec::kPtm) + 1, "every codec is implemented");

Unexpected unsupportedCodec(Codec codec) {
  return fail(ErrorCode::kUnsupported, fmt::format("codec {}: unknown codec", int(codec)));
}

}  // namespace

const CodecFunctions* findCodec(Codec codec) {
  const size_t index = size_t(codec);
  return index < std::size(kCodecTable) ? &kCodecTable[index] : nullptr;
}

}  // namespace tessera::detail

namespace tessera {

bool codecNeedsParent(Codec codec) {
  const detail::CodecFunctions* functions = detail::findCodec(codec);
  return functions != nullptr && functions->needs_parent;
}

}  // namespace tessera

namespace tessera::detail {

Result<std::vector<uint8_t>> encodeTile(Codec codec, const ImageView& tile,
                                        const EncodeOptions& options, const ParentTexels* parent,
                                        CodecScratch* scratch) {
  const CodecFunctions* functions = findCodec(codec);
  if (functions == nullptr) return unsupportedCodec(codec);
  return functions->encode(tile, options, parent, scratch);
}

Result<void> decodeTile(Codec codec, std::span<const uint8_t> payload, Image& out,
                        const ParentTexels* parent, CodecScratch* scratch) {
  const CodecFunctions* functions = findCodec(codec);
  if (functions == nullptr) return unsupportedCodec(codec);
  return functions->decode(payload, out, parent, scratch);
}

// Helpers shared by the codecs.

std::span<const uint8_t> packedTexels(const ImageView& tile, CodecScratch::State& state) {
  const size_t row_bytes = size_t(tile.width_px) * tile.channels;
  if (tile.stride_bytes == row_bytes) return {tile.data, row_bytes * tile.height_px};
  state.texels.resize(row_bytes * tile.height_px);
  for (uint32_t y = 0; y < tile.height_px; ++y)
    std::memcpy(state.texels.data() + y * row_bytes, tile.row(y), row_bytes);
  return state.texels;
}

std::string geometryText(uint32_t width_px, uint32_t height_px, uint32_t channels) {
  return fmt::format("{}x{}x{}", width_px, height_px, channels);
}

Unexpected geometryMismatch(const char* what, const Image& expected, uint32_t width_px,
                            uint32_t height_px, uint32_t channels) {
  return fail(ErrorCode::kCorrupt,
              fmt::format("{}: {} expected, stream is {}", what,
                          geometryText(expected.width_px, expected.height_px, expected.channels),
                          geometryText(width_px, height_px, channels)));
}

std::vector<uint8_t> exactCopy(std::span<const uint8_t> bytes) {
  return std::vector<uint8_t>(bytes.begin(), bytes.end());
}

}  // namespace tessera::detail
