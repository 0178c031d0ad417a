//! A job's dance on other skeletons, checked by the tools that read them: `motion.bvh?rig=mixamo`
//! and `motion.glb?rig=mixamo` imported by Blender onto armatures with Mixamo's bone names,
//! `motion.vrma` played by `@pixiv/three-vrm-animation` in chromium on a humanoid the test builds,
//! and `motion.smpl.npz` read back (and by numpy). Each compares angles between bones, or bone
//! directions, with the job's motion.json. Also: `rig=choreo` is the stored file, unknown rigs
//! and parameters are refused, and an unfinished job answers as the other result routes do.
//!
//! An uploaded rig (the Unreal-named fixture, centimetres) goes through the same Blender check by its id.
//! Needs Debian's blender, node with `tests/web/node_modules` (`npm ci`), chromium and numpy for
//! /usr/bin/python3 (all from `scripts/setup.sh --test`); without them this fails under `CI=true`
//! and prints a notice otherwise.
use crate::common_models::models_dir;
use crate::helpers::{expect_problem, short_song, spawn_app_with, TestApp};
use choreo::motion::retarget::smpl;
use nalgebra::{UnitQuaternion, Vector3};
use reqwest::StatusCode;
use serde_json::{json, Value};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// The bar: the angles between bones match motion.json's within this median, degrees.
const MEDIAN_LIMIT_DEG: f64 = 10.0;
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
        assert!(
            *v <= MEDIAN_LIMIT_DEG,
            "{what}: {k} off by {v:.1}° median (limit {MEDIAN_LIMIT_DEG}°)"
        );
    }
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

    smpl_npz_follows_the_dance(&npz_path, &motion, &frames);
    if have("Debian's blender", runs("blender", &["--version"])) {
        let mixamo: Vec<String> = choreo::motion::retarget::mixamo().rig.names;
        blender_reads_the_files(
            "mixamo",
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
        blender_reads_the_files(
            "uploaded",
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
        three_vrm_plays_the_vrma(&vrma_path, &motion_path, dir.path());
    }
    let _ = motion_path;
}

/// Blender imports both files onto one armature each with the rig's bone names (`names`, at
/// least); the angles between bones in its evaluated pose follow motion.json's.
#[allow(clippy::too_many_arguments)]
fn blender_reads_the_files(
    rig: &str,
    bvh: &Path,
    glb: &Path,
    dir: &Path,
    motion: &Value,
    frames: &[usize],
    names: &[String],
    landmark: &dyn Fn(&str) -> String,
) {
    let out = dir.join(format!("blender.{rig}.json"));
    let list = frames
        .iter()
        .map(|f| f.to_string())
        .collect::<Vec<_>>()
        .join(",");
    let script = root().join("tests/blender/check_retarget.py");
    let run = std::process::Command::new("blender")
        .args(["-b", "--factory-startup", "--python-exit-code", "1", "-P"])
        .arg(&script)
        .arg("--")
        .args([bvh, glb])
        .arg(&list)
        .arg(&out)
        .output()
        .expect("run blender");
    let log =
        String::from_utf8_lossy(&run.stdout).to_string() + &String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "blender failed:\n{log}");
    let result: Value =
        serde_json::from_str(&std::fs::read_to_string(&out).expect("blender result"))
            .expect("json");
    for kind in ["bvh", "glb"] {
        let r = &result[kind];
        assert!(r.get("error").is_none(), "{kind}: {}", r["error"]);
        assert_eq!(r["armatures"], 1, "{kind}: {r}");
        let bones: Vec<&str> = r["bones"]
            .as_array()
            .expect("bones")
            .iter()
            .filter_map(Value::as_str)
            .collect();
        for name in names {
            assert!(
                bones.contains(&name.as_str()),
                "{kind}: Blender's armature lacks {name}: {bones:?}"
            );
        }
        assert_eq!(
            r["frames"].as_u64(),
            motion["num_frames"].as_u64(),
            "{kind}: frame count"
        );
        let pose = |t: usize| -> Pose {
            r["poses"][t.to_string()]
                .as_object()
                .unwrap_or_else(|| panic!("{kind}: no pose at frame {t}"))
                .iter()
                .map(|(k, v)| {
                    (
                        k.clone(),
                        Vector3::new(
                            v[0].as_f64().unwrap(),
                            v[1].as_f64().unwrap(),
                            v[2].as_f64().unwrap(),
                        ),
                    )
                })
                .collect()
        };
        compare(
            &format!("Blender, motion.{kind}?rig={rig}"),
            motion,
            frames,
            &pose,
            landmark,
        );
    }
}

