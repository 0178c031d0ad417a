//! Retargeting: a dance on a skeleton other than choreo's own.
//!
//! Every target skeleton is described the same way, whatever it comes from (a built-in such as
//! Mixamo, VRM or SMPL, or a BVH/glb a user uploads): a rigid [`Rig`] with the target's own joint
//! names, hierarchy and rest offsets, and for each of its joints the humanoid bone it is, if any
//! ([`HumanBone`], the VRM 1.0 humanoid vocabulary, which every naming convention we read maps
//! onto). The solver only ever sees that description, so a built-in and an uploaded rig take the
//! same path.
//!
//! - [`retarget`] (`solve.rs`): the solver, choreo's rig onto any target (its module doc says how).
//! - [`mixamo`], [`vrm`], [`smpl`]: the built-in targets and their files (`.vrma`, `.npz`);
//!   `body.rs` is the reference body the first two share.
//! - [`from_motion_json`] (`source.rs`): a job's motion.json back into the rig motion it was.
//!
//! Crates: `nalgebra` for rotations (already choreo's), `serde_json` for the `.vrma`'s glTF JSON
//! (its extension is plain JSON that `gltf-json`'s typed structs do not carry), `ndarray-npy` for
//! the `.npy` arrays and `zip` for the `.npz` container (numpy's own format, stored as
//! `numpy.savez` does; `zip` was already built for the API docs).
use serde::{Deserialize, Serialize};

use super::rig::Rig;

mod body;
mod gltf_skin;
pub mod mixamo;
pub mod names;
pub mod smpl;
mod solve;
mod source;
pub mod uploaded;
pub mod vrm;

pub use mixamo::mixamo;
pub use smpl::{smpl, smpl_npz};
pub use solve::{retarget, REQUIRED};
pub use source::from_motion_json;
pub use vrm::{vrm, vrma_bytes};

/// A humanoid bone, named as in VRM 1.0's `VRMC_vrm.humanoid.humanBones` (body bones; fingers,
/// eyes and jaw are not in choreo's capture and stay unmapped).
///
/// The vocabulary every mapping goes through: Mixamo, Unreal, Rigify and SMPL names are mapped
/// onto it, and the solver maps it onto choreo's joints.
#[derive(
    Clone,
    Copy,
    Debug,
    PartialEq,
    Eq,
    Hash,
    PartialOrd,
    Ord,
    Serialize,
    Deserialize,
    utoipa::ToSchema,
)]
#[serde(rename_all = "camelCase")]
pub enum HumanBone {
    Hips,
    Spine,
    Chest,
    UpperChest,
    Neck,
    Head,
    LeftShoulder,
    LeftUpperArm,
    LeftLowerArm,
    LeftHand,
    RightShoulder,
    RightUpperArm,
    RightLowerArm,
    RightHand,
    LeftUpperLeg,
    LeftLowerLeg,
    LeftFoot,
    LeftToes,
    RightUpperLeg,
    RightLowerLeg,
    RightFoot,
    RightToes,
}

impl HumanBone {
    /// Every bone, parents before children.
    pub const ALL: [HumanBone; 22] = [
        HumanBone::Hips,
        HumanBone::Spine,
        HumanBone::Chest,
        HumanBone::UpperChest,
        HumanBone::Neck,
        HumanBone::Head,
        HumanBone::LeftShoulder,
        HumanBone::LeftUpperArm,
        HumanBone::LeftLowerArm,
        HumanBone::LeftHand,
        HumanBone::RightShoulder,
        HumanBone::RightUpperArm,
        HumanBone::RightLowerArm,
        HumanBone::RightHand,
        HumanBone::LeftUpperLeg,
        HumanBone::LeftLowerLeg,
        HumanBone::LeftFoot,
        HumanBone::LeftToes,
        HumanBone::RightUpperLeg,
        HumanBone::RightLowerLeg,
        HumanBone::RightFoot,
        HumanBone::RightToes,
    ];

    /// VRM's name of the bone (`leftUpperArm`).
    pub fn vrm_name(self) -> &'static str {
        match self {
            HumanBone::Hips => "hips",
            HumanBone::Spine => "spine",
            HumanBone::Chest => "chest",
            HumanBone::UpperChest => "upperChest",
            HumanBone::Neck => "neck",
            HumanBone::Head => "head",
            HumanBone::LeftShoulder => "leftShoulder",
            HumanBone::LeftUpperArm => "leftUpperArm",
            HumanBone::LeftLowerArm => "leftLowerArm",
            HumanBone::LeftHand => "leftHand",
            HumanBone::RightShoulder => "rightShoulder",
            HumanBone::RightUpperArm => "rightUpperArm",
            HumanBone::RightLowerArm => "rightLowerArm",
            HumanBone::RightHand => "rightHand",
            HumanBone::LeftUpperLeg => "leftUpperLeg",
            HumanBone::LeftLowerLeg => "leftLowerLeg",
            HumanBone::LeftFoot => "leftFoot",
            HumanBone::LeftToes => "leftToes",
            HumanBone::RightUpperLeg => "rightUpperLeg",
            HumanBone::RightLowerLeg => "rightLowerLeg",
            HumanBone::RightFoot => "rightFoot",
            HumanBone::RightToes => "rightToes",
        }
    }

    /// The bone for a VRM name (exact, as VRM spells it).
    pub fn from_vrm_name(name: &str) -> Option<HumanBone> {
        HumanBone::ALL.into_iter().find(|b| b.vrm_name() == name)
    }
}

