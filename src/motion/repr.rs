//! Representations the models predict, with exact inverses, and foot-contact labels.
//!
//! # Pose features (what the models predict)
//! One row of [`FEATURE_DIM`] = 73 numbers per frame:
//! - `[0, 69)`: the 23 joints relative to the root (body centre), rotated into the body's facing
//!   frame (yaw removed), metres, joint-major `x, y, z`;
//! - `69`, `70`: root velocity `x`, `z` in the facing frame of the previous frame, metres per
//!   frame (0 on frame 0);
//! - `71`: root height `y`, metres (absolute, so the dancer cannot drift into the floor);
//! - `72`: yaw velocity, radians per frame, wrapped to (−π, π] (0 on frame 0).
//!
//! The facing direction is horizontal and perpendicular to the right-to-left axis of hips and
//! shoulders together: `forward = up × (right − left)`; yaw θ turns +z onto it
//! (`forward = (sin θ, 0, cos θ)`).
//!
//! [`from_features`] integrates yaw and root velocity back from a [`RootStart`] (the first frame's
//! ground position and yaw), which makes [`to_features`] → [`from_features`] exact up to float
//! rounding.
use ndarray::{s, Array2, Array3, ArrayView2, ArrayView3};
use serde::{Deserialize, Serialize};

use super::skeleton::{FOOT_POINTS, HIPS, SHOULDERS};
use super::{Motion, MotionError, NUM_JOINTS};

/// Width of the local-pose block: 23 joints × 3.
pub const POSE_DIM: usize = NUM_JOINTS * 3;
/// Index of root velocity x (facing frame, m/frame).
pub const ROOT_VX: usize = POSE_DIM;
/// Index of root velocity z (facing frame, m/frame).
pub const ROOT_VZ: usize = POSE_DIM + 1;
/// Index of root height y (m).
pub const ROOT_Y: usize = POSE_DIM + 2;
/// Index of yaw velocity (rad/frame).
pub const YAW_VEL: usize = POSE_DIM + 3;
/// Width of one feature row.
pub const FEATURE_DIM: usize = POSE_DIM + 4;

/// A foot point is in contact when within this height of its lowest level in the motion (m).
pub const CONTACT_HEIGHT_M: f32 = 0.04;
/// ...and moving slower than this (m/s). Ballroom feet glide, so this is generous.
pub const CONTACT_SPEED_M_S: f32 = 0.40;
/// Percentile of a foot point's height taken as its floor level (robust to marker glitches).
const FLOOR_PERCENTILE: f64 = 5.0;

/// Where integration of root velocities starts: the root's ground position and yaw at frame 0.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RootStart {
    pub x: f32,
    pub z: f32,
    /// Radians.
    pub yaw: f32,
}

/// Facing yaw (radians) of one `[J, 3]` frame.
pub fn facing_yaw(frame: ArrayView2<'_, f32>) -> f32 {
    let mut rx = 0.0f64;
    let mut rz = 0.0f64;
    for [right, left] in [HIPS, SHOULDERS] {
        rx += f64::from(frame[[right, 0]] - frame[[left, 0]]);
        rz += f64::from(frame[[right, 2]] - frame[[left, 2]]);
    }
    // forward = up × right = (rz, 0, −rx)
    let (fx, fz) = (rz, -rx);
    fx.atan2(fz) as f32
}

/// `a` wrapped to (−π, π].
pub(crate) fn wrap(a: f64) -> f64 {
    let two_pi = std::f64::consts::TAU;
    let mut a = a % two_pi;
    if a > std::f64::consts::PI {
        a -= two_pi;
    } else if a <= -std::f64::consts::PI {
        a += two_pi;
    }
    a
}

/// Rotates `(x, z)` about y by `theta`: `R_y(θ)` applied to `(x, 0, z)`.
fn rot_y(theta: f64, x: f64, z: f64) -> (f64, f64) {
    let (s, c) = theta.sin_cos();
    (c * x + s * z, -s * x + c * z)
}

fn check_positions(positions: ArrayView3<'_, f32>) -> Result<usize, MotionError> {
    let sh = positions.shape();
    if sh[1] != NUM_JOINTS || sh[2] != 3 {
        return Err(MotionError::Shape(format!(
            "positions {sh:?}, expected [T, {NUM_JOINTS}, 3]"
        )));
    }
    Ok(sh[0])
}

