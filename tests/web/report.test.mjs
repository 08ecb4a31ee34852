// The first-run report in headless Chromium: `tessera demo` writes out/demo.html and one
// report.html per flight (HTML made in C++: src/tools/demo_command.cpp, fly_render.cpp). The
// pages must read at a glance, so their layout is checked from the page itself: nothing wider
// than the page, no plot text clipped by its SVG or overlapping another, a legend for every
// plot and every level-tinted picture, pictures that fit, and the same headline numbers as
// summary.json. Screenshots go to TESSERA_WEB_ARTIFACTS (ctest: the build folder).
import { after, before, test } from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import path from 'node:path';
import { pathToFileURL } from 'node:url';

import { launchChromium, tempDir, tessera } from './lib/harness.mjs';

const FLIGHTS = ['jump', 'pan', 'zoom'];
const artifacts = process.env.TESSERA_WEB_ARTIFACTS || tempDir('report-shots');
let dir;
let browser;

before(async () => {
  dir = tempDir('report');
  await tessera('demo', '--dir', dir, '--size', '2048x2048', '--seconds', '0.5', '--viewport', '640x360');
  browser = await launchChromium({ viewport: { width: 1280, height: 900 } });
});

after(async () => {
  await browser?.close();
  if (dir) fs.rmSync(dir, { recursive: true, force: true });
});

const summaryOf = (flight) => JSON.parse(fs.readFileSync(path.join(dir, 'demo', flight, 'summary.json'), 'utf8'));

/** The value at a JSON pointer ("/update_ms/p99"). */
function at(json, pointer) {
  return pointer.split('/').slice(1).reduce((node, key) => (node == null ? undefined : node[key]), json);
}

/** Opens `file`, waits for every picture, saves a full-page screenshot as `shot`. */
async function open(file, shot) {
  const page = await browser.context.newPage();
  await page.goto(pathToFileURL(file).href);
  await page.waitForFunction(() => [...document.images].every((img) => img.complete && img.naturalWidth > 0), null, {
    timeout: 30000,
  });
  await page.evaluate(() => Promise.all([...document.images].map((img) => img.decode())));
  fs.mkdirSync(artifacts, { recursive: true });
  await page.screenshot({ path: path.join(artifacts, shot), fullPage: true });
  return page;
}

/** Layout facts measured in the page. */
function layoutFacts(page) {
  return page.evaluate(() => {
    const width = document.documentElement.clientWidth;
    const describe = (el) => `${el.tagName.toLowerCase()}${el.className?.baseVal ?? el.className ? '.' + (el.className.baseVal ?? el.className) : ''} "${(el.textContent || '').trim().slice(0, 40)}"`;
    const overflowing = [];
    for (const el of document.body.querySelectorAll('*')) {
      const r = el.getBoundingClientRect();
      if (r.width === 0 && r.height === 0) continue;
      if (r.left < -0.5 || r.right > width + 0.5) overflowing.push(`${describe(el)}: ${r.left.toFixed(1)}..${r.right.toFixed(1)} of ${width}`);
    }
    const clipped = [];
    const overlapping = [];
    const plots = [];
    for (const svg of document.querySelectorAll('svg')) {
      const box = svg.getBoundingClientRect();
      const texts = [...svg.querySelectorAll('text')].map((t) => [t, t.getBoundingClientRect()]);
      for (const [t, r] of texts)
        if (r.left < box.left - 0.5 || r.right > box.right + 0.5 || r.top < box.top - 0.5 || r.bottom > box.bottom + 0.5)
          clipped.push(describe(t));
      for (let i = 0; i < texts.length; ++i)
        for (let j = i + 1; j < texts.length; ++j) {
          const [a, ra] = texts[i];
          const [b, rb] = texts[j];
          const w = Math.min(ra.right, rb.right) - Math.max(ra.left, rb.left);
          const h = Math.min(ra.bottom, rb.bottom) - Math.max(ra.top, rb.top);
          if (w > 1 && h > 1) overlapping.push(`${describe(a)} / ${describe(b)}`);
        }
      plots.push({
        title: svg.querySelector('text.title')?.textContent,
        series: svg.querySelectorAll('polyline.series').length,
        legends: [...svg.querySelectorAll('g.legend text')].map((t) => t.textContent),
      });
    }
    const pictures = [...document.images].map((img) => ({
      alt: img.alt,
      width: img.getBoundingClientRect().width,
      room: img.parentElement.getBoundingClientRect().width,
    }));
    const levelLegends = [...document.querySelectorAll('.level-legend')].map((l) => l.querySelectorAll('.swatch').length);
    const tinted = [...document.images].filter((img) => /tinted by the level/.test(img.alt)).length;
    const figures = [...document.querySelectorAll('[data-figure]')].map((cell) => ({
      section: cell.closest('section')?.id ?? null,
      pointer: cell.dataset.figure,
      value: Number(cell.dataset.value),
      text: cell.textContent,
    }));
    return {
      width,
      scrollWidth: document.documentElement.scrollWidth,
      overflowing,
      clipped,
      overlapping,
      plots,
      pictures,
      levelLegends,
      tinted,
      figures,
      warning: document.querySelector('.warning')?.textContent ?? '',
      text: document.body.innerText,
    };
  });
}

