// The access log (access_log.h).
#include "access_log.h"

#include <algorithm>
#include <chrono>
#include <ctime>

#include <fmt/format.h>

namespace tessera::detail {

namespace {

// `target` with the value of its query's `sig` parameter replaced by REDACTED.
std::string withoutSignature(std::string_view target) {
  std::string out(target);
  const size_t query = out.find('?');
  if (query == std::string::npos) return out;
  for (size_t at = out.find("sig=", query); at != std::string::npos;
       at = out.find("sig=", at + 1)) {
    if (out[at - 1] != '?' && out[at - 1] != '&') continue;
    const size_t end = std::min(out.find('&', at), out.size());
    out.replace(at + 4, end - at - 4, "REDACTED");
  }
  return out;
}

}  // namespace

Result<void> AccessLog::open(const std::string& path) {
  if (path.empty()) return {};
  if (path == "-") {
    file_ = stdout;
    return {};
  }
  file_ = std::fopen(path.c_str(), "a");
  owned_ = file_ != nullptr;
  if (!file_) return fail(ErrorCode::kIo, fmt::format("{}: cannot open the access log", path));
  return {};
}

AccessLog::~AccessLog() {
  if (owned_) std::fclose(file_);
}

void AccessLog::write(const std::string& peer, std::string_view method, std::string_view target,
                      unsigned status, uint64_t bytes, int64_t micros) {
  if (!file_) return;
  const auto now = std::chrono::system_clock::now();
  const std::time_t seconds = std::chrono::system_clock::to_time_t(now);
  const int millis = int(
      std::chrono::duration_cast<std::chrono::milliseconds>(now.time_since_epoch()).count() % 1000);
  std::tm parts{};
  ::gmtime_r(&seconds, &parts);
  char stamp[32];
  std::strftime(stamp, sizeof stamp, "%Y-%m-%dT%H:%M:%S", &parts);
  // Targets are logged as received, minus anything that could break the line format and
  // the signature of a signed URL (a credential until it expires).
  std::string safe_target = withoutSignature(target.substr(0, 2048));
  for (char& c : safe_target)
    if (uint8_t(c) < 0x21 || uint8_t(c) >= 0x7f) c = '?';
  std::string line = fmt::format("{}.{:03d}Z {} {} {} {} {} {}\n", stamp, millis, peer,
                                 method.empty() ? "-" : method,
                                 safe_target.empty() ? "-" : safe_target, status, bytes, micros);
  std::lock_guard lock(mutex_);
  std::fwrite(line.data(), 1, line.size(), file_);
  std::fflush(file_);
}

}  // namespace tessera::detail
