// The frame contexts' destructors, in the decode library: a ptm state holds both kinds, and
// freeing a context is libzstd's work, not encoder code.
#include "zstd/zstd_frame.h"

#include <zstd.h>

namespace tessera::detail {

ZstdFrameDecoder::~ZstdFrameDecoder() {
  ZSTD_freeDCtx(context);
}

ZstdFrameEncoder::~ZstdFrameEncoder() {
  ZSTD_freeCCtx(context);
}

}  // namespace tessera::detail
