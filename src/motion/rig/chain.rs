//! Chain inverse kinematics: each joint solved from its parent's fitted end (shortest arc and
//! twist for one child, Wahba's problem for several), the root turned with the body.
use nalgebra::{Unit, UnitQuaternion, Vector3};
use ndarray::{ArrayView2, ArrayView3, Axis};

use super::{arc, fk_frame, rig_index, targets, wahba, Rig, RigMotion};
use crate::motion::repr::facing_yaw;
use crate::motion::{skeleton, MotionError};

/// Inverse kinematics: local rotations of `rig` that follow `positions` around `root`.
pub fn solve(
    rig: &Rig,
    positions: ArrayView3<'_, f32>,
    root: ArrayView2<'_, f32>,
    fps: f64,
) -> Result<RigMotion, MotionError> {
    let tg = targets(positions, root)?;
    let n = rig.names.len();
    let children: Vec<Vec<usize>> = (0..n).map(|j| rig.children(j)).collect();
    let order = rig.order();
    // Twist references of single-child joints: descendants two and three levels down.
    let twist_refs: Vec<Vec<usize>> = (0..n)
        .map(|j| {
            let mut refs = Vec::new();
            for &c in &children[j] {
                for &g in &children[c] {
                    refs.push(g);
                    refs.extend(children[g].iter().copied());
                }
            }
            refs
        })
        .collect();
    // Rest position of every joint relative to its ancestors (identity rotations).
    let rest_rel = |from: usize, to: usize| -> Vector3<f64> {
        let mut v = Vector3::zeros();
        let mut k = to;
        while k != from {
            v += rig.offsets[k];
            match rig.parents[k] {
                Some(p) => k = p,
                None => break,
            }
        }
        v
    };
    let mut rotations = Vec::with_capacity(tg.len());
    let mut root_translation = Vec::with_capacity(tg.len());
    for frame in &tg {
        let mut pos = vec![Vector3::zeros(); n];
        let mut world = vec![UnitQuaternion::identity(); n];
        let mut local = vec![UnitQuaternion::identity(); n];
        for &j in &order {
            let parent_world = rig.parents[j].map_or(UnitQuaternion::identity(), |p| world[p]);
            pos[j] = match rig.parents[j] {
                None => frame[j],
                Some(p) => pos[p] + world[p] * rig.offsets[j],
            };
            let kids = &children[j];
            let w = match kids.len() {
                0 => parent_world,
                1 => {
                    let c = kids[0];
                    let rest_dir = parent_world * rig.offsets[c];
                    let target_dir = frame[c] - pos[j];
                    if target_dir.norm() < 1e-9 || rest_dir.norm() < 1e-9 {
                        parent_world
                    } else {
                        let swing = arc(&rest_dir, &target_dir) * parent_world;
                        twist(swing, &target_dir, &pos[j], frame, &twist_refs[j], |g| {
                            rest_rel(j, g)
                        })
                    }
                }
                _ => {
                    let rest: Vec<Vector3<f64>> = kids.iter().map(|&c| rig.offsets[c]).collect();
                    let target: Vec<Vector3<f64>> = kids.iter().map(|&c| frame[c] - pos[j]).collect();
                    wahba(&rest, &target).unwrap_or(parent_world)
                }
            };
            world[j] = w;
            local[j] = parent_world.inverse() * w;
        }
        root_translation.push(frame[0]);
        // The root's children (spine and pelvis) share one rest direction, so the best fit above
        // leaves the root free to turn about it, and it did: 90° (median) from one frame to the
        // next, the children turning back. Positions do not show it; a tool that interpolates
        // between frames would spin the torso. The facing yaw tilted onto the spine fixes the
        // turn; every world position and every other local rotation stays.
        let t = rotations.len();
        rotations.push(rerooted(rig, root_rotation(rig, positions.index_axis(Axis(0), t), frame), &local));
    }
    Ok(RigMotion {
        rig: rig.clone(),
        fps,
        root_translation,
        rotations,
    })
}

/// Adds the twist about `axis` to `swing` that brings the references closest to their targets.
fn twist(
    swing: UnitQuaternion<f64>,
    axis: &Vector3<f64>,
    origin: &Vector3<f64>,
    frame: &[Vector3<f64>],
    refs: &[usize],
    rest_rel: impl Fn(usize) -> Vector3<f64>,
) -> UnitQuaternion<f64> {
    let a = axis.normalize();
    let (mut sin_sum, mut cos_sum) = (0.0, 0.0);
    for &g in refs {
        let have = swing * rest_rel(g);
        let want = frame[g] - origin;
        let have_p = have - a * have.dot(&a);
        let want_p = want - a * want.dot(&a);
        // Unnormalised: a reference far off the axis has a well-defined angle and counts more.
        sin_sum += have_p.cross(&want_p).dot(&a);
        cos_sum += have_p.dot(&want_p);
    }
    if sin_sum == 0.0 && cos_sum == 0.0 {
        return swing;
    }
    let angle = sin_sum.atan2(cos_sum);
    UnitQuaternion::from_axis_angle(&Unit::new_unchecked(a), angle) * swing
}

/// The root's rotation for the least-squares IK: the facing yaw of the 23-joint `frame`, tilted
/// by the shortest arc that turns the spine's rest offset towards the spine's target as seen from
/// the root's (`target`, rig-indexed). The tilt keeps the root where the body centre track puts
/// it as the body leans; the yaw settles the turn about the spine's offset, which the spine's and
/// the pelvis's offsets (the root's two children, in one direction) leave free.
pub(super) fn root_rotation(rig: &Rig, frame: ArrayView2<'_, f32>, target: &[Vector3<f64>]) -> UnitQuaternion<f64> {
    let yaw = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), f64::from(facing_yaw(frame)));
    let spine = rig_index(skeleton::SPINE);
    let (rest, data) = (yaw * rig.offsets[spine], target[spine] - target[0]);
    if rest.norm() < 1e-9 || data.norm() < 1e-9 {
        return yaw;
    }
    arc(&rest, &data) * yaw
}

/// The same pose with the root's rotation replaced by `root_rot`: the root's children take the
/// difference, so every world position and every other local rotation stays.
pub(super) fn rerooted(rig: &Rig, root_rot: UnitQuaternion<f64>, local: &[UnitQuaternion<f64>]) -> Vec<UnitQuaternion<f64>> {
    let (_, world) = fk_frame(rig, &Vector3::zeros(), local);
    let mut out = local.to_vec();
    for (j, p) in rig.parents.iter().enumerate() {
        match p {
            None => out[j] = root_rot,
            Some(p) if rig.parents[*p].is_none() => out[j] = root_rot.inverse() * world[j],
            Some(_) => {}
        }
    }
    out
}
