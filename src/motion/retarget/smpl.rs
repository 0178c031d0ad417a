//! The built-in `smpl` target and its AMASS-style `.npz`.
//!
//! # The skeleton
//! SMPL's 24 joints in SMPL's order and hierarchy (Loper et al., *SMPL: A Skinned Multi-Person
//! Linear Model*, SIGGRAPH Asia 2015): pelvis, left/right hip, spine1, knees, spine2, ankles,
//! spine3, feet, neck, collars, head, shoulders, elbows, wrists, hands. SMPL's left is +x, y up,
//! facing +z, the rest pose a T-pose.
//!
//! **The rest joint positions are approximate.** SMPL's exact joints come from its model file
//! (the joint regressor applied to the template mesh at the body's `betas`), which we may not
//! ship. [`REST`] is a symmetric, centimetre-rounded layout of the neutral body at `betas = 0` in
//! SMPL's own frame (pelvis about 22 cm below the origin, feet about 1.15 m below it), placed by
//! hand to SMPL's proportions. Rotations do not depend on it beyond the rest directions of the
//! bones, which it gets right to a few degrees; `trans` does (see below), to a few centimetres.
//!
//! # The file
//! As AMASS writes its captures (and EDGE and Bailando users exchange them), read with
//! `numpy.load`:
//! - `poses`: `[T, 72]` float64, each joint's local rotation as an axis-angle (radians), in SMPL's
//!   joint order; joint 0's is the global orientation;
//! - `trans`: `[T, 3]` float64, metres: the pelvis's world position minus its rest position
//!   ([`REST`]`[0]`), so SMPL's forward kinematics put the pelvis where the dance has it;
//! - `mocap_framerate`: float64 scalar (25 for choreo);
//! - `betas`: 16 zeros (AMASS's count; SMPL reads the first 10);
//! - `gender`: the string `neutral`.
//!
//! Coordinates are SMPL's own (y up), as AIST++ and EDGE keep them; AMASS's captures are z up (a
//! −90° turn about x brings these into that frame).
//!
//! The container is a zip (crate `zip`, stored, no compression, as `numpy.savez` writes it);
//! float arrays are written by `ndarray-npy`; the one string by hand, a 0-d `<U7` array (the
//! `.npy` format's header is a Python dict literal, version 1.0).
use std::io::{Cursor, Write as _};

use nalgebra::Vector3;
use ndarray::{Array1, Array2};
use ndarray_npy::WriteNpyExt;

use super::{HumanBone, RetargetError, TargetSkeleton};
use crate::motion::rig::{Rig, RigMotion};

/// SMPL's joint names, in its order.
pub const JOINT_NAMES: [&str; 24] = [
    "pelvis",
    "left_hip",
    "right_hip",
    "spine1",
    "left_knee",
    "right_knee",
    "spine2",
    "left_ankle",
    "right_ankle",
    "spine3",
    "left_foot",
    "right_foot",
    "neck",
    "left_collar",
    "right_collar",
    "head",
    "left_shoulder",
    "right_shoulder",
    "left_elbow",
    "right_elbow",
    "left_wrist",
    "right_wrist",
    "left_hand",
    "right_hand",
];

/// SMPL's parent of each joint (`None` for the pelvis).
pub const PARENTS: [Option<usize>; 24] = [
    None,
    Some(0),
    Some(0),
    Some(0),
    Some(1),
    Some(2),
    Some(3),
    Some(4),
    Some(5),
    Some(6),
    Some(7),
    Some(8),
    Some(9),
    Some(9),
    Some(9),
    Some(12),
    Some(13),
    Some(14),
    Some(16),
    Some(17),
    Some(18),
    Some(19),
    Some(20),
    Some(21),
];

/// Approximate rest (T-pose) joint positions of the neutral body, metres, SMPL's frame; see the
/// module doc.
pub const REST: [[f64; 3]; 24] = [
    [0.000, -0.223, 0.028],  // pelvis
    [0.069, -0.314, 0.023],  // left_hip
    [-0.069, -0.314, 0.023], // right_hip
    [0.000, -0.110, 0.015],  // spine1
    [0.105, -0.690, 0.015],  // left_knee
    [-0.105, -0.690, 0.015], // right_knee
    [0.000, 0.030, 0.025],   // spine2
    [0.088, -1.087, -0.028], // left_ankle
    [-0.088, -1.087, -0.028],
    [0.000, 0.085, 0.025],   // spine3
    [0.118, -1.143, 0.095],  // left_foot
    [-0.118, -1.143, 0.095], // right_foot
    [0.000, 0.290, -0.010],  // neck
    [0.075, 0.190, -0.005],  // left_collar
    [-0.075, 0.190, -0.005], // right_collar
    [0.000, 0.355, 0.045],   // head
    [0.173, 0.237, -0.015],  // left_shoulder
    [-0.173, 0.237, -0.015], // right_shoulder
    [0.433, 0.220, -0.030],  // left_elbow
    [-0.433, 0.220, -0.030], // right_elbow
    [0.683, 0.225, -0.030],  // left_wrist
    [-0.683, 0.225, -0.030], // right_wrist
    [0.770, 0.215, -0.040],  // left_hand
    [-0.770, 0.215, -0.040], // right_hand
];

