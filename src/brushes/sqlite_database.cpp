// The SQLite backend of BrushDatabase: one file; instances in a plain table and their bounds in
// an R*Tree virtual table with the same ids, joined per query (docs/procedural.md, "The brush
// database"; R*Tree auxiliary columns measured 2.4x slower to read back per row).
#include <tessera/brushes.h>

#include <algorithm>
#include <cstring>

#include <fmt/format.h>
#include <sqlite3.h>

#include "brush_codec.h"

namespace tessera {

namespace {

constexpr const char* kSchema = R"sql(
CREATE TABLE IF NOT EXISTS tessera_meta(key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS brushes(
  id INTEGER PRIMARY KEY, name TEXT NOT NULL UNIQUE, blend INTEGER NOT NULL,
  mask INTEGER NOT NULL, mask_low INTEGER NOT NULL, mask_high INTEGER NOT NULL);
CREATE TABLE IF NOT EXISTS brush_images(
  brush_id INTEGER NOT NULL REFERENCES brushes(id), variant INTEGER NOT NULL,
  width INTEGER NOT NULL, height INTEGER NOT NULL, rgba BLOB NOT NULL,
  PRIMARY KEY(brush_id, variant));
CREATE TABLE IF NOT EXISTS instances(
  id INTEGER PRIMARY KEY, brush_id INTEGER NOT NULL REFERENCES brushes(id),
  x REAL NOT NULL, y REAL NOT NULL, radius REAL NOT NULL, rotation REAL NOT NULL,
  scale REAL NOT NULL, opacity INTEGER NOT NULL, tint INTEGER NOT NULL, layer INTEGER NOT NULL,
  variant INTEGER NOT NULL);
CREATE VIRTUAL TABLE IF NOT EXISTS instance_bounds USING rtree(id, min_x, max_x, min_y, max_y);
)sql";

constexpr const char* kInstanceColumns =
    "id, brush_id, x, y, radius, rotation, scale, opacity, tint, layer, variant";

/// A prepared statement, finalized on scope exit.
class Statement {
 public:
  Statement() = default;
  Statement(const Statement&) = delete;
  Statement& operator=(const Statement&) = delete;
  ~Statement() { sqlite3_finalize(stmt_); }
  sqlite3_stmt** out() { return &stmt_; }
  sqlite3_stmt* get() const { return stmt_; }

 private:
  sqlite3_stmt* stmt_ = nullptr;
};

BrushInstance readInstance(sqlite3_stmt* stmt) {
  BrushInstance instance;
  instance.id = uint64_t(sqlite3_column_int64(stmt, 0));
  instance.brush = uint32_t(sqlite3_column_int64(stmt, 1));
  instance.x_px = sqlite3_column_double(stmt, 2);
  instance.y_px = sqlite3_column_double(stmt, 3);
  instance.radius_px = float(sqlite3_column_double(stmt, 4));
  instance.rotation_rad = float(sqlite3_column_double(stmt, 5));
  instance.scale = float(sqlite3_column_double(stmt, 6));
  instance.opacity = uint8_t(sqlite3_column_int(stmt, 7));
  instance.tint_rgba = uint32_t(sqlite3_column_int64(stmt, 8));
  instance.layer = int32_t(sqlite3_column_int64(stmt, 9));
  instance.variant = uint8_t(sqlite3_column_int(stmt, 10));
  return instance;
}

class SqliteBrushDatabase final : public BrushDatabase {
 public:
  SqliteBrushDatabase(sqlite3* db, std::string name) : db_(db), name_(std::move(name)) {}
  ~SqliteBrushDatabase() override { sqlite3_close_v2(db_); }

  const std::string& name() const override { return name_; }
  const char* backend() const override { return "sqlite"; }

  Result<void> exec(const char* sql) {
    char* message = nullptr;
    if (sqlite3_exec(db_, sql, nullptr, nullptr, &message) != SQLITE_OK) {
      std::string text = message ? message : sqlite3_errmsg(db_);
      sqlite3_free(message);
      return fail(ErrorCode::kIo, fmt::format("{}: {}", name_, text));
    }
    return {};
  }

