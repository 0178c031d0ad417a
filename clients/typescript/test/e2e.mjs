// The client against a real choreo server (run by tests/web.rs, which starts the server):
// uploads a song from disk, waits for its analysis, asks for a dance, waits for it (its
// server-sent events when the server has them), and downloads motion.glb and motion.json; then
// uploads a rig, lists it, downloads the dance on it and deletes it.
//
//   API_URL=http://127.0.0.1:PORT API_KEY=… SONG=path MODEL=id [EXPECT_EVENTS=1] node test/e2e.mjs
//
// Prints one JSON summary line (prefixed "summary: ") and exits 0, or prints why and exits 1.
import { openAsBlob } from 'node:fs';
import { basename } from 'node:path';
import { fileURLToPath } from 'node:url';
import { ApiError, Choreo } from '../dist/index.js';

const env = (name) => {
  const value = process.env[name];
  if (!value) throw new Error(`${name} is not set`);
  return value;
};
function check(condition, message) {
  if (!condition) throw new Error(`check failed: ${message}`);
}

const choreo = new Choreo({ baseUrl: env('API_URL'), apiKey: process.env.API_KEY });
const song = await choreo.upload(await openAsBlob(env('SONG')), basename(env('SONG')));
check(song.id && song.duration_s > 1, `uploaded: ${JSON.stringify(song)}`);
const analysed = await choreo.waitForSong(song.id);
check(analysed.analysis, `analysed: ${analysed.analysis_status} ${analysed.analysis_error}`);

const job = await choreo.createJob({ song_id: song.id, model: env('MODEL'), seed: 5 });
check(job.status === 'queued' || job.status === 'running', `created: ${JSON.stringify(job)}`);
const events = [];
const updates = [];
const done = await choreo.wait(job.id, { onEvent: (e) => events.push(e), onUpdate: (j) => updates.push([j.status, j.stage ?? null, j.progress]) });
check(done.status === 'succeeded', `the job ended ${done.status}: ${done.error}`);
check(done.id === job.id && done.links.motion_glb, `the final view: ${JSON.stringify(done)}`);
if (process.env.EXPECT_EVENTS === '1') {
  check(choreo.lastTransport === 'events', `followed by ${choreo.lastTransport}, not by the server's events`);
  const seqs = events.filter((e) => e.type !== 'done').map((e) => e.data.seq);
  check(seqs.every((s, i) => i === 0 || s > seqs[i - 1]), `events in order: ${seqs}`);
  check(events.some((e) => e.type === 'progress'), `progress events: ${events.map((e) => e.type)}`);
  check(events.at(-1)?.type === 'done', 'the last event is done');
}
// Progress never goes back while the job runs.
const progress = updates.filter(([s]) => s === 'running').map(([, , p]) => p);
check(progress.every((p, i) => i === 0 || p >= progress[i - 1] - 1e-9), `progress: ${progress}`);

const glb = new Uint8Array(await (await choreo.download(job.id, 'motion.glb')).arrayBuffer());
check(new TextDecoder().decode(glb.subarray(0, 4)) === 'glTF' && glb.length > 10_000, `motion.glb: ${glb.length} bytes`);
const motion = await (await choreo.download(job.id, 'motion.json')).json();
check(motion.fps === 25 && motion.num_frames > 25 && motion.positions.length === motion.num_frames, `motion.json: ${motion.fps} fps, ${motion.num_frames} frames`);
const audio = await choreo.songAudio(song.id);
check(audio.size === (await openAsBlob(env('SONG'))).size, 'the song comes back as uploaded');

// A rig of one's own: listed once uploaded, a dance downloaded on it, gone once deleted.
const rigFile = fileURLToPath(new URL('../../../tests/fixtures/rig_unreal_cm.bvh', import.meta.url));
const rig = await choreo.uploadRig(await openAsBlob(rigFile), null, 'mannequin.bvh');
const listed = async () => (await choreo.listRigs({ limit: 100 })).items.map((r) => r.id);
check((await listed()).includes(rig.id), `the uploaded rig ${rig.id} is listed`);
const onRig = await (await choreo.download(job.id, 'motion.bvh', { rig: rig.id })).text();
check(onRig.startsWith('HIERARCHY') && onRig.includes('pelvis'), 'motion.bvh on the rig has its joints');
await choreo.deleteRig(rig.id);
check(!(await listed()).includes(rig.id), 'the deleted rig is no longer listed');
const gone = await choreo.rig(rig.id).catch((e) => e);
check(gone instanceof ApiError && gone.status === 404 && gone.code === 'rig-not-found', `the deleted rig: ${gone}`);

console.log('summary: ' + JSON.stringify({
  song_id: song.id, job_id: job.id, transport: choreo.lastTransport, events: events.map((e) => e.type),
  updates: updates.length, glb_bytes: glb.length, frames: motion.num_frames, rig_id: rig.id,
}));
