//! The job store's contract, run against both stores: a SQLite file and a real PostgreSQL
//! server started for each test (`common/postgres.rs`). Each contract is a function of the store;
//! `contract!` makes one test per store from it, so both stores answer every case the same way.
#[path = "queue/deletion.rs"]
mod deletion;
#[path = "common/postgres.rs"]
mod postgres;
#[path = "queue/rigs.rs"]
mod rigs;
#[path = "queue/tenants.rs"]
mod tenants;

use choreo::audio::AudioFormat;
use choreo::queue::{
    Beat, Idempotency, JobFiles, JobFilter, JobId, JobKind, LeasePolicy, NewJob, Outcome, PgStore,
    QueueError, Registered, Scope, Song, SongId, SqliteStore, Status, Store, TenantId,
};
use choreo::stage::Stage;
use chrono::Utc;
use sqlx::Row;
use std::collections::HashSet;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::Notify;
use tokio_util::sync::CancellationToken;

use deletion::deletion_and_expiry_leave_only_an_audit_line;
use rigs::{
    rigs_keep_their_skeleton_and_mapping, rigs_list_by_tenant_delete_once_and_expire_unused,
};
use tenants::{claims_are_fair_between_tenants, tenants_see_only_their_own_rows};

/// A store under test and what keeps it alive (its temp dir or its server).
struct TestDb {
    store: Arc<dyn Store>,
    events: Events,
    _dir: Option<tempfile::TempDir>,
    _server: Option<postgres::Postgres>,
}

/// Raw access to `job_events`, which no trait method reads.
enum Events {
    Sqlite(SqliteStore),
    Postgres(PgStore),
}

impl TestDb {
    async fn sqlite() -> Self {
        let dir = tempfile::tempdir().expect("tempdir");
        let store = SqliteStore::open(&dir.path().join("q.sqlite"))
            .await
            .expect("open sqlite");
        Self {
            store: Arc::new(store.clone()),
            events: Events::Sqlite(store),
            _dir: Some(dir),
            _server: None,
        }
    }

    async fn postgres() -> Self {
        let server = tokio::task::spawn_blocking(postgres::Postgres::start)
            .await
            .expect("start postgres");
        let url = choreo::config::Secret::new(server.url());
        let store = PgStore::connect(&url, std::time::Duration::from_secs(3))
            .await
            .expect("connect postgres");
        Self {
            store: Arc::new(store.clone()),
            events: Events::Postgres(store),
            _dir: None,
            _server: Some(server),
        }
    }

    /// `(from_status, to_status)` of a job's events, oldest first.
    async fn events(&self, id: JobId) -> Vec<(Option<String>, String)> {
        let rows = match &self.events {
            Events::Sqlite(s) => sqlx::query(
                "SELECT from_status, to_status FROM job_events WHERE job_id = ? ORDER BY seq",
            )
            .bind(id.to_string())
            .fetch_all(s.pool())
            .await
            .expect("sqlite events")
            .iter()
            .map(|r| (r.get::<Option<String>, _>(0), r.get::<String, _>(1)))
            .collect(),
            Events::Postgres(s) => sqlx::query(
                "SELECT from_status, to_status FROM job_events WHERE job_id = $1 ORDER BY seq",
            )
            .bind(id.0)
            .fetch_all(s.pool())
            .await
            .expect("postgres events")
            .iter()
            .map(|r| (r.get::<Option<String>, _>(0), r.get::<String, _>(1)))
            .collect(),
        };
        rows
    }
}

fn policy(lease_ms: u64, backoff_ms: u64) -> LeasePolicy {
    LeasePolicy {
        lease: Duration::from_millis(lease_ms),
        backoff: Duration::from_millis(backoff_ms),
    }
}

fn song(sha: &str) -> Song {
    Song {
        id: SongId::new(),
        tenant: TenantId::OPEN,
        filename: "a.ogg".into(),
        format: AudioFormat::Ogg,
        duration_s: 1.0,
        sample_rate: 44_100,
        channels: 2,
        sha256: sha.into(),
        size_bytes: 1,
        analysis: None,
        created_at: Utc::now(),
    }
}

