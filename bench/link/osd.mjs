// Drives bench/link/osd.html in headless Chromium (tests/web's harness) and prints one JSON
// line: {first_complete_ms, full_detail_ms, tiles_loaded}. The page and OpenSeadragon come
// from a local static server; only the pyramid goes through the link under test.
//   node bench/link/osd.mjs --dzi URL --x X --y Y --tpp S --viewport 1920x1080 --timeout-s 120
import path from 'node:path';
import { fileURLToPath } from 'node:url';

import { launchChromium, startStatic, webDir } from '../../tests/web/lib/harness.mjs';

const here = path.dirname(fileURLToPath(import.meta.url));
const args = Object.fromEntries(
  process.argv.slice(2).reduce((pairs, word, i, all) => (word.startsWith('--') ? [...pairs, [word.slice(2), all[i + 1]]] : pairs), []),
);
for (const name of ['dzi', 'x', 'y', 'tpp', 'viewport'])
  if (args[name] === undefined) throw new Error(`osd.mjs: --${name} is required`);
const [width, height] = args.viewport.split('x').map(Number);
const timeoutMs = Number(args['timeout-s'] ?? 120) * 1000;

const pages = await startStatic({ '/bench/': here, '/modules/': path.join(webDir, 'node_modules') });
const browser = await launchChromium({ viewport: { width, height } });
try {
  const page = await browser.context.newPage();
  const query = new URLSearchParams({ dzi: args.dzi, x: args.x, y: args.y, tpp: args.tpp });
  await page.goto(`${pages.url}/bench/osd.html?${query}`);
  await page.waitForFunction(() => window.linkResult.error !== null || window.linkResult.fullDetailMs !== null, null, {
    timeout: timeoutMs,
    polling: 20,
  });
  const result = await page.evaluate(() => window.linkResult);
  if (result.error) throw new Error(`osd.mjs: ${args.dzi}: ${result.error}`);
  console.log(JSON.stringify({ first_complete_ms: result.firstCompleteMs, full_detail_ms: result.fullDetailMs, tiles_loaded: result.tilesLoaded }));
} finally {
  await browser.close();
  await pages.stop();
}