/// Pose features `[T, FEATURE_DIM]` of world positions `[T, 23, 3]` around root track `[T, 3]`,
/// and where the root started.
pub fn to_features(
    positions: ArrayView3<'_, f32>,
    root: ArrayView2<'_, f32>,
) -> Result<(Array2<f32>, RootStart), MotionError> {
    let t_len = check_positions(positions)?;
    if root.shape() != [t_len, 3] {
        return Err(MotionError::Shape(format!(
            "root {:?}, expected [{t_len}, 3]",
            root.shape()
        )));
    }
    let mut out = Array2::zeros((t_len, FEATURE_DIM));
    let yaws: Vec<f64> = positions
        .outer_iter()
        .map(|f| f64::from(facing_yaw(f)))
        .collect();
    for t in 0..t_len {
        let yaw = yaws[t];
        let (rx, ry, rz) = (
            f64::from(root[[t, 0]]),
            f64::from(root[[t, 1]]),
            f64::from(root[[t, 2]]),
        );
        for j in 0..NUM_JOINTS {
            let dx = f64::from(positions[[t, j, 0]]) - rx;
            let dy = f64::from(positions[[t, j, 1]]) - ry;
            let dz = f64::from(positions[[t, j, 2]]) - rz;
            let (lx, lz) = rot_y(-yaw, dx, dz);
            out[[t, 3 * j]] = lx as f32;
            out[[t, 3 * j + 1]] = dy as f32;
            out[[t, 3 * j + 2]] = lz as f32;
        }
        out[[t, ROOT_Y]] = ry as f32;
        if t > 0 {
            let dx = rx - f64::from(root[[t - 1, 0]]);
            let dz = rz - f64::from(root[[t - 1, 2]]);
            let (vx, vz) = rot_y(-yaws[t - 1], dx, dz);
            out[[t, ROOT_VX]] = vx as f32;
            out[[t, ROOT_VZ]] = vz as f32;
            out[[t, YAW_VEL]] = wrap(yaw - yaws[t - 1]) as f32;
        }
    }
    let start = match t_len {
        0 => RootStart::default(),
        _ => RootStart {
            x: root[[0, 0]],
            z: root[[0, 2]],
            yaw: yaws[0] as f32,
        },
    };
    Ok((out, start))
}

/// Inverse of [`to_features`]: world positions `[T, 23, 3]` and root track `[T, 3]`.
pub fn from_features(
    features: ArrayView2<'_, f32>,
    start: RootStart,
    fps: f64,
) -> Result<(Motion, Array2<f32>), MotionError> {
    if features.shape()[1] != FEATURE_DIM {
        return Err(MotionError::Shape(format!(
            "features {:?}, expected [T, {FEATURE_DIM}]",
            features.shape()
        )));
    }
    let t_len = features.shape()[0];
    let mut positions = Array3::zeros((t_len, NUM_JOINTS, 3));
    let mut root = Array2::zeros((t_len, 3));
    let (mut x, mut z, mut yaw) = (f64::from(start.x), f64::from(start.z), f64::from(start.yaw));
    for t in 0..t_len {
        let f = features.row(t);
        if t > 0 {
            let (dx, dz) = rot_y(yaw, f64::from(f[ROOT_VX]), f64::from(f[ROOT_VZ]));
            x += dx;
            z += dz;
            yaw += f64::from(f[YAW_VEL]);
        }
        let y = f64::from(f[ROOT_Y]);
        root[[t, 0]] = x as f32;
        root[[t, 1]] = y as f32;
        root[[t, 2]] = z as f32;
        for j in 0..NUM_JOINTS {
            let (wx, wz) = rot_y(yaw, f64::from(f[3 * j]), f64::from(f[3 * j + 2]));
            positions[[t, j, 0]] = (x + wx) as f32;
            positions[[t, j, 1]] = (y + f64::from(f[3 * j + 1])) as f32;
            positions[[t, j, 2]] = (z + wz) as f32;
        }
    }
    Ok((Motion { fps, positions }, root))
}

