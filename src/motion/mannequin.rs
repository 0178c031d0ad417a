//! A mannequin made by code for any [`Rig`]: capsules on the bones, skinned to the skeleton, so
//! a glTF viewer shows a figure dancing rather than an empty armature.
//!
//! No third-party asset: every bone (parent `p` → joint `j`, longer than [`MIN_BONE_M`]) gets a
//! capsule from `p`'s rest position to `j`'s, its radius sized by the bone's length; the bones
//! into both ends of a left/right pair of siblings (shoulders, hips) get a bar between the two,
//! and a thick trunk joins the lowest bar to the highest; a bone between two joints whose names
//! say "head" is a head-sized capsule. Limbs are rigid: each vertex of a capsule on the bone
//! `p → j` is bound to `p` alone, because the forward kinematics moves that bone rigidly with
//! `p`'s frame (`pos[j] = pos[p] + rot[p] · offset[j]`), and a bar to the joint the pair hangs
//! from. Rigid pieces cannot candy-wrap; the round ends of neighbouring capsules overlap at the
//! joints, so no gap opens when a joint bends (a jointed artist's mannequin). Only the trunk
//! bends: it is bound to the hips' joint at the bottom and the shoulders' at the top, blended
//! smoothly along its side.
//!
//! The mesh is in the rest pose, the bind pose of the skin [`super::export::glb_bytes`] writes
//! (world rest position of each joint, identity rotations), so its inverse bind matrices are the
//! translations by minus the rest positions.
use std::collections::BTreeMap;

use gj::validation::{Checked::Valid, USize64};
use gltf_json as gj;
use nalgebra::Vector3;

use super::rig::Rig;
use super::MotionError;

/// Bones shorter than this get no capsule (branch joints that share their parent's position).
pub const MIN_BONE_M: f64 = 0.01;
/// Capsule radius as a fraction of the bone's length, and its bounds (metres).
const RADIUS_PER_LENGTH: f64 = 0.2;
const MIN_RADIUS_M: f64 = 0.02;
const MAX_RADIUS_M: f64 = 0.055;
/// Radius of the bar between a left/right pair (shoulders, hips).
const BAR_RADIUS_M: f64 = 0.06;
/// Radius of a bone between two head joints.
const HEAD_RADIUS_M: f64 = 0.085;
/// Vertices around a capsule, and rings on each of its round ends.
const AROUND: usize = 12;
const END_RINGS: usize = 4;
/// Rings along the trunk's side, where its two joints blend.
const TRUNK_RINGS: usize = 6;

/// A skinned triangle mesh in the rest pose.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    /// Rest-pose vertex positions, metres, y up.
    pub positions: Vec<[f32; 3]>,
    /// Unit normals.
    pub normals: Vec<[f32; 3]>,
    /// The two rig joints each vertex follows (the same one twice for a rigid piece)...
    pub joints: Vec<[u16; 2]>,
    /// ... and the second one's weight (the first has the rest).
    pub weights: Vec<f32>,
    /// Triangles, counter-clockwise seen from outside.
    pub indices: Vec<u32>,
}

/// World rest position of every joint (identity rotations): the bind pose.
pub fn rest_positions(rig: &Rig) -> Vec<Vector3<f64>> {
    let mut rest = vec![Vector3::zeros(); rig.names.len()];
    for j in rig.order() {
        rest[j] = match rig.parents[j] {
            None => rig.offsets[j],
            Some(p) => rest[p] + rig.offsets[j],
        };
    }
    rest
}

fn is_head(name: &str) -> bool {
    name.to_ascii_lowercase().contains("head")
}

/// Whether two sibling names are a left/right pair (`left_hip`/`right_hip`, `LeftArm`/`RightArm`,
/// `thigh_l`/`thigh_r`, `DEF-thigh.L`/`DEF-thigh.R`).
fn mirrored(a: &str, b: &str) -> bool {
    let (a, b) = (a.to_ascii_lowercase(), b.to_ascii_lowercase());
    if a == b {
        return false;
    }
    if a.replace("left", "right") == b || b.replace("left", "right") == a {
        return true;
    }
    let swap_suffix = |s: &str| -> Option<String> {
        for (l, r) in [("_l", "_r"), (".l", ".r"), ("_r", "_l"), (".r", ".l")] {
            if let Some(stem) = s.strip_suffix(l) {
                return Some(format!("{stem}{r}"));
            }
        }
        None
    };
    swap_suffix(&a).as_deref() == Some(b.as_str())
}

impl Mesh {
    /// Appends a capsule from `a` to `b` of radius `r`, every vertex bound to `joint`.
    fn capsule(&mut self, a: Vector3<f64>, b: Vector3<f64>, r: f64, joint: u16) {
        self.blended_capsule(a, b, r, (joint, joint), 0);
    }

