// The choreo page: upload a song, shape a dance (model, seed, style, key poses), follow the job,
// play the dance in 3-D in time with the song, read its report, download its files.
// It talks to the public /v1 API only (this origin, or ?api=ORIGIN with CORS there) through the
// TypeScript client (clients/typescript: types generated from the OpenAPI document), with the API
// key from the key field sent as a bearer secret when the server asks for one, and follows a job
// by its server-sent events.
import { Choreo, ApiError } from '../../clients/typescript/src/index.ts';
import { Timeline, decodePeaks } from './timeline.js';
import { Stage } from './player.js';
import { ReportView } from './report.js';
import { JOINT_NAMES, LIBRARY, PoseEditor, clonePose, drawPose } from './poses.js';

const $ = (id) => document.getElementById(id);
/** Frames per second of every choreo dance (motion.json's fps). */
const FPS = 25;
/** The styles the API takes (its DanceStyle), for models that say `style: true`. */
const STYLES = ['waltz', 'rumba', 'cha-cha', 'tango'];

const params = new URLSearchParams(location.search);
let api = new Choreo();
/** A path of the API (a job's links, a song's audio) fetched with the key, as a Blob. */
const blobOf = async (path) => (await api.fetch(path)).blob();
const jsonOf = async (path) => (await api.fetch(path)).json();
const state = {
  models: [],
  song: null, // SongView of the song being choreographed
  keys: [], // [{time_s, joints, label}], sorted by time
  selectedKey: -1,
  cursor: 0,
  chosen: null, // {joints, label}: the pose "Add" places
  watching: null, // id of the job whose progress is shown
  jobs: [], // recent generate jobs
  rigs: {}, // id → RigView of the rigs uploaded from this page
};
const audioCache = new Map(); // song id → {url, peaks, duration}
const motionCache = new Map(); // job id → motion.json

// ---------------------------------------------------------------- messages
let toastTimer = 0;
function toast(message) {
  const el = $('toast');
  el.textContent = message;
  el.hidden = false;
  clearTimeout(toastTimer);
  toastTimer = setTimeout(() => { el.hidden = true; }, 8000);
}
// The server answers 401 both without a key and with one it does not know: the page knows which
// it sent, and says which.
const describe = (e) => (e instanceof ApiError && e.status === 401
  ? ($('api-key').value.trim()
    ? 'Key not accepted: the server knows no API key with this secret. Check it, or ask for a new one (choreo keys create).'
    : 'Key required: the API wants an API key. Enter it above and press Connect.')
  : e?.message || String(e));
/** Runs an async UI action; failures become a message on the page, never an uncaught error. */
const guard = (fn) => async (...args) => {
  try {
    return await fn(...args);
  } catch (e) {
    console.warn(e);
    toast(describe(e));
    return undefined;
  }
};
window.addEventListener('choreo-error', (e) => toast(describe(e.detail)));

// ---------------------------------------------------------------- connection
async function connect() {
  const base = $('api-base').value.trim();
  const key = $('api-key').value.trim();
  localStorage.setItem('choreo.api', base);
  localStorage.setItem('choreo.key', key);
  api = new Choreo({ baseUrl: base, apiKey: key });
  $('api-status').textContent = 'connecting…';
  try {
    state.models = await api.models();
  } catch (e) {
    $('api-status').textContent = describe(e);
    $('api-status').className = 'status bad';
    throw e;
  }
  $('api-status').textContent = `connected: ${state.models.length} model${state.models.length === 1 ? '' : 's'}`;
  $('api-status').className = 'status ok';
  $('toast').hidden = true;
  fillModels();
  await refreshJobs();
}

// ---------------------------------------------------------------- song
const songTimeline = new Timeline($('song-wave'), {
  onCursor: (t) => setCursor(t),
  onKeySelect: (i) => selectKey(i),
  onKeyMove: (i, t) => moveKey(i, t),
});

function setCursor(t) {
  state.cursor = snap(t);
  $('cursor-time').textContent = `${state.cursor.toFixed(2)} s`;
  songTimeline.set({ cursor: state.cursor });
}

