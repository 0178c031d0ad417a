//! Exports: BVH, JSON and glTF 2.0 (.glb) of one rigid skeleton, so all three formats agree.
//!
//! Every export goes through [`prepare`] (or [`prepare_with_root`] when the body centre is known,
//! as for dataset dances): fit the rig (median bone lengths) and solve its rotations
//! ([`super::rig`]). The JSON `positions` are the forward kinematics of exactly that rig and those
//! rotations, which the BVH and the glb carry too.
//!
//! The worker calls [`write_all`]; the API and the CLI can call [`bvh_string`], [`json_string`]
//! and [`glb_bytes`] on the prepared [`RigMotion`].
use std::io::Write as _;
use std::path::{Path, PathBuf};

use gj::validation::{Checked::Valid, USize64};
use gltf_json as gj;
use nalgebra::{UnitQuaternion, Vector3};
use ndarray::ArrayView2;
use serde::{Deserialize, Serialize};

use super::rig::{fit_and_solve_seeded, Aim, RigMotion};
use super::skeleton::body_centre_track;
use super::{Motion, MotionError};

/// A motion as JSON: what `GET …/motion.json` returns and tools outside the project read.
///
/// All lengths in metres, y up, right-handed; joints in `joint_names` order (the rig's: the body
/// centre first, then the 23 dataset joints, then the branch joints `pelvis` and `neck`).
#[derive(Clone, Debug, Serialize, Deserialize, utoipa::ToSchema)]
pub struct MotionJson {
    /// Frames per second.
    pub fps: f64,
    /// Number of frames `T`.
    pub num_frames: usize,
    /// Joint names, `J` of them.
    pub joint_names: Vec<String>,
    /// Parent index of each joint; −1 for the root.
    pub parents: Vec<i64>,
    /// Rest offset of each joint from its parent, in the parent's frame, metres: the rigid skeleton.
    pub offsets: Vec<[f32; 3]>,
    /// `[T][J][3]` world positions, metres, y up: forward kinematics of `offsets`,
    /// `root_translation` and `rotations`.
    pub positions: Vec<Vec<[f32; 3]>>,
    /// `[T][3]` world position of the root joint, metres.
    pub root_translation: Vec<[f32; 3]>,
    /// `[T][J][4]` local rotations relative to the parent, quaternions `x, y, z, w`.
    pub rotations: Vec<Vec<[f32; 4]>>,
}

/// Where [`write_all`] put the files.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ExportPaths {
    pub bvh: PathBuf,
    pub json: PathBuf,
    pub glb: PathBuf,
}

/// File names [`write_all`] uses.
pub const BVH_FILE: &str = "motion.bvh";
/// JSON file name.
pub const JSON_FILE: &str = "motion.json";
/// glb file name.
pub const GLB_FILE: &str = "motion.glb";

/// Fits the rigid skeleton of a motion whose body centre is unknown (generated motion): the root
/// is the weighted centroid of [`super::skeleton::CENTRE_WEIGHTS`].
pub fn prepare(motion: &Motion) -> Result<RigMotion, MotionError> {
    prepare_anchored(motion, &[])
}

/// As [`prepare`], with the skeleton fitted to the `anchors` frames (the user's key poses) when
/// there are any, and then every frame solved in least squares; see [`super::rig::fit_and_solve`].
pub fn prepare_anchored(motion: &Motion, anchors: &[usize]) -> Result<RigMotion, MotionError> {
    prepare_seeded(motion, anchors, 0)
}

/// [`prepare_anchored`] for a dance whose first `seed_frames` frames are the request's seed
/// motion: without key poses the skeleton is fitted on those frames alone, so the seed motion
/// comes back on its own body ([`fit_and_solve_seeded`]).
pub fn prepare_seeded(
    motion: &Motion,
    anchors: &[usize],
    seed_frames: usize,
) -> Result<RigMotion, MotionError> {
    let root = body_centre_track(motion.positions.view());
    // A served dance's angles are what it is judged by, its bone lengths the network's whim.
    prepare_root_anchored(motion, root.view(), anchors, seed_frames, Aim::DanceBones)
}

