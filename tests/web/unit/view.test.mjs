// The web viewer's geometry (web/viewer/view.js): level rule, screen mapping, visible tiles and
// their priority order, pan and zoom. Run by ctest as `node --test` (label web).
import assert from 'node:assert/strict';
import { execFileSync } from 'node:child_process';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { test } from 'node:test';

import {
  desiredLevel,
  fitView,
  footprint,
  levelBlend,
  neededTiles,
  panBy,
  screenToTexture,
  textureToScreen,
  tileRect,
  visibleTileRange,
  zoomAbout,
} from '../../../web/viewer/view.js';

// A 3000x2000 image in 256 px tiles: levels 3000x2000 (12x8), 1500x1000 (6x4), 750x500 (3x2),
// 375x250 (2x1), 188x125 (1x1), as `tessera info` lists them.
const image = {
  index: 0,
  width: 3000,
  height: 2000,
  tile_size: 256,
  border: 1,
  level_count: 5,
  tile_content_type: 'image/png',
  levels: [
    { level: 0, width: 3000, height: 2000, tiles_x: 12, tiles_y: 8 },
    { level: 1, width: 1500, height: 1000, tiles_x: 6, tiles_y: 4 },
    { level: 2, width: 750, height: 500, tiles_x: 3, tiles_y: 2 },
    { level: 3, width: 375, height: 250, tiles_x: 2, tiles_y: 1 },
    { level: 4, width: 188, height: 125, tiles_x: 1, tiles_y: 1 },
  ],
};

const close = (a, b, eps = 1e-9) => assert.ok(Math.abs(a - b) <= eps, `${a} != ${b}`);

test('the desired level is the largest L with 2^L <= texels per pixel, clamped', () => {
  const cases = [
    [0.25, 0], [1, 0], [1.999, 0], [2, 1], [3.99, 1], [4, 2], [7.5, 2], [8, 3], [16, 4],
    [1e6, 4], [0, 0], [-3, 0], [Number.NaN, 0],
  ];
  for (const [tpp, level] of cases) assert.equal(desiredLevel(tpp, 5), level, `tpp ${tpp}`);
  assert.equal(desiredLevel(1e6, 1), 0);
});

test('the desired level agrees with the native desiredLevelFor (tessera render prints it)', (t) => {
  const cli = process.env.TESSERA_CLI;
  if (!cli) {
    t.skip('TESSERA_CLI not set (ctest sets it)');
    return;
  }
  const dir = fs.mkdtempSync(path.join(os.tmpdir(), 'tessera-web-unit-'));
  try {
    const archive = path.join(dir, 'a.tess');
    execFileSync(cli, ['build', 'synthetic:3000x2000:1:3', '-o', archive, '--codec', 'png', '--quiet']);
    for (const tpp of [0.5, 1, 1.5, 2, 2.0000001, 3.999, 4, 6, 8, 15.9, 16, 40]) {
      const out = execFileSync(cli, [
        'render', archive, '--centre', '1500,1000', '--texels-per-pixel', String(tpp),
        '--viewport', '4x4', '-o', path.join(dir, 'r.png'),
      ]).toString();
      const match = /level (\d+) of (\d+)/.exec(out);
      assert.ok(match, out);
      assert.equal(desiredLevel(tpp, Number(match[2])), Number(match[1]), `tpp ${tpp}`);
    }
  } finally {
    fs.rmSync(dir, { recursive: true, force: true });
  }
});

test('the trilinear weight of level L + 1 is log2(tpp) - L, 0 at the coarsest level', () => {
  assert.deepEqual(levelBlend(1, 5), { level: 0, blend: 0 });
  assert.deepEqual(levelBlend(0.5, 5), { level: 0, blend: 0 });
  const b = levelBlend(3, 5);
  assert.equal(b.level, 1);
  close(b.blend, Math.log2(3) - 1);
  assert.deepEqual(levelBlend(40, 5), { level: 4, blend: 0 });
});

test('screen and texture coordinates follow docs/rendering.md and invert each other', () => {
  const view = { cx: 150, cy: 100, tpp: 1, rotation: 0, width: 80, height: 60 };
  // Pixel centres on texel centres: pixel (px, py) sees texel (110 + px, 70 + py)'s centre.
  const [u, v] = screenToTexture(view, 3.5, 7.5);
  close(u, 113.5);
  close(v, 77.5);
  // 90 degrees: as the CLI test of `tessera render`, pixel (px, py) of a 20x20 view on
  // (150, 100) shows texel (159 - py, 90 + px).
  const rotated = { cx: 150, cy: 100, tpp: 1, rotation: Math.PI / 2, width: 20, height: 20 };
  const [ru, rv] = screenToTexture(rotated, 4.5, 2.5);
  close(ru, 159 - 2 + 0.5);
  close(rv, 90 + 4 + 0.5);
  for (const probe of [view, rotated, { ...rotated, tpp: 3.7, rotation: 0.4 }]) {
    const [a, b] = screenToTexture(probe, 12.25, 5.5);
    const [sx, sy] = textureToScreen(probe, a, b);
    close(sx, 12.25, 1e-9);
    close(sy, 5.5, 1e-9);
  }
});