/** Audio and waveform of a song, fetched once (with the key) and kept as a blob URL. */
async function songAudio(songId, blob = null) {
  if (audioCache.has(songId)) return audioCache.get(songId);
  const bytes = blob ?? (await api.songAudio(songId));
  let wave = { peaks: null, duration: 0 };
  try {
    wave = await decodePeaks(await bytes.arrayBuffer());
  } catch (e) {
    console.warn('no waveform:', e);
  }
  const entry = { url: URL.createObjectURL(bytes), ...wave };
  audioCache.set(songId, entry);
  return entry;
}

function showSong(song) {
  state.song = song;
  const a = song.analysis;
  const analysis = a
    ? `${a.tempo_bpm.toFixed(1)} BPM, ${a.beat_times.length} beats, ${a.downbeat_times.length} downbeats`
    : song.analysis_status === 'failed' ? `analysis failed: ${song.analysis_error}` : 'analysing…';
  $('song-info').textContent = `${song.filename} · ${song.format} · ${song.duration_s.toFixed(2)} s · ${analysis}`;
  $('song-info').dataset.songId = song.id;
  $('song-info').dataset.analysed = a ? 'true' : 'false';
  songTimeline.set({ duration: song.duration_s, beats: a?.beat_times ?? [], downbeats: a?.downbeat_times ?? [] });
  updateSubmit();
}

const uploadSong = guard(async (file) => {
  if (!file) return;
  $('song-info').textContent = `Uploading ${file.name}…`;
  let song;
  try {
    song = await api.upload(file);
  } catch (e) {
    // The song shown before stays chosen; the line says what happened to this one.
    $('song-info').textContent = `${file.name} was not uploaded: ${describe(e)}`;
    $('song-info').dataset.failed = 'true';
    throw e;
  }
  delete $('song-info').dataset.failed;
  state.keys = [];
  renderKeys();
  showSong(song);
  const audio = await songAudio(song.id, file);
  songTimeline.set({ peaks: audio.peaks });
  showSong(await api.waitForSong(song.id, showSong));
});

$('song-file').addEventListener('change', (e) => uploadSong(e.target.files[0]));
// A song dropped anywhere on the page is uploaded (and the browser does not navigate to it).
const drop = $('drop');
drop.addEventListener('dragenter', () => drop.classList.add('over'));
drop.addEventListener('dragleave', () => drop.classList.remove('over'));
window.addEventListener('dragover', (e) => e.preventDefault());
window.addEventListener('drop', (e) => {
  e.preventDefault();
  drop.classList.remove('over');
  if (e.dataTransfer?.files.length) uploadSong(e.dataTransfer.files[0]);
});

// ---------------------------------------------------------------- model, seed, style
function model() {
  return state.models.find((m) => m.id === $('model').value) ?? null;
}

function fillModels() {
  const select = $('model');
  const previous = select.value;
  select.replaceChildren(...state.models.map((m) => new Option(m.id, m.id)));
  // The server's first model is its default (the one whose served dances score closest to real
  // ones), as in the README and `choreo generate`.
  const preferred = state.models.find((m) => m.id === previous) ?? state.models[0];
  if (preferred) select.value = preferred.id;
  modelChanged();
}

function modelChanged() {
  const m = model();
  const caps = m?.capabilities ?? {};
  $('model-info').textContent = m ? `${m.paper}` : 'No models on this server.';
  const style = $('style');
  style.disabled = !caps.style;
  const styles = Array.isArray(caps.styles) ? caps.styles : STYLES;
  style.replaceChildren(new Option('from the music', ''), ...(caps.style ? styles.map((s) => new Option(s, s)) : []));
  // Sampling controls, like style, only for models whose capabilities name them.
  $('temperature').disabled = !caps.temperature;
  $('top-k').disabled = !caps.top_k;
  $('keys-box').disabled = !caps.key_poses;
  $('keys-note').textContent = caps.key_poses
    ? 'Choose a pose (from the library of real train-split poses, or any frame of a dance), put the cursor on the song, and add it.'
    : `${m?.id ?? 'This model'} does not take key poses; choose a model that does to place them.`;
  updateSubmit();
}
$('model').addEventListener('change', modelChanged);

