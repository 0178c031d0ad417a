//! The warps: the song's beats as a clock, the grids of each fraction and phase, the matching of
//! kinematic beats to grid points per span between fixed frames, and the smoothed warp (steps 2–4
//! of the stage, [`super`]).
use super::rhythm::{ankle_speed, kinematic_beats, rhythm};
use super::*;

/// The warps [`align_served`] chooses from, one per grid fraction within reach (the least cost
/// of its phases and, where no fixed time lies after the first frame, of [`PACES`], a pace's
/// dropped tail counted), with their costs; the rhythm read from `view` (the same frames as
/// `motion`, e.g. with the feet planted), the warps applying to `motion`. `Err`: why there is
/// none.
pub(super) fn plan_from(
    motion: &Motion,
    view: &Motion,
    beat_times_s: &[f64],
    fixed_times_s: &[f64],
) -> Result<Vec<(Warp, f64)>, &'static str> {
    let frames = motion.num_frames();
    let held = fixed_times_s
        .iter()
        .any(|t| t.is_finite() && *t * motion.fps >= 0.5);
    // The dance's mean joint speed, as the plausibility verdict takes it.
    let steps = crate::motion::skeleton::mean_speed(motion.positions.view(), motion.fps);
    let speed = steps.iter().sum::<f64>() / steps.len().max(1) as f64;
    let paces: Vec<f64> = PACES
        .into_iter()
        .filter(|&p| p == 1.0 || (!held && p * speed >= LIVELY_M_S))
        .collect();
    let end_s = frames.saturating_sub(1) as f64 / motion.fps;
    // Per grid fraction: (q, cost, warp).
    let mut best: Vec<(f64, f64, Warp)> = Vec::new();
    let mut why = None;
    for pace in paces {
        let paced;
        let m = if pace == 1.0 {
            view
        } else {
            let at: Vec<f64> = (0..frames).map(|f| f as f64 * pace).collect();
            paced = resample(view, &at);
            &paced
        };
        // A pace that warps nothing would only drop the tail: it has no candidates.
        let candidates = match plan_at(m, beat_times_s, fixed_times_s, pace) {
            Ok(c) => c,
            Err(w) => {
                why.get_or_insert(w);
                continue;
            }
        };
        for (q, mut warp, cost) in candidates {
            let cost = cost + DROPPED_PER_S * (1.0 - pace) * end_s;
            warp.source_frames.iter_mut().for_each(|s| *s *= pace);
            warp.summary.step_hz /= pace;
            warp.summary.pace = pace;
            match best.iter_mut().find(|b| b.0 == q) {
                Some(b) if cost < b.1 => *b = (q, cost, warp),
                Some(_) => {}
                None => best.push((q, cost, warp)),
            }
        }
    }
    if best.is_empty() {
        return Err(why.unwrap_or("no grid of the beat is within the warp's reach"));
    }
    let fps = motion.fps;
    Ok(best
        .into_iter()
        .map(|(_, cost, mut warp)| {
            let slopes: Vec<f64> = warp.source_frames.windows(2).map(|w| w[1] - w[0]).collect();
            let shifts: Vec<f64> = warp
                .source_frames
                .iter()
                .enumerate()
                .map(|(f, &s)| (s - f as f64).abs() / fps)
                .collect();
            let s = &mut warp.summary;
            s.mean_shift_s = shifts.iter().sum::<f64>() / shifts.len() as f64;
            s.max_shift_s = shifts.iter().copied().fold(0.0, f64::max);
            s.slope_min = slopes.iter().copied().fold(f64::INFINITY, f64::min);
            s.slope_max = slopes.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            (warp, cost)
        })
        .collect())
}

