#pragma once
// A fault-injecting ByteSource for tests of the loader and the streamer: it wraps a healthy
// source and, while faulting, fails reads, delivers short or corrupted data, or holds reads at
// a gate the test opens. Everything is driven by the test through condition variables; no
// timing is involved.

#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <tessera/byte_source.h>

namespace tessera::test {

/// What a faulted read does.
enum class FaultKind {
  kNone,       ///< passes the read through
  kError,      ///< returns a kIo error naming the source and the offset
  kShortRead,  ///< fills only the first half of `out`, zeroes the rest, and reports success
               ///< (a broken source that ignores its short count)
  kFlipBytes,  ///< reads through, then flips the low bit of one byte every `flip_stride_bytes`
               ///< (starting half a stride in) and reports success
};

/// Which reads fault and how.
struct FaultConfig {
  FaultKind kind = FaultKind::kNone;
  /// Faults one read in `every` (the 1st, the (every+1)th, ... since `setFaults`); 1 = all.
  uint32_t every = 1;
  /// Only reads that start at or after this offset fault (e.g. past the directory).
  uint64_t min_offset_bytes = 0;
  uint64_t flip_stride_bytes = 256;
};

/// One call on the source, in the order calls arrived.
struct SourceAccess {
  bool hint = false;  ///< a prefetch range, else a read
  uint64_t offset_bytes = 0;
  uint64_t length_bytes = 0;
};

/// Thread-safe, like every ByteSource.
class FaultSource final : public ByteSource {
 public:
  explicit FaultSource(std::shared_ptr<ByteSource> inner);
  /// Opens the gate so no reader stays blocked.
  ~FaultSource() override;

  uint64_t sizeBytes() const override;
  const std::string& name() const override;
  [[nodiscard]] Result<void> read(uint64_t offset_bytes, std::span<uint8_t> out) const override;
  /// Logs each range, then passes the hint on.
  uint64_t prefetch(std::span<const ByteRange> ranges) const override;

  /// Starts faulting as `config` says (restarting the `every` count).
  void setFaults(const FaultConfig& config);
  /// Stops faulting: later reads pass through. Does not open the gate.
  void stopFaulting();

  /// Closes the gate: every later read blocks (before reading) until `openGate`.
  void closeGate();
  /// Opens the gate and wakes every blocked reader.
  void openGate();
  /// Waits until at least `readers` reads are blocked at the gate at once. Returns false if
  /// that has not happened within `timeout_s` (a deadline for a broken test, not a delay).
  bool waitUntilBlocked(uint32_t readers, double timeout_s = 30) const;
  /// Waits until at least `faults` faults were injected in total; false after `timeout_s`.
  bool waitForFaults(uint64_t faults, double timeout_s = 30) const;

  uint64_t reads() const;           ///< read calls so far, faulted or not
  uint64_t faultsInjected() const;  ///< faulted reads so far
  uint32_t blockedNow() const;      ///< reads waiting at the gate now
  /// Every read and prefetch range so far, in arrival order (a read is logged when it
  /// arrives, before the gate).
  std::vector<SourceAccess> accesses() const;

 private:
  std::shared_ptr<ByteSource> inner_;
  std::string name_;
  mutable std::mutex mutex_;  // guards everything below
  mutable std::condition_variable changed_;
  FaultConfig config_;
  bool gate_closed_ = false;
  mutable uint64_t faultable_reads_ = 0;  ///< reads eligible for faulting since setFaults
  mutable uint64_t reads_ = 0;
  mutable uint64_t faults_ = 0;
  mutable uint32_t blocked_ = 0;
  mutable std::vector<SourceAccess> accesses_;
};

}  // namespace tessera::test
