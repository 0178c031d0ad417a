//! A rig's skeleton read from a glTF (or a glb's JSON chunk): the parts of the document it is
//! read from, its nodes and skins, with everything else skipped unread and kept compactly, and
//! the skin's joints baked into world rest positions ([`read_gltf`]).
//!
//! Written here rather than read through `gltf_json::Root` (which the exporter still uses to
//! write glb): `Root` deserializes the whole document, and every empty node `{}` becomes a struct
//! of a few hundred bytes, so a 9 MB file of three million empty nodes took 676 MB before it could
//! be refused. Here the other arrays (meshes, accessors, materials, …) go through serde's
//! `IgnoredAny`, which allocates nothing; nodes are counted as they are read and refused past
//! [`MAX_NODES`]; and a node costs 8 bytes (its children's range) plus what it actually carries (a
//! name, a transform, child indices), each no larger than the text that sent it. What is kept is
//! then a few times the bytes sent at most, whatever the file holds.
use nalgebra::{Matrix4, Quaternion, UnitQuaternion, Vector3};
use serde::de::{self, Deserializer, SeqAccess, Visitor};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::fmt;

use super::uploaded::{Raw, RigFileError, MAX_JOINTS};

/// Most nodes a glTF may have (a rigged, dressed avatar has a few thousand).
pub const MAX_NODES: usize = 65_536;
/// Deepest node nesting read in a glTF (deeper only exhausts the stack or the time).
const MAX_DEPTH: usize = 256;

/// A glTF document's nodes and skins.
#[derive(Default, Deserialize)]
pub struct Document {
    #[serde(default)]
    pub nodes: Nodes,
    #[serde(default)]
    pub skins: Vec<Skin>,
}

/// A skin: the nodes that are its joints, and its name.
#[derive(Deserialize)]
pub struct Skin {
    pub joints: Vec<u32>,
    #[serde(default)]
    pub name: Option<String>,
}

/// A node's local transform as stored.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Transform {
    /// Column-major 4 × 4.
    Matrix([f32; 16]),
    /// Translation, rotation (`[x, y, z, w]`), scale; each defaults to the identity's.
    Trs {
        translation: [f32; 3],
        rotation: [f32; 4],
        scale: [f32; 3],
    },
}

/// The nodes, compactly: per node the range of its children in one shared array; names and
/// transforms only for the nodes that have them, in node order.
#[derive(Default)]
pub struct Nodes {
    ranges: Vec<(u32, u32)>,
    children: Vec<u32>,
    names: Vec<(u32, String)>,
    transforms: Vec<(u32, Transform)>,
}

impl Nodes {
    /// How many nodes there are.
    pub fn count(&self) -> usize {
        self.ranges.len()
    }

    /// Node `i`'s children.
    pub fn children(&self, i: usize) -> &[u32] {
        self.ranges.get(i).map_or(&[], |&(start, len)| {
            &self.children[start as usize..(start + len) as usize]
        })
    }

    /// Node `i`'s name, if it has one.
    pub fn name(&self, i: usize) -> Option<&str> {
        find(&self.names, i).map(String::as_str)
    }

    /// Node `i`'s transform; `None` is the identity.
    pub fn transform(&self, i: usize) -> Option<&Transform> {
        find(&self.transforms, i)
    }
}

/// The value kept for node `i` in a list sorted by node.
fn find<T>(list: &[(u32, T)], i: usize) -> Option<&T> {
    let i = u32::try_from(i).ok()?;
    list.binary_search_by_key(&i, |(node, _)| *node)
        .ok()
        .map(|k| &list[k].1)
}

/// One node as sent, read on the stack before its parts are kept.
#[derive(Deserialize)]
struct Node {
    #[serde(default)]
    name: Option<String>,
    #[serde(default)]
    children: Vec<u32>,
    #[serde(default)]
    matrix: Option<[f32; 16]>,
    #[serde(default)]
    translation: Option<[f32; 3]>,
    #[serde(default)]
    rotation: Option<[f32; 4]>,
    #[serde(default)]
    scale: Option<[f32; 3]>,
}

impl<'de> Deserialize<'de> for Nodes {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        deserializer.deserialize_seq(NodesVisitor)
    }
}

struct NodesVisitor;

