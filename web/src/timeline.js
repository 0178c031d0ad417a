// A song's time axis on a canvas: waveform, beats and downbeats, key-pose flags, a cursor, a
// playhead and a loop region. The song section uses it to place key poses, the player to seek
// and to choose the section to loop.

const BINS = 4000;

/** Min/max of the audio (channels mixed) in BINS bins: what the waveform draws. */
export function peaks(audioBuffer) {
  const channels = Array.from({ length: audioBuffer.numberOfChannels }, (_, c) => audioBuffer.getChannelData(c));
  const length = audioBuffer.length;
  const bins = Math.min(BINS, length);
  const out = new Float32Array(bins * 2);
  for (let b = 0; b < bins; b++) {
    const start = Math.floor((b * length) / bins);
    const end = Math.max(start + 1, Math.floor(((b + 1) * length) / bins));
    let lo = 0, hi = 0;
    for (let i = start; i < end; i++) {
      let v = 0;
      for (const ch of channels) v += ch[i];
      v /= channels.length;
      if (v < lo) lo = v;
      if (v > hi) hi = v;
    }
    out[b * 2] = lo;
    out[b * 2 + 1] = hi;
  }
  return out;
}

/** Decodes a song's bytes for its waveform (no audio output needed). 8 kHz is plenty for a
 * picture and keeps a 15-minute song's samples to tens of megabytes. */
export async function decodePeaks(arrayBuffer) {
  const ctx = new OfflineAudioContext(1, 1, 8000);
  const buffer = await ctx.decodeAudioData(arrayBuffer);
  return { peaks: peaks(buffer), duration: buffer.duration };
}

const css = (name) => getComputedStyle(document.documentElement).getPropertyValue(name).trim();

export class Timeline {
  /**
   * canvas: the canvas to draw on.
   * handlers: onCursor(t), onKeyMove(i, t), onKeySelect(i), onSeek(t), onRange(a, b); any may be absent.
   * A drag starting on a key flag moves the key; otherwise a click sets the cursor (onCursor) or
   * seeks (onSeek), and a drag across selects a range (onRange).
   */
  constructor(canvas, handlers = {}) {
    this.canvas = canvas;
    this.handlers = handlers;
    this.duration = 0;
    this.peaks = null;
    this.beats = [];
    this.downbeats = [];
    this.keys = [];
    this.selected = -1;
    this.cursor = null;
    this.playhead = null;
    this.loop = null;
    new ResizeObserver(() => this.resize()).observe(canvas);
    this.resize();
    this.listen();
  }

  resize() {
    const ratio = window.devicePixelRatio || 1;
    const width = Math.max(1, Math.round(this.canvas.clientWidth * ratio));
    const height = Math.max(1, Math.round(this.canvas.clientHeight * ratio));
    if (this.canvas.width !== width || this.canvas.height !== height) {
      this.canvas.width = width;
      this.canvas.height = height;
    }
    this.draw();
  }

  /** Changes what is shown; a playhead-only change redraws from the cached picture. */
  set(fields) {
    const onlyPlayhead = Object.keys(fields).every((k) => k === 'playhead');
    Object.assign(this, fields);
    if (onlyPlayhead && this.base) this.blit();
    else this.draw();
  }

  x(t) { return this.duration > 0 ? (t / this.duration) * this.canvas.width : 0; }

  time(clientX) {
    const rect = this.canvas.getBoundingClientRect();
    const f = Math.min(1, Math.max(0, (clientX - rect.left) / Math.max(1, rect.width)));
    return f * this.duration;
  }

  keyAt(clientX) {
    const rect = this.canvas.getBoundingClientRect();
    const px = ((clientX - rect.left) / Math.max(1, rect.width)) * this.canvas.width;
    const ratio = window.devicePixelRatio || 1;
    let best = -1, bestD = 7 * ratio;
    this.keys.forEach((k, i) => {
      const d = Math.abs(this.x(k.time_s) - px);
      if (d < bestD) { best = i; bestD = d; }
    });
    return best;
  }

