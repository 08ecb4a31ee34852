// tessera.build for Python: files, and images the caller supplies row band by row band
// (RowSource, tessera/build.h) through a Python object whose `fill(first_row, out)` writes rows
// into a NumPy view of the builder's band (python/tessera/_sources.py adapts arrays and
// iterators to it). The build runs with the GIL released; the row and progress callbacks take
// it back. A Python exception in a callback cancels the build (no output is left) and is raised
// again, unchanged, when buildArchive returns; so is Ctrl-C.

#include <atomic>
#include <exception>
#include <string>
#include <utility>
#include <vector>

#include <pybind11/numpy.h>
#include <pybind11/stl.h>

#include <tessera/build.h>

#include "bindings.h"

namespace py = pybind11;

namespace tessera::python {
namespace {

/// What the callbacks share with the call: the first Python exception, and the cancel flag it
/// raises so the builder stops at its next band.
struct CallbackState {
  std::exception_ptr raised;
  std::atomic<bool> cancel{false};
  void record() {
    if (!raised) raised = std::current_exception();
    cancel = true;
  }
};

Codec parseCodec(const std::string& name) {
  Codec codec;
  if (!parseCodecName(name, &codec))
    throw LibraryError{
        {ErrorCode::kInvalidArgument,
         "unknown codec '" + name + "' (raw, zstd, lz4, jpeg, png, webp, ptm, zdelta, bc1, bc7)"}};
  return codec;
}

TileOrder parseOrder(const std::string& name) {
  if (name == "hilbert") return TileOrder::kHilbert;
  if (name == "quadtree") return TileOrder::kQuadtree;
  if (name == "row-major") return TileOrder::kRowMajor;
  throw LibraryError{
      {ErrorCode::kInvalidArgument, "unknown order '" + name + "' (hilbert, quadtree, row-major)"}};
}

/// A RowSource over `filler`, a Python object with name, width, height, channels, band_rows
/// and fill(first_row, out).
RowSource rowSource(const py::object& filler, CallbackState& state) {
  RowSource source;
  source.name = filler.attr("name").cast<std::string>();
  source.width_px = filler.attr("width").cast<uint32_t>();
  source.height_px = filler.attr("height").cast<uint32_t>();
  source.channels = filler.attr("channels").cast<uint32_t>();
  source.band_rows = filler.attr("band_rows").cast<uint32_t>();
  const std::string sample_type = filler.attr("sample_type").cast<std::string>();
  if (!parseSampleTypeName(sample_type, &source.sample_type))
    throw LibraryError{
        {ErrorCode::kInvalidArgument, source.name + ": unknown sample type '" + sample_type + "'"}};
  const uint32_t width = source.width_px, channels = source.channels;
  const SampleType type = source.sample_type;
  source.read_rows = [filler, &state, width, channels, type](
                         uint32_t first_row, uint32_t rows,
                         std::span<uint8_t> out) -> Result<void> {
    py::gil_scoped_acquire acquire;
    try {
      if (PyErr_CheckSignals() != 0) throw py::error_already_set();
      // A view of the builder's band, valid during this call only (fill must not keep it).
      const py::ssize_t s = sampleBytes(type);
      py::array band(dtypeOf(type), {py::ssize_t(rows), py::ssize_t(width), py::ssize_t(channels)},
                     {py::ssize_t(width) * channels * s, py::ssize_t(channels) * s, s}, out.data(),
                     py::capsule(out.data(), [](void*) {}));
      filler.attr("fill")(first_row, band);
      return {};
    } catch (...) {
      state.record();
      return fail(ErrorCode::kCancelled, "rows from Python failed");
    }
  };
  return source;
}

BuildOptions buildOptions(const py::dict& options) {
  BuildOptions built;
  built.output = options["output"].cast<std::string>();
  built.inputs = options["inputs"].cast<std::vector<std::string>>();
  built.tile_size_px = options["tile_size"].cast<uint32_t>();
  built.border_px = options["border"].cast<uint32_t>();
  built.codec = parseCodec(options["codec"].cast<std::string>());
  built.quality = options["quality"].cast<int>();
  built.effort = options["effort"].cast<int>();
  built.chroma_subsampling = options["chroma_subsampling"].cast<bool>();
  built.srgb_downsample = options["srgb_downsample"].cast<bool>();
  built.order = parseOrder(options["order"].cast<std::string>());
  built.threads = options["threads"].cast<uint32_t>();
  built.page_tiles_log2 = options["page_tiles_log2"].cast<uint32_t>();
  built.image_names = options["image_names"].cast<std::vector<std::string>>();
  built.memory_limit_bytes = options["memory_limit"].cast<uint64_t>();
  built.spool_dir = options["spool_dir"].cast<std::string>();
  return built;
}

/// Builds from `options` (a dict of every BuildOptions field, made by tessera.build) and the
/// row fillers; `progress(dict)` is called about every 100 ms and at the end.
BuildReport build(const py::dict& options, const py::list& fillers, const py::object& progress) {
  CallbackState state;
  BuildOptions built = buildOptions(options);
  for (const py::handle filler : fillers)
    built.row_sources.push_back(rowSource(py::reinterpret_borrow<py::object>(filler), state));
  std::function<void(const BuildProgress&)> on_progress;
  if (!progress.is_none()) {
    on_progress = [&progress, &state](const BuildProgress& p) {
      py::gil_scoped_acquire acquire;
      if (state.raised) return;
      try {
        if (PyErr_CheckSignals() != 0) throw py::error_already_set();
        progress(py::dict(
            py::arg("pixels_done") = p.pixels_done, py::arg("pixels_total") = p.pixels_total,
            py::arg("tiles_written") = p.tiles_written, py::arg("elapsed_s") = p.elapsed_s));
      } catch (...) {
        state.record();
      }
    };
  }
  Result<BuildReport> report = BuildReport();
  {
    py::gil_scoped_release release;
    report = buildArchive(built, on_progress, &state.cancel);
  }
  // The fillers' closures hold Python references: drop them while the GIL is held.
  built.row_sources.clear();
  if (state.raised) std::rethrow_exception(state.raised);
  return valueOrThrow(std::move(report));
}

}  // namespace

void registerBuild(py::module_& module) {
  py::class_<BuildReport>(module, "BuildReport", "What a finished build reports.")
      .def_readonly("output_bytes", &BuildReport::output_bytes)
      .def_readonly("tiles_encoded", &BuildReport::tiles_encoded)
      .def_readonly("tiles_copied", &BuildReport::tiles_copied)
      .def_readonly("tiles_uniform", &BuildReport::tiles_uniform)
      .def_readonly("tiles_empty", &BuildReport::tiles_empty)
      .def_readonly("payload_bytes", &BuildReport::payload_bytes)
      .def_readonly("elapsed_s", &BuildReport::elapsed_s)
      .def_readonly("megapixels_per_s", &BuildReport::megapixels_per_s)
      .def_readonly("images", &BuildReport::images)
      .def_readonly("memory_estimate_bytes", &BuildReport::memory_estimate_bytes);
  module.def("build", &build, py::arg("options"), py::arg("fillers"), py::arg("progress"));
}

}  // namespace tessera::python
