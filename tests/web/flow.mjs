// Drives Debian's chromium through the choreo page, the way a person would use it, against real
// choreo servers (started by tests/web.rs): the page from PAGE_URL, the API on another origin
// (API_URL, bearer token TOKEN, CORS allowing PAGE_URL). Upload by file input and by drop, key
// poses from the library and from an earlier dance's frame (one joint dragged), submit, progress,
// playback in sync with the song, scrub, the mannequin and the stick toggle, rigs (pick, upload,
// mapping, downloads), loop, compare, report plots, downloads, deep links.
//
//   PAGE_URL=… API_URL=… TOKEN=… SONG=path OUT_DIR=dir [EXPECT_EVENTS=1] node tests/web/flow.mjs
//
// Prints one JSON summary line (prefixed "summary: ") and exits 0, or prints why and exits 1.
// Screenshots go to OUT_DIR.
import { chromium } from 'playwright-core';
import { mkdtempSync, readFileSync, writeFileSync, mkdirSync } from 'node:fs';
import { join, basename } from 'node:path';
import { fileURLToPath } from 'node:url';
import { recordMediaClock, sampleFor, checkSamples } from './clock.mjs';

const env = (name) => {
  const value = process.env[name];
  if (!value) throw new Error(`${name} is not set`);
  return value;
};
const PAGE = env('PAGE_URL');
const API = env('API_URL');
const TOKEN = env('TOKEN');
const SONG = env('SONG');
const OUT = env('OUT_DIR');
const CHROMIUM = process.env.CHROMIUM || '/usr/bin/chromium';
const JOB_TIMEOUT_MS = Number(process.env.JOB_TIMEOUT_MS || 300_000);
const EXPECT_EVENTS = process.env.EXPECT_EVENTS === '1';
const EVENTS_URL = /\/v1\/jobs\/[^/]+\/events$/;

mkdirSync(OUT, { recursive: true });
const summary = { screenshots: [], sync: {} };
const pageErrors = [];
const consoleErrors = [];
const foreignRequests = [];

function check(condition, message) {
  if (!condition) throw new Error(`check failed: ${message}`);
}
const log = (...args) => console.log(`[${new Date().toISOString().slice(11, 19)}]`, ...args);

/** GET from the API with the token, from node (to compare what the page shows with the source). */
async function apiJson(path) {
  const response = await fetch(`${API}${path}`, { headers: { Authorization: `Bearer ${TOKEN}` } });
  check(response.ok, `GET ${path}: ${response.status}`);
  return response.json();
}

function watch(page, name) {
  const allowed = [new URL(PAGE).origin, new URL(API).origin];
  page.on('pageerror', (e) => pageErrors.push(`${name}: ${e.message}`));
  page.on('console', (m) => {
    if (m.type() !== 'error') return;
    // A server without the job events route answers 404 there, and the page polls instead; with
    // EXPECT_EVENTS=1 (the spec has the route) that 404 is an error like any other.
    if (!EXPECT_EVENTS && / 404 /.test(m.text()) && EVENTS_URL.test(m.location().url ?? '')) {
      summary.events_route_missing = (summary.events_route_missing ?? 0) + 1;
      return;
    }
    consoleErrors.push(`${name}: ${m.text()}`);
  });
  page.on('request', (r) => {
    const url = r.url();
    if (url.startsWith('blob:') || url.startsWith('data:')) return;
    if (!allowed.includes(new URL(url).origin)) foreignRequests.push(url);
  });
}

async function shot(page, name) {
  const path = join(OUT, `${name}.png`);
  await page.screenshot({ path, fullPage: false });
  summary.screenshots.push(path);
  log('screenshot', path);
}