fn analyze(song: SongId, max_attempts: u32) -> NewJob {
    NewJob {
        tenant: TenantId::OPEN,
        kind: JobKind::Analyze { song_id: song },
        priority: 0,
        max_attempts,
        idempotency: None,
    }
}

/// A song with its analyze job (`max_attempts` 2), which is queued.
async fn with_song(store: &dyn Store) -> SongId {
    let s = song(&format!("sha-{}", SongId::new()));
    let id = s.id;
    let (stored, created) = store.add_song(s, analyze(id, 2)).await.expect("add song");
    assert!(created);
    stored.id
}

async fn claim_is_exclusive_and_expired_leases_retry_then_fail(db: TestDb) {
    let store = db.store.as_ref();
    with_song(store).await;
    let p = policy(50, 0);
    let first = store.claim("w1", p).await.expect("claim").expect("a job");
    assert_eq!((first.status, first.attempts), (Status::Running, 1));
    assert!(
        store.claim("w2", p).await.expect("claim").is_none(),
        "one job, claimed once"
    );
    tokio::time::sleep(Duration::from_millis(80)).await;
    assert_eq!(
        store.requeue_expired(p).await.expect("requeue").requeued,
        vec![first.id]
    );
    // The dead worker can no longer heartbeat or finish it.
    assert_eq!(
        store
            .heartbeat(first.id, "w1", "x", 0.5, p)
            .await
            .expect("beat"),
        Beat::Lost
    );
    assert!(!store
        .complete(first.id, "w1", Outcome::Files(JobFiles::default()))
        .await
        .expect("complete"));
    let second = store
        .claim("w2", p)
        .await
        .expect("claim")
        .expect("requeued job");
    assert_eq!((second.id, second.attempts), (first.id, 2));
    tokio::time::sleep(Duration::from_millis(80)).await;
    assert_eq!(
        store.requeue_expired(p).await.expect("requeue").failed,
        vec![first.id],
        "max_attempts = 2 reached"
    );
    let job = store.job(Scope::All, first.id).await.expect("job");
    assert_eq!(job.status, Status::Failed);
    assert!(job.finished_at.is_some());
    assert!(
        job.error
            .as_deref()
            .is_some_and(|e| e.contains("lease expired on attempt 2 of 2")),
        "{:?}",
        job.error
    );
    let events = db.events(first.id).await;
    let events: Vec<(Option<&str>, &str)> = events
        .iter()
        .map(|(f, t)| (f.as_deref(), t.as_str()))
        .collect();
    assert_eq!(
        events,
        [
            (None, "queued"),
            (Some("queued"), "running"),
            (Some("running"), "queued"),
            (Some("queued"), "running"),
            (Some("running"), "failed")
        ]
    );
}

async fn cancel_queued_is_immediate_and_running_is_requested(db: TestDb) {
    let store = db.store.as_ref();
    let song = with_song(store).await;
    let running = store
        .claim("w", policy(5_000, 0))
        .await
        .expect("claim")
        .expect("job");
    let queued = store
        .register(analyze(song, 1))
        .await
        .expect("register")
        .job()
        .clone();
    let cancelled = store.cancel(Scope::All, queued.id).await.expect("cancel");
    assert_eq!(
        (cancelled.status, cancelled.finished_at.is_some()),
        (Status::Cancelled, true)
    );
    let after = store.cancel(Scope::All, running.id).await.expect("cancel");
    assert_eq!(
        (after.status, after.cancel_requested),
        (Status::Running, true)
    );
    let beat = store
        .heartbeat(running.id, "w", "x", 0.5, policy(5_000, 0))
        .await;
    assert_eq!(
        beat.expect("beat"),
        Beat::Held {
            cancel_requested: true
        }
    );
    assert!(
        !store
            .finish_cancelled(running.id, "someone-else")
            .await
            .expect("finish"),
        "only the owner finishes"
    );
    assert!(store
        .finish_cancelled(running.id, "w")
        .await
        .expect("finish"));
    assert_eq!(
        store.job(Scope::All, running.id).await.expect("job").status,
        Status::Cancelled
    );
    // Cancelling a finished job changes nothing.
    let again = store
        .cancel(Scope::All, running.id)
        .await
        .expect("cancel again");
    assert_eq!(again.status, Status::Cancelled);
    assert!(matches!(
        store.cancel(Scope::All, JobId::new()).await,
        Err(QueueError::JobNotFound(_))
    ));
}