/** The layout facts every page must hold. */
function assertLayout(facts, name) {
  assert.ok(facts.scrollWidth <= facts.width, `${name}: the page scrolls sideways (${facts.scrollWidth} > ${facts.width})`);
  assert.deepEqual(facts.overflowing, [], `${name}: elements wider than the page`);
  assert.deepEqual(facts.clipped, [], `${name}: SVG text clipped`);
  assert.deepEqual(facts.overlapping, [], `${name}: SVG texts overlap`);
  for (const picture of facts.pictures) assert.ok(picture.width <= picture.room + 0.5, `${name}: picture "${picture.alt}" wider than its box`);
}

/** Every figure shown equals summary.json's, as a number and as the text rounds it. */
function assertFigures(figures, summaryFor, name) {
  assert.ok(figures.length > 0, `${name}: no headline figures`);
  for (const figure of figures) {
    const summary = summaryFor(figure.section);
    const expected = at(summary, figure.pointer);
    assert.equal(typeof expected, 'number', `${name}: ${figure.pointer} is not in summary.json`);
    assert.ok(Math.abs(figure.value - expected) <= 1e-9 * Math.max(1, Math.abs(expected)), `${name}: ${figure.pointer} is ${figure.value} on the page, ${expected} in summary.json`);
    const shown = /-?\d+(\.\d+)?/.exec(figure.text);
    assert.ok(shown, `${name}: ${figure.pointer} shows no number: ${figure.text}`);
    const decimals = shown[1] ? shown[1].length - 1 : 0;
    assert.ok(Math.abs(Number(shown[0]) - expected) <= 0.5 * 10 ** -decimals + 1e-9, `${name}: ${figure.pointer} shows "${figure.text}" for ${expected}`);
  }
}

test('the demo page: a thumbnail and the headline figures of each flight against their targets', async () => {
  const page = await open(path.join(dir, 'demo.html'), 'report-demo.png');
  const facts = await layoutFacts(page);
  assertLayout(facts, 'demo.html');
  assertFigures(facts.figures, (section) => summaryOf(section), 'demo.html');
  for (const flight of FLIGHTS) {
    assert.ok(facts.figures.some((f) => f.section === flight && f.pointer === '/frames_full_detail_pct'), `no figures for ${flight}`);
    assert.ok(facts.pictures.some((p) => p.alt.startsWith(flight)), `no thumbnail of ${flight}`);
  }
  assert.match(facts.text, /pass/);
  assert.match(facts.text, /target/);
  // Slower than real time is said whenever a flight was.
  for (const flight of FLIGHTS) {
    const slow = summaryOf(flight).slowdown > 1.05;
    assert.equal(facts.warning.includes(`${flight} took`), slow, `${flight}: slowdown ${summaryOf(flight).slowdown}, warning "${facts.warning}"`);
  }
  assert.doesNotMatch(facts.text, /\b5 s a flight\b/);
  await page.close();
});

for (const flight of FLIGHTS) {
  test(`the ${flight} report: plots with round ticks and legends, pictures that fit, a level legend`, async () => {
    const summary = summaryOf(flight);
    const page = await open(path.join(dir, 'demo', flight, 'report.html'), `report-${flight}.png`);
    const facts = await layoutFacts(page);
    assertLayout(facts, `${flight}/report.html`);
    assertFigures(facts.figures, () => summary, `${flight}/report.html`);
    assert.ok(facts.plots.length >= 5, 'plots missing');
    for (const plot of facts.plots) {
      assert.ok(plot.series >= 1, `${plot.title}: no series`);
      assert.equal(plot.legends.length, plot.series, `${plot.title}: a legend entry per series`);
    }
    // Round ticks: every y tick label of a plot is a multiple of one step of 1, 2 or 5 x 10^k.
    const ticks = await page.evaluate(() =>
      [...document.querySelectorAll('svg.plot')].map((svg) =>
        [...svg.querySelectorAll("text[text-anchor='end']")].map((t) => t.textContent).filter((t) => /^-?\d+(\.\d+)?$/.test(t)).map(Number),
      ),
    );
    for (const labels of ticks) {
      const y = labels.filter((v, i) => i === 0 || v > labels[i - 1]);
      if (y.length < 2) continue;
      const step = y[1] - y[0];
      const mantissa = step / 10 ** Math.floor(Math.log10(step) + 1e-9);
      assert.ok([1, 2, 5].some((m) => Math.abs(mantissa - m) < 1e-6), `tick step ${step} (${y.join(', ')})`);
    }
    // Each tinted picture has the level legend, with a swatch per level.
    assert.ok(facts.tinted > 0, 'no level-tinted picture');
    assert.ok(facts.levelLegends.length >= 1, 'no level legend');
    for (const swatches of facts.levelLegends) assert.equal(swatches, summary.levels);
    // The same PSNR everywhere: the jumps table and the captions say what summary.json says.
    for (const jump of summary.jumps)
      if (typeof jump.rest_psnr_db === 'number') assert.match(facts.text, new RegExp(`${jump.rest_psnr_db.toFixed(1)} dB`));
    assert.doesNotMatch(facts.text, /999/);
    assert.equal(facts.warning !== '', summary.slowdown > 1.05, `slowdown ${summary.slowdown}, warning "${facts.warning}"`);
    await page.close();
  });
}
