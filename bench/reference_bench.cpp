// The CPU reference renderer's speed on 1920x1080 views of a synthetic 8192x8192 RGB archive
// (256-px zstd tiles, built once into the temp directory): orthographic at one texel per pixel
// (bilinear on one level), between levels (trilinear), rotated, and a tilted perspective view
// (per-pixel level, many levels). Each iteration is a whole renderReference call, reads and
// decodes included, as `tessera fly` pays it for a PSNR check.
//
//   ninja -C build-bench tessera_reference_bench && build-bench/bench/tessera_reference_bench
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>

#include <benchmark/benchmark.h>
#include <unistd.h>

#include <tessera/build.h>
#include <tessera/render.h>

namespace {

using namespace tessera;

std::shared_ptr<Archive> benchArchive() {
  static std::shared_ptr<Archive> archive = [] {
    const std::string path = (std::filesystem::temp_directory_path() /
                              ("tessera_reference_bench_" + std::to_string(::getpid()) + ".tess"))
                                 .string();
    BuildOptions options;
    options.inputs = {"synthetic:8192x8192:1:3"};
    options.output = path;
    options.codec = Codec::kZstd;
    Result<BuildReport> built = buildArchive(options);
    if (!built) {
      std::fprintf(stderr, "%s\n", built.error().message.c_str());
      std::abort();
    }
    Result<std::shared_ptr<Archive>> opened = Archive::openFile(path);
    if (!opened) {
      std::fprintf(stderr, "%s\n", opened.error().message.c_str());
      std::abort();
    }
    std::filesystem::remove(path);  // the open descriptor keeps it readable
    return *opened;
  }();
  return archive;
}

void render(benchmark::State& state, const View& view) {
  const std::shared_ptr<Archive> archive = benchArchive();
  for (auto _ : state) {
    Result<Picture> picture = renderReference(*archive, view);
    if (!picture) {
      state.SkipWithError(picture.error().message.c_str());
      return;
    }
    benchmark::DoNotOptimize(picture->rgba.data());
  }
  state.SetItemsProcessed(state.iterations() * int64_t(view.viewportWidth()) *
                          view.viewportHeight());
}

View ortho(double tpp, double rotation) {
  View view;
  view.ortho = {4100.3, 4050.7, tpp, 1920, 1080, rotation};
  return view;
}

void BM_OrthoOneTexelPerPixel(benchmark::State& state) {
  render(state, ortho(1, 0));
}
void BM_OrthoTrilinear(benchmark::State& state) {
  render(state, ortho(1.5, 0));
}
void BM_OrthoRotated(benchmark::State& state) {
  render(state, ortho(1.3, 0.5));
}
void BM_PerspectiveTilted(benchmark::State& state) {
  View view;
  view.kind = View::Kind::kPerspective;
  view.perspective = {4096, 6000, 400, 0.3, -0.5, 1.0, 1920, 1080};
  render(state, view);
}

BENCHMARK(BM_OrthoOneTexelPerPixel)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_OrthoTrilinear)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_OrthoRotated)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_PerspectiveTilted)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
