//! Scale-out: one API process (`choreo serve --no-workers`) and three worker processes
//! (`choreo worker`) share a real PostgreSQL and a data dir. While 120 songs' analyze jobs run,
//! workers are SIGKILLed at random and started again; from `job_events`, every job succeeded
//! exactly once and none was lost.
use crate::helpers::{listening_base, spawn_process as spawn, upload_to};
use crate::postgres::Postgres;
use rand::{Rng, SeedableRng};
use reqwest::StatusCode;
use sqlx::Row;
use std::path::Path;
use std::process::Stdio;
use std::time::{Duration, Instant};
use tokio::process::{Child, Command};

/// Songs uploaded, so analyze jobs run.
const SONGS: usize = 120;
/// Worker processes.
const WORKERS: usize = 3;

/// `choreo <args>` sharing the database and data dir, with short leases so a killed worker's
/// job returns to the queue within a second.
fn choreo(args: &[&str], data_dir: &Path, database_url: &str) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_choreo"));
    c.args(args)
        .arg("--data-dir")
        .arg(data_dir)
        .arg("--models-dir")
        .arg(data_dir.join("no-models"))
        .env("CHOREO_DATABASE_URL", database_url)
        .env("CHOREO_LEASE_S", "1")
        .env("CHOREO_HEARTBEAT_S", "0.2")
        .env("CHOREO_RETRY_BACKOFF_S", "0")
        .env("CHOREO_POLL_S", "0.5")
        // Enough attempts that no job runs out of them however often its workers die.
        .env("CHOREO_MAX_ATTEMPTS", "50")
        .env("RUST_LOG", "warn")
        .stdout(Stdio::piped())
        .kill_on_drop(true);
    c
}

async fn worker(data_dir: &Path, url: &str) -> Child {
    let (child, line) = spawn(choreo(&["worker", "--workers", "1"], data_dir, url)).await;
    assert_eq!(line, "choreo worker running 1 workers");
    child
}

