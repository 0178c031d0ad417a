//! The tempo curve: how fast the music goes at each moment, for songs whose tempo changes.
//!
//! librosa's tracker ([`super::rhythm`]) assumes one tempo for the whole song. Where a song
//! speeds up or slows down, its beats drift off the music on one side of the change. Here the
//! local tempo is followed through time, and the beat tracker then runs with a beat period per
//! frame ([`super::rhythm::beat_track_periods`]).
//!
//! # Method
//! Every second, the row of the 8 s autocorrelation tempogram (the one [`super::rhythm::tempo`]
//! averages) is read on a log-tempo grid ([`BINS_PER_OCTAVE`] bins per octave, 30–480 BPM).
//! When the tempo changes by a factor `r`, that whole pattern (the beat, its subdivisions and
//! its bars) moves by `log2 r` octaves. So the curve is found as a *shift* of a reference
//! pattern: a Viterbi path over shifts of at most [`MAX_SHIFT`] bins, whose score at each second
//! is the correlation of the row with the shifted reference, weighted around the beat level
//! (a Gaussian [`LEVEL_WIDTH_OCTAVES`] wide), and whose moves cost [`SHIFT_COST`] per bin. The
//! reference starts as the mean row and is rebuilt from the rows aligned by the path
//! ([`ITERATIONS`] times). Matching the whole pattern, not only its strongest peak, keeps one
//! metrical level across a change: reading the local peak alone, a song that speeds up 1.56×
//! is heard at half its new tempo, because 0.78× of the old tempo is the nearer peak.
//!
//! The beat level of the curve is chosen as librosa chooses a song's tempo (the 120 BPM prior
//! on the aligned mean row), at the song's mean rate, so a song that changes tempo is heard at
//! the level the unchanged song would be heard at.
//!
//! A song is *steady* when less than [`CHANGED_SHARE`] of its seconds (its first and last
//! [`EDGE_S`] apart, where the window is half padding) lie more than [`STEADY_BINS`] bins
//! (about 6 %) from the median: those keep librosa's single-tempo tracker unchanged, so every
//! steady song gets the beats it got before the curve existed. A curve that moves more than
//! [`MAX_OCTAVES_PER_MINUTE`] (its moves summed) is *erratic*: the rhythm's texture changes
//! (a section in other subdivisions), not its tempo, or not in a way one curve describes, and
//! the song keeps librosa's tracker too. hungarian_dance_5 is one: its curve wanders between
//! 87 and 160 BPM (1.9 octaves a minute) where librosa's beats keep 152–161 BPM; the songs
//! that speed up 1.56× once move 0.5–0.9 octave a minute.
//!
//! Measured (`tests/audio.rs`, `tempo_*`; `docs/experiments.md`): on two real songs played at
//! 0.8× and then 1.25× the curve jumps 1.56× at the join within one second, at the right level.
use ndarray::Array2;

use super::rhythm::tempo_prior;
use super::TempoPoint;

/// Resolution of the log-tempo grid.
pub const BINS_PER_OCTAVE: usize = 36;
/// Lowest tempo of the grid (BPM); the grid spans four octaves.
const LOWEST_BPM: f64 = 30.0;
const OCTAVES: usize = 4;
/// One curve step, in seconds.
pub const STEP_S: f64 = 1.0;
/// Largest shift from the reference, bins (25 = 0.69 octave, a factor 1.62). A larger change
/// within one song cannot be told from the music moving to another metrical level.
pub const MAX_SHIFT: usize = 25;
/// Viterbi cost of moving the curve by one bin between steps, in correlation units: a jump
/// of 0.64 octave (23 bins) then needs the new tempo to fit better for about 10 s.
const SHIFT_COST: f64 = 0.08;
/// Standard deviation of the weight around the beat level, octaves.
const LEVEL_WIDTH_OCTAVES: f64 = 0.5;
/// Rounds of (Viterbi path, reference rebuilt from the aligned rows).
const ITERATIONS: usize = 3;
/// A step further than this from the median shift counts as changed (3 bins ≈ 6 %).
pub const STEADY_BINS: i64 = 3;
/// A song whose share of changed steps reaches this is not steady.
pub const CHANGED_SHARE: f64 = 0.25;
/// Seconds at each end left out of the steady test (half the tempogram window).
pub const EDGE_S: f64 = 4.0;
/// A curve whose moves add up to more than this is not followed (see the module doc).
pub const MAX_OCTAVES_PER_MINUTE: f64 = 1.5;
/// Curve points are at most this far apart where the tempo moves (seconds).
pub const POINT_SPACING_S: f64 = 2.0;

