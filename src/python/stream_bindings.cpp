// tessera.Streamer for Python: the streaming runtime as `tessera fly` drives it without a GPU.
// Each update() is a frame: the view goes in, the tiles that became resident, the ones released
// and the frame's coverage come out; the Python side plays a renderer with room for every tile
// (it accepts every upload). The GIL is held during update (it never waits on disk or
// decoding, tessera/stream.h), so Python threads calling one Streamer are serialised by it;
// wait() releases it.

#include <map>
#include <memory>
#include <tuple>
#include <utility>

#include <pybind11/numpy.h>
#include <pybind11/stl.h>

#include <tessera/stream.h>

#include "bindings.h"

namespace py = pybind11;

namespace tessera::python {
namespace {

using TileKey = std::tuple<uint32_t, uint32_t, uint32_t, uint32_t>;  // image, level, x, y

TileKey keyOf(const TileId& id) {
  return {id.image, id.level, id.x, id.y};
}

py::tuple tupleOf(const TileId& id) {
  return py::make_tuple(id.level, id.x, id.y);
}

class PyStreamer {
 public:
  PyStreamer(std::shared_ptr<Archive> archive, uint32_t width, uint32_t height,
             uint64_t cache_bytes, uint32_t loader_threads) {
    if (width == 0 || height == 0)
      throw LibraryError{{ErrorCode::kInvalidArgument, "viewport must be at least 1x1 px"}};
    StreamerOptions options;
    if (cache_bytes) options.cache_budget_bytes = cache_bytes;
    options.loader_threads = loader_threads;
    options.loader_priority = LoaderPriority::kNice;  // a notebook has no render thread to spare
    width_ = width;
    height_ = height;
    streamer_ = valueOrThrow(TileStreamer::create(std::move(archive), options));
  }

  py::dict update(double centre_x, double centre_y, double texels_per_pixel, uint32_t image,
                  double rotation) {
    View view;
    view.image = image;
    view.ortho = {centre_x, centre_y, texels_per_pixel, width_, height_, rotation};
    const FrameUpdate& frame = streamer_->update(view);
    ApplyResult applied;
    py::list uploaded, released;
    for (const auto& tile : frame.uploads) {
      applied.accepted.push_back(tile->id);
      resident_[keyOf(tile->id)] = tile;
      uploaded.append(tupleOf(tile->id));
    }
    for (const TileId& id : frame.releases) {
      resident_.erase(keyOf(id));
      released.append(tupleOf(id));
    }
    streamer_->acknowledge(applied);
    py::list failures;
    for (const LoadFailure& failure : frame.failures) failures.append(failure.message);
    const FrameReport& r = frame.report;
    return py::dict(py::arg("desired_level") = r.desired_level,
                    py::arg("finest_full_level") = r.finest_full_level,
                    py::arg("coverage") = r.coverage_desired,
                    py::arg("fully_covered") = r.fully_covered, py::arg("uploaded") = uploaded,
                    py::arg("released") = released, py::arg("resident") = resident_.size(),
                    py::arg("queue_length") = r.queue_length, py::arg("in_flight") = r.in_flight,
                    py::arg("tiles_loaded_total") = r.tiles_loaded_total,
                    py::arg("failures") = failures);
  }

  py::list resident() const {
    py::list tiles;
    for (const auto& [key, tile] : resident_) tiles.append(tupleOf(tile->id));
    return tiles;
  }

  /// A resident tile's decoded texels (with borders), read-only and zero-copy: the array keeps
  /// the cache's tile alive.
  py::object tile(uint32_t level, uint32_t x, uint32_t y, uint32_t image) const {
    auto found = resident_.find({image, level, x, y});
    if (found == resident_.end()) return py::none();
    auto* owned = new std::shared_ptr<const DecodedTile>(found->second);
    py::capsule owner(owned,
                      [](void* p) { delete static_cast<std::shared_ptr<const DecodedTile>*>(p); });
    const Image& texels = (*owned)->texels;
    const py::ssize_t h = texels.height_px, w = texels.width_px, c = texels.channels;
    py::array_t<uint8_t> array({h, w, c}, {w * c, c, py::ssize_t(1)}, texels.texels.data(), owner);
    py::detail::array_proxy(array.ptr())->flags &= ~py::detail::npy_api::NPY_ARRAY_WRITEABLE_;
    return array;
  }

  void wait() {
    py::gil_scoped_release release;
    streamer_->waitIdleForTesting();
  }

 private:
  std::unique_ptr<TileStreamer> streamer_;
  uint32_t width_ = 0;
  uint32_t height_ = 0;
  std::map<TileKey, std::shared_ptr<const DecodedTile>> resident_;
};

}  // namespace

void registerStreamer(py::module_& module) {
  py::class_<PyStreamer>(module, "Streamer")
      .def(py::init<std::shared_ptr<Archive>, uint32_t, uint32_t, uint64_t, uint32_t>(),
           py::arg("archive"), py::arg("width") = 1280, py::arg("height") = 720,
           py::arg("cache_bytes") = 0, py::arg("loader_threads") = 0)
      .def("update", &PyStreamer::update, py::arg("centre_x"), py::arg("centre_y"),
           py::arg("texels_per_pixel") = 1.0, py::arg("image") = 0, py::arg("rotation") = 0.0)
      .def("resident", &PyStreamer::resident)
      .def("tile", &PyStreamer::tile, py::arg("level"), py::arg("x"), py::arg("y"),
           py::arg("image") = 0)
      .def("wait", &PyStreamer::wait);
}

}  // namespace tessera::python
