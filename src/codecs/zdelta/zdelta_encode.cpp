#include <algorithm>
#include <cstring>

#include <zstd.h>

#include "codec_internal.h"
#include "zdelta/zdelta.h"
#include "zstd/zstd_frame.h"

namespace tessera::detail {

namespace {

// As the zstd codec: the fast level, since the builder encodes every tile.
constexpr int kDefaultZdeltaLevel = 1;

struct ZdeltaEncodeState : CodecState {
  ZstdFrameEncoder frame;
  std::vector<uint8_t> packed;
  std::vector<uint8_t> planes;
};

template <class Sample>
void applyDelta(std::span<const uint8_t> packed, const ImageView& tile,
                std::vector<uint8_t>& planes) {
  constexpr size_t kBytes = sizeof(Sample);
  const size_t row_samples = size_t(tile.width_px) * tile.channels;
  const size_t count = row_samples * tile.height_px;
  std::vector<Sample> samples(count);
  std::memcpy(samples.data(), packed.data(), count * kBytes);
  planes.resize(count * kBytes);
  for (size_t i = 0; i < count; ++i) {
    Sample prediction = 0;
    if (i % row_samples >= tile.channels)
      prediction = samples[i - tile.channels];
    else if (i >= row_samples)
      prediction = samples[i - row_samples];
    const Sample residual = Sample(samples[i] - prediction);
    for (size_t k = 0; k < kBytes; ++k) planes[k * count + i] = uint8_t(residual >> (8 * k));
  }
}

}  // namespace

Result<std::vector<uint8_t>> encodeZdelta(const ImageView& tile, const EncodeOptions& options,
                                          const ParentTexels* /*parent*/, CodecScratch* scratch) {
  ScratchRef ref(scratch);
  auto& state = ref.state<ZdeltaEncodeState>(Codec::kZdelta, CodecSide::kEncode);
  std::span<const uint8_t> packed = packedTexels(tile, state.packed);
  switch (sampleBytes(tile.sample_type)) {
    case 1: applyDelta<uint8_t>(packed, tile, state.planes); break;
    case 2: applyDelta<uint16_t>(packed, tile, state.planes); break;
    default: applyDelta<uint32_t>(packed, tile, state.planes); break;
  }
  int level = options.effort != 0 ? options.effort : kDefaultZdeltaLevel;
  level = std::clamp(level, ZSTD_minCLevel(), ZSTD_maxCLevel());
  return compressZstdFrame(state.planes, level, "zdelta payload", state.frame);
}

}  // namespace tessera::detail
