#pragma once
// The ptm codec (docs/codecs.md, "ptm (6)"): Marvie & Bouatouch's progressive texture maps, each
// tile coded against its decoded parent. What its decoder and encoder share: the payload's
// predictor and coder values and the per-thread state. The encoder's entry points are in
// ptm_encode.h.

#include <cstdint>
#include <vector>

#include "codec_internal.h"
#include "ptm/ptm.h"
#include "ptm/ptm_rans.h"
#include "zstd/zstd_frame.h"

namespace tessera::detail {

/// What a thread keeps between ptm tiles: buffers sized to one tile, reused. Nothing carries
/// data from one call to the next.
struct PtmState : CodecState {
  std::vector<uint8_t> texels;        ///< a packed copy of a strided input
  std::vector<uint8_t> plane;         ///< coder 0's symbol planes, or the lane section's copy
  std::vector<uint8_t> compressed;    ///< rANS bytes before they join the payload
  std::vector<int16_t> upsampled;     ///< the parent upsampled to the tile, 16 times the texels
  std::vector<int16_t> parent_blend;  ///< 3 P + Pv over one row's parent columns
  std::vector<int16_t> detail;        ///< predictor 4: 16 texel - upsampled, per decoded texel
  std::vector<uint16_t> errors;       ///< coder 6: each texel's coded error
  std::vector<rans::Model> tables;    ///< the models of a payload's explicit tables
  ZstdFrameEncoder zstd_encoder;      ///< coder 0's frames
  ZstdFrameDecoder zstd_decoder;
};

/// The ptm state a call uses: the caller's scratch's, or one of its own.
inline PtmState* ptmState(const ScratchRef& ref, CodecSide side) {
  return &ref.state<PtmState>(Codec::kPtm, side);
}

/// How a payload predicts the texels it codes; its first byte. 2 (the parent bilinearly
/// upsampled) was removed in format 1.0: no effort wrote it.
enum class Predictor : uint8_t {
  kRoot = 0,           ///< no parent: LOCO-I median of the left, up and up-left texels
  kParentNearest = 1,  ///< the parent texel of the child's 2x2 block
  /// the median; the parent serves eq. 3's remainder, whose expected value follows from the
  /// median's guess at the derived texel
  kNeighbourMedian = 3,
  /// the bilinear parent plus the neighbours' median departure from theirs, pulled towards what
  /// eq. 3's block sum leaves for the texels not yet decoded
  kParentCorrected = 4,
  /// the median plus the payload's least-squares weights of the neighbours', the parent's and
  /// predictor 4's departures from it (ptm_least_squares.h)
  kLeastSquares = 5,
};
constexpr bool isKeptPredictor(uint8_t value) {
  return value <= 5 && value != 2;
}

/// How a payload entropy-codes its symbols; its second byte without the flags below. 5 (coder
/// 6's activity without the parent) was removed in format 1.0: no effort wrote it.
enum class PtmCoder : uint8_t {
  kZstd = 0,  ///< one zstd frame per channel of residuals and one of remainders
  kRans = 1,  ///< rANS, each symbol modelled by its context (block position, local activity)
  /// rANS, green first and each later channel's context following the residual before it
  kRansChained = 2,
  kRansMixture = 3,         ///< kRans with model family 2 (15-bit, heavier tails)
  kRansMixtureChained = 4,  ///< kRansChained with model family 2
  /// kRansMixtureChained whose activity is the parent's gradients, the errors coded at the left
  /// and upper texels and the prediction's distance from the parent (without a parent, the
  /// neighbours' gradients halved and the errors)
  kRansParentErrors = 6,
  /// kRans's symbols and contexts coded in bands of eight rows that decode side by side
  /// (ptm_lanes.h)
  kRansLanes = 7,
};
constexpr bool isKeptCoder(uint8_t value) {
  return value <= 7 && value != 5;
}
/// Set in a rANS coder's byte when explicit tables follow its model bytes.
inline constexpr uint8_t kPtmTablesFlag = 0x08;
/// Set in coder 7's byte, with 3 or 4 channels, when red's and blue's contexts follow green's
/// residual (ptm::lanes::greenLedClass).
inline constexpr uint8_t kPtmGreenLedFlag = 0x10;

constexpr bool isRansCoder(PtmCoder coder) {
  return coder != PtmCoder::kZstd;
}
/// The coders whose later channels' contexts follow the residual coded before them.
constexpr bool isChainedCoder(PtmCoder coder) {
  return coder == PtmCoder::kRansChained || coder == PtmCoder::kRansMixtureChained ||
         coder == PtmCoder::kRansParentErrors;
}
/// The coder whose activity weighs the coded errors and the parent.
constexpr bool isErrorActivityCoder(PtmCoder coder) {
  return coder == PtmCoder::kRansParentErrors;
}
/// Coders 1, 2 and 7 take their models from family 1, the others from family 2.
constexpr rans::FamilyId familyOf(PtmCoder coder) {
  return coder == PtmCoder::kRans || coder == PtmCoder::kRansChained ||
                 coder == PtmCoder::kRansLanes
             ? rans::FamilyId::kGeometric12
             : rans::FamilyId::kMixture15;
}

}  // namespace tessera::detail
