//! A job's dance on other skeletons, checked by the tools that read them: `motion.bvh?rig=mixamo`
//! and `motion.glb?rig=mixamo` imported by Blender onto armatures with Mixamo's bone names,
//! `motion.vrma` played by `@pixiv/three-vrm-animation` in chromium on a humanoid the test builds,
//! and `motion.smpl.npz` read back (and by numpy). Each compares angles between bones, or bone
//! directions, with the job's motion.json. Also: `rig=choreo` is the stored file, unknown rigs
//! and parameters are refused, and an unfinished job answers as the other result routes do.
//!
//! An uploaded rig (the Unreal-named fixture, centimetres) goes through the same Blender check by its id.
//! Knees and hips are held to [`LEG_LIMIT_DEG`]; no joint of any retargeted BVH (Mixamo, VRM, SMPL,
//! uploaded) turns more than 60° between two frames; the glb's armature is named for the rig and
//! `tools/blender_import.py` imports it at the dance's frame rate ([`blender`]).
//! Needs Debian's blender, node with `tests/web/node_modules` (`npm ci`), chromium and numpy for
//! /usr/bin/python3 (all from `scripts/setup.sh --test`); without them this fails under `CI=true`
//! and prints a notice otherwise.
use crate::common_models::models_dir;
use crate::helpers::{expect_problem, short_song, spawn_app_with, TestApp};
use nalgebra::Vector3;
use reqwest::StatusCode;
use serde_json::{json, Value};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

mod blender;
mod readers;

/// The bar: the angles between bones match motion.json's within this median, degrees.
const MEDIAN_LIMIT_DEG: f64 = 10.0;
/// The bar for knees and hips, whose angles are what the dance does with the legs.
const LEG_LIMIT_DEG: f64 = 6.0;
/// Frames compared per dance (spread evenly).
const FRAMES: usize = 40;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Whether a tool this test needs is there; panics under CI=true when it is not.
fn have(what: &str, ok: bool) -> bool {
    if !ok {
        let message = format!(
            "the retarget test needs {what}: run `scripts/setup.sh --test` (or `make test`)"
        );
        assert!(
            std::env::var("CI").as_deref() != Ok("true"),
            "{message} (CI=true)"
        );
        eprintln!("NOTICE: skipping part of the retarget test: {message}");
    }
    ok
}

fn runs(cmd: &str, args: &[&str]) -> bool {
    std::process::Command::new(cmd)
        .args(args)
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false)
}

