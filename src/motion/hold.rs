//! Holds: a body that stands in one pose for seconds in the middle of a song.
//!
//! A property of the motion, measured in every report ([`crate::metrics::musicality`]) and read
//! by the stages that would make one (tsmt's mid-song redraw, the beat-align stage's choice of
//! warp), so it lives here, beside [`super::skeleton::mean_speed`], not in `metrics`.
//!
//! The liveliness measures of [`crate::metrics::physical`] average a whole dance, and the freezing
//! ratio ([`crate::metrics::kinematics::freezing`]) compares its first and last 30 s, so a dance
//! that steps for two minutes and stands for 19 s between scores like one that never stops (tsmt on
//! `vibe_ace`, seed 2, 26–45 s at 0.2–0.4 m/s: the tsmt card).
//!
//! - **hold** ([`longest_hold_s`]): the longest span (s) over which every one-second mean joint
//!   speed ([`crate::motion::skeleton::mean_speed`], world positions) is under
//!   [`HOLD_SPEED_M_S`]. World speed, not root-relative: a dancer who walks in one pose is not
//!   holding it.
//!
//! Over the 43 real dances (`real_dances_hold`): two rumbas hold a pose for 9.5 s (DANCE_R_7,
//! from 6 s) and 8.6 s (DANCE_R_9, from 5 s); every other dance at most 4.8 s, the waltzes
//! 3.3–4.0 s (a figure's closing pose), the cha-chas at most 2.9 s.
use ndarray::ArrayView3;

use super::skeleton::mean_speed;

/// The longest hold of the 43 real dances (s), measured by `real_dances_hold`.
pub const HOLD_REAL_MAX_S: f64 = 9.5;

/// A hold this long (s) is longer than 41 of the 43 real dances' (all but two rumba poses), and
/// the preview's title names it.
pub const HOLD_NOTED_S: f64 = 5.0;

/// A second whose mean joint speed is under this (m/s) is held.
pub const HOLD_SPEED_M_S: f64 = 0.3;

/// The longest hold (s, [`longest_hold_s`]) of `[T, J, 3]` world positions at `fps`.
pub fn longest_hold_s(positions: ArrayView3<'_, f32>, fps: f64) -> f64 {
    longest_slow_s(&mean_speed(positions, fps), fps, HOLD_SPEED_M_S)
}

/// The longest span (s) over which every one-second mean of the per-frame `speed` (at `fps`) is
/// under `below` ([`slow_spans`]).
pub fn longest_slow_s(speed: &[f64], fps: f64, below: f64) -> f64 {
    slow_spans(speed, fps, below)
        .iter()
        .map(|r| r.len())
        .max()
        .map_or(0.0, |n| n as f64 / fps)
}

/// The spans of frames of the per-frame `speed` (at `fps`) covered by one-second windows, a
/// frame apart, whose every mean is under `below`, in order: a run of k windows spans k − 1
/// frames and a second.
pub fn slow_spans(speed: &[f64], fps: f64, below: f64) -> Vec<std::ops::Range<usize>> {
    let w = (fps.round() as usize).max(1);
    let mut spans = Vec::new();
    if speed.len() < w {
        return spans;
    }
    let mut start = None;
    let mut sum: f64 = speed[..w].iter().sum();
    for end in w..=speed.len() {
        if end > w {
            sum += speed[end - 1] - speed[end - 1 - w];
        }
        match (sum / (w as f64) < below, start) {
            (true, None) => start = Some(end - w),
            (false, Some(s)) => {
                spans.push(s..end - 1);
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        spans.push(s..speed.len());
    }
    spans
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stand_between_steps_is_a_hold_as_long_as_it_lasts() {
        let fps = 25.0;
        // 0.8 m/s, 4 s standing (0.1 m/s), 0.8 m/s.
        let mut speed = vec![0.8; 500];
        for s in &mut speed[200..300] {
            *s = 0.1;
        }
        let hold = longest_slow_s(&speed, fps, HOLD_SPEED_M_S);
        // A window 18 of whose 25 frames stand is under 0.3 m/s, so the hold takes in 7 frames
        // of stepping on each side: 4 s + 2 × 0.28 s.
        assert!((hold - 4.56).abs() < 1e-9, "{hold}");
        assert_eq!(slow_spans(&speed, fps, HOLD_SPEED_M_S), vec![193..307]);
        assert_eq!(longest_slow_s(&[0.8; 500], fps, HOLD_SPEED_M_S), 0.0);
        assert_eq!(longest_slow_s(&[0.1; 10], fps, HOLD_SPEED_M_S), 0.0);
        assert!((longest_slow_s(&[0.1; 500], fps, HOLD_SPEED_M_S) - 20.0).abs() < 1e-9);
    }

    /// The real figures quoted above (where `../shared` holds the dances).
    #[test]
    fn real_dances_hold() {
        let Some(ds) = crate::motion::dataset::Dataset::open_for_test() else {
            return;
        };
        let mut all = Vec::new();
        for id in ds.all_ids() {
            let d = ds.load(&id).expect("a real dance loads");
            let p = d.motion.positions.view();
            let speed = mean_speed(p, d.motion.fps);
            let spans = slow_spans(&speed, d.motion.fps, HOLD_SPEED_M_S);
            let from_s = spans
                .iter()
                .max_by_key(|r| r.len())
                .map(|r| r.start as f64 / d.motion.fps);
            all.push((longest_hold_s(p, d.motion.fps), from_s, id));
        }
        all.sort_by(|a, b| b.0.total_cmp(&a.0));
        for r in &all[..6] {
            println!("{r:?}");
        }
        assert_eq!(all.len(), 43);
        // Two rumba poses, then every other dance under HOLD_NOTED_S.
        assert!(
            all[0].0 <= HOLD_REAL_MAX_S && all[1].0 > HOLD_NOTED_S,
            "{:?}",
            &all[..2]
        );
        assert!(all[2].0 < HOLD_NOTED_S, "{:?}", all[2]);
    }
}
