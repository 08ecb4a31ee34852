// `tessera export` read back by an independent reader: the pmtiles npm package (protomaps'
// own) opens the PMTiles file, with and without leaf directories, and every tile it returns
// equals what `tessera serve` sends for the same XYZ tile; the Deep Zoom folder holds, file
// for file, what the server's Deep Zoom endpoint sends. Tiles outside the image are absent.
import assert from 'node:assert/strict';
import fs from 'node:fs';
import path from 'node:path';
import { test } from 'node:test';

import { buildArchive, startServe, tempDir, tessera, webDir } from './lib/harness.mjs';

// From web/node_modules (npm ci --prefix web), as the browser tests load their libraries.
const { PMTiles } = await import(path.join(webDir, 'node_modules/pmtiles/dist/esm/index.js'));

class FileSource {
  constructor(file) {
    this.file = file;
    this.fd = fs.openSync(file, 'r');
  }
  getKey() {
    return this.file;
  }
  async getBytes(offset, length) {
    const buffer = Buffer.alloc(length);
    const read = fs.readSync(this.fd, buffer, 0, length, offset);
    return { data: buffer.buffer.slice(buffer.byteOffset, buffer.byteOffset + read) };
  }
  close() {
    fs.closeSync(this.fd);
  }
}

async function fetchBytes(url) {
  const response = await fetch(url);
  assert.equal(response.status, 200, url);
  return Buffer.from(await response.arrayBuffer());
}

// The XYZ grid of a W x H image: zoom z shows it scaled by 2^(maxZoom - z) in 256-px tiles.
function xyzTiles(width, height, maxZoom) {
  const tiles = [];
  for (let z = 0; z <= maxZoom; ++z) {
    const scale = 2 ** (maxZoom - z);
    const cols = Math.ceil(Math.ceil(width / scale) / 256);
    const rows = Math.ceil(Math.ceil(height / scale) / 256);
    for (let y = 0; y < rows; ++y) for (let x = 0; x < cols; ++x) tiles.push({ z, x, y, cols, rows });
  }
  return tiles;
}

async function checkPmtiles(file, server, name, ext, expect) {
  const source = new FileSource(file);
  try {
    const archive = new PMTiles(source);
    const header = await archive.getHeader();
    assert.equal(header.specVersion, 3);
    assert.equal(header.tileType, expect.tileType);
    assert.equal(header.maxZoom, expect.maxZoom);
    assert.equal(header.minZoom, 0);
    assert.equal(header.rootDirectoryOffset + header.rootDirectoryLength <= 16384, true);
    assert.equal(header.leafDirectoryLength > 0, expect.leaves, 'leaf directories');
    const tiles = xyzTiles(expect.width, expect.height, expect.maxZoom);
    assert.equal(header.numAddressedTiles, tiles.length);
    for (const { z, x, y } of tiles) {
      const tile = await archive.getZxy(z, x, y);
      assert.ok(tile, `tile ${z}/${x}/${y} missing`);
      const served = await fetchBytes(`${server.url}/${name}/0/xyz/${z}/${x}/${y}.${ext}`);
      assert.ok(Buffer.from(tile.data).equals(served), `tile ${z}/${x}/${y} differs from the server's`);
    }
    // Outside the image: one column and one row past the finest grid, where the zoom has them.
    const last = tiles[tiles.length - 1];
    const side = 2 ** last.z;
    if (last.cols < side) assert.equal(await archive.getZxy(last.z, last.cols, 0), undefined);
    if (last.rows < side) assert.equal(await archive.getZxy(last.z, 0, last.rows), undefined);
    assert.ok(last.cols < side || last.rows < side, 'the image leaves part of the grid empty');
    const metadata = await archive.getMetadata();
    assert.equal(metadata.tessera.width, expect.width);
    assert.equal(metadata.format, ext);
  } finally {
    source.close();
  }
}

test('PMTiles and Deep Zoom exports read back tile for tile', { timeout: 240000 }, async () => {
  const dir = tempDir('export');
  const jpeg = await buildArchive('synthetic:1500x1100:2:3', path.join(dir, 'rgb.tess'), '--codec', 'jpeg');
  const png = await buildArchive('synthetic:700x900:3:4', path.join(dir, 'rgba.tess'), '--codec', 'webp');
  const server = await startServe([jpeg, png]);
  try {
    const cases = [
      { name: 'rgb', ext: 'jpg', tileType: 3, width: 1500, height: 1100, maxZoom: 3 },
      { name: 'rgba', ext: 'png', tileType: 2, width: 700, height: 900, maxZoom: 2 },
    ];
    for (const c of cases) {
      const archive = path.join(dir, `${c.name}.tess`);
      const plain = path.join(dir, `${c.name}.pmtiles`);
      await tessera('export', archive, '--to', 'pmtiles', plain, '--quiet');
      await checkPmtiles(plain, server, c.name, c.ext, { ...c, leaves: false });
      const leafy = path.join(dir, `${c.name}-leaves.pmtiles`);
      await tessera('export', archive, '--to', 'pmtiles', leafy, '--quiet', '--pmtiles-leaf-entries', '3');
      await checkPmtiles(leafy, server, c.name, c.ext, { ...c, leaves: true });

      const dzi = path.join(dir, `${c.name}.dzi`);
      await tessera('export', archive, '--to', 'dzi', dzi, '--quiet');
      assert.equal(fs.readFileSync(dzi, 'utf8'), (await fetchBytes(`${server.url}/${c.name}/0.dzi`)).toString());
      const files = path.join(dir, `${c.name}_files`);
      let count = 0;
      for (const level of fs.readdirSync(files)) {
        for (const tile of fs.readdirSync(path.join(files, level))) {
          const served = await fetchBytes(`${server.url}/${c.name}/0_files/${level}/${tile}`);
          assert.ok(fs.readFileSync(path.join(files, level, tile)).equals(served), `${level}/${tile}`);
          assert.ok(tile.endsWith(`.${c.ext}`));
          ++count;
        }
      }
      assert.ok(count > 10, `${count} Deep Zoom tiles`);
      assert.deepEqual(fs.readdirSync(dir).filter((f) => f.includes('.partial-')), []);
    }
  } finally {
    await server.stop();
    fs.rmSync(dir, { recursive: true, force: true });
  }
});
