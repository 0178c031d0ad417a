//! A dance's pace after a tempo that changes inside the song (a DJ mix, a medley, a ritardando).
//!
//! The networks hear a song at one pace: dance-revolution's beat clock resamples the whole song by
//! one factor, and dancenet and tsmt step at their own steady rate (their step rate after ÷ before
//! a 1.5625× speed-up was 0.99–1.06). The beat-align stage keeps one grid fraction and a mean
//! slope of 1 over the dance, so it cannot add the change either. This stage does, before it:
//! where the song's beats say the tempo changes, the dance is time-warped so that its pace
//! follows the local tempo (output frame `f` shows source time `∫ r`, `r = (p̄ / p(f))^α`, `p`
//! the local beat length, scaled so the dance's last frame stays its last), in place of beat
//! alignment ([`crate::motion::after_model`] skips it after this warp). `α` is 1 for a dance at
//! one pace, and the share of the change a dance's own steps lack where they change already
//! (the key-pose transformer's own ratio was 1.24–1.95). It leaves alone a steady song (p90 ÷ p10
//! of the local beat under [`CHANGE_RATIO`]), a dance with key poses or a seed motion (their
//! frames are fixed), and a dance whose own steps already follow the change within 10 %.
use super::rhythm::{ankle_speed, step_rate, CHECK_ZERO_PAD};
use super::{resample, Motion};

/// The local beat's p90 ÷ p10 above which the song's tempo is taken to change (a steady song's
/// tracked beats vary by a few per cent).
pub const CHANGE_RATIO: f64 = 1.2;
/// Beats either side whose intervals' median is the local beat.
const HALF_WINDOW: usize = 4;
/// The least share of the music's change the warp adds: below 0 it slows the fast part of a
/// dance whose own steps sped up more than the music; a measured step rate that jumped to a
/// harmonic would ask for far more, so the share is bounded.
const MIN_ALPHA: f64 = -1.0;
/// Shortest stretch (s) of one pace whose step rate is measured.
const MIN_STRETCH_S: f64 = 8.0;

/// The local beat length (s) at each frame: the median of the beat intervals around the nearest
/// beat; `None` when the song has too few beats in the dance.
fn local_beat(beats: &[f64], frames: usize, fps: f64) -> Option<Vec<f64>> {
    let inside: Vec<f64> = beats
        .iter()
        .copied()
        .filter(|&b| b >= 0.0 && b <= frames as f64 / fps)
        .collect();
    if inside.len() < 4 * HALF_WINDOW {
        return None;
    }
    let intervals: Vec<f64> = inside.windows(2).map(|w| w[1] - w[0]).collect();
    let at_beat: Vec<f64> = (0..intervals.len())
        .map(|i| {
            let lo = i.saturating_sub(HALF_WINDOW);
            let hi = (i + HALF_WINDOW + 1).min(intervals.len());
            let mut w = intervals[lo..hi].to_vec();
            w.sort_by(f64::total_cmp);
            w[w.len() / 2]
        })
        .collect();
    Some(
        (0..frames)
            .map(|f| {
                let t = f as f64 / fps;
                let i = inside.partition_point(|&b| b <= t).saturating_sub(1);
                at_beat[i.min(at_beat.len() - 1)]
            })
            .collect(),
    )
}

fn percentile(v: &[f64], q: f64) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s[((s.len() - 1) as f64 * q).round() as usize]
}

/// The longest run of frames whose local beat satisfies `keep`, as `(start, end)`.
fn longest_run(period: &[f64], keep: impl Fn(f64) -> bool) -> (usize, usize) {
    let (mut best, mut start) = ((0, 0), None);
    for (f, &p) in period
        .iter()
        .enumerate()
        .chain(std::iter::once((period.len(), &f64::NAN)))
    {
        match (keep(p), start) {
            (true, None) => start = Some(f),
            (false, Some(s)) => {
                if f - s > best.1 - best.0 {
                    best = (s, f);
                }
                start = None;
            }
            _ => {}
        }
    }
    best
}

/// The local beat's (per frame) 10th and 90th percentiles.
fn spread(period: &[f64]) -> (f64, f64) {
    (percentile(period, 0.1), percentile(period, 0.9))
}

/// Whether a local beat spread from `p10` to `p90` is a tempo change ([`CHANGE_RATIO`]).
fn changes((p10, p90): (f64, f64)) -> bool {
    p90 / p10 >= CHANGE_RATIO
}

/// Whether the song's tempo changes over a dance of `frames` at `fps` (what [`follow_tempo`]
/// warps for).
pub fn tempo_changes(beat_times_s: &[f64], frames: usize, fps: f64) -> bool {
    local_beat(beat_times_s, frames, fps).is_some_and(|p| changes(spread(&p)))
}

/// The step rate (Hz) of frames `range` of `motion`.
fn steps_hz(motion: &Motion, (a, b): (usize, usize)) -> Option<f64> {
    let p = motion.positions.slice(ndarray::s![a..b, .., ..]);
    step_rate(&ankle_speed(p, motion.fps), motion.fps, CHECK_ZERO_PAD).map(|(hz, _)| hz)
}

