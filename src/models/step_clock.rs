//! The step clock: a phase that turns once per step of the song's beats,
//! given to a network beside the music (dancenet: every gated layer's conditioning,
//! `dancenet::Config::step_clock`; tsmt: the pose stream's input and the fusion,
//! `tsmt::Config::step_clock`). Written for dancenet first; the text below tells its story.
//!
//! Real dancers step at a fixed fraction of the beat (1/2 in rumba and cha-cha, 1/3 in waltz),
//! and the decoder, taught by teacher forcing, learned to continue the step rate of its own
//! history: the beat one-hot, a beat clock at the beat's own rate and a lock term on free runs all
//! left its own lock at chance (model card). The history already says when the next step comes,
//! so nothing made the decoder read it from the music. Here the decoder is given a phase φ that
//! names where in the step cycle each frame lies. In training φ comes from the song's beats,
//! shifted and at the fraction that the real dancer's toes swing with in that window
//! (`train::dancenet::phase`): it then says more than the history does (when the *next* step
//! comes), so the decoder learns to step with it. Served, φ is `2π · f · B(t)` of the song's
//! beat count B and the style's fraction f, so the steps the decoder makes follow the song's
//! beats, and its tempo.
//!
//! The columns: `sin φ, cos φ, sin 2φ, cos 2φ` (the second harmonic lets a step's two halves,
//! lift and plant, differ); all zero where the song has under two beats.
use ndarray::Array2;

use crate::models::DanceStyle;

/// Columns the clock adds to the conditioning.
pub const WIDTH: i64 = 4;

/// A style's step rate (Hz) on the real dances: its fraction of the beat at the data's tempi
/// (waltz 1/3 of 87 BPM, rumba 1/2 of 87–96, cha-cha 1/2 of 115–127; tango: rumba's). A served
/// clock's fraction is halved while its steps would come over 1.5 times this fast, so a song the
/// tracker hears in double time (174 BPM for an 87-BPM waltz) is danced at a waltz's rate.
pub fn step_hz(style: DanceStyle) -> f64 {
    match style {
        DanceStyle::Waltz => 0.49,
        DanceStyle::Rumba | DanceStyle::Tango => 0.76,
        DanceStyle::ChaCha => 1.0,
    }
}

/// Steps per beat of a style's dancers (the tempo lock on the real dances, docs/evaluation.md).
pub fn step_fraction(style: DanceStyle) -> f64 {
    match style {
        DanceStyle::Waltz => 1.0 / 3.0,
        DanceStyle::ChaCha | DanceStyle::Rumba | DanceStyle::Tango => 0.5,
    }
}

/// Beat count at each of `n` frames from a beat column (one where a beat falls): linear between
/// beats, the nearest interval carried on beyond the first and last. `None` under two beats.
pub fn beat_count(is_beat: &[bool]) -> Option<Vec<f64>> {
    let beats: Vec<f64> = is_beat
        .iter()
        .enumerate()
        .filter(|(_, &b)| b)
        .map(|(t, _)| t as f64)
        .collect();
    if beats.len() < 2 {
        return None;
    }
    Some(
        (0..is_beat.len())
            .map(|t| {
                let t = t as f64;
                let k = beats.partition_point(|&b| b <= t).clamp(1, beats.len() - 1);
                let (a, b) = (beats[k - 1], beats[k]);
                (k - 1) as f64 + (t - a) / (b - a)
            })
            .collect(),
    )
}

/// The clock's columns `[n, WIDTH]` of phases `φ` (radians).
pub fn columns(phase: &[f64]) -> Array2<f32> {
    Array2::from_shape_fn((phase.len(), WIDTH as usize), |(t, c)| {
        let p = phase[t] * if c < 2 { 1.0 } else { 2.0 };
        (if c % 2 == 0 { p.sin() } else { p.cos() }) as f32
    })
}

/// The served clock of a song: `is_beat` its beat column on the network's frames (`fps`), the
/// style's fraction, halved while the steps would come over 1.5 × [`step_hz`]. Zeros where
/// the song has under two beats (the decoder then dances on its history, as it did before).
pub fn of_song(is_beat: &[bool], style: DanceStyle, fps: f64) -> Array2<f32> {
    match phase_of_song(is_beat, style, fps) {
        Some(phase) => columns(&phase),
        None => Array2::zeros((is_beat.len(), WIDTH as usize)),
    }
}

/// The phases (radians) behind [`of_song`]; `None` under two beats.
pub fn phase_of_song(is_beat: &[bool], style: DanceStyle, fps: f64) -> Option<Vec<f64>> {
    clock_at(is_beat, fps, |beats_per_s| {
        let mut f = step_fraction(style);
        while f * beats_per_s > 1.5 * step_hz(style) && f > 1.0 / 12.0 {
            f /= 2.0;
        }
        f
    })
}

