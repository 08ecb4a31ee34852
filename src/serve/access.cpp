#include "access.h"

#include <sys/stat.h>

#include <openssl/crypto.h>
#include <openssl/evp.h>
#include <openssl/hmac.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <optional>
#include <fstream>
#include <sstream>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <tessera/serve.h>

namespace tessera::detail {

namespace {

// Shorter secrets can be searched; 128 bits for tokens, 256 for HMAC keys (RFC 2104 wants at
// least the hash's output length).
constexpr size_t kMinTokenBytes = 16;
constexpr size_t kMinSecretBytes = 32;
constexpr off_t kMaxAccessFileBytes = off_t(16) << 20;  // thousands of rules fit in far less
constexpr std::string_view kSignaturePrefix = "tessera-url-v1";

std::string sha256(std::string_view bytes) {
  unsigned char digest[EVP_MAX_MD_SIZE];
  unsigned int length = 0;
  EVP_Digest(bytes.data(), bytes.size(), digest, &length, EVP_sha256(), nullptr);
  return std::string(reinterpret_cast<const char*>(digest), length);
}

std::string hex(std::string_view bytes) {
  static constexpr char kDigits[] = "0123456789abcdef";
  std::string out;
  out.reserve(bytes.size() * 2);
  for (unsigned char c : bytes) {
    out += kDigits[c >> 4];
    out += kDigits[c & 15];
  }
  return out;
}

std::string hmacSha256Hex(std::string_view secret, std::string_view message) {
  unsigned char mac[EVP_MAX_MD_SIZE];
  unsigned int length = 0;
  HMAC(EVP_sha256(), secret.data(), int(secret.size()),
       reinterpret_cast<const unsigned char*>(message.data()), message.size(), mac, &length);
  return hex(std::string_view(reinterpret_cast<const char*>(mac), length));
}

// Equal strings, in time that depends on their lengths only.
bool constantTimeEquals(std::string_view a, std::string_view b) {
  return a.size() == b.size() && CRYPTO_memcmp(a.data(), b.data(), a.size()) == 0;
}

bool matchesAny(const std::vector<std::string>& patterns, std::string_view archive) {
  return std::any_of(patterns.begin(), patterns.end(),
                     [&](const std::string& pattern) { return archiveMatches(pattern, archive); });
}

std::string signatureMessage(std::string_view key_id, std::string_view scope,
                             std::string_view range, int64_t expires) {
  return fmt::format("{}\n{}\n{}\n{}\n{}", kSignaturePrefix, key_id, scope, range, expires);
}

// The parameters of a query; a name given twice is kept as "\x01" so that it never verifies.
std::unordered_map<std::string, std::string> queryParameters(std::string_view query) {
  std::unordered_map<std::string, std::string> out;
  while (!query.empty()) {
    const size_t amp = query.find('&');
    const std::string_view pair = query.substr(0, amp);
    const size_t eq = pair.find('=');
    const std::string name(pair.substr(0, eq));
    const std::string value(eq == std::string_view::npos ? "" : pair.substr(eq + 1));
    auto [it, inserted] = out.emplace(name, value);
    if (!inserted) it->second.assign(1, '\x01');
    if (amp == std::string_view::npos) break;
    query.remove_prefix(amp + 1);
  }
  return out;
}

std::optional<uint64_t> parseNumber(std::string_view text) {
  uint64_t value = 0;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (ec != std::errc() || end != text.data() + text.size() || text.empty()) return std::nullopt;
  return value;
}

// "A-B" with A <= B.
std::optional<std::pair<uint64_t, uint64_t>> parseSpan(std::string_view text) {
  const size_t dash = text.find('-');
  if (dash == std::string_view::npos) return std::nullopt;
  const auto first = parseNumber(text.substr(0, dash));
  const auto last = parseNumber(text.substr(dash + 1));
  if (!first || !last || *first > *last) return std::nullopt;
  return std::pair{*first, *last};
}

// Every range of a Range field ("bytes=a-b, c-d") lies inside `allowed`; open and suffix
// ranges ("a-", "-n") do not, since their end depends on the file.
bool rangeWithin(std::string_view field, std::pair<uint64_t, uint64_t> allowed) {
  constexpr std::string_view kUnit = "bytes=";
  if (!field.starts_with(kUnit)) return false;
  field.remove_prefix(kUnit.size());
  while (true) {
    const size_t comma = field.find(',');
    std::string_view spec = field.substr(0, comma);
    while (!spec.empty() && spec.front() == ' ') spec.remove_prefix(1);
    while (!spec.empty() && spec.back() == ' ') spec.remove_suffix(1);
    const auto span = parseSpan(spec);
    if (!span || span->first < allowed.first || span->second > allowed.second) return false;
    if (comma == std::string_view::npos) return true;
    field.remove_prefix(comma + 1);
  }
}

Result<std::vector<std::string>> patternList(const nlohmann::json& value,
                                             const std::string& where) {
  if (!value.is_array() || value.empty())
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: expected a non-empty list of archive names or patterns", where));
  std::vector<std::string> out;
  for (const nlohmann::json& item : value) {
    if (!item.is_string() || item.get_ref<const std::string&>().empty())
      return fail(ErrorCode::kInvalidArgument,
                  fmt::format("{}: every archive pattern is a non-empty string", where));
    out.push_back(item.get<std::string>());
  }
  return out;
}

Result<std::string> secretField(const nlohmann::json& entry, const char* field, size_t min_bytes,
                                const std::string& where) {
  if (!entry.contains(field) || !entry[field].is_string())
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: \"{}\" (a string) is missing", where, field));
  std::string value = entry[field].get<std::string>();
  if (value.size() < min_bytes)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{}: \"{}\" has {} bytes, fewer than the {} that resist guessing",
                            where, field, value.size(), min_bytes));
  return value;
}

