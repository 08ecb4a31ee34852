// The web viewer in headless Chromium against `tessera serve`: the picture at rest against the
// CPU reference (`tessera render`) of the same view, wheel zoom and drag pan, a touch pinch,
// cancellation of requests that left the view, the level overlay, and bc1/bc7 tiles uploaded
// as stored blocks against the PNG path. Run by ctest (label web) with TESSERA_CLI set; tiles
// come from small archives built in a temp dir.
import assert from 'node:assert/strict';
import fs from 'node:fs';
import path from 'node:path';
import { after, before, test } from 'node:test';

import {
  buildArchive,
  compare,
  launchChromium,
  referencePicture,
  screenshotPicture,
  startServe,
  tempDir,
} from './lib/harness.mjs';
import { writePngRgb } from './lib/png.mjs';

// The page background (web/viewer/viewer.css) shows where the canvas is transparent.
const BACKGROUND = [0x20, 0x20, 0x20];
// The reference is what a GPU renderer must match at rest on a lossless codec (45 dB, as the
// native renderers, docs/rendering.md). What differs is the GPU's filtering precision:
// SwiftShader's bilinear and blend weights are coarser than the reference's doubles, which
// shows where neighbouring texels differ most (an RGBA image's torn edge: transparent black
// beside white). Measured: 55-62 dB; largest difference 4 of 255 on the RGB archive and 11
// on 11 pixels of 307,200 at the RGBA archive's translucent edges. So: PSNR >= 45 dB, and at
// most 0.1% of the pixels off by more than 8 (an error of a tile, a level or a half-texel
// shift moves far more pixels than that).
const MIN_PSNR_DB = 45;
const MAX_OVER_SHARE = 0.001;
const VIEWPORT = { width: 640, height: 480 };

let dir;
let archive;
let ocean;
let packed;
let patches;
let blocks1;
let blocks7;
let server;
let browser;
let page;

before(async () => {
  dir = tempDir('viewer');
  archive = await buildArchive('synthetic:3000x2000:7:3', path.join(dir, 'scene.tess'), '--codec', 'png', '--border', '1');
  // RGBA with transparent surroundings, and many uniform tiles (sea), which the server sends
  // as a colour in a header instead of a payload.
  ocean = await buildArchive('synthetic:3000x2000', path.join(dir, 'ocean.tess'), '--codec', 'png', '--border', '1');
  // A codec browsers cannot decode: tiles come as `?format=png` transcodes.
  packed = await buildArchive('synthetic:1000x700:3:3', path.join(dir, 'packed.tess'), '--codec', 'zstd', '--border', '1');
  // Tiles of sharply different colours, each also split by sharp steps through its middle, so
  // that filtering sharp features inside tiles is the yardstick for filtering them across tile
  // edges; without a border a seam shows as a larger difference there.
  const source = path.join(dir, 'patches.png');
  writePatches(source);
  patches = await buildArchive(source, path.join(dir, 'patches.tess'), '--codec', 'png', '--tile', '128');
  // GPU block codecs: bc1 with a border (stored side 130, padded to 132 by the blocks) and
  // bc7 without one (RGBA).
  blocks1 = await buildArchive('synthetic:600x400:5:3', path.join(dir, 'blocks1.tess'), '--codec', 'bc1', '--border', '1', '--tile', '128');
  blocks7 = await buildArchive('synthetic:600x400', path.join(dir, 'blocks7.tess'), '--codec', 'bc7', '--tile', '128');
  server = await startServe([archive, ocean, packed, patches, blocks1, blocks7]);
  browser = await launchChromium({ viewport: VIEWPORT, hasTouch: true });
  page = await browser.context.newPage();
  page.on('pageerror', (error) => console.error(`page error: ${error.message}`));
  await page.goto(`${server.url}/#archive=scene`);
  await page.waitForFunction(() => window.tessera && window.tessera.status().archive === 'scene');
  await page.evaluate(() => window.tessera.showPanels(false));
});

after(async () => {
  if (browser) await browser.close();
  if (server) {
    // A clean exit after SIGTERM: under the sanitizers a report would end it otherwise.
    const exit = await server.stop();
    assert.deepEqual(exit, { code: 0, signal: null }, `tessera serve: ${server.log()}`);
  }
  if (dir) fs.rmSync(dir, { recursive: true, force: true });
});

