//! Knees that bend forwards: a served step after any model (in [`super::finish`]).
//!
//! A network that draws each joint coordinate on its own (tsmt) or regresses joints without a
//! rig can put a bent knee behind the hip–ankle line, against the foot: a knee bending the wrong
//! way (`metrics::musicality`'s knee direction counts them; real dances at most 5.8 % of
//! knee-frames, tsmt's network up to 35 % on unseen songs).
//!
//! The correction is a pole-vector flip. The knee turns about the hip–ankle line, which keeps both
//! bone lengths (hip–knee, knee–ankle) and the hip and ankle where they are. With the knee's
//! angle φ about that line measured from the foot's heel → toe direction (both taken
//! perpendicular to the line), a knee behind the line (|φ| > [`LEFT_ALONE_DEG`] = 90°) is mirrored
//! to π − φ: in front, as far to the side as it was. The mirror moves a knee just behind the line by
//! almost nothing (at 90° it is the identity), so the corrected knee is a continuous function of
//! the pose: a knee that drifts backwards glides along the side and turns back, and nothing pops;
//! the knee keeps its angular speed about the line. (Folding only knees past 120°, to leave a real
//! dancer's foot turned out under a slightly hyperextended knee alone, left tsmt at 10–15 %: most
//! of its backward knees lie at 120–140°.)
//! Weights make the remaining edges continuous: a knee
//! straighter than [`STRAIGHT_DEG`] is left alone (its direction means nothing) and fully corrected
//! from [`KNEE_BENT_DEG`] on. A foot pointed along the leg (no heel → toe direction across it)
//! or along its own shin ([`POINTED_COS`]: a leg flicked back) gives the knee no direction, and
//! there the pelvis does: the direction the hips face (up × the left → right hip line), blended in
//! as the foot's direction fades out. A knee bends forwards of the pelvis too (a real dancer's
//! turn-out reaches 45–60°, inside the 90° left alone), and a leg flicked back keeps its knee in
//! front of the hip–ankle line by that measure, so it stays. (Leaving pointed feet alone
//! instead left half of tsmt's backward knees where they were: on DANCE_C_8's test segment, seed
//! 1, 12.5 % of its knee-frames came out 5.8 %.)
use nalgebra::{Unit, UnitQuaternion, Vector3};
use ndarray::ArrayViewMut3;

use super::skeleton::{ANKLES, HEELS, HIPS, TOES};
use super::smoothstep;

/// Knees, right and left (between [`HIPS`] and [`ANKLES`]).
const KNEES: [usize; 2] = [8, 17];

/// A knee bent at least this much (degrees between thigh and shin) is fully corrected when it
/// points backwards (the musicality metric's threshold).
pub const KNEE_BENT_DEG: f64 = 15.0;
/// A knee bent less than this is left alone; between the two the correction fades in.
pub const STRAIGHT_DEG: f64 = 10.0;
/// Knees within this angle (degrees, about the hip–ankle line) of the foot's direction stay;
/// past it |φ| maps linearly onto [`LEFT_ALONE_DEG`]…0 (at 90°: the mirror).
pub const LEFT_ALONE_DEG: f64 = 90.0;
/// As [`LEFT_ALONE_DEG`] where the pelvis gives the direction (see [`forward_knee`]).
pub const PELVIS_LEFT_ALONE_DEG: f64 = 120.0;
/// Share of the foot's heel → toe length that must lie across the hip–ankle line for it to give a
/// direction (fully from twice this).
const FOOT_ACROSS: f64 = 0.2;

/// A pointed foot gives the knee no direction: where the cosine between heel → toe and the shin
/// (knee → ankle) passes the first value the correction fades out, gone at the second. Standing,
/// the foot lies across the shin (cosine about 0–0.2); a leg flicked back with a pointed foot
/// (real dances do it, e.g. in the first 1.6 s of DANCE_C_2, C_4 and R_5: cosine 0.66) points the
/// foot backwards along the shin, and the knee, bent the right way, would be turned through up
/// to 0.66 m.
const POINTED_COS: (f64, f64) = (0.4, 0.6);

