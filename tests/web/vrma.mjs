// A job's motion.vrma in a real VRM runtime: Debian's chromium loads it with
// @pixiv/three-vrm-animation (VRMAnimationLoaderPlugin + createVRMAnimationClip) and plays it on a
// humanoid this page builds (three-vrm-core's VRMHumanoid over plain three.js bones, proportions
// unlike choreo's `vrm` target, no upperChest nor toes, rest bones turned so the normalized rig has
// work to do); node then compares the humanoid's bone directions with motion.json's.
//
// Run by tests/api/retarget.rs: node tests/web/vrma.mjs VRMA MOTION_JSON OUT_JSON
// Prints nothing on success but the summary; exits non-zero on any failure.
import { chromium } from 'playwright-core';
import { createServer } from 'node:http';
import { readFileSync, writeFileSync } from 'node:fs';
import { join, dirname, extname } from 'node:path';
import { fileURLToPath } from 'node:url';

const [vrmaPath, motionPath, outPath] = process.argv.slice(2);
if (!outPath) throw new Error('usage: node vrma.mjs VRMA MOTION_JSON OUT_JSON');
const CHROMIUM = process.env.CHROMIUM || '/usr/bin/chromium';
const here = dirname(fileURLToPath(import.meta.url));
const modules = join(here, 'node_modules');
const FPS = 25;

// The page: an import map onto the pinned npm packages, and the check itself.
const page = `<!doctype html><meta charset="utf-8"><title>vrma</title>
<script type="importmap">{"imports": {
  "three": "/m/three/build/three.module.js",
  "three/addons/": "/m/three/examples/jsm/",
  "@pixiv/three-vrm-core": "/m/@pixiv/three-vrm-core/lib/three-vrm-core.module.js",
  "@pixiv/three-vrm-animation": "/m/@pixiv/three-vrm-animation/lib/three-vrm-animation.module.js"
}}</script>
<script type="module">
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { VRMHumanoid, VRMCore } from '@pixiv/three-vrm-core';
import { VRMAnimationLoaderPlugin, createVRMAnimationClip } from '@pixiv/three-vrm-animation';

window.run = async (frames) => {
  // A humanoid unlike choreo's vrm target: shorter legs, longer arms, wider shoulders; every raw
  // bone's rest rotation turned 30° about an axis of its own while its children keep their T-pose
  // positions, as avatars exported from other tools have.
  const T = {
    hips: [null, [0, 0.90, 0]], spine: ['hips', [0, 1.00, 0.01]], chest: ['spine', [0, 1.15, 0]],
    neck: ['chest', [0, 1.45, 0]], head: ['neck', [0, 1.55, 0.02]],
    leftShoulder: ['chest', [0.05, 1.38, 0]], leftUpperArm: ['leftShoulder', [0.20, 1.40, 0]],
    leftLowerArm: ['leftUpperArm', [0.52, 1.40, 0]], leftHand: ['leftLowerArm', [0.80, 1.40, 0]],
    rightShoulder: ['chest', [-0.05, 1.38, 0]], rightUpperArm: ['rightShoulder', [-0.20, 1.40, 0]],
    rightLowerArm: ['rightUpperArm', [-0.52, 1.40, 0]], rightHand: ['rightLowerArm', [-0.80, 1.40, 0]],
    leftUpperLeg: ['hips', [0.10, 0.84, 0]], leftLowerLeg: ['leftUpperLeg', [0.10, 0.46, 0]],
    leftFoot: ['leftLowerLeg', [0.10, 0.07, 0]],
    rightUpperLeg: ['hips', [-0.10, 0.84, 0]], rightLowerLeg: ['rightUpperLeg', [-0.10, 0.46, 0]],
    rightFoot: ['rightLowerLeg', [-0.10, 0.07, 0]],
  };
  const scene = new THREE.Scene();
  const bones = {};
  const world = {};
  let k = 0;
  for (const [name, [parent, pos]] of Object.entries(T)) {
    const bone = new THREE.Bone();
    bone.name = 'raw_' + name;
    // World rest rotation of this bone; its local one is relative to the parent's.
    const q = new THREE.Quaternion().setFromAxisAngle(new THREE.Vector3(Math.sin(k), Math.cos(k), 0.5).normalize(), Math.PI / 6);
    k += 1;
    world[name] = { p: new THREE.Vector3(...pos), q };
    if (parent) {
      const pw = world[parent];
      bone.position.copy(new THREE.Vector3(...pos).sub(pw.p).applyQuaternion(pw.q.clone().invert()));
      bone.quaternion.copy(pw.q.clone().invert().multiply(q));
      bones[parent].add(bone);
    } else {
      bone.position.set(...pos);
      bone.quaternion.copy(q);
      scene.add(bone);
    }
    bones[name] = bone;
  }
  scene.updateMatrixWorld(true);
  const humanoid = new VRMHumanoid(Object.fromEntries(Object.entries(bones).map(([n, node]) => [n, { node }])));
  scene.add(humanoid.normalizedHumanBonesRoot);
  const vrm = new VRMCore({ scene, meta: { metaVersion: '1' }, humanoid });

  const loader = new GLTFLoader();
  loader.register((parser) => new VRMAnimationLoaderPlugin(parser));
  const gltf = await loader.loadAsync('/motion.vrma');
  const animations = gltf.userData.vrmAnimations;
  if (!animations || animations.length !== 1) throw new Error('expected one VRM animation, got ' + (animations && animations.length));
  const clip = createVRMAnimationClip(animations[0], vrm);
  const mixer = new THREE.AnimationMixer(vrm.scene);
  mixer.clipAction(clip).play();
  const out = { duration: clip.duration, tracks: clip.tracks.length, frames: [] };
  const p = (n) => bones[n].getWorldPosition(new THREE.Vector3()).toArray();
  for (const f of frames) {
    mixer.setTime(f / ${FPS});
    vrm.update(0);
    scene.updateMatrixWorld(true);
    out.frames.push(Object.fromEntries(Object.keys(T).map((n) => [n, p(n)])));
  }
  return out;
};
window.ready = true;
</script>`;

