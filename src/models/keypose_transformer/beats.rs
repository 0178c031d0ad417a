//! What the scaffold hears of a song ([`SongCues`]: its beat grid, tempo, meter and energy), and
//! the time maps that retime a bank clip onto it ([`TimeMap`], [`resample_rows`]).
//!
//! A train clip handed to the network in the clip's own timing, a pose every 12 frames, moves
//! the feet at that fixed 0.48-s spacing on every song and at every tempo (measured: 7 of 30
//! dances tempo-locked; the same song at 0.85× and 1.2× stepped at one rate). A real dancer's
//! steps sit at a fixed fraction of the beat, so a clip whose own beats are put on the song's beats
//! carries its steps onto the song's beat: the clip is played faster or slower between matched
//! beat pairs (a piecewise-linear map from song frames to clip frames), and its poses are read at
//! the song's beats.
use ndarray::{Array2, ArrayView2};

use crate::motion::repr::{ROOT_VX, ROOT_VZ, YAW_VEL};

/// Seconds of music each side of a frame whose mean onset strength is its local energy.
pub const ENERGY_HALF_S: f64 = 4.0;

/// A beat interval this many median periods long or longer holds beats the tracker missed.
const GAP: f64 = 1.5;

/// The song as the scaffold hears it, on the motion's frame clock.
#[derive(Clone, Debug)]
pub struct SongCues {
    /// Beat frames (fractional), ascending: the tracker's beats, gaps of a missed beat filled, and
    /// the grid continued at the median period before the first and after the last so it covers
    /// every frame of the dance (the first ≤ 0, the last ≥ the last frame).
    pub beats: Vec<f64>,
    /// Median beat period, frames.
    pub period: f64,
    /// Beats per bar (3 or 4) from the downbeats; 4 when they do not tell.
    pub bar: usize,
    /// Prefix sums of the onset strength per frame (`energy[t]` = sum of frames `< t`).
    energy: Vec<f64>,
    fps: f64,
}

impl SongCues {
    /// Cues of an `n`-frame dance at `fps` from the song's analysis (beat and downbeat times in
    /// seconds) and its onset strength per frame. Fewer than two beats (silence, a click):
    /// a grid every `fallback_period` frames.
    pub fn new(
        beat_times_s: &[f64],
        downbeat_times_s: &[f64],
        onset: &[f32],
        fps: f64,
        n: usize,
        fallback_period: f64,
    ) -> Self {
        let tracked: Vec<f64> = beat_times_s
            .iter()
            .map(|t| t * fps)
            .filter(|f| f.is_finite())
            .collect();
        let period = median_step(&tracked).unwrap_or(fallback_period).max(1.0);
        let mut beats = Vec::with_capacity(tracked.len() + 8);
        for (i, &b) in tracked.iter().enumerate() {
            if let Some(&prev) = i.checked_sub(1).and_then(|p| tracked.get(p)) {
                let gap = b - prev;
                if gap >= GAP * period {
                    let k = (gap / period).round() as usize;
                    beats.extend((1..k).map(|j| prev + gap * j as f64 / k as f64));
                }
            }
            beats.push(b);
        }
        if beats.is_empty() {
            beats.push(0.0);
        }
        let last_frame = n.saturating_sub(1) as f64;
        let mut before = Vec::new();
        let mut f = beats[0];
        while f > 0.0 {
            f -= period;
            before.push(f);
        }
        before.reverse();
        before.append(&mut beats);
        let mut beats = before;
        while *beats.last().unwrap_or(&0.0) < last_frame {
            let next = beats.last().copied().unwrap_or(0.0) + period;
            beats.push(next);
        }
        if beats.len() < 2 {
            beats.push(beats[0] + period);
        }
        let down: Vec<f64> = downbeat_times_s.iter().map(|t| t * fps).collect();
        let bar = beats_a_bar(median_step(&down), period);
        let mut energy = Vec::with_capacity(onset.len() + 1);
        energy.push(0.0);
        for &v in onset {
            let last = *energy.last().unwrap_or(&0.0);
            energy.push(last + f64::from(v).max(0.0));
        }
        Self {
            beats,
            period,
            bar,
            energy,
            fps,
        }
    }

