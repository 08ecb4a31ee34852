#pragma once
// Typed owners of OpenGL objects: each deletes its object with the matching glDelete*, so a
// texture can never be passed where a buffer is expected and nothing leaks on an early return.

#include <epoxy/gl.h>

#include <string>
#include <cstdint>
#include <utility>
#include <vector>

#include <tessera/format.h>
#include <tessera/result.h>

namespace tessera::gl {

template <void (*Delete)(GLuint)>
class Object {
 public:
  Object() = default;
  explicit Object(GLuint name) : name_(name) {}
  ~Object() { reset(); }
  Object(Object&& other) noexcept : name_(std::exchange(other.name_, 0)) {}
  Object& operator=(Object&& other) noexcept {
    if (this != &other) {
      reset();
      name_ = std::exchange(other.name_, 0);
    }
    return *this;
  }
  Object(const Object&) = delete;
  Object& operator=(const Object&) = delete;

  GLuint get() const { return name_; }
  explicit operator bool() const { return name_ != 0; }
  void reset() {
    if (name_) Delete(name_);
    name_ = 0;
  }

 private:
  GLuint name_ = 0;
};

namespace detail {
inline void deleteTexture(GLuint n) {
  glDeleteTextures(1, &n);
}
inline void deleteBuffer(GLuint n) {
  glDeleteBuffers(1, &n);
}
inline void deleteVertexArray(GLuint n) {
  glDeleteVertexArrays(1, &n);
}
inline void deleteFramebuffer(GLuint n) {
  glDeleteFramebuffers(1, &n);
}
inline void deleteProgram(GLuint n) {
  glDeleteProgram(n);
}
inline void deleteRenderbuffer(GLuint n) {
  glDeleteRenderbuffers(1, &n);
}
}  // namespace detail

using Texture = Object<detail::deleteTexture>;
using Buffer = Object<detail::deleteBuffer>;
using VertexArray = Object<detail::deleteVertexArray>;
using Framebuffer = Object<detail::deleteFramebuffer>;
using Program = Object<detail::deleteProgram>;
using Renderbuffer = Object<detail::deleteRenderbuffer>;

/// Creates a texture of `target` (direct state access).
Texture createTexture(GLenum target);
Buffer createBuffer();
VertexArray createVertexArray();
Framebuffer createFramebuffer();

/// Compiles and links a vertex and fragment shader; the error carries the driver's log.
[[nodiscard]] Result<Program> linkProgram(const char* name, const std::string& vertex_source,
                                          const std::string& fragment_source);

/// Pixel transfer format of a tile with `channels` channels: GL_RED, GL_RG, GL_RGB, GL_RGBA.
GLenum tilePixelFormat(uint32_t channels);

/// Internal format that stores texels of `channels` channels as they come: GL_R8 ... GL_RGBA8.
GLenum tileInternalFormat(uint32_t channels);
/// Sets the swizzle that shows grey as (g, g, g, 1), grey+alpha as (g, g, g, a) and RGB as
/// opaque, as tessera/render.h's Picture does.
void setChannelSwizzle(const Texture& texture, uint32_t channels);

/// How tiles of a sample type travel to the GPU and are held there, samples as stored: u8 as
/// GL_R8 ... GL_RGBA8, u16 as GL_R16 ... GL_RGBA16 (normalised: v / 65535), f32 as GL_R32F ...
/// GL_RGBA32F. The shaders' display window maps them back to sample values (renderer_base).
struct TileTexelFormat {
  GLenum internal_format = GL_R8;  ///< for glTextureStorage*
  GLenum pixel_format = GL_RED;    ///< GL_RED ... GL_RGBA, for pixel transfers
  GLenum pixel_type = GL_UNSIGNED_BYTE;
};
TileTexelFormat tileTexelFormat(uint32_t channels, SampleType type);

/// A 2D array texture that stores tiles of `channels` channels of `type` as they are stored
/// (tileTexelFormat), with a swizzle that shows grey as (g, g, g, 1), grey+alpha as
/// (g, g, g, a) and RGB as opaque, as tessera/render.h's Picture does. Linear filtering,
/// clamped at the edges. Null when the driver cannot allocate it.
Texture createTileArray(uint32_t channels, SampleType type, GLsizei side, GLsizei layers);

/// The block-compressed internal format a tile array of `codec` tiles (bc1, bc7) takes, when
/// the current context samples it: bc1 as GL_COMPRESSED_RGB_S3TC_DXT1_EXT (its three-colour
/// blocks opaque black, as the CPU decoder gives RGB), with GL_EXT_texture_compression_s3tc;
/// bc7 as GL_COMPRESSED_RGBA_BPTC_UNORM, with OpenGL 4.2 or GL_ARB_texture_compression_bptc.
/// 0 for any other codec or without the extension.
GLenum blockInternalFormat(Codec codec);

/// As createTileArray, for tiles uploaded as stored blocks of `internal_format`
/// (blockInternalFormat); `side` is a multiple of 4. Null when the driver cannot allocate it.
Texture createBlockTileArray(GLenum internal_format, uint32_t channels, GLsizei side,
                             GLsizei layers);

/// A frame's upload staging: the bytes of every tile copied into one pixel-unpack buffer,
/// orphaned each frame so the driver never waits for the previous frame's transfer.
class UploadStaging {
 public:
  /// Copies `sources` (pointer, length) one after the other and leaves the buffer bound as
  /// GL_PIXEL_UNPACK_BUFFER; texture updates then take their offsets as pointers.
  void stage(const std::vector<std::pair<const uint8_t*, size_t>>& sources);
  /// Unbinds the buffer (later pixel transfers read client memory again).
  void unbind();

 private:
  Buffer buffer_;
};

/// An RGBA8 colour target of a given size, drawn into and read back.
class ColourTarget {
 public:
  /// (Re)allocates when the size (or `with_depth`) changes; binds it for drawing with the
  /// viewport set. `with_depth` adds a 24-bit depth buffer (the scene renderer's).
  void bind(uint32_t width, uint32_t height, bool with_depth = false);
  /// Reads the picture back, rows top to bottom.
  void read(std::vector<uint8_t>& rgba) const;
  /// Blits to the default framebuffer, scaled to the window.
  void blitToWindow(uint32_t window_width, uint32_t window_height) const;
  uint32_t width() const { return width_; }
  uint32_t height() const { return height_; }

 private:
  Texture colour_;
  Framebuffer framebuffer_;
  Renderbuffer depth_;
  uint32_t width_ = 0, height_ = 0;
};

}  // namespace tessera::gl