// ---------------------------------------------------------------- key poses
/** Times land on frames (the API rounds time_s × 25), within the song's last whole frame. */
function snap(t) {
  const frames = state.song ? Math.floor(state.song.duration_s * FPS) : 0;
  const frame = Math.min(Math.max(0, Math.round(t * FPS)), Math.max(0, frames - 1));
  return frame / FPS;
}

/** A frame no other key uses, as near `t` as possible (two keys may not share a frame). */
function freeTime(t, except = -1) {
  const taken = new Set(state.keys.filter((_, i) => i !== except).map((k) => Math.round(k.time_s * FPS)));
  const frames = Math.floor((state.song?.duration_s ?? 0) * FPS);
  const start = Math.round(snap(t) * FPS);
  for (let d = 0; d < frames; d++) {
    for (const f of [start + d, start - d]) if (f >= 0 && f < frames && !taken.has(f)) return f / FPS;
  }
  return null;
}

function choose(joints, label) {
  state.chosen = { joints: clonePose(joints), label };
  $('pose-chosen').textContent = label;
  updateSubmit();
}

function renderKeys() {
  state.keys.sort((a, b) => a.time_s - b.time_s);
  const list = $('key-list');
  list.replaceChildren(...state.keys.map((k, i) => {
    const li = document.createElement('li');
    const button = document.createElement('button');
    button.type = 'button';
    button.textContent = `${k.time_s.toFixed(2)} s · ${k.label}`;
    button.className = i === state.selectedKey ? 'selected' : '';
    button.addEventListener('click', () => selectKey(i));
    li.append(button);
    return li;
  }));
  songTimeline.set({ keys: state.keys, selected: state.selectedKey });
  const key = state.keys[state.selectedKey];
  editor.show(key ? key.joints : null);
  $('key-time').value = key ? key.time_s.toFixed(2) : '';
  $('key-time').disabled = !key;
  $('key-delete').disabled = !key;
  $('key-list').dataset.count = String(state.keys.length);
}

function selectKey(i) {
  state.selectedKey = i;
  renderKeys();
}

function moveKey(i, t) {
  const time = freeTime(t, i);
  if (time == null) return;
  const key = state.keys[i];
  key.time_s = time;
  renderKeys();
  state.selectedKey = state.keys.indexOf(key);
  renderKeys();
}

const editor = new PoseEditor($('key-editor'), () => {
  const key = state.keys[state.selectedKey];
  if (key && !key.label.endsWith(' (edited)')) key.label += ' (edited)';
  renderKeys();
});

$('key-add').addEventListener('click', () => {
  if (!state.chosen) return toast('Choose a pose first: one from the library, or a frame of a dance.');
  if (!state.song) return toast('Upload a song first.');
  const time = freeTime(state.cursor);
  if (time == null) return toast('Every frame of this song has a key pose.');
  const key = { time_s: time, joints: clonePose(state.chosen.joints), label: state.chosen.label };
  state.keys.push(key);
  state.keys.sort((a, b) => a.time_s - b.time_s);
  state.selectedKey = state.keys.indexOf(key);
  renderKeys();
});
$('key-delete').addEventListener('click', () => {
  if (state.selectedKey < 0) return;
  state.keys.splice(state.selectedKey, 1);
  state.selectedKey = -1;
  renderKeys();
});
$('key-time').addEventListener('change', (e) => {
  if (state.selectedKey >= 0) moveKey(state.selectedKey, Number(e.target.value));
});

