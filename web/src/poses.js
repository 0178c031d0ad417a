// Poses in motion.json's layout (26 joints, its joint_names order, metres, y up): drawn as stick
// figures (front view), and edited by dragging joints.
import library from './poses.json';

export const JOINT_NAMES = library.joint_names;
export const PARENTS = library.parents;
export const LIBRARY = library.poses;

/** A deep copy of a pose. */
export const clonePose = (joints) => joints.map((p) => [p[0], p[1], p[2]]);

const sideColour = (name) => (name.startsWith('left_') ? '#2b6cb0' : name.startsWith('right_') ? '#d4662a' : '#444');

/** The canvas transform for a pose: body centre in the middle, the floor (y = 0) near the bottom. */
function frame(canvas, joints) {
  const scale = canvas.height / 2.3; // px per metre: room for a 2 m dancer and a raised arm
  const cx = joints[0][0];
  return {
    scale,
    px: (p) => [canvas.width / 2 + (p[0] - cx) * scale, canvas.height - 12 - p[1] * scale],
    metres: (x, y) => [cx + (x - canvas.width / 2) / scale, (canvas.height - 12 - y) / scale],
  };
}

/** Draws a pose, front view, over a floor line; `highlight` rings one joint. */
export function drawPose(canvas, joints, { highlight = -1, label = '' } = {}) {
  const g = canvas.getContext('2d');
  g.clearRect(0, 0, canvas.width, canvas.height);
  g.fillStyle = '#fbfaf6';
  g.fillRect(0, 0, canvas.width, canvas.height);
  if (!joints) return;
  const f = frame(canvas, joints);
  g.strokeStyle = '#c9c3b4';
  g.lineWidth = 1;
  g.beginPath();
  g.moveTo(0, canvas.height - 12);
  g.lineTo(canvas.width, canvas.height - 12);
  g.stroke();
  const width = Math.max(2, canvas.height / 80);
  PARENTS.forEach((parent, j) => {
    if (parent < 0) return;
    const [x0, y0] = f.px(joints[parent]);
    const [x1, y1] = f.px(joints[j]);
    g.strokeStyle = sideColour(JOINT_NAMES[j]);
    g.lineWidth = width;
    g.lineCap = 'round';
    g.beginPath();
    g.moveTo(x0, y0);
    g.lineTo(x1, y1);
    g.stroke();
  });
  // The head: a circle around the midpoint of the two head markers.
  const [hx, hy] = f.px(joints[1].map((v, k) => (v + joints[2][k]) / 2));
  g.strokeStyle = '#444';
  g.lineWidth = width;
  g.beginPath();
  g.arc(hx, hy, 0.1 * f.scale, 0, Math.PI * 2);
  g.stroke();
  joints.forEach((p, j) => {
    const [x, y] = f.px(p);
    g.fillStyle = j === highlight ? '#0a7d32' : '#222';
    g.beginPath();
    g.arc(x, y, j === highlight ? width * 1.8 : width * 0.9, 0, Math.PI * 2);
    g.fill();
  });
  if (label) {
    g.fillStyle = '#555';
    g.font = `${Math.max(10, canvas.height / 22)}px sans-serif`;
    g.fillText(label, 4, 14);
  }
}

const CHILDREN = PARENTS.map((_, j) => PARENTS.flatMap((p, c) => (p === j ? [c] : [])));

/** The joint and every joint hanging from it. */
function subtree(j) {
  const out = [j];
  for (let i = 0; i < out.length; i++) out.push(...CHILDREN[out[i]]);
  return out;
}

/**
 * A pose editor on a canvas: drag a joint and it turns about its parent in the front (x–y)
 * plane, carrying every joint below it, so bone lengths stay as they were.
 */
export class PoseEditor {
  constructor(canvas, onChange) {
    this.canvas = canvas;
    this.onChange = onChange;
    this.joints = null;
    this.active = -1;
    this.listen();
  }

  show(joints) {
    this.joints = joints;
    this.active = -1;
    drawPose(this.canvas, joints);
  }

  /** Where joint `j` is drawn, in client (page) pixels: for tests that drag it. */
  clientPoint(j) {
    if (!this.joints) return null;
    const rect = this.canvas.getBoundingClientRect();
    const [x, y] = frame(this.canvas, this.joints).px(this.joints[j]);
    return [rect.left + (x / this.canvas.width) * rect.width, rect.top + (y / this.canvas.height) * rect.height];
  }

  canvasPoint(e) {
    const rect = this.canvas.getBoundingClientRect();
    return [((e.clientX - rect.left) / rect.width) * this.canvas.width, ((e.clientY - rect.top) / rect.height) * this.canvas.height];
  }

  listen() {
    let drag = null;
    this.canvas.addEventListener('pointerdown', (e) => {
      if (!this.joints) return;
      const [x, y] = this.canvasPoint(e);
      const f = frame(this.canvas, this.joints);
      let best = -1, bestD = 12;
      this.joints.forEach((p, j) => {
        if (PARENTS[j] < 0) return; // the body centre is the pose's origin
        const [px, py] = f.px(p);
        const d = Math.hypot(px - x, py - y);
        if (d < bestD) { best = j; bestD = d; }
      });
      if (best < 0) return;
      this.canvas.setPointerCapture(e.pointerId);
      drag = { joint: best, f };
      this.active = best;
      drawPose(this.canvas, this.joints, { highlight: best });
    });
    this.canvas.addEventListener('pointermove', (e) => {
      if (!drag) return;
      const [x, y] = this.canvasPoint(e);
      const [mx, my] = drag.f.metres(x, y);
      const j = drag.joint, pivot = this.joints[PARENTS[j]];
      const now = Math.atan2(this.joints[j][1] - pivot[1], this.joints[j][0] - pivot[0]);
      const want = Math.atan2(my - pivot[1], mx - pivot[0]);
      if (Math.hypot(this.joints[j][0] - pivot[0], this.joints[j][1] - pivot[1]) < 1e-4) return;
      const a = want - now, c = Math.cos(a), s = Math.sin(a);
      for (const k of subtree(j)) {
        const dx = this.joints[k][0] - pivot[0], dy = this.joints[k][1] - pivot[1];
        this.joints[k][0] = pivot[0] + c * dx - s * dy;
        this.joints[k][1] = pivot[1] + s * dx + c * dy;
      }
      drawPose(this.canvas, this.joints, { highlight: j });
    });
    const end = () => {
      if (!drag) return;
      drag = null;
      this.onChange?.(this.joints);
    };
    this.canvas.addEventListener('pointerup', end);
    this.canvas.addEventListener('pointercancel', end);
  }
}
