//! Chain inverse kinematics: each joint solved from its parent's fitted end (shortest arc and
//! twist for one child, Wahba's problem for several), the root turned with the body, every
//! joint's twist carried from the previous frame where the data leaves it free and no joint turning
//! further in a frame than a body does ([`super::continuity`]).
use nalgebra::{UnitQuaternion, Vector3};
use ndarray::{ArrayView2, ArrayView3, Axis};

use super::continuity::{is_motion, limit_turn, max_turn, twist, wahba_carried};
use super::root::root_rotation;
use super::{arc, targets, Rig, RigMotion};
use crate::motion::MotionError;

/// Inverse kinematics: local rotations of `rig` that follow `positions` around `root`, frame
/// after frame: each frame's twists start from the previous frame's and no joint turns faster
/// than a body does at `fps`, so the frames are a motion (with `fps` no number they are unrelated
/// poses, each solved on its own).
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
    let mut rotations: Vec<Vec<UnitQuaternion<f64>>> = Vec::with_capacity(tg.len());
    let mut root_translation = Vec::with_capacity(tg.len());
    let mut carried_yaw = None;
    let max = max_turn(fps);
    for (t, frame) in tg.iter().enumerate() {
        let mut pos = vec![Vector3::zeros(); n];
        let mut world = vec![UnitQuaternion::identity(); n];
        let mut local = vec![UnitQuaternion::identity(); n];
        for &j in &order {
            let parent_world = rig.parents[j].map_or(UnitQuaternion::identity(), |p| world[p]);
            pos[j] = match rig.parents[j] {
                None => frame[j],
                Some(p) => pos[p] + world[p] * rig.offsets[j],
            };
            // The previous frame's local rotation on this frame's parent: what the twist is
            // carried from.
            let carried = rotations
                .last()
                .filter(|_| is_motion(fps))
                .map(|prev| parent_world * prev[j]);
            let kids = &children[j];
            let w = match (rig.parents[j], kids.len()) {
                // The root's children (spine and pelvis) share one rest direction, so a best fit
                // leaves the root free to turn about it, and it did: 90° (median) from one frame
                // to the next, the children turning back. The facing yaw tilted onto the spine
                // settles the turn.
                (None, _) => {
                    let (r, yaw) =
                        root_rotation(rig, positions.index_axis(Axis(0), t), frame, carried_yaw);
                    carried_yaw = is_motion(fps).then_some(yaw);
                    r
                }
                (Some(_), 0) => parent_world,
                (Some(_), 1) => {
                    let c = kids[0];
                    let rest_dir = parent_world * rig.offsets[c];
                    let target_dir = frame[c] - pos[j];
                    if target_dir.norm() < 1e-9 || rest_dir.norm() < 1e-9 {
                        carried.unwrap_or(parent_world)
                    } else {
                        let swing = arc(&rest_dir, &target_dir) * parent_world;
                        let refs = twist_refs[j]
                            .iter()
                            .map(|&g| (swing * rest_rel(j, g), frame[g] - pos[j]));
                        twist(swing, &target_dir, refs, carried)
                    }
                }
                (Some(_), _) => {
                    let rest: Vec<Vector3<f64>> = kids.iter().map(|&c| rig.offsets[c]).collect();
                    let target: Vec<Vector3<f64>> =
                        kids.iter().map(|&c| frame[c] - pos[j]).collect();
                    wahba_carried(&rest, &target, carried).unwrap_or(parent_world)
                }
            };
            let w = match carried {
                Some(c) => limit_turn(c, w, max),
                None => w,
            };
            world[j] = w;
            local[j] = parent_world.inverse() * w;
        }
        root_translation.push(frame[0]);
        rotations.push(local);
    }
    Ok(RigMotion {
        rig: rig.clone(),
        fps,
        root_translation,
        rotations,
    })
}
