//! The solver's geometry: rest frames, shortest arcs, means of points and rotations, forward
//! kinematics from world rotations, the two-bone IK of the legs (step 4 of the solver's doc),
//! and the smoothing of the hips' drop.
use nalgebra::{Matrix3, Rotation3, Unit, UnitQuaternion, Vector3};

use crate::motion::rig::limit_turn;

/// A leg is never stretched past this share of its length (a straight knee has no bend plane).
pub(super) const MAX_REACH: f64 = 0.999;
/// How far forward (m) the IK leans the knee's bend direction: what decides it for a knee bent
/// less than this off the hip–ankle line.
pub(super) const KNEE_FORWARD_M: f64 = 0.02;

/// A rest frame: the bone direction, then `second` made perpendicular to it.
pub(super) fn frame(dir: &Vector3<f64>, second: &Vector3<f64>) -> Rotation3<f64> {
    let x = dir.try_normalize(1e-12).unwrap_or_else(Vector3::y);
    let mut y = second - x * x.dot(second);
    if y.norm() < 1e-6 {
        // The bone runs along `second`: any perpendicular will do, the same in both skeletons.
        let alt = if x.x.abs() < 0.9 {
            Vector3::x()
        } else {
            Vector3::z()
        };
        y = alt - x * x.dot(&alt);
    }
    let y = y.normalize();
    Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, x.cross(&y)]))
}

/// Shortest-arc rotation taking direction `a` onto `b` (identity when either is degenerate).
pub(super) fn arc(a: &Vector3<f64>, b: &Vector3<f64>) -> UnitQuaternion<f64> {
    if a.norm() < 1e-12 || b.norm() < 1e-12 {
        return UnitQuaternion::identity();
    }
    UnitQuaternion::rotation_between(a, b).unwrap_or_else(|| {
        let perp = a.cross(&Vector3::x());
        let perp = if perp.norm() < 1e-6 {
            a.cross(&Vector3::y())
        } else {
            perp
        };
        UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_normalize(perp), std::f64::consts::PI)
    })
}

pub(super) fn mean(points: impl Iterator<Item = Vector3<f64>>) -> Vector3<f64> {
    let (sum, n) = points.fold((Vector3::zeros(), 0usize), |(s, n), p| (s + p, n + 1));
    if n == 0 {
        Vector3::zeros()
    } else {
        sum / n as f64
    }
}

/// Positions from world rotations (FK with world, not local, rotations).
pub(super) fn fk_world(
    rig: &crate::motion::rig::Rig,
    order: &[usize],
    root: &Vector3<f64>,
    w: &[UnitQuaternion<f64>],
) -> Vec<Vector3<f64>> {
    let mut pos = vec![Vector3::zeros(); rig.names.len()];
    for &j in order {
        pos[j] = match rig.parents[j] {
            None => root + rig.offsets[j],
            Some(p) => pos[p] + w[p] * rig.offsets[j],
        };
    }
    pos
}

/// Local rotations from world ones.
pub(super) fn locals(
    rig: &crate::motion::rig::Rig,
    w: &[UnitQuaternion<f64>],
) -> Vec<UnitQuaternion<f64>> {
    (0..w.len())
        .map(|j| match rig.parents[j] {
            None => w[j],
            Some(p) => w[p].inverse() * w[j],
        })
        .collect()
}

/// Two-bone IK: turns the thigh (`jt`, at `hip`) and shin (`js`, at `knee`) so the ankle (`jf`)
/// reaches `goal`, in the plane the knee bends in now; the foot keeps its world rotation.
#[allow(clippy::too_many_arguments)]
pub(super) fn two_bone_ik(
    w: &mut [UnitQuaternion<f64>],
    jt: usize,
    js: usize,
    jf: usize,
    hip: Vector3<f64>,
    knee: Vector3<f64>,
    ankle: Vector3<f64>,
    goal: Vector3<f64>,
) {
    let (a, b) = ((knee - hip).norm(), (ankle - knee).norm());
    let to_goal = goal - hip;
    if a < 1e-6 || b < 1e-6 || to_goal.norm() < 1e-6 {
        return;
    }
    let d = to_goal
        .norm()
        .clamp((a - b).abs() + 1e-6, MAX_REACH * (a + b));
    let u = to_goal / to_goal.norm();
    // The bend direction: where the knee is now, off the hip–goal line, leaning forward by
    // KNEE_FORWARD_M: a knee bent a few centimetres keeps its own direction, and a nearly
    // straight one (whose offset turns with every millimetre of marker noise: a 64° turn of the
    // knee in one frame once the hips stand where the dance's knee angle reaches the floor)
    // bends forward, as knees do.
    let off = (knee - hip) - u * u.dot(&(knee - hip));
    let fwd = w[jt] * Vector3::z();
    let fwd = fwd - u * u.dot(&fwd);
    let fwd = if fwd.norm() > 1e-6 {
        fwd.normalize()
    } else {
        Vector3::zeros()
    };
    let lean = off + fwd * KNEE_FORWARD_M;
    if lean.norm() < 1e-6 {
        return;
    }
    let v = lean.normalize();
    let cos_a = ((a * a + d * d - b * b) / (2.0 * a * d)).clamp(-1.0, 1.0);
    let new_knee = hip + a * (cos_a * u + (1.0 - cos_a * cos_a).sqrt() * v);
    let new_ankle = hip + u * d;
    let foot = w[jf];
    let turn_thigh = arc(&(knee - hip), &(new_knee - hip));
    w[jt] = turn_thigh * w[jt];
    let shin_now = turn_thigh * (ankle - knee);
    w[js] = arc(&shin_now, &(new_ankle - new_knee)) * turn_thigh * w[js];
    w[jf] = foot;
}