// The library: real poses of the dataset's train split (web/tools/pose-library.mjs).
$('pose-library').replaceChildren(...LIBRARY.map((pose, i) => {
  const button = document.createElement('button');
  button.type = 'button';
  button.className = 'pose';
  button.title = pose.name;
  button.dataset.index = String(i);
  const c = document.createElement('canvas');
  c.width = 70;
  c.height = 90;
  drawPose(c, pose.joints);
  button.append(c);
  button.addEventListener('click', () => {
    for (const b of $('pose-library').children) b.classList.toggle('selected', b === button);
    choose(pose.joints, `library: ${pose.name}`);
  });
  return button;
}));

function showTab(which) {
  const library = which === 'library';
  $('tab-library').setAttribute('aria-selected', String(library));
  $('tab-job').setAttribute('aria-selected', String(!library));
  $('pose-library').hidden = !library;
  $('pose-job').hidden = library;
}
$('tab-library').addEventListener('click', () => showTab('library'));
$('tab-job').addEventListener('click', () => showTab('job'));

async function motionOf(jobId) {
  if (!motionCache.has(jobId)) motionCache.set(jobId, await (await api.download(jobId, 'motion.json')).json());
  return motionCache.get(jobId);
}

const poseJobChanged = guard(async () => {
  const id = $('pose-job-select').value;
  if (!id) return;
  const motion = await motionOf(id);
  $('pose-frame').max = String(motion.num_frames - 1);
  $('pose-frame').value = String(Math.min(Number($('pose-frame').value), motion.num_frames - 1));
  poseFrameChanged();
});
function poseFrameChanged() {
  const motion = motionCache.get($('pose-job-select').value);
  if (!motion) return;
  const frame = Number($('pose-frame').value);
  $('pose-frame-label').textContent = `frame ${frame} · ${(frame / motion.fps).toFixed(2)} s`;
  drawPose($('pose-job-preview'), motion.positions[frame]);
}
$('pose-job-select').addEventListener('change', poseJobChanged);
$('pose-frame').addEventListener('input', poseFrameChanged);
$('pose-job-use').addEventListener('click', () => {
  const id = $('pose-job-select').value;
  const motion = motionCache.get(id);
  if (!motion) return toast('Choose a dance first.');
  const frame = Number($('pose-frame').value);
  choose(motion.positions[frame], `dance ${id.slice(0, 8)} @ ${(frame / motion.fps).toFixed(2)} s`);
});

// ---------------------------------------------------------------- submit and follow
function updateSubmit() {
  $('submit').disabled = !(state.song && model());
}

function request() {
  const m = model();
  const body = { song_id: state.song.id, model: m.id, plant_feet: $('plant-feet').checked };
  const seed = $('seed').value.trim();
  if (seed !== '') {
    // JSON numbers past 2^53 lose digits in JavaScript; the API takes any u64, the page these.
    const n = Number(seed);
    if (!Number.isSafeInteger(n) || n < 0) throw new Error(`The seed must be a whole number from 0 to ${Number.MAX_SAFE_INTEGER}.`);
    body.seed = n;
  }
  // `style` goes only to models that say they take it; others would answer 422.
  if (m.capabilities.style && $('style').value) body.style = $('style').value;
  const temperature = $('temperature').value.trim();
  if (m.capabilities.temperature && temperature !== '') body.temperature = Number(temperature);
  const topK = $('top-k').value.trim();
  if (m.capabilities.top_k && topK !== '') body.top_k = Number(topK);
  if (m.capabilities.key_poses && state.keys.length) {
    body.key_poses = state.keys.map((k) => ({ time_s: k.time_s, joints: k.joints }));
  }
  return body;
}

const submit = guard(async () => {
  $('submit').disabled = true;
  // The last job's state goes, so nothing reads it as this one's.
  $('job-progress').value = 0;
  $('job-stage').textContent = 'submitting…';
  delete $('job-stage').dataset.status;
  delete $('job-stage').dataset.jobId;
  try {
    let job;
    try {
      job = await api.createJob(request());
    } catch (e) {
      $('job-stage').textContent = 'not submitted';
      throw e;
    }
    await follow(job.id);
  } finally {
    updateSubmit();
  }
});
$('submit').addEventListener('click', submit);

