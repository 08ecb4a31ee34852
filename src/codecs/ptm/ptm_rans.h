#pragma once
// ptm's context-modelled entropy coder (docs/codecs.md, "ptm (6)"): byte-wise rANS with one
// state per channel over a shared byte stream (Giesen's ryg_rans), whose distributions come
// from a fixed family, so that a tile sends one byte per context instead of a frequency table,
// and a table only for a context that no family model fits well enough ("Tables"). Decoding
// never reads outside its input and takes a bounded number of steps per symbol; a read past the
// end returns 0 and sets a flag the caller checks at the end. ptm_rans.cpp builds the families
// and reads tables; the encoder's half is ptm_rans_encode.cpp (tessera::encoders).

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace tessera::detail::rans {

/// Symbols 0..62 are zigzag residuals; 63 escapes a residual of 63..255.
inline constexpr uint32_t kAlphabet = 64;
inline constexpr uint32_t kEscape = kAlphabet - 1;
/// Models per family: every value of a context's model byte names one.
inline constexpr uint32_t kModelCount = 256;
/// The states' lower bound between symbols, and where every state starts and ends.
inline constexpr uint32_t kLower = 1u << 23;
/// A slot's symbol comes from 4096 buckets per model, each naming the symbol of its first slot:
/// one slot per bucket at 12 bits; at 15 bits 8, and a bucket where a symbol ends is marked
/// kSharedBucket and sends the decoder on a short search.
inline constexpr uint32_t kBucketBits = 12;
inline constexpr uint32_t kBuckets = 1u << kBucketBits;
inline constexpr uint8_t kSharedBucket = 0x80;

/// Family 1: 12-bit probabilities, geometric in the zigzag code or in |residual|. Family 2:
/// 15-bit, geometric mixtures with heavier tails (docs/codecs.md).
enum class FamilyId : uint8_t { kGeometric12, kMixture15 };
constexpr uint32_t scaleBits(FamilyId family) {
  return family == FamilyId::kGeometric12 ? 12 : 15;
}

/// Models of one kind (shape) per family: model kind * meansPerKind + k has the kind's k-th mean.
constexpr uint32_t meansPerKind(FamilyId family) {
  return family == FamilyId::kGeometric12 ? 64 : 32;
}

/// One distribution: frequencies summing to the family's scale, each at least 1.
struct Model {
  uint8_t bucket_symbol[kBuckets];  ///< kSharedBucket set where another symbol starts inside
  uint32_t entry[kAlphabet + 1];    ///< start | freq << 16; entry[kAlphabet] is the scale
  uint16_t freq[kAlphabet];
  uint16_t start[kAlphabet];
  float cost_bits[kAlphabet];  ///< encoder only: -log2 of the symbol's probability

  template <uint32_t kScaleBits>
  uint32_t symbolOf(uint32_t slot) const {
    uint32_t symbol = bucket_symbol[slot >> (kScaleBits - kBucketBits)];
    if constexpr (kScaleBits > kBucketBits) {
      if ((symbol & kSharedBucket) != 0) [[unlikely]] {
        symbol &= ~uint32_t(kSharedBucket);
        while (slot >= (entry[symbol + 1] & 0xffff)) ++symbol;
      }
    }
    return symbol;
  }
};

/// A family's kModelCount models, built once (thread-safe) in integers, so that every platform
/// derives the same tables.
const Model* models(FamilyId family);

/// A residual byte read as signed, zigzagged: 0, -1, 1, -2, ... -> 0, 1, 2, 3, ...
inline uint32_t zigzag(uint8_t residual) {
  const int value = int8_t(residual);
  return value >= 0 ? uint32_t(2 * value) : uint32_t(-2 * value - 1);
}
inline uint8_t unzigzag(uint32_t code) {
  return uint8_t((code & 1) != 0 ? -int(code >> 1) - 1 : int(code >> 1));
}

/// Bounded forward reader of a stream of kScaleBits-bit models.
template <uint32_t kScaleBits>
class Decoder {
 public:
  static constexpr uint32_t kScale = 1u << kScaleBits;
  // After a decode x >= (kLower >> kScaleBits) * freq >= 2^8: two bytes always renormalise.
  static_assert(kScaleBits <= 15 && kScaleBits >= 8);

  /// `bytes` starts with `states` initial states, u32 LE each. False when they are missing or
  /// out of range.
  bool start(std::span<const uint8_t> bytes, uint32_t states) {
    next_ = bytes.data();
    end_ = bytes.data() + bytes.size();
    if (bytes.size() < size_t(states) * 4) return false;
    for (uint32_t s = 0; s < states; ++s) {
      uint32_t x = 0;
      for (int i = 0; i < 4; ++i) x |= uint32_t(*next_++) << (8 * i);
      if (x < kLower || x >= (kLower << 8)) return false;
      state_[s] = x;
    }
    return true;
  }

  /// One residual byte of state `state` under `model`.
  [[gnu::always_inline]] uint8_t decode(uint32_t state, const Model& model) {
    uint32_t& x = state_[state];
    const uint32_t slot = x & (kScale - 1);
    uint32_t symbol = model.symbolOf<kScaleBits>(slot);
    const uint32_t entry = model.entry[symbol];
    x = (entry >> 16) * (x >> kScaleBits) + slot - (entry & 0xffff);
    renormalise(x);
    if (symbol == kEscape) [[unlikely]] {
      // 8 uniform bits, each byte value of frequency kScale / 256.
      const uint32_t uniform_slot = x & (kScale - 1);
      symbol = uniform_slot >> (kScaleBits - 8);
      x = (kScale >> 8) * (x >> kScaleBits) + (uniform_slot & ((kScale >> 8) - 1));
      renormalise(x);
      if (symbol < kEscape) failed_ = true;  // the encoder escapes only what 0..62 cannot say
    }
    return unzigzag(symbol);
  }

  /// True once a read passed the end or an escape was malformed.
  bool failed() const { return failed_; }
  /// True when all of the input was read, no more, and every state is back at kLower.
  bool finishedCleanly(uint32_t states) const {
    if (failed_ || next_ != end_) return false;
    for (uint32_t s = 0; s < states; ++s)
      if (state_[s] != kLower) return false;
    return true;
  }

 private:
  [[gnu::always_inline]] void renormalise(uint32_t& x) {
    if (x < kLower) {
      x = (x << 8) | nextByte();
      if (x < kLower) x = (x << 8) | nextByte();
    }
  }
  [[gnu::always_inline]] uint8_t nextByte() {
    if (next_ == end_) [[unlikely]] {
      failed_ = true;
      return 0;
    }
    return *next_++;
  }

  const uint8_t* next_ = nullptr;
  const uint8_t* end_ = nullptr;
  uint32_t state_[4] = {kLower, kLower, kLower, kLower};
  bool failed_ = false;
};

/// Explicit tables: a table gives each symbol s < count a level 0..63, 0 for an absent symbol,
/// else q for a weight of 2^((q - 1) / 4); frequencies follow as a family model's do.
inline constexpr uint32_t kTableLevels = 64;
inline constexpr uint32_t kTableLevelBits = 6;
/// Bytes of a table of `count` symbols: the count, then the levels packed 6 bits each.
constexpr size_t tableBytes(uint32_t count) {
  return 1 + (size_t(count) * kTableLevelBits + 7) / 8;
}
/// The model of a table at `scale_bits`; without `costs` cost_bits is left as it was.
void buildTableModel(const uint8_t* levels, uint32_t count, uint32_t scale_bits, Model& model,
                     bool costs = true);
/// What builds a model from weights, shared with the encoder's pricing of tables: the weights
/// of a table's levels, frequencies summing to 2^scale_bits (each at least 1, the first largest
/// taking up the rounding), and a symbol's bits at a frequency (an escape's with its 8 bits).
void tableWeights(const uint8_t* levels, uint32_t count, uint64_t (&weight)[kAlphabet]);
void frequencies(const uint64_t (&weight)[kAlphabet], uint32_t scale_bits,
                 uint16_t (&freq)[kAlphabet]);
double symbolBits(uint32_t scale_bits, uint16_t freq, uint32_t symbol);
/// Reads a tables section of `context_count` contexts at the start of `bytes` into `models` and
/// `context_models` (whose family entries the caller set): the section's length, or 0 when it
/// is truncated, flags no context or one past the last, a count is outside 1..64, a table has
/// no weight or padding bits are set.
size_t readTables(std::span<const uint8_t> bytes, uint32_t context_count, uint32_t scale_bits,
                  std::vector<Model>& models, std::span<const Model*> context_models);

// The encoder's half (ptm_rans_encode.cpp, tessera::encoders).

/// How often each symbol occurs in each context: counts[context * kAlphabet + symbol], with
/// context = channel * contexts_per_channel + contexts[i] for residuals[i] of channel
/// i % channels and symbol its zigzag code, kEscape from kEscape on.
struct ContextCounts {
  uint32_t context_count = 0;
  std::vector<uint32_t> counts;
};
ContextCounts countByContext(std::span<const uint8_t> residuals, std::span<const uint8_t> contexts,
                             uint32_t channels, uint32_t contexts_per_channel);
/// Each context's model of `family` that codes its symbols in the fewest bits (0 when unused)
/// into `params`; returns the bits, which encode() meets to within its final states.
double chooseModels(FamilyId family, const ContextCounts& counts, std::vector<uint8_t>& params);
/// Moves contexts onto models other contexts of `params` already use, the smallest contexts
/// first, where that costs at most `slack` of the context's bits plus a byte: fewer distinct
/// models for coder 7's decoder, whose tables compete for its cache. Returns the bits.
double shareModels(FamilyId family, const ContextCounts& counts, double slack,
                   std::vector<uint8_t>& params);
/// The tables a payload sends, and every context's model with them.
struct Tables {
  std::vector<uint8_t> section;  ///< bitmap of flagged contexts, then their tables
  std::vector<Model> models;     ///< one per table, in context order
  std::vector<const Model*> context_models;
  double bits = 0;  ///< the symbols' bits under context_models
};
/// A context takes a table where its bits fall by more than the table's bytes plus
/// `min_gain_bytes`. False, with only context_models set, where none pays for the bitmap too.
bool chooseTables(FamilyId family, const ContextCounts& counts, std::span<const uint8_t> params,
                  Tables& tables, double min_gain_bytes);
/// Appends the states and bytes of `residuals` (channel i % channels, context contexts[i]),
/// coded backwards under `context_models`, so that Decoder reads them in order.
void encode(FamilyId family, std::span<const uint8_t> residuals, std::span<const uint8_t> contexts,
            uint32_t channels, uint32_t contexts_per_channel,
            std::span<const Model* const> context_models, std::vector<uint8_t>& work,
            std::vector<uint8_t>& out);

}  // namespace tessera::detail::rans
