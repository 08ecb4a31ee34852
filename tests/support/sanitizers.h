#pragma once
// Whether this test binary runs under AddressSanitizer (CI's ASan stage adds UBSan). Tests
// whose figures or environment the sanitizer runtimes change ask it: the runtimes hold far
// more memory than the program, and need free descriptors of their own.

#include <cstdlib>
#include <string>

namespace tessera::test {

/// True in ASan (+UBSan) builds, with GCC or clang.
constexpr bool sanitized() {
#if defined(__SANITIZE_ADDRESS__)
  return true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
  return true;
#else
  return false;
#endif
#else
  return false;
#endif
}

/// "ASAN_OPTIONS=<this process's options>:detect_leaks=0", for `env` in front of a windowed
/// child. LeakSanitizer's exit-time scan stops every thread, and its tracer has crashed (signal
/// 11, exit 134) while X and llvmpipe threads wound down; the last setting of a flag wins.
inline std::string asanOptionsWithoutLeakCheck() {
  const char* options = std::getenv("ASAN_OPTIONS");
  return std::string("ASAN_OPTIONS=") + (options ? std::string(options) + ":" : "") +
         "detect_leaks=0";
}

}  // namespace tessera::test
