//! `DELETE /v1/songs/{id}`, `DELETE /v1/jobs/{id}` and `retention_days`, on SQLite and on
//! PostgreSQL: what is deleted or expires leaves no file in the data dir (and, under moto, none in
//! the bucket) and no row, only a `deleted` line per job in `job_events`; another tenant's ids
//! (two API keys) are 404 and keep their rows.
use crate::artifacts::{choreo, files_under, wait_job as wait_job_at, Moto, BUCKET, PREFIX};
use crate::common_models::models_dir;
use crate::helpers::{
    expect_problem, listening_base, short_song, song, spawn_app_with, spawn_process as spawn,
    upload_to, TestApp,
};
use crate::postgres::Postgres;
use choreo::config::{Config, Secret};
use choreo::queue::{KeyLimits, NewKey, PgStore, SqliteStore};
use futures::TryStreamExt;
use object_store::ObjectStore;
use reqwest::StatusCode;
use serde_json::{json, Value};
use sqlx::Row;
use std::path::Path;
use std::time::{Duration, Instant};

/// The retention of the retention tests: 4.32 s.
const FEW_SECONDS_IN_DAYS: f64 = 0.00005;

/// The database a test runs on: the data dir's SQLite file, or a PostgreSQL server of its own.
enum Db {
    Sqlite,
    Postgres(Postgres),
}

impl Db {
    async fn start(postgres: bool) -> Self {
        if postgres {
            Db::Postgres(
                tokio::task::spawn_blocking(Postgres::start)
                    .await
                    .expect("start postgres"),
            )
        } else {
            Db::Sqlite
        }
    }

    fn configure(&self, config: &mut Config) {
        if let Db::Postgres(server) = self {
            config.database_url = Some(Secret::new(server.url()));
        }
    }

    /// A second connection to the service's database, to look at its rows.
    async fn rows(&self, app: &TestApp) -> Rows {
        match self {
            Db::Sqlite => Rows::Sqlite(
                SqliteStore::open(&app.data_dir.path().join("choreo.sqlite"))
                    .await
                    .expect("open sqlite"),
            ),
            Db::Postgres(server) => Rows::Postgres(
                PgStore::connect(&Secret::new(server.url()), Duration::from_secs(5))
                    .await
                    .expect("connect postgres"),
            ),
        }
    }
}

enum Rows {
    Sqlite(SqliteStore),
    Postgres(PgStore),
}

/// Runs `$body` with `$pool` bound to the pool of either store.
macro_rules! on_pool {
    ($rows:expr, $pool:ident => $body:expr) => {
        match $rows {
            Rows::Sqlite(store) => {
                let $pool = store.pool();
                $body
            }
            Rows::Postgres(store) => {
                let $pool = store.pool();
                $body
            }
        }
    };
}

/// One `job_events` line: from, to, error.
type Event = (Option<String>, String, Option<String>);

impl Rows {
    /// `SELECT COUNT(*) FROM <table>`.
    async fn count(&self, table: &str) -> i64 {
        let sql = format!("SELECT COUNT(*) AS n FROM {table}");
        on_pool!(self, pool => sqlx::query(&sql)
            .fetch_one(pool)
            .await
            .expect("count")
            .try_get::<i64, _>("n")
            .expect("n"))
    }

    /// A job's `job_events` lines, in order.
    async fn events(&self, job: &str) -> Vec<Event> {
        let sql = "SELECT from_status, to_status, error FROM job_events \
                   WHERE CAST(job_id AS TEXT) = $1 AND to_status IS NOT NULL ORDER BY seq";
        on_pool!(self, pool => sqlx::query(sql)
            .bind(job)
            .fetch_all(pool)
            .await
            .expect("events")
            .iter()
            .map(|r| {
                (
                    r.try_get("from_status").expect("from"),
                    r.try_get("to_status").expect("to"),
                    r.try_get("error").expect("error"),
                )
            })
            .collect::<Vec<Event>>())
    }

    /// Asserts a job's last `job_events` line says it was deleted, from `from`, for a reason
    /// containing `reason`: nothing was recorded for it after its deletion.
    async fn assert_deleted(&self, job: &str, from: &str, reason: &str) {
        let events = self.events(job).await;
        let Some((last_from, to, error)) = events.last() else {
            panic!("job {job} left no line in job_events");
        };
        assert_eq!(to, "deleted", "job {job}: {events:?}");
        assert_eq!(last_from.as_deref(), Some(from), "job {job}: {events:?}");
        assert!(
            error.as_deref().is_some_and(|e| e.contains(reason)),
            "job {job}: {events:?}"
        );
    }
}