/** Shows a job's progress until it ends; opens the dance when it succeeds. */
async function follow(id) {
  state.watching = id;
  $('job-cancel').hidden = false;
  const show = (job) => {
    $('job-progress').value = job.progress;
    const stage = job.stage ? ` · ${job.stage}` : '';
    $('job-stage').textContent = `${job.status}${stage} · ${Math.round(job.progress * 100)} %${job.error ? ` · ${job.error}` : ''}`;
    $('job-stage').dataset.status = job.status;
    $('job-stage').dataset.jobId = job.id;
  };
  // The job's server-sent events move the bar (a server without them is polled).
  const job = await api.wait(id, { onUpdate: show });
  $('job-cancel').hidden = true;
  state.watching = null;
  await refreshJobs();
  if (job.status === 'succeeded') await openJob(job.id, 'a');
  else toast(`The job ${job.status}${job.error ? `: ${job.error}` : ''}.`);
}
$('job-cancel').addEventListener('click', guard(async () => {
  if (state.watching) await api.cancel(state.watching);
}));

// ---------------------------------------------------------------- player
const audio = $('audio');
const stages = { a: new Stage($('stage-a')), b: null };
const slots = { a: null, b: null }; // {job, motion, report, view}
let animationTime = 0;
let renderedFrames = 0;
let frameMs = 0;
let dirty = true;
let scrubbing = false;
stages.a.controls.addEventListener('change', () => { dirty = true; });

const playerTimeline = new Timeline($('player-wave'), {
  onSeek: (t) => seek(t),
  onRange: (a, b) => {
    $('loop-a').value = a.toFixed(2);
    $('loop-b').value = b.toFixed(2);
    $('loop').checked = true;
    loopChanged();
    seek(a);
  },
});

function loop() {
  const a = Number($('loop-a').value), b = Number($('loop-b').value);
  return { a, b, on: $('loop').checked && b > a + 0.1 };
}
function loopChanged() {
  playerTimeline.set({ loop: loop() });
}
for (const id of ['loop', 'loop-a', 'loop-b']) $(id).addEventListener('input', loopChanged);

function seek(t) {
  audio.currentTime = Math.max(0, Math.min(t, audio.duration || t));
  dirty = true;
}

$('play').addEventListener('click', guard(async () => {
  if (audio.paused) await audio.play();
  else audio.pause();
}));
audio.addEventListener('play', () => { $('play').textContent = 'Pause'; });
audio.addEventListener('pause', () => { $('play').textContent = 'Play'; });
audio.addEventListener('seeked', () => { dirty = true; });
$('mute').addEventListener('change', (e) => { audio.muted = e.target.checked; });
$('scrub').addEventListener('input', (e) => { scrubbing = true; seek(Number(e.target.value)); });
$('scrub').addEventListener('change', () => { scrubbing = false; });

/** One display frame: the song's audio clock sets the dance's time; nothing else keeps time. */
function tick() {
  const started = performance.now();
  let t = audio.currentTime;
  const l = loop();
  if (l.on && !audio.paused && t >= l.b) {
    audio.currentTime = l.a;
    t = l.a;
  }
  if (slots.a && (dirty || !audio.paused)) {
    animationTime = stages.a.setTime(t);
    stages.a.render();
    if (slots.b) {
      stages.b.setTime(t);
      stages.b.render();
    }
    renderedFrames++;
    dirty = false;
    if (!scrubbing) $('scrub').value = String(t);
    $('time').textContent = `${t.toFixed(2)} / ${(audio.duration || 0).toFixed(2)} s`;
    playerTimeline.set({ playhead: t });
    slots.a.view.setPlayhead(t);
    slots.b?.view.setPlayhead(t);
    frameMs = performance.now() - started;
  }
  requestAnimationFrame(tick);
}
requestAnimationFrame(tick);

