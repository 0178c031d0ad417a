//! Joint names → humanoid bones, for the naming conventions rigs come with.
//!
//! [`humanoid_for`] reads one name; [`map_skeleton`] reads a whole skeleton, where the hierarchy
//! settles what a name alone cannot. Conventions read (case-insensitive, namespace prefixes such
//! as `mixamorig:`, `mixamorig1:`, `Armature|` or a bare `mixamorig_` ignored):
//!
//! | bone | Mixamo | VRM / VRoid | Unreal | Rigify (deform) | SMPL |
//! |---|---|---|---|---|---|
//! | hips | `Hips` | `hips` / `J_Bip_C_Hips` | `pelvis` | `DEF-spine` | `pelvis` |
//! | spine … upper chest | `Spine`, `Spine1`, `Spine2` | `spine`, `chest`, `upperChest` | `spine_01`…`spine_05` | `DEF-spine.001`…`.003` | `spine1`…`spine3` |
//! | neck, head | `Neck`, `Head` | `neck`, `head` | `neck_01`, `head` | `DEF-spine.004`, `DEF-spine.006` | `neck`, `head` |
//! | shoulder (clavicle) | `LeftShoulder` | `leftShoulder` | `clavicle_l` | `DEF-shoulder.L` | `left_collar` |
//! | upper arm | `LeftArm` | `leftUpperArm` | `upperarm_l` | `DEF-upper_arm.L` | `left_shoulder` |
//! | lower arm | `LeftForeArm` | `leftLowerArm` | `lowerarm_l` | `DEF-forearm.L` | `left_elbow` |
//! | hand | `LeftHand` | `leftHand` | `hand_l` | `DEF-hand.L` | `left_wrist` |
//! | upper leg | `LeftUpLeg` | `leftUpperLeg` | `thigh_l` | `DEF-thigh.L` | `left_hip` |
//! | lower leg | `LeftLeg` | `leftLowerLeg` | `calf_l` | `DEF-shin.L` | `left_knee` |
//! | foot | `LeftFoot` | `leftFoot` | `foot_l` | `DEF-foot.L` | `left_ankle` |
//! | toes | `LeftToeBase` | `leftToes` | `ball_l` | `DEF-toe.L` | `left_foot` |
//!
//! Two SMPL names mean one bone further down the limb than the same word elsewhere:
//! `left_shoulder` is the upper arm (its clavicle is `left_collar`) and `left_foot` the toes (its
//! foot is `left_ankle`). A name alone cannot tell, so [`humanoid_for`] gives the common reading
//! and [`map_skeleton`] corrects it from the hierarchy: a joint that reads as the same bone as its
//! nearest mapped ancestor is the next bone down (shoulder → upper arm, foot → toes), or nothing
//! (twist and roll segments such as Rigify's `DEF-upper_arm.L.001` repeat their parent's bone).
//!
//! Spines differ in count (Mixamo 3, Unreal 3 or 5, SMPL 3, VRM 1–3): [`map_skeleton`] takes the
//! spine joints between the hips and the neck in hierarchy order and names them Spine, Chest,
//! UpperChest; with more than three, the first, the middle and the last.
use std::collections::BTreeMap;

use super::HumanBone;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Side {
    Left,
    Right,
}

/// Strips namespaces and tool prefixes: `Armature|mixamorig1:LeftArm` → (`leftarm`, Mixamo).
fn strip(name: &str) -> (String, bool) {
    let last = name.rsplit([':', '|']).next().unwrap_or(name);
    let mut s = last.trim().to_ascii_lowercase();
    let mut mixamo = name.to_ascii_lowercase().contains("mixamorig");
    if let Some(rest) = s.strip_prefix("mixamorig") {
        // `mixamorig_Hips`, `mixamorig1Hips`: the colon replaced by tools that refuse it.
        s = rest
            .trim_start_matches(|c: char| c.is_ascii_digit() || c == '_')
            .to_string();
        mixamo = true;
    }
    for prefix in ["j_bip_", "bip01_", "bip01 ", "bip001 ", "b_"] {
        if let Some(rest) = s.strip_prefix(prefix) {
            s = rest.to_string();
        }
    }
    (s, mixamo)
}

