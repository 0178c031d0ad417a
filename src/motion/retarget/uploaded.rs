//! A target skeleton read from a user's file: a BVH or a glb whose skeleton stands in its rest
//! pose (T- or A-pose), mapped onto humanoid bones by name ([`super::names`]) or by an explicit
//! mapping.
//!
//! - **BVH**: the hierarchy's `OFFSET`s are the rest pose, already in the form a
//!   [`TargetSkeleton`] keeps (offsets in the parent's frame, rest rotations identity); the
//!   frames are not read (the `MOTION` header's claim is checked, so a file claiming more
//!   frames than it holds is refused), and a file with a hierarchy but no `MOTION` is read too.
//! - **glb** (or a `.gltf` JSON): the skeleton is the skin's joints (the skin with the most joints
//!   when there are several), each joint's parent its nearest ancestor node that is a joint too;
//!   the rest pose is the joints' node transforms as stored (not the animation), with every node
//!   above them applied. It is baked to the BVH form: each offset is the joint's world rest
//!   position less its parent's, so the rotations and scales of the rest nodes (Mixamo's 0.01
//!   armature scale, a Blender export's axis turn) end up in the offsets.
//!
//! **Units**: glTF is metres and BVH has none, so both are read by the rest pose's height (the
//! spread of the joints' world heights, y up): 0.3–3 is metres, 30–300 centimetres, 300–3000
//! millimetres, scaled to metres; anything else is refused (a height no humanoid has in any unit).
//!
//! The skeleton must have the bones a dance needs ([`REQUIRED`]); a rig that lacks one is
//! refused, naming the bones it could not map and the joints left unmapped.
use std::collections::{BTreeMap, BTreeSet};

use super::gltf_skin::{glb_json, read_gltf};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::names::map_skeleton;
use super::{HumanBone, TargetSkeleton};
use crate::motion::bvh::Bvh;
use crate::motion::rig::Rig;

/// Most joints an uploaded skeleton may have: the BVH reader's own cap, which glTF skins are
/// held to as well.
pub const MAX_JOINTS: usize = crate::motion::bvh::MAX_BVH_JOINTS;
pub use super::gltf_skin::MAX_NODES;

/// The humanoid bones a dance needs: the legs and feet it stands on, the trunk and head it faces
/// with, and the arms it moves. Shoulders, chest, neck, hands and toes are driven when present.
pub const REQUIRED: [HumanBone; 13] = [
    HumanBone::Hips,
    HumanBone::Spine,
    HumanBone::Head,
    HumanBone::LeftUpperLeg,
    HumanBone::LeftLowerLeg,
    HumanBone::LeftFoot,
    HumanBone::RightUpperLeg,
    HumanBone::RightLowerLeg,
    HumanBone::RightFoot,
    HumanBone::LeftUpperArm,
    HumanBone::LeftLowerArm,
    HumanBone::RightUpperArm,
    HumanBone::RightLowerArm,
];

/// The kind of file a rig came in, found from its bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum RigFormat {
    Bvh,
    Glb,
}

impl RigFormat {
    /// The stored file's extension.
    pub fn extension(self) -> &'static str {
        match self {
            RigFormat::Bvh => "bvh",
            RigFormat::Glb => "glb",
        }
    }
}

/// The length unit a file's rest pose was read in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum Units {
    M,
    Cm,
    Mm,
}

impl Units {
    fn to_metres(self) -> f64 {
        match self {
            Units::M => 1.0,
            Units::Cm => 0.01,
            Units::Mm => 0.001,
        }
    }
}

/// Why a file could not become a target skeleton.
#[derive(Debug, thiserror::Error)]
pub enum RigFileError {
    #[error("the file is neither a BVH (text starting with HIERARCHY) nor a glb/glTF")]
    UnknownFormat,
    #[error("BVH: {0}")]
    Bvh(String),
    #[error("glTF: {0}")]
    Gltf(String),
    #[error("{0} is not a finite number")]
    NotFinite(String),
    #[error("the glTF has no skin: export the armature with its mesh (a skin lists the skeleton's joints)")]
    NoSkin,
    #[error("the skeleton has {count} joints; at most {limit} are read")]
    TooManyJoints { count: usize, limit: usize },
    #[error("the skeleton has {0} root joints ({1}); a rig has one root")]
    SeveralRoots(usize, String),
    #[error("joint name {0:?} appears twice; joint names must be unique")]
    DuplicateName(String),
    #[error("the rest pose is {height:.3} units tall, no humanoid height in metres, centimetres or millimetres")]
    Scale { height: f64 },
    #[error("`mapping` names joint {0:?}, which the skeleton does not have")]
    UnknownJoint(String),
    #[error("the skeleton has no joint for {missing}; name the joints in `mapping` (joint name → humanoid bone) — unmapped joints: {unmapped}")]
    Unmapped { missing: String, unmapped: String },
}

