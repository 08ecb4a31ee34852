// The web viewer's request plan, progress and texture cache (web/viewer/schedule.js).
import assert from 'node:assert/strict';
import { test } from 'node:test';

import {
  LruCache,
  RateMeter,
  blockCodec,
  blockPayloadBytes,
  planRequests,
  tileUrl,
  windowQuery,
  uniformColour,
  viewProgress,
} from '../../../web/viewer/schedule.js';

const tiles = (...keys) => keys.map((key) => ({ key }));

test('requests start in priority order, up to the in-flight limit', () => {
  const needed = tiles('4/0/0', '3/0/0', '3/1/0', '2/1/1', '2/0/1');
  const plan = planRequests(needed, {
    isResident: (key) => key === '3/0/0',
    inFlight: new Set(['4/0/0']),
    failed: new Set(['3/1/0']),
    maxInFlight: 3,
  });
  assert.deepEqual(plan.cancel, []);
  // 4/0/0 in flight, 3/0/0 resident, 3/1/0 failed: the next two by priority fill the 3 slots.
  assert.deepEqual(plan.start.map((t) => t.key), ['2/1/1', '2/0/1']);
});

test('requests for tiles out of view are cancelled and their slots reused', () => {
  const needed = tiles('4/0/0', '1/5/5', '1/5/6');
  const plan = planRequests(needed, {
    isResident: (key) => key === '4/0/0',
    inFlight: new Set(['1/0/0', '1/0/1', '1/5/5']),
    failed: new Set(),
    maxInFlight: 3,
  });
  assert.deepEqual(plan.cancel.sort(), ['1/0/0', '1/0/1']);
  assert.deepEqual(plan.start.map((t) => t.key), ['1/5/6']);
  // Nothing starts when every slot holds a tile still in view.
  const full = planRequests(needed, {
    isResident: () => false,
    inFlight: new Set(['1/5/5', '1/5/6']),
    failed: new Set(),
    maxInFlight: 2,
  });
  assert.deepEqual(full, { start: [], cancel: [] });
});

test('progress: complete only when every needed tile is resident; idle when nothing can move', () => {
  const needed = tiles('a', 'b', 'c');
  const state = (resident, inFlight, failed) => ({
    isResident: (key) => resident.includes(key),
    inFlight: new Set(inFlight),
    failed: new Set(failed),
  });
  assert.deepEqual(viewProgress(needed, state(['a', 'b', 'c'], [], [])), {
    complete: true, missing: 0, failed: 0, idle: true,
  });
  assert.deepEqual(viewProgress(needed, state(['a'], ['b'], [])), {
    complete: false, missing: 2, failed: 0, idle: false,
  });
  // A failed tile leaves the view incomplete but idle: nothing more will come.
  assert.deepEqual(viewProgress(needed, state(['a', 'b'], [], ['c'])), {
    complete: false, missing: 1, failed: 1, idle: true,
  });
});

test('the cache evicts the least recently used, never pinned or protected entries', () => {
  const evicted = [];
  const cache = new LruCache(3, {
    onEvict: (key, value) => evicted.push([key, value]),
    pinned: (key) => key.startsWith('4/'),
  });
  cache.set('4/0/0', 'coarse');
  cache.set('1/0/0', 'a');
  cache.set('1/1/0', 'b');
  assert.equal(cache.get('1/0/0'), 'a'); // now 1/1/0 is the least recently used non-pinned
  cache.set('1/2/0', 'c');
  assert.deepEqual(evicted, [['1/1/0', 'b']]);
  assert.ok(cache.has('4/0/0'));
  // Protected keys (the current frame's) survive even above capacity.
  cache.set('1/3/0', 'd', new Set(['1/0/0', '1/2/0']));
  assert.equal(cache.size, 4);
  assert.deepEqual(evicted.map(([key]) => key), ['1/1/0']);
  cache.trim();
  assert.equal(cache.size, 3);
  assert.deepEqual(evicted.map(([key]) => key), ['1/1/0', '1/0/0']);
  assert.equal(cache.evictions, 2);
  // peek does not refresh: 1/2/0 is evicted next.
  cache.peek('1/2/0');
  cache.set('1/4/0', 'e');
  assert.deepEqual(evicted.at(-1), ['1/2/0', 'c']);
  // Replacing a value frees the old one.
  cache.set('1/4/0', 'e2');
  assert.deepEqual(evicted.at(-1), ['1/4/0', 'e']);
  cache.clear();
  assert.equal(cache.size, 0);
  assert.throws(() => new LruCache(0), RangeError);
});