/// Fits the rigid skeleton of a motion around a known root track `[T, 3]` (carried exactly).
pub fn prepare_with_root(
    motion: &Motion,
    root: ArrayView2<'_, f32>,
) -> Result<RigMotion, MotionError> {
    prepare_root_anchored(motion, root, &[], 0, Aim::FittedEnds)
}

fn prepare_root_anchored(
    motion: &Motion,
    root: ArrayView2<'_, f32>,
    anchors: &[usize],
    seed_frames: usize,
    aim: Aim,
) -> Result<RigMotion, MotionError> {
    if motion.num_frames() == 0 {
        return Err(MotionError::Shape("motion has no frames".into()));
    }
    if !(motion.fps > 0.0 && motion.fps.is_finite()) {
        return Err(MotionError::Invalid(format!("invalid fps {}", motion.fps)));
    }
    let mut m = fit_and_solve_seeded(
        motion.positions.view(),
        root,
        motion.fps,
        anchors,
        seed_frames,
        aim,
    )?;
    make_continuous(&mut m);
    Ok(m)
}

/// Flips quaternion signs so each joint's rotation track never jumps hemispheres (q and −q are
/// the same rotation; interpolation and learning prefer the continuous one).
fn make_continuous(m: &mut RigMotion) {
    for t in 1..m.rotations.len() {
        let (prev, cur) = m.rotations.split_at_mut(t);
        for (p, c) in prev[t - 1].iter().zip(cur[0].iter_mut()) {
            if p.coords.dot(&c.coords) < 0.0 {
                *c = UnitQuaternion::new_unchecked(-c.into_inner());
            }
        }
    }
}

/// The JSON document of a prepared motion.
pub fn to_json(m: &RigMotion) -> MotionJson {
    let world = m.world_positions();
    let n = m.rig.names.len();
    let v3 = |v: &Vector3<f64>| [v.x as f32, v.y as f32, v.z as f32];
    MotionJson {
        fps: m.fps,
        num_frames: m.num_frames(),
        joint_names: m.rig.names.clone(),
        parents: m
            .rig
            .parents
            .iter()
            .map(|p| p.map_or(-1, |p| p as i64))
            .collect(),
        offsets: m.rig.offsets.iter().map(v3).collect(),
        positions: (0..m.num_frames())
            .map(|t| {
                (0..n)
                    .map(|j| {
                        [
                            world[[t, j, 0]] as f32,
                            world[[t, j, 1]] as f32,
                            world[[t, j, 2]] as f32,
                        ]
                    })
                    .collect()
            })
            .collect(),
        root_translation: m.root_translation.iter().map(v3).collect(),
        rotations: m
            .rotations
            .iter()
            .map(|frame| {
                frame
                    .iter()
                    .map(|q| {
                        let c = q.coords;
                        [c[0] as f32, c[1] as f32, c[2] as f32, c[3] as f32]
                    })
                    .collect()
            })
            .collect(),
    }
}

/// The JSON text of a prepared motion.
pub fn json_string(m: &RigMotion) -> Result<String, MotionError> {
    serde_json::to_string(&to_json(m)).map_err(|e| MotionError::Export(e.to_string()))
}

/// The BVH text of a prepared motion.
pub fn bvh_string(m: &RigMotion) -> Result<String, MotionError> {
    super::bvh::write_bvh(m)
}

/// The skin's name in choreo's own glb (what Blender names its armature).
pub const CHOREO_ARMATURE: &str = "choreo_skeleton";

/// The binary glTF 2.0 (.glb) of a prepared motion on choreo's rig: [`glb_bytes_named`] with
/// [`CHOREO_ARMATURE`].
pub fn glb_bytes(m: &RigMotion) -> Result<Vec<u8>, MotionError> {
    glb_bytes_named(m, CHOREO_ARMATURE)
}