  listen() {
    let drag = null;
    this.canvas.addEventListener('pointerdown', (e) => {
      if (!this.duration) return;
      this.canvas.setPointerCapture(e.pointerId);
      const key = this.handlers.onKeyMove ? this.keyAt(e.clientX) : -1;
      drag = { key, x0: e.clientX, t0: this.time(e.clientX), moved: false };
      if (key >= 0) this.handlers.onKeySelect?.(key);
    });
    this.canvas.addEventListener('pointermove', (e) => {
      if (!drag) return;
      if (Math.abs(e.clientX - drag.x0) > 3) drag.moved = true;
      if (!drag.moved) return;
      const t = this.time(e.clientX);
      if (drag.key >= 0) this.handlers.onKeyMove(drag.key, t);
      else if (this.handlers.onRange) this.set({ loop: { a: Math.min(drag.t0, t), b: Math.max(drag.t0, t), on: true } });
    });
    this.canvas.addEventListener('pointerup', (e) => {
      if (!drag) return;
      const t = this.time(e.clientX);
      if (drag.key < 0) {
        if (drag.moved && this.handlers.onRange) this.handlers.onRange(Math.min(drag.t0, t), Math.max(drag.t0, t));
        else if (!drag.moved) (this.handlers.onSeek || this.handlers.onCursor)?.(t);
      }
      drag = null;
    });
  }

  /** Draws everything but the playhead into a cached picture, then shows it with the playhead. */
  draw() {
    this.base ??= document.createElement('canvas');
    this.base.width = this.canvas.width;
    this.base.height = this.canvas.height;
    this.drawBase(this.base);
    this.blit();
  }

  blit() {
    const g = this.canvas.getContext('2d');
    g.drawImage(this.base, 0, 0);
    if (this.playhead != null && this.duration) {
      const ratio = window.devicePixelRatio || 1;
      g.strokeStyle = '#111';
      g.lineWidth = 2 * ratio;
      g.beginPath();
      g.moveTo(this.x(this.playhead) + 0.5, 0);
      g.lineTo(this.x(this.playhead) + 0.5, this.canvas.height);
      g.stroke();
    }
  }

  drawBase(canvas) {
    const g = canvas.getContext('2d');
    const w = canvas.width, h = canvas.height, ratio = window.devicePixelRatio || 1;
    g.fillStyle = css('--wave-bg') || '#f4f1ea';
    g.fillRect(0, 0, w, h);
    if (!this.duration) {
      g.fillStyle = css('--muted') || '#777';
      g.font = `${12 * ratio}px sans-serif`;
      g.fillText('no song yet', 8 * ratio, h / 2);
      return;
    }
    if (this.loop?.on && this.loop.b > this.loop.a) {
      g.fillStyle = 'rgba(80, 140, 220, 0.18)';
      g.fillRect(this.x(this.loop.a), 0, this.x(this.loop.b) - this.x(this.loop.a), h);
    }
    if (this.peaks) {
      const bins = this.peaks.length / 2;
      g.fillStyle = css('--wave') || '#6b6b6b';
      for (let px = 0; px < w; px++) {
        const b0 = Math.floor((px / w) * bins), b1 = Math.max(b0 + 1, Math.floor(((px + 1) / w) * bins));
        let lo = 0, hi = 0;
        for (let b = b0; b < b1 && b < bins; b++) {
          lo = Math.min(lo, this.peaks[b * 2]);
          hi = Math.max(hi, this.peaks[b * 2 + 1]);
        }
        const y0 = h / 2 - hi * (h / 2) * 0.95, y1 = h / 2 - lo * (h / 2) * 0.95;
        g.fillRect(px, y0, 1, Math.max(1, y1 - y0));
      }
    }
    const line = (t, color, width, top = 0) => {
      g.strokeStyle = color;
      g.lineWidth = width * ratio;
      g.beginPath();
      g.moveTo(this.x(t) + 0.5, top);
      g.lineTo(this.x(t) + 0.5, h);
      g.stroke();
    };
    for (const t of this.beats) line(t, 'rgba(230, 140, 30, 0.75)', 1);
    for (const t of this.downbeats) line(t, 'rgba(200, 30, 40, 0.9)', 2.5);
    this.keys.forEach((k, i) => {
      const x = this.x(k.time_s);
      line(k.time_s, i === this.selected ? '#0a7d32' : '#2aa84a', i === this.selected ? 3 : 2);
      g.fillStyle = i === this.selected ? '#0a7d32' : '#2aa84a';
      g.beginPath();
      g.moveTo(x, 0);
      g.lineTo(x + 12 * ratio, 5 * ratio);
      g.lineTo(x, 10 * ratio);
      g.fill();
    });
    if (this.cursor != null) line(this.cursor, '#1f5fbf', 1.5);
  }
}