    /// Mean onset strength within [`ENERGY_HALF_S`] of `frame`; 0 without onsets.
    pub fn energy_at(&self, frame: f64) -> f64 {
        let n = self.energy.len() - 1;
        if n == 0 {
            return 0.0;
        }
        let half = ENERGY_HALF_S * self.fps;
        let a = (frame - half).clamp(0.0, n as f64) as usize;
        let b = ((frame + half).clamp(0.0, n as f64) as usize).max((a + 1).min(n));
        if b <= a {
            return 0.0;
        }
        (self.energy[b] - self.energy[a]) / (b - a) as f64
    }
}

/// Median of the steps of an ascending sequence; none with fewer than two values.
/// Beats a bar from the median downbeat step and the beat period (the same unit): 3 where the
/// downbeats come every three beats, else 4 (also when there are no downbeats to tell).
pub fn beats_a_bar(downbeat_step: Option<f64>, beat_period: f64) -> usize {
    downbeat_step.map_or(4, |d| {
        if (d / beat_period).round() as usize == 3 {
            3
        } else {
            4
        }
    })
}

pub fn median_step(x: &[f64]) -> Option<f64> {
    let mut d: Vec<f64> = x
        .windows(2)
        .map(|p| p[1] - p[0])
        .filter(|d| *d > 0.0)
        .collect();
    if d.is_empty() {
        return None;
    }
    d.sort_by(f64::total_cmp);
    Some(d[d.len() / 2])
}

/// A monotone piecewise-linear map through `(x, y)` pairs, continued past the ends with the
/// slope of the end segments: song frames → clip frames, or beat index → frame.
#[derive(Clone, Debug, PartialEq)]
pub struct TimeMap {
    pairs: Vec<(f64, f64)>,
}

impl TimeMap {
    /// Keeps the pairs whose `x` and `y` both rise (a pair that would fold time back is dropped);
    /// none when fewer than two remain.
    pub fn new(pairs: impl IntoIterator<Item = (f64, f64)>) -> Option<Self> {
        let mut kept: Vec<(f64, f64)> = Vec::new();
        for (x, y) in pairs {
            if !(x.is_finite() && y.is_finite()) {
                continue;
            }
            match kept.last() {
                Some(&(px, py)) if x <= px || y <= py => {}
                _ => kept.push((x, y)),
            }
        }
        (kept.len() >= 2).then_some(Self { pairs: kept })
    }

    /// The segment holding `x` (the first or last beyond the ends).
    fn segment(&self, x: f64) -> usize {
        let i = self.pairs.partition_point(|p| p.0 <= x);
        i.clamp(1, self.pairs.len() - 1) - 1
    }

    /// `y` at `x`.
    pub fn at(&self, x: f64) -> f64 {
        let i = self.segment(x);
        let ((x0, y0), (x1, y1)) = (self.pairs[i], self.pairs[i + 1]);
        y0 + (x - x0) * (y1 - y0) / (x1 - x0)
    }

    /// `dy/dx` at `x` (the segment's).
    pub fn slope(&self, x: f64) -> f64 {
        let i = self.segment(x);
        let ((x0, y0), (x1, y1)) = (self.pairs[i], self.pairs[i + 1]);
        (y1 - y0) / (x1 - x0)
    }

    /// The last pair's `x`.
    pub fn last_x(&self) -> f64 {
        self.pairs[self.pairs.len() - 1].0
    }
}

/// Row `t` of `rows` `[l, d]` at a fractional frame (linear between neighbours, held at the ends).
pub fn row_at(rows: ArrayView2<'_, f32>, t: f64) -> Vec<f32> {
    let l = rows.nrows();
    let t = t.clamp(0.0, (l - 1) as f64);
    let i = (t.floor() as usize).min(l - 1);
    let j = (i + 1).min(l - 1);
    let w = (t - i as f64) as f32;
    rows.row(i)
        .iter()
        .zip(rows.row(j).iter())
        .map(|(a, b)| a + w * (b - a))
        .collect()
}