/// Foot-contact labels `[T, 4]` (1.0 = on the floor) for [`FOOT_POINTS`] (right heel, right toe,
/// left heel, left toe): within [`CONTACT_HEIGHT_M`] of that point's floor level (its 5th
/// percentile height in the motion) and slower than [`CONTACT_SPEED_M_S`] (central difference).
pub fn foot_contacts(positions: ArrayView3<'_, f32>, fps: f64) -> Result<Array2<f32>, MotionError> {
    let t_len = check_positions(positions)?;
    let mut out = Array2::zeros((t_len, FOOT_POINTS.len()));
    if t_len == 0 {
        return Ok(out);
    }
    for (k, &j) in FOOT_POINTS.iter().enumerate() {
        let heights: Vec<f32> = positions.slice(s![.., j, 1]).to_vec();
        let floor = percentile(&heights, FLOOR_PERCENTILE);
        for t in 0..t_len {
            let (a, b) = (t.saturating_sub(1), (t + 1).min(t_len - 1));
            let span = (b - a).max(1) as f64 / fps;
            let mut d2 = 0.0f64;
            for c in 0..3 {
                let d = f64::from(positions[[b, j, c]] - positions[[a, j, c]]);
                d2 += d * d;
            }
            let speed = (d2.sqrt() / span) as f32;
            let low = heights[t] - floor < CONTACT_HEIGHT_M;
            out[[t, k]] = if low && speed < CONTACT_SPEED_M_S {
                1.0
            } else {
                0.0
            };
        }
    }
    Ok(out)
}

/// Linear-interpolated percentile `p` (0–100) of `values` (not empty).
pub(crate) fn percentile(values: &[f32], p: f64) -> f32 {
    let mut v: Vec<f32> = values.to_vec();
    v.sort_by(|a, b| a.total_cmp(b));
    if v.is_empty() {
        return f32::NAN;
    }
    let pos = (p / 100.0).clamp(0.0, 1.0) * (v.len() - 1) as f64;
    let lo = pos.floor() as usize;
    let hi = pos.ceil() as usize;
    let w = (pos - lo as f64) as f32;
    v[lo] * (1.0 - w) + v[hi] * w
}

/// Height of the lowest foot point ([`FOOT_POINTS`]) relative to the root, from one feature row's
/// local pose (metres; negative: the feet are below the body centre).
pub fn lowest_foot_local_y(row: ndarray::ArrayView1<'_, f32>) -> f32 {
    FOOT_POINTS
        .iter()
        .map(|&j| row[3 * j + 1])
        .fold(f32::INFINITY, f32::min)
}

/// Replaces the root height (column [`ROOT_Y`]) by the lowest foot's clearance above `floor`
/// (metres), in place. A model that predicts clearance instead of an absolute height cannot put the
/// dancer in the air or under the floor by getting the height wrong while the legs are right: the
/// height follows from the legs ([`clearance_to_height`]).
pub fn height_to_clearance(features: &mut Array2<f32>, floor: f32) {
    for mut row in features.rows_mut() {
        let low = lowest_foot_local_y(row.view());
        row[ROOT_Y] += low - floor;
    }
}

/// Inverse of [`height_to_clearance`] with the floor at `y = 0`; a clearance below 0 (a foot under
/// the floor) is raised to 0.
pub fn clearance_to_height(features: &mut Array2<f32>) {
    for mut row in features.rows_mut() {
        let low = lowest_foot_local_y(row.view());
        row[ROOT_Y] = row[ROOT_Y].max(0.0) - low;
    }
}

/// The floor of a dance in feature form: the 1st percentile of the lowest foot's world height
/// (the floor foot planting and the metrics use, `motion::feet::FLOOR_PERCENTILE`).
pub fn floor_of_features(features: ndarray::ArrayView2<'_, f32>) -> f32 {
    let lows: Vec<f32> = features
        .rows()
        .into_iter()
        .map(|r| r[ROOT_Y] + lowest_foot_local_y(r))
        .collect();
    percentile(&lows, super::feet::FLOOR_PERCENTILE)
}

