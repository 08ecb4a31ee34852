// The backend table (as bgfx's s_rendererCreator): one row per RendererKind, in its order,
// with the name tools take and the function that creates it. A new backend adds its kind to
// tessera/renderer.h and its row here; the static_asserts catch a row missing or out of place.
#include <tessera/renderer.h>

#include <iterator>

#include <fmt/format.h>

#include "renderers.h"

namespace tessera {

namespace {

using CreateRenderer = Result<std::unique_ptr<Renderer>> (*)(const ImageInfo&,
                                                             const RendererOptions&);

struct RendererBackend {
  RendererKind kind;
  const char* name;
  CreateRenderer create;
};

constexpr RendererBackend kBackends[] = {
    {RendererKind::kTileQuads, "tile-quads", gl::createTileQuadsRenderer},
    {RendererKind::kClipmap, "clipmap", gl::createClipmapRenderer},
};

static_assert(std::size(kBackends) == size_t(RendererKind::kCount), "one row per RendererKind");

constexpr bool rowsInKindOrder() {
  for (size_t i = 0; i < std::size(kBackends); ++i)
    if (size_t(kBackends[i].kind) != i) return false;
  return true;
}
static_assert(rowsInKindOrder(), "the table is indexed by RendererKind: rows in its order");

}  // namespace

const char* rendererName(RendererKind kind) {
  return size_t(kind) < std::size(kBackends) ? kBackends[size_t(kind)].name : "unknown";
}

std::optional<RendererKind> rendererNamed(std::string_view name) {
  for (const RendererBackend& backend : kBackends)
    if (name == backend.name) return backend.kind;
  return std::nullopt;
}

Result<std::unique_ptr<Renderer>> createRenderer(RendererKind kind, const ImageInfo& info,
                                                 const RendererOptions& options) {
  if (size_t(kind) >= std::size(kBackends))
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("renderer kind {} is not in the backend table", int(kind)));
  if (info.channels < 1 || info.channels > 4 || info.tile_size_px == 0)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("{} renderer: image with {} channels and {} px tiles",
                            kBackends[size_t(kind)].name, info.channels, info.tile_size_px));
  return kBackends[size_t(kind)].create(info, options);
}

}  // namespace tessera
