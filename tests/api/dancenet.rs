//! A `dancenet` job end to end with the committed weights: a real song through the API, the
//! style asked for or predicted from the song (stated by the job and its report), seeded sampling
//! reproducible, a seed motion taken back in, and what the model does not take refused up front.
use crate::common_models::models_dir;
use crate::helpers::{expect_problem, short_song, spawn_app_with};
use reqwest::StatusCode;
use serde_json::{json, Value};

/// Mean distance (m) between the root-relative joints of two motion.json documents, frame by frame.
fn pose_distance(a: &Value, b: &Value) -> f64 {
    let frames = |m: &Value| -> Vec<Vec<[f64; 3]>> {
        m["positions"]
            .as_array()
            .expect("positions")
            .iter()
            .map(|f| {
                f.as_array()
                    .expect("frame")
                    .iter()
                    .map(|j| [0, 1, 2].map(|c| j[c].as_f64().expect("number")))
                    .collect()
            })
            .collect()
    };
    let (fa, fb) = (frames(a), frames(b));
    let (mut sum, mut n) = (0.0, 0usize);
    for (x, y) in fa.iter().zip(&fb) {
        for (p, q) in x.iter().zip(y) {
            sum += (0..3)
                .map(|c| ((p[c] - x[0][c]) - (q[c] - y[0][c])).powi(2))
                .sum::<f64>()
                .sqrt();
            n += 1;
        }
    }
    sum / n.max(1) as f64
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn dancenet_dances_a_real_song_in_the_style_asked_for_or_the_one_it_hears() {
    let app = spawn_app_with(|c| c.models_dir = models_dir()).await;
    let capabilities = app.capabilities("dancenet").await;
    for (cap, want) in [
        ("style", true),
        ("temperature", true),
        ("seed_motion", true),
        ("top_k", false),
        ("key_poses", false),
    ] {
        assert_eq!(capabilities[cap], want, "{cap}: {capabilities}");
    }

    let song = app.upload_ok(&short_song()).await;
    let song_id = song["id"].as_str().expect("song id");
    let frames = (song["duration_s"].as_f64().expect("duration") * 25.0).floor() as usize;

    // No style asked: the classifier picks one from the song, and the job and report say so.
    let job = app
        .dance(&json!({"song_id": song_id, "model": "dancenet", "seed": 3}))
        .await;
    let view = app.job(&job).await;
    assert_eq!(view["style"]["predicted"], true, "{view}");
    let picked = view["style"]["style"]
        .as_str()
        .expect("a style")
        .to_string();
    let p: Vec<f64> = view["style"]["probabilities"]
        .as_array()
        .expect("probabilities")
        .iter()
        .filter_map(Value::as_f64)
        .collect();
    assert_eq!(p.len(), 4);
    assert!(
        (p.iter().sum::<f64>() - 1.0).abs() < 1e-3,
        "probabilities sum to 1: {p:?}"
    );
    let report: Value = app
        .get(&format!("/v1/jobs/{job}/report.json"))
        .await
        .json()
        .await
        .expect("report");
    assert_eq!(report["style"], view["style"]);
    // dancenet runs in seconds: no clock to report.
    assert!(report.get("beat_time").is_none(), "{report}");
    // Without a seed motion its opening check ran: the draws tried, the one kept, what it saw.
    let check = &report["opening_check"];
    let (tried, kept) = (check["tried"].as_u64(), check["kept"].as_u64());
    assert!(
        matches!((tried, kept), (Some(t), Some(k)) if k < t && t <= 6),
        "{report}"
    );
    assert!(
        check["arms_m_s"].as_f64().is_some_and(|a| a > 0.0),
        "{report}"
    );
    assert_eq!(report["frames"], frames);
    let speed = report["scores"]["physical"]["mean_speed_m_s"]
        .as_f64()
        .expect("speed");
    assert!(speed > 0.1, "the sampled dance moves: {speed} m/s");

    // A style asked for is danced and stated; another style makes another dance.
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
    let other_style = if picked == "rumba" { "waltz" } else { "rumba" };
    let body = |seed: u64, style: &str| json!({"song_id": song_id, "model": "dancenet", "seed": seed, "style": style, "temperature": 0.9});
    let asked = app.dance(&body(3, other_style)).await;
    let view = app.job(&asked).await;
    assert_eq!(
        view["style"],
        json!({"style": other_style, "predicted": false}),
        "{view}"
    );
    let (a, b) = (text(job).await, text(asked.clone()).await);
    let (ma, mb): (Value, Value) = (
        serde_json::from_str(&a).expect("json"),
        serde_json::from_str(&b).expect("json"),
    );
    let d = pose_distance(&ma, &mb);
    assert!(
        d > 0.02,
        "{picked} and {other_style} danced with one seed are {d:.3} m apart"
    );

    // Seeded sampling: the same seed gives the same dance, another seed another.
    let (again, other_seed) = (
        app.dance(&body(3, other_style)).await,
        app.dance(&body(4, other_style)).await,
    );
    assert_eq!(b, text(again).await, "same seed, same dance");
    assert_ne!(b, text(other_seed).await, "another seed, another dance");

    // What comes out goes back in: the first second as a seed motion opens the next dance.
    let seed_frames: Vec<Value> = mb["positions"].as_array().expect("positions")[..25].to_vec();
    let seeded = app.dance(&json!({"song_id": song_id, "model": "dancenet", "seed": 9, "style": "waltz", "seed_motion": {"fps": 25.0, "positions": seed_frames}})).await;
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
        let worst = rel(&mb, f)
            .iter()
            .zip(rel(&second, f))
            .map(|(a, b)| (0..3).map(|c| (a[c] - b[c]).powi(2)).sum::<f64>().sqrt())
            .fold(0.0, f64::max);
        assert!(
            worst < 0.05,
            "seed frame {f}: a joint is {worst:.3} m from where the seed motion had it"
        );
    }

    // What the model does not take is refused before anything runs.
    for (bad, field) in [
        (json!({"style": "polka"}), "style"),
        (json!({"top_k": 5}), "top_k"),
        (json!({"temperature": 0.0}), "temperature"),
    ] {
        let mut body = json!({"song_id": song_id, "model": "dancenet"});
        body.as_object_mut()
            .expect("object")
            .extend(bad.as_object().expect("object").clone());
        let problem = expect_problem(
            app.post_job(&body, None).await,
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid-field",
        )
        .await;
        assert_eq!(problem["field"], field, "{problem}");
    }
    let pose = json!({"time_s": 1.0, "joints": vec![[0.0, 0.0, 0.0]; 23]});
    let keyed = app
        .post_job(
            &json!({"song_id": song_id, "model": "dancenet", "key_poses": [pose]}),
            None,
        )
        .await;
    expect_problem(keyed, StatusCode::UNPROCESSABLE_ENTITY, "invalid-field").await;
    app.stop().await;
}