const PATCHES = { width: 1024, height: 768, tile: 128 };

function writePatches(file) {
  const { width, height, tile } = PATCHES;
  const rgb = new Uint8Array(width * height * 3);
  for (let y = 0; y < height; y += 1)
    for (let x = 0; x < width; x += 1) {
      const t = Math.floor(x / tile) * 7 + Math.floor(y / tile) * 13 + ((x % tile) * 2 >= tile ? 3 : 0) + ((y % tile) * 2 >= tile ? 5 : 0);
      const base = [(t * 53) % 200, (t * 97 + 60) % 200, (t * 31 + 120) % 200];
      for (let c = 0; c < 3; c += 1)
        rgb[(y * width + x) * 3 + c] = base[c] + Math.floor((((x % tile) + (y % tile) * (c + 1)) % tile) / 3);
    }
  writePngRgb(file, width, height, rgb);
}

/**
 * The largest channel difference between two pictures of the view `view` (no rotation), over
 * the pixels within one texel of a tile edge of `levels` and over all the others.
 */
function edgeAndInteriorDifference(a, b, view, levels) {
  let edge = 0;
  let interior = 0;
  for (let py = 0; py < view.height; py += 1)
    for (let px = 0; px < view.width; px += 1) {
      const u = view.cx + (px + 0.5 - view.width / 2) * view.tpp;
      const v = view.cy + (py + 0.5 - view.height / 2) * view.tpp;
      if (u < 0 || v < 0 || u >= PATCHES.width || v >= PATCHES.height) continue;
      const nearEdge = levels.some((level) => {
        const span = PATCHES.tile * 2 ** level;
        const du = Math.abs(u - Math.round(u / span) * span);
        const dv = Math.abs(v - Math.round(v / span) * span);
        return Math.min(du, dv) <= 2 ** level + view.tpp;
      });
      const i = (py * view.width + px) * 4;
      let d = 0;
      for (let c = 0; c < 3; c += 1) d = Math.max(d, Math.abs(a.rgba[i + c] - b.rgba[i + c]));
      if (nearEdge) edge = Math.max(edge, d);
      else interior = Math.max(interior, d);
    }
  return { edge, interior };
}

const status = () => page.evaluate(() => window.tessera.status());
const settle = () => page.waitForFunction(() => window.tessera.status().settled, null, { timeout: 60000 });

async function setView(view) {
  await page.evaluate((v) => window.tessera.setView({ rotation: 0, ...v }), view);
  await settle();
}

/** The canvas as the page shows it, against the reference of the viewer's own view. */
async function compareWithReference() {
  const { view, archive: name } = await status();
  const shot = screenshotPicture(await page.locator('#view').screenshot(), dir);
  const reference = await referencePicture({ scene: archive, ocean, packed, patches, blocks1, blocks7 }[name], view, BACKGROUND, dir);
  return { view, ...compare(shot, reference) };
}

test('WebGL2 runs in headless Chromium (SwiftShader)', async () => {
  const version = await page.evaluate(() => document.createElement('canvas').getContext('webgl2').getParameter(0x1f02));
  assert.match(version, /^WebGL 2\.0/);
});

test('at rest the viewer draws the reference picture of its view', async () => {
  const views = [
    { cx: 1500, cy: 1000, tpp: 1 }, // pixel centres on texel centres, level 0 only
    { cx: 1234.5, cy: 876.25, tpp: 2.6 }, // level 1 blended with level 2 (trilinear)
    { cx: 700.3, cy: 500.7, tpp: 0.37 }, // level 0 magnified
    { cx: 1500, cy: 1000, tpp: 1.7, rotation: 0.5 }, // rotated, levels 0 and 1
    { cx: 1500, cy: 1000, tpp: 7 }, // the whole image with transparent surroundings
    { cx: 2950, cy: 1980, tpp: 1.3 }, // the image's bottom-right corner and cut edge tiles
  ];
  for (const view of views) {
    await setView(view);
    const s = await status();
    assert.equal(s.missing, 0);
    const result = await compareWithReference();
    assert.ok(
      result.psnr >= MIN_PSNR_DB && result.overShare <= MAX_OVER_SHARE,
      `view ${JSON.stringify(view)}: PSNR ${result.psnr.toFixed(1)} dB, largest difference ${result.maxAbs}, ${result.overShare * 100}% of pixels off by more than 8`,
    );
  }
  // Reopened (empty cache), the whole image at 7 texels per pixel (level 2, as the fitted
  // view it opens with) takes exactly the tiles of levels 2 to 4: 3x2 + 2x1 + 1, none finer.
  const { requested } = await status();
  await page.evaluate(() => window.tessera.open('scene', 0));
  await setView({ cx: 1500, cy: 1000, tpp: 7 });
  const coarse = await status();
  assert.equal(coarse.level, 2);
  assert.equal(coarse.requested - requested, 6 + 2 + 1);
});