/// The binary glTF 2.0 (.glb) of a prepared motion: one node per joint in the rig's hierarchy, a
/// skin called `armature` over them (so tools treat it as a skeleton; Blender's importer names
/// the armature after it), and one animation with the root's translation and every joint's
/// rotation, linear, one key per frame at `t / fps` seconds.
///
/// glTF has no frame rate: times are seconds, and Blender's importer puts each key on frame
/// `time × the scene's fps`, so the dance lasts its seconds at any scene rate but keys land
/// between frames unless the scene runs at the dance's rate. The frame rate goes where a tool
/// can read it before importing: `extras.fps` on the scene (Blender copies a scene's extras
/// into its custom properties) and on the animation (with `extras.frames`).
/// `tools/blender_import.py` sets the scene's rate from it.
pub fn glb_bytes_named(m: &RigMotion, armature: &str) -> Result<Vec<u8>, MotionError> {
    let t_len = m.num_frames();
    let n = m.rig.names.len();
    if t_len == 0 {
        return Err(MotionError::Export("motion has no frames".into()));
    }
    let mut root = gj::Root {
        asset: gj::Asset {
            generator: Some(format!("choreo {}", env!("CARGO_PKG_VERSION"))),
            ..Default::default()
        },
        ..Default::default()
    };
    let mut bin: Vec<u8> = Vec::new();
    let buffer = gj::Index::<gj::Buffer>::new(0);

    // Appends f32 data as one buffer view + accessor.
    let mut add = |root: &mut gj::Root,
                   data: &[f32],
                   type_: gj::accessor::Type,
                   count: usize,
                   min_max: Option<(serde_json::Value, serde_json::Value)>|
     -> gj::Index<gj::Accessor> {
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        let offset = bin.len();
        for v in data {
            bin.extend_from_slice(&v.to_le_bytes());
        }
        let view = root.push(gj::buffer::View {
            buffer,
            byte_length: USize64::from(data.len() * 4),
            byte_offset: Some(USize64::from(offset)),
            byte_stride: None,
            name: None,
            target: None,
            extensions: None,
            extras: Default::default(),
        });
        let (min, max) = match min_max {
            Some((a, b)) => (Some(a), Some(b)),
            None => (None, None),
        };
        root.push(gj::Accessor {
            buffer_view: Some(view),
            byte_offset: None,
            count: USize64::from(count),
            component_type: Valid(gj::accessor::GenericComponentType(
                gj::accessor::ComponentType::F32,
            )),
            extensions: None,
            extras: Default::default(),
            type_: Valid(type_),
            min,
            max,
            name: None,
            normalized: false,
            sparse: None,
        })
    };

    // Nodes, one per joint, in rig order; children lists from the parents.
    let order = m.rig.order();
    for j in 0..n {
        let children: Vec<gj::Index<gj::Node>> = m
            .rig
            .children(j)
            .into_iter()
            .map(|c| gj::Index::new(c as u32))
            .collect();
        let q = m.rotations[0][j].coords;
        let translation = match m.rig.parents[j] {
            None => m.root_translation[0] + m.rig.offsets[j],
            Some(_) => m.rig.offsets[j],
        };
        root.push(gj::Node {
            name: Some(m.rig.names[j].clone()),
            translation: Some([
                translation.x as f32,
                translation.y as f32,
                translation.z as f32,
            ]),
            rotation: Some(gj::scene::UnitQuaternion([
                q[0] as f32,
                q[1] as f32,
                q[2] as f32,
                q[3] as f32,
            ])),
            children: (!children.is_empty()).then_some(children),
            ..Default::default()
        });
    }
    let root_joint = order[0];
    let scene = root.push(gj::Scene {
        extensions: None,
        extras: Default::default(),
        name: Some("choreo".into()),
        nodes: vec![gj::Index::new(root_joint as u32)],
    });
    root.scene = Some(scene);

    // Skin: bind pose = rest pose (identity rotations), inverse bind = minus the rest position.
    let mut rest = vec![Vector3::zeros(); n];
    for &j in &order {
        rest[j] = match m.rig.parents[j] {
            None => m.rig.offsets[j],
            Some(p) => rest[p] + m.rig.offsets[j],
        };
    }
    let mut ibm = Vec::with_capacity(16 * n);
    for r in &rest {
        ibm.extend_from_slice(&[
            1.0,
            0.0,
            0.0,
            0.0,
            0.0,
            1.0,
            0.0,
            0.0,
            0.0,
            0.0,
            1.0,
            0.0,
            -r.x as f32,
            -r.y as f32,
            -r.z as f32,
            1.0,
        ]);
    }
    let ibm_acc = add(&mut root, &ibm, gj::accessor::Type::Mat4, n, None);
    let skin = root.push(gj::Skin {
        extensions: None,
        extras: Default::default(),
        inverse_bind_matrices: Some(ibm_acc),
        joints: (0..n).map(|j| gj::Index::new(j as u32)).collect(),
        name: Some(armature.to_string()),
        skeleton: Some(gj::Index::new(root_joint as u32)),
    });

    // Animation.
    let times: Vec<f32> = (0..t_len).map(|t| (t as f64 / m.fps) as f32).collect();
    let t_max = times[t_len - 1];
    let input = add(
        &mut root,
        &times,
        gj::accessor::Type::Scalar,
        t_len,
        Some((serde_json::json!([0.0]), serde_json::json!([t_max]))),
    );
    let mut samplers = Vec::new();
    let mut channels = Vec::new();
    let mut channel = |samplers: &mut Vec<gj::animation::Sampler>,
                       output: gj::Index<gj::Accessor>,
                       node: usize,
                       path: gj::animation::Property| {
        let sampler = gj::Index::new(samplers.len() as u32);
        samplers.push(gj::animation::Sampler {
            extensions: None,
            extras: Default::default(),
            input,
            interpolation: Valid(gj::animation::Interpolation::Linear),
            output,
        });
        channels.push(gj::animation::Channel {
            sampler,
            target: gj::animation::Target {
                extensions: None,
                extras: Default::default(),
                node: gj::Index::new(node as u32),
                path: Valid(path),
            },
            extensions: None,
            extras: Default::default(),
        });
    };
    let root_track: Vec<f32> = m
        .root_translation
        .iter()
        .flat_map(|r| {
            let p = r + m.rig.offsets[root_joint];
            [p.x as f32, p.y as f32, p.z as f32]
        })
        .collect();
    let acc = add(
        &mut root,
        &root_track,
        gj::accessor::Type::Vec3,
        t_len,
        None,
    );
    channel(
        &mut samplers,
        acc,
        root_joint,
        gj::animation::Property::Translation,
    );
    for j in 0..n {
        let track: Vec<f32> = m
            .rotations
            .iter()
            .flat_map(|frame| {
                let c = frame[j].coords;
                [c[0] as f32, c[1] as f32, c[2] as f32, c[3] as f32]
            })
            .collect();
        let acc = add(&mut root, &track, gj::accessor::Type::Vec4, t_len, None);
        channel(&mut samplers, acc, j, gj::animation::Property::Rotation);
    }
    root.push(gj::Animation {
        extensions: None,
        extras: Default::default(),
        channels,
        name: Some("dance".into()),
        samplers,
    });
    // A figure for viewers to show: the skin's mannequin, made from the rig.
    super::mannequin::attach(&mut root, &mut bin, &m.rig, skin, scene)?;
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    root.push(gj::Buffer {
        byte_length: USize64::from(bin.len()),
        name: None,
        uri: None,
        extensions: None,
        extras: Default::default(),
    });

    let mut doc =
        serde_json::to_value(&root).map_err(|e| MotionError::Export(format!("glTF JSON: {e}")))?;
    // gltf-json's `extras` need a serde_json feature the rest of the build does without.
    doc["scenes"][0]["extras"] = serde_json::json!({ "fps": m.fps });
    doc["animations"][0]["extras"] = serde_json::json!({ "fps": m.fps, "frames": t_len });
    let mut json =
        serde_json::to_vec(&doc).map_err(|e| MotionError::Export(format!("glTF JSON: {e}")))?;
    while json.len() % 4 != 0 {
        json.push(b' ');
    }
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let total_u32 = u32::try_from(total)
        .map_err(|_| MotionError::Export(format!("glb of {total} bytes exceeds 4 GiB")))?;
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&total_u32.to_le_bytes());
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(&0x4E4F_534Au32.to_le_bytes()); // "JSON"
    out.extend_from_slice(&json);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(&0x004E_4942u32.to_le_bytes()); // "BIN\0"
    out.extend_from_slice(&bin);
    Ok(out)
}

