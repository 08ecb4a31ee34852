// Fuzzes the coverage hints decoder (docs/format.md, "Coverage hints"). Input: the scene's
// texture count (u32, little-endian), then the block's bytes. Checks that an accepted block is
// canonical (it re-encodes to exactly its bytes) and that every cell's entries lie in range and
// in order, so the streamer may index by them without checks of its own.
#include <algorithm>

#include "format/coverage_hints.h"
#include "format_fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace tessera;
  fuzz::InputReader input({data, size});
  if (!input.has(4)) return 0;
  const uint32_t textures = uint32_t(input.take(4));
  const std::span<const uint8_t> bytes = input.rest();
  Result<CoverageHints> hints = detail::decodeCoverageHints(bytes, textures, "fuzz");
  if (!hints) {
    if (hints.error().message.empty())
      fuzz::die("coverage_hints_fuzzer", "error without a message");
    return 0;
  }
  for (uint32_t c = 0; c < hints->cellCount(); ++c) {
    uint32_t previous = 0;
    bool first = true;
    for (const CoverageHint& e : hints->cell(c)) {
      if (e.texture >= textures || e.coverage_q == 0 || (!first && e.texture <= previous))
        fuzz::die("coverage_hints_fuzzer", "accepted an entry out of range or order");
      previous = e.texture;
      first = false;
    }
  }
  const std::vector<uint8_t> again = detail::encodeCoverageHints(*hints);
  if (again.size() != bytes.size() || !std::equal(again.begin(), again.end(), bytes.begin()))
    fuzz::die("coverage_hints_fuzzer", "an accepted block does not re-encode to its bytes");
  return 0;
}
