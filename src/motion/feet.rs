//! Foot planting: a foot that bears weight does not slide.
//!
//! An autoregressive model predicts where the body travels and what the legs do as separate
//! numbers, and they disagree: the body glides while a foot on the floor slides under it (foot
//! skating, `metrics::kinematics::foot_skating`). A dancer travels by pushing off a planted foot.
//! [`plant_feet`] holds the supporting foot in place: on every frame step where a foot point is
//! within [`SUPPORT_HEIGHT_M`] of the floor, the lowest such point is the support, and the whole
//! body is shifted horizontally by minus that point's horizontal step. The shift is a translation
//! accumulated step by step, so positions stay continuous, the skeleton stays rigid and the pose
//! relative to the body centre is unchanged (key poses, which are root-relative, still hold).
//! Each step's correction is spread over ±0.12 s ([`PLANT_BLEND_S`]) so a support that starts
//! or ends changes the body's speed gradually, not in one frame.
//! What is left of travel is what the legs do. This follows the idea of footskate clean-up
//! (Kovar, Schreiner and Gleicher, SCA 2002) with a translation in place of their IK.
use ndarray::{ArrayView3, ArrayViewMut3};

use super::skeleton::FOOT_POINTS;

/// A foot point this close to the floor (metres) can bear weight.
pub const SUPPORT_HEIGHT_M: f64 = 0.05;
/// A support keeps the weight unless the other foot, held instead, leaves this much less slide
/// (m/s per touching point): below it the two are a tie, and a tie must not flicker.
pub const SUPPORT_SWITCH_M_S: f64 = 0.05;
/// The floor is this percentile (0–100) of the lowest foot point's height per frame, so a few
/// noisy frames below it do not lower it.
pub const FLOOR_PERCENTILE: f64 = 1.0;

/// The lowest of `feet`'s heights (y) on every frame of `[T, J, 3]`, metres.
pub fn lowest_foot(positions: ArrayView3<'_, f32>, feet: &[usize]) -> Vec<f64> {
    (0..positions.dim().0)
        .map(|f| {
            feet.iter()
                .map(|&j| f64::from(positions[[f, j, 1]]))
                .fold(f64::INFINITY, f64::min)
        })
        .collect()
}

/// The floor height (metres, y) under a motion `[T, J, 3]`: the [`FLOOR_PERCENTILE`]th
/// percentile of the per-frame lowest of `feet`, linearly interpolated as numpy does; NaN for
/// an empty motion.
pub fn floor_height(positions: ArrayView3<'_, f32>, feet: &[usize]) -> f64 {
    let mut lowest = lowest_foot(positions, feet);
    if lowest.is_empty() {
        return f64::NAN;
    }
    lowest.sort_by(f64::total_cmp);
    let pos = FLOOR_PERCENTILE / 100.0 * (lowest.len() - 1) as f64;
    let (lo, hi) = (pos.floor() as usize, pos.ceil() as usize);
    lowest[lo] + (lowest[hi] - lowest[lo]) * (pos - lo as f64)
}

/// The two feet as (heel, toe) points: right, left.
const FEET: [[usize; 2]; 2] = [
    [FOOT_POINTS[0], FOOT_POINTS[1]],
    [FOOT_POINTS[2], FOOT_POINTS[3]],
];

