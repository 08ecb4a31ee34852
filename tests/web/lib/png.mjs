// Minimal PNG reading and picture comparison for the browser tests: 8-bit greyscale, RGB and
// RGBA (with or without alpha), non-interlaced, as Chromium's screenshots and `tessera render`
// write them. Anything else is refused by name, never misread.
import fs from 'node:fs';
import zlib from 'node:zlib';

/** Decodes a PNG file to {width, height, rgba: Uint8Array}. */
export function readPng(file) {
  const bytes = fs.readFileSync(file);
  const signature = [137, 80, 78, 71, 13, 10, 26, 10];
  if (!signature.every((b, i) => bytes[i] === b)) throw new Error(`${file}: not a PNG`);
  let offset = 8;
  let width = 0;
  let height = 0;
  let colourType = -1;
  const idat = [];
  while (offset < bytes.length) {
    const length = bytes.readUInt32BE(offset);
    const type = bytes.toString('latin1', offset + 4, offset + 8);
    const data = bytes.subarray(offset + 8, offset + 8 + length);
    if (type === 'IHDR') {
      width = data.readUInt32BE(0);
      height = data.readUInt32BE(4);
      const depth = data[8];
      colourType = data[9];
      if (depth !== 8 || data[12] !== 0 || ![0, 2, 4, 6].includes(colourType))
        throw new Error(`${file}: PNG depth ${depth}, colour type ${colourType}, interlace ${data[12]} not supported`);
    } else if (type === 'IDAT') {
      idat.push(data);
    } else if (type === 'IEND') {
      break;
    }
    offset += 12 + length;
  }
  const channels = { 0: 1, 2: 3, 4: 2, 6: 4 }[colourType];
  const raw = zlib.inflateSync(Buffer.concat(idat));
  const stride = width * channels;
  if (raw.length !== height * (stride + 1)) throw new Error(`${file}: PNG data has the wrong size`);
  const pixels = new Uint8Array(height * stride);
  for (let y = 0; y < height; y += 1) {
    const filter = raw[y * (stride + 1)];
    const line = raw.subarray(y * (stride + 1) + 1, (y + 1) * (stride + 1));
    const out = pixels.subarray(y * stride, (y + 1) * stride);
    const prev = y > 0 ? pixels.subarray((y - 1) * stride, y * stride) : new Uint8Array(stride);
    for (let i = 0; i < stride; i += 1) {
      const a = i >= channels ? out[i - channels] : 0;
      const b = prev[i];
      const c = i >= channels ? prev[i - channels] : 0;
      let predicted = 0;
      if (filter === 1) predicted = a;
      else if (filter === 2) predicted = b;
      else if (filter === 3) predicted = (a + b) >> 1;
      else if (filter === 4) {
        const p = a + b - c;
        const pa = Math.abs(p - a);
        const pb = Math.abs(p - b);
        const pc = Math.abs(p - c);
        predicted = pa <= pb && pa <= pc ? a : pb <= pc ? b : c;
      } else if (filter !== 0) throw new Error(`${file}: PNG filter ${filter} unknown`);
      out[i] = (line[i] + predicted) & 255;
    }
  }
  const rgba = new Uint8Array(width * height * 4);
  for (let p = 0; p < width * height; p += 1) {
    const s = pixels.subarray(p * channels, p * channels + channels);
    const grey = channels <= 2;
    rgba[p * 4] = s[0];
    rgba[p * 4 + 1] = grey ? s[0] : s[1];
    rgba[p * 4 + 2] = grey ? s[0] : s[2];
    rgba[p * 4 + 3] = channels === 2 ? s[1] : channels === 4 ? s[3] : 255;
  }
  return { width, height, rgba };
}

/**
 * The picture as the page shows it over an opaque background colour [r, g, b] (straight alpha,
 * as the viewer's canvas and the reference hold it), rounded to 8 bits.
 */
export function composite(picture, background) {
  const rgba = new Uint8Array(picture.rgba.length);
  for (let i = 0; i < rgba.length; i += 4) {
    const a = picture.rgba[i + 3] / 255;
    for (let c = 0; c < 3; c += 1)
      rgba[i + c] = Math.round(picture.rgba[i + c] * a + background[c] * (1 - a));
    rgba[i + 3] = 255;
  }
  return { width: picture.width, height: picture.height, rgba };
}

/**
 * PSNR over the RGB channels (both pictures opaque), the largest channel difference and the
 * share of pixels whose largest channel difference exceeds `tolerance`.
 */
export function compare(a, b, tolerance = 8) {
  if (a.width !== b.width || a.height !== b.height)
    throw new Error(`pictures differ in size: ${a.width}x${a.height} and ${b.width}x${b.height}`);
  let sum = 0;
  let maxAbs = 0;
  let over = 0;
  for (let i = 0; i < a.rgba.length; i += 4) {
    let pixelMax = 0;
    for (let c = 0; c < 3; c += 1) {
      const d = Math.abs(a.rgba[i + c] - b.rgba[i + c]);
      sum += d * d;
      pixelMax = Math.max(pixelMax, d);
    }
    maxAbs = Math.max(maxAbs, pixelMax);
    if (pixelMax > tolerance) over += 1;
  }
  const mse = sum / ((a.rgba.length / 4) * 3);
  return {
    psnr: mse === 0 ? Infinity : 10 * Math.log10((255 * 255) / mse),
    maxAbs,
    overShare: over / (a.rgba.length / 4),
  };
}

const CRC_TABLE = (() => {
  const table = new Uint32Array(256);
  for (let n = 0; n < 256; n += 1) {
    let c = n;
    for (let k = 0; k < 8; k += 1) c = c & 1 ? 0xedb88320 ^ (c >>> 1) : c >>> 1;
    table[n] = c >>> 0;
  }
  return table;
})();

function crc32(bytes) {
  let c = 0xffffffff;
  for (const b of bytes) c = CRC_TABLE[(c ^ b) & 255] ^ (c >>> 8);
  return (c ^ 0xffffffff) >>> 0;
}

function chunk(type, data) {
  const out = Buffer.alloc(12 + data.length);
  out.writeUInt32BE(data.length, 0);
  out.write(type, 4, 'latin1');
  data.copy(out, 8);
  out.writeUInt32BE(crc32(out.subarray(4, 8 + data.length)), 8 + data.length);
  return out;
}

/** Writes an 8-bit RGB PNG of `rgb` (width * height * 3 bytes), for test inputs. */
export function writePngRgb(file, width, height, rgb) {
  const header = Buffer.alloc(13);
  header.writeUInt32BE(width, 0);
  header.writeUInt32BE(height, 4);
  header[8] = 8; // bit depth
  header[9] = 2; // RGB
  const raw = Buffer.alloc(height * (width * 3 + 1));
  for (let y = 0; y < height; y += 1)
    Buffer.from(rgb.buffer, rgb.byteOffset + y * width * 3, width * 3).copy(raw, y * (width * 3 + 1) + 1);
  fs.writeFileSync(
    file,
    Buffer.concat([
      Buffer.from([137, 80, 78, 71, 13, 10, 26, 10]),
      chunk('IHDR', header),
      chunk('IDAT', zlib.deflateSync(raw)),
      chunk('IEND', Buffer.alloc(0)),
    ]),
  );
}
