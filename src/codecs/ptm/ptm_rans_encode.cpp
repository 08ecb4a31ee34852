// ptm's rANS, the encoder's half (ptm_rans.h): symbol counts, the choice of each context's
// family model, model sharing, explicit tables and the byte-wise rANS pass.
#include <algorithm>
#include <cmath>
#include <utility>

#include "ptm/ptm_rans.h"

namespace tessera::detail::rans {

namespace {

// Bits of `count`'s symbols under `model`.
double bitsUnder(const uint32_t* count, const Model& model) {
  double bits = 0;
  for (uint32_t s = 0; s < kAlphabet; ++s)
    if (count[s] != 0) bits += count[s] * double(model.cost_bits[s]);
  return bits;
}

// The level that stands for a frequency `f` at the family's scale: 4 log2 f, rounded, plus 1.
uint8_t levelOf(double f) {
  return uint8_t(
      std::clamp(std::lround(4 * std::log2(std::max(1.0, f))), 0L, long(kTableLevels) - 2) + 1);
}

// One rANS step (Giesen's ryg_rans): bytes go out backwards.
template <uint32_t kScaleBits>
void put(uint32_t& x, uint32_t start, uint32_t freq, uint8_t*& out) {
  const uint32_t x_max = ((kLower >> kScaleBits) << 8) * freq;
  while (x >= x_max) {
    *--out = uint8_t(x);
    x >>= 8;
  }
  x = ((x / freq) << kScaleBits) + (x % freq) + start;
}

template <uint32_t kScaleBits>
void encodeAt(std::span<const uint8_t> residuals, std::span<const uint8_t> contexts,
              uint32_t channels, uint32_t contexts_per_channel,
              std::span<const Model* const> context_models, std::vector<uint8_t>& work,
              std::vector<uint8_t>& out) {
  // Each symbol emits at most 2 bytes, an escaped one 4; then 4 bytes of state per channel.
  work.resize(residuals.size() * 4 + 16);
  uint8_t* const end = work.data() + work.size();
  uint8_t* cursor = end;
  uint32_t state[4] = {kLower, kLower, kLower, kLower};
  uint32_t channel = uint32_t(residuals.size() % channels);
  for (size_t i = residuals.size(); i-- > 0;) {
    channel = channel == 0 ? channels - 1 : channel - 1;
    const Model& model = *context_models[channel * contexts_per_channel + contexts[i]];
    const uint32_t z = zigzag(residuals[i]);
    if (z >= kEscape) {
      constexpr uint32_t kUniform = (1u << kScaleBits) >> 8;
      put<kScaleBits>(state[channel], z * kUniform, kUniform, cursor);
      put<kScaleBits>(state[channel], model.start[kEscape], model.freq[kEscape], cursor);
    } else {
      put<kScaleBits>(state[channel], model.start[z], model.freq[z], cursor);
    }
  }
  for (uint32_t c = channels; c-- > 0;)
    for (int shift = 24; shift >= 0; shift -= 8) *--cursor = uint8_t(state[c] >> shift);
  out.insert(out.end(), cursor, end);
}

// Appends the table of `symbols` levels to `section`, 6 bits each from the low bits on.
void appendTable(const uint8_t* level, uint32_t symbols, std::vector<uint8_t>& section) {
  section.push_back(uint8_t(symbols));
  uint32_t acc = 0, acc_bits = 0;
  for (uint32_t s = 0; s < symbols; ++s) {
    acc |= uint32_t(level[s]) << acc_bits;
    for (acc_bits += kTableLevelBits; acc_bits >= 8; acc_bits -= 8, acc >>= 8)
      section.push_back(uint8_t(acc));
  }
  if (acc_bits > 0) section.push_back(uint8_t(acc));
}

}  // namespace

ContextCounts countByContext(std::span<const uint8_t> residuals, std::span<const uint8_t> contexts,
                             uint32_t channels, uint32_t contexts_per_channel) {
  ContextCounts out;
  out.context_count = channels * contexts_per_channel;
  out.counts.assign(size_t(out.context_count) * kAlphabet, 0);
  uint32_t channel = 0;  // a counter, not i % channels: a division per symbol is slow
  for (size_t i = 0; i < residuals.size(); ++i) {
    const uint32_t z = zigzag(residuals[i]);
    const uint32_t context = channel * contexts_per_channel + contexts[i];
    ++out.counts[size_t(context) * kAlphabet + (z < kEscape ? z : kEscape)];
    if (++channel == channels) channel = 0;
  }
  return out;
}

double chooseModels(FamilyId family_id, const ContextCounts& context_counts,
                    std::vector<uint8_t>& params) {
  const Model* family = models(family_id);
  const uint32_t means = meansPerKind(family_id);
  const uint32_t coarse_step = family_id == FamilyId::kGeometric12 ? 8 : 4;
  params.assign(context_counts.context_count, 0);
  double total_bits = 0;
  for (uint32_t context = 0; context < context_counts.context_count; ++context) {
    const uint32_t* count = &context_counts.counts[size_t(context) * kAlphabet];
    // A context sees few distinct symbols, so each model is priced over those alone.
    uint32_t used_count = 0;
    uint8_t used[kAlphabet];
    double used_weight[kAlphabet];
    for (uint32_t s = 0; s < kAlphabet; ++s)
      if (count[s] != 0) {
        used_weight[used_count] = count[s];
        used[used_count++] = uint8_t(s);
      }
    if (used_count == 0) continue;
    auto bitsOf = [&](uint32_t k) {
      double bits = 0;
      for (uint32_t i = 0; i < used_count; ++i)
        bits += used_weight[i] * double(family[k].cost_bits[used[i]]);
      return bits;
    };
    // Within a kind the cost falls and then rises with the mean: every coarse_step-th mean, then
    // the neighbours of the best of those.
    double best = -1;
    for (uint32_t first = 0; first < kModelCount; first += means) {
      uint32_t coarse = first;
      double coarse_bits = -1;
      for (uint32_t k = first + coarse_step / 2; k < first + means; k += coarse_step) {
        const double bits = bitsOf(k);
        if (coarse_bits < 0 || bits < coarse_bits) {
          coarse_bits = bits;
          coarse = k;
        }
      }
      const uint32_t low = coarse >= first + coarse_step - 1 ? coarse - (coarse_step - 1) : first;
      const uint32_t high = std::min(first + means - 1, coarse + coarse_step - 1);
      for (uint32_t k = low; k <= high; ++k) {
        const double bits = k == coarse ? coarse_bits : bitsOf(k);
        if (best < 0 || bits < best) {
          best = bits;
          params[context] = uint8_t(k);
        }
      }
    }
    total_bits += best;
  }
  return total_bits;
}

double shareModels(FamilyId family_id, const ContextCounts& context_counts, double slack,
                   std::vector<uint8_t>& params) {
  const Model* family = models(family_id);
  auto countOf = [&](uint32_t context) { return &context_counts.counts[context * kAlphabet]; };
  // The used contexts by symbol count, and how many use each model.
  std::vector<std::pair<uint64_t, uint32_t>> by_size;
  uint32_t users[kModelCount] = {};
  for (uint32_t context = 0; context < context_counts.context_count; ++context) {
    uint64_t symbols = 0;
    for (uint32_t s = 0; s < kAlphabet; ++s) symbols += countOf(context)[s];
    if (symbols == 0) continue;
    by_size.emplace_back(symbols, context);
    ++users[params[context]];
  }
  std::sort(by_size.begin(), by_size.end());
  double total_bits = 0;
  for (const auto& [symbols, context] : by_size) {
    const uint32_t own_model = params[context];
    const double own = bitsUnder(countOf(context), family[own_model]);
    double best = own;
    // A model another context shares already stays.
    if (users[own_model] == 1) {
      double cheapest = -1;
      uint32_t cheapest_model = own_model;
      for (uint32_t model = 0; model < kModelCount; ++model) {
        if (users[model] == 0 || model == own_model) continue;
        const double bits = bitsUnder(countOf(context), family[model]);
        if (cheapest < 0 || bits < cheapest) {
          cheapest = bits;
          cheapest_model = model;
        }
      }
      if (cheapest >= 0 && cheapest <= own * (1 + slack) + 8) {
        best = cheapest;
        --users[own_model];
        ++users[cheapest_model];
        params[context] = uint8_t(cheapest_model);
      }
    }
    total_bits += best;
  }
  return total_bits;
}

bool chooseTables(FamilyId family_id, const ContextCounts& context_counts,
                  std::span<const uint8_t> params, Tables& tables, double min_gain_bytes) {
  const uint32_t context_count = context_counts.context_count;
  const uint32_t scale_bits = scaleBits(family_id);
  const Model* family = models(family_id);
  tables = {};
  tables.context_models.resize(context_count);
  std::vector<uint8_t> levels(size_t(context_count) * kAlphabet, 0);
  std::vector<uint32_t> flagged, table_symbols;
  double saved_bits = 0;
  for (uint32_t context = 0; context < context_count; ++context) {
    const uint32_t* count = &context_counts.counts[size_t(context) * kAlphabet];
    tables.context_models[context] = &family[params[context]];
    const double bits = bitsUnder(count, family[params[context]]);
    tables.bits += bits;
    double total = 0;
    uint32_t symbols = 0;
    for (uint32_t s = 0; s < kAlphabet; ++s)
      if (count[s] != 0) {
        total += count[s];
        symbols = s + 1;
      }
    if (symbols == 0) continue;
    uint8_t* level = &levels[size_t(context) * kAlphabet];
    for (uint32_t s = 0; s < symbols; ++s)
      if (count[s] != 0) level[s] = levelOf(count[s] * double(1u << scale_bits) / total);
    // The candidate's frequencies alone price it.
    uint64_t weight[kAlphabet];
    uint16_t freq[kAlphabet];
    tableWeights(level, symbols, weight);
    frequencies(weight, scale_bits, freq);
    double table_bits = 0;
    for (uint32_t s = 0; s < symbols; ++s)
      if (count[s] != 0) table_bits += count[s] * symbolBits(scale_bits, freq[s], s);
    const double gain = bits - table_bits - 8.0 * double(tableBytes(symbols));
    if (gain <= 8.0 * min_gain_bytes) continue;
    saved_bits += gain;
    flagged.push_back(context);
    table_symbols.push_back(symbols);
  }
  const size_t bitmap_bytes = (context_count + 7) / 8;
  if (flagged.empty() || saved_bits <= 8.0 * double(bitmap_bytes)) return false;
  tables.section.assign(bitmap_bytes, 0);
  tables.models.resize(flagged.size());
  for (size_t t = 0; t < flagged.size(); ++t) {
    const uint32_t context = flagged[t], symbols = table_symbols[t];
    const uint8_t* level = &levels[size_t(context) * kAlphabet];
    tables.section[context / 8] |= uint8_t(1u << (context % 8));
    appendTable(level, symbols, tables.section);
    Model& model = tables.models[t];
    buildTableModel(level, symbols, scale_bits, model);
    const uint32_t* count = &context_counts.counts[size_t(context) * kAlphabet];
    for (uint32_t s = 0; s < symbols; ++s)
      tables.bits += count[s] * (double(model.cost_bits[s]) -
                                 double(tables.context_models[context]->cost_bits[s]));
    tables.context_models[context] = &model;
  }
  return true;
}

void encode(FamilyId family, std::span<const uint8_t> residuals, std::span<const uint8_t> contexts,
            uint32_t channels, uint32_t contexts_per_channel,
            std::span<const Model* const> context_models, std::vector<uint8_t>& work,
            std::vector<uint8_t>& out) {
  if (family == FamilyId::kGeometric12)
    encodeAt<12>(residuals, contexts, channels, contexts_per_channel, context_models, work, out);
  else
    encodeAt<15>(residuals, contexts, channels, contexts_per_channel, context_models, work, out);
}

}  // namespace tessera::detail::rans
