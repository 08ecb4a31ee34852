#pragma once
// Tessera's fast BC1 encoder, for transcoding decoded tiles (JPEG, mostly) to BC1 on the
// loader threads (docs/codecs.md, "Fast bc1 transcoder"). It sits in tessera::codecs, the
// decode side, as basis_universal's transcoder sits apart from its encoder: it uses no
// third-party encoder and no builder code, so the runtime may link it and the rule "the runtime
// never links an encoder" (docs/architecture.md) still holds. The archive's bc1 tiles keep
// libsquish's slower, better fit (bc/bc.h, encodeBc1). The header sits with decode.h, where the
// stream module sees it: the loader threads call it when StreamerOptions::transcode_to_bc1 is set.

#include <cstdint>
#include <span>

#include <tessera/format.h>
#include <tessera/result.h>

namespace tessera::detail {

/// Encodes `tile` (8-bit samples, 1..4 channels, any width and height of at least 1, any stride
/// of at least a row) as a BC1 payload into `payload`, in the stored bc1 layout (bc/bc.h): the 4x4
/// blocks in row-major order, the tile padded by repeating its last column and row. Grey is
/// spread to R, G and B; alpha is ignored and every block decodes opaque (four-colour blocks,
/// or one colour). Writes exactly bcPayloadBytes(Codec::kBc1, width, height) bytes at the
/// start of `payload`, which must hold at least that many; allocates nothing.
/// Returns kUnsupported for samples other than 8-bit and kInvalidArgument for an empty tile,
/// a channel count outside 1..4 or a short `payload`, writing nothing then.
/// Thread-safe: it keeps no state between calls.
[[nodiscard]] Result<void> encodeBc1Fast(const ImageView& tile, std::span<uint8_t> payload);

}  // namespace tessera::detail
