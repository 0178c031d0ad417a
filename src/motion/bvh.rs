//! BVH, written and read by hand (the `bvh_anim` crate depends on a crate flagged unsound,
//! RUSTSEC-2023-0086).
//!
//! What we write: one `ROOT` (the body centre) with 6 channels
//! (`Xposition Yposition Zposition Zrotation Yrotation Xrotation`), every other joint with
//! `Zrotation Yrotation Xrotation`, offsets in **metres** (y up) from the rig's median bone
//! lengths, `Frame Time` = 1 / fps. Rotations are intrinsic ZYX Euler angles in degrees:
//! `R = Rz · Ry · Rx`, the usual BVH reading of the channel order, each joint's three angles the
//! triple nearest the previous frame's ([`euler_zyx_deg_near`]: unwrapped past ±180°, the other
//! of the two triples of one rotation where it is nearer), so a tool that interpolates the
//! channels as numbers turns the bones the short way. Leaf joints get an `End Site` 5 cm further
//! along their bone so tools draw them a bone.
//!
//! What we read: any BVH with 3 or 6 channels per joint in any axis order (position channels are
//! honoured on every joint), `End Site`s skipped, in memory that follows the bytes sent
//! ([`read`]). [`Bvh::to_motion`] maps a file that uses our joint names onto the 23-joint
//! skeleton.
use std::fmt::Write as _;

use nalgebra::{UnitQuaternion, Vector3};

use super::rig::{Rig, RigMotion};
use super::MotionError;

mod read;
pub use read::{Bvh, Channel, MAX_BVH_BYTES, MAX_BVH_JOINTS};

/// Length of the end site drawn past each leaf joint, metres.
const END_SITE_M: f64 = 0.05;

/// Writes a rig motion as BVH text.
pub fn write_bvh(m: &RigMotion) -> Result<String, MotionError> {
    if m.fps <= 0.0 || !m.fps.is_finite() {
        return Err(MotionError::Export(format!("invalid fps {}", m.fps)));
    }
    let rig = &m.rig;
    let order = rig.order();
    let mut out = String::with_capacity(64 * 1024 + m.num_frames() * rig.names.len() * 40);
    out.push_str("HIERARCHY\n");
    write_joint(&mut out, rig, order[0], 0);
    let _ = writeln!(out, "MOTION\nFrames: {}", m.num_frames());
    let _ = writeln!(out, "Frame Time: {:.8}", 1.0 / m.fps);
    let mut previous: Vec<Option<[f64; 3]>> = vec![None; rig.names.len()];
    for (t, locals) in m.rotations.iter().enumerate() {
        let r = m.root_translation[t];
        let mut line = String::with_capacity(rig.names.len() * 40);
        let _ = write!(line, "{:.6} {:.6} {:.6}", r.x, r.y, r.z);
        for &j in &order {
            let [z, y, x] = match previous[j] {
                Some(p) => euler_zyx_deg_near(&locals[j], p),
                None => euler_zyx_deg(&locals[j]),
            };
            previous[j] = Some([z, y, x]);
            let _ = write!(line, " {z:.6} {y:.6} {x:.6}");
        }
        out.push_str(&line);
        out.push('\n');
    }
    Ok(out)
}

fn write_joint(out: &mut String, rig: &Rig, j: usize, depth: usize) {
    let pad = "  ".repeat(depth);
    let o = rig.offsets[j];
    if rig.parents[j].is_none() {
        let _ = writeln!(out, "{pad}ROOT {}", rig.names[j]);
    } else {
        let _ = writeln!(out, "{pad}JOINT {}", rig.names[j]);
    }
    let _ = writeln!(out, "{pad}{{");
    let _ = writeln!(out, "{pad}  OFFSET {:.6} {:.6} {:.6}", o.x, o.y, o.z);
    if rig.parents[j].is_none() {
        let _ = writeln!(
            out,
            "{pad}  CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation"
        );
    } else {
        let _ = writeln!(out, "{pad}  CHANNELS 3 Zrotation Yrotation Xrotation");
    }
    let kids = rig.children(j);
    if kids.is_empty() {
        let e = o.try_normalize(1e-9).unwrap_or_else(Vector3::y) * END_SITE_M;
        let _ = writeln!(out, "{pad}  End Site\n{pad}  {{");
        let _ = writeln!(out, "{pad}    OFFSET {:.6} {:.6} {:.6}", e.x, e.y, e.z);
        let _ = writeln!(out, "{pad}  }}");
    }
    for c in kids {
        write_joint(out, rig, c, depth + 1);
    }
    let _ = writeln!(out, "{pad}}}");
}

