#pragma once
// Checks shared by the file-based band readers (TIFF, PNG, JPEG), so each failure reads the
// same whichever reader meets it first: "scan.tif: no such file", "scan.tif: empty file".

#include <cstdint>
#include <string>

#include <tessera/result.h>

namespace tessera::detail {

/// Upper bound on the bytes a reader holds for one band (its decoded rows plus the strip or
/// tile it decodes them from). An image whose natural band exceeds it is refused with
/// kTooLarge rather than allocated: 2^24 px x 4 channels x 16 rows fits; a 100000-row strip
/// of a wide image does not, and readers then fall back to smaller units or refuse.
inline constexpr uint64_t kMaxBandBytes = uint64_t(1) << 30;

/// Fails with kNotFound when `path` does not exist, kIo when it cannot be read or is not a
/// regular file, kCorrupt when it is empty; otherwise returns its size in bytes.
[[nodiscard]] Result<uint64_t> checkSourceFile(const std::string& path);

/// Fails with kCorrupt for a zero side and kTooLarge for a side over kMaxImageSidePx, naming
/// `path` and both sides.
[[nodiscard]] Result<void> checkSourceDimensions(const std::string& path, uint64_t width_px,
                                                 uint64_t height_px);

}  // namespace tessera::detail