/// Writes `bytes` to `path` atomically: a temporary file in the same folder, then a rename.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), MotionError> {
    let dir = path.parent().unwrap_or_else(|| Path::new("."));
    std::fs::create_dir_all(dir).map_err(|e| MotionError::io(dir, e))?;
    let mut tmp = tempfile::NamedTempFile::new_in(dir).map_err(|e| MotionError::io(dir, e))?;
    tmp.write_all(bytes).map_err(|e| MotionError::io(path, e))?;
    tmp.as_file()
        .sync_all()
        .map_err(|e| MotionError::io(path, e))?;
    // Temporary files are private (0600); results are ordinary readable files.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt as _;
        tmp.as_file()
            .set_permissions(std::fs::Permissions::from_mode(0o644))
            .map_err(|e| MotionError::io(path, e))?;
    }
    tmp.persist(path)
        .map_err(|e| MotionError::io(path, e.error))?;
    Ok(())
}

/// Exports a prepared motion as `motion.bvh`, `motion.json` and `motion.glb` in `dir`.
pub fn write_all_rig(m: &RigMotion, dir: &Path) -> Result<ExportPaths, MotionError> {
    // Render everything first so a failure leaves no partial set behind.
    let bvh = bvh_string(m)?;
    let json = json_string(m)?;
    let glb = glb_bytes(m)?;
    let paths = ExportPaths {
        bvh: dir.join(BVH_FILE),
        json: dir.join(JSON_FILE),
        glb: dir.join(GLB_FILE),
    };
    write_atomic(&paths.bvh, bvh.as_bytes())?;
    write_atomic(&paths.json, json.as_bytes())?;
    write_atomic(&paths.glb, &glb)?;
    Ok(paths)
}

