//! Validation of motion users send: key poses and seed motions.
//!
//! [`super::input`] turns what the API and the CLI accept (either joint set, or BVH) into the
//! canonical forms checked here:
//! - a **key pose** is [`KeyPose`] `{time_s, joints}`, `joints` 23 × `[x, y, z]` metres relative
//!   to the body centre, in [`JOINT_NAMES`] order; one frame of a BVH becomes one with
//!   [`key_pose_from_bvh`];
//! - a **seed motion** is a [`Motion`] of 23 world joints (metres, y up); a BVH that names its
//!   joints as we do (any file choreo exported) becomes one with [`seed_from_bvh`].
//!
//! Every check returns an [`InputError`] the API maps to 422. The models check key poses with
//! [`key_frames`], which the API's [`validate_key_poses`] runs before its own plausibility checks,
//! so a job the API accepted is never failed by its model for its key poses.
//!
//! # Which times a key pose may have
//! A dance of a song of `d` seconds has `n = ⌊d · fps⌋` frames ([`song_frames`]; at least one). A key
//! pose at `time_s` lands on frame `round(time_s · fps)` ([`key_frame`]), which must be one of
//! them: `0 ≤ time_s` and `round(time_s · fps) < n`, i.e. `time_s < (n − ½) / fps`. A key in the
//! song's last fraction of a frame therefore has no frame and is refused. Two key poses on the
//! same frame are refused too.
//!
//! # Bone-length tolerance
//! Motion capture itself is noisy: over all 69,262 frames of the dataset a bone's length strays
//! from its median by up to 27 cm (marker swaps), and the sum of the 23 bone lengths stays within
//! 0.82–1.09 × its median. So a pose is absurd when any bone is longer than its dataset median
//! ([`REFERENCE_BONE_M`]) plus [`BONE_SLACK_M`] = 0.35 m, or when the sum of its bone lengths is
//! outside [`TOTAL_RATIO`] = 0.5–1.5 × the dataset's (a collapsed or inflated skeleton, such as
//! centimetres sent as metres). Every frame of the dataset passes (`tests/motion.rs`).
use super::bvh::Bvh;
pub use super::input_error::InputError;
use super::input_error::JointSet;
use super::skeleton::{body_centre, JOINT_NAMES, PARENTS};
use super::{KeyPose, Motion, MotionError, NUM_JOINTS};

/// Median over the dataset of each joint's distance to its parent ([`PARENTS`]; the spine's to the
/// body centre), metres.
pub const REFERENCE_BONE_M: [f32; NUM_JOINTS] = [
    0.109, 0.490, 0.148, 0.335, 0.288, 0.113, 0.155, 0.197, 0.449, 0.329, 0.117, 0.181, 0.348,
    0.275, 0.182, 0.126, 0.200, 0.470, 0.329, 0.125, 0.167, 0.122, 0.048,
];
/// How much longer than its reference a bone may be, metres.
pub const BONE_SLACK_M: f32 = 0.35;
/// Allowed range of the sum of bone lengths, as a ratio of the reference sum.
pub const TOTAL_RATIO: (f32, f32) = (0.5, 1.5);
/// Longest seed motion accepted, frames (10 minutes at 25 fps).
pub const MAX_SEED_FRAMES: usize = 15_000;
/// Highest seed-motion frame rate accepted.
pub const MAX_SEED_FPS: f64 = 240.0;

