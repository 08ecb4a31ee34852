#pragma once
// The access log of `tessera serve --access-log`: one line a request (time, peer, method,
// target, status, body bytes, microseconds), written whole under a lock by any I/O thread.

#include <cstdint>
#include <cstdio>
#include <mutex>
#include <string>
#include <string_view>

#include <tessera/result.h>

namespace tessera::detail {

class AccessLog {
 public:
  /// `path` empty: no log; "-": standard output; otherwise the file, appended to.
  [[nodiscard]] Result<void> open(const std::string& path);
  ~AccessLog();
  bool enabled() const { return file_ != nullptr; }
  /// One line; the target as received, without control bytes and a signed URL's signature.
  void write(const std::string& peer, std::string_view method, std::string_view target,
             unsigned status, uint64_t bytes, int64_t micros);

 private:
  std::mutex mutex_;  // guards writes to file_
  std::FILE* file_ = nullptr;
  bool owned_ = false;
};

}  // namespace tessera::detail
