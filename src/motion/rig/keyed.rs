//! Served dances with key poses: every frame aimed along the dance's bones, each key frame posed
//! in least squares (for the mean joint distance where the squared one leaves it off), and the
//! key's correction faded out around it.
use nalgebra::{UnitQuaternion, Vector3};
use ndarray::{ArrayView2, ArrayView3};

use super::chain::{solve, solve_aimed, Aim};
use super::continuity::{is_motion, limit_turn, max_turn};
use super::least_squares::{
    centred_mean_distance, fit_frame_weighted, inverse_distance_weights, position_error,
    REWEIGHT_FROM_M, ROTATION_PRIOR_M,
};
use super::{fit_frame, targets, Rig, RigMotion};
use crate::motion::MotionError;

/// Seconds either side of a key pose over which [`solve_keyed`] fades its correction out. Longer
/// bends more frames (1 s: a captured dance with four of its own poses as keys lost 0.03
/// authenticity, at 0.5 s 0.02); shorter accelerates more (0.25 s: 16.7 m/s² near a key of
/// DANCE_R_9, whose own is 12.8; at 0.5 s 14.3).
pub const KEY_REACH_S: f64 = 0.5;

/// Inverse kinematics for a served dance with key poses: every frame aimed along the dance's
/// bones ([`solve_aimed`] with `aim`), and each key frame posed in least squares ([`fit_frame`],
/// from whichever chain pose, aimed along the bones or from the fitted ends, fits closer). The key's
/// correction (each joint's turn from the chain's pose to the fitted one, and the root's move) is
/// faded out over [`KEY_REACH_S`] either side (a smoothstep), from one key's to the next's where
/// they are closer.
///
/// Why: the least squares land a key pose as closely as one rigid skeleton can (its bone lengths
/// are the key poses'), but on every other frame they bend the angles between bones to make up
/// whatever bone lengths the dance drew, which is what a dance is judged real by: served over every
/// frame, keypose-transformer's dances with 4 key poses lost authenticity 0.914 → 0.600 (test
/// split), and a real dance with four of its own poses as keys 0.854 → 0.632. Only the key frames
/// need to land; blending the whole least-squares pose in around them (rather than the key's
/// correction) still cost arms that change length 0.03 more.
pub fn solve_keyed(
    rig: &Rig,
    positions: ArrayView3<'_, f32>,
    root: ArrayView2<'_, f32>,
    fps: f64,
    keys: &[usize],
    aim: Aim,
) -> Result<RigMotion, MotionError> {
    let tg = targets(positions, root)?;
    let chain = solve_aimed(rig, positions, root, fps, aim)?;
    let mut keys: Vec<usize> = keys.iter().copied().filter(|&k| k < tg.len()).collect();
    keys.sort_unstable();
    keys.dedup();
    // Each key's correction: the local turn from the chain's pose to the fitted one, per joint,
    // and the root's move.
    let mut ends = None;
    let corrections: Vec<(Vector3<f64>, Vec<UnitQuaternion<f64>>)> = keys
        .iter()
        .map(|&k| {
            let (chain_root, chain_local) = (&chain.root_translation[k], &chain.rotations[k]);
            let mut fit = fit_frame(rig, chain_root, chain_local, &tg[k]);
            if aim != Aim::FittedEnds {
                // The least squares find a local best; from the fitted ends' pose (where the
                // least squares on every frame started) it was up to 1 cm closer on some keys.
                let ends = match &ends {
                    Some(e) => e,
                    None => ends.insert(solve(rig, positions, root, fps)?),
                };
                let other = fit_frame(rig, &ends.root_translation[k], &ends.rotations[k], &tg[k]);
                if position_error(rig, &other.0, &other.1, &tg[k])
                    < position_error(rig, &fit.0, &fit.1, &tg[k])
                {
                    fit = other;
                }
            }
            let fit = fit_key_frame(rig, fit, &tg[k]);
            let turns = chain_local
                .iter()
                .zip(&fit.1)
                .map(|(c, f)| c.inverse() * f)
                .collect();
            Ok((fit.0 - chain_root, turns))
        })
        .collect::<Result<_, MotionError>>()?;
    // Unrelated poses (fps no number): only the key frames themselves.
    let reach = if is_motion(fps) {
        KEY_REACH_S * fps
    } else {
        0.0
    };
    let fade = |d: f64, span: f64| -> f64 {
        if d <= 0.0 {
            1.0
        } else if d >= span {
            0.0
        } else {
            let x = 1.0 - d / span;
            x * x * (3.0 - 2.0 * x)
        }
    };
    let max = max_turn(fps);
    let mut root_translation = Vec::with_capacity(tg.len());
    let mut rotations: Vec<Vec<UnitQuaternion<f64>>> = Vec::with_capacity(tg.len());
    for t in 0..tg.len() {
        let (chain_root, chain_local) = (chain.root_translation[t], &chain.rotations[t]);
        // The keys on either side, each faded over the reach or the gap between them, whichever
        // is shorter, so a key frame carries its own correction and no other.
        let after = keys.partition_point(|&k| k < t);
        let before = after.checked_sub(1).filter(|&i| keys[i] <= t);
        let next = (after < keys.len()).then_some(after);
        let gap = match (before, next) {
            (Some(a), Some(b)) => (keys[b] - keys[a]) as f64,
            _ => f64::INFINITY,
        };
        let span = reach.min(gap);
        let w_before = before.map_or(0.0, |a| fade((t - keys[a]) as f64, span));
        let w_next = next.map_or(0.0, |b| fade((keys[b] - t) as f64, span));
        let amount = w_before.max(w_next);
        if amount <= 0.0 {
            root_translation.push(chain_root);
            rotations.push(chain_local.clone());
            continue;
        }
        let towards_next = w_next / (w_before + w_next);
        let (root_move, turns): (Vector3<f64>, Vec<UnitQuaternion<f64>>) = match (before, next) {
            (Some(a), Some(b)) if w_before > 0.0 && w_next > 0.0 => {
                let ((ra, ta), (rb, tb)) = (&corrections[a], &corrections[b]);
                (
                    ra + (rb - ra) * towards_next,
                    ta.iter()
                        .zip(tb)
                        .map(|(x, y)| x.slerp(y, towards_next))
                        .collect(),
                )
            }
            (Some(a), _) if w_before > 0.0 => corrections[a].clone(),
            (_, Some(b)) => corrections[b].clone(),
            _ => unreachable!("a key within reach"),
        };
        let id = UnitQuaternion::identity();
        let posed = chain_local
            .iter()
            .zip(&turns)
            .map(|(c, d)| c * id.slerp(d, amount));
        let posed: Vec<_> = match rotations.last() {
            Some(prev) => prev
                .iter()
                .zip(posed)
                .map(|(p, b)| limit_turn(*p, b, max))
                .collect(),
            None => posed.collect(),
        };
        root_translation.push(chain_root + root_move * amount);
        rotations.push(posed);
    }
    Ok(RigMotion {
        rig: rig.clone(),
        fps,
        root_translation,
        rotations,
    })
}

