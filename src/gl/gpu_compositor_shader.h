#pragma once
// The GPU compositor's fragment shader: one fragment per stored-tile texel loops over the
// tile's instances in drawing order and does, in integers, what sampleInstance, the mask and
// blendTexel do on the CPU (src/procedural/kernel.cpp), line for line, so that the texels are
// the same. The per-instance setup (double arithmetic) stays on the CPU and arrives as 16.16
// fixed-point integers; 64-bit integers (GL_ARB_gpu_shader_int64) hold them as the CPU does.

namespace tessera::gl {

/// Per instance: kSetupInt64s 64-bit values and kParamInts 32-bit ones (layouts in
/// gpu_compositor.cpp, `packInstance`).
inline constexpr int kSetupInt64s = 8;
inline constexpr int kParamInts = 16;

inline const char* const kCompositorVertexShader = R"(#version 450 core
void main() {
  // One triangle over the whole viewport.
  vec2 corner = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
  gl_Position = vec4(corner * 2.0 - 1.0, 0.0, 1.0);
}
)";

/// Follows a "#version 450 core", the extension and the two #defines of the sizes above.
inline const char* const kCompositorFragmentShader =
    R"(layout(std430, binding = 0) readonly buffer BrushTexels { uint brush_texels[]; };  // RGBA8
layout(std430, binding = 1) readonly buffer LayerBytes { uint layer_bytes[]; };    // 4 a uint
layout(std430, binding = 2) readonly buffer MaskTables { uint mask_tables[]; };    // 256 a brush
layout(std430, binding = 3) readonly buffer Setups { int64_t setups[]; };
layout(std430, binding = 4) readonly buffer Params { int params[]; };
// Per stored-tile column x0, x1, fx, then per row y0, y1, fy: the layer's bilinear taps.
layout(std430, binding = 5) readonly buffer LayerTaps { int layer_taps[]; };

uniform ivec2 origin;         // level texel of stored texel (0, 0)
uniform ivec4 valid;          // i0, i1, j0, j1: stored texels inside the level
uniform int instance_count;
uniform int side;
uniform int layer_width;      // width of the layer mip the level reads
uniform uint layer_offsets[3];  // byte offset of that mip: [1] height, [2] slope

out uvec4 colour;

uint div255(uint x) {
  uint t = x + 128u;
  return (t + (t >> 8)) >> 8;
}

uint bilinear(uint t00, uint t10, uint t01, uint t11, uint fx, uint fy) {
  uint h0 = (t00 * (256u - fx) + t10 * fx + 128u) >> 8;
  uint h1 = (t01 * (256u - fx) + t11 * fx + 128u) >> 8;
  return (h0 * (256u - fy) + h1 * fy + 128u) >> 8;
}

uvec4 brushTexel(uint index) {
  uint p = brush_texels[index];
  return uvec4(p & 255u, (p >> 8) & 255u, (p >> 16) & 255u, p >> 24);
}

uint layerByte(uint index) {
  return (layer_bytes[index >> 2] >> (8u * (index & 3u))) & 255u;
}

uint blendChannel(int mode, uint b, uint s) {
  if (mode == 1) return div255(b * s);
  if (mode == 2) return min(255u, b + s);
  if (mode == 3) return b < 128u ? div255(2u * b * s) : 255u - div255(2u * (255u - b) * (255u - s));
  return s;
}

uint layerValue(int source, int ci, int cj) {
  uint base = layer_offsets[source];
  int c = 3 * ci, r = 3 * (side + cj);
  uint x0 = uint(layer_taps[c]), x1 = uint(layer_taps[c + 1]), fx = uint(layer_taps[c + 2]);
  uint y0 = uint(layer_taps[r]), y1 = uint(layer_taps[r + 1]), fy = uint(layer_taps[r + 2]);
  uint w = uint(layer_width), gx = 256u - fx, gy = 256u - fy;
  return ((layerByte(base + y0 * w + x0) * gx + layerByte(base + y0 * w + x1) * fx) * gy +
          (layerByte(base + y1 * w + x0) * gx + layerByte(base + y1 * w + x1) * fx) * fy +
          32768u) >> 16;
}

