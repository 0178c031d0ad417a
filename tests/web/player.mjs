// Drives Debian's chromium through web/sample/player.html, a page of someone else's that shows a
// dance with <choreo-player> (run by tests/web.rs against a real choreo server): the sample's
// server address and ids replaced by the test's, the page served by a small server of this
// script on another origin (http://127.0.0.1:PAGE_PORT, which the choreo server's cors_origins
// lists), with the api-key attribute when TOKEN is set. Checks that the element loads, plays, and keeps the dance within one motion
// frame of the song; that its camera is on the dancer after seeks across a dance that travels;
// that the song itself seeks (with a key or without one); and that a dance it cannot load is
// reported inside it.
//
//   API_URL=… JOB_ID=… SONG_ID=… PAGE_PORT=… [TOKEN=…] OUT_DIR=dir node tests/web/player.mjs
//
// Prints one JSON summary line (prefixed "summary: ") and exits 0, or prints why and exits 1.
import { chromium } from 'playwright-core';
import { createServer } from 'node:http';
import { readFileSync, mkdirSync } from 'node:fs';
import { join } from 'node:path';
import { recordMediaClock, sampleFor, checkSamples } from './clock.mjs';

const env = (name) => {
  const value = process.env[name];
  if (!value) throw new Error(`${name} is not set`);
  return value;
};
const API = env('API_URL');
const OUT = env('OUT_DIR');
const TOKEN = process.env.TOKEN;
const CHROMIUM = process.env.CHROMIUM || '/usr/bin/chromium';
const SAMPLE = new URL('../../web/sample/player.html', import.meta.url);
const PAGE = `http://127.0.0.1:${env('PAGE_PORT')}/player.html`;

function check(condition, message) {
  if (!condition) throw new Error(`check failed: ${message}`);
}
const log = (...args) => console.log(`[${new Date().toISOString().slice(11, 19)}]`, ...args);

let html = readFileSync(SAMPLE, 'utf8')
  .replaceAll('http://127.0.0.1:8080', API)
  .replaceAll('JOB_ID', env('JOB_ID'))
  .replaceAll('SONG_ID', env('SONG_ID'));
if (TOKEN) html = html.replace('<choreo-player id="player"', `<choreo-player id="player" api-key="${TOKEN}"`);
check(html.includes(`${API}/assets/choreo-player.js`), 'the sample loads the element from the server');

// The page's own server: this page at /player.html, nothing else.
const pages = createServer((req, res) => {
  if (req.url === '/player.html') res.writeHead(200, { 'content-type': 'text/html; charset=utf-8' }).end(html);
  else res.writeHead(404).end();
});
await new Promise((resolve) => pages.listen(Number(env('PAGE_PORT')), '127.0.0.1', resolve));

