// What the web viewer fetches, cancels and keeps: the request plan for a view and the bounded
// texture cache (least recently used first out). Pure, so tests/web/unit checks them in node.

/**
 * The requests to start and to cancel for a view. `needed` is neededTiles(view, image): in
 * priority order (coarse first, then centre-out). Requests in flight for tiles the view no
 * longer needs are cancelled (the view jumped or zoomed away: their bytes would be wasted on
 * tiles nobody sees, while the visible ones wait). Then, up to `maxInFlight` requests in all,
 * the first needed tiles that are neither resident, nor in flight, nor failed start.
 *
 * @param {Array<{key: string}>} needed tiles in priority order
 * @param {{isResident: (key: string) => boolean, inFlight: Set<string>, failed: Set<string>,
 *          maxInFlight: number}} state
 * @returns {{start: Array<object>, cancel: string[]}}
 */
export function planRequests(needed, state) {
  const neededKeys = new Set(needed.map((t) => t.key));
  const cancel = [...state.inFlight].filter((key) => !neededKeys.has(key));
  let slots = state.maxInFlight - (state.inFlight.size - cancel.length);
  const start = [];
  for (const tile of needed) {
    if (slots <= 0) break;
    if (state.isResident(tile.key) || state.inFlight.has(tile.key) || state.failed.has(tile.key))
      continue;
    start.push(tile);
    slots -= 1;
  }
  return { start, cancel };
}

/**
 * Where a view stands: `complete` when every needed tile is resident (the picture is the one
 * the reference draws at rest), `missing` the needed tiles not resident, `failed` those whose
 * request failed, and `idle` when nothing is in flight and nothing more can be started.
 */
export function viewProgress(needed, state) {
  let missing = 0;
  let failed = 0;
  let startable = 0;
  for (const tile of needed) {
    if (state.isResident(tile.key)) continue;
    missing += 1;
    if (state.failed.has(tile.key)) failed += 1;
    else if (!state.inFlight.has(tile.key)) startable += 1;
  }
  return {
    complete: missing === 0,
    missing,
    failed,
    idle: state.inFlight.size === 0 && startable === 0,
  };
}

/**
 * A cache of at most `capacity` entries, evicting the least recently used first; entries whose
 * key is `pinned(key)` (the coarsest level, so nothing is ever blank) or in the set passed to
 * trim (what the current frame draws) are never evicted. `onEvict(key, value)` frees an entry
 * (the WebGL texture).
 */
export class LruCache {
  constructor(capacity, { onEvict = () => {}, pinned = () => false } = {}) {
    if (!(capacity >= 1)) throw new RangeError(`cache capacity must be at least 1, got ${capacity}`);
    this.capacity = capacity;
    this.onEvict = onEvict;
    this.pinned = pinned;
    this.entries = new Map(); // insertion order = recency order, oldest first
    this.evictions = 0;
  }

  get size() {
    return this.entries.size;
  }

  has(key) {
    return this.entries.has(key);
  }

  /** The value, marked as just used; undefined when absent. */
  get(key) {
    const value = this.entries.get(key);
    if (value === undefined) return undefined;
    this.entries.delete(key);
    this.entries.set(key, value);
    return value;
  }

  /** The value without changing its recency. */
  peek(key) {
    return this.entries.get(key);
  }

  /**
   * Inserts (or replaces) an entry as the most recent, then trims to capacity; the new entry
   * itself is never the one evicted.
   */
  set(key, value, protect = new Set()) {
    const old = this.entries.get(key);
    if (old !== undefined) {
      this.entries.delete(key);
      if (old !== value) this.onEvict(key, old);
    }
    this.entries.set(key, value);
    this.trim(new Set([...protect, key]));
  }

  /**
   * Evicts the least recently used entries until at most `capacity` remain, skipping pinned
   * and protected ones (so the cache may stay above capacity while a frame needs more).
   */
  trim(protect = new Set()) {
    if (this.entries.size <= this.capacity) return;
    for (const [key, value] of this.entries) {
      if (this.entries.size <= this.capacity) break;
      if (this.pinned(key) || protect.has(key)) continue;
      this.entries.delete(key);
      this.evictions += 1;
      this.onEvict(key, value);
    }
  }

  /** Removes every entry, calling onEvict for each. */
  clear() {
    for (const [key, value] of this.entries) this.onEvict(key, value);
    this.entries.clear();
  }
}

/** Bytes per second over a sliding window of `windowMs` milliseconds. */
export class RateMeter {
  constructor(windowMs = 1000) {
    this.windowMs = windowMs;
    this.samples = [];
    this.total = 0;
  }

