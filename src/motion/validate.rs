//! Validation of motion users send: key poses and seed motions (§6 of the motion issue).
//!
//! Formats the API takes:
//! - a **key pose** is [`KeyPose`] `{time_s, joints}`, `joints` 23 × `[x, y, z]` metres relative
//!   to the body centre, in [`JOINT_NAMES`] order, or one frame of an uploaded BVH
//!   ([`key_pose_from_bvh`]);
//! - a **seed motion** is JSON frames (`[T][23][3]` world metres, y up) or a BVH ([`seed_from_bvh`])
//!   that names its joints as we do (any file choreo exported does).
//!
//! Every check returns an [`InputError`] the API maps to 422.
//!
//! # Bone-length tolerance
//! Motion capture itself is noisy: over all 69,262 frames of the dataset a bone's length strays
//! from its median by up to 27 cm (marker swaps), and the sum of the 23 bone lengths stays within
//! 0.82–1.09 × its median. So a pose is absurd when any bone is longer than its dataset median
//! ([`REFERENCE_BONE_M`]) plus [`BONE_SLACK_M`] = 0.35 m, or when the sum of its bone lengths is
//! outside [`TOTAL_RATIO`] = 0.5–1.5 × the dataset's (a collapsed or inflated skeleton, such as
//! centimetres sent as metres). Every frame of the dataset passes (`tests/motion.rs`).
use super::bvh::Bvh;
use super::skeleton::{body_centre, JOINT_NAMES, PARENTS};
use super::{KeyPose, Motion, MotionError, MOTION_FPS, NUM_JOINTS};

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
/// Two key poses closer than this in time are duplicates (half a motion frame), seconds.
pub const DUPLICATE_TIME_S: f64 = 0.5 / MOTION_FPS;
/// Longest seed motion accepted, frames (10 minutes at 25 fps).
pub const MAX_SEED_FRAMES: usize = 15_000;

/// Why user-supplied motion was refused (HTTP 422).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InputError {
    #[error("{what} is not a finite number")]
    NonFinite { what: String },
    #[error("{what} has {got} joints, expected {expected}")]
    WrongJointCount {
        what: String,
        got: usize,
        expected: usize,
    },
    #[error("{what}: bone {joint} is {length_m:.3} m long, at most {max_m:.3} m is plausible (are the units metres?)")]
    AbsurdBone {
        what: String,
        joint: &'static str,
        length_m: f32,
        max_m: f32,
    },
    #[error("{what}: bone lengths sum to {total_m:.2} m, plausible is {min_m:.2}–{max_m:.2} m (are the units metres?)")]
    AbsurdSize {
        what: String,
        total_m: f32,
        min_m: f32,
        max_m: f32,
    },
    #[error("key pose at {time_s} s is outside the song (0–{duration_s:.2} s)")]
    TimeOutsideSong { time_s: f64, duration_s: f64 },
    #[error("key poses at {first_s} s and {second_s} s fall on the same frame")]
    DuplicateTime { first_s: f64, second_s: f64 },
    #[error("{0}")]
    Malformed(String),
}

impl InputError {
    /// Stable kebab-case code for problem responses.
    pub fn code(&self) -> &'static str {
        match self {
            InputError::NonFinite { .. } => "non-finite",
            InputError::WrongJointCount { .. } => "wrong-joint-count",
            InputError::AbsurdBone { .. } => "absurd-bone-length",
            InputError::AbsurdSize { .. } => "absurd-skeleton-size",
            InputError::TimeOutsideSong { .. } => "time-outside-song",
            InputError::DuplicateTime { .. } => "duplicate-time",
            InputError::Malformed(_) => "malformed-motion",
        }
    }
}

