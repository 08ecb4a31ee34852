#pragma once
// The ptm codec's context-modelled entropy coder (docs/codecs.md, "ptm (6)", coders 1-6):
// byte-wise rANS with one state per channel over a shared byte stream, whose symbol
// distributions come from a fixed family of discretised distributions, so a tile sends one
// byte per context instead of a frequency table, and a table only for a context that no
// family model fits well enough to be worth its bytes ("Tables"). Decoding never reads
// outside its input and takes a bounded number of steps per symbol: renormalisation at most
// two bytes, the symbol search at most kAlphabet; a read past the end returns 0 and sets a
// flag that the caller checks once at the end.

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace tessera::detail::rans {

/// Symbols 0..62 are zigzag residuals; 63 escapes a residual of 63..255, sent as 8 uniform bits.
inline constexpr uint32_t kAlphabet = 64;
inline constexpr uint32_t kEscape = kAlphabet - 1;
/// Distributions in each family: every value of a context's parameter byte names one.
inline constexpr uint32_t kModelCount = 256;
/// The lower bound of the state between symbols, and the value every state starts at.
inline constexpr uint32_t kLower = 1u << 23;
/// The decoder finds a slot's symbol in a table of kBuckets buckets per model, each naming the
/// symbol of its first slot: at 12 bits a bucket is one slot; at 15 bits it is 8, and a bucket
/// in which a symbol ends is marked kSharedBucket and sends the decoder on a short search over
/// the starts (rare, so the branch stays predicted). A full 15-bit table would be 32 KiB per
/// model; buckets holding frequency and start instead, 2^6 to 2^10 of them, decoded 10 %
/// slower.
inline constexpr uint32_t kBucketBits = 12;
inline constexpr uint8_t kSharedBucket = 0x80;
inline constexpr uint32_t kBuckets = 1u << kBucketBits;

/// The two model families (docs/codecs.md, "ptm (6)"). Coders 1 and 2 use the first, coders 3
/// to 5 the second.
enum class FamilyId : uint8_t {
  /// 12-bit probabilities; geometric in the zigzag code (models 0-63, so payloads written
  /// before the other kinds existed decode unchanged) or in |residual| with symbol 0's weight
  /// as is, doubled or halved.
  kGeometric12,
  /// 15-bit probabilities; mostly geometric mixtures in |residual|, a geometric plus a share
  /// of one with the fourth root of its ratio, for the heavier tails that contexts of mixed
  /// activity see (the eight kinds: docs/codecs.md).
  kMixture15,
};

/// The probability resolution of a family, in bits.
constexpr uint32_t scaleBits(FamilyId family) {
  return family == FamilyId::kGeometric12 ? 12 : 15;
}

/// One member of a family: frequencies summing to the family's scale, each at least 1.
struct Model {
  /// The symbol of each bucket's first slot, with kSharedBucket where another starts inside.
  uint8_t bucket_symbol[kBuckets];
  /// start | freq << 16 per symbol; entry[kAlphabet] is the sentinel start, the scale.
  uint32_t entry[kAlphabet + 1];
  uint16_t freq[kAlphabet];
  uint16_t start[kAlphabet];
  float cost_bits[kAlphabet];  ///< encoder only: -log2 of the symbol's probability

  /// The symbol whose slots [start, start + freq) hold `slot` (below the scale).
  template <uint32_t kScaleBits>
  uint32_t symbolOf(uint32_t slot) const {
    static_assert(kScaleBits >= kBucketBits);
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

/// A family's kModelCount models, built once (thread-safe) with integer arithmetic only, so
/// every platform derives identical tables.
const Model* models(FamilyId family);

/// Zigzag map of a residual byte read as a signed value: 0, -1, 1, -2, ... -> 0, 1, 2, 3, ...
inline uint32_t zigzag(uint8_t residual) {
  const int value = int8_t(residual);
  return value >= 0 ? uint32_t(2 * value) : uint32_t(-2 * value - 1);
}
inline uint8_t unzigzag(uint32_t code) {
  return uint8_t((code & 1) != 0 ? -int(code >> 1) - 1 : int(code >> 1));
}

/// Bounded forward reader of the encoded bytes, for models of kScaleBits-bit probabilities.
template <uint32_t kScaleBits>
class Decoder {
 public:
  static constexpr uint32_t kScale = 1u << kScaleBits;
  // After a decode x >= (kLower >> kScaleBits) * freq >= 2^8, so two bytes always renormalise.
  static_assert(kScaleBits <= 15 && kScaleBits >= 8);

  /// `bytes` starts with the initial state of each of `states` channels (u32 LE each).
  /// Returns false when the bytes cannot hold them or a state is out of range.
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

  /// Decodes one residual byte of channel `state` under `model`.
  uint8_t decode(uint32_t state, const Model& model) {
    uint32_t& x = state_[state];
    const uint32_t slot = x & (kScale - 1);
    uint32_t symbol = model.symbolOf<kScaleBits>(slot);
    const uint32_t entry = model.entry[symbol];
    x = (entry >> 16) * (x >> kScaleBits) + slot - (entry & 0xffff);
    renormalise(x);
    if (symbol == kEscape) [[unlikely]] {
      // Uniform 8 bits: frequency kScale / 256 for every byte value.
      const uint32_t uniform_slot = x & (kScale - 1);
      symbol = uniform_slot >> (kScaleBits - 8);
      x = (kScale >> 8) * (x >> kScaleBits) + (uniform_slot & ((kScale >> 8) - 1));
      renormalise(x);
      if (symbol < kEscape) failed_ = true;  // the encoder escapes only what 0..62 cannot say
    }
    return unzigzag(symbol);
  }

  /// True once a symbol was read past the end of the input or an escape was malformed: the
  /// stream can no longer finish cleanly.
  bool failed() const { return failed_; }

  /// True when every symbol was read from inside the input, all of it was used, and every
  /// state ended where the encoder started it.
  bool finishedCleanly(uint32_t states) const {
    if (failed_ || next_ != end_) return false;
    for (uint32_t s = 0; s < states; ++s)
      if (state_[s] != kLower) return false;
    return true;
  }

 private:
  void renormalise(uint32_t& x) {
    if (x < kLower) {
      x = (x << 8) | nextByte();
      if (x < kLower) x = (x << 8) | nextByte();
    }
  }

  uint8_t nextByte() {
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

/// Encodes `residuals[i]` (channel i % channels) with model `context_models[context]` where
/// context = `contexts[i]` + channel * contexts_per_channel, in reverse, so that Decoder reads
/// them in order i = 0, 1, .... Appends the states and bytes to `out`.
void encode(FamilyId family, std::span<const uint8_t> residuals, std::span<const uint8_t> contexts,
            uint32_t channels, uint32_t contexts_per_channel,
            std::span<const Model* const> context_models, std::vector<uint8_t>& work,
            std::vector<uint8_t>& out);

/// How often each symbol occurs in each context, the same for both families, so that every
/// choice made for one walk's symbols counts them once: counts[context * kAlphabet + symbol],
/// with context = channel * contexts_per_channel + contexts[i] for residuals[i] of channel
/// i % channels, and symbol the zigzag code, kEscape for any code from kEscape on.
struct ContextCounts {
  uint32_t context_count = 0;
  std::vector<uint32_t> counts;
};
ContextCounts countByContext(std::span<const uint8_t> residuals, std::span<const uint8_t> contexts,
                             uint32_t channels, uint32_t contexts_per_channel);

/// Explicit tables (docs/codecs.md, "ptm (6)", "Tables"): a context whose symbols a table of
/// their own codes in fewer bits than its family model, the table's bytes included, sends one.
/// A table gives each symbol s < count a level 0..63: 0 for an absent symbol, else q for a
/// weight of 2^((q - 1) / 4); symbols from count on have level 0. Frequencies follow from the
/// weights as a family model's do (each at least 1), so every table is a valid model.
inline constexpr uint32_t kTableLevels = 64;
inline constexpr uint32_t kTableLevelBits = 6;

/// Bytes of a table of `count` symbols: the count, then the levels packed 6 bits each.
constexpr size_t tableBytes(uint32_t count) {
  return 1 + (size_t(count) * kTableLevelBits + 7) / 8;
}

/// The model of a table: `levels[s]` for s < count, 0 after; `scale_bits` as the family's.
/// Without `costs`, cost_bits is left as it was: only encoders read it.
void buildTableModel(const uint8_t* levels, uint32_t count, uint32_t scale_bits, Model& model,
                     bool costs = true);

/// The tables a payload sends, and every context's model with them.
struct Tables {
  /// As in the payload: a bitmap of channels * contexts_per_channel bits (bit i of byte i / 8
  /// for context i, channel-major), then each flagged context's table in context order.
  std::vector<uint8_t> section;
  std::vector<Model> models;  ///< one per table, in context order
  /// Every context's model: a table's, else the family model its parameter byte names.
  std::vector<const Model*> context_models;
  /// The symbols' bits under context_models (table bytes not included).
  double bits = 0;
};

/// Chooses the tables for symbols whose family models are `params` (chooseModels'): a context
/// takes one where its bits fall by more than the table's bytes plus `min_gain_bytes` (the
/// price a coder sets on a table's decoding). Returns false, and `tables` empty but for
/// context_models, when no context gains enough to pay for the bitmap too.
bool chooseTables(FamilyId family, const ContextCounts& counts, std::span<const uint8_t> params,
                  Tables& tables, double min_gain_bytes = 0);

/// Reads a tables section of `context_count` contexts at the start of `bytes` into `models` and
/// `context_models` (whose family entries the caller set): the section's length, or 0 when it
/// is truncated, a count is outside 1..64, or padding bits are set. The models are for
/// decoding: their cost_bits are not computed.
size_t readTables(std::span<const uint8_t> bytes, uint32_t context_count, uint32_t scale_bits,
                  std::vector<Model>& models, std::span<const Model*> context_models);

/// For each (channel, context), the model of `family` that codes its residuals in the fewest
/// bits: `params` gets one byte per context of `counts` (0 for unused contexts). Returns the
/// bits the symbols cost under those models, which encode() meets to within a few bytes (its
/// final states).
double chooseModels(FamilyId family, const ContextCounts& counts, std::vector<uint8_t>& params);

/// Moves contexts onto models that other contexts of `params` (chooseModels') already use,
/// the contexts with the fewest symbols first, wherever that costs at most `slack` of the
/// context's bits plus one byte: fewer distinct models, for a decoder whose per-model tables
/// compete for its cache (coder 7's, 16 KiB each). Returns the bits the symbols cost under
/// the models it leaves in `params`.
double shareModels(FamilyId family, const ContextCounts& counts, double slack,
                   std::vector<uint8_t>& params);

}  // namespace tessera::detail::rans
