#include "upload_ring.h"

#include <algorithm>
#include <cstring>

#include <tessera/check.h>

namespace tessera::gl {

size_t RingSpans::room() const {
  if (frames_.empty() && !open_) return capacity_;
  if (full_) return 0;
  if (head_ >= tail_) return std::max(capacity_ - head_, tail_);
  return tail_ - head_;
}

std::optional<size_t> RingSpans::take(size_t bytes) {
  if (frames_.empty() && !open_) {
    head_ = tail_ = 0;
    full_ = false;
  }
  if (full_) return std::nullopt;
  std::optional<size_t> offset;
  if (head_ >= tail_) {
    if (capacity_ - head_ >= bytes) {
      offset = head_;
    } else if (tail_ >= bytes) {
      offset = 0;  // wraps: the end of the ring stays unused this time round
    }
  } else if (tail_ - head_ >= bytes) {
    offset = head_;
  }
  if (!offset) return std::nullopt;
  if (!open_) open_begin_ = *offset;
  open_ = true;
  head_ = *offset + bytes;
  if (head_ == capacity_) head_ = 0;
  full_ = bytes > 0 && head_ == tail_;
  return offset;
}

void RingSpans::close(uint64_t fence) {
  if (!open_) return;
  frames_.push_back({open_begin_, head_, fence});
  open_ = false;
}

std::vector<uint64_t> RingSpans::retire(const std::function<bool(uint64_t)>& signalled) {
  std::vector<uint64_t> freed;
  while (!frames_.empty() && signalled(frames_.front().fence)) {
    tail_ = frames_.front().end;
    freed.push_back(frames_.front().fence);
    frames_.pop_front();
    full_ = false;
  }
  return freed;
}

UploadRing::UploadRing(size_t capacity_bytes) : spans_(capacity_bytes) {
  if (capacity_bytes == 0 ||
      !(epoxy_gl_version() >= 44 || epoxy_has_gl_extension("GL_ARB_buffer_storage")))
    return;
  const GLbitfield flags = GL_MAP_WRITE_BIT | GL_MAP_PERSISTENT_BIT | GL_MAP_COHERENT_BIT;
  buffer_ = createBuffer();
  while (glGetError() != GL_NO_ERROR) {
  }
  glNamedBufferStorage(buffer_.get(), GLsizeiptr(capacity_bytes), nullptr, flags);
  if (glGetError() == GL_NO_ERROR)
    mapped_ = static_cast<uint8_t*>(
        glMapNamedBufferRange(buffer_.get(), 0, GLsizeiptr(capacity_bytes), flags));
  if (!mapped_) buffer_.reset();  // no room for it: the orphaned buffer instead
}

UploadRing::~UploadRing() {
  for (auto& [id, fence] : fences_) glDeleteSync(fence);
  if (mapped_) glUnmapNamedBuffer(buffer_.get());
}

size_t UploadRing::room() {
  if (!mapped_) return SIZE_MAX;
  // Fences signal in order; a poll with a timeout of 0 never waits.
  spans_.retire([&](uint64_t fence) {
    TESSERA_CHECK(!fences_.empty() && fences_.front().first == fence) << "fence order";
    if (glClientWaitSync(fences_.front().second, 0, 0) == GL_TIMEOUT_EXPIRED) return false;
    glDeleteSync(fences_.front().second);
    fences_.pop_front();
    return true;
  });
  return spans_.room();
}

size_t UploadRing::stage(const std::vector<std::pair<const uint8_t*, size_t>>& sources) {
  staged_ = true;
  if (!mapped_) {
    fallback_.stage(sources);
    return 0;
  }
  size_t total = 0;
  for (const auto& source : sources) total += source.second;
  const std::optional<size_t> base = spans_.take(total);
  TESSERA_CHECK(base) << "staged " << total << " bytes with room() " << spans_.room();
  size_t offset = *base;
  for (const auto& [data, length] : sources) {
    std::memcpy(mapped_ + offset, data, length);
    offset += length;
  }
  glBindBuffer(GL_PIXEL_UNPACK_BUFFER, buffer_.get());
  glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
  return *base;
}

void UploadRing::finish() {
  if (!staged_) return;
  staged_ = false;
  if (mapped_) {
    const uint64_t id = next_fence_++;
    fences_.emplace_back(id, glFenceSync(GL_SYNC_GPU_COMMANDS_COMPLETE, 0));
    spans_.close(id);
  }
  glBindBuffer(GL_PIXEL_UNPACK_BUFFER, 0);
}

}  // namespace tessera::gl