/// Holds the supporting foot in place (see the module doc), in place on world positions
/// `[T, J, 3]` in metres, y up. Returns the number of frame steps that had a support.
///
/// A foot can support on a step when one of its points (heel, toe) is within
/// [`SUPPORT_HEIGHT_M`] of the floor on both frames. Of the feet that can, the support is the one
/// that, held still, leaves the touching points (both feet's) the least summed slide: a foot
/// dragged along by a gliding body is not the one bearing weight, and holding it would make the
/// foot that is planted slide instead. The support stays with the same foot (a dancer's weight
/// does not flicker between feet) unless the other leaves [`SUPPORT_SWITCH_M_S`] per touching
/// point less slide, or it lifts. The body moves by minus the mean horizontal step of the
/// support's touching points.
///
/// Why not the first foot down, kept while it touches: on 75 whole
/// served dances (the five songs of `../shared/audio`, seeds 1, 2 and 7, the four served models
/// and dance-revolution's rhythm-term weights) feet in contact slid less on 67, by model
/// 0.378–0.531 → 0.367–0.518 m/s, acceleration and verdicts unchanged (docs/serving.md).
pub fn plant_feet(mut positions: ArrayViewMut3<'_, f32>, fps: f64) -> usize {
    let t = positions.dim().0;
    if t < 2 {
        return 0;
    }
    // Heights decide support and horizontal shifts leave them alone, and every frame before f is
    // shifted by the same amount as f, so each frame's correction comes from the input alone.
    let floor = floor_height(positions.view(), &FOOT_POINTS);
    let mut step = vec![[0.0f32; 2]; t];
    let mut supported = 0;
    let mut support: Option<usize> = None;
    for f in 1..t {
        let touching = |foot: usize| -> Vec<usize> {
            FEET[foot]
                .iter()
                .copied()
                .filter(|&j| {
                    f64::from(positions[[f - 1, j, 1]]) - floor < SUPPORT_HEIGHT_M
                        && f64::from(positions[[f, j, 1]]) - floor < SUPPORT_HEIGHT_M
                })
                .collect()
        };
        let points = [touching(0), touching(1)];
        let slide_of =
            |j: usize| [0, 2].map(|axis| positions[[f, j, axis]] - positions[[f - 1, j, axis]]);
        let slides: Vec<[f32; 2]> = points.iter().flatten().map(|&j| slide_of(j)).collect();
        if slides.is_empty() {
            support = None;
            continue;
        }
        // The foot's own step: the mean over its touching points.
        let foot_step = |foot: usize| {
            let n = points[foot].len() as f32;
            points[foot].iter().fold([0.0f32; 2], |acc, &j| {
                let d = slide_of(j);
                [acc[0] + d[0] / n, acc[1] + d[1] / n]
            })
        };
        // Each touching foot with its own step and what every touching point slides if that
        // foot is held still, each computed once.
        let candidates: Vec<(usize, [f32; 2], f32)> = (0..2)
            .filter(|&k| !points[k].is_empty())
            .map(|k| {
                let own = foot_step(k);
                let left_over = slides
                    .iter()
                    .map(|d| (d[0] - own[0]).hypot(d[1] - own[1]))
                    .sum();
                (k, own, left_over)
            })
            .collect();
        let best = candidates
            .iter()
            .min_by(|a, b| a.2.total_cmp(&b.2))
            .expect("a touching foot");
        let margin = (SUPPORT_SWITCH_M_S / fps) as f32 * slides.len() as f32;
        let &(foot, own, _) = candidates
            .iter()
            .find(|c| Some(c.0) == support && c.2 <= best.2 + margin)
            .unwrap_or(best);
        support = Some(foot);
        step[f] = [-own[0], -own[1]];
        supported += 1;
    }
    let step = spread(&step, PLANT_BLEND_S * fps);
    let (mut ox, mut oz) = (0.0f32, 0.0f32);
    for (f, [dx, dz]) in step.into_iter().enumerate() {
        ox += dx;
        oz += dz;
        for mut joint in positions.slice_mut(ndarray::s![f, .., ..]).outer_iter_mut() {
            joint[0] += ox;
            joint[2] += oz;
        }
    }
    supported
}

/// The standard deviation (seconds) over which each frame's planting correction is spread. A
/// support that begins or ends changes the body's speed by the foot's slide; applied on one frame
/// that is a pop (dance-revolution's served acceleration p99.9 67 m/s², max 83, against 9 and 13
/// for its network alone); spread over ±3σ it is a push (p99.9 24, max 28). A wider σ (0.08 s:
/// p99.9 10) also spreads the travel so much that the dances slow below 0.5 m/s.
pub const PLANT_BLEND_S: f64 = 0.04;

