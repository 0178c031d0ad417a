// Derives the page's small library of key poses from the real dataset's train split.
//
//   node tools/pose-library.mjs ../../shared/data/dance-with-melody src/poses.json   (npm run poses)
//
// Candidates are every 25th frame (one a second) of every train dance. 36 are picked by
// farthest-point sampling on the body-centre-relative pose (mean joint distance), starting from
// the frame nearest the mean pose, then refined by a few k-medoids rounds (each pick replaced by
// the medoid of the candidates nearest it); the 24 largest groups (of at least 10) are kept: the
// library spans the train split's range of poses, and each pose is a typical one of its group
// rather than a rare extreme (or a capture glitch).
// Deterministic: the same data gives the same file.
// Poses are written in motion.json's 26-joint layout (see src/motion/rig.rs): the body centre
// at (0, its height, 0), the 23 dataset joints, then pelvis and neck (both at the spine), in
// metres, so the API takes them as `key_poses[].joints` as they are.
import { readFileSync, writeFileSync } from 'node:fs';
import { join } from 'node:path';

const COUNT = 24;
// Picks before pruning: groups of fewer than MIN_GROUP candidates are rare extremes (or capture
// glitches) and are dropped; the COUNT largest groups are kept.
const PICKS = 36;
const MIN_GROUP = 10;
const STEP = 25;
const STYLES = { C: 'cha-cha', R: 'rumba', T: 'tango', W: 'waltz' };
// motion.json's joint_names and parents (src/motion/rig.rs): body_centre, the dataset's 23, pelvis, neck.
const JOINT_NAMES = [
  'body_centre', 'head_right', 'head_left', 'spine', 'right_shoulder', 'right_elbow', 'right_forearm',
  'right_wrist', 'right_hip', 'right_knee', 'right_ankle', 'right_heel', 'right_toe', 'left_shoulder',
  'left_elbow', 'left_forearm', 'left_wrist', 'left_hip', 'left_knee', 'left_ankle', 'left_heel',
  'left_toe', 'left_hand_dir', 'right_hand_dir', 'pelvis', 'neck',
];
const PARENTS = [-1, 2, 25, 0, 3, 4, 5, 6, 24, 8, 9, 10, 10, 3, 13, 14, 15, 24, 17, 18, 19, 19, 14, 7, 0, 3];
const SPINE = 2; // dataset index

/** Reads a little-endian float32 .npy file: { shape, data }. */
function readNpy(path) {
  const buf = readFileSync(path);
  if (buf.toString('latin1', 0, 6) !== '\x93NUMPY') throw new Error(`${path}: not an .npy file`);
  const major = buf[6];
  const headerLen = major === 1 ? buf.readUInt16LE(8) : buf.readUInt32LE(8);
  const start = major === 1 ? 10 : 12;
  const header = buf.toString('latin1', start, start + headerLen);
  if (!header.includes("'descr': '<f4'") || header.includes("'fortran_order': True")) {
    throw new Error(`${path}: expected little-endian float32 in C order, got ${header}`);
  }
  const shape = header.match(/'shape': \(([^)]*)\)/)[1].split(',').map((s) => s.trim()).filter(Boolean).map(Number);
  const offset = start + headerLen;
  const data = new Float32Array(buf.buffer.slice(buf.byteOffset + offset, buf.byteOffset + buf.length));
  return { shape, data };
}

const [dataDir, outPath] = process.argv.slice(2);
if (!dataDir || !outPath) {
  console.error('usage: node tools/pose-library.mjs DATA_DIR OUT.json');
  process.exit(2);
}
const split = JSON.parse(readFileSync(join(dataDir, 'split.json'), 'utf8'));

