#pragma once
/// \file
/// `Result<T>`: a value or an `Error`, the return type of everything that touches files,
/// network, decoding or user input. Its interface is a subset of C++23 `std::expected`
/// (GCC 12's libstdc++ offers `<expected>` only under C++23), so it can become an alias later.
/// No exception crosses the public API; tools print `error().message` and exit non-zero.

#include <string>
#include <type_traits>
#include <utility>
#include <variant>

#include <tessera/check.h>

namespace tessera {

/// What kind of failure, for callers that branch on it (retry I/O, report corrupt data).
enum class ErrorCode {
  kInvalidArgument,  ///< caller asked for something impossible (bad level, bad option)
  kNotFound,         ///< file, image, tile or endpoint missing
  kIo,               ///< read or write failed (errno-level problems, disk full)
  kCorrupt,          ///< bytes fail a checksum or a structural rule
  kUnsupported,      ///< valid input this build does not handle (16-bit TIFF, a newer version)
  kTooLarge,         ///< dimensions or lengths over a documented bound
  kCancelled,        ///< the operation was interrupted on request
  kInternal,         ///< a library we call failed in a way we did not classify
};

/// Names the code for messages and JSON output, e.g. "corrupt".
const char* errorCodeName(ErrorCode code);

/// A failure. `message` names the object and the problem, e.g.
/// "scan.tess: tile (3,12,7) checksum mismatch at offset 81234".
struct Error {
  ErrorCode code = ErrorCode::kInternal;
  std::string message;
};

/// Wraps an `Error` so `Result<T>` can be built from it unambiguously, like `std::unexpected`.
class Unexpected {
 public:
  explicit Unexpected(Error error) : error_(std::move(error)) {}
  Unexpected(ErrorCode code, std::string message) : error_{code, std::move(message)} {}
  const Error& error() const& { return error_; }
  Error&& error() && { return std::move(error_); }

 private:
  Error error_;
};

/// A value of type `T` or an `Error`. Owned by one thread; copyable when `T` is.
template <typename T>
class [[nodiscard]] Result {
 public:
  using value_type = T;

  template <typename U = T, typename = std::enable_if_t<std::is_constructible_v<T, U&&>>>
  Result(U&& value) : state_(std::in_place_index<0>, std::forward<U>(value)) {}
  Result(Unexpected unexpected) : state_(std::in_place_index<1>, std::move(unexpected).error()) {}

  bool has_value() const { return state_.index() == 0; }
  explicit operator bool() const { return has_value(); }

  /// Aborts with the error message when there is no value: a caller bug, not an input error.
  T& value() & {
    checkHasValue();
    return std::get<0>(state_);
  }
  const T& value() const& {
    checkHasValue();
    return std::get<0>(state_);
  }
  T&& value() && {
    checkHasValue();
    return std::get<0>(std::move(state_));
  }
  T& operator*() & { return value(); }
  const T& operator*() const& { return value(); }
  T&& operator*() && { return std::move(*this).value(); }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }

  /// Valid only when `!has_value()`.
  const Error& error() const& {
    TESSERA_CHECK(!has_value()) << "Result::error() called on a value";
    return std::get<1>(state_);
  }
  Error&& error() && {
    TESSERA_CHECK(!has_value()) << "Result::error() called on a value";
    return std::get<1>(std::move(state_));
  }

 private:
  void checkHasValue() const {
    TESSERA_CHECK(has_value()) << "Result::value() on error: " << std::get<1>(state_).message;
  }
  std::variant<T, Error> state_;
};

/// `Result<void>`: success or an `Error`.
template <>
class [[nodiscard]] Result<void> {
 public:
  using value_type = void;
  Result() = default;
  Result(Unexpected unexpected) : error_(std::move(unexpected).error()), failed_(true) {}

  bool has_value() const { return !failed_; }
  explicit operator bool() const { return has_value(); }
  void value() const {
    TESSERA_CHECK(has_value()) << "Result::value() on error: " << error_.message;
  }
  const Error& error() const& {
    TESSERA_CHECK(failed_) << "Result::error() called on success";
    return error_;
  }
  Error&& error() && {
    TESSERA_CHECK(failed_) << "Result::error() called on success";
    return std::move(error_);
  }

 private:
  Error error_;
  bool failed_ = false;
};

/// Builds an error result: `return fail(ErrorCode::kCorrupt, fmt::format(...));`.
inline Unexpected fail(ErrorCode code, std::string message) {
  return Unexpected(code, std::move(message));
}

/// Forwards an error from another result type: `if (!r) return forward(r);`.
template <typename T>
Unexpected forwardError(const Result<T>& result) {
  return Unexpected(result.error());
}

}  // namespace tessera

/// Evaluates `expr` (a `Result<T>`); on error returns it from the enclosing function, which
/// must itself return some `Result<U>`.
#define TESSERA_TRY(expr)                                                          \
  do {                                                                             \
    auto&& tessera_try_result_ = (expr);                                           \
    if (!tessera_try_result_) return ::tessera::forwardError(tessera_try_result_); \
  } while (false)

/// Declares `var` from the value of `expr` (a `Result<T>`), or returns its error.
#define TESSERA_ASSIGN_OR_RETURN(var, expr)                                     \
  auto TESSERA_CONCAT_(tessera_result_, __LINE__) = (expr);                     \
  if (!TESSERA_CONCAT_(tessera_result_, __LINE__))                              \
    return ::tessera::forwardError(TESSERA_CONCAT_(tessera_result_, __LINE__)); \
  var = std::move(TESSERA_CONCAT_(tessera_result_, __LINE__)).value()

#define TESSERA_CONCAT_INNER_(a, b) a##b
#define TESSERA_CONCAT_(a, b) TESSERA_CONCAT_INNER_(a, b)
