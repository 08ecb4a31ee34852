#include <fmt/format.h>

#include <tessera/gl.h>

#include "gl/renderers.h"

namespace tessera {

namespace gl {

Picture TargetRenderer::readPixels() {
  Picture picture;
  picture.width = target_.width();
  picture.height = target_.height();
  target_.read(picture.rgba);
  return picture;
}

void TargetRenderer::present(uint32_t window_width, uint32_t window_height) {
  target_.blitToWindow(window_width, window_height);
}

}  // namespace gl

Result<std::unique_ptr<GlRenderer>> GlRenderer::create(RendererKind kind, const ImageInfo& info,
                                                       const GlRendererOptions& options) {
  if (info.channels < 1 || info.channels > 4 || info.tile_size_px == 0)
    return fail(ErrorCode::kInvalidArgument,
                fmt::format("renderer: image with {} channels and {} px tiles", info.channels,
                            info.tile_size_px));
  switch (kind) {
    case RendererKind::kTileQuads: return gl::createTileQuadsRenderer(info, options);
    case RendererKind::kClipmap: return gl::createClipmapRenderer(info, options);
  }
  return fail(ErrorCode::kInvalidArgument, "unknown renderer kind");
}

}  // namespace tessera
