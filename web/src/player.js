// The 3-D view of one dance: three.js plays the job's motion.glb (its skeleton, its animation and
// the skinned mannequin the server builds into every glb) with an AnimationMixer. The stick view
// (setView('sticks')) draws capsules between the animated joints instead. The view never keeps
// time itself: the caller sets it from the song's audio element every frame (setTime), so the
// dance cannot drift from the music.
import {
  AmbientLight, CircleGeometry, Color, CylinderGeometry, DirectionalLight, GridHelper, Mesh,
  MeshBasicMaterial, MeshStandardMaterial, PerspectiveCamera, Scene, SphereGeometry, Vector3, WebGLRenderer,
  AnimationMixer, Quaternion, Fog,
} from 'three';
import { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';

const UP = new Vector3(0, 1, 0);
// How closely the camera follows the dancer across the floor: it closes 63 % of the gap in this
// many seconds of the dance (a critically smooth chase, not a jolt on every step), and jumps to
// the dancer when the time moves by more than FOLLOW_JUMP_S at once (a seek).
const FOLLOW_S = 0.25;
const FOLLOW_JUMP_S = 0.5;
const LIMB = new CylinderGeometry(1, 1, 1, 12);
const BALL = new SphereGeometry(1, 16, 12);
const MATERIALS = {
  left: new MeshStandardMaterial({ color: 0x2b6cb0, roughness: 0.6 }),
  right: new MeshStandardMaterial({ color: 0xd4662a, roughness: 0.6 }),
  centre: new MeshStandardMaterial({ color: 0x555555, roughness: 0.7 }),
  head: new MeshStandardMaterial({ color: 0xe8d9c0, roughness: 0.8 }),
};
// Thinner limbs for the hand-direction points and the feet; no limb for zero-length branches.
const radius = (name) => (name.includes('hand_dir') ? 0.012 : /heel|toe/.test(name) ? 0.02 : /head/.test(name) ? 0.015 : 0.035);
const side = (name) => (name.startsWith('left_') ? 'left' : name.startsWith('right_') ? 'right' : 'centre');

let software = null;
/** Whether WebGL here is rasterised in software (once per page, from a throwaway context). */
function softwareRendering() {
  if (software === null) {
    const gl = document.createElement('canvas').getContext('webgl2');
    const info = gl?.getExtension('WEBGL_debug_renderer_info');
    const name = gl ? String(gl.getParameter(info ? info.UNMASKED_RENDERER_WEBGL : gl.RENDERER)) : '';
    software = /swiftshader|llvmpipe|software/i.test(name);
    gl?.getExtension('WEBGL_lose_context')?.loseContext();
  }
  return software;
}

export class Stage {
  constructor(container) {
    this.container = container;
    // A software rasteriser (no GPU: SwiftShader, llvmpipe) spends most of a frame on
    // multisampling and then stalls the page; there the figure is drawn without it.
    this.renderer = new WebGLRenderer({ antialias: !softwareRendering() });
    this.renderer.setPixelRatio(Math.min(2, window.devicePixelRatio || 1));
    container.appendChild(this.renderer.domElement);
    this.scene = new Scene();
    this.scene.background = new Color(0xf3f0e8);
    // The floor fades into the background instead of ending in a band of grid lines.
    this.scene.fog = new Fog(0xf3f0e8, 5, 12);
    this.camera = new PerspectiveCamera(40, 1, 0.05, 100);
    this.camera.position.set(0, 1.5, 4.5);
    this.controls = new OrbitControls(this.camera, this.renderer.domElement);
    this.controls.target.set(0, 1, 0);
    this.controls.update();
    this.scene.add(new AmbientLight(0xffffff, 1.2));
    const sun = new DirectionalLight(0xffffff, 2.2);
    sun.position.set(2, 5, 3);
    this.scene.add(sun);
    const grid = new GridHelper(20, 40, 0xb8b0a0, 0xd8d2c4);
    this.scene.add(grid);
    this.shadow = new Mesh(new CircleGeometry(0.35, 32), new MeshBasicMaterial({ color: 0x000000, transparent: true, opacity: 0.15 }));
    this.shadow.rotation.x = -Math.PI / 2;
    this.shadow.position.y = 0.002;
    this.scene.add(this.shadow);
    this.view = 'figure';
    this.shown = 'figure';
    this.clear();
    new ResizeObserver(() => this.resize()).observe(container);
    this.resize();
  }

  resize() {
    const w = Math.max(1, this.container.clientWidth), h = Math.max(1, this.container.clientHeight);
    this.renderer.setSize(w, h, true);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.render();
  }

  clear() {
    if (this.root) this.scene.remove(this.root);
    for (const part of this.parts || []) this.scene.remove(part.mesh);
    this.root = null;
    this.parts = [];
    this.figures = [];
    this.action = null;
    this.duration = 0;
    this.followedAt = null;
    this.render();
  }

  /** Loads a motion.glb (bytes); returns the clip's duration in seconds. */
  async load(glb) {
    this.clear();
    const gltf = await new GLTFLoader().parseAsync(glb, '');
    const clip = gltf.animations[0];
    if (!clip) throw new Error('motion.glb has no animation');
    this.root = gltf.scene;
    this.scene.add(this.root);
    this.mixer = new AnimationMixer(this.root);
    this.action = this.mixer.clipAction(clip);
    this.action.play();
    this.duration = clip.duration;
    // Only the skeleton's joints (GLTFLoader makes every skin joint a Bone): the scene node and
    // the mannequin's node are not joints, so no limb is drawn from the origin to the root.
    this.bones = {};
    this.figures = [];
    this.root.traverse((node) => {
      if (node.isBone && node.name) this.bones[node.name] = node;
      if (node.isSkinnedMesh) {
        // Its bounding sphere is the rest pose's; the dancer leaves it, so never cull it.
        node.frustumCulled = false;
        this.figures.push(node);
      }
    });
    this.centre = this.bones.body_centre ?? Object.values(this.bones).find((b) => !b.parent?.isBone) ?? this.root;
    for (const node of Object.values(this.bones)) {
      const parent = node.parent;
      if (!parent?.isBone) continue;
      const mesh = new Mesh(LIMB, MATERIALS[side(node.name)]);
      this.scene.add(mesh);
      this.parts.push({ kind: 'limb', mesh, from: parent, to: node, r: radius(node.name) });
    }
    if (this.bones.head_left && this.bones.head_right) {
      const mesh = new Mesh(BALL, MATERIALS.head);
      mesh.scale.setScalar(0.11);
      this.scene.add(mesh);
      this.parts.push({ kind: 'head', mesh, a: this.bones.head_left, b: this.bones.head_right });
    }
    for (const name of ['left_wrist', 'right_wrist', 'left_knee', 'right_knee', 'left_elbow', 'right_elbow']) {
      if (!this.bones[name]) continue;
      const mesh = new Mesh(BALL, MATERIALS[side(name)]);
      mesh.scale.setScalar(0.045);
      this.scene.add(mesh);
      this.parts.push({ kind: 'ball', mesh, at: this.bones[name] });
    }
    this.setView(this.view);
    this.setTime(0);
    const centre = this.centre.getWorldPosition(new Vector3());
    this.controls.target.set(centre.x, 0.95, centre.z);
    this.camera.position.set(centre.x, 1.35, centre.z + 3.4);
    this.controls.update();
    return this.duration;
  }

  /** Shows the pose at `t` seconds (clamped to the dance); returns the animation time it shows. */
  setTime(t) {
    if (!this.action) return 0;
    this.action.time = Math.min(Math.max(0, t), this.duration);
    this.mixer.update(0);
    this.root.updateMatrixWorld(true);
    const a = new Vector3(), b = new Vector3(), d = new Vector3(), q = new Quaternion();
    for (const part of this.parts) {
      if (part.kind === 'limb') {
        part.from.getWorldPosition(a);
        part.to.getWorldPosition(b);
        d.subVectors(b, a);
        const length = d.length();
        part.mesh.visible = this.shown === 'sticks' && length > 0.01;
        if (!part.mesh.visible) continue;
        part.mesh.position.addVectors(a, b).multiplyScalar(0.5);
        part.mesh.quaternion.copy(q.setFromUnitVectors(UP, d.divideScalar(length)));
        part.mesh.scale.set(part.r, length, part.r);
      } else if (part.kind === 'head') {
        part.a.getWorldPosition(a);
        part.b.getWorldPosition(b);
        part.mesh.position.addVectors(a, b).multiplyScalar(0.5);
      } else {
        part.at.getWorldPosition(part.mesh.position);
      }
    }
    // The camera follows the dancer across the floor, keeping the angle the user gave it: by the
    // dance's time, so a seek lands on the dancer wherever they travelled (a dancenet dance
    // reaches 5.6 m from its start) and a slow display frame rate does not lose them.
    const centre = this.centre.getWorldPosition(a);
    this.shadow.position.x = centre.x;
    this.shadow.position.z = centre.z;
    const moved = this.followedAt === null ? Infinity : Math.abs(this.action.time - this.followedAt);
    const gain = moved > FOLLOW_JUMP_S ? 1 : 1 - Math.exp(-moved / FOLLOW_S);
    this.followedAt = this.action.time;
    const shift = new Vector3(centre.x - this.controls.target.x, 0, centre.z - this.controls.target.z).multiplyScalar(gain);
    this.controls.target.add(shift);
    this.camera.position.add(shift);
    this.controls.update();
    return this.action.time;
  }

  /** 'figure' (the skinned mannequin) or 'sticks' (capsules between the joints); a glb without a
   * mannequin is always drawn as sticks. Returns the view shown. */
  setView(view = 'figure') {
    this.view = view;
    const figure = view === 'figure' && this.figures.length > 0;
    for (const mesh of this.figures) mesh.visible = figure;
    for (const part of this.parts) part.mesh.visible = !figure;
    this.shown = figure ? 'figure' : 'sticks';
    this.render();
    return this.shown;
  }

  /** The mannequin as drawn now: whether it is shown, its triangle count, and for each named
   * joint the skinned world position of the mesh vertex nearest that joint at rest (the bind
   * pose), with that joint's own position now: a skin that follows its skeleton keeps the two
   * together. Null without a mannequin. */
  figure(names = []) {
    const mesh = this.figures[0];
    if (!mesh) return null;
    this.root.updateMatrixWorld(true);
    const positions = mesh.geometry.getAttribute('position');
    const v = new Vector3();
    const joints = {};
    for (const name of names) {
      const bone = this.bones[name];
      const index = bone ? mesh.skeleton.bones.indexOf(bone) : -1;
      if (index < 0) continue;
      // The joint's rest position: the inverse of its inverse bind matrix, applied to the origin.
      const rest = new Vector3().applyMatrix4(mesh.skeleton.boneInverses[index].clone().invert());
      let nearest = 0, best = Infinity;
      for (let i = 0; i < positions.count; i++) {
        const d = v.fromBufferAttribute(positions, i).distanceToSquared(rest);
        if (d < best) { best = d; nearest = i; }
      }
      mesh.getVertexPosition(nearest, v); // a SkinnedMesh's applies its bones
      v.applyMatrix4(mesh.matrixWorld);
      joints[name] = { vertex: v.toArray(), joint: bone.getWorldPosition(new Vector3()).toArray(), rest_distance: Math.sqrt(best) };
    }
    return { shown: mesh.visible, triangles: (mesh.geometry.index?.count ?? 0) / 3, joints };
  }

  /** The stick view's limbs, [parent joint, joint] names: only between joints of the skeleton. */
  limbs() {
    return this.parts.filter((p) => p.kind === 'limb').map((p) => [p.from.name, p.to.name]);
  }

  /** The world position of a joint now, in metres. */
  joint(name) {
    const bone = this.bones?.[name];
    return bone ? bone.getWorldPosition(new Vector3()).toArray() : null;
  }

  /** Where a joint is drawn now, in normalised device coordinates ([x, y], −1…1 across and up
   * the view; outside that range it is off screen), or null without that joint. */
  onScreen(name) {
    const p = this.joint(name);
    if (!p) return null;
    const v = new Vector3(...p).project(this.camera);
    return [v.x, v.y];
  }

  render() {
    this.renderer.render(this.scene, this.camera);
  }
}
