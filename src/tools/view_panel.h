#pragma once
// The size and place of `tessera view`'s panel, and the part of a history ring its graphs
// plot: plain arithmetic, so that what the panel covers is tested without a window.

#include <algorithm>
#include <cstddef>

namespace tessera::cli {

/// The panel's box in a framebuffer of fb_w x fb_h pixels.
struct PanelLayout {
  float x = 10;  ///< left edge, px
  float y = 10;  ///< top edge, px
  /// Width, px: the panel's text wraps at it instead of running off its edge.
  float width = 0;
  /// Height at most, px: the panel fits its open sections up to this and scrolls beyond.
  float max_height = 0;
};

/// A panel that leaves the picture visible: about a quarter of the window's width (280 to
/// 360 px, and never more than the window less its margins), at most the window's height
/// less its margins. The sections are tabs, the streaming one shown first, so that the panel
/// covers less than an eighth of a 1280x720 window.
inline PanelLayout panelLayout(int fb_w, int fb_h) {
  constexpr float kMargin = 10;
  PanelLayout layout;
  const float room_w = std::max(0.0f, float(fb_w) - 2 * kMargin);
  layout.width = std::min(room_w, std::clamp(0.24f * float(fb_w), 280.0f, 360.0f));
  layout.max_height = std::max(0.0f, float(fb_h) - 2 * kMargin);
  return layout;
}

/// What to plot of a ring of `capacity` samples whose next write goes to `next`, holding
/// `count` so far: only the samples recorded (a graph padded with zeros looks empty at
/// first), oldest first, on a scale from zero to a little above the largest of them.
struct PlotWindow {
  int count = 0;      ///< samples to plot
  int offset = 0;     ///< index of the oldest in the ring
  float max = 1;      ///< top of the scale
  float largest = 0;  ///< the largest sample plotted
};

inline PlotWindow plotWindow(const float* ring, size_t capacity, size_t next, size_t count,
                             float smallest_max) {
  PlotWindow window;
  window.count = int(std::min(count, capacity));
  window.offset = count < capacity ? 0 : int(next % capacity);
  for (int i = 0; i < window.count; ++i)
    window.largest = std::max(window.largest, ring[(size_t(window.offset) + size_t(i)) % capacity]);
  window.max = std::max(smallest_max, window.largest * 1.25f);
  return window;
}

}  // namespace tessera::cli