/// The local tempo of a song, one value per [`STEP_S`].
#[derive(Clone, Debug, PartialEq)]
pub struct LocalTempo {
    /// Onset frames per step.
    pub step_frames: usize,
    /// Tempo at each step (BPM), at the beat level of the whole curve.
    pub bpm: Vec<f64>,
    /// Shift of each step from the median, bins of the log-tempo grid.
    pub shift: Vec<i64>,
    /// See the module doc.
    pub steady: bool,
    /// See the module doc.
    pub erratic: bool,
}

fn grid() -> Vec<f64> {
    (0..OCTAVES * BINS_PER_OCTAVE)
        .map(|k| LOWEST_BPM * 2f64.powf(k as f64 / BINS_PER_OCTAVE as f64))
        .collect()
}

/// The beat level of a mean pattern on the grid: librosa's choice (prior × strength, ≤ 320 BPM).
fn level(pattern: &[f64], bpm: &[f64]) -> usize {
    let mut best = (f64::NEG_INFINITY, 0);
    for (k, (&v, &b)) in pattern.iter().zip(bpm).enumerate() {
        if b > 320.0 {
            break;
        }
        let score = (1e6 * v.max(0.0)).ln_1p() + tempo_prior(b);
        if score > best.0 {
            best = (score, k);
        }
    }
    best.1
}

/// `pattern[k + s]` for every `k`, zero outside the grid.
fn shifted(pattern: &[f64], s: i64) -> Vec<f64> {
    let nb = pattern.len() as i64;
    (0..nb)
        .map(|k| {
            let j = k + s;
            if (0..nb).contains(&j) {
                pattern[j as usize]
            } else {
                0.0
            }
        })
        .collect()
}

/// Weighted Pearson correlation of `row[k + s]` with `reference[k]` over the bins both cover.
fn correlation(row: &[f64], reference: &[f64], weight: &[f64], s: i64) -> f64 {
    let nb = row.len() as i64;
    let (mut sw, mut sa, mut sb) = (0.0, 0.0, 0.0);
    for k in 0..nb {
        let j = k + s;
        if (0..nb).contains(&j) {
            let w = weight[k as usize];
            sw += w;
            sa += w * row[j as usize];
            sb += w * reference[k as usize];
        }
    }
    if sw <= 0.0 {
        return -1.0;
    }
    let (ma, mb) = (sa / sw, sb / sw);
    let (mut ab, mut aa, mut bb) = (0.0, 0.0, 0.0);
    for k in 0..nb {
        let j = k + s;
        if (0..nb).contains(&j) {
            let w = weight[k as usize];
            let (a, b) = (row[j as usize] - ma, reference[k as usize] - mb);
            ab += w * a * b;
            aa += w * a * a;
            bb += w * b * b;
        }
    }
    ab / (aa * bb + 1e-12).sqrt()
}

/// The best path of shifts (−`MAX_SHIFT`..=`MAX_SHIFT`) through `score[step][shift]`.
fn viterbi(score: &[Vec<f64>]) -> Vec<i64> {
    let Some(first) = score.first() else {
        return Vec::new();
    };
    let n_s = first.len();
    let mut cum = first.clone();
    let mut back = vec![vec![0usize; n_s]; score.len()];
    for (t, row) in score.iter().enumerate().skip(1) {
        let mut next = vec![f64::NEG_INFINITY; n_s];
        for to in 0..n_s {
            for (from, &c) in cum.iter().enumerate() {
                let v = c - SHIFT_COST * to.abs_diff(from) as f64;
                if v > next[to] {
                    next[to] = v;
                    back[t][to] = from;
                }
            }
            next[to] += row[to];
        }
        cum = next;
    }
    let mut at = (0..n_s)
        .max_by(|&a, &b| cum[a].total_cmp(&cum[b]))
        .unwrap_or(0);
    let mut path = vec![0i64; score.len()];
    for t in (0..score.len()).rev() {
        path[t] = at as i64 - MAX_SHIFT as i64;
        at = back[t][at];
    }
    path
}

