#include <tessera/byte_source.h>

#include <cstring>

#include <fmt/format.h>

namespace tessera {

namespace {

class MemorySource final : public ByteSource {
 public:
  MemorySource(std::vector<uint8_t> bytes, std::string name)
      : bytes_(std::move(bytes)), name_(std::move(name)) {}

  uint64_t sizeBytes() const override { return bytes_.size(); }
  const std::string& name() const override { return name_; }

  Result<void> read(uint64_t offset_bytes, std::span<uint8_t> out) const override {
    if (offset_bytes > bytes_.size() || out.size() > bytes_.size() - offset_bytes)
      return fail(ErrorCode::kIo, fmt::format("{}: read [{}, +{}) past the end ({} bytes)", name_,
                                              offset_bytes, out.size(), bytes_.size()));
    if (!out.empty()) std::memcpy(out.data(), bytes_.data() + offset_bytes, out.size());
    return {};
  }

 private:
  std::vector<uint8_t> bytes_;
  std::string name_;
};

}  // namespace

std::shared_ptr<ByteSource> makeMemorySource(std::vector<uint8_t> bytes, std::string name) {
  return std::make_shared<MemorySource>(std::move(bytes), std::move(name));
}

}  // namespace tessera