/// The dance with its pace following the song's tempo where it changes (module doc); the dance
/// as it came where it does not, where `fixed` (key poses or a seed motion), or where its steps
/// follow already.
pub fn follow_tempo(motion: Motion, beat_times_s: &[f64], fixed: bool) -> Motion {
    let frames = motion.num_frames();
    let fps = motion.fps;
    if fixed || frames < 2 {
        return motion;
    }
    let Some(period) = local_beat(beat_times_s, frames, fps) else {
        return motion;
    };
    let (p10, p90) = spread(&period);
    if !changes((p10, p90)) {
        return motion;
    }
    let median = percentile(&period, 0.5);
    // Split between the two paces at their geometric middle: a song of two equal halves has its
    // median on one of them, which would leave that side no run to measure.
    let middle = (p10 * p90).sqrt();
    let slow = longest_run(&period, |p| p > middle);
    let fast = longest_run(&period, |p| p < middle);
    let long = |(a, b): (usize, usize)| (b - a) as f64 / fps >= MIN_STRETCH_S;
    // How much of the music's change the warp adds: all of it to a dance at one pace; to a dance
    // whose own steps already change by `own`, the part it lacks (music^alpha × own = music).
    let mut alpha = 1.0;
    if long(slow) && long(fast) {
        let mean = |(a, b): (usize, usize)| period[a..b].iter().sum::<f64>() / (b - a) as f64;
        let music = mean(slow) / mean(fast);
        if let (Some(s), Some(f)) = (steps_hz(&motion, slow), steps_hz(&motion, fast)) {
            let own = f / s;
            if (own / music).ln().abs() < 1.1f64.ln() {
                return motion;
            }
            alpha = (1.0 - own.ln() / music.ln()).clamp(MIN_ALPHA, 1.0);
        }
    }
    let rate: Vec<f64> = period.iter().map(|p| (median / p).powf(alpha)).collect();
    let mean_rate = rate.iter().sum::<f64>() / frames as f64;
    let scale = (frames - 1) as f64 / (frames as f64 * mean_rate).max(1e-9);
    let mut source = Vec::with_capacity(frames);
    let mut s = 0.0;
    for r in &rate {
        source.push(s);
        s += r * scale;
    }
    tracing::debug!(
        p10,
        p90,
        "the dance's pace follows the song's changing tempo"
    );
    resample(&motion, &source)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn beats(until: f64, change_at: f64, before: f64, after: f64) -> Vec<f64> {
        let mut out = vec![0.0];
        while *out.last().unwrap() < until {
            let t = *out.last().unwrap();
            out.push(t + if t < change_at { before } else { after });
        }
        out
    }

    /// A walk at one pace over a song that speeds up 1.5625× half way: the warped walk steps
    /// 1.5625× as often after the change, and a steady song leaves it as it came.
    #[test]
    fn a_steady_pace_speeds_up_with_the_song_and_a_steady_song_changes_nothing() {
        let fps = 25.0;
        let frames = 1500;
        let mut positions = ndarray::Array3::<f32>::zeros((frames, crate::motion::NUM_JOINTS, 3));
        for f in 0..frames {
            let phase = (f as f64 / fps * std::f64::consts::TAU * 1.0).sin() as f32;
            for j in 0..crate::motion::NUM_JOINTS {
                positions[[f, j, 0]] = 0.2 * phase;
                positions[[f, j, 1]] = 0.1 * phase.abs();
            }
        }
        let motion = Motion { fps, positions };
        let steady = follow_tempo(motion.clone(), &beats(60.0, 100.0, 0.5, 0.5), false);
        assert_eq!(steady.positions, motion.positions);
        let changing = beats(60.0, 30.0, 0.625, 0.4);
        let warped = follow_tempo(motion.clone(), &changing, false);
        let (a, b) = (
            steps_hz(&warped, (50, 700)).unwrap(),
            steps_hz(&warped, (800, 1450)).unwrap(),
        );
        assert!(((b / a) / 1.5625 - 1.0).abs() < 0.1, "{a} → {b} Hz");
        assert_eq!(warped.num_frames(), frames);
        // Key poses keep their frames: nothing moves.
        let fixed = follow_tempo(motion.clone(), &changing, true);
        assert_eq!(fixed.positions, motion.positions);
    }

    /// A walk whose own pace already speeds up 1.25× at the change (a network that hears part
    /// of it): the warp adds only what it lacks, so it steps 1.5625× as often after, not 1.95×.
    #[test]
    fn a_pace_that_changes_partly_gets_the_rest() {
        let fps = 25.0;
        let frames = 1500;
        let change_frame = 750;
        let mut positions = ndarray::Array3::<f32>::zeros((frames, crate::motion::NUM_JOINTS, 3));
        let mut phase_at = 0.0f64;
        for f in 0..frames {
            let hz = if f < change_frame { 1.0 } else { 1.25 };
            phase_at += std::f64::consts::TAU * hz / fps;
            let phase = phase_at.sin() as f32;
            for j in 0..crate::motion::NUM_JOINTS {
                positions[[f, j, 0]] = 0.2 * phase;
                positions[[f, j, 1]] = 0.1 * phase.abs();
            }
        }
        let motion = Motion { fps, positions };
        let warped = follow_tempo(motion, &beats(60.0, 30.0, 0.625, 0.4), false);
        let (a, b) = (
            steps_hz(&warped, (50, 700)).unwrap(),
            steps_hz(&warped, (800, 1450)).unwrap(),
        );
        assert!(((b / a) / 1.5625 - 1.0).abs() < 0.1, "{a} → {b} Hz");
    }
}
