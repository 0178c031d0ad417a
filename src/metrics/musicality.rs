//! Does the dance go with *this* song: tempo lock, arm liveliness, knee direction (and, kept with
//! them in every report and eval row, the longest hold of [`crate::motion::hold`]).
//!
//! # Tempo lock
//! Real dancers step at a fixed fraction of the beat. Over a whole dance, the peak (0.25–3 Hz) of
//! the spectrum of both ankles' summed speed, divided by the song's beat rate, is 1/2 for rumba
//! and cha-cha and 1/3 for waltz (1/6 where the tracker counts double time): within 2 % of one of
//! [`TEMPO_FRACTIONS`] on 28 of the 43 dances of dance-with-melody, within 3 % on 32. Models that
//! ignore the music land there by chance. FACT's beat-align score cannot see this on this data
//! (real 0.175 against mismatched 0.177: dancers' speed minima do not phase-lock to the beats,
//! [`super::beats`]), so the rate, not the phase, is what we measure.
//!
//! The speed is summed over the two ankles, its mean removed, Hann-windowed and zero-padded to
//! [`ZERO_PAD`] times its length: a 30-s test dance has a 0.033 Hz bin, 4 % of a waltz's step
//! rate, too coarse for a 3 % tolerance; padding interpolates the spectrum between bins. The beat
//! rate is `(beats − 1) / (last beat − first beat)` over the song's beats that fall inside the
//! dance (the rate the dancer heard, not an average over an intro it did not dance).
//!
//! # Arm liveliness
//! Mean speed of the elbows and wrists relative to the spine joint: what the arms do, not where
//! the body travels. Real dances 0.43–1.44 m/s (median 0.61); a model that holds its arms in one
//! ballroom hold for the whole song moves them 0.3–0.4.
//!
//! # Knee direction
//! The share of knee-frames (both knees pooled) in which the knee is bent more than
//! [`KNEE_BENT_DEG`] and lies behind the hip–ankle line, against the foot's direction (heel → toe,
//! both taken perpendicular to the hip–ankle line): a knee bending the wrong way. Real dances at
//! most 4.6 % (a knee slightly hyperextended while the foot turns out reads as "behind").
use ndarray::{ArrayView3, Axis};
use realfft::RealFftPlanner;

use crate::motion::skeleton::{ANKLES, HEELS, HIPS, SPINE, TOES};
use crate::motion::Motion;

/// The fractions of the beat rate real dancers step at (1/6: a waltz whose tracker counts double
/// time; 2/3 and 1: fast figures).
pub const TEMPO_FRACTIONS: [f64; 6] = [1.0 / 6.0, 1.0 / 4.0, 1.0 / 3.0, 1.0 / 2.0, 2.0 / 3.0, 1.0];
/// How [`TEMPO_FRACTIONS`] are written, in their order.
const FRACTION_NAMES: [&str; 6] = ["1/6", "1/4", "1/3", "1/2", "2/3", "1"];

/// The nearest of [`TEMPO_FRACTIONS`] to `q`, written as a fraction ("1/2").
pub fn fraction_name(q: f64) -> &'static str {
    let nearest = (0..TEMPO_FRACTIONS.len())
        .min_by(|&a, &b| {
            (TEMPO_FRACTIONS[a] - q)
                .abs()
                .total_cmp(&(TEMPO_FRACTIONS[b] - q).abs())
        })
        .unwrap_or(0);
    FRACTION_NAMES[nearest]
}