/** Opens a succeeded job's dance in view `slot` ('a': the main one, with its song; 'b': beside it). */
const openJob = guard(async (id, slot = 'a') => {
  const job = await api.job(id);
  if (job.kind !== 'generate') throw new Error(`job ${id} is an ${job.kind} job: it has no dance`);
  if (job.status === 'queued' || job.status === 'running') {
    toast(`That dance is still ${job.status}; following it.`);
    await follow(job.id);
    return;
  }
  if (job.status !== 'succeeded') throw new Error(`job ${id} ${job.status}${job.error ? `: ${job.error}` : ''}`);
  const [glb, motion, report, song] = await Promise.all([
    api.fetch(job.links.motion_glb).then((r) => r.arrayBuffer()),
    motionOf(job.id),
    jsonOf(job.links.report),
    jsonOf(job.links.song),
  ]);
  if (slot === 'b' && !stages.b) {
    $('view-b').hidden = false;
    stages.b = new Stage($('stage-b'));
    stages.b.controls.addEventListener('change', () => { dirty = true; });
  }
  const stage = stages[slot];
  await stage.load(glb);
  $('keys-box').hidden = false; // a dance exists: its frames can be key poses
  const title = `${job.model} · seed ${job.seed} · ${job.id.slice(0, 8)}…`;
  if (slot === 'a') {
    const media = await songAudio(song.id);
    if (audio.src !== media.url) {
      audio.pause();
      audio.src = media.url;
      await new Promise((resolve, reject) => {
        audio.addEventListener('loadedmetadata', resolve, { once: true });
        audio.addEventListener('error', () => reject(new Error('the browser cannot play this song')), { once: true });
      });
    }
    if (!state.song) {
      showSong(song);
      songTimeline.set({ peaks: media.peaks });
    }
    playerTimeline.set({
      duration: song.duration_s,
      peaks: media.peaks,
      beats: song.analysis?.beat_times ?? [],
      downbeats: song.analysis?.downbeat_times ?? [],
    });
    $('scrub').max = String(song.duration_s);
    $('scrub').disabled = false;
    $('play').disabled = false;
    $('take-pose').disabled = false;
    if (Number($('loop-b').value) <= 0 || Number($('loop-b').value) > song.duration_s) $('loop-b').value = song.duration_s.toFixed(2);
    $('view-a-title').textContent = title;
    const url = new URL(location.href);
    url.searchParams.set('job', job.id);
    history.replaceState(null, '', url);
  } else {
    const other = slots.a && slots.a.job.song_id !== job.song_id ? ' (danced to another song)' : '';
    $('view-b-title').textContent = title + other;
    $('compare').value = job.id;
    const url = new URL(location.href);
    url.searchParams.set('compare', job.id);
    history.replaceState(null, '', url);
  }
  const container = $(`report-${slot}`);
  container.hidden = false;
  const view = new ReportView(container, { api, job, report, motion, analysis: song.analysis });
  slots[slot] = { job, motion, report, view };
  stage.setView($('stick-view').checked ? 'sticks' : 'figure');
  if (slot === 'a') showRigDownloads();
  $(`view-${slot}`).dataset.jobId = job.id;
  dirty = true;
  document.dispatchEvent(new CustomEvent('choreo-opened', { detail: { slot, id: job.id } }));
});

// ---------------------------------------------------------------- character and rigs
// The mannequin (in every motion.glb) or the stick figure; the rig the downloads are made for.
$('stick-view').addEventListener('change', (e) => {
  const view = e.target.checked ? 'sticks' : 'figure';
  for (const stage of [stages.a, stages.b]) stage?.setView(view);
  dirty = true;
});

/** The files of a job on rig `rig`: a built-in's name or an uploaded rig's id. */
function rigFiles(rig) {
  if (rig === 'vrm') return [['motion.vrma', 'VRM animation (.vrma)']];
  if (rig === 'smpl') return [['motion.smpl.npz', 'SMPL (.npz)']];
  const query = rig === 'choreo' ? '' : `?rig=${encodeURIComponent(rig)}`;
  return [[`motion.bvh${query}`, 'BVH'], [`motion.glb${query}`, 'glb']];
}