  Result<void> prepare(const char* sql, Statement& statement) {
    if (sqlite3_prepare_v2(db_, sql, -1, statement.out(), nullptr) != SQLITE_OK)
      return error("prepare");
    return {};
  }

  Unexpected error(const char* what) {
    return fail(ErrorCode::kIo, fmt::format("{}: {}: {}", name_, what, sqlite3_errmsg(db_)));
  }

  // Creates the schema in a new file, or checks an existing file's version.
  Result<void> initialise(bool create) {
    // WAL lets one writer and many readers (the build's workers) share the file; a large page
    // cache and a memory map keep tile queries off the read() path.
    TESSERA_TRY(
        exec("PRAGMA journal_mode=WAL; PRAGMA synchronous=NORMAL; "
             "PRAGMA cache_size=-131072; PRAGMA mmap_size=17179869184;"));
    Statement has_meta;
    TESSERA_TRY(
        prepare("SELECT COUNT(*) FROM sqlite_master WHERE type = 'table' AND name = "
                "'tessera_meta'",
                has_meta));
    if (sqlite3_step(has_meta.get()) != SQLITE_ROW) return error("open");
    if (sqlite3_column_int(has_meta.get(), 0) == 1) {
      Statement check;
      TESSERA_TRY(prepare("SELECT value FROM tessera_meta WHERE key = 'schema_version'", check));
      int version =
          sqlite3_step(check.get()) == SQLITE_ROW ? sqlite3_column_int(check.get(), 0) : 0;
      if (version != kBrushSchemaVersion)
        return fail(ErrorCode::kUnsupported,
                    fmt::format("{}: brush database schema version {} (this build reads {})", name_,
                                version, kBrushSchemaVersion));
      return {};
    }
    if (!create) return fail(ErrorCode::kNotFound, name_ + ": not a Tessera brush database");
    TESSERA_TRY(exec("BEGIN"));
    Result<void> created = exec(kSchema);
    if (created)
      created = exec(fmt::format("INSERT INTO tessera_meta VALUES('schema_version', '{}')",
                                 kBrushSchemaVersion)
                         .c_str());
    if (!created) {
      (void)exec("ROLLBACK");
      return created;
    }
    return exec("COMMIT");
  }

  Result<void> setTextureExtent(const TextureExtent& extent) override {
    return exec(fmt::format("INSERT OR REPLACE INTO tessera_meta VALUES('texture_width', '{}'), "
                            "('texture_height', '{}')",
                            extent.width_px, extent.height_px)
                    .c_str());
  }

  Result<TextureExtent> textureExtent() override {
    Statement statement;
    TESSERA_TRY(
        prepare("SELECT key, value FROM tessera_meta WHERE key IN ('texture_width', "
                "'texture_height')",
                statement));
    TextureExtent extent;
    while (sqlite3_step(statement.get()) == SQLITE_ROW) {
      std::string key = reinterpret_cast<const char*>(sqlite3_column_text(statement.get(), 0));
      uint32_t value = uint32_t(std::strtoul(
          reinterpret_cast<const char*>(sqlite3_column_text(statement.get(), 1)), nullptr, 10));
      (key == "texture_width" ? extent.width_px : extent.height_px) = value;
    }
    return extent;
  }

  Result<uint32_t> addBrush(const Brush& brush) override {
    TESSERA_TRY(validateBrush(brush, name_ + ": brush " + brush.name));
    TESSERA_TRY(exec("BEGIN IMMEDIATE"));
    Result<uint32_t> id = addBrushInTransaction(brush);
    if (!id) {
      (void)exec("ROLLBACK");
      return id;
    }
    TESSERA_TRY(exec("COMMIT"));
    return id;
  }

