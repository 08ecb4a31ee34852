// The ByteSource interface lives with the archive reader that consumes it; the file and
// memory implementations are in the stream module.
#include <tessera/byte_source.h>

namespace tessera {

Result<void> ByteSource::readMany(std::span<const ByteRange> ranges) const {
  for (const ByteRange& range : ranges)
    TESSERA_TRY(read(range.offset_bytes, {range.out, size_t(range.length_bytes)}));
  return {};
}

}  // namespace tessera