/// The warps of `motion` (the network's played at `pace`), one per grid fraction within reach
/// (its phase of least cost), as (fraction, warp, cost); their slopes are kept within
/// [`SLOPE_RANGE`] once `pace` is applied. `Err`: why there is none.
pub(super) fn plan_at(
    motion: &Motion,
    beat_times_s: &[f64],
    fixed_times_s: &[f64],
    pace: f64,
) -> Result<Vec<(f64, Warp, f64)>, &'static str> {
    let frames = motion.num_frames();
    let fps = motion.fps;
    if frames < MIN_FRAMES || fps <= 0.0 || !fps.is_finite() {
        return Err("the dance is too short");
    }
    let end_s = (frames - 1) as f64 / fps;
    let Some(clock) = BeatClock::new(beat_times_s, frames as f64 / fps) else {
        return Err("fewer than 4 beats within the dance");
    };
    let speed = ankle_speed(motion.positions.view(), fps);
    let Some((step_hz, filtered)) = rhythm(&speed, fps) else {
        return Err("no step rate: the ankles do not move");
    };
    let kin = kinematic_beats(&filtered, fps, step_hz);
    // Fixed frames: the start, the end, and each key pose's frame (as `serve` anchors them).
    let mut fixed: Vec<usize> = fixed_times_s
        .iter()
        .filter(|t| t.is_finite())
        .map(|t| ((t * fps).round().max(0.0) as usize).min(frames - 1))
        .collect();
    fixed.extend([0, frames - 1]);
    fixed.sort_unstable();
    fixed.dedup();
    let anchors: Vec<f64> = fixed.iter().map(|&f| f as f64 / fps).collect();

    // Every grid within reach: its spacing over the motion's cycle is the slope of a lock.
    let mut out = Vec::new();
    for &q in &GRID_FRACTIONS {
        let slope = pace * q * clock.rate_hz / step_hz;
        // A grid outside the band the step rate is read in (with the lock's tolerance) cannot be
        // the served dance's step rate: a waltz at 87 bpm stepped every 6 beats (0.24 Hz) reads
        // as 0.25 Hz, 4 % off (eval 2026-11-25: dancenet's four waltz test dances).
        let grid_hz = q * clock.rate_hz;
        let in_band = grid_hz >= STEP_BAND_HZ.0 * (1.0 + LOCK_TOLERANCE)
            && grid_hz <= STEP_BAND_HZ.1 / (1.0 + LOCK_TOLERANCE);
        if !in_band || !(SLOPE_RANGE.0..=SLOPE_RANGE.1).contains(&slope) {
            continue;
        }
        let mut best: Option<(f64, Vec<Pair>, f64)> = None; // (cost, pairs, locked s)
        for start in grid_phases(q) {
            let grid = clock.grid(q, start, end_s);
            let (mut cost, mut pairs, mut locked) = (0.0, Vec::new(), 0.0);
            for span in anchors.windows(2) {
                let (a, b) = (span[0], span[1]);
                let k: Vec<f64> = kin.iter().copied().filter(|&t| t > a && t < b).collect();
                let g: Vec<f64> = grid.iter().copied().filter(|&t| t > a && t < b).collect();
                let p = match_span(a, b, &k, &g, pace);
                cost += p.cost;
                locked += p.locked_s;
                pairs.extend(p.pairs);
            }
            if best.as_ref().is_none_or(|b| cost < b.0) {
                best = Some((cost, pairs, locked));
            }
        }
        let Some((cost, pairs, locked_s)) = best else {
            continue;
        };
        // Knots (served s, source s): the fixed frames and the matched beats, in time order.
        let mut knots: Vec<Pair> = anchors
            .iter()
            .map(|&a| Pair { out: a, src: a })
            .chain(pairs.iter().copied())
            .collect();
        knots.sort_by(|x, y| x.out.total_cmp(&y.out));
        let source_frames = smooth_warp(&knots, &fixed, frames, fps);
        // Shifts and slopes are measured by `plan_from`, on the warp of the network's own frames.
        let summary = BeatAlignSummary {
            applied: true,
            skipped: None,
            step_hz,
            beat_hz: clock.rate_hz,
            grid_fraction: q,
            grid_spacing_s: 1.0 / (q * clock.rate_hz),
            kinematic_beats: kin.len(),
            matched_beats: pairs.len(),
            locked_share: locked_s / end_s,
            pace: 1.0,
            ..BeatAlignSummary::default()
        };
        out.push((
            q,
            Warp {
                source_frames,
                summary,
            },
            cost,
        ));
    }
    if out.is_empty() {
        return Err("no grid of the beat is within the warp's reach of the motion's step rate");
    }
    Ok(out)
}

/// The song's beats as a clock: beat index as a function of time, linear between beats and
/// extrapolated at the mean spacing before the first and after the last.
pub(super) struct BeatClock {
    times: Vec<f64>,
    period: f64,
    /// The beat rate over the dance, as the metric takes it: `(n − 1) / (last − first)` of the
    /// beats within it.
    pub(super) rate_hz: f64,
}

impl BeatClock {
    pub(super) fn new(beat_times_s: &[f64], duration_s: f64) -> Option<Self> {
        let mut times: Vec<f64> = beat_times_s
            .iter()
            .copied()
            .filter(|t| t.is_finite())
            .collect();
        times.sort_by(f64::total_cmp);
        times.dedup_by(|a, b| (*a - *b).abs() < 1e-6);
        let inside: Vec<f64> = times
            .iter()
            .copied()
            .filter(|t| (0.0..=duration_s).contains(t))
            .collect();
        let (first, last) = (*inside.first()?, *inside.last()?);
        if inside.len() < MIN_BEATS || last <= first {
            return None;
        }
        let rate_hz = (inside.len() - 1) as f64 / (last - first);
        let period = (times[times.len() - 1] - times[0]) / (times.len() - 1) as f64;
        Some(Self {
            times,
            period,
            rate_hz,
        })
    }

