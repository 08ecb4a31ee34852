#pragma once
// Byte buffers whose pages cost memory only once written.

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>

namespace tessera::detail {

/// A byte array allocated without being written. `std::vector<uint8_t>(n)` writes n zeros, so
/// a band sized for a claimed width was resident before a single row had been decoded (a
/// 57-byte PNG claiming 2000000 x 2000000 px reached 8 GiB before its first row failed). Here
/// a large buffer is a fresh mapping, and the kernel backs a page only when a row first lands
/// in it. The bytes are undefined until written. Owned by one thread.
class UninitializedBuffer {
 public:
  UninitializedBuffer() = default;
  explicit UninitializedBuffer(size_t size_bytes) { resize(size_bytes); }

  /// Makes the buffer `size_bytes` long; when the size changes the contents are discarded.
  void resize(size_t size_bytes) {
    if (size_bytes == size_bytes_) return;
    bytes_ = size_bytes ? std::make_unique_for_overwrite<uint8_t[]>(size_bytes) : nullptr;
    size_bytes_ = size_bytes;
  }
  uint8_t* data() { return bytes_.get(); }
  const uint8_t* data() const { return bytes_.get(); }
  size_t size() const { return size_bytes_; }
  std::span<uint8_t> span() { return {bytes_.get(), size_bytes_}; }

 private:
  std::unique_ptr<uint8_t[]> bytes_;
  size_t size_bytes_ = 0;
};

}  // namespace tessera::detail