    /// Appends a capsule from `a` to `b` of radius `r` with `mid_rings` rings along its side,
    /// its vertices bound to `joints.0` at `a`'s end and to `joints.1` at `b`'s, blended
    /// smoothly in between.
    fn blended_capsule(
        &mut self,
        a: Vector3<f64>,
        b: Vector3<f64>,
        r: f64,
        joints: (u16, u16),
        mid_rings: usize,
    ) {
        use std::f64::consts::{FRAC_PI_2, TAU};
        let axis = b - a;
        let len = axis.norm();
        let w = if len > 1e-9 { axis / len } else { Vector3::y() };
        // Any two unit vectors perpendicular to the axis and to each other.
        let helper = if w.x.abs() < 0.9 {
            Vector3::x()
        } else {
            Vector3::z()
        };
        let u = w.cross(&helper).normalize();
        let v = w.cross(&u);
        let base = self.positions.len() as u32;
        // Rings from the pole behind `a` to the pole past `b`: latitude −90° … 0° around `a`,
        // the side rings, then 0° … 90° around `b`. Each: (centre, latitude, share of `b`'s joint).
        let mut rings: Vec<(Vector3<f64>, f64, f64)> = Vec::new();
        for k in 0..=END_RINGS {
            rings.push((a, -FRAC_PI_2 * (1.0 - k as f64 / END_RINGS as f64), 0.0));
        }
        for k in 1..=mid_rings {
            let t = k as f64 / (mid_rings + 1) as f64;
            rings.push((a + axis * t, 0.0, t * t * (3.0 - 2.0 * t)));
        }
        for k in 0..=END_RINGS {
            rings.push((b, FRAC_PI_2 * (k as f64 / END_RINGS as f64), 1.0));
        }
        for &(centre, lat, share) in &rings {
            for k in 0..AROUND {
                let lon = TAU * k as f64 / AROUND as f64;
                let n = w * lat.sin() + (u * lon.cos() + v * lon.sin()) * lat.cos();
                let p = centre + n * r;
                self.positions.push([p.x as f32, p.y as f32, p.z as f32]);
                self.normals.push([n.x as f32, n.y as f32, n.z as f32]);
                self.joints.push([joints.0, joints.1]);
                self.weights.push(share as f32);
            }
        }
        for ring in 0..rings.len() - 1 {
            for k in 0..AROUND {
                let k2 = (k + 1) % AROUND;
                let (i0, i1) = (
                    base + (ring * AROUND + k) as u32,
                    base + (ring * AROUND + k2) as u32,
                );
                let (j0, j1) = (i0 + AROUND as u32, i1 + AROUND as u32);
                // (u, v, w) is right-handed and rings climb along w: this winding faces out.
                self.indices.extend_from_slice(&[i0, i1, j1, i0, j1, j0]);
            }
        }
    }
}

/// The mannequin of `rig` in its rest pose (module doc).
pub fn build(rig: &Rig) -> Result<Mesh, MotionError> {
    let n = rig.names.len();
    if n > usize::from(u16::MAX) {
        return Err(MotionError::Export(format!(
            "{n} joints: a skin's joint index is 16 bits"
        )));
    }
    let rest = rest_positions(rig);
    let mut mesh = Mesh::default();
    for j in rig.order() {
        let Some(p) = rig.parents[j] else { continue };
        let len = rig.offsets[j].norm();
        if len < MIN_BONE_M {
            continue;
        }
        let r = if is_head(&rig.names[p]) && is_head(&rig.names[j]) {
            HEAD_RADIUS_M
        } else {
            (RADIUS_PER_LENGTH * len).clamp(MIN_RADIUS_M, MAX_RADIUS_M)
        };
        mesh.capsule(rest[p], rest[j], r, p as u16);
    }
    // Bars between left/right siblings, bound to the joint they hang from.
    let mut children: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
    // (joint, middle, width) of each bar.
    let mut bars: Vec<(usize, Vector3<f64>, f64)> = Vec::new();
    for (j, p) in rig.parents.iter().enumerate() {
        if let Some(p) = p {
            children.entry(*p).or_default().push(j);
        }
    }
    for (&p, kids) in &children {
        for (i, &a) in kids.iter().enumerate() {
            for &b in &kids[i + 1..] {
                if mirrored(&rig.names[a], &rig.names[b])
                    && (rest[a] - rest[b]).norm() >= MIN_BONE_M
                {
                    mesh.capsule(rest[a], rest[b], BAR_RADIUS_M, p as u16);
                    bars.push((p, (rest[a] + rest[b]) / 2.0, (rest[a] - rest[b]).norm()));
                }
            }
        }
    }
    // The trunk: from the lowest bar's middle (the hips) to the highest's (the shoulders), bound
    // to the lower bar's joint at the bottom and the upper's at the top, blended between.
    if let (Some(low), Some(high)) = (
        bars.iter().min_by(|x, y| x.1.y.total_cmp(&y.1.y)),
        bars.iter().max_by(|x, y| x.1.y.total_cmp(&y.1.y)),
    ) {
        if (high.1 - low.1).norm() >= 0.1 {
            let r = (0.6 * 0.5 * low.2.max(high.2)).clamp(0.07, 0.14);
            mesh.blended_capsule(low.1, high.1, r, (low.0 as u16, high.0 as u16), TRUNK_RINGS);
        }
    }
    Ok(mesh)
}