/// The local tempo from the tempogram `tg` (`[frames, lags]`, the 8 s window of
/// [`super::rhythm::tempo_window`]) of an onset envelope at `sr / hop` frames per second.
pub fn local_tempo(tg: &Array2<f32>, sr: u32, hop: usize) -> LocalTempo {
    let frame_rate = sr as f64 / hop as f64;
    let step_frames = ((STEP_S * frame_rate).round() as usize).max(1);
    let bpm_grid = grid();
    let nb = bpm_grid.len();
    let lags = tg.ncols();
    let n_steps = tg.nrows().div_ceil(step_frames);
    // Each step's tempogram row at the grid's tempi (linear in lag between whole lags).
    let rows: Vec<Vec<f64>> = (0..n_steps)
        .map(|i| {
            let row = tg.row(i * step_frames);
            bpm_grid
                .iter()
                .map(|&b| {
                    let lag = 60.0 * frame_rate / b;
                    let l = lag.floor() as usize;
                    if l + 1 >= lags {
                        return 0.0;
                    }
                    let f = lag - l as f64;
                    row[l] as f64 * (1.0 - f) + row[l + 1] as f64 * f
                })
                .collect()
        })
        .collect();
    let mean_of = |shift: &[i64]| -> Vec<f64> {
        let (mut sum, mut n) = (vec![0.0; nb], vec![0usize; nb]);
        for (row, &s) in rows.iter().zip(shift) {
            for (k, v) in shifted(row, s).into_iter().enumerate() {
                let j = k as i64 + s;
                if (0..nb as i64).contains(&j) {
                    sum[k] += v;
                    n[k] += 1;
                }
            }
        }
        sum.iter()
            .zip(&n)
            .map(|(s, &c)| if c > 0 { s / c as f64 } else { 0.0 })
            .collect()
    };
    let mut shift = vec![0i64; n_steps];
    let mut reference = mean_of(&shift);
    for _ in 0..ITERATIONS {
        let beat = level(&reference, &bpm_grid) as f64;
        let width = LEVEL_WIDTH_OCTAVES * BINS_PER_OCTAVE as f64;
        let weight: Vec<f64> = (0..nb)
            .map(|k| (-0.5 * ((k as f64 - beat) / width).powi(2)).exp())
            .collect();
        let score: Vec<Vec<f64>> = rows
            .iter()
            .map(|row| {
                (-(MAX_SHIFT as i64)..=MAX_SHIFT as i64)
                    .map(|s| correlation(row, &reference, &weight, s))
                    .collect()
            })
            .collect();
        shift = viterbi(&score);
        let median = median_i64(&shift);
        shift.iter_mut().for_each(|s| *s -= median);
        reference = mean_of(&shift);
    }
    // The level at the song's mean rate, as librosa would pick it for the song played steadily.
    let mean_shift = if shift.is_empty() {
        0
    } else {
        (shift.iter().sum::<i64>() as f64 / shift.len() as f64).round() as i64
    };
    let at_mean = shifted(&reference, -mean_shift);
    let base = bpm_grid[level(&at_mean, &bpm_grid)]
        / 2f64.powf(mean_shift as f64 / BINS_PER_OCTAVE as f64);
    let bpm = shift
        .iter()
        .map(|&s| base * 2f64.powf(s as f64 / BINS_PER_OCTAVE as f64))
        .collect();
    let edge = (EDGE_S / STEP_S).round() as usize;
    let inner: &[i64] = if shift.len() > 2 * edge {
        &shift[edge..shift.len() - edge]
    } else {
        &shift
    };
    let median = median_i64(inner);
    let changed = inner
        .iter()
        .filter(|&&s| (s - median).abs() > STEADY_BINS)
        .count();
    let steady = (changed as f64) < CHANGED_SHARE * inner.len().max(1) as f64;
    let moved: i64 = shift.windows(2).map(|w| (w[1] - w[0]).abs()).sum();
    let minutes = (shift.len() as f64 * step_frames as f64 / frame_rate / 60.0).max(1e-9);
    let erratic = moved as f64 / BINS_PER_OCTAVE as f64 / minutes > MAX_OCTAVES_PER_MINUTE;
    LocalTempo {
        step_frames,
        bpm,
        shift,
        steady,
        erratic,
    }
}

fn median_i64(v: &[i64]) -> i64 {
    let mut s = v.to_vec();
    s.sort_unstable();
    s.get(s.len() / 2).copied().unwrap_or(0)
}

