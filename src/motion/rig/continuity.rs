//! Every joint's rotation kept continuous over time: its twist about its bone carried from the
//! previous frame where the data leaves it free, and no joint turning faster than
//! [`MAX_TURN_DEG_PER_S`] (55° a frame at 25 fps).
//!
//! # Twist
//! The chain IK aims every bone exactly at its child's target, so no joint position depends on
//! how a joint is twisted about its own bone: the twist is the rig's free choice, and it is what
//! a skinned mesh follows. Chosen frame by frame from the descendants alone it flips by up to
//! 180° between two frames wherever they pass near the bone's axis (a straight arm, a hand in
//! line with the forearm): the pose looks the same, the mesh wraps. So each frame's twist is the
//! one that best agrees with two things at once:
//! - the **data**: the grandchildren and great-grandchildren placed as close as possible to their
//!   targets, each weighted by its distance from the bone axis (a reference far off the axis has
//!   a well-defined angle and counts more);
//! - the **carried twist**: the joint's local rotation of the previous frame, as one more
//!   reference [`CARRY_RADIUS_M`] off the axis. Where the data is well determined it wins; where
//!   its references come near the axis, the carried twist holds.
//!
//! The twist then moves at most [`MAX_TWIST_STEP_DEG`] from the carried one in a frame. A joint
//! with no references (a wrist, whose only child is the hand-direction point) is pulled gently
//! ([`REST_PULL_SHARE`]) towards the shortest arc from its rest direction, so carried twist
//! does not wind up over repeated circles. A joint with several children (Wahba's problem) takes
//! from the carried rotation the turn its children leave free when they come in line
//! ([`wahba_carried`]).
//!
//! # Turns of the data's own
//! With the twist carried, what is left of the flips over the 43 dances is the data's: a bone
//! whose direction jumps 80–145° in one frame and back (the 4.7 cm wrist → hand-direction bone
//! most of all, the head's and the forearm's now and then), on 0.3–0.9 % of a dance's frames. No
//! body turns a limb 60° in 1/25 s and back; a mesh that followed would snap. So a joint turns at
//! most [`MAX_TURN_DEG_PER_S`] from its carried rotation ([`limit_turn`]), and the joints below
//! it are placed from where it points: on those frames the positions leave the data.
use nalgebra::{Matrix3, Rotation3, Unit, UnitQuaternion, Vector3};

/// The carried twist counts as one reference this far (metres) from the bone's axis. 3 cm: the
/// right elbow's references (wrist, hand-direction point) sit 4–5 cm off its axis (median over
/// DANCE_C_8) and under 2 cm on one frame in ten, where their angle swings freely.
pub const CARRY_RADIUS_M: f64 = 0.03;

/// The most a joint's twist turns from the carried twist in one frame (degrees). A twist the data
/// asks for that is further away (a reference that crossed the axis) is reached over several
/// frames rather than in one jump.
pub const MAX_TWIST_STEP_DEG: f64 = 25.0;

/// A joint with no twist references is pulled towards the shortest arc from its rest direction
/// with this share of the carried twist's weight.
pub const REST_PULL_SHARE: f64 = 0.1;

/// A joint with several children takes the carried rotation with (at most) this share of the
/// carried twist's weight ([`wahba_carried`]).
pub const WAHBA_CARRY_SHARE: f64 = 0.1;

/// The carried twist's weight: a reference [`CARRY_RADIUS_M`] off the axis.
const CARRY_WEIGHT: f64 = CARRY_RADIUS_M * CARRY_RADIUS_M;

