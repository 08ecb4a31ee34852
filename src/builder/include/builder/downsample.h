#pragma once
// 2x2 box downsampling of one pair of rows (docs/format.md, "Levels"): the builder's pyramid
// and the archive updater (src/update) average with these, so an updated region equals a build.

#include <cstdint>

#include <tessera/format.h>

namespace tessera::detail {

/// Averages `top` and `bottom` (the same pointer for an odd image's last row) in 2x2 blocks
/// into `out`, ceil(width / 2) texels; an odd last column is averaged with itself.
/// Each channel is the rounded mean (sum + 2) / 4. With alpha (2 or 4 channels) colour is
/// weighted by alpha, so transparent no-data texels do not darken their neighbours; a block
/// that is fully transparent becomes all zero. With `srgb`, colour is averaged in linear light.
void downsampleRowPair(const uint8_t* top, const uint8_t* bottom, uint32_t width, uint32_t channels,
                       bool srgb, uint8_t* out);

/// downsampleRowPair without the vector kernels: the rule written out one texel at a time,
/// kept as the oracle the vector kernels are tested against (the same bytes for every input).
void downsampleRowPairScalar(const uint8_t* top, const uint8_t* bottom, uint32_t width,
                             uint32_t channels, bool srgb, uint8_t* out);

/// The integer pyramid of progressive texture maps (Marvie & Bouatouch, eq. 1 with the integer
/// solution of eq. 3): every channel, alpha included and unweighted, is floor(sum / 4), so the
/// remainder sum % 4 lets a child be rebuilt from its parent. Same geometry as
/// downsampleRowPair: an odd last row or column is averaged with itself, as if the level were
/// extended by replicating its edge, which is what tiles' padding does (docs/format.md, "ptm").
void downsampleRowPairFloor(const uint8_t* top, const uint8_t* bottom, uint32_t width,
                            uint32_t channels, uint8_t* out);

/// downsampleRowPair for samples wider than a byte (docs/builder.md, "16-bit and float").
/// u16: the rounded mean, alpha-weighted as for 8-bit (64-bit sums, no overflow). f32: each
/// channel, alpha included and unweighted, is the mean in double of the block's samples that
/// are not NaN, rounded once to float; a block whose four samples are all NaN gives the first
/// one's bits; infinities propagate (+Inf with -Inf gives NaN, as IEEE addition does).
void downsampleRowPairWide(const uint8_t* top, const uint8_t* bottom, uint32_t width,
                           uint32_t channels, SampleType type, uint8_t* out);

}  // namespace tessera::detail
