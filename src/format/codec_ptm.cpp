// ptm: progressive texture maps (Marvie & Bouatouch, "Remote Rendering of Massively Textured 3D
// Scenes Through Progressive Texture Maps", part I). A tile is coded as what its decoded parent
// does not already say: in each 2x2 block three children are predicted and their residuals
// kept, and the fourth follows from the parent and the remainder of the integer average
// (eq. 3). Byte layout and the measurements behind the choices: docs/codecs.md, "ptm (6)".
#include <algorithm>
#include <cstring>

#include <fmt/format.h>

#include "codec_internal.h"

namespace tessera::detail {

namespace {

constexpr size_t kHeaderBytes = 2;
constexpr size_t kStreamLengthBytes = 4;

// Levels 1-9 gave sizes within 1 % of each other on residual planes (Huffman-coded literals
// with few matches), so the cheapest level wins: the builder encodes every tile.
constexpr int kDefaultZstdLevel = 1;

// Where each child texel finds its parent along one axis (ParentTexels explains the offset).
struct AxisMap {
  std::vector<uint32_t> parent;     ///< parent texel index of the block holding this child
  std::vector<uint32_t> neighbour;  ///< the parent texel on this child's side of `parent`
  std::vector<uint8_t> derived;     ///< 1 for the second child of a block wholly in the tile
};

// Returns false when a child texel's block falls outside the parent tile: the caller passed
// geometry that does not come from one image's quadtree.
bool mapAxis(uint32_t child_px, uint32_t parent_px, uint64_t offset, AxisMap& map) {
  map.parent.resize(child_px);
  map.neighbour.resize(child_px);
  map.derived.resize(child_px);
  for (uint32_t i = 0; i < child_px; ++i) {
    const uint64_t u = offset + i;
    const uint64_t j = u >> 1;
    if (j >= parent_px) return false;
    const bool second = (u & 1) != 0;
    map.parent[i] = uint32_t(j);
    // Bilinear upsampling weights the parent texel on the child's side of its block.
    map.neighbour[i] =
        second ? uint32_t(std::min<uint64_t>(j + 1, parent_px - 1)) : uint32_t(j == 0 ? 0 : j - 1);
    // A block whose first child lies before the tile (odd border) is coded texel by texel.
    map.derived[i] = second && i > 0;
  }
  return true;
}

// LOCO-I's median edge detector (Weinberger et al., "The LOCO-I lossless image compression
// algorithm"), for tiles coded without a parent.
inline int medPredict(int left, int up, int up_left) {
  const int low = std::min(left, up), high = std::max(left, up);
  if (up_left >= high) return low;
  if (up_left <= low) return high;
  return left + up - up_left;
}

struct Planes {
  uint8_t* residuals[4];   ///< per channel: symbols of the coded texels, raster order
  uint8_t* remainders[4];  ///< per channel: eq. 3's remainder of each derived texel
};

// One routine codes and decodes, so the two can never disagree on a prediction. Encoding reads
// `texels` and writes `planes`; decoding reads `planes` and writes `texels`. Arithmetic is
// modulo 256: bit-exact for any input, and for a floor-average pyramid every remainder is 0..3.
template <bool kEncode, uint32_t kChannels, Predictor kPredictor>
void codeTexels(uint8_t* texels, uint32_t width, uint32_t height, const ImageView* parent,
                const AxisMap* columns, const AxisMap* rows, Planes planes) {
  constexpr bool kColourTransform = kChannels >= 3;
  const size_t stride = size_t(width) * kChannels;
  uint8_t* residual[4];
  uint8_t* remainder[4];
  for (uint32_t c = 0; c < kChannels; ++c) {
    residual[c] = planes.residuals[c];
    remainder[c] = planes.remainders[c];
  }
  for (uint32_t y = 0; y < height; ++y) {
    uint8_t* row = texels + y * stride;
    const uint8_t* up_row = y > 0 ? row - stride : nullptr;
    const uint8_t* parent_row = nullptr;
    const uint8_t* parent_near = nullptr;
    bool derived_row = false;
    if constexpr (kPredictor != Predictor::kRoot) {
      parent_row = parent->row(rows->parent[y]);
      parent_near = parent->row(rows->neighbour[y]);
      derived_row = rows->derived[y] != 0;
    }
    for (uint32_t x = 0; x < width; ++x) {
      uint8_t* texel = row + size_t(x) * kChannels;
      if constexpr (kPredictor != Predictor::kRoot) {
        const uint8_t* p = parent_row + size_t(columns->parent[x]) * kChannels;
        if (derived_row && columns->derived[x]) {
          // Marvie & Bouatouch eq. 3: d = 4 * parent + e - a - b - c.
          const uint8_t* b = up_row + size_t(x) * kChannels;
          const uint8_t* a = b - kChannels;
          const uint8_t* c3 = texel - kChannels;
          for (uint32_t c = 0; c < kChannels; ++c) {
            const uint32_t known = 4u * p[c] - a[c] - b[c] - c3[c];
            if constexpr (kEncode)
              *remainder[c]++ = uint8_t(texel[c] - known);
            else
              texel[c] = uint8_t(known + *remainder[c]++);
          }
          continue;
        }
      }
      int predicted[4];
      for (uint32_t c = 0; c < kChannels; ++c) {
        if constexpr (kPredictor == Predictor::kRoot) {
          const int left = x > 0 ? (texel - kChannels)[c] : (y > 0 ? up_row[c] : 0);
          const int up = y > 0 ? up_row[size_t(x) * kChannels + c] : left;
          const int up_left = x > 0 && y > 0 ? up_row[size_t(x - 1) * kChannels + c] : left;
          predicted[c] = medPredict(left, up, up_left);
        } else if constexpr (kPredictor == Predictor::kParentNearest) {
          predicted[c] = parent_row[size_t(columns->parent[x]) * kChannels + c];
        } else {
          const size_t j = size_t(columns->parent[x]) * kChannels + c;
          const size_t jn = size_t(columns->neighbour[x]) * kChannels + c;
          predicted[c] =
              (9 * parent_row[j] + 3 * parent_row[jn] + 3 * parent_near[j] + parent_near[jn] + 8) >>
              4;
        }
      }
      // Subtract-green on residuals: colour channels share most of their error.
      if constexpr (kEncode) {
        uint8_t symbols[4];
        for (uint32_t c = 0; c < kChannels; ++c) symbols[c] = uint8_t(texel[c] - predicted[c]);
        if constexpr (kColourTransform) {
          symbols[0] = uint8_t(symbols[0] - symbols[1]);
          symbols[2] = uint8_t(symbols[2] - symbols[1]);
        }
        for (uint32_t c = 0; c < kChannels; ++c) *residual[c]++ = symbols[c];
      } else {
        uint8_t symbols[4];
        for (uint32_t c = 0; c < kChannels; ++c) symbols[c] = *residual[c]++;
        if constexpr (kColourTransform) {
          symbols[0] = uint8_t(symbols[0] + symbols[1]);
          symbols[2] = uint8_t(symbols[2] + symbols[1]);
        }
        for (uint32_t c = 0; c < kChannels; ++c) texel[c] = uint8_t(predicted[c] + symbols[c]);
      }
    }
  }
}

template <bool kEncode, uint32_t kChannels>
void codeWith(Predictor predictor, uint8_t* texels, uint32_t width, uint32_t height,
              const ImageView* parent, const AxisMap* columns, const AxisMap* rows, Planes planes) {
  switch (predictor) {
    case Predictor::kRoot:
      return codeTexels<kEncode, kChannels, Predictor::kRoot>(texels, width, height, parent,
                                                              columns, rows, planes);
    case Predictor::kParentNearest:
      return codeTexels<kEncode, kChannels, Predictor::kParentNearest>(
          texels, width, height, parent, columns, rows, planes);
    case Predictor::kParentBilinear:
      return codeTexels<kEncode, kChannels, Predictor::kParentBilinear>(
          texels, width, height, parent, columns, rows, planes);
  }
}

template <bool kEncode>
void code(Predictor predictor, uint32_t channels, uint8_t* texels, uint32_t width, uint32_t height,
          const ImageView* parent, const AxisMap* columns, const AxisMap* rows, Planes planes) {
  switch (channels) {
    case 1:
      return codeWith<kEncode, 1>(predictor, texels, width, height, parent, columns, rows, planes);
    case 2:
      return codeWith<kEncode, 2>(predictor, texels, width, height, parent, columns, rows, planes);
    case 3:
      return codeWith<kEncode, 3>(predictor, texels, width, height, parent, columns, rows, planes);
    default:
      return codeWith<kEncode, 4>(predictor, texels, width, height, parent, columns, rows, planes);
  }
}

// Symbol counts of one tile: `coded` residuals and `derived` remainders per channel.
struct SymbolCounts {
  size_t coded = 0;
  size_t derived = 0;
};

SymbolCounts countSymbols(uint32_t width, uint32_t height, const AxisMap* columns,
                          const AxisMap* rows) {
  const size_t total = size_t(width) * height;
  if (columns == nullptr) return {total, 0};
  size_t derived_columns = 0, derived_rows = 0;
  for (uint8_t d : columns->derived) derived_columns += d;
  for (uint8_t d : rows->derived) derived_rows += d;
  const size_t derived = derived_columns * derived_rows;
  return {total - derived, derived};
}

// Maps both axes, or explains why the parent does not fit.
Result<void> mapParent(const ImageView& parent_view, const ParentTexels& parent, uint32_t width,
                       uint32_t height, uint32_t channels, AxisMap& columns, AxisMap& rows) {
  if (parent_view.channels != channels)
    return fail(ErrorCode::kInvalidArgument, fmt::format("ptm: parent has {} channels, tile {}",
                                                         parent_view.channels, channels));
  if (parent.quadrant_x > 1 || parent.quadrant_y > 1 ||
      !mapAxis(width, parent_view.width_px,
               uint64_t(parent.quadrant_x) * parent.tile_size_px + parent.border_px, columns) ||
      !mapAxis(height, parent_view.height_px,
               uint64_t(parent.quadrant_y) * parent.tile_size_px + parent.border_px, rows))
    return fail(
        ErrorCode::kInvalidArgument,
        fmt::format("ptm: a {}x{} tile in quadrant ({},{}) at tile size {}, border {} "
                    "does not fit its {}x{} parent",
                    width, height, parent.quadrant_x, parent.quadrant_y, parent.tile_size_px,
                    parent.border_px, parent_view.width_px, parent_view.height_px));
  return {};
}

void appendU32(std::vector<uint8_t>& out, uint32_t value) {
  for (int i = 0; i < 4; ++i) out.push_back(uint8_t(value >> (8 * i)));
}

}  // namespace

Result<std::vector<uint8_t>> encodePtm(const ImageView& tile, const EncodeOptions& options,
                                       const ParentTexels* parent, Predictor predictor,
                                       CodecScratch* scratch) {
  ScratchRef state(scratch);
  const uint32_t width = tile.width_px, height = tile.height_px, channels = tile.channels;
  if (parent == nullptr) predictor = Predictor::kRoot;
  AxisMap columns, rows;
  const bool has_parent = predictor != Predictor::kRoot;
  if (has_parent)
    TESSERA_TRY(mapParent(parent->texels, *parent, width, height, channels, columns, rows));
  const SymbolCounts counts =
      countSymbols(width, height, has_parent ? &columns : nullptr, has_parent ? &rows : nullptr);

  std::span<const uint8_t> packed = packedTexels(tile, *state);
  state->plane.resize((counts.coded + counts.derived) * channels);
  Planes planes{};
  for (uint32_t c = 0; c < channels; ++c) {
    planes.residuals[c] = state->plane.data() + c * counts.coded;
    planes.remainders[c] = state->plane.data() + channels * counts.coded + c * counts.derived;
  }
  // Encoding only reads the texels; the shared routine takes a mutable pointer for decoding.
  code<true>(predictor, channels, const_cast<uint8_t*>(packed.data()), width, height,
             has_parent ? &parent->texels : nullptr, &columns, &rows, planes);

  const int level = options.effort != 0 ? options.effort : kDefaultZstdLevel;
  std::vector<uint8_t> payload = {uint8_t(predictor), 0};
  auto addStream = [&](const uint8_t* symbols, size_t count) -> Result<void> {
    if (count == 0) {
      appendU32(payload, 0);
      return {};
    }
    TESSERA_ASSIGN_OR_RETURN(std::vector<uint8_t> frame,
                             compressZstdFrame({symbols, count}, level, "ptm payload", *state));
    appendU32(payload, uint32_t(frame.size()));
    payload.insert(payload.end(), frame.begin(), frame.end());
    return {};
  };
  // The compressed frames reuse state->compressed, so the planes stay valid throughout.
  for (uint32_t c = 0; c < channels; ++c) TESSERA_TRY(addStream(planes.residuals[c], counts.coded));
  if (has_parent)
    for (uint32_t c = 0; c < channels; ++c)
      TESSERA_TRY(addStream(planes.remainders[c], counts.derived));
  return payload;
}

Result<void> decodePtm(std::span<const uint8_t> payload, Image& out, const ParentTexels* parent,
                       CodecScratch* scratch) {
  ScratchRef state(scratch);
  const uint32_t width = out.width_px, height = out.height_px, channels = out.channels;
  if (payload.size() < kHeaderBytes)
    return fail(ErrorCode::kCorrupt,
                fmt::format("ptm payload: {} bytes, shorter than its header", payload.size()));
  if (payload[0] > uint8_t(Predictor::kParentBilinear))
    return fail(ErrorCode::kCorrupt, fmt::format("ptm payload: unknown predictor {}", payload[0]));
  if (payload[1] != 0)
    return fail(ErrorCode::kCorrupt,
                fmt::format("ptm payload: reserved byte is {}, must be 0", payload[1]));
  const Predictor predictor = Predictor(payload[0]);
  const bool has_parent = predictor != Predictor::kRoot;
  if (has_parent && parent == nullptr)
    return fail(ErrorCode::kCorrupt,
                "ptm payload: coded against a parent tile, but the tile has none (coarsest "
                "level)");
  AxisMap columns, rows;
  if (has_parent)
    TESSERA_TRY(mapParent(parent->texels, *parent, width, height, channels, columns, rows));
  const SymbolCounts counts =
      countSymbols(width, height, has_parent ? &columns : nullptr, has_parent ? &rows : nullptr);

  state->plane.resize((counts.coded + counts.derived) * channels);
  Planes planes{};
  for (uint32_t c = 0; c < channels; ++c) {
    planes.residuals[c] = state->plane.data() + c * counts.coded;
    planes.remainders[c] = state->plane.data() + channels * counts.coded + c * counts.derived;
  }
  size_t position = kHeaderBytes;
  auto readStream = [&](uint8_t* symbols, size_t count, const char* what,
                        uint32_t channel) -> Result<void> {
    if (payload.size() - position < kStreamLengthBytes)
      return fail(ErrorCode::kCorrupt,
                  fmt::format("ptm payload: truncated before the {} of channel {}", what, channel));
    uint32_t length = 0;
    for (size_t i = 0; i < kStreamLengthBytes; ++i)
      length |= uint32_t(payload[position + i]) << (8 * i);
    position += kStreamLengthBytes;
    if (length > payload.size() - position)
      return fail(ErrorCode::kCorrupt,
                  fmt::format("ptm payload: {} of channel {} is {} bytes, only {} left", what,
                              channel, length, payload.size() - position));
    if (count == 0) {
      if (length != 0)
        return fail(ErrorCode::kCorrupt,
                    fmt::format("ptm payload: {} of channel {} must be empty", what, channel));
      return {};
    }
    const std::string name = fmt::format("ptm payload: {} of channel {}", what, channel);
    TESSERA_TRY(decompressZstdFrame(payload.subspan(position, length), {symbols, count},
                                    name.c_str(), *state));
    position += length;
    return {};
  };
  for (uint32_t c = 0; c < channels; ++c)
    TESSERA_TRY(readStream(planes.residuals[c], counts.coded, "residuals", c));
  if (has_parent)
    for (uint32_t c = 0; c < channels; ++c)
      TESSERA_TRY(readStream(planes.remainders[c], counts.derived, "remainders", c));
  if (position != payload.size())
    return fail(ErrorCode::kCorrupt,
                fmt::format("ptm payload: {} trailing bytes", payload.size() - position));
  code<false>(predictor, channels, out.texels.data(), width, height,
              has_parent ? &parent->texels : nullptr, &columns, &rows, planes);
  return {};
}

}  // namespace tessera::detail
