#pragma once
// ptm's encoder (docs/codecs.md, "ptm (6)"), tessera::encoders only: a payload of an explicit
// predictor and coder, its size estimate, and the walk recorded once for several estimates.
// ptm_effort.cpp's rules pick what each `effort` writes; the codec study and the tests call
// these directly.

#include <cstdint>
#include <optional>
#include <vector>

#include "codecs/encode.h"
#include "ptm/ptm_codec.h"

namespace tessera::detail {

/// Predictor 5's weights as fitted to one tile and its parent, so that several encodings of the
/// tile fit it once.
struct PtmLeastSquaresFit {
  bool fitted = false;
  /// Take the weights fitted without predictor 4's estimate: their decoders skip predictor 4's
  /// work, for a payload a little larger. Coder 7 always takes them.
  bool without_estimate = false;
  int8_t weights[4 * 4 * 9] = {};  ///< [position][channel][term], the payload's layout
  int8_t weights_without_estimate[4 * 4 * 9] = {};
};

/// The payload of `tile` with `predictor` (predictor 0 where `parent` is null) and `coder`.
/// With predictor 5, a `fit` already fitted supplies the weights; one not yet fitted gets them.
Result<std::vector<uint8_t>> encodePtm(const ImageView& tile, const EncodeOptions& options,
                                       const ParentTexels* parent, Predictor predictor,
                                       PtmCoder coder, CodecScratch* scratch,
                                       PtmLeastSquaresFit* fit = nullptr);
/// encodePtm's payload size: exactly for zstd, to within the final states for rANS (the walk and
/// the model choice, without the rANS pass).
Result<size_t> estimatePtmBytes(const ImageView& tile, const EncodeOptions& options,
                                const ParentTexels* parent, Predictor predictor, PtmCoder coder,
                                CodecScratch* scratch, PtmLeastSquaresFit* fit = nullptr);

/// A tile's symbols and contexts as a rANS coder's walk records them, with the payload's header.
/// Coders 1, 3 and 7 walk alike, as do 2 and 4 (walksAlike): a recording for one estimates and
/// encodes each, so a tile costs one walk per predictor and kind of walk, not one per estimate.
struct PtmRecording {
  PtmCoder coder = PtmCoder::kRans;  ///< the coder it was recorded for
  uint32_t channels = 0;
  uint32_t width = 0, height = 0;  ///< of the tile, in texels
  uint32_t contexts = 0;           ///< contexts per channel
  std::vector<uint8_t> header;     ///< predictor, coder, predictor 5's weights
  std::vector<uint8_t> symbols;    ///< in the walk's order
  std::vector<uint8_t> symbol_contexts;
  rans::ContextCounts counts;  ///< counted once for every estimate
  bool green_led = false;      ///< coder 7's green-led contexts (leadRecordingByGreen)
};
constexpr bool walksAlike(PtmCoder a, PtmCoder b) {
  return isChainedCoder(a) == isChainedCoder(b) &&
         isErrorActivityCoder(a) == isErrorActivityCoder(b);
}
/// Walks the tile as encodePtm does with the rANS coder `coder` into `recording`.
Result<void> recordPtm(const ImageView& tile, const ParentTexels* parent, Predictor predictor,
                       PtmCoder coder, CodecScratch* scratch, PtmLeastSquaresFit* fit,
                       PtmRecording& recording);
/// `recording` (of coder 7's walk, 3 or 4 channels) with green-led contexts, recounted.
void leadRecordingByGreen(const PtmRecording& recording, PtmRecording& led);
/// estimatePtmBytes of the recorded tile with `coder` (walking alike); the model bytes it chose
/// go to `models` when given, for encodeRecordedPtm.
size_t estimateRecordedPtm(const PtmRecording& recording, PtmCoder coder,
                           std::vector<uint8_t>* models = nullptr);
/// encodePtm's payload of the recorded tile with `coder`, with `models` or choosing them. A
/// context takes an explicit table where it saves `table_min_gain_bytes` beyond the table's
/// bytes, by default the coder's rule (coder 7: lanes::kTableMinGainBytes, else 0); tests and
/// the fuzz corpus pass 0 to seed the decoders' tables on small tiles.
std::vector<uint8_t> encodeRecordedPtm(const PtmRecording& recording, PtmCoder coder,
                                       CodecScratch* scratch,
                                       const std::vector<uint8_t>* models = nullptr,
                                       std::optional<double> table_min_gain_bytes = {});

}  // namespace tessera::detail