test('without a border, tile edges are filtered from the neighbours: no seam, magnified or minified', async () => {
  await page.evaluate(() => window.tessera.open('patches', 0));
  const views = [
    { view: { cx: 512, cy: 384, tpp: 1 / 7.8 }, levels: [0] }, // magnified at a tile corner
    { view: { cx: 400.3, cy: 300.6, tpp: 0.61 }, levels: [0] }, // magnified, edges off centre
    { view: { cx: 512, cy: 384, tpp: 3.7 }, levels: [1, 2] }, // minified: levels 1 and 2 blend
  ];
  for (const { view: wanted, levels } of views) {
    await setView(wanted);
    const s = await status();
    assert.equal(s.missing, 0);
    const shot = screenshotPicture(await page.locator('#view').screenshot(), dir);
    const reference = await referencePicture(patches, s.view, BACKGROUND, dir);
    const { edge, interior } = edgeAndInteriorDifference(shot, reference, s.view, levels);
    const { psnr } = compare(shot, reference);
    console.log(`patches ${JSON.stringify(wanted)}: across edges ${edge}, inside ${interior}, ${psnr.toFixed(1)} dB`);
    assert.ok(psnr >= MIN_PSNR_DB, `view ${JSON.stringify(wanted)}: PSNR ${psnr.toFixed(1)} dB`);
    assert.ok(edge <= Math.max(interior, 1), `view ${JSON.stringify(wanted)}: largest difference across tile edges ${edge}, inside tiles ${interior}`);
  }
});

test('tiles are requested coarse level first, then centre-out', async () => {
  await page.evaluate(() => window.tessera.open('scene', 0));
  await settle(); // the fitted view: levels 2-4 resident
  const requested = [];
  const onRequest = (request) => {
    const match = /\/scene\/0\/(\d+)\/(\d+)\/(\d+)$/.exec(new URL(request.url()).pathname);
    if (match) requested.push(match.slice(1).map(Number));
  };
  page.on('request', onRequest);
  const view = { cx: 1400, cy: 900, tpp: 1 };
  await setView(view);
  page.off('request', onRequest);
  // Levels 1 and 0 (the blend's level 1 first), each tile once, each level centre-out.
  assert.deepEqual([...new Set(requested.map(([level]) => level))], [1, 0]);
  assert.equal(new Set(requested.map((t) => t.join('/'))).size, requested.length);
  const distance = ([level, x, y]) => {
    const span = 256 * 2 ** level;
    return Math.hypot((x + 0.5) * span - view.cx, (y + 0.5) * span - view.cy);
  };
  for (let i = 1; i < requested.length; i += 1)
    if (requested[i][0] === requested[i - 1][0])
      assert.ok(distance(requested[i]) >= distance(requested[i - 1]), `request ${i} ${requested[i]} is nearer the centre than ${requested[i - 1]}`);
  // The first level-0 request is the tile under the centre: (1400, 900) / 256 -> (5, 3).
  assert.deepEqual(requested.find(([level]) => level === 0), [0, 5, 3]);
});

