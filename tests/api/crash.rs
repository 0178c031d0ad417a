//! Crash recovery: `kill -9` a real `choreo serve` mid-job, restart it on the same data dir,
//! and every job finishes exactly once.
use crate::helpers::{short_song, song};
use serde_json::Value;
use sqlx::sqlite::SqliteConnectOptions;
use sqlx::Row;
use std::path::Path;
use std::process::Stdio;
use std::time::{Duration, Instant};
use tokio::io::{AsyncBufReadExt, BufReader};
use tokio::process::{Child, Command};

/// Starts `choreo serve` on port 0 and returns it with its address.
async fn serve(data_dir: &Path) -> (Child, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_choreo"))
        .args([
            "serve",
            "--bind",
            "127.0.0.1:0",
            "--workers",
            "1",
            "--data-dir",
        ])
        .arg(data_dir)
        .arg("--models-dir")
        .arg(data_dir.join("no-models"))
        // A short lease, so the dead process's job is requeued quickly after the restart.
        .env("CHOREO_LEASE_S", "1")
        .env("CHOREO_HEARTBEAT_S", "0.2")
        .env("CHOREO_RETRY_BACKOFF_S", "0")
        .env("CHOREO_POLL_S", "0.1")
        .env("RUST_LOG", "warn")
        .stdout(Stdio::piped())
        .kill_on_drop(true)
        .spawn()
        .expect("spawn choreo serve");
    let stdout = child.stdout.take().expect("stdout");
    let mut lines = BufReader::new(stdout).lines();
    let line = tokio::time::timeout(Duration::from_secs(30), lines.next_line())
        .await
        .expect("choreo serve printed its address within 30 s")
        .expect("read stdout")
        .expect("a line");
    let addr = crate::helpers::listening_base(&line);
    (child, addr)
}

async fn jobs(client: &reqwest::Client, base: &str, query: &str) -> Vec<Value> {
    let page: Value = client
        .get(format!("{base}/v1/jobs?limit=100{query}"))
        .send()
        .await
        .expect("GET")
        .json()
        .await
        .expect("json");
    page["items"].as_array().expect("items").clone()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_killed_server_resumes_and_every_job_finishes_exactly_once() {
    let data = tempfile::tempdir().expect("tempdir");
    let client = reqwest::Client::new();
    let (mut first, base) = serve(data.path()).await;

    let names = [
        "lets_go_fishin.ogg",
        "sugar_plum_fairy.ogg",
        "vibe_ace.ogg",
        "hungarian_dance_5.ogg",
    ];
    let mut paths: Vec<_> = names.iter().map(|n| song(n)).collect();
    paths.push(short_song());
    for path in &paths {
        let bytes = std::fs::read(path).expect("read");
        crate::helpers::upload_to(&client, &base, bytes, "song.ogg").await;
    }

    // Wait for a job to be mid-run, then kill -9.
    let deadline = Instant::now() + Duration::from_secs(60);
    let running = loop {
        let running = jobs(&client, &base, "&status=running").await;
        if let Some(job) = running.first() {
            break job["id"].as_str().expect("id").to_string();
        }
        assert!(Instant::now() < deadline, "no job started within 60 s");
        tokio::time::sleep(Duration::from_millis(10)).await;
    };
    first.start_kill().expect("SIGKILL");
    first.wait().await.expect("killed server exits");

    let (mut second, base) = serve(data.path()).await;
    let deadline = Instant::now() + Duration::from_secs(180);
    let all = loop {
        let all = jobs(&client, &base, "").await;
        if all.iter().all(|j| {
            ["succeeded", "failed", "cancelled"].contains(&j["status"].as_str().unwrap_or(""))
        }) {
            break all;
        }
        assert!(
            Instant::now() < deadline,
            "jobs unfinished 180 s after the restart: {all:?}"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    };
    assert_eq!(all.len(), paths.len(), "no job lost or duplicated: {all:?}");
    for job in &all {
        assert_eq!(job["status"], "succeeded", "{job}");
        let song: Value = client
            .get(format!(
                "{base}{}",
                job["links"]["song"].as_str().expect("link")
            ))
            .send()
            .await
            .expect("GET")
            .json()
            .await
            .expect("json");
        assert!(song["analysis"]["tempo_bpm"].is_number(), "{song}");
    }
    // The job seen running is the one killed, unless it finished in the instant before the kill;
    // either way exactly one job ran twice.
    let twice: Vec<&Value> = all.iter().filter(|j| j["attempts"] == 2).collect();
    assert_eq!(
        twice.len(),
        1,
        "exactly one job was cut off and ran again: {all:?}"
    );
    let killed = twice[0]["id"].as_str().expect("id").to_string();
    if killed != running {
        eprintln!(
            "note: job {running} finished just before the kill; {killed} was the one cut off"
        );
    }

    // Graceful stop, then read the real SQLite file: its event log shows each job succeeded once.
    let pid = second.id().expect("pid").to_string();
    let status = std::process::Command::new("kill")
        .args(["-TERM", &pid])
        .status()
        .expect("kill -TERM");
    assert!(status.success());
    let exit = tokio::time::timeout(Duration::from_secs(30), second.wait())
        .await
        .expect("stops within 30 s")
        .expect("exit");
    assert!(exit.success(), "graceful shutdown exits 0: {exit}");

    let options = SqliteConnectOptions::new()
        .filename(data.path().join("choreo.sqlite"))
        .read_only(true);
    let pool = sqlx::SqlitePool::connect_with(options)
        .await
        .expect("open db");
    let rows = sqlx::query(
        "SELECT job_id, SUM(to_status = 'succeeded'), SUM(to_status = 'running'), SUM(from_status = 'running' AND to_status = 'queued') \
         FROM job_events GROUP BY job_id",
    )
    .fetch_all(&pool)
    .await
    .expect("events");
    assert_eq!(rows.len(), paths.len());
    for row in rows {
        let id: String = row.get(0);
        let (succeeded, runs, requeues): (i64, i64, i64) = (row.get(1), row.get(2), row.get(3));
        assert_eq!(succeeded, 1, "job {id} succeeded exactly once");
        if id == killed {
            assert_eq!(
                (runs, requeues),
                (2, 1),
                "job {id}: killed mid-run, requeued once, run again"
            );
        } else {
            assert_eq!((runs, requeues), (1, 0), "job {id} ran once");
        }
    }
}
