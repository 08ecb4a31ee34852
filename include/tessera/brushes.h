#pragma once
/// \file
/// The brush database: brushes and their instances in a real spatial database (Demeulemeester
/// et al.: "All instance data is stored in a database so that texture tiles can be recomposed
/// at any time"). One interface, two backends: SQLite with its R*Tree module, embedded in one
/// `.sqlite` file (the default), and PostgreSQL + PostGIS for teams that edit one world
/// together. Importers for instance lists in CSV, JSON and GeoJSON. The schema and its version
/// are in docs/procedural.md, "The brush database".

#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <tessera/procedural.h>
#include <tessera/result.h>

namespace tessera {

/// The schema version this build writes and reads (tessera_meta.schema_version).
inline constexpr int kBrushSchemaVersion = 1;

/// The texture the instances paint, in level-0 texels.
struct TextureExtent {
  uint32_t width_px = 0;  ///< 0 until set
  uint32_t height_px = 0;
};

/// Brushes and instances in a spatial database. Owned by one thread (a connection); open one per
/// thread. Every write is one transaction: on error nothing of it is kept.
class BrushDatabase {
 public:
  virtual ~BrushDatabase() = default;
  /// The file path or connection string, for messages.
  virtual const std::string& name() const = 0;
  /// "sqlite" or "postgis".
  virtual const char* backend() const = 0;

  [[nodiscard]] virtual Result<void> setTextureExtent(const TextureExtent& extent) = 0;
  [[nodiscard]] virtual Result<TextureExtent> textureExtent() = 0;

  /// Adds a brush and returns its id, the index instances use (0, 1, 2, ... in order of
  /// addition). Names are unique (kInvalidArgument for a duplicate); images are checked with
  /// validateBrush.
  [[nodiscard]] virtual Result<uint32_t> addBrush(const Brush& brush) = 0;
  /// Every brush, indexed by id.
  [[nodiscard]] virtual Result<std::vector<Brush>> brushes() = 0;

  /// Adds instances in one transaction and returns their new ids (the instances' own `id` is
  /// ignored). Each is checked with validateInstance and its brush must exist; the first bad
  /// one fails the whole call, naming its position, and nothing is added.
  [[nodiscard]] virtual Result<std::vector<uint64_t>> addInstances(
      std::span<const BrushInstance> instances) = 0;
  /// Appends to `out` every instance whose instanceBounds intersect `box` (closed intervals),
  /// in drawing order (drawsBefore). Both backends return the same set for the same data.
  [[nodiscard]] virtual Result<void> query(const BoxPx& box, std::vector<BrushInstance>& out) = 0;
  /// Deletes instances by id; returns how many existed.
  [[nodiscard]] virtual Result<uint64_t> deleteInstances(std::span<const uint64_t> ids) = 0;
  /// Deletes every instance whose bounds intersect `box`; returns how many.
  [[nodiscard]] virtual Result<uint64_t> deleteInstancesIn(const BoxPx& box) = 0;
  [[nodiscard]] virtual Result<uint64_t> instanceCount() = 0;
  /// Calls `visit` for every instance in id order until it returns false.
  [[nodiscard]] virtual Result<void> forEachInstance(
      const std::function<bool(const BrushInstance&)>& visit) = 0;
};

/// Opens (and with `create`, creates) an SQLite brush database file. Fails naming the file:
/// not a brush database, a newer schema version, SQLite without R*Tree.
[[nodiscard]] Result<std::unique_ptr<BrushDatabase>> openSqliteBrushDatabase(
    const std::string& path, bool create);
/// Connects to PostgreSQL with a libpq connection string ("host=/tmp/x dbname=world" or a
/// postgresql:// URI) and, with `create`, creates the schema (and the postgis extension) when
/// missing. Fails naming the connection and the server's message.
[[nodiscard]] Result<std::unique_ptr<BrushDatabase>> openPostgisBrushDatabase(
    const std::string& connection, bool create);
/// Either: a postgresql:// or postgres:// URI, or a string with "dbname=" or "host=", opens
/// PostGIS; anything else is an SQLite file path.
[[nodiscard]] Result<std::unique_ptr<BrushDatabase>> openBrushDatabase(const std::string& location,
                                                                       bool create);

/// Instance list formats.
enum class InstanceFileFormat { kCsv, kJson, kGeoJson };
/// By extension: .csv, .json, .geojson; false for anything else.
bool instanceFileFormatFor(std::string_view path, InstanceFileFormat* format);

/// Parses an instance list. `brush_ids` resolves brush names (a "brush" field may also be a
/// decimal id). Fails on the first bad row, naming `name`, the line and the column (CSV:
/// "a.csv:12:3: radius: 'x' is not a number"; JSON and GeoJSON: the line and column of a syntax
/// error, or the instance's index and field). Pure: no database access.
[[nodiscard]] Result<std::vector<BrushInstance>> parseInstances(
    std::string_view text, InstanceFileFormat format, const std::string& name,
    const std::function<bool(std::string_view, uint32_t*)>& brush_ids);

/// What an import did.
struct ImportReport {
  uint64_t instances = 0;
  uint64_t first_id = 0;  ///< ids of the imported instances, in file order (0 when none)
  uint64_t last_id = 0;
};
/// Reads and parses the whole file, then adds every instance in one transaction: a bad row or
/// a failed write leaves the database as it was.
[[nodiscard]] Result<ImportReport> importInstances(BrushDatabase& database,
                                                   const std::string& path);

/// Instance sets for tests and benchmarks, deterministic for a seed: a realistic mix of large
/// base-layer instances, many small detail stamps and heavy overlap over a texture of
/// `extent` (docs/procedural.md, "Generated instance sets").
std::vector<BrushInstance> generateInstances(uint64_t count, const TextureExtent& extent,
                                             uint32_t brush_count, uint64_t seed);

}  // namespace tessera