test('uniform tiles and transparency: an RGBA archive at rest matches the reference', async () => {
  const uniform = [];
  const transcoded = [];
  const onResponse = (response) => {
    if (response.status() === 204 && response.headers()['x-tessera-tile-kind'] === 'uniform') uniform.push(response.url());
    if (response.url().includes('format=')) transcoded.push(response.url());
  };
  page.on('response', onResponse);
  await page.evaluate(() => window.tessera.open('ocean', 0));
  for (const view of [{ cx: 1500, cy: 1000, tpp: 4.5 }, { cx: 2100.5, cy: 900.5, tpp: 1.3 }, { cx: 150, cy: 1900, tpp: 0.8 }]) {
    await setView(view);
    const s = await status();
    assert.equal(s.failed, 0, JSON.stringify(s.errors));
    const result = await compareWithReference();
    assert.ok(
      result.psnr >= MIN_PSNR_DB && result.overShare <= MAX_OVER_SHARE,
      `ocean ${JSON.stringify(view)}: PSNR ${result.psnr.toFixed(1)} dB, largest difference ${result.maxAbs}, ${result.overShare * 100}% of pixels off by more than 8`,
    );
  }
  page.off('response', onResponse);
  // Uniform tiles came as a colour (204 and a header), none as a transcoded picture.
  assert.ok(uniform.length >= 1, 'no uniform tile was fetched');
  assert.deepEqual(transcoded, []);
  await page.evaluate(() => window.tessera.open('scene', 0));
  await settle();
});

test('tiles of a codec browsers cannot decode come as PNG transcodes and match the reference', async () => {
  const urls = [];
  const onRequest = (request) => {
    if (new URL(request.url()).pathname.startsWith('/packed/0/')) urls.push(request.url());
  };
  page.on('request', onRequest);
  await page.evaluate(() => window.tessera.open('packed', 0));
  await setView({ cx: 480.5, cy: 333.25, tpp: 1.6 });
  page.off('request', onRequest);
  assert.ok(urls.length >= 3, `only ${urls.length} tile requests`);
  for (const url of urls) assert.match(url, /\?format=png$/);
  const result = await compareWithReference();
  assert.ok(
    result.psnr >= MIN_PSNR_DB && result.overShare <= MAX_OVER_SHARE,
    `zstd archive: PSNR ${result.psnr.toFixed(1)} dB, ${result.overShare * 100}% of pixels off by more than 8`,
  );
  await page.evaluate(() => window.tessera.open('scene', 0));
  await settle();
});

test('bc1 and bc7 tiles go to the GPU as stored where the browser samples them, else as PNG', async () => {
  const cases = [
    // Magnified over a few tiles each, to keep SwiftShader's work small: bc1's padded tiles
    // with their border, then the same view through the PNG path; bc7's tile edges filtered
    // from the neighbours (border 0), against the reference only (its PNG path is bc1's code).
    { name: 'blocks1', codec: 'bc1', view: { cx: 320.5, cy: 210.25, tpp: 0.5 }, pngPath: true },
    { name: 'blocks7', codec: 'bc7', view: { cx: 256.5, cy: 192.25, tpp: 0.3 }, pngPath: false },
  ];
  for (const { name, codec, view, pngPath } of cases) {
    const urls = [];
    const onRequest = (request) => {
      if (new URL(request.url()).pathname.startsWith(`/${name}/0/`)) urls.push(request.url());
    };
    page.on('request', onRequest);
    const before = await status();
    // Block uploads back on (the last case's PNG view is at rest: nothing in flight) and the
    // view set before the first frame: the fitted view it opens with fetches nothing.
    await page.evaluate(async ([n, v]) => {
      await window.tessera.open(n, 0);
      window.tessera.setBlockUploads(true);
      window.tessera.setView({ rotation: 0, ...v });
    }, [name, view]);
    await settle();
    page.off('request', onRequest);
    const stored = await status();
    assert.equal(stored.failed, before.failed, JSON.stringify(stored.errors));
    const offered = stored.blockCodecs.includes(codec);
    const uploads = stored.blockUploads - before.blockUploads;
    const asStored = urls.filter((url) => !url.includes('format='));
    console.log(`${codec}: ${offered ? `the browser samples ${codec}; ${uploads} tiles uploaded as stored blocks` : `the browser does not sample ${codec}; PNG transcodes`} (${urls.length} requests)`);
    if (offered) {
      assert.ok(uploads >= 2, `${uploads} block uploads`);
      assert.equal(asStored.length, uploads, 'every tile fetched as stored was uploaded as blocks');
    } else {
      assert.equal(uploads, 0);
      assert.deepEqual(asStored, []);
    }
    const blockShot = screenshotPicture(await page.locator('#view').screenshot(), dir);
    const reference = await referencePicture({ blocks1, blocks7 }[name], stored.view, BACKGROUND, dir);
    const result = compare(blockShot, reference);
    console.log(`${codec}: against the reference ${result.psnr.toFixed(1)} dB (largest ${result.maxAbs})`);
    assert.ok(
      result.psnr >= MIN_PSNR_DB && result.overShare <= MAX_OVER_SHARE,
      `${codec}: against the reference: PSNR ${result.psnr.toFixed(1)} dB, largest difference ${result.maxAbs}`,
    );
    if (!pngPath) continue;
    // The same view through the PNG path: the server's CPU decode of the same blocks.
    urls.length = 0;
    page.on('request', onRequest);
    await page.evaluate(() => window.tessera.setBlockUploads(false));
    await settle();
    page.off('request', onRequest);
    const png = await status();
    assert.equal(png.blockUploads, stored.blockUploads);
    assert.ok(urls.length >= 2, `${urls.length} requests after turning block uploads off`);
    for (const url of urls) assert.match(url, /\?format=png$/);
    const pngShot = screenshotPicture(await page.locator('#view').screenshot(), dir);
    // bc1's thirds may round one level apart between decoders (docs/codecs.md); the pictures
    // are otherwise the same texels through the same filter.
    const paths = compare(blockShot, pngShot);
    console.log(`${codec}: blocks against PNG ${paths.psnr.toFixed(1)} dB (largest ${paths.maxAbs})`);
    assert.ok(
      paths.psnr >= MIN_PSNR_DB && paths.overShare <= MAX_OVER_SHARE,
      `${codec}: blocks against PNG: PSNR ${paths.psnr.toFixed(1)} dB, largest difference ${paths.maxAbs}`,
    );
  }
  await page.evaluate(() => window.tessera.open('scene', 0));
  await settle();
});