/// A dance is tempo-locked when its step-rate ratio is within this relative distance of a
/// fraction (the tempo-lock bar: 3 %).
pub const TEMPO_LOCK_TOLERANCE: f64 = 0.03;
/// The band (Hz) searched for the step rate: slower is drift, faster is jitter.
pub const STEP_BAND_HZ: (f64, f64) = (0.25, 3.0);
/// The speed series is zero-padded to this many times its length before the FFT.
pub const ZERO_PAD: usize = 16;
/// Elbows and wrists, the joints whose speed relative to the spine is the arms' liveliness.
pub const ARM_JOINTS: [usize; 4] = [4, 6, 13, 15];
/// A knee bent less than this (degrees between thigh and shin) is straight, whichever side.
pub const KNEE_BENT_DEG: f64 = 15.0;
/// The fewest beats and frames a tempo lock is measured on.
/// Right and left knee.
const KNEES: [usize; 2] = [8, 17];
const MIN_BEATS: usize = 4;
const MIN_FRAMES: usize = 50;

/// The dominant step rate of a dance against its song's beat rate.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize, utoipa::ToSchema)]
pub struct TempoLock {
    /// Peak of the ankles' speed spectrum within [`STEP_BAND_HZ`] (Hz).
    pub step_hz: f64,
    /// The song's beat rate over the dance (Hz).
    pub beat_hz: f64,
    /// `step_hz / beat_hz`.
    pub ratio: f64,
    /// The nearest of [`TEMPO_FRACTIONS`].
    pub fraction: f64,
    /// `|ratio − fraction| / fraction`.
    pub distance: f64,
    /// `distance ≤` [`TEMPO_LOCK_TOLERANCE`].
    pub locked: bool,
}

/// The measures of this module (and the hold, [`crate::motion::hold`]) for one dance (`Default`: nothing measured, for reports
/// written before they existed).
#[derive(
    Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize, utoipa::ToSchema,
)]
pub struct Musicality {
    /// `None` when the dance is shorter than 2 s or has fewer than 4 beats.
    pub tempo_lock: Option<TempoLock>,
    /// Mean speed of elbows and wrists relative to the spine (m/s).
    pub arm_speed_m_s: f64,
    /// Share of knee-frames bent backwards (0..=1).
    pub knee_backward_share: f64,
    /// The longest span (s) held in one pose ([`crate::motion::hold::longest_hold_s`]; 0 in reports
    /// written before it was measured).
    #[serde(default)]
    pub longest_hold_s: f64,
    /// How far the arms' posture moves over the song (m, [`super::posture::posture_variety_m`]): near 0 for a
    /// dance that holds one figure throughout. `None` for a dance shorter than 12 s, and in
    /// reports written before it was measured.
    #[serde(default)]
    pub posture_variety_m: Option<f64>,
}

impl Musicality {
    /// Measures `motion` (23 joints, metres) against the song's beats on the dance's clock
    /// (seconds from motion frame 0).
    pub fn of(motion: &Motion, beat_times_s: &[f64]) -> Self {
        let p = motion.positions.view();
        Self {
            tempo_lock: tempo_lock(p, motion.fps, beat_times_s),
            arm_speed_m_s: arm_speed_m_s(p, motion.fps),
            knee_backward_share: knee_backward_share(p),
            longest_hold_s: crate::motion::hold::longest_hold_s(p, motion.fps),
            posture_variety_m: super::posture::posture_variety_m(p, motion.fps),
        }
    }
}

/// A set of dances against the musicality bars: the share tempo-locked, the stillest arms, the
/// worst knees (each bar is on every dance, so the set reports its extremes, not its means).
#[derive(
    Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize, utoipa::ToSchema,
)]
pub struct MusicalitySummary {
    /// Dances with a measurable step rate.
    pub measured: usize,
    /// Of those, tempo-locked within [`TEMPO_LOCK_TOLERANCE`].
    pub tempo_locked: usize,
    /// `tempo_locked / measured` (NaN when none was measured).
    pub tempo_locked_share: f64,
    /// The slowest dance's arms (m/s).
    pub arm_speed_min_m_s: f64,
    /// The worst dance's share of knee-frames bent backwards.
    pub knee_backward_max: f64,
    /// The longest hold of any dance (s; 0 in files written before it was measured).
    #[serde(default)]
    pub longest_hold_max_s: f64,
    /// The dance whose arms' posture moved least over its song (m; `None` when no dance was long
    /// enough, or in files written before it was measured).
    #[serde(default)]
    pub posture_variety_min_m: Option<f64>,
}