/// The humanoid bone of each SMPL joint (its `*_hand` joints, the knuckles, follow the wrists).
const BONES: [Option<HumanBone>; 24] = [
    Some(HumanBone::Hips),
    Some(HumanBone::LeftUpperLeg),
    Some(HumanBone::RightUpperLeg),
    Some(HumanBone::Spine),
    Some(HumanBone::LeftLowerLeg),
    Some(HumanBone::RightLowerLeg),
    Some(HumanBone::Chest),
    Some(HumanBone::LeftFoot),
    Some(HumanBone::RightFoot),
    Some(HumanBone::UpperChest),
    Some(HumanBone::LeftToes),
    Some(HumanBone::RightToes),
    Some(HumanBone::Neck),
    Some(HumanBone::LeftShoulder),
    Some(HumanBone::RightShoulder),
    Some(HumanBone::Head),
    Some(HumanBone::LeftUpperArm),
    Some(HumanBone::RightUpperArm),
    Some(HumanBone::LeftLowerArm),
    Some(HumanBone::RightLowerArm),
    Some(HumanBone::LeftHand),
    Some(HumanBone::RightHand),
    None,
    None,
];

/// Betas written (AMASS's count).
pub const NUM_BETAS: usize = 16;

/// The name of the [`smpl`] target's armature.
pub const ARMATURE: &str = "SMPL";

/// The `smpl` target: SMPL's 24 joints, approximate T-pose rest, metres, in an armature called
/// [`ARMATURE`].
pub fn smpl() -> TargetSkeleton {
    let p = |j: usize| Vector3::from(REST[j]);
    let offsets = (0..24)
        .map(|j| PARENTS[j].map_or_else(Vector3::zeros, |par| p(j) - p(par)))
        .collect();
    TargetSkeleton {
        rig: Rig {
            names: JOINT_NAMES.iter().map(|s| s.to_string()).collect(),
            parents: PARENTS.to_vec(),
            offsets,
        },
        humanoid: BONES.to_vec(),
        armature: ARMATURE.to_string(),
    }
}

/// The AMASS-style `.npz` of a motion retargeted onto [`smpl`].
pub fn smpl_npz(m: &RigMotion) -> Result<Vec<u8>, RetargetError> {
    let err = |reason: String| RetargetError::Write {
        format: "smpl npz",
        reason,
    };
    if m.rig.names.iter().map(String::as_str).ne(JOINT_NAMES) {
        return Err(err("the motion is not on SMPL's 24 joints".into()));
    }
    let t_len = m.num_frames();
    if t_len == 0 {
        return Err(RetargetError::EmptyMotion);
    }
    let mut poses = Array2::<f64>::zeros((t_len, 72));
    let mut trans = Array2::<f64>::zeros((t_len, 3));
    let pelvis = Vector3::from(REST[0]);
    for t in 0..t_len {
        for (j, q) in m.rotations[t].iter().enumerate() {
            let aa = q.scaled_axis();
            for c in 0..3 {
                poses[[t, 3 * j + c]] = aa[c];
            }
        }
        // The root joint's world position is the root translation (its rest offset is zero).
        let p = m.root_translation[t] + m.rig.offsets[0] - pelvis;
        for c in 0..3 {
            trans[[t, c]] = p[c];
        }
    }
    let npy = |write: &dyn Fn(&mut Vec<u8>) -> Result<(), ndarray_npy::WriteNpyError>| -> Result<Vec<u8>, RetargetError> {
        let mut buf = Vec::new();
        write(&mut buf).map_err(|e| err(e.to_string()))?;
        Ok(buf)
    };
    let entries: Vec<(&str, Vec<u8>)> = vec![
        ("poses.npy", npy(&|b| poses.write_npy(b))?),
        ("trans.npy", npy(&|b| trans.write_npy(b))?),
        (
            "mocap_framerate.npy",
            npy(&|b| ndarray::arr0(m.fps).write_npy(b))?,
        ),
        (
            "betas.npy",
            npy(&|b| Array1::<f64>::zeros(NUM_BETAS).write_npy(b))?,
        ),
        ("gender.npy", unicode_scalar_npy("neutral")),
    ];
    let mut zip = zip::ZipWriter::new(Cursor::new(Vec::new()));
    let options =
        zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    for (name, bytes) in entries {
        zip.start_file(name, options)
            .map_err(|e| err(e.to_string()))?;
        zip.write_all(&bytes).map_err(|e| err(e.to_string()))?;
    }
    Ok(zip.finish().map_err(|e| err(e.to_string()))?.into_inner())
}

/// A 0-d numpy array holding one string (`dtype '<U{n}'`, UTF-32 little-endian), `.npy` 1.0.
fn unicode_scalar_npy(s: &str) -> Vec<u8> {
    let chars: Vec<char> = s.chars().collect();
    let mut header = format!(
        "{{'descr': '<U{}', 'fortran_order': False, 'shape': (), }}",
        chars.len().max(1)
    );
    // Magic (6) + version (2) + header length (2) + header, padded with spaces to a multiple of
    // 64 and ended by a newline.
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut out = Vec::with_capacity(10 + header.len() + 4 * chars.len());
    out.extend_from_slice(b"\x93NUMPY\x01\x00");
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    for c in chars {
        out.extend_from_slice(&(c as u32).to_le_bytes());
    }
    out
}
