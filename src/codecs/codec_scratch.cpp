// CodecScratch and the helpers every codec shares. Part of the decode library, so that every
// program that holds a CodecScratch can create and free one.
#include <tessera/codec_scratch.h>

#include <algorithm>
#include <cstring>

#include <fmt/format.h>

#include "codec_internal.h"

namespace tessera {

/// One state per codec and side, in the order first used: a thread uses one or two codecs, so
/// a short list searched in order beats a table indexed by every codec value.
struct CodecScratch::Parts {
  struct Entry {
    Codec codec;
    detail::CodecSide side;
    std::unique_ptr<detail::CodecState> state;
  };
  std::vector<Entry> entries;
};

CodecScratch::CodecScratch() : parts_(std::make_unique<Parts>()) {}
CodecScratch::~CodecScratch() = default;

}  // namespace tessera

namespace tessera::detail {

std::unique_ptr<CodecState>& ScratchRef::stateSlot(CodecScratch& scratch, Codec codec,
                                                   CodecSide side) {
  std::vector<CodecScratch::Parts::Entry>& entries = scratch.parts().entries;
  for (CodecScratch::Parts::Entry& entry : entries)
    if (entry.codec == codec && entry.side == side) return entry.state;
  entries.push_back({codec, side, nullptr});
  return entries.back().state;
}

std::span<const uint8_t> packedTexels(const ImageView& tile, std::vector<uint8_t>& buffer) {
  const size_t row_bytes = size_t(tile.width_px) * tile.texelBytes();
  if (tile.stride_bytes == row_bytes) return {tile.data, row_bytes * tile.height_px};
  buffer.resize(row_bytes * tile.height_px);
  for (uint32_t y = 0; y < tile.height_px; ++y)
    std::memcpy(buffer.data() + y * row_bytes, tile.row(y), row_bytes);
  return buffer;
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