/// The running maximum over ±`r` frames, then its running mean over ±`r`: never below the input,
/// with no corner in one frame.
pub(super) fn spread_max(x: &[f64], r: usize) -> Vec<f64> {
    let n = x.len();
    let window = |t: usize| t.saturating_sub(r)..(t + r + 1).min(n);
    let max: Vec<f64> = (0..n)
        .map(|t| x[window(t)].iter().copied().fold(0.0, f64::max))
        .collect();
    (0..n)
        .map(|t| max[window(t)].iter().sum::<f64>() / window(t).len() as f64)
        .collect()
}

/// The normalised sum of unit quaternions, each on the first one's hemisphere: their mean
/// rotation when they are close (as one foot's alignments over frames are).
pub(super) fn mean_rotation(qs: impl Iterator<Item = UnitQuaternion<f64>>) -> UnitQuaternion<f64> {
    let mut first: Option<nalgebra::Vector4<f64>> = None;
    let mut sum = nalgebra::Vector4::zeros();
    for q in qs {
        let c = q.coords;
        let f = *first.get_or_insert(c);
        sum += if f.dot(&c) < 0.0 { -c } else { c };
    }
    UnitQuaternion::from_quaternion(nalgebra::Quaternion::from(sum))
}

/// `q` twisted about `axis` (its own bone, in its own frame) by the angle nearest none that
/// keeps it within `max` radians of `prev`: the bone points where `q` points, and its twist
/// catches up with `q`'s as fast as the turn allows. Where no twist does (the bone's direction
/// alone turns further than `max`), the twist that turns least, turned `max` from `prev` towards
/// it along the shortest way.
///
/// With `D = prev⁻¹·q = (c, v)` and a twist of `2h` about the axis `n`, the turn's half-angle has
/// cosine `|c·cos h − (v·n)·sin h| = A·|cos(h + α)|` (`A = |(c, v·n)|`, `α = atan2(v·n, c)`): within
/// `max` where `h + α` lies within `acos(cos(max/2) / A)` of a multiple of π.
pub(super) fn limit_bone_turn(
    prev: &UnitQuaternion<f64>,
    q: &UnitQuaternion<f64>,
    axis: &Unit<Vector3<f64>>,
    max: f64,
) -> UnitQuaternion<f64> {
    use std::f64::consts::PI;
    let d = prev.inverse() * q;
    let (c, s) = (d.w, d.imag().dot(axis));
    let (a, alpha) = (c.hypot(s), s.atan2(c));
    let twisted = |h: f64| q * UnitQuaternion::from_axis_angle(axis, 2.0 * h);
    let k = (0.5 * max).cos();
    if a < k {
        return limit_turn(*prev, twisted(-alpha), max);
    }
    let beta = (k / a).min(1.0).acos();
    // The allowed half-twists are intervals about −α + mπ; the one nearest none wins (|α| ≤ π,
    // so m in −2..=2 covers every interval that can hold it).
    let h = (-2..=2)
        .map(|m| {
            let centre = -alpha + f64::from(m) * PI;
            0.0f64.clamp(centre - beta, centre + beta)
        })
        .min_by(|x, y| x.abs().total_cmp(&y.abs()))
        .unwrap_or(0.0);
    twisted(h)
}

/// Flips quaternion signs so each joint's track never jumps hemispheres.
pub(super) fn make_continuous(rotations: &mut [Vec<UnitQuaternion<f64>>]) {
    for t in 1..rotations.len() {
        let (prev, cur) = rotations.split_at_mut(t);
        for (p, c) in prev[t - 1].iter().zip(cur[0].iter_mut()) {
            if p.coords.dot(&c.coords) < 0.0 {
                *c = UnitQuaternion::new_unchecked(-c.into_inner());
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bone keeps its direction and the turn stays within the limit, by the least twist
    /// away from the asked rotation; a turn already within it is left alone.
    #[test]
    fn a_bone_turn_is_limited_by_its_twist_first() {
        let axis = Unit::new_normalize(Vector3::new(0.2, -1.0, 0.1));
        let max = 55f64.to_radians();
        let prev = UnitQuaternion::from_euler_angles(0.3, -0.2, 0.5);
        let swing =
            |deg: f64| UnitQuaternion::from_axis_angle(&Vector3::x_axis(), f64::to_radians(deg));
        let twist = |deg: f64| UnitQuaternion::from_axis_angle(&axis, f64::to_radians(deg));
        for (swing_deg, twist_deg) in [(10.0, 80.0), (40.0, -75.0), (20.0, 179.0), (5.0, 30.0)] {
            let q = prev * swing(swing_deg) * twist(twist_deg);
            let got = limit_bone_turn(&prev, &q, &axis, max);
            let (dir_q, dir_got) = (q * axis.into_inner(), got * axis.into_inner());
            assert!((dir_q - dir_got).norm() < 1e-9, "{swing_deg}/{twist_deg}");
            let turn = prev.angle_to(&got);
            if prev.angle_to(&q) <= max {
                assert!(got.angle_to(&q) < 1e-9, "{swing_deg}/{twist_deg}: changed");
            } else {
                // As close to q as the limit lets it be: exactly at the limit.
                assert!((turn - max).abs() < 1e-9, "{swing_deg}/{twist_deg}: {turn}");
            }
        }
        // A swing past the limit alone: turned the limit's way towards the least-twist pose.
        let q = prev * swing(70.0) * twist(90.0);
        let got = limit_bone_turn(&prev, &q, &axis, max);
        assert!((prev.angle_to(&got) - max).abs() < 1e-9);
    }
}
