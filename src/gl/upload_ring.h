#pragma once
// Uploads through a persistently mapped buffer ring (OpenGL 4.4 buffer storage): each frame's
// tiles are copied into the next free span of one buffer mapped once for its whole life, and
// the span is fenced when the frame's texture updates are issued. A span is reused only
// after its fence has signalled, which is polled, never waited for: a frame that finds no room
// uploads nothing, and its tiles are declined and offered again (docs/rendering.md,
// "Uploads"). Without GL 4.4 (no ARB_buffer_storage) the staging buffer is orphaned each frame
// instead.

#include <cstddef>
#include <cstdint>
#include <deque>
#include <functional>
#include <optional>
#include <utility>
#include <vector>

#include "gl/gl_objects.h"

namespace tessera::gl {

/// Which bytes of a ring are in use until which fence: the policy of UploadRing, apart from
/// GL so that tests can signal fences at will. Owned by one thread.
class RingSpans {
 public:
  explicit RingSpans(size_t capacity_bytes) : capacity_(capacity_bytes) {}

  /// The largest contiguous run of bytes free now (after retire()).
  size_t room() const;
  /// Takes `bytes` contiguous bytes and returns their offset, or nullopt when no free run is
  /// that long. The bytes stay taken until the fence of the frame that took them signals.
  std::optional<size_t> take(size_t bytes);
  /// Ends a frame: everything taken since the last close belongs to `fence`.
  void close(uint64_t fence);
  /// Frees, oldest first, the frames whose fence `signalled` says has signalled; stops at the
  /// first that has not (fences signal in order). Returns the fences freed, for deletion.
  std::vector<uint64_t> retire(const std::function<bool(uint64_t)>& signalled);
  size_t capacity() const { return capacity_; }
  /// Frames closed and not yet retired.
  size_t framesInFlight() const { return frames_.size(); }

 private:
  struct Frame {
    size_t begin = 0;  ///< first byte, in the ring
    size_t end = 0;    ///< one past the last; end < begin when the frame wrapped
    uint64_t fence = 0;
  };
  size_t capacity_;
  size_t head_ = 0;  ///< where the next take starts looking
  size_t tail_ = 0;  ///< first byte still in use (== head_ when nothing is)
  bool full_ = false;
  size_t open_begin_ = 0;  ///< where the frame being filled began
  bool open_ = false;      ///< bytes taken since the last close
  std::deque<Frame> frames_;
};

/// A frame's upload staging. Render thread only, with the context current.
class UploadRing {
 public:
  /// A ring of `capacity_bytes` when the context has buffer storage (GL 4.4 or
  /// ARB_buffer_storage) and `capacity_bytes` > 0, else an orphaned buffer per frame (room
  /// unlimited).
  explicit UploadRing(size_t capacity_bytes);
  ~UploadRing();
  UploadRing(const UploadRing&) = delete;
  UploadRing& operator=(const UploadRing&) = delete;

  /// Bytes this frame can stage: the free run of the ring after retiring the spans whose
  /// fences have signalled (never waits), or SIZE_MAX without a ring.
  size_t room();
  /// Copies `sources` one after the other and leaves the buffer bound as
  /// GL_PIXEL_UNPACK_BUFFER; returns the offset of the first byte (texture updates then take
  /// offsets from it). Their total must be at most room().
  size_t stage(const std::vector<std::pair<const uint8_t*, size_t>>& sources);
  /// After the texture updates of the staged bytes: fences them and unbinds the buffer.
  void finish();
  bool persistent() const { return mapped_ != nullptr; }

 private:
  RingSpans spans_;
  Buffer buffer_;
  uint8_t* mapped_ = nullptr;  ///< the persistent mapping; null without buffer storage
  std::deque<std::pair<uint64_t, GLsync>> fences_;  ///< the frames in flight, oldest first
  uint64_t next_fence_ = 1;
  UploadStaging fallback_;
  bool staged_ = false;
};

}  // namespace tessera::gl
