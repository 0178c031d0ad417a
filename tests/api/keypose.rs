//! The key-pose transformer through the API: four key poses taken from a real test dance, the
//! dance generated to that dance's own song, and the BVH read back must pass through each key
//! pose at its time.
use crate::helpers::{expect_problem, spawn_app_with};
use choreo::motion::dataset::Dataset;
use choreo::motion::KeyPose;
use reqwest::StatusCode;
use serde_json::{json, Value};
use std::path::Path;

/// The consistency target for the generated motion (mean per-joint error at the key
/// frames, centroid-aligned), cm; the report measures it before export.
const KEY_POSE_TARGET_CM: f64 = 3.0;
/// The error through the BVH, per key pose, cm: the same 3 cm. The BVH is a rigid skeleton;
/// the export fits it to the key-pose frames (`rig::fit_and_solve`'s anchors), so the body the
/// user posed is the body that dances, and solves it in least squares (measured 0.49–1.28 cm on
/// these four; 0.52–2.19 cm with the chain IK on the key frames' median skeleton; 3.26–4.88 cm
/// when the skeleton was fitted to every frame, whose poses come from several captured dancers).
const THROUGH_BVH_CM: f64 = 3.0;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn keypose_transformer_passes_through_four_real_key_poses() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let ds = Dataset::open(&root.join("../shared/data/dance-with-melody")).unwrap_or_else(|e| {
        panic!(
            "the key-pose API test needs ../shared (CI={}): {e}",
            std::env::var("CI").unwrap_or_default()
        )
    });
    let dance = ds.load("DANCE_W_22").expect("a test dance");
    let rel = dance.root_relative();
    let keys: Vec<KeyPose> = [100usize, 300, 500, 800]
        .iter()
        .map(|&f| KeyPose {
            time_s: dance.song_time_s(f),
            joints: rel
                .outer_iter()
                .nth(f)
                .expect("frame")
                .outer_iter()
                .map(|p| [f64::from(p[0]), f64::from(p[1]), f64::from(p[2])])
                .collect(),
        })
        .collect();

    let app = spawn_app_with(|c| c.models_dir = crate::common_models::models_dir()).await;
    let song = app.upload_ok(&dance.audio_path).await;
    let song_id = song["id"].as_str().expect("song id");
    let duration = song["duration_s"].as_f64().expect("duration");

    // Bad key poses are refused before anything is queued.
    let mut outside = keys.clone();
    outside[0].time_s = duration + 1.0;
    let short = KeyPose {
        time_s: 1.0,
        joints: vec![[0.0; 3]; 5],
    };
    for bad in [json!(outside), json!([short])] {
        let r = app
            .post_job(
                &json!({"song_id": song_id, "model": "keypose-transformer", "key_poses": bad}),
                None,
            )
            .await;
        expect_problem(r, StatusCode::UNPROCESSABLE_ENTITY, "invalid-field").await;
    }

    let response = app.post_job(&json!({"song_id": song_id, "model": "keypose-transformer", "seed": 1, "key_poses": keys}), None).await;
    assert_eq!(response.status(), StatusCode::ACCEPTED);
    let job: Value = response.json().await.expect("job");
    let id = job["id"].as_str().expect("job id").to_string();
    let done = app.wait_job(&id).await;
    assert_eq!(done["status"], "succeeded", "{done}");

    let text = app
        .get(&format!("/v1/jobs/{id}/motion.bvh"))
        .await
        .text()
        .await
        .expect("bvh");
    let motion = choreo::motion::bvh::Bvh::parse(&text)
        .expect("BVH parses")
        .to_motion()
        .expect("23 named joints");
    let errors: Vec<f64> = keys
        .iter()
        .map(|key| {
            choreo::metrics::kinematics::key_pose_error_cm(
                motion.positions.view(),
                motion.fps,
                std::slice::from_ref(key),
            )
            .expect("key pose inside the dance")
        })
        .collect();
    eprintln!("key-pose errors through the BVH (cm): {errors:.2?}");
    for (key, err) in keys.iter().zip(&errors) {
        assert!(
            *err < THROUGH_BVH_CM,
            "key pose at {:.2} s missed by {err:.2} cm",
            key.time_s
        );
    }
    let report: Value = app
        .get(&format!("/v1/jobs/{id}/report.json"))
        .await
        .json()
        .await
        .expect("report");
    assert!(
        report["scores"]["key_pose_error_cm"]
            .as_f64()
            .is_some_and(|e| e < KEY_POSE_TARGET_CM),
        "{report}"
    );
    app.stop().await;
}