impl MusicalitySummary {
    /// Summarises the dances' measures.
    pub fn of<'a>(dances: impl IntoIterator<Item = &'a Musicality>) -> Self {
        let mut s = Self {
            arm_speed_min_m_s: f64::INFINITY,
            ..Self::default()
        };
        let mut any = false;
        for m in dances {
            any = true;
            if let Some(lock) = m.tempo_lock {
                s.measured += 1;
                s.tempo_locked += usize::from(lock.locked);
            }
            s.arm_speed_min_m_s = s.arm_speed_min_m_s.min(m.arm_speed_m_s);
            s.knee_backward_max = s.knee_backward_max.max(m.knee_backward_share);
            s.longest_hold_max_s = s.longest_hold_max_s.max(m.longest_hold_s);
            if let Some(v) = m.posture_variety_m {
                s.posture_variety_min_m = Some(s.posture_variety_min_m.map_or(v, |w| w.min(v)));
            }
        }
        if !any {
            s.arm_speed_min_m_s = f64::NAN;
        }
        s.tempo_locked_share = if s.measured == 0 {
            f64::NAN
        } else {
            s.tempo_locked as f64 / s.measured as f64
        };
        s
    }

    /// The mean dance, for a set's `mean` scores: arms, knees, holds and posture variety averaged
    /// (the last over the dances long enough to have one), no tempo lock (a set's tempo lock is
    /// [`MusicalitySummary::tempo_locked_share`]).
    pub fn mean<'a>(dances: impl IntoIterator<Item = &'a Musicality> + Clone) -> Musicality {
        let n = dances.clone().into_iter().count().max(1) as f64;
        let mean_of =
            |f: fn(&Musicality) -> f64| dances.clone().into_iter().map(f).sum::<f64>() / n;
        Musicality {
            tempo_lock: None,
            arm_speed_m_s: mean_of(|m| m.arm_speed_m_s),
            knee_backward_share: mean_of(|m| m.knee_backward_share),
            longest_hold_s: mean_of(|m| m.longest_hold_s),
            posture_variety_m: {
                let v: Vec<f64> = dances
                    .into_iter()
                    .filter_map(|m| m.posture_variety_m)
                    .collect();
                (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
            },
        }
    }
}

/// What the real dances measure (`reference_train.json`, `choreo eval --write-reference`), each
/// against its own song's beats.
#[derive(
    Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize, utoipa::ToSchema,
)]
pub struct MusicalityReference {
    /// The bars on the set (tempo-locked share, stillest arms, worst knees).
    pub summary: MusicalitySummary,
    /// Dances whose step rate is within 2 % of a fraction of the beat rate.
    pub within_2_percent: usize,
    /// Slowest and fastest dance's arms (m/s).
    pub arm_speed_range_m_s: [f64; 2],
    /// The median dance's arms (m/s).
    pub arm_speed_median_m_s: f64,
    /// The stillest and the most changing dance's arms' posture over the song (m,
    /// [`super::posture::posture_variety_m`]; absent in files written before it was measured).
    #[serde(default)]
    pub posture_variety_range_m: Option<[f64; 2]>,
    /// The median dance's posture variety (m).
    #[serde(default)]
    pub posture_variety_median_m: Option<f64>,
}

