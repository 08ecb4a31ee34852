// tessera-pyramid-study: bytes and coding speed of whole tile pyramids per codec, for the ptm
// codec study (docs/benchmarks.md, "Progressive lossless pyramids (ptm): codec study").
//
// For each input (a synthetic:WxH:seed:channels spec, a PNG/JPEG/TIFF path, or a .webp photo)
// it builds the pyramid in memory exactly as `tessera build` would (rounded box average for the
// other codecs, the floor average for ptm; 256-px tiles, no border), encodes every tile with each
// codec and reports, against the raw base level (level 0 tiles as stored, padding included):
// the whole pyramid's bytes, ptm's overhead over its own base level, and single-thread decode
// and encode throughput in megapixels of pyramid per second (ptm decoded coarse to fine against
// the decoded parents, as a reader does). ptm's rows are its efforts as `tessera build` writes
// them. `--levels` adds each level's bits per texel. JPEG XL lossless (libjxl, single-threaded)
// is a row when the build found libjxl-dev; it is not an archive codec.
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <webp/decode.h>
#if TESSERA_STUDY_JXL
#include <jxl/decode.h>
#include <jxl/encode.h>
#endif

#include "builder/band_reader.h"
#include "builder/downsample.h"
#include "codecs/encode.h"
#include "ptm/ptm_codec.h"

using namespace tessera;
using namespace tessera::detail;

namespace {

constexpr uint32_t kTilePx = 256;

Image readInput(const std::string& input) {
  if (input.size() > 5 && input.substr(input.size() - 5) == ".webp") {
    FILE* file = std::fopen(input.c_str(), "rb");
    if (!file) return {};
    std::vector<uint8_t> bytes;
    uint8_t chunk[65536];
    for (size_t n; (n = std::fread(chunk, 1, sizeof chunk, file)) > 0;)
      bytes.insert(bytes.end(), chunk, chunk + n);
    std::fclose(file);
    int width = 0, height = 0;
    uint8_t* rgb = WebPDecodeRGB(bytes.data(), bytes.size(), &width, &height);
    if (!rgb) return {};
    Image image(uint32_t(width), uint32_t(height), 3);
    std::memcpy(image.texels.data(), rgb, image.texels.size());
    WebPFree(rgb);
    return image;
  }
  auto reader = openBandReader(input);
  if (!reader) {
    fmt::print(stderr, "{}\n", reader.error().message);
    return {};
  }
  const SourceInfo& info = (*reader)->info();
  Image image(info.width_px, info.height_px, info.channels);
  if (!(*reader)->readRows(info.height_px, image.texels)) return {};
  return image;
}

std::vector<Image> makePyramid(Image level0, bool floor_average) {
  std::vector<Image> levels{std::move(level0)};
  while (levels.back().width_px > kTilePx || levels.back().height_px > kTilePx) {
    const Image& from = levels.back();
    Image next((from.width_px + 1) / 2, (from.height_px + 1) / 2, from.channels);
    for (uint32_t y = 0; y < next.height_px; ++y) {
      const uint8_t* top = from.row(2 * y);
      const uint8_t* bottom = from.row(std::min(2 * y + 1, from.height_px - 1));
      if (floor_average)
        downsampleRowPairFloor(top, bottom, from.width_px, from.channels, next.row(y));
      else
        downsampleRowPair(top, bottom, from.width_px, from.channels, false, next.row(y));
    }
    levels.push_back(std::move(next));
  }
  return levels;
}

Image cutTile(const Image& level, uint32_t x, uint32_t y) {
  Image tile(kTilePx, kTilePx, level.channels);
  for (uint32_t j = 0; j < kTilePx; ++j) {
    const uint32_t ly = std::min(y * kTilePx + j, level.height_px - 1);
    for (uint32_t i = 0; i < kTilePx; ++i) {
      const uint32_t lx = std::min(x * kTilePx + i, level.width_px - 1);
      std::memcpy(tile.row(j) + size_t(i) * level.channels,
                  level.row(ly) + size_t(lx) * level.channels, level.channels);
    }
  }
  return tile;
}

#if TESSERA_STUDY_JXL
// libjxl's lossless mode on one tile: 8 bits per sample, grey or RGB plus alpha for 2 and 4
// channels, no parallel runner (the study measures one core).
class JxlTileCodec {
 public:
  JxlTileCodec() : encoder_(JxlEncoderCreate(nullptr)), decoder_(JxlDecoderCreate(nullptr)) {}
  ~JxlTileCodec() {
    JxlEncoderDestroy(encoder_);
    JxlDecoderDestroy(decoder_);
  }
  JxlTileCodec(const JxlTileCodec&) = delete;
  JxlTileCodec& operator=(const JxlTileCodec&) = delete;

