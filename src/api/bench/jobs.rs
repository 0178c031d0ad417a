//! `choreo bench jobs`: dances a minute per worker, through the real service, with 1 and 2
//! workers (or the counts asked for).
//!
//! For each worker count it starts the service on port 0 with a temporary data dir and that many
//! workers, uploads one song over HTTP, queues `jobs` dances of it (seeds 1, 2, …) at once as a
//! client would (`POST /v1/jobs`), and polls `GET /v1/jobs/{id}` until every one has finished.
//! The song's decoded audio, features and beats are computed by the first job that needs them
//! and read from the song's cache by the others, so many seeds on one song is the case measured.
//! Each worker count runs on the same song in the same process, so their ratio is the scaling.
use super::{json_field, post, BenchError, Conn};
use crate::api::Server;
use crate::config::Config;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// What to run.
#[derive(Clone, Debug)]
pub struct JobsBench {
    /// The song every job dances.
    pub song: PathBuf,
    /// The model every job asks for.
    pub model: String,
    /// Jobs queued at once (seeds 1..=jobs).
    pub jobs: usize,
    /// Worker counts to measure, each on a fresh service.
    pub workers: Vec<usize>,
    /// The service configuration (its data dir, bind address and worker count are replaced).
    pub config: Config,
}

/// One worker count's figures.
#[derive(Clone, Debug, serde::Serialize)]
pub struct JobsRow {
    pub workers: usize,
    pub jobs: usize,
    pub succeeded: usize,
    /// From the first job queued to the last one finished.
    pub seconds: f64,
    pub jobs_per_min: f64,
    pub jobs_per_min_per_worker: f64,
    /// This row's jobs per minute over the first row's, and what perfect scaling would give.
    pub speedup: f64,
    pub ideal_speedup: f64,
}

/// Runs the bench; one row per worker count, in order.
pub async fn run(bench: JobsBench) -> Result<Vec<JobsRow>, BenchError> {
    let bytes = tokio::fs::read(&bench.song).await?;
    let mut rows: Vec<JobsRow> = Vec::new();
    for &asked in &bench.workers {
        let workers = asked.max(1);
        let data = tempfile::tempdir()?;
        let mut config = bench.config.clone();
        config.data_dir = data.path().to_path_buf();
        config.bind = "127.0.0.1:0".into();
        config.workers = workers;
        let server = Server::start(config).await?;
        let result = measure(&server, &bytes, &bench, workers).await;
        server.stop().await;
        let (seconds, succeeded) = result?;
        let jobs_per_min = bench.jobs as f64 * 60.0 / seconds;
        let (base_rate, base_workers) = rows
            .first()
            .map_or((jobs_per_min, workers), |r| (r.jobs_per_min, r.workers));
        rows.push(JobsRow {
            workers,
            jobs: bench.jobs,
            succeeded,
            seconds,
            jobs_per_min,
            jobs_per_min_per_worker: jobs_per_min / workers as f64,
            speedup: jobs_per_min / base_rate,
            ideal_speedup: workers as f64 / base_workers as f64,
        });
    }
    Ok(rows)
}

/// Uploads the song, queues the jobs and waits for them: (seconds, jobs that succeeded).
async fn measure(
    server: &Server,
    song: &[u8],
    bench: &JobsBench,
    workers: usize,
) -> Result<(f64, usize), BenchError> {
    let addr = server.addr();
    let mut conn = Conn::open(addr).await?;
    let song_id = super::upload(&mut conn, song).await?;
    let started = Instant::now();
    let mut ids = Vec::with_capacity(bench.jobs);
    for seed in 1..=bench.jobs {
        let body = serde_json::json!({"song_id": song_id, "model": bench.model, "seed": seed})
            .to_string()
            .into_bytes();
        let response = post(&mut conn, "/v1/jobs", "application/json", &body, 202).await?;
        ids.push(json_field(&response, "id")?);
    }
    tracing::info!(workers, jobs = ids.len(), "jobs queued");
    let mut succeeded = 0;
    let mut pending = ids;
    // A 3-minute song takes seconds a job; polled as a client would, ten times a second.
    while !pending.is_empty() {
        tokio::time::sleep(Duration::from_millis(100)).await;
        let mut still = Vec::with_capacity(pending.len());
        for id in pending {
            let head = format!("GET /v1/jobs/{id} HTTP/1.1\r\nHost: bench\r\n\r\n");
            let (status, response) = conn.request(head.as_bytes(), &[]).await?;
            if status != 200 {
                return Err(BenchError::Protocol(format!(
                    "GET /v1/jobs/{id} answered {status}"
                )));
            }
            match json_field(&response, "status")?.as_str() {
                "succeeded" => succeeded += 1,
                "failed" | "cancelled" => {
                    return Err(BenchError::Protocol(format!(
                        "job {id} did not succeed: {}",
                        String::from_utf8_lossy(&response)
                    )))
                }
                _ => still.push(id),
            }
        }
        pending = still;
    }
    Ok((started.elapsed().as_secs_f64(), succeeded))
}