  Result<uint32_t> addBrushInTransaction(const Brush& brush) {
    Statement exists, count, insert, image;
    TESSERA_TRY(prepare("SELECT 1 FROM brushes WHERE name = ?", exists));
    sqlite3_bind_text(exists.get(), 1, brush.name.c_str(), -1, SQLITE_TRANSIENT);
    if (sqlite3_step(exists.get()) == SQLITE_ROW)
      return fail(ErrorCode::kInvalidArgument,
                  fmt::format("{}: a brush named '{}' exists", name_, brush.name));
    TESSERA_TRY(prepare("SELECT COUNT(*) FROM brushes", count));
    sqlite3_step(count.get());
    uint32_t id = uint32_t(sqlite3_column_int64(count.get(), 0));
    TESSERA_TRY(prepare("INSERT INTO brushes VALUES(?, ?, ?, ?, ?, ?)", insert));
    sqlite3_bind_int64(insert.get(), 1, id);
    sqlite3_bind_text(insert.get(), 2, brush.name.c_str(), -1, SQLITE_TRANSIENT);
    sqlite3_bind_int(insert.get(), 3, int(brush.blend));
    sqlite3_bind_int(insert.get(), 4, int(brush.mask));
    sqlite3_bind_int(insert.get(), 5, brush.mask_low);
    sqlite3_bind_int(insert.get(), 6, brush.mask_high);
    if (sqlite3_step(insert.get()) != SQLITE_DONE) return error("add brush");
    TESSERA_TRY(prepare("INSERT INTO brush_images VALUES(?, ?, ?, ?, ?)", image));
    for (size_t v = 0; v < brush.images.size(); ++v) {
      const Image& picture = brush.images[v];
      sqlite3_reset(image.get());
      sqlite3_bind_int64(image.get(), 1, id);
      sqlite3_bind_int64(image.get(), 2, int64_t(v));
      sqlite3_bind_int64(image.get(), 3, picture.width_px);
      sqlite3_bind_int64(image.get(), 4, picture.height_px);
      sqlite3_bind_blob64(image.get(), 5, picture.texels.data(), picture.texels.size(),
                          SQLITE_STATIC);
      if (sqlite3_step(image.get()) != SQLITE_DONE) return error("add brush image");
    }
    return id;
  }

  Result<std::vector<Brush>> brushes() override {
    Statement list, images;
    TESSERA_TRY(prepare(
        "SELECT id, name, blend, mask, mask_low, mask_high FROM brushes ORDER BY id", list));
    std::vector<Brush> result;
    while (sqlite3_step(list.get()) == SQLITE_ROW) {
      Brush brush;
      brush.name = reinterpret_cast<const char*>(sqlite3_column_text(list.get(), 1));
      TESSERA_TRY(decodeBrushFields(
          sqlite3_column_int(list.get(), 2), sqlite3_column_int(list.get(), 3),
          sqlite3_column_int(list.get(), 4), sqlite3_column_int(list.get(), 5), name_, brush));
      result.push_back(std::move(brush));
    }
    TESSERA_TRY(
        prepare("SELECT brush_id, width, height, rgba FROM brush_images ORDER BY brush_id, "
                "variant",
                images));
    while (sqlite3_step(images.get()) == SQLITE_ROW) {
      uint64_t id = uint64_t(sqlite3_column_int64(images.get(), 0));
      if (id >= result.size())
        return fail(ErrorCode::kCorrupt, fmt::format("{}: image of unknown brush {}", name_, id));
      const void* blob = sqlite3_column_blob(images.get(), 3);
      size_t bytes = size_t(sqlite3_column_bytes(images.get(), 3));
      TESSERA_ASSIGN_OR_RETURN(Image image,
                               decodeBrushImage(uint32_t(sqlite3_column_int64(images.get(), 1)),
                                                uint32_t(sqlite3_column_int64(images.get(), 2)),
                                                static_cast<const uint8_t*>(blob), bytes,
                                                name_ + ": brush " + result[id].name));
      result[id].images.push_back(std::move(image));
    }
    for (const Brush& brush : result)
      TESSERA_TRY(validateBrush(brush, name_ + ": brush " + brush.name));
    return result;
  }

