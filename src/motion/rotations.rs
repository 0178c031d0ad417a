//! Rotation features: the motion representation of DanceNet (Zhuang et al. 2020, §3.1), with an
//! exact inverse through the rig's forward kinematics.
//!
//! One row per frame, [`Layout::dim`] numbers:
//! - `[0, 4)` the root, as changes from the previous frame so a dance depends neither on where it
//!   starts nor where it faces: horizontal velocity `x`, `z` of the anchor (the spine joint, where
//!   the rig's pelvis and spine branch) in the facing frame of the previous frame (m/frame), the
//!   lowest foot point's clearance above the dance's floor (m; the height follows from the legs,
//!   as in [`super::repr::height_to_clearance`]), and the yaw velocity (rad/frame). All 0 on frame 0
//!   but the clearance.
//! - `[4, 4 + 6R)` the local rotation of each of the `R` rig joints that have a rotation of their
//!   own (every joint with a child, but the root), in the continuous 6-D form
//!   ([`super::rig::rotations_6d`]). The root's own rotation is the facing yaw alone, so the
//!   root's children (spine and pelvis) carry the body's lean in their rotations.
//! - the last 15: the end effectors ([`END_EFFECTORS`]: head, wrists, toes) relative to the anchor
//!   in the facing frame (m), which the paper predicts beside the rotations.
//!
//! Foot contacts are labelled separately ([`super::repr::foot_contacts`] of the rigid motion).
//!
//! [`encode`] solves the rig's rotations ([`super::rig::solve`]), so [`decode`] returns the
//! rigid skeleton's motion: exact for a motion that is already rigid, within the rigid fit (1–3 cm
//! on captured dances) for one that is not.
use nalgebra::{UnitQuaternion, Vector3};
use ndarray::{Array2, Array3, ArrayView2, ArrayView3};

use super::repr::{facing_yaw, foot_contacts, wrap, RootStart};
use super::rig::{fk_frame, rig_index, rotation_from_6d, solve, Rig};
use super::skeleton::{FOOT_POINTS, HEAD, SPINE, TOES, WRISTS};
use super::{feet, Motion, MotionError, NUM_JOINTS};

/// Root columns: velocity x, velocity z, clearance, yaw velocity.
pub const ROOT_DIMS: usize = 4;
/// Column of the anchor's velocity `x` (facing frame, m/frame).
pub const ROOT_VX: usize = 0;
/// Column of the anchor's velocity `z` (facing frame, m/frame).
pub const ROOT_VZ: usize = 1;
/// Column of the lowest foot point's clearance above the floor (m).
pub const CLEARANCE: usize = 2;
/// Column of the yaw velocity (rad/frame).
pub const YAW_VEL: usize = 3;
/// End effectors as dataset joints: the head (midpoint of its two markers), right and left
/// wrists, right and left toes.
pub const END_EFFECTORS: [&[usize]; 5] =
    [&HEAD, &[WRISTS[0]], &[WRISTS[1]], &[TOES[0]], &[TOES[1]]];
/// End-effector columns (3 each).
pub const EE_DIMS: usize = 3 * END_EFFECTORS.len();

/// Which rig joints carry a rotation, and where each block of a row sits.
#[derive(Clone, Debug, PartialEq)]
pub struct Layout {
    /// Rig joints with a 6-D rotation column block, in rig order.
    pub joints: Vec<usize>,
}

impl Layout {
    /// The joints of `rig` that have a child, but the root.
    pub fn of(rig: &Rig) -> Self {
        Self {
            joints: (1..rig.parents.len())
                .filter(|&j| !rig.children(j).is_empty())
                .collect(),
        }
    }

    /// Width of a row.
    pub fn dim(&self) -> usize {
        ROOT_DIMS + 6 * self.joints.len() + EE_DIMS
    }

    /// Columns of the rotations.
    pub fn rotations(&self) -> std::ops::Range<usize> {
        ROOT_DIMS..ROOT_DIMS + 6 * self.joints.len()
    }

    /// Columns of the end effectors.
    pub fn end_effectors(&self) -> std::ops::Range<usize> {
        let r = self.rotations().end;
        r..r + EE_DIMS
    }
}

