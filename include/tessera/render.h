#pragma once
/// \file
/// What a view shows, independent of any GPU: the sampling rules every renderer follows
/// (docs/rendering.md), the CPU reference renderer that applies them straight from the
/// archive (the ground truth for the GPU renderers), and picture comparison.
///
/// Sampling rules, in short. Screen pixel (px, py) has its centre at (px + 0.5, py + 0.5), row
/// 0 at the top. Its level-0 texel coordinate (u, v) (texel (i, j) covers [i, i+1) x [j, j+1))
/// comes from the view (`textureAt`, tessera/view.h). Its level of detail is lambda =
/// log2(rho), rho the larger of |d(u,v)/dx| and |d(u,v)/dy| in level-0 texels per pixel
/// (OpenGL's rule; `levelOfDetailAt`). With
/// L = floor(lambda) clamped to the levels, the pixel shows the finest level T >= L that is
/// available there (its tile resident): if T == L < coarsest, bilinear at L blended with
/// bilinear at L + 1 by lambda - L (trilinear); otherwise bilinear at T. Bilinear at a level
/// samples that level's texel grid at (u, v) / 2^level, clamped to the level's image (edge
/// texels replicate, as stored tile borders and padding do). Pixels whose (u, v) falls
/// outside the level-0 image, or whose ray misses the ground, are transparent black.

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <tessera/archive.h>
#include <tessera/result.h>
#include <tessera/view.h>

namespace tessera {

/// An RGBA8 picture, rows top to bottom. Channels an image lacks are filled as a renderer
/// shows them: grey as (g, g, g, 255), grey+alpha as (g, g, g, a), RGB with alpha 255.
struct Picture {
  uint32_t width = 0;
  uint32_t height = 0;
  std::vector<uint8_t> rgba;  ///< width * height * 4 bytes
};

/// What the reference may sample: `available(tile)` says whether a tile is resident (a GPU
/// renderer holding exactly those tiles should draw the same picture); empty means every
/// tile of the archive is.
struct ReferenceOptions {
  std::function<bool(const TileId&)> available;
};

/// Draws `view` on the CPU from the archive's tiles by the sampling rules above. Reads and
/// decodes the tiles it needs (each once per call). Fails naming the archive and the tile when
/// one cannot be read or decoded; kInvalidArgument for an image the archive lacks;
/// kUnsupported for a u16 or f32 image (the GL renderers draw those through a display window).
/// Level L + 1 of a trilinear blend is sampled whether or not `available` lists its tile (the
/// streamer keeps parents of resident tiles resident). Runs on the calling thread, which may
/// be any: the archive is thread-safe and `available` is called only from this call.
[[nodiscard]] Result<Picture> renderReference(const Archive& archive, const View& view,
                                              const ReferenceOptions& options = {});

/// The level each pixel of `view` shows by the sampling rules (the finest available level at
/// or above floor(lambda); the next level may blend in), row-major, -1 outside the image or
/// where nothing is available. Reads no tile: for level overlays (Backes et al., Fig. 1).
/// Fails (kInvalidArgument) for an image the archive lacks. Any thread, as renderReference.
[[nodiscard]] Result<std::vector<int32_t>> levelsShown(const Archive& archive, const View& view,
                                                       const ReferenceOptions& options = {});

/// How far two pictures of the same size are apart, over all four channels.
struct PictureDifference {
  double psnr_db = 0;    ///< +infinity when identical
  uint32_t max_abs = 0;  ///< largest difference of one channel, 0..255
  double mean_abs = 0;   ///< mean absolute difference per channel
};

/// Compares two pictures; fails (kInvalidArgument) when their sizes differ. Thread-safe.
[[nodiscard]] Result<PictureDifference> comparePictures(const Picture& a, const Picture& b);

}  // namespace tessera