/// The twist to add to `swing` (which already turns the bone onto `axis`): see the module doc.
/// `refs` are `(have, want)` pairs: a reference's position relative to the joint as `swing`
/// places it, and its target. `carried`: where the previous frame's local rotation puts the joint
/// now (none on the first frame).
pub fn twist(
    swing: UnitQuaternion<f64>,
    axis: &Vector3<f64>,
    refs: impl Iterator<Item = (Vector3<f64>, Vector3<f64>)>,
    carried: Option<UnitQuaternion<f64>>,
) -> UnitQuaternion<f64> {
    let a = axis.normalize();
    let (mut sin_sum, mut cos_sum, mut any) = (0.0, 0.0, false);
    for (have, want) in refs {
        let have_p = have - a * have.dot(&a);
        let want_p = want - a * want.dot(&a);
        // Unnormalised: a reference far off the axis has a well-defined angle and counts more.
        sin_sum += have_p.cross(&want_p).dot(&a);
        cos_sum += have_p.dot(&want_p);
        any = true;
    }
    if !any {
        // The shortest arc itself, pulled on like a reference.
        cos_sum += REST_PULL_SHARE * CARRY_WEIGHT;
    }
    let angle = match carried {
        None if sin_sum == 0.0 && cos_sum == 0.0 => 0.0,
        None => sin_sum.atan2(cos_sum),
        Some(carried) => {
            let from = twist_angle(&(carried * swing.inverse()), &a);
            let to =
                (sin_sum + CARRY_WEIGHT * from.sin()).atan2(cos_sum + CARRY_WEIGHT * from.cos());
            let max = MAX_TWIST_STEP_DEG.to_radians();
            from + wrap(to - from).clamp(-max, max)
        }
    };
    UnitQuaternion::from_axis_angle(&Unit::new_unchecked(a), angle) * swing
}

/// The angle of the rotation about `axis` (unit) closest to `q`: its twist in a swing–twist
/// decomposition.
pub fn twist_angle(q: &UnitQuaternion<f64>, axis: &Vector3<f64>) -> f64 {
    2.0 * q.imag().dot(axis).atan2(q.w)
}

/// The fastest a joint's local rotation turns (degrees per second): see the module doc. 55° a
/// frame at the data's 25 fps, below the 60° of [`crate::metrics::rotation_flips::FLIP_DEG`] and
/// above any turn of real motion: the largest joint turn per frame of DANCE_C_8 (cha-cha, the
/// fastest dances) is under 50° but for the data's jumps.
pub const MAX_TURN_DEG_PER_S: f64 = 55.0 * 25.0;

/// Whether frames at `fps` are a motion, whose rotations are kept continuous: a frame rate that
/// is no number says they are unrelated poses, each solved on its own (as
/// [`super::Rig::fit_lengths`] solves its key frames).
pub fn is_motion(fps: f64) -> bool {
    fps.is_finite() && fps > 0.0
}

/// The most a joint turns in one frame at `fps` (radians; no limit where [`is_motion`] is not).
pub fn max_turn(fps: f64) -> f64 {
    if is_motion(fps) {
        (MAX_TURN_DEG_PER_S / fps)
            .to_radians()
            .min(std::f64::consts::PI)
    } else {
        std::f64::consts::PI
    }
}

/// `to`, or the rotation `max` radians from `from` towards it when `to` is further.
pub fn limit_turn(
    from: UnitQuaternion<f64>,
    to: UnitQuaternion<f64>,
    max: f64,
) -> UnitQuaternion<f64> {
    match (to * from.inverse()).axis_angle() {
        Some((axis, angle)) if angle > max => UnitQuaternion::from_axis_angle(&axis, max) * from,
        _ => to,
    }
}

/// `a` wrapped to [−π, π).
fn wrap(a: f64) -> f64 {
    let t = std::f64::consts::TAU;
    a - t * ((a + std::f64::consts::PI) / t).floor()
}

