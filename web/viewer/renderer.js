// WebGL2 drawing of the web viewer: one texture per resident tile (borders included), each
// drawn as a quad over the level-0 rectangle it covers, with texture coordinates that skip its
// stored border. Levels are drawn coarsest first, each over the last, so a coarser tile shows
// wherever a finer one is missing (nothing is blank once the coarsest level is in); the
// desired level L is blended over level L + 1 with weight 1 - f (constant blend alpha), which
// is the trilinear filter of docs/rendering.md for an orthographic view (lambda is the same at
// every pixel). Bilinear sampling of a tile with border >= 1 reads its neighbours' texels from
// the border, as the reference does; quads are cut at the image's edges, where the stored
// padding replicates the edge texels as the reference's clamping does. Archives without a
// border are filtered in the shader, as the native tile-quads renderer does
// (docs/rendering.md): each quad also gets the 3 x 3 tiles around it, and the four texels of a
// bilinear footprint come from whichever of them holds each; a neighbour that is not resident
// lends nothing, its texels come from the nearest texels of the tile itself. Tiles of a bc1
// or bc7 archive may be compressed textures of the stored blocks, padded past the stored
// tile's last column and row to whole blocks: bordered quads scale their texture coordinates
// by the padded side, and the unbordered shader's texel fetches never reach the padding.

import { tileRect } from './view.js';

const VERTEX_SHADER = `#version 300 es
precision highp float;
// The quad's corner in 0..1, its level-0 rectangle relative to the view centre, its texture
// coordinates, and the view: texels per pixel, rotation and viewport.
in vec2 a_corner;
uniform vec4 u_rect;      // u0 - cx, v0 - cy, u1 - cx, v1 - cy (level-0 texels)
uniform vec4 u_texRect;   // s0, t0, s1, t1 in the stored tile's 0..1 range
uniform vec2 u_viewport;  // device pixels
uniform float u_tpp;
uniform vec2 u_rotation;  // cos, sin
out vec2 v_tex;
void main() {
  vec2 rel = mix(u_rect.xy, u_rect.zw, a_corner) / u_tpp;
  // Inverse of u = cx + tpp (c dx - s dy), v = cy + tpp (s dx + c dy).
  vec2 screen = vec2(u_rotation.x * rel.x + u_rotation.y * rel.y,
                     -u_rotation.y * rel.x + u_rotation.x * rel.y) + 0.5 * u_viewport;
  gl_Position = vec4(screen.x / u_viewport.x * 2.0 - 1.0, 1.0 - screen.y / u_viewport.y * 2.0,
                     0.0, 1.0);
  v_tex = mix(u_texRect.xy, u_texRect.zw, a_corner);
}`;

const FRAGMENT_SHADER = `#version 300 es
precision highp float;
in vec2 v_tex;
uniform sampler2D u_tile;
uniform vec4 u_tint;  // rgb, weight (0 without the level overlay)
out vec4 outColor;
void main() {
  vec4 texel = texture(u_tile, v_tex);
  outColor = vec4(mix(texel.rgb, u_tint.rgb, u_tint.a), texel.a);
}`;

