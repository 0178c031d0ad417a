//! report.json's `serving` list: one entry per serving stage that ran, in the order they run,
//! with numbers a reader can trust, on a real song through the real model.
use crate::common_models::models_dir;
use crate::helpers::{short_song, spawn_app_with, TestApp};
use serde_json::{json, Value};

async fn serving(app: &TestApp, request: Value) -> Vec<Value> {
    let job = app.dance(&request).await;
    let report: Value = app
        .get(&format!("/v1/jobs/{job}/report.json"))
        .await
        .json()
        .await
        .expect("report");
    report["serving"]
        .as_array()
        .unwrap_or_else(|| panic!("report.json has a serving list: {report}"))
        .clone()
}

fn names(stages: &[Value]) -> Vec<&str> {
    stages.iter().filter_map(|s| s["stage"].as_str()).collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_report_says_what_each_serving_stage_did() {
    let app = spawn_app_with(|c| c.models_dir = models_dir()).await;
    let song = app.upload_ok(&short_song()).await;
    let song_id = song["id"].as_str().expect("song id");
    let request = json!({"song_id": song_id, "model": "dance-revolution", "seed": 1});
    let stages = serving(&app, request).await;
    // A steady song: tempo_follow runs and leaves it (the song's tempo does not change).
    assert_eq!(
        names(&stages),
        [
            "tempo_follow",
            "beat_align",
            "knees_forward",
            "ground",
            "land_hangs",
            "plant_feet",
            "rigid_fit",
            "calm_bursts",
            "ground_rig",
        ],
        "{stages:#?}"
    );
    let frames = |s: &Value| s["frames_changed"].as_u64().expect("frames_changed");
    for s in &stages {
        let largest = s["largest_move_m"].as_f64().expect("largest_move_m");
        assert!(largest >= 0.0 && largest.is_finite(), "{s}");
        assert_eq!(s["changed"].as_bool(), Some(frames(s) > 0), "{s}");
        assert_eq!(frames(s) == 0, largest == 0.0, "{s}");
        for side in ["before", "after"] {
            for measure in ["authenticity", "coherence"] {
                let v = s[side][measure].as_f64().expect("plausibility");
                assert!((0.0..=1.0).contains(&v), "{side}.{measure} of {s}");
            }
        }
    }
    // Each stage is given what the one before it left.
    for pair in stages.windows(2) {
        assert_eq!(pair[0]["after"], pair[1]["before"], "{pair:?}");
    }
    let stage = |name: &str| {
        stages
            .iter()
            .find(|s| s["stage"] == name)
            .unwrap_or_else(|| panic!("{name} in {stages:#?}"))
    };
    // A network's feet slide: planting holds them on a real song, and says how often.
    let plant = stage("plant_feet");
    assert!(frames(plant) > 0, "{plant}");
    assert!(plant["frame_steps_planted"].as_u64().expect("count") > 0);
    // The rigid fit moves every frame a little (bones at one length), none by a metre.
    let fit = stage("rigid_fit");
    assert!(frames(fit) > 0, "{fit}");
    assert!(fit["largest_move_m"].as_f64().expect("move") < 1.0, "{fit}");
    // Counts ride only on the stages that keep them.
    assert!(stage("beat_align")["frames_retimed"].is_u64());
    assert!(stage("knees_forward")["knee_frames_turned"].is_u64());
    assert!(stage("calm_bursts")["frames_calmed"].is_u64());
    assert!(fit.get("frames_retimed").is_none(), "{fit}");

    // Feet as they came: the stages that plant them did not run, and the list says so.
    let request =
        json!({"song_id": song_id, "model": "dance-revolution", "seed": 1, "plant_feet": false});
    let raw = serving(&app, request).await;
    assert_eq!(
        names(&raw),
        ["tempo_follow", "beat_align", "rigid_fit"],
        "{raw:#?}"
    );
    app.stop().await;
}