/// `@pixiv/three-vrm-animation` plays the .vrma on a humanoid unlike the target; its bones point
/// where motion.json's do.
fn three_vrm_plays_the_vrma(vrma: &Path, motion: &Path, dir: &Path) {
    let out = dir.join("vrma.json");
    let run = std::process::Command::new("node")
        .arg(root().join("tests/web/vrma.mjs"))
        .args([vrma, motion, &out])
        .output()
        .expect("run node");
    let log =
        String::from_utf8_lossy(&run.stdout).to_string() + &String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "tests/web/vrma.mjs failed:\n{log}");
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(&out).expect("vrma result")).expect("json");
    eprintln!(
        "three-vrm, motion.vrma: median bone direction error (deg): {}",
        summary["median_deg"]
    );
    let medians = summary["median_deg"].as_object().expect("median_deg");
    assert!(medians.len() >= 8, "{summary}");
    for (bone, v) in medians {
        let v = v.as_f64().expect("number");
        assert!(
            v <= MEDIAN_LIMIT_DEG,
            "three-vrm: {bone} points {v:.1}° off motion.json's (median)"
        );
    }
}

/// The npz has AMASS's arrays (numpy reads them); its poses, put through SMPL's kinematic tree,
/// bend knees and elbows as motion.json does.
fn smpl_npz_follows_the_dance(npz: &Path, motion: &Value, frames: &[usize]) {
    use ndarray_npy::ReadNpyExt;
    let file = std::fs::File::open(npz).expect("npz");
    let mut zip = zip::ZipArchive::new(file).expect("npz is a zip");
    let mut read = |name: &str| -> ndarray::ArrayD<f64> {
        let entry = zip
            .by_name(name)
            .unwrap_or_else(|_| panic!("npz lacks {name}"));
        ndarray::ArrayD::<f64>::read_npy(entry).unwrap_or_else(|e| panic!("{name}: {e}"))
    };
    let poses = read("poses.npy");
    let trans = read("trans.npy");
    let t_len = motion["num_frames"].as_u64().expect("frames") as usize;
    assert_eq!(poses.shape(), [t_len, 72]);
    assert_eq!(trans.shape(), [t_len, 3]);
    assert_eq!(
        read("mocap_framerate.npy").iter().next().copied(),
        motion["fps"].as_f64()
    );
    let target = smpl::smpl();
    let pose = |t: usize| -> Pose {
        let locals: Vec<UnitQuaternion<f64>> = (0..24)
            .map(|j| {
                UnitQuaternion::from_scaled_axis(Vector3::new(
                    poses[[t, 3 * j]],
                    poses[[t, 3 * j + 1]],
                    poses[[t, 3 * j + 2]],
                ))
            })
            .collect();
        let root = Vector3::new(trans[[t, 0]], trans[[t, 1]], trans[[t, 2]])
            + Vector3::from(smpl::REST[0]);
        let (pos, _) = choreo::motion::rig::fk_frame(&target.rig, &root, &locals);
        target.rig.names.iter().cloned().zip(pos).collect()
    };
    // SMPL's collar-to-shoulder and the hips differ from choreo's markers; knees and elbows are
    // what is compared on SMPL.
    let mut knee_elbow: HashMap<&str, Vec<f64>> = HashMap::new();
    for &t in frames {
        let want = angles(&choreo_pose(motion, t), &|k| k.to_string());
        // SMPL names these landmarks as choreo does (left_shoulder … left_ankle).
        let got = angles(&pose(t), &|k| k.to_string());
        for ((name, a), (_, b)) in want.iter().zip(&got) {
            if name.ends_with("knee") || name.ends_with("elbow") {
                knee_elbow.entry(name).or_default().push((a - b).abs());
            }
        }
    }
    for (k, v) in knee_elbow {
        let m = median(v);
        eprintln!("SMPL npz: {k} bend off by {m:.1}° median");
        assert!(
            m <= MEDIAN_LIMIT_DEG,
            "SMPL npz: {k} bend off by {m:.1}° median"
        );
    }
    if have(
        "numpy for /usr/bin/python3 (python3-numpy)",
        runs("/usr/bin/python3", &["-c", "import numpy"]),
    ) {
        let check = "import sys, numpy as np\nd = np.load(sys.argv[1])\nassert sorted(d.files) == ['betas', 'gender', 'mocap_framerate', 'poses', 'trans'], d.files\nassert d['poses'].dtype == np.float64 and d['poses'].shape[1] == 72\nassert d['trans'].shape == (d['poses'].shape[0], 3)\nassert str(d['gender']) == 'neutral', d['gender']\nassert float(d['mocap_framerate']) == 25.0\nassert not d['betas'].any()\nprint('numpy reads', d['poses'].shape)";
        let run = std::process::Command::new("/usr/bin/python3")
            .args(["-c", check])
            .arg(npz)
            .output()
            .expect("python3");
        assert!(
            run.status.success(),
            "numpy cannot read the npz: {}",
            String::from_utf8_lossy(&run.stderr)
        );
    }
}
