//! The built-in `vrm` target and the VRM Animation (`.vrma`) file.
//!
//! # The target
//! VRM 1.0's humanoid bones (`VRMC_vrm.humanoid`: hips, spine, chest, upperChest, neck, head,
//! shoulders, upper and lower arms, hands, upper and lower legs, feet, toes) on the reference
//! body ([`super::body`]) in the T-pose, facing +z as VRM 1.0 avatars do. Nodes are named by the
//! bone (`leftUpperArm`).
//!
//! # The file (`VRMC_vrm_animation` 1.0)
//! A glTF 2.0 binary whose root carries `extensions.VRMC_vrm_animation = {specVersion: "1.0",
//! humanoid: {humanBones: {hips: {node: 0}, …}}}`, one node per joint in the rest pose (each
//! node's `translation` its rest offset, no rotation), and one animation: the hips' translation
//! and every humanoid bone's rotation.
//!
//! Why the rest nodes carry no rotation: `@pixiv/three-vrm-animation` maps each track onto the
//! avatar's *normalized* bones as `p · a · c⁻¹`, with `c` the bone's and `p` its humanoid
//! parent's world rotation in the file's rest pose; normalized bones have identity rotations in
//! the T-pose. With identity rest rotations `p = c = 1`, so the tracks are exactly the local
//! rotations of a T-pose skeleton: what [`super::retarget`] computes for this target. The hips'
//! translation is read as a world position and scaled by the avatar's hips height over the
//! file's (the hips node's rest height), so the dance keeps its feet on any avatar's floor.
use serde_json::json;

use super::body::{self, BodyJoint};
use super::{RetargetError, TargetSkeleton};
use crate::motion::rig::RigMotion;

/// The extension's name.
pub const EXTENSION: &str = "VRMC_vrm_animation";

fn name(joint: &BodyJoint) -> String {
    match joint.bone {
        Some(b) => b.vrm_name().to_string(),
        // End points are plain nodes: headTop_end, leftToes_end.
        None => match joint.key {
            "head_top" => "head_end".into(),
            "left_toe_end" => "leftToes_end".into(),
            "right_toe_end" => "rightToes_end".into(),
            other => other.to_string(),
        },
    }
}

/// The `vrm` target: VRM 1.0 humanoid bones, T-pose, metres, in an armature called `Armature`
/// (what the VRM add-on for Blender calls an imported avatar's).
pub fn vrm() -> TargetSkeleton {
    body::skeleton(super::DEFAULT_ARMATURE, name)
}

