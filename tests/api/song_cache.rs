//! A song's work done once: three generate jobs with other seeds on one song decode it, analyse
//! it, compute its features and run the model's music encoder once (counted on `/metrics`; for
//! dance-revolution, then dancenet), a fourth job with the first one's seed, served all from the
//! caches, makes byte for byte the same dance, the cache counts in the
//! tenant's storage, and it goes with the song.
//!
//! A `choreo serve` process of its own: the stage metrics are the process's, and other tests in
//! this binary run jobs at the same time.
use crate::common_models::models_dir;
use crate::helpers::{short_song, spawn_process, upload_to};
use choreo::queue::TenantId;
use serde_json::{json, Value};
use std::path::Path;
use std::process::Stdio;
use std::time::{Duration, Instant};
use tokio::process::Command;

/// Models with an encoder pass kept for the next seeds: each asks for a feature set of its own.
const MODELS: [&str; 2] = ["dance-revolution", "dancenet"];

async fn dance(
    client: &reqwest::Client,
    base: &str,
    song_id: &str,
    model: &str,
    seed: u64,
) -> String {
    let response = client
        .post(format!("{base}/v1/jobs"))
        .json(&json!({"song_id": song_id, "model": model, "seed": seed}))
        .send()
        .await
        .expect("POST /v1/jobs");
    assert_eq!(response.status(), reqwest::StatusCode::ACCEPTED);
    let job: Value = response.json().await.expect("job");
    let id = job["id"].as_str().expect("id").to_string();
    let deadline = Instant::now() + Duration::from_secs(120);
    loop {
        let job: Value = client
            .get(format!("{base}/v1/jobs/{id}"))
            .send()
            .await
            .expect("GET job")
            .json()
            .await
            .expect("job json");
        match job["status"].as_str() {
            Some("succeeded") => return id,
            Some("failed" | "cancelled") => panic!("job {id} did not succeed: {job}"),
            _ => {}
        }
        assert!(Instant::now() < deadline, "job {id} not done in 120 s");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// `choreo_stage_duration_seconds_count{kind="generate",stage=…}` for each stage.
async fn generate_stage_counts(client: &reqwest::Client, base: &str) -> Vec<(String, u64)> {
    let text = client
        .get(format!("{base}/metrics"))
        .send()
        .await
        .expect("GET /metrics")
        .text()
        .await
        .expect("metrics text");
    ["decode-audio", "analyze", "features", "encode"]
        .into_iter()
        .map(|stage| {
            let count = text
                .lines()
                .filter(|l| {
                    l.starts_with("choreo_stage_duration_seconds_count")
                        && l.contains("kind=\"generate\"")
                        && l.contains(&format!("stage=\"{stage}\""))
                })
                .filter_map(|l| l.rsplit(' ').next()?.parse::<u64>().ok())
                .sum();
            (stage.to_string(), count)
        })
        .collect()
}

async fn motion_json(client: &reqwest::Client, base: &str, job: &str) -> Vec<u8> {
    let response = client
        .get(format!("{base}/v1/jobs/{job}/motion.json"))
        .send()
        .await
        .expect("GET motion.json");
    assert_eq!(response.status(), reqwest::StatusCode::OK);
    response.bytes().await.expect("bytes").to_vec()
}

fn dir_bytes(dir: &Path) -> u64 {
    std::fs::read_dir(dir)
        .map(|entries| {
            entries
                .filter_map(Result::ok)
                .filter_map(|e| e.metadata().ok())
                .map(|m| m.len())
                .sum()
        })
        .unwrap_or(0)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn three_seeds_on_one_song_decode_analyse_compute_features_and_encode_once() {
    let data = tempfile::tempdir().expect("tempdir");
    let mut command = Command::new(env!("CARGO_BIN_EXE_choreo"));
    command
        .args(["serve", "--bind", "127.0.0.1:0", "--workers", "1"])
        .arg("--data-dir")
        .arg(data.path())
        .arg("--models-dir")
        .arg(models_dir())
        .env("CHOREO_POLL_S", "0.1")
        .env("RUST_LOG", "warn")
        .stdout(Stdio::piped())
        .kill_on_drop(true);
    let (mut child, line) = spawn_process(command).await;
    let base = crate::helpers::listening_base(&line);
    let client = reqwest::Client::new();

    let bytes = std::fs::read(short_song()).expect("song");
    let song = upload_to(&client, &base, bytes, "trumpet.ogg").await;
    let song_id = song["id"].as_str().expect("song id").to_string();

    for (i, model) in MODELS.into_iter().enumerate() {
        let first = dance(&client, &base, &song_id, model, 1).await;
        dance(&client, &base, &song_id, model, 2).await;
        dance(&client, &base, &song_id, model, 3).await;
        // The song analysed once in all; decoded once for each model's features (the samples are
        // not stored), and each model's features and encoding once.
        let once = vec![
            ("decode-audio".to_string(), i as u64 + 1),
            ("analyze".to_string(), 1),
            ("features".to_string(), i as u64 + 1),
            ("encode".to_string(), i as u64 + 1),
        ];
        assert_eq!(generate_stage_counts(&client, &base).await, once, "{model}");

        // Seed 1 again, all from the caches: the dance of the job that computed everything.
        let again = dance(&client, &base, &song_id, model, 1).await;
        assert_eq!(generate_stage_counts(&client, &base).await, once, "{model}");
        assert!(
            motion_json(&client, &base, &first).await == motion_json(&client, &base, &again).await,
            "{model}: the cached job's motion.json differs from the uncached one's"
        );
    }

    // Stored beside the song, counted with it in its tenant's storage.
    let cache = data.path().join("song-cache").join(&song_id);
    let cached = dir_bytes(&cache);
    assert!(cached > 0, "nothing in {}", cache.display());
    let store = choreo::queue::open(
        &choreo::config::Database::Sqlite(data.path().join("choreo.sqlite")),
        Duration::from_secs(5),
    )
    .await
    .expect("open the store");
    let id = song_id.parse().expect("song id");
    let size = store
        .song(choreo::queue::Scope::All, id)
        .await
        .expect("song")
        .size_bytes;
    let usage = store.usage(TenantId::OPEN).await.expect("usage");
    let results: u64 = {
        let mut sum = 0;
        for job in std::fs::read_dir(data.path().join("jobs")).expect("jobs dir") {
            sum += dir_bytes(&job.expect("entry").path());
        }
        sum
    };
    assert_eq!(usage.stored_bytes, size + cached + results);

    // Deleted with the song.
    let response = client
        .delete(format!("{base}/v1/songs/{song_id}"))
        .send()
        .await
        .expect("DELETE");
    assert_eq!(response.status(), reqwest::StatusCode::NO_CONTENT);
    assert!(!cache.exists(), "{} outlived its song", cache.display());
    assert_eq!(
        store
            .usage(TenantId::OPEN)
            .await
            .expect("usage")
            .stored_bytes,
        0
    );

    child.start_kill().expect("stop choreo serve");
    let _ = child.wait().await;
}