/** Download buttons for the open dance on the chosen rig (fetched with the key, then saved). */
function showRigDownloads() {
  const box = $('rig-downloads');
  box.replaceChildren();
  const job = slots.a?.job;
  if (!job) return;
  const rig = $('rig').value;
  const label = $('rig').selectedOptions[0]?.textContent ?? rig;
  for (const [file, kind] of rigFiles(rig)) {
    const button = document.createElement('button');
    button.type = 'button';
    button.textContent = `Download ${kind} · ${label}`;
    button.dataset.file = file;
    button.addEventListener('click', guard(async () => {
      button.disabled = true;
      try {
        const blob = await blobOf(`/v1/jobs/${job.id}/${file}`);
        const a = document.createElement('a');
        a.href = URL.createObjectURL(blob);
        a.download = `${job.id}-${rig}-${file.split('?')[0]}`;
        document.body.append(a);
        a.click();
        a.remove();
        setTimeout(() => URL.revokeObjectURL(a.href), 60_000);
      } finally {
        button.disabled = false;
      }
    }));
    box.append(button);
  }
}
$('rig').addEventListener('change', () => {
  showRigDownloads();
  const option = $('rig').selectedOptions[0];
  if (option?.dataset.uploaded) showMapping(state.rigs[option.value]);
  else $('rig-mapping').hidden = true;
});

/** Shows an uploaded rig's mapping: which of its joints drives which humanoid bone. */
function showMapping(rig) {
  if (!rig) return;
  const rows = $('rig-mapping-rows');
  rows.replaceChildren();
  for (const [joint, bone] of Object.entries(rig.mapping)) {
    const tr = document.createElement('tr');
    for (const text of [joint, bone]) {
      const td = document.createElement('td');
      td.textContent = text;
      tr.append(td);
    }
    rows.append(tr);
  }
  $('rig-mapping-title').textContent = `${rig.filename}: ${Object.keys(rig.mapping).length} joints mapped, ${rig.unmapped.length} left as they are (${rig.format}, read in ${rig.units})`;
  $('rig-unmapped').textContent = rig.unmapped.length ? `Unmapped: ${rig.unmapped.join(', ')}` : '';
  $('rig-mapping').hidden = false;
  $('rig-mapping').open = true;
}

$('rig-file').addEventListener('change', guard(async (e) => {
  const file = e.target.files?.[0];
  if (!file) return;
  $('rig-status').textContent = `Reading ${file.name}…`;
  try {
    const rig = await api.uploadRig(file);
    state.rigs[rig.id] = rig;
    const option = document.createElement('option');
    option.value = rig.id;
    option.dataset.uploaded = 'true';
    option.textContent = `${rig.filename} (yours)`;
    $('rig').append(option);
    $('rig').value = rig.id;
    $('rig-status').textContent = `${rig.filename}: rig ${rig.id.slice(0, 8)}…`;
    showMapping(rig);
    showRigDownloads();
  } catch (err) {
    $('rig-status').textContent = `${file.name} was refused: ${err.message}`;
    throw err;
  } finally {
    e.target.value = '';
  }
}));

$('take-pose').addEventListener('click', () => {
  if (!slots.a) return;
  const { motion, job } = slots.a;
  const frame = Math.min(motion.num_frames - 1, Math.round(animationTime * motion.fps));
  choose(motion.positions[frame], `dance ${job.id.slice(0, 8)} @ ${(frame / motion.fps).toFixed(2)} s`);
  document.getElementById('dance-section').scrollIntoView({ behavior: 'smooth' });
});

$('compare').addEventListener('change', guard(async (e) => {
  const id = e.target.value;
  if (id) return openJob(id, 'b');
  $('view-b').hidden = true;
  $('report-b').hidden = true;
  slots.b = null;
  const url = new URL(location.href);
  url.searchParams.delete('compare');
  history.replaceState(null, '', url);
  return undefined;
}));