mkdirSync(OUT, { recursive: true });
const browser = await chromium.launch({
  executablePath: CHROMIUM,
  headless: true,
  args: ['--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run', '--disable-background-networking',
    '--disable-component-update', '--disable-sync', '--autoplay-policy=no-user-gesture-required'],
});
const summary = {};
try {
  const page = await browser.newPage({ viewport: { width: 900, height: 700 } });
  await page.addInitScript(recordMediaClock);
  const errors = [];
  page.on('pageerror', (e) => errors.push(e.message));
  page.on('console', (m) => { if (m.type() === 'error') errors.push(m.text()); });
  const requests = [];
  page.on('request', (r) => requests.push(r.url()));
  page.on('response', (r) => { if (r.status() >= 400) errors.push(`${r.status()} ${r.url()}`); });
  await page.goto(PAGE);
  const loaded = await page.evaluate(async () => {
    const p = document.getElementById('player');
    await customElements.whenDefined('choreo-player');
    await p.loaded;
    return { duration: p.duration, frames: p.renderedFrames };
  });
  check(loaded.duration > 1, `the dance loaded: ${JSON.stringify(loaded)}`);
  check(requests.some((u) => u.endsWith('/motion.glb')) && requests.some((u) => u.endsWith('/audio')), `fetched the dance and the song: ${requests}`);

  // Play from the start: in every sample the pose is the song's clock as read in its frame, and
  // within a motion frame of the live clock (clock.mjs).
  await page.evaluate(() => document.getElementById('player').play());
  await page.waitForFunction(() => document.getElementById('player').audioTime > 0.3, null, { timeout: 20_000 });
  const samples = await sampleFor(page, 'element', 3);
  summary.sync = checkSamples(samples, 'playing', check);
  log('sync', JSON.stringify(summary.sync));
  const advanced = samples[samples.length - 1].audio - samples[0].audio;
  check(advanced > 1, `the song played ${advanced} s`);

  // Paused and sought: the pose drawn is the one at the new time; the dancer moved.
  await page.evaluate(() => document.getElementById('player').pause());
  const before = await page.evaluate(() => document.getElementById('player').joint('body_centre'));
  await page.evaluate(() => document.getElementById('player').seek(0.2));
  await page.waitForFunction(() => Math.abs(document.getElementById('player').animationTime - 0.2) < 1e-3, null, { timeout: 5_000 });
  const after = await page.evaluate(() => document.getElementById('player').joint('body_centre'));
  check(before && after && Math.hypot(...before.map((v, i) => v - after[i])) > 1e-4, `seeking moved the dancer: ${before} → ${after}`);
  // The page's own clock line reads the element's contract.
  await page.waitForFunction(() => /dance 0\.20 s/.test(document.getElementById('clock').textContent), null, { timeout: 5_000 });
  // The camera follows the dancer: after each seek, wherever the dance has travelled, the body
  // centre is drawn near the middle of the view (NDC 0 is the middle, ±1 the edges).
  const follow = { worst_off_centre: 0, travelled_m: 0, seeks: [] };
  let start = null;
  for (const t of [0.1, 2.4, 4.7, 0.1, 4.7]) {
    await page.evaluate((s) => document.getElementById('player').seek(s), t);
    await page.waitForFunction((s) => Math.abs(document.getElementById('player').animationTime - s) < 1e-3, t, { timeout: 5_000 });
    const at = await page.evaluate(() => {
      const p = document.getElementById('player');
      return { ndc: p.onScreen('body_centre'), world: p.joint('body_centre') };
    });
    check(at.ndc && at.world, `the body centre is drawn: ${JSON.stringify(at)}`);
    start ??= at.world;
    follow.travelled_m = Math.max(follow.travelled_m, Math.hypot(at.world[0] - start[0], at.world[2] - start[2]));
    follow.worst_off_centre = Math.max(follow.worst_off_centre, Math.abs(at.ndc[0]), Math.abs(at.ndc[1]));
    follow.seeks.push({ t, ndc: at.ndc.map((v) => +v.toFixed(3)), x: +at.world[0].toFixed(2) });
  }
  summary.follow = follow;
  log('follow', JSON.stringify(follow));

  // The song seeks too and plays on from there: with a key it is a blob; without, the <audio>
  // reads the server's URL, which must answer Range requests for Chromium to seek in it (a
  // song it cannot seek plays again from 0).
  await page.evaluate(() => document.getElementById('player').seek(3.0));
  await page.evaluate(() => document.getElementById('player').play());
  await page.waitForTimeout(400);
  const heard = await page.evaluate(() => {
    const p = document.getElementById('player');
    const t = p.audioTime;
    p.pause();
    return t;
  });
  summary.audio_seek = { to: 3.0, heard: +heard.toFixed(3), keyed: Boolean(TOKEN) };
  log('audio seek', JSON.stringify(summary.audio_seek));
  check(heard >= 2.95 && heard < 4.0, `the song plays on from 3.0 s, not from its start: ${heard}`);
  const shot = join(OUT, 'choreo-player.png');
  await page.screenshot({ path: shot });
  summary.screenshot = shot;
  check(errors.length === 0, `no errors on the page: ${errors}`);

  // A dance that cannot be loaded says so inside the element and fires choreo-error: a missing
  // job (404 with its problem's detail), and a server that does not answer (the hint names CORS).
  summary.errors = await page.evaluate(async (api) => {
    const shown = async (src) => {
      const p = document.createElement('choreo-player');
      p.setAttribute('src', src);
      const fired = new Promise((resolve) => p.addEventListener('choreo-error', (e) => resolve(String(e.detail?.message ?? e.detail)), { once: true }));
      document.body.appendChild(p);
      const message = await fired;
      const error = p.error;
      p.remove();
      return { message, error };
    };
    return [
      await shown(`${api}/v1/jobs/00000000-0000-0000-0000-000000000000/motion.glb`),
      await shown('http://127.0.0.1:9/motion.glb'),
    ];
  }, API);
  log('errors', JSON.stringify(summary.errors));
  check(/HTTP 40[14]/.test(summary.errors[0].error ?? ''), `a missing dance is shown as an HTTP error: ${JSON.stringify(summary.errors[0])}`);
  check(/cors_origins/.test(summary.errors[1].error ?? '') && summary.errors[1].message === summary.errors[1].error,
    `an unreachable server is shown with the CORS hint: ${JSON.stringify(summary.errors[1])}`);
} finally {
  await browser.close();
  pages.close();
}
console.log('summary: ' + JSON.stringify(summary));
