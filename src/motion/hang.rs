//! Hangs: a body held off the floor for longer than a dancer can be.
//!
//! A property of the motion (as [`super::hold`] is): reported by [`crate::metrics::physical`]'s
//! verdict and read by the beat-align stage, which serves no warp that lengthens a hang in place
//! of one that lengthens a hold.
//!
//! The floor-contact measures of [`crate::metrics::physical`] summarise the lowest foot over a
//! whole dance (its p5 and median), so a dance that stands on the floor for 24 s and floats 0.33 m
//! up with both feet for 1.2 s in between scores like one that never leaves it (tsmt on
//! `choice_drum_bass`, seed 1, at 19–20 s). A dancer cannot: a 1.2-s flight is a 1.8-m jump.
//!
//! - **lift** ([`contact_lift`]): per frame, the lowest heel or toe's height above its own lowest
//!   within ±1 s ([`crate::motion::feet::lift`], the grounding stage's own window, the span in
//!   which a dancer's feet touch the floor at least once). It is measured against that local floor, not `y = 0`,
//!   because the capture's floor drifts by tens of centimetres over some real dances
//!   (DANCE_W_31's lowest foot has a median 0.35 m above its first percentile). Heels and toes,
//!   the points grounding stands a dance on, not the ankles too: the fitted skeleton can drop an
//!   ankle below its own heel and toes for a few frames, and that false floor, 5–7 cm low, made
//!   a float the stage had brought down to 0.05–0.18 m read 0.12–0.17 (tsmt, DANCE_W_3 seed 5).
//! - **hang**: the longest span (s) in which the lift stays above [`HANG_LIFT_M`].
//!
//! Over the 43 real dances (`real_dances_lift_and_hang`): the lift is at most 0.14 m, and stays
//! above 0.10 m for at most 0.72 s (DANCE_C_7); the verdict allows a hang of
//! [`super::limits::HANG_S`].
use ndarray::ArrayView3;

use super::feet::{lift, lowest_foot};
use super::skeleton::FOOT_POINTS;

/// The longest hang of the 43 real dances (s, DANCE_C_7), measured by `real_dances_lift_and_hang`.
pub const HANG_REAL_MAX_S: f64 = 0.72;

/// A lift above this (m) is off the floor for the hang.
pub const HANG_LIFT_M: f64 = 0.10;

/// [`lift`] of the lowest heel or toe ([`FOOT_POINTS`]) of world positions `[T, J, 3]`.
pub fn contact_lift(positions: ArrayView3<'_, f32>, fps: f64) -> Vec<f64> {
    lift(&lowest_foot(positions, &FOOT_POINTS), fps)
}

/// The longest hang (s, [`longest_hang_s`] of [`contact_lift`]) of world positions `[T, J, 3]`.
pub fn hang_s(positions: ArrayView3<'_, f32>, fps: f64) -> f64 {
    longest_hang_s(&contact_lift(positions, fps), fps)
}

/// The longest span (s) in which `lift` (from [`lift`]) stays above [`HANG_LIFT_M`].
pub fn longest_hang_s(lift: &[f64], fps: f64) -> f64 {
    let (mut best, mut run) = (0usize, 0usize);
    for &h in lift {
        run = if h > HANG_LIFT_M { run + 1 } else { 0 };
        best = best.max(run);
    }
    best as f64 / fps
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_float_between_steps_is_a_hang_and_a_drifting_floor_is_not() {
        // Steps touching the floor every 0.5 s, on a floor that rises 0.2 m over 20 s.
        let fps = 25.0;
        let stepping: Vec<f64> = (0..500)
            .map(|f| 0.01 * f as f64 / fps + if f % 12 < 6 { 0.0 } else { 0.08 })
            .collect();
        let l = lift(&stepping, fps);
        assert!(
            l.iter().all(|&h| h < 0.1),
            "max {:?}",
            l.iter().copied().reduce(f64::max)
        );
        assert_eq!(longest_hang_s(&l, fps), 0.0);
        // The same with 1.2 s (30 frames) at 0.33 m in the middle.
        let mut floating = stepping.clone();
        for h in &mut floating[200..230] {
            *h += 0.33;
        }
        let l = lift(&floating, fps);
        assert!((longest_hang_s(&l, fps) - 1.2).abs() < 1e-9);
        assert!(l.iter().copied().fold(0.0, f64::max) > 0.33);
    }

    /// The real figures quoted above (where `../shared` holds the dances).
    #[test]
    fn real_dances_lift_and_hang() {
        let Some(ds) = crate::motion::dataset::Dataset::open_for_test() else {
            return;
        };
        let (mut lift_max, mut hang_max) = (0.0f64, (0.0f64, String::new()));
        for id in ds.all_ids() {
            let d = ds.load(&id).expect("a real dance loads");
            let l = contact_lift(d.motion.positions.view(), d.motion.fps);
            lift_max = l.iter().copied().fold(lift_max, f64::max);
            let hang = longest_hang_s(&l, d.motion.fps);
            if hang > hang_max.0 {
                hang_max = (hang, id);
            }
        }
        println!("real dances: lift max {lift_max:.3} m, longest hang {hang_max:?}");
        assert!(lift_max < 0.15, "lift {lift_max}");
        assert!(
            (hang_max.0 - HANG_REAL_MAX_S).abs() < 0.01,
            "hang {hang_max:?}"
        );
    }
}
