// Fuzzes the tile decoders with hostile payloads, and the encoders and decoders together with
// arbitrary texels (round-trip mode). Input layout: codec_fuzz_input.h.
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include "codec_fuzz_input.h"
#include "codecs/bc/bc.h"
#include "codecs/bc1_fast.h"
#include "codecs/encode.h"

namespace tessera::fuzz {
namespace {

[[noreturn]] void die(const char* what, const CodecFuzzInput& input, const char* detail = "") {
  std::fprintf(stderr, "codec_fuzzer: %s: %s %ux%ux%u %s\n", what, codecName(input.codec),
               input.width_px, input.height_px, input.channels, detail);
  std::abort();
}

// A ptm tile is decoded against its parent: for a square tile of even side (a stored tile with
// no border) fuzzParentTexels, refining the header's quarter; other shapes get none, so only
// parentless payloads decode. The codec is lossless for any child against any parent, so round
// trips need no floor-average pyramid.
struct FuzzParent {
  Image texels;
  detail::ParentTexels view;
  const detail::ParentTexels* get() const { return texels.texels.empty() ? nullptr : &view; }
};

FuzzParent fuzzParent(const CodecFuzzInput& input) {
  FuzzParent parent;
  if (input.codec != Codec::kPtm || input.width_px != input.height_px || input.width_px % 2)
    return parent;
  parent.texels = fuzzParentTexels(input.width_px, input.channels);
  parent.view = {parent.texels.view(), input.quadrant_x, input.quadrant_y, input.width_px, 0};
  return parent;
}

void fuzzDecode(const CodecFuzzInput& input, CodecScratch& scratch) {
  Image out(input.width_px, input.height_px, input.channels, input.sample_type);
  const size_t expected_bytes = out.texels.size();
  const FuzzParent parent = fuzzParent(input);
  auto result = detail::decodeTile(input.codec, input.rest, out, parent.get(), &scratch);
  if (result && out.texels.size() != expected_bytes) die("decode changed the tile size", input);
  if (!result && result.error().message.empty()) die("error without a message", input);
}

// The loader's fast BC1 transcoder takes any 8-bit tile, alpha ignored: its payload must be
// exactly the stored size, decode, and come back opaque.
void fuzzFastBc1(const CodecFuzzInput& input, const Image& tile, CodecScratch& scratch) {
  std::vector<uint8_t> payload(
      detail::bcPayloadBytes(Codec::kBc1, input.width_px, input.height_px) + 1, 0xA5);
  auto encoded = detail::encodeBc1Fast(tile.view(), payload);
  if (input.sample_type != SampleType::kU8) {
    if (encoded || encoded.error().code != ErrorCode::kUnsupported)
      die("the fast bc1 encoder took wide samples", input);
    return;
  }
  if (!encoded) die("fast bc1 encode failed", input, encoded.error().message.c_str());
  if (payload.back() != 0xA5) die("fast bc1 wrote past its payload", input);
  payload.pop_back();
  Image decoded(input.width_px, input.height_px, 4);
  auto result = detail::decodeTile(Codec::kBc1, payload, decoded, nullptr, &scratch);
  if (!result) die("decode of a fast bc1 payload failed", input, result.error().message.c_str());
  for (size_t i = 3; i < decoded.texels.size(); i += 4)
    if (decoded.texels[i] != 255) die("fast bc1 block not opaque", input);
}

void fuzzRoundTrip(const CodecFuzzInput& input, CodecScratch& scratch) {
  if (input.rest.size() < 2) return;
  detail::EncodeOptions options;
  options.quality = 1 + input.rest[0] % 100;
  options.effort = input.rest[1] & 15;
  if (options.effort > 9) options.effort = 9;
  options.chroma_subsampling = (input.rest[1] >> 4) & 1;
  const std::span<const uint8_t> seed = input.rest.subspan(2);

  Image tile(input.width_px, input.height_px, input.channels, input.sample_type);
  for (size_t i = 0; i < tile.texels.size(); ++i)
    tile.texels[i] = seed.empty() ? 0 : seed[i % seed.size()];
  if (input.codec == Codec::kBc1) fuzzFastBc1(input, tile, scratch);
  const detail::CodecEncoder* encoder = detail::findEncoder(input.codec);
  const FuzzParent parent = fuzzParent(input);
  auto payload = detail::encodeTile(input.codec, tile.view(), options, parent.get(), &scratch);
  if (encoder == nullptr) {
    if (payload) die("unimplemented codec encoded", input);
    return;
  }
  // BC1 has no alpha: a tile with alpha is refused, and said why.
  const bool alpha = input.channels == 2 || input.channels == 4;
  if (!codecSupportsSampleType(input.codec, input.sample_type) ||
      (input.codec == Codec::kBc1 && alpha)) {
    if (payload || payload.error().code != ErrorCode::kUnsupported)
      die("a codec took samples it cannot hold", input);
    return;
  }
  if (!payload) die("encode failed", input, payload.error().message.c_str());

  Image decoded(input.width_px, input.height_px, input.channels, input.sample_type);
  auto result = detail::decodeTile(input.codec, *payload, decoded, parent.get(), &scratch);
  if (!result) die("decode of a fresh payload failed", input, result.error().message.c_str());
  if (codecIsLossless(input.codec)) {
    if (decoded.texels != tile.texels) die("lossless round trip changed texels", input);
  } else if (input.codec == Codec::kJpeg && alpha) {
    for (size_t i = input.channels - 1; i < tile.texels.size(); i += input.channels)
      if (decoded.texels[i] != tile.texels[i]) die("JPEG alpha changed", input);
  }
}

}  // namespace
}  // namespace tessera::fuzz

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace tessera::fuzz;
  CodecFuzzInput input;
  if (!parseCodecFuzzInput({data, size}, &input)) return 0;
  // One scratch per process, as a worker keeps one: it also checks that no state leaks from
  // one (possibly failed) call into the next.
  static tessera::CodecScratch scratch;
  if (input.round_trip) {
    fuzzRoundTrip(input, scratch);
  } else {
    fuzzDecode(input, scratch);
  }
  return 0;
}