/// Checks one pose `[23][3]` (any origin): finite, joint count, plausible bone lengths.
pub fn check_pose(what: &str, joints: &[[f64; 3]], root: [f64; 3]) -> Result<(), InputError> {
    if joints.len() != NUM_JOINTS {
        return Err(InputError::WrongJointCount {
            what: what.to_string(),
            got: joints.len(),
            asked: Some(JointSet::Dataset),
        });
    }
    for (j, p) in joints.iter().enumerate() {
        if p.iter().any(|v| !v.is_finite()) {
            return Err(InputError::NonFinite {
                what: format!("{what}, joint {}", JOINT_NAMES[j]),
            });
        }
    }
    let mut total = 0.0f32;
    for j in 0..NUM_JOINTS {
        let parent = PARENTS[j].map_or(root, |p| joints[p]);
        let len = (0..3)
            .map(|c| (joints[j][c] - parent[c]).powi(2))
            .sum::<f64>()
            .sqrt() as f32;
        let max_m = REFERENCE_BONE_M[j] + BONE_SLACK_M;
        if len > max_m {
            return Err(InputError::AbsurdBone {
                what: what.to_string(),
                joint: JOINT_NAMES[j],
                length_m: len,
                max_m,
            });
        }
        total += len;
    }
    let reference: f32 = REFERENCE_BONE_M.iter().sum();
    let (lo, hi) = (TOTAL_RATIO.0 * reference, TOTAL_RATIO.1 * reference);
    if !(lo..=hi).contains(&total) {
        return Err(InputError::AbsurdSize {
            what: what.to_string(),
            total_m: total,
            min_m: lo,
            max_m: hi,
        });
    }
    Ok(())
}

/// Frames a model makes for a song of `duration_s` seconds at `fps`: `⌊duration_s · fps⌋`, at least
/// one. The one rule: every model's `generate`, the style classifier and the API's key-pose check
/// call it, so a key pose the API accepted always lands on a frame the model makes.
pub fn song_frames(duration_s: f64, fps: f64) -> usize {
    let n = (duration_s * fps).floor();
    if n.is_finite() && n >= 1.0 {
        n as usize
    } else {
        1
    }
}

/// The frame key pose `index` at `time_s` lands on, `round(time_s · fps)`, when it is one of the
/// dance's `frames` frames (see the module doc).
pub fn key_frame(index: usize, time_s: f64, frames: usize, fps: f64) -> Result<usize, InputError> {
    if !time_s.is_finite() {
        return Err(InputError::NonFinite {
            what: format!("key pose {index} time_s"),
        });
    }
    let frame = (time_s * fps).round();
    if time_s < 0.0 || frame < 0.0 || frame >= frames as f64 {
        return Err(InputError::TimeOutsideSong {
            index,
            time_s,
            frame: frame as i64,
            frames,
            fps,
            limit_s: (frames as f64 - 0.5) / fps,
        });
    }
    Ok(frame as usize)
}

/// The frame of each canonical key pose for a dance of `frames` frames at `fps`, checking what a
/// model needs to serve them: 23 finite joints, a time on a frame of the dance, no two on one
/// frame. The models call it ([`crate::models::keypose_transformer::local_keys`]); the API calls
/// it through [`validate_key_poses`], so a key pose the API accepts is one the model serves.
pub fn key_frames(poses: &[KeyPose], frames: usize, fps: f64) -> Result<Vec<usize>, InputError> {
    let mut at = Vec::with_capacity(poses.len());
    let mut taken = std::collections::HashMap::with_capacity(poses.len());
    for (i, p) in poses.iter().enumerate() {
        let frame = key_frame(i, p.time_s, frames, fps)?;
        if let Some(&first) = taken.get(&frame) {
            return Err(InputError::DuplicateTime {
                first,
                second: i,
                first_s: poses[first].time_s,
                second_s: p.time_s,
                frame,
            });
        }
        taken.insert(frame, i);
        if p.joints.len() != NUM_JOINTS {
            return Err(InputError::WrongJointCount {
                what: format!("key pose {i}"),
                got: p.joints.len(),
                asked: Some(JointSet::Dataset),
            });
        }
        if let Some(j) = p
            .joints
            .iter()
            .position(|v| v.iter().any(|c| !c.is_finite()))
        {
            return Err(InputError::NonFinite {
                what: format!("key pose {i}, joint {}", JOINT_NAMES[j]),
            });
        }
        at.push(frame);
    }
    Ok(at)
}

/// Validates canonical key poses for a dance of `frames` frames at `fps` and returns each one's
/// frame: [`key_frames`], and plausible bone lengths ([`check_pose`]). The API's check.
pub fn validate_key_poses(
    poses: &[KeyPose],
    frames: usize,
    fps: f64,
) -> Result<Vec<usize>, InputError> {
    let at = key_frames(poses, frames, fps)?;
    for (i, p) in poses.iter().enumerate() {
        // Key poses are relative to the body centre, so the root is the origin.
        check_pose(&format!("key pose {i}"), &p.joints, [0.0; 3])?;
    }
    Ok(at)
}

