// Per-file loading, the other side of the cold-load benchmark: what a viewer of the scene's own
// files does (a glTF viewer reads the scene file, then each model's buffers, then each image,
// decoding every image at full resolution). Here the scene file is the .stg, the models are
// AC3D files parsed by Assimp (as the scene builder does) and the images PNG or JPEG decoded
// to RGBA by libpng or libjpeg-turbo. Each file is one read (local) or one GET (HTTP, one
// keep-alive connection per thread, as a browser keeps a few per host); a texture shared by
// several models is loaded once, as a viewer's cache by URL does.
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <sstream>
#include <string_view>
#include <thread>

#include <assimp/Importer.hpp>
#include <assimp/material.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <curl/curl.h>
#include <fmt/format.h>
#include <png.h>
#include <turbojpeg.h>

#include "scene_coldload.h"

namespace coldload {
namespace {

using tessera::ErrorCode;
using tessera::fail;
using tessera::Result;

// A file by path or http(s) URL: `origin` ("http://host:port", empty for a local file) and
// the path, so that relative references resolve as paths do.
struct Uri {
  std::string origin;
  std::filesystem::path path;
  std::string text() const { return origin + path.generic_string(); }
  Uri sibling(const std::string& relative) const {
    return {origin, (path.parent_path() / relative).lexically_normal()};
  }
};

Uri parseUri(const std::string& text) {
  const size_t scheme = text.find("://");
  if (scheme == std::string::npos) return {"", std::filesystem::path(text)};
  const size_t slash = text.find('/', scheme + 3);
  if (slash == std::string::npos) return {text, "/"};
  return {text.substr(0, slash), text.substr(slash)};
}

size_t appendBody(char* data, size_t size, size_t count, void* out) {
  auto* bytes = static_cast<std::vector<uint8_t>*>(out);
  bytes->insert(bytes->end(), data, data + size * count);
  return size * count;
}

// One thread's way to the files: a keep-alive curl handle for URLs, plain reads for paths.
// Owned by one thread.
class Fetcher {
 public:
  Fetcher() : curl_(curl_easy_init()) {}
  ~Fetcher() { curl_easy_cleanup(curl_); }
  Fetcher(const Fetcher&) = delete;
  Fetcher& operator=(const Fetcher&) = delete;

  Result<std::vector<uint8_t>> fetch(const Uri& uri) {
    std::vector<uint8_t> bytes;
    if (uri.origin.empty()) {
      std::ifstream in(uri.path, std::ios::binary | std::ios::ate);
      if (!in) return fail(ErrorCode::kNotFound, uri.text() + ": cannot open");
      bytes.resize(size_t(in.tellg()));
      in.seekg(0);
      if (!in.read(reinterpret_cast<char*>(bytes.data()), std::streamsize(bytes.size()))) {
        return fail(ErrorCode::kIo, uri.text() + ": short read");
      }
      return bytes;
    }
    const std::string url = uri.text();
    curl_easy_setopt(curl_, CURLOPT_URL, url.c_str());
    curl_easy_setopt(curl_, CURLOPT_WRITEFUNCTION, appendBody);
    curl_easy_setopt(curl_, CURLOPT_WRITEDATA, &bytes);
    curl_easy_setopt(curl_, CURLOPT_NOSIGNAL, 1L);
    const CURLcode code = curl_easy_perform(curl_);
    long status = 0;
    curl_easy_getinfo(curl_, CURLINFO_RESPONSE_CODE, &status);
    if (code != CURLE_OK || status != 200) {
      return fail(ErrorCode::kIo,
                  fmt::format("{}: {} (HTTP {})", url, curl_easy_strerror(code), status));
    }
    return bytes;
  }

