// The web viewer served by `tessera serve` at `/` (docs/web.md): lists the archives, streams
// the tiles a view needs with the native runtime's priorities (coarse first, centre-out,
// cancelled when out of view; Backes et al., section 6), keeps a bounded texture cache and
// draws with WebGL2 (renderer.js). `window.tessera` lets tests and scripts set the view and
// wait for the picture to settle.

import {
  fitView,
  levelBlend,
  neededTiles,
  panBy,
  screenToTexture,
  visibleTileRange,
  zoomAbout,
} from './view.js';
import {
  LruCache,
  RateMeter,
  blockCodec,
  blockPayloadBytes,
  isWide,
  planRequests,
  tileUrl,
  uniformColour,
  viewProgress,
  windowQuery,
} from './schedule.js';
import { LEVEL_COLOURS, TileRenderer } from './renderer.js';

const DEFAULT_MAX_IN_FLIGHT = 6; // Chromium's and Firefox's HTTP/1.1 connections per host
const DEFAULT_CACHE_TILES = 384; // ~100 MiB of RGBA 258 px tiles, about 5 full-HD views

const $ = (id) => document.getElementById(id);

class Viewer {
  constructor() {
    this.canvas = $('view');
    this.renderer = new TileRenderer(this.canvas);
    this.archive = null; // {name, info}
    this.image = null; // info.images[i]
    this.view = null;
    this.overlay = false;
    this.display = null; // {low, high, gamma} of a wide image; null: the server's default
    this.maxInFlight = DEFAULT_MAX_IN_FLIGHT;
    this.inFlight = new Map(); // key -> {controller, tile}
    this.failed = new Map(); // key -> message
    this.generation = 0; // bumped when the archive or image changes
    this.cache = this.makeCache(DEFAULT_CACHE_TILES);
    this.rate = new RateMeter(1000);
    this.counters = { requested: 0, loaded: 0, aborted: 0, failed: 0, bytes: 0, frames: 0, blockUploads: 0 };
    // False: bc1 and bc7 tiles come as PNG transcodes even where the GPU samples their blocks
    // (a comparison of the two paths; window.tessera.setBlockUploads).
    this.blockUploads = true;
    this.frameTimes = [];
    this.dirty = true;
    this.drawnSinceChange = false;
    this.lastDraw = { quads: 0, needed: 0, progress: null };
    this.scheduled = false;
  }

  makeCache(capacity) {
    return new LruCache(capacity, {
      onEvict: (key, entry) => this.renderer.release(entry),
      pinned: (key) => this.image !== null && key.startsWith(`${this.image.level_count - 1}/`),
    });
  }

