//! Which choreo joint drives which humanoid bone: the joints the solver reads, the bones a
//! target must have, each bone's aim (step 1 of the solver's doc) and the legs foot IK solves.
use super::super::HumanBone;

/// Choreo joints the solver reads, by name (motion.json's `joint_names`).
pub(super) const CHOREO_JOINTS: [&str; 21] = [
    "pelvis",
    "spine",
    "neck",
    "head_left",
    "head_right",
    "left_shoulder",
    "left_elbow",
    "left_forearm",
    "left_wrist",
    "right_shoulder",
    "right_elbow",
    "right_forearm",
    "right_wrist",
    "left_hip",
    "left_knee",
    "left_ankle",
    "left_toe",
    "right_hip",
    "right_knee",
    "right_ankle",
    "right_toe",
];

/// Humanoid bones a target must have to take a dance.
pub const REQUIRED: [HumanBone; 13] = [
    HumanBone::Hips,
    HumanBone::Spine,
    HumanBone::Head,
    HumanBone::LeftUpperArm,
    HumanBone::LeftLowerArm,
    HumanBone::RightUpperArm,
    HumanBone::RightLowerArm,
    HumanBone::LeftUpperLeg,
    HumanBone::LeftLowerLeg,
    HumanBone::LeftFoot,
    HumanBone::RightUpperLeg,
    HumanBone::RightLowerLeg,
    HumanBone::RightFoot,
];

/// How one humanoid bone is aimed: choreo's driver joint and the choreo and target point sets
/// (each a mean) from which its direction runs.
pub(super) struct Aim {
    pub(super) driver: &'static str,
    pub(super) from: &'static [&'static str],
    pub(super) to: &'static [&'static str],
    pub(super) target_from: &'static [HumanBone],
    pub(super) target_to: &'static [HumanBone],
    /// The second axis of the rest frames: up (feet, which point forward) or forward.
    pub(super) up: bool,
}

/// The aim of each bone choreo can drive; `None` for bones that follow their parent.
pub(super) fn aim(b: HumanBone) -> Option<Aim> {
    use HumanBone as B;
    const SHOULDERS: &[&str] = &["left_shoulder", "right_shoulder"];
    const HIPS: &[&str] = &["left_hip", "right_hip"];
    const HEAD: &[&str] = &["head_left", "head_right"];
    const UPPER_ARMS: &[HumanBone] = &[B::LeftUpperArm, B::RightUpperArm];
    const UPPER_LEGS: &[HumanBone] = &[B::LeftUpperLeg, B::RightUpperLeg];
    let a = |driver, from, to, target_from, target_to| {
        Some(Aim {
            driver,
            from,
            to,
            target_from,
            target_to,
            up: false,
        })
    };
    match b {
        B::Hips => a("pelvis", HIPS, &["spine"], UPPER_LEGS, &[B::Spine]),
        B::Spine | B::Chest | B::UpperChest => {
            a("spine", &["spine"], SHOULDERS, &[B::Spine], UPPER_ARMS)
        }
        B::Neck | B::Head => a("neck", SHOULDERS, HEAD, UPPER_ARMS, &[B::Head]),
        B::LeftUpperArm => a(
            "left_shoulder",
            &["left_shoulder"],
            &["left_elbow"],
            &[B::LeftUpperArm],
            &[B::LeftLowerArm],
        ),
        // The lower arms take choreo's forearm joint's rotation, not the elbow's: choreo's elbow
        // joint hangs the forearm marker and the hand-direction point off one rotation, and where
        // the two disagree it spins up to 55° a frame while its forearm joint turns back (the
        // forearm's world rotation 9-23° a frame where the elbow's turned 45-55°, a
        // dance-revolution dance). Driven by the elbow, a target's lower arm turned 61-66° in a
        // frame on 1.7 % of that dance's steps; by the forearm, on 3 of its 1145 steps (63° at
        // most), where the forearm's own turn is at choreo's 55° limit.
        B::LeftLowerArm => a(
            "left_forearm",
            &["left_elbow"],
            &["left_wrist"],
            &[B::LeftLowerArm],
            &[B::LeftHand],
        ),
        B::RightUpperArm => a(
            "right_shoulder",
            &["right_shoulder"],
            &["right_elbow"],
            &[B::RightUpperArm],
            &[B::RightLowerArm],
        ),
        B::RightLowerArm => a(
            "right_forearm",
            &["right_elbow"],
            &["right_wrist"],
            &[B::RightLowerArm],
            &[B::RightHand],
        ),
        B::LeftUpperLeg => a(
            "left_hip",
            &["left_hip"],
            &["left_knee"],
            &[B::LeftUpperLeg],
            &[B::LeftLowerLeg],
        ),
        B::LeftLowerLeg => a(
            "left_knee",
            &["left_knee"],
            &["left_ankle"],
            &[B::LeftLowerLeg],
            &[B::LeftFoot],
        ),
        B::RightUpperLeg => a(
            "right_hip",
            &["right_hip"],
            &["right_knee"],
            &[B::RightUpperLeg],
            &[B::RightLowerLeg],
        ),
        B::RightLowerLeg => a(
            "right_knee",
            &["right_knee"],
            &["right_ankle"],
            &[B::RightLowerLeg],
            &[B::RightFoot],
        ),
        B::LeftFoot => Some(Aim {
            up: true,
            ..a(
                "left_ankle",
                &["left_ankle"],
                &["left_toe"],
                &[B::LeftFoot],
                &[B::LeftToes],
            )?
        }),
        B::RightFoot => Some(Aim {
            up: true,
            ..a(
                "right_ankle",
                &["right_ankle"],
                &["right_toe"],
                &[B::RightFoot],
                &[B::RightToes],
            )?
        }),
        B::LeftShoulder
        | B::RightShoulder
        | B::LeftHand
        | B::RightHand
        | B::LeftToes
        | B::RightToes => None,
    }
}

/// The legs for foot IK: thigh, shin, foot bones and choreo's ankle.
pub(super) const LEGS: [(HumanBone, HumanBone, HumanBone, &str); 2] = [
    (
        HumanBone::LeftUpperLeg,
        HumanBone::LeftLowerLeg,
        HumanBone::LeftFoot,
        "left_ankle",
    ),
    (
        HumanBone::RightUpperLeg,
        HumanBone::RightLowerLeg,
        HumanBone::RightFoot,
        "right_ankle",
    ),
];