test('wheel zooms about the pointer and dragging pans with it', async () => {
  await setView({ cx: 1500, cy: 1000, tpp: 2 });
  const texelAt = (x, y) => page.evaluate(([sx, sy]) => window.tessera.textureAt(sx, sy), [x, y]);
  const under = await texelAt(200, 150);
  await page.mouse.move(200, 150);
  await page.mouse.wheel(0, -400); // 400 px of wheel: 2x closer (web/viewer/main.js)
  await page.waitForFunction(() => window.tessera.status().view.tpp < 1.5);
  let s = await status();
  assert.ok(Math.abs(s.view.tpp - 1) < 1e-9, `tpp ${s.view.tpp} after a 400 px wheel from 2`);
  const still = await texelAt(200, 150);
  assert.ok(Math.hypot(still[0] - under[0], still[1] - under[1]) < 1e-6, 'the texel under the pointer moved');

  const grabbed = await texelAt(400, 300);
  await page.mouse.move(400, 300);
  await page.mouse.down();
  await page.mouse.move(350, 260, { steps: 5 });
  await page.mouse.move(300, 250, { steps: 5 });
  await page.mouse.up();
  const dropped = await texelAt(300, 250);
  assert.ok(Math.hypot(dropped[0] - grabbed[0], dropped[1] - grabbed[1]) < 1e-6, 'the dragged texel is not under the pointer');
  await settle();
  const result = await compareWithReference();
  assert.ok(result.psnr >= MIN_PSNR_DB && result.overShare <= MAX_OVER_SHARE, `after zoom and pan: PSNR ${result.psnr.toFixed(1)} dB`);
  s = await status();
  assert.equal(s.level, 0);
});

test('a two-finger pinch zooms about its midpoint', async () => {
  await setView({ cx: 1500, cy: 1000, tpp: 4 });
  const cdp = await browser.context.newCDPSession(page);
  const midpoint = [320, 240];
  const under = await page.evaluate(([x, y]) => window.tessera.textureAt(x, y), midpoint);
  const touch = (type, spread) =>
    cdp.send('Input.dispatchTouchEvent', {
      type,
      touchPoints:
        type === 'touchEnd'
          ? []
          : [
              { x: midpoint[0] - spread, y: midpoint[1], id: 1 },
              { x: midpoint[0] + spread, y: midpoint[1], id: 2 },
            ],
    });
  await touch('touchStart', 50);
  for (let spread = 60; spread <= 200; spread += 20) await touch('touchMove', spread);
  await touch('touchEnd', 0);
  await page.waitForFunction(() => window.tessera.status().view.tpp < 1.5);
  const s = await status();
  // The fingers went from 100 to 400 px apart: 4x closer, 4 -> 1 texel per pixel.
  assert.ok(Math.abs(s.view.tpp - 1) < 0.02, `tpp ${s.view.tpp} after a 4x pinch`);
  const still = await page.evaluate(([x, y]) => window.tessera.textureAt(x, y), midpoint);
  assert.ok(Math.hypot(still[0] - under[0], still[1] - under[1]) < 1, 'the pinch midpoint moved');
  await cdp.detach();
  await settle();
});