/** Samples the two clocks while the song plays; every pose is the song's clock (clock.mjs). */
async function checkSync(page, label, seconds = 3) {
  const samples = await sampleFor(page, 'page', seconds);
  const sync = checkSamples(samples, label, check);
  summary.sync[label] = sync;
  log(label, JSON.stringify(sync));
  check(sync.audio_advanced_s > 0.6 * sync.wall_s,
    `${label}: the song's currentTime advanced ${sync.audio_advanced_s.toFixed(2)} s in ${sync.wall_s.toFixed(2)} s of wall time`);
  return samples;
}

/** Waits for the job the page follows (one other than `previous`) to end; returns its id. */
async function waitJob(page, previous = null) {
  await page.waitForFunction((prev) => {
    const stage = document.getElementById('job-stage');
    return stage.dataset.jobId && stage.dataset.jobId !== prev && ['succeeded', 'failed', 'cancelled'].includes(stage.dataset.status);
  }, previous, { timeout: JOB_TIMEOUT_MS, polling: 200 });
  const status = await page.$eval('#job-stage', (e) => e.dataset.status);
  const text = await page.$eval('#job-stage', (e) => e.textContent);
  check(status === 'succeeded', `job ended ${status}: ${text}`);
  return page.$eval('#job-stage', (e) => e.dataset.jobId);
}

/** Waits until view `slot` shows job `id` with its report drawn. */
async function waitOpened(page, slot, id) {
  await page.waitForFunction(([s, j]) => document.getElementById(`view-${s}`).dataset.jobId === j
    && document.querySelector(`#report-${s} canvas.plot.speed`), [slot, id], { timeout: 60_000 });
}

/** Whether a canvas has more than one colour (a plot or a pose was drawn on it). */
const drawn = (page, selector) => page.$eval(selector, (c) => {
  const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
  const colours = new Set();
  for (let i = 0; i < d.length; i += 4 * 7) colours.add((d[i] << 16) | (d[i + 1] << 8) | d[i + 2]);
  return colours.size;
});

/**
 * How far the drawn skeleton is from motion.json at the time on screen: the body centre (the
 * glb's root translation, linear between frames as here) and the worst joint. At a frame's own
 * time the glb's skeleton gives motion.json's positions (measured within 0.3 mm); between frames
 * it turns its joints (slerp) where this interpolates positions linearly, a few millimetres apart.
 */
async function poseError(page, motion) {
  const shown = await page.evaluate((names) => new Promise((r) => requestAnimationFrame(() => r({
    t: window.choreoPlayer.animationTime, joints: names.map((n) => window.choreoPlayer.joint(n)),
  }))), motion.joint_names);
  const f = shown.t * motion.fps, f0 = Math.min(Math.floor(f), motion.num_frames - 1), f1 = Math.min(f0 + 1, motion.num_frames - 1);
  const at = (j) => [0, 1, 2].map((k) => motion.positions[f0][j][k] * (1 - (f - f0)) + motion.positions[f1][j][k] * (f - f0));
  const errors = shown.joints.map((p, j) => (p ? Math.hypot(...at(j).map((v, k) => v - p[k])) : Infinity));
  const worst = Math.max(...errors);
  return { time_s: shown.t, body_centre: errors[0], worst_joint: worst, worst_joint_name: motion.joint_names[errors.indexOf(worst)] };
}

async function setRange(page, selector, value) {
  await page.$eval(selector, (e, v) => {
    e.value = String(v);
    e.dispatchEvent(new Event('input', { bubbles: true }));
    e.dispatchEvent(new Event('change', { bubbles: true }));
  }, value);
}

async function clickTimeline(page, selector, fraction) {
  const locator = page.locator(selector);
  await locator.scrollIntoViewIfNeeded();
  const box = await locator.boundingBox();
  await locator.click({ position: { x: box.width * fraction, y: box.height / 2 } });
}