  std::optional<std::vector<uint8_t>> encode(const Image& tile, int effort) {
    JxlEncoderReset(encoder_);
    const bool alpha = tile.channels == 2 || tile.channels == 4;
    JxlBasicInfo info;
    JxlEncoderInitBasicInfo(&info);
    info.xsize = tile.width_px;
    info.ysize = tile.height_px;
    info.bits_per_sample = 8;
    info.num_color_channels = tile.channels >= 3 ? 3 : 1;
    info.num_extra_channels = alpha ? 1 : 0;
    info.alpha_bits = alpha ? 8 : 0;
    info.uses_original_profile = JXL_TRUE;  // lossless needs the samples as they are
    if (JxlEncoderSetBasicInfo(encoder_, &info) != JXL_ENC_SUCCESS) return std::nullopt;
    if (alpha) {
      JxlExtraChannelInfo extra;
      JxlEncoderInitExtraChannelInfo(JXL_CHANNEL_ALPHA, &extra);
      extra.bits_per_sample = 8;
      if (JxlEncoderSetExtraChannelInfo(encoder_, 0, &extra) != JXL_ENC_SUCCESS)
        return std::nullopt;
    }
    JxlColorEncoding colour;
    JxlColorEncodingSetToSRGB(&colour, info.num_color_channels == 1);
    if (JxlEncoderSetColorEncoding(encoder_, &colour) != JXL_ENC_SUCCESS) return std::nullopt;
    JxlEncoderFrameSettings* settings = JxlEncoderFrameSettingsCreate(encoder_, nullptr);
    if (JxlEncoderSetFrameLossless(settings, JXL_TRUE) != JXL_ENC_SUCCESS ||
        JxlEncoderFrameSettingsSetOption(settings, JXL_ENC_FRAME_SETTING_EFFORT, effort) !=
            JXL_ENC_SUCCESS)
      return std::nullopt;
    const JxlPixelFormat format{tile.channels, JXL_TYPE_UINT8, JXL_NATIVE_ENDIAN, 0};
    if (JxlEncoderAddImageFrame(settings, &format, tile.texels.data(), tile.texels.size()) !=
        JXL_ENC_SUCCESS)
      return std::nullopt;
    JxlEncoderCloseInput(encoder_);
    std::vector<uint8_t> out(4096);
    size_t used = 0;
    for (;;) {
      uint8_t* next = out.data() + used;
      size_t available = out.size() - used;
      const JxlEncoderStatus status = JxlEncoderProcessOutput(encoder_, &next, &available);
      used = size_t(next - out.data());
      if (status == JXL_ENC_SUCCESS) break;
      if (status != JXL_ENC_NEED_MORE_OUTPUT) return std::nullopt;
      out.resize(out.size() * 2);
    }
    out.resize(used);
    return out;
  }

  bool decode(const std::vector<uint8_t>& payload, Image& out) {
    JxlDecoderReset(decoder_);
    if (JxlDecoderSubscribeEvents(decoder_, JXL_DEC_FULL_IMAGE) != JXL_DEC_SUCCESS ||
        JxlDecoderSetInput(decoder_, payload.data(), payload.size()) != JXL_DEC_SUCCESS)
      return false;
    JxlDecoderCloseInput(decoder_);
    const JxlPixelFormat format{out.channels, JXL_TYPE_UINT8, JXL_NATIVE_ENDIAN, 0};
    for (;;) {
      switch (JxlDecoderProcessInput(decoder_)) {
        case JXL_DEC_NEED_IMAGE_OUT_BUFFER:
          if (JxlDecoderSetImageOutBuffer(decoder_, &format, out.texels.data(),
                                          out.texels.size()) != JXL_DEC_SUCCESS)
            return false;
          break;
        case JXL_DEC_FULL_IMAGE: break;
        case JXL_DEC_SUCCESS: return true;
        default: return false;
      }
    }
  }

