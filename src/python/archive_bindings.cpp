// tessera.Archive for Python: open by path or URL, images and levels, metadata, regions and
// tiles as NumPy arrays (zero-copy: the array owns the decoded buffer), verify. Every call that
// reads or decodes releases the GIL; the Archive is thread-safe (tessera/archive.h), so Python
// threads may read one archive at once.

#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <pybind11/numpy.h>
#include <pybind11/stl.h>

#include <tessera/archive.h>
#include <tessera/open.h>

#include "bindings.h"

namespace py = pybind11;

namespace tessera::python {
namespace {

/// An (height, width, channels) array of the image's dtype over `image`'s texels, which it takes
/// over: the buffer moves into a capsule the array keeps alive, so no byte is copied.
py::array toArray(Image image) {
  auto* owned = new Image(std::move(image));
  py::capsule owner(owned, [](void* p) { delete static_cast<Image*>(p); });
  return arrayOver(*owned, std::move(owner));
}

const ImageInfo& imageAt(const Archive& archive, uint32_t image) {
  if (image >= archive.images().size())
    throw LibraryError{{ErrorCode::kInvalidArgument,
                        archive.name() + ": image " + std::to_string(image) + " out of 0.." +
                            std::to_string(archive.images().size() - 1)}};
  return archive.images()[image];
}

py::array readRegion(const Archive& archive, uint32_t level, int64_t x, int64_t y, uint32_t width,
                     uint32_t height, uint32_t image, bool rgba) {
  const ImageInfo& info = imageAt(archive, image);
  if (level >= info.level_count)
    throw LibraryError{{ErrorCode::kInvalidArgument, archive.name() + ": level " +
                                                         std::to_string(level) + " out of 0.." +
                                                         std::to_string(info.level_count - 1)}};
  Result<Image> region = Image();
  {
    py::gil_scoped_release release;
    const PixelRect rect{x, y, width, height};
    region =
        rgba ? archive.readRegionRgba(image, level, rect) : archive.readRegion(image, level, rect);
  }
  return toArray(valueOrThrow(std::move(region)));
}

/// One tile's directory entry as Python sees it.
struct TileInfo {
  TileId id;
  TileEntry entry;
};

TileInfo tileInfo(const Archive& archive, uint32_t level, uint32_t x, uint32_t y, uint32_t image) {
  const TileId id{image, level, x, y};
  Result<TileEntry> entry = TileEntry();
  {
    py::gil_scoped_release release;
    entry = archive.tileEntry(id);
  }
  return {id, valueOrThrow(std::move(entry))};
}

py::array readTile(const Archive& archive, uint32_t level, uint32_t x, uint32_t y, uint32_t image) {
  Result<Image> tile = Image();
  {
    py::gil_scoped_release release;
    tile = archive.readTile({image, level, x, y});
  }
  return toArray(valueOrThrow(std::move(tile)));
}

VerifyReport verify(const Archive& archive, bool decode, const py::object& progress) {
  std::function<void(uint64_t, uint64_t)> on_progress;
  if (!progress.is_none()) {
    on_progress = [&progress](uint64_t done, uint64_t total) {
      py::gil_scoped_acquire acquire;
      progress(done, total);  // an exception here propagates after verify returns
    };
  }
  // A Python exception inside the callback cannot unwind through the library: catch it there,
  // finish verify, and raise it afterwards.
  std::exception_ptr raised;
  std::function<void(uint64_t, uint64_t)> guarded;
  if (on_progress) {
    guarded = [&](uint64_t done, uint64_t total) {
      if (raised) return;
      try {
        on_progress(done, total);
      } catch (...) {
        raised = std::current_exception();
      }
    };
  }
  VerifyReport report;
  {
    py::gil_scoped_release release;
    report = archive.verify(decode, guarded);
  }
  if (raised) std::rethrow_exception(raised);
  return report;
}

py::object metadata(const Archive& archive) {
  return py::module_::import("json").attr("loads")(archive.metadataJson());
}

void registerImageInfo(py::module_& module) {
  py::class_<ImageInfo>(module, "ImageInfo", "One image of an archive: size, tiles, levels.")
      .def_readonly("width", &ImageInfo::width_px)
      .def_readonly("height", &ImageInfo::height_px)
      .def_readonly("channels", &ImageInfo::channels)
      .def_property_readonly("sample_type",
                             [](const ImageInfo& info) { return sampleTypeName(info.sample_type); })
      .def_property_readonly("dtype",
                             [](const ImageInfo& info) { return dtypeOf(info.sample_type); })
      .def_readonly("tile_size", &ImageInfo::tile_size_px)
      .def_readonly("border", &ImageInfo::border_px)
      .def_readonly("level_count", &ImageInfo::level_count)
      .def_readonly("name", &ImageInfo::name)
      .def_property_readonly("codec",
                             [](const ImageInfo& info) { return codecName(info.default_codec); })
      .def_property_readonly(
          "levels",
          [](const ImageInfo& info) {
            py::list levels;
            for (uint32_t l = 0; l < info.level_count; ++l)
              levels.append(py::dict(py::arg("level") = l, py::arg("width") = info.levelWidthPx(l),
                                     py::arg("height") = info.levelHeightPx(l),
                                     py::arg("tiles_x") = info.tilesX(l),
                                     py::arg("tiles_y") = info.tilesY(l)));
            return levels;
          })
      .def("__repr__", [](const ImageInfo& info) {
        return "<ImageInfo '" + info.name + "' " + std::to_string(info.width_px) + "x" +
               std::to_string(info.height_px) + "x" + std::to_string(info.channels) + ", " +
               std::to_string(info.level_count) + " levels>";
      });
}

void registerTileInfo(py::module_& module) {
  py::class_<TileInfo>(module, "TileInfo", "A tile's address and directory entry.")
      .def_property_readonly("image", [](const TileInfo& t) { return t.id.image; })
      .def_property_readonly("level", [](const TileInfo& t) { return t.id.level; })
      .def_property_readonly("x", [](const TileInfo& t) { return t.id.x; })
      .def_property_readonly("y", [](const TileInfo& t) { return t.id.y; })
      .def_property_readonly("kind", [](const TileInfo& t) { return tileKindName(t.entry.kind); })
      .def_property_readonly("codec", [](const TileInfo& t) { return codecName(t.entry.codec); })
      .def_property_readonly("offset", [](const TileInfo& t) { return t.entry.offset_bytes; })
      .def_property_readonly("length", [](const TileInfo& t) { return t.entry.length_bytes; })
      .def("__repr__", [](const TileInfo& t) {
        return "<TileInfo (" + std::to_string(t.id.image) + "," + std::to_string(t.id.level) + "," +
               std::to_string(t.id.x) + "," + std::to_string(t.id.y) + ") " +
               tileKindName(t.entry.kind) + ">";
      });
}

void registerVerifyReport(py::module_& module) {
  py::class_<VerifyReport>(module, "VerifyReport", "What Archive.verify found.")
      .def_property_readonly("ok", &VerifyReport::ok)
      .def_readonly("tiles_checked", &VerifyReport::tiles_checked)
      .def_readonly("payloads_checked", &VerifyReport::payloads_checked)
      .def_readonly("payload_bytes", &VerifyReport::payload_bytes)
      .def_readonly("pages_checked", &VerifyReport::pages_checked)
      .def_readonly("fault_count", &VerifyReport::fault_count)
      .def_readonly("faults", &VerifyReport::faults);
}

}  // namespace

void registerArchive(py::module_& module) {
  registerImageInfo(module);
  registerTileInfo(module);
  registerVerifyReport(module);
  py::class_<Archive, std::shared_ptr<Archive>>(module, "Archive",
                                                "An opened archive; thread-safe.")
      .def_property_readonly("name", &Archive::name)
      .def_property_readonly("images", &Archive::images)
      .def_property_readonly("file_bytes", &Archive::fileBytes)
      .def_property_readonly("metadata", &metadata)
      .def_property_readonly("metadata_json", &Archive::metadataJson)
      .def("read_region", &readRegion, py::arg("level"), py::arg("x"), py::arg("y"),
           py::arg("width"), py::arg("height"), py::arg("image") = 0, py::arg("rgba") = false)
      .def("tile_info", &tileInfo, py::arg("level"), py::arg("x"), py::arg("y"),
           py::arg("image") = 0)
      .def("read_tile", &readTile, py::arg("level"), py::arg("x"), py::arg("y"),
           py::arg("image") = 0)
      .def("verify_report", &verify, py::arg("decode") = true, py::arg("progress") = py::none());
  module.def(
      "open_archive",
      [](const std::string& path_or_url) {
        Result<std::shared_ptr<Archive>> opened = std::shared_ptr<Archive>();
        {
          py::gil_scoped_release release;
          opened = openArchive(path_or_url);
        }
        return valueOrThrow(std::move(opened));
      },
      py::arg("path_or_url"));
}

}  // namespace tessera::python