Result<void> checkKeys(const nlohmann::json& object, std::initializer_list<std::string_view> known,
                       const std::string& where) {
  for (const auto& [key, value] : object.items())
    if (std::find(known.begin(), known.end(), key) == known.end())
      return fail(ErrorCode::kInvalidArgument, fmt::format("{}: unknown key \"{}\"", where, key));
  return {};
}

}  // namespace

bool archiveMatches(std::string_view pattern, std::string_view archive) {
  // Iterative glob with one backtrack point: linear in practice, never exponential.
  size_t p = 0, a = 0, star = std::string_view::npos, resume = 0;
  while (a < archive.size()) {
    if (p < pattern.size() && (pattern[p] == '?' || pattern[p] == archive[a])) {
      ++p;
      ++a;
    } else if (p < pattern.size() && pattern[p] == '*') {
      star = p++;
      resume = a;
    } else if (star != std::string_view::npos) {
      p = star + 1;
      a = ++resume;
    } else {
      return false;
    }
  }
  while (p < pattern.size() && pattern[p] == '*') ++p;
  return p == pattern.size();
}

std::string signedQuery(std::string_view key_id, std::string_view secret, std::string_view scope,
                        int64_t expires_unix_s, std::string_view range) {
  const std::string sig =
      hmacSha256Hex(secret, signatureMessage(key_id, scope, range, expires_unix_s));
  std::string query = fmt::format("key={}&expires={}", key_id, expires_unix_s);
  if (scope.starts_with("archive:")) query += fmt::format("&archive={}", scope.substr(8));
  if (!range.empty()) query += fmt::format("&range={}", range);
  return query + "&sig=" + sig;
}

