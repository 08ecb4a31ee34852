// The PostgreSQL + PostGIS backend of BrushDatabase, for teams that edit one world together:
// instances with their bounds as a geometry under a GiST index (docs/procedural.md, "The brush
// database"). The same rules as the SQLite backend: brush ids dense from 0, instance ids from 1
// in insertion order, exact bounds test after the index, drawing order.
#include <tessera/brushes.h>

#include <algorithm>
#include <cstdlib>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <libpq-fe.h>

#include "brush_codec.h"

namespace tessera {

namespace {

constexpr const char* kSchema = R"sql(
CREATE EXTENSION IF NOT EXISTS postgis;
CREATE TABLE IF NOT EXISTS tessera_meta(key text PRIMARY KEY, value text NOT NULL);
CREATE TABLE IF NOT EXISTS brushes(
  id integer PRIMARY KEY, name text NOT NULL UNIQUE, blend smallint NOT NULL,
  mask smallint NOT NULL, mask_low smallint NOT NULL, mask_high smallint NOT NULL);
CREATE TABLE IF NOT EXISTS brush_images(
  brush_id integer NOT NULL REFERENCES brushes(id), variant integer NOT NULL,
  width integer NOT NULL, height integer NOT NULL, rgba bytea NOT NULL,
  PRIMARY KEY(brush_id, variant));
CREATE TABLE IF NOT EXISTS instances(
  id bigint PRIMARY KEY, brush_id integer NOT NULL REFERENCES brushes(id),
  x double precision NOT NULL, y double precision NOT NULL, radius real NOT NULL,
  rotation real NOT NULL, scale real NOT NULL, opacity smallint NOT NULL, tint bigint NOT NULL,
  layer integer NOT NULL, variant smallint NOT NULL, bounds geometry(Polygon) NOT NULL);
CREATE INDEX IF NOT EXISTS instances_bounds ON instances USING gist(bounds);
INSERT INTO tessera_meta VALUES('schema_version', '1') ON CONFLICT DO NOTHING;
)sql";

constexpr const char* kInstanceColumns =
    "id, brush_id, x, y, radius, rotation, scale, opacity, tint, layer, variant";

class PgResult {
 public:
  explicit PgResult(PGresult* result) : result_(result) {}
  PgResult(const PgResult&) = delete;
  PgResult& operator=(const PgResult&) = delete;
  ~PgResult() { PQclear(result_); }
  PGresult* get() const { return result_; }
  int rows() const { return PQntuples(result_); }
  const char* at(int row, int column) const { return PQgetvalue(result_, row, column); }

 private:
  PGresult* result_;
};

BrushInstance readInstance(const PgResult& result, int row) {
  BrushInstance instance;
  instance.id = std::strtoull(result.at(row, 0), nullptr, 10);
  instance.brush = uint32_t(std::strtoul(result.at(row, 1), nullptr, 10));
  instance.x_px = std::strtod(result.at(row, 2), nullptr);
  instance.y_px = std::strtod(result.at(row, 3), nullptr);
  instance.radius_px = std::strtof(result.at(row, 4), nullptr);
  instance.rotation_rad = std::strtof(result.at(row, 5), nullptr);
  instance.scale = std::strtof(result.at(row, 6), nullptr);
  instance.opacity = uint8_t(std::atoi(result.at(row, 7)));
  instance.tint_rgba = uint32_t(std::strtoull(result.at(row, 8), nullptr, 10));
  instance.layer = int32_t(std::strtol(result.at(row, 9), nullptr, 10));
  instance.variant = uint8_t(std::atoi(result.at(row, 10)));
  return instance;
}

class PostgisBrushDatabase final : public BrushDatabase {
 public:
  PostgisBrushDatabase(PGconn* connection, std::string name)
      : connection_(connection), name_(std::move(name)) {}
  ~PostgisBrushDatabase() override { PQfinish(connection_); }

  const std::string& name() const override { return name_; }
  const char* backend() const override { return "postgis"; }

  Unexpected error(const std::string& what) {
    std::string message = PQerrorMessage(connection_);
    while (!message.empty() && (message.back() == '\n' || message.back() == ' '))
      message.pop_back();
    return fail(ErrorCode::kIo, fmt::format("{}: {}: {}", name_, what, message));
  }

  // Runs `sql` with text parameters; fails unless the server answers with rows or success.
  Result<std::unique_ptr<PgResult>> run(const std::string& sql,
                                        const std::vector<std::string>& params = {}) {
    std::vector<const char*> values;
    for (const std::string& p : params) values.push_back(p.c_str());
    auto result = std::make_unique<PgResult>(
        params.empty() ? PQexec(connection_, sql.c_str())
                       : PQexecParams(connection_, sql.c_str(), int(values.size()), nullptr,
                                      values.data(), nullptr, nullptr, 0));
    ExecStatusType status = PQresultStatus(result->get());
    if (status != PGRES_COMMAND_OK && status != PGRES_TUPLES_OK)
      return error(sql.substr(0, sql.find_first_of("(\n")));
    return result;
  }