/// A skeleton to retarget onto: its own joints, hierarchy and rest pose, and which humanoid
/// bone each joint is.
///
/// `rig.offsets` are the rest pose (T- or A-pose, metres, y up, each in its parent's frame, the
/// parent's rest rotation being the identity: the form BVH uses). A glb whose rest nodes carry
/// rotations is first baked into this form by whoever reads it.
#[derive(Clone, Debug, PartialEq)]
pub struct TargetSkeleton {
    /// Joint names (the target's own, e.g. `mixamorig:LeftArm`), parents and rest offsets.
    pub rig: Rig,
    /// For each joint of `rig`, the humanoid bone it is; `None` for joints the dance does not
    /// drive (they keep their rest rotation).
    pub humanoid: Vec<Option<HumanBone>>,
    /// What the skeleton is called in the files: the glb's skin, which Blender's importer names
    /// the armature after (Mixamo's own downloads import as `Armature`).
    pub armature: String,
}

/// The armature name of a skeleton whose file gave it none: Blender's and Mixamo's default.
pub const DEFAULT_ARMATURE: &str = "Armature";

/// The built-in targets' names (`choreo`, the dance's own rig, is no target: nothing to solve).
pub const BUILTINS: [&str; 3] = ["mixamo", "vrm", "smpl"];

/// A built-in target by name ([`BUILTINS`]).
pub fn builtin(name: &str) -> Option<TargetSkeleton> {
    match name {
        "mixamo" => Some(mixamo()),
        "vrm" => Some(vrm()),
        "smpl" => Some(smpl()),
        _ => None,
    }
}

/// The files a retargeted dance is written as.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// BVH ([`crate::motion::bvh::write_bvh`]), any target.
    Bvh,
    /// glTF binary with a skin and one animation ([`crate::motion::export::glb_bytes`]), any target.
    Glb,
    /// VRM Animation ([`vrma_bytes`]); the dance is put on [`vrm`].
    Vrma,
    /// AMASS-style SMPL parameters ([`smpl_npz`]); the dance is put on [`smpl`].
    SmplNpz,
}

/// The bytes of `src` (a dance on choreo's rig) on `target` as `format`; [`Format::Vrma`] and
/// [`Format::SmplNpz`] have their own target and ignore `target`.
pub fn render(
    src: &super::rig::RigMotion,
    target: &TargetSkeleton,
    format: Format,
) -> Result<Vec<u8>, RetargetError> {
    let export = |e: super::MotionError| RetargetError::Write {
        format: "bvh/glb",
        reason: e.to_string(),
    };
    match format {
        Format::Bvh => super::bvh::write_bvh(&retarget(src, target)?)
            .map(String::into_bytes)
            .map_err(export),
        Format::Glb => super::export::glb_bytes_named(&retarget(src, target)?, &target.armature)
            .map_err(export),
        Format::Vrma => {
            let target = vrm();
            vrma_bytes(&retarget(src, &target)?, &target)
        }
        Format::SmplNpz => smpl_npz(&retarget(src, &smpl())?),
    }
}

/// Why a dance could not be put on a target skeleton.
#[derive(Debug, thiserror::Error)]
pub enum RetargetError {
    #[error("the target skeleton is malformed: {0}")]
    InvalidTarget(String),
    #[error("the target skeleton has no `{}` bone; a dance needs hips, spine, head, both upper and lower arms, upper and lower legs and feet", .0.vrm_name())]
    MissingBone(HumanBone),
    #[error("two joints of the target skeleton are the `{}` bone", .0.vrm_name())]
    DuplicateBone(HumanBone),
    #[error("the motion is not on choreo's skeleton (motion.json's joints): {0}")]
    NotChoreoMotion(String),
    #[error("the motion has no frames")]
    EmptyMotion,
    #[error("writing the {format} file failed: {reason}")]
    Write {
        format: &'static str,
        reason: String,
    },
}

impl RetargetError {
    /// Stable kebab-case name of the failure.
    pub fn code(&self) -> &'static str {
        match self {
            RetargetError::InvalidTarget(_) => "invalid-target-skeleton",
            RetargetError::MissingBone(_) => "target-bone-missing",
            RetargetError::DuplicateBone(_) => "target-bone-duplicated",
            RetargetError::NotChoreoMotion(_) => "not-choreo-motion",
            RetargetError::EmptyMotion => "empty-motion",
            RetargetError::Write { .. } => "retarget-write-failed",
        }
    }

    /// Whether the error is the caller's (their skeleton or motion), not the server's.
    pub fn is_client_error(&self) -> bool {
        match self {
            RetargetError::InvalidTarget(_)
            | RetargetError::MissingBone(_)
            | RetargetError::DuplicateBone(_)
            | RetargetError::NotChoreoMotion(_)
            | RetargetError::EmptyMotion => true,
            RetargetError::Write { .. } => false,
        }
    }
}

#[cfg(test)]
mod tests;
