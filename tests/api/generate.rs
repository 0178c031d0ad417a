//! A generate job end to end with the committed dance-revolution weights: a real song through
//! the real decoder, the trained model, and the exporters; the BVH read back by our reader.
use crate::common_models::models_dir;
use crate::helpers::{expect_problem, short_song, spawn_app_with};
use reqwest::StatusCode;
use serde_json::{json, Value};

async fn generate(app: &crate::helpers::TestApp, song_id: &str, seed: u64) -> String {
    app.dance(&json!({"song_id": song_id, "model": "dance-revolution", "seed": seed}))
        .await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn dance_revolution_dances_a_real_song_through_the_api() {
    let app = spawn_app_with(|c| c.models_dir = models_dir()).await;
    let models: Value = app.get("/v1/models").await.json().await.expect("models");
    let dr = models
        .as_array()
        .or_else(|| models["models"].as_array())
        .expect("model list")
        .iter()
        .find(|m| m["id"] == "dance-revolution")
        .cloned()
        .expect("dance-revolution is listed");
    assert_eq!(dr["capabilities"]["key_poses"], false);

    let song = app.upload_ok(&short_song()).await;
    let song_id = song["id"].as_str().expect("song id");
    let duration = song["duration_s"].as_f64().expect("duration");
    let job = generate(&app, song_id, 1).await;

    let bvh = app.get(&format!("/v1/jobs/{job}/motion.bvh")).await;
    assert_eq!(bvh.status(), StatusCode::OK);
    let bvh = choreo::motion::bvh::Bvh::parse(&bvh.text().await.expect("bvh text"))
        .expect("our reader reads the BVH");
    let frames = (duration * 25.0).floor() as usize;
    assert_eq!(
        bvh.num_frames(),
        frames,
        "one BVH frame per 1/25 s of music"
    );
    assert!((bvh.frame_time - 0.04).abs() < 1e-6);

    let motion: Value = app
        .get(&format!("/v1/jobs/{job}/motion.json"))
        .await
        .json()
        .await
        .expect("motion json");
    assert_eq!(motion["fps"], 25.0);
    // The exported rig is the 23 dataset joints plus the branch joints the motion module adds.
    let names: Vec<&str> = motion["joint_names"]
        .as_array()
        .expect("joint_names")
        .iter()
        .filter_map(Value::as_str)
        .collect();
    for joint in choreo::motion::skeleton::JOINT_NAMES {
        assert!(names.contains(&joint), "{joint} missing from {names:?}");
    }
    let joints = names.len();
    let positions = motion["positions"].as_array().expect("positions");
    assert_eq!(positions.len(), frames);
    let values = || {
        positions
            .iter()
            .filter_map(Value::as_array)
            .flatten()
            .filter_map(Value::as_array)
            .flatten()
    };
    assert_eq!(values().count(), frames * joints * 3);
    assert!(
        values().all(|v| v.as_f64().is_some_and(f64::is_finite)),
        "positions are finite numbers"
    );

    let report: Value = app
        .get(&format!("/v1/jobs/{job}/report.json"))
        .await
        .json()
        .await
        .expect("report");
    assert_eq!(report["frames"], frames);
    assert!(
        report["scores"]["fid_k"]
            .as_f64()
            .is_some_and(f64::is_finite),
        "{report}"
    );
    // The physical-plausibility numbers and their verdict ride in every report.
    assert!(
        report["scores"]["physical"]["lowest_foot_m"]["median"]
            .as_f64()
            .is_some_and(f64::is_finite),
        "{report}"
    );
    assert!(
        report["scores"]["physical"]["mean_speed_m_s"]
            .as_f64()
            .is_some_and(|v| v > 0.0),
        "{report}"
    );
    assert_eq!(
        report["scores"]["verdict"]["criteria"]
            .as_array()
            .map(Vec::len),
        Some(8),
        "{report}"
    );
    assert!(report["music_beat_times"]
        .as_array()
        .is_some_and(|b| !b.is_empty()));
    // The network ran in beat time: the report says at what tempo and at what factor it heard
    // this song (never above the model's max_factor of 1: a slower song is not slowed).
    assert_eq!(
        report["beat_time"]["reference_bpm"], dr["beat_time"]["bpm"],
        "{report}"
    );
    let factor = report["beat_time"]["factor"].as_f64().expect("factor");
    assert!(factor > 0.5 && factor <= 1.0, "{factor}");

    // The same seed gives the same dance; another seed another one.
    let again = generate(&app, song_id, 1).await;
    let other = generate(&app, song_id, 8).await;
    let text = |id: String| {
        let app = &app;
        async move {
            app.get(&format!("/v1/jobs/{id}/motion.json"))
                .await
                .text()
                .await
                .expect("text")
        }
    };
    let a_id = job.clone();
    let (a, b, c) = (text(job).await, text(again).await, text(other).await);
    assert_eq!(a, b, "same seed, same dance");
    assert_ne!(a, c, "another seed, another dance");

    // Feet are planted by default; `plant_feet: false` gives the model's motion as it came: the
    // same poses, moved only horizontally, and feet that skate at least as much. The beat-align
    // stage plans its warp on the planted rhythm too where feet are planted, so the two dances
    // share their timing only where both warps were planned on the network's rhythm: seed 1's
    // are on this song (seed 7's planted warp followed the planted rhythm after the 10-s
    // warm-up), and the reports say so before the poses are compared.
    let raw = app.dance(&json!({"song_id": song_id, "model": "dance-revolution", "seed": 1, "plant_feet": false})).await;
    let warp_of = |id: String| {
        let app = &app;
        async move {
            let r: Value = app
                .get(&format!("/v1/jobs/{id}/report.json"))
                .await
                .json()
                .await
                .expect("report");
            let b = &r["beat_align"];
            (
                b["rhythm_from"].clone(),
                b["grid_fraction"].clone(),
                b["applied"].clone(),
            )
        }
    };
    let (planted_warp, raw_warp) = (warp_of(a_id.clone()).await, warp_of(raw.clone()).await);
    assert_eq!(planted_warp, raw_warp, "one warp for both");
    assert_eq!(planted_warp.0, "network", "{planted_warp:?}");
    let json_of = |id: &str| {
        let app = &app;
        let id = id.to_string();
        async move {
            app.get(&format!("/v1/jobs/{id}/motion.json"))
                .await
                .json::<Value>()
                .await
                .expect("motion json")
        }
    };
    let (planted, unplanted) = (json_of(&a_id).await, json_of(&raw).await);
    let frame = |m: &Value, f: usize| -> Vec<[f64; 3]> {
        m["positions"][f]
            .as_array()
            .expect("frame")
            .iter()
            .map(|p| [0, 1, 2].map(|c| p[c].as_f64().expect("number")))
            .collect()
    };
    let mut moved = 0.0f64;
    for f in 0..frames {
        let (p, r) = (frame(&planted, f), frame(&unplanted, f));
        // Grounding moves a whole frame up or down by one amount (the dance onto the floor).
        let dy = p[0][1] - r[0][1];
        for j in 0..p.len() {
            assert!(
                (p[j][1] - r[j][1] - dy).abs() < 1e-4,
                "a frame's heights move together (frame {f}, joint {j})"
            );
            for c in [0, 2] {
                let relative = |m: &[[f64; 3]]| m[j][c] - m[0][c];
                assert!(
                    (relative(&p) - relative(&r)).abs() < 1e-3,
                    "the pose is kept (frame {f}, joint {j})"
                );
            }
        }
        moved = moved.max((p[0][0] - r[0][0]).abs().max((p[0][2] - r[0][2]).abs()));
    }
    // Planting is judged against the same dance kept on the floor and not planted (the stage
    // grounds first, and grounding alone changes which frames touch the floor), both measured by
    // the report's metric on the dataset's 23 joints, read back as the retargeter reads a job's
    // motion.json.
    let joints = |m: &Value| {
        let json: choreo::motion::export::MotionJson =
            serde_json::from_value(m.clone()).expect("motion.json");
        choreo::motion::retarget::from_motion_json(&json)
            .expect("choreo's rig")
            .joint_positions()
    };
    let mut grounded = joints(&unplanted);
    choreo::motion::feet::keep_on_floor(grounded.view_mut(), 25.0);
    let skating = |a: &ndarray::Array3<f32>| {
        choreo::metrics::kinematics::foot_skating(
            a.view(),
            25.0,
            &choreo::motion::skeleton::FOOT_POINTS,
        )
    };
    let (planted_skate, grounded_skate) = (skating(&joints(&planted)), skating(&grounded));
    let report: Value = app
        .get(&format!("/v1/jobs/{a_id}/report.json"))
        .await
        .json()
        .await
        .expect("report");
    assert!(
        (report["scores"]["foot_skating"]["mean_contact_speed_m_s"]
            .as_f64()
            .expect("contact speed")
            - planted_skate.mean_contact_speed_m_s)
            .abs()
            < 5e-3,
        "the report measures the served motion: {report}"
    );
    eprintln!(
        "plant_feet: skate ratio {:.3} → {:.3}, contact speed {:.3} → {:.3} m/s, body moved up to {moved:.3} m",
        grounded_skate.skate_ratio,
        planted_skate.skate_ratio,
        grounded_skate.mean_contact_speed_m_s,
        planted_skate.mean_contact_speed_m_s
    );
    assert!(moved > 0.01, "planting moved the body");
    assert!(
        planted_skate.mean_contact_speed_m_s < grounded_skate.mean_contact_speed_m_s,
        "feet on the floor slide slower when planted: {planted_skate:?} vs grounded {grounded_skate:?}"
    );

    // A model that cannot honour key poses says so instead of ignoring them.
    let pose = json!({"time_s": 1.0, "joints": vec![[0.0, 0.0, 0.0]; 23]});
    let refused = app
        .post_job(
            &json!({"song_id": song_id, "model": "dance-revolution", "key_poses": [pose]}),
            None,
        )
        .await;
    expect_problem(refused, StatusCode::UNPROCESSABLE_ENTITY, "invalid-field").await;
    app.stop().await;
}
