// MBTiles 1.3: one SQLite file, tiles keyed by zoom, column and TMS row (y counted from the
// bottom), written under a temporary name in one transaction and renamed into place.
#include <filesystem>
#include <memory>

#include <fmt/format.h>
#include <sqlite3.h>

#include "export_writers.h"
#include "uniform_pictures.h"
#include "output/output_file.h"

namespace tessera::detail {

namespace {

struct DatabaseCloser {
  void operator()(sqlite3* db) const { sqlite3_close(db); }
};
struct StatementFinalizer {
  void operator()(sqlite3_stmt* statement) const { sqlite3_finalize(statement); }
};
using Database = std::unique_ptr<sqlite3, DatabaseCloser>;
using Statement = std::unique_ptr<sqlite3_stmt, StatementFinalizer>;

Result<void> sqliteFailure(const std::string& path, sqlite3* db, const char* doing) {
  return fail(ErrorCode::kIo, fmt::format("{}: {}: {}", path, doing, sqlite3_errmsg(db)));
}

Result<void> execute(const std::string& path, sqlite3* db, const char* sql) {
  if (sqlite3_exec(db, sql, nullptr, nullptr, nullptr) != SQLITE_OK)
    return sqliteFailure(path, db, sql);
  return {};
}

Result<Statement> prepare(const std::string& path, sqlite3* db, const char* sql) {
  sqlite3_stmt* statement = nullptr;
  if (sqlite3_prepare_v2(db, sql, -1, &statement, nullptr) != SQLITE_OK)
    return forwardError(sqliteFailure(path, db, sql));
  return Statement(statement);
}

Result<void> insertMetadata(const std::string& path, sqlite3* db, const Archive& archive,
                            const ImageInfo& info, const std::string& tile_format) {
  TESSERA_ASSIGN_OR_RETURN(Statement insert,
                           prepare(path, db, "INSERT INTO metadata (name, value) VALUES (?, ?)"));
  const std::pair<std::string, std::string> rows[] = {
      {"name", info.name.empty() ? archive.name() : info.name},
      {"format", tile_format},
      {"type", "baselayer"},
      {"version", "1"},
      {"description",
       fmt::format("{} x {} px, exported by tessera", info.width_px, info.height_px)},
      {"minzoom", "0"},
      {"maxzoom", std::to_string(xyzMaxZoom(info))},
      {"bounds", "-180,-85.05112878,180,85.05112878"}};
  for (const auto& [key, value] : rows) {
    sqlite3_bind_text(insert.get(), 1, key.c_str(), -1, SQLITE_TRANSIENT);
    sqlite3_bind_text(insert.get(), 2, value.c_str(), -1, SQLITE_TRANSIENT);
    if (sqlite3_step(insert.get()) != SQLITE_DONE)
      return sqliteFailure(path, db, "inserting metadata");
    sqlite3_reset(insert.get());
  }
  return {};
}

Result<void> insertTiles(const std::string& path, sqlite3* db, const Archive& archive,
                         const ExportOptions& options, PictureFormat format, ExportReport& report) {
  TESSERA_ASSIGN_OR_RETURN(
      Statement insert, prepare(path, db,
                                "INSERT INTO tiles (zoom_level, tile_column, tile_row, tile_data) "
                                "VALUES (?, ?, ?, ?)"));
  const std::vector<XyzTile> tiles = xyzTilesOf(archive.images()[options.image]);
  UniformPictures uniforms(archive.images()[options.image], format, options.jpeg_quality);
  for (const XyzTile& t : tiles) {
    Result<Picture> picture = exportXyzTile(archive, options.image, t.z, t.x, t.y, uniforms);
    if (!picture)
      return fail(picture.error().code, fmt::format("{}: XYZ tile {}/{}/{}: {}", path, t.z, t.x,
                                                    t.y, picture.error().message));
    sqlite3_bind_int(insert.get(), 1, int(t.z));
    sqlite3_bind_int(insert.get(), 2, int(t.x));
    sqlite3_bind_int64(insert.get(), 3, (int64_t(1) << t.z) - 1 - t.y);  // TMS row
    sqlite3_bind_blob(insert.get(), 4, picture->bytes.data(), int(picture->bytes.size()),
                      SQLITE_STATIC);
    if (sqlite3_step(insert.get()) != SQLITE_DONE)
      return sqliteFailure(path, db, "inserting a tile");
    sqlite3_reset(insert.get());
    report.bytes += picture->bytes.size();
    report.tiles_copied += picture->copied ? 1 : 0;
    ++report.tiles;
    if (options.on_progress) options.on_progress(report.tiles, tiles.size());
  }
  report.tiles_uniform = uniforms.tilesServed();
  return {};
}

Result<void> writeDatabase(const std::string& path, const Archive& archive,
                           const ExportOptions& options, ExportReport& report) {
  sqlite3* raw = nullptr;
  const int opened =
      sqlite3_open_v2(path.c_str(), &raw, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE, nullptr);
  Database db(raw);
  if (opened != SQLITE_OK) return sqliteFailure(path, raw, "cannot create");
  const ImageInfo& info = archive.images()[options.image];
  const PictureFormat format = dziFormat(info);
  report.tile_format = dziExtension(format);
  TESSERA_TRY(execute(path, db.get(),
                      "PRAGMA journal_mode=OFF; PRAGMA synchronous=OFF; BEGIN;"
                      "CREATE TABLE metadata (name TEXT, value TEXT);"
                      "CREATE TABLE tiles (zoom_level INTEGER, tile_column INTEGER, "
                      "tile_row INTEGER, tile_data BLOB);"));
  TESSERA_TRY(insertMetadata(path, db.get(), archive, info, report.tile_format));
  TESSERA_TRY(insertTiles(path, db.get(), archive, options, format, report));
  TESSERA_TRY(execute(path, db.get(),
                      "CREATE UNIQUE INDEX tile_index ON tiles "
                      "(zoom_level, tile_column, tile_row); COMMIT;"));
  return {};
}

}  // namespace

Result<ExportReport> exportMbtiles(const Archive& archive, const std::string& out_path,
                                   const ExportOptions& options) {
  ExportReport report;
  // SQLite writes through a path, so the file is built under a temporary name (journal off:
  // the file is new either way).
  TESSERA_TRY(writeThroughPartialFile(out_path, [&](const std::string& partial) {
    return writeDatabase(partial, archive, options, report);
  }));
  std::error_code error;
  report.bytes = std::filesystem::file_size(out_path, error);
  return report;
}

}  // namespace tessera::detail