async fn idempotency_key_returns_the_same_job_or_conflicts(db: TestDb) {
    let store = db.store.as_ref();
    let song = with_song(store).await;
    let job = |hash: &str| NewJob {
        idempotency: Some(Idempotency {
            key: "k".into(),
            request_hash: hash.into(),
        }),
        ..analyze(song, 1)
    };
    let a = store.register(job("h1")).await.expect("register");
    let b = store.register(job("h1")).await.expect("register again");
    assert!(matches!(a, Registered::Created(_)) && matches!(b, Registered::Existing(_)));
    assert_eq!(a.job().id, b.job().id);
    assert!(
        matches!(store.register(job("h2")).await, Err(QueueError::IdempotencyConflict(id)) if id == a.job().id)
    );
    assert!(matches!(
        store.register(analyze(SongId::new(), 1)).await,
        Err(QueueError::SongNotFound(_))
    ));
}

async fn failures_retry_with_backoff_until_attempts_run_out(db: TestDb) {
    let store = db.store.as_ref();
    with_song(store).await;
    let p = policy(5_000, 300);
    let job = store.claim("w", p).await.expect("claim").expect("job");
    assert!(
        !store
            .fail(job.id, "other", "boom", true, p)
            .await
            .expect("fail"),
        "only the owner fails it"
    );
    assert!(store
        .fail(job.id, "w", "boom", true, p)
        .await
        .expect("fail"));
    let queued = store.job(Scope::All, job.id).await.expect("job");
    assert_eq!(
        (queued.status, queued.error.as_deref()),
        (Status::Queued, Some("boom"))
    );
    assert!(
        store.claim("w", p).await.expect("claim").is_none(),
        "not before its backoff"
    );
    tokio::time::sleep(Duration::from_millis(400)).await;
    let again = store
        .claim("w", p)
        .await
        .expect("claim")
        .expect("claimable after the backoff");
    assert_eq!((again.id, again.attempts), (job.id, 2));
    assert!(store
        .fail(job.id, "w", "boom again", true, p)
        .await
        .expect("fail"));
    let failed = store.job(Scope::All, job.id).await.expect("job");
    assert_eq!(
        (failed.status, failed.error.as_deref()),
        (Status::Failed, Some("boom again")),
        "2 of 2 attempts used"
    );

    // A failure that is not retryable fails at once.
    let song = with_song(store).await;
    let other = store.claim("w", p).await.expect("claim").expect("job");
    assert_eq!(other.kind.song_id(), song);
    assert!(store
        .fail(other.id, "w", "bad input", false, p)
        .await
        .expect("fail"));
    assert_eq!(
        store.job(Scope::All, other.id).await.expect("job").status,
        Status::Failed
    );
}

async fn complete_stores_the_outcome_once(db: TestDb) {
    let store = db.store.as_ref();
    let song = with_song(store).await;
    let p = policy(5_000, 0);
    let analysis = store.claim("w", p).await.expect("claim").expect("job");
    let outcome = choreo::audio::Analysis {
        tempo_bpm: 120.0,
        beat_times: vec![0.5, 1.0],
        downbeat_times: vec![0.5],
        tempo_curve: vec![],
    };
    assert!(store
        .complete(analysis.id, "w", Outcome::Analysis(outcome))
        .await
        .expect("complete"));
    assert!(
        !store
            .complete(analysis.id, "w", Outcome::Files(JobFiles::default()))
            .await
            .expect("twice"),
        "a finished job stays finished"
    );
    let done = store.job(Scope::All, analysis.id).await.expect("job");
    assert_eq!(
        (done.status, done.progress, done.stage),
        (Status::Succeeded, 1.0, Some(Stage::Done))
    );
    assert_eq!(
        store
            .song(Scope::All, song)
            .await
            .expect("song")
            .analysis
            .map(|a| a.beat_times),
        Some(vec![0.5, 1.0])
    );

    store.register(analyze(song, 1)).await.expect("register");
    let files = store.claim("w", p).await.expect("claim").expect("job");
    let beat = store
        .heartbeat(files.id, "w", Stage::Generate.as_str(), 0.4, p)
        .await
        .expect("beat");
    assert_eq!(
        beat,
        Beat::Held {
            cancel_requested: false
        }
    );
    let running = store.job(Scope::All, files.id).await.expect("job");
    assert_eq!(
        (running.stage, running.progress),
        (Some(Stage::Generate), 0.4)
    );
    // The style a model chose on the user's behalf is stored with the files.
    let style = choreo::models::StyleChoice {
        style: choreo::models::DanceStyle::Rumba,
        predicted: true,
        probabilities: vec![0.1, 0.7, 0.05, 0.15],
    };
    let written = JobFiles {
        files: vec!["motion.bvh".into(), "report.json".into()],
        style: Some(style),
        ..JobFiles::default()
    };
    assert!(store
        .complete(files.id, "w", Outcome::Files(written.clone()))
        .await
        .expect("complete"));
    assert_eq!(
        store.job(Scope::All, files.id).await.expect("job").files,
        written
    );
}

