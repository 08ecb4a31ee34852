// Writes the seed corpora of the format fuzzers (header, root_directory, directory_page,
// page_index, metadata, archive) from small archives built here: each parser's input cut out
// of a real file, in the layout of format_fuzz_input.h. Usage:
//   tessera_format_corpus fuzz/corpus
// The builder is deterministic, so regenerating changes files only when the format does.
#include <tessera/build.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "format/directory.h"
#include "format/header.h"
#include "format_fuzz_input.h"

namespace {

using namespace tessera;
namespace fs = std::filesystem;

bool writeFile(const fs::path& path, const std::vector<uint8_t>& bytes) {
  fs::create_directories(path.parent_path());
  std::ofstream file(path, std::ios::binary);
  file.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
  if (!file) std::fprintf(stderr, "%s: cannot write\n", path.c_str());
  return bool(file);
}

std::vector<uint8_t> slice(const std::vector<uint8_t>& file, const detail::BlockRef& block) {
  return {file.begin() + std::ptrdiff_t(block.offset_bytes),
          file.begin() + std::ptrdiff_t(block.offset_bytes + block.length_bytes)};
}

std::vector<uint8_t> withPrefix(std::vector<uint8_t> prefix, const std::vector<uint8_t>& bytes) {
  prefix.insert(prefix.end(), bytes.begin(), bytes.end());
  return prefix;
}

// Cuts every parser's input out of one archive file.
bool writeSeeds(const fs::path& out, const std::string& name, const std::vector<uint8_t>& file) {
  bool ok = writeFile(out / "archive" / name, file);
  ok &= writeFile(out / "header" / name, {file.begin(), file.begin() + detail::kHeaderBytes});
  Result<detail::FileHeader> header = detail::decodeHeader(file, name);
  if (!header) return false;
  std::vector<uint8_t> file_size;
  fuzz::appendLe(file_size, header->file_bytes, 8);
  std::vector<uint8_t> root_prefix{uint8_t(header->image_count - 1)};
  root_prefix.insert(root_prefix.end(), file_size.begin(), file_size.end());
  const std::vector<uint8_t> root = slice(file, header->root);
  ok &= writeFile(out / "root_directory" / name, withPrefix(root_prefix, root));
  if (header->metadata.length_bytes > 0)
    ok &= writeFile(out / "metadata" / name,
                    withPrefix({uint8_t(header->image_count)}, slice(file, header->metadata)));
  Result<std::vector<detail::ImageRecord>> records =
      detail::decodeRootDirectory(root, *header, name);
  if (!records) return false;
  for (size_t image = 0; image < records->size(); ++image) {
    const detail::ImageRecord& record = (*records)[image];
    for (uint32_t level = 0; level < record.levels.size(); ++level) {
      const detail::BlockRef& index = record.levels[level].page_index;
      if (index.length_bytes == 0) continue;
      const std::string seed = name + "_i" + std::to_string(image) + "_l" + std::to_string(level);
      std::vector<uint8_t> prefix = fuzz::geometryBytes(record.info, level, 0, 0);
      prefix.insert(prefix.end(), file_size.begin(), file_size.end());
      ok &= writeFile(out / "page_index" / seed, withPrefix(prefix, slice(file, index)));
      Result<std::vector<detail::PageRef>> pages =
          detail::decodePageIndex(slice(file, index), record.info, level, header->file_bytes, name);
      if (!pages || pages->empty() || (*pages)[0].length_bytes == 0) continue;
      ok &= writeFile(out / "directory_page" / seed, withPrefix(prefix, slice(file, (*pages)[0])));
    }
  }
  return ok;
}

struct SeedArchive {
  const char* name;
  std::vector<std::string> inputs;
  Codec codec;
  uint32_t border_px;
  uint32_t page_tiles_log2;
};

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s CORPUS_DIR (fuzz/corpus)\n", argv[0]);
    return 2;
  }
  const fs::path out = argv[1];
  const fs::path work = fs::temp_directory_path() / "tessera_format_corpus";
  fs::create_directories(work);
  // Small, several levels and pages, every tile kind: a few KiB each.
  const SeedArchive seeds[] = {
      {"zstd", {"synthetic:300x200:3:3"}, Codec::kZstd, 0, 3},
      {"jpeg_border", {"synthetic:200x130:5:4"}, Codec::kJpeg, 2, 3},
      {"png_set", {"synthetic:140x90:1:3", "synthetic:70x300:2:4"}, Codec::kPng, 1, 5},
  };
  bool ok = true;
  for (const SeedArchive& seed : seeds) {
    BuildOptions options;
    options.inputs = seed.inputs;
    options.output = (work / (std::string(seed.name) + ".tess")).string();
    options.codec = seed.codec;
    options.quality = 40;
    options.tile_size_px = 64;
    options.border_px = seed.border_px;
    options.page_tiles_log2 = seed.page_tiles_log2;
    options.threads = 1;
    Result<BuildReport> built = buildArchive(options);
    if (!built) {
      std::fprintf(stderr, "%s\n", built.error().message.c_str());
      return 1;
    }
    std::ifstream file(options.output, std::ios::binary);
    const std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(file)),
                                     std::istreambuf_iterator<char>());
    ok &= writeSeeds(out, seed.name, bytes);
  }
  fs::remove_all(work);
  return ok ? 0 : 1;
}
