// The sync check shared by flow.mjs (the page at /) and player.mjs (<choreo-player>): the dance's
// pose in every frame comes from the song's audio clock, read in that frame.
//
// Why it records the clock rather than comparing two live reads: a sample reads `audioTime` in an
// animation frame after the player drew, so the live clock has moved on by whatever ran between
// the two callbacks (the player's drawing, Chromium's own work, its media clock's next step). That
// time is not the player's: it reached 12.8 ms on an idle machine and 23.8 ms on a loaded one, past
// the "drawing time + 10 ms" once allowed, and the check failed 2 runs in 6 with nothing wrong in
// the player. So the page's `currentTime` is wrapped (before any of its scripts run) to record
// every value read or set, and each sample checks the pose against the last value the page took
// from the clock before the sample: exactly, not within a slack. A player 4 ms behind the clock
// fails it (the old slack let it through), and so does one that draws every other frame.
export const FRAME_S = 1 / 25;

/** For `addInitScript`: records each `currentTime` read or set (wall time, value), the last 64. */
export function recordMediaClock() {
  const own = Object.getOwnPropertyDescriptor(HTMLMediaElement.prototype, 'currentTime');
  const taken = [];
  const note = (value) => {
    taken.push({ at: performance.now(), value });
    if (taken.length > 64) taken.shift();
  };
  Object.defineProperty(window, '__choreoClockTaken', { value: taken });
  Object.defineProperty(HTMLMediaElement.prototype, 'currentTime', {
    configurable: true,
    enumerable: own.enumerable,
    get() {
      const value = own.get.call(this);
      note(value);
      return value;
    },
    set(value) {
      own.set.call(this, value);
      note(own.get.call(this));
    },
  });
}

/**
 * One sample, read in an animation frame after the player drew it: `drawnFrom` is the last clock
 * value the page took before this callback (the player's read of this frame, or the loop's jump),
 * `takenAt` when, `frameStart` the frame's time; `player` is `'element'` (<choreo-player
 * id="player">) or `'page'` (window.choreoPlayer).
 */
export const sample = (page, player) => page.evaluate((which) => new Promise((resolve) => requestAnimationFrame((frameStart) => {
  const p = which === 'element' ? document.getElementById('player') : window.choreoPlayer;
  const taken = window.__choreoClockTaken;
  const last = taken[taken.length - 1] ?? { at: -Infinity, value: NaN };
  resolve({
    drawnFrom: last.value, takenAt: last.at, frameStart, duration: p.duration,
    audio: p.audioTime, animation: p.animationTime, frames: p.renderedFrames, frameMs: p.frameMs, now: performance.now(),
  });
})), player);

/** Samples (as [`sample`]) every 100 ms for `seconds` while the song plays. */
export async function sampleFor(page, player, seconds) {
  const samples = [];
  const end = Date.now() + seconds * 1000;
  while (Date.now() < end) {
    samples.push(await sample(page, player));
    await page.waitForTimeout(100);
  }
  return samples;
}

/**
 * Checks samples taken while the song played; returns the summary. Every pose is the clock's value
 * taken in its own frame (clamped to the dance, as the player clamps it); frames drawn in time
 * stay within one motion frame of the live clock; CPU-starved frames (drawing alone over a motion
 * frame: the 2-core machine is shared) are at most a fifth; at least 5 frames were drawn.
 */
export function checkSamples(samples, label, check) {
  const gap = (s) => Math.abs(s.audio - s.animation);
  for (const s of samples) {
    const expected = Math.min(Math.max(0, s.drawnFrom), s.duration);
    check(Math.abs(s.animation - expected) <= 1e-6,
      `${label}: the pose is at ${s.animation.toFixed(4)} s where the clock read in its frame said ${expected.toFixed(4)} s`);
    check(s.takenAt >= s.frameStart,
      `${label}: the clock was last read ${(s.frameStart - s.takenAt).toFixed(1)} ms before this frame began (a stale pose)`);
  }
  const starved = samples.filter((s) => s.frameMs > FRAME_S * 1000);
  const inTime = samples.filter((s) => s.frameMs <= FRAME_S * 1000);
  const worst = Math.max(...inTime.map(gap));
  check(starved.length <= samples.length / 5, `${label}: ${starved.length} of ${samples.length} frames took over ${FRAME_S * 1000} ms to draw`);
  check(worst <= FRAME_S, `${label}: |audioTime − animationTime| reached ${worst.toFixed(4)} s (> ${FRAME_S} s)`);
  const first = samples[0], last = samples[samples.length - 1];
  check(last.frames - first.frames >= 5, `${label}: only ${last.frames - first.frames} frames drawn while playing`);
  // Forward steps only: a loop's jump back is not time played.
  const advanced = samples.slice(1).reduce((sum, s, i) => sum + Math.max(0, s.audio - samples[i].audio), 0);
  const frameMs = samples.map((s) => s.frameMs).sort((a, b) => a - b);
  const lead = samples.map((s) => s.now - s.takenAt).sort((a, b) => a - b);
  return {
    samples: samples.length, worst_diff_s: worst, worst_diff_all_s: Math.max(...samples.map(gap)), starved_frames: starved.length,
    audio_advanced_s: advanced, wall_s: (last.now - first.now) / 1000, frames_drawn: last.frames - first.frames,
    frame_ms_median: frameMs[Math.floor(frameMs.length / 2)], frame_ms_max: frameMs[frameMs.length - 1],
    clock_read_to_sample_ms_max: lead[lead.length - 1],
  };
}