impl RigFileError {
    /// Stable kebab-case code.
    pub fn code(&self) -> &'static str {
        match self {
            RigFileError::UnknownFormat => "rig-format",
            RigFileError::Bvh(_) => "rig-bvh",
            RigFileError::Gltf(_) => "rig-gltf",
            RigFileError::NotFinite(_) => "motion-not-finite",
            RigFileError::NoSkin => "rig-no-skin",
            RigFileError::TooManyJoints { .. } => "rig-too-many-joints",
            RigFileError::SeveralRoots(..) => "rig-several-roots",
            RigFileError::DuplicateName(_) => "rig-duplicate-joint",
            RigFileError::Scale { .. } => "rig-scale",
            RigFileError::UnknownJoint(_) => "rig-mapping-unknown-joint",
            RigFileError::Unmapped { .. } => "rig-unmapped",
        }
    }

    /// Whether the bytes are not a rig file at all (415) rather than a rig we cannot use (422).
    pub fn is_unsupported_media(&self) -> bool {
        match self {
            RigFileError::UnknownFormat => true,
            RigFileError::Bvh(_)
            | RigFileError::Gltf(_)
            | RigFileError::NotFinite(_)
            | RigFileError::NoSkin
            | RigFileError::TooManyJoints { .. }
            | RigFileError::SeveralRoots(..)
            | RigFileError::DuplicateName(_)
            | RigFileError::Scale { .. }
            | RigFileError::UnknownJoint(_)
            | RigFileError::Unmapped { .. } => false,
        }
    }

    /// The request field at fault.
    pub fn field(&self) -> &'static str {
        match self {
            RigFileError::UnknownJoint(_) | RigFileError::Unmapped { .. } => "mapping",
            RigFileError::UnknownFormat
            | RigFileError::Bvh(_)
            | RigFileError::Gltf(_)
            | RigFileError::NotFinite(_)
            | RigFileError::NoSkin
            | RigFileError::TooManyJoints { .. }
            | RigFileError::SeveralRoots(..)
            | RigFileError::DuplicateName(_)
            | RigFileError::Scale { .. } => "file",
        }
    }
}

/// A skeleton read from a file, before mapping: names, parents and world rest positions in the
/// file's units.
pub(super) struct Raw {
    pub(super) names: Vec<String>,
    pub(super) parents: Vec<Option<usize>>,
    pub(super) rest: Vec<Vector3<f64>>,
    /// The name of the node the skeleton hangs from (a glb's armature), if the file has one.
    pub(super) armature: Option<String>,
}

/// A file read into a target skeleton.
#[derive(Clone, Debug, PartialEq)]
pub struct ReadRig {
    pub format: RigFormat,
    pub units: Units,
    pub skeleton: TargetSkeleton,
}

/// What a [`TargetSkeleton`] is stored as (a row's JSON).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SkeletonJson {
    pub names: Vec<String>,
    /// −1 for the root.
    pub parents: Vec<i64>,
    /// Rest offsets in the parent's frame, metres.
    pub offsets: Vec<[f64; 3]>,
    pub humanoid: Vec<Option<HumanBone>>,
    /// The armature's name; rigs stored before it was kept read as [`super::DEFAULT_ARMATURE`].
    #[serde(default = "default_armature")]
    pub armature: String,
}

fn default_armature() -> String {
    super::DEFAULT_ARMATURE.to_string()
}

impl From<&TargetSkeleton> for SkeletonJson {
    fn from(s: &TargetSkeleton) -> Self {
        SkeletonJson {
            names: s.rig.names.clone(),
            parents: s
                .rig
                .parents
                .iter()
                .map(|p| p.map_or(-1, |p| p as i64))
                .collect(),
            offsets: s.rig.offsets.iter().map(|o| [o.x, o.y, o.z]).collect(),
            humanoid: s.humanoid.clone(),
            armature: s.armature.clone(),
        }
    }
}

