// tessera-gpu-floor: the GPU cost of a still frame of each renderer against the single-fetch
// floor, in one run on one GPU at one viewport (issue 30, item 2; docs/rendering.md, "Cost of
// a still frame").
//
// The floor is what any tiled viewer must at least pay: the viewport covered by textured
// quads, one bilinear fetch per pixel from a texture array of 256-px tiles, at the same zoom
// as the renderers' view, into a target of the same size and format. The renderers draw the
// same view of a real archive once every tile it needs is resident (nothing uploading), so the
// ratio is the price of their sampling rules: coarse levels under fine ones, the per-fragment
// level of detail, the blend with the parent, filtering across tile edges.
//
//   tessera-gpu-floor ARCHIVE [--viewport 1920x1080,3840x2160] [--zoom 1.37] [--frames 40]
//                             [--renderer tile-quads,clipmap] [--json FILE]
//
// Every figure is GPU time from GL_TIME_ELAPSED queries, read back after the timed frames (a
// benchmark may wait; the render thread never does). Prints one Markdown table.

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include <epoxy/gl.h>
#include <fmt/format.h>

#include <tessera/archive.h>
#include <tessera/gl.h>
#include <tessera/open.h>
#include <tessera/renderer.h>
#include <tessera/stream.h>

namespace {

using namespace tessera;

struct Options {
  std::string archive;
  std::vector<std::pair<uint32_t, uint32_t>> viewports{{1920, 1080}, {3840, 2160}};
  double zoom = 1.37;  // texels per pixel: not a power of two, so every pixel filters
  int frames = 40;
  std::vector<RendererKind> renderers{RendererKind::kTileQuads, RendererKind::kClipmap};
  std::string json;
};

[[noreturn]] void usage(const std::string& why) {
  std::fprintf(stderr,
               "tessera-gpu-floor: %s\nusage: tessera-gpu-floor ARCHIVE [--viewport WxH[,WxH...]] "
               "[--zoom T] [--frames N] [--renderer tile-quads,clipmap] [--json FILE]\n",
               why.c_str());
  std::exit(2);
}

std::vector<std::string> splitList(const std::string& text) {
  std::vector<std::string> parts;
  size_t start = 0;
  while (start <= text.size()) {
    const size_t comma = std::min(text.find(',', start), text.size());
    if (comma > start) parts.push_back(text.substr(start, comma - start));
    start = comma + 1;
  }
  return parts;
}

Options parseOptions(int argc, char** argv) {
  Options options;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    const auto value = [&]() -> std::string {
      if (i + 1 >= argc) usage(arg + " needs a value");
      return argv[++i];
    };
    if (arg == "--viewport") {
      options.viewports.clear();
      for (const std::string& item : splitList(value())) {
        unsigned w = 0, h = 0;
        if (std::sscanf(item.c_str(), "%ux%u", &w, &h) != 2 || w == 0 || h == 0 || w > 16384 ||
            h > 16384)
          usage("bad viewport '" + item + "' (WxH, each 1..16384)");
        options.viewports.emplace_back(w, h);
      }
    } else if (arg == "--zoom") {
      options.zoom = std::atof(value().c_str());
      if (!(options.zoom > 0.05 && options.zoom < 64)) usage("--zoom must be in 0.05..64");
    } else if (arg == "--frames") {
      options.frames = std::atoi(value().c_str());
      if (options.frames < 3 || options.frames > 10000) usage("--frames must be in 3..10000");
    } else if (arg == "--renderer") {
      options.renderers.clear();
      for (const std::string& name : splitList(value())) {
        const auto kind = rendererNamed(name);
        if (!kind) usage("unknown renderer '" + name + "'");
        options.renderers.push_back(*kind);
      }
    } else if (arg == "--json") {
      options.json = value();
    } else if (!arg.empty() && arg[0] == '-') {
      usage("unknown option " + arg);
    } else if (options.archive.empty()) {
      options.archive = arg;
    } else {
      usage("one archive only");
    }
  }
  if (options.archive.empty()) usage("no archive given");
  return options;
}

double median(std::vector<double> values) {
  if (values.empty()) return -1;
  std::sort(values.begin(), values.end());
  return values[values.size() / 2];
}

