// Mesa's decoders as the independent reference for bc1 and bc7: tiles encoded by Tessera are
// uploaded as stored (glCompressedTexImage2D) and read back decompressed by the driver, which
// must agree with Tessera's CPU decoder. Skips, saying why, where the driver lacks the formats.
#include <epoxy/gl.h>

#include <cstdlib>
#include <vector>

#include <gtest/gtest.h>

#include "bc/bc.h"
#include "codecs/encode.h"
#include "gl_test_context.h"
#include "support/test_images.h"

namespace tessera::detail {
namespace {

// Defined by EXT_texture_compression_s3tc; epoxy's core headers may not name it.
constexpr GLenum kCompressedRgbS3tcDxt1 = 0x83F0;

/// The driver's RGBA decoding of `payload`, a `side` x `side` tile of `internal_format`.
std::vector<uint8_t> driverDecode(GLenum internal_format, const std::vector<uint8_t>& payload,
                                  uint32_t side) {
  const uint32_t padded = bcBlocksAlong(side) * kBcBlockSidePx;
  GLuint texture = 0;
  glGenTextures(1, &texture);
  glBindTexture(GL_TEXTURE_2D, texture);
  glCompressedTexImage2D(GL_TEXTURE_2D, 0, internal_format, GLsizei(padded), GLsizei(padded), 0,
                         GLsizei(payload.size()), payload.data());
  std::vector<uint8_t> rgba(size_t(padded) * padded * 4);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glGetTexImage(GL_TEXTURE_2D, 0, GL_RGBA, GL_UNSIGNED_BYTE, rgba.data());
  EXPECT_EQ(glGetError(), GLenum(GL_NO_ERROR));
  glDeleteTextures(1, &texture);
  return rgba;
}

void expectDriverAgrees(Codec codec, GLenum internal_format, int tolerance) {
  // A side that is a multiple of 4, so the padded texture is the tile itself.
  constexpr uint32_t kSide = 64;
  Image tile(kSide, kSide, 4);
  tile.texels = test::makeTestPixels(kSide, kSide, 4, 11);
  if (codec == Codec::kBc1)
    for (size_t i = 3; i < tile.texels.size(); i += 4) tile.texels[i] = 255;
  Image rgb_or_rgba = tile;
  if (codec == Codec::kBc1) {  // bc1 takes no alpha channel: give it the RGB
    rgb_or_rgba = Image(kSide, kSide, 3);
    for (size_t t = 0; t < size_t(kSide) * kSide; ++t)
      for (int c = 0; c < 3; ++c) rgb_or_rgba.texels[t * 3 + c] = tile.texels[t * 4 + c];
  }
  auto payload = encodeTile(codec, rgb_or_rgba.view(), {});
  ASSERT_TRUE(payload.has_value()) << payload.error().message;
  Image cpu(kSide, kSide, 4);
  ASSERT_TRUE(decodeTile(codec, *payload, cpu).has_value());
  const std::vector<uint8_t> gpu = driverDecode(internal_format, *payload, kSide);
  int worst = 0;
  for (size_t i = 0; i < gpu.size(); ++i) worst = std::max(worst, std::abs(gpu[i] - cpu.texels[i]));
  EXPECT_LE(worst, tolerance) << codecName(codec) << ": driver and CPU decoder differ";
}

TEST(BcUpload, DriverDecodesBc7AsTheCpuDecoderDoes) {
  test::sharedGlContext();
  if (!epoxy_has_gl_extension("GL_ARB_texture_compression_bptc") && epoxy_gl_version() < 42)
    GTEST_SKIP() << "the GL driver offers no BPTC (BC7) textures";
  // BC7's interpolation is exact in the specification: no tolerance.
  expectDriverAgrees(Codec::kBc7, GL_COMPRESSED_RGBA_BPTC_UNORM, 0);
}

TEST(BcUpload, DriverDecodesBc1AsTheCpuDecoderDoes) {
  test::sharedGlContext();
  if (!epoxy_has_gl_extension("GL_EXT_texture_compression_s3tc"))
    GTEST_SKIP() << "the GL driver offers no S3TC (BC1) textures (GL_EXT_texture_compression_s3tc)";
  // BC1 leaves the thirds' rounding to the implementation: one level either way.
  expectDriverAgrees(Codec::kBc1, kCompressedRgbS3tcDxt1, 1);
}

}  // namespace
}  // namespace tessera::detail