impl MusicalityReference {
    /// Measures real dances, each with the song's beats on its own clock.
    pub fn compute(dances: &[(&Motion, &[f64])]) -> Self {
        let all: Vec<Musicality> = dances
            .iter()
            .map(|(m, beats)| Musicality::of(m, beats))
            .collect();
        let mut arms: Vec<f64> = all.iter().map(|m| m.arm_speed_m_s).collect();
        arms.sort_by(f64::total_cmp);
        let mut postures: Vec<f64> = all.iter().filter_map(|m| m.posture_variety_m).collect();
        postures.sort_by(f64::total_cmp);
        Self {
            summary: MusicalitySummary::of(&all),
            within_2_percent: all
                .iter()
                .filter(|m| m.tempo_lock.is_some_and(|l| l.distance <= 0.02))
                .count(),
            arm_speed_range_m_s: [
                arms.first().copied().unwrap_or(f64::NAN),
                arms.last().copied().unwrap_or(f64::NAN),
            ],
            arm_speed_median_m_s: arms.get(arms.len() / 2).copied().unwrap_or(f64::NAN),
            posture_variety_range_m: postures.first().zip(postures.last()).map(|(a, b)| [*a, *b]),
            posture_variety_median_m: postures.get(postures.len() / 2).copied(),
        }
    }
}

/// The beat rate (Hz) of the beats within `[0, duration_s]`: `(n − 1) / (last − first)`.
pub fn beat_rate_hz(beat_times_s: &[f64], duration_s: f64) -> Option<f64> {
    let inside: Vec<f64> = beat_times_s
        .iter()
        .copied()
        .filter(|t| (0.0..=duration_s).contains(t))
        .collect();
    let (first, last) = (inside.first()?, inside.last()?);
    (inside.len() >= MIN_BEATS && last > first).then(|| (inside.len() - 1) as f64 / (last - first))
}

/// The frequency (Hz) of the largest magnitude within `band` of the spectrum of `x` (sampled at
/// `rate` Hz), after removing the mean, a Hann window and zero-padding to `ZERO_PAD × len`.
pub fn spectral_peak_hz(x: &[f64], rate: f64, band: (f64, f64)) -> Option<f64> {
    let n = x.len();
    if n < 2 {
        return None;
    }
    let mean = x.iter().sum::<f64>() / n as f64;
    let padded = n * ZERO_PAD;
    let mut input = vec![0.0; padded];
    for (i, (v, out)) in x.iter().zip(input.iter_mut()).enumerate() {
        // The periodic Hann window numpy's `hanning` is not: numpy's is symmetric (n − 1).
        let w = 0.5 - 0.5 * (2.0 * std::f64::consts::PI * i as f64 / (n - 1) as f64).cos();
        *out = (v - mean) * w;
    }
    let fft = RealFftPlanner::<f64>::new().plan_fft_forward(padded);
    let mut spectrum = fft.make_output_vec();
    // realfft only errors on buffer lengths, which come from the plan itself.
    fft.process(&mut input, &mut spectrum).ok()?;
    let bin_hz = rate / padded as f64;
    spectrum
        .iter()
        .enumerate()
        .map(|(k, c)| (k as f64 * bin_hz, c.norm()))
        .filter(|(f, _)| (band.0..=band.1).contains(f))
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(f, _)| f)
}

/// Tempo lock of a dance (positions `[T, 23, 3]` in metres) against the song's beats on the
/// dance's clock.
pub fn tempo_lock(
    positions: ArrayView3<'_, f32>,
    fps: f64,
    beat_times_s: &[f64],
) -> Option<TempoLock> {
    let frames = positions.len_of(Axis(0));
    if frames < MIN_FRAMES {
        return None;
    }
    let beat_hz = beat_rate_hz(beat_times_s, frames as f64 / fps)?;
    let speed: Vec<f64> = (1..frames)
        .map(|f| {
            ANKLES
                .iter()
                .map(|&j| step_length(positions, f, j) * fps)
                .sum()
        })
        .collect();
    let step_hz = spectral_peak_hz(&speed, fps, STEP_BAND_HZ)?;
    let ratio = step_hz / beat_hz;
    let (fraction, distance) = TEMPO_FRACTIONS
        .iter()
        .map(|&q| (q, (ratio - q).abs() / q))
        .min_by(|a, b| a.1.total_cmp(&b.1))?;
    Some(TempoLock {
        step_hz,
        beat_hz,
        ratio,
        fraction,
        distance,
        locked: distance <= TEMPO_LOCK_TOLERANCE,
    })
}