/// Validates a seed motion: fps, length, and every frame as a pose around its body centre.
pub fn validate_seed_motion(motion: &Motion) -> Result<(), InputError> {
    if !(motion.fps.is_finite() && motion.fps > 0.0) {
        return Err(InputError::NonFinite {
            what: "seed motion fps".into(),
        });
    }
    if motion.fps > MAX_SEED_FPS {
        return Err(InputError::Malformed(format!(
            "seed motion at {} fps; at most {MAX_SEED_FPS} fps is accepted",
            motion.fps
        )));
    }
    let sh = motion.positions.shape();
    if sh[1] != NUM_JOINTS || sh[2] != 3 {
        return Err(InputError::WrongJointCount {
            what: "seed motion".into(),
            got: sh[1],
            asked: Some(JointSet::Dataset),
        });
    }
    if sh[0] == 0 || sh[0] > MAX_SEED_FRAMES {
        return Err(InputError::Malformed(format!(
            "seed motion has {} frames, expected 1–{MAX_SEED_FRAMES}",
            sh[0]
        )));
    }
    for (t, frame) in motion.positions.outer_iter().enumerate() {
        let joints: Vec<[f64; 3]> = frame
            .outer_iter()
            .map(|p| [f64::from(p[0]), f64::from(p[1]), f64::from(p[2])])
            .collect();
        if joints.iter().flatten().any(|v| !v.is_finite()) {
            return Err(InputError::NonFinite {
                what: format!("seed motion frame {t}"),
            });
        }
        let c = body_centre(frame);
        check_pose(
            &format!("seed motion frame {t}"),
            &joints,
            [f64::from(c[0]), f64::from(c[1]), f64::from(c[2])],
        )?;
    }
    Ok(())
}

fn bvh_input(what: &str, e: MotionError) -> InputError {
    match e {
        MotionError::NotFinite { line, what: value } => InputError::NonFinite {
            what: format!("{what}, line {line}: {value}"),
        },
        e => InputError::Malformed(format!("{what}: {e}")),
    }
}

/// A seed motion from BVH text (metres, y up, our joint names), validated.
pub fn seed_from_bvh(text: &str) -> Result<Motion, InputError> {
    let what = "seed motion BVH";
    let bvh = Bvh::parse(text).map_err(|e| bvh_input(what, e))?;
    let motion = bvh.to_motion().map_err(|e| bvh_input(what, e))?;
    validate_seed_motion(&motion)?;
    Ok(motion)
}

