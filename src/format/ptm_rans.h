#pragma once
// The ptm codec's context-modelled entropy coder (docs/codecs.md, "ptm (6)", coder 1): byte-wise
// rANS with one state per channel over a shared byte stream, whose symbol distributions come
// from a fixed family of discretised geometric distributions, so a tile sends one byte per
// context instead of a frequency table. Decoding never reads outside its input and never
// loops: renormalisation takes at most two bytes, and a read past the end returns 0 and sets a
// flag that the caller checks once at the end.

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace tessera::detail::rans {

inline constexpr uint32_t kScaleBits = 12;
inline constexpr uint32_t kScale = 1u << kScaleBits;
/// Symbols 0..62 are zigzag residuals; 63 escapes a residual of 63..255, sent as 8 uniform bits.
inline constexpr uint32_t kAlphabet = 64;
inline constexpr uint32_t kEscape = kAlphabet - 1;
/// Distributions in the family: every value of a context's parameter byte names one (models
/// 0-63 are the first family's, so payloads written with it decode unchanged).
inline constexpr uint32_t kModelCount = 256;
/// The lower bound of the state between symbols, and the value every state starts at.
inline constexpr uint32_t kLower = 1u << 23;

/// One member of the family: frequencies summing to kScale, each at least 1.
struct Model {
  uint16_t freq[kAlphabet];
  uint16_t start[kAlphabet];
  uint8_t symbol_of_slot[kScale];
  float cost_bits[kAlphabet];  ///< encoder only: -log2 of the symbol's probability
};

/// The family, built once (thread-safe) with integer arithmetic only, so every platform
/// derives identical tables.
const Model* models();

/// Zigzag map of a residual byte read as a signed value: 0, -1, 1, -2, ... -> 0, 1, 2, 3, ...
inline uint32_t zigzag(uint8_t residual) {
  const int value = int8_t(residual);
  return value >= 0 ? uint32_t(2 * value) : uint32_t(-2 * value - 1);
}
inline uint8_t unzigzag(uint32_t code) {
  return uint8_t((code & 1) != 0 ? -int(code >> 1) - 1 : int(code >> 1));
}

/// Bounded forward reader of the encoded bytes.
class Decoder {
 public:
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
    uint32_t symbol = decodeSymbol(state, model);
    if (symbol == kEscape) [[unlikely]] {
      // Uniform 8 bits: frequency kScale / 256 for every byte value.
      uint32_t& x = state_[state];
      const uint32_t slot = x & (kScale - 1);
      symbol = slot >> (kScaleBits - 8);
      x = (kScale >> 8) * (x >> kScaleBits) + (slot & ((kScale >> 8) - 1));
      renormalise(x);
      if (symbol < kEscape) failed_ = true;  // the encoder escapes only what 0..62 cannot say
    }
    return unzigzag(symbol);
  }

  /// True when every symbol was read from inside the input, all of it was used, and every
  /// state ended where the encoder started it.
  bool finishedCleanly(uint32_t states) const {
    if (failed_ || next_ != end_) return false;
    for (uint32_t s = 0; s < states; ++s)
      if (state_[s] != kLower) return false;
    return true;
  }

 private:
  uint32_t decodeSymbol(uint32_t state, const Model& model) {
    uint32_t& x = state_[state];
    const uint32_t slot = x & (kScale - 1);
    const uint32_t symbol = model.symbol_of_slot[slot];
    x = model.freq[symbol] * (x >> kScaleBits) + slot - model.start[symbol];
    renormalise(x);
    return symbol;
  }

  // x >= kLower before a decode and freq >= 1 leave x >= 2^11, so two bytes always suffice.
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

/// Encodes `residuals[i]` (channel i % channels) with model `models()[params[context]]` where
/// context = `contexts[i]` + channel * contexts_per_channel, in reverse, so that Decoder reads
/// them in order i = 0, 1, .... Appends the states and bytes to `out`.
void encode(std::span<const uint8_t> residuals, std::span<const uint8_t> contexts,
            uint32_t channels, uint32_t contexts_per_channel, std::span<const uint8_t> params,
            std::vector<uint8_t>& work, std::vector<uint8_t>& out);

/// For each (channel, context), the model that codes its residuals in the fewest bits, by
/// counting: `params` gets channels * contexts_per_channel bytes (0 for unused contexts).
/// Returns the bits the symbols cost under those models, which encode() meets to within a few
/// bytes (its final states).
double chooseModels(std::span<const uint8_t> residuals, std::span<const uint8_t> contexts,
                    uint32_t channels, uint32_t contexts_per_channel, std::vector<uint8_t>& params);

}  // namespace tessera::detail::rans
