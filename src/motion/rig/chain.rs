//! Chain inverse kinematics: each bone turned onto its child's target, from the joint's fitted
//! position or along the dance's own bone ([`Aim`]; shortest arc and twist for one child, Wahba's
//! problem for several), the root turned with the body, every joint's twist carried from the previous frame
//! where the data leaves it free and no joint turning further in a frame than a body does
//! ([`super::continuity`]).
//!
//! # Why the dance's bones, not the fitted joint's reach
//! The angle between two bones is what a dance is judged real by
//! ([`crate::metrics::plausibility`]), and a rigid skeleton that turns every bone onto the
//! dance's own direction keeps every such angle whatever its bone lengths. Each bone used to be
//! aimed from its joint's *fitted* position at the child's target instead, so a joint the fixed
//! (median) lengths put elsewhere bent the next bone to make up the distance. Networks do not
//! keep bone lengths: dance-revolution's upper arm measures 8–47 cm over hungarian_dance_5 (seed
//! 0, sd 8.5 cm), so the elbow sat 7 cm (median) off and the 13-cm elbow → forearm bone swung 28°
//! (median, 82° p90) to reach its target: the forearm's angle went outside the real limits on
//! 44 % of frames (2 % as drawn), its angular velocity on 59 % of steps (10 %), and authenticity
//! 0.74 → 0.32, coherence 0.78 → 0.30. The head (spine → head_left → head_right, 6.5° median,
//! from the spine's fitted position) lost keypose-transformer 13 % of frames on trumpet_loop.
//! Aimed along the dance's bones, those angles change by 0.0° and the worst loss over 5 models ×
//! 2 songs × 2 seeds is 0.017 authenticity, 0.015 coherence (tsmt); what is left comes from the
//! joints whose children one rigid body part carries together (spine → shoulders, pelvis → hips,
//! ankle → heel and toe: about 1° median).
//!
//! The price is position: a bone drawn longer or shorter than the rig's moves the joints below
//! it by the difference, down the chain, rather than being absorbed by the next bone's direction.
//! On the 43 captured dances around their own body centre that took the per-dance mean error from
//! under 3 cm (p95) to 4.8 cm and the BVH 3.2 cm from the data on average, so a captured dance,
//! whose positions are the truth, keeps [`Aim::FittedEnds`]; a served dance, whose network drew
//! its bones at whatever length, is aimed along its bones ([`Aim::DanceBones`]).
use nalgebra::{UnitQuaternion, Vector3};
use ndarray::{ArrayView2, ArrayView3, Axis};

use super::continuity::{is_motion, limit_turn, max_turn, twist, wahba_carried};
use super::root::root_rotation;
use super::{arc, targets, Rig, RigMotion};
use crate::motion::{skeleton, MotionError, NUM_JOINTS};

/// Where each bone of the chain IK points from (see the module doc).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Aim {
    /// From the joint's fitted position to its child's target: the joints land closest to their
    /// targets, the angles between bones bent by whatever the bone lengths leave over.
    FittedEnds,
    /// Along the dance's own bone, from the joint's target to its child's: the angles between
    /// bones are the dance's, the joints off by the bone lengths' differences down the chain.
    DanceBones,
}

/// Inverse kinematics: local rotations of `rig` that follow `positions` around `root`, frame
/// after frame: each frame's twists start from the previous frame's and no joint turns faster
/// than a body does at `fps`, so the frames are a motion (with `fps` no number they are unrelated
/// poses, each solved on its own). Each bone aimed from its joint's fitted end
/// ([`Aim::FittedEnds`]); [`solve_aimed`] chooses.
pub fn solve(
    rig: &Rig,
    positions: ArrayView3<'_, f32>,
    root: ArrayView2<'_, f32>,
    fps: f64,
) -> Result<RigMotion, MotionError> {
    solve_aimed(rig, positions, root, fps, Aim::FittedEnds)
}

/// [`solve`] with each bone aimed as `aim` says.
pub fn solve_aimed(
    rig: &Rig,
    positions: ArrayView3<'_, f32>,
    root: ArrayView2<'_, f32>,
    fps: f64,
    aim: Aim,
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
    // The children each joint's rotation aims at along the dance's bones. A joint whose children
    // are one body joint and
    // hand-direction markers (the left elbow: its forearm and the left hand's marker) aims its
    // bone exactly at the body joint, the markers only choosing the twist: a best fit over both
    // bent the forearm off the dance's own by 1° (median) and moved the elbow's angle out of
    // the real limits on frames the dance had it inside.
    let is_marker =
        |k: usize| (1..=NUM_JOINTS).contains(&k) && !skeleton::ANATOMICAL.contains(&(k - 1));
    let aimed: Vec<Vec<usize>> = children
        .iter()
        .map(|kids| {
            let body: Vec<usize> = kids.iter().copied().filter(|&c| !is_marker(c)).collect();
            if body.len() == 1 {
                body
            } else {
                kids.clone()
            }
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
            let (kids, origin) = match aim {
                Aim::FittedEnds => (&children[j], pos[j]),
                Aim::DanceBones => (&aimed[j], frame[j]),
            };
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
                    let target_dir = frame[c] - origin;
                    if target_dir.norm() < 1e-9 || rest_dir.norm() < 1e-9 {
                        carried.unwrap_or(parent_world)
                    } else {
                        let swing = arc(&rest_dir, &target_dir) * parent_world;
                        let markers = children[j].iter().filter(|&&m| m != c);
                        let refs = twist_refs[j]
                            .iter()
                            .chain(markers)
                            .map(|&g| (swing * rest_rel(j, g), frame[g] - origin));
                        twist(swing, &target_dir, refs, carried)
                    }
                }
                (Some(_), _) => {
                    let rest: Vec<Vector3<f64>> = kids.iter().map(|&c| rig.offsets[c]).collect();
                    let target: Vec<Vector3<f64>> =
                        kids.iter().map(|&c| frame[c] - origin).collect();
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