/// Fractions of the beat a training window's clock may turn at: those of the real dances
/// (1/2, 1/3, and 1/6 where the tracker counts a waltz in double time), and their neighbours.
pub const FRACTIONS: [f64; 5] = [1.0 / 6.0, 1.0 / 4.0, 1.0 / 3.0, 1.0 / 2.0, 2.0 / 3.0];

/// The phases of a clock at the fraction of the beat (one of [`FRACTIONS`], the training
/// clock's) whose step rate is nearest `hz` in ratio; `None` under two beats.
pub fn phase_near(is_beat: &[bool], hz: f64, fps: f64) -> Option<Vec<f64>> {
    clock_at(is_beat, fps, |beats_per_s| {
        FRACTIONS
            .into_iter()
            .min_by(|a, b| {
                let d = |f: f64| (f * beats_per_s / hz).ln().abs();
                d(*a).total_cmp(&d(*b))
            })
            .unwrap_or(0.5)
    })
}

/// The phases of a clock that turns once a bar of `bar` beats (1/3 of the beat in three beats a
/// bar, 1/4 in four), halved or doubled while its step rate lies outside `band` (Hz, low to
/// high): one fraction for one song over a wide span of tempi, so a song played faster turns
/// it faster, where [`phase_near`] keeps one pace. `None` under two beats.
pub fn phase_per_bar(is_beat: &[bool], bar: usize, band: [f64; 2], fps: f64) -> Option<Vec<f64>> {
    clock_at(is_beat, fps, |beats_per_s| {
        let mut f = 1.0 / bar.max(1) as f64;
        while f * beats_per_s > band[1] && f > 1.0 / 64.0 {
            f /= 2.0;
        }
        while f * beats_per_s < band[0] && f < 1.0 {
            f *= 2.0;
        }
        f
    })
}

/// The phases of a clock that turns at the fraction `fraction(beats per second)` of the song's
/// beat count; `None` under two beats. The served rules above differ only in the fraction.
fn clock_at(is_beat: &[bool], fps: f64, fraction: impl Fn(f64) -> f64) -> Option<Vec<f64>> {
    let count = beat_count(is_beat)?;
    let n = count.len();
    let f = fraction((count[n - 1] - count[0]) / ((n - 1).max(1) as f64 / fps));
    Some(
        count
            .iter()
            .map(|&b| std::f64::consts::TAU * f * b)
            .collect(),
    )
}

/// The style whose step rule a song of `bar` beats a bar is danced by where the model is not
/// told a style (tsmt): three beats a bar steps as a waltz does (1/3 of the beat), any other
/// metre as a rumba (1/2). The tempo lock accepts either on any song; the metre picks the one a
/// dancer would.
pub fn style_of_metre(bar: usize) -> DanceStyle {
    if bar == 3 {
        DanceStyle::Waltz
    } else {
        DanceStyle::Rumba
    }
}