test('requests for tiles that left the view are aborted, and the new view loads', async () => {
  await page.evaluate(() => window.tessera.open('scene', 0));
  // Hold every level-0 tile request of the top-left part of the image until released.
  const held = [];
  const failed = [];
  const onFailed = (request) => failed.push([request.url(), request.failure()?.errorText]);
  page.on('requestfailed', onFailed);
  const pattern = /\/scene\/0\/0\/[0-3]\/[0-3](\?|$)/;
  await page.route(pattern, (route) => held.push(route));
  const before = await status();
  await page.evaluate(() => window.tessera.setView({ cx: 400, cy: 300, tpp: 1 }));
  // Every slot taken by a held level-0 tile (the coarser levels came first and are in).
  await page.waitForFunction(() => {
    const s = window.tessera.status();
    return s.inFlight === s.maxInFlight && s.inFlightKeys.every((key) => key.startsWith('0/'));
  });
  const stalled = await status();
  assert.equal(stalled.settled, false);
  assert.equal(held.length, stalled.inFlight);
  // Jump to the other corner: the held tiles are out of view.
  await page.evaluate(() => window.tessera.setView({ cx: 2600, cy: 1700, tpp: 1 }));
  await settle();
  const after = await status();
  assert.ok(
    after.aborted - before.aborted >= stalled.inFlight,
    `aborted ${after.aborted - before.aborted} of ${stalled.inFlight} requests in flight`,
  );
  const abortedHeld = failed.filter(([url]) => pattern.test(url));
  assert.equal(abortedHeld.length, stalled.inFlight, 'the browser saw each held request fail');
  for (const [, reason] of abortedHeld) assert.match(reason, /ABORTED/);
  await page.unroute(pattern);
  page.off('requestfailed', onFailed);
  const result = await compareWithReference();
  assert.ok(result.psnr >= MIN_PSNR_DB && result.overShare <= MAX_OVER_SHARE, `after the jump: PSNR ${result.psnr.toFixed(1)} dB`);
});

test('the level overlay tints each pixel by its level, and the stats panel reports', async () => {
  await setView({ cx: 1500, cy: 1000, tpp: 1 });
  const plain = screenshotPicture(await page.locator('#view').screenshot(), dir);
  await page.evaluate(() => window.tessera.setOverlay(true));
  await settle();
  const tinted = screenshotPicture(await page.locator('#view').screenshot(), dir);
  await page.evaluate(() => window.tessera.setOverlay(false));
  // Level 0 is tinted towards (0.95, 0.2, 0.2) by 0.45 (web/viewer/renderer.js).
  const tint = [0.95, 0.2, 0.2].map((c) => c * 255);
  let worst = 0;
  for (let i = 0; i < plain.rgba.length; i += 4)
    for (let c = 0; c < 3; c += 1) {
      const expected = plain.rgba[i + c] * 0.55 + tint[c] * 0.45;
      worst = Math.max(worst, Math.abs(tinted.rgba[i + c] - expected));
    }
  assert.ok(worst <= 2, `overlay differs from the tinted picture by ${worst}`);
  await page.evaluate(() => window.tessera.showPanels(true));
  await page.waitForFunction(() => /at rest/.test(document.getElementById('stats').textContent));
  const text = await page.locator('#stats').textContent();
  assert.match(text, /level 0/);
  assert.match(text, /in flight 0\/6/);
  assert.match(text, /cache \d+\/384 tiles/);
  await page.evaluate(() => window.tessera.showPanels(false));
});

test('an unknown archive in the address is reported on the page, not thrown away', async () => {
  const other = await browser.context.newPage();
  await other.goto(`${server.url}/#archive=nope`);
  await other.waitForFunction(() => document.getElementById('error').textContent !== '');
  assert.match(await other.locator('#error').textContent(), /no archive named 'nope'/);
  await other.close();
});
