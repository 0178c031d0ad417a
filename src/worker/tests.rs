//! Worker tests against a real SQLite file, with an executor whose behaviour each song names.
use super::*;
use crate::audio::{Analysis, AudioFormat};
use crate::queue::{
    JobId, JobKind, NewJob, Scope, SongId, SongStore, SqliteStore, Status, TenantId,
};
use crate::stage::Stage;

/// Panics for songs named `panic`, runs until cancelled for `slow`, succeeds otherwise.
struct Scripted;

impl Execute for Scripted {
    fn execute(
        &self,
        _job: &Job,
        song: &Song,
        progress: &mut dyn Progress,
    ) -> Result<Outcome, WorkerError> {
        match song.filename.as_str() {
            "panic" => panic!("injected fault"),
            "slow" => {
                for i in 0..1000 {
                    progress.report(Stage::Analyze, i as f32 / 1000.0)?;
                    std::thread::sleep(Duration::from_millis(10));
                }
                Err(WorkerError::Export("slow job was never cancelled".into()))
            }
            _ => Ok(Outcome::Analysis(Analysis {
                tempo_bpm: 120.0,
                beat_times: vec![0.5],
                downbeat_times: vec![0.5],
                tempo_curve: vec![],
            })),
        }
    }
}

/// A song (an empty file in the data dir: `Scripted` never reads it) and its analyze job.
async fn add(store: &SqliteStore, data: &std::path::Path, name: &str) -> JobId {
    let song = Song {
        id: SongId::new(),
        tenant: TenantId::OPEN,
        filename: name.into(),
        format: AudioFormat::Wav,
        duration_s: 1.0,
        sample_rate: 8000,
        channels: 1,
        sha256: format!("sha-{name}"),
        size_bytes: 1,
        analysis: None,
        created_at: chrono::Utc::now(),
    };
    std::fs::write(
        DataDir::create(data)
            .expect("data dir")
            .song_path(song.id, song.format),
        b"",
    )
    .expect("song file");
    let job = NewJob {
        tenant: TenantId::OPEN,
        kind: JobKind::Analyze { song_id: song.id },
        priority: 0,
        max_attempts: 1,
        idempotency: None,
    };
    let (song, _) = store.add_song(song, job).await.expect("add song");
    store
        .analyze_job(song.id)
        .await
        .expect("query")
        .expect("analyze job")
        .id
}

async fn wait_terminal(store: &SqliteStore, id: JobId) -> Job {
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let job = store.job(Scope::All, id).await.expect("job");
        if job.status.is_terminal() {
            return job;
        }
        assert!(
            Instant::now() < deadline,
            "job {id} still {} after 20 s",
            job.status
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

fn context(store: Arc<SqliteStore>, data: &std::path::Path) -> Context {
    Context {
        store,
        artifacts: Arc::new(crate::artifacts::LocalArtifacts::new(
            DataDir::create(data).expect("data dir"),
        )),
        executor: Arc::new(Scripted),
        policy: LeasePolicy {
            lease: Duration::from_secs(5),
            backoff: Duration::ZERO,
        },
        heartbeat: Duration::from_millis(50),
        poll: Duration::from_millis(20),
        wake: Arc::new(Notify::new()),
        alive: Arc::default(),
        data_root: data.to_path_buf(),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_panic_fails_its_job_and_the_worker_runs_the_next() {
    let dir = tempfile::tempdir().expect("tempdir");
    let store = Arc::new(
        SqliteStore::open(&dir.path().join("db.sqlite"))
            .await
            .expect("open"),
    );
    let bad = add(&store, dir.path(), "panic").await;
    let good = add(&store, dir.path(), "fine").await;
    let shutdown = CancellationToken::new();
    let handles = start(context(store.clone(), dir.path()), 1, shutdown.clone());

    let bad = wait_terminal(&store, bad).await;
    assert_eq!(bad.status, Status::Failed);
    let error = bad.error.unwrap_or_default();
    assert!(
        error.contains("panicked") && error.contains("injected fault"),
        "{error}"
    );
    let good = wait_terminal(&store, good).await;
    assert_eq!(
        good.status,
        Status::Succeeded,
        "the same single worker ran the next job"
    );
    let song = store
        .song(Scope::All, good.kind.song_id())
        .await
        .expect("song");
    assert_eq!(song.analysis.map(|a| a.tempo_bpm), Some(120.0));

    shutdown.cancel();
    for handle in handles {
        handle.await.expect("worker task ends cleanly");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_cancelled_running_job_stops_at_its_next_checkpoint() {
    let dir = tempfile::tempdir().expect("tempdir");
    let store = Arc::new(
        SqliteStore::open(&dir.path().join("db.sqlite"))
            .await
            .expect("open"),
    );
    let slow = add(&store, dir.path(), "slow").await;
    let shutdown = CancellationToken::new();
    let handles = start(context(store.clone(), dir.path()), 1, shutdown.clone());

    // Wait until it runs and has reported progress through a heartbeat.
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        let job = store.job(Scope::All, slow).await.expect("job");
        if job.status == Status::Running && job.progress > 0.0 {
            assert_eq!(job.stage, Some(Stage::Analyze));
            break;
        }
        assert!(
            Instant::now() < deadline,
            "job never showed progress: {job:?}"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let asked = Instant::now();
    store.cancel(Scope::All, slow).await.expect("cancel");
    let job = wait_terminal(&store, slow).await;
    assert_eq!(job.status, Status::Cancelled);
    assert!(
        asked.elapsed() < Duration::from_secs(2),
        "stopped within a heartbeat or two: {:?}",
        asked.elapsed()
    );
    assert!(job.progress < 1.0);

    shutdown.cancel();
    for handle in handles {
        handle.await.expect("worker task ends cleanly");
    }
}
