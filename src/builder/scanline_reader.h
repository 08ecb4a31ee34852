#pragma once
// The row loop of the band readers whose decoder yields one row per call (libpng's
// png_read_row, libjpeg's jpeg_read_scanlines): rows into the caller's band, the decoder's end
// checked after the last row, and a failed decoder never called again.

#include <cstdint>
#include <span>
#include <string>

#include "band_reader.h"

namespace tessera::detail {

/// A BandReader over a decoder that yields one row at a time. A subclass sets info_ when it
/// opens and implements the three decoder steps; readRows is the one loop they share. Owned by
/// one thread.
class ScanlineReader : public BandReader {
 public:
  const SourceInfo& info() const final { return info_; }
  /// Decodes rows one by one into `out`; after the image's last row, reads to the end of its
  /// data (finishDecoding), so a file cut or padded there fails too. A decoder error fails with
  /// kCorrupt naming the file, the row and the decoder's message, and every later call repeats
  /// it: a decoder's state is undefined after an error.
  [[nodiscard]] Result<void> readRows(uint32_t rows, std::span<uint8_t> out) final;

 protected:
  explicit ScanlineReader(std::string path) : path_(std::move(path)) {}

  /// Decodes the next row into `row` (width_px * channels samples). False after a decoder error.
  virtual bool decodeRow(uint8_t* row) = 0;
  /// Reads past the last row to the end of the image data (PNG IEND, JPEG EOI). False after a
  /// decoder error.
  virtual bool finishDecoding() = 0;
  /// The decoder's message for the last failed step.
  virtual const char* decoderMessage() const = 0;

  const std::string path_;
  SourceInfo info_;  ///< set by the subclass's open, constant after

 private:
  uint32_t next_row_ = 0;  ///< rows delivered so far
  std::string failure_;    ///< the first decoder error, repeated by every later call
};

}  // namespace tessera::detail