/// Splits a side off a lowercased name: `left…`, `right…`, `l_…`, `…_l`, `….l`, `…_left`.
fn side_of(s: &str) -> (Option<Side>, &str) {
    for (word, side) in [("left", Side::Left), ("right", Side::Right)] {
        if let Some(rest) = s.strip_prefix(word) {
            return (Some(side), rest);
        }
        for sep in ["_", ".", "-", " "] {
            if let Some(rest) = s.strip_suffix(&format!("{sep}{word}")[..]) {
                return (Some(side), rest);
            }
        }
    }
    for (letter, side) in [("l", Side::Left), ("r", Side::Right)] {
        for sep in ["_", ".", "-", " "] {
            if let Some(rest) = s.strip_prefix(&format!("{letter}{sep}")[..]) {
                return (Some(side), rest);
            }
            if let Some(rest) = s.strip_suffix(&format!("{sep}{letter}")[..]) {
                return (Some(side), rest);
            }
        }
    }
    // VRoid's centre bones (`J_Bip_C_Hips`).
    (None, s.strip_prefix("c_").unwrap_or(s))
}

/// Rigify's deform bones: `DEF-spine.NNN` is the whole trunk, `DEF-<limb>.L` a limb, and a
/// trailing `.NNN` after the side a twist segment of the bone above it.
fn rigify(s: &str) -> Option<Option<HumanBone>> {
    let rest = s.strip_prefix("def-").or_else(|| s.strip_prefix("def_"))?;
    if let Some(n) = rest.strip_prefix("spine") {
        return Some(match n {
            "" => Some(HumanBone::Hips),
            ".001" => Some(HumanBone::Spine),
            ".002" => Some(HumanBone::Chest),
            ".003" => Some(HumanBone::UpperChest),
            ".004" => Some(HumanBone::Neck),
            ".006" => Some(HumanBone::Head),
            _ => None,
        });
    }
    let (limb, side) = match rest.rsplit_once('.') {
        Some((limb, "l")) => (limb, Side::Left),
        Some((limb, "r")) => (limb, Side::Right),
        // `DEF-upper_arm.L.001` and the like: twist segments, unmapped.
        _ => return Some(None),
    };
    Some(sided(side, &compact(limb)))
}

/// Lowercase letters and digits only.
fn compact(s: &str) -> String {
    s.chars().filter(char::is_ascii_alphanumeric).collect()
}

/// A limb bone from its side and its name without the side.
fn sided(side: Side, base: &str) -> Option<HumanBone> {
    use HumanBone as B;
    let (l, r) = match base {
        "shoulder" | "clavicle" | "collar" => (B::LeftShoulder, B::RightShoulder),
        "arm" | "upperarm" => (B::LeftUpperArm, B::RightUpperArm),
        "forearm" | "lowerarm" | "elbow" => (B::LeftLowerArm, B::RightLowerArm),
        "hand" | "wrist" => (B::LeftHand, B::RightHand),
        "upleg" | "upperleg" | "thigh" | "hip" => (B::LeftUpperLeg, B::RightUpperLeg),
        "leg" | "lowerleg" | "calf" | "shin" | "knee" => (B::LeftLowerLeg, B::RightLowerLeg),
        "foot" | "ankle" => (B::LeftFoot, B::RightFoot),
        "toebase" | "toes" | "toe" | "ball" => (B::LeftToes, B::RightToes),
        _ => return None,
    };
    Some(match side {
        Side::Left => l,
        Side::Right => r,
    })
}