Result<std::shared_ptr<const AccessRules>> AccessRules::load(const std::string& path) {
  // A FIFO would block the read (and the SIGHUP reload with it); a device or a huge file is
  // not a set of rules.
  struct stat status {};
  if (::stat(path.c_str(), &status) != 0)
    return fail(ErrorCode::kNotFound, fmt::format("{}: cannot read the access file", path));
  if (!S_ISREG(status.st_mode))
    return fail(ErrorCode::kIo, fmt::format("{}: the access file is not a regular file", path));
  if (status.st_size > kMaxAccessFileBytes)
    return fail(ErrorCode::kTooLarge, fmt::format("{}: access file of {} bytes, over {}", path,
                                                  status.st_size, kMaxAccessFileBytes));
  std::ifstream in(path, std::ios::binary);
  if (!in) return fail(ErrorCode::kNotFound, fmt::format("{}: cannot read the access file", path));
  std::stringstream text;
  text << in.rdbuf();
  return parse(text.str(), path);
}

Result<std::shared_ptr<const AccessRules>> AccessRules::parse(std::string_view json,
                                                              const std::string& name) {
  const nlohmann::json doc = nlohmann::json::parse(json, nullptr, false);
  if (!doc.is_object())
    return fail(ErrorCode::kInvalidArgument, fmt::format("{}: not a JSON object", name));
  TESSERA_TRY(checkKeys(doc, {"public", "tokens", "signing_keys", "cors", "rate_limit"}, name));
  auto rules = std::make_shared<AccessRules>();
  if (doc.contains("public")) {
    TESSERA_ASSIGN_OR_RETURN(rules->public_, patternList(doc["public"], name + ": public"));
  }
  const auto entries = [&](const char* key) -> Result<nlohmann::json> {
    if (!doc.contains(key)) return nlohmann::json::array();
    if (!doc[key].is_array())
      return fail(ErrorCode::kInvalidArgument, fmt::format("{}: \"{}\" is not a list", name, key));
    return doc[key];
  };
  TESSERA_ASSIGN_OR_RETURN(nlohmann::json tokens, entries("tokens"));
  for (size_t i = 0; i < tokens.size(); ++i) {
    const std::string where = fmt::format("{}: tokens[{}]", name, i);
    if (!tokens[i].is_object()) return fail(ErrorCode::kInvalidArgument, where + ": not an object");
    TESSERA_TRY(checkKeys(tokens[i], {"token", "archives", "comment"}, where));
    TESSERA_ASSIGN_OR_RETURN(std::string token,
                             secretField(tokens[i], "token", kMinTokenBytes, where));
    TESSERA_ASSIGN_OR_RETURN(std::vector<std::string> archives,
                             patternList(tokens[i].value("archives", nlohmann::json()), where));
    rules->tokens_.push_back({sha256(token), std::move(archives)});
  }
  TESSERA_ASSIGN_OR_RETURN(nlohmann::json keys, entries("signing_keys"));
  for (size_t i = 0; i < keys.size(); ++i) {
    const std::string where = fmt::format("{}: signing_keys[{}]", name, i);
    if (!keys[i].is_object()) return fail(ErrorCode::kInvalidArgument, where + ": not an object");
    TESSERA_TRY(checkKeys(keys[i], {"id", "secret", "archives", "comment"}, where));
    if (!keys[i].contains("id") || !keys[i]["id"].is_string() ||
        keys[i]["id"].get_ref<const std::string&>().empty() ||
        keys[i]["id"].get_ref<const std::string&>().find_first_of("&=\n") != std::string::npos)
      return fail(ErrorCode::kInvalidArgument,
                  where + ": \"id\" must be a non-empty string without '&', '=' or newline");
    TESSERA_ASSIGN_OR_RETURN(std::string secret,
                             secretField(keys[i], "secret", kMinSecretBytes, where));
    TESSERA_ASSIGN_OR_RETURN(std::vector<std::string> archives,
                             patternList(keys[i].value("archives", nlohmann::json()), where));
    rules->keys_.push_back(
        {keys[i]["id"].get<std::string>(), std::move(secret), std::move(archives)});
  }
  TESSERA_ASSIGN_OR_RETURN(nlohmann::json cors, entries("cors"));
  for (size_t i = 0; i < cors.size(); ++i) {
    const std::string where = fmt::format("{}: cors[{}]", name, i);
    if (!cors[i].is_object() || !cors[i].contains("origin") || !cors[i]["origin"].is_string())
      return fail(ErrorCode::kInvalidArgument, where + ": expected {\"archives\", \"origin\"}");
    TESSERA_TRY(checkKeys(cors[i], {"archives", "origin"}, where));
    TESSERA_ASSIGN_OR_RETURN(std::vector<std::string> archives,
                             patternList(cors[i].value("archives", nlohmann::json()), where));
    rules->cors_.push_back({std::move(archives), cors[i]["origin"].get<std::string>()});
  }
  if (doc.contains("rate_limit")) {
    const nlohmann::json& limit = doc["rate_limit"];
    const std::string where = name + ": rate_limit";
    if (!limit.is_object() || !limit.contains("requests_per_second") ||
        !limit["requests_per_second"].is_number() || limit["requests_per_second"] <= 0)
      return fail(ErrorCode::kInvalidArgument,
                  where + ": expected {\"requests_per_second\": N > 0, \"burst\": M}");
    TESSERA_TRY(checkKeys(limit, {"requests_per_second", "burst"}, where));
    rules->requests_per_second_ = limit["requests_per_second"].get<double>();
    rules->burst_ = limit.value("burst", rules->requests_per_second_);
    if (rules->burst_ < 1)
      return fail(ErrorCode::kInvalidArgument, where + ": burst must be at least 1");
  }
  return std::shared_ptr<const AccessRules>(std::move(rules));
}