test('tile URLs: stored payload for browser codecs, a PNG transcode otherwise', () => {
  const png = { index: 2, tile_content_type: 'image/png' };
  const zstd = { index: 0, tile_content_type: 'application/octet-stream' };
  assert.equal(tileUrl('earth', png, 3, 4, 5), 'earth/2/3/4/5');
  assert.equal(tileUrl('earth', png, 3, 4, 5, true), 'earth/2/3/4/5?format=png');
  assert.equal(tileUrl('a b', zstd, 0, 1, 2), 'a%20b/0/0/1/2?format=png');
});

test('tile URLs of bc1 and bc7 archives: the stored blocks where the GPU samples them', () => {
  const bc1 = { index: 0, codec: 'bc1', tile_content_type: 'application/octet-stream', sample_type: 'u8', payload_side: 260 };
  const bc7 = { ...bc1, codec: 'bc7' };
  const both = new Set(['bc1', 'bc7']);
  assert.equal(blockCodec(bc1, both), 'bc1');
  assert.equal(blockCodec(bc7, new Set(['bc7'])), 'bc7');
  assert.equal(blockCodec(bc7, new Set(['bc1'])), null);
  assert.equal(blockCodec(bc1, null), null);
  // Without the padded side from info.json the texture cannot be sized: PNG.
  assert.equal(blockCodec({ ...bc1, payload_side: undefined }, both), null);
  assert.equal(blockCodec({ ...bc1, payload_side: 258 }, both), null);
  assert.equal(blockCodec({ ...bc1, codec: 'zstd' }, both), null);
  assert.equal(blockCodec({ ...bc1, codec: 'toString' }, both), null);
  assert.equal(tileUrl('e', bc1, 1, 2, 3, false, null, both), 'e/0/1/2/3');
  assert.equal(tileUrl('e', bc1, 1, 2, 3, true, null, both), 'e/0/1/2/3?format=png');
  assert.equal(tileUrl('e', bc1, 1, 2, 3, false, null, new Set()), 'e/0/1/2/3?format=png');
  assert.equal(tileUrl('e', bc1, 1, 2, 3), 'e/0/1/2/3?format=png');
  // 260 px: 65 x 65 blocks of 8 (bc1) or 16 (bc7) bytes.
  assert.equal(blockPayloadBytes('bc1', 260), 65 * 65 * 8);
  assert.equal(blockPayloadBytes('bc7', 128), 32 * 32 * 16);
});

test('tile URLs of wide images: always the 8-bit transcode, with the display window', () => {
  const u16 = { index: 1, tile_content_type: 'application/octet-stream', sample_type: 'u16' };
  const u8png = { index: 0, tile_content_type: 'image/png', sample_type: 'u8' };
  assert.equal(tileUrl('dem', u16, 2, 3, 4), 'dem/1/2/3/4?format=png');
  assert.equal(
    tileUrl('dem', u16, 2, 3, 4, false, { low: -5.5, high: 1200, gamma: 0.5 }),
    'dem/1/2/3/4?format=png&window=-5.5,1200&gamma=0.5',
  );
  assert.equal(tileUrl('rgb', u8png, 0, 0, 0, false, { low: 0, high: 1, gamma: 1 }), 'rgb/0/0/0/0');
  assert.throws(() => windowQuery({ low: 5, high: 5, gamma: 1 }), RangeError);
  assert.throws(() => windowQuery({ low: 0, high: 5, gamma: 0 }), RangeError);
  assert.throws(() => windowQuery({ low: Number.NaN, high: 5, gamma: 1 }), RangeError);
});

test('the byte rate counts the last window only', () => {
  const meter = new RateMeter(1000);
  meter.add(1000, 0);
  meter.add(3000, 500);
  assert.equal(meter.rate(900), 4000);
  assert.equal(meter.rate(1200), 3000);
  assert.equal(meter.rate(2000), 0);
});

test('a uniform tile colour expands its channels as every renderer does', () => {
  // uniform_rgba little-endian: bytes r=0x11 g=0x22 b=0x33 a=0x44 print as 44332211.
  assert.deepEqual(uniformColour('11223344', 4), [0x11, 0x22, 0x33, 0x44]);
  assert.deepEqual(uniformColour('11223300', 3), [0x11, 0x22, 0x33, 255]);
  assert.deepEqual(uniformColour('11800000', 2), [0x11, 0x11, 0x11, 0x80]);
  assert.deepEqual(uniformColour('ff000000', 1), [255, 255, 255, 255]);
  assert.equal(uniformColour('xyz', 3), null);
  assert.equal(uniformColour(null, 3), null);
  assert.equal(uniformColour('123456789', 3), null);
});
