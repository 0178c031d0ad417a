//! Key poses and seed motion as users send them, made into the canonical forms the models take
//! and validated: the one entry point the API (and `choreo generate`) calls, [`key_poses`] and
//! [`seed_motion`].
//!
//! # Two joint sets, told apart by their count
//! - **`choreo`** (the default): motion.json's `joint_names`, 26 joints. Index 0 is
//!   `body_centre` (the rig's root), index `j + 1` is dataset joint `j` for the 23 dataset joints
//!   ([`JOINT_NAMES`], [`rig::rig_index`]), then `pelvis` (24) and `neck` (25), branch joints the
//!   rig adds at the spine ([`rig`]). A frame of a choreo `motion.json` (`positions[t]`) is a pose
//!   in this set, in world coordinates. A key pose is made relative to its `body_centre`, so world
//!   and root-relative poses both work; `pelvis` and `neck` must be finite but are not used (the
//!   rig derives them from the spine).
//! - **`dataset`**: the 23 dataset joints in [`JOINT_NAMES`] order, key poses relative to the body
//!   centre, seed motion in world coordinates (the format before motion.json had its rig).
//!
//! `joint_set` may be left out: 26 joints are `choreo`, 23 `dataset`. A given `joint_set` must
//! match the count, and any other count is refused naming both sets.
//!
//! # BVH
//! Instead of positions, a key pose may be one frame of a BVH (`bvh: {text, frame}`) and a seed
//! motion a whole BVH (`bvh: text`), when the file names its joints as choreo does: any
//! `motion.bvh` choreo wrote ([`validate::key_pose_from_bvh`], [`validate::seed_from_bvh`]).
//!
//! # Canonical forms
//! Key poses: [`KeyPose`], 23 joints relative to the body centre, in the order sent, each on a
//! frame of the dance ([`validate::validate_key_poses`], the same check the models make).
//! Seed motion: a [`Motion`] of 23 world joints at [`MOTION_FPS`], resampled linearly from its own
//! frame rate when that differs (the models read it frame by frame).
use ndarray::{Array3, ArrayView3, Axis};
use serde::{Deserialize, Serialize};

use super::input_error::InputError;
pub use super::input_error::JointSet;
use super::rig::{self, RIG_JOINTS};
use super::skeleton::JOINT_NAMES;
use super::validate::{self, MAX_SEED_FPS};
use super::{KeyPose, Motion, MOTION_FPS, NUM_JOINTS};

/// One frame of a BVH file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct BvhFrame {
    /// The BVH text, metres, y up, joints named as choreo names them: e.g. a job's `motion.bvh`.
    pub text: String,
    /// Frame of the file, from 0.
    #[serde(deserialize_with = "whole_number")]
    pub frame: usize,
}

/// A whole number sent as `380` or as `380.0`: JSON Schema's `integer` (the OpenAPI document's
/// type for it) admits both, so the API takes both.
fn whole_number<'de, D: serde::Deserializer<'de>>(deserializer: D) -> Result<usize, D::Error> {
    use serde::de::Error;
    let n = serde_json::Number::deserialize(deserializer)?;
    let whole = n.as_u64().or_else(|| {
        n.as_f64()
            .filter(|f| f.fract() == 0.0 && (0.0..=u64::MAX as f64).contains(f))
            .map(|f| f as u64)
    });
    whole.and_then(|u| usize::try_from(u).ok()).ok_or_else(|| {
        D::Error::custom(format!(
            "invalid value {n}, expected a frame index (a whole number from 0)"
        ))
    })
}

/// A key pose as sent: `joints` (either joint set) or one frame of a BVH, and its time in the song.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = key_pose_example)]
pub struct KeyPoseInput {
    /// Seconds from the song's start. The pose lands on frame `round(time_s × 25)`, which must be
    /// one of the dance's `⌊duration_s × 25⌋` frames: `0 ≤ time_s < (⌊duration_s × 25⌋ − 0.5) / 25`
    /// (a key in the song's last half frame is refused). Two key poses may not share a frame.
    pub time_s: f64,
    /// Which joints `joints` lists. Optional: 26 joints are `choreo`, 23 `dataset`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joint_set: Option<JointSet>,
    /// `J × [x, y, z]` metres, y up. `choreo` (26, in motion.json's `joint_names` order: any
    /// `positions[t]` of a motion.json): world or root-relative, made relative to `body_centre`.
    /// `dataset` (23, the dataset's order): relative to the body centre. Give `joints` or `bvh`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joints: Option<Vec<[f64; 3]>>,
    /// One frame of a BVH instead of `joints` (e.g. of a job's `motion.bvh`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bvh: Option<BvhFrame>,
}