// ---------------------------------------------------------------- jobs on the server
async function refreshJobs() {
  const page = await api.jobs({ limit: 50 });
  state.jobs = page.items.filter((j) => j.kind === 'generate');
  const done = state.jobs.filter((j) => j.status === 'succeeded');
  // Key poses come after a first dance: before one exists the panel would crowd out the song.
  if (done.length > 0) $('keys-box').hidden = false;
  const label = (j) => `${j.model} · seed ${j.seed} · ${j.id.slice(0, 8)}`;
  const keep = (select, first) => {
    const value = select.value;
    select.replaceChildren(...first, ...done.map((j) => new Option(label(j), j.id)));
    if ([...select.options].some((o) => o.value === value)) select.value = value;
  };
  keep($('compare'), [new Option('(none)', '')]);
  keep($('pose-job-select'), [new Option('(choose a dance)', '')]);
  $('jobs-list').replaceChildren(...state.jobs.map((j) => {
    const tr = document.createElement('tr');
    for (const text of [new Date(j.created_at).toLocaleString(), j.model, String(j.seed), j.status]) {
      tr.insertCell().textContent = text;
    }
    const actions = tr.insertCell();
    if (j.status === 'succeeded') {
      const link = document.createElement('a');
      link.href = `?job=${j.id}`;
      link.textContent = 'open';
      link.addEventListener('click', (e) => { e.preventDefault(); openJob(j.id, 'a'); });
      const compare = document.createElement('button');
      compare.type = 'button';
      compare.textContent = 'compare';
      compare.addEventListener('click', () => openJob(j.id, 'b'));
      actions.append(link, ' ', compare);
    }
    return tr;
  }));
}
$('jobs-refresh').addEventListener('click', guard(refreshJobs));

// ---------------------------------------------------------------- start
$('connection').addEventListener('submit', guard(async (e) => {
  e.preventDefault();
  await connect();
  await openLinked();
}));

/** Opens the dances the address names (?job=ID&compare=ID), unless they are open already. */
async function openLinked() {
  if (params.get('job') && !slots.a) await openJob(params.get('job'), 'a');
  if (params.get('compare') && !slots.b) await openJob(params.get('compare'), 'b');
}
$('api-base').value = params.get('api') ?? localStorage.getItem('choreo.api') ?? '';
// choreo.token: what the field was called before API keys; its value is a bearer secret too.
$('api-key').value = localStorage.getItem('choreo.key') ?? localStorage.getItem('choreo.token') ?? '';
renderKeys();
setCursor(0);

/** For tests and tools: the player's clocks and state. */
window.choreoPlayer = {
  /** The song's position, seconds (the audio element's currentTime). */
  get audioTime() { return audio.currentTime; },
  /** The time of the pose on screen, seconds (the animation's time at the last drawn frame). */
  get animationTime() { return animationTime; },
  get duration() { return slots.a ? stages.a.duration : 0; },
  get playing() { return !audio.paused; },
  get jobId() { return slots.a?.job.id ?? null; },
  get compareJobId() { return slots.b?.job.id ?? null; },
  /** Frames drawn since the page loaded. */
  get renderedFrames() { return renderedFrames; },
  /** How long the last drawn frame took, milliseconds (from reading the audio clock to the end). */
  get frameMs() { return frameMs; },
  /** A joint's world position (metres) in the main view, as drawn. */
  joint: (name) => stages.a.joint(name),
  /** The main view's mannequin now (Stage.figure), or null. */
  figure: (names) => stages.a.figure(names),
  /** 'figure' or 'sticks': what the main view draws. */
  get view() { return stages.a.shown; },
  /** The stick view's limbs in the main view, [from, to] joint names. */
  limbs: () => stages.a.limbs(),
  /** The key poses placed so far: [{time_s, joints, label}] (copies). */
  get keyPoses() { return state.keys.map((k) => ({ ...k, joints: clonePose(k.joints) })); },
  /** Where joint `name` of the selected key pose is drawn in the editor, client pixels. */
  keyEditorPoint: (name) => editor.clientPoint(JOINT_NAMES.indexOf(name)),
  play: () => audio.play(),
  pause: () => audio.pause(),
  seek,
};

guard(async () => {
  await connect();
  await openLinked();
})();