    /// Beat index (fractional) at time `t`.
    fn phase(&self, t: f64) -> f64 {
        let n = self.times.len();
        if t <= self.times[0] {
            return (t - self.times[0]) / self.period;
        }
        if t >= self.times[n - 1] {
            return (n - 1) as f64 + (t - self.times[n - 1]) / self.period;
        }
        let i = self.times.partition_point(|&b| b <= t) - 1;
        i as f64 + (t - self.times[i]) / (self.times[i + 1] - self.times[i])
    }

    /// Time at beat index `phase`.
    fn time_at(&self, phase: f64) -> f64 {
        let n = self.times.len();
        if phase <= 0.0 {
            return self.times[0] + phase * self.period;
        }
        if phase >= (n - 1) as f64 {
            return self.times[n - 1] + (phase - (n - 1) as f64) * self.period;
        }
        let i = phase.floor() as usize;
        self.times[i] + (phase - i as f64) * (self.times[i + 1] - self.times[i])
    }

    /// Grid points in `(0, end_s)`: beat indices `start + n / q`.
    fn grid(&self, q: f64, start: f64, end_s: f64) -> Vec<f64> {
        let spacing = 1.0 / q;
        let (p0, p1) = (self.phase(0.0), self.phase(end_s));
        let first = ((p0 - start) / spacing).ceil() as i64;
        let last = ((p1 - start) / spacing).floor() as i64;
        (first..=last)
            .map(|n| self.time_at(start + n as f64 * spacing))
            .filter(|&t| t > 0.0 && t < end_s)
            .collect()
    }
}

/// Where a grid of `q` × the beat rate may start, in beats: each beat of a group (2/3: each half
/// beat of its 1½).
pub(super) fn grid_phases(q: f64) -> Vec<f64> {
    let spacing = 1.0 / q;
    let step = if (spacing - spacing.round()).abs() < 1e-9 {
        1.0
    } else {
        0.5
    };
    (0..(spacing / step).round() as usize)
        .map(|m| m as f64 * step)
        .collect()
}

/// A knot of the warp: served time `out` shows source time `src` (s).
#[derive(Clone, Copy, Debug)]
pub(super) struct Pair {
    out: f64,
    src: f64,
}

/// The best monotone matching of one span between fixed times.
pub(super) struct SpanPlan {
    cost: f64,
    pairs: Vec<Pair>,
    locked_s: f64,
}

/// Cost of a segment lasting `d_out` served seconds over `d_src` seconds of the motion played at
/// `pace`, locked or not, skipping `skips` beats; `None` when the slope (of the network's motion:
/// `pace · d_src / d_out`) is out of range.
pub(super) fn segment_cost(
    d_out: f64,
    d_src: f64,
    locked: bool,
    skips: usize,
    pace: f64,
) -> Option<f64> {
    if d_out <= 0.0 || d_src <= 0.0 {
        return None;
    }
    let slope = pace * d_src / d_out;
    if !(SLOPE_RANGE.0..=SLOPE_RANGE.1).contains(&slope) {
        return None;
    }
    let limit = SLOPE_RANGE.0.ln().abs().max(SLOPE_RANGE.1.ln().abs());
    let distortion = DISTORTION_AT_LIMIT_PER_S * (slope.ln() / limit).powi(2);
    Some(d_out * (distortion + if locked { 0.0 } else { UNLOCKED_PER_S }) + SKIP * skips as f64)
}