/// Wahba's problem (the rotation `R` minimising `Σ |R·rest_k − target_k|²`, by SVD), with the
/// turn its children leave free settled by the carried rotation.
///
/// With `B = Σ target_k · rest_kᵀ = U S Vᵀ` the solution is `U diag(1, 1, ±1) Vᵀ`, and turning it
/// by `θ` about `U`'s first column (the targets' main direction) costs `(s₂ + s₃)(1 − cos θ)`:
/// nothing when the children are in line. That turn is chosen like a twist, the data asking for
/// none with weight `s₂ + s₃` and the carried rotation asking for its own with weight
/// `w · w / (w + s₂ + s₃)`, `w` = [`WAHBA_CARRY_SHARE`] · [`CARRY_RADIUS_M`]²: the carried turn
/// settles children in line and fades as they pin the turn down, so a rigid motion comes back
/// exactly.
pub fn wahba_carried(
    rest: &[Vector3<f64>],
    target: &[Vector3<f64>],
    carried: Option<UnitQuaternion<f64>>,
) -> Option<UnitQuaternion<f64>> {
    let mut b = Matrix3::zeros();
    for (r, d) in rest.iter().zip(target) {
        b += d * r.transpose();
    }
    let svd = b.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let det = (u * v_t).determinant();
    let m = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, det.signum()));
    let rot = Rotation3::from_matrix_unchecked(u * m * v_t);
    let q = UnitQuaternion::from_rotation_matrix(&rot);
    if !q.coords.iter().all(|c| c.is_finite()) {
        return None;
    }
    let Some(c) = carried else { return Some(q) };
    // nalgebra's SVD sorts the singular values in decreasing order.
    let (axis, s) = (u.column(0).into_owned(), svd.singular_values);
    let stiffness = s[1] + s[2] * det.signum();
    let w = WAHBA_CARRY_SHARE * CARRY_WEIGHT;
    let w = w * w / (w + stiffness.max(0.0));
    let from = twist_angle(&(c * q.inverse()), &axis);
    let angle = (w * from.sin()).atan2(stiffness.max(0.0) + w * from.cos());
    Some(UnitQuaternion::from_axis_angle(&Unit::new_normalize(axis), angle) * q)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn twist_angle_reads_back_a_twist_and_ignores_the_swing() {
        let a = Vector3::new(0.3, -0.5, 0.8).normalize();
        for deg in [-170.0f64, -40.0, 0.0, 25.0, 179.0] {
            let q = UnitQuaternion::from_axis_angle(&Unit::new_normalize(a), deg.to_radians());
            assert!(
                (twist_angle(&q, &a).to_degrees() - deg).abs() < 1e-9,
                "{deg}"
            );
        }
        assert!((wrap(2.5 * std::f64::consts::PI) - 0.5 * std::f64::consts::PI).abs() < 1e-12);
        assert!((wrap(-1.5 * std::f64::consts::PI) - 0.5 * std::f64::consts::PI).abs() < 1e-12);
    }

    #[test]
    fn a_turn_is_limited_along_the_shortest_way() {
        let from = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 0.3);
        let max = max_turn(25.0);
        assert!((max.to_degrees() - 55.0).abs() < 1e-9);
        assert_eq!(max_turn(f64::NAN), std::f64::consts::PI);
        let near = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.5) * from;
        assert_eq!(limit_turn(from, near, max), near);
        let far = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 2.5) * from;
        let got = limit_turn(from, far, max);
        assert!((got.angle_to(&from) - max).abs() < 1e-9);
        assert!((got.angle_to(&far) - (2.5 - max)).abs() < 1e-9);
        // The same rotation with the other sign is no turn.
        assert!(
            limit_turn(from, UnitQuaternion::new_unchecked(-from.into_inner()), max)
                .angle_to(&from)
                < 1e-12
        );
    }

    #[test]
    fn a_reference_on_the_axis_leaves_the_carried_twist() {
        let axis = Vector3::y();
        let carried = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 1.0);
        // The reference 1 mm off the axis, on the far side from the carried twist.
        let refs = [(
            Vector3::new(0.001, 0.3, 0.0),
            Vector3::new(-0.001, 0.3, 0.0),
        )];
        let q = twist(
            UnitQuaternion::identity(),
            &axis,
            refs.into_iter(),
            Some(carried),
        );
        assert!(q.angle_to(&carried) < 0.01, "{}", q.angle_to(&carried));
        // Without the carried twist it follows the reference: half a turn.
        let q = twist(UnitQuaternion::identity(), &axis, refs.into_iter(), None);
        assert!((q.angle() - std::f64::consts::PI).abs() < 1e-6);
    }

    #[test]
    fn a_well_determined_twist_is_followed_up_to_the_step_limit() {
        let axis = Vector3::y();
        let refs = |deg: f64| {
            let r = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), deg.to_radians())
                * Vector3::new(0.2, 0.1, 0.0);
            [(Vector3::new(0.2, 0.1, 0.0), r)]
        };
        let from = UnitQuaternion::identity();
        let q = twist(
            UnitQuaternion::identity(),
            &axis,
            refs(10.0).into_iter(),
            Some(from),
        );
        assert!(
            (q.angle().to_degrees() - 10.0).abs() < 0.5,
            "{}",
            q.angle().to_degrees()
        );
        let q = twist(
            UnitQuaternion::identity(),
            &axis,
            refs(120.0).into_iter(),
            Some(from),
        );
        assert!(
            (q.angle().to_degrees() - MAX_TWIST_STEP_DEG).abs() < 1e-6,
            "{}",
            q.angle().to_degrees()
        );
    }
}