/// The humanoid bone a joint name stands for in any convention of the module doc, if any.
///
/// Spine numbers follow the name's convention: Mixamo's (`mixamorig:Spine1` = Chest) when the
/// Mixamo prefix is there, otherwise SMPL's and Unreal's (`spine1`, `spine_01` = Spine). Read a
/// whole skeleton with [`map_skeleton`], which settles spines and SMPL's shifted limb names.
pub fn humanoid_for(name: &str) -> Option<HumanBone> {
    use HumanBone as B;
    let (s, mixamo) = strip(name);
    if let Some(bone) = rigify(&s) {
        return bone;
    }
    let (side, rest) = side_of(&s);
    let base = compact(rest);
    if let Some(side) = side {
        return sided(side, &base);
    }
    match base.as_str() {
        "hips" | "hip" | "pelvis" => Some(B::Hips),
        "spine" | "spine0" | "spine00" | "spine01" => Some(B::Spine),
        "spine1" if mixamo => Some(B::Chest),
        "spine2" if mixamo => Some(B::UpperChest),
        "spine1" => Some(B::Spine),
        "spine2" | "spine02" | "chest" => Some(B::Chest),
        "spine3" | "spine03" | "spine04" | "spine05" | "upperchest" => Some(B::UpperChest),
        "neck" | "neck1" | "neck01" => Some(B::Neck),
        "head" => Some(B::Head),
        _ => None,
    }
}

/// The bone one step down the limb from `bone`, for a joint that repeats its ancestor's bone.
fn next_down(bone: HumanBone) -> Option<HumanBone> {
    use HumanBone as B;
    match bone {
        B::LeftShoulder => Some(B::LeftUpperArm),
        B::RightShoulder => Some(B::RightUpperArm),
        B::LeftFoot => Some(B::LeftToes),
        B::RightFoot => Some(B::RightToes),
        B::Hips
        | B::Spine
        | B::Chest
        | B::UpperChest
        | B::Neck
        | B::Head
        | B::LeftUpperArm
        | B::LeftLowerArm
        | B::LeftHand
        | B::RightUpperArm
        | B::RightLowerArm
        | B::RightHand
        | B::LeftUpperLeg
        | B::LeftLowerLeg
        | B::LeftToes
        | B::RightUpperLeg
        | B::RightLowerLeg
        | B::RightToes => None,
    }
}

fn is_spine(bone: Option<HumanBone>) -> bool {
    matches!(
        bone,
        Some(HumanBone::Spine | HumanBone::Chest | HumanBone::UpperChest)
    )
}

/// Joints with every parent before its children (parents must name earlier or later joints of
/// the same list; a cycle leaves its joints out).
fn hierarchy_order(parents: &[Option<usize>]) -> Vec<usize> {
    let mut children = vec![Vec::new(); parents.len()];
    let mut stack = Vec::new();
    for (j, p) in parents.iter().enumerate() {
        match p {
            Some(p) if *p < parents.len() => children[*p].push(j),
            _ => stack.push(j),
        }
    }
    stack.reverse();
    let mut out = Vec::with_capacity(parents.len());
    while let Some(j) = stack.pop() {
        out.push(j);
        stack.extend(children[j].iter().rev());
    }
    out
}

