#pragma once
/// \file
/// Reusable state of the tile codecs, kept by a thread that decodes or encodes many tiles.

#include <memory>

namespace tessera {

/// Per-thread reusable state of the tile codecs: library handles that are costly to set up per
/// call (TurboJPEG, zstd contexts) and scratch buffers. Each codec creates its own part on first
/// use and frees it with this object; no part carries data from one call to the next. Owned by
/// one thread: a worker keeps one and passes it to every decode (Archive::decodeTile) or
/// encode. Wherever a `CodecScratch*` is taken, null makes the call set up and free its own.
class CodecScratch {
 public:
  CodecScratch();
  ~CodecScratch();
  CodecScratch(const CodecScratch&) = delete;
  CodecScratch& operator=(const CodecScratch&) = delete;

  /// The codecs' parts, opaque outside src/codecs.
  struct Parts;
  Parts& parts() { return *parts_; }

 private:
  std::unique_ptr<Parts> parts_;
};

}  // namespace tessera
