#pragma once
/// \file
/// The OpenGL backend (OpenGL 4.5 core, loaded with libepoxy; library tessera::gl): a
/// context, headless through EGL on the surfaceless platform (Mesa llvmpipe in CI, no display)
/// or windowed, for the renderers of the `kTileQuads` and `kClipmap` rows of the backend table
/// (tessera/renderer.h): `createRenderer` makes them on the thread where a context is current.

#include <cstdint>
#include <memory>
#include <string>

#include <tessera/renderer.h>
#include <tessera/result.h>

namespace tessera {

/// The window of a windowed context, opaque here: the tools' viewer reads the windowing
/// library's handle from it through the gl module's own header (gl/window.h).
struct GlWindow;

/// An OpenGL 4.5 core context, current on the thread that created it. Owned by one thread:
/// the one it is current on; `makeCurrent` moves it.
class GlContext {
 public:
  /// A context with no window or display: EGL's surfaceless platform (Mesa). Renderers draw
  /// into framebuffers of their own. Fails naming what is missing (no EGL, no driver, no 4.5).
  [[nodiscard]] static Result<std::unique_ptr<GlContext>> createHeadless();
  /// A window (GLFW) with its context current. Fails when there is no display (the message
  /// says so and points to the headless `tessera fly`).
  [[nodiscard]] static Result<std::unique_ptr<GlContext>> createWindow(uint32_t width,
                                                                       uint32_t height,
                                                                       const std::string& title);
  ~GlContext();
  GlContext(const GlContext&) = delete;
  GlContext& operator=(const GlContext&) = delete;

  /// Makes this context current on the calling thread.
  void makeCurrent();
  /// GL_RENDERER and GL_VERSION, e.g. "llvmpipe (LLVM 15.0.6, 256 bits), 4.5 (Core Profile)".
  std::string description() const;
  /// The window, or null for a headless context. Owned by this context, valid while it lives.
  GlWindow* window() const;

 private:
  struct Impl;
  explicit GlContext(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace tessera
