// Shared pieces of the browser tests: the paths ctest passes, archives built and pictures
// rendered by the real `tessera` binary, `tessera serve` on an ephemeral port, a static file
// server for the interop pages, and headless Chromium through playwright-core.
import { execFile, spawn } from 'node:child_process';
import fs from 'node:fs';
import http from 'node:http';
import { createRequire } from 'node:module';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { promisify } from 'node:util';

import { composite, compare, readPng } from './png.mjs';

const run = promisify(execFile);
const here = path.dirname(fileURLToPath(import.meta.url));
export const repoRoot = path.resolve(here, '../../..');
export const webDir = path.join(repoRoot, 'web');

function required(name) {
  const value = process.env[name];
  if (!value) throw new Error(`${name} is not set: run these tests through ctest (label web)`);
  return value;
}

export const cli = () => required('TESSERA_CLI');
export const chromiumPath = () => process.env.TESSERA_CHROMIUM || '/usr/bin/chromium';

/** playwright-core from web/node_modules, with a clear error when `npm ci` has not run. */
export function playwright() {
  const require = createRequire(path.join(webDir, 'package.json'));
  try {
    return require('playwright-core');
  } catch (error) {
    throw new Error(`playwright-core is not installed in ${webDir}: run 'npm ci --prefix web' (${error.message})`);
  }
}

export function tempDir(prefix) {
  return fs.mkdtempSync(path.join(os.tmpdir(), `tessera-web-${prefix}-`));
}

export async function tessera(...args) {
  try {
    return (await run(cli(), args, { maxBuffer: 1 << 24 })).stdout;
  } catch (error) {
    throw new Error(`tessera ${args.join(' ')} failed: ${error.stderr || error.message}`);
  }
}

/** Builds `source` into `file` with the given extra options. */
export async function buildArchive(source, file, ...options) {
  await tessera('build', source, '-o', file, '--quiet', ...options);
  return file;
}

/**
 * The CPU reference picture of an orthographic view ({cx, cy, tpp, rotation (radians), width,
 * height}) composited over `background`, as a page with that background shows it.
 */
export async function referencePicture(archive, view, background, dir, image = 0) {
  const out = path.join(dir, `reference-${Date.now()}-${Math.random().toString(36).slice(2)}.png`);
  await tessera(
    'render', archive, '--image', String(image),
    '--centre', `${view.cx},${view.cy}`, '--texels-per-pixel', String(view.tpp),
    '--viewport', `${view.width}x${view.height}`,
    '--rotation', String(((view.rotation || 0) * 180) / Math.PI), '-o', out,
  );
  const picture = composite(readPng(out), background);
  fs.rmSync(out);
  return picture;
}

/** Decodes a screenshot (PNG bytes) into an opaque picture. */
export function screenshotPicture(bytes, dir) {
  const file = path.join(dir, `shot-${Date.now()}-${Math.random().toString(36).slice(2)}.png`);
  fs.writeFileSync(file, bytes);
  const picture = composite(readPng(file), [0, 0, 0]);
  fs.rmSync(file);
  return picture;
}

export { compare };

/**
 * Starts `tessera serve PATH... --port 0 ARGS` and resolves when it prints its "listening on
 * URL" line (no sleeping, no fixed port). `stop()` ends it with SIGTERM and waits.
 */
export function startServe(paths, ...args) {
  return new Promise((resolve, reject) => {
    const child = spawn(cli(), ['serve', ...paths, '--port', '0', '--bind', '127.0.0.1', ...args], {
      stdio: ['ignore', 'pipe', 'pipe'],
    });
    let out = '';
    let err = '';
    const exited = new Promise((done) => child.on('exit', (code, signal) => done({ code, signal })));
    child.stderr.on('data', (d) => (err += d));
    child.stdout.on('data', (d) => {
      out += d;
      const match = /listening on (http:\/\/\S+)/.exec(out);
      if (match && !child.resolved) {
        child.resolved = true;
        resolve({
          url: match[1].replace(/\/$/, ''),
          stop: async () => {
            child.kill('SIGTERM');
            return exited;
          },
          log: () => err,
        });
      }
    });
    child.on('error', reject);
    exited.then(({ code, signal }) => {
      if (!child.resolved) reject(new Error(`tessera serve exited (${code ?? signal}) before listening: ${err}`));
    });
  });
}

const TYPES = { '.html': 'text/html', '.js': 'text/javascript', '.mjs': 'text/javascript', '.css': 'text/css', '.png': 'image/png', '.svg': 'image/svg+xml', '.map': 'application/json' };

/**
 * A static server on 127.0.0.1 port 0 for `roots` ({'/prefix/': dir}): the interop pages and
 * the OpenSeadragon and Leaflet builds from web/node_modules, so nothing comes from a CDN.
 */
export function startStatic(roots) {
  const server = http.createServer((req, res) => {
    const url = new URL(req.url, 'http://x');
    for (const [prefix, dir] of Object.entries(roots)) {
      if (!url.pathname.startsWith(prefix)) continue;
      const file = path.resolve(dir, decodeURIComponent(url.pathname.slice(prefix.length)));
      if (!file.startsWith(path.resolve(dir) + path.sep) || !fs.existsSync(file) || !fs.statSync(file).isFile()) break;
      res.writeHead(200, { 'Content-Type': TYPES[path.extname(file)] || 'application/octet-stream' });
      fs.createReadStream(file).pipe(res);
      return;
    }
    res.writeHead(404, { 'Content-Type': 'text/plain' });
    res.end(`not found: ${url.pathname}`);
  });
  return new Promise((resolve) =>
    server.listen(0, '127.0.0.1', () =>
      resolve({
        url: `http://127.0.0.1:${server.address().port}`,
        stop: () => new Promise((done) => server.close(done)),
      }),
    ),
  );
}

/**
 * Headless Chromium (Debian's) with WebGL2 on SwiftShader, in a fresh profile. Returns
 * {context, close}. `options` go to the browser context (viewport, hasTouch, ...).
 */
export async function launchChromium(options = {}) {
  const { chromium } = playwright();
  if (!fs.existsSync(chromiumPath()))
    throw new Error(`no Chromium at ${chromiumPath()}: scripts/install-deps.sh installs Debian's chromium`);
  const profile = tempDir('profile');
  const context = await chromium.launchPersistentContext(profile, {
    executablePath: chromiumPath(),
    headless: true,
    args: [
      '--headless',
      '--no-sandbox',
      '--disable-gpu',
      '--disable-quic',
      '--no-first-run',
      '--disable-background-networking',
      '--disable-component-update',
      '--disable-sync',
      '--use-angle=swiftshader',
      '--enable-unsafe-swiftshader',
      '--force-color-profile=srgb',
    ],
    deviceScaleFactor: 1,
    ...options,
  });
  return {
    context,
    close: async () => {
      await context.close();
      fs.rmSync(profile, { recursive: true, force: true });
    },
  };
}
