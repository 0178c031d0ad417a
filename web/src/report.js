// A job's report as plots (music beats against motion beats; speed over time), its scores, and
// its files to download.

/** Mean joint speed per frame (m/s) from motion.json, over the 23 dataset joints. */
export function speeds(motion) {
  const { positions, fps } = motion;
  const out = new Float32Array(positions.length);
  for (let t = 1; t < positions.length; t++) {
    let sum = 0;
    for (let j = 1; j <= 23; j++) {
      const a = positions[t][j], b = positions[t - 1][j];
      sum += Math.hypot(a[0] - b[0], a[1] - b[1], a[2] - b[2]);
    }
    out[t] = (sum / 23) * fps;
  }
  out[0] = out[1] ?? 0;
  // Half a beat of smoothing (5 frames): the plot shows the dance's pulse, not capture jitter.
  const smooth = new Float32Array(out.length);
  for (let t = 0; t < out.length; t++) {
    let s = 0, n = 0;
    for (let k = Math.max(0, t - 2); k <= Math.min(out.length - 1, t + 2); k++) { s += out[k]; n++; }
    smooth[t] = s / n;
  }
  return smooth;
}

function canvas(parent, kind, label) {
  const figure = document.createElement('figure');
  const c = document.createElement('canvas');
  c.className = `plot ${kind}`;
  const caption = document.createElement('figcaption');
  caption.textContent = label;
  figure.append(c, caption);
  parent.append(figure);
  return c;
}

/** Sizes a canvas's pixels to its box (only when they differ: resizing clears it); returns the pixel ratio. */
function fit(c) {
  const ratio = window.devicePixelRatio || 1;
  const w = Math.max(1, Math.round(c.clientWidth * ratio)), h = Math.max(1, Math.round(c.clientHeight * ratio));
  if (c.width !== w) c.width = w;
  if (c.height !== h) c.height = h;
  return ratio;
}

const fmt = (v) => (typeof v === 'number' ? (Number.isInteger(v) ? String(v) : v.toFixed(3)) : String(v));

/** Numeric and boolean leaves of an object, as [dotted.path, value] rows. */
function leaves(obj, prefix = '') {
  if (obj == null || typeof obj !== 'object' || Array.isArray(obj)) return [[prefix, obj]];
  return Object.entries(obj).flatMap(([k, v]) => leaves(v, prefix ? `${prefix}.${k}` : k));
}

// What a stage counted of its own work, by its report.json name.
const COUNTS = [
  ['frames_retimed', 'frames re-timed'],
  ['knee_frames_turned', 'knee-frames turned'],
  ['frame_steps_planted', 'frame steps planted'],
  ['frames_calmed', 'frames calmed'],
];

/** A share as a percentage with one decimal. */
const pct = (v) => `${(100 * v).toFixed(1)} %`;

/**
 * report.json's `serving` list as a table: what each stage after the model did, in order, and
 * the dance's authenticity and coherence after it (a fall marked, so a stage that makes the dance
 * less real stands out).
 */
function servingTable(stages) {
  const table = document.createElement('table');
  table.className = 'serving';
  const head = table.createTHead().insertRow();
  for (const label of ['stage', 'frames moved', 'largest move', 'counted', 'authenticity', 'coherence']) {
    const th = document.createElement('th');
    th.textContent = label;
    head.append(th);
  }
  const body = table.createTBody();
  for (const s of stages) {
    const tr = body.insertRow();
    tr.dataset.stage = s.stage;
    tr.insertCell().textContent = s.stage;
    tr.insertCell().textContent = s.changed ? String(s.frames_changed) : '–';
    tr.insertCell().textContent = s.changed ? `${(100 * s.largest_move_m).toFixed(1)} cm` : '–';
    tr.insertCell().textContent = COUNTS.filter(([k]) => s[k] != null).map(([k, label]) => `${s[k]} ${label}`).join(', ');
    for (const measure of ['authenticity', 'coherence']) {
      const cell = tr.insertCell();
      const before = s.before[measure], after = s.after[measure];
      cell.textContent = before === after ? pct(after) : `${pct(before)} → ${pct(after)}`;
      if (after < before) cell.className = 'fell';
    }
  }
  const details = document.createElement('details');
  const summary = document.createElement('summary');
  summary.textContent = `Serving stages (${stages.length})`;
  details.append(summary, table);
  return details;
}

