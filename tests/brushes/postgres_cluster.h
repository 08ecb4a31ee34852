#pragma once
// A throwaway PostgreSQL cluster for tests: initdb into a temporary folder, pg_ctl start on a
// Unix socket in that folder (no TCP), one database per test, pg_ctl stop and removal at the
// end. As root (CI), the server runs as the `postgres` user through runuser.

#include <memory>
#include <string>

namespace tessera::testing {

class PostgresCluster {
 public:
  /// Starts a cluster, or returns null and says why (binaries missing, PostGIS missing).
  static std::unique_ptr<PostgresCluster> start(std::string* why_not);
  ~PostgresCluster();
  PostgresCluster(const PostgresCluster&) = delete;
  PostgresCluster& operator=(const PostgresCluster&) = delete;

  /// Creates a fresh database and returns its libpq connection string.
  std::string createDatabase(const std::string& name);

 private:
  PostgresCluster() = default;
  bool run(const std::string& command) const;
  std::string dir_;
  std::string bin_;
  std::string as_user_;  ///< "runuser -u postgres -- " as root, "" otherwise
};

}  // namespace tessera::testing