  // Runs `body` inside BEGIN/COMMIT; any error rolls back.
  template <typename T, typename F>
  Result<T> transaction(F body) {
    TESSERA_TRY(run("BEGIN"));
    Result<T> result = body();
    if (!result) {
      (void)run("ROLLBACK");
      return result;
    }
    TESSERA_TRY(run("COMMIT"));
    return result;
  }

  Result<void> initialise(bool create) {
    TESSERA_TRY(run("SET client_min_messages = warning"));
    TESSERA_ASSIGN_OR_RETURN(auto exists, run("SELECT to_regclass('tessera_meta') IS NOT NULL"));
    if (std::string(exists->at(0, 0)) != "t") {
      if (!create) return fail(ErrorCode::kNotFound, name_ + ": not a Tessera brush database");
      Result<bool> created = transaction<bool>([&]() -> Result<bool> {
        TESSERA_TRY(run(kSchema));
        return true;
      });
      if (!created) return forwardError(created);
    }
    TESSERA_ASSIGN_OR_RETURN(auto version,
                             run("SELECT value FROM tessera_meta WHERE key = 'schema_version'"));
    int found = version->rows() ? std::atoi(version->at(0, 0)) : 0;
    if (found != kBrushSchemaVersion)
      return fail(ErrorCode::kUnsupported,
                  fmt::format("{}: brush database schema version {} (this build reads {})", name_,
                              found, kBrushSchemaVersion));
    return {};
  }

  Result<void> setTextureExtent(const TextureExtent& extent) override {
    TESSERA_TRY(
        run("INSERT INTO tessera_meta VALUES('texture_width', $1), ('texture_height', $2) "
            "ON CONFLICT(key) DO UPDATE SET value = EXCLUDED.value",
            {std::to_string(extent.width_px), std::to_string(extent.height_px)}));
    return {};
  }

  Result<TextureExtent> textureExtent() override {
    TESSERA_ASSIGN_OR_RETURN(auto rows, run("SELECT key, value FROM tessera_meta WHERE key IN "
                                            "('texture_width', 'texture_height')"));
    TextureExtent extent;
    for (int r = 0; r < rows->rows(); ++r) {
      uint32_t value = uint32_t(std::strtoul(rows->at(r, 1), nullptr, 10));
      (std::string(rows->at(r, 0)) == "texture_width" ? extent.width_px : extent.height_px) = value;
    }
    return extent;
  }

  Result<uint32_t> addBrush(const Brush& brush) override {
    TESSERA_TRY(validateBrush(brush, name_ + ": brush " + brush.name));
    return transaction<uint32_t>([&]() -> Result<uint32_t> {
      TESSERA_TRY(run("LOCK TABLE brushes IN EXCLUSIVE MODE"));
      TESSERA_ASSIGN_OR_RETURN(auto same,
                               run("SELECT 1 FROM brushes WHERE name = $1", {brush.name}));
      if (same->rows())
        return fail(ErrorCode::kInvalidArgument,
                    fmt::format("{}: a brush named '{}' exists", name_, brush.name));
      TESSERA_ASSIGN_OR_RETURN(auto count, run("SELECT COUNT(*) FROM brushes"));
      uint32_t id = uint32_t(std::strtoul(count->at(0, 0), nullptr, 10));
      TESSERA_TRY(run("INSERT INTO brushes VALUES($1, $2, $3, $4, $5, $6)",
                      {std::to_string(id), brush.name, std::to_string(int(brush.blend)),
                       std::to_string(int(brush.mask)), std::to_string(brush.mask_low),
                       std::to_string(brush.mask_high)}));
      for (size_t v = 0; v < brush.images.size(); ++v) {
        const Image& image = brush.images[v];
        const char* values[5];
        std::string id_text = std::to_string(id), variant = std::to_string(v),
                    width = std::to_string(image.width_px),
                    height = std::to_string(image.height_px);
        values[0] = id_text.c_str();
        values[1] = variant.c_str();
        values[2] = width.c_str();
        values[3] = height.c_str();
        values[4] = reinterpret_cast<const char*>(image.texels.data());
        const int lengths[5] = {0, 0, 0, 0, int(image.texels.size())};
        const int formats[5] = {0, 0, 0, 0, 1};  // the blob as binary
        PgResult result(PQexecParams(connection_,
                                     "INSERT INTO brush_images VALUES($1, $2, $3, $4, $5)", 5,
                                     nullptr, values, lengths, formats, 0));
        if (PQresultStatus(result.get()) != PGRES_COMMAND_OK) return error("add brush image");
      }
      return id;
    });
  }