export class ReportView {
  /** job: JobView; report: report.json; motion: motion.json; analysis: the song's analysis (or null). */
  constructor(container, { api, job, report, motion, analysis }) {
    this.container = container;
    container.replaceChildren();
    this.duration = motion.num_frames / motion.fps;
    const title = document.createElement('h3');
    const style = report.style ? ` · ${report.style.style}${report.style.predicted ? ' (from the music)' : ''}` : '';
    // The opening check (dance-revolution, dancenet): where the seed's own draw shuffled or
    // flailed in the song's first 20 s, another draw of the seed was danced; say so.
    const check = report.opening_check;
    const opening = check && check.kept > 0 ? ` · draw ${check.kept}` : '';
    title.textContent = `${job.model} · seed ${job.seed}${opening}${style} · ${job.id.slice(0, 8)}…`;
    if (opening) {
      title.title = `The seed's own draw shuffled or flailed in the song's first 20 s; draw ${check.kept} of ${check.tried} tried was danced (report.json: opening_check).`;
    }
    container.append(title);

    this.beats = canvas(container, 'beats', 'Beats: music (top; downbeats thick; the line: its tempo in BPM) against the dance\'s motion beats (bottom)');
    this.speed = canvas(container, 'speed', 'Mean joint speed over time (m/s), music beats behind');
    this.music = report.music_beat_times ?? analysis?.beat_times ?? [];
    this.downbeats = analysis?.downbeat_times ?? [];
    // The music's tempo through the song (two points when it is steady; absent in analyses
    // stored before it existed).
    this.tempoCurve = report.music_tempo_curve ?? analysis?.tempo_curve ?? [];
    const kinematic = report.kinematic_beat_times ?? {};
    this.motionBeats = kinematic.bailando ?? Object.values(kinematic)[0] ?? [];
    this.speeds = speeds(motion);
    this.fps = motion.fps;
    this.playhead = 0;

    const downloads = document.createElement('div');
    downloads.className = 'downloads';
    const files = [['motion.bvh', 'BVH'], ['motion.glb', 'glb'], ['motion.json', 'JSON'], ['report.json', 'report'], ['preview.png', 'preview']];
    for (const [file, label] of files) {
      const button = document.createElement('button');
      button.type = 'button';
      button.textContent = `Download ${label}`;
      button.dataset.file = file;
      // Fetched with the key (a plain link could not send it), then saved from a blob URL.
      button.addEventListener('click', async () => {
        button.disabled = true;
        try {
          const blob = await (await api.fetch(`/v1/jobs/${job.id}/${file}`)).blob();
          const a = document.createElement('a');
          a.href = URL.createObjectURL(blob);
          a.download = `${job.id}-${file}`;
          document.body.append(a);
          a.click();
          a.remove();
          setTimeout(() => URL.revokeObjectURL(a.href), 60_000);
        } catch (e) {
          window.dispatchEvent(new CustomEvent('choreo-error', { detail: e }));
        } finally {
          button.disabled = false;
        }
      });
      downloads.append(button);
    }
    container.append(downloads);

    const table = document.createElement('table');
    table.className = 'scores';
    const rows = [...leaves(report.scores ?? {}, 'scores'), ...leaves(report.physical ?? {}, 'physical'),
      ...(report.opening_check ? leaves(report.opening_check, 'opening_check') : [])]
      .filter(([, v]) => typeof v === 'number' || typeof v === 'boolean' || v === null);
    for (const [name, value] of rows) {
      const tr = table.insertRow();
      tr.insertCell().textContent = name;
      tr.insertCell().textContent = value === null ? '–' : fmt(value);
    }
    const details = document.createElement('details');
    const summary = document.createElement('summary');
    summary.textContent = `Scores (${rows.length})`;
    details.append(summary, table);
    container.append(details);
    if (report.serving?.length) container.append(servingTable(report.serving));

    new ResizeObserver(() => this.draw()).observe(this.speed);
    this.draw();
  }

  x(c, t) { return (t / this.duration) * c.width; }

  /** Draws both plots into cached pictures, then shows them with the playhead. */
  draw() {
    this.bases = [this.beats, this.speed].map((c) => {
      fit(c);
      const base = document.createElement('canvas');
      base.width = c.width;
      base.height = c.height;
      return base;
    });
    this.drawBeats(this.bases[0], this.beats);
    this.drawSpeed(this.bases[1], this.speed);
    this.blit();
  }

  blit() {
    const ratio = window.devicePixelRatio || 1;
    [this.beats, this.speed].forEach((c, i) => {
      const g = c.getContext('2d');
      g.drawImage(this.bases[i], 0, 0);
      g.strokeStyle = '#111';
      g.lineWidth = 1.5 * ratio;
      g.beginPath();
      g.moveTo(this.x(c, this.playhead), 0);
      g.lineTo(this.x(c, this.playhead), c.height);
      g.stroke();
    });
  }