async fn songs_are_one_per_content_and_jobs_page_newest_first(db: TestDb) {
    let store = db.store.as_ref();
    let first = song("same-bytes");
    let first_id = first.id;
    let (stored, created) = store
        .add_song(first, analyze(first_id, 1))
        .await
        .expect("add");
    assert!(created);
    let twin = song("same-bytes");
    let twin_id = twin.id;
    let (existing, created) = store
        .add_song(twin, analyze(twin_id, 1))
        .await
        .expect("add twin");
    assert!(!created);
    assert_eq!(existing.id, stored.id);
    assert_eq!(
        store
            .song_by_sha256(TenantId::OPEN, "same-bytes")
            .await
            .expect("by sha")
            .map(|s| s.id),
        Some(stored.id)
    );
    assert!(matches!(
        store.song(Scope::All, twin_id).await,
        Err(QueueError::SongNotFound(_))
    ));
    let analyze_job = store
        .analyze_job(stored.id)
        .await
        .expect("query")
        .expect("its analyze job");

    let mut ids = vec![analyze_job.id];
    for _ in 0..4 {
        ids.push(
            store
                .register(analyze(stored.id, 1))
                .await
                .expect("register")
                .job()
                .id,
        );
    }
    ids.reverse();
    let page = store
        .jobs(
            Scope::All,
            JobFilter {
                limit: 3,
                ..JobFilter::default()
            },
        )
        .await
        .expect("page");
    assert_eq!(page.iter().map(|j| j.id).collect::<Vec<_>>(), ids[..3]);
    let next = store
        .jobs(
            Scope::All,
            JobFilter {
                limit: 3,
                before: Some(ids[2]),
                ..JobFilter::default()
            },
        )
        .await
        .expect("next page");
    assert_eq!(next.iter().map(|j| j.id).collect::<Vec<_>>(), ids[3..]);
    store.cancel(Scope::All, ids[0]).await.expect("cancel");
    let cancelled = store
        .jobs(
            Scope::All,
            JobFilter {
                status: Some(Status::Cancelled),
                limit: 10,
                ..JobFilter::default()
            },
        )
        .await
        .expect("filter");
    assert_eq!(
        cancelled.iter().map(|j| j.id).collect::<Vec<_>>(),
        vec![ids[0]]
    );
    let by_model = store
        .jobs(
            Scope::All,
            JobFilter {
                model: Some("dance-revolution".into()),
                limit: 10,
                ..JobFilter::default()
            },
        )
        .await;
    assert!(
        by_model.expect("filter").is_empty(),
        "analyze jobs have no model"
    );
    let counts = store.counts().await.expect("counts");
    assert_eq!(
        counts,
        vec![
            (Status::Queued, 4),
            (Status::Running, 0),
            (Status::Succeeded, 0),
            (Status::Failed, 0),
            (Status::Cancelled, 1)
        ]
    );
    store.ping().await.expect("ping");
}

async fn higher_priority_runs_first(db: TestDb) {
    let store = db.store.as_ref();
    let song = with_song(store).await;
    let p = policy(5_000, 0);
    let urgent = store
        .register(NewJob {
            priority: 5,
            ..analyze(song, 1)
        })
        .await
        .expect("register")
        .job()
        .id;
    assert_eq!(
        store.claim("w", p).await.expect("claim").map(|j| j.id),
        Some(urgent)
    );
}