/// The `.vrma` bytes of a motion retargeted onto a T-pose target (normally [`vrm`]); joints with
/// a humanoid bone are listed in the extension and animated.
pub fn vrma_bytes(m: &RigMotion, target: &TargetSkeleton) -> Result<Vec<u8>, RetargetError> {
    let err = |reason: String| RetargetError::Write {
        format: "vrma",
        reason,
    };
    let n = m.rig.names.len();
    let t_len = m.num_frames();
    if t_len == 0 {
        return Err(RetargetError::EmptyMotion);
    }
    if target.humanoid.len() != n || target.rig.names != m.rig.names {
        return Err(err("the motion is not on the target's skeleton".into()));
    }
    let order = m.rig.order();
    let root = order[0];
    let mut bin = Bin::default();
    let times: Vec<f32> = (0..t_len).map(|t| (t as f64 / m.fps) as f32).collect();
    let input = bin.accessor(
        &times,
        "SCALAR",
        t_len,
        Some((json!([0.0]), json!([times[t_len - 1]]))),
    );

    let nodes: Vec<serde_json::Value> = (0..n)
        .map(|j| {
            let o = m.rig.offsets[j];
            let mut node = json!({ "name": m.rig.names[j], "translation": [o.x as f32, o.y as f32, o.z as f32] });
            let kids = m.rig.children(j);
            if !kids.is_empty() {
                node["children"] = json!(kids);
            }
            node
        })
        .collect();
    // The hips stand at their rest height over the floor (y = 0 in every retargeted motion): the
    // loader scales the hips' track by the avatar's hips height over this one.
    let mut nodes = nodes;
    let rest = crate::motion::rig::fk_frame(
        &m.rig,
        &nalgebra::Vector3::zeros(),
        &vec![nalgebra::UnitQuaternion::identity(); n],
    )
    .0;
    let floor = rest.iter().map(|p| p.y).fold(f64::INFINITY, f64::min);
    nodes[root]["translation"] = json!([0.0, (rest[root].y - floor) as f32, 0.0]);

    let mut samplers = Vec::new();
    let mut channels = Vec::new();
    let mut channel = |output: usize, node: usize, path: &str| {
        channels
            .push(json!({ "sampler": samplers.len(), "target": { "node": node, "path": path } }));
        samplers.push(json!({ "input": input, "output": output, "interpolation": "LINEAR" }));
    };
    let track: Vec<f32> = m
        .root_translation
        .iter()
        .flat_map(|r| {
            let p = r + m.rig.offsets[root];
            [p.x as f32, p.y as f32, p.z as f32]
        })
        .collect();
    channel(
        bin.accessor(&track, "VEC3", t_len, None),
        root,
        "translation",
    );
    let mut human_bones = serde_json::Map::new();
    for j in 0..n {
        let Some(b) = target.humanoid[j] else {
            continue;
        };
        human_bones.insert(b.vrm_name().into(), json!({ "node": j }));
        let track: Vec<f32> = m
            .rotations
            .iter()
            .flat_map(|f| {
                let c = f[j].coords;
                [c[0] as f32, c[1] as f32, c[2] as f32, c[3] as f32]
            })
            .collect();
        channel(bin.accessor(&track, "VEC4", t_len, None), j, "rotation");
    }
    if !human_bones.contains_key("hips") || target.humanoid[root].is_none() {
        return Err(err("the hips must be the root joint".into()));
    }
    let doc = json!({
        "asset": { "version": "2.0", "generator": format!("choreo {}", env!("CARGO_PKG_VERSION")) },
        "extensionsUsed": [EXTENSION],
        "extensions": { EXTENSION: { "specVersion": "1.0", "humanoid": { "humanBones": human_bones } } },
        "scene": 0,
        "scenes": [{ "nodes": [root] }],
        "nodes": nodes,
        "animations": [{ "name": "dance", "channels": channels, "samplers": samplers }],
        "accessors": bin.accessors,
        "bufferViews": bin.views,
        "buffers": [{ "byteLength": bin.data.len() }],
    });
    let json = serde_json::to_vec(&doc).map_err(|e| err(e.to_string()))?;
    glb(json, bin.data).map_err(err)
}

/// A glTF binary buffer being filled: its bytes, buffer views and accessors.
#[derive(Default)]
struct Bin {
    data: Vec<u8>,
    views: Vec<serde_json::Value>,
    accessors: Vec<serde_json::Value>,
}

impl Bin {
    /// Appends f32 data as one buffer view and accessor; returns the accessor's index.
    fn accessor(
        &mut self,
        values: &[f32],
        type_: &str,
        count: usize,
        min_max: Option<(serde_json::Value, serde_json::Value)>,
    ) -> usize {
        let offset = self.data.len();
        for v in values {
            self.data.extend_from_slice(&v.to_le_bytes());
        }
        self.views
            .push(json!({ "buffer": 0, "byteOffset": offset, "byteLength": values.len() * 4 }));
        let mut acc = json!({ "bufferView": self.views.len() - 1, "componentType": 5126, "count": count, "type": type_ });
        if let Some((min, max)) = min_max {
            acc["min"] = min;
            acc["max"] = max;
        }
        self.accessors.push(acc);
        self.accessors.len() - 1
    }
}

/// Packs a glTF JSON document and its binary buffer as a .glb (both chunks padded to 4 bytes).
pub(super) fn glb(mut json: Vec<u8>, mut bin: Vec<u8>) -> Result<Vec<u8>, String> {
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let len =
        |n: usize| u32::try_from(n).map_err(|_| format!("glb of {total} bytes exceeds 4 GiB"));
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&len(total)?.to_le_bytes());
    out.extend_from_slice(&len(json.len())?.to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json);
    out.extend_from_slice(&len(bin.len())?.to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&bin);
    Ok(out)
}