/// Angle between two vectors, degrees.
fn angle(a: Vector3<f64>, b: Vector3<f64>) -> f64 {
    (a.dot(&b) / (a.norm() * b.norm()))
        .clamp(-1.0, 1.0)
        .acos()
        .to_degrees()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Joint positions of one pose by name.
type Pose = HashMap<String, Vector3<f64>>;

/// The angles compared, from a pose and the names of its joints for each landmark:
/// elbows and knees (between the two bones), shoulders and hips (upper arm or thigh against the
/// torso, mid-hips to mid-shoulders).
fn angles(p: &Pose, n: &dyn Fn(&str) -> String) -> Vec<(&'static str, f64)> {
    let at = |k: &str| {
        p.get(&n(k))
            .copied()
            .unwrap_or_else(|| panic!("no joint {} in the pose", n(k)))
    };
    let torso = (at("left_shoulder") + at("right_shoulder")) / 2.0
        - (at("left_hip") + at("right_hip")) / 2.0;
    let mut out = Vec::new();
    for (side, elbow, knee, shoulder, hip) in [
        (
            "left",
            "left elbow",
            "left knee",
            "left shoulder",
            "left hip",
        ),
        (
            "right",
            "right elbow",
            "right knee",
            "right shoulder",
            "right hip",
        ),
    ] {
        let j = |k: &str| at(&format!("{side}_{k}"));
        out.push((
            elbow,
            angle(j("shoulder") - j("elbow"), j("wrist") - j("elbow")),
        ));
        out.push((knee, angle(j("hip") - j("knee"), j("ankle") - j("knee"))));
        out.push((shoulder, angle(torso, j("elbow") - j("shoulder"))));
        out.push((hip, angle(torso, j("knee") - j("hip"))));
    }
    out
}

/// motion.json's pose at frame `t` by its joint names.
fn choreo_pose(motion: &Value, t: usize) -> Pose {
    let names = motion["joint_names"].as_array().expect("joint_names");
    names
        .iter()
        .enumerate()
        .map(|(j, name)| {
            let p = &motion["positions"][t][j];
            (
                name.as_str().expect("name").to_string(),
                Vector3::new(
                    p[0].as_f64().unwrap(),
                    p[1].as_f64().unwrap(),
                    p[2].as_f64().unwrap(),
                ),
            )
        })
        .collect()
}

/// Mixamo's bone for each landmark `angles` reads.
fn mixamo_name(k: &str) -> String {
    let (side, rest) = k.split_once('_').expect("side_joint");
    let side = if side == "left" { "Left" } else { "Right" };
    let bone = match rest {
        "shoulder" => "Arm",
        "elbow" => "ForeArm",
        "wrist" => "Hand",
        "hip" => "UpLeg",
        "knee" => "Leg",
        "ankle" => "Foot",
        other => panic!("no landmark {other}"),
    };
    format!("mixamorig:{side}{bone}")
}

/// The Unreal-named fixture rig's bone for each landmark `angles` reads.
fn unreal_name(k: &str) -> String {
    let (side, rest) = k.split_once('_').expect("side_joint");
    let bone = match rest {
        "shoulder" => "upperarm",
        "elbow" => "lowerarm",
        "wrist" => "hand",
        "hip" => "thigh",
        "knee" => "calf",
        "ankle" => "foot",
        other => panic!("no landmark {other}"),
    };
    format!("{bone}_{}", &side[..1])
}

/// Per angle, the median over frames of |target − motion.json|; asserts each within the limit.
fn compare(
    what: &str,
    motion: &Value,
    frames: &[usize],
    target: &dyn Fn(usize) -> Pose,
    n: &dyn Fn(&str) -> String,
) {
    let mut diffs: HashMap<&str, Vec<f64>> = HashMap::new();
    for &t in frames {
        let want = angles(&choreo_pose(motion, t), &|k| k.to_string());
        let got = angles(&target(t), n);
        for ((name, a), (_, b)) in want.iter().zip(&got) {
            diffs.entry(name).or_default().push((a - b).abs());
        }
    }
    let mut medians: Vec<(&str, f64)> = diffs.into_iter().map(|(k, v)| (k, median(v))).collect();
    medians.sort_by(|a, b| a.0.cmp(b.0));
    eprintln!(
        "{what}: median |angle − motion.json's| (deg): {}",
        medians
            .iter()
            .map(|(k, v)| format!("{k} {v:.1}"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    for (k, v) in &medians {
        let limit = if k.ends_with("knee") || k.ends_with("hip") {
            LEG_LIMIT_DEG
        } else {
            MEDIAN_LIMIT_DEG
        };
        assert!(
            *v <= limit,
            "{what}: {k} off by {v:.1}° median (limit {limit}°)"
        );
    }
}

/// No joint of a retargeted BVH turns more than 60° between two frames (read back by choreo's
/// own BVH reader, the Euler angles as the file has them).
fn no_joint_turns_past_60(what: &str, bvh: &[u8]) {
    use choreo::metrics::rotation_flips::{RotationFlips, FLIP_DEG};
    let text = std::str::from_utf8(bvh).expect("BVH is text");
    let m = choreo::motion::bvh::Bvh::parse(text)
        .and_then(|b| b.to_rig_motion())
        .unwrap_or_else(|e| panic!("{what}: {e}"));
    let flips = RotationFlips::of(&m);
    eprintln!(
        "{what}: largest one-frame joint turn {:.1}° ({} of {} steps past 60°)",
        flips.max_step_deg, flips.steps_over_60, flips.steps
    );
    assert!(flips.max_step_deg <= FLIP_DEG, "{what}: {flips:?}");
}

async fn bytes(app: &TestApp, path: &str) -> Vec<u8> {
    let response = app.get(path).await;
    assert_eq!(response.status(), StatusCode::OK, "GET {path}");
    response.bytes().await.expect("body").to_vec()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_dance_goes_onto_mixamo_vrm_and_smpl_and_the_tools_read_it() {
    let app = spawn_app_with(|c| c.models_dir = models_dir()).await;
    let song = app.upload_ok(&short_song()).await;
    let song_id = song["id"].as_str().expect("song id");
    let id = app
        .dance(&json!({"song_id": song_id, "model": "keypose-transformer", "seed": 7}))
        .await;
    let base = format!("/v1/jobs/{id}");
    let motion: Value = app
        .get(&format!("{base}/motion.json"))
        .await
        .json()
        .await
        .expect("motion.json");
    let t_len = motion["num_frames"].as_u64().expect("num_frames") as usize;
    let frames: Vec<usize> = (0..FRAMES)
        .map(|i| i * (t_len - 1) / (FRAMES - 1))
        .collect();

    // choreo is the default and the stored file, byte for byte.
    for file in ["motion.bvh", "motion.glb"] {
        let stored = bytes(&app, &format!("{base}/{file}")).await;
        assert_eq!(
            stored,
            bytes(&app, &format!("{base}/{file}?rig=choreo")).await,
            "{file}?rig=choreo"
        );
    }
    expect_problem(
        app.get(&format!("{base}/motion.bvh?rig=nobody")).await,
        StatusCode::NOT_FOUND,
        "rig-not-found",
    )
    .await;
    expect_problem(
        app.get(&format!("{base}/motion.glb?rigg=mixamo")).await,
        StatusCode::BAD_REQUEST,
        "invalid-query",
    )
    .await;
    expect_problem(
        app.get("/v1/jobs/0190d3c0-0000-7000-8000-000000000000/motion.vrma")
            .await,
        StatusCode::NOT_FOUND,
        "job-not-found",
    )
    .await;

    // Mixamo: BVH and glb.
    let response = app.get(&format!("{base}/motion.bvh?rig=mixamo")).await;
    assert_eq!(response.status(), StatusCode::OK);
    let disposition = response
        .headers()
        .get("content-disposition")
        .and_then(|v| v.to_str().ok())
        .unwrap_or("")
        .to_string();
    assert!(disposition.contains("motion.mixamo.bvh"), "{disposition}");
    let bvh = response.bytes().await.expect("bvh").to_vec();
    assert!(
        bvh.starts_with(b"HIERARCHY\nROOT mixamorig:Hips\n"),
        "{}",
        String::from_utf8_lossy(&bvh[..60])
    );
    let glb = bytes(&app, &format!("{base}/motion.glb?rig=mixamo")).await;
    assert_eq!(&glb[..4], b"glTF");
    no_joint_turns_past_60("motion.bvh?rig=mixamo", &bvh);
    for rig in ["vrm", "smpl"] {
        let other = bytes(&app, &format!("{base}/motion.bvh?rig={rig}")).await;
        no_joint_turns_past_60(&format!("motion.bvh?rig={rig}"), &other);
    }
    let vrma = bytes(&app, &format!("{base}/motion.vrma")).await;
    assert_eq!(&vrma[..4], b"glTF");
    let npz = bytes(&app, &format!("{base}/motion.smpl.npz")).await;

    let dir = tempfile::tempdir().expect("tempdir");
    let write = |name: &str, b: &[u8]| -> PathBuf {
        let p = dir.path().join(name);
        std::fs::write(&p, b).expect("write");
        p
    };
    let motion_path = write("motion.json", motion.to_string().as_bytes());
    let bvh_path = write("motion.mixamo.bvh", &bvh);
    let glb_path = write("motion.mixamo.glb", &glb);
    let vrma_path = write("motion.vrma", &vrma);
    let npz_path = write("motion.smpl.npz", &npz);

    // An uploaded skeleton (Unreal names, centimetres, other proportions) by its id, both files.
    let fixture =
        std::fs::read(root().join("tests/fixtures/rig_unreal_cm.bvh")).expect("rig fixture");
    let form = reqwest::multipart::Form::new().part(
        "file",
        reqwest::multipart::Part::bytes(fixture).file_name("mannequin.bvh"),
    );
    let response = app
        .client
        .post(app.url("/v1/rigs"))
        .multipart(form)
        .send()
        .await
        .expect("POST /v1/rigs");
    assert_eq!(response.status(), StatusCode::CREATED);
    let rig: Value = response.json().await.expect("rig");
    let rig_id = rig["id"].as_str().expect("rig id");
    let unreal_bvh = bytes(&app, &format!("{base}/motion.bvh?rig={rig_id}")).await;
    assert!(
        unreal_bvh.starts_with(b"HIERARCHY\nROOT pelvis\n"),
        "{}",
        String::from_utf8_lossy(&unreal_bvh[..40])
    );
    no_joint_turns_past_60("motion.bvh?rig=<uploaded>", &unreal_bvh);
    let unreal_bvh_path = write("motion.unreal.bvh", &unreal_bvh);
    let unreal_glb_path = write(
        "motion.unreal.glb",
        &bytes(&app, &format!("{base}/motion.glb?rig={rig_id}")).await,
    );
    expect_problem(
        app.get(&format!(
            "{base}/motion.bvh?rig=0191f0a0-0000-7000-8000-000000000000"
        ))
        .await,
        StatusCode::NOT_FOUND,
        "rig-not-found",
    )
    .await;

    // An unfinished job answers 409 like the other result routes (a second dance, asked for at once).
    let response = app
        .post_job(
            &json!({"song_id": song_id, "model": "keypose-transformer", "seed": 8}),
            None,
        )
        .await;
    let pending: Value = response.json().await.expect("job");
    let pending_id = pending["id"].as_str().expect("id");
    let response = app
        .get(&format!("/v1/jobs/{pending_id}/motion.bvh?rig=mixamo"))
        .await;
    if response.status() != StatusCode::OK {
        expect_problem(response, StatusCode::CONFLICT, "job-not-finished").await;
    }
    app.wait_job(pending_id).await;
    app.stop().await;

    readers::smpl_npz_follows_the_dance(&npz_path, &motion, &frames);
    if have("Debian's blender", runs("blender", &["--version"])) {
        let mixamo: Vec<String> = choreo::motion::retarget::mixamo().rig.names;
        blender::the_import_recipe_plays_the_dance(
            &bvh_path,
            &glb_path,
            choreo::motion::retarget::DEFAULT_ARMATURE,
            dir.path(),
            &motion,
        );
        blender::blender_reads_the_files(
            "mixamo",
            "Armature",
            &bvh_path,
            &glb_path,
            dir.path(),
            &motion,
            &frames,
            &mixamo,
            &mixamo_name,
        );
        let unreal: Vec<String> = [
            "pelvis",
            "spine_03",
            "head",
            "upperarm_l",
            "lowerarm_r",
            "hand_l",
            "thigh_r",
            "calf_l",
            "foot_r",
            "ball_l",
        ]
        .map(String::from)
        .to_vec();
        blender::blender_reads_the_files(
            "uploaded",
            "Armature",
            &unreal_bvh_path,
            &unreal_glb_path,
            dir.path(),
            &motion,
            &frames,
            &unreal,
            &unreal_name,
        );
    }
    let node_ready = runs("node", &["--version"])
        && root()
            .join("tests/web/node_modules/@pixiv/three-vrm-animation")
            .is_dir()
        && Path::new(&std::env::var("CHROMIUM").unwrap_or_else(|_| "/usr/bin/chromium".into()))
            .is_file();
    if have(
        "node, chromium and tests/web/node_modules (npm ci)",
        node_ready,
    ) {
        readers::three_vrm_plays_the_vrma(&vrma_path, &motion_path, dir.path());
    }
    let _ = motion_path;
}
