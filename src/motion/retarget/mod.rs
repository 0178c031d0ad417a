//! Retargeting: a dance on a skeleton other than choreo's own (issue 26).
//!
//! Every target skeleton is described the same way, whatever it comes from (a built-in such as
//! Mixamo, VRM or SMPL, or a BVH/glb a user uploads): a rigid [`Rig`] with the target's own joint
//! names, hierarchy and rest offsets, and for each of its joints the humanoid bone it is, if any
//! ([`HumanBone`], the VRM 1.0 humanoid vocabulary, which every naming convention we read maps
//! onto). The solver only ever sees that description, so a built-in and an uploaded rig take the
//! same path.
use serde::{Deserialize, Serialize};

use super::rig::Rig;

pub mod names;
pub mod uploaded;

/// A humanoid bone, named as in VRM 1.0's `VRMC_vrm.humanoid.humanBones` (body bones; fingers,
/// eyes and jaw are not in choreo's capture and stay unmapped).
///
/// The vocabulary every mapping goes through: Mixamo, Unreal, Rigify and SMPL names are mapped
/// onto it, and the solver maps it onto choreo's joints.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize, utoipa::ToSchema)]
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
}