/// Key pose `index` at `time_s` from frame `frame` of BVH text (metres, y up, our joint names),
/// relative to its body centre: the root joint when the file has one (choreo's exports), else the
/// weighted centroid. Its time is checked by [`validate_key_poses`].
pub fn key_pose_from_bvh(
    text: &str,
    frame: usize,
    index: usize,
    time_s: f64,
) -> Result<KeyPose, InputError> {
    let what = format!("key pose {index} BVH");
    let bvh = Bvh::parse(text).map_err(|e| bvh_input(&what, e))?;
    if frame >= bvh.num_frames() {
        return Err(InputError::Malformed(format!(
            "{what} has {} frames, no frame {frame}",
            bvh.num_frames()
        )));
    }
    let world = bvh.world_frame(frame);
    let idx = bvh.dataset_joints().map_err(|e| bvh_input(&what, e))?;
    let f = ndarray::Array2::from_shape_fn((NUM_JOINTS, 3), |(j, c)| world[idx[j]][c] as f32);
    let c = match bvh.names.iter().position(|n| n == super::rig::ROOT_NAME) {
        Some(k) => [world[k][0], world[k][1], world[k][2]],
        None => body_centre(f.view()).map(f64::from),
    };
    let joints = (0..NUM_JOINTS)
        .map(|j| [0, 1, 2].map(|a| world[idx[j]][a] - c[a]))
        .collect();
    let pose = KeyPose { time_s, joints };
    check_pose(&format!("key pose {index}"), &pose.joints, [0.0; 3])?;
    Ok(pose)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A plausible pose: every joint at its reference distance straight above its parent... which
    /// is a line, not a body, but has exactly the reference bone lengths.
    fn line_pose() -> Vec<[f64; 3]> {
        let mut joints = vec![[0.0; 3]; NUM_JOINTS];
        for j in super::super::skeleton::topological_order() {
            let base = PARENTS[j].map_or([0.0; 3], |p| joints[p]);
            joints[j] = [base[0], base[1] + f64::from(REFERENCE_BONE_M[j]), base[2]];
        }
        joints
    }

    fn pose(time_s: f64) -> KeyPose {
        KeyPose {
            time_s,
            joints: line_pose(),
        }
    }

    #[test]
    fn accepts_plausible_key_poses() {
        assert_eq!(
            validate_key_poses(&[pose(1.0), pose(2.0)], 250, 25.0),
            Ok(vec![25, 50])
        );
    }

    #[test]
    fn a_key_pose_must_land_on_a_frame_of_the_dance() {
        // A 5.3 s song has 132 frames at 25 fps: 0..=131, times up to (132 − ½) / 25 = 5.26 s.
        let n = song_frames(5.3, 25.0);
        assert_eq!(n, 132);
        assert_eq!(key_frame(0, 0.0, n, 25.0), Ok(0));
        assert_eq!(key_frame(0, 131.0 / 25.0, n, 25.0), Ok(131));
        assert_eq!(key_frame(0, 5.259, n, 25.0), Ok(131));
        for outside in [5.26, 5.29, 5.3, -0.001] {
            assert_eq!(
                key_frame(0, outside, n, 25.0).unwrap_err().code(),
                "time-outside-song",
                "{outside}"
            );
        }
        assert_eq!(
            song_frames(0.01, 25.0),
            1,
            "the models make at least one frame"
        );
        assert_eq!(song_frames(f64::NAN, 25.0), 1);
    }

    #[test]
    fn refuses_each_kind_of_bad_key_pose() {
        let mut nan = pose(1.0);
        nan.joints[4][1] = f64::NAN;
        let v = |poses: &[KeyPose]| validate_key_poses(poses, 250, 25.0).unwrap_err().code();
        assert_eq!(v(&[nan]), "motion-not-finite");
        let mut inf = pose(1.0);
        inf.time_s = f64::INFINITY;
        assert_eq!(v(&[inf]), "motion-not-finite");
        let mut short = pose(1.0);
        short.joints.pop();
        assert_eq!(v(&[short]), "wrong-joint-count");
        let mut cm = pose(1.0);
        cm.joints.iter_mut().flatten().for_each(|v| *v *= 100.0);
        assert_eq!(v(&[cm]), "absurd-bone-length");
        let mut long_arm = pose(1.0);
        long_arm.joints[6][0] += 1.0; // right wrist a metre from the forearm
        assert_eq!(v(&[long_arm]), "absurd-bone-length");
        let mut collapsed = pose(1.0);
        collapsed
            .joints
            .iter_mut()
            .flatten()
            .for_each(|v| *v *= 0.1);
        assert_eq!(v(&[collapsed]), "absurd-skeleton-size");
        assert_eq!(v(&[pose(12.0)]), "time-outside-song");
        assert_eq!(v(&[pose(-0.5)]), "time-outside-song");
        // 3.0 s and 3.01 s are both frame 75; 3.03 s is frame 76 (0.03 s apart, yet distinct frames).
        assert_eq!(v(&[pose(3.0), pose(1.0), pose(3.01)]), "duplicate-time");
        assert_eq!(
            validate_key_poses(&[pose(3.0), pose(3.03)], 250, 25.0),
            Ok(vec![75, 76])
        );
        // 3.021 s and 3.059 s are 0.038 s apart but share frame 76.
        assert_eq!(v(&[pose(3.021), pose(3.059)]), "duplicate-time");
    }
}
