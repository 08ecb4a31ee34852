#pragma once
// Whether this test binary runs under AddressSanitizer (CI's ASan stage adds UBSan). Tests
// whose figures or environment the sanitizer runtimes change ask it: the runtimes hold far
// more memory than the program, and need free descriptors of their own.

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

}  // namespace tessera::test