fn step_length(p: ArrayView3<'_, f32>, f: usize, j: usize) -> f64 {
    (0..3)
        .map(|c| (f64::from(p[[f, j, c]]) - f64::from(p[[f - 1, j, c]])).powi(2))
        .sum::<f64>()
        .sqrt()
}

/// Mean speed (m/s) of [`ARM_JOINTS`] relative to the spine joint; 0 for fewer than 2 frames.
pub fn arm_speed_m_s(positions: ArrayView3<'_, f32>, fps: f64) -> f64 {
    let frames = positions.len_of(Axis(0));
    if frames < 2 {
        return 0.0;
    }
    let rel = |f: usize, j: usize, c: usize| {
        f64::from(positions[[f, j, c]]) - f64::from(positions[[f, SPINE, c]])
    };
    let mut sum = 0.0;
    for f in 1..frames {
        for &j in &ARM_JOINTS {
            sum += (0..3)
                .map(|c| (rel(f, j, c) - rel(f - 1, j, c)).powi(2))
                .sum::<f64>()
                .sqrt();
        }
    }
    sum * fps / ((frames - 1) * ARM_JOINTS.len()) as f64
}

/// Share of knee-frames (both legs) bent more than [`KNEE_BENT_DEG`] with the knee behind the
/// hip–ankle line against the foot's heel → toe direction; 0 for no frames.
pub fn knee_backward_share(positions: ArrayView3<'_, f32>) -> f64 {
    let frames = positions.len_of(Axis(0));
    if frames == 0 {
        return 0.0;
    }
    let at = |f: usize, j: usize| {
        let v = positions.slice(ndarray::s![f, j, ..]);
        nalgebra::Vector3::new(f64::from(v[0]), f64::from(v[1]), f64::from(v[2]))
    };
    let knees = KNEES;
    let mut backward = 0usize;
    for f in 0..frames {
        for leg in 0..2 {
            let (hip, knee, ankle) = (at(f, HIPS[leg]), at(f, knees[leg]), at(f, ANKLES[leg]));
            let (thigh, shin) = (knee - hip, ankle - knee);
            let bent = thigh.angle(&shin).to_degrees() > KNEE_BENT_DEG;
            let Some(line) = (ankle - hip).try_normalize(1e-9) else {
                continue;
            };
            let off_line = |v: nalgebra::Vector3<f64>| v - line * v.dot(&line);
            let knee_side = off_line(knee - hip);
            let foot = off_line(at(f, TOES[leg]) - at(f, HEELS[leg]));
            if bent && knee_side.dot(&foot) < 0.0 {
                backward += 1;
            }
        }
    }
    backward as f64 / (2 * frames) as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array3;

    /// A standing skeleton whose ankles bob at `step_hz` (speed peaks at twice the bob for a
    /// sine of position: the ankles' speed |cos| has its fundamental at 2 × the position's).
    fn stepping(frames: usize, fps: f64, ankle_hz: f64) -> Array3<f32> {
        let mut p = Array3::<f32>::zeros((frames, 23, 3));
        for f in 0..frames {
            let t = f as f64 / fps;
            for j in 0..23 {
                p[[f, j, 1]] = 1.0;
            }
            let (hy, ky, ay) = (0.9, 0.5, 0.1);
            for (leg, phase) in [(0usize, 0.0), (1usize, std::f64::consts::PI)] {
                p[[f, HIPS[leg], 1]] = hy;
                p[[f, HIPS[leg] + 1, 1]] = ky;
                p[[f, HIPS[leg] + 1, 2]] = 0.05; // knee forward (+z)
                p[[f, ANKLES[leg], 1]] = ay;
                p[[f, ANKLES[leg], 2]] =
                    (0.2 * (2.0 * std::f64::consts::PI * ankle_hz * t + phase).sin()) as f32;
                p[[f, HEELS[leg], 1]] = 0.02;
                p[[f, TOES[leg], 1]] = 0.02;
                p[[f, TOES[leg], 2]] = 0.15; // toes forward (+z)
            }
        }
        p
    }

    #[test]
    fn the_step_rate_is_found_to_a_fraction_of_a_percent() {
        // Ankles swinging at 0.36 Hz: each ankle's speed peaks twice a cycle, 0.72 Hz; a
        // 90-bpm song (1.5 Hz) makes that 0.48 of the beat, 4 % from 1/2: not locked.
        let fps = 25.0;
        let p = stepping(25 * 60, fps, 0.36);
        let beats: Vec<f64> = (0..90).map(|i| i as f64 / 1.5).collect();
        let lock = tempo_lock(p.view(), fps, &beats).expect("measurable");
        assert!((lock.step_hz - 0.72).abs() < 0.005, "{lock:?}");
        assert!((lock.beat_hz - 1.5).abs() < 1e-9);
        assert_eq!(lock.fraction, 0.5);
        assert!(!lock.locked, "{lock:?}");
        // At 0.375 Hz the ankles' speed peaks at 0.75 Hz = half the beat: locked.
        let lock =
            tempo_lock(stepping(25 * 60, fps, 0.375).view(), fps, &beats).expect("measurable");
        assert!(lock.distance < 0.005 && lock.locked, "{lock:?}");
    }

    #[test]
    fn too_short_or_beatless_dances_have_no_tempo_lock() {
        let p = stepping(40, 25.0, 0.5);
        assert_eq!(tempo_lock(p.view(), 25.0, &[0.0, 0.5, 1.0, 1.5]), None);
        let p = stepping(500, 25.0, 0.5);
        assert_eq!(tempo_lock(p.view(), 25.0, &[0.0, 0.5, 1.0]), None);
        // Beats after the dance do not count.
        assert_eq!(
            tempo_lock(p.view(), 25.0, &[0.0, 0.5, 30.0, 31.0, 32.0]),
            None
        );
    }

    #[test]
    fn arms_held_still_against_the_spine_do_not_count_as_lively() {
        // The whole body translating at 1 m/s: the arms move with the spine, 0 relative to it.
        let mut p = Array3::<f32>::zeros((50, 23, 3));
        for f in 0..50 {
            for j in 0..23 {
                p[[f, j, 0]] = f as f32 / 25.0;
            }
        }
        assert!(arm_speed_m_s(p.view(), 25.0).abs() < 1e-6);
        // One wrist circling the spine at 0.5 m/s: a quarter of that over the four arm joints.
        for f in 0..50 {
            let a = f as f64 / 25.0 * 0.5 / 0.25; // radius 0.25 m, 0.5 m/s
            p[[f, 6, 1]] = (0.25 * a.cos()) as f32;
            p[[f, 6, 2]] = (0.25 * a.sin()) as f32;
        }
        let v = arm_speed_m_s(p.view(), 25.0);
        assert!((v - 0.125).abs() < 0.002, "{v}");
    }

    #[test]
    fn a_knee_behind_the_line_against_the_toes_is_backwards() {
        let mut p = stepping(10, 25.0, 0.0);
        assert_eq!(
            knee_backward_share(p.view()),
            0.0,
            "knee forward of the line, with the toes"
        );
        // Move one knee 10 cm behind the hip–ankle line (against the toes, −z): bent ~23°.
        for f in 0..10 {
            p[[f, HIPS[0] + 1, 2]] = -0.1;
        }
        assert!((knee_backward_share(p.view()) - 0.5).abs() < 1e-9);
        // A straight knee slightly behind the line (< 15° bend) is not counted.
        for f in 0..10 {
            p[[f, HIPS[0] + 1, 2]] = -0.02;
        }
        assert_eq!(knee_backward_share(p.view()), 0.0);
    }
}