/// Appends `bytes` to the binary chunk (4-byte aligned) as one buffer view.
fn view(
    root: &mut gj::Root,
    bin: &mut Vec<u8>,
    bytes: &[u8],
    target: gj::buffer::Target,
) -> gj::Index<gj::buffer::View> {
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let offset = bin.len();
    bin.extend_from_slice(bytes);
    root.push(gj::buffer::View {
        buffer: gj::Index::new(0),
        byte_length: USize64::from(bytes.len()),
        byte_offset: Some(USize64::from(offset)),
        byte_stride: None,
        name: None,
        target: Some(Valid(target)),
        extensions: None,
        extras: Default::default(),
    })
}

fn accessor(
    root: &mut gj::Root,
    view: gj::Index<gj::buffer::View>,
    count: usize,
    component: gj::accessor::ComponentType,
    type_: gj::accessor::Type,
    min_max: Option<([f32; 3], [f32; 3])>,
) -> gj::Index<gj::Accessor> {
    let (min, max) = match min_max {
        Some((lo, hi)) => (Some(serde_json::json!(lo)), Some(serde_json::json!(hi))),
        None => (None, None),
    };
    root.push(gj::Accessor {
        buffer_view: Some(view),
        byte_offset: None,
        count: USize64::from(count),
        component_type: Valid(gj::accessor::GenericComponentType(component)),
        extensions: None,
        extras: Default::default(),
        type_: Valid(type_),
        min,
        max,
        name: None,
        normalized: false,
        sparse: None,
    })
}