const candidates = [];
for (const dance of split.train) {
  const skel = readNpy(join(dataDir, dance, 'skeletons.npy'));
  const centre = readNpy(join(dataDir, dance, 'center.npy'));
  const [frames, joints] = skel.shape;
  if (joints !== 23) throw new Error(`${dance}: expected 23 joints, got ${joints}`);
  for (let t = 0; t < frames; t += STEP) {
    // Body-centre-relative joints, centimetres → metres.
    const rel = Array.from(skel.data.subarray(t * 69, t * 69 + 69), (v) => v / 100);
    candidates.push({ dance, frame: t, rel, height: centre.data[t * 3 + 1] / 100 });
  }
}

function distance(a, b) {
  let sum = 0;
  for (let j = 0; j < 23; j++) {
    const dx = a[j * 3] - b[j * 3], dy = a[j * 3 + 1] - b[j * 3 + 1], dz = a[j * 3 + 2] - b[j * 3 + 2];
    sum += Math.sqrt(dx * dx + dy * dy + dz * dz);
  }
  return sum / 23;
}

const mean = new Array(69).fill(0);
for (const c of candidates) c.rel.forEach((v, i) => { mean[i] += v / candidates.length; });
let first = 0;
candidates.forEach((c, i) => { if (distance(c.rel, mean) < distance(candidates[first].rel, mean)) first = i; });

const chosen = [first];
const nearest = candidates.map((c) => distance(c.rel, candidates[first].rel));
while (chosen.length < Math.min(PICKS, candidates.length)) {
  let best = 0;
  nearest.forEach((d, i) => { if (d > nearest[best]) best = i; });
  chosen.push(best);
  candidates.forEach((c, i) => { nearest[i] = Math.min(nearest[i], distance(c.rel, candidates[best].rel)); });
}

// k-medoids rounds: assign every candidate to its nearest pick, move each pick to its group's medoid.
for (let round = 0; round < 5; round++) {
  const groups = chosen.map(() => []);
  candidates.forEach((c, i) => {
    let g = 0;
    chosen.forEach((k, n) => { if (distance(c.rel, candidates[k].rel) < distance(c.rel, candidates[chosen[g]].rel)) g = n; });
    groups[g].push(i);
  });
  let moved = 0;
  groups.forEach((members, n) => {
    let best = chosen[n], bestCost = Infinity;
    for (const m of members) {
      let cost = 0;
      for (const o of members) cost += distance(candidates[m].rel, candidates[o].rel);
      if (cost < bestCost) { bestCost = cost; best = m; }
    }
    if (best !== chosen[n]) moved++;
    chosen[n] = best;
    candidates[best].group = members.length;
  });
  if (moved === 0) break;
}

const round = (v) => Math.round(v * 1000) / 1000;
const kept = chosen
  .filter((i) => candidates[i].group >= MIN_GROUP)
  .sort((a, b) => candidates[b].group - candidates[a].group)
  .slice(0, COUNT)
  .sort((a, b) => candidates[a].dance.localeCompare(candidates[b].dance) || candidates[a].frame - candidates[b].frame);
const poses = kept.map((i) => {
  const c = candidates[i];
  const centre = [0, c.height, 0];
  const joint = (j) => [0, 1, 2].map((k) => round(centre[k] + c.rel[j * 3 + k]));
  const joints = [centre.map(round)];
  for (let j = 0; j < 23; j++) joints.push(joint(j));
  joints.push(joint(SPINE), joint(SPINE)); // pelvis and neck sit at the spine
  const style = STYLES[c.dance.split('_')[1]] ?? 'unknown';
  return { name: `${style} · ${c.dance} frame ${c.frame}`, dance: c.dance, frame: c.frame, style, group: c.group, joints };
});

const out = {
  source: `dance-with-melody train split (${split.train.length} dances): ${poses.length} medoid poses of every ${STEP}th frame, by web/tools/pose-library.mjs`,
  joint_names: JOINT_NAMES,
  parents: PARENTS,
  poses,
};
writeFileSync(outPath, JSON.stringify(out) + '\n');
console.log(`${poses.length} poses from ${candidates.length} candidate frames → ${outPath}`);