  drawBeats(c) {
    const ratio = window.devicePixelRatio || 1, g = c.getContext('2d'), h = c.height;
    g.fillStyle = '#fbfaf6';
    g.fillRect(0, 0, c.width, h);
    const tick = (t, y0, y1, color, width) => {
      g.strokeStyle = color;
      g.lineWidth = width * ratio;
      g.beginPath();
      g.moveTo(this.x(c, t), y0);
      g.lineTo(this.x(c, t), y1);
      g.stroke();
    };
    g.fillStyle = '#777';
    g.font = `${11 * ratio}px sans-serif`;
    g.fillText('music', 4 * ratio, 12 * ratio);
    g.fillText('motion', 4 * ratio, h - 4 * ratio);
    for (const t of this.music) tick(t, 16 * ratio, h / 2 - 2 * ratio, 'rgba(230,140,30,0.9)', 1.5);
    for (const t of this.downbeats) tick(t, 16 * ratio, h / 2 - 2 * ratio, 'rgba(200,30,40,0.95)', 3);
    for (const t of this.motionBeats) tick(t, h / 2 + 2 * ratio, h - 16 * ratio, 'rgba(43,108,176,0.95)', 2);
    this.drawTempo(c, g, ratio);
  }

  // The tempo curve over the music's ticks: a thin line (higher is faster, scaled to the song's
  // own range), and its BPM written where it starts and wherever it moves by 3 % or more.
  drawTempo(c, g, ratio) {
    const curve = this.tempoCurve;
    if (curve.length === 0) return;
    const bpms = curve.map((p) => p.bpm);
    const lo = Math.min(...bpms) * 0.95, hi = Math.max(...bpms) * 1.05;
    const top = 16 * ratio, bottom = c.height / 2 - 2 * ratio;
    const y = (bpm) => bottom - ((bpm - lo) / (hi - lo)) * (bottom - top);
    g.strokeStyle = 'rgba(60,60,60,0.8)';
    g.lineWidth = 1.25 * ratio;
    g.beginPath();
    curve.forEach((p, i) => {
      const x = this.x(c, p.time_s);
      if (i === 0) g.moveTo(x, y(p.bpm));
      else g.lineTo(x, y(p.bpm));
    });
    g.stroke();
    g.fillStyle = '#333';
    g.font = `${10 * ratio}px sans-serif`;
    let shown = null;
    for (const p of curve) {
      if (shown !== null && Math.abs(p.bpm / shown - 1) < 0.03) continue;
      g.fillText(`${p.bpm.toFixed(0)} BPM`, this.x(c, p.time_s) + 3 * ratio, Math.max(top + 10 * ratio, y(p.bpm) - 3 * ratio));
      shown = p.bpm;
    }
  }

  drawSpeed(c) {
    const ratio = window.devicePixelRatio || 1, g = c.getContext('2d'), h = c.height;
    g.fillStyle = '#fbfaf6';
    g.fillRect(0, 0, c.width, h);
    const top = Math.max(0.5, ...this.speeds) * 1.1;
    const y = (v) => h - 4 * ratio - (v / top) * (h - 14 * ratio);
    for (const t of this.music) {
      g.strokeStyle = 'rgba(230,140,30,0.35)';
      g.lineWidth = ratio;
      g.beginPath();
      g.moveTo(this.x(c, t), 0);
      g.lineTo(this.x(c, t), h);
      g.stroke();
    }
    g.strokeStyle = '#c9c3b4';
    g.fillStyle = '#777';
    g.font = `${10 * ratio}px sans-serif`;
    for (let v = 0.5; v < top; v += 0.5) {
      g.beginPath();
      g.moveTo(0, y(v));
      g.lineTo(c.width, y(v));
      g.stroke();
      g.fillText(`${v.toFixed(1)} m/s`, 3 * ratio, y(v) - 2 * ratio);
    }
    g.strokeStyle = '#2b6cb0';
    g.lineWidth = 1.5 * ratio;
    g.beginPath();
    this.speeds.forEach((v, t) => {
      const px = this.x(c, t / this.fps);
      if (t === 0) g.moveTo(px, y(v));
      else g.lineTo(px, y(v));
    });
    g.stroke();
  }

  /** Moves the playhead; redraws (from the cached plots) only when it moved by a pixel or more. */
  setPlayhead(t) {
    const moved = Math.abs(this.x(this.speed, t) - this.x(this.speed, this.playhead)) >= 1;
    this.playhead = t;
    if (moved) this.blit();
  }
}
