#include "codecs/encode.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <turbojpeg.h>
#include <zstd.h>

#include "support/test_images.h"

namespace tessera::detail {
namespace {

// ptm without a parent codes the tile on its own (the coarsest level's mode), so every generic
// test below covers that mode; codec_ptm_test.cpp covers coding against a parent.
constexpr Codec kLosslessCodecs[] = {Codec::kRaw,  Codec::kZstd, Codec::kLz4,   Codec::kPng,
                                     Codec::kWebp, Codec::kPtm,  Codec::kZdelta};
constexpr Codec kAllCodecs[] = {Codec::kRaw, Codec::kZstd, Codec::kLz4, Codec::kJpeg,
                                Codec::kPng, Codec::kWebp, Codec::kPtm, Codec::kZdelta};

struct Size {
  uint32_t width_px;
  uint32_t height_px;
};
constexpr Size kSizes[] = {{1, 1}, {3, 5}, {64, 64}, {258, 258}};

using test::nextRandom;

// Photo-like texels: smooth low-frequency shading, a hard-edged disk, and a little sensor
// noise, so compressors see the statistics of real tiles rather than flat or random data.
// Alpha, when present, is a ramp with fully transparent and fully opaque areas.
Image makeImageLike(uint32_t width, uint32_t height, uint32_t channels, uint32_t seed = 1) {
  Image image(width, height, channels);
  uint32_t random = seed * 2654435761u + 1;
  const float cx = width * 0.6f, cy = height * 0.4f, radius = std::min(width, height) * 0.25f;
  for (uint32_t y = 0; y < height; ++y) {
    for (uint32_t x = 0; x < width; ++x) {
      const bool inside = (x - cx) * (x - cx) + (y - cy) * (y - cy) < radius * radius;
      uint8_t* texel = image.row(y) + size_t(x) * channels;
      const uint32_t colour_channels = channels == 2 || channels == 4 ? channels - 1 : channels;
      for (uint32_t c = 0; c < colour_channels; ++c) {
        float value = 120 + 50 * std::sin(x * 0.031f + c * 1.7f + seed) * std::cos(y * 0.023f) +
                      25 * std::sin((x + 2 * y) * 0.011f * (c + 1));
        if (inside) value = 220 - c * 40 + 0.2f * value;
        value += float(int(nextRandom(random) % 7) - 3);
        texel[c] = uint8_t(std::clamp(value, 0.0f, 255.0f));
      }
      if (colour_channels != channels) {
        const int ramp = int(x * 512 / std::max(width, 1u)) - 128;
        texel[channels - 1] = uint8_t(std::clamp(ramp, 0, 255));
      }
    }
  }
  return image;
}

// The same texels with `pad` junk bytes after every row.
struct StridedCopy {
  std::vector<uint8_t> bytes;
  ImageView view;
};
StridedCopy stridedCopy(const Image& image, size_t pad) {
  StridedCopy copy;
  const size_t row_bytes = image.strideBytes();
  const size_t stride = row_bytes + pad;
  copy.bytes.assign(stride * image.height_px, 0xA5);
  for (uint32_t y = 0; y < image.height_px; ++y)
    std::memcpy(copy.bytes.data() + y * stride, image.row(y), row_bytes);
  copy.view = {copy.bytes.data(), image.width_px, image.height_px, image.channels, stride};
  return copy;
}

std::vector<uint8_t> encodeOrDie(Codec codec, const ImageView& view,
                                 const EncodeOptions& options = {},
                                 CodecScratch* scratch = nullptr) {
  auto payload = encodeTile(codec, view, options, nullptr, scratch);
  EXPECT_TRUE(payload.has_value()) << (payload ? "" : payload.error().message);
  return payload ? std::move(payload).value() : std::vector<uint8_t>{};
}

double psnr(const Image& a, const Image& b, bool skip_alpha = false) {
  double squared = 0;
  size_t count = 0;
  for (size_t i = 0; i < a.texels.size(); ++i) {
    const bool is_alpha = (a.channels == 2 || a.channels == 4) && i % a.channels == a.channels - 1;
    if (skip_alpha && is_alpha) continue;
    const double d = double(a.texels[i]) - double(b.texels[i]);
    squared += d * d;
    ++count;
  }
  if (squared == 0) return 1e9;
  return 10 * std::log10(255.0 * 255.0 / (squared / double(count)));
}

// Every prefix length for small payloads; for big ones every length within `dense` of either
// end, where headers and end markers live, and about `dense` more spread evenly between, which
// keeps each loop around a second under ASan.
std::vector<size_t> truncationLengths(size_t size, size_t dense) {
  std::vector<size_t> lengths;
  if (size <= 3 * dense) {
    for (size_t n = 0; n < size; ++n) lengths.push_back(n);
    return lengths;
  }
  for (size_t n = 0; n < dense; ++n) lengths.push_back(n);
  const size_t step = std::max<size_t>(1, (size - 2 * dense) / dense);
  for (size_t n = dense; n < size - dense; n += step) lengths.push_back(n);
  for (size_t n = size - dense; n < size; ++n) lengths.push_back(n);
  return lengths;
}

std::string trace(Codec codec, uint32_t width, uint32_t height, uint32_t channels) {
  return std::string(codecName(codec)) + " " + std::to_string(width) + "x" +
         std::to_string(height) + "x" + std::to_string(channels);
}

TEST(Codec, LosslessCodecsRoundTripBitExactForEverySizeAndChannelCount) {
  CodecScratch scratch;
  for (Codec codec : kLosslessCodecs) {
    for (Size size : kSizes) {
      for (uint32_t channels = 1; channels <= 4; ++channels) {
        SCOPED_TRACE(trace(codec, size.width_px, size.height_px, channels));
        Image image = makeImageLike(size.width_px, size.height_px, channels);
        std::vector<uint8_t> payload = encodeOrDie(codec, image.view(), {}, &scratch);
        Image decoded(size.width_px, size.height_px, channels);
        auto result = decodeTile(codec, payload, decoded, nullptr, &scratch);
        ASSERT_TRUE(result.has_value()) << result.error().message;
        EXPECT_EQ(decoded.texels, image.texels);
      }
    }
  }
}

TEST(Codec, DecodeWritesEveryTexelOfAReusedBuffer) {
  // The streamer decodes into recycled tile buffers without clearing them: a codec that left
  // any texel alone would show the previous tile's texels there.
  CodecScratch scratch;
  for (Codec codec : kAllCodecs) {
    for (Size size : kSizes) {
      for (uint32_t channels = 1; channels <= 4; ++channels) {
        SCOPED_TRACE(trace(codec, size.width_px, size.height_px, channels));
        Image image = makeImageLike(size.width_px, size.height_px, channels, 5);
        std::vector<uint8_t> payload = encodeOrDie(codec, image.view(), {}, &scratch);
        Image cleared(size.width_px, size.height_px, channels);
        ASSERT_TRUE(decodeTile(codec, payload, cleared, nullptr, &scratch).has_value());
        for (uint8_t garbage : {uint8_t{0xAB}, uint8_t{0xFF}}) {
          Image reused(size.width_px, size.height_px, channels);
          std::fill(reused.texels.begin(), reused.texels.end(), garbage);
          ASSERT_TRUE(decodeTile(codec, payload, reused, nullptr, &scratch).has_value());
          EXPECT_EQ(reused.texels, cleared.texels) << "garbage " << int(garbage);
        }
      }
    }
  }
}

TEST(Codec, LosslessCodecsRoundTripStridedInput) {
  for (Codec codec : kLosslessCodecs) {
    for (uint32_t channels = 1; channels <= 4; ++channels) {
      SCOPED_TRACE(trace(codec, 67, 33, channels));
      Image image = makeImageLike(67, 33, channels, 7);
      StridedCopy strided = stridedCopy(image, 13);
      std::vector<uint8_t> payload = encodeOrDie(codec, strided.view);
      // The padding must not leak into the payload: the packed image encodes identically.
      if (codec != Codec::kWebp) {
        EXPECT_EQ(payload, encodeOrDie(codec, image.view()));
      }
      Image decoded(67, 33, channels);
      auto result = decodeTile(codec, payload, decoded);
      ASSERT_TRUE(result.has_value()) << result.error().message;
      EXPECT_EQ(decoded.texels, image.texels);
    }
  }
}

TEST(Codec, LosslessCodecsRoundTripNoiseAndFlatTiles) {
  for (Codec codec : kLosslessCodecs) {
    for (uint32_t channels = 1; channels <= 4; ++channels) {
      SCOPED_TRACE(trace(codec, 64, 64, channels));
      Image noise(64, 64, channels);
      uint32_t random = 99;
      for (uint8_t& texel : noise.texels) texel = uint8_t(nextRandom(random));
      Image flat(64, 64, channels);
      std::fill(flat.texels.begin(), flat.texels.end(), 0);
      for (const Image* image : {&noise, &flat}) {
        std::vector<uint8_t> payload = encodeOrDie(codec, image->view());
        Image decoded(64, 64, channels);
        auto result = decodeTile(codec, payload, decoded);
        ASSERT_TRUE(result.has_value()) << result.error().message;
        EXPECT_EQ(decoded.texels, image->texels);
      }
    }
  }
}

TEST(Codec, EveryEffortRoundTripsExactly) {
  Image image = makeImageLike(64, 64, 3);
  for (Codec codec : {Codec::kZstd, Codec::kPng, Codec::kWebp}) {
    for (int effort : {1, 5, 9}) {
      SCOPED_TRACE(trace(codec, 64, 64, 3) + " effort " + std::to_string(effort));
      EncodeOptions options;
      options.effort = effort;
      std::vector<uint8_t> payload = encodeOrDie(codec, image.view(), options);
      Image decoded(64, 64, 3);
      ASSERT_TRUE(decodeTile(codec, payload, decoded).has_value());
      EXPECT_EQ(decoded.texels, image.texels);
    }
  }
}

TEST(Codec, ScratchIsOptionalAndReusableAcrossCodecsAndSizes) {
  CodecScratch scratch;
  for (int round = 0; round < 2; ++round) {
    for (Codec codec : kAllCodecs) {
      for (Size size : {Size{258, 258}, Size{3, 5}, Size{64, 64}}) {
        SCOPED_TRACE(trace(codec, size.width_px, size.height_px, 4));
        Image image = makeImageLike(size.width_px, size.height_px, 4, round);
        std::vector<uint8_t> with_scratch = encodeOrDie(codec, image.view(), {}, &scratch);
        EXPECT_EQ(with_scratch, encodeOrDie(codec, image.view()));
        Image a(size.width_px, size.height_px, 4), b(size.width_px, size.height_px, 4);
        ASSERT_TRUE(decodeTile(codec, with_scratch, a, nullptr, &scratch).has_value());
        ASSERT_TRUE(decodeTile(codec, with_scratch, b).has_value());
        EXPECT_EQ(a.texels, b.texels);
      }
    }
  }
}

TEST(Codec, TablesDescribeEveryImplementedCodec) {
  for (Codec codec : kAllCodecs) {
    const CodecDecoder* decoder = findDecoder(codec);
    const CodecEncoder* encoder = findEncoder(codec);
    ASSERT_NE(decoder, nullptr) << codecName(codec);
    ASSERT_NE(encoder, nullptr) << codecName(codec);
    EXPECT_EQ(decoder->codec, codec);
    EXPECT_EQ(encoder->codec, codec);
    EXPECT_EQ(codecNeedsParent(codec), codec == Codec::kPtm);
    EXPECT_EQ(codecIsLossless(codec), codec != Codec::kJpeg);
  }
}

TEST(Codec, UnknownCodecValueIsUnsupported) {
  Image image(4, 4, 1);
  std::vector<uint8_t> payload(16, 0);
  EXPECT_EQ(findDecoder(Codec(200)), nullptr);
  EXPECT_EQ(findEncoder(Codec(200)), nullptr);
  auto decoded = decodeTile(Codec(200), payload, image);
  ASSERT_FALSE(decoded.has_value());
  EXPECT_EQ(decoded.error().code, ErrorCode::kUnsupported);
}

TEST(Codec, JpegRoundTripPsnrIsHighAndImprovesWithQuality) {
  for (uint32_t channels : {1u, 3u}) {
    for (bool subsampling : {true, false}) {
      SCOPED_TRACE(trace(Codec::kJpeg, 256, 256, channels) + (subsampling ? " 4:2:0" : " 4:4:4"));
      Image image = makeImageLike(256, 256, channels);
      double previous_psnr = 0;
      size_t previous_bytes = 0;
      for (int quality : {50, 85, 95}) {
        EncodeOptions options;
        options.quality = quality;
        options.chroma_subsampling = subsampling;
        std::vector<uint8_t> payload = encodeOrDie(Codec::kJpeg, image.view(), options);
        Image decoded(256, 256, channels);
        auto result = decodeTile(Codec::kJpeg, payload, decoded);
        ASSERT_TRUE(result.has_value()) << result.error().message;
        const double db = psnr(image, decoded);
        EXPECT_GT(db, previous_psnr) << "quality " << quality;
        EXPECT_GT(payload.size(), previous_bytes) << "quality " << quality;
        if (quality == 85) {
          EXPECT_GT(db, 36.0);
        } else if (quality == 95) {
          EXPECT_GT(db, 38.0);
        }
        previous_psnr = db;
        previous_bytes = payload.size();
      }
    }
  }
}

TEST(Codec, JpegHandlesEverySizeChannelCountAndStride) {
  CodecScratch scratch;
  for (Size size : kSizes) {
    for (uint32_t channels = 1; channels <= 4; ++channels) {
      SCOPED_TRACE(trace(Codec::kJpeg, size.width_px, size.height_px, channels));
      Image image = makeImageLike(size.width_px, size.height_px, channels, 3);
      StridedCopy strided = stridedCopy(image, 5);
      std::vector<uint8_t> payload = encodeOrDie(Codec::kJpeg, strided.view, {}, &scratch);
      EXPECT_EQ(payload, encodeOrDie(Codec::kJpeg, image.view(), {}, &scratch));
      Image decoded(size.width_px, size.height_px, channels);
      auto result = decodeTile(Codec::kJpeg, payload, decoded, nullptr, &scratch);
      ASSERT_TRUE(result.has_value()) << result.error().message;
      // Tiny tiles are all edge, where 4:2:0 chroma hurts most; the 256-px test above holds
      // the tight bounds.
      EXPECT_GT(psnr(image, decoded, /*skip_alpha=*/true), size.width_px >= 64 ? 30.0 : 20.0);
    }
  }
}

TEST(Codec, JpegKeepsAlphaExactly) {
  for (uint32_t channels : {2u, 4u}) {
    SCOPED_TRACE(trace(Codec::kJpeg, 258, 258, channels));
    Image image = makeImageLike(258, 258, channels);
    std::vector<uint8_t> payload = encodeOrDie(Codec::kJpeg, image.view());
    Image decoded(258, 258, channels);
    ASSERT_TRUE(decodeTile(Codec::kJpeg, payload, decoded).has_value());
    for (size_t i = channels - 1; i < image.texels.size(); i += channels)
      ASSERT_EQ(decoded.texels[i], image.texels[i]) << "texel " << i / channels;
  }
}

TEST(Codec, JpegOpaqueAlphaCostsOnlyAFewBytes) {
  Image rgba = makeImageLike(256, 256, 4);
  Image rgb(256, 256, 3);
  for (size_t i = 0; i < size_t(256) * 256; ++i) {
    rgba.texels[4 * i + 3] = 255;
    std::memcpy(&rgb.texels[3 * i], &rgba.texels[4 * i], 3);
  }
  const size_t with_alpha = encodeOrDie(Codec::kJpeg, rgba.view()).size();
  const size_t without = encodeOrDie(Codec::kJpeg, rgb.view()).size();
  EXPECT_LE(with_alpha, without + 32);
}

TEST(Codec, JpegDecodeNamesBothGeometriesOnMismatch) {
  Image image = makeImageLike(256, 256, 3);
  std::vector<uint8_t> payload = encodeOrDie(Codec::kJpeg, image.view());
  Image wrong(258, 258, 3);
  auto result = decodeTile(Codec::kJpeg, payload, wrong);
  ASSERT_FALSE(result.has_value());
  EXPECT_EQ(result.error().code, ErrorCode::kCorrupt);
  EXPECT_EQ(result.error().message, "jpeg payload: 258x258x3 expected, stream is 256x256x3");
}

TEST(Codec, DecodeRejectsWrongDimensionsOrChannels) {
  for (Codec codec : kAllCodecs) {
    for (uint32_t channels = 1; channels <= 4; ++channels) {
      SCOPED_TRACE(trace(codec, 40, 24, channels));
      Image image = makeImageLike(40, 24, channels);
      std::vector<uint8_t> payload = encodeOrDie(codec, image.view());
      // Each wrong geometry has a different byte count, so even raw can tell.
      const Image wrong_geometries[] = {Image(41, 24, channels), Image(40, 23, channels),
                                        Image(24, 41, channels), Image(40, 24, channels % 4 + 1)};
      for (const Image& wrong_template : wrong_geometries) {
        Image wrong = wrong_template;
        auto result = decodeTile(codec, payload, wrong);
        EXPECT_FALSE(result.has_value())
            << "decoded as " << wrong.width_px << "x" << wrong.height_px << "x" << wrong.channels;
        if (!result) {
          EXPECT_EQ(result.error().code, ErrorCode::kCorrupt);
          EXPECT_EQ(result.error().message.rfind(std::string(codecName(codec)), 0), 0u)
              << result.error().message;
        }
      }
    }
  }
}

TEST(Codec, DecodeRejectsTrailingBytes) {
  for (Codec codec : kAllCodecs) {
    for (uint32_t channels = 1; channels <= 4; ++channels) {
      SCOPED_TRACE(trace(codec, 30, 20, channels));
      Image image = makeImageLike(30, 20, channels);
      const std::vector<uint8_t> payload = encodeOrDie(codec, image.view());
      for (const std::vector<uint8_t>& suffix :
           {std::vector<uint8_t>{0}, std::vector<uint8_t>{0xFF, 0xD9},
            std::vector<uint8_t>(100, 0x55)}) {
        std::vector<uint8_t> padded = payload;
        padded.insert(padded.end(), suffix.begin(), suffix.end());
        Image decoded(30, 20, channels);
        auto result = decodeTile(codec, padded, decoded);
        ASSERT_FALSE(result.has_value()) << suffix.size() << " trailing bytes accepted";
        EXPECT_EQ(result.error().code, ErrorCode::kCorrupt);
      }
    }
  }
}

void expectEveryTruncationRejected(Codec codec, const Image& image, size_t dense,
                                   CodecScratch* scratch) {
  const std::vector<uint8_t> payload = encodeOrDie(codec, image.view(), {}, scratch);
  Image decoded(image.width_px, image.height_px, image.channels);
  for (size_t length : truncationLengths(payload.size(), dense)) {
    // A fresh allocation of exactly `length` bytes, so ASan reports any read past it.
    std::vector<uint8_t> prefix(payload.begin(), payload.begin() + ptrdiff_t(length));
    auto result = decodeTile(codec, prefix, decoded, nullptr, scratch);
    ASSERT_FALSE(result.has_value()) << "prefix of " << length << " of " << payload.size();
    ASSERT_EQ(result.error().code, ErrorCode::kCorrupt) << result.error().message;
  }
}

TEST(Codec, DecodeRejectsEveryTruncation) {
  CodecScratch scratch;
  for (Codec codec : kAllCodecs) {
    for (uint32_t channels = 1; channels <= 4; ++channels) {
      SCOPED_TRACE(trace(codec, 48, 40, channels));
      expectEveryTruncationRejected(codec, makeImageLike(48, 40, channels), 512, &scratch);
    }
  }
}

TEST(Codec, DecodeRejectsTruncationOfLargeTiles) {
  // 4 channels: the JPEG alpha container and every lossless codec's largest stream; the other
  // channel counts are covered densely at 48x40 above.
  CodecScratch scratch;
  for (Codec codec : kAllCodecs) {
    SCOPED_TRACE(trace(codec, 258, 258, 4));
    expectEveryTruncationRejected(codec, makeImageLike(258, 258, 4), 128, &scratch);
  }
}

// Also checks that a failed decode leaves nothing behind in the scratch: the valid payload
// decodes identically right after each corrupt one (codec_fuzzer found libjpeg's decompressor
// keeping a bad Huffman table across images).
TEST(Codec, SingleByteCorruptionNeverCrashesNorPoisonsTheScratch) {
  CodecScratch scratch;
  for (Codec codec : kAllCodecs) {
    for (uint32_t channels = 1; channels <= 4; ++channels) {
      SCOPED_TRACE(trace(codec, 20, 12, channels));
      Image image = makeImageLike(20, 12, channels);
      const std::vector<uint8_t> payload = encodeOrDie(codec, image.view(), {}, &scratch);
      Image baseline(20, 12, channels);
      ASSERT_TRUE(decodeTile(codec, payload, baseline, nullptr, &scratch).has_value());
      size_t rejected = 0;
      for (size_t i = 0; i < payload.size(); ++i) {
        for (uint8_t flip : {uint8_t(0x01), uint8_t(0xFF)}) {
          std::vector<uint8_t> corrupt = payload;
          corrupt[i] ^= flip;
          Image decoded(20, 12, channels);
          auto result = decodeTile(codec, corrupt, decoded, nullptr, &scratch);
          if (result) {
            ASSERT_EQ(decoded.texels.size(), image.texels.size());
          } else {
            ASSERT_EQ(result.error().code, ErrorCode::kCorrupt) << result.error().message;
            ++rejected;
          }
          Image again(20, 12, channels);
          auto valid = decodeTile(codec, payload, again, nullptr, &scratch);
          ASSERT_TRUE(valid.has_value())
              << "after corrupting byte " << i << ": " << valid.error().message;
          ASSERT_EQ(again.texels, baseline.texels) << "after corrupting byte " << i;
        }
      }
      const size_t attempts = 2 * payload.size();
      // PNG checksums every chunk, so no corruption goes unnoticed; raw has no structure
      // beyond its size. The others detect what breaks their structure (see docs/codecs.md).
      if (codec == Codec::kPng) {
        EXPECT_EQ(rejected, attempts);
      } else if (codec == Codec::kRaw) {
        EXPECT_EQ(rejected, 0u);
      }
    }
  }
}

TEST(Codec, ZstdDecodeRejectsFrameWithoutContentSize) {
  Image image = makeImageLike(16, 16, 3);
  ZSTD_CCtx* cctx = ZSTD_createCCtx();
  ZSTD_CCtx_setParameter(cctx, ZSTD_c_contentSizeFlag, 0);
  std::vector<uint8_t> frame(ZSTD_compressBound(image.texels.size()));
  // Streaming without a pledged size leaves the content size out of the header.
  ZSTD_outBuffer output{frame.data(), frame.size(), 0};
  ZSTD_inBuffer input{image.texels.data(), image.texels.size(), 0};
  ASSERT_EQ(ZSTD_compressStream2(cctx, &output, &input, ZSTD_e_end), 0u);
  ZSTD_freeCCtx(cctx);
  frame.resize(output.pos);
  Image decoded(16, 16, 3);
  auto result = decodeTile(Codec::kZstd, frame, decoded);
  ASSERT_FALSE(result.has_value());
  EXPECT_NE(result.error().message.find("size"), std::string::npos) << result.error().message;
}

TEST(Codec, ZstdDecodeRejectsTwoFrames) {
  Image image = makeImageLike(16, 16, 1);
  std::vector<uint8_t> payload = encodeOrDie(Codec::kZstd, image.view());
  std::vector<uint8_t> twice = payload;
  twice.insert(twice.end(), payload.begin(), payload.end());
  Image decoded(16, 16, 1);
  EXPECT_FALSE(decodeTile(Codec::kZstd, twice, decoded).has_value());
}

// The check the TIFF export and import make before copying a payload: it must accept exactly
// what the decoder accepts, judged on the headers alone.
TEST(Codec, ZstdWholeFrameCheckAcceptsOnlyWhatTheDecoderTakes) {
  Image image = makeImageLike(16, 16, 2);
  const std::vector<uint8_t> payload = encodeOrDie(Codec::kZstd, image.view());
  EXPECT_TRUE(isWholeZstdFrame(payload, image.texels.size()));
  EXPECT_FALSE(isWholeZstdFrame(payload, image.texels.size() + 1));
  for (size_t length = 0; length < payload.size(); ++length) {
    const std::vector<uint8_t> prefix(payload.begin(), payload.begin() + length);
    EXPECT_FALSE(isWholeZstdFrame(prefix, image.texels.size())) << "prefix of " << length;
  }
  std::vector<uint8_t> trailing = payload;
  trailing.push_back(0);
  EXPECT_FALSE(isWholeZstdFrame(trailing, image.texels.size()));
  std::vector<uint8_t> twice = payload;
  twice.insert(twice.end(), payload.begin(), payload.end());
  EXPECT_FALSE(isWholeZstdFrame(twice, image.texels.size()));
  // A frame without its content size, as libtiff's ZSTD writer makes them.
  ZSTD_CCtx* cctx = ZSTD_createCCtx();
  ZSTD_CCtx_setParameter(cctx, ZSTD_c_contentSizeFlag, 0);
  std::vector<uint8_t> unsized(ZSTD_compressBound(image.texels.size()));
  ZSTD_outBuffer output{unsized.data(), unsized.size(), 0};
  ZSTD_inBuffer input{image.texels.data(), image.texels.size(), 0};
  ASSERT_EQ(ZSTD_compressStream2(cctx, &output, &input, ZSTD_e_end), 0u);
  ZSTD_freeCCtx(cctx);
  unsized.resize(output.pos);
  EXPECT_FALSE(isWholeZstdFrame(unsized, image.texels.size()));
}

TEST(Codec, JpegDecodeRejectsProgressiveJpeg) {
  Image image = makeImageLike(64, 64, 3);
  tjhandle handle = tjInitCompress();
  unsigned char* jpeg = nullptr;
  unsigned long jpeg_bytes = 0;
  ASSERT_EQ(tjCompress2(handle, image.texels.data(), 64, 0, 64, TJPF_RGB, &jpeg, &jpeg_bytes,
                        TJSAMP_420, 85, TJFLAG_PROGRESSIVE),
            0);
  std::vector<uint8_t> payload(jpeg, jpeg + jpeg_bytes);
  tjFree(jpeg);
  tjDestroy(handle);
  Image decoded(64, 64, 3);
  auto result = decodeTile(Codec::kJpeg, payload, decoded);
  ASSERT_FALSE(result.has_value());
  EXPECT_NE(result.error().message.find("baseline"), std::string::npos) << result.error().message;
}

TEST(Codec, JpegDecodeRejectsColourStreamForGrayTile) {
  Image image = makeImageLike(32, 32, 3);
  std::vector<uint8_t> payload = encodeOrDie(Codec::kJpeg, image.view());
  Image gray(32, 32, 1);
  auto result = decodeTile(Codec::kJpeg, payload, gray);
  ASSERT_FALSE(result.has_value());
  EXPECT_EQ(result.error().message, "jpeg payload: 32x32x1 expected, stream is 32x32x3");
}

TEST(Codec, JpegDecodeRejectsAlphaLengthPastTheEnd) {
  Image image = makeImageLike(32, 32, 4);
  std::vector<uint8_t> payload = encodeOrDie(Codec::kJpeg, image.view());
  payload[3] = 0x7F;  // JPEG length near 2 GiB
  Image decoded(32, 32, 4);
  EXPECT_FALSE(decodeTile(Codec::kJpeg, payload, decoded).has_value());
}

TEST(Codec, WebpDecodeRejectsColourStreamForGrayTile) {
  Image image = makeImageLike(32, 32, 3);
  std::vector<uint8_t> payload = encodeOrDie(Codec::kWebp, image.view());
  Image gray(32, 32, 1);
  auto result = decodeTile(Codec::kWebp, payload, gray);
  ASSERT_FALSE(result.has_value());
  EXPECT_NE(result.error().message.find("not gray"), std::string::npos) << result.error().message;
}

TEST(Codec, WebpKeepsColourUnderTransparentAlpha) {
  Image image = makeImageLike(32, 32, 4);
  for (size_t i = 0; i < 32 * 32; i += 2) image.texels[4 * i + 3] = 0;
  std::vector<uint8_t> payload = encodeOrDie(Codec::kWebp, image.view());
  Image decoded(32, 32, 4);
  ASSERT_TRUE(decodeTile(Codec::kWebp, payload, decoded).has_value());
  EXPECT_EQ(decoded.texels, image.texels);
}

TEST(Codec, PngDecodeNamesColourTypeOnMismatch) {
  Image image = makeImageLike(32, 32, 2);
  std::vector<uint8_t> payload = encodeOrDie(Codec::kPng, image.view());
  Image rgba(32, 32, 4);
  auto result = decodeTile(Codec::kPng, payload, rgba);
  ASSERT_FALSE(result.has_value());
  EXPECT_EQ(result.error().message,
            "png payload: 32x32x4 expected, stream is 32x32 8-bit gray+alpha");
}

}  // namespace
}  // namespace tessera::detail