  Result<std::vector<uint64_t>> addInstances(std::span<const BrushInstance> instances) override {
    TESSERA_ASSIGN_OR_RETURN(uint64_t brush_count, countBrushes());
    TESSERA_TRY(checkInstances(instances, brush_count, name_));
    TESSERA_TRY(exec("BEGIN IMMEDIATE"));
    Result<std::vector<uint64_t>> ids = insertInstances(instances);
    if (!ids) {
      (void)exec("ROLLBACK");
      return ids;
    }
    TESSERA_TRY(exec("COMMIT"));
    return ids;
  }

  Result<uint64_t> countBrushes() {
    Statement count;
    TESSERA_TRY(prepare("SELECT COUNT(*) FROM brushes", count));
    sqlite3_step(count.get());
    return uint64_t(sqlite3_column_int64(count.get(), 0));
  }

  Result<std::vector<uint64_t>> insertInstances(std::span<const BrushInstance> instances) {
    Statement max_id, insert, bounds;
    TESSERA_TRY(prepare("SELECT COALESCE(MAX(id), 0) FROM instances", max_id));
    sqlite3_step(max_id.get());
    uint64_t next = uint64_t(sqlite3_column_int64(max_id.get(), 0)) + 1;
    TESSERA_TRY(prepare("INSERT INTO instances VALUES(?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)", insert));
    TESSERA_TRY(prepare("INSERT INTO instance_bounds VALUES(?, ?, ?, ?, ?)", bounds));
    std::vector<uint64_t> ids;
    ids.reserve(instances.size());
    for (const BrushInstance& instance : instances) {
      sqlite3_stmt* s = insert.get();
      sqlite3_reset(s);
      sqlite3_bind_int64(s, 1, int64_t(next));
      sqlite3_bind_int64(s, 2, instance.brush);
      sqlite3_bind_double(s, 3, instance.x_px);
      sqlite3_bind_double(s, 4, instance.y_px);
      sqlite3_bind_double(s, 5, instance.radius_px);
      sqlite3_bind_double(s, 6, instance.rotation_rad);
      sqlite3_bind_double(s, 7, instance.scale);
      sqlite3_bind_int(s, 8, instance.opacity);
      sqlite3_bind_int64(s, 9, instance.tint_rgba);
      sqlite3_bind_int64(s, 10, instance.layer);
      sqlite3_bind_int(s, 11, instance.variant);
      if (sqlite3_step(s) != SQLITE_DONE) return error("add instance");
      const BoxPx box = instanceBounds(instance);
      sqlite3_stmt* b = bounds.get();
      sqlite3_reset(b);
      sqlite3_bind_int64(b, 1, int64_t(next));
      sqlite3_bind_double(b, 2, box.x0);
      sqlite3_bind_double(b, 3, box.x1);
      sqlite3_bind_double(b, 4, box.y0);
      sqlite3_bind_double(b, 5, box.y1);
      if (sqlite3_step(b) != SQLITE_DONE) return error("add instance bounds");
      ids.push_back(next++);
    }
    return ids;
  }

  Result<void> query(const BoxPx& box, std::vector<BrushInstance>& out) override {
    if (!query_.get()) {
      TESSERA_TRY(
          prepare("SELECT i.id, brush_id, x, y, radius, rotation, scale, opacity, tint, "
                  "layer, variant FROM instance_bounds b JOIN instances i ON i.id = b.id "
                  "WHERE b.min_x <= ?1 AND b.max_x >= ?2 AND b.min_y <= ?3 AND "
                  "b.max_y >= ?4",
                  query_));
    }
    sqlite3_stmt* s = query_.get();
    sqlite3_reset(s);
    sqlite3_bind_double(s, 1, box.x1);
    sqlite3_bind_double(s, 2, box.x0);
    sqlite3_bind_double(s, 3, box.y1);
    sqlite3_bind_double(s, 4, box.y0);
    const size_t first = out.size();
    int rc;
    while ((rc = sqlite3_step(s)) == SQLITE_ROW) {
      BrushInstance instance = readInstance(s);
      // The R*Tree keeps 32-bit boxes rounded outwards: the exact test in double follows.
      if (instanceBounds(instance).intersects(box)) out.push_back(instance);
    }
    if (rc != SQLITE_DONE) return error("query");
    std::sort(out.begin() + std::ptrdiff_t(first), out.end(), drawsBefore);
    return {};
  }

