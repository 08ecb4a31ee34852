#include <tessera/format.h>

#include <algorithm>
#include <string_view>

namespace tessera {

namespace {

// The codec values of docs/format.md, "Codecs": what the format says of each, independent of
// any implementation (src/codecs has the decoders and encoders).
struct CodecSpec {
  Codec codec;
  const char* name;
  bool needs_parent;  ///< coded against the decoded parent tile
  bool lossless;      ///< decode(encode(x)) == x bit for bit
};

constexpr CodecSpec kCodecSpecs[] = {
    {Codec::kRaw, "raw", false, true},  {Codec::kZstd, "zstd", false, true},
    {Codec::kLz4, "lz4", false, true},  {Codec::kJpeg, "jpeg", false, false},
    {Codec::kPng, "png", false, true},  {Codec::kWebp, "webp", false, true},
    {Codec::kPtm, "ptm", true, true},   {Codec::kZdelta, "zdelta", false, true},
    {Codec::kBc1, "bc1", false, false}, {Codec::kBc7, "bc7", false, false},
};

const CodecSpec* findSpec(Codec codec) {
  for (const auto& entry : kCodecSpecs)
    if (entry.codec == codec) return &entry;
  return nullptr;
}

uint32_t ceilShift(uint32_t value, uint32_t shift) {
  return uint32_t((uint64_t(value) + (uint64_t(1) << shift) - 1) >> shift);
}

}  // namespace

const char* codecName(Codec codec) {
  const CodecSpec* spec = findSpec(codec);
  return spec != nullptr ? spec->name : "unknown";
}

bool codecNeedsParent(Codec codec) {
  const CodecSpec* spec = findSpec(codec);
  return spec != nullptr && spec->needs_parent;
}

bool codecIsLossless(Codec codec) {
  const CodecSpec* spec = findSpec(codec);
  return spec != nullptr && spec->lossless;
}

bool parseCodecName(std::string_view name, Codec* codec) {
  for (const auto& entry : kCodecSpecs) {
    if (name == entry.name) {
      *codec = entry.codec;
      return true;
    }
  }
  return false;
}

const char* sampleTypeName(SampleType type) {
  switch (type) {
    case SampleType::kU8: return "u8";
    case SampleType::kU16: return "u16";
    case SampleType::kF32: return "f32";
  }
  return "unknown";
}

bool parseSampleTypeName(std::string_view name, SampleType* type) {
  for (SampleType candidate : {SampleType::kU8, SampleType::kU16, SampleType::kF32}) {
    if (name == sampleTypeName(candidate)) {
      *type = candidate;
      return true;
    }
  }
  return false;
}

bool codecSupportsSampleType(Codec codec, SampleType type) {
  switch (codec) {
    case Codec::kRaw:
    case Codec::kZstd:
    case Codec::kLz4:
    case Codec::kZdelta: return true;
    // PNG has 16-bit channels but no float; the others are 8-bit by construction.
    case Codec::kPng: return type != SampleType::kF32;
    case Codec::kJpeg:
    case Codec::kWebp:
    case Codec::kPtm:
    case Codec::kBc1:
    case Codec::kBc7: return type == SampleType::kU8;
  }
  return false;
}

const char* tileKindName(TileKind kind) {
  switch (kind) {
    case TileKind::kEmpty: return "empty";
    case TileKind::kUniform: return "uniform";
    case TileKind::kEncoded: return "encoded";
    case TileKind::kProcedural: return "procedural";
  }
  return "unknown";
}

// Each level halves the previous one rounding up, so an odd edge column or row is averaged
// with its own replica: ceil(w / 2^L) (docs/format.md, "Levels").
uint32_t ImageInfo::levelWidthPx(uint32_t level) const {
  return std::max<uint32_t>(1, ceilShift(width_px, std::min<uint32_t>(level, 31)));
}

uint32_t ImageInfo::levelHeightPx(uint32_t level) const {
  return std::max<uint32_t>(1, ceilShift(height_px, std::min<uint32_t>(level, 31)));
}

// Padding to whole tiles: Backes et al., eq. 1, d = ceil(r / t) * t.
uint32_t ImageInfo::tilesX(uint32_t level) const {
  return (levelWidthPx(level) + tile_size_px - 1) / tile_size_px;
}

uint32_t ImageInfo::tilesY(uint32_t level) const {
  return (levelHeightPx(level) + tile_size_px - 1) / tile_size_px;
}

uint32_t levelCountFor(uint32_t width_px, uint32_t height_px, uint32_t tile_size_px) {
  uint32_t levels = 1;
  uint64_t w = width_px, h = height_px;
  while (w > tile_size_px || h > tile_size_px) {
    w = (w + 1) / 2;
    h = (h + 1) / 2;
    ++levels;
  }
  return levels;
}

}  // namespace tessera