const AccessRules::Token* AccessRules::tokenOf(std::string_view authorization,
                                               bool* presented) const {
  *presented = false;
  constexpr std::string_view kScheme = "bearer ";
  if (authorization.size() <= kScheme.size()) return nullptr;
  for (size_t i = 0; i < kScheme.size(); ++i)
    if (std::tolower(static_cast<unsigned char>(authorization[i])) != kScheme[i]) return nullptr;
  *presented = true;
  const std::string digest = sha256(authorization.substr(kScheme.size()));
  // Every token is compared, so the time does not say which one matched.
  const Token* found = nullptr;
  for (const Token& token : tokens_)
    if (constantTimeEquals(token.digest, digest)) found = &token;
  return found;
}

AccessDecision AccessRules::checkSignature(const AccessRequest& request) const {
  const auto params = queryParameters(request.query);
  const auto get = [&](const char* name) -> std::string_view {
    const auto it = params.find(name);
    return it == params.end() ? std::string_view() : std::string_view(it->second);
  };
  const std::string_view key_id = get("key"), sig = get("sig"), range = get("range");
  const std::optional<uint64_t> expires = parseNumber(get("expires"));
  const auto refuse = [](std::string why) {
    return AccessDecision{AccessVerdict::kForbidden, std::move(why)};
  };
  if (key_id.empty() || !expires) return refuse("signed URL without key or expires");
  const auto key =
      std::find_if(keys_.begin(), keys_.end(), [&](const SigningKey& k) { return k.id == key_id; });
  if (key == keys_.end()) return refuse("signed URL with an unknown key");
  const std::string scope = params.count("archive") ? fmt::format("archive:{}", get("archive"))
                                                    : std::string(request.path);
  const std::string expected =
      hmacSha256Hex(key->secret, signatureMessage(key_id, scope, range, int64_t(*expires)));
  if (!constantTimeEquals(expected, sig)) return refuse("signature does not match");
  if (int64_t(*expires) < request.now_unix_s) return refuse("signed URL expired");
  if (params.count("archive") && get("archive") != request.archive)
    return refuse("signed for another archive");
  if (!matchesAny(key->archives, request.archive)) return refuse("key does not reach the archive");
  if (!range.empty()) {
    const auto allowed = parseSpan(range);
    if (!allowed || !rangeWithin(request.range, *allowed))
      return refuse("request outside the signed range");
  }
  return {AccessVerdict::kAllowed, "signed URL"};
}

