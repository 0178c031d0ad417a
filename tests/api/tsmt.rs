//! A `tsmt` job end to end with the committed weights: a real song through the API, the sampled
//! dance back as motion.json and a report, seeded draws reproducible, sampling options checked.
use crate::common_models::models_dir;
use crate::helpers::{expect_problem, short_song, spawn_app_with};
use reqwest::StatusCode;
use serde_json::{json, Value};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tsmt_samples_a_dance_for_a_real_song() {
    let app = spawn_app_with(|c| c.models_dir = models_dir()).await;
    let capabilities = app.capabilities("tsmt").await;
    for (cap, want) in [
        ("temperature", true),
        ("top_k", true),
        ("seed_motion", true),
        ("key_poses", false),
        ("style", false),
    ] {
        assert_eq!(capabilities[cap], want, "{cap}: {capabilities}");
    }

    let song = app.upload_ok(&short_song()).await;
    let song_id = song["id"].as_str().expect("song id");
    let frames = (song["duration_s"].as_f64().expect("duration") * 25.0).floor() as usize;
    let body = |seed: u64| json!({"song_id": song_id, "model": "tsmt", "seed": seed, "temperature": 0.8, "top_k": 8});
    let job = app.dance(&body(4)).await;

    let motion: Value = app
        .get(&format!("/v1/jobs/{job}/motion.json"))
        .await
        .json()
        .await
        .expect("motion json");
    let positions = motion["positions"].as_array().expect("positions");
    assert_eq!(positions.len(), frames, "one frame per 1/25 s of music");
    let joints = motion["joint_names"].as_array().expect("joint names").len();
    let values: Vec<f64> = positions
        .iter()
        .filter_map(Value::as_array)
        .flatten()
        .filter_map(Value::as_array)
        .flatten()
        .filter_map(Value::as_f64)
        .collect();
    assert_eq!(values.len(), frames * joints * 3);
    assert!(
        values.iter().all(|v| v.is_finite() && v.abs() < 100.0),
        "positions are finite and near the dancer"
    );

    let report: Value = app
        .get(&format!("/v1/jobs/{job}/report.json"))
        .await
        .json()
        .await
        .expect("report");
    assert_eq!(report["frames"], frames);
    let speed = report["scores"]["physical"]["mean_speed_m_s"]
        .as_f64()
        .expect("speed");
    assert!(speed > 0.05, "the sampled dance moves: {speed} m/s");
    assert!(
        report["scores"]["rhythm"]["beat_prf"]["f"]
            .as_f64()
            .is_some_and(f64::is_finite),
        "TSMT's beat F rides in the report: {report}"
    );

    // Seeded sampling: the same seed gives the same dance, another seed another.
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
    let (again, other) = (app.dance(&body(4)).await, app.dance(&body(5)).await);
    let (a, b, c) = (text(job).await, text(again).await, text(other).await);
    assert_eq!(a, b, "same seed, same dance");
    assert_ne!(a, c, "another seed, another dance");

    // What comes out goes back in: the first second of this dance as a seed motion opens the next
    // dance (kept as its first frames, up to the export's rigid fit), and the rest is sampled.
    let first: Value = serde_json::from_str(&a).expect("motion json");
    let seed_frames: Vec<Value> = first["positions"].as_array().expect("positions")[..25].to_vec();
    let seeded = app.dance(&json!({"song_id": song_id, "model": "tsmt", "seed": 9, "seed_motion": {"fps": 25.0, "positions": seed_frames}})).await;
    let second: Value = serde_json::from_str(&text(seeded).await).expect("motion json");
    assert_eq!(second["positions"].as_array().map(Vec::len), Some(frames));
    let rel = |m: &Value, f: usize| -> Vec<[f64; 3]> {
        let p: Vec<[f64; 3]> = m["positions"][f]
            .as_array()
            .expect("frame")
            .iter()
            .map(|j| [0, 1, 2].map(|c| j[c].as_f64().expect("number")))
            .collect();
        p.iter()
            .map(|j| [j[0] - p[0][0], j[1] - p[0][1], j[2] - p[0][2]])
            .collect()
    };
    for f in [0, 12, 24] {
        let worst = rel(&first, f)
            .iter()
            .zip(rel(&second, f))
            .map(|(a, b)| (0..3).map(|c| (a[c] - b[c]).powi(2)).sum::<f64>().sqrt())
            .fold(0.0, f64::max);
        assert!(
            worst < 0.05,
            "seed frame {f}: a joint is {worst:.3} m from where the seed motion had it"
        );
    }

    // Sampling options out of range, and key poses the model cannot honour, are refused up front.
    for bad in [
        json!({"temperature": 0.0}),
        json!({"temperature": 6.0}),
        json!({"top_k": 0}),
        json!({"top_k": 301}),
    ] {
        let mut body = json!({"song_id": song_id, "model": "tsmt"});
        body.as_object_mut()
            .expect("object")
            .extend(bad.as_object().expect("object").clone());
        expect_problem(
            app.post_job(&body, None).await,
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid-field",
        )
        .await;
    }
    let pose = json!({"time_s": 1.0, "joints": vec![[0.0, 0.0, 0.0]; 23]});
    let keyed = app
        .post_job(
            &json!({"song_id": song_id, "model": "tsmt", "key_poses": [pose]}),
            None,
        )
        .await;
    expect_problem(keyed, StatusCode::UNPROCESSABLE_ENTITY, "invalid-field").await;
    app.stop().await;
}
