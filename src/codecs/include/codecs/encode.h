#pragma once
// The encode side of the codec plug-ins (docs/architecture.md, "Codecs"): what the builder, the
// server's transcoder, picture output and the benches use. It lives in its own library,
// tessera::encoders, which the runtime never links (as basis_universal keeps its encoder apart
// from its transcoder). Every codec has one row in the encoder table (encoders.cpp).

#include <cstdint>
#include <vector>

#include <tessera/codec_scratch.h>
#include <tessera/format.h>
#include <tessera/result.h>

#include "codecs/decode.h"

namespace tessera::detail {

/// Encoder settings. `quality` is used by lossy codecs only (JPEG 1..100); `effort` by codecs
/// with a speed/size trade-off (zstd level, PNG/WebP effort, ptm mode), 0 meaning the codec's
/// default.
struct EncodeOptions {
  int quality = 85;
  int effort = 0;
  /// JPEG chroma subsampling: true for 4:2:0 (the default of libvips at Q < 90), false for 4:4:4.
  bool chroma_subsampling = true;
};

/// Encodes `tile` (any width and height, channels 1..4, any stride of at least a row). `parent`
/// is the decoded parent for codecs that need one, null at the coarsest level. Fails only on
/// encoder errors (a tile too large for the codec, a library failure).
using EncodeFunction = Result<std::vector<uint8_t>> (*)(const ImageView& tile,
                                                        const EncodeOptions& options,
                                                        const ParentTexels* parent,
                                                        CodecScratch* scratch);

/// One codec's encode side. Thread-safe: the function holds no state between calls beyond the
/// caller's CodecScratch.
struct CodecEncoder {
  Codec codec;
  EncodeFunction encode;
};

/// The encoder of `codec`, or null for codec values this build cannot encode.
const CodecEncoder* findEncoder(Codec codec);

/// Looks up the encoder, checks the tile's geometry (a contract) and encodes; an unknown codec
/// is kUnsupported.
[[nodiscard]] Result<std::vector<uint8_t>> encodeTile(Codec codec, const ImageView& tile,
                                                      const EncodeOptions& options,
                                                      const ParentTexels* parent = nullptr,
                                                      CodecScratch* scratch = nullptr);

}  // namespace tessera::detail