// Border 0: the quad is drawn by the first vertex shader; the fragment computes its own
// texel coordinate from its pixel centre, exactly as the reference does (a coordinate
// interpolated across the quad would move with the rasterizer's vertex snapping, which shows
// at sharp edges), and filters by hand over the 3 x 3 tiles around the quad's (units 0..8,
// row-major, the quad's own tile in unit 4).
const FRAGMENT_SHADER_NEIGHBOURS = `#version 300 es
precision highp float;
precision highp int;
uniform sampler2D u_tiles[9];
uniform vec2 u_viewport;
uniform float u_tpp;
uniform vec2 u_rotation;    // cos, sin
uniform float u_scale;      // 2^level
uniform vec2 u_centre;      // the view centre in texels of the quad's level, from the tile's origin
uniform int u_present;      // bit i: unit i holds a resident tile
uniform ivec2 u_origin;     // the tile's first texel, in level texels
uniform int u_tileSize;
uniform ivec2 u_levelSize;  // the level's texels across and down
uniform vec4 u_tint;
out vec4 outColor;

// A 1x1 texture is a uniform tile: every texel is its one texel.
vec4 texelOf(sampler2D tile, ivec2 p) {
  return textureSize(tile, 0).x == 1 ? texelFetch(tile, ivec2(0), 0) : texelFetch(tile, p, 0);
}

vec4 texelInUnit(int unit, ivec2 p) {
  if (unit == 0) return texelOf(u_tiles[0], p);
  if (unit == 1) return texelOf(u_tiles[1], p);
  if (unit == 2) return texelOf(u_tiles[2], p);
  if (unit == 3) return texelOf(u_tiles[3], p);
  if (unit == 5) return texelOf(u_tiles[5], p);
  if (unit == 6) return texelOf(u_tiles[6], p);
  if (unit == 7) return texelOf(u_tiles[7], p);
  if (unit == 8) return texelOf(u_tiles[8], p);
  return texelOf(u_tiles[4], p);
}

// Texel rel (from the tile's origin) of the level, clamped to the level's image (whose edge
// texels replicate), from the tile that holds it, or from the nearest texel of the quad's own
// tile when that one is absent.
vec4 levelTexel(ivec2 rel) {
  rel = clamp(rel + u_origin, ivec2(0), u_levelSize - 1) - u_origin;
  ivec2 side = ivec2(rel.x < 0 ? -1 : (rel.x >= u_tileSize ? 1 : 0),
                     rel.y < 0 ? -1 : (rel.y >= u_tileSize ? 1 : 0));
  int unit = (side.y + 1) * 3 + side.x + 1;
  if (((u_present >> unit) & 1) == 0) return texelInUnit(4, clamp(rel, ivec2(0), ivec2(u_tileSize - 1)));
  return texelInUnit(unit, rel - side * u_tileSize);
}

void main() {
  // Screen offset from the view centre, y down; then u = cx + tpp (c dx - s dy),
  // v = cy + tpp (s dx + c dy) (docs/rendering.md), in this level's texels.
  vec2 d = vec2(gl_FragCoord.x, u_viewport.y - gl_FragCoord.y) - 0.5 * u_viewport;
  vec2 rel = vec2(u_rotation.x * d.x - u_rotation.y * d.y, u_rotation.y * d.x + u_rotation.x * d.y);
  vec2 q = u_centre + rel * (u_tpp / u_scale) - 0.5;
  vec2 base = floor(q);
  vec2 f = q - base;
  ivec2 i = ivec2(base);
  vec4 top = mix(levelTexel(i), levelTexel(i + ivec2(1, 0)), f.x);
  vec4 bottom = mix(levelTexel(i + ivec2(0, 1)), levelTexel(i + ivec2(1, 1)), f.x);
  vec4 texel = mix(top, bottom, f.y);
  outColor = vec4(mix(texel.rgb, u_tint.rgb, u_tint.a), texel.a);
}`;

/** Overlay colours by level, finest first (Backes et al., Fig. 1 tints levels the same way). */
export const LEVEL_COLOURS = [
  [0.95, 0.2, 0.2],
  [0.95, 0.6, 0.1],
  [0.9, 0.9, 0.1],
  [0.3, 0.85, 0.2],
  [0.1, 0.8, 0.8],
  [0.2, 0.4, 0.95],
  [0.6, 0.3, 0.9],
  [0.9, 0.3, 0.7],
];

function compile(gl, type, source) {
  const shader = gl.createShader(type);
  gl.shaderSource(shader, source);
  gl.compileShader(shader);
  if (!gl.getShaderParameter(shader, gl.COMPILE_STATUS))
    throw new Error(`shader: ${gl.getShaderInfoLog(shader)}`);
  return shader;
}

/** Links a program with a_corner at attribute 0; returns {program, loc: {uniform: location}}. */
function link(gl, vertex, fragment, uniforms) {
  const program = gl.createProgram();
  gl.attachShader(program, compile(gl, gl.VERTEX_SHADER, vertex));
  gl.attachShader(program, compile(gl, gl.FRAGMENT_SHADER, fragment));
  gl.bindAttribLocation(program, 0, 'a_corner');
  gl.linkProgram(program);
  if (!gl.getProgramParameter(program, gl.LINK_STATUS))
    throw new Error(`program: ${gl.getProgramInfoLog(program)}`);
  const loc = {};
  for (const name of uniforms) loc[name] = gl.getUniformLocation(program, name);
  return { program, loc };
}

