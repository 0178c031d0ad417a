//! The reference body the built-in Mixamo and VRM targets share: joint positions of a 1.75 m
//! adult in the T-pose, metres, y up, facing +z (the character's left on +x), feet on y = 0.
//!
//! # Where the proportions come from
//! Heights and lengths are fractions of the stature `H` from the anthropometric segment table in
//! D. A. Winter, *Biomechanics and Motor Control of Human Movement* (4th ed., 2009), Fig. 4.1
//! (after Drillis and Contini): hip (greater trochanter) 0.530 H, knee 0.285 H, ankle 0.039 H,
//! shoulder 0.818 H, chin 0.870 H, shoulder breadth 0.259 H, upper arm 0.186 H, forearm
//! 0.146 H, foot length 0.152 H. Where a skeleton joint is not a landmark of the table (the spine
//! joints, the base of the skull, the clavicle's inner end) it is placed between its neighbours
//! as Mixamo's and VRoid's rigs place it (spine joints evenly spaced from the pelvis to the base
//! of the neck, the clavicle starting 6 cm from the midline). Mixamo's own characters (Y Bot,
//! X Bot) are about this size; no third-party asset is copied.
use nalgebra::Vector3;

use super::HumanBone;

/// Stature of the reference body, metres.
pub const STATURE_M: f64 = 1.75;

/// A joint of the reference body: its humanoid bone (or an end point that is none), its parent
/// among these joints and its rest position.
#[derive(Clone, Copy, Debug)]
pub struct BodyJoint {
    /// The humanoid bone; `None` for end points (top of the head, tip of the toes).
    pub bone: Option<HumanBone>,
    /// A stable key naming the joint for the targets (`head_top`, `left_toe_end` for ends).
    pub key: &'static str,
    /// Index of the parent in [`joints`], `None` for the hips.
    pub parent: Option<usize>,
    /// World position at rest, metres.
    pub position: Vector3<f64>,
}

/// The reference body's joints, parents before children.
pub fn joints() -> Vec<BodyJoint> {
    let h = STATURE_M;
    let hip_y = 0.530 * h;
    let knee_y = 0.285 * h;
    let ankle_y = 0.039 * h;
    let shoulder_y = 0.818 * h;
    let neck_y = 0.860 * h;
    let head_y = 0.910 * h;
    // Hip joint centres sit 9 cm either side of the midline; the pelvis joint 6 cm above them.
    let hip_x = 0.09;
    let pelvis_y = hip_y + 0.06;
    let shoulder_x = 0.100 * h;
    let upper_arm = 0.186 * h;
    let forearm = 0.146 * h;
    // The ball of the foot lies about 0.8 of the foot length ahead of the heel, the ankle 0.2.
    let foot = 0.152 * h;
    let spine_step = (shoulder_y - 0.03 - pelvis_y) / 3.0;
    let v = Vector3::new;
    let mut out: Vec<BodyJoint> = Vec::new();
    let mut push = |bone: Option<HumanBone>,
                    key: &'static str,
                    parent: Option<usize>,
                    position: Vector3<f64>| {
        out.push(BodyJoint {
            bone,
            key,
            parent,
            position,
        });
        out.len() - 1
    };
    let hips = push(Some(HumanBone::Hips), "hips", None, v(0.0, pelvis_y, 0.0));
    let spine = push(
        Some(HumanBone::Spine),
        "spine",
        Some(hips),
        v(0.0, pelvis_y + spine_step, 0.0),
    );
    let chest = push(
        Some(HumanBone::Chest),
        "chest",
        Some(spine),
        v(0.0, pelvis_y + 2.0 * spine_step, 0.0),
    );
    let upper_chest = push(
        Some(HumanBone::UpperChest),
        "upper_chest",
        Some(chest),
        v(0.0, pelvis_y + 3.0 * spine_step, 0.0),
    );
    let neck = push(
        Some(HumanBone::Neck),
        "neck",
        Some(upper_chest),
        v(0.0, neck_y, 0.0),
    );
    let head = push(
        Some(HumanBone::Head),
        "head",
        Some(neck),
        v(0.0, head_y, 0.01),
    );
    push(None, "head_top", Some(head), v(0.0, h, 0.01));
    use HumanBone as B;
    let sides = [
        (
            1.0,
            [
                B::LeftShoulder,
                B::LeftUpperArm,
                B::LeftLowerArm,
                B::LeftHand,
                B::LeftUpperLeg,
                B::LeftLowerLeg,
                B::LeftFoot,
                B::LeftToes,
            ],
            [
                "left_shoulder",
                "left_upper_arm",
                "left_lower_arm",
                "left_hand",
                "left_upper_leg",
                "left_lower_leg",
                "left_foot",
                "left_toes",
                "left_toe_end",
            ],
        ),
        (
            -1.0,
            [
                B::RightShoulder,
                B::RightUpperArm,
                B::RightLowerArm,
                B::RightHand,
                B::RightUpperLeg,
                B::RightLowerLeg,
                B::RightFoot,
                B::RightToes,
            ],
            [
                "right_shoulder",
                "right_upper_arm",
                "right_lower_arm",
                "right_hand",
                "right_upper_leg",
                "right_lower_leg",
                "right_foot",
                "right_toes",
                "right_toe_end",
            ],
        ),
    ];
    for (sx, bones, keys) in sides {
        let clavicle = push(
            Some(bones[0]),
            keys[0],
            Some(upper_chest),
            v(sx * 0.06, shoulder_y - 0.02, 0.0),
        );
        let arm = push(
            Some(bones[1]),
            keys[1],
            Some(clavicle),
            v(sx * shoulder_x, shoulder_y, 0.0),
        );
        let fore = push(
            Some(bones[2]),
            keys[2],
            Some(arm),
            v(sx * (shoulder_x + upper_arm), shoulder_y, 0.0),
        );
        push(
            Some(bones[3]),
            keys[3],
            Some(fore),
            v(sx * (shoulder_x + upper_arm + forearm), shoulder_y, 0.0),
        );
        let up_leg = push(
            Some(bones[4]),
            keys[4],
            Some(hips),
            v(sx * hip_x, hip_y, 0.0),
        );
        let leg = push(
            Some(bones[5]),
            keys[5],
            Some(up_leg),
            v(sx * hip_x, knee_y, 0.0),
        );
        let ankle = push(
            Some(bones[6]),
            keys[6],
            Some(leg),
            v(sx * hip_x, ankle_y, 0.0),
        );
        let toes = push(
            Some(bones[7]),
            keys[7],
            Some(ankle),
            v(sx * hip_x, 0.02, 0.6 * foot),
        );
        push(None, keys[8], Some(toes), v(sx * hip_x, 0.0, 0.8 * foot));
    }
    out
}

/// The reference body as a target skeleton called `armature`, each joint named by `name` (the
/// target's own naming of the joint's key). Offsets are in the parent's frame with identity rest rotations
/// (the T-pose); the root's offset is zero, its rest position carried by the root translation.
pub fn skeleton(armature: &str, name: impl Fn(&BodyJoint) -> String) -> super::TargetSkeleton {
    let joints = joints();
    let offsets = joints
        .iter()
        .map(|j| match j.parent {
            None => Vector3::zeros(),
            Some(p) => j.position - joints[p].position,
        })
        .collect();
    super::TargetSkeleton {
        rig: super::Rig {
            names: joints.iter().map(&name).collect(),
            parents: joints.iter().map(|j| j.parent).collect(),
            offsets,
        },
        humanoid: joints.iter().map(|j| j.bone).collect(),
        armature: armature.to_string(),
    }
}