/// Rounds of [`fit_key_frame`]'s reweighting: 24 moved no key of the test dances' own poses
/// further than 8 did.
const KEY_REWEIGHT_ROUNDS: usize = 8;

/// A key frame fitted for the mean joint distance (what a key's error is, and what a user sees)
/// rather than the squared one: [`fit_frame`]'s least-squares pose refined by iteratively
/// reweighted least squares, each joint weighted by the inverse of its distance (Weiszfeld's
/// step), keeping the pose with the smallest mean distance about the joints' centroid (as
/// `metrics::kinematics::key_pose_errors_cm` measures it). Squared distances let one joint the
/// rigid skeleton cannot reach (a captured arm of another length) pull every other joint off its
/// target; the mean distance leaves it off and lands the rest.
fn fit_key_frame(
    rig: &Rig,
    fit: (Vector3<f64>, Vec<UnitQuaternion<f64>>),
    target: &[Vector3<f64>],
) -> (Vector3<f64>, Vec<UnitQuaternion<f64>>) {
    let centred_mean = |pose: &(Vector3<f64>, Vec<UnitQuaternion<f64>>)| -> f64 {
        centred_mean_distance(rig, &pose.0, &pose.1, target)
    };
    let mut best_error = centred_mean(&fit);
    if best_error < REWEIGHT_FROM_M {
        return fit;
    }
    let mut best = fit.clone();
    let mut pose = fit;
    for _ in 0..KEY_REWEIGHT_ROUNDS {
        let weights = inverse_distance_weights(rig, &pose.0, &pose.1, target);
        pose = fit_frame_weighted(rig, &pose.0, &pose.1, target, ROTATION_PRIOR_M, &weights);
        let error = centred_mean(&pose);
        if error < best_error {
            (best, best_error) = (pose.clone(), error);
        }
    }
    best
}