/// Turns backward knees forward, in place on world positions `[T, J, 3]` (the dataset's 23
/// joints; see the module doc). Returns the number of knee-frames moved.
pub fn bend_forward(mut positions: ArrayViewMut3<'_, f32>) -> usize {
    let (frames, joints, _) = positions.dim();
    if joints < super::NUM_JOINTS {
        return 0;
    }
    let mut moved = 0;
    for f in 0..frames {
        let at = |p: &ArrayViewMut3<'_, f32>, j: usize| {
            Vector3::new(
                f64::from(p[[f, j, 0]]),
                f64::from(p[[f, j, 1]]),
                f64::from(p[[f, j, 2]]),
            )
        };
        // up × (right hip − left hip): where the pelvis faces (the step moves knees only).
        let right = at(&positions, HIPS[0]) - at(&positions, HIPS[1]);
        let pelvis = Vector3::new(right.z, 0.0, -right.x);
        for leg in 0..2 {
            let (hip, knee, ankle) = (
                at(&positions, HIPS[leg]),
                at(&positions, KNEES[leg]),
                at(&positions, ANKLES[leg]),
            );
            let Some(turned) = forward_knee(
                hip,
                knee,
                ankle,
                (at(&positions, HEELS[leg]), at(&positions, TOES[leg])),
                pelvis,
            ) else {
                continue;
            };
            for c in 0..3 {
                positions[[f, KNEES[leg], c]] = turned[c] as f32;
            }
            moved += 1;
        }
    }
    moved
}