void main() {
  ivec2 ij = ivec2(gl_FragCoord.xy);
  // Texels past the level's edge repeat the nearest valid one (compositeTile's edge copy).
  int ci = clamp(ij.x, valid.x, valid.y - 1), cj = clamp(ij.y, valid.z, valid.w - 1);
  int64_t x = int64_t(origin.x + ci), y = int64_t(origin.y + cj);
  uvec4 dst = uvec4(0u);
  for (int n = 0; n < instance_count; ++n) {
    int p = n * PARAM_INTS;
    // The instance's rectangle: its reach, the valid rectangle and its clip.
    if (ci < params[p] || ci >= params[p + 1] || cj < params[p + 2] || cj >= params[p + 3]) continue;
    int q = n * SETUP_INT64S;
    int64_t dx = x - setups[q], dy = y - setups[q + 1];
    int64_t u = setups[q + 2] + setups[q + 4] * dx + setups[q + 5] * dy;
    int64_t v = setups[q + 3] + setups[q + 6] * dx + setups[q + 7] * dy;
    int64_t x0l = u >> 16, y0l = v >> 16;
    int w = params[p + 13], h = params[p + 14];
    if (x0l < -1l || x0l >= int64_t(w) || y0l < -1l || y0l >= int64_t(h)) continue;
    int x0 = int(x0l), y0 = int(y0l);
    uint fx = uint(u >> 8) & 255u, fy = uint(v >> 8) & 255u;
    // Taps outside the image have alpha 0 and the colour of the nearest edge texel.
    bool in_x0 = x0 >= 0, in_x1 = x0 + 1 < w, in_y0 = y0 >= 0, in_y1 = y0 + 1 < h;
    int cx0 = in_x0 ? x0 : 0, cx1 = in_x1 ? x0 + 1 : w - 1;
    int cy0 = in_y0 ? y0 : 0, cy1 = in_y1 ? y0 + 1 : h - 1;
    uint base = uint(params[p + 12]);
    uvec4 t00 = brushTexel(base + uint(cy0 * w + cx0)), t10 = brushTexel(base + uint(cy0 * w + cx1));
    uvec4 t01 = brushTexel(base + uint(cy1 * w + cx0)), t11 = brushTexel(base + uint(cy1 * w + cx1));
    uint alpha = bilinear(in_x0 && in_y0 ? t00.a : 0u, in_x1 && in_y0 ? t10.a : 0u,
                          in_x0 && in_y1 ? t01.a : 0u, in_x1 && in_y1 ? t11.a : 0u, fx, fy);
    if (alpha == 0u) continue;
    uvec4 s;
    for (int c = 0; c < 3; ++c)
      s[c] = div255(bilinear(t00[c], t10[c], t01[c], t11[c], fx, fy) * uint(params[p + 4 + c]));
    alpha = div255(div255(alpha * uint(params[p + 7])) * uint(params[p + 8]));
    if (alpha == 0u) continue;
    int mask = params[p + 10];
    if (mask != 0) {
      alpha = div255(alpha * mask_tables[uint(params[p + 11]) + layerValue(mask, ci, cj)]);
      if (alpha == 0u) continue;
    }
    int mode = params[p + 9];
    uint ab = dst.a;
    if (ab == 255u) {
      for (int c = 0; c < 3; ++c)
        dst[c] = div255(alpha * blendChannel(mode, dst[c], s[c]) + (255u - alpha) * dst[c]);
    } else if (ab == 0u) {
      dst = uvec4(s.rgb, alpha);
    } else {
      uint backdrop_weight = div255(ab * (255u - alpha));
      uint ao = alpha + backdrop_weight;
      for (int c = 0; c < 3; ++c) {
        uint b = dst[c];
        uint mixed = div255((255u - ab) * s[c] + ab * blendChannel(mode, b, s[c]));
        dst[c] = (alpha * mixed + backdrop_weight * b + ao / 2u) / ao;
      }
      dst.a = ao;
    }
  }
  colour = dst;
}
)";

}  // namespace tessera::gl
