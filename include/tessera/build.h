#pragma once
/// \file
/// Building archives from TIFF/BigTIFF, PNG, JPEG or the synthetic source: a streaming
/// pyramid (one band per level, Backes et al. section 4) encoded on all cores and written
/// atomically.

#include <atomic>
#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include <tessera/format.h>
#include <tessera/result.h>

namespace tessera {

/// Most encoder threads a build accepts (BuildOptions::threads).
inline constexpr uint32_t kMaxBuildThreads = 1024;

/// An image the caller supplies row by row instead of as a file: the Python package builds from
/// NumPy arrays (memory-mapped ones included) and iterators of row bands this way. The builder
/// pulls rows top to bottom as it needs them, one band at a time: a tile row (tile_size_px
/// rows), or `band_rows` up to four tile rows when that is more; the source never has to hold
/// the whole image.
struct RowSource {
  /// Names the source in messages and in the archive metadata ("source"), e.g. "array".
  std::string name;
  uint32_t width_px = 0;   ///< 1..kMaxImageSidePx
  uint32_t height_px = 0;  ///< 1..kMaxImageSidePx
  uint32_t channels = 0;   ///< 1 gray, 2 gray+alpha, 3 RGB, 4 RGBA
  uint32_t band_rows = 0;  ///< rows the source delivers most cheaply at once; 0 = any
  /// u8, u16 or f32 samples (host byte order); wide samples need a codec that holds them.
  SampleType sample_type = SampleType::kU8;
  /// Fills `out` with rows [first_row, first_row + rows), tightly packed (width_px * channels *
  /// sampleBytes(sample_type) bytes per row). Called on the building thread, top to bottom, each
  /// row exactly once. An error fails the build with its message (prefixed with `name` if it does
  /// not start with it).
  std::function<Result<void>(uint32_t first_row, uint32_t rows, std::span<uint8_t> out)> read_rows;
};

/// Everything `tessera build` can set. Defaults are the CLI's defaults.
struct BuildOptions {
  /// One or more sources, one image each (a scene's texture set): paths, or
  /// "synthetic:WxH[:seed[:channels]]".
  std::vector<std::string> inputs;
  /// Images supplied by the caller (RowSource), after those of `inputs`.
  std::vector<RowSource> row_sources;
  std::string output;           ///< the archive path; written atomically
  uint32_t tile_size_px = 256;  ///< power of two, 64..2048
  uint32_t border_px = 0;       ///< 0..16
  Codec codec = Codec::kJpeg;
  int quality = 85;  ///< JPEG quality 1..100
  /// Codec effort: zstd level, PNG/WebP effort, ptm mode 1-3 (docs/codecs.md); 0 = default.
  int effort = 0;
  bool chroma_subsampling = true;  ///< JPEG 4:2:0 (true) or 4:4:4
  bool srgb_downsample = false;    ///< average levels in linear light
  TileOrder order = TileOrder::kHilbert;
  uint32_t threads = 0;          ///< encoder threads, 0..kMaxBuildThreads; 0 = all cores
  uint32_t page_tiles_log2 = 5;  ///< directory page side in tiles, as a power of two (3..8)
  /// Optional image names stored in metadata, one per input (inputs, then row_sources);
  /// default: the input's file name, or the row source's name.
  std::vector<std::string> image_names;
  /// Most memory the build may need, in bytes; 0 = defaultBuildMemoryLimitBytes(). The need is
  /// estimated from the sizes the inputs claim, after their headers are read and before any
  /// row is allocated, and a build over the limit is refused (docs/builder.md, "Memory budget").
  uint64_t memory_limit_bytes = 0;
  /// Directory for the spool of encoded tiles (about the archive's size, removed at the end);
  /// empty = the output's directory.
  std::string spool_dir;
};

/// Progress for a terminal bar. Called from the building thread about every 100 ms.
struct BuildProgress {
  uint64_t pixels_done = 0;  ///< level-0 pixels read so far
  uint64_t pixels_total = 0;
  uint64_t tiles_written = 0;
  double elapsed_s = 0;
};

/// What a finished build reports.
struct BuildReport {
  uint64_t output_bytes = 0;
  uint64_t tiles_encoded = 0;
  /// Tiles an import took as stored, neither decoded nor encoded (docs/import.md); they are not
  /// counted in tiles_encoded.
  uint64_t tiles_copied = 0;
  uint64_t tiles_uniform = 0;
  uint64_t tiles_empty = 0;
  uint64_t payload_bytes = 0;
  double elapsed_s = 0;
  double megapixels_per_s = 0;  ///< level-0 megapixels / elapsed
  std::vector<ImageInfo> images;
  uint64_t memory_estimate_bytes = 0;  ///< the memory the build was estimated to need
  uint64_t memory_limit_bytes = 0;     ///< the limit it was checked against
};

/// The memory limit of a build that sets none: half of the machine's physical memory, or of
/// the control group's memory limit (cgroup v2 `memory.max`, v1 `memory.limit_in_bytes`) where
/// that is lower. Thread-safe.
[[nodiscard]] uint64_t defaultBuildMemoryLimitBytes();

/// Checks what needs no input file: quality 1..100, the effort's range for the codec (zstd
/// -100..22, png and webp 0..9, ptm 0..4, none for raw, lz4 and jpeg: 0 only), tile size,
/// border, directory page size, threads up to kMaxBuildThreads, the codec's availability, and
/// that an output is named. kInvalidArgument (kUnsupported for a codec missing from this build)
/// naming the value and what is accepted; row sources without a callback or with a channel count
/// outside 1..4. buildArchive calls it first.
[[nodiscard]] Result<void> validateBuildOptions(const BuildOptions& options);

/// Builds an archive. On any failure, and when `cancel` becomes true, nothing is left at
/// `options.output` (a previous file there is untouched) and no temporary file remains.
/// Errors name the input or output file and the problem. Before anything is allocated or
/// written it refuses: an output path that exists and is not a regular file (kInvalidArgument),
/// inputs whose claimed size needs more memory than the limit (kTooLarge, naming the input, its
/// claimed size and the memory needed), and too little free space for the spool and the archive
/// (kIo). A hostile header costs no more memory than the rows that arrive. Blocking; owned by
/// the caller's thread.
[[nodiscard]] Result<BuildReport> buildArchive(
    const BuildOptions& options, const std::function<void(const BuildProgress&)>& on_progress = {},
    const std::atomic<bool>* cancel = nullptr);

}  // namespace tessera