/// A motion in rotation features.
#[derive(Clone, Debug)]
pub struct Encoded {
    /// `[T, Layout::dim]`.
    pub features: Array2<f32>,
    /// `[T, 4]` foot contacts of the rigid motion (1 = on the floor), [`FOOT_POINTS`] order.
    pub contacts: Array2<f32>,
    /// The anchor's ground position and yaw on frame 0.
    pub start: RootStart,
}

fn yaw_rotation(yaw: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_axis_angle(&Vector3::y_axis(), yaw)
}

/// The anchor: the spine joint, the root's child where the spine and the pelvis branch.
const ANCHOR: usize = rig_index(SPINE);

/// Checks that every child of the root sits at the anchor's rest offset, which [`decode`]'s
/// yaw-only root needs to put the spine and the pelvis where [`encode`] saw them.
fn check_rig(rig: &Rig) -> Result<(), MotionError> {
    if rig.parents.first() != Some(&None) || rig.offsets.len() != rig.parents.len() {
        return Err(MotionError::Shape("rig without a root first".into()));
    }
    for c in rig.children(0) {
        if (rig.offsets[c] - rig.offsets[ANCHOR]).norm() > 1e-6 {
            return Err(MotionError::Invalid(format!(
                "rig joint {} is not at the anchor's rest offset",
                rig.names[c]
            )));
        }
    }
    Ok(())
}

/// Lowest foot point's height in world positions of the rig `[RIG_JOINTS]`.
fn lowest_foot(pos: &[Vector3<f64>]) -> f64 {
    FOOT_POINTS
        .iter()
        .map(|&j| pos[rig_index(j)].y)
        .fold(f64::INFINITY, f64::min)
}

/// Rotation features of world positions `[T, 23, 3]` on `rig`.
pub fn encode(rig: &Rig, positions: ArrayView3<'_, f32>, fps: f64) -> Result<Encoded, MotionError> {
    check_rig(rig)?;
    let layout = Layout::of(rig);
    // The root track that puts the anchor exactly on the spine joint: with the body centre as
    // the root (as the export does), the spine would land off its target by however much the
    // centre-to-spine distance differs from the rig's, and every joint below it with it.
    let yaws: Vec<f64> = positions
        .outer_iter()
        .map(|f| f64::from(facing_yaw(f)))
        .collect();
    let mut root = Array2::<f32>::zeros((positions.dim().0, 3));
    for (t, &yaw) in yaws.iter().enumerate() {
        let r = Vector3::new(
            f64::from(positions[[t, SPINE, 0]]),
            f64::from(positions[[t, SPINE, 1]]),
            f64::from(positions[[t, SPINE, 2]]),
        ) - yaw_rotation(yaw) * rig.offsets[ANCHOR];
        for c in 0..3 {
            root[[t, c]] = r[c] as f32;
        }
    }
    let rigid = solve(rig, positions, root.view(), fps)?;
    let t_len = rigid.num_frames();
    let frames: Vec<_> = (0..t_len)
        .map(|t| fk_frame(rig, &rigid.root_translation[t], &rigid.rotations[t]))
        .collect();
    let mut rigid_positions = Array3::<f32>::zeros((t_len, NUM_JOINTS, 3));
    for (t, (pos, _)) in frames.iter().enumerate() {
        for j in 0..NUM_JOINTS {
            for c in 0..3 {
                rigid_positions[[t, j, c]] = pos[rig_index(j)][c] as f32;
            }
        }
    }
    let floor = feet::floor_height(rigid_positions.view(), &FOOT_POINTS);
    let mut out = Array2::<f32>::zeros((t_len, layout.dim()));
    for t in 0..t_len {
        let (pos, world) = &frames[t];
        let facing = yaw_rotation(yaws[t]);
        let unfaced = facing.inverse();
        let anchor = pos[ANCHOR];
        let mut row = out.row_mut(t);
        if t > 0 {
            let step = anchor - frames[t - 1].0[ANCHOR];
            let v = yaw_rotation(yaws[t - 1]).inverse() * Vector3::new(step.x, 0.0, step.z);
            row[ROOT_VX] = v.x as f32;
            row[ROOT_VZ] = v.z as f32;
            row[YAW_VEL] = wrap(yaws[t] - yaws[t - 1]) as f32;
        }
        row[CLEARANCE] = (lowest_foot(pos) - floor) as f32;
        for (k, &j) in layout.joints.iter().enumerate() {
            let local = match rig.parents[j] {
                Some(0) => unfaced * world[j],
                _ => rigid.rotations[t][j],
            };
            let m = local.to_rotation_matrix();
            let m = m.matrix();
            for r in 0..3 {
                row[ROOT_DIMS + 6 * k + r] = m[(r, 0)] as f32;
                row[ROOT_DIMS + 6 * k + 3 + r] = m[(r, 1)] as f32;
            }
        }
        let ee0 = layout.end_effectors().start;
        for (e, joints) in END_EFFECTORS.iter().enumerate() {
            let p = joints
                .iter()
                .map(|&j| pos[rig_index(j)])
                .sum::<Vector3<f64>>()
                / joints.len() as f64;
            let local = unfaced * (p - anchor);
            for c in 0..3 {
                row[ee0 + 3 * e + c] = local[c] as f32;
            }
        }
    }
    let contacts = foot_contacts(rigid_positions.view(), fps)?;
    let start = match t_len {
        0 => RootStart::default(),
        _ => RootStart {
            x: frames[0].0[ANCHOR].x as f32,
            z: frames[0].0[ANCHOR].z as f32,
            yaw: yaws[0] as f32,
        },
    };
    Ok(Encoded {
        features: out,
        contacts,
        start,
    })
}

