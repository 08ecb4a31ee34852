// View geometry of the web viewer: the orthographic camera of docs/rendering.md ("Screen and
// texture coordinates"), the level rule of the native runtime and the tiles a view needs.
// Pure functions without DOM or WebGL, so node's test runner checks them (tests/web/unit).
//
// A view is {cx, cy, tpp, rotation, width, height}: the level-0 texel at the screen centre,
// level-0 texels per device pixel, the screen rotation in radians (positive turns screen x
// towards image y) and the viewport in device pixels. Level 0 is the finest level.

/** Texels per pixel at or below 0 (or not a number) reads as 1, as in the runtime. */
export function effectiveTpp(tpp) {
  return Number.isFinite(tpp) && tpp > 0 ? tpp : 1;
}

/**
 * The level whose texels are at least as dense as the screen's pixels: the largest L with
 * 2^L <= tpp, clamped to [0, levelCount - 1]. The same rule as desiredLevelFor in
 * include/tessera/stream.h (Backes et al., eq. 5, in its texel-to-pixel form), so the browser
 * asks for the level the native runtime would.
 */
export function desiredLevel(tpp, levelCount) {
  const t = effectiveTpp(tpp);
  let level = 0;
  // Doubling avoids log2's rounding at exact powers of two (2^L <= tpp must hold exactly).
  while (level + 1 < levelCount && 2 ** (level + 1) <= t) level += 1;
  return level;
}

/**
 * How a view draws, by the sampling rules of docs/rendering.md: level L = the desired level,
 * and the weight f of level L + 1 in the trilinear blend, f = log2(tpp) - L clamped to [0, 1]
 * (0 when L is the coarsest level or the view magnifies level 0).
 */
export function levelBlend(tpp, levelCount) {
  const t = effectiveTpp(tpp);
  const level = desiredLevel(t, levelCount);
  if (level >= levelCount - 1) return { level, blend: 0 };
  const f = Math.log2(t) - level;
  return { level, blend: Math.min(1, Math.max(0, f)) };
}

/** The level-0 texel (u, v) that screen point (sx, sy) sees (pixel units, top-left origin). */
export function screenToTexture(view, sx, sy) {
  const t = effectiveTpp(view.tpp);
  const dx = sx - view.width / 2;
  const dy = sy - view.height / 2;
  const c = Math.cos(view.rotation || 0);
  const s = Math.sin(view.rotation || 0);
  return [view.cx + t * (c * dx - s * dy), view.cy + t * (s * dx + c * dy)];
}

/** The screen point that sees level-0 texel (u, v): the inverse of screenToTexture. */
export function textureToScreen(view, u, v) {
  const t = effectiveTpp(view.tpp);
  const du = (u - view.cx) / t;
  const dv = (v - view.cy) / t;
  const c = Math.cos(view.rotation || 0);
  const s = Math.sin(view.rotation || 0);
  return [view.width / 2 + c * du + s * dv, view.height / 2 - s * du + c * dv];
}

/** Bounding box [u0, v0, u1, v1] of what the screen sees, in level-0 texels. */
export function footprint(view) {
  const corners = [
    screenToTexture(view, 0, 0),
    screenToTexture(view, view.width, 0),
    screenToTexture(view, 0, view.height),
    screenToTexture(view, view.width, view.height),
  ];
  const us = corners.map((p) => p[0]);
  const vs = corners.map((p) => p[1]);
  return [Math.min(...us), Math.min(...vs), Math.max(...us), Math.max(...vs)];
}

/** Geometry of one level of an image description from info.json (`levels[level]`). */
export function levelInfo(image, level) {
  const entry = image.levels[level];
  return { width: entry.width, height: entry.height, tilesX: entry.tiles_x, tilesY: entry.tiles_y };
}

/**
 * The tile range [x0, y0, x1, y1) (exclusive ends) of `level` that the view's footprint
 * meets, clipped to the image: tile (x, y) of level L covers level-0 texels
 * [x t 2^L, (x + 1) t 2^L) x [y t 2^L, (y + 1) t 2^L), cut at the image's W x H. Null when the
 * view sees none of the image.
 */
