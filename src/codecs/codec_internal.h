#pragma once
// Shared by the codecs' folders: each codec's part of a CodecScratch, and helpers every codec
// needs (packing strided input, error text).

#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include <tessera/codec_scratch.h>
#include <tessera/format.h>
#include <tessera/result.h>

namespace tessera::detail {

/// A codec's reusable state in a CodecScratch. A codec derives its own (handles, buffers) and
/// frees what it holds in its destructor.
struct CodecState {
  virtual ~CodecState() = default;
};

/// Which side of a codec a state serves: a thread that both encodes and decodes (the builder's
/// checks, the codec study) keeps one of each.
enum class CodecSide : uint8_t { kDecode = 0, kEncode = 1 };

/// Resolves a possibly null CodecScratch: the caller's, or one that lives as long as this
/// object. Owned by one thread.
class ScratchRef {
 public:
  explicit ScratchRef(CodecScratch* scratch) : scratch_(scratch) {
    if (scratch_ == nullptr) scratch_ = &local_.emplace();
  }
  CodecScratch& scratch() const { return *scratch_; }
  /// The `side` state of `codec`, of type T (derived from CodecState), created on first use.
  template <class T>
  T& state(Codec codec, CodecSide side) const {
    std::unique_ptr<CodecState>& slot = stateSlot(*scratch_, codec, side);
    if (!slot) slot = std::make_unique<T>();
    return static_cast<T&>(*slot);
  }

 private:
  static std::unique_ptr<CodecState>& stateSlot(CodecScratch& scratch, Codec codec, CodecSide side);
  std::optional<CodecScratch> local_;
  CodecScratch* scratch_ = nullptr;
};

/// The tile's texels as one packed span: the tile itself when its rows are contiguous,
/// otherwise a copy in `buffer`.
std::span<const uint8_t> packedTexels(const ImageView& tile, std::vector<uint8_t>& buffer);

/// "258x258x3", for messages.
std::string geometryText(uint32_t width_px, uint32_t height_px, uint32_t channels);

/// The error for a payload whose stream disagrees with the expected geometry:
/// "jpeg payload: 258x258x3 expected, stream is 256x256x3".
Unexpected geometryMismatch(const char* what, const Image& expected, uint32_t width_px,
                            uint32_t height_px, uint32_t channels);

/// Copies `bytes` into an exact-size vector, the payload the caller keeps.
std::vector<uint8_t> exactCopy(std::span<const uint8_t> bytes);

}  // namespace tessera::detail