/// Times of one frame, ms: the GPU's (a GL_TIME_ELAPSED query) and the wall time from a
/// finished pipeline to the frame finished (glFinish on both sides). The second is what a
/// software rasteriser such as llvmpipe can be trusted for: it rasterises at flush time,
/// outside the span a timer query sees.
struct FrameTimes {
  std::vector<double> gpu_ms;
  std::vector<double> finished_ms;
  /// CPU time of the whole process over the same span: with a software rasteriser that is
  /// the frame's work, and unlike wall time it barely moves on a machine busy with others.
  std::vector<double> process_cpu_ms;
};

double processCpuMs() {
  timespec now{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &now);
  return double(now.tv_sec) * 1e3 + double(now.tv_nsec) / 1e6;
}

/// `frames` calls of `draw`, each inside its own query and between two glFinish; the query
/// results are read after the last frame. The first two frames (shader compilation, first
/// touches of memory) are dropped.
template <typename Draw>
FrameTimes timeFrames(int frames, Draw&& draw) {
  std::vector<GLuint> queries(static_cast<size_t>(frames));
  glGenQueries(frames, queries.data());
  FrameTimes times;
  for (int i = 0; i < frames; ++i) {
    glFinish();
    const auto began = std::chrono::steady_clock::now();
    const double cpu_began = processCpuMs();
    glBeginQuery(GL_TIME_ELAPSED, queries[size_t(i)]);
    draw();
    glEndQuery(GL_TIME_ELAPSED);
    glFinish();
    times.finished_ms.push_back(
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - began)
            .count());
    times.process_cpu_ms.push_back(processCpuMs() - cpu_began);
  }
  for (GLuint query : queries) {
    GLuint64 ns = 0;
    glGetQueryObjectui64v(query, GL_QUERY_RESULT, &ns);  // waits: fine in a benchmark
    times.gpu_ms.push_back(double(ns) / 1e6);
  }
  glDeleteQueries(frames, queries.data());
  for (std::vector<double>* list : {&times.gpu_ms, &times.finished_ms, &times.process_cpu_ms})
    list->erase(list->begin(), list->begin() + 2);
  return times;
}

/// Medians of a FrameTimes.
struct FrameCost {
  double gpu_ms = -1;
  double finished_ms = -1;
  double process_cpu_ms = -1;
};
FrameCost medians(const FrameTimes& times) {
  return {median(times.gpu_ms), median(times.finished_ms), median(times.process_cpu_ms)};
}

GLuint compileProgram(const char* vertex, const char* fragment) {
  const auto stage = [](GLenum type, const char* source) {
    const GLuint shader = glCreateShader(type);
    glShaderSource(shader, 1, &source, nullptr);
    glCompileShader(shader);
    GLint ok = 0;
    glGetShaderiv(shader, GL_COMPILE_STATUS, &ok);
    if (!ok) {
      char log[2048] = {};
      glGetShaderInfoLog(shader, sizeof log, nullptr, log);
      std::fprintf(stderr, "tessera-gpu-floor: shader does not compile: %s\n", log);
      std::exit(1);
    }
    return shader;
  };
  const GLuint program = glCreateProgram();
  const GLuint vs = stage(GL_VERTEX_SHADER, vertex);
  const GLuint fs = stage(GL_FRAGMENT_SHADER, fragment);
  glAttachShader(program, vs);
  glAttachShader(program, fs);
  glLinkProgram(program);
  glDeleteShader(vs);
  glDeleteShader(fs);
  return program;
}

// One quad per instance, laid out on a grid of `tile_px_on_screen` squares from the top-left
// corner; each samples its own layer once, bilinearly, at texture coordinates inside it.
constexpr const char* kFloorVertex = R"(#version 450 core
uniform vec2 viewport;
uniform float tile_px_on_screen;
uniform int columns;
uniform int layers;
out vec2 uv;
flat out int layer;
void main() {
  const vec2 corners[6] = vec2[](vec2(0, 0), vec2(1, 0), vec2(0, 1),
                                 vec2(1, 0), vec2(1, 1), vec2(0, 1));
  vec2 corner = corners[gl_VertexID];
  vec2 cell = vec2(gl_InstanceID % columns, gl_InstanceID / columns);
  vec2 pixel = (cell + corner) * tile_px_on_screen;
  uv = corner;
  layer = gl_InstanceID % layers;
  gl_Position = vec4(pixel / viewport * 2.0 - 1.0, 0.0, 1.0);
}
)";
constexpr const char* kFloorFragment = R"(#version 450 core
uniform sampler2DArray tiles;
in vec2 uv;
flat in int layer;
out vec4 colour;
void main() { colour = texture(tiles, vec3(uv, float(layer))); }
)";

