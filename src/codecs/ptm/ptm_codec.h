#pragma once
// The ptm codec (docs/codecs.md, "ptm (6)"): Marvie & Bouatouch's progressive texture maps,
// each tile coded against its decoded parent. What the codec's files share: the payload's
// predictor and coder values, the per-thread state, and the encoder's entry points that the
// codec study and the tests call with explicit choices.

#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include "codec_internal.h"
#include "codecs/encode.h"
#include "ptm/ptm.h"
#include "ptm/ptm_rans.h"
#include "zstd/zstd_frame.h"

namespace tessera::detail {

/// What a thread keeps between ptm tiles: buffers sized to one tile, reused. Nothing carries
/// data from one call to the next.
struct PtmState : CodecState {
  /// Tightly packed copy of a strided input, or an intermediate plane.
  std::vector<uint8_t> texels;
  /// Symbol planes (coder 0) or a lane section's scratch.
  std::vector<uint8_t> plane;
  /// Compressed bytes before they are copied into the exact-size payload.
  std::vector<uint8_t> compressed;
  /// The parent bilinearly upsampled to the tile, 16 times the texel scale.
  std::vector<int16_t> upsampled;
  /// One row of the two parent rows an upsampled row reads, blended (3 P + Pv).
  std::vector<int16_t> parent_blend;
  /// Predictor 4's detail of each coded texel (16 texel - upsampled).
  std::vector<int16_t> detail;
  /// Coders 5 and 6: each texel's coded error (sum of its symbols' magnitudes over channels).
  std::vector<uint16_t> errors;
  /// The models of a payload's explicit tables.
  std::vector<rans::Model> ptm_tables;
  ZstdFrameEncoder zstd_encoder;  ///< coder 0's frames
  ZstdFrameDecoder zstd_decoder;
};

/// The ptm state a call uses: the caller's scratch's, or one of its own.
inline PtmState* ptmState(const ScratchRef& ref, CodecSide side) {
  return &ref.state<PtmState>(Codec::kPtm, side);
}

/// How a ptm payload predicts the texels it codes (docs/codecs.md, "ptm (6)"); stored in the
/// payload's first byte.
enum class Predictor : uint8_t {
  kRoot = 0,            ///< no parent: LOCO-I median of left, up and up-left texels
  kParentNearest = 1,   ///< the parent texel of the child's 2x2 block
  kParentBilinear = 2,  ///< the parent bilinearly upsampled (weights 9, 3, 3, 1 / 16)
  /// LOCO-I median of the child's neighbours; the parent only for eq. 3's remainder, whose
  /// expected value the median's guess at the derived texel gives
  kNeighbourMedian = 3,
  /// the bilinear parent plus the neighbours' median departure from it, pulled towards what
  /// the 2x2 block's sum (eq. 3) leaves for the texels not yet decoded; remainder as in 3
  kParentCorrected = 4,
  /// the neighbour median plus a linear combination of eight texels' and one prediction's
  /// departures from it (the left, up, up-left and up-right texels, the four parent texels
  /// bilinear upsampling weighs, predictor 4's prediction), with weights per block position
  /// and channel that the encoder fits to the tile by least squares and stores in the
  /// payload; remainder as in 3, from the same prediction of the derived texel
  kLeastSquares = 5,
};

/// How a ptm payload entropy-codes its symbols; stored in the payload's second byte.
enum class PtmCoder : uint8_t {
  kZstd = 0,  ///< one zstd frame per channel for residuals, one for remainders
  kRans = 1,  ///< rANS over the symbols, each modelled by its context (local activity)
  /// rANS with green coded first and each later channel's context raised or lowered by the
  /// residual coded before it in the same texel
  kRansChained = 2,
  /// kRans with the second model family: 15-bit probabilities, heavier tails
  kRansMixture = 3,
  /// kRansChained with the second model family
  kRansMixtureChained = 4,
  /// kRansMixtureChained whose activity also weighs the errors coded at the left and upper
  /// texels, as CALIC's error energy does
  kRansMixtureChainedErrors = 5,
  /// kRansMixtureChainedErrors whose activity takes the parent's gradients in place of the
  /// decoded neighbours', plus each coded texel's prediction's distance from its parent texel;
  /// at the coarsest level, without a parent, it codes as kRansMixtureChainedErrors
  kRansParentErrors = 6,
  /// kRans's symbols and contexts (model family 1), with every predictor but 2, coded in
  /// bands of eight rows that decode side by side (ptm_lanes.h): one 32-bit state per channel
  /// and row of the band, a word stream and an escape stream per channel; explicit tables
  /// as coders 1-6
  kRansLanes = 7,
};

/// Set in a rANS coder's byte when explicit tables follow its model bytes (docs/codecs.md,
/// "ptm (6)", "Tables").
inline constexpr uint8_t kPtmTablesFlag = 0x08;
/// Set in coder 7's byte, with 3 or 4 channels, when red's and blue's contexts follow green's
/// residual in the same texel (ptm::lanes::leadByGreen; docs/codecs.md, "ptm (6)", "Lanes").
inline constexpr uint8_t kPtmGreenLedFlag = 0x10;
/// True for the rANS coders, whose payload is model bytes and one rANS stream.
constexpr bool isRansCoder(PtmCoder coder) {
  return coder != PtmCoder::kZstd;
}
/// True for the coders whose later channels' contexts follow the residual coded before them.
constexpr bool isChainedCoder(PtmCoder coder) {
  return coder == PtmCoder::kRansChained || coder == PtmCoder::kRansMixtureChained ||
         coder == PtmCoder::kRansMixtureChainedErrors || coder == PtmCoder::kRansParentErrors;
}
/// True for the coders whose activity class weighs the neighbours' coded errors.
constexpr bool isErrorActivityCoder(PtmCoder coder) {
  return coder == PtmCoder::kRansMixtureChainedErrors || coder == PtmCoder::kRansParentErrors;
}
/// True when `coder` can code `predictor`'s residuals: every coder can but coder 7, which has
/// every predictor but 2 (bilinear parent).
constexpr bool codesPredictor(PtmCoder coder, Predictor predictor) {
  return coder != PtmCoder::kRansLanes || predictor != Predictor::kParentBilinear;
}
/// True for the coder whose activity reads the parent instead of the decoded neighbours.
constexpr bool isParentActivityCoder(PtmCoder coder) {
  return coder == PtmCoder::kRansParentErrors;
}

/// Predictor 5's weights as fitted to one tile and its parent. They depend on nothing else, so
/// a caller that estimates a tile with several coders passes one of these to fit it once.
struct PtmLeastSquaresFit {
  bool fitted = false;
  /// Which of the fit's two weight sets a payload takes: the one without predictor 4's estimate
  /// decodes faster (its decoders skip predictor 4's work) and codes a little larger.
  bool without_estimate = false;
  int8_t weights[4 * 4 * 9] = {};  ///< [position][channel][term], the payload's layout
  int8_t weights_without_estimate[4 * 4 * 9] = {};  ///< the same, the estimate's weights 0
};

/// Encodes a ptm payload with `predictor` (kRoot when `parent` is null) and `coder`. The codec
/// table's entry uses the defaults; the codec study compares the others. With predictor 5, a
/// `fit` already fitted to this tile supplies the weights; one not yet fitted receives them.
Result<std::vector<uint8_t>> encodePtm(const ImageView& tile, const EncodeOptions& options,
                                       const ParentTexels* parent, Predictor predictor,
                                       PtmCoder coder, CodecScratch* scratch,
                                       PtmLeastSquaresFit* fit = nullptr);
/// Encodes the tile with the one of `predictors` (with a parent; kRoot without) that gives the
/// smallest payload with `coder`: which predictor suits a tile depends on the image
/// (docs/codecs.md, "ptm (6)"). zstd payloads are compared as coded; rANS ones by
/// estimatePtmBytes, so only the chosen one is coded.
Result<std::vector<uint8_t>> encodePtmSmallest(const ImageView& tile, const EncodeOptions& options,
                                               const ParentTexels* parent,
                                               std::span<const Predictor> predictors,
                                               PtmCoder coder, CodecScratch* scratch);
/// The size encodePtm's payload would have, without coding it where that can be saved: to
/// within a few bytes for the rANS coders (walk and model choice only), exactly for zstd.
Result<size_t> estimatePtmBytes(const ImageView& tile, const EncodeOptions& options,
                                const ParentTexels* parent, Predictor predictor, PtmCoder coder,
                                CodecScratch* scratch, PtmLeastSquaresFit* fit = nullptr);
/// A tile's symbols and their contexts as one of the rANS coders' texel walks records them,
/// with the payload's header (and predictor 5's weights). Coders 1 and 3 walk alike, as do 2
/// and 4; they differ only in the family their models come from. So a recording made for one
/// coder estimates and encodes every coder that walks as it does (walksAlike), and the default
/// encoder walks a tile once for an estimate and the payload that follows it instead of twice.
struct PtmRecording {
  PtmCoder coder = PtmCoder::kRans;  ///< the coder it was recorded for
  uint32_t channels = 0;
  uint32_t width = 0, height = 0;  ///< of the tile, in texels
  uint32_t contexts = 0;           ///< contexts per channel
  std::vector<uint8_t> header;     ///< predictor, coder, predictor 5's weights
  std::vector<uint8_t> symbols;    ///< in decoding order
  std::vector<uint8_t> symbol_contexts;
  /// The symbols counted per context, once for every estimate of the coders that walk alike.
  rans::ContextCounts counts;
  /// Coder 7 only: the contexts are green-led (leadRecordingByGreen), and so is the payload.
  bool green_led = false;
};
/// True when coders `a` and `b` (both rANS) record the same symbols and contexts.
constexpr bool walksAlike(PtmCoder a, PtmCoder b) {
  return isChainedCoder(a) == isChainedCoder(b) &&
         isErrorActivityCoder(a) == isErrorActivityCoder(b) &&
         isParentActivityCoder(a) == isParentActivityCoder(b);
}
/// `recording` (for coder 7, or coder 1, which walks alike; a tile of 3 or 4 channels;
/// green-led or not) with green-led contexts (ptm::lanes::leadByGreen), recounted, into `led`.
void leadRecordingByGreen(const PtmRecording& recording, PtmRecording& led);
/// Walks the tile as encodePtm does with the rANS coder `coder` into `recording`.
Result<void> recordPtm(const ImageView& tile, const ParentTexels* parent, Predictor predictor,
                       PtmCoder coder, CodecScratch* scratch, PtmLeastSquaresFit* fit,
                       PtmRecording& recording);
/// estimatePtmBytes of the recorded tile with `coder`, which must walk as the recording's does.
/// The model bytes it chose go to `models` when given, for encodeRecordedPtm.
size_t estimateRecordedPtm(const PtmRecording& recording, PtmCoder coder,
                           std::vector<uint8_t>* models = nullptr);
/// encodePtm's payload of the recorded tile with `coder` (walking as the recording's does),
/// with the `models` estimateRecordedPtm chose for it, or choosing them when null. A context
/// takes an explicit table where it saves `table_min_gain_bytes` beyond the table's bytes;
/// without it, the coder's own rule (coder 7: ptm::lanes::kTableMinGainBytes, else 0). Only
/// tools that must seed a decoder's tables on small tiles (tests, the fuzz corpus) pass it.
std::vector<uint8_t> encodeRecordedPtm(const PtmRecording& recording, PtmCoder coder,
                                       CodecScratch* scratch,
                                       const std::vector<uint8_t>* models = nullptr,
                                       std::optional<double> table_min_gain_bytes = {});
/// Which of `predictors` gives the smallest payload with `coder` by estimatePtmBytes (kRoot
/// without a parent); its estimate goes to `estimated_bytes` when given.
Result<Predictor> smallestPtmPredictor(const ImageView& tile, const EncodeOptions& options,
                                       const ParentTexels* parent,
                                       std::span<const Predictor> predictors, PtmCoder coder,
                                       CodecScratch* scratch, size_t* estimated_bytes);
}  // namespace tessera::detail