async fn concurrent_claims_take_each_job_once(db: TestDb) {
    const JOBS: usize = 60;
    let song = with_song(db.store.as_ref()).await;
    for _ in 1..JOBS {
        db.store.register(analyze(song, 1)).await.expect("register");
    }
    let p = policy(30_000, 0);
    let claimers: Vec<_> = (0..6)
        .map(|n| {
            let store = db.store.clone();
            tokio::spawn(async move {
                let owner = format!("w{n}");
                let mut mine = Vec::new();
                while let Some(job) = store.claim(&owner, p).await.expect("claim") {
                    assert!(store
                        .complete(job.id, &owner, Outcome::Files(JobFiles::default()))
                        .await
                        .expect("complete"));
                    mine.push(job.id);
                }
                mine
            })
        })
        .collect();
    let mut all = Vec::new();
    for claimer in claimers {
        all.extend(claimer.await.expect("claimer"));
    }
    assert_eq!(all.len(), JOBS, "every job claimed");
    assert_eq!(
        all.iter().collect::<HashSet<_>>().len(),
        JOBS,
        "no job claimed twice"
    );
    for id in all {
        let succeeded = db
            .events(id)
            .await
            .iter()
            .filter(|(_, to)| to == "succeeded")
            .count();
        assert_eq!(succeeded, 1, "job {id} succeeded once");
    }
}

macro_rules! contract {
    ($($name:ident),* $(,)?) => {
        mod sqlite {
            $(
                #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
                async fn $name() {
                    super::$name(super::TestDb::sqlite().await).await;
                }
            )*
        }
        mod postgres_store {
            $(
                #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
                async fn $name() {
                    super::$name(super::TestDb::postgres().await).await;
                }
            )*
        }
    };
}

contract!(
    claims_are_fair_between_tenants,
    tenants_see_only_their_own_rows,
    claim_is_exclusive_and_expired_leases_retry_then_fail,
    cancel_queued_is_immediate_and_running_is_requested,
    idempotency_key_returns_the_same_job_or_conflicts,
    failures_retry_with_backoff_until_attempts_run_out,
    complete_stores_the_outcome_once,
    songs_are_one_per_content_and_jobs_page_newest_first,
    higher_priority_runs_first,
    concurrent_claims_take_each_job_once,
    rigs_keep_their_skeleton_and_mapping,
    rigs_list_by_tenant_delete_once_and_expire_unused,
    deletion_and_expiry_leave_only_an_audit_line,
);

/// PostgreSQL only: a job queued through one connection pool (another process) wakes a watcher
/// at once, and a socket URL works as well as TCP.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn postgres_notifies_watchers_of_new_jobs() {
    let server = tokio::task::spawn_blocking(postgres::Postgres::start)
        .await
        .expect("start postgres");
    let api = PgStore::connect(
        &choreo::config::Secret::new(server.socket_url()),
        std::time::Duration::from_secs(3),
    )
    .await
    .expect("connect over the socket");
    let worker = PgStore::connect(
        &choreo::config::Secret::new(server.url()),
        std::time::Duration::from_secs(3),
    )
    .await
    .expect("connect over TCP");
    let wake = Arc::new(Notify::new());
    let shutdown = CancellationToken::new();
    // Created before the watcher starts, so its wake-up on listening cannot be missed.
    let listening = wake.notified();
    let watcher = tokio::spawn({
        let (worker, wake, shutdown) = (worker.clone(), wake.clone(), shutdown.clone());
        async move { choreo::queue::JobStore::watch(&worker, wake, shutdown).await }
    });
    // The watcher wakes once when it starts listening; wait for that, then queue a job.
    tokio::time::timeout(Duration::from_secs(10), listening)
        .await
        .expect("watcher listening");
    let woken = wake.notified();
    let song = with_song(&api).await;
    tokio::time::timeout(Duration::from_secs(5), woken)
        .await
        .expect("a new job wakes the watcher");
    let job = choreo::queue::JobStore::claim(&worker, "w", policy(5_000, 0))
        .await
        .expect("claim")
        .expect("the job");
    assert_eq!(job.kind.song_id(), song);
    shutdown.cancel();
    watcher
        .await
        .expect("watcher task")
        .expect("watch ends cleanly");
}
