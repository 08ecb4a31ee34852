#include "view_screenshot.h"

#include <filesystem>

#include <fmt/format.h>

namespace tessera::cli {

std::string nextScreenshotPath(const std::string& dir) {
  for (uint32_t n = 1;; ++n) {
    std::string path =
        (std::filesystem::path(dir) / fmt::format("tessera-screenshot-{}.png", n)).string();
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) return path;
  }
}

}  // namespace tessera::cli