 private:
  JxlEncoder* encoder_;
  JxlDecoder* decoder_;
};
#endif

struct Variant {
  std::string name;
  Codec codec;
  int effort;
  bool jxl = false;  ///< libjxl lossless at `effort` instead of `codec`
};

struct Tiles {
  std::vector<std::vector<Image>> levels;  ///< [level][y * tiles_x + x]
  std::vector<uint32_t> tiles_x;
};

Tiles cutAll(const std::vector<Image>& pyramid) {
  Tiles tiles;
  for (const Image& level : pyramid) {
    const uint32_t tx = (level.width_px + kTilePx - 1) / kTilePx;
    const uint32_t ty = (level.height_px + kTilePx - 1) / kTilePx;
    tiles.tiles_x.push_back(tx);
    tiles.levels.emplace_back();
    for (uint32_t y = 0; y < ty; ++y)
      for (uint32_t x = 0; x < tx; ++x) tiles.levels.back().push_back(cutTile(level, x, y));
  }
  return tiles;
}

// The parent of tile `i` of level `l`, taken from `parents`: level l + 1's tiles as coded, or
// as decoded.
ParentTexels parentOf(const Tiles& tiles, const std::vector<Image>& parents, size_t l, size_t i) {
  const uint32_t x = uint32_t(i % tiles.tiles_x[l]), y = uint32_t(i / tiles.tiles_x[l]);
  return {parents[(y / 2) * tiles.tiles_x[l + 1] + x / 2].view(), x & 1, y & 1, kTilePx, 0};
}

void study(const std::string& input, double min_seconds, const std::string& only, bool per_level) {
  Image level0 = readInput(input);
  if (level0.texels.empty()) {
    fmt::print(stderr, "{}: cannot read\n", input);
    return;
  }
  const Tiles rounded = cutAll(makePyramid(level0, false));
  const Tiles floored = cutAll(makePyramid(level0, true));
  const double raw_base = double(rounded.levels[0].size()) * kTilePx * kTilePx * level0.channels;
  double pyramid_px = 0;
  for (const auto& level : rounded.levels) pyramid_px += double(level.size()) * kTilePx * kTilePx;
  fmt::print("\n{} ({}x{}x{}, {} levels, raw base {:.1f} MB, pyramid {:.1f} MP)\n", input,
             level0.width_px, level0.height_px, level0.channels, rounded.levels.size(),
             raw_base / 1e6, pyramid_px / 1e6);
  fmt::print(
      "| codec | pyramid / raw base | raw base : pyramid | pyramid over base coded alone | decode "
      "MP/s per core | encode MP/s per core |\n|---|---:|---:|---:|---:|---:|\n");
  const std::vector<Variant> variants = {
    {"raw", Codec::kRaw, 0},
    {"lz4", Codec::kLz4, 0},
    {"zstd-1", Codec::kZstd, 1},
    {"zstd-3", Codec::kZstd, 3},
    {"zstd-9", Codec::kZstd, 9},
    {"png (effort 2)", Codec::kPng, 0},
    {"webp-lossless (effort 1)", Codec::kWebp, 0},
    // libwebp's own default preset: 5-8x slower to encode than the archive's default, smaller.
    {"webp-lossless (effort 6)", Codec::kWebp, 6},
    {"ptm effort 1 (nearest parent + zstd)", Codec::kPtm, 1},
    {"ptm effort 2 (nearest parent + zstd, or the lanes)", Codec::kPtm, 2},
    {"ptm default (tessera build --codec ptm)", Codec::kPtm, 0},
#if TESSERA_STUDY_JXL
    // libjxl's default effort is 7; 3 is its fast lossless setting.
    {"jpeg-xl lossless (effort 3)", Codec::kRaw, 3, true},
    {"jpeg-xl lossless (effort 7)", Codec::kRaw, 7, true},
#endif
  };
#if TESSERA_STUDY_JXL
  JxlTileCodec jxl;
#else
  fmt::print("(JPEG XL lossless: not built; install libjxl-dev and reconfigure)\n");
#endif
  CodecScratch scratch;
  auto encodeVariant =
      [&](const Variant& variant, const Image& tile, const EncodeOptions& options,
          const std::optional<ParentTexels>& parent) -> Result<std::vector<uint8_t>> {
#if TESSERA_STUDY_JXL
    if (variant.jxl) {
      std::optional<std::vector<uint8_t>> payload = jxl.encode(tile, variant.effort);
      if (!payload) return fail(ErrorCode::kInvalidArgument, "libjxl refused the tile");
      return std::move(*payload);
    }
#endif
    return encodeTile(variant.codec, tile.view(), options, parent ? &*parent : nullptr, &scratch);
  };
  // A level coded on its own: for ptm the effort's mode without a parent (seed 003's reference
  // for the overhead), for the rest the codec itself.
  auto encodeAlone = [&](const Variant& variant, const Image& tile, const EncodeOptions& options) {
    return encodeVariant(variant, tile, options, std::nullopt);
  };
  auto decodeVariant = [&](const Variant& variant, const std::vector<uint8_t>& payload, Image& out,
                           const std::optional<ParentTexels>& parent) -> bool {
#if TESSERA_STUDY_JXL
    if (variant.jxl) return jxl.decode(payload, out);
#endif
    return bool(decodeTile(variant.codec, payload, out, parent ? &*parent : nullptr, &scratch));
  };
  // The size target compares the default with the smaller of PNG and WebP-lossless;
  // the ratio columns round too coarsely to tell a near tie.
  double smallest_peer_bytes = 0;
  std::string smallest_peer;
  for (const Variant& variant : variants) {
    if (!only.empty() && variant.name.find(only) == std::string::npos) continue;
    const bool ptm = variant.codec == Codec::kPtm;
    const Tiles& tiles = ptm ? floored : rounded;
    std::vector<std::vector<std::vector<uint8_t>>> payloads(tiles.levels.size());
    double total = 0;
    std::vector<double> level_bytes(tiles.levels.size(), 0);
    EncodeOptions options;
    options.effort = variant.effort;
    const auto encode_start = std::chrono::steady_clock::now();
    for (size_t l = tiles.levels.size(); l-- > 0;) {
      for (size_t i = 0; i < tiles.levels[l].size(); ++i) {
        const Image& tile = tiles.levels[l][i];
        std::optional<ParentTexels> parent;
        if (ptm && l + 1 < tiles.levels.size()) parent = parentOf(tiles, tiles.levels[l + 1], l, i);
        Result<std::vector<uint8_t>> payload = encodeVariant(variant, tile, options, parent);
        if (!payload) {
          fmt::print(stderr, "{}: {}\n", variant.name, payload.error().message);
          return;
        }
        total += payload->size();
        level_bytes[l] += payload->size();
        payloads[l].push_back(std::move(*payload));
      }
    }
    const double encode_seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - encode_start).count();
    // Decode the whole pyramid, coarse to fine, until min_seconds have passed; the fastest
    // round counts, so that other work on a shared machine lowers the figure less.
    std::vector<std::vector<Image>> decoded(tiles.levels.size());
    for (size_t l = 0; l < tiles.levels.size(); ++l)
      decoded[l].assign(tiles.levels[l].size(), Image(kTilePx, kTilePx, level0.channels));
    bool exact = true;
    const auto start = std::chrono::steady_clock::now();
    double elapsed = 0;
    double fastest_round = 0;
    do {
      const auto round_start = std::chrono::steady_clock::now();
      for (size_t l = tiles.levels.size(); l-- > 0;) {
        for (size_t i = 0; i < payloads[l].size(); ++i) {
          std::optional<ParentTexels> parent;
          if (ptm && l + 1 < tiles.levels.size()) parent = parentOf(tiles, decoded[l + 1], l, i);
          if (!decodeVariant(variant, payloads[l][i], decoded[l][i], parent)) exact = false;
        }
      }
      const auto now = std::chrono::steady_clock::now();
      const double round = std::chrono::duration<double>(now - round_start).count();
      if (fastest_round == 0 || round < fastest_round) fastest_round = round;
      elapsed = std::chrono::duration<double>(now - start).count();
    } while (elapsed < min_seconds);
    for (size_t l = 0; l < tiles.levels.size() && exact; ++l)
      for (size_t i = 0; i < tiles.levels[l].size(); ++i)
        if (decoded[l][i].texels != tiles.levels[l][i].texels) exact = false;
    // Seed 003's overhead: the whole pyramid against the base level coded on its own by the
    // same codec (for ptm: its parentless mode with the same entropy coder), not against ptm's
    // parent-coded level 0.
    double base_alone = 0;
    for (const Image& tile : tiles.levels[0]) {
      auto alone = encodeAlone(variant, tile, options);
      base_alone += alone ? double(alone->size()) : 0;
    }
    fmt::print("| {} | {:.3f} | {:.2f}:1 | {:.1f} % | {:.0f}{} | {:.1f} |\n", variant.name,
               total / raw_base, raw_base / total, 100.0 * (total - base_alone) / base_alone,
               pyramid_px / fastest_round / 1e6, exact ? "" : " (NOT EXACT)",
               pyramid_px / encode_seconds / 1e6);
    if ((variant.codec == Codec::kPng || variant.codec == Codec::kWebp) &&
        (smallest_peer_bytes == 0 || total < smallest_peer_bytes)) {
      smallest_peer_bytes = total;
      smallest_peer = variant.name;
    }
    if (ptm) {
      // What the default chose: its share of the pyramid's bytes per (predictor, coder).
      std::map<std::pair<int, int>, double> chosen;
      for (const auto& level : payloads)
        for (const auto& payload : level) chosen[{payload[0], payload[1]}] += payload.size();
      std::string shares;
      // The coder byte's flags: explicit tables follow, and coder 7's contexts are green-led
      // (docs/codecs.md).
      using tessera::detail::kPtmGreenLedFlag, tessera::detail::kPtmTablesFlag;
      for (const auto& [key, bytes] : chosen)
        shares +=
            fmt::format("{}predictor {} coder {}{}{} {:.1f} %", shares.empty() ? "" : ", ",
                        key.first, key.second & ~int(kPtmTablesFlag | kPtmGreenLedFlag),
                        (key.second & kPtmGreenLedFlag) != 0 ? " green-led" : "",
                        (key.second & kPtmTablesFlag) != 0 ? "+tables" : "", 100.0 * bytes / total);
      const std::string mode =
          variant.effort == 0 ? std::string("default") : fmt::format("effort {}", variant.effort);
      fmt::print("\n({}'s bytes by predictor and coder: {})\n", mode, shares);
      fmt::print("({}: {:.0f} bytes; its base level alone: {:.0f} bytes)\n", mode, total,
                 base_alone);
      if (smallest_peer_bytes > 0 && variant.effort == 0)
        fmt::print("(the default is {:.2f} % {} than {}, {:.0f} bytes)\n",
                   100.0 * std::abs(total - smallest_peer_bytes) / smallest_peer_bytes,
                   total <= smallest_peer_bytes ? "smaller" : "larger", smallest_peer,
                   smallest_peer_bytes);
      fmt::print("\n");
    }
    if (per_level) {
      // Where the overhead lies: each level's bytes as coded in the pyramid, and the same level
      // coded on its own, both in bits per texel.
      for (size_t l = 0; l < tiles.levels.size(); ++l) {
        double alone = 0;
        for (const Image& tile : tiles.levels[l]) {
          auto coded = encodeAlone(variant, tile, options);
          alone += coded ? double(coded->size()) : 0;
        }
        const double texels = double(tiles.levels[l].size()) * kTilePx * kTilePx;
        fmt::print("|   level {} | {:.3f} bits/texel in the pyramid | {:.3f} alone | | | |\n", l,
                   8 * level_bytes[l] / texels, 8 * alone / texels);
      }
    }
  }
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    fmt::print(stderr, "usage: {} [--seconds S] [--only NAME-PART] [--levels] INPUT...\n", argv[0]);
    return 2;
  }
  double seconds = 0.5;
  std::string only;
  bool per_level = false;
  for (int i = 1; i < argc; ++i) {
    if (std::string(argv[i]) == "--levels") {
      per_level = true;
      continue;
    }
    if (std::string(argv[i]) == "--only" && i + 1 < argc) {
      only = argv[++i];
      continue;
    }
    if (std::string(argv[i]) == "--seconds" && i + 1 < argc) {
      seconds = std::atof(argv[++i]);
      continue;
    }
    study(argv[i], seconds, only, per_level);
  }
  return 0;
}
