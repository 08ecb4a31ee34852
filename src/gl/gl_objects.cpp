#include "gl/gl_objects.h"

#include <algorithm>
#include <cstring>
#include <vector>

#include <fmt/format.h>

namespace tessera::gl {

Texture createTexture(GLenum target) {
  GLuint name = 0;
  glCreateTextures(target, 1, &name);
  return Texture(name);
}

Buffer createBuffer() {
  GLuint name = 0;
  glCreateBuffers(1, &name);
  return Buffer(name);
}

VertexArray createVertexArray() {
  GLuint name = 0;
  glCreateVertexArrays(1, &name);
  return VertexArray(name);
}

Framebuffer createFramebuffer() {
  GLuint name = 0;
  glCreateFramebuffers(1, &name);
  return Framebuffer(name);
}

namespace {

Result<GLuint> compile(const char* name, GLenum stage, const std::string& source) {
  GLuint shader = glCreateShader(stage);
  const char* text = source.c_str();
  glShaderSource(shader, 1, &text, nullptr);
  glCompileShader(shader);
  GLint ok = 0;
  glGetShaderiv(shader, GL_COMPILE_STATUS, &ok);
  if (!ok) {
    GLint length = 0;
    glGetShaderiv(shader, GL_INFO_LOG_LENGTH, &length);
    std::string log(size_t(std::max(length, 1)), '\0');
    glGetShaderInfoLog(shader, length, nullptr, log.data());
    glDeleteShader(shader);
    return fail(ErrorCode::kInternal,
                fmt::format("{} {} shader does not compile: {}", name,
                            stage == GL_VERTEX_SHADER ? "vertex" : "fragment", log.c_str()));
  }
  return shader;
}

}  // namespace

Result<Program> linkProgram(const char* name, const std::string& vertex_source,
                            const std::string& fragment_source) {
  Result<GLuint> vertex = compile(name, GL_VERTEX_SHADER, vertex_source);
  if (!vertex) return forwardError(vertex);
  Result<GLuint> fragment = compile(name, GL_FRAGMENT_SHADER, fragment_source);
  if (!fragment) {
    glDeleteShader(*vertex);
    return forwardError(fragment);
  }
  Program program(glCreateProgram());
  glAttachShader(program.get(), *vertex);
  glAttachShader(program.get(), *fragment);
  glLinkProgram(program.get());
  glDeleteShader(*vertex);
  glDeleteShader(*fragment);
  GLint ok = 0;
  glGetProgramiv(program.get(), GL_LINK_STATUS, &ok);
  if (!ok) {
    GLint length = 0;
    glGetProgramiv(program.get(), GL_INFO_LOG_LENGTH, &length);
    std::string log(size_t(std::max(length, 1)), '\0');
    glGetProgramInfoLog(program.get(), length, nullptr, log.data());
    return fail(ErrorCode::kInternal,
                fmt::format("{} program does not link: {}", name, log.c_str()));
  }
  return program;
}

GLenum tilePixelFormat(uint32_t channels) {
  switch (channels) {
    case 1: return GL_RED;
    case 2: return GL_RG;
    case 3: return GL_RGB;
    default: return GL_RGBA;
  }
}

GLenum tileInternalFormat(uint32_t channels) {
  static const GLenum kInternal[] = {GL_R8, GL_RG8, GL_RGB8, GL_RGBA8};
  return kInternal[std::clamp<uint32_t>(channels, 1, 4) - 1];
}

void setChannelSwizzle(const Texture& texture, uint32_t channels) {
  static const GLint kSwizzles[4][4] = {{GL_RED, GL_RED, GL_RED, GL_ONE},
                                        {GL_RED, GL_RED, GL_RED, GL_GREEN},
                                        {GL_RED, GL_GREEN, GL_BLUE, GL_ONE},
                                        {GL_RED, GL_GREEN, GL_BLUE, GL_ALPHA}};
  glTextureParameteriv(texture.get(), GL_TEXTURE_SWIZZLE_RGBA,
                       kSwizzles[std::clamp<uint32_t>(channels, 1, 4) - 1]);
}

TileTexelFormat tileTexelFormat(uint32_t channels, SampleType type) {
  static const GLenum kU16[] = {GL_R16, GL_RG16, GL_RGB16, GL_RGBA16};
  static const GLenum kF32[] = {GL_R32F, GL_RG32F, GL_RGB32F, GL_RGBA32F};
  const uint32_t index = std::clamp<uint32_t>(channels, 1, 4) - 1;
  switch (type) {
    case SampleType::kU16: return {kU16[index], tilePixelFormat(channels), GL_UNSIGNED_SHORT};
    case SampleType::kF32: return {kF32[index], tilePixelFormat(channels), GL_FLOAT};
    default: return {tileInternalFormat(channels), tilePixelFormat(channels), GL_UNSIGNED_BYTE};
  }
}

Texture createTileArray(uint32_t channels, SampleType type, GLsizei side, GLsizei layers) {
  Texture texture = createTexture(GL_TEXTURE_2D_ARRAY);
  while (glGetError() != GL_NO_ERROR) {
  }
  glTextureStorage3D(texture.get(), 1, tileTexelFormat(channels, type).internal_format, side, side,
                     layers);
  if (glGetError() != GL_NO_ERROR) return Texture();
  glTextureParameteri(texture.get(), GL_TEXTURE_MIN_FILTER, GL_LINEAR);
  glTextureParameteri(texture.get(), GL_TEXTURE_MAG_FILTER, GL_LINEAR);
  glTextureParameteri(texture.get(), GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
  glTextureParameteri(texture.get(), GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  setChannelSwizzle(texture, channels);
  return texture;
}

GLenum blockInternalFormat(Codec codec) {
  // EXT_texture_compression_s3tc's value: epoxy's core headers may not name it.
  constexpr GLenum kCompressedRgbS3tcDxt1 = 0x83F0;
  if (codec == Codec::kBc1 && epoxy_has_gl_extension("GL_EXT_texture_compression_s3tc"))
    return kCompressedRgbS3tcDxt1;
  if (codec == Codec::kBc7 &&
      (epoxy_gl_version() >= 42 || epoxy_has_gl_extension("GL_ARB_texture_compression_bptc")))
    return GL_COMPRESSED_RGBA_BPTC_UNORM;
  return 0;
}

Texture createBlockTileArray(GLenum internal_format, uint32_t channels, GLsizei side,
                             GLsizei layers) {
  Texture texture = createTexture(GL_TEXTURE_2D_ARRAY);
  while (glGetError() != GL_NO_ERROR) {
  }
  glTextureStorage3D(texture.get(), 1, internal_format, side, side, layers);
  if (glGetError() != GL_NO_ERROR) return Texture();
  glTextureParameteri(texture.get(), GL_TEXTURE_MIN_FILTER, GL_LINEAR);
  glTextureParameteri(texture.get(), GL_TEXTURE_MAG_FILTER, GL_LINEAR);
  glTextureParameteri(texture.get(), GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
  glTextureParameteri(texture.get(), GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  setChannelSwizzle(texture, channels);
  return texture;
}

void UploadStaging::stage(const std::vector<std::pair<const uint8_t*, size_t>>& sources) {
  if (!buffer_) buffer_ = createBuffer();
  size_t total = 0;
  for (const auto& source : sources) total += source.second;
  glNamedBufferData(buffer_.get(), GLsizeiptr(std::max<size_t>(total, 1)), nullptr, GL_STREAM_DRAW);
  if (total > 0) {
    auto* mapped = static_cast<uint8_t*>(glMapNamedBufferRange(
        buffer_.get(), 0, GLsizeiptr(total), GL_MAP_WRITE_BIT | GL_MAP_INVALIDATE_BUFFER_BIT));
    size_t offset = 0;
    for (const auto& [data, length] : sources) {
      std::memcpy(mapped + offset, data, length);
      offset += length;
    }
    glUnmapNamedBuffer(buffer_.get());
  }
  glBindBuffer(GL_PIXEL_UNPACK_BUFFER, buffer_.get());
  glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
}

void UploadStaging::unbind() {
  glBindBuffer(GL_PIXEL_UNPACK_BUFFER, 0);
}

void ColourTarget::bind(uint32_t width, uint32_t height, bool with_depth) {
  if (width != width_ || height != height_ || !framebuffer_ || with_depth != bool(depth_)) {
    colour_ = createTexture(GL_TEXTURE_2D);
    glTextureStorage2D(colour_.get(), 1, GL_RGBA8, GLsizei(width), GLsizei(height));
    framebuffer_ = createFramebuffer();
    glNamedFramebufferTexture(framebuffer_.get(), GL_COLOR_ATTACHMENT0, colour_.get(), 0);
    depth_.reset();
    if (with_depth) {
      GLuint name = 0;
      glCreateRenderbuffers(1, &name);
      depth_ = Renderbuffer(name);
      glNamedRenderbufferStorage(name, GL_DEPTH_COMPONENT24, GLsizei(width), GLsizei(height));
      glNamedFramebufferRenderbuffer(framebuffer_.get(), GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER,
                                     name);
    }
    width_ = width;
    height_ = height;
  }
  glBindFramebuffer(GL_FRAMEBUFFER, framebuffer_.get());
  glViewport(0, 0, GLsizei(width), GLsizei(height));
}

void ColourTarget::read(std::vector<uint8_t>& rgba) const {
  rgba.resize(size_t(width_) * height_ * 4);
  if (rgba.empty()) return;
  glBindFramebuffer(GL_READ_FRAMEBUFFER, framebuffer_.get());
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadPixels(0, 0, GLsizei(width_), GLsizei(height_), GL_RGBA, GL_UNSIGNED_BYTE, rgba.data());
  // OpenGL's rows run bottom to top; pictures run top to bottom.
  const size_t row = size_t(width_) * 4;
  std::vector<uint8_t> swap(row);
  for (uint32_t y = 0; y < height_ / 2; ++y) {
    uint8_t* a = rgba.data() + y * row;
    uint8_t* b = rgba.data() + (height_ - 1 - y) * row;
    std::memcpy(swap.data(), a, row);
    std::memcpy(a, b, row);
    std::memcpy(b, swap.data(), row);
  }
}

void ColourTarget::blitToWindow(uint32_t window_width, uint32_t window_height) const {
  glBlitNamedFramebuffer(framebuffer_.get(), 0, 0, 0, GLsizei(width_), GLsizei(height_), 0, 0,
                         GLsizei(window_width), GLsizei(window_height), GL_COLOR_BUFFER_BIT,
                         GL_LINEAR);
}

}  // namespace tessera::gl