/// A motion to continue from, as sent: `positions` (either joint set) with their `fps`, or a BVH.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = seed_motion_example)]
pub struct SeedMotionInput {
    /// Frames per second of `positions` (0 < fps ≤ 240; required with them). A BVH gives its own.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fps: Option<f64>,
    /// Which joints each frame of `positions` lists. Optional: 26 joints are `choreo`, 23 `dataset`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joint_set: Option<JointSet>,
    /// `T × J × [x, y, z]` world metres, y up, 1 to 1,024 frames (the API's cap; models use only the
    /// last frames). `choreo` (26): a slice of motion.json's `positions`; `dataset` (23): the
    /// dataset's order. Give `positions` or `bvh`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 1, max_items = 1024)]
    pub positions: Option<Vec<Vec<[f64; 3]>>>,
    /// A whole BVH text instead of `positions` (e.g. a job's `motion.bvh`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bvh: Option<String>,
}

/// `positions[100]` of `choreo export DANCE_W_22 --format json`, millimetre precision: a pose as
/// a motion.json holds it, for the schema's examples.
const EXAMPLE_POSE: [[f64; 3]; RIG_JOINTS] = [
    [-0.169, 0.894, 1.006],
    [-0.285, 1.429, 0.903],
    [-0.195, 1.489, 0.891],
    [-0.179, 1.023, 1.034],
    [-0.312, 1.325, 0.992],
    [-0.574, 1.34, 1.105],
    [-0.559, 1.362, 1.213],
    [-0.445, 1.381, 1.318],
    [-0.288, 0.856, 1.053],
    [-0.148, 0.487, 1.255],
    [-0.177, 0.179, 1.223],
    [-0.182, 0.063, 1.148],
    [-0.058, 0.081, 1.33],
    [-0.074, 1.312, 0.876],
    [0.186, 1.233, 0.853],
    [0.268, 1.398, 0.855],
    [0.381, 1.341, 0.847],
    [-0.098, 0.86, 0.944],
    [-0.077, 0.395, 0.956],
    [-0.212, 0.156, 0.809],
    [-0.319, 0.088, 0.763],
    [-0.127, 0.037, 0.885],
    [0.237, 1.344, 0.835],
    [-0.45, 1.373, 1.365],
    [-0.179, 1.023, 1.034],
    [-0.179, 1.023, 1.034],
];

fn key_pose_example() -> serde_json::Value {
    serde_json::json!({"time_s": 2.0, "joints": EXAMPLE_POSE})
}

fn seed_motion_example() -> serde_json::Value {
    serde_json::json!({"fps": MOTION_FPS, "positions": [EXAMPLE_POSE]})
}

/// Key poses as sent, made canonical and validated for a dance of `frames` frames at `fps`
/// ([`validate::song_frames`]).
pub fn key_poses(
    inputs: &[KeyPoseInput],
    frames: usize,
    fps: f64,
) -> Result<Vec<KeyPose>, InputError> {
    let poses = inputs
        .iter()
        .enumerate()
        .map(|(i, k)| key_pose(i, k))
        .collect::<Result<Vec<_>, _>>()?;
    validate::validate_key_poses(&poses, frames, fps)?;
    Ok(poses)
}

/// One key pose as sent → canonical (not yet checked against the song).
fn key_pose(index: usize, input: &KeyPoseInput) -> Result<KeyPose, InputError> {
    let what = format!("key pose {index}");
    match (&input.joints, &input.bvh) {
        (Some(joints), None) => {
            let set = JointSet::resolve(&what, input.joint_set, joints.len())?;
            finite(&what, set, joints)?;
            let root = match set {
                JointSet::Choreo => joints[0],
                JointSet::Dataset => [0.0; 3],
            };
            let joints = (0..NUM_JOINTS)
                .map(|j| [0, 1, 2].map(|c| joints[set.index_of(j)][c] - root[c]))
                .collect();
            Ok(KeyPose {
                time_s: input.time_s,
                joints,
            })
        }
        (None, Some(bvh)) => {
            if input.joint_set.is_some() {
                return Err(InputError::Malformed(format!(
                    "{what}: `joint_set` goes with `joints`; a BVH names its joints"
                )));
            }
            validate::key_pose_from_bvh(&bvh.text, bvh.frame, index, input.time_s)
        }
        (Some(_), Some(_)) | (None, None) => Err(InputError::Malformed(format!(
            "{what}: give either `joints` or `bvh`"
        ))),
    }
}