AccessDecision AccessRules::authorize(const AccessRequest& request) const {
  if (matchesAny(public_, request.archive)) return {AccessVerdict::kAllowed, "public"};
  bool presented = false;
  if (const Token* token = tokenOf(request.authorization, &presented)) {
    if (matchesAny(token->archives, request.archive)) return {AccessVerdict::kAllowed, "token"};
    return {AccessVerdict::kForbidden, "token does not reach the archive"};
  }
  if (presented) return {AccessVerdict::kUnauthenticated, "unknown token"};
  if (queryParameters(request.query).count("sig")) return checkSignature(request);
  return {AccessVerdict::kUnauthenticated, "no credential"};
}

bool AccessRules::isPublic(std::string_view archive) const {
  return matchesAny(public_, archive);
}

bool AccessRules::mayList(std::string_view archive, std::string_view authorization) const {
  if (matchesAny(public_, archive)) return true;
  bool presented = false;
  const Token* token = tokenOf(authorization, &presented);
  return token && matchesAny(token->archives, archive);
}

const std::string& AccessRules::corsOrigin(std::string_view archive,
                                           const std::string& fallback) const {
  for (const CorsRule& rule : cors_)
    if (matchesAny(rule.archives, archive)) return rule.origin;
  return fallback;
}

const std::string* AccessRules::secretOf(std::string_view key_id) const {
  for (const SigningKey& key : keys_)
    if (key.id == key_id) return &key.secret;
  return nullptr;
}

RateLimiter::RateLimiter(double rate, double burst, size_t max_clients)
    : rate_(rate), burst_(std::max(burst, 1.0)), max_clients_(max_clients) {}

bool RateLimiter::admit(std::string_view client, std::chrono::steady_clock::time_point now,
                        double* retry_after_s) {
  if (rate_ <= 0) return true;
  std::lock_guard lock(mutex_);
  auto it = buckets_.find(std::string(client));
  if (it == buckets_.end()) {
    if (buckets_.size() >= max_clients_) {
      // Idle clients have refilled to the burst: dropping them loses nothing.
      for (auto drop = buckets_.begin(); drop != buckets_.end();) {
        const double idle = std::chrono::duration<double>(now - drop->second.last).count();
        drop = drop->second.tokens + idle * rate_ >= burst_ ? buckets_.erase(drop) : ++drop;
      }
      if (buckets_.size() >= max_clients_) buckets_.erase(buckets_.begin());
    }
    it = buckets_.emplace(std::string(client), Bucket{burst_, now}).first;
  }
  Bucket& bucket = it->second;
  const double elapsed = std::chrono::duration<double>(now - bucket.last).count();
  bucket.tokens = std::min(burst_, bucket.tokens + std::max(elapsed, 0.0) * rate_);
  bucket.last = now;
  if (bucket.tokens >= 1) {
    bucket.tokens -= 1;
    return true;
  }
  if (retry_after_s) *retry_after_s = (1 - bucket.tokens) / rate_;
  return false;
}

}  // namespace tessera::detail

namespace tessera {

Result<std::string> signServeQuery(const std::string& access_file, const std::string& key_id,
                                   const std::string& scope, int64_t expires_unix_s,
                                   const std::string& range) {
  TESSERA_ASSIGN_OR_RETURN(std::shared_ptr<const detail::AccessRules> rules,
                           detail::AccessRules::load(access_file));
  const std::string* secret = rules->secretOf(key_id);
  if (!secret)
    return fail(ErrorCode::kNotFound,
                fmt::format("{}: no signing key \"{}\"", access_file, key_id));
  if (scope.empty() || (scope.front() != '/' && !scope.starts_with("archive:")))
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("scope \"{}\": a request path (/...) or archive:NAME", scope));
  if (!range.empty() && !detail::parseSpan(range))
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("range \"{}\": expected FIRST-LAST byte offsets", range));
  return detail::signedQuery(key_id, *secret, scope, expires_unix_s, range);
}

}  // namespace tessera
