//! 50 concurrent uploads while polling at 200 requests/s: no errors, no SQLITE_BUSY as a 5xx.
use crate::helpers::{fixture, shared_audio, short_song, spawn_app};
use reqwest::StatusCode;
use serde_json::Value;
use std::collections::HashSet;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn fifty_concurrent_uploads_while_polling() {
    let app = Arc::new(spawn_app().await);
    // Ten distinct files (so ten songs), each uploaded five times at once: the duplicates race.
    let mut files = vec![
        short_song(),
        fixture("wav"),
        fixture("flac"),
        fixture("mp3"),
        fixture("m4a"),
    ];
    for name in [
        "hungarian_dance_5.ogg",
        "vibe_ace.ogg",
        "sugar_plum_fairy.ogg",
        "lets_go_fishin.ogg",
    ] {
        files.push(shared_audio().join(name));
    }
    let bytes: Vec<Vec<u8>> = files
        .iter()
        .map(|f| std::fs::read(f).expect("read"))
        .collect();
    let distinct = bytes.iter().collect::<HashSet<_>>().len();

    let done = Arc::new(AtomicBool::new(false));
    let polls = Arc::new(AtomicU64::new(0));
    let poll_failures = Arc::new(std::sync::Mutex::new(Vec::<String>::new()));
    let poller = {
        let (app, done, polls, failures) = (
            app.clone(),
            done.clone(),
            polls.clone(),
            poll_failures.clone(),
        );
        tokio::spawn(async move {
            // 200 requests/s: one every 5 ms, alternating the job list and the health probe.
            let mut tick = tokio::time::interval(Duration::from_millis(5));
            tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Burst);
            let mut n = 0u64;
            let mut in_flight = Vec::new();
            while !done.load(Ordering::Relaxed) {
                tick.tick().await;
                n += 1;
                let path = if n.is_multiple_of(2) {
                    "/v1/jobs?limit=20"
                } else {
                    "/healthz"
                };
                let (app, polls, failures) = (app.clone(), polls.clone(), failures.clone());
                in_flight.push(tokio::spawn(async move {
                    let response = app.get(path).await;
                    polls.fetch_add(1, Ordering::Relaxed);
                    if response.status() != StatusCode::OK {
                        let status = response.status();
                        let body = response.text().await.unwrap_or_default();
                        failures
                            .lock()
                            .unwrap_or_else(|p| p.into_inner())
                            .push(format!("{path}: {status} {body}"));
                    }
                }));
            }
            for task in in_flight {
                task.await.expect("poll task");
            }
        })
    };

    let started = Instant::now();
    let uploads: Vec<_> = (0..50)
        .map(|i| {
            let app = app.clone();
            let body = bytes[i % bytes.len()].clone();
            tokio::spawn(async move {
                let response = app.upload_bytes(&format!("song-{i}"), body).await;
                let status = response.status();
                let json: Value = response.json().await.expect("json");
                (status, json)
            })
        })
        .collect();
    let mut ids = HashSet::new();
    let mut created = 0;
    for upload in uploads {
        let (status, json) = upload.await.expect("upload task");
        assert!(
            status == StatusCode::CREATED || status == StatusCode::OK,
            "{status}: {json}"
        );
        created += usize::from(status == StatusCode::CREATED);
        ids.insert(json["id"].as_str().expect("id").to_string());
    }
    let upload_time = started.elapsed();
    // Keep polling a little while the analyze jobs run.
    tokio::time::sleep(Duration::from_millis(500)).await;
    done.store(true, Ordering::Relaxed);
    poller.await.expect("poller");
    let seconds = started.elapsed().as_secs_f64();

    let failures = poll_failures
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .clone();
    assert!(failures.is_empty(), "polls failed: {failures:?}");
    let polls = polls.load(Ordering::Relaxed);
    assert!(
        polls as f64 >= 150.0 * seconds,
        "{polls} polls in {seconds:.1} s is under 200/s"
    );
    assert_eq!(ids.len(), distinct, "each distinct file is one song");
    assert_eq!(
        created, distinct,
        "exactly one upload per distinct file created it"
    );
    let page: Value = app
        .get("/v1/jobs?limit=100")
        .await
        .json()
        .await
        .expect("page");
    assert_eq!(
        page["items"].as_array().map(Vec::len),
        Some(distinct),
        "one analyze job per song"
    );
    eprintln!(
        "50 uploads in {:.2} s; {polls} polls in {seconds:.2} s",
        upload_time.as_secs_f64()
    );
}
