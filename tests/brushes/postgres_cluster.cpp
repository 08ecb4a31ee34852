#include "brushes/postgres_cluster.h"

#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fmt/format.h>

namespace tessera::testing {

namespace {

// The folder holding initdb and pg_ctl: PATH first, then Debian's versioned folders.
std::string findPostgresBin() {
  if (std::system("command -v initdb >/dev/null 2>&1 && command -v pg_ctl >/dev/null 2>&1") == 0)
    return "";
  std::error_code ec;
  for (int version = 20; version >= 11; --version) {
    std::string dir = fmt::format("/usr/lib/postgresql/{}/bin/", version);
    if (std::filesystem::exists(dir + "initdb", ec) && std::filesystem::exists(dir + "pg_ctl", ec))
      return dir;
  }
  return "-";
}

}  // namespace

bool PostgresCluster::run(const std::string& command) const {
  std::string line = fmt::format("{}{} >>{}/commands.log 2>&1", as_user_, command, dir_);
  return std::system(line.c_str()) == 0;
}

std::unique_ptr<PostgresCluster> PostgresCluster::start(std::string* why_not) {
  std::string bin = findPostgresBin();
  if (bin == "-") {
    *why_not = "initdb/pg_ctl not found (Debian package postgresql)";
    return nullptr;
  }
  if (std::system("command -v psql >/dev/null 2>&1") != 0) {
    *why_not = "psql not found (Debian package postgresql-client)";
    return nullptr;
  }
  std::unique_ptr<PostgresCluster> cluster(new PostgresCluster());
  cluster->bin_ = bin;
  char pattern[] = "/tmp/tessera-pg-XXXXXX";
  if (!mkdtemp(pattern)) {
    *why_not = "mkdtemp failed";
    return nullptr;
  }
  cluster->dir_ = pattern;
  if (geteuid() == 0) {
    // initdb refuses to run as root: the cluster belongs to the postgres user.
    if (std::system("id postgres >/dev/null 2>&1") != 0) {
      *why_not = "running as root and there is no postgres user to own the cluster";
      return nullptr;
    }
    cluster->as_user_ = "runuser -u postgres -- ";
    std::system(fmt::format("chown postgres {}", cluster->dir_).c_str());
  }
  const std::string& dir = cluster->dir_;
  if (!cluster->run(fmt::format("{}initdb -D {}/data -U tessera -A trust --no-sync -E UTF8 "
                                "--locale=C",
                                bin, dir))) {
    *why_not = "initdb failed; see " + dir + "/commands.log";
    return nullptr;
  }
  if (!cluster->run(fmt::format("{0}pg_ctl -D {1}/data -l {1}/server.log -w -t 60 -o \"-k {1} -c "
                                "listen_addresses='' -c fsync=off -c full_page_writes=off\" start",
                                bin, dir))) {
    *why_not = "pg_ctl start failed; see " + dir + "/server.log";
    return nullptr;
  }
  if (!cluster->run(fmt::format("psql -h {} -U tessera -d postgres -v ON_ERROR_STOP=1 -c \"CREATE "
                                "DATABASE probe\" -c \"\\c probe\" -c \"CREATE EXTENSION postgis\"",
                                dir))) {
    *why_not = "the PostGIS extension is not installed (Debian package postgresql-15-postgis-3)";
    return nullptr;  // the destructor stops the server
  }
  return cluster;
}

std::string PostgresCluster::createDatabase(const std::string& name) {
  run(
      fmt::format("psql -h {} -U tessera -d postgres -c \"DROP DATABASE IF EXISTS {}\" -c \"CREATE "
                  "DATABASE {}\"",
                  dir_, name, name));
  return fmt::format("host={} dbname={} user=tessera", dir_, name);
}

PostgresCluster::~PostgresCluster() {
  if (dir_.empty()) return;
  run(fmt::format("{}pg_ctl -D {}/data -m immediate -w stop", bin_, dir_));
  std::error_code ec;
  std::filesystem::remove_all(dir_, ec);
}

}  // namespace tessera::testing