  Result<uint64_t> deleteInstances(std::span<const uint64_t> ids) override {
    TESSERA_TRY(exec("BEGIN IMMEDIATE"));
    Statement remove, remove_bounds;
    Result<void> prepared = prepare("DELETE FROM instances WHERE id = ?", remove);
    if (prepared) prepared = prepare("DELETE FROM instance_bounds WHERE id = ?", remove_bounds);
    if (!prepared) {
      (void)exec("ROLLBACK");
      return forwardError(prepared);
    }
    uint64_t deleted = 0;
    for (uint64_t id : ids) {
      sqlite3_reset(remove.get());
      sqlite3_bind_int64(remove.get(), 1, int64_t(id));
      if (sqlite3_step(remove.get()) != SQLITE_DONE) {
        Unexpected failure = error("delete");
        (void)exec("ROLLBACK");
        return failure;
      }
      deleted += uint64_t(sqlite3_changes(db_));
      sqlite3_reset(remove_bounds.get());
      sqlite3_bind_int64(remove_bounds.get(), 1, int64_t(id));
      if (sqlite3_step(remove_bounds.get()) != SQLITE_DONE) {
        Unexpected failure = error("delete");
        (void)exec("ROLLBACK");
        return failure;
      }
    }
    TESSERA_TRY(exec("COMMIT"));
    return deleted;
  }

  Result<uint64_t> deleteInstancesIn(const BoxPx& box) override {
    std::vector<BrushInstance> found;
    TESSERA_TRY(query(box, found));
    std::vector<uint64_t> ids;
    for (const BrushInstance& instance : found) ids.push_back(instance.id);
    return deleteInstances(ids);
  }

  Result<uint64_t> instanceCount() override {
    Statement count;
    TESSERA_TRY(prepare("SELECT COUNT(*) FROM instances", count));
    sqlite3_step(count.get());
    return uint64_t(sqlite3_column_int64(count.get(), 0));
  }

  Result<void> forEachInstance(const std::function<bool(const BrushInstance&)>& visit) override {
    Statement all;
    TESSERA_TRY(prepare(
        fmt::format("SELECT {} FROM instances ORDER BY id", kInstanceColumns).c_str(), all));
    int rc;
    while ((rc = sqlite3_step(all.get())) == SQLITE_ROW)
      if (!visit(readInstance(all.get()))) return {};
    if (rc != SQLITE_DONE) return error("list");
    return {};
  }

 private:
  sqlite3* db_;
  std::string name_;
  Statement query_;  ///< the tile query, prepared once
};

}  // namespace

Result<std::unique_ptr<BrushDatabase>> openSqliteBrushDatabase(const std::string& path,
                                                               bool create) {
  sqlite3* db = nullptr;
  // One connection per thread (BrushDatabase is owned by one thread): no mutex per call.
  int flags = SQLITE_OPEN_READWRITE | SQLITE_OPEN_NOMUTEX | (create ? SQLITE_OPEN_CREATE : 0);
  if (sqlite3_open_v2(path.c_str(), &db, flags, nullptr) != SQLITE_OK) {
    std::string message = db ? sqlite3_errmsg(db) : "out of memory";
    sqlite3_close_v2(db);
    return fail(create ? ErrorCode::kIo : ErrorCode::kNotFound,
                fmt::format("{}: cannot open: {}", path, message));
  }
  if (!sqlite3_compileoption_used("ENABLE_RTREE")) {
    sqlite3_close_v2(db);
    return fail(ErrorCode::kUnsupported, path + ": this SQLite lacks the R*Tree module");
  }
  sqlite3_busy_timeout(db, 10000);
  auto database = std::make_unique<SqliteBrushDatabase>(db, path);
  TESSERA_TRY(database->initialise(create));
  return std::unique_ptr<BrushDatabase>(std::move(database));
}

}  // namespace tessera