/// A seed motion as sent, made canonical (23 world joints at [`MOTION_FPS`]) and validated.
pub fn seed_motion(input: &SeedMotionInput) -> Result<Motion, InputError> {
    let motion = match (&input.positions, &input.bvh) {
        (Some(positions), None) => {
            let fps = input.fps.ok_or_else(|| {
                InputError::Malformed("seed motion: `fps` is required with `positions`".into())
            })?;
            if !(fps.is_finite() && fps > 0.0 && fps <= MAX_SEED_FPS) {
                return Err(InputError::Malformed(format!(
                    "seed motion fps is {fps}; it must be in (0, {MAX_SEED_FPS}]"
                )));
            }
            if positions.is_empty() || positions.len() > validate::MAX_SEED_FRAMES {
                return Err(InputError::Malformed(format!(
                    "seed motion has {} frames, expected 1–{}",
                    positions.len(),
                    validate::MAX_SEED_FRAMES
                )));
            }
            let set =
                JointSet::resolve("seed motion frame 0", input.joint_set, positions[0].len())?;
            for (t, frame) in positions.iter().enumerate() {
                let what = format!("seed motion frame {t}");
                JointSet::resolve(&what, Some(set), frame.len())?;
                finite(&what, set, frame)?;
            }
            let positions = Array3::from_shape_fn((positions.len(), NUM_JOINTS, 3), |(t, j, c)| {
                positions[t][set.index_of(j)][c] as f32
            });
            Motion { fps, positions }
        }
        (None, Some(text)) => {
            if input.fps.is_some() || input.joint_set.is_some() {
                return Err(InputError::Malformed(
                    "seed motion: a BVH gives its own frame rate and joints; send `bvh` alone"
                        .into(),
                ));
            }
            validate::seed_from_bvh(text)?
        }
        (Some(_), Some(_)) | (None, None) => {
            return Err(InputError::Malformed(
                "seed motion: give either `positions` or `bvh`".into(),
            ))
        }
    };
    validate::validate_seed_motion(&motion)?;
    Ok(resample(&motion, MOTION_FPS))
}

/// Refuses a non-finite coordinate anywhere in a pose of `set`, naming the joint.
fn finite(what: &str, set: JointSet, joints: &[[f64; 3]]) -> Result<(), InputError> {
    match joints.iter().position(|p| p.iter().any(|v| !v.is_finite())) {
        None => Ok(()),
        Some(k) => {
            let name = match set {
                JointSet::Choreo => rig::joint_names().get(k).cloned().unwrap_or_default(),
                JointSet::Dataset => JOINT_NAMES
                    .get(k)
                    .map(|s| s.to_string())
                    .unwrap_or_default(),
            };
            Err(InputError::NonFinite {
                what: format!("{what}, joint {k} ({name})"),
            })
        }
    }
}

/// The motion at `fps`, by linear interpolation between its frames (itself when already there):
/// frames at `k / fps` for every `k` with `k / fps` within the motion.
pub fn resample(motion: &Motion, fps: f64) -> Motion {
    let t_in = motion.num_frames();
    if motion.fps == fps || t_in < 2 {
        return Motion {
            fps,
            positions: motion.positions.clone(),
        };
    }
    let last_s = (t_in - 1) as f64 / motion.fps;
    let t_out = (last_s * fps + 1e-9).floor() as usize + 1;
    Motion {
        fps,
        positions: lerp_frames(
            motion.positions.view(),
            (0..t_out).map(|k| k as f64 / fps * motion.fps),
        ),
    }
}

