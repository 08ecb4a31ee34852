#pragma once
// A Beast body made of parts: bytes held in memory (a tile payload, a multipart header) or a
// span of an archive file read in 64 KiB chunks while it is written, so a response of any size
// holds at most one chunk per connection.

#include <algorithm>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <boost/asio/buffer.hpp>
#include <boost/beast/core/error.hpp>
#include <boost/beast/http/error.hpp>
#include <boost/beast/http/message.hpp>
#include <boost/optional.hpp>

#include <tessera/byte_source.h>

namespace tessera::detail {

/// One part: bytes in memory (`memory`, kept alive by `owner`; no owner for static data), or,
/// when `source` is set, `length_bytes` of it from `offset_bytes`.
struct BodyPart {
  std::shared_ptr<const void> owner;
  std::string_view memory;
  std::shared_ptr<const ByteSource> source;  ///< kept alive while the response is written
  uint64_t offset_bytes = 0;
  uint64_t length_bytes = 0;
  uint64_t size() const { return source ? length_bytes : memory.size(); }

  static BodyPart text(std::shared_ptr<const std::string> bytes) {
    std::string_view view(*bytes);
    return {std::move(bytes), view, nullptr, 0, 0};
  }
  static BodyPart text(std::string bytes) {
    return text(std::make_shared<const std::string>(std::move(bytes)));
  }
  static BodyPart payload(std::vector<uint8_t> bytes) {
    auto owned = std::make_shared<const std::vector<uint8_t>>(std::move(bytes));
    std::string_view view(reinterpret_cast<const char*>(owned->data()), owned->size());
    return {std::move(owned), view, nullptr, 0, 0};
  }
  /// Bytes with static storage duration (the embedded viewer).
  static BodyPart staticBytes(std::string_view bytes) { return {nullptr, bytes, nullptr, 0, 0}; }
  static BodyPart file(std::shared_ptr<const ByteSource> source, uint64_t offset_bytes,
                       uint64_t length_bytes) {
    return {nullptr, {}, std::move(source), offset_bytes, length_bytes};
  }
};

struct PartsBody {
  using value_type = std::vector<BodyPart>;

  static uint64_t size(const value_type& parts) {
    uint64_t total = 0;
    for (const BodyPart& part : parts) total += part.size();
    return total;
  }

  /// Owned by the connection writing the response.
  class writer {
   public:
    using const_buffers_type = boost::asio::const_buffer;
    static constexpr size_t kChunkBytes = 64 * 1024;

    template <bool isRequest, class Fields>
    writer(const boost::beast::http::header<isRequest, Fields>&, const value_type& parts)
        : parts_(parts) {}

    void init(boost::beast::error_code& ec) { ec = {}; }

    boost::optional<std::pair<const_buffers_type, bool>> get(boost::beast::error_code& ec) {
      ec = {};
      while (index_ < parts_.size() && offset_ >= parts_[index_].size()) {
        ++index_;
        offset_ = 0;
      }
      if (index_ >= parts_.size()) return boost::none;
      const BodyPart& part = parts_[index_];
      const bool later_parts = index_ + 1 < parts_.size();
      if (!part.source) {
        offset_ = part.size();
        return {{boost::asio::buffer(part.memory.data(), part.memory.size()), later_parts}};
      }
      uint64_t length = std::min<uint64_t>(kChunkBytes, part.length_bytes - offset_);
      chunk_.resize(size_t(length));
      Result<void> read = part.source->read(part.offset_bytes + offset_, chunk_);
      if (!read) {
        // The headers are out already: all that can be done is to cut the connection.
        ec = boost::beast::http::error::partial_message;
        return boost::none;
      }
      offset_ += length;
      return {{boost::asio::buffer(chunk_), offset_ < part.length_bytes || later_parts}};
    }

   private:
    const value_type& parts_;
    size_t index_ = 0;
    uint64_t offset_ = 0;
    std::vector<uint8_t> chunk_;
  };
};

}  // namespace tessera::detail