export class TileRenderer {
  /** Throws when the canvas cannot give a WebGL2 context. */
  constructor(canvas) {
    // Straight alpha, as stored and as the reference filters it; the page composites it.
    const gl = canvas.getContext('webgl2', {
      alpha: true,
      premultipliedAlpha: false,
      antialias: false,
      preserveDrawingBuffer: true,
    });
    if (!gl) throw new Error('this browser gives no WebGL2 context');
    this.gl = gl;
    this.bordered = link(gl, VERTEX_SHADER, FRAGMENT_SHADER, [
      'u_rect', 'u_texRect', 'u_viewport', 'u_tpp', 'u_rotation', 'u_tile', 'u_tint',
    ]);
    this.unbordered = link(gl, VERTEX_SHADER, FRAGMENT_SHADER_NEIGHBOURS, [
      'u_rect', 'u_viewport', 'u_tpp', 'u_rotation', 'u_tiles', 'u_present', 'u_scale',
      'u_centre', 'u_origin', 'u_tileSize', 'u_levelSize', 'u_tint',
    ]);
    this.vao = gl.createVertexArray();
    gl.bindVertexArray(this.vao);
    const buffer = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, buffer);
    gl.bufferData(gl.ARRAY_BUFFER, new Float32Array([0, 0, 1, 0, 0, 1, 1, 1]), gl.STATIC_DRAW);
    // Both programs bind a_corner to location 0 (link() below).
    gl.enableVertexAttribArray(0);
    gl.vertexAttribPointer(0, 2, gl.FLOAT, false, 0, 0);
    gl.bindVertexArray(null);
    this.maxTextureSize = gl.getParameter(gl.MAX_TEXTURE_SIZE);
    // Block codecs the context samples as stored, by codec name: their tiles skip the decode
    // and take an eighth (bc1) or a quarter (bc7) of the texture memory. RGBA DXT1, as the CPU
    // decoder reads bc1: a three-colour block's index 3 is transparent black.
    this.blockFormats = new Map();
    const s3tc = gl.getExtension('WEBGL_compressed_texture_s3tc');
    if (s3tc) this.blockFormats.set('bc1', s3tc.COMPRESSED_RGBA_S3TC_DXT1_EXT);
    const bptc = gl.getExtension('EXT_texture_compression_bptc');
    if (bptc) this.blockFormats.set('bc7', bptc.COMPRESSED_RGBA_BPTC_UNORM_EXT);
  }

  /** A texture of a decoded stored tile (ImageBitmap or ImageData), exactly as decoded. */
  upload(source) {
    const gl = this.gl;
    const texture = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, texture);
    gl.pixelStorei(gl.UNPACK_PREMULTIPLY_ALPHA_WEBGL, false);
    gl.pixelStorei(gl.UNPACK_COLORSPACE_CONVERSION_WEBGL, gl.NONE);
    gl.pixelStorei(gl.UNPACK_FLIP_Y_WEBGL, false);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA8, gl.RGBA, gl.UNSIGNED_BYTE, source);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.LINEAR);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.LINEAR);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
    return { texture, width: source.width, height: source.height, bytes: source.width * source.height * 4 };
  }

  /**
   * A texture of a stored bc1 or bc7 tile (a Uint8Array of 4x4 blocks, row-major) covering
   * `side` x `side` texels, padding included (`payload_side`; a multiple of 4). The padding
   * lies past the stored tile's last column and row; `paddedSide` lets the quads skip it.
   */
  uploadBlocks(codec, blocks, side) {
    const gl = this.gl;
    const texture = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, texture);
    gl.compressedTexImage2D(gl.TEXTURE_2D, 0, this.blockFormats.get(codec), side, side, 0, blocks);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.LINEAR);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.LINEAR);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
    return { texture, width: side, height: side, paddedSide: side, bytes: blocks.byteLength };
  }

  /** A texture of RGBA8 pixels (a uniform tile: 1x1, stretched over the tile's quad). */
  uploadPixels(rgba, width, height) {
    const gl = this.gl;
    const texture = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, texture);
    gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA8, width, height, 0, gl.RGBA, gl.UNSIGNED_BYTE, rgba);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
    return { texture, width, height, bytes: width * height * 4 };
  }

  release(entry) {
    this.gl.deleteTexture(entry.texture);
  }

  /**
   * Draws a frame. `layers` lists, coarsest level first, {level, tiles: [{x, y, entry,
   * neighbours}], alpha}: alpha 1 draws over what is below, alpha < 1 blends (the trilinear
   * step). `neighbours` (archives without a border) holds the 3 x 3 resident entries around the
   * tile, row-major, null where a tile is not resident.
   */
  draw(view, image, layers, overlay) {
    const gl = this.gl;
    gl.viewport(0, 0, view.width, view.height);
    gl.clearColor(0, 0, 0, 0);
    gl.clear(gl.COLOR_BUFFER_BIT);
    const { program, loc } = image.border > 0 ? this.bordered : this.unbordered;
    gl.useProgram(program);
    gl.bindVertexArray(this.vao);
    gl.uniform2f(loc.u_viewport, view.width, view.height);
    gl.uniform1f(loc.u_tpp, view.tpp);
    gl.uniform2f(loc.u_rotation, Math.cos(view.rotation || 0), Math.sin(view.rotation || 0));
    if (image.border > 0) gl.uniform1i(loc.u_tile, 0);
    else gl.uniform1iv(loc.u_tiles, [0, 1, 2, 3, 4, 5, 6, 7, 8]);
    let quads = 0;
    for (const layer of layers) {
      if (layer.alpha < 1) {
        gl.enable(gl.BLEND);
        gl.blendColor(0, 0, 0, layer.alpha);
        gl.blendFunc(gl.CONSTANT_ALPHA, gl.ONE_MINUS_CONSTANT_ALPHA);
      } else {
        gl.disable(gl.BLEND);
      }
      const colour = LEVEL_COLOURS[layer.level % LEVEL_COLOURS.length];
      gl.uniform4f(loc.u_tint, colour[0], colour[1], colour[2], overlay ? 0.45 : 0);
      if (image.border === 0) {
        const level = image.levels[layer.level];
        gl.uniform1i(loc.u_tileSize, image.tile_size);
        gl.uniform2i(loc.u_levelSize, level.width, level.height);
      }
      for (const tile of layer.tiles) {
        if (image.border > 0) this.bindBordered(view, image, layer.level, tile, loc);
        else this.bindUnbordered(view, image, layer.level, tile, loc);
        gl.drawArrays(gl.TRIANGLE_STRIP, 0, 4);
        quads += 1;
      }
    }
    gl.disable(gl.BLEND);
    gl.activeTexture(gl.TEXTURE0);
    return quads;
  }

  /** The quad of a tile with borders: its rectangle and the stored tile's coordinates. */
  bindBordered(view, image, level, { x, y, entry }, loc) {
    const gl = this.gl;
    const border = image.border;
    const side = image.tile_size + 2 * border;
    // Texture coordinates are fractions of the texture, whose padding (block tiles) follows the
    // stored tile.
    const texSide = entry.paddedSide || side;
    const scale = 2 ** level;
    const [u0, v0, u1, v1] = tileRect(image, level, x, y);
    // The rectangle in this tile's level texels, offset by the border into the stored tile.
    const ox = x * image.tile_size - border;
    const oy = y * image.tile_size - border;
    gl.uniform4f(loc.u_rect, u0 - view.cx, v0 - view.cy, u1 - view.cx, v1 - view.cy);
    gl.uniform4f(
      loc.u_texRect,
      (u0 / scale - ox) / texSide,
      (v0 / scale - oy) / texSide,
      (u1 / scale - ox) / texSide,
      (v1 / scale - oy) / texSide,
    );
    gl.activeTexture(gl.TEXTURE0);
    gl.bindTexture(gl.TEXTURE_2D, entry.texture);
  }

  /** The quad of a tile without borders: its rectangle, its level texels and its neighbours. */
  bindUnbordered(view, image, level, { x, y, entry, neighbours }, loc) {
    const gl = this.gl;
    const scale = 2 ** level;
    const [u0, v0, u1, v1] = tileRect(image, level, x, y);
    gl.uniform4f(loc.u_rect, u0 - view.cx, v0 - view.cy, u1 - view.cx, v1 - view.cy);
    gl.uniform1f(loc.u_scale, scale);
    // In double here, so the fragment works with small numbers whatever the image's size.
    gl.uniform2f(loc.u_centre, view.cx / scale - x * image.tile_size, view.cy / scale - y * image.tile_size);
    gl.uniform2i(loc.u_origin, x * image.tile_size, y * image.tile_size);
    let present = 0;
    for (let unit = 0; unit < 9; unit += 1) {
      const neighbour = unit === 4 ? entry : neighbours ? neighbours[unit] : null;
      if (neighbour) present |= 1 << unit;
      gl.activeTexture(gl.TEXTURE0 + unit);
      gl.bindTexture(gl.TEXTURE_2D, (neighbour || entry).texture);
    }
    gl.uniform1i(loc.u_present, present);
  }
}
