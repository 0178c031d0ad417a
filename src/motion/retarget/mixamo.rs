//! The built-in `mixamo` target: Mixamo's bone names on the reference body ([`super::body`]) in
//! the T-pose, written as BVH ([`crate::motion::bvh::write_bvh`]) and glb
//! ([`crate::motion::export::glb_bytes`]) like choreo's own rig.
//!
//! Mixamo names every bone `mixamorig:` + a name (`Hips`, `Spine`, `Spine1`, `Spine2`, `Neck`,
//! `Head`, `HeadTop_End`, `LeftShoulder`, `LeftArm`, `LeftForeArm`, `LeftHand`, `LeftUpLeg`,
//! `LeftLeg`, `LeftFoot`, `LeftToeBase`, `LeftToe_End` and the right side). Its three spine
//! bones are VRM's spine, chest and upper chest. Fingers are left out: choreo has none.
use super::body::{self, BodyJoint};
use super::TargetSkeleton;

/// The prefix of every Mixamo bone name.
pub const PREFIX: &str = "mixamorig:";

/// Mixamo's name of a reference-body joint (without [`PREFIX`]).
fn name(joint: &BodyJoint) -> &'static str {
    match joint.key {
        "hips" => "Hips",
        "spine" => "Spine",
        "chest" => "Spine1",
        "upper_chest" => "Spine2",
        "neck" => "Neck",
        "head" => "Head",
        "head_top" => "HeadTop_End",
        "left_shoulder" => "LeftShoulder",
        "left_upper_arm" => "LeftArm",
        "left_lower_arm" => "LeftForeArm",
        "left_hand" => "LeftHand",
        "left_upper_leg" => "LeftUpLeg",
        "left_lower_leg" => "LeftLeg",
        "left_foot" => "LeftFoot",
        "left_toes" => "LeftToeBase",
        "left_toe_end" => "LeftToe_End",
        "right_shoulder" => "RightShoulder",
        "right_upper_arm" => "RightArm",
        "right_lower_arm" => "RightForeArm",
        "right_hand" => "RightHand",
        "right_upper_leg" => "RightUpLeg",
        "right_lower_leg" => "RightLeg",
        "right_foot" => "RightFoot",
        "right_toes" => "RightToeBase",
        "right_toe_end" => "RightToe_End",
        other => other,
    }
}

/// The `mixamo` target: 25 joints named `mixamorig:*`, T-pose, metres, in an armature called
/// `Armature` as Mixamo's own downloads have it (scripts written for Mixamo characters look
/// for it).
pub fn mixamo() -> TargetSkeleton {
    body::skeleton(super::DEFAULT_ARMATURE, |j| format!("{PREFIX}{}", name(j)))
}