  Result<std::vector<Brush>> brushes() override {
    TESSERA_ASSIGN_OR_RETURN(
        auto rows,
        run("SELECT id, name, blend, mask, mask_low, mask_high FROM brushes ORDER BY id"));
    std::vector<Brush> result(size_t(rows->rows()));
    for (int r = 0; r < rows->rows(); ++r) {
      Brush& brush = result[size_t(r)];
      brush.name = rows->at(r, 1);
      TESSERA_TRY(decodeBrushFields(std::atoi(rows->at(r, 2)), std::atoi(rows->at(r, 3)),
                                    std::atoi(rows->at(r, 4)), std::atoi(rows->at(r, 5)), name_,
                                    brush));
    }
    // Binary results, so the RGBA bytes come back as they went in.
    PgResult images(PQexecParams(connection_,
                                 "SELECT brush_id, width, height, rgba FROM brush_images ORDER BY "
                                 "brush_id, variant",
                                 0, nullptr, nullptr, nullptr, nullptr, 1));
    if (PQresultStatus(images.get()) != PGRES_TUPLES_OK) return error("brush images");
    auto be32 = [&](int row, int column) {
      const uint8_t* p = reinterpret_cast<const uint8_t*>(images.at(row, column));
      return uint32_t(p[0]) << 24 | uint32_t(p[1]) << 16 | uint32_t(p[2]) << 8 | p[3];
    };
    for (int r = 0; r < images.rows(); ++r) {
      uint32_t id = be32(r, 0);
      if (id >= result.size())
        return fail(ErrorCode::kCorrupt, fmt::format("{}: image of unknown brush {}", name_, id));
      TESSERA_ASSIGN_OR_RETURN(Image image,
                               decodeBrushImage(be32(r, 1), be32(r, 2),
                                                reinterpret_cast<const uint8_t*>(images.at(r, 3)),
                                                size_t(PQgetlength(images.get(), r, 3)),
                                                name_ + ": brush " + result[id].name));
      result[id].images.push_back(std::move(image));
    }
    for (const Brush& brush : result)
      TESSERA_TRY(validateBrush(brush, name_ + ": brush " + brush.name));
    return result;
  }

  Result<std::vector<uint64_t>> addInstances(std::span<const BrushInstance> instances) override {
    TESSERA_ASSIGN_OR_RETURN(auto count, run("SELECT COUNT(*) FROM brushes"));
    TESSERA_TRY(checkInstances(instances, std::strtoull(count->at(0, 0), nullptr, 10), name_));
    return transaction<std::vector<uint64_t>>([&]() { return copyInstances(instances); });
  }

  // COPY with ids taken after the table's largest under an exclusive lock, so concurrent
  // writers serialise and ids follow insertion order as in the SQLite backend.
  Result<std::vector<uint64_t>> copyInstances(std::span<const BrushInstance> instances) {
    TESSERA_TRY(run("LOCK TABLE instances IN EXCLUSIVE MODE"));
    TESSERA_ASSIGN_OR_RETURN(auto max_id, run("SELECT COALESCE(MAX(id), 0) FROM instances"));
    uint64_t next = std::strtoull(max_id->at(0, 0), nullptr, 10) + 1;
    {
      PgResult copy(
          PQexec(connection_,
                 fmt::format("COPY instances({}, bounds) FROM STDIN", kInstanceColumns).c_str()));
      if (PQresultStatus(copy.get()) != PGRES_COPY_IN) return error("copy");
    }
    std::vector<uint64_t> ids;
    ids.reserve(instances.size());
    std::string buffer;
    for (size_t i = 0; i < instances.size(); ++i) {
      const BrushInstance& s = instances[i];
      const BoxPx b = instanceBounds(s);
      fmt::format_to(
          std::back_inserter(buffer),
          "{}\t{}\t{}\t{}\t{}\t{}\t{}\t{}\t{}\t{}\t{}\tPOLYGON(({} {},{} {},{} {},{} {},{} "
          "{}))\n",
          next, s.brush, s.x_px, s.y_px, s.radius_px, s.rotation_rad, s.scale, int(s.opacity),
          s.tint_rgba, s.layer, int(s.variant), b.x0, b.y0, b.x1, b.y0, b.x1, b.y1, b.x0, b.y1,
          b.x0, b.y0);
      ids.push_back(next++);
      if (buffer.size() > (1u << 20) || i + 1 == instances.size()) {
        if (PQputCopyData(connection_, buffer.data(), int(buffer.size())) != 1)
          return error("copy data");
        buffer.clear();
      }
    }
    if (PQputCopyEnd(connection_, nullptr) != 1) return error("copy end");
    PgResult done(PQgetResult(connection_));
    if (PQresultStatus(done.get()) != PGRES_COMMAND_OK) {
      Unexpected failure = error("copy");
      while (PGresult* rest = PQgetResult(connection_)) PQclear(rest);
      return failure;
    }
    while (PGresult* rest = PQgetResult(connection_)) PQclear(rest);
    return ids;
  }