/// Where the knee goes (see the module doc), or `None` where it stays. `foot` is (heel, toe);
/// `pelvis` the direction the hips face.
fn forward_knee(
    hip: Vector3<f64>,
    knee: Vector3<f64>,
    ankle: Vector3<f64>,
    (heel, toe): (Vector3<f64>, Vector3<f64>),
    pelvis: Vector3<f64>,
) -> Option<Vector3<f64>> {
    let line = Unit::try_new(ankle - hip, 1e-9)?;
    let off_line = |v: Vector3<f64>| v - line.into_inner() * v.dot(&line);
    let bend = (knee - hip).angle(&(ankle - knee)).to_degrees();
    let foot = toe - heel;
    let across = off_line(foot);
    let shin = Unit::try_new(ankle - knee, 1e-9)?;
    let along_shin = foot.dot(&shin) / foot.norm().max(1e-9);
    let weight = smoothstep(STRAIGHT_DEG, KNEE_BENT_DEG, bend);
    // How far the foot gives the direction; the pelvis gives the rest.
    let by_foot = smoothstep(
        FOOT_ACROSS,
        2.0 * FOOT_ACROSS,
        across.norm() / foot.norm().max(1e-9),
    ) * (1.0 - smoothstep(POINTED_COS.0, POINTED_COS.1, along_shin));
    let unit = |v: Vector3<f64>| v.try_normalize(1e-9).unwrap_or_else(Vector3::zeros);
    let forward = Unit::try_new(
        unit(across) * by_foot + unit(off_line(pelvis)) * (1.0 - by_foot),
        1e-6,
    )?;
    let side = line.cross(&forward);
    let k = off_line(knee - hip);
    let phi = k.dot(&side).atan2(k.dot(&forward));
    // The pelvis is a looser guide than the foot (hips turn under a dancer's legs): knees up to
    // PELVIS_LEFT_ALONE_DEG from its direction stay.
    let fold = (LEFT_ALONE_DEG * by_foot + PELVIS_LEFT_ALONE_DEG * (1.0 - by_foot)).to_radians();
    if weight <= 0.0 || phi.abs() <= fold {
        return None;
    }
    // |φ| in (fold, π] onto [0, fold), on φ's side, reached by turning about the hip–ankle line,
    // so both bone lengths hold.
    let target = (fold - (phi.abs() - fold) * fold / (std::f64::consts::PI - fold)).copysign(phi);
    let turn = (target - phi) * weight;
    Some(hip + UnitQuaternion::from_axis_angle(&line, turn) * (knee - hip))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::NUM_JOINTS;
    use ndarray::Array3;

    /// One frame of legs: hips at y = 0, ankles at y = −0.8, toes towards +z, each knee `knee_z`
    /// in front of its hip–ankle line (negative: behind) and `knee_x` to the side.
    fn legs(knee_z: f32, knee_x: f32) -> Array3<f32> {
        let mut p = Array3::<f32>::zeros((1, NUM_JOINTS, 3));
        for (leg, x) in [(0usize, -0.1f32), (1, 0.1)] {
            let set = |p: &mut Array3<f32>, j: usize, v: [f32; 3]| {
                (0..3).for_each(|c| p[[0, j, c]] = v[c])
            };
            set(&mut p, HIPS[leg], [x, 0.0, 0.0]);
            set(&mut p, KNEES[leg], [x + knee_x, -0.4, knee_z]);
            set(&mut p, ANKLES[leg], [x, -0.8, 0.0]);
            set(&mut p, HEELS[leg], [x, -0.85, -0.05]);
            set(&mut p, TOES[leg], [x, -0.87, 0.12]);
        }
        p
    }

    fn dist(p: &Array3<f32>, a: usize, b: usize) -> f32 {
        (0..3)
            .map(|c| (p[[0, a, c]] - p[[0, b, c]]).powi(2))
            .sum::<f32>()
            .sqrt()
    }

    #[test]
    fn a_backward_knee_comes_forward_with_its_bone_lengths() {
        let mut p = legs(-0.1, 0.03);
        let before = p.clone();
        assert_eq!(bend_forward(p.view_mut()), 2);
        for leg in 0..2 {
            let k = KNEES[leg];
            assert!(p[[0, k, 2]] > 0.08, "knee now {} in front", p[[0, k, 2]]);
            assert!(
                p[[0, k, 0]] - p[[0, HIPS[leg], 0]] > 0.0,
                "the knee keeps its side"
            );
            assert!((dist(&p, k, HIPS[leg]) - dist(&before, k, HIPS[leg])).abs() < 1e-5);
            assert!((dist(&p, k, ANKLES[leg]) - dist(&before, k, ANKLES[leg])).abs() < 1e-5);
        }
        // Nothing but the knees moved.
        for j in (0..NUM_JOINTS).filter(|j| !KNEES.contains(j)) {
            assert_eq!(
                p.slice(ndarray::s![0, j, ..]),
                before.slice(ndarray::s![0, j, ..])
            );
        }
    }

    #[test]
    fn forward_straight_and_sideways_knees_stay() {
        // Forward, straight (slightly behind), sideways.
        for (z, x) in [(0.1, 0.0), (0.2, -0.05), (-0.02, 0.0), (0.0, 0.1)] {
            let mut p = legs(z, x);
            let before = p.clone();
            assert_eq!(bend_forward(p.view_mut()), 0, "knee at z {z}, x {x}");
            assert_eq!(p, before);
        }
    }

    #[test]
    fn a_knee_drifting_backwards_glides_without_a_pop() {
        // The knee circles the hip–ankle line in small steps; the corrected knee moves no more per
        // step than the input does, times the fold's factor (2).
        let steps = 400;
        let r = 0.1f32;
        let mut prev: Option<[f32; 3]> = None;
        for i in 0..=steps {
            let a = i as f32 / steps as f32 * std::f32::consts::TAU;
            let mut p = legs(r * a.cos(), r * a.sin());
            bend_forward(p.view_mut());
            let k = [
                p[[0, KNEES[0], 0]],
                p[[0, KNEES[0], 1]],
                p[[0, KNEES[0], 2]],
            ];
            let behind_limit =
                -r * (LEFT_ALONE_DEG.to_radians() - std::f64::consts::FRAC_PI_2).sin() as f32;
            assert!(
                k[2] >= behind_limit - 1e-5,
                "step {i}: knee behind at {}",
                k[2]
            );
            if let Some(q) = prev {
                let d = (0..3).map(|c| (k[c] - q[c]).powi(2)).sum::<f32>().sqrt();
                assert!(
                    d <= 2.05 * r * std::f32::consts::TAU / steps as f32,
                    "step {i}: knee jumped {d}"
                );
            }
            prev = Some(k);
        }
    }

    #[test]
    fn a_backward_knee_over_a_pointed_foot_comes_forward_by_the_pelvis() {
        // The knee 0.1 m behind the hip–ankle line, the foot pointed along the shin (no direction
        // across the leg): tsmt draws such legs. The hips face +z, so the knee comes to +z.
        let mut p = legs(0.0, 0.0);
        let (hip, knee, ankle) = (
            Vector3::new(-0.1, 0.0, 0.0),
            Vector3::new(-0.1, -0.4, -0.1),
            Vector3::new(-0.1, -0.8, 0.0),
        );
        let shin = (ankle - knee).normalize();
        for (j, v) in [
            (HIPS[0], hip),
            (KNEES[0], knee),
            (ANKLES[0], ankle),
            (HEELS[0], ankle - shin * 0.05),
            (TOES[0], ankle + shin * 0.15),
        ] {
            (0..3).for_each(|c| p[[0, j, c]] = v[c] as f32);
        }
        assert_eq!(bend_forward(p.view_mut()), 1);
        assert!(
            p[[0, KNEES[0], 2]] > 0.05,
            "knee now at z {}",
            p[[0, KNEES[0], 2]]
        );
    }

    #[test]
    fn a_leg_flicked_back_with_a_pointed_foot_stays() {
        // Thigh forward and down, shin back and up, the foot pointed along the shin: the knee is
        // bent the right way, but the foot's heel → toe lies behind the hip–ankle line.
        let mut p = legs(0.0, 0.0);
        let (hip, knee, ankle) = (
            Vector3::new(-0.1, 0.0, 0.0),
            Vector3::new(-0.1, -0.4, 0.15),
            Vector3::new(-0.1, -0.45, -0.3),
        );
        let shin = (ankle - knee).normalize();
        let heel = ankle - shin * 0.05 + Vector3::new(0.0, 0.03, 0.0);
        let toe = ankle + shin * 0.15;
        for (j, v) in [
            (HIPS[0], hip),
            (KNEES[0], knee),
            (ANKLES[0], ankle),
            (HEELS[0], heel),
            (TOES[0], toe),
        ] {
            (0..3).for_each(|c| p[[0, j, c]] = v[c] as f32);
        }
        let before = p.clone();
        assert_eq!(bend_forward(p.view_mut()), 0);
        assert_eq!(p, before);
    }

    /// The 43 real dances (where `../shared` holds them): how many knee-frames move and how far.
    /// Prints the figures the model card quotes; real knees must barely move.
    #[test]
    fn real_dances_are_nearly_unchanged() {
        let Some(ds) = crate::motion::dataset::Dataset::open_for_test() else {
            return;
        };
        let (mut frames, mut moved, mut max_move, mut dances_moved) =
            (0usize, 0usize, 0f32, 0usize);
        let (mut beyond_5cm, mut far) = (0usize, 0usize);
        for id in ds.all_ids() {
            let Ok(d) = ds.load(&id) else { continue };
            let mut p = d.motion.positions.clone();
            let n = bend_forward(p.view_mut());
            let dance_max = (&p - &d.motion.positions)
                .mapv(f32::abs)
                .fold(0f32, |a, &v| a.max(v));
            let knee_moves: Vec<f32> = (0..p.dim().0)
                .flat_map(|f| KNEES.map(|k| (f, k)))
                .map(|(f, k)| {
                    (0..3)
                        .map(|c| (p[[f, k, c]] - d.motion.positions[[f, k, c]]).powi(2))
                        .sum::<f32>()
                        .sqrt()
                })
                .collect();
            beyond_5cm += knee_moves.iter().filter(|&&m| m > 0.05).count();
            far += knee_moves.iter().filter(|&&m| m > 0.2).count();
            // Over the three coordinates of a knee: at most √3 times the largest coordinate move.
            max_move = max_move.max(dance_max * 3f32.sqrt());
            frames += 2 * p.dim().0;
            moved += n;
            dances_moved += usize::from(n > 0);
            println!(
                "{id}: {n} knee-frames of {} moved, largest coordinate move {:.3} m",
                2 * p.dim().0,
                dance_max
            );
        }
        if frames == 0 {
            return;
        }
        let share = moved as f64 / frames as f64;
        println!("real dances: {moved} of {frames} knee-frames moved ({:.2} %) in {dances_moved} dances, {beyond_5cm} by more than 5 cm, {far} by more than 20 cm; largest knee move ≤ {max_move:.3} m", 100.0 * share);
        // Most moves are a few centimetres: knees just past 90° (or 120° from the pelvis) mirror
        // to just inside. Foot-guided only, 2.9 % of real knee-frames moved, 181 by more than 5 cm;
        // with the pelvis where the foot is pointed, 3.9 %, 630 (0.45 %).
        assert!(
            share < 0.045,
            "{:.1} % of real knee-frames moved",
            100.0 * share
        );
        assert!(
            (beyond_5cm as f64) < 0.006 * frames as f64,
            "{beyond_5cm} real knee-frames moved more than 5 cm"
        );
        assert!(far <= 4, "{far} real knee-frames moved more than 20 cm");
    }
}
