#pragma once
/// \file
/// A simulated network link that wraps any byte source: the `--link` option of `tessera fly`
/// and `tessera view`, tests and benchmarks. With it a local archive behaves as one read over
/// a network, for the adaptive scheduling of Marvie & Bouatouch ("Remote Rendering of
/// Massively Textured 3D Scenes Through Progressive Texture Maps", part III), which adapts
/// what it requests to the bandwidth it measures.

#include <atomic>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>

#include <tessera/byte_source.h>
#include <tessera/result.h>

namespace tessera {

/// A simulated network link.
struct LinkModel {
  double bits_per_s = 20e6;  ///< shared by every read in flight
  double rtt_s = 0.04;       ///< per read: the request goes out and the first byte comes back
};

/// Parses "RATE:RTT", e.g. "20mbit:40ms", "2mbit:150ms", "500kbit:0.3s", "1gbit:2ms":
/// RATE in bit, kbit, mbit or gbit (per second; k = 1000), RTT in us, ms or s. Fails naming
/// the text and what is wrong.
[[nodiscard]] Result<LinkModel> parseLinkModel(const std::string& text);

/// What a throttled source transferred.
struct LinkStatsTotal {
  uint64_t reads = 0;            ///< reads started
  uint64_t bytes = 0;            ///< bytes that crossed the simulated link
  uint64_t reads_cancelled = 0;  ///< reads abandoned through readCancellable's flag
};

/// A byte source behind a simulated link: each read waits its round trip, then its bytes
/// cross a link of `bits_per_s` shared by all reads in flight (fair, in slices of 5 ms of
/// link time), then come from `inner`. `readCancellable` stops at the next slice once its
/// flag is set, counting only the bytes that crossed. Prefetch hints are not passed on: the
/// link is the bottleneck being simulated. The waits are the simulation, not synchronisation
/// (docs/runtime.md, "A simulated link"). Thread-safe.
class ThrottledSource final : public ByteSource {
 public:
  /// `inner` must not be null.
  ThrottledSource(std::shared_ptr<ByteSource> inner, const LinkModel& link);
  ~ThrottledSource() override;
  ThrottledSource(const ThrottledSource&) = delete;
  ThrottledSource& operator=(const ThrottledSource&) = delete;

  uint64_t sizeBytes() const override;
  /// The inner source's name with the link, e.g. "x.tess (via 20 Mbit/s, 40 ms link)".
  const std::string& name() const override;
  [[nodiscard]] Result<void> read(uint64_t offset_bytes, std::span<uint8_t> out) const override;
  [[nodiscard]] Result<void> readCancellable(uint64_t offset_bytes, std::span<uint8_t> out,
                                             const std::atomic<bool>& cancel) const override;
  const LinkModel& link() const { return link_; }
  /// Reads, bytes and cancelled reads so far.
  LinkStatsTotal totals() const;
  /// The same figures as a network source gives them (requests, bytes received, cancelled,
  /// in flight, the last 64 reads with their round trip as the first byte's time).
  std::optional<LinkStats> linkStats() const override;

 private:
  struct State;  // the link's schedule and counters, behind their mutex (link.cpp)

  Result<void> transfer(uint64_t offset_bytes, std::span<uint8_t> out,
                        const std::atomic<bool>* cancel) const;

  std::shared_ptr<ByteSource> inner_;
  LinkModel link_;
  std::string name_;
  std::unique_ptr<State> state_;
};

/// `inner` behind a simulated link.
std::shared_ptr<ThrottledSource> makeThrottledSource(std::shared_ptr<ByteSource> inner,
                                                     const LinkModel& link);

}  // namespace tessera