/// The humanoid bone of every joint of a skeleton (`names[j]`, `parents[j]`), by name, with the
/// hierarchy settling spines and repeated bones (module doc), then `overrides` (joint name →
/// bone, or `None` to leave a joint unmapped) applied over it: an overridden bone is taken from
/// any other joint that had it. Each bone ends on at most one joint.
pub fn map_skeleton(
    names: &[String],
    parents: &[Option<usize>],
    overrides: &BTreeMap<String, Option<HumanBone>>,
) -> Vec<Option<HumanBone>> {
    let n = names.len();
    let order = hierarchy_order(parents);
    let mut bones: Vec<Option<HumanBone>> = names.iter().map(|s| humanoid_for(s)).collect();

    // Spines, in hierarchy order, renamed by their count.
    let spines: Vec<usize> = order
        .iter()
        .copied()
        .filter(|&j| is_spine(bones[j]))
        .collect();
    for &j in &spines {
        bones[j] = None;
    }
    let k = spines.len();
    let picks: Vec<(usize, HumanBone)> = match k {
        0 => vec![],
        1 => vec![(0, HumanBone::Spine)],
        2 => vec![(0, HumanBone::Spine), (1, HumanBone::Chest)],
        _ => vec![
            (0, HumanBone::Spine),
            (k / 2, HumanBone::Chest),
            (k - 1, HumanBone::UpperChest),
        ],
    };
    for (i, bone) in picks {
        bones[spines[i]] = Some(bone);
    }

    // A joint that repeats its nearest mapped ancestor's bone is the next bone down, if any.
    let mut nearest: Vec<Option<HumanBone>> = vec![None; n];
    for &j in &order {
        let above = parents[j].and_then(|p| nearest.get(p).copied().flatten());
        if let (Some(b), Some(a)) = (bones[j], above) {
            if a == b {
                bones[j] = next_down(b);
            }
        }
        nearest[j] = bones[j].or(above);
    }

    // Each bone on one joint: the first in hierarchy order keeps it.
    let mut taken = std::collections::BTreeSet::new();
    for &j in &order {
        if let Some(b) = bones[j] {
            if !taken.insert(b) {
                bones[j] = None;
            }
        }
    }

    // A "shoulder" that goes straight on to the elbow, with no upper arm between (choreo's own
    // rig, marker sets), is where the upper arm starts: it is the upper arm.
    for (shoulder, upper, lower) in [
        (
            HumanBone::LeftShoulder,
            HumanBone::LeftUpperArm,
            HumanBone::LeftLowerArm,
        ),
        (
            HumanBone::RightShoulder,
            HumanBone::RightUpperArm,
            HumanBone::RightLowerArm,
        ),
    ] {
        if !taken.contains(&upper) && taken.contains(&lower) {
            if let Some(b) = bones.iter_mut().find(|b| **b == Some(shoulder)) {
                *b = Some(upper);
            }
        }
    }

    for (name, bone) in overrides {
        let Some(j) = names.iter().position(|s| s == name) else {
            continue;
        };
        if let Some(b) = bone {
            for other in bones.iter_mut() {
                if *other == Some(*b) {
                    *other = None;
                }
            }
        }
        bones[j] = *bone;
    }
    bones
}

#[cfg(test)]
mod tests {
    use super::*;
    use HumanBone as B;

    #[test]
    fn mixamo_names_with_any_namespace() {
        for (name, bone) in [
            ("mixamorig:Hips", B::Hips),
            ("mixamorig1:Spine", B::Spine),
            ("mixamorig:Spine1", B::Chest),
            ("mixamorig:Spine2", B::UpperChest),
            ("Armature|mixamorig:LeftArm", B::LeftUpperArm),
            ("mixamorig_LeftForeArm", B::LeftLowerArm),
            ("mixamorig:RightHand", B::RightHand),
            ("mixamorig:LeftShoulder", B::LeftShoulder),
            ("mixamorig:LeftUpLeg", B::LeftUpperLeg),
            ("MIXAMORIG:LEFTLEG", B::LeftLowerLeg),
            ("mixamorig:RightFoot", B::RightFoot),
            ("mixamorig:LeftToeBase", B::LeftToes),
            ("mixamorig:Neck", B::Neck),
            ("mixamorig:Head", B::Head),
        ] {
            assert_eq!(humanoid_for(name), Some(bone), "{name}");
        }
        for name in [
            "mixamorig:HeadTop_End",
            "mixamorig:LeftHandThumb1",
            "mixamorig:LeftToe_End",
        ] {
            assert_eq!(humanoid_for(name), None, "{name}");
        }
    }

    #[test]
    fn vrm_and_vroid_names() {
        for bone in HumanBone::ALL {
            assert_eq!(
                humanoid_for(bone.vrm_name()),
                Some(bone),
                "{}",
                bone.vrm_name()
            );
        }
        for (name, bone) in [
            ("J_Bip_C_Hips", B::Hips),
            ("J_Bip_C_UpperChest", B::UpperChest),
            ("J_Bip_L_UpperArm", B::LeftUpperArm),
            ("J_Bip_R_LowerArm", B::RightLowerArm),
            ("J_Bip_L_ToeBase", B::LeftToes),
            ("J_Bip_R_Shoulder", B::RightShoulder),
        ] {
            assert_eq!(humanoid_for(name), Some(bone), "{name}");
        }
        assert_eq!(humanoid_for("J_Sec_Hair1_01"), None);
    }

