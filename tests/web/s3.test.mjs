// Archives in S3-compatible object stores (s3:// URLs, docs/remote.md "Object stores"):
// - s3rver (an S3 implementation in Node.js, from web/node_modules) holds an archive that
//   `tessera verify` and `tessera extract` read through s3://, with the same pixels as the
//   local file, and `tessera serve` serves from it; a missing key and a URL without a key fail
//   naming the URL;
// - a store written here that checks AWS Signature Version 4 as AWS documents it (s3rver does
//   not check V4 signatures): requests signed with the right secret and a session token are
//   served, a wrong secret is refused and the error names the access key id, never the secret.
import assert from 'node:assert/strict';
import { execFile } from 'node:child_process';
import crypto from 'node:crypto';
import fs from 'node:fs';
import http from 'node:http';
import path from 'node:path';
import { test } from 'node:test';
import { promisify } from 'node:util';

import { buildArchive, cli, startServe, tempDir, tessera, webDir } from './lib/harness.mjs';

const run = promisify(execFile);
const { default: S3rver } = await import(path.join(webDir, 'node_modules/s3rver/lib/s3rver.js'));

/** Runs the CLI with `env` added; resolves to {code, stdout, stderr}, never throws. */
async function tesseraWith(env, ...args) {
  try {
    const { stdout, stderr } = await run(cli(), args, { env: { ...cleanEnv(), ...env } });
    return { code: 0, stdout, stderr };
  } catch (error) {
    return { code: error.code, stdout: error.stdout, stderr: error.stderr };
  }
}

// The machine's own AWS settings must not leak into the test.
function cleanEnv() {
  const env = { ...process.env, HOME: '/nonexistent' };
  for (const name of Object.keys(env)) if (name.startsWith('AWS_')) delete env[name];
  return env;
}

const sha256 = (data) => crypto.createHash('sha256').update(data).digest('hex');
const hmac = (key, data) => crypto.createHmac('sha256', key).update(data).digest();

/**
 * Checks the Authorization header of a GET as AWS documents Signature Version 4 for S3
 * (canonical request, string to sign, derived key); returns a reason or null when valid.
 */
function sigV4Problem(request, secrets) {
  const header = request.headers.authorization || '';
  const parsed = /^AWS4-HMAC-SHA256 Credential=([^/]+)\/(\d{8})\/([^/]+)\/s3\/aws4_request, ?SignedHeaders=([a-z0-9;-]+), ?Signature=([0-9a-f]{64})$/.exec(header);
  if (!parsed) return `malformed Authorization: ${header}`;
  const [, keyId, date, region, signedHeaders, signature] = parsed;
  if (!(keyId in secrets)) return `unknown access key ${keyId}`;
  const names = signedHeaders.split(';');
  for (const required of ['host', 'x-amz-date', 'x-amz-content-sha256'])
    if (!names.includes(required)) return `${required} not signed`;
  const amzDate = request.headers['x-amz-date'];
  if (!amzDate || amzDate.slice(0, 8) !== date) return 'x-amz-date does not match the scope';
  const canonicalHeaders = names
    .map((name) => `${name}:${String(request.headers[name] ?? '').trim().replace(/\s+/g, ' ')}\n`)
    .join('');
  const [pathPart, query = ''] = request.url.split('?');
  const canonicalRequest = [
    request.method, pathPart, query, canonicalHeaders, signedHeaders,
    request.headers['x-amz-content-sha256'],
  ].join('\n');
  const scope = `${date}/${region}/s3/aws4_request`;
  const toSign = ['AWS4-HMAC-SHA256', amzDate, scope, sha256(canonicalRequest)].join('\n');
  let key = hmac(`AWS4${secrets[keyId]}`, date);
  for (const part of [region, 's3', 'aws4_request']) key = hmac(key, part);
  const expected = hmac(key, toSign).toString('hex');
  return expected === signature ? null : 'signature does not match';
}

/** A store serving one object with byte ranges to requests signed with `secrets`. */
function startCheckingStore(objectPath, file, secrets, seen) {
  const bytes = fs.readFileSync(file);
  const server = http.createServer((request, response) => {
    const problem = sigV4Problem(request, secrets);
    seen.push({ problem, token: request.headers['x-amz-security-token'] });
    if (problem) {
      response.writeHead(403, { 'Content-Type': 'application/xml' });
      response.end('<Error><Code>SignatureDoesNotMatch</Code></Error>');
      return;
    }
    if (request.url !== objectPath) {
      response.writeHead(404);
      response.end();
      return;
    }
    const range = /^bytes=(\d+)-(\d+)$/.exec(request.headers.range || '');
    const first = range ? Number(range[1]) : 0;
    const last = range ? Math.min(Number(range[2]), bytes.length - 1) : bytes.length - 1;
    response.writeHead(range ? 206 : 200, {
      ETag: '"v1"',
      'Content-Length': String(last - first + 1),
      ...(range ? { 'Content-Range': `bytes ${first}-${last}/${bytes.length}` } : {}),
    });
    response.end(bytes.subarray(first, last + 1));
  });
  return new Promise((resolve) => server.listen(0, '127.0.0.1', () => resolve(server)));
}