async function run(context) {
  const page = await context.newPage();
  watch(page, 'main');
  const models = await apiJson('/v1/models');
  const keyModel = models.find((m) => m.capabilities.key_poses);
  const plainModel = models.find((m) => !m.capabilities.key_poses) ?? models[0];
  check(keyModel, `a model that takes key poses is served: ${JSON.stringify(models)}`);

  // 1. The page, its API on another origin, and no API key yet: the API says 401 and the page says so.
  await page.goto(`${PAGE}/?api=${encodeURIComponent(API)}`);
  await page.waitForFunction(() => /^Key required/.test(document.getElementById('api-status').textContent), null, { timeout: 20_000 });
  // A wrong key reads otherwise than a missing one.
  await page.fill('#api-key', 'not-a-key');
  await page.click('#api-connect');
  await page.waitForFunction(() => /^Key not accepted/.test(document.getElementById('api-status').textContent), null, { timeout: 20_000 });
  check(consoleErrors.every((e) => e.includes('401')), `before the key, only 401s: ${consoleErrors}`);
  consoleErrors.length = 0;
  await page.fill('#api-key', TOKEN);
  await page.click('#api-connect');
  await page.waitForFunction(() => document.getElementById('api-status').textContent.startsWith('connected'), null, { timeout: 20_000 });

  // Before any dance the key-pose panel stays out of the way.
  check(await page.$eval('#keys-box', (e) => e.hidden), 'no key-pose panel before a dance exists');

  // 2. A file that is not a song: the page says so and is not left "uploading".
  await page.setInputFiles('#song-file', { name: 'notasong.txt', mimeType: 'text/plain', buffer: Buffer.from('these are words, not music\n') });
  await page.waitForFunction(() => document.getElementById('song-info').dataset.failed === 'true', null, { timeout: 20_000 });
  const failedLine = await page.$eval('#song-info', (e) => e.textContent);
  check(/notasong\.txt was not uploaded: /.test(failedLine) && !/Uploading/.test(failedLine), `a failed upload is said: ${failedLine}`);
  summary.failed_upload = failedLine;
  consoleErrors.length = 0; // the refused upload's 4xx, expected

  // Upload with the file input, then drop the same file: the same song (the API dedups).
  await page.setInputFiles('#song-file', SONG);
  await page.waitForFunction(() => document.getElementById('song-info').dataset.analysed === 'true', null, { timeout: 60_000 });
  const songId = await page.$eval('#song-info', (e) => e.dataset.songId);
  const bytes = readFileSync(SONG).toString('base64');
  await page.evaluate(([b64, name]) => {
    const raw = Uint8Array.from(atob(b64), (c) => c.charCodeAt(0));
    const dt = new DataTransfer();
    dt.items.add(new File([raw], name, { type: 'audio/ogg' }));
    const target = document.getElementById('drop');
    target.dispatchEvent(new DragEvent('dragover', { dataTransfer: dt, bubbles: true, cancelable: true }));
    target.dispatchEvent(new DragEvent('drop', { dataTransfer: dt, bubbles: true, cancelable: true }));
  }, [bytes, basename(SONG)]);
  await page.waitForFunction((id) => {
    const info = document.getElementById('song-info');
    return info.dataset.songId === id && info.dataset.analysed === 'true';
  }, songId, { timeout: 60_000 });
  const song = await apiJson(`/v1/songs/${songId}`);
  check(song.analysis && song.analysis.beat_times.length > 0, `the song has beats: ${JSON.stringify(song)}`);
  check(await drawn(page, '#song-wave') > 3, 'the waveform is drawn');
  await shot(page, '01-song');

  // 3. A first dance with a model without key poses: the "earlier dance" to take a pose from.
  await page.selectOption('#model', plainModel.id);
  for (const m of models) {
    await page.selectOption('#model', m.id);
    for (const [control, capability] of [['#style', 'style'], ['#temperature', 'temperature'], ['#top-k', 'top_k'], ['#keys-box', 'key_poses']]) {
      check(await page.$eval(control, (e) => e.disabled) === !m.capabilities[capability], `${control} is enabled exactly when ${m.id} takes ${capability}`);
    }
  }
  await page.selectOption('#model', plainModel.id);
  await page.fill('#seed', '7');
  const firstPost = page.waitForRequest((r) => r.url() === `${API}/v1/jobs` && r.method() === 'POST');
  await page.click('#submit');
  const firstBody = (await firstPost).postDataJSON();
  check(firstBody.seed === 7 && firstBody.model === plainModel.id && !('key_poses' in firstBody), `first request: ${JSON.stringify(firstBody)}`);
  check(('style' in firstBody) === false || plainModel.capabilities.style, 'style is sent only to a model that takes it');
  const firstJob = await waitJob(page);
  await waitOpened(page, 'a', firstJob);
  log('first dance', firstJob);
  // A model with an opening check (no seed motion here): its report says what the check did,
  // and the page's scores list it.
  if (['dance-revolution', 'dancenet'].includes(plainModel.id)) {
    const firstReport = await apiJson(`/v1/jobs/${firstJob}/report.json`);
    check(firstReport.opening_check && firstReport.opening_check.tried >= 1, `the report has the opening check: ${JSON.stringify(firstReport.opening_check)}`);
    const names = await page.$$eval('#report-a table.scores tr td:first-child', (tds) => tds.map((td) => td.textContent));
    check(names.includes('opening_check.kept'), `the page lists the opening check: ${names.slice(-6)}`);
    summary.opening_check = firstReport.opening_check;
  }

  // 4. Key poses for the key-pose model: one from the library, one from a frame of the first dance.
  await page.selectOption('#model', keyModel.id);
  check(await page.$eval('#keys-box', (e) => !e.disabled), 'key poses are enabled for the key-pose model');
  await page.fill('#seed', '3');
  await page.click('#tab-library');
  await page.click('#pose-library button.pose[data-index="4"]');
  await clickTimeline(page, '#song-wave', 0.3);
  await page.click('#key-add');
  await page.click('#tab-job');
  await page.selectOption('#pose-job-select', firstJob);
  await page.waitForFunction(() => Number(document.getElementById('pose-frame').max) > 0, null, { timeout: 20_000 });
  await setRange(page, '#pose-frame', 60);
  await page.click('#pose-job-use');
  await clickTimeline(page, '#song-wave', 0.7);
  await page.click('#key-add');
  let keys = await page.evaluate(() => window.choreoPlayer.keyPoses);
  check(keys.length === 2, `two key poses placed: ${keys.length}`);
  const firstMotion = await apiJson(`/v1/jobs/${firstJob}/motion.json`);
  const fromDance = keys.find((k) => k.label.startsWith('dance'));
  check(fromDance && JSON.stringify(fromDance.joints) === JSON.stringify(firstMotion.positions[60]), 'the dance pose is frame 60 of the first dance');

  // Drag the selected pose's left wrist; its bone keeps its length.
  const names = firstMotion.joint_names;
  const wrist = names.indexOf('left_wrist'), forearm = names.indexOf('left_forearm');
  const before = keys.find((k) => k.label.startsWith('dance')).joints;
  await page.locator('#key-editor').scrollIntoViewIfNeeded();
  const [x, y] = await page.evaluate(() => window.choreoPlayer.keyEditorPoint('left_wrist'));
  await page.mouse.move(x, y);
  await page.mouse.down();
  await page.mouse.move(x + 20, y - 30, { steps: 5 });
  await page.mouse.up();
  keys = await page.evaluate(() => window.choreoPlayer.keyPoses);
  const after = keys.find((k) => k.label.startsWith('dance')).joints;
  const dist = (a, b) => Math.hypot(a[0] - b[0], a[1] - b[1], a[2] - b[2]);
  check(dist(after[wrist], before[wrist]) > 0.02, `dragging moved the wrist (${dist(after[wrist], before[wrist]).toFixed(3)} m)`);
  check(Math.abs(dist(after[wrist], after[forearm]) - dist(before[wrist], before[forearm])) < 1e-6, 'the dragged bone keeps its length');
  await shot(page, '02-key-poses');

  // 5. Submit, and watch the progress.
  const stages = [];
  await page.exposeFunction('recordStage', (s) => stages.push(s));
  await page.evaluate(() => new MutationObserver(() => window.recordStage(document.getElementById('job-stage').textContent))
    .observe(document.getElementById('job-stage'), { childList: true, characterData: true, subtree: true }));
  const post = page.waitForRequest((r) => r.url() === `${API}/v1/jobs` && r.method() === 'POST');
  await page.click('#submit');
  const body = (await post).postDataJSON();
  check(body.key_poses?.length === 2 && body.seed === 3 && body.plant_feet === true, `request: ${JSON.stringify({ ...body, key_poses: body.key_poses?.length })}`);
  check(body.key_poses.every((k) => k.joints.length === 26 && Number.isInteger(Math.round(k.time_s * 25))), 'key poses carry 26 joints at frame times');
  await page.waitForFunction((prev) => {
    const id = document.getElementById('job-stage').dataset.jobId;
    return id && id !== prev;
  }, firstJob, { timeout: 20_000 });
  await shot(page, '03-progress');
  const keyJob = await waitJob(page, firstJob);
  check(keyJob !== firstJob, 'a new job was followed');
  summary.progress = stages;
  check(stages.some((s) => /^(queued|running)/.test(s)), `progress was shown before the end: ${stages}`);
  await waitOpened(page, 'a', keyJob);
  log('key-pose dance', keyJob, 'stages seen:', stages.length);
  check(new URL(page.url()).searchParams.get('job') === keyJob, 'the address names the open dance');

  // 6. Compare with the first dance, side by side.
  await page.selectOption('#compare', firstJob);
  await waitOpened(page, 'b', firstJob);
  check(await page.evaluate(() => window.choreoPlayer.compareJobId) === firstJob, 'the second view shows the first dance');

  // 7. Play: the dance follows the song's clock.
  await page.click('#play');
  await page.waitForFunction(() => window.choreoPlayer.playing && window.choreoPlayer.audioTime > 0.3, null, { timeout: 20_000 });
  await checkSync(page, 'playing');
  await page.locator('#player-section').scrollIntoViewIfNeeded();
  await shot(page, '04-playing');

  // The figure drawn is the dance's pose at that time: its body centre where motion.json has it.
  await page.click('#play'); // pause
  await page.waitForFunction(() => !window.choreoPlayer.playing);
  const keyMotion = await apiJson(`/v1/jobs/${keyJob}/motion.json`);
  // Between frames only the body centre is compared: the glb turns joints (slerp) where motion.json
  // is interpolated linearly here, centimetres apart on a fast foot; joints are compared at frame 50.
  summary.pose_error_m = await poseError(page, keyMotion);
  check(summary.pose_error_m.body_centre < 0.001, `the drawn body centre is off: ${JSON.stringify(summary.pose_error_m)}`);

  // 8. Scrub to 2 s: both clocks go there.
  await setRange(page, '#scrub', 2);
  await page.waitForFunction(() => Math.abs(window.choreoPlayer.audioTime - 2) < 0.05 && Math.abs(window.choreoPlayer.animationTime - 2) < 0.05, null, { timeout: 10_000 });
  // 2 s is frame 50 itself: there the figure drawn is motion.json's frame, joint for joint.
  summary.pose_error_at_frame_m = await poseError(page, keyMotion);
  check(Math.abs(summary.pose_error_at_frame_m.time_s * 25 - 50) < 1e-3 && summary.pose_error_at_frame_m.worst_joint < 0.01,
    `at frame 50 the drawn joints are motion.json's: ${JSON.stringify(summary.pose_error_at_frame_m)}`);

  // 8b. The mannequin (in every motion.glb) is what is drawn, and it moves with the song: at two
  // times of the song the mesh vertex nearest each wrist and ankle (at rest) is still at that
  // joint, and the joints have moved between the two. The stick view is a toggle; it draws no
  // pole from the floor (only limbs between joints of the skeleton).
  await page.locator('#player-section').scrollIntoViewIfNeeded();
  check(await page.evaluate(() => window.choreoPlayer.view) === 'figure', 'the mannequin is the default view');
  const ends = ['left_wrist', 'right_wrist', 'left_ankle', 'right_ankle'];
  const figureAt = async (t, name) => {
    await setRange(page, '#scrub', t);
    await page.waitForFunction((s) => Math.abs(window.choreoPlayer.animationTime - s) < 1e-3, t, { timeout: 10_000 });
    const figure = await page.evaluate((n) => new Promise((r) => requestAnimationFrame(() => r(window.choreoPlayer.figure(n)))), ends);
    await shot(page, name);
    check(figure && figure.shown && figure.triangles > 1000, `the mannequin is drawn at ${t} s: ${JSON.stringify(figure)}`);
    for (const joint of ends) {
      const j = figure.joints[joint];
      const off = Math.hypot(...j.vertex.map((v, k) => v - j.joint[k]));
      check(j.rest_distance < 0.04 && off < j.rest_distance + 0.02, `at ${t} s the mannequin's ${joint} vertex is ${off.toFixed(3)} m from the joint (rest ${j.rest_distance.toFixed(3)})`);
    }
    return figure;
  };
  const early = await figureAt(1.0, '04b-mannequin-1s');
  const late = await figureAt(3.0, '04c-mannequin-3s');
  const travel = Math.max(...ends.map((j) => Math.hypot(...early.joints[j].vertex.map((v, k) => v - late.joints[j].vertex[k]))));
  check(travel > 0.05, `the mannequin moved between 1 s and 3 s (${travel.toFixed(3)} m)`);
  summary.mannequin = { triangles: early.triangles, travel_m: travel, wrist_off_m: Math.hypot(...early.joints.left_wrist.vertex.map((v, k) => v - early.joints.left_wrist.joint[k])) };
  await page.click('#stick-view');
  check(await page.evaluate(() => window.choreoPlayer.view) === 'sticks', 'the toggle shows the stick figure');
  check(!(await page.evaluate(() => window.choreoPlayer.figure([]).shown)), 'the mannequin is hidden in the stick view');
  const limbs = await page.evaluate(() => window.choreoPlayer.limbs());
  check(limbs.length >= 20 && limbs.every(([from, to]) => keyMotion.joint_names.includes(from) && keyMotion.joint_names.includes(to)) || false,
    `every stick limb joins two joints (no pole from the floor): ${JSON.stringify(limbs)}`);
  await shot(page, '04d-sticks');
  await page.click('#stick-view');
  check(await page.evaluate(() => window.choreoPlayer.view) === 'figure', 'the toggle brings the mannequin back');

  // 8c. Rigs: the picker's downloads name the rig; an uploaded BVH shows its mapping.
  const rigButtons = () => page.$$eval('#rig-downloads button', (bs) => bs.map((b) => b.dataset.file));
  check(JSON.stringify(await rigButtons()) === JSON.stringify(['motion.bvh', 'motion.glb']), `choreo's downloads: ${await rigButtons()}`);
  await page.selectOption('#rig', 'mixamo');
  check(JSON.stringify(await rigButtons()) === JSON.stringify(['motion.bvh?rig=mixamo', 'motion.glb?rig=mixamo']), `mixamo's downloads: ${await rigButtons()}`);
  await page.selectOption('#rig', 'vrm');
  check(JSON.stringify(await rigButtons()) === JSON.stringify(['motion.vrma']), `vrm's download: ${await rigButtons()}`);
  await page.selectOption('#rig', 'smpl');
  check(JSON.stringify(await rigButtons()) === JSON.stringify(['motion.smpl.npz']), `smpl's download: ${await rigButtons()}`);
  const rigPost = page.waitForResponse((r) => r.url() === `${API}/v1/rigs` && r.request().method() === 'POST');
  await page.setInputFiles('#rig-file', fileURLToPath(new URL('../fixtures/rig_unreal_cm.bvh', import.meta.url)));
  const rigResponse = await rigPost;
  check(rigResponse.status() === 201, `the rig upload answered ${rigResponse.status()}`);
  const rig = await rigResponse.json();
  await page.waitForFunction(() => !document.getElementById('rig-mapping').hidden, null, { timeout: 10_000 });
  const rows = await page.$$eval('#rig-mapping-rows tr', (trs) => trs.map((tr) => [...tr.cells].map((c) => c.textContent)));
  check(rows.some(([j, b]) => j === 'pelvis' && b === 'hips') && rows.some(([j, b]) => j === 'upperarm_l' && b === 'leftUpperArm'), `the mapping is shown: ${JSON.stringify(rows)}`);
  check(rows.length === Object.keys(rig.mapping).length, 'every mapped joint is listed');
  check(await page.$eval('#rig', (e) => e.value) === rig.id, 'the uploaded rig is picked');
  check(JSON.stringify(await rigButtons()) === JSON.stringify([`motion.bvh?rig=${rig.id}`, `motion.glb?rig=${rig.id}`]), `the uploaded rig's downloads: ${await rigButtons()}`);
  summary.rig = { id: rig.id, mapped: rows.length, units: rig.units };
  await page.locator('#player-section').scrollIntoViewIfNeeded();
  await shot(page, '04e-rig-uploaded');
  await page.selectOption('#rig', 'choreo');

  // 9. Loop 1–2.5 s, chosen by dragging across the strip, and play through the loop end twice.
  const duration = song.duration_s;
  await page.locator('#player-wave').scrollIntoViewIfNeeded();
  const strip = await page.locator('#player-wave').boundingBox();
  await page.mouse.move(strip.x + strip.width * (1 / duration), strip.y + strip.height / 2);
  await page.mouse.down();
  await page.mouse.move(strip.x + strip.width * (2.5 / duration), strip.y + strip.height / 2, { steps: 8 });
  await page.mouse.up();
  const loop = await page.evaluate(() => ({ on: document.getElementById('loop').checked, a: Number(document.getElementById('loop-a').value), b: Number(document.getElementById('loop-b').value) }));
  check(loop.on && Math.abs(loop.a - 1) < 0.1 && Math.abs(loop.b - 2.5) < 0.1, `loop chosen by dragging: ${JSON.stringify(loop)}`);
  await page.click('#play');
  const looped = await checkSync(page, 'looping', 3.5);
  const times = looped.map((s) => s.audio);
  check(times.every((t) => t >= loop.a - 0.05 && t <= loop.b + 0.1), `looping stays in ${loop.a}–${loop.b}: ${times.map((t) => t.toFixed(2))}`);
  check(times.some((t, i) => i > 0 && t < times[i - 1] - 0.5), `the loop wrapped: ${times.map((t) => t.toFixed(2))}`);
  await page.click('#play');
  await page.waitForFunction(() => !window.choreoPlayer.playing);

  // 10. The report: plots drawn for both dances; files downloaded.
  for (const slot of ['a', 'b']) {
    for (const plot of ['beats', 'speed']) check(await drawn(page, `#report-${slot} canvas.plot.${plot}`) > 3, `${plot} plot of ${slot} is drawn`);
  }
  await page.locator('#report-section').scrollIntoViewIfNeeded();
  await shot(page, '05-report');
  const download = async (file) => {
    const [d] = await Promise.all([page.waitForEvent('download'), page.click(`#report-a button[data-file="${file}"]`)]);
    const path = join(OUT, `download-${file}`);
    await d.saveAs(path);
    return readFileSync(path);
  };
  const bvh = await download('motion.bvh');
  check(bvh.toString('utf8', 0, 9) === 'HIERARCHY', 'the BVH download is a BVH');
  const glb = await download('motion.glb');
  check(glb.toString('latin1', 0, 4) === 'glTF', 'the glb download is a glb');
  const json = JSON.parse((await download('motion.json')).toString('utf8'));
  check(json.num_frames === keyMotion.num_frames, 'the JSON download is the motion');
  summary.downloads = { bvh: bvh.length, glb: glb.length, json_frames: json.num_frames };

  // 11. A deep link opens a dance (the key is remembered on the page's origin).
  const linked = await context.newPage();
  watch(linked, 'deep link');
  await linked.goto(`${PAGE}/?job=${firstJob}&api=${encodeURIComponent(API)}`);
  await waitOpened(linked, 'a', firstJob);
  check(await linked.evaluate(() => window.choreoPlayer.jobId) === firstJob, 'the deep link opened its dance');
  await linked.click('#play');
  await linked.waitForFunction(() => window.choreoPlayer.playing && window.choreoPlayer.audioTime > 0.3, null, { timeout: 20_000 });
  await checkSync(linked, 'deep link', 2);
  await shot(linked, '06-deep-link');
  await linked.click('#play'); // pause, then frame 40 (1.6 s) itself
  await linked.waitForFunction(() => !window.choreoPlayer.playing);
  await setRange(linked, '#scrub', 1.6);
  await linked.waitForFunction(() => Math.abs(window.choreoPlayer.animationTime - 1.6) < 1e-3, null, { timeout: 10_000 });
  summary.pose_error_deep_link_m = await poseError(linked, firstMotion);
  check(summary.pose_error_deep_link_m.worst_joint < 0.01, `deep link: at frame 40 a drawn joint is off: ${JSON.stringify(summary.pose_error_deep_link_m)}`);
  await linked.close();

  // 12. The page served by the API server itself (same origin): the key typed, the link followed.
  const same = await context.newPage();
  watch(same, 'same origin');
  await same.goto(`${API}/?job=${keyJob}`);
  await same.waitForFunction(() => /API key/i.test(document.getElementById('api-status').textContent), null, { timeout: 20_000 });
  await same.fill('#api-key', TOKEN);
  await same.click('#api-connect');
  await waitOpened(same, 'a', keyJob);
  await same.close();
  // The same-origin page's first try had no token: its 401s are expected, nothing else.
  const unexpected = consoleErrors.filter((e) => !(e.startsWith('same origin:') && e.includes('401')));
  check(unexpected.length === 0, `console errors: ${unexpected.join(' | ')}`);
  summary.jobs = { first: firstJob, key_poses: keyJob };
}