    #[test]
    fn unreal_mannequin_names() {
        for (name, bone) in [
            ("pelvis", B::Hips),
            ("spine_01", B::Spine),
            ("spine_02", B::Chest),
            ("spine_03", B::UpperChest),
            ("neck_01", B::Neck),
            ("head", B::Head),
            ("clavicle_l", B::LeftShoulder),
            ("upperarm_l", B::LeftUpperArm),
            ("lowerarm_r", B::RightLowerArm),
            ("hand_l", B::LeftHand),
            ("thigh_r", B::RightUpperLeg),
            ("calf_l", B::LeftLowerLeg),
            ("foot_r", B::RightFoot),
            ("ball_l", B::LeftToes),
        ] {
            assert_eq!(humanoid_for(name), Some(bone), "{name}");
        }
        for name in [
            "upperarm_twist_01_l",
            "thigh_twist_01_r",
            "ik_foot_root",
            "root",
        ] {
            assert_eq!(humanoid_for(name), None, "{name}");
        }
    }

    #[test]
    fn rigify_deform_names() {
        for (name, bone) in [
            ("DEF-spine", B::Hips),
            ("DEF-spine.001", B::Spine),
            ("DEF-spine.003", B::UpperChest),
            ("DEF-spine.004", B::Neck),
            ("DEF-spine.006", B::Head),
            ("DEF-shoulder.L", B::LeftShoulder),
            ("DEF-upper_arm.L", B::LeftUpperArm),
            ("DEF-forearm.R", B::RightLowerArm),
            ("DEF-hand.L", B::LeftHand),
            ("DEF-thigh.L", B::LeftUpperLeg),
            ("DEF-shin.R", B::RightLowerLeg),
            ("DEF-foot.L", B::LeftFoot),
            ("DEF-toe.L", B::LeftToes),
        ] {
            assert_eq!(humanoid_for(name), Some(bone), "{name}");
        }
        for name in [
            "DEF-upper_arm.L.001",
            "DEF-spine.005",
            "DEF-thigh.R.001",
            "ORG-spine",
            "MCH-foot.L",
        ] {
            assert_eq!(humanoid_for(name), None, "{name}");
        }
    }

    #[test]
    fn smpl_names_alone() {
        for (name, bone) in [
            ("pelvis", B::Hips),
            ("left_hip", B::LeftUpperLeg),
            ("right_knee", B::RightLowerLeg),
            ("left_ankle", B::LeftFoot),
            ("spine1", B::Spine),
            ("spine2", B::Chest),
            ("spine3", B::UpperChest),
            ("neck", B::Neck),
            ("left_collar", B::LeftShoulder),
            ("right_elbow", B::RightLowerArm),
            ("left_wrist", B::LeftHand),
        ] {
            assert_eq!(humanoid_for(name), Some(bone), "{name}");
        }
    }

    fn skeleton(joints: &[(&str, Option<usize>)]) -> (Vec<String>, Vec<Option<usize>>) {
        (
            joints.iter().map(|j| j.0.to_string()).collect(),
            joints.iter().map(|j| j.1).collect(),
        )
    }

    fn mapped(names: &[String], bones: &[Option<HumanBone>]) -> BTreeMap<String, HumanBone> {
        names
            .iter()
            .zip(bones)
            .filter_map(|(n, b)| b.map(|b| (n.clone(), b)))
            .collect()
    }

    #[test]
    fn smpl_skeleton_shifts_shoulder_and_foot_down_the_limb() {
        let (names, parents) = skeleton(&[
            ("pelvis", None),
            ("left_hip", Some(0)),
            ("left_knee", Some(1)),
            ("left_ankle", Some(2)),
            ("left_foot", Some(3)),
            ("spine1", Some(0)),
            ("spine2", Some(5)),
            ("spine3", Some(6)),
            ("neck", Some(7)),
            ("head", Some(8)),
            ("left_collar", Some(7)),
            ("left_shoulder", Some(10)),
            ("left_elbow", Some(11)),
            ("left_wrist", Some(12)),
            ("left_hand", Some(13)),
        ]);
        let m = mapped(&names, &map_skeleton(&names, &parents, &BTreeMap::new()));
        assert_eq!(m["left_foot"], B::LeftToes);
        assert_eq!(m["left_ankle"], B::LeftFoot);
        assert_eq!(m["left_collar"], B::LeftShoulder);
        assert_eq!(m["left_shoulder"], B::LeftUpperArm);
        assert_eq!(m["left_wrist"], B::LeftHand);
        assert!(
            !m.contains_key("left_hand"),
            "SMPL's hand joint is past the wrist: {m:?}"
        );
        assert_eq!(
            (m["spine1"], m["spine2"], m["spine3"]),
            (B::Spine, B::Chest, B::UpperChest)
        );
    }

