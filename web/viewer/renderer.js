// WebGL2 drawing of the web viewer: one texture per resident tile (borders included), each
// drawn as a quad over the level-0 rectangle it covers, with texture coordinates that skip its
// stored border. Levels are drawn coarsest first, each over the last, so a coarser tile shows
// wherever a finer one is missing (nothing is blank once the coarsest level is in); the
// desired level L is blended over level L + 1 with weight 1 - f (constant blend alpha), which
// is the trilinear filter of docs/rendering.md for an orthographic view (lambda is the same at
// every pixel). Bilinear sampling of a tile with border >= 1 reads its neighbours' texels from
// the border, as the reference does; quads are cut at the image's edges, where the stored
// padding replicates the edge texels as the reference's clamping does.

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
    const program = gl.createProgram();
    gl.attachShader(program, compile(gl, gl.VERTEX_SHADER, VERTEX_SHADER));
    gl.attachShader(program, compile(gl, gl.FRAGMENT_SHADER, FRAGMENT_SHADER));
    gl.linkProgram(program);
    if (!gl.getProgramParameter(program, gl.LINK_STATUS))
      throw new Error(`program: ${gl.getProgramInfoLog(program)}`);
    this.program = program;
    this.loc = {};
    for (const name of ['u_rect', 'u_texRect', 'u_viewport', 'u_tpp', 'u_rotation', 'u_tile', 'u_tint'])
      this.loc[name] = gl.getUniformLocation(program, name);
    this.vao = gl.createVertexArray();
    gl.bindVertexArray(this.vao);
    const buffer = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, buffer);
    gl.bufferData(gl.ARRAY_BUFFER, new Float32Array([0, 0, 1, 0, 0, 1, 1, 1]), gl.STATIC_DRAW);
    const corner = gl.getAttribLocation(program, 'a_corner');
    gl.enableVertexAttribArray(corner);
    gl.vertexAttribPointer(corner, 2, gl.FLOAT, false, 0, 0);
    gl.bindVertexArray(null);
    this.maxTextureSize = gl.getParameter(gl.MAX_TEXTURE_SIZE);
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
   * Draws a frame. `layers` lists, coarsest level first, {level, tiles: [{x, y, entry}],
   * alpha}: alpha 1 draws over what is below, alpha < 1 blends (the trilinear step).
   */
  draw(view, image, layers, overlay) {
    const gl = this.gl;
    gl.viewport(0, 0, view.width, view.height);
    gl.clearColor(0, 0, 0, 0);
    gl.clear(gl.COLOR_BUFFER_BIT);
    gl.useProgram(this.program);
    gl.bindVertexArray(this.vao);
    gl.uniform2f(this.loc.u_viewport, view.width, view.height);
    gl.uniform1f(this.loc.u_tpp, view.tpp);
    gl.uniform2f(this.loc.u_rotation, Math.cos(view.rotation || 0), Math.sin(view.rotation || 0));
    gl.uniform1i(this.loc.u_tile, 0);
    gl.activeTexture(gl.TEXTURE0);
    const border = image.border;
    const side = image.tile_size + 2 * border;
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
      gl.uniform4f(this.loc.u_tint, colour[0], colour[1], colour[2], overlay ? 0.45 : 0);
      const scale = 2 ** layer.level;
      for (const { x, y, entry } of layer.tiles) {
        const [u0, v0, u1, v1] = tileRect(image, layer.level, x, y);
        // The rectangle in this tile's level texels, offset by the border into the stored tile.
        const ox = x * image.tile_size - border;
        const oy = y * image.tile_size - border;
        gl.uniform4f(this.loc.u_rect, u0 - view.cx, v0 - view.cy, u1 - view.cx, v1 - view.cy);
        gl.uniform4f(
          this.loc.u_texRect,
          (u0 / scale - ox) / side,
          (v0 / scale - oy) / side,
          (u1 / scale - ox) / side,
          (v1 / scale - oy) / side,
        );
        gl.bindTexture(gl.TEXTURE_2D, entry.texture);
        gl.drawArrays(gl.TRIANGLE_STRIP, 0, 4);
        quads += 1;
      }
    }
    gl.disable(gl.BLEND);
    return quads;
  }
}
