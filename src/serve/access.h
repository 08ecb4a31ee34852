#pragma once
// Access control of `tessera serve` (docs/serve.md, "Access control"): which archives a
// request may read (public, a bearer token, or a signed URL), per-client rate limits and
// per-archive CORS origins, from one JSON file. Pure decisions over a request's fields, so the
// rules are tested without sockets; the router applies them before it looks an archive up.

#include <chrono>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include <tessera/result.h>

namespace tessera::detail {

enum class AccessVerdict : uint8_t {
  kAllowed,
  kUnauthenticated,  ///< 401: no credential, or a token that is nobody's
  kForbidden,        ///< 403: a credential that does not reach this archive, path or range
};

struct AccessDecision {
  AccessVerdict verdict = AccessVerdict::kAllowed;
  /// Why, for the server's log only: a client learns 401 or 403 and nothing else (neither
  /// whether the archive exists nor which rule refused it).
  std::string reason;
};

/// What a request carries that access control looks at.
struct AccessRequest {
  std::string_view archive;        ///< the archive its path names; empty for none
  std::string_view path;           ///< the raw path of the target, query excluded
  std::string_view query;          ///< the raw query, without '?'
  std::string_view authorization;  ///< the Authorization field
  std::string_view range;          ///< the Range field
  int64_t now_unix_s = 0;
};

/// The rules of one access file. Immutable once loaded; thread-safe.
class AccessRules {
 public:
  /// Reads and checks `path` (JSON; the schema is in docs/serve.md). Errors name the file and
  /// the entry. Secrets stay in memory only: no error message or log line ever holds one.
  [[nodiscard]] static Result<std::shared_ptr<const AccessRules>> load(const std::string& path);
  /// Same, from the file's text (for tests); `name` stands for the file in messages.
  [[nodiscard]] static Result<std::shared_ptr<const AccessRules>> parse(std::string_view json,
                                                                        const std::string& name);

  /// May this request read its archive? Routes without an archive are not asked.
  AccessDecision authorize(const AccessRequest& request) const;
  /// Is `archive` readable without a credential?
  bool isPublic(std::string_view archive) const;
  /// May a request with these credentials see `archive` listed in /api/archives?
  bool mayList(std::string_view archive, std::string_view authorization) const;
  /// The CORS origin for `archive`'s routes: the first matching rule's, else `fallback`.
  const std::string& corsOrigin(std::string_view archive, const std::string& fallback) const;

  /// The secret of signing key `key_id`, or null.
  const std::string* secretOf(std::string_view key_id) const;

  double requestsPerSecond() const { return requests_per_second_; }
  double burst() const { return burst_; }

  struct Token {
    std::string digest;  ///< SHA-256 of the token: compared in constant time, whatever its length
    std::vector<std::string> archives;
  };
  struct SigningKey {
    std::string id, secret;
    std::vector<std::string> archives;
  };
  struct CorsRule {
    std::vector<std::string> archives;
    std::string origin;
  };

 private:
  AccessDecision checkSignature(const AccessRequest& request) const;
  const Token* tokenOf(std::string_view authorization, bool* presented) const;

  std::vector<std::string> public_;
  std::vector<Token> tokens_;
  std::vector<SigningKey> keys_;
  std::vector<CorsRule> cors_;
  double requests_per_second_ = 0;  ///< 0: no limit
  double burst_ = 0;
};

/// `archive` matches `pattern`: a name, or a glob with '*' (any run) and '?' (one character).
bool archiveMatches(std::string_view pattern, std::string_view archive);

/// The query parameters of a signed URL for `scope` (an exact path such as "/earth.tess", or
/// "archive:NAME" for every route of archive NAME), valid until `expires_unix_s`, for the byte
/// range "START-END" when `range` is not empty. HMAC-SHA256 under `secret` (docs/serve.md).
std::string signedQuery(std::string_view key_id, std::string_view secret, std::string_view scope,
                        int64_t expires_unix_s, std::string_view range);

/// Token buckets per client address: `rate` requests a second, bursts of `burst`. Bounded
/// memory: beyond `max_clients` addresses the fullest buckets (idle clients) are dropped.
/// Thread-safe.
class RateLimiter {
 public:
  RateLimiter(double rate, double burst, size_t max_clients = 100'000);
  /// Takes one request from `client`'s bucket; false (and the seconds until one is back in
  /// `retry_after_s`) when it is empty. Always true when the rate is 0.
  bool admit(std::string_view client, std::chrono::steady_clock::time_point now,
             double* retry_after_s = nullptr);

 private:
  struct Bucket {
    double tokens = 0;
    std::chrono::steady_clock::time_point last;
  };
  const double rate_, burst_;
  const size_t max_clients_;
  std::mutex mutex_;
  std::unordered_map<std::string, Bucket> buckets_;
};

}  // namespace tessera::detail