/// Adds the mannequin of `rig` to a glTF document whose nodes `0..J` are the rig's joints and
/// whose `skin` binds them in the rest pose: the mesh, a material, and a node (in `scene`'s root
/// nodes, untransformed, as skinned meshes must be) that carries both. Buffer data goes to `bin`,
/// the binary chunk of buffer 0.
pub fn attach(
    root: &mut gj::Root,
    bin: &mut Vec<u8>,
    rig: &Rig,
    skin: gj::Index<gj::Skin>,
    scene: gj::Index<gj::Scene>,
) -> Result<(), MotionError> {
    use gj::accessor::{ComponentType as C, Type as T};
    let mesh = build(rig)?;
    if mesh.positions.is_empty() {
        return Ok(());
    }
    let count = mesh.positions.len();
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for p in &mesh.positions {
        for c in 0..3 {
            lo[c] = lo[c].min(p[c]);
            hi[c] = hi[c].max(p[c]);
        }
    }
    let f32s =
        |v: &[[f32; 3]]| -> Vec<u8> { v.iter().flatten().flat_map(|x| x.to_le_bytes()).collect() };
    let array = gj::buffer::Target::ArrayBuffer;
    let v = view(root, bin, &f32s(&mesh.positions), array);
    let position = accessor(root, v, count, C::F32, T::Vec3, Some((lo, hi)));
    let v = view(root, bin, &f32s(&mesh.normals), array);
    let normal = accessor(root, v, count, C::F32, T::Vec3, None);
    let joints: Vec<u8> = mesh
        .joints
        .iter()
        .flat_map(|&[a, b]| [a, b, 0, 0])
        .flat_map(u16::to_le_bytes)
        .collect();
    let v = view(root, bin, &joints, array);
    let joints = accessor(root, v, count, C::U16, T::Vec4, None);
    let weights: Vec<u8> = mesh
        .weights
        .iter()
        .flat_map(|&w| [1.0 - w, w, 0.0, 0.0])
        .flat_map(f32::to_le_bytes)
        .collect();
    let v = view(root, bin, &weights, array);
    let weights = accessor(root, v, count, C::F32, T::Vec4, None);
    let indices: Vec<u8> = mesh.indices.iter().flat_map(|i| i.to_le_bytes()).collect();
    let v = view(root, bin, &indices, gj::buffer::Target::ElementArrayBuffer);
    let indices = accessor(root, v, mesh.indices.len(), C::U32, T::Scalar, None);

    let material = root.push(gj::Material {
        name: Some("mannequin".into()),
        pbr_metallic_roughness: gj::material::PbrMetallicRoughness {
            base_color_factor: gj::material::PbrBaseColorFactor([0.78, 0.80, 0.86, 1.0]),
            metallic_factor: gj::material::StrengthFactor(0.0),
            roughness_factor: gj::material::StrengthFactor(0.6),
            ..Default::default()
        },
        ..Default::default()
    });
    let attributes = BTreeMap::from([
        (Valid(gj::mesh::Semantic::Positions), position),
        (Valid(gj::mesh::Semantic::Normals), normal),
        (Valid(gj::mesh::Semantic::Joints(0)), joints),
        (Valid(gj::mesh::Semantic::Weights(0)), weights),
    ]);
    let mesh = root.push(gj::Mesh {
        extensions: None,
        extras: Default::default(),
        name: Some("mannequin".into()),
        primitives: vec![gj::mesh::Primitive {
            attributes,
            extensions: None,
            extras: Default::default(),
            indices: Some(indices),
            material: Some(material),
            mode: Valid(gj::mesh::Mode::Triangles),
            targets: None,
        }],
        weights: None,
    });
    let node = root.push(gj::Node {
        name: Some("mannequin".into()),
        mesh: Some(mesh),
        skin: Some(skin),
        ..Default::default()
    });
    root.scenes
        .get_mut(scene.value())
        .ok_or_else(|| {
            MotionError::Export("the glTF document has no scene for the mannequin".into())
        })?
        .nodes
        .push(node);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rig() -> Rig {
        let names = [
            "hips",
            "left_hip",
            "left_knee",
            "right_hip",
            "right_knee",
            "spine",
            "head",
            "head_top",
        ];
        Rig {
            names: names.iter().map(|s| s.to_string()).collect(),
            parents: vec![
                None,
                Some(0),
                Some(1),
                Some(0),
                Some(3),
                Some(0),
                Some(5),
                Some(6),
            ],
            offsets: vec![
                Vector3::new(0.0, 1.0, 0.0),
                Vector3::new(0.1, 0.0, 0.0),
                Vector3::new(0.0, -0.45, 0.0),
                Vector3::new(-0.1, 0.0, 0.0),
                Vector3::new(0.0, -0.45, 0.0),
                Vector3::new(0.0, 0.005, 0.0),
                Vector3::new(0.0, 0.5, 0.0),
                Vector3::new(0.0, 0.2, 0.0),
            ],
        }
    }

    #[test]
    fn every_bone_gets_a_capsule_bound_to_its_parent_and_pairs_a_bar() {
        let rig = rig();
        let mesh = build(&rig).expect("mesh");
        let per_capsule = 2 * (END_RINGS + 1) * AROUND;
        // Bones: two hips, two thighs, spine→head (the 5 mm hips→spine is skipped), the head;
        // one bar between the hips.
        assert_eq!(mesh.positions.len(), 7 * per_capsule);
        assert_eq!(
            mesh.indices.len(),
            7 * (2 * (END_RINGS + 1) - 1) * AROUND * 6
        );
        assert!(mesh
            .indices
            .iter()
            .all(|&i| (i as usize) < mesh.positions.len()));
        // The thigh (left_hip → left_knee) follows left_hip; the head capsule is head-sized.
        let rest = rest_positions(&rig);
        let thigh: Vec<_> = (0..mesh.positions.len())
            .filter(|&i| mesh.joints[i] == [1, 1])
            .collect();
        assert_eq!(thigh.len(), per_capsule);
        for &i in &thigh {
            let p = Vector3::from(mesh.positions[i].map(f64::from));
            let (a, b) = (rest[1], rest[2]);
            let t = ((p - a).dot(&(b - a)) / (b - a).norm_squared()).clamp(0.0, 1.0);
            let d = (p - (a + (b - a) * t)).norm();
            assert!((d - 0.055).abs() < 1e-4, "thigh vertex {d} m from its bone");
        }
        let head = (0..mesh.positions.len())
            .filter(|&i| mesh.joints[i] == [6, 6])
            .count();
        assert_eq!(head, per_capsule);
        for nrm in &mesh.normals {
            let l = (nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2]).sqrt();
            assert!((l - 1.0).abs() < 1e-4);
        }
    }

    #[test]
    fn left_right_pairs_are_found_in_every_convention() {
        assert!(mirrored("left_hip", "right_hip"));
        assert!(mirrored("mixamorig:LeftUpLeg", "mixamorig:RightUpLeg"));
        assert!(mirrored("thigh_l", "thigh_r"));
        assert!(mirrored("DEF-thigh.L", "DEF-thigh.R"));
        assert!(!mirrored("left_hip", "left_hip"));
        assert!(!mirrored("spine", "left_hip"));
    }
}