/// The rigid motion of rotation features `[T, Layout::dim]` on `rig`, its floor at `y = 0`; a
/// clearance below 0 (a foot under the floor) is raised to 0. The end-effector columns are not
/// used: the rotations place every joint.
pub fn decode(
    rig: &Rig,
    features: ArrayView2<'_, f32>,
    start: RootStart,
    fps: f64,
) -> Result<Motion, MotionError> {
    check_rig(rig)?;
    let layout = Layout::of(rig);
    if features.ncols() != layout.dim() {
        return Err(MotionError::Shape(format!(
            "features {:?}, expected [T, {}]",
            features.shape(),
            layout.dim()
        )));
    }
    let t_len = features.nrows();
    let n = rig.parents.len();
    let mut positions = Array3::<f32>::zeros((t_len, NUM_JOINTS, 3));
    let (mut x, mut z, mut yaw) = (f64::from(start.x), f64::from(start.z), f64::from(start.yaw));
    let mut local = vec![UnitQuaternion::identity(); n];
    for t in 0..t_len {
        let f = features.row(t);
        if t > 0 {
            let d =
                yaw_rotation(yaw) * Vector3::new(f64::from(f[ROOT_VX]), 0.0, f64::from(f[ROOT_VZ]));
            x += d.x;
            z += d.z;
            yaw += f64::from(f[YAW_VEL]);
        }
        let facing = yaw_rotation(yaw);
        local[0] = facing;
        for (k, &j) in layout.joints.iter().enumerate() {
            let c = ROOT_DIMS + 6 * k;
            let v = [f[c], f[c + 1], f[c + 2], f[c + 3], f[c + 4], f[c + 5]];
            local[j] = rotation_from_6d(&v).ok_or_else(|| {
                MotionError::Invalid(format!("frame {t}: degenerate rotation of rig joint {j}"))
            })?;
        }
        // The anchor at (x, 0, z) first; then the height that puts the lowest foot at its clearance.
        let root = Vector3::new(x, 0.0, z) - facing * rig.offsets[ANCHOR];
        let (pos, _) = fk_frame(rig, &root, &local);
        let lift = f64::from(f[CLEARANCE]).max(0.0) - lowest_foot(&pos);
        for j in 0..NUM_JOINTS {
            let p = pos[rig_index(j)];
            positions[[t, j, 0]] = p.x as f32;
            positions[[t, j, 1]] = (p.y + lift) as f32;
            positions[[t, j, 2]] = p.z as f32;
        }
    }
    Ok(Motion { fps, positions })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::rig::{joint_errors, RIG_JOINTS};
    use rand::{Rng, SeedableRng};

    /// A rig with plausible offsets: the data's hierarchy, bones pointing down the legs and out
    /// along the arms, the root's children at one offset.
    fn rig() -> Rig {
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let mut r = Rig::from_offsets(&vec![[0.0; 3]; RIG_JOINTS]).expect("hierarchy");
        for j in 1..RIG_JOINTS {
            r.offsets[j] = Vector3::new(
                rng.gen_range(-0.1..0.1),
                rng.gen_range(-0.3..-0.1),
                rng.gen_range(-0.1..0.1),
            );
        }
        let anchor = Vector3::new(0.0, 0.1, 0.0);
        for c in r.children(0) {
            r.offsets[c] = anchor;
        }
        // The neck sits on the spine joint (a branch joint of the rig at the same point).
        r.offsets[NUM_JOINTS + 2] = Vector3::zeros();
        r
    }

    /// Positions of a rigid motion of `rig`: random local rotations, each turning steadily (up to
    /// 0.1 rad a frame about each axis: a motion, which the rig keeps continuous, not unrelated
    /// poses), the body turning and travelling.
    fn rigid_motion(rig: &Rig, t_len: usize) -> Array3<f32> {
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        let (pose, spin): (Vec<UnitQuaternion<f64>>, Vec<Vector3<f64>>) = (0..RIG_JOINTS)
            .map(|_| {
                let q = UnitQuaternion::from_euler_angles(
                    rng.gen_range(-0.6..0.6),
                    rng.gen_range(-0.6..0.6),
                    rng.gen_range(-0.6..0.6),
                );
                (
                    q,
                    Vector3::new(
                        rng.gen_range(-0.1..0.1),
                        rng.gen_range(-0.1..0.1),
                        rng.gen_range(-0.1..0.1),
                    ),
                )
            })
            .unzip();
        let mut out = Array3::zeros((t_len, NUM_JOINTS, 3));
        for t in 0..t_len {
            let local: Vec<UnitQuaternion<f64>> = (0..RIG_JOINTS)
                .map(|j| {
                    if j == 0 {
                        UnitQuaternion::from_euler_angles(
                            0.1 * (t as f64 * 0.3).sin(),
                            0.05 * t as f64,
                            0.0,
                        )
                    } else if rig.children(j).is_empty() {
                        UnitQuaternion::identity()
                    } else {
                        UnitQuaternion::from_scaled_axis(spin[j] * t as f64) * pose[j]
                    }
                })
                .collect();
            let root = Vector3::new(0.02 * t as f64, 1.0, -0.01 * t as f64);
            let (pos, _) = fk_frame(rig, &root, &local);
            for j in 0..NUM_JOINTS {
                for c in 0..3 {
                    out[[t, j, c]] = pos[rig_index(j)][c] as f32;
                }
            }
        }
        out
    }

    #[test]
    fn a_rigid_motion_round_trips() {
        let rig = rig();
        let p = rigid_motion(&rig, 40);
        let e = encode(&rig, p.view(), 25.0).expect("encode");
        assert_eq!(e.features.ncols(), Layout::of(&rig).dim());
        let back = decode(&rig, e.features.view(), e.start, 25.0).expect("decode");
        // The decoded dance stands on y = 0: compare after moving the original onto its floor.
        let floor = feet::floor_height(p.view(), &FOOT_POINTS) as f32;
        let mut want = p.clone();
        want.slice_mut(ndarray::s![.., .., 1])
            .mapv_inplace(|y| y - floor);
        // A frame whose lowest foot is under the floor (the 1st percentile) is raised onto it.
        for (t, low) in feet::lowest_foot(want.view(), &FOOT_POINTS)
            .into_iter()
            .enumerate()
        {
            if low < 0.0 {
                want.slice_mut(ndarray::s![t, .., 1])
                    .mapv_inplace(|y| y - low as f32);
            }
        }
        let err = joint_errors(back.positions.view(), want.view()).fold(0f32, |a, &b| a.max(b));
        assert!(err < 1e-4, "max error {err} m");
    }

    #[test]
    fn the_features_do_not_depend_on_where_the_dance_starts_or_faces() {
        let rig = rig();
        let p = rigid_motion(&rig, 30);
        // The same dance turned by 1 rad about y and moved 3 m away.
        let (s, c) = 1.0f32.sin_cos();
        let mut q = p.clone();
        for t in 0..30 {
            for j in 0..NUM_JOINTS {
                let (x, z) = (p[[t, j, 0]], p[[t, j, 2]]);
                q[[t, j, 0]] = c * x + s * z + 3.0;
                q[[t, j, 2]] = -s * x + c * z - 2.0;
            }
        }
        let a = encode(&rig, p.view(), 25.0).expect("encode").features;
        let b = encode(&rig, q.view(), 25.0).expect("encode").features;
        let d = (&a - &b).mapv(f32::abs).fold(0f32, |m, &v| m.max(v));
        assert!(d < 1e-4, "features moved by {d}");
    }
}