impl<'de> Visitor<'de> for NodesVisitor {
    type Value = Nodes;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "an array of at most {MAX_NODES} nodes")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Nodes, A::Error> {
        let mut nodes = Nodes::default();
        while let Some(node) = seq.next_element::<Node>()? {
            let i = nodes.ranges.len();
            if i == MAX_NODES {
                return Err(de::Error::custom(format!(
                    "more than {MAX_NODES} nodes; a rig has at most that many"
                )));
            }
            // Both fit in u32: nodes are capped, and children are fewer than the bytes sent.
            let start = nodes.children.len() as u32;
            nodes.children.extend_from_slice(&node.children);
            nodes.ranges.push((start, node.children.len() as u32));
            let i = i as u32;
            if let Some(name) = node.name {
                nodes.names.push((i, name));
            }
            let transform = match (node.matrix, node.translation, node.rotation, node.scale) {
                (Some(m), ..) => Some(Transform::Matrix(m)),
                (None, None, None, None) => None,
                (None, t, r, s) => Some(Transform::Trs {
                    translation: t.unwrap_or([0.0; 3]),
                    rotation: r.unwrap_or([0.0, 0.0, 0.0, 1.0]),
                    scale: s.unwrap_or([1.0; 3]),
                }),
            };
            if let Some(transform) = transform {
                nodes.transforms.push((i, transform));
            }
        }
        Ok(nodes)
    }
}

/// The JSON chunk of a glb.
pub(super) fn glb_json(bytes: &[u8]) -> Result<&[u8], RigFileError> {
    let u32_at = |i: usize| -> Option<u32> {
        Some(u32::from_le_bytes(bytes.get(i..i + 4)?.try_into().ok()?))
    };
    let bad = |why: &str| RigFileError::Gltf(format!("not a glb: {why}"));
    if u32_at(4) != Some(2) {
        return Err(bad("version is not 2"));
    }
    let len = u32_at(12).ok_or_else(|| bad("no JSON chunk"))? as usize;
    if u32_at(16) != Some(0x4E4F_534A) {
        return Err(bad("the first chunk is not JSON"));
    }
    bytes
        .get(20..20usize.saturating_add(len))
        .ok_or_else(|| bad("the JSON chunk is cut short"))
}

/// Node `i`'s local transform.
fn local_matrix(nodes: &Nodes, i: usize) -> Matrix4<f64> {
    match nodes.transform(i) {
        None => Matrix4::identity(),
        Some(Transform::Matrix(m)) => Matrix4::from_column_slice(&m.map(f64::from)),
        Some(Transform::Trs {
            translation,
            rotation,
            scale,
        }) => {
            let t = translation.map(f64::from);
            let r = rotation.map(f64::from);
            let s = scale.map(f64::from);
            let q = UnitQuaternion::from_quaternion(Quaternion::new(r[3], r[0], r[1], r[2]));
            Matrix4::new_translation(&Vector3::from(t))
                * q.to_homogeneous()
                * Matrix4::new_nonuniform_scaling(&Vector3::from(s))
        }
    }
}