  Result<void> query(const BoxPx& box, std::vector<BrushInstance>& out) override {
    if (!query_prepared_) {
      PgResult prepared(PQprepare(
          connection_, "tessera_query",
          fmt::format("SELECT {} FROM instances WHERE bounds && ST_MakeEnvelope($1, $2, $3, $4)",
                      kInstanceColumns)
              .c_str(),
          4, nullptr));
      if (PQresultStatus(prepared.get()) != PGRES_COMMAND_OK) return error("prepare query");
      query_prepared_ = true;
    }
    std::string values[4] = {fmt::format("{}", box.x0), fmt::format("{}", box.y0),
                             fmt::format("{}", box.x1), fmt::format("{}", box.y1)};
    const char* params[4] = {values[0].c_str(), values[1].c_str(), values[2].c_str(),
                             values[3].c_str()};
    PgResult rows(PQexecPrepared(connection_, "tessera_query", 4, params, nullptr, nullptr, 0));
    if (PQresultStatus(rows.get()) != PGRES_TUPLES_OK) return error("query");
    const size_t first = out.size();
    for (int r = 0; r < rows.rows(); ++r) {
      BrushInstance instance = readInstance(rows, r);
      // The index compares 32-bit boxes: the exact test in double follows, as in SQLite.
      if (instanceBounds(instance).intersects(box)) out.push_back(instance);
    }
    std::sort(out.begin() + std::ptrdiff_t(first), out.end(), drawsBefore);
    return {};
  }

  Result<uint64_t> deleteInstances(std::span<const uint64_t> ids) override {
    std::string array = fmt::format("{{{}}}", fmt::join(ids, ","));
    TESSERA_ASSIGN_OR_RETURN(auto result,
                             run("DELETE FROM instances WHERE id = ANY($1::bigint[])", {array}));
    return std::strtoull(PQcmdTuples(result->get()), nullptr, 10);
  }

  Result<uint64_t> deleteInstancesIn(const BoxPx& box) override {
    std::vector<BrushInstance> found;
    TESSERA_TRY(query(box, found));
    std::vector<uint64_t> ids;
    for (const BrushInstance& instance : found) ids.push_back(instance.id);
    return deleteInstances(ids);
  }

  Result<uint64_t> instanceCount() override {
    TESSERA_ASSIGN_OR_RETURN(auto count, run("SELECT COUNT(*) FROM instances"));
    return std::strtoull(count->at(0, 0), nullptr, 10);
  }

  Result<void> forEachInstance(const std::function<bool(const BrushInstance&)>& visit) override {
    Result<bool> listed = transaction<bool>([&]() -> Result<bool> {
      TESSERA_TRY(
          run(fmt::format("DECLARE tessera_all NO SCROLL CURSOR FOR SELECT {} FROM "
                          "instances ORDER BY id",
                          kInstanceColumns)));
      while (true) {
        TESSERA_ASSIGN_OR_RETURN(auto rows, run("FETCH 10000 FROM tessera_all"));
        if (rows->rows() == 0) break;
        for (int r = 0; r < rows->rows(); ++r)
          if (!visit(readInstance(*rows, r))) return true;
      }
      return true;
    });
    if (!listed) return forwardError(listed);
    return {};
  }

 private:
  PGconn* connection_;
  std::string name_;
  bool query_prepared_ = false;
};

}  // namespace

Result<std::unique_ptr<BrushDatabase>> openPostgisBrushDatabase(const std::string& connection,
                                                                bool create) {
  PGconn* conn = PQconnectdb(connection.c_str());
  if (!conn) return fail(ErrorCode::kInternal, connection + ": libpq could not allocate");
  if (PQstatus(conn) != CONNECTION_OK) {
    std::string message = PQerrorMessage(conn);
    PQfinish(conn);
    while (!message.empty() && message.back() == '\n') message.pop_back();
    return fail(ErrorCode::kIo, fmt::format("{}: cannot connect: {}", connection, message));
  }
  auto database = std::make_unique<PostgisBrushDatabase>(conn, connection);
  TESSERA_TRY(database->initialise(create));
  return std::unique_ptr<BrushDatabase>(std::move(database));
}

Result<std::unique_ptr<BrushDatabase>> openBrushDatabase(const std::string& location, bool create) {
  bool postgres =
      location.rfind("postgresql://", 0) == 0 || location.rfind("postgres://", 0) == 0 ||
      location.find("dbname=") != std::string::npos || location.find("host=") != std::string::npos;
  return postgres ? openPostgisBrushDatabase(location, create)
                  : openSqliteBrushDatabase(location, create);
}

}  // namespace tessera