  async open(name, imageIndex = 0) {
    const listed = this.archives.find((a) => a.name === name);
    if (!listed) throw new Error(`no archive named '${name}' on this server`);
    const response = await fetch(new URL(listed.info.replace(/^\//, ''), document.baseURI));
    if (!response.ok) throw new Error(`${listed.info}: HTTP ${response.status}`);
    const info = await response.json();
    const image = info.images[imageIndex];
    if (!image) throw new Error(`${name} has no image ${imageIndex}`);
    image.index = imageIndex;
    this.cancelAll();
    this.cache.clear();
    this.failed.clear();
    this.generation += 1;
    this.archive = { name, info };
    this.image = image;
    this.display = null;
    this.view = fitView(image, this.canvas.width, this.canvas.height);
    this.fillImageSelect();
    this.fillWindowControls();
    this.changed();
  }

  /**
   * Shows a wide image through another display window ({low, high, gamma}, or null for the
   * server's default): every tile is fetched again, mapped by the server (docs/web.md). Throws
   * a RangeError for a window the server would refuse.
   */
  setDisplay(display) {
    windowQuery(display); // checks it
    this.cancelAll();
    this.cache.clear();
    this.failed.clear();
    this.generation += 1;
    this.display = display;
    this.fillWindowControls();
    this.changed();
  }

  fillWindowControls() {
    const wide = isWide(this.image);
    $('window').hidden = !wide;
    if (!wide) return;
    const shown = this.display || { ...this.image.display_window, gamma: 1 };
    $('window-low').value = shown.low ?? '';
    $('window-high').value = shown.high ?? '';
    $('window-gamma').value = shown.gamma ?? 1;
  }

  /** The block codecs whose stored tiles this viewer uploads as they are (a Set of names). */
  gpuCodecs() {
    return this.blockUploads ? new Set(this.renderer.blockFormats.keys()) : new Set();
  }

  /** Uploads bc1 and bc7 tiles as stored (on) or fetches PNG transcodes (off); refetches. */
  setBlockUploads(on) {
    this.blockUploads = Boolean(on);
    this.cancelAll();
    this.cache.clear();
    this.failed.clear();
    this.generation += 1;
    this.changed();
  }

  cancelAll() {
    for (const { controller } of this.inFlight.values()) controller.abort();
    this.counters.aborted += this.inFlight.size;
    this.inFlight.clear();
  }

  setView(next) {
    this.view = { ...this.view, ...next, width: this.canvas.width, height: this.canvas.height };
    this.changed();
  }

  changed() {
    this.dirty = true;
    this.drawnSinceChange = false;
    this.schedule();
  }

  schedule() {
    if (this.scheduled) return;
    this.scheduled = true;
    requestAnimationFrame((t) => this.frame(t));
  }

  resize() {
    const dpr = window.devicePixelRatio || 1;
    const w = Math.max(1, Math.round(this.canvas.clientWidth * dpr));
    const h = Math.max(1, Math.round(this.canvas.clientHeight * dpr));
    if (w === this.canvas.width && h === this.canvas.height) return;
    this.canvas.width = w;
    this.canvas.height = h;
    if (this.view) this.setView({});
  }

  isResident = (key) => this.cache.has(key);

  /** Starts and cancels requests for the current view; returns the needed tiles. */
  stream() {
    const needed = neededTiles(this.view, this.image);
    const plan = planRequests(needed, {
      isResident: this.isResident,
      inFlight: new Set(this.inFlight.keys()),
      failed: new Set(this.failed.keys()),
      maxInFlight: this.maxInFlight,
    });
    for (const key of plan.cancel) {
      this.inFlight.get(key).controller.abort();
      this.inFlight.delete(key);
      this.counters.aborted += 1;
    }
    for (const tile of plan.start) this.fetchTile(tile, false);
    return needed;
  }

  async fetchTile(tile, forcePng) {
    const controller = new AbortController();
    const generation = this.generation;
    this.inFlight.set(tile.key, { controller, tile });
    this.counters.requested += 1;
    const codecs = this.gpuCodecs();
    const path = tileUrl(this.archive.name, this.image, tile.level, tile.x, tile.y, forcePng, this.display, codecs);
    const blocks = forcePng ? null : blockCodec(this.image, codecs);
    const done = () => {
      // A cancelled request was already taken out of the map (maybe replaced by a new one).
      const current = this.inFlight.get(tile.key);
      if (current && current.controller === controller) this.inFlight.delete(tile.key);
    };
    try {
      const response = await fetch(new URL(path, document.baseURI), { signal: controller.signal });
      if (!response.ok) throw new Error(`${path}: HTTP ${response.status}`);
      if (response.status === 204) {
        // No stored payload (docs/serve.md): a uniform tile's colour comes in a header and
        // fills a 1x1 texture (every texel of the stored tile, borders included, is that
        // colour); an empty tile is asked for again as a transcoded PNG.
        const colour =
          response.headers.get('X-Tessera-Tile-Kind') === 'uniform'
            ? uniformColour(response.headers.get('X-Tessera-Uniform-Rgba'), this.image.channels)
            : null;
        if (!colour) {
          done();
          if (forcePng) throw new Error(`${path}: no content`);
          if (generation === this.generation && !controller.signal.aborted) this.fetchTile(tile, true);
          return;
        }
        if (controller.signal.aborted || generation !== this.generation) return;
        this.store(tile, this.renderer.uploadPixels(new Uint8Array(colour), 1, 1), 0, done);
        return;
      }
      if (blocks) {
        // A tile stored in another codec than the archive's has no blocks to upload.
        if (response.headers.get('X-Tessera-Codec') !== blocks) {
          done();
          if (generation === this.generation && !controller.signal.aborted) this.fetchTile(tile, true);
          return;
        }
        const data = new Uint8Array(await response.arrayBuffer());
        if (controller.signal.aborted || generation !== this.generation) return;
        const side = this.image.payload_side;
        const expected = blockPayloadBytes(blocks, side);
        if (data.byteLength !== expected)
          throw new Error(`${path}: ${data.byteLength} bytes of ${blocks}, expected ${expected} for ${side}x${side} texels`);
        const entry = this.renderer.uploadBlocks(blocks, data, side);
        this.counters.blockUploads += 1;
        this.store(tile, entry, data.byteLength, done);
        return;
      }
      const blob = await response.blob();
      const bitmap = await createImageBitmap(blob, {
        premultiplyAlpha: 'none',
        colorSpaceConversion: 'none',
      });
      if (controller.signal.aborted || generation !== this.generation) {
        bitmap.close();
        return;
      }
      const side = this.image.tile_size + 2 * this.image.border;
      if (bitmap.width !== side || bitmap.height !== side) {
        bitmap.close();
        throw new Error(`${path}: ${bitmap.width}x${bitmap.height} px, expected ${side}x${side}`);
      }
      const entry = this.renderer.upload(bitmap);
      bitmap.close();
      this.store(tile, entry, blob.size, done);
    } catch (error) {
      done();
      if (controller.signal.aborted || error.name === 'AbortError') return;
      if (generation !== this.generation) return;
      this.failed.set(tile.key, String(error.message || error));
      this.counters.failed += 1;
      console.warn(`tessera viewer: tile ${tile.key}: ${error.message || error}`);
      this.changed();
    }
  }

  store(tile, entry, bytes, done) {
    this.rate.add(bytes, performance.now());
    this.counters.bytes += bytes;
    this.counters.loaded += 1;
    done();
    this.cache.set(tile.key, entry, this.protectedKeys());
    this.changed();
  }

  /** Keys the current frame draws: never evicted for another tile of the same frame. */
  protectedKeys() {
    return new Set(this.lastNeeded ? this.lastNeeded.map((t) => t.key) : []);
  }

  /**
   * Without borders the renderer filters across tile edges from the resident tiles around
   * each one (renderer.js): the 3 x 3 entries around (x, y), row-major, null where absent.
   * With borders each tile carries its neighbours' texels and this is null.
   */
  neighbours(level, x, y) {
    if (this.image.border > 0) return null;
    const out = [];
    for (let dy = -1; dy <= 1; dy += 1)
      for (let dx = -1; dx <= 1; dx += 1) out.push(this.cache.peek(`${level}/${x + dx}/${y + dy}`) || null);
    return out;
  }

  /** Layers to draw, coarsest first: each level's resident tiles in view. */
  layers(blend) {
    const out = [];
    const { level: desired } = blend;
    for (let level = this.image.level_count - 1; level >= desired; level -= 1) {
      const range = visibleTileRange(this.view, this.image, level);
      if (!range) continue;
      const tiles = [];
      for (let y = range[1]; y < range[3]; y += 1)
        for (let x = range[0]; x < range[2]; x += 1) {
          const entry = this.cache.get(`${level}/${x}/${y}`);
          if (entry) tiles.push({ x, y, entry, neighbours: this.neighbours(level, x, y) });
        }
      // The desired level blends over the next coarser one by 1 - f (trilinear); every other
      // level covers what is below it.
      const alpha = level === desired && blend.blend > 0 ? 1 - blend.blend : 1;
      out.push({ level, tiles, alpha });
    }
    return out;
  }

  frame(now) {
    this.scheduled = false;
    if (!this.image) return;
    const needed = this.stream();
    this.lastNeeded = needed;
    this.cache.trim(this.protectedKeys());
    const blend = levelBlend(this.view.tpp, this.image.level_count);
    if (this.dirty) {
      const quads = this.renderer.draw(this.view, this.image, this.layers(blend), this.overlay);
      this.dirty = false;
      this.counters.frames += 1;
      this.frameTimes.push(now);
      this.lastDraw.quads = quads;
    }
    const progress = viewProgress(needed, {
      isResident: this.isResident,
      inFlight: new Set(this.inFlight.keys()),
      failed: new Set(this.failed.keys()),
    });
    this.lastDraw.needed = needed.length;
    this.lastDraw.progress = progress;
    this.lastDraw.blend = blend;
    this.drawnSinceChange = true;
  }

  status() {
    const progress = this.lastDraw.progress || { complete: false, missing: 0, failed: 0, idle: false };
    const blend = this.lastDraw.blend || { level: -1, blend: 0 };
    return {
      archive: this.archive ? this.archive.name : null,
      image: this.image ? this.image.index : null,
      view: this.view ? { ...this.view } : null,
      level: blend.level,
      blend: blend.blend,
      needed: this.lastDraw.needed,
      missing: progress.missing,
      failedTiles: progress.failed,
      complete: progress.complete,
      idle: progress.idle && this.inFlight.size === 0,
      // At rest with everything at the desired level, and that picture drawn.
      settled:
        progress.complete && progress.idle && this.inFlight.size === 0 && !this.dirty && this.drawnSinceChange,
      inFlight: this.inFlight.size,
      inFlightKeys: [...this.inFlight.keys()],
      maxInFlight: this.maxInFlight,
      blockCodecs: [...this.renderer.blockFormats.keys()],
      cacheTiles: this.cache.size,
      cacheCapacity: this.cache.capacity,
      cacheBytes: [...this.cache.entries.values()].reduce((sum, e) => sum + e.bytes, 0),
      evictions: this.cache.evictions,
      quads: this.lastDraw.quads,
      ...this.counters,
      errors: [...this.failed.values()].slice(0, 5),
    };
  }

  fps(now) {
    while (this.frameTimes.length && this.frameTimes[0] < now - 1000) this.frameTimes.shift();
    return this.frameTimes.length;
  }

  updatePanel(now) {
    if (!this.view) return;
    const s = this.status();
    const mib = (bytes) => (bytes / 1048576).toFixed(1);
    const lines = [
      `fps ${this.fps(now)}   frames ${s.frames}`,
      `level ${s.level}${s.blend > 0 ? ` + ${s.blend.toFixed(2)} of ${s.level + 1}` : ''}   ` +
        `${(1 / s.view.tpp).toFixed(3)} px/texel`,
      `in flight ${s.inFlight}/${s.maxInFlight}   missing ${s.missing}/${s.needed}`,
      `cache ${s.cacheTiles}/${s.cacheCapacity} tiles, ${mib(s.cacheBytes)} MiB, ${s.evictions} evicted`,
      `${(this.rate.rate(now) / 1024).toFixed(0)} KiB/s   ${mib(s.bytes)} MiB in ${s.loaded} tiles` +
        (s.blockUploads ? `, ${s.blockUploads} as GPU blocks` : ''),
      `requested ${s.requested}   aborted ${s.aborted}   failed ${s.failed}`,
      s.settled ? 'at rest: every tile at the desired level' : s.complete ? 'drawing' : 'loading',
    ];
    $('stats').textContent = lines.join('\n');
  }

  fillImageSelect() {
    const select = $('image');
    select.replaceChildren(
      ...this.archive.info.images.map((img, i) => {
        const option = document.createElement('option');
        option.value = String(i);
        option.textContent = `${i}: ${img.name || 'image'} ${img.width}x${img.height} ${img.codec}`;
        return option;
      }),
    );
    select.value = String(this.image.index);
    $('archive').value = this.archive.name;
    this.fillLegend();
  }

  fillLegend() {
    const legend = $('legend');
    legend.replaceChildren(
      ...Array.from({ length: this.image.level_count }, (_, level) => {
        const item = document.createElement('span');
        const c = LEVEL_COLOURS[level % LEVEL_COLOURS.length].map((x) => Math.round(x * 255));
        item.style.background = `rgb(${c.join(',')})`;
        item.textContent = String(level);
        return item;
      }),
    );
    legend.hidden = !this.overlay;
  }

  setOverlay(on) {
    this.overlay = Boolean(on);
    $('overlay').checked = this.overlay;
    $('legend').hidden = !this.overlay;
    this.changed();
  }
}

/** Mouse, wheel, touch (pointer events: one finger pans, two pinch) and keyboard. */
function bindInput(viewer) {
  const canvas = viewer.canvas;
  const pointers = new Map(); // pointerId -> [x, y] in device pixels
  const dpr = () => window.devicePixelRatio || 1;
  const local = (event) => {
    const rect = canvas.getBoundingClientRect();
    return [(event.clientX - rect.left) * dpr(), (event.clientY - rect.top) * dpr()];
  };
  const limits = () => {
    const fit = fitView(viewer.image, canvas.width, canvas.height).tpp;
    return [1 / 64, Math.max(fit * 4, 1)];
  };
  const zoom = (factor, sx, sy) => {
    const [minTpp, maxTpp] = limits();
    viewer.setView(zoomAbout(viewer.view, factor, sx, sy, minTpp, maxTpp));
  };
  canvas.addEventListener('pointerdown', (event) => {
    if (!viewer.view) return;
    canvas.setPointerCapture(event.pointerId);
    pointers.set(event.pointerId, local(event));
  });
  canvas.addEventListener('pointermove', (event) => {
    if (!pointers.has(event.pointerId) || !viewer.view) return;
    const before = [...pointers.values()];
    pointers.set(event.pointerId, local(event));
    const after = [...pointers.values()];
    if (after.length === 1) {
      viewer.setView(panBy(viewer.view, after[0][0] - before[0][0], after[0][1] - before[0][1]));
    } else if (after.length >= 2) {
      // Pinch: the midpoint pans, the change of the fingers' distance zooms about it.
      const mid = (p) => [(p[0][0] + p[1][0]) / 2, (p[0][1] + p[1][1]) / 2];
      const dist = (p) => Math.hypot(p[0][0] - p[1][0], p[0][1] - p[1][1]);
      const [m0, m1] = [mid(before), mid(after)];
      const panned = panBy(viewer.view, m1[0] - m0[0], m1[1] - m0[1]);
      const [minTpp, maxTpp] = limits();
      const factor = dist(before) > 0 ? dist(after) / dist(before) : 1;
      viewer.setView(zoomAbout(panned, factor, m1[0], m1[1], minTpp, maxTpp));
    }
  });
  const lift = (event) => pointers.delete(event.pointerId);
  canvas.addEventListener('pointerup', lift);
  canvas.addEventListener('pointercancel', lift);
  canvas.addEventListener(
    'wheel',
    (event) => {
      if (!viewer.view) return;
      event.preventDefault();
      const pixels = event.deltaY * (event.deltaMode === 1 ? 40 : event.deltaMode === 2 ? 800 : 1);
      const [sx, sy] = local(event);
      zoom(2 ** (-pixels / 400), sx, sy);
    },
    { passive: false },
  );
  canvas.addEventListener('dblclick', (event) => {
    if (!viewer.view) return;
    const [sx, sy] = local(event);
    zoom(event.shiftKey ? 0.5 : 2, sx, sy);
  });
  window.addEventListener('keydown', (event) => {
    if (!viewer.view || event.target instanceof HTMLSelectElement) return;
    const step = 100 * dpr();
    const w = canvas.width / 2;
    const h = canvas.height / 2;
    const actions = {
      ArrowLeft: () => viewer.setView(panBy(viewer.view, step, 0)),
      ArrowRight: () => viewer.setView(panBy(viewer.view, -step, 0)),
      ArrowUp: () => viewer.setView(panBy(viewer.view, 0, step)),
      ArrowDown: () => viewer.setView(panBy(viewer.view, 0, -step)),
      '+': () => zoom(2, w, h),
      '=': () => zoom(2, w, h),
      '-': () => zoom(0.5, w, h),
      0: () => viewer.setView(fitView(viewer.image, canvas.width, canvas.height)),
      q: () => viewer.setView({ rotation: (viewer.view.rotation || 0) - Math.PI / 12 }),
      e: () => viewer.setView({ rotation: (viewer.view.rotation || 0) + Math.PI / 12 }),
      l: () => viewer.setOverlay(!viewer.overlay),
      p: () => ($('stats').hidden = !$('stats').hidden),
    };
    const action = actions[event.key];
    if (action) {
      event.preventDefault();
      action();
    }
  });
}

async function start() {
  let viewer;
  try {
    viewer = new Viewer();
  } catch (error) {
    $('error').textContent = `Cannot draw: ${error.message}`;
    throw error;
  }
  const response = await fetch(new URL('api/archives', document.baseURI));
  if (!response.ok) throw new Error(`/api/archives: HTTP ${response.status}`);
  viewer.archives = (await response.json()).archives;
  const archiveSelect = $('archive');
  archiveSelect.replaceChildren(
    ...viewer.archives.map((a) => {
      const option = document.createElement('option');
      option.value = a.name;
      option.textContent = a.name;
      return option;
    }),
  );
  viewer.resize();
  setInterval(() => viewer.updatePanel(performance.now()), 250);
  new ResizeObserver(() => viewer.resize()).observe(viewer.canvas);
  bindInput(viewer);
  const showError = (error) => {
    $('error').textContent = String(error.message || error);
    console.error(error);
  };
  const openAndReport = (name, image) => {
    $('error').textContent = '';
    viewer.open(name, image).catch(showError);
  };
  archiveSelect.addEventListener('change', () => openAndReport(archiveSelect.value, 0));
  $('image').addEventListener('change', () => openAndReport(viewer.archive.name, Number($('image').value)));
  $('overlay').addEventListener('change', () => viewer.setOverlay($('overlay').checked));
  const applyWindow = () => {
    const display = {
      low: Number.parseFloat($('window-low').value),
      high: Number.parseFloat($('window-high').value),
      gamma: Number.parseFloat($('window-gamma').value),
    };
    try {
      viewer.setDisplay(display);
      $('error').textContent = '';
    } catch (error) {
      showError(error);
    }
  };
  for (const id of ['window-low', 'window-high', 'window-gamma'])
    $(id).addEventListener('change', applyWindow);
  $('window-auto').addEventListener('click', () => viewer.setDisplay(null));

  const params = new URLSearchParams(location.hash.slice(1));
  window.tessera = {
    viewer,
    open: (name, image = 0) => viewer.open(name, image),
    /** {cx, cy, tpp, rotation}; the viewport is the canvas's, in device pixels. */
    setView: (view) => viewer.setView(view),
    fit: () => viewer.setView(fitView(viewer.image, viewer.canvas.width, viewer.canvas.height)),
    status: () => viewer.status(),
    textureAt: (sx, sy) => screenToTexture(viewer.view, sx, sy),
    setOverlay: (on) => viewer.setOverlay(on),
    setDisplayWindow: (display) => viewer.setDisplay(display),
    showPanels: (on) => {
      for (const id of ['stats', 'bar']) $(id).hidden = !on;
    },
    /** On (the default): bc1 and bc7 tiles go to the GPU as stored where it samples them. */
    setBlockUploads: (on) => viewer.setBlockUploads(on),
    setMaxInFlight: (n) => {
      viewer.maxInFlight = Math.max(1, n | 0);
      viewer.changed();
    },
    setCacheCapacity: (n) => {
      viewer.cache.capacity = Math.max(1, n | 0);
      viewer.changed();
    },
  };
  if (viewer.archives.length === 0) {
    $('error').textContent = 'This server serves no archives.';
    return;
  }
  const name = params.get('archive') || viewer.archives[0].name;
  await viewer.open(name, Number(params.get('image') || 0));
  if (params.get('overlay') === '1') viewer.setOverlay(true);
}

start().catch((error) => {
  $('error').textContent = String(error.message || error);
  console.error(error);
});