impl LocalTempo {
    /// Whether the beats should follow the curve: it moves, and not erratically.
    pub fn follows(&self) -> bool {
        !self.steady && !self.erratic
    }

    /// The beat period (onset frames) at each of `n` frames, linear in tempo between steps.
    pub fn periods(&self, n: usize, frame_rate: f64) -> Vec<f64> {
        (0..n)
            .map(|i| 60.0 * frame_rate / self.bpm_at_frame(i as f64))
            .collect()
    }

    fn bpm_at_frame(&self, frame: f64) -> f64 {
        let Some(&last) = self.bpm.last() else {
            return 120.0;
        };
        let x = frame / self.step_frames as f64;
        let i = x.floor() as usize;
        if i + 1 >= self.bpm.len() {
            return last;
        }
        let f = x - i as f64;
        self.bpm[i] * (1.0 - f) + self.bpm[i + 1] * f
    }

    /// Median tempo over the song's steps (BPM).
    pub fn median_bpm(&self) -> f64 {
        let mut b = self.bpm.clone();
        b.sort_by(f64::total_cmp);
        b.get(b.len() / 2).copied().unwrap_or(0.0)
    }

    /// The curve as served: a point where the tempo moves, at most every [`POINT_SPACING_S`],
    /// and the first and last step; steps that equal both neighbours are left out.
    pub fn points(&self, frame_rate: f64) -> Vec<TempoPoint> {
        let step_s = self.step_frames as f64 / frame_rate;
        let every = ((POINT_SPACING_S / step_s).round() as usize).max(1);
        let n = self.bpm.len();
        let mut picked: Vec<usize> = (0..n).step_by(every).collect();
        if n > 0 && picked.last() != Some(&(n - 1)) {
            picked.push(n - 1);
        }
        let mut out: Vec<TempoPoint> = Vec::new();
        for (j, &i) in picked.iter().enumerate() {
            let same_before = j > 0 && self.bpm[picked[j - 1]] == self.bpm[i];
            let same_after = j + 1 < picked.len() && self.bpm[picked[j + 1]] == self.bpm[i];
            if same_before && same_after {
                continue;
            }
            out.push(TempoPoint {
                time_s: i as f64 * step_s,
                bpm: self.bpm[i],
            });
        }
        out
    }
}

/// The curve of a steady song: its one tempo from the first to the last frame.
pub fn flat(bpm: f64, duration_s: f64) -> Vec<TempoPoint> {
    if bpm <= 0.0 {
        return Vec::new();
    }
    vec![
        TempoPoint { time_s: 0.0, bpm },
        TempoPoint {
            time_s: duration_s.max(0.0),
            bpm,
        },
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::audio::rhythm::{tempo_window, tempogram};

    /// Clicks at `bpm(t)`, as an onset envelope at 22 050 / 512 frames per second.
    fn clicks(seconds: f64, bpm: impl Fn(f64) -> f64) -> Vec<f32> {
        let fr = 22050.0 / 512.0;
        let n = (seconds * fr) as usize;
        let mut env = vec![0.0f32; n];
        let mut t = 0.0;
        while t < seconds {
            let i = (t * fr).round() as usize;
            if i < n {
                env[i] = 1.0;
            }
            t += 60.0 / bpm(t);
        }
        env
    }

    #[test]
    fn a_click_track_at_one_tempo_is_steady() {
        let env = clicks(40.0, |_| 100.0);
        let local = local_tempo(&tempogram(&env, tempo_window(22050, 512)), 22050, 512);
        assert!(local.steady, "{:?}", local.shift);
        assert!(
            (local.median_bpm() / 100.0 - 1.0).abs() < 0.03,
            "{}",
            local.median_bpm()
        );
    }

    #[test]
    fn a_click_track_that_speeds_up_is_followed_at_one_level() {
        let env = clicks(60.0, |t| if t < 30.0 { 90.0 } else { 140.0 });
        let local = local_tempo(&tempogram(&env, tempo_window(22050, 512)), 22050, 512);
        assert!(local.follows(), "{:?}", local.shift);
        let (early, late) = (local.bpm[12], local.bpm[48]);
        assert!((early / 90.0 - 1.0).abs() < 0.04, "{early}");
        assert!((late / 140.0 - 1.0).abs() < 0.04, "{late}");
        let points = local.points(22050.0 / 512.0);
        assert!(points.len() < 20, "{}", points.len());
    }
}
