#pragma once
// Payload clustering orders (docs/format.md, "Clustering"): the sequence in which a writer
// lays out the payloads of an image's tiles, so that tiles close on screen are close in the
// file and a clip region is read with few, large reads.

#include <cstdint>
#include <vector>

#include <tessera/format.h>

namespace tessera::detail {

/// Position of (x, y) along a Hilbert curve filling a 2^bits x 2^bits square.
uint64_t hilbertIndex(uint32_t bits, uint32_t x, uint32_t y);

/// Every tile of `info`'s pyramid (tagged with `image`) in `order`:
/// kHilbert and kRowMajor go coarsest level first, then Hilbert or row order within a level;
/// kQuadtree is a depth-first pre-order walk from the coarsest level, parent before its four
/// children (Zhou et al., depth-first clustering), so any subtree is one contiguous run.
std::vector<TileId> tileOrder(const ImageInfo& info, uint32_t image, TileOrder order);

}  // namespace tessera::detail