/// A 30 s mono 22 050 Hz WAV click track at `bpm`, with a little seeded noise: real audio the
/// analysis finds beats in, and different bytes for every song.
fn click_track(bpm: f64, seed: u64) -> Vec<u8> {
    const SR: u32 = 22_050;
    let n = SR as usize * 30;
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let period = 60.0 / bpm;
    let mut bytes = Vec::with_capacity(44 + 2 * n);
    bytes.extend_from_slice(b"RIFF");
    bytes.extend_from_slice(&(36 + 2 * n as u32).to_le_bytes());
    bytes.extend_from_slice(b"WAVEfmt ");
    bytes.extend_from_slice(&16u32.to_le_bytes());
    bytes.extend_from_slice(&1u16.to_le_bytes());
    bytes.extend_from_slice(&1u16.to_le_bytes());
    bytes.extend_from_slice(&SR.to_le_bytes());
    bytes.extend_from_slice(&(SR * 2).to_le_bytes());
    bytes.extend_from_slice(&2u16.to_le_bytes());
    bytes.extend_from_slice(&16u16.to_le_bytes());
    bytes.extend_from_slice(b"data");
    bytes.extend_from_slice(&(2 * n as u32).to_le_bytes());
    for i in 0..n {
        let t = i as f64 / f64::from(SR);
        let since_beat = t % period;
        let click = (-since_beat * 40.0).exp() * (2.0 * std::f64::consts::PI * 1000.0 * t).sin();
        let sample = 0.6 * click + 0.01 * rng.gen_range(-1.0..1.0);
        bytes.extend_from_slice(&((sample * 32_767.0) as i16).to_le_bytes());
    }
    bytes
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn workers_killed_at_random_lose_no_job_and_run_each_once() {
    let server = tokio::task::spawn_blocking(Postgres::start)
        .await
        .expect("start postgres");
    let url = server.url();
    let data = tempfile::tempdir().expect("tempdir");
    let (_api, line) = spawn(choreo(
        &["serve", "--no-workers", "--bind", "127.0.0.1:0"],
        data.path(),
        &url,
    ))
    .await;
    let base = listening_base(&line);
    let client = reqwest::Client::new();
    let ready = client
        .get(format!("{base}/readyz"))
        .send()
        .await
        .expect("readyz");
    assert_eq!(
        ready.status(),
        StatusCode::OK,
        "an API-only process is ready without workers"
    );

    let mut workers = Vec::new();
    for _ in 0..WORKERS {
        workers.push(worker(data.path(), &url).await);
    }

    let started = Instant::now();
    let uploads = tokio::spawn({
        let (client, base) = (client.clone(), base.clone());
        async move {
            for i in 0..SONGS {
                let wav = click_track(80.0 + i as f64 * 0.5, i as u64);
                upload_to(&client, &base, wav, &format!("click-{i}.wav")).await;
            }
        }
    });

    let pool = sqlx::PgPool::connect(&url)
        .await
        .expect("connect to postgres");
    let mut rng = rand::rngs::StdRng::seed_from_u64(15);
    let mut kills = 0;
    let deadline = Instant::now() + Duration::from_secs(420);
    loop {
        // Jobs take tens of milliseconds, so a kill at a random moment often lands between jobs:
        // aim at a process that holds a running job (its lease owner is `<pid>-<suffix>`), at a
        // random short delay, so recovery is exercised on every run.
        tokio::time::sleep(Duration::from_millis(rng.gen_range(30..300))).await;
        let (jobs, open): (i64, i64) = {
            let row = sqlx::query("SELECT COUNT(*), COUNT(*) FILTER (WHERE status IN ('queued', 'running')) FROM jobs")
                .fetch_one(&pool)
                .await
                .expect("count jobs");
            (row.get(0), row.get(1))
        };
        if uploads.is_finished() && jobs == SONGS as i64 && open == 0 {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "{open} of {jobs} jobs still open after 420 s ({kills} kills)"
        );
        let owners: Vec<String> = sqlx::query_scalar(
            "SELECT lease_owner FROM jobs WHERE status = 'running' AND lease_owner IS NOT NULL",
        )
        .fetch_all(&pool)
        .await
        .expect("running jobs");
        let busy: Vec<usize> = (0..WORKERS)
            .filter(|&w| {
                let pid = workers[w].id().map(|p| format!("{p}-"));
                pid.is_some_and(|pid| owners.iter().any(|o| o.starts_with(&pid)))
            })
            .collect();
        let victim = if busy.is_empty() {
            rng.gen_range(0..WORKERS)
        } else {
            busy[rng.gen_range(0..busy.len())]
        };
        workers[victim].start_kill().expect("SIGKILL");
        workers[victim].wait().await.expect("killed worker exits");
        kills += 1;
        workers[victim] = worker(data.path(), &url).await;
    }
    uploads.await.expect("uploads");
    let elapsed = started.elapsed();

    let rows = sqlx::query(
        "SELECT j.id::TEXT, j.status, j.attempts, \
                COUNT(*) FILTER (WHERE e.to_status = 'succeeded'), \
                COUNT(*) FILTER (WHERE e.to_status = 'running'), \
                COUNT(*) FILTER (WHERE e.from_status = 'running' AND e.to_status = 'queued') \
         FROM jobs j JOIN job_events e ON e.job_id = j.id GROUP BY j.id, j.status, j.attempts",
    )
    .fetch_all(&pool)
    .await
    .expect("events");
    assert_eq!(rows.len(), SONGS, "one analyze job per song, none lost");
    let mut requeued = 0;
    for row in &rows {
        let (id, status, attempts): (String, String, i64) = (row.get(0), row.get(1), row.get(2));
        let (succeeded, runs, requeues): (i64, i64, i64) = (row.get(3), row.get(4), row.get(5));
        assert_eq!(
            (status.as_str(), succeeded),
            ("succeeded", 1),
            "job {id} succeeded exactly once"
        );
        assert_eq!(runs, attempts, "job {id}: every attempt is one claim");
        assert_eq!(
            requeues,
            runs - 1,
            "job {id}: each extra run follows a requeue of a killed attempt"
        );
        requeued += requeues;
    }
    let analysed: i64 = sqlx::query("SELECT COUNT(*) FROM songs WHERE analysis IS NOT NULL")
        .fetch_one(&pool)
        .await
        .expect("songs")
        .get(0);
    assert_eq!(analysed, SONGS as i64, "every song has its analysis");
    let owners: i64 =
        sqlx::query("SELECT COUNT(DISTINCT worker) FROM job_events WHERE to_status = 'succeeded'")
            .fetch_one(&pool)
            .await
            .expect("owners")
            .get(0);
    eprintln!(
        "scale-out: {SONGS} jobs in {:.1} s on {WORKERS} worker processes, {kills} SIGKILLs, {requeued} attempts cut off and rerun, \
         finished by {owners} worker lives",
        elapsed.as_secs_f64()
    );
    assert!(kills > 0, "the test killed workers");
    assert!(
        requeued > 0,
        "at least one kill landed mid-job, so recovery was exercised"
    );
    assert!(
        owners > WORKERS as i64,
        "jobs were finished by restarted workers too"
    );
}