/// The floor frame's cost (medians of the timed frames).
FrameCost floorFrame(uint32_t width, uint32_t height, double zoom, int frames) {
  constexpr int kTile = 256;
  const double tile_px_on_screen = kTile / zoom;
  const int columns = int(std::ceil(width / tile_px_on_screen));
  const int rows = int(std::ceil(height / tile_px_on_screen));
  const int layers = std::min(columns * rows, 2048);

  GLuint texture = 0;
  glCreateTextures(GL_TEXTURE_2D_ARRAY, 1, &texture);
  glTextureStorage3D(texture, 1, GL_RGBA8, kTile, kTile, layers);
  glTextureParameteri(texture, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
  glTextureParameteri(texture, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
  glTextureParameteri(texture, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
  glTextureParameteri(texture, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  std::vector<uint8_t> texels(size_t(kTile) * kTile * 4);
  std::mt19937 random(7);
  for (int layer = 0; layer < layers; ++layer) {
    for (uint8_t& texel : texels) texel = uint8_t(random());
    glTextureSubImage3D(texture, 0, 0, 0, layer, kTile, kTile, 1, GL_RGBA, GL_UNSIGNED_BYTE,
                        texels.data());
  }

  GLuint target = 0, framebuffer = 0, vertex_array = 0;
  glCreateTextures(GL_TEXTURE_2D, 1, &target);
  glTextureStorage2D(target, 1, GL_RGBA8, GLsizei(width), GLsizei(height));
  glCreateFramebuffers(1, &framebuffer);
  glNamedFramebufferTexture(framebuffer, GL_COLOR_ATTACHMENT0, target, 0);
  glCreateVertexArrays(1, &vertex_array);
  const GLuint program = compileProgram(kFloorVertex, kFloorFragment);
  glUseProgram(program);
  glUniform2f(glGetUniformLocation(program, "viewport"), float(width), float(height));
  glUniform1f(glGetUniformLocation(program, "tile_px_on_screen"), float(tile_px_on_screen));
  glUniform1i(glGetUniformLocation(program, "columns"), columns);
  glUniform1i(glGetUniformLocation(program, "layers"), layers);
  glUniform1i(glGetUniformLocation(program, "tiles"), 0);
  glBindTextureUnit(0, texture);
  glBindVertexArray(vertex_array);
  glBindFramebuffer(GL_FRAMEBUFFER, framebuffer);
  glViewport(0, 0, GLsizei(width), GLsizei(height));
  glDisable(GL_BLEND);
  glDisable(GL_DEPTH_TEST);

  const FrameCost cost = medians(timeFrames(frames, [&] {
    glClearColor(0, 0, 0, 1);
    glClear(GL_COLOR_BUFFER_BIT);
    glDrawArraysInstanced(GL_TRIANGLES, 0, 6, columns * rows);
  }));

  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  glUseProgram(0);
  glDeleteProgram(program);
  glDeleteVertexArrays(1, &vertex_array);
  glDeleteFramebuffers(1, &framebuffer);
  glDeleteTextures(1, &target);
  glDeleteTextures(1, &texture);
  return cost;
}

struct StillFrame {
  FrameCost cost;
  bool settled = false;
  uint32_t tiles_drawn = 0;
};

/// Streams `view` until nothing is loading or uploading, then times still frames.
Result<StillFrame> rendererStillFrame(const std::shared_ptr<Archive>& archive, RendererKind kind,
                                      const View& view, int frames) {
  StreamerOptions streamer_options;
  streamer_options.cache_budget_bytes = size_t(1) << 30;
  TESSERA_ASSIGN_OR_RETURN(std::unique_ptr<TileStreamer> streamer,
                           TileStreamer::create(archive, streamer_options));
  TESSERA_ASSIGN_OR_RETURN(std::unique_ptr<Renderer> renderer,
                           createRenderer(kind, archive->images()[view.image]));
  StillFrame result;
  int quiet = 0;
  for (int i = 0; i < 2000 && quiet < 2; ++i) {
    const FrameUpdate& update = streamer->update(view);
    streamer->acknowledge(renderer->apply(update));
    renderer->draw(view);
    const bool idle = update.uploads.size() == renderer->stats().declined &&
                      update.report.queue_length == 0 && update.report.in_flight == 0;
    quiet = idle ? quiet + 1 : 0;
    streamer->waitIdleForTesting();
  }
  result.settled = quiet >= 2;
  result.cost = medians(timeFrames(frames, [&] { renderer->draw(view); }));
  result.tiles_drawn = renderer->stats().tiles_drawn;
  return result;
}

}  // namespace

int main(int argc, char** argv) {
  const Options options = parseOptions(argc, argv);
  auto archive = openArchive(options.archive);
  if (!archive) {
    std::fprintf(stderr, "tessera-gpu-floor: %s\n", archive.error().message.c_str());
    return 1;
  }
  auto context = GlContext::createHeadless();
  if (!context) {
    std::fprintf(stderr, "tessera-gpu-floor: %s\n", context.error().message.c_str());
    return 1;
  }
  const ImageInfo& image = (*archive)->images()[0];
  const std::string gl = (*context)->description();
  std::printf("GL: %s; archive %s (%ux%u), zoom %.2f texels per pixel, %d frames\n\n", gl.c_str(),
              options.archive.c_str(), image.width_px, image.height_px, options.zoom,
              options.frames);
  std::printf(
      "| viewport | renderer | floor GPU ms | still GPU ms | / floor | floor finished ms | "
      "still finished ms | / floor | floor CPU ms | still CPU ms | / floor | tiles drawn |\n");
  std::printf("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
  std::string json = fmt::format(R"({{"gl":"{}","zoom":{},"frames":{},"rows":[)", gl, options.zoom,
                                 options.frames);
  bool failed = false;
  for (const auto& [width, height] : options.viewports) {
    const FrameCost floor = floorFrame(width, height, options.zoom, options.frames);
    for (RendererKind kind : options.renderers) {
      View view;
      view.ortho = {image.width_px / 2.0, image.height_px / 2.0, options.zoom, width, height, 0};
      auto still = rendererStillFrame(*archive, kind, view, options.frames);
      if (!still) {
        std::fprintf(stderr, "tessera-gpu-floor: %s: %s\n", rendererName(kind),
                     still.error().message.c_str());
        failed = true;
        continue;
      }
      const FrameCost& cost = still->cost;
      std::printf(
          "| %ux%u | %s%s | %.3f | %.3f | %.2fx | %.3f | %.3f | %.2fx | %.3f | %.3f | "
          "%.2fx | %u |\n",
          width, height, rendererName(kind), still->settled ? "" : " (never settled)", floor.gpu_ms,
          cost.gpu_ms, cost.gpu_ms / floor.gpu_ms, floor.finished_ms, cost.finished_ms,
          cost.finished_ms / floor.finished_ms, floor.process_cpu_ms, cost.process_cpu_ms,
          cost.process_cpu_ms / floor.process_cpu_ms, still->tiles_drawn);
      json += fmt::format(
          R"({}{{"viewport":"{}x{}","renderer":"{}","floor_gpu_ms":{:.4f},"still_gpu_ms":{:.4f},)"
          R"("floor_finished_ms":{:.4f},"still_finished_ms":{:.4f},"floor_process_cpu_ms":{:.4f},)"
          R"("still_process_cpu_ms":{:.4f},"tiles_drawn":{},"settled":{}}})",
          json.back() == '[' ? "" : ",", width, height, rendererName(kind), floor.gpu_ms,
          cost.gpu_ms, floor.finished_ms, cost.finished_ms, floor.process_cpu_ms,
          cost.process_cpu_ms, still->tiles_drawn, still->settled);
      failed = failed || !still->settled;
    }
  }
  json += "]}\n";
  if (!options.json.empty()) {
    std::ofstream out(options.json);
    out << json;
    if (!out) {
      std::fprintf(stderr, "tessera-gpu-floor: cannot write %s\n", options.json.c_str());
      return 1;
    }
  }
  return failed ? 1 : 0;
}