/// The positions at fractional source frames, each linearly interpolated between the two frames
/// around it (the last frame held past the end). [`resample`] and the models' beat time
/// (`models::beat_time`) read motion this way; `motion::beat_align::resample` is the Catmull-Rom
/// counterpart for its warp.
pub fn lerp_frames(
    positions: ArrayView3<'_, f32>,
    source_frames: impl ExactSizeIterator<Item = f64>,
) -> Array3<f32> {
    let (n, joints, dims) = positions.dim();
    let mut out = Array3::zeros((source_frames.len(), joints, dims));
    if n == 0 {
        return out;
    }
    for (mut frame, x) in out.axis_iter_mut(Axis(0)).zip(source_frames) {
        let a = (x.floor().max(0.0) as usize).min(n - 1);
        let b = (a + 1).min(n - 1);
        let w = (x - a as f64).clamp(0.0, 1.0) as f32;
        let (fa, fb) = (
            positions.index_axis(Axis(0), a),
            positions.index_axis(Axis(0), b),
        );
        frame.assign(&(&fa * (1.0 - w) + &fb * w));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::export;
    use crate::motion::skeleton::{topological_order, PARENTS};
    use crate::motion::validate::REFERENCE_BONE_M;

    #[test]
    fn a_bvh_frame_is_any_json_form_of_a_whole_number() {
        let frame = |v: &str| {
            serde_json::from_str::<BvhFrame>(&format!(r#"{{"text": "", "frame": {v}}}"#))
                .map(|b| b.frame)
        };
        assert_eq!(frame("380").ok(), Some(380));
        assert_eq!(frame("380.0").ok(), Some(380));
        for bad in ["1.5", "-1", "\"3\"", "1e300"] {
            assert!(frame(bad).is_err(), "{bad}");
        }
    }

    /// A plausible motion of `t` frames: a figure with the reference bone lengths (each bone
    /// leaning a little differently, so the rig has a body, not a line) walking along x.
    fn walking(t: usize) -> Motion {
        let mut positions = Array3::zeros((t, NUM_JOINTS, 3));
        for f in 0..t {
            let mut joints = [[0.0f32; 3]; NUM_JOINTS];
            for j in topological_order() {
                let base = PARENTS[j].map_or([0.0, 1.0, 0.0], |p| joints[p]);
                let lean = 0.3 * ((j as f32) * 1.7 + f as f32 * 0.05).sin();
                let down = if (7..=11).contains(&j) || (16..=20).contains(&j) {
                    -1.0
                } else {
                    1.0
                };
                let l = REFERENCE_BONE_M[j];
                joints[j] = [
                    base[0] + l * lean.sin(),
                    base[1] + down * l * lean.cos(),
                    base[2] + 0.1 * l,
                ];
            }
            for (j, p) in joints.iter().enumerate() {
                positions[[f, j, 0]] = p[0] + 0.02 * f as f32;
                positions[[f, j, 1]] = p[1];
                positions[[f, j, 2]] = p[2];
            }
        }
        Motion {
            fps: MOTION_FPS,
            positions,
        }
    }

    fn motion_json(m: &Motion) -> export::MotionJson {
        export::to_json(&export::prepare(m).expect("prepare"))
    }

    fn to_f64(frame: &[[f32; 3]]) -> Vec<[f64; 3]> {
        frame.iter().map(|p| p.map(f64::from)).collect()
    }

    #[test]
    fn the_choreo_set_is_motion_json_joint_names() {
        let json = motion_json(&walking(10));
        assert_eq!(json.joint_names, rig::joint_names());
        assert_eq!(json.joint_names.len(), JointSet::Choreo.joint_count());
        assert_eq!(json.joint_names[0], rig::ROOT_NAME);
        for (j, name) in JOINT_NAMES.iter().enumerate() {
            assert_eq!(json.joint_names[JointSet::Choreo.index_of(j)], *name);
        }
        assert_eq!(&json.joint_names[24..], ["pelvis", "neck"]);
    }

    #[test]
    fn a_motion_json_frame_is_a_key_pose_relative_to_its_body_centre() {
        let json = motion_json(&walking(30));
        let f = 17;
        let input = KeyPoseInput {
            time_s: 0.5,
            joint_set: None,
            joints: Some(to_f64(&json.positions[f])),
            bvh: None,
        };
        let keys = key_poses(std::slice::from_ref(&input), 30, MOTION_FPS)
            .expect("a motion.json frame is a key pose");
        let centre = json.positions[f][0];
        for j in 0..NUM_JOINTS {
            for (c, &centre_c) in centre.iter().enumerate() {
                let want = f64::from(json.positions[f][j + 1][c]) - f64::from(centre_c);
                assert!((keys[0].joints[j][c] - want).abs() < 1e-6, "joint {j}");
            }
        }
        // The same pose named explicitly, and already root-relative, gives the same key.
        let named = KeyPoseInput {
            joint_set: Some(JointSet::Choreo),
            ..input.clone()
        };
        assert_eq!(key_poses(&[named], 30, MOTION_FPS), Ok(keys.clone()));
        let rel: Vec<[f64; 3]> = to_f64(&json.positions[f])
            .iter()
            .map(|p| [0, 1, 2].map(|c| p[c] - f64::from(centre[c])))
            .collect();
        let relative = KeyPoseInput {
            joints: Some(rel),
            ..input.clone()
        };
        let again = key_poses(&[relative], 30, MOTION_FPS).expect("root-relative");
        for j in 0..NUM_JOINTS {
            for c in 0..3 {
                assert!((again[0].joints[j][c] - keys[0].joints[j][c]).abs() < 1e-6);
            }
        }
        // The dataset set of the same pose passes through unchanged.
        let dataset = KeyPoseInput {
            time_s: 0.5,
            joint_set: Some(JointSet::Dataset),
            joints: Some(keys[0].joints.clone()),
            bvh: None,
        };
        assert_eq!(key_poses(&[dataset], 30, MOTION_FPS), Ok(keys.clone()));
        // And a frame of the motion.bvh beside it is the same key pose, up to float printing.
        let m = export::prepare(&walking(30)).expect("prepare");
        let text = export::bvh_string(&m).expect("bvh");
        let from_bvh = KeyPoseInput {
            time_s: 0.5,
            joint_set: None,
            joints: None,
            bvh: Some(BvhFrame { text, frame: f }),
        };
        let b =
            key_poses(&[from_bvh], 30, MOTION_FPS).expect("a frame of motion.bvh is a key pose");
        for j in 0..NUM_JOINTS {
            for c in 0..3 {
                assert!(
                    (b[0].joints[j][c] - keys[0].joints[j][c]).abs() < 1e-3,
                    "joint {j}: {:?} vs {:?}",
                    b[0].joints[j],
                    keys[0].joints[j]
                );
            }
        }
    }

    #[test]
    fn the_schema_examples_are_accepted() {
        let key: KeyPoseInput =
            serde_json::from_value(key_pose_example()).expect("key pose example");
        assert_eq!(key_poses(&[key], 100, MOTION_FPS).expect("valid").len(), 1);
        let seed: SeedMotionInput =
            serde_json::from_value(seed_motion_example()).expect("seed example");
        assert_eq!(seed_motion(&seed).expect("valid").num_frames(), 1);
    }

    #[test]
    fn wrong_counts_and_mixed_inputs_are_refused_naming_both_sets() {
        let json = motion_json(&walking(5));
        let pose = to_f64(&json.positions[0]);
        let key = |joints: Vec<[f64; 3]>, set| KeyPoseInput {
            time_s: 0.0,
            joint_set: set,
            joints: Some(joints),
            bvh: None,
        };
        for (joints, set) in [
            (pose[..25].to_vec(), None),
            (pose[..24].to_vec(), None),
            (pose.clone(), Some(JointSet::Dataset)),
            (pose[1..24].to_vec(), Some(JointSet::Choreo)),
        ] {
            let err = key_poses(&[key(joints, set)], 5, MOTION_FPS).unwrap_err();
            assert_eq!(err.code(), "wrong-joint-count");
            let text = err.to_string();
            assert!(
                text.contains("\"choreo\"")
                    && text.contains("26")
                    && text.contains("\"dataset\"")
                    && text.contains("23"),
                "{text}"
            );
        }
        let mut nan = pose.clone();
        nan[25][1] = f64::NAN; // the neck: unused, but still refused
        let err = key_poses(&[key(nan, None)], 5, MOTION_FPS).unwrap_err();
        assert_eq!(err.code(), "motion-not-finite");
        assert!(err.to_string().contains("neck"), "{err}");
        let both = KeyPoseInput {
            bvh: Some(BvhFrame {
                text: String::new(),
                frame: 0,
            }),
            ..key(pose.clone(), None)
        };
        assert_eq!(
            key_poses(&[both], 5, MOTION_FPS).unwrap_err().code(),
            "malformed-motion"
        );
        let neither = KeyPoseInput {
            time_s: 0.0,
            joint_set: None,
            joints: None,
            bvh: None,
        };
        assert_eq!(
            key_poses(&[neither], 5, MOTION_FPS).unwrap_err().code(),
            "malformed-motion"
        );
        // A seed motion's frames must all have the count of the first.
        let mut frames: Vec<Vec<[f64; 3]>> = json.positions.iter().map(|f| to_f64(f)).collect();
        frames[3].pop();
        let seed = SeedMotionInput {
            fps: Some(25.0),
            joint_set: None,
            positions: Some(frames),
            bvh: None,
        };
        let err = seed_motion(&seed).unwrap_err();
        assert_eq!(err.code(), "wrong-joint-count");
        assert!(err.to_string().contains("frame 3"), "{err}");
    }

    #[test]
    fn a_motion_json_slice_and_a_motion_bvh_are_seed_motions() {
        let source = walking(40);
        let m = export::prepare(&source).expect("prepare");
        let json = export::to_json(&m);
        let frames: Vec<Vec<[f64; 3]>> = json.positions[10..30].iter().map(|f| to_f64(f)).collect();
        let seed = seed_motion(&SeedMotionInput {
            fps: Some(25.0),
            joint_set: None,
            positions: Some(frames.clone()),
            bvh: None,
        })
        .expect("slice");
        assert_eq!(seed.positions.shape(), [20, NUM_JOINTS, 3]);
        for t in 0..20 {
            for j in 0..NUM_JOINTS {
                for c in 0..3 {
                    assert_eq!(seed.positions[[t, j, c]], json.positions[10 + t][j + 1][c]);
                }
            }
        }
        // The dataset set: the same 23 world joints.
        let dataset: Vec<Vec<[f64; 3]>> = frames.iter().map(|f| f[1..24].to_vec()).collect();
        let same = seed_motion(&SeedMotionInput {
            fps: Some(25.0),
            joint_set: Some(JointSet::Dataset),
            positions: Some(dataset),
            bvh: None,
        })
        .expect("dataset");
        assert_eq!(same.positions, seed.positions);
        // The whole motion.bvh.
        let text = export::bvh_string(&m).expect("bvh");
        let from_bvh = seed_motion(&SeedMotionInput {
            fps: None,
            joint_set: None,
            positions: None,
            bvh: Some(text),
        })
        .expect("bvh seed");
        assert_eq!(from_bvh.num_frames(), 40);
        let err = (0..NUM_JOINTS)
            .map(|j| {
                (0..3)
                    .map(|c| (from_bvh.positions[[12, j, c]] - json.positions[12][j + 1][c]).abs())
                    .fold(0.0f32, f32::max)
            })
            .fold(0.0f32, f32::max);
        assert!(err < 1e-3, "BVH and JSON frames differ by {err} m");
        // fps is required with positions and refused beside a BVH.
        let no_fps = SeedMotionInput {
            fps: None,
            joint_set: None,
            positions: Some(frames),
            bvh: None,
        };
        assert_eq!(seed_motion(&no_fps).unwrap_err().code(), "malformed-motion");
    }

    #[test]
    fn a_seed_at_another_rate_is_resampled_to_the_model_rate() {
        let source = walking(51); // 2 s at 25 fps
        let m50 = resample(&source, 50.0);
        assert_eq!(m50.num_frames(), 101);
        let back = resample(&m50, MOTION_FPS);
        assert_eq!(back.num_frames(), 51);
        let d = (&back.positions - &source.positions)
            .mapv(f32::abs)
            .fold(0.0f32, |a, &b| a.max(b));
        assert!(d < 1e-5, "{d}");
        // Half-way frames are the mean of their neighbours.
        for c in 0..3 {
            let mid = 0.5 * (source.positions[[3, 4, c]] + source.positions[[4, 4, c]]);
            assert!((m50.positions[[7, 4, c]] - mid).abs() < 1e-5);
        }
    }
}