const userDataDir = mkdtempSync(join(OUT, 'chromium-profile-'));
const context = await chromium.launchPersistentContext(userDataDir, {
  executablePath: CHROMIUM,
  headless: true,
  acceptDownloads: true,
  viewport: { width: 1280, height: 900 },
  args: ['--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run', '--disable-background-networking',
    '--disable-component-update', '--disable-sync'],
});
// Every page of the context records its media clock for checkSync (clock.mjs).
await context.addInitScript(recordMediaClock);
let failed = null;
try {
  await run(context);
} catch (e) {
  failed = e;
  const pages = context.pages();
  if (pages.length) await pages[pages.length - 1].screenshot({ path: join(OUT, 'failure.png') }).catch(() => {});
}
await context.close();
if (!failed && pageErrors.length) failed = new Error(`page errors: ${pageErrors.join(' | ')}`);
if (!failed && foreignRequests.length) failed = new Error(`requests to other origins: ${foreignRequests.join(' ')}`);
writeFileSync(join(OUT, 'summary.json'), JSON.stringify({ ...summary, pageErrors, consoleErrors, failed: failed?.message ?? null }, null, 2));
if (failed) {
  console.error(`web flow failed: ${failed.stack || failed}`);
  if (pageErrors.length) console.error('page errors:', pageErrors);
  if (consoleErrors.length) console.error('console errors:', consoleErrors);
  process.exit(1);
}
console.log(`summary: ${JSON.stringify(summary)}`);