/// End-effector positions `[T, 5, 3]`: right wrist, left wrist, right toe, left toe, and the
/// head (midpoint of the two head markers).
pub fn end_effectors(positions: ArrayView3<'_, f32>) -> Result<Array3<f32>, MotionError> {
    use super::skeleton::{HEAD, TOES, WRISTS};
    let t_len = check_positions(positions)?;
    let mut out = Array3::zeros((t_len, 5, 3));
    for t in 0..t_len {
        for (k, j) in [WRISTS[0], WRISTS[1], TOES[0], TOES[1]]
            .into_iter()
            .enumerate()
        {
            for c in 0..3 {
                out[[t, k, c]] = positions[[t, j, c]];
            }
        }
        for c in 0..3 {
            out[[t, 4, c]] = 0.5 * (positions[[t, HEAD[0], c]] + positions[[t, HEAD[1], c]]);
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A synthetic walker: a fixed pose turning and translating.
    fn walker(t_len: usize) -> (Array3<f32>, Array2<f32>) {
        let mut pos = Array3::zeros((t_len, NUM_JOINTS, 3));
        let mut root = Array2::zeros((t_len, 3));
        for t in 0..t_len {
            let yaw = 0.05 * t as f64 + 3.0; // crosses ±π
            let (cx, cz) = (0.02 * t as f64, -0.01 * t as f64);
            root[[t, 0]] = cx as f32;
            root[[t, 1]] = 1.0;
            root[[t, 2]] = cz as f32;
            for j in 0..NUM_JOINTS {
                // Right-side joints at −x... in the body frame the right is −x when facing +z.
                let side = if super::super::skeleton::JOINT_NAMES[j].starts_with("right") {
                    -0.2
                } else if super::super::skeleton::JOINT_NAMES[j].starts_with("left") {
                    0.2
                } else {
                    0.0
                };
                let local = (side, 0.3 - 0.04 * j as f64, 0.01 * (j % 3) as f64);
                let (wx, wz) = rot_y(yaw, local.0, local.2);
                pos[[t, j, 0]] = (cx + wx) as f32;
                pos[[t, j, 1]] = (1.0 + local.1) as f32;
                pos[[t, j, 2]] = (cz + wz) as f32;
            }
        }
        (pos, root)
    }

    #[test]
    fn facing_yaw_of_a_body_facing_plus_z_is_zero() {
        let (pos, _) = walker(1);
        // walker frame 0 has yaw 3.0
        let y = facing_yaw(pos.index_axis(ndarray::Axis(0), 0));
        assert!((wrap(f64::from(y) - 3.0)).abs() < 1e-5, "yaw {y}");
    }

    #[test]
    fn features_invert_exactly() {
        let (pos, root) = walker(200);
        let (f, start) = to_features(pos.view(), root.view()).expect("features");
        assert_eq!(f.shape(), &[200, FEATURE_DIM]);
        let (m, root2) = from_features(f.view(), start, 25.0).expect("inverse");
        let err = (&m.positions - &pos)
            .mapv(f32::abs)
            .fold(0.0f32, |a, &b| a.max(b));
        assert!(err < 1e-5, "max error {err}");
        let rerr = (&root2 - &root)
            .mapv(f32::abs)
            .fold(0.0f32, |a, &b| a.max(b));
        assert!(rerr < 1e-5);
        // Local pose is heading invariant: every frame of the walker has the same local pose.
        let d = (&f.slice(s![0, ..POSE_DIM]) - &f.slice(s![150, ..POSE_DIM]))
            .mapv(f32::abs)
            .fold(0.0f32, |a, &b| a.max(b));
        assert!(d < 1e-5);
    }

    #[test]
    fn clearance_round_trips_and_grounds() {
        let (pos, root) = walker(20);
        let (f, _) = to_features(pos.view(), root.view()).expect("features");
        let floor = floor_of_features(f.view());
        let mut g = f.clone();
        height_to_clearance(&mut g, floor);
        // The walker's lowest foot is at the same height on every frame: clearance 0 there.
        assert!(g.column(ROOT_Y).iter().all(|v| v.abs() < 1e-5));
        clearance_to_height(&mut g);
        // With the floor moved to 0, the lowest foot now stands exactly on it.
        for t in 0..20 {
            assert!((g[[t, ROOT_Y]] + lowest_foot_local_y(g.row(t))).abs() < 1e-5);
            assert!((g[[t, ROOT_Y]] - (f[[t, ROOT_Y]] - floor)).abs() < 1e-5);
        }
        // A foot predicted under the floor is raised onto it.
        let mut h = g.clone();
        h[[3, ROOT_Y]] = -0.3;
        clearance_to_height(&mut h);
        assert!((h[[3, ROOT_Y]] + lowest_foot_local_y(h.row(3))).abs() < 1e-6);
    }

    #[test]
    fn contacts_need_low_and_slow_feet() {
        let t_len = 50;
        let mut pos = Array3::zeros((t_len, NUM_JOINTS, 3));
        for t in 0..t_len {
            // right toe lifts and moves after frame 25; left foot stays planted
            let lift = if t >= 25 { 0.2 } else { 0.0 };
            pos[[t, 11, 1]] = lift;
            pos[[t, 11, 0]] = if t >= 25 { 0.05 * t as f32 } else { 0.0 };
        }
        let c = foot_contacts(pos.view(), 25.0).expect("contacts");
        assert_eq!(c[[10, 1]], 1.0);
        assert_eq!(c[[40, 1]], 0.0);
        assert_eq!(c[[40, 3]], 1.0);
    }
}