/// Checks one pose `[23][3]` (any origin): finite, joint count, plausible bone lengths.
pub fn check_pose(what: &str, joints: &[[f64; 3]], root: [f64; 3]) -> Result<(), InputError> {
    if joints.len() != NUM_JOINTS {
        return Err(InputError::WrongJointCount {
            what: what.to_string(),
            got: joints.len(),
            expected: NUM_JOINTS,
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

/// Validates key poses against a song of `song_duration_s` seconds.
pub fn validate_key_poses(poses: &[KeyPose], song_duration_s: f64) -> Result<(), InputError> {
    for (i, p) in poses.iter().enumerate() {
        if !p.time_s.is_finite() {
            return Err(InputError::NonFinite {
                what: format!("key pose {i} time_s"),
            });
        }
        if p.time_s < 0.0 || p.time_s > song_duration_s {
            return Err(InputError::TimeOutsideSong {
                time_s: p.time_s,
                duration_s: song_duration_s,
            });
        }
        // Key poses are relative to the body centre, so the root is the origin.
        check_pose(&format!("key pose {i}"), &p.joints, [0.0; 3])?;
    }
    let mut times: Vec<f64> = poses.iter().map(|p| p.time_s).collect();
    times.sort_by(f64::total_cmp);
    for w in times.windows(2) {
        if w[1] - w[0] < DUPLICATE_TIME_S {
            return Err(InputError::DuplicateTime {
                first_s: w[0],
                second_s: w[1],
            });
        }
    }
    Ok(())
}

/// Validates a seed motion: fps, length, and every frame as a pose around its body centre.
pub fn validate_seed_motion(motion: &Motion) -> Result<(), InputError> {
    if !(motion.fps.is_finite() && motion.fps > 0.0) {
        return Err(InputError::NonFinite {
            what: "seed motion fps".into(),
        });
    }
    let sh = motion.positions.shape();
    if sh[1] != NUM_JOINTS || sh[2] != 3 {
        return Err(InputError::WrongJointCount {
            what: "seed motion".into(),
            got: sh[1],
            expected: NUM_JOINTS,
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

fn bvh_input(e: MotionError) -> InputError {
    InputError::Malformed(e.to_string())
}

/// A seed motion from BVH text (metres, y up, our joint names), validated.
pub fn seed_from_bvh(text: &str) -> Result<Motion, InputError> {
    let bvh = Bvh::parse(text).map_err(bvh_input)?;
    let motion = bvh.to_motion().map_err(bvh_input)?;
    validate_seed_motion(&motion)?;
    Ok(motion)
}

/// A key pose at `time_s` from frame `frame` of BVH text, relative to its body centre, validated
/// (`song_duration_s` bounds the time).
pub fn key_pose_from_bvh(
    text: &str,
    frame: usize,
    time_s: f64,
    song_duration_s: f64,
) -> Result<KeyPose, InputError> {
    let bvh = Bvh::parse(text).map_err(bvh_input)?;
    let motion = bvh.to_motion().map_err(bvh_input)?;
    if frame >= motion.num_frames() {
        return Err(InputError::Malformed(format!(
            "BVH has {} frames, no frame {frame}",
            motion.num_frames()
        )));
    }
    let f = motion.positions.index_axis(ndarray::Axis(0), frame);
    // The body centre is the root joint when the file has one (our exports), else the centroid.
    let c = match bvh.names.iter().position(|n| n == super::rig::ROOT_NAME) {
        Some(k) => {
            let w = bvh.world_positions();
            [w[[frame, k, 0]], w[[frame, k, 1]], w[[frame, k, 2]]]
        }
        None => body_centre(f).map(f64::from),
    };
    let joints = f
        .outer_iter()
        .map(|p| {
            [
                f64::from(p[0]) - c[0],
                f64::from(p[1]) - c[1],
                f64::from(p[2]) - c[2],
            ]
        })
        .collect();
    let pose = KeyPose { time_s, joints };
    validate_key_poses(std::slice::from_ref(&pose), song_duration_s)?;
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
        assert_eq!(validate_key_poses(&[pose(1.0), pose(2.0)], 10.0), Ok(()));
    }

    #[test]
    fn refuses_each_kind_of_bad_key_pose() {
        let mut nan = pose(1.0);
        nan.joints[4][1] = f64::NAN;
        assert_eq!(validate_key_poses(&[nan], 10.0).unwrap_err().code(), "non-finite");
        let mut inf = pose(1.0);
        inf.time_s = f64::INFINITY;
        assert_eq!(validate_key_poses(&[inf], 10.0).unwrap_err().code(), "non-finite");
        let mut short = pose(1.0);
        short.joints.pop();
        assert_eq!(validate_key_poses(&[short], 10.0).unwrap_err().code(), "wrong-joint-count");
        let mut cm = pose(1.0);
        cm.joints.iter_mut().flatten().for_each(|v| *v *= 100.0);
        assert_eq!(validate_key_poses(&[cm], 10.0).unwrap_err().code(), "absurd-bone-length");
        let mut long_arm = pose(1.0);
        long_arm.joints[6][0] += 1.0; // right wrist a metre from the forearm
        assert_eq!(validate_key_poses(&[long_arm], 10.0).unwrap_err().code(), "absurd-bone-length");
        let mut collapsed = pose(1.0);
        collapsed.joints.iter_mut().flatten().for_each(|v| *v *= 0.1);
        assert_eq!(validate_key_poses(&[collapsed], 10.0).unwrap_err().code(), "absurd-skeleton-size");
        assert_eq!(validate_key_poses(&[pose(12.0)], 10.0).unwrap_err().code(), "time-outside-song");
        assert_eq!(validate_key_poses(&[pose(-0.5)], 10.0).unwrap_err().code(), "time-outside-song");
        assert_eq!(
            validate_key_poses(&[pose(3.0), pose(1.0), pose(3.01)], 10.0).unwrap_err().code(),
            "duplicate-time"
        );
    }
}