/// Spreads each frame's step over its neighbours with Gaussian weights of `sigma` frames, each
/// source's weights renormalised within the motion, so the total (the travel) is unchanged.
fn spread(step: &[[f32; 2]], sigma: f64) -> Vec<[f32; 2]> {
    let t = step.len();
    if !(sigma.is_finite() && sigma > 0.0) {
        return step.to_vec();
    }
    let radius = (3.0 * sigma).ceil() as usize;
    let weight = |d: usize| (-0.5 * (d as f64 / sigma).powi(2)).exp();
    let mut out = vec![[0.0f32; 2]; t];
    for (f, s) in step.iter().enumerate() {
        if s[0] == 0.0 && s[1] == 0.0 {
            continue;
        }
        let (lo, hi) = (f.saturating_sub(radius), (f + radius).min(t - 1));
        let total: f64 = (lo..=hi).map(|g| weight(g.abs_diff(f))).sum();
        for (g, o) in out.iter_mut().enumerate().take(hi + 1).skip(lo) {
            let w = (weight(g.abs_diff(f)) / total) as f32;
            o[0] += s[0] * w;
            o[1] += s[1] * w;
        }
    }
    out
}

/// Half-width of the window (seconds) in which a dancer's feet touch the floor at least once.
pub const GROUND_WINDOW_S: f64 = 1.0;

/// Keeps a dance on the floor, in place on world positions `[T, J, 3]` (metres, y up, floor at
/// y = 0): the whole body moves vertically by minus the lowest foot point's minimum over ±1 s
/// ([`GROUND_WINDOW_S`]), averaged over another ±1 s so the shift has no corner a viewer would
/// see. A dancer bears weight on a foot at least once in any two seconds, so a dance whose feet
/// never come near the floor (a network that predicts the root height apart from the legs) is put
/// back on it, and one that sinks is lifted; steps, lifts and the pose are unchanged. Returns the
/// mean shift (m, positive = lowered).
pub fn ground(mut positions: ArrayViewMut3<'_, f32>, fps: f64) -> f64 {
    let t = positions.dim().0;
    if t == 0 || !(fps.is_finite() && fps > 0.0) {
        return 0.0;
    }
    let lowest = lowest_foot(positions.view(), &FOOT_POINTS);
    let w = (GROUND_WINDOW_S * fps).round().max(1.0) as usize;
    let shift = window_mean(&window_min(&lowest, w), w);
    lower(positions.view_mut(), &shift);
    shift.iter().sum::<f64>() / t as f64
}

/// What the served stages do to keep a dance on the floor, in place on world positions: [`ground`],
/// then [`land_hangs`].
pub fn keep_on_floor(mut positions: ArrayViewMut3<'_, f32>, fps: f64) {
    ground(positions.view_mut(), fps);
    land_hangs(positions, fps);
}

/// Both feet held more than this (m) over their lowest within ±1 s are off the floor for
/// [`land_hangs`].
pub const AIRBORNE_M: f64 = 0.05;
/// Half the longest time (s) both feet may stay off the floor before [`land_hangs`] lowers the
/// body: a 0.24-s flight is a hop that rises 7 cm.
pub const AIRBORNE_HALF_S: f64 = 0.12;

/// Brings a hang down, in place on world positions `[T, J, 3]` (metres, y up): where both feet
/// stay more than [`AIRBORNE_M`] over their lowest within ±1 s ([`GROUND_WINDOW_S`]) for longer
/// than 2 × [`AIRBORNE_HALF_S`], the whole body is lowered by that excess, eroded and averaged over
/// ±[`AIRBORNE_HALF_S`] so the shift ramps rather than jumps. [`ground`] cannot: its floor is the lowest foot
/// within ±1 s, so a float between two steps keeps it (tsmt on `choice_drum_bass`, seed 1, held
/// both feet 0.33 m up for 1.2 s; real dances hold them 0.10 m up for at most 0.72 s,
/// `motion::hang`). The erosion's minimum never exceeds a frame's own excess, so no foot is
/// pushed below its lowest within ±1 s, and a hop shorter than 0.24 s is left as it is; of the
/// real dances' frames, 0.9 % would move by more than 1 cm (at most 7 cm). Returns the largest
/// shift (m).
pub fn land_hangs(mut positions: ArrayViewMut3<'_, f32>, fps: f64) -> f64 {
    if positions.dim().0 == 0 || !(fps.is_finite() && fps > 0.0) {
        return 0.0;
    }
    let excess: Vec<f64> = lift(&lowest_foot(positions.view(), &FOOT_POINTS), fps)
        .iter()
        .map(|l| (l - AIRBORNE_M).max(0.0))
        .collect();
    let w = (AIRBORNE_HALF_S * fps).round().max(1.0) as usize;
    let shift = window_mean(&window_min(&excess, w), w);
    lower(positions.view_mut(), &shift);
    shift.iter().copied().fold(0.0, f64::max)
}

