#pragma once
// Runs the real `tessera` binary (TESSERA_CLI_PATH, a compile definition of the test target)
// or another program as a child process, capturing its exit code, stdout and stderr.

#include <string>
#include <vector>

namespace tessera::test {

struct RunResult {
  int exit_code = -1;
  std::string out;
  std::string err;
};

/// The whole file as a string ("" when it cannot be read).
std::string slurp(const std::string& path);

/// Runs `program` with `args` (and `env`, or this process's environment when null), capturing
/// stdout and stderr through files next to `dir`; a failure to start or a death by signal
/// fails the test.
RunResult runProgram(const std::string& program, const std::vector<std::string>& args,
                     const std::string& dir, const std::vector<std::string>* env = nullptr);

inline RunResult runTessera(const std::vector<std::string>& args, const std::string& dir,
                            const std::vector<std::string>* env = nullptr) {
  return runProgram(TESSERA_CLI_PATH, args, dir, env);
}

}  // namespace tessera::test