const server = createServer((req, res) => {
  const url = new URL(req.url, 'http://x');
  let body;
  let type = 'text/javascript';
  if (url.pathname === '/') { body = page; type = 'text/html'; }
  else if (url.pathname === '/favicon.ico') { res.writeHead(204); res.end(); return; }
  else if (url.pathname === '/motion.vrma') { body = readFileSync(vrmaPath); type = 'model/gltf-binary'; }
  else if (url.pathname.startsWith('/m/') && !url.pathname.includes('..')) {
    try { body = readFileSync(join(modules, url.pathname.slice(3))); } catch { body = null; }
    if (extname(url.pathname) !== '.js') type = 'application/octet-stream';
  }
  if (body == null) { res.writeHead(404); res.end(); return; }
  res.writeHead(200, { 'content-type': type });
  res.end(body);
});
await new Promise((r) => server.listen(0, '127.0.0.1', r));
const origin = `http://127.0.0.1:${server.address().port}`;

const motion = JSON.parse(readFileSync(motionPath, 'utf8'));
const n = motion.num_frames;
const frames = Array.from({ length: 40 }, (_, i) => Math.floor((i * (n - 1)) / 39));
const browser = await chromium.launch({ executablePath: CHROMIUM, args: ['--no-sandbox'] });
let result;
try {
  const tab = await browser.newPage();
  const errors = [];
  tab.on('pageerror', (e) => errors.push(e.message));
  tab.on('console', (m) => { if (m.type() === 'error') errors.push(m.text()); });
  await tab.goto(origin + '/');
  await tab.waitForFunction(() => window.ready === true, null, { timeout: 30_000 });
  result = await tab.evaluate((f) => window.run(f), frames);
  if (errors.length) throw new Error('page errors: ' + errors.join('; '));
} finally {
  await browser.close();
  server.close();
}

// Bone directions: the humanoid's against motion.json's (choreo joints).
const idx = Object.fromEntries(motion.joint_names.map((name, i) => [name, i]));
const sub = (a, b) => a.map((v, i) => v - b[i]);
const angle = (a, b) => {
  const d = a.reduce((s, v, i) => s + v * b[i], 0) / Math.hypot(...a) / Math.hypot(...b);
  return (Math.acos(Math.max(-1, Math.min(1, d))) * 180) / Math.PI;
};
const pairs = {
  leftUpperArm: [['left_shoulder', 'left_elbow'], ['leftUpperArm', 'leftLowerArm']],
  leftLowerArm: [['left_elbow', 'left_wrist'], ['leftLowerArm', 'leftHand']],
  rightUpperArm: [['right_shoulder', 'right_elbow'], ['rightUpperArm', 'rightLowerArm']],
  rightLowerArm: [['right_elbow', 'right_wrist'], ['rightLowerArm', 'rightHand']],
  leftUpperLeg: [['left_hip', 'left_knee'], ['leftUpperLeg', 'leftLowerLeg']],
  leftLowerLeg: [['left_knee', 'left_ankle'], ['leftLowerLeg', 'leftFoot']],
  rightUpperLeg: [['right_hip', 'right_knee'], ['rightUpperLeg', 'rightLowerLeg']],
  rightLowerLeg: [['right_knee', 'right_ankle'], ['rightLowerLeg', 'rightFoot']],
  spine: [['spine', 'left_shoulder'], ['spine', 'leftUpperArm']],
};
const median = (v) => { const s = [...v].sort((a, b) => a - b); return s[Math.floor(s.length / 2)]; };
const summary = { duration: result.duration, tracks: result.tracks, frames: frames.length, median_deg: {}, max_deg: {} };
for (const [bone, [[ca, cb], [ta, tb]]] of Object.entries(pairs)) {
  const errs = frames.map((f, i) => {
    const P = motion.positions[f];
    const H = result.frames[i];
    return angle(sub(P[idx[cb]], P[idx[ca]]), sub(H[tb], H[ta]));
  });
  summary.median_deg[bone] = median(errs);
  summary.max_deg[bone] = Math.max(...errs);
}
// Where the hips went: the avatar's hips height over the dance's, scaled by the avatar's size.
summary.hips_y = result.frames.map((fr) => fr.hips[1]);
writeFileSync(outPath, JSON.stringify(summary, null, 1));
console.log(JSON.stringify({ median_deg: summary.median_deg, max_deg: summary.max_deg, tracks: summary.tracks }));
