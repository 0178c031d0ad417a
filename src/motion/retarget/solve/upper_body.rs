//! The upper body's joints choreo has fewer of (steps 2 and 5 of the solver's doc): the torso's
//! turn spread over the target's spine bones, the head kept facing with the torso, the lower
//! arms' turn limited.
use nalgebra::{UnitQuaternion, Vector3};

use super::kinematics::limit_bone_turn;
use super::{Prepared, HEAD_TURN_KEPT_DEG};
use crate::motion::retarget::HumanBone;
use crate::motion::rig::{max_turn, twist_angle};

/// The lower arms' local rotations kept within [`max_turn`] of the previous frame's: by their
/// twist about the bone where that suffices, else by lagging the bone itself
/// ([`limit_bone_turn`]).
///
/// A target's lower arm is one joint where choreo has two (elbow and forearm, each turning at
/// most 55° a frame, [`max_turn`]), so it takes their composed turn: 70-73° in one frame on a
/// dancenet dance (most of it the forearm's twist), up to 87° on captured dances (DANCE_R_9,
/// DANCE_C_2: 0.1-0.2 % of steps). The twist is free (no position depends on it), so it is held
/// back and catches up over the next frames; the bone's direction alone turned past 55° on one
/// step of that dancenet dance (the data's own jumps on the captures), where the bone follows a
/// frame late.
pub(super) fn limit_lower_arms(p: &Prepared, rotations: &mut [Vec<UnitQuaternion<f64>>], fps: f64) {
    let max = max_turn(fps);
    for b in [HumanBone::LeftLowerArm, HumanBone::RightLowerArm] {
        let Some(&j) = p.bones.get(&b) else { continue };
        let Some(axis) = p.aims[j]
            .as_ref()
            .and_then(|a| nalgebra::Unit::try_new(a.rest_dir, 1e-9))
        else {
            continue;
        };
        for t in 1..rotations.len() {
            let prev = rotations[t - 1][j];
            rotations[t][j] = limit_bone_turn(&prev, &rotations[t][j], &axis, max);
        }
    }
}

/// Spreads the torso's turn from the hips over the target's spine bones (`spine`, hips first):
/// its twist about the spine (`axis`, the spine's rest direction from its first bone to the upper
/// arms) in equal shares, its bend on the first bone, so the last one (the chest the arms and
/// neck hang from) ends where the torso is. Choreo has one spine joint; on a rig with three,
/// putting its whole turn on the first bone left the other two at rest (SMPL's spine2 and spine3
/// always 0). The bend stays on the first bone: spread too, it curved the back and moved the
/// shoulders off the line choreo's spine points along (the hips' angle against the torso
/// 3-4° → 7-11° off motion.json's, median, on beat-graph and keypose-transformer dances).
pub(super) fn spread_torso(
    w: &mut [UnitQuaternion<f64>],
    hips: usize,
    spine: &[usize],
    torso: UnitQuaternion<f64>,
    axis: &Vector3<f64>,
) {
    let turn = w[hips].inverse() * torso;
    let Some(axis) = nalgebra::Unit::try_new(*axis, 1e-9) else {
        return;
    };
    // Swing-twist about the spine's own axis (the hips' frame is the rest frame at rest).
    let twist = twist_angle(&turn, &axis);
    let twist = twist - std::f64::consts::TAU * (twist / std::f64::consts::TAU).round();
    let k = spine.len() as f64;
    let share = UnitQuaternion::from_axis_angle(&axis, twist / k);
    let swing = turn * UnitQuaternion::from_axis_angle(&axis, -twist);
    let mut world = w[hips] * swing;
    for &j in spine {
        world *= share;
        w[j] = world;
    }
    if let Some(&last) = spine.last() {
        // Exactly the torso (the shares compose to the twist up to rounding).
        w[last] = torso;
    }
}

/// The head's twist about its own bone (`rest_dir`, the bone's rest direction), measured from
/// the torso, read as the line the two head markers make: taken modulo half a turn, kept as it is
/// up to [`HEAD_TURN_KEPT_DEG`] either way, and brought back to facing the torso beyond that.
///
/// The capture's two head markers swap labels: on each of the 30 waltzes 10-47 % of frames have
/// them reversed against the shoulders (more than 90° apart about the vertical; on the other 13
/// dances 0-0.1 %, 90 % of frames within 33-60°), and the models trained on them do it too.
/// Choreo's rig follows the markers, turning its head round at most 25° a frame; on a target the
/// head then faced backwards and the neck, halfway between, swung through 180° in one frame
/// where the twist crossed half a turn (the 0.8 % of frame steps past 60° on a beat-graph dance).
/// The markers' midpoint, and so the bone's direction, is the same either way round; only which
/// way the face points is not. Modulo half a turn the face is always forward, but jumps where the
/// line stands across the shoulders (±90°), as the choreo head turns through it; the tent beyond
/// `HEAD_TURN_KEPT_DEG` meets itself there (0° from either side), so the head's facing follows the
/// markers' line continuously, at most twice as fast as it turns.
pub(super) fn face_with_torso(
    head: &mut UnitQuaternion<f64>,
    torso: &UnitQuaternion<f64>,
    rest_dir: &Vector3<f64>,
) {
    use std::f64::consts::{FRAC_PI_2, PI};
    let Some(axis) = nalgebra::Unit::try_new(*rest_dir, 1e-9) else {
        return;
    };
    let rel = torso.inverse() * *head;
    // Swing-twist: the twist's angle about the bone's own (local) axis.
    let twist = twist_angle(&rel, &axis);
    // The marker line's angle, modulo half a turn, in (-90°, 90°].
    let line = twist - PI * (twist / PI).round();
    let kept = HEAD_TURN_KEPT_DEG.to_radians();
    let facing = if line.abs() <= kept {
        line
    } else {
        line.signum() * kept * (FRAC_PI_2 - line.abs()) / (FRAC_PI_2 - kept)
    };
    *head *= UnitQuaternion::from_axis_angle(&axis, facing - twist);
}