/// Feature rows `[l, 73]` read at song frames `0..n` through `map` (song frame → clip frame): a
/// clip played at the map's pace. The per-frame velocities (root travel, yaw) scale with it.
pub fn resample_rows(rows: ArrayView2<'_, f32>, map: &TimeMap, n: usize) -> Array2<f32> {
    let mut out = Array2::<f32>::zeros((n, rows.ncols()));
    for s in 0..n {
        let row = row_at(rows, map.at(s as f64));
        out.row_mut(s).assign(&ndarray::ArrayView1::from(&row));
        let rate = map.slope(s as f64) as f32;
        for c in [ROOT_VX, ROOT_VZ, YAW_VEL] {
            if c < out.ncols() {
                out[[s, c]] *= rate;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_grid_fills_missed_beats_and_covers_the_dance() {
        // Beats every 0.5 s from 1 s, one missed at 3 s; 10 s at 25 fps.
        let times: Vec<f64> = (2..20)
            .map(|k| k as f64 * 0.5)
            .filter(|t| (*t - 3.0).abs() > 1e-9)
            .collect();
        let c = SongCues::new(&times, &[1.0, 3.0, 5.0, 7.0], &[1.0; 250], 25.0, 250, 12.0);
        assert!((c.period - 12.5).abs() < 1e-9);
        assert!(c.beats[0] <= 0.0 && *c.beats.last().unwrap() >= 249.0);
        assert!(
            c.beats
                .windows(2)
                .all(|p| (p[1] - p[0] - 12.5).abs() < 1e-9),
            "{:?}",
            c.beats
        );
        assert_eq!(c.bar, 4);
        assert!((c.energy_at(100.0) - 1.0).abs() < 1e-9);
        // Three beats a bar.
        let w = SongCues::new(&times, &[1.0, 2.5, 4.0, 5.5], &[], 25.0, 250, 12.0);
        assert_eq!(w.bar, 3);
        assert_eq!(w.energy_at(10.0), 0.0);
        // No beats: the fallback grid.
        let s = SongCues::new(&[], &[], &[], 25.0, 100, 12.0);
        assert!(
            s.beats
                .windows(2)
                .all(|p| (p[1] - p[0] - 12.0).abs() < 1e-9)
                && s.beats.len() >= 9
        );
    }

    #[test]
    fn a_time_map_puts_clip_beats_on_song_beats_and_is_monotone() {
        // Song beats every 10 frames from 3; the clip's beats every 14 frames from 5, a little uneven.
        let song: Vec<f64> = (0..8).map(|k| 3.0 + 10.0 * k as f64).collect();
        let clip = [5.0, 19.0, 32.0, 47.0, 61.0, 74.0, 89.0, 103.0];
        let map = TimeMap::new(song.iter().copied().zip(clip)).unwrap();
        for (s, c) in song.iter().zip(clip) {
            assert!((map.at(*s) - c).abs() < 1e-9);
        }
        let ys: Vec<f64> = (-20..120).map(|s| map.at(s as f64 * 0.5)).collect();
        assert!(ys.windows(2).all(|p| p[1] > p[0]));
        // Beyond the ends the end segments' slopes continue.
        assert!((map.slope(-100.0) - 1.4).abs() < 1e-9 && (map.slope(500.0) - 1.4).abs() < 1e-9);
        // Pairs that would fold time back are dropped.
        let m = TimeMap::new([(0.0, 0.0), (1.0, 2.0), (2.0, 1.0), (3.0, 4.0)]).unwrap();
        assert_eq!(m.pairs.len(), 3);
        assert!(TimeMap::new([(0.0, 0.0)]).is_none());
    }

    #[test]
    fn resampled_rows_follow_the_map_and_scale_velocities() {
        let rows = Array2::from_shape_fn((50, crate::motion::repr::FEATURE_DIM), |(t, c)| {
            if c == ROOT_VX {
                0.02
            } else {
                t as f32
            }
        });
        // Played twice as fast: song frame s reads clip frame 2s + 1.
        let map = TimeMap::new([(0.0, 1.0), (10.0, 21.0)]).unwrap();
        let out = resample_rows(rows.view(), &map, 12);
        assert!((out[[5, 0]] - 11.0).abs() < 1e-5);
        assert!((out[[5, ROOT_VX]] - 0.04).abs() < 1e-6);
        // Half frames interpolate.
        assert!((row_at(rows.view(), 2.5)[0] - 2.5).abs() < 1e-6);
        assert_eq!(row_at(rows.view(), 80.0)[0], 49.0);
    }
}