/// The files of a data dir that are songs or results (not the database or its journal).
fn stored_files(dir: &Path) -> Vec<String> {
    files_under(dir)
        .into_iter()
        .filter(|f| !f.starts_with("choreo.sqlite"))
        .collect()
}

/// Polls `check` until it answers `Ok`, for at most `limit`; the last `Err` says what was seen.
async fn eventually<F, Fut>(limit: Duration, what: &str, mut check: F)
where
    F: FnMut() -> Fut,
    Fut: std::future::Future<Output = Result<(), String>>,
{
    let deadline = Instant::now() + limit;
    loop {
        match check().await {
            Ok(()) => return,
            Err(seen) => assert!(
                Instant::now() < deadline,
                "{what}: not so after {limit:?}: {seen}"
            ),
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
}

async fn submit(app: &TestApp, song: &Value, seed: u64) -> String {
    let response = app
        .post_job(
            &json!({"song_id": song["id"], "model": "dance-revolution", "seed": seed}),
            None,
        )
        .await;
    assert_eq!(response.status(), StatusCode::ACCEPTED);
    let job: Value = response.json().await.expect("job");
    id(&job)
}

/// A song long enough (11 min) that its dance is still running when it is deleted: five times
/// `lets_go_fishin.ogg`, mono 22 050 Hz WAV (29 MB), made once per build with ffmpeg.
fn long_song() -> std::path::PathBuf {
    static MADE: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let out = Path::new(env!("CARGO_TARGET_TMPDIR")).join("delete-fixtures/long.wav");
    let _guard = MADE.lock().unwrap_or_else(|p| p.into_inner());
    if out.is_file() {
        return out;
    }
    let dir = out.parent().expect("dir");
    std::fs::create_dir_all(dir).expect("fixture dir");
    let partial = dir.join("partial-long.wav");
    let status = std::process::Command::new("ffmpeg")
        .args(["-v", "error", "-y", "-stream_loop", "4", "-i"])
        .arg(song("lets_go_fishin.ogg"))
        .args(["-ac", "1", "-ar", "22050", "-c:a", "pcm_s16le"])
        .arg(&partial)
        .status()
        .expect("ffmpeg is needed to make test fixtures: run `scripts/setup.sh --test`");
    assert!(status.success(), "ffmpeg failed to make {}", out.display());
    std::fs::rename(&partial, &out).expect("fixture rename");
    out
}

fn id(value: &Value) -> String {
    value["id"].as_str().expect("id").to_string()
}

/// A new API key (a tenant of its own) in `app`'s store, as `choreo keys create` makes one;
/// returns its secret.
async fn api_key(app: &TestApp, name: &str) -> String {
    let (key, secret) = NewKey::mint(name, false, KeyLimits::default());
    let server = app.server.as_ref().expect("the server runs");
    server
        .state()
        .store
        .add_key(key)
        .await
        .expect("add the key");
    secret
}

/// Deletion on one store: a finished job, another tenant's song and job, and a song whose dance
/// is running.
async fn deletion(postgres: bool) {
    let db = Db::start(postgres).await;
    let models = models_dir();
    // One worker: the dance of the long song runs alone, so it is running when it is deleted.
    let mut app = spawn_app_with(|c| {
        c.models_dir = models;
        c.workers = 1;
        db.configure(c);
    })
    .await;
    // Two tenants, each an API key: the helpers' requests are the first's.
    app.token = Some(api_key(&app, "mine").await);
    let theirs = api_key(&app, "theirs").await;
    let rows = db.rows(&app).await;
    let data = app.data_dir.path();

    // A finished job: DELETE removes its results and its row; its song stays.
    let short = app.upload_ok(&short_song()).await;
    let short_id = id(&short);
    let finished = app
        .dance(&json!({"song_id": short_id, "model": "dance-revolution", "seed": 1}))
        .await;
    assert!(stored_files(data)
        .iter()
        .any(|f| f.starts_with(&format!("jobs/{finished}/"))));
    let response = app.delete(&format!("/v1/jobs/{finished}")).await;
    assert_eq!(response.status(), StatusCode::NO_CONTENT);
    assert!(response.bytes().await.expect("body").is_empty());
    for path in [
        format!("/v1/jobs/{finished}"),
        format!("/v1/jobs/{finished}/motion.bvh"),
    ] {
        expect_problem(app.get(&path).await, StatusCode::NOT_FOUND, "job-not-found").await;
    }
    expect_problem(
        app.delete(&format!("/v1/jobs/{finished}")).await,
        StatusCode::NOT_FOUND,
        "job-not-found",
    )
    .await;
    let left = stored_files(data);
    assert!(!left.iter().any(|f| f.contains(&finished)), "{left:?}");
    assert!(
        left.iter()
            .any(|f| f.starts_with(&format!("songs/{short_id}"))),
        "{left:?}"
    );
    assert_eq!(
        app.get(&format!("/v1/songs/{short_id}")).await.status(),
        StatusCode::OK
    );
    rows.assert_deleted(
        &finished,
        "succeeded",
        &format!("DELETE /v1/jobs/{finished}"),
    )
    .await;

    // Another tenant's song (the same bytes: a song of its own) and its analyze job: 404 to this
    // tenant, for DELETE as for GET, and still theirs afterwards.
    let form = reqwest::multipart::Form::new().part(
        "file",
        reqwest::multipart::Part::bytes(std::fs::read(short_song()).expect("song"))
            .file_name("theirs.ogg"),
    );
    let response = app
        .client
        .post(app.url("/v1/songs"))
        .bearer_auth(&theirs)
        .multipart(form)
        .send()
        .await
        .expect("their upload");
    assert_eq!(response.status(), StatusCode::CREATED);
    let their_song = id(&response.json::<Value>().await.expect("song"));
    assert_ne!(their_song, short_id);
    let their_get = |path: String| app.client.get(app.url(&path)).bearer_auth(&theirs).send();
    let page: Value = their_get("/v1/jobs?limit=10".into())
        .await
        .expect("their jobs")
        .json()
        .await
        .expect("page");
    let their_job = id(&page["items"][0]);
    for (path, code) in [
        (format!("/v1/songs/{their_song}"), "song-not-found"),
        (format!("/v1/jobs/{their_job}"), "job-not-found"),
    ] {
        expect_problem(app.delete(&path).await, StatusCode::NOT_FOUND, code).await;
        expect_problem(app.get(&path).await, StatusCode::NOT_FOUND, code).await;
        let theirs_still = their_get(path.clone()).await.expect("their GET");
        assert_eq!(
            theirs_still.status(),
            StatusCode::OK,
            "{path} is still theirs"
        );
    }

    // A song whose dance is running: DELETE stops the dance and removes the song, its analysis,
    // both jobs and every file, and the worker records and leaves nothing for the deleted job.
    let long = app.upload_ok(&long_song()).await;
    let long_id = id(&long);
    let analyze = id(&app.analyze_job_of(&long_id).await);
    let running = submit(&app, &long, 2).await;
    eventually(Duration::from_secs(120), "the dance runs", || async {
        let job = app.job(&running).await;
        assert_ne!(
            job["status"], "succeeded",
            "the dance finished before it could be deleted: {job}"
        );
        if job["status"] == "running" {
            Ok(())
        } else {
            Err(job.to_string())
        }
    })
    .await;
    let response = app.delete(&format!("/v1/songs/{long_id}")).await;
    assert_eq!(response.status(), StatusCode::NO_CONTENT);
    for path in [
        format!("/v1/songs/{long_id}"),
        format!("/v1/songs/{long_id}/audio"),
    ] {
        expect_problem(
            app.get(&path).await,
            StatusCode::NOT_FOUND,
            "song-not-found",
        )
        .await;
    }
    for job in [&analyze, &running] {
        expect_problem(
            app.get(&format!("/v1/jobs/{job}")).await,
            StatusCode::NOT_FOUND,
            "job-not-found",
        )
        .await;
    }
    expect_problem(
        app.delete(&format!("/v1/songs/{long_id}")).await,
        StatusCode::NOT_FOUND,
        "song-not-found",
    )
    .await;
    let mentions =
        |f: &String| f.contains(&long_id) || f.contains(&running) || f.contains(&analyze);
    eventually(
        Duration::from_secs(60),
        "the deleted song's files are gone",
        || async {
            let left: Vec<String> = stored_files(data).into_iter().filter(mentions).collect();
            if left.is_empty() {
                Ok(())
            } else {
                Err(format!("{left:?}"))
            }
        },
    )
    .await;
    // Long enough for the stopped dance to have written anything it still would.
    tokio::time::sleep(Duration::from_secs(3)).await;
    let left: Vec<String> = stored_files(data).into_iter().filter(mentions).collect();
    assert!(left.is_empty(), "written after the deletion: {left:?}");
    let reason = format!("DELETE /v1/songs/{long_id}");
    rows.assert_deleted(&running, "running", &reason).await;
    rows.assert_deleted(&analyze, "succeeded", &reason).await;

    // This tenant's last song goes too, and the other tenant deletes its own.
    assert_eq!(
        app.delete(&format!("/v1/songs/{short_id}")).await.status(),
        StatusCode::NO_CONTENT
    );
    let response = app
        .client
        .delete(app.url(&format!("/v1/songs/{their_song}")))
        .bearer_auth(&theirs)
        .send()
        .await
        .expect("their DELETE");
    assert_eq!(response.status(), StatusCode::NO_CONTENT);
    eventually(
        Duration::from_secs(30),
        "the data dir holds no song or result",
        || async {
            let left = stored_files(data);
            if left.is_empty() {
                Ok(())
            } else {
                Err(format!("{left:?}"))
            }
        },
    )
    .await;
    assert_eq!(rows.count("songs").await, 0);
    assert_eq!(rows.count("jobs").await, 0);
    rows.assert_deleted(
        &their_job,
        "succeeded",
        &format!("DELETE /v1/songs/{their_song}"),
    )
    .await;
    let page: Value = app
        .get("/v1/jobs?limit=100")
        .await
        .json()
        .await
        .expect("page");
    assert_eq!(page["items"], json!([]), "{page}");
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn deletion_leaves_no_file_and_no_row_on_sqlite() {
    deletion(false).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn deletion_leaves_no_file_and_no_row_on_postgres() {
    deletion(true).await;
}

/// Retention on one store: a result downloaded now and then is kept past the retention; once
/// unused, it expires, and its song with it.
async fn retention(postgres: bool) {
    let db = Db::start(postgres).await;
    let models = models_dir();
    let app = spawn_app_with(|c| {
        c.models_dir = models;
        c.retention_days = Some(FEW_SECONDS_IN_DAYS);
        c.sweep_grace_s = 3.0;
        db.configure(c);
    })
    .await;
    let rows = db.rows(&app).await;
    let data = app.data_dir.path();
    let keep = Duration::from_secs_f64(FEW_SECONDS_IN_DAYS * 86_400.0);

    let song = app.upload_ok(&short_song()).await;
    let song_id = id(&song);
    let job = submit(&app, &song, 4).await;
    assert_eq!(app.wait_job(&job).await["status"], "succeeded");
    let analyze = id(&app.analyze_job_of(&song_id).await);
    // Each download is a use: twice the retention later, the dance and its song are still there.
    let until = Instant::now() + 2 * keep;
    while Instant::now() < until {
        let response = app.get(&format!("/v1/jobs/{job}/report.json")).await;
        assert_eq!(response.status(), StatusCode::OK, "a used result is kept");
        tokio::time::sleep(Duration::from_millis(500)).await;
    }
    assert_eq!(
        app.get(&format!("/v1/songs/{song_id}")).await.status(),
        StatusCode::OK,
        "a song is kept while a dance made from it is used"
    );

    // Unused now: gone within a few retentions, files and rows.
    eventually(
        Duration::from_secs(60),
        "the unused song and dance expire",
        || async {
            let left = stored_files(data);
            let (songs, jobs) = (rows.count("songs").await, rows.count("jobs").await);
            if left.is_empty() && songs == 0 && jobs == 0 {
                Ok(())
            } else {
                Err(format!("files {left:?}, {songs} songs, {jobs} jobs"))
            }
        },
    )
    .await;
    expect_problem(
        app.get(&format!("/v1/songs/{song_id}")).await,
        StatusCode::NOT_FOUND,
        "song-not-found",
    )
    .await;
    expect_problem(
        app.get(&format!("/v1/jobs/{job}")).await,
        StatusCode::NOT_FOUND,
        "job-not-found",
    )
    .await;
    rows.assert_deleted(&job, "succeeded", "expired").await;
    rows.assert_deleted(&analyze, "succeeded", "expired").await;
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn retention_of_a_few_seconds_leaves_no_file_and_no_row_on_sqlite() {
    retention(false).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn retention_of_a_few_seconds_leaves_no_file_and_no_row_on_postgres() {
    retention(true).await;
}

/// Every key in the bucket under the test prefix.
async fn bucket_keys(bucket: &dyn ObjectStore) -> Vec<String> {
    let prefix = object_store::path::Path::from(PREFIX);
    bucket
        .list(Some(&prefix))
        .map_ok(|meta| meta.location.to_string())
        .try_collect()
        .await
        .expect("list the bucket")
}

/// An API-only process and a worker process on separate disks, PostgreSQL and a bucket under
/// moto: a deleted job's results leave the bucket at once, and the retention pass (worker side)
/// empties the bucket and both disks of an unused song and its dance.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn deleted_and_expired_files_leave_the_bucket_and_every_disk() {
    let server = tokio::task::spawn_blocking(Postgres::start)
        .await
        .expect("start postgres");
    let moto = Moto::start();
    let client = reqwest::Client::new();
    moto.make_bucket(&client).await;
    let bucket = object_store::aws::AmazonS3Builder::new()
        .with_bucket_name(BUCKET)
        .with_region("us-east-1")
        .with_endpoint(&moto.endpoint)
        .with_allow_http(true)
        .with_access_key_id("test")
        .with_secret_access_key("test")
        .build()
        .expect("bucket client");

    let (api_dir, worker_dir) = (
        tempfile::tempdir().expect("tempdir"),
        tempfile::tempdir().expect("tempdir"),
    );
    let with_retention = |mut c: tokio::process::Command| {
        c.env("CHOREO_RETENTION_DAYS", FEW_SECONDS_IN_DAYS.to_string())
            .env("CHOREO_SWEEP_GRACE_S", "3");
        c
    };
    let (_api, line) = spawn(with_retention(choreo(
        &["serve", "--no-workers", "--bind", "127.0.0.1:0"],
        api_dir.path(),
        &server.url(),
        &moto.endpoint,
    )))
    .await;
    let base = listening_base(&line);
    let (_worker, line) = spawn(with_retention(choreo(
        &["worker", "--workers", "1"],
        worker_dir.path(),
        &server.url(),
        &moto.endpoint,
    )))
    .await;
    assert_eq!(line, "choreo worker running 1 workers");

    let bytes = std::fs::read(short_song()).expect("song");
    let song = upload_to(&client, &base, bytes, "t.ogg").await;
    let song_id = id(&song);
    let mut jobs = Vec::new();
    for seed in [5, 6] {
        let response = client
            .post(format!("{base}/v1/jobs"))
            .json(&json!({"song_id": song_id, "model": "dance-revolution", "seed": seed}))
            .send()
            .await
            .expect("POST job");
        assert_eq!(response.status(), StatusCode::ACCEPTED);
        jobs.push(id(&response.json::<Value>().await.expect("job")));
    }
    for job in &jobs {
        assert_eq!(
            wait_job_at(&client, &base, job).await["status"],
            "succeeded"
        );
    }
    let (deleted, kept) = (&jobs[0], &jobs[1]);
    // The API host caches the song when it serves its audio: a copy the expiry must reach too.
    let audio = client
        .get(format!("{base}/v1/songs/{song_id}/audio"))
        .send()
        .await
        .expect("audio");
    assert_eq!(audio.status(), StatusCode::OK);
    let keys = bucket_keys(&bucket).await;
    assert!(
        keys.contains(&format!("{PREFIX}/songs/{song_id}.ogg")),
        "{keys:?}"
    );
    assert!(
        keys.iter().any(|k| k.contains(deleted.as_str())),
        "{keys:?}"
    );

    let response = client
        .delete(format!("{base}/v1/jobs/{deleted}"))
        .send()
        .await
        .expect("DELETE");
    assert_eq!(response.status(), StatusCode::NO_CONTENT);
    let keys = bucket_keys(&bucket).await;
    assert!(
        !keys.iter().any(|k| k.contains(deleted.as_str())),
        "the deleted job's results left the bucket: {keys:?}"
    );

    let rows = Rows::Postgres(
        PgStore::connect(&Secret::new(server.url()), Duration::from_secs(5))
            .await
            .expect("connect"),
    );
    eventually(
        Duration::from_secs(90),
        "the bucket, both disks and the database are empty",
        || async {
            let keys = bucket_keys(&bucket).await;
            let api = stored_files(api_dir.path());
            let worker = stored_files(worker_dir.path());
            let (songs, jobs) = (rows.count("songs").await, rows.count("jobs").await);
            if keys.is_empty() && api.is_empty() && worker.is_empty() && songs == 0 && jobs == 0 {
                Ok(())
            } else {
                Err(format!(
                    "bucket {keys:?}, api disk {api:?}, worker disk {worker:?}, {songs} songs, {jobs} jobs"
                ))
            }
        },
    )
    .await;
    rows.assert_deleted(deleted, "succeeded", "DELETE /v1/jobs")
        .await;
    rows.assert_deleted(kept, "succeeded", "expired").await;
}