/// `phase` (rows `first..first + len` of a song whose phases are `phase`, `first` may be
/// negative and the end past the song): the song's phase, carried on at its first and last
/// step's rate outside it. A context clip danced before the song's first frame hears the clock
/// run on backwards.
pub fn phase_span(phase: &[f64], first: i64, len: usize) -> Vec<f64> {
    let n = phase.len() as i64;
    (first..first + len as i64)
        .map(|t| match n {
            0 => 0.0,
            1 => phase[0],
            _ if t < 0 => phase[0] + t as f64 * (phase[1] - phase[0]),
            _ if t >= n => {
                phase[(n - 1) as usize]
                    + (t - n + 1) as f64 * (phase[(n - 1) as usize] - phase[(n - 2) as usize])
            }
            _ => phase[t as usize],
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_beat_count_runs_on_between_and_beyond_the_beats() {
        let mut beats = vec![false; 30];
        beats[5] = true;
        beats[15] = true;
        beats[23] = true;
        let b = beat_count(&beats).unwrap();
        assert!((b[5] - 0.0).abs() < 1e-9 && (b[10] - 0.5).abs() < 1e-9);
        assert!((b[19] - 1.5).abs() < 1e-9 && (b[27] - 2.5).abs() < 1e-9);
        assert!((b[0] + 0.5).abs() < 1e-9, "before the first beat: {}", b[0]);
        assert!(beat_count(&beats[..10]).is_none());
    }

    /// A waltz at 87 BPM turns the clock once every 3 beats; the same style on a song tracked
    /// at 174 BPM once every 6, so the step rate stays a waltz's.
    #[test]
    fn the_served_clock_turns_once_a_step_and_folds_double_time() {
        let fps = 25.0;
        let beats = |bpm: f64| -> Vec<bool> {
            let period = fps * 60.0 / bpm;
            let mut b = vec![false; 1000];
            let mut t: f64 = 3.0;
            while (t as usize) < b.len() {
                b[t.round() as usize] = true;
                t += period;
            }
            b
        };
        // Frames between zero crossings upwards of sin φ: one turn.
        let turn = |c: &Array2<f32>| -> f64 {
            let ups: Vec<usize> = (1..c.nrows())
                .filter(|&t| c[[t - 1, 0]] < 0.0 && c[[t, 0]] >= 0.0)
                .collect();
            (ups[ups.len() - 1] - ups[0]) as f64 / (ups.len() - 1) as f64
        };
        let slow = of_song(&beats(87.0), DanceStyle::Waltz, fps);
        let beat = fps * 60.0 / 87.0;
        assert!(
            (turn(&slow) / beat - 3.0).abs() < 0.05,
            "{}",
            turn(&slow) / beat
        );
        let fast = of_song(&beats(174.0), DanceStyle::Waltz, fps);
        assert!(
            (turn(&fast) / beat - 3.0).abs() < 0.05,
            "{}",
            turn(&fast) / beat
        );
        let rumba = of_song(&beats(90.0), DanceStyle::Rumba, fps);
        assert!((turn(&rumba) / (fps * 60.0 / 90.0) - 2.0).abs() < 0.05);
        // Sin and cos of one phase, and of twice it.
        for t in [0usize, 100, 500] {
            let r = slow.row(t);
            assert!((r[0] * r[0] + r[1] * r[1] - 1.0).abs() < 1e-5);
            assert!((r[2] - 2.0 * r[0] * r[1]).abs() < 1e-5);
        }
        assert!(of_song(&[false; 50], DanceStyle::Waltz, fps)
            .iter()
            .all(|&v| v == 0.0));
    }

    /// A clock near 0.49 Hz turns once every 4 beats at 130 BPM (0.54 Hz; 1/6 would be 0.36),
    /// every 3 at 87 (0.48), every 6 at 174 (0.48); it starts at zero on the first beat.
    #[test]
    fn a_clock_near_a_step_rate_turns_at_the_nearest_fraction_of_the_beat() {
        let fps = 25.0;
        let beats = |bpm: f64| -> Vec<bool> {
            let mut b = vec![false; 2000];
            let mut t: f64 = 10.0;
            while (t.round() as usize) < b.len() {
                b[t.round() as usize] = true;
                t += fps * 60.0 / bpm;
            }
            b
        };
        for (bpm, fraction) in [(130.0, 0.25), (87.0, 1.0 / 3.0), (174.0, 1.0 / 6.0)] {
            let p = phase_near(&beats(bpm), 0.49, fps).unwrap();
            let hz = (p[1500] - p[500]) / std::f64::consts::TAU / (1000.0 / fps);
            let want = fraction * bpm / 60.0;
            assert!(
                (hz / want - 1.0).abs() < 0.01,
                "{bpm} BPM: {hz} Hz, not {want}"
            );
            assert!(p[10].abs() < 1e-9, "{bpm} BPM: {}", p[10]);
        }
        assert!(phase_near(&[false; 50], 0.49, fps).is_none());
    }

    #[test]
    fn a_clock_once_a_bar_follows_the_tempo_inside_its_band() {
        // Beats every 12 frames at 25 fps: 125 BPM, 2.08 beats a second.
        let beats = |every: usize| -> Vec<bool> { (0..500).map(|t| t % every == 0).collect() };
        let rate = |p: &[f64]| (p[400] - p[100]) / std::f64::consts::TAU / 12.0;
        let band = [0.3, 0.8];
        // Four beats a bar: 1/4 of the beat, 0.52 Hz; the same song 1.2× faster turns 1.2× faster.
        let at = phase_per_bar(&beats(12), 4, band, 25.0).unwrap();
        assert!((rate(&at) - 2.0833 / 4.0).abs() < 1e-3, "{}", rate(&at));
        let faster = phase_per_bar(&beats(10), 4, band, 25.0).unwrap();
        assert!((rate(&faster) / rate(&at) - 1.2).abs() < 1e-3);
        // Three beats a bar at 125 BPM: 1/3, 0.69 Hz; at 250 BPM halved into the band.
        let waltz = phase_per_bar(&beats(12), 3, band, 25.0).unwrap();
        assert!((rate(&waltz) - 2.0833 / 3.0).abs() < 1e-3);
        let double = phase_per_bar(&beats(6), 3, band, 25.0).unwrap();
        assert!(
            (rate(&double) - 4.1667 / 6.0).abs() < 1e-3,
            "{}",
            rate(&double)
        );
        assert!(phase_per_bar(&[false; 10], 4, band, 25.0).is_none());
    }

    #[test]
    fn a_span_runs_the_clock_on_before_and_after_the_song() {
        let phase: Vec<f64> = (0..10).map(|t| 0.3 * t as f64 + 1.0).collect();
        let span = phase_span(&phase, -3, 16);
        let want: Vec<f64> = (-3..13).map(|t| 0.3 * t as f64 + 1.0).collect();
        for (a, b) in span.iter().zip(&want) {
            assert!((a - b).abs() < 1e-9, "{span:?}");
        }
        assert_eq!(style_of_metre(3), DanceStyle::Waltz);
        assert_eq!(style_of_metre(4), DanceStyle::Rumba);
    }
}