export function visibleTileRange(view, image, level) {
  const [u0, v0, u1, v1] = footprint(view);
  const span = image.tile_size * 2 ** level;
  const info = levelInfo(image, level);
  const cu0 = Math.max(0, u0);
  const cv0 = Math.max(0, v0);
  const cu1 = Math.min(image.width, u1);
  const cv1 = Math.min(image.height, v1);
  if (cu0 >= cu1 || cv0 >= cv1) return null;
  const x0 = Math.max(0, Math.floor(cu0 / span));
  const y0 = Math.max(0, Math.floor(cv0 / span));
  const x1 = Math.min(info.tilesX, Math.floor((cu1 - 1e-9) / span) + 1);
  const y1 = Math.min(info.tilesY, Math.floor((cv1 - 1e-9) / span) + 1);
  if (x0 >= x1 || y0 >= y1) return null;
  return [x0, y0, x1, y1];
}

/** The level-0 rectangle [u0, v0, u1, v1] a tile covers, cut at the image's edges. */
export function tileRect(image, level, x, y) {
  const span = image.tile_size * 2 ** level;
  return [
    x * span,
    y * span,
    Math.min(image.width, (x + 1) * span),
    Math.min(image.height, (y + 1) * span),
  ];
}

/** Key of a tile in maps and sets. */
export function tileKey(level, x, y) {
  return `${level}/${x}/${y}`;
}

/**
 * Every tile the view needs, in the order to fetch them: the coarsest level first, then each
 * finer level down to the desired one (parents before children, as the native streamer keeps
 * them, Backes et al., section 6), and within a level centre-out (distance from the tile's
 * centre to the view's centre). Each entry is {level, x, y, key, distance}. Levels finer than
 * the desired one are never asked for.
 */
export function neededTiles(view, image) {
  const coarsest = image.level_count - 1;
  const { level: desired } = levelBlend(view.tpp, image.level_count);
  const out = [];
  for (let level = coarsest; level >= desired; level -= 1) {
    const range = visibleTileRange(view, image, level);
    if (!range) continue;
    const [x0, y0, x1, y1] = range;
    const span = image.tile_size * 2 ** level;
    const tiles = [];
    for (let y = y0; y < y1; y += 1) {
      for (let x = x0; x < x1; x += 1) {
        const du = (x + 0.5) * span - view.cx;
        const dv = (y + 0.5) * span - view.cy;
        tiles.push({ level, x, y, key: tileKey(level, x, y), distance: Math.hypot(du, dv) });
      }
    }
    tiles.sort((a, b) => a.distance - b.distance || a.y - b.y || a.x - b.x);
    out.push(...tiles);
  }
  return out;
}

/** Zooms by `factor` (> 1 zooms in) about screen point (sx, sy), which keeps its texel. */
export function zoomAbout(view, factor, sx, sy, minTpp, maxTpp) {
  const [u, v] = screenToTexture(view, sx, sy);
  const tpp = Math.min(maxTpp, Math.max(minTpp, effectiveTpp(view.tpp) / factor));
  const next = { ...view, tpp };
  const [u2, v2] = screenToTexture(next, sx, sy);
  next.cx += u - u2;
  next.cy += v - v2;
  return next;
}

/** Pans so that the texel under the screen moves by (dx, dy) pixels with the pointer. */
export function panBy(view, dx, dy) {
  const [u0, v0] = screenToTexture(view, 0, 0);
  const [u1, v1] = screenToTexture(view, dx, dy);
  return { ...view, cx: view.cx - (u1 - u0), cy: view.cy - (v1 - v0) };
}

/** The view that shows the whole image, centred, in a width x height viewport. */
export function fitView(image, width, height) {
  const tpp = Math.max(image.width / Math.max(1, width), image.height / Math.max(1, height));
  return { cx: image.width / 2, cy: image.height / 2, tpp, rotation: 0, width, height };
}