 private:
  CURL* curl_;
};

// Full-resolution RGBA, as a viewer uploads it.
Result<uint64_t> decodeImage(const Uri& uri, const std::vector<uint8_t>& bytes) {
  const std::string ext = uri.path.extension().string();
  if (ext == ".jpg" || ext == ".jpeg") {
    tjhandle handle = tjInitDecompress();
    int w = 0, h = 0, subsampling = 0, colorspace = 0;
    bool ok = tjDecompressHeader3(handle, bytes.data(), bytes.size(), &w, &h, &subsampling,
                                  &colorspace) == 0;
    std::vector<uint8_t> pixels(size_t(w) * h * 4);
    ok = ok && tjDecompress2(handle, bytes.data(), bytes.size(), pixels.data(), w, 0, h, TJPF_RGBA,
                             0) == 0;
    tjDestroy(handle);
    if (!ok) return fail(ErrorCode::kCorrupt, uri.text() + ": JPEG decode failed");
    return uint64_t(w) * h;
  }
  png_image image{};
  image.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_memory(&image, bytes.data(), bytes.size())) {
    return fail(ErrorCode::kCorrupt, uri.text() + ": " + image.message);
  }
  image.format = PNG_FORMAT_RGBA;
  std::vector<uint8_t> pixels(PNG_IMAGE_SIZE(image));
  if (!png_image_finish_read(&image, nullptr, pixels.data(), 0, nullptr)) {
    png_image_free(&image);
    return fail(ErrorCode::kCorrupt, uri.text() + ": " + image.message);
  }
  return uint64_t(image.width) * image.height;
}

// The texture files a model's materials name (every slot the scene importer reads).
Result<std::vector<std::string>> parseModel(const Uri& uri, const std::vector<uint8_t>& bytes) {
  Assimp::Importer importer;
  const aiScene* scene =
      importer.ReadFileFromMemory(bytes.data(), bytes.size(),
                                  aiProcess_Triangulate | aiProcess_JoinIdenticalVertices |
                                      aiProcess_SortByPType | aiProcess_ValidateDataStructure,
                                  uri.path.extension().string().substr(1).c_str());
  if (!scene) return fail(ErrorCode::kCorrupt, uri.text() + ": " + importer.GetErrorString());
  std::vector<std::string> textures;
  for (unsigned m = 0; m < scene->mNumMaterials; ++m) {
    for (int type = aiTextureType_DIFFUSE; type <= aiTextureType_UNKNOWN; ++type) {
      aiString reference;
      if (scene->mMaterials[m]->GetTexture(aiTextureType(type), 0, &reference) == AI_SUCCESS &&
          reference.length > 0) {
        textures.push_back(reference.C_Str());
      }
    }
  }
  return textures;
}

// Only the texture names of an AC3D model (its `texture "file"` lines), its geometry left
// unparsed: a lower bound for a viewer whose models need no parsing (glTF's binary buffers go
// to the GPU as they are).
std::vector<std::string> acTextureNames(const std::vector<uint8_t>& bytes) {
  std::vector<std::string> out;
  const std::string_view text(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  const std::string_view prefix = "\ntexture \"";
  for (size_t at = text.find(prefix); at != std::string_view::npos;
       at = text.find(prefix, at + 1)) {
    const size_t begin = at + prefix.size(), end = text.find('"', begin);
    if (end == std::string_view::npos) break;
    out.emplace_back(text.substr(begin, end - begin));
  }
  return out;
}

// The viewer's loader: a fixed pool working through model and texture files; a model's
// textures are queued once it is parsed. Thread-safe.
class PerFileLoader {
 public:
  PerFileLoader(uint32_t threads, bool parse_models)
      : threads_(threads), parse_models_(parse_models) {}

  Result<PerFileReport> run(const std::vector<Uri>& models) {
    for (const Uri& model : models) queueOnce({model, true});
    std::vector<std::thread> pool;
    for (uint32_t i = 0; i < threads_; ++i) pool.emplace_back([this] { work(); });
    for (std::thread& thread : pool) thread.join();
    if (!error_.empty()) return fail(ErrorCode::kIo, error_);
    return report_;
  }

 private:
  struct Task {
    Uri uri;
    bool model = false;
  };

  void queueOnce(Task task) {
    std::lock_guard lock(mutex_);
    if (!seen_.insert(task.uri.text()).second) return;
    queue_.push_back(std::move(task));
    wake_.notify_one();
  }

  void work() {
    Fetcher fetcher;
    for (;;) {
      Task task;
      {
        std::unique_lock lock(mutex_);
        wake_.wait(lock, [&] { return !queue_.empty() || running_ == 0; });
        if (queue_.empty()) return;
        task = std::move(queue_.front());
        queue_.pop_front();
        ++running_;
      }
      Result<void> done = load(fetcher, task);
      std::lock_guard lock(mutex_);
      if (!done && error_.empty()) error_ = done.error().message;
      --running_;
      wake_.notify_all();  // a finished task may end the run or have queued textures
    }
  }

  Result<void> load(Fetcher& fetcher, const Task& task) {
    TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> bytes, fetcher.fetch(task.uri));
    {
      std::lock_guard lock(mutex_);
      ++report_.files;
      report_.bytes += bytes.size();
    }
    if (task.model) {
      std::vector<std::string> textures;
      if (parse_models_) {
        TESSERA_ASSIGN_OR_RETURN(textures, parseModel(task.uri, bytes));
      } else {
        textures = acTextureNames(bytes);
      }
      {
        std::lock_guard lock(mutex_);
        ++report_.models;
      }
      for (const std::string& texture : textures) queueOnce({task.uri.sibling(texture), false});
      return {};
    }
    TESSERA_ASSIGN_OR_RETURN(uint64_t texels, decodeImage(task.uri, bytes));
    std::lock_guard lock(mutex_);
    ++report_.textures;
    report_.texels += texels;
    return {};
  }

  const uint32_t threads_;
  const bool parse_models_;
  std::mutex mutex_;  // guards everything below
  std::condition_variable wake_;
  std::deque<Task> queue_;
  std::set<std::string> seen_;
  uint32_t running_ = 0;
  PerFileReport report_;
  std::string error_;
};

}  // namespace

Result<PerFileReport> loadPerFile(const std::string& stg_uri, const std::set<uint32_t>& lines,
                                  uint32_t threads, bool parse_models) {
  const auto start = std::chrono::steady_clock::now();
  const Uri stg = parseUri(stg_uri);
  Fetcher fetcher;
  TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> bytes, fetcher.fetch(stg));
  std::istringstream text(std::string(bytes.begin(), bytes.end()));
  std::vector<Uri> models;
  std::string line_text;
  for (uint32_t line = 1; std::getline(text, line_text); ++line) {
    std::istringstream fields(line_text);
    std::string keyword, model;
    if (!(fields >> keyword >> model) || keyword != "OBJECT_STATIC") continue;
    if (lines.empty() || lines.count(line)) models.push_back(stg.sibling(model));
  }
  PerFileLoader loader(std::max(1u, threads), parse_models);
  TESSERA_ASSIGN_OR_RETURN(PerFileReport report, loader.run(models));
  ++report.files;
  report.bytes += bytes.size();
  report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return report;
}

}  // namespace coldload