pub(super) fn read_gltf(json: &[u8]) -> Result<Raw, RigFileError> {
    let root: Document =
        serde_json::from_slice(json).map_err(|e| RigFileError::Gltf(e.to_string()))?;
    let skin = root
        .skins
        .iter()
        .max_by_key(|s| s.joints.len())
        .ok_or(RigFileError::NoSkin)?;
    let joints: Vec<usize> = skin.joints.iter().map(|&j| j as usize).collect();
    if joints.len() > MAX_JOINTS {
        return Err(RigFileError::TooManyJoints {
            count: joints.len(),
            limit: MAX_JOINTS,
        });
    }
    let nodes = &root.nodes;
    // Each node's parent, `NO_PARENT` for a root: four bytes a node, as the nodes themselves.
    const NO_PARENT: u32 = u32::MAX;
    let mut node_parent: Vec<u32> = vec![NO_PARENT; nodes.count()];
    for i in 0..nodes.count() {
        for &c in nodes.children(i) {
            let c = c as usize;
            if c >= nodes.count() || node_parent[c] != NO_PARENT {
                return Err(RigFileError::Gltf(format!(
                    "node {c} is out of range or has two parents"
                )));
            }
            node_parent[c] = i as u32;
        }
    }
    let parent_of = |i: usize| {
        Some(node_parent[i])
            .filter(|&p| p != NO_PARENT)
            .map(|p| p as usize)
    };
    // Ancestors (nearest first) of a node, refusing cycles and absurd depth.
    let ancestors = |mut i: usize| -> Result<Vec<usize>, RigFileError> {
        let mut out = Vec::new();
        while let Some(p) = parent_of(i) {
            if out.len() >= MAX_DEPTH {
                return Err(RigFileError::Gltf(
                    "node hierarchy nested too deeply or cyclic".into(),
                ));
            }
            out.push(p);
            i = p;
        }
        Ok(out)
    };
    let index_of: BTreeMap<usize, usize> = joints
        .iter()
        .enumerate()
        .map(|(k, &node)| (node, k))
        .collect();
    if index_of.len() != joints.len() {
        return Err(RigFileError::Gltf("the skin lists a joint twice".into()));
    }
    let mut names = Vec::with_capacity(joints.len());
    let mut parents = Vec::with_capacity(joints.len());
    let mut rest = Vec::with_capacity(joints.len());
    for (k, &node) in joints.iter().enumerate() {
        if node >= nodes.count() {
            return Err(RigFileError::Gltf(format!(
                "skin joint {node} is not a node"
            )));
        }
        names.push(
            nodes
                .name(node)
                .map_or_else(|| format!("joint{k}"), str::to_string),
        );
        let up = ancestors(node)?;
        parents.push(up.iter().find_map(|a| index_of.get(a).copied()));
        let mut world = local_matrix(nodes, node);
        for &a in &up {
            world = local_matrix(nodes, a) * world;
        }
        let p = world.column(3);
        if !(p.x.is_finite() && p.y.is_finite() && p.z.is_finite()) {
            return Err(RigFileError::NotFinite(format!(
                "the rest position of joint {:?}",
                names[k]
            )));
        }
        rest.push(Vector3::new(p.x, p.y, p.z));
    }
    // Parents before children, as a rig lists them.
    let depth = |j: usize| {
        let mut d = 0;
        let mut cur = parents[j];
        while let Some(p) = cur {
            d += 1;
            cur = parents[p];
        }
        d
    };
    let mut order: Vec<usize> = (0..joints.len()).collect();
    order.sort_by_key(|&j| depth(j));
    let new_index: BTreeMap<usize, usize> = order
        .iter()
        .enumerate()
        .map(|(new, &old)| (old, new))
        .collect();
    // The armature as Blender's importer names it: the node the root joint hangs from, else the
    // skin.
    let armature = (0..joints.len())
        .find(|&k| parents[k].is_none())
        .and_then(|k| parent_of(joints[k]))
        .and_then(|node| nodes.name(node).map(str::to_string))
        .or_else(|| skin.name.clone())
        .filter(|n| !n.trim().is_empty());
    Ok(Raw {
        armature,
        names: order.iter().map(|&j| names[j].clone()).collect(),
        parents: order
            .iter()
            .map(|&j| parents[j].map(|p| new_index[&p]))
            .collect(),
        rest: order.iter().map(|&j| rest[j]).collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn other_parts_are_skipped_and_nodes_are_capped() {
        let doc: Document = serde_json::from_str(
            r#"{"asset": {"version": "2.0"}, "meshes": [{}, {}], "nodes": [{"name": "a", "children": [1], "extras": {"x": [1, 2]}}, {"translation": [0, 1, 0]}], "skins": [{"joints": [0, 1]}]}"#,
        )
        .expect("read");
        assert_eq!(doc.nodes.count(), 2);
        assert_eq!(doc.nodes.children(0), &[1]);
        assert_eq!(doc.nodes.children(1), &[] as &[u32]);
        assert_eq!((doc.nodes.name(0), doc.nodes.name(1)), (Some("a"), None));
        assert_eq!(doc.nodes.transform(0), None);
        assert_eq!(
            doc.nodes.transform(1),
            Some(&Transform::Trs {
                translation: [0.0, 1.0, 0.0],
                rotation: [0.0, 0.0, 0.0, 1.0],
                scale: [1.0; 3]
            })
        );
        assert_eq!(doc.skins[0].joints, vec![0, 1]);
        let many = format!("{{\"nodes\": [{}{{}}]}}", "{},".repeat(MAX_NODES));
        let err = serde_json::from_str::<Document>(&many)
            .err()
            .expect("refused");
        assert!(err.to_string().contains("more than 65536 nodes"), "{err}");
    }
}