impl TryFrom<SkeletonJson> for TargetSkeleton {
    type Error = String;
    fn try_from(s: SkeletonJson) -> Result<Self, String> {
        let n = s.names.len();
        if s.parents.len() != n || s.offsets.len() != n || s.humanoid.len() != n {
            return Err(format!(
                "{n} names but {} parents, {} offsets, {} bones",
                s.parents.len(),
                s.offsets.len(),
                s.humanoid.len()
            ));
        }
        let parents = s
            .parents
            .iter()
            .map(|&p| match p {
                -1 => Ok(None),
                p if p >= 0 && (p as usize) < n => Ok(Some(p as usize)),
                p => Err(format!("parent {p} out of range")),
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(TargetSkeleton {
            rig: Rig {
                names: s.names,
                parents,
                offsets: s
                    .offsets
                    .iter()
                    .map(|o| Vector3::new(o[0], o[1], o[2]))
                    .collect(),
            },
            humanoid: s.humanoid,
            armature: s.armature,
        })
    }
}

/// Reads `bytes` (BVH, glb or glTF JSON) into a target skeleton, mapping its joints by name with
/// `overrides` (joint name → bone, or `None` for no bone) applied over the names.
pub fn read(
    bytes: &[u8],
    overrides: &BTreeMap<String, Option<HumanBone>>,
) -> Result<ReadRig, RigFileError> {
    let (format, raw) = if bytes.starts_with(b"glTF") {
        (RigFormat::Glb, read_gltf(glb_json(bytes)?)?)
    } else {
        let text = std::str::from_utf8(bytes).map_err(|_| RigFileError::UnknownFormat)?;
        let text = text.trim_start_matches('\u{feff}').trim_start();
        if text.starts_with("HIERARCHY") {
            (RigFormat::Bvh, read_bvh(text)?)
        } else if text.starts_with('{') {
            (RigFormat::Glb, read_gltf(text.as_bytes())?)
        } else {
            return Err(RigFileError::UnknownFormat);
        }
    };
    let Raw {
        names,
        parents,
        rest,
        armature,
    } = raw;
    if names.len() > MAX_JOINTS {
        return Err(RigFileError::TooManyJoints {
            count: names.len(),
            limit: MAX_JOINTS,
        });
    }
    let mut seen = BTreeSet::new();
    for name in &names {
        if !seen.insert(name.as_str()) {
            return Err(RigFileError::DuplicateName(name.clone()));
        }
    }
    let roots: Vec<&str> = names
        .iter()
        .zip(&parents)
        .filter(|(_, p)| p.is_none())
        .map(|(n, _)| n.as_str())
        .collect();
    if roots.len() != 1 {
        return Err(RigFileError::SeveralRoots(roots.len(), roots.join(", ")));
    }
    for name in overrides.keys() {
        if !seen.contains(name.as_str()) {
            return Err(RigFileError::UnknownJoint(name.clone()));
        }
    }

    let (lo, hi) = rest
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p.y), hi.max(p.y))
        });
    let height = hi - lo;
    let units = match height {
        h if (0.3..3.0).contains(&h) => Units::M,
        h if (30.0..300.0).contains(&h) => Units::Cm,
        h if (300.0..3000.0).contains(&h) => Units::Mm,
        h => return Err(RigFileError::Scale { height: h }),
    };
    let scale = units.to_metres();
    let offsets = (0..names.len())
        .map(|j| match parents[j] {
            None => rest[j] * scale,
            Some(p) => (rest[j] - rest[p]) * scale,
        })
        .collect();
    let humanoid = map_skeleton(&names, &parents, overrides);
    let have: BTreeSet<HumanBone> = humanoid.iter().flatten().copied().collect();
    let missing: Vec<&str> = REQUIRED
        .iter()
        .filter(|b| !have.contains(b))
        .map(|b| b.vrm_name())
        .collect();
    if !missing.is_empty() {
        let unmapped: Vec<&str> = names
            .iter()
            .zip(&humanoid)
            .filter(|(_, b)| b.is_none())
            .map(|(n, _)| n.as_str())
            .take(40)
            .collect();
        return Err(RigFileError::Unmapped {
            missing: missing.join(", "),
            unmapped: unmapped.join(", "),
        });
    }
    Ok(ReadRig {
        format,
        units,
        skeleton: TargetSkeleton {
            rig: Rig {
                names,
                parents,
                offsets,
            },
            humanoid,
            // A glb's own armature name; a BVH has none (Blender names its import after the file).
            armature: armature.unwrap_or_else(default_armature),
        },
    })
}