/// Exports a motion (generated or not) as BVH, JSON and glb in `dir`: the worker's entry point.
pub fn write_all(motion: &Motion, dir: &Path) -> Result<ExportPaths, MotionError> {
    write_all_anchored(motion, dir, &[])
}

/// As [`write_all`], with the skeleton fitted to the key-pose frames `anchors` when there are any.
pub fn write_all_anchored(
    motion: &Motion,
    dir: &Path,
    anchors: &[usize],
) -> Result<ExportPaths, MotionError> {
    let m = prepare_anchored(motion, anchors)?;
    write_all_rig(&m, dir)
}

/// The dataset's joints as the exported rig places them: `motion.json`'s positions less the body
/// centre (joint 0) and the branch joints after them, i.e. what a user downloads, in [`Motion`] form.
pub fn served_motion(m: &RigMotion) -> Motion {
    let world = m.world_positions();
    let positions = world
        .slice(ndarray::s![.., 1..=super::NUM_JOINTS, ..])
        .mapv(|v| v as f32);
    Motion {
        fps: m.fps,
        positions,
    }
}

/// Export formats the CLI and the API name.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    Bvh,
    Json,
    Glb,
}

impl std::str::FromStr for Format {
    type Err = MotionError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "bvh" => Ok(Format::Bvh),
            "json" => Ok(Format::Json),
            "glb" => Ok(Format::Glb),
            other => Err(MotionError::Invalid(format!(
                "unknown format {other:?} (bvh, json or glb)"
            ))),
        }
    }
}

/// The bytes of one format of a prepared motion.
pub fn render(m: &RigMotion, format: Format) -> Result<Vec<u8>, MotionError> {
    match format {
        Format::Bvh => bvh_string(m).map(String::into_bytes),
        Format::Json => json_string(m).map(String::into_bytes),
        Format::Glb => glb_bytes(m),
    }
}

/// Exports dataset dance `id` in `format` to `out`: what `choreo export` runs.
pub fn export_dance(
    dataset_root: &Path,
    id: &str,
    format: Format,
    out: &Path,
) -> Result<(), MotionError> {
    let ds = super::dataset::Dataset::open(dataset_root)?;
    let dance = ds.load(id)?;
    let m = prepare_with_root(&dance.motion, dance.center.view())?;
    write_atomic(out, &render(&m, format)?)
}
