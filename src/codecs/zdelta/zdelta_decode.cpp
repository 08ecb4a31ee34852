#include <cstring>

#include "codec_internal.h"
#include "zdelta/zdelta.h"
#include "zstd/zstd_frame.h"

namespace tessera::detail {

namespace {

struct ZdeltaDecodeState : CodecState {
  ZstdFrameDecoder frame;
  std::vector<uint8_t> planes;
};

// Inverse of the encoder's transform: gathers sample i's bytes from the planes and adds the
// prediction back. Wrapping unsigned arithmetic makes every residual valid, so no input can
// make this fail once the frame has the right size.
template <class Sample>
void undoDelta(std::span<const uint8_t> planes, Image& out) {
  constexpr size_t kBytes = sizeof(Sample);
  const size_t row_samples = size_t(out.width_px) * out.channels;
  const size_t count = row_samples * out.height_px;
  std::vector<Sample> samples(count);
  for (size_t i = 0; i < count; ++i) {
    Sample residual = 0;
    for (size_t k = 0; k < kBytes; ++k)
      residual |= Sample(Sample(planes[k * count + i]) << (8 * k));
    Sample prediction = 0;
    if (i % row_samples >= out.channels)
      prediction = samples[i - out.channels];
    else if (i >= row_samples)
      prediction = samples[i - row_samples];
    samples[i] = Sample(residual + prediction);
  }
  std::memcpy(out.texels.data(), samples.data(), count * kBytes);
}

}  // namespace

Result<void> decodeZdelta(std::span<const uint8_t> payload, Image& out,
                          const ParentTexels* /*parent*/, CodecScratch* scratch) {
  ScratchRef ref(scratch);
  auto& state = ref.state<ZdeltaDecodeState>(Codec::kZdelta, CodecSide::kDecode);
  state.planes.resize(out.texels.size());
  TESSERA_TRY(decompressZstdFrame(payload, state.planes, "zdelta payload", state.frame));
  switch (sampleBytes(out.sample_type)) {
    case 1: undoDelta<uint8_t>(state.planes, out); break;
    case 2: undoDelta<uint16_t>(state.planes, out); break;
    default: undoDelta<uint32_t>(state.planes, out); break;
  }
  return {};
}

}  // namespace tessera::detail
