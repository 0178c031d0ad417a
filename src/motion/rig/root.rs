//! The root's rotation: the body's facing yaw, tilted onto the spine, carried over from the
//! previous frame where the facing is ill-determined.
use nalgebra::{UnitQuaternion, Vector3};
use ndarray::ArrayView2;

use super::{arc, rig_index, Rig};
use crate::motion::skeleton::{HIPS, SHOULDERS, SPINE};

/// The previous frame's facing counts as a body this wide (metres, hips plus shoulders) facing
/// that way. A body faces along `up × (right − left)` of its hips and shoulders, about 65 cm wide
/// in the data; where a generated pose folds them onto each other the yaw swings freely and the
/// carried yaw holds it.
pub const YAW_CARRY_M: f64 = 0.05;

/// The facing direction `(x, z)` of a `[23, 3]` frame as [`crate::motion::repr::facing_yaw`]
/// takes it (`yaw = atan2(x, z)`), unnormalised: its length is the width the yaw rests on.
fn facing(frame: ArrayView2<'_, f32>) -> (f64, f64) {
    let (mut rx, mut rz) = (0.0, 0.0);
    for [right, left] in [HIPS, SHOULDERS] {
        rx += f64::from(frame[[right, 0]] - frame[[left, 0]]);
        rz += f64::from(frame[[right, 2]] - frame[[left, 2]]);
    }
    // forward = up × right
    (rz, -rx)
}

/// The root's rotation and its yaw (radians): the facing yaw of the 23-joint `frame`, pulled
/// towards `carried_yaw` (the previous frame's, none on the first), tilted by the shortest arc
/// that turns the spine's rest offset towards the spine's target as seen from the root's
/// (`target`, rig-indexed). The tilt keeps the root where the body centre track puts it as the
/// body leans; the yaw settles the turn about the spine's offset, which the spine's and the
/// pelvis's offsets (the root's two children, in one direction) leave free.
pub(super) fn root_rotation(
    rig: &Rig,
    frame: ArrayView2<'_, f32>,
    target: &[Vector3<f64>],
    carried_yaw: Option<f64>,
) -> (UnitQuaternion<f64>, f64) {
    let (mut x, mut z) = facing(frame);
    if let Some(c) = carried_yaw {
        x += YAW_CARRY_M * c.sin();
        z += YAW_CARRY_M * c.cos();
    }
    let yaw_angle = if x == 0.0 && z == 0.0 {
        carried_yaw.unwrap_or(0.0)
    } else {
        x.atan2(z)
    };
    let yaw = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), yaw_angle);
    let spine = rig_index(SPINE);
    let (rest, data) = (yaw * rig.offsets[spine], target[spine] - target[0]);
    if rest.norm() < 1e-9 || data.norm() < 1e-9 {
        return (yaw, yaw_angle);
    }
    (arc(&rest, &data) * yaw, yaw_angle)
}