/// Matches kinematic beats `k` to grid points `g` (both sorted, inside `(a, b)`), monotonically,
/// with the span's ends fixed (`a → a`, `b → b`), for the motion played at `pace`.
pub(super) fn match_span(a: f64, b: f64, k: &[f64], g: &[f64], pace: f64) -> SpanPlan {
    let (m, n) = (k.len(), g.len());
    // Leaving the span as it is: slope 1, nothing locked.
    let mut best = SpanPlan {
        cost: UNLOCKED_PER_S * (b - a) + SKIP * (m + n) as f64,
        pairs: Vec::new(),
        locked_s: 0.0,
    };
    if m == 0 || n == 0 {
        return best;
    }
    // cost, previous node (None: the span's start), locked seconds so far.
    let mut table: Vec<Option<(f64, Option<usize>, f64)>> = vec![None; m * n];
    for i in 0..m {
        for j in 0..n {
            let mut cell: Option<(f64, Option<usize>, f64)> = None;
            let mut offer = |c: f64, prev: Option<usize>, locked: f64| {
                if cell.is_none_or(|x| c < x.0) {
                    cell = Some((c, prev, locked));
                }
            };
            if i < MAX_EDGE_SKIP && j < MAX_EDGE_SKIP {
                if let Some(c) = segment_cost(g[j] - a, k[i] - a, false, i + j, pace) {
                    offer(c, None, 0.0);
                }
            }
            for da in 1..=MAX_RUN.min(i) {
                for db in 1..=MAX_RUN.min(j) {
                    let p = (i - da) * n + (j - db);
                    let Some((pc, _, pl)) = table[p] else {
                        continue;
                    };
                    let locked = da == db;
                    if let Some(c) = segment_cost(
                        g[j] - g[j - db],
                        k[i] - k[i - da],
                        locked,
                        da + db - 2,
                        pace,
                    ) {
                        offer(
                            pc + c,
                            Some(p),
                            pl + if locked { g[j] - g[j - db] } else { 0.0 },
                        );
                    }
                }
            }
            table[i * n + j] = cell;
        }
    }
    let mut end: Option<(f64, usize, f64)> = None;
    for i in m.saturating_sub(MAX_EDGE_SKIP)..m {
        for j in n.saturating_sub(MAX_EDGE_SKIP)..n {
            let Some((c, _, l)) = table[i * n + j] else {
                continue;
            };
            if let Some(e) =
                segment_cost(b - g[j], b - k[i], false, (m - 1 - i) + (n - 1 - j), pace)
            {
                if end.is_none_or(|x| c + e < x.0) {
                    end = Some((c + e, i * n + j, l));
                }
            }
        }
    }
    if let Some((cost, last, locked_s)) = end.filter(|e| e.0 < best.cost) {
        let mut pairs = Vec::new();
        let mut at = Some(last);
        while let Some(node) = at {
            let prev = table[node].and_then(|(_, prev, _)| prev);
            pairs.push(Pair {
                out: g[node % n],
                src: k[node / n],
            });
            at = prev;
        }
        pairs.reverse();
        best = SpanPlan {
            cost,
            pairs,
            locked_s,
        };
    }
    best
}

/// The warp through `knots` (seconds) as source frames per served frame: piecewise linear, its
/// per-frame slope Gaussian-smoothed, then scaled per span between `fixed` frames so each maps to
/// itself.
pub(super) fn smooth_warp(knots: &[Pair], fixed: &[usize], frames: usize, fps: f64) -> Vec<f64> {
    let (outs, srcs): (Vec<f64>, Vec<f64>) =
        knots.iter().map(|p| (p.out * fps, p.src * fps)).unzip();
    let linear = |f: f64| -> f64 {
        let i = outs.partition_point(|&o| o <= f).clamp(1, outs.len() - 1);
        let (o0, o1, s0, s1) = (outs[i - 1], outs[i], srcs[i - 1], srcs[i]);
        if o1 > o0 {
            s0 + (f - o0) * (s1 - s0) / (o1 - o0)
        } else {
            s0
        }
    };
    let slope: Vec<f64> = (0..frames - 1)
        .map(|f| linear(f as f64 + 1.0) - linear(f as f64))
        .collect();
    let sigma = SLOPE_SMOOTH_S * fps;
    let radius = (3.0 * sigma).ceil() as isize;
    let kernel: Vec<f64> = (-radius..=radius)
        .map(|d| (-0.5 * (d as f64 / sigma).powi(2)).exp())
        .collect();
    let total: f64 = kernel.iter().sum();
    let last = slope.len() as isize - 1;
    let smoothed: Vec<f64> = (0..slope.len() as isize)
        .map(|f| {
            kernel
                .iter()
                .zip(-radius..=radius)
                .map(|(w, d)| w * slope[(f + d).clamp(0, last) as usize])
                .sum::<f64>()
                / total
        })
        .collect();
    let mut out = vec![0.0; frames];
    for span in fixed.windows(2) {
        let (a, b) = (span[0], span[1]);
        let sum: f64 = smoothed[a..b].iter().sum();
        let scale = if sum > 0.0 { (b - a) as f64 / sum } else { 1.0 };
        out[a] = a as f64;
        let mut acc = a as f64;
        for f in a..b {
            acc += smoothed[f] * scale;
            out[f + 1] = acc;
        }
        out[b] = b as f64;
    }
    out
}
