// ptm's lane coder (ptm_lanes.h, ptm_lanes_internal.h): the encoder, the section's parsing and
// the scalar decoder every processor runs. The SIMD decoder is in ptm_lanes_simd.h.
#include <algorithm>
#include <cstddef>
#include <cstring>
#include <memory>

#include "format/byte_io.h"
#include "ptm/ptm_lanes_internal.h"

namespace tessera::detail::ptm::lanes {

bool parse(std::span<const uint8_t> section, uint32_t channels, size_t extra_bytes,
           std::vector<uint8_t>& padded, Streams& streams) {
  const size_t header = headerBytes(channels);
  if (section.size() < header) return false;
  const uint8_t* at = section.data();
  for (uint32_t c = 0; c < channels; ++c)
    for (uint32_t k = 0; k < kLanes; ++k) {
      const uint32_t state = loadU32(at);
      at += 4;
      if (state < kLower) return false;
      streams.states[c][k] = state;
    }
  uint32_t lengths[4][2];
  size_t total = 0;
  for (uint32_t c = 0; c < channels; ++c)
    for (uint32_t i = 0; i < 2; ++i) {
      lengths[c][i] = loadU32(at);
      at += 4;
      total += lengths[c][i];
    }
  // Every byte belongs to a stream: a section that says otherwise is corrupt.
  if (total != section.size() - header) return false;
  for (uint32_t c = 0; c < channels; ++c)
    if (lengths[c][0] % 2 != 0) return false;
  padded.assign(total + 2 * channels * kPadding + extra_bytes, 0);
  uint8_t* to = padded.data();
  for (uint32_t c = 0; c < channels; ++c)
    for (uint32_t i = 0; i < 2; ++i) {
      std::memcpy(to, at, lengths[c][i]);
      (i == 0 ? streams.words : streams.escapes)[c] = to;
      (i == 0 ? streams.words_end : streams.escapes_end)[c] = to + lengths[c][i];
      at += lengths[c][i];
      to += lengths[c][i] + kPadding;
    }
  return true;
}

void sumLeastSquaresWeights(const int8_t* weights, uint32_t channels, int (&sums)[kLsSets][4]) {
  for (uint32_t set = 0; set < kLsSets; ++set)
    for (uint32_t c = 0; c < 4; ++c) {
      sums[set][c] = 0;
      if (c < channels)
        for (uint32_t k = 0; k < kLsTerms; ++k)
          sums[set][c] += weights[(set * channels + c) * kLsTerms + k];
    }
}

bool finished(const Streams& streams, uint32_t channels) {
  for (uint32_t c = 0; c < channels; ++c) {
    if (streams.words[c] != streams.words_end[c] || streams.escapes[c] != streams.escapes_end[c])
      return false;
    for (uint32_t k = 0; k < kLanes; ++k)
      if (streams.states[c][k] != kLower) return false;
  }
  return true;
}

void leadByGreen(std::span<const uint8_t> symbols, std::span<uint8_t> contexts, uint32_t channels) {
  for (size_t at = 0; at + channels <= contexts.size(); at += channels) {
    // A remainder's texel keeps its contexts: every channel of it is a remainder.
    if (contexts[at + kGreenChannel] >= kCodedContexts) continue;
    const uint32_t context = contexts[at + kGreenChannel];
    const uint32_t led =
        context / kActivityClasses * kActivityClasses +
        greenLedClass(context % kActivityClasses, symbols[at + kGreenChannel] == 0);
    for (uint32_t c = 0; c < channels; ++c)
      if (followsGreen(c)) contexts[at + c] = uint8_t(led);
  }
}

namespace {

// --- scalar ---------------------------------------------------------------------------------

// One symbol of channel `c` in lane `lane`: the residual byte, or false at corrupt input.
bool decodeSymbol(Streams& s, uint32_t c, uint32_t lane, const rans::Model& model,
                  uint8_t& residual) {
  uint32_t& x = s.states[c][lane];
  const uint32_t slot = x & (kScale - 1);
  const uint32_t symbol = model.bucket_symbol[slot];
  const uint32_t entry = model.entry[symbol];
  x = (entry >> 16) * (x >> kScaleBits) + slot - (entry & 0xffff);
  if (x < kLower) {
    if (s.words_end[c] - s.words[c] < 2) return false;
    x = (x << 16) | uint32_t(s.words[c][0]) | uint32_t(s.words[c][1]) << 8;
    s.words[c] += 2;
  }
  uint32_t code = symbol;
  if (symbol == kEscape) {
    if (s.escapes[c] == s.escapes_end[c]) return false;
    code = *s.escapes[c]++;
    if (code < kEscape) return false;
  }
  residual = rans::unzigzag(code);
  return true;
}

// Predictor 4: a decoded texel's departure from the upsampled parent, which the texels after it
// read as neighbours.
void keepDetail(const Geometry& g, size_t index) {
  if (!g.corrected) return;
  for (uint32_t c = 0; c < g.channels; ++c)
    g.detail[index + c] = int16_t(16 * g.texels[index + c] - g.upsampled[index + c]);
}

// Predictor 5's prediction of channel c of texel (x, y) at block position `position`, as the
// walk makes it (leastSquaresPredictFactored): `texel` points at the channel, `estimate16` is
// predictor 4's estimate and `median` the neighbours' median.
int leastSquaresPrediction(const Geometry& g, uint32_t x, uint32_t y, uint32_t position, uint32_t c,
                           const uint8_t* texel, const NeighbourOffsets& n, bool origin,
                           int estimate16, int median) {
  const uint32_t ch = g.channels;
  const uint8_t* parent_row = g.parent->row(g.rows->parent[y]);
  const uint8_t* parent_near = g.parent->row(g.rows->neighbour[y]);
  const size_t at = size_t(g.columns->parent[x]) * ch + c;
  const size_t side_at = size_t(g.columns->neighbour[x]) * ch + c;
  return leastSquaresPredictFactored(g.ls_weights + (position * ch + c) * kLsTerms,
                                     g.ls_weight_sums[position][c], texel, n.left, n.up, n.up_left,
                                     n.up_right, origin, parent_row + at, parent_row + side_at,
                                     parent_near + at, parent_near + side_at, estimate16, median);
}

// Texel (x, y) decoded by `lane`, with the shared walk's rules for its predictor (any but 2) and
// coder 1 (ptm_walk.h, codeTexels).
bool decodeTexel(const Geometry& g, Streams& s, uint32_t x, uint32_t y, uint32_t lane) {
  const uint32_t ch = g.channels;
  const size_t index = (size_t(y) * g.width + x) * ch;
  uint8_t* texel = g.texels + index;
  const NeighbourOffsets neighbours = neighbourOffsets(x, y, g.width, ch);
  const auto [left, up, up_left, up_right] = neighbours;
  const bool origin = x == 0 && y == 0;
  int activity = 0;
  if (!origin)
    for (uint32_t c = 0; c < ch; ++c) {
      const int n = texel[up + c], nw = texel[up_left + c];
      activity +=
          std::abs(texel[left + c] - nw) + std::abs(n - nw) + std::abs(texel[up_right + c] - n);
    }
  const uint32_t activity_class = activityClass(activity, ch);
  const rans::Model* const* models = g.models;
  if (g.has_parent && g.rows->derived[y] != 0 && g.columns->derived[x] != 0) {
    // Marvie & Bouatouch eq. 3, with the remainder the median expects (codeTexels).
    const uint8_t* p = g.parent->row(g.rows->parent[y]) + size_t(g.columns->parent[x]) * ch;
    const uint8_t* b = texel + up;
    const uint8_t* a = texel + up_left;
    const uint8_t* c3 = texel + left;
    for (uint32_t c = 0; c < ch; ++c) {
      const uint32_t known = 4u * p[c] - a[c] - b[c] - c3[c];
      // The remainder the guess at d implies; predictor 1 expects none.
      uint32_t expected = 0;
      if (!g.nearest) {
        int guess = medPredict(c3[c], b[c], a[c]);
        if (g.least_squares) {
          // Predictor 5's guess, with predictor 4's estimate without the block's pull.
          int estimate16 = 0;
          if (g.corrected) {
            const int16_t* d = g.detail + index + c;
            estimate16 = g.upsampled[index + c] + medPredict(d[left], d[up], d[up_left]);
          }
          guess = leastSquaresPrediction(g, x, y, 3, c, texel + c, neighbours, false, estimate16,
                                         guess);
        }
        expected = uint32_t(std::clamp(guess + a[c] + b[c] + c3[c] - 4 * p[c], 0, 3));
      }
      uint8_t symbol;
      if (!decodeSymbol(s, c, lane, *models[c * g.contexts + kCodedContexts + activity_class],
                        symbol))
        return false;
      texel[c] = uint8_t(known + expected + symbol);
    }
    keepDetail(g, index);
    return true;
  }
  const uint32_t position = g.has_parent ? 2u * g.rows->second[y] + g.columns->second[x] : 0u;
  const uint32_t context = position * kActivityClasses + activity_class;
  uint8_t symbols[4];
  if (g.green_led) {
    // Green first: red's and blue's contexts follow its residual.
    if (!decodeSymbol(s, kGreenChannel, lane, *models[kGreenChannel * g.contexts + context],
                      symbols[kGreenChannel]))
      return false;
    const uint32_t led =
        position * kActivityClasses + greenLedClass(activity_class, symbols[kGreenChannel] == 0);
    for (uint32_t c = 0; c < ch; ++c)
      if (c != kGreenChannel &&
          !decodeSymbol(s, c, lane, *models[c * g.contexts + (followsGreen(c) ? led : context)],
                        symbols[c]))
        return false;
  } else {
    for (uint32_t c = 0; c < ch; ++c)
      if (!decodeSymbol(s, c, lane, *models[c * g.contexts + context], symbols[c])) return false;
  }
  if (ch >= 3) {
    symbols[0] = uint8_t(symbols[0] + symbols[1]);
    symbols[2] = uint8_t(symbols[2] + symbols[1]);
  }
  const bool full = g.corrected && g.rows->full[y] != 0 && g.columns->full[x] != 0;
  for (uint32_t c = 0; c < ch; ++c) {
    // Through `neighbours`: a lambda may not capture structured bindings before C++20, and
    // clang 14 (the fuzz build's) does not yet allow it.
    auto median = [&] {
      return origin ? 0
                    : medPredict(texel[neighbours.left + c], texel[neighbours.up + c],
                                 texel[neighbours.up_left + c]);
    };
    int predicted = 0;
    if (g.corrected || g.least_squares) {
      const int estimate =
          g.corrected
              ? parentCorrectedEstimate(
                    g.upsampled + index + c, g.detail + index + c, texel + c, neighbours, origin,
                    full, position, g.parent->row(g.rows->parent[y])[g.columns->parent[x] * ch + c],
                    ch, size_t(g.width) * ch)
              : 0;
      predicted = g.least_squares ? leastSquaresPrediction(g, x, y, position, c, texel + c,
                                                           neighbours, origin, estimate, median())
                                  : parentCorrectedPrediction(estimate);
    } else if (g.nearest) {
      predicted = g.parent->row(g.rows->parent[y])[g.columns->parent[x] * ch + c];
    } else {
      predicted = median();
    }
    texel[c] = uint8_t(predicted + symbols[c]);
  }
  keepDetail(g, index);
  return true;
}

bool decodeScalar(const Geometry& g, Streams& s) {
  const uint32_t steps = stepsPerBand(g.width);
  for (uint32_t y0 = 0; y0 < g.height; y0 += kLanes) {
    const uint32_t rows = std::min(kLanes, g.height - y0);
    for (uint32_t t = 0; t < steps; ++t)
      for (uint32_t k = 0; k < rows; ++k) {
        if (t < 2 * k || t - 2 * k >= g.width) continue;
        if (!decodeTexel(g, s, t - 2 * k, y0 + k, k)) return false;
      }
  }
  return true;
}

}  // namespace

bool simdAvailable() {
  static const bool available = __builtin_cpu_supports("avx2") != 0;
  return available;
}

bool avx512Available() {
  static const bool available = simdAvailable() && __builtin_cpu_supports("avx512f") != 0 &&
                                __builtin_cpu_supports("avx512vl") != 0 &&
                                __builtin_cpu_supports("avx512bw") != 0 &&
                                __builtin_cpu_supports("avx512dq") != 0;
  return available;
}

namespace {

// A model's kScale entries of the SIMD decoders' symbol table (slotTables()).
void fillSlots(const rans::Model& model, uint32_t* slots) {
  for (uint32_t symbol = 0; symbol < rans::kAlphabet; ++symbol) {
    const uint32_t freq = model.freq[symbol], first = symbol | freq << kFreqShift;
    // Entry i of the run: the bias i added to the symbol and frequency (the fields do not
    // overlap, so the sum is the or of the format).
    uint32_t* run = slots + model.start[symbol];
    for (uint32_t i = 0; i < freq; ++i) run[i] = first + (i << kBiasShift);
  }
}

}  // namespace

const uint32_t* slotTables() {
  static const std::unique_ptr<uint32_t[]> tables = [] {
    auto built = std::make_unique<uint32_t[]>(size_t(rans::kModelCount) * kScale);
    const rans::Model* family = rans::models(kFamily);
    for (uint32_t m = 0; m < rans::kModelCount; ++m)
      fillSlots(family[m], built.get() + size_t(m) * kScale);
    return built;
  }();
  return tables.get();
}

void slotModels(std::span<const rans::Model* const> context_models, SlotModels& out) {
  const rans::Model* family = rans::models(kFamily);
  const auto family_from = reinterpret_cast<uintptr_t>(family);
  const auto family_to = reinterpret_cast<uintptr_t>(family + rans::kModelCount);
  uint32_t tables = 0;
  for (size_t i = 0; i < context_models.size(); ++i) {
    const auto at = reinterpret_cast<uintptr_t>(context_models[i]);
    if (at >= family_from && at < family_to)
      out.offsets[i] = int32_t((context_models[i] - family) * kScale);
    else
      out.offsets[i] = int32_t((rans::kModelCount + tables++) * kScale);
  }
  if (tables == 0) {
    out.tables = slotTables();
    return;
  }
  // Each thread writes its tiles' tables behind its own copy of the family's entries: 4 MiB
  // copied once per decoding thread, against a copy of the tile's family models at every tile.
  thread_local std::unique_ptr<uint32_t[]> with_room;
  if (with_room == nullptr) {
    with_room = std::make_unique_for_overwrite<uint32_t[]>(
        size_t(rans::kModelCount + 4 * kParentContexts) * kScale);
    std::memcpy(with_room.get(), slotTables(), size_t(rans::kModelCount) * kScale * 4);
  }
  for (size_t i = 0; i < context_models.size(); ++i)
    if (out.offsets[i] >= int32_t(rans::kModelCount * kScale))
      fillSlots(*context_models[i], with_room.get() + out.offsets[i]);
  out.tables = with_room.get();
}

void encode(std::span<const uint8_t> symbols, std::span<const uint8_t> contexts, uint32_t width,
            uint32_t height, uint32_t channels, uint32_t contexts_per_channel,
            std::span<const rans::Model* const> context_models, std::vector<uint8_t>& out) {
  // Escape bytes in decoding order; words in reverse (rANS codes backwards), per channel.
  std::vector<uint8_t> escapes[4];
  std::vector<uint16_t> words[4];
  uint32_t states[4][kLanes];
  for (auto& channel : states)
    for (uint32_t& state : channel) state = kLower;
  const uint32_t steps = stepsPerBand(width);
  for (uint32_t y0 = 0; y0 < height; y0 += kLanes) {
    const uint32_t rows = std::min(kLanes, height - y0);
    for (uint32_t t = 0; t < steps; ++t)
      for (uint32_t k = 0; k < rows; ++k) {
        if (t < 2 * k || t - 2 * k >= width) continue;
        const size_t at = (size_t(y0 + k) * width + (t - 2 * k)) * channels;
        for (uint32_t c = 0; c < channels; ++c) {
          const uint32_t code = rans::zigzag(symbols[at + c]);
          if (code >= kEscape) escapes[c].push_back(uint8_t(code));
        }
      }
  }
  const uint32_t bands = (height + kLanes - 1) / kLanes;
  for (uint32_t band = bands; band-- > 0;) {
    const uint32_t y0 = band * kLanes;
    const uint32_t rows = std::min(kLanes, height - y0);
    for (uint32_t t = steps; t-- > 0;)
      for (uint32_t k = rows; k-- > 0;) {
        if (t < 2 * k || t - 2 * k >= width) continue;
        const size_t at = (size_t(y0 + k) * width + (t - 2 * k)) * channels;
        for (uint32_t c = 0; c < channels; ++c) {
          const uint32_t symbol = std::min(rans::zigzag(symbols[at + c]), kEscape);
          const rans::Model& model = *context_models[c * contexts_per_channel + contexts[at + c]];
          const uint32_t freq = model.freq[symbol];
          uint32_t& x = states[c][k];
          // x stays below 2^32 after coding: x < freq * 2^20 before it.
          if (x >= (freq << (32 - kScaleBits))) {
            words[c].push_back(uint16_t(x));
            x >>= 16;
          }
          x = ((x / freq) << kScaleBits) + x % freq + model.start[symbol];
        }
      }
  }
  for (uint32_t c = 0; c < channels; ++c)
    for (uint32_t k = 0; k < kLanes; ++k) appendU32(out, states[c][k]);
  for (uint32_t c = 0; c < channels; ++c) {
    appendU32(out, uint32_t(words[c].size() * 2));
    appendU32(out, uint32_t(escapes[c].size()));
  }
  for (uint32_t c = 0; c < channels; ++c) {
    for (size_t i = words[c].size(); i-- > 0;) {
      out.push_back(uint8_t(words[c][i]));
      out.push_back(uint8_t(words[c][i] >> 8));
    }
    out.insert(out.end(), escapes[c].begin(), escapes[c].end());
  }
}

bool decode(std::span<const uint8_t> section, const Walk& walk, uint32_t channels,
            Predictor predictor, std::span<const rans::Model* const> context_models, bool green_led,
            std::vector<uint8_t>& padded, Path path) {
  if (green_led && channels < 3) return false;
  if (path == Path::kFastest && avx512Available())
    return avx512::decodeSimd(section, walk, channels, predictor, context_models, green_led,
                              padded);
  if ((path == Path::kFastest || path == Path::kAvx2) && simdAvailable())
    return avx2::decodeSimd(section, walk, channels, predictor, context_models, green_led, padded);
  // The scalar lanes read predictor 4's planes, which prepareWalk leaves out where the SIMD
  // decoder was to run (decodesWithoutPlanes).
  if (computesParentCorrectedEstimate(predictor, walk) && walk.upsampled == nullptr) return false;
  Streams streams;
  if (!parse(section, channels, 0, padded, streams)) return false;
  Geometry geometry{walk.texels,
                    walk.width,
                    walk.height,
                    channels,
                    predictor != Predictor::kRoot,
                    predictor == Predictor::kParentNearest,
                    computesParentCorrectedEstimate(predictor, walk),
                    predictor == Predictor::kLeastSquares,
                    walk.parent,
                    walk.columns,
                    walk.rows,
                    context_models.data(),
                    uint32_t(context_models.size() / channels),
                    walk.upsampled,
                    walk.detail,
                    walk.ls_weights,
                    {}};
  if (geometry.least_squares)
    sumLeastSquaresWeights(walk.ls_weights, channels, geometry.ls_weight_sums);
  geometry.green_led = green_led;
  return decodeScalar(geometry, streams) && finished(streams, channels);
}

}  // namespace tessera::detail::ptm::lanes