fn read_bvh(text: &str) -> Result<Raw, RigFileError> {
    // The rest pose is the hierarchy: a MOTION section's claim is checked, its frames unread.
    let bvh = Bvh::parse_rest_pose(text).map_err(|e| match e {
        crate::motion::MotionError::NotFinite { line, what } => {
            RigFileError::NotFinite(format!("line {line}: {what}"))
        }
        e => RigFileError::Bvh(e.to_string()),
    })?;
    // The parser has held the joints to MAX_JOINTS.
    let n = bvh.names.len();
    let mut rest = vec![Vector3::zeros(); n];
    // The parser lists parents before their children.
    for j in 0..n {
        rest[j] = match bvh.parents[j] {
            None => bvh.offsets[j],
            Some(p) => rest[p] + bvh.offsets[j],
        };
    }
    Ok(Raw {
        names: bvh.names,
        parents: bvh.parents,
        rest,
        armature: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An Unreal-mannequin-named skeleton in centimetres (a hierarchy only), longer-legged than
    /// choreo's dancers: the fixture the API and page tests upload too.
    const UNREAL_BVH: &str = include_str!("../../../tests/fixtures/rig_unreal_cm.bvh");

    #[test]
    fn an_unreal_bvh_in_centimetres_is_read_in_metres_and_mapped() {
        let got = read(UNREAL_BVH.as_bytes(), &BTreeMap::new()).expect("read");
        assert_eq!((got.format, got.units), (RigFormat::Bvh, Units::Cm));
        let s = &got.skeleton;
        assert_eq!(s.rig.names.len(), 22);
        let at = |name: &str| s.rig.names.iter().position(|n| n == name).expect(name);
        assert!((s.rig.offsets[at("calf_l")] - Vector3::new(0.0, -0.45, 0.0)).norm() < 1e-12);
        assert!((s.rig.offsets[at("pelvis")] - Vector3::new(0.0, 0.95, 0.0)).norm() < 1e-12);
        assert_eq!(s.humanoid[at("spine_01")], Some(HumanBone::Spine));
        assert_eq!(s.humanoid[at("spine_03")], Some(HumanBone::UpperChest));
        assert_eq!(s.humanoid[at("ball_r")], Some(HumanBone::RightToes));
        assert_eq!(s.armature, super::super::DEFAULT_ARMATURE);
        // Round trip through the stored form.
        let back = TargetSkeleton::try_from(SkeletonJson::from(s)).expect("stored form");
        assert_eq!(&back, s);
    }

    #[test]
    fn a_skeleton_without_legs_is_refused_naming_the_bones() {
        let text = UNREAL_BVH.replace("thigh_l", "leg_thing_l");
        let err = read(text.as_bytes(), &BTreeMap::new()).expect_err("no left thigh");
        let msg = err.to_string();
        assert_eq!(err.code(), "rig-unmapped");
        assert!(
            msg.contains("leftUpperLeg") && msg.contains("leg_thing_l"),
            "{msg}"
        );
        // ... and accepted once the mapping names it.
        let overrides =
            BTreeMap::from([("leg_thing_l".to_string(), Some(HumanBone::LeftUpperLeg))]);
        let got = read(text.as_bytes(), &overrides).expect("mapped by hand");
        assert!(got
            .skeleton
            .humanoid
            .contains(&Some(HumanBone::LeftUpperLeg)));
        let bad = BTreeMap::from([("nope".to_string(), None)]);
        assert_eq!(
            read(text.as_bytes(), &bad)
                .expect_err("unknown joint")
                .code(),
            "rig-mapping-unknown-joint"
        );
    }

    #[test]
    fn junk_and_absurd_scales_are_refused() {
        assert_eq!(
            read(b"\x00\x01 not a rig", &BTreeMap::new())
                .expect_err("junk")
                .code(),
            "rig-format"
        );
        let tiny = UNREAL_BVH.replace("OFFSET 0 -45 0", "OFFSET 0 -45000 0");
        assert_eq!(
            read(tiny.as_bytes(), &BTreeMap::new())
                .expect_err("scale")
                .code(),
            "rig-scale"
        );
    }

    #[test]
    fn a_glb_rest_pose_is_baked_through_node_transforms() {
        // Mixamo-like: an armature node scaled by 0.01 and turned, joints in centimetres.
        let m = |name: &str, t: [f32; 3], children: &[u32]| {
            let kids: Vec<String> = children.iter().map(u32::to_string).collect();
            format!(
                r#"{{"name":"{name}","translation":[{},{},{}]{}}}"#,
                t[0],
                t[1],
                t[2],
                if kids.is_empty() {
                    String::new()
                } else {
                    format!(r#","children":[{}]"#, kids.join(","))
                }
            )
        };
        let mut nodes = vec![
            // 0: the armature, 0.01 scale and a quarter turn about y.
            r#"{"name":"Avatar","rotation":[0,0.70710677,0,0.70710677],"scale":[0.01,0.01,0.01],"children":[1]}"#.to_string(),
            m("mixamorig:Hips", [0.0, 100.0, 0.0], &[2, 5, 8]),
            m("mixamorig:LeftUpLeg", [10.0, -5.0, 0.0], &[3]),
            m("mixamorig:LeftLeg", [0.0, -45.0, 0.0], &[4]),
            m("mixamorig:LeftFoot", [0.0, -42.0, 0.0], &[]),
            m("mixamorig:RightUpLeg", [-10.0, -5.0, 0.0], &[6]),
            m("mixamorig:RightLeg", [0.0, -45.0, 0.0], &[7]),
            m("mixamorig:RightFoot", [0.0, -42.0, 0.0], &[]),
            m("mixamorig:Spine", [0.0, 10.0, 0.0], &[9]),
            m("mixamorig:Neck", [0.0, 40.0, 0.0], &[10, 11, 13]),
            m("mixamorig:Head", [0.0, 10.0, 0.0], &[]),
            m("mixamorig:LeftArm", [20.0, 0.0, 0.0], &[12]),
            m("mixamorig:LeftForeArm", [28.0, 0.0, 0.0], &[]),
            m("mixamorig:RightArm", [-20.0, 0.0, 0.0], &[14]),
            m("mixamorig:RightForeArm", [-28.0, 0.0, 0.0], &[]),
        ];
        nodes.push(r#"{"name":"Body","mesh":0,"skin":0}"#.to_string());
        let joints: Vec<String> = (1..15).map(|i: u32| i.to_string()).collect();
        let json = format!(
            r#"{{"asset":{{"version":"2.0"}},"nodes":[{}],"skins":[{{"joints":[{}]}}],"scenes":[{{"nodes":[0,15]}}]}}"#,
            nodes.join(","),
            joints.join(",")
        );
        let mut glb = Vec::new();
        let mut chunk = json.into_bytes();
        while chunk.len() % 4 != 0 {
            chunk.push(b' ');
        }
        glb.extend_from_slice(b"glTF");
        glb.extend_from_slice(&2u32.to_le_bytes());
        glb.extend_from_slice(&((20 + chunk.len()) as u32).to_le_bytes());
        glb.extend_from_slice(&(chunk.len() as u32).to_le_bytes());
        glb.extend_from_slice(&0x4E4F_534Au32.to_le_bytes());
        glb.extend_from_slice(&chunk);
        let got = read(&glb, &BTreeMap::new()).expect("read glb");
        assert_eq!((got.format, got.units), (RigFormat::Glb, Units::M));
        let s = &got.skeleton;
        // The node the skeleton hangs from names the armature, as in Blender.
        assert_eq!(s.armature, "Avatar");
        let at = |name: &str| s.rig.names.iter().position(|n| n == name).expect(name);
        // The quarter turn about y takes +x to −z: the left thigh's 10 cm along x is 0.1 m along −z.
        let thigh = s.rig.offsets[at("mixamorig:LeftUpLeg")];
        assert!(
            (thigh - Vector3::new(0.0, -0.05, -0.1)).norm() < 1e-6,
            "{thigh}"
        );
        assert_eq!(s.rig.parents[at("mixamorig:Hips")], None);
        assert_eq!(
            s.rig.parents[at("mixamorig:LeftLeg")],
            Some(at("mixamorig:LeftUpLeg"))
        );
        assert_eq!(
            s.humanoid[at("mixamorig:LeftForeArm")],
            Some(HumanBone::LeftLowerArm)
        );
        for (j, p) in s.rig.parents.iter().enumerate() {
            assert!(p.is_none_or(|p| p < j), "parents come first");
        }
    }
}
