#pragma once
/// \file
/// The OpenGL backend (OpenGL 4.5 core, loaded with libepoxy; library tessera::gl): a
/// context, headless through EGL on the surfaceless platform (Mesa llvmpipe in CI, no display)
/// or windowed, for the renderers of the `kTileQuads` and `kClipmap` rows of the backend table
/// (tessera/renderer.h): `createRenderer` makes them on the thread where a context is current.

#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include <tessera/procedural.h>
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

/// Composites procedural tiles (tessera/procedural.h) in a fragment shader: the same inputs as
/// compositeTile (the instances of a tile after the query, in drawing order, their clips, the
/// brush set's mip pyramids and layers) and the same integer arithmetic texel by texel (mip
/// choice, sample positions, filter weights, blend rounding: everything compositeTile computes
/// after the per-instance setup, which this class runs on the CPU through the same code), so a
/// composited tile equals compositeTile's (the contract is within 1 per channel; the tests
/// measure the difference). Needs OpenGL 4.5 with GL_ARB_gpu_shader_int64 (64-bit integers in
/// shaders: the brush coordinates are 16.16 fixed point of up to 64 bits). Owned by the thread
/// whose context is current at `create`; it binds its own program, framebuffer and buffers.
class GpuCompositor {
 public:
  /// Compiles the shader and uploads the set's brush pyramids, mask tables and layer pyramids.
  /// Fails (kUnsupported) without the int64 extension or when the set exceeds the driver's
  /// largest storage buffer.
  [[nodiscard]] static Result<std::unique_ptr<GpuCompositor>> create(
      std::shared_ptr<const BrushSet> brushes);
  ~GpuCompositor();
  GpuCompositor(const GpuCompositor&) = delete;
  GpuCompositor& operator=(const GpuCompositor&) = delete;

  /// compositeTile's contract on the GPU: `out` becomes the stored tile (sidePx() square,
  /// 4 channels); an instance naming a brush the set lacks fails the tile (kCorrupt).
  [[nodiscard]] Result<void> compositeTile(const TileGeometry& tile,
                                           std::span<const BrushInstance> instances, Image& out,
                                           std::span<const TileClip> clips = {});
  const BrushSet& brushSet() const;

  struct Impl;

 private:
  explicit GpuCompositor(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// A TileCompositor (tessera/procedural.h) that composites on the GPU, for
/// Archive::setTileCompositor: a thread of its own holding a headless context and one
/// GpuCompositor per brush set; the threads that decode tiles (the loader pool) wait for their
/// tile, the render thread never calls it. Fails (kUnsupported) naming what is missing.
[[nodiscard]] Result<std::shared_ptr<TileCompositor>> createGpuTileCompositor();

}  // namespace tessera