test('an archive in s3rver reads through s3:// as the local file does', async () => {
  const dir = tempDir('tessera-s3-');
  const archive = await buildArchive('synthetic:700x500', path.join(dir, 'a.tess'), '--tile', '128');
  const store = new S3rver({
    port: 0, address: '127.0.0.1', silent: true, directory: path.join(dir, 'store'),
    configureBuckets: [{ name: 'tiles' }],
  });
  const { port } = await store.run();
  try {
    const put = await fetch(`http://127.0.0.1:${port}/tiles/maps/a.tess`, {
      method: 'PUT', body: fs.readFileSync(archive),
    });
    assert.equal(put.status, 200);
    const env = {
      AWS_ENDPOINT_URL: `http://127.0.0.1:${port}`, AWS_ACCESS_KEY_ID: 'S3RVER',
      AWS_SECRET_ACCESS_KEY: 'S3RVER', AWS_REGION: 'eu-west-1',
    };
    const verified = await tesseraWith(env, 'verify', 's3://tiles/maps/a.tess', '-q');
    assert.equal(verified.code, 0, verified.stderr);

    const remote = path.join(dir, 'remote.png');
    const local = path.join(dir, 'local.png');
    const extracted = await tesseraWith(env, 'extract', 's3://tiles/maps/a.tess', '--level', '1', '--rect', '0,0,350,250', '-o', remote);
    assert.equal(extracted.code, 0, extracted.stderr);
    await tessera('extract', archive, '--level', '1', '--rect', '0,0,350,250', '-o', local);
    assert.deepEqual(fs.readFileSync(remote), fs.readFileSync(local));

    // `tessera serve` serves the object: its bytes by range, and the archive's endpoints.
    const saved = { ...process.env };
    Object.assign(process.env, env);
    let server;
    try {
      server = await startServe(['s3://tiles/maps/a.tess']);
    } finally {
      for (const name of Object.keys(env)) delete process.env[name];
      Object.assign(process.env, saved);
    }
    try {
      const range = await fetch(`${server.url}/a.tess`, { headers: { Range: 'bytes=100-4195' } });
      assert.equal(range.status, 206);
      assert.deepEqual(Buffer.from(await range.arrayBuffer()), fs.readFileSync(archive).subarray(100, 4196));
      const info = await fetch(`${server.url}/a/info.json`);
      assert.equal(info.status, 200);
      assert.equal((await info.json()).images[0].width, 700);
    } finally {
      await server.stop();
    }

    const missing = await tesseraWith(env, 'info', 's3://tiles/maps/none.tess');
    assert.notEqual(missing.code, 0);
    assert.match(missing.stderr, /s3:\/\/tiles\/maps\/none\.tess/);
    assert.match(missing.stderr, /404|not found/i);

    const noKey = await tesseraWith(env, 'info', 's3://tiles');
    assert.notEqual(noKey.code, 0);
    assert.match(noKey.stderr, /needs a bucket and a key/);
  } finally {
    await store.close();
    fs.rmSync(dir, { recursive: true, force: true });
  }
});

test('requests are signed with Signature Version 4; a wrong secret is refused and not shown', async () => {
  const dir = tempDir('tessera-s3-sig-');
  const archive = await buildArchive('synthetic:300x200', path.join(dir, 'b.tess'), '--tile', '64');
  const seen = [];
  const secret = 'wJalrXUtnFEMI/K7MDENG/bPxRfiCYEXAMPLEKEY';
  const server = await startCheckingStore('/bucket/dir/b%20c.tess', archive, { AKIDEXAMPLE: secret }, seen);
  const endpoint = `http://127.0.0.1:${server.address().port}`;
  try {
    const good = await tesseraWith(
      { AWS_ENDPOINT_URL_S3: endpoint, AWS_ACCESS_KEY_ID: 'AKIDEXAMPLE', AWS_SECRET_ACCESS_KEY: secret,
        AWS_SESSION_TOKEN: 'session-token-1', AWS_DEFAULT_REGION: 'ap-south-1' },
      'verify', 's3://bucket/dir/b c.tess', '-q');
    assert.equal(good.code, 0, `${good.stderr} ${JSON.stringify(seen.slice(0, 3))}`);
    assert.ok(seen.length > 0);
    assert.ok(seen.every((request) => request.problem === null && request.token === 'session-token-1'));

    // The credentials file's profile, when the environment has no key.
    fs.writeFileSync(path.join(dir, 'credentials'),
      `[default]\naws_access_key_id = WRONG\naws_secret_access_key = x\n\n[work]\naws_access_key_id = AKIDEXAMPLE\naws_secret_access_key = ${secret}\n`);
    const profile = await tesseraWith(
      { AWS_ENDPOINT_URL: endpoint, AWS_SHARED_CREDENTIALS_FILE: path.join(dir, 'credentials'),
        AWS_PROFILE: 'work' },
      'info', 's3://bucket/dir/b c.tess', '--no-levels');
    assert.equal(profile.code, 0, profile.stderr);

    const wrongSecret = 'not-the-secret-7f3a';
    const bad = await tesseraWith(
      { AWS_ENDPOINT_URL: endpoint, AWS_ACCESS_KEY_ID: 'AKIDEXAMPLE', AWS_SECRET_ACCESS_KEY: wrongSecret },
      'info', 's3://bucket/dir/b c.tess');
    assert.notEqual(bad.code, 0);
    assert.match(bad.stderr, /403/);
    assert.match(bad.stderr, /AKIDEXAMPLE/);
    assert.ok(!bad.stderr.includes(wrongSecret) && !bad.stdout.includes(wrongSecret));
  } finally {
    server.close();
    fs.rmSync(dir, { recursive: true, force: true });
  }
});