/// Intrinsic ZYX Euler angles `[z, y, x]` in degrees with `R = Rz(z) · Ry(y) · Rx(x)`.
pub fn euler_zyx_deg(q: &UnitQuaternion<f64>) -> [f64; 3] {
    euler_zyx_locked(q).0
}

/// [`euler_zyx_deg`], and whether the rotation is in gimbal lock (`x` then 0).
fn euler_zyx_locked(q: &UnitQuaternion<f64>) -> ([f64; 3], bool) {
    let m = q.to_rotation_matrix();
    let m = m.matrix();
    let sy = (-m[(2, 0)]).clamp(-1.0, 1.0);
    let y = sy.asin();
    let locked = sy.abs() >= 1.0 - 1e-9;
    let (z, x) = if !locked {
        (m[(1, 0)].atan2(m[(0, 0)]), m[(2, 1)].atan2(m[(2, 2)]))
    } else {
        // Gimbal lock: only z − x (or z + x) is defined; put it all in z.
        ((-m[(0, 1)]).atan2(m[(1, 1)]), 0.0)
    };
    ([z.to_degrees(), y.to_degrees(), x.to_degrees()], locked)
}

/// The intrinsic ZYX Euler angles of `q` (degrees, as [`euler_zyx_deg`]) nearest `previous`: of
/// the two triples of one rotation, `(z, y, x)` and `(z + 180, 180 − y, x + 180)`, each angle
/// moved by whole turns to lie within 180° of the previous one, the one that moves least. In
/// gimbal lock (`y` = ±90°, where only `z ∓ x` is defined) `x` stays where it was.
pub fn euler_zyx_deg_near(q: &UnitQuaternion<f64>, previous: [f64; 3]) -> [f64; 3] {
    let ([mut z, y, mut x], locked) = euler_zyx_locked(q);
    if locked {
        // y = +90°: R depends on z − x; y = −90°: on z + x. `euler_zyx_deg` put it all in z.
        x = previous[2];
        z += y.signum() * x;
    }
    let near = |a: f64, p: f64| a + 360.0 * ((p - a) / 360.0).round();
    let fit = |c: [f64; 3]| {
        let v = [
            near(c[0], previous[0]),
            near(c[1], previous[1]),
            near(c[2], previous[2]),
        ];
        let cost: f64 = v.iter().zip(&previous).map(|(a, p)| (a - p).abs()).sum();
        (v, cost)
    };
    let (a, cost_a) = fit([z, y, x]);
    let (b, cost_b) = fit([z + 180.0, 180.0 - y, x + 180.0]);
    if cost_b < cost_a {
        b
    } else {
        a
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn euler_zyx_round_trips() {
        for (a, b, c) in [
            (0.3, -0.4, 1.2),
            (-2.0, 1.0, 0.1),
            (0.0, std::f64::consts::FRAC_PI_2 - 1e-4, 0.4),
        ] {
            let q = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), a)
                * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), b)
                * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), c);
            let [z, y, x] = euler_zyx_deg(&q);
            let back = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), z.to_radians())
                * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), y.to_radians())
                * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), x.to_radians());
            assert!(back.angle_to(&q) < 1e-6, "{a} {b} {c}");
        }
    }

    fn zyx(z: f64, y: f64, x: f64) -> UnitQuaternion<f64> {
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), z.to_radians())
            * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), y.to_radians())
            * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), x.to_radians())
    }

    /// A joint turning steadily about z past ±180°, and one through y = 90°: the angles written
    /// move the short way and still read back as the rotation.
    #[test]
    fn euler_angles_follow_the_previous_frame() {
        for (turn, tilt) in [(7.0, 20.0), (-11.0, 80.0)] {
            let mut prev = euler_zyx_deg(&zyx(0.0, tilt, 30.0));
            for t in 1..100 {
                let q = zyx(turn * t as f64, tilt + 0.3 * t as f64, 30.0);
                let e = euler_zyx_deg_near(&q, prev);
                assert!(
                    zyx(e[0], e[1], e[2]).angle_to(&q) < 1e-6,
                    "frame {t}: {e:?}"
                );
                let step = e
                    .iter()
                    .zip(&prev)
                    .map(|(a, p)| (a - p).abs())
                    .fold(0.0, f64::max);
                assert!(step < 20.0, "frame {t}: {prev:?} → {e:?}");
                prev = e;
            }
        }
        // Gimbal lock: x kept, z takes the rest.
        let e = euler_zyx_deg_near(&zyx(40.0, 90.0, 10.0), [35.0, 89.0, 12.0]);
        assert!(
            (e[2] - 12.0).abs() < 1e-9
                && zyx(e[0], e[1], e[2]).angle_to(&zyx(40.0, 90.0, 10.0)) < 1e-6,
            "{e:?}"
        );
    }
}
