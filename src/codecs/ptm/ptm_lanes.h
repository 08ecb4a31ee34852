#pragma once
// ptm's lane coder (coder 7; docs/codecs.md, "ptm (6)", "Lanes"). The texel walk of every
// predictor but 2 (bilinear parent) with coder 1's contexts, ordered so that a decoder can work on
// eight rows at once: the tile is cut into bands of eight rows, and in each band row k decodes
// texel x = t - 2k at step t, a wavefront in which every texel's left, up-left, up and up-right
// neighbours were decoded at an earlier step. Each (channel, row of the band) has its own rANS
// state, with 32-bit states renormalised by 16-bit words, one word stream per channel, and escaped
// residuals as plain bytes in a stream of their own: so eight texels' symbols of one channel decode
// with the same instructions (AVX2 gathers where the processor has them). The scalar texel-by-texel
// walk (ptm_walk.h) decoded the codec study's inputs at 16-40 MP/s per core, bound by its
// instruction count rather than by latency: running rows side by side is what lets SIMD cut it.
//
// The symbols and contexts are exactly coder 1's (RansRecorder<false, false>), so the encoder
// records a tile with the shared walk and only orders and codes the symbols differently.
// Predictor 4's pull (eq. 3's block sum) reads texels of the block decoded at earlier steps,
// the left one in the same row and the two above in the row before, so it fits the wavefront;
// predictor 5 adds the neighbours', the parent's and predictor 4's terms, which do too, and
// predictor 1 reads the parent alone.

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "ptm/ptm_rans.h"
#include "ptm/ptm_walk.h"

namespace tessera::detail::ptm::lanes {

/// Rows decoded side by side: one band.
inline constexpr uint32_t kLanes = 8;
/// A state's lower bound between symbols; states lie in [kLower, 2^32), and every state starts
/// (encoder) and must end (decoder) at kLower.
inline constexpr uint32_t kLower = 1u << 16;
/// The models come from family 1, whose 12-bit tables name a slot's symbol in one lookup.
inline constexpr rans::FamilyId kFamily = rans::FamilyId::kGeometric12;

/// What an explicit table must save beyond its own bytes for coder 7 to send it. The SIMD
/// decoder builds each table into kScale entries of its symbol table (16 KiB) before the
/// tile: on the codec study's synthetic source a table cost about 2.5 us of a 256-px tile's
/// 290-360 us, whatever it saved (docs/benchmarks.md, "thirteenth session").
inline constexpr double kTableMinGainBytes = 256;

/// Coder 7 moves a context onto a model another context uses where that costs at most this
/// share of the context's bits plus a byte (rans::shareModels): each distinct model is 16 KiB
/// of the SIMD decoder's symbol table, and fewer of them stay in its cache. On the codec
/// study's three inputs effort 2 decoded 3-7 % faster for pyramids within 0.4 %
/// (docs/benchmarks.md, "thirteenth session").
inline constexpr double kShareModelsSlack = 0.03;

/// Coder 7's green-led contexts (kPtmGreenLedFlag, tiles of 3 and 4 channels): in a coded
/// texel, red's and blue's activity class follows whether green's residual in the same texel
/// is zero, as coder 2's chained contexts follow each residual before them. Colour channels
/// err together, so a zero green makes zeros likelier in red and blue; on the codec study's
/// photograph effort 2 came out 9.8 % smaller (docs/benchmarks.md, "fourteenth session").
/// Green is the only lead, where coder 2 chains red on green and blue on red: the SIMD
/// decoder reads whether green's symbol is zero from green's slot and its model's frequency
/// of zero, before green's lookup, so red's and blue's lookups wait for no other.
inline constexpr uint32_t kGreenChannel = 1;
/// True for the channels whose class follows green's: red and blue, not alpha.
constexpr bool followsGreen(uint32_t channel) {
  return channel == 0 || channel == 2;
}
/// Red's and blue's class in a coded texel of activity class `activity_class` whose green
/// residual is zero (`green_zero`) or not: of the rules tried on the study's three inputs,
/// halved after a zero and raised by two after anything else coded the photograph smallest
/// without costing the others.
constexpr uint32_t greenLedClass(uint32_t activity_class, bool green_zero) {
  return green_zero
             ? activity_class / 2
             : (activity_class + 2 < kActivityClasses ? activity_class + 2 : kActivityClasses - 1);
}
/// Rewrites the contexts RansRecorder<false, false> recorded (`channels` per texel, 3 or 4) to
/// the green-led ones: red's and blue's in each coded texel by greenLedClass; remainders, and
/// green's and alpha's, as they were.
void leadByGreen(std::span<const uint8_t> symbols, std::span<uint8_t> contexts, uint32_t channels);

/// Bytes of the section's header: each (channel, lane) state as u32, then per channel the
/// lengths of its word stream and its escape stream as u32.
constexpr size_t headerBytes(uint32_t channels) {
  return size_t(channels) * (kLanes * 4 + 2 * 4);
}

/// Appends the lane section of a tile of `width` x `height` texels whose symbols and contexts
/// RansRecorder<false, false> recorded in raster order (`channels` per texel), each coded
/// under `context_models[channel * contexts_per_channel + context]` (family kFamily, or an
/// explicit table at its scale).
void encode(std::span<const uint8_t> symbols, std::span<const uint8_t> contexts, uint32_t width,
            uint32_t height, uint32_t channels, uint32_t contexts_per_channel,
            std::span<const rans::Model* const> context_models, std::vector<uint8_t>& out);

/// How decode() may run: the fastest the processor allows; the AVX2 build of the SIMD decoder
/// even where the AVX-512 one would run (else the scalar lanes); or the scalar lanes only. The
/// last two are for tests that compare the decoders.
enum class Path : uint8_t { kFastest, kScalar, kAvx2 };

/// Decodes the lane section `section` into walk.texels: the walk prepareWalk made for
/// `predictor` (any but 2) with coder 7; `context_models` holds each (channel, context)'s
/// model, channel-major: the model of family kFamily its model byte names, or the explicit
/// table the payload sends for it (rans::readTables, at kFamily's scale); `green_led` says the
/// contexts are the green-led ones (3 or 4 channels only); `padded` is scratch.
/// Returns false when the section is truncated or corrupt (a state out of range, a stream that
/// does not end where its symbols do, an escape of a residual that needed none).
bool decode(std::span<const uint8_t> section, const Walk& walk, uint32_t channels,
            Predictor predictor, std::span<const rans::Model* const> context_models, bool green_led,
            std::vector<uint8_t>& padded, Path path = Path::kFastest);

/// True when decode() can take its SIMD path on this processor (AVX2).
bool simdAvailable();

/// True when decode(Path::kFastest) needs none of the walk's planes of predictor 4 (it takes
/// the SIMD path, which computes the upsampled parent itself): prepareWalk's `planes` may then
/// be false. The scalar lanes refuse a walk without them.
inline bool decodesWithoutPlanes() {
  return simdAvailable();
}

/// True when decode()'s fastest path is the SIMD decoder's AVX-512 build (AVX-512 F, VL, BW
/// and DQ on top of AVX2): the same instructions on 256-bit vectors, with 32 vector registers.
bool avx512Available();

}  // namespace tessera::detail::ptm::lanes
