#pragma once
/// \file
/// Contract checks. A failed check is a bug in the caller or in Tessera, never bad input:
/// it prints file:line, the condition and the streamed explanation, then aborts.
/// `TESSERA_CHECK(cond) << "why";` is always on; `TESSERA_DCHECK` only in debug builds.

#include <sstream>

namespace tessera::detail {

/// Collects the streamed explanation and aborts in its destructor. Owned by one thread.
class CheckFailure {
 public:
  CheckFailure(const char* file, int line, const char* condition);
  [[noreturn]] ~CheckFailure();
  template <typename T>
  CheckFailure& operator<<(const T& part) {
    stream_ << part;
    return *this;
  }

 private:
  std::ostringstream stream_;
};

/// Lets `cond ? (void)0 : Voidify() & CheckFailure(...) << ...` type-check as void.
struct CheckVoidify {
  void operator&(const CheckFailure&) {}
};

}  // namespace tessera::detail

#define TESSERA_CHECK(condition)                    \
  (condition) ? (void)0                             \
              : ::tessera::detail::CheckVoidify() & \
                    ::tessera::detail::CheckFailure(__FILE__, __LINE__, #condition)

#ifdef NDEBUG
#define TESSERA_DCHECK(condition) \
  while (false) TESSERA_CHECK(condition)
#else
#define TESSERA_DCHECK(condition) TESSERA_CHECK(condition)
#endif