/// Per frame of `lowest` (the lowest foot point's height, m), its height above its own lowest
/// within ±[`GROUND_WINDOW_S`]: what [`land_hangs`] brings down and `motion::hang` measures, one
/// definition so the stage and the verdict agree on the floor.
pub fn lift(lowest: &[f64], fps: f64) -> Vec<f64> {
    let floor = window_min(lowest, (GROUND_WINDOW_S * fps).round().max(1.0) as usize);
    lowest.iter().zip(&floor).map(|(l, f)| l - f).collect()
}

/// Per index, the smallest of `v` within ±`w` (cut at the ends).
fn window_min(v: &[f64], w: usize) -> Vec<f64> {
    (0..v.len())
        .map(|f| {
            v[f.saturating_sub(w)..(f + w + 1).min(v.len())]
                .iter()
                .copied()
                .fold(f64::INFINITY, f64::min)
        })
        .collect()
}

/// Per index, the mean of `v` within ±`w` (cut at the ends).
fn window_mean(v: &[f64], w: usize) -> Vec<f64> {
    (0..v.len())
        .map(|f| {
            let r = &v[f.saturating_sub(w)..(f + w + 1).min(v.len())];
            r.iter().sum::<f64>() / r.len() as f64
        })
        .collect()
}

/// Moves every joint of frame `f` down by `shift[f]` (m).
fn lower(mut positions: ArrayViewMut3<'_, f32>, shift: &[f64]) {
    for (f, &dy) in shift.iter().enumerate() {
        for j in 0..positions.dim().1 {
            positions[[f, j, 1]] -= dy as f32;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::NUM_JOINTS;
    use ndarray::Array3;

    /// A body whose foot points touch the floor while it glides along x at 1 m/s.
    fn gliding(frames: usize, lift: impl Fn(usize) -> f32) -> Array3<f32> {
        Array3::from_shape_fn((frames, NUM_JOINTS, 3), |(f, j, c)| match c {
            0 => f as f32 * 0.04 + j as f32 * 0.01,
            1 => {
                if FOOT_POINTS.contains(&j) {
                    lift(f)
                } else {
                    1.0
                }
            }
            _ => 0.1 * j as f32,
        })
    }

    #[test]
    fn grounding_puts_a_floating_dance_on_the_floor_and_keeps_its_steps() {
        // Feet 1.2 m up, one foot point lifting 0.3 m for half a second every two seconds.
        let lift = |f: usize| if f % 50 < 12 { 1.5 } else { 1.2 };
        let mut p = gliding(300, lift);
        let before = p.clone();
        let shift = ground(p.view_mut(), 25.0);
        assert!((shift - 1.2).abs() < 1e-4, "shift {shift}");
        for f in 0..300 {
            let low = FOOT_POINTS
                .iter()
                .map(|&j| p[[f, j, 1]])
                .fold(f32::INFINITY, f32::min);
            assert!(low.abs() < 0.31, "frame {f}: lowest foot {low}");
            // The pose and horizontal travel are untouched; only heights move, all by one amount.
            let d0 = p[[f, 0, 1]] - before[[f, 0, 1]];
            for j in 0..NUM_JOINTS {
                assert!((p[[f, j, 1]] - before[[f, j, 1]] - d0).abs() < 1e-5);
                assert_eq!(p[[f, j, 0]], before[[f, j, 0]]);
            }
        }
        // Sinking is lifted the same way.
        let mut q = gliding(100, |_| -0.4);
        ground(q.view_mut(), 25.0);
        assert!(FOOT_POINTS.iter().all(|&j| q[[50, j, 1]].abs() < 1e-5));
    }

    #[test]
    fn a_float_between_steps_comes_down_and_a_hop_stays() {
        // Stepping (a foot down every 0.5 s), with both feet 0.33 m up for 1.2 s from frame 200
        // and a 0.16-s hop (4 frames at 0.2 m) at frame 100.
        let lift = |f: usize| match f {
            200..230 => 0.33,
            100..104 => 0.2,
            _ if f % 12 < 6 => 0.0,
            _ => 0.03,
        };
        let mut p = gliding(400, lift);
        let before = p.clone();
        let max_shift = land_hangs(p.view_mut(), 25.0);
        let low = |q: &Array3<f32>, f: usize| {
            FOOT_POINTS
                .iter()
                .map(|&j| q[[f, j, 1]])
                .fold(f32::INFINITY, f32::min)
        };
        assert!((0.2..0.29).contains(&max_shift), "shift {max_shift}");
        // Brought down: the feet are over 0.10 m up for at most 0.4 s of the 1.2 (take-off and
        // landing, 0.2 s each).
        let up = (195..235).filter(|&f| low(&p, f) > 0.10).count();
        assert!(up <= 10, "{up} frames still over 0.10 m");
        for f in 0..400 {
            // Never under the floor, and away from the float the dance is as it was.
            assert!(low(&p, f) >= -1e-6, "frame {f}: {}", low(&p, f));
            if !(190..240).contains(&f) {
                assert_eq!(
                    p.slice(ndarray::s![f, .., ..]),
                    before.slice(ndarray::s![f, .., ..])
                );
            }
            // Only heights move, the whole body by one amount.
            let d0 = p[[f, 0, 1]] - before[[f, 0, 1]];
            for j in 0..NUM_JOINTS {
                assert!((p[[f, j, 1]] - before[[f, j, 1]] - d0).abs() < 1e-5);
                assert_eq!(p[[f, j, 0]], before[[f, j, 0]]);
            }
        }
        // The lowering ramps over 7 frames (±0.12 s): its vertical acceleration is at most the
        // 0.28-m excess / 7 per frame², 25 m/s², where the float itself jumps 0.33 m in a frame.
        let dy = |f: usize| f64::from(p[[f, 0, 1]] - before[[f, 0, 1]]);
        let acc = (1..399)
            .map(|f| ((dy(f + 1) - 2.0 * dy(f) + dy(f - 1)) * 625.0).abs())
            .fold(0.0, f64::max);
        assert!(acc < 25.5, "{acc} m/s²");
    }

    /// The 43 real dances (where `../shared` holds them): how many frames [`land_hangs`] moves
    /// by more than 1 cm, and how far.
    #[test]
    fn real_dances_are_barely_brought_down() {
        let Some(ds) = crate::motion::dataset::Dataset::open_for_test() else {
            return;
        };
        let (mut frames, mut moved, mut most) = (0usize, 0usize, 0.0f32);
        for id in ds.all_ids() {
            let d = ds.load(&id).expect("a real dance loads");
            let mut p = d.motion.positions.clone();
            land_hangs(p.view_mut(), d.motion.fps);
            for f in 0..p.dim().0 {
                let dy = d.motion.positions[[f, 0, 1]] - p[[f, 0, 1]];
                moved += usize::from(dy > 0.01);
                most = most.max(dy);
            }
            frames += p.dim().0;
        }
        let share = 100.0 * moved as f64 / frames as f64;
        println!("real dances: {moved} of {frames} frames lowered > 1 cm ({share:.2} %), at most {most:.3} m");
        assert!(share < 2.0 && most < 0.1, "{share:.2} %, {most} m");
    }

    #[test]
    fn a_gliding_planted_body_stops_and_keeps_its_pose() {
        let mut p = gliding(50, |_| 0.0);
        let before = p.clone();
        assert_eq!(plant_feet(p.view_mut(), 25.0), 49);
        // Away from the ends (where the spread correction is cut), the body no longer travels;
        // heights and the pose relative to joint 0 are unchanged everywhere.
        let r = 12;
        for f in 0..50 {
            for j in 0..NUM_JOINTS {
                if (r..50 - r).contains(&f) {
                    assert!(
                        (p[[f, j, 0]] - p[[r, j, 0]]).abs() < 1e-5,
                        "frame {f} travels"
                    );
                }
                assert_eq!(p[[f, j, 1]], before[[f, j, 1]]);
                assert!(
                    ((p[[f, j, 0]] - p[[f, 0, 0]]) - (before[[f, j, 0]] - before[[f, 0, 0]])).abs()
                        < 1e-5
                );
            }
        }
        // The whole glide is taken back.
        assert!((p[[49, 0, 0]] - before[[0, 0, 0]]).abs() < 1e-4);
    }

    #[test]
    fn a_foot_that_lands_slows_the_body_without_a_pop() {
        // Gliding at 1 m/s with the feet 30 cm up, then on the floor from frame 30: planted on one
        // frame, the body would stop at 25 m/s²; spread, the stop takes several frames (under
        // half the pop at σ = one frame).
        let mut p = gliding(60, |f| if f < 30 { 0.3 } else { 0.0 });
        let before = p.clone();
        plant_feet(p.view_mut(), 25.0);
        let acc = |q: &ndarray::Array3<f32>, f: usize| {
            ((q[[f + 1, 0, 0]] - 2.0 * q[[f, 0, 0]] + q[[f - 1, 0, 0]]) * 625.0).abs()
        };
        let (raw, planted) = (
            (1..59).map(|f| acc(&before, f)).fold(0.0, f32::max),
            (1..59).map(|f| acc(&p, f)).fold(0.0, f32::max),
        );
        assert!(raw < 1e-3, "the glide itself is steady: {raw}");
        assert!(planted < 25.0 / 2.0, "landing pops at {planted} m/s²");
        // Once the spread has passed, the body stands still.
        assert!((p[[59, 0, 0]] - p[[40, 0, 0]]).abs() < 1e-4);
    }

    #[test]
    fn feet_in_the_air_travel_freely() {
        // On the floor for frames 0..10, then 30 cm up: only the first 9 steps are planted.
        let mut p = gliding(40, |f| if f < 10 { 0.0 } else { 0.3 });
        let before = p.clone();
        assert_eq!(plant_feet(p.view_mut(), 25.0), 9);
        let shift = p[[39, 0, 0]] - before[[39, 0, 0]];
        assert!((shift + 9.0 * 0.04).abs() < 1e-4, "{shift}");
        // Continuous: no step is larger than the original 4 cm.
        for f in 1..40 {
            assert!((p[[f, 0, 0]] - p[[f - 1, 0, 0]]).abs() <= 0.04 + 1e-5);
        }
    }

    #[test]
    fn the_foot_that_is_planted_bears_the_weight_not_the_one_dragged_along() {
        // The body glides at 0.5 m/s with the right toe on the floor, dragged along; from frame 10
        // the left foot lands flat and stays where it landed. The right toe touched first, but
        // held still it would make the landed foot slide: the weight passes to the left foot.
        let (heel_r, toe_r, heel_l, toe_l) = (
            FOOT_POINTS[0],
            FOOT_POINTS[1],
            FOOT_POINTS[2],
            FOOT_POINTS[3],
        );
        let mut p = Array3::from_shape_fn((40, NUM_JOINTS, 3), |(f, j, c)| {
            let glide = f as f32 * 0.02;
            let landed = j == heel_l || j == toe_l;
            match c {
                0 if landed && f >= 10 => 0.2,
                0 => glide,
                1 if j == toe_r => 0.0,
                1 if landed && f >= 10 => 0.0,
                1 if j == heel_r || landed => 0.3,
                1 => 1.0,
                _ => 0.1 * j as f32,
            }
        });
        plant_feet(p.view_mut(), 25.0);
        let speed = |j: usize, f: usize| (p[[f, j, 0]] - p[[f - 1, j, 0]]).abs() * 25.0;
        for f in 16..40 {
            assert!(
                speed(heel_l, f) < 0.05,
                "frame {f}: the landed foot slides {} m/s",
                speed(heel_l, f)
            );
            assert!(
                speed(toe_r, f) > 0.45,
                "frame {f}: the dragged toe slides {} m/s",
                speed(toe_r, f)
            );
        }
    }
}
