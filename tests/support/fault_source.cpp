#include "support/fault_source.h"

#include <algorithm>
#include <chrono>
#include <cstring>

#include <fmt/format.h>

namespace tessera::test {

FaultSource::FaultSource(std::shared_ptr<ByteSource> inner)
    : inner_(std::move(inner)), name_("faulty:" + inner_->name()) {}

FaultSource::~FaultSource() {
  openGate();
}

uint64_t FaultSource::sizeBytes() const {
  return inner_->sizeBytes();
}

const std::string& FaultSource::name() const {
  return name_;
}

Result<void> FaultSource::read(uint64_t offset_bytes, std::span<uint8_t> out) const {
  FaultConfig config;
  bool fault = false;
  {
    std::unique_lock lock(mutex_);
    ++reads_;
    accesses_.push_back({false, offset_bytes, out.size()});
    if (gate_closed_) {
      ++blocked_;
      changed_.notify_all();
      changed_.wait(lock, [&] { return !gate_closed_; });
      --blocked_;
    }
    config = config_;
    if (config.kind != FaultKind::kNone && offset_bytes >= config.min_offset_bytes) {
      fault = faultable_reads_++ % std::max(1u, config.every) == 0;
      if (fault) {
        ++faults_;
        changed_.notify_all();
      }
    }
  }
  if (!fault) return inner_->read(offset_bytes, out);
  switch (config.kind) {
    case FaultKind::kNone: break;
    case FaultKind::kError:
      return fail(ErrorCode::kIo, fmt::format("{}: injected I/O error reading [{}, +{})", name_,
                                              offset_bytes, out.size()));
    case FaultKind::kShortRead: {
      size_t delivered = out.size() / 2;
      if (auto read = inner_->read(offset_bytes, out.first(delivered)); !read) return read;
      std::memset(out.data() + delivered, 0, out.size() - delivered);
      return {};
    }
    case FaultKind::kFlipBytes: {
      if (auto read = inner_->read(offset_bytes, out); !read) return read;
      uint64_t stride = std::max<uint64_t>(1, config.flip_stride_bytes);
      for (uint64_t i = stride / 2; i < out.size(); i += stride) out[i] ^= 1;
      if (out.size() <= stride / 2 && !out.empty()) out[0] ^= 1;
      return {};
    }
  }
  return inner_->read(offset_bytes, out);
}

void FaultSource::setFaults(const FaultConfig& config) {
  std::lock_guard lock(mutex_);
  config_ = config;
  faultable_reads_ = 0;
}

void FaultSource::stopFaulting() {
  std::lock_guard lock(mutex_);
  config_.kind = FaultKind::kNone;
}

void FaultSource::closeGate() {
  std::lock_guard lock(mutex_);
  gate_closed_ = true;
}

void FaultSource::openGate() {
  {
    std::lock_guard lock(mutex_);
    gate_closed_ = false;
  }
  changed_.notify_all();
}

bool FaultSource::waitUntilBlocked(uint32_t readers, double timeout_s) const {
  std::unique_lock lock(mutex_);
  return changed_.wait_for(lock, std::chrono::duration<double>(timeout_s),
                           [&] { return blocked_ >= readers; });
}

bool FaultSource::waitForFaults(uint64_t faults, double timeout_s) const {
  std::unique_lock lock(mutex_);
  return changed_.wait_for(lock, std::chrono::duration<double>(timeout_s),
                           [&] { return faults_ >= faults; });
}

uint64_t FaultSource::prefetch(std::span<const ByteRange> ranges) const {
  {
    std::lock_guard lock(mutex_);
    for (const ByteRange& range : ranges)
      accesses_.push_back({true, range.offset_bytes, range.length_bytes});
  }
  return inner_->prefetch(ranges);
}

std::vector<SourceAccess> FaultSource::accesses() const {
  std::lock_guard lock(mutex_);
  return accesses_;
}

uint64_t FaultSource::reads() const {
  std::lock_guard lock(mutex_);
  return reads_;
}

uint64_t FaultSource::faultsInjected() const {
  std::lock_guard lock(mutex_);
  return faults_;
}

uint32_t FaultSource::blockedNow() const {
  std::lock_guard lock(mutex_);
  return blocked_;
}

}  // namespace tessera::test