    #[test]
    fn five_unreal_spines_take_first_middle_last() {
        let (names, parents) = skeleton(&[
            ("pelvis", None),
            ("spine_01", Some(0)),
            ("spine_02", Some(1)),
            ("spine_03", Some(2)),
            ("spine_04", Some(3)),
            ("spine_05", Some(4)),
            ("neck_01", Some(5)),
        ]);
        let bones = map_skeleton(&names, &parents, &BTreeMap::new());
        assert_eq!(
            bones,
            vec![
                Some(B::Hips),
                Some(B::Spine),
                None,
                Some(B::Chest),
                None,
                Some(B::UpperChest),
                Some(B::Neck)
            ]
        );
    }

    #[test]
    fn mixamo_skeleton_spines_and_overrides() {
        let (names, parents) = skeleton(&[
            ("mixamorig:Hips", None),
            ("mixamorig:Spine", Some(0)),
            ("mixamorig:Spine1", Some(1)),
            ("mixamorig:Spine2", Some(2)),
            ("mixamorig:Neck", Some(3)),
            ("Bone.007", Some(4)),
        ]);
        let bones = map_skeleton(&names, &parents, &BTreeMap::new());
        assert_eq!(
            bones,
            vec![
                Some(B::Hips),
                Some(B::Spine),
                Some(B::Chest),
                Some(B::UpperChest),
                Some(B::Neck),
                None
            ]
        );
        let overrides = BTreeMap::from([
            ("Bone.007".to_string(), Some(B::Head)),
            ("mixamorig:Spine2".to_string(), None),
        ]);
        let bones = map_skeleton(&names, &parents, &overrides);
        assert_eq!(bones[5], Some(B::Head));
        assert_eq!(bones[3], None);
        // An override takes its bone from the joint that had it.
        let overrides = BTreeMap::from([("Bone.007".to_string(), Some(B::Neck))]);
        let bones = map_skeleton(&names, &parents, &overrides);
        assert_eq!((bones[4], bones[5]), (None, Some(B::Neck)));
    }

    #[test]
    fn a_shoulder_joint_that_goes_straight_to_the_elbow_is_the_upper_arm() {
        let (names, parents) = skeleton(&[
            ("body_centre", None),
            ("spine", Some(0)),
            ("left_shoulder", Some(1)),
            ("left_elbow", Some(2)),
            ("left_forearm", Some(3)),
            ("left_wrist", Some(4)),
            ("pelvis", Some(0)),
        ]);
        let m = mapped(&names, &map_skeleton(&names, &parents, &BTreeMap::new()));
        assert_eq!(m["left_shoulder"], B::LeftUpperArm);
        assert_eq!(m["left_elbow"], B::LeftLowerArm);
        assert!(
            !m.contains_key("left_forearm"),
            "the forearm marker repeats the lower arm: {m:?}"
        );
        assert_eq!(m["left_wrist"], B::LeftHand);
        assert_eq!(m["pelvis"], B::Hips);
    }

    #[test]
    fn twist_segments_repeating_a_bone_stay_unmapped() {
        let (names, parents) = skeleton(&[
            ("DEF-spine", None),
            ("DEF-upper_arm.L", Some(0)),
            ("DEF-upper_arm.L.001", Some(1)),
            ("DEF-forearm.L", Some(2)),
            ("forearm_l_twist", Some(3)),
        ]);
        let bones = map_skeleton(&names, &parents, &BTreeMap::new());
        assert_eq!(
            bones,
            vec![
                Some(B::Hips),
                Some(B::LeftUpperArm),
                None,
                Some(B::LeftLowerArm),
                None
            ]
        );
    }
}