test('visible tiles: the footprint cut at the image, per level', () => {
  const view = { cx: 1500, cy: 1000, tpp: 1, rotation: 0, width: 800, height: 600 };
  assert.deepEqual(footprint(view), [1100, 700, 1900, 1300]);
  // Level 0: u 1100..1900 -> tiles 4..7, v 700..1300 -> tiles 2..5.
  assert.deepEqual(visibleTileRange(view, image, 0), [4, 2, 8, 6]);
  assert.deepEqual(visibleTileRange(view, image, 1), [2, 1, 4, 3]);
  assert.deepEqual(visibleTileRange(view, image, 4), [0, 0, 1, 1]);
  // A view over the top-left corner sees tile (0, 0) only; one beside the image sees nothing.
  const corner = { ...view, cx: 0, cy: 0, width: 100, height: 100 };
  assert.deepEqual(visibleTileRange(corner, image, 0), [0, 0, 1, 1]);
  assert.equal(visibleTileRange({ ...view, cx: -1000 }, image, 0), null);
  // A tile edge exactly at the footprint's end does not pull in the next tile.
  const edge = { cx: 128, cy: 128, tpp: 1, rotation: 0, width: 256, height: 256 };
  assert.deepEqual(visibleTileRange(edge, image, 0), [0, 0, 1, 1]);
  // Rotation widens the footprint to the rotated screen's bounding box.
  const turned = { ...edge, rotation: Math.PI / 4 };
  assert.deepEqual(visibleTileRange(turned, image, 0), [0, 0, 2, 2]);
  // Edge tiles are cut at the image: the last column of level 0 ends at 3000, not 3072.
  assert.deepEqual(tileRect(image, 0, 11, 7), [2816, 1792, 3000, 2000]);
  assert.deepEqual(tileRect(image, 4, 0, 0), [0, 0, 3000, 2000]);
});

test('needed tiles come coarsest level first, then centre-out within each level', () => {
  const view = { cx: 1400, cy: 900, tpp: 2.5, rotation: 0, width: 800, height: 600 };
  const needed = neededTiles(view, image);
  const levels = needed.map((t) => t.level);
  // Levels 4, 3, 2, 1 (the desired level, tpp 2.5): never level 0.
  assert.deepEqual([...new Set(levels)], [4, 3, 2, 1]);
  for (let i = 1; i < levels.length; i += 1) assert.ok(levels[i] <= levels[i - 1]);
  for (const level of [4, 3, 2, 1]) {
    const ofLevel = needed.filter((t) => t.level === level);
    const range = visibleTileRange(view, image, level);
    assert.equal(ofLevel.length, (range[2] - range[0]) * (range[3] - range[1]));
    for (let i = 1; i < ofLevel.length; i += 1)
      assert.ok(ofLevel[i].distance >= ofLevel[i - 1].distance);
  }
  // The first tile of the desired level holds the view's centre: (1400, 900) / 512 -> (2, 1).
  const first = needed.find((t) => t.level === 1);
  assert.deepEqual([first.x, first.y], [2, 1]);
  assert.equal(new Set(needed.map((t) => t.key)).size, needed.length);
});

test('zooming keeps the texel under the pointer; panning moves it with the pointer', () => {
  const view = { cx: 1500, cy: 1000, tpp: 2, rotation: 0.3, width: 800, height: 600 };
  const before = screenToTexture(view, 100, 50);
  const zoomed = zoomAbout(view, 2, 100, 50, 1 / 64, 100);
  close(zoomed.tpp, 1);
  const after = screenToTexture(zoomed, 100, 50);
  close(after[0], before[0], 1e-9);
  close(after[1], before[1], 1e-9);
  assert.equal(zoomAbout(view, 1000, 0, 0, 0.5, 100).tpp, 0.5);
  assert.equal(zoomAbout(view, 1e-6, 0, 0, 0.5, 100).tpp, 100);
  const grabbed = screenToTexture(view, 300, 200);
  const panned = panBy(view, 40, -25);
  const moved = screenToTexture(panned, 340, 175);
  close(moved[0], grabbed[0], 1e-9);
  close(moved[1], grabbed[1], 1e-9);
});

test('fit shows the whole image centred', () => {
  const view = fitView(image, 600, 600);
  assert.equal(view.tpp, 5);
  const [u0, v0, u1, v1] = footprint(view);
  assert.ok(u0 <= 0 && v0 <= 0 && u1 >= 3000 && v1 >= 2000);
  close(u1 - u0, 3000);
});
