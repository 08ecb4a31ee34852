#include "lz4/lz4.h"

#include <fmt/format.h>
#include <lz4.h>

#include "codec_internal.h"

namespace tessera::detail {

namespace {

struct Lz4EncodeState : CodecState {
  std::vector<uint8_t> packed;      ///< a strided tile's texels, packed
  std::vector<uint8_t> compressed;  ///< the block before it is copied into the payload
};

}  // namespace

Result<std::vector<uint8_t>> encodeLz4(const ImageView& tile, const EncodeOptions& /*options*/,
                                       const ParentTexels* /*parent*/, CodecScratch* scratch) {
  ScratchRef ref(scratch);
  auto& state = ref.state<Lz4EncodeState>(Codec::kLz4, CodecSide::kEncode);
  std::span<const uint8_t> texels = packedTexels(tile, state.packed);
  if (texels.size() > size_t(LZ4_MAX_INPUT_SIZE))
    return fail(ErrorCode::kTooLarge,
                fmt::format("lz4 payload: {} bytes exceed the LZ4 block limit", texels.size()));
  int bound = LZ4_compressBound(int(texels.size()));
  state.compressed.resize(size_t(bound));
  int written = LZ4_compress_default(reinterpret_cast<const char*>(texels.data()),
                                     reinterpret_cast<char*>(state.compressed.data()),
                                     int(texels.size()), bound);
  if (written <= 0)
    return fail(ErrorCode::kInternal,
                fmt::format("lz4 payload: compression of {} bytes failed", texels.size()));
  return exactCopy(std::span(state.compressed.data(), size_t(written)));
}

}  // namespace tessera::detail