  add(bytes, nowMs) {
    this.samples.push([nowMs, bytes]);
    this.total += bytes;
  }

  rate(nowMs) {
    while (this.samples.length && this.samples[0][0] <= nowMs - this.windowMs) this.samples.shift();
    const sum = this.samples.reduce((acc, [, bytes]) => acc + bytes, 0);
    return (sum * 1000) / this.windowMs;
  }
}

const BROWSER_TYPES = new Set(['image/jpeg', 'image/png', 'image/webp']);

/** Bytes of one 4x4 block of the codecs whose stored tiles a GPU samples as they are. */
const BLOCK_BYTES = { bc1: 8, bc7: 16 };

/**
 * The block codec (`bc1` or `bc7`) of an image whose stored tiles the viewer uploads as they
 * are, or null. It needs 8-bit samples, `payload_side` in info.json (the side the blocks cover,
 * padding included) and the codec in `gpuCodecs`, the names of the block codecs the WebGL
 * context samples (a Set; null or empty: none).
 */
export function blockCodec(image, gpuCodecs) {
  if (!gpuCodecs || !Object.hasOwn(BLOCK_BYTES, image.codec) || !gpuCodecs.has(image.codec)) return null;
  if (isWide(image) || !Number.isInteger(image.payload_side) || image.payload_side % 4 !== 0) return null;
  return image.codec;
}

/** The bytes of a stored tile of block codec `codec` whose blocks cover `side` x `side` texels. */
export function blockPayloadBytes(codec, side) {
  return Math.ceil(side / 4) ** 2 * BLOCK_BYTES[codec];
}

/**
 * The URL path of a tile for the browser: the stored payload when the archive's codec is one
 * browsers decode (tile_content_type image/jpeg, png or webp) or a block codec the GPU samples
 * (`blockCodec(image, gpuCodecs)`), else `?format=png`, a lossless transcode of the same stored
 * tile (borders included). `forcePng` asks for the transcode anyway: uniform and empty tiles
 * have no stored payload. A 16-bit or float image (sample_type u16 or f32) is always the
 * transcode, mapped to 8 bits by the server with `display` ({low, high, gamma}; null: the
 * server's default window).
 */
export function tileUrl(archiveName, image, level, x, y, forcePng = false, display = null, gpuCodecs = null) {
  const path = `${encodeURIComponent(archiveName)}/${image.index}/${level}/${x}/${y}`;
  if (isWide(image)) return `${path}?format=png${windowQuery(display)}`;
  if (forcePng) return `${path}?format=png`;
  return BROWSER_TYPES.has(image.tile_content_type) || blockCodec(image, gpuCodecs) ? path : `${path}?format=png`;
}

/** True for an image whose samples are not 8-bit: its tiles need a display window. */
export function isWide(image) {
  return image.sample_type !== undefined && image.sample_type !== 'u8';
}

/**
 * The query parameters of a display window (docs/serve.md): `&window=LOW,HIGH&gamma=G`, or
 * nothing for null. Throws a RangeError for a window the server would refuse, so that the
 * viewer says so before any request.
 */
export function windowQuery(display) {
  if (!display) return '';
  const { low, high, gamma } = display;
  if (![low, high, gamma].every(Number.isFinite)) throw new RangeError('the window needs numbers');
  if (!(low < high)) throw new RangeError('the window\'s low end must be below its high end');
  if (!(gamma > 0)) throw new RangeError('gamma must be above 0');
  return `&window=${low},${high}&gamma=${gamma}`;
}

/**
 * The RGBA colour of a uniform tile from `tessera serve`'s X-Tessera-Uniform-Rgba header (8 hex
 * digits, two per channel in channel order: rrggbbaa), expanded to RGBA
 * as every renderer expands texels (docs/rendering.md): grey g as (g, g, g, 255), grey+alpha
 * as (g, g, g, a), RGB with alpha 255. Null when the header is not 8 hex digits.
 */
export function uniformColour(header, channels) {
  if (typeof header !== 'string' || !/^[0-9a-fA-F]{8}$/.test(header)) return null;
  const b = [0, 2, 4, 6].map((at) => Number.parseInt(header.slice(at, at + 2), 16));
  if (channels === 1) return [b[0], b[0], b[0], 255];
  if (channels === 2) return [b[0], b[0], b[0], b[1]];
  if (channels === 3) return [b[0], b[1], b[2], 255];
  return b;
}
