//! Quotas hold under requests racing each other, on SQLite and on PostgreSQL: 50 job requests
//! released together at a queue limit, 20 distinct uploads at once against a storage quota, and a
//! tenant at its quota gets no more results. Limits are checked where they are set, and a limit
//! stored out of range cannot break a request. The race figures are printed (`--nocapture`).
use crate::helpers::{expect_problem, short_song};
use crate::tenants::{spawn, spawn_with, App, Db};
use choreo::queue::keys::key_id_of;
use choreo::queue::{KeyLimits, NewKey, TenantId, Usage};
use reqwest::StatusCode;
use serde_json::json;

mod sqlite {
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn fifty_job_requests_at_once_get_exactly_the_queue_limit() {
        super::fifty_job_requests_at_once_get_exactly_the_queue_limit(super::Db::Sqlite).await
    }
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn twenty_uploads_at_once_never_store_past_the_quota() {
        super::twenty_uploads_at_once_never_store_past_the_quota(super::Db::Sqlite).await
    }
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_tenant_at_its_quota_gets_no_more_results() {
        super::a_tenant_at_its_quota_gets_no_more_results(super::Db::Sqlite).await
    }
}

mod postgres {
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn fifty_job_requests_at_once_get_exactly_the_queue_limit() {
        super::fifty_job_requests_at_once_get_exactly_the_queue_limit(super::Db::Postgres).await
    }
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn twenty_uploads_at_once_never_store_past_the_quota() {
        super::twenty_uploads_at_once_never_store_past_the_quota(super::Db::Postgres).await
    }
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_tenant_at_its_quota_gets_no_more_results() {
        super::a_tenant_at_its_quota_gets_no_more_results(super::Db::Postgres).await
    }
}

async fn usage(app: &App, secret: &str) -> Usage {
    let key = key_id_of(secret).expect("a minted secret names its key");
    app.store().usage(TenantId(key.0)).await.expect("usage")
}

async fn fifty_job_requests_at_once_get_exactly_the_queue_limit(db: Db) {
    const REQUESTS: usize = 50;
    const LIMIT: u64 = 4;
    // No workers: what is queued stays queued.
    let app = spawn_with(db, false, |c| {
        c.models_dir = crate::common_models::models_dir();
    })
    .await;
    let limits = KeyLimits {
        max_queued_jobs: Some(LIMIT),
        ..KeyLimits::default()
    };
    let key = app.key("racer", limits).await;
    // The upload's analyze job is the first of the four.
    let song = app.song(&key).await;
    let body = json!({"song_id": song, "model": "dance-revolution", "priority": -100});
    let answers = futures::future::join_all((0..REQUESTS).map(|_| app.post_job(&key, &body))).await;
    let accepted = answers
        .iter()
        .filter(|r| r.status() == StatusCode::ACCEPTED)
        .count();
    let refused: Vec<_> = answers
        .into_iter()
        .filter(|r| r.status() == StatusCode::TOO_MANY_REQUESTS)
        .collect();
    let queued = usage(&app, &key).await.queued_jobs;
    eprintln!(
        "{db:?}: {REQUESTS} job requests at once at max_queued_jobs {LIMIT} (one analyze job queued): \
         {accepted} accepted, {} refused with 429; {queued} queued",
        refused.len()
    );
    assert_eq!(accepted as u64, LIMIT - 1);
    assert_eq!(refused.len(), REQUESTS - accepted);
    assert_eq!(queued, LIMIT);
    let first = refused.into_iter().next().expect("refusals");
    expect_problem(first, StatusCode::TOO_MANY_REQUESTS, "too-many-queued-jobs").await;
    // An upload would queue an analyze job too: refused alike, nothing stored.
    let other_song = crate::helpers::fixture("wav");
    expect_problem(
        app.upload(&key, &other_song).await,
        StatusCode::TOO_MANY_REQUESTS,
        "too-many-queued-jobs",
    )
    .await;
    app.stop().await;
}

/// A mono 16-bit WAV of a sine at `hz`, `seconds` long at 22,050 Hz: distinct bytes per tone.
fn tone(hz: f64, seconds: f64) -> Vec<u8> {
    let sr = 22_050u32;
    let n = (seconds * f64::from(sr)) as u32;
    let mut wav = Vec::with_capacity(44 + 2 * n as usize);
    wav.extend_from_slice(b"RIFF");
    wav.extend_from_slice(&(36 + 2 * n).to_le_bytes());
    wav.extend_from_slice(b"WAVEfmt ");
    wav.extend_from_slice(&16u32.to_le_bytes());
    wav.extend_from_slice(&1u16.to_le_bytes()); // PCM
    wav.extend_from_slice(&1u16.to_le_bytes()); // mono
    wav.extend_from_slice(&sr.to_le_bytes());
    wav.extend_from_slice(&(2 * sr).to_le_bytes());
    wav.extend_from_slice(&2u16.to_le_bytes());
    wav.extend_from_slice(&16u16.to_le_bytes());
    wav.extend_from_slice(b"data");
    wav.extend_from_slice(&(2 * n).to_le_bytes());
    for i in 0..n {
        let t = f64::from(i) / f64::from(sr);
        let v = (0.5 * (2.0 * std::f64::consts::PI * hz * t).sin() * 32767.0) as i16;
        wav.extend_from_slice(&v.to_le_bytes());
    }
    wav
}

async fn twenty_uploads_at_once_never_store_past_the_quota(db: Db) {
    const UPLOADS: usize = 20;
    let app = spawn_with(db, false, |_| {}).await;
    let dir = tempfile::tempdir().expect("tempdir");
    let files: Vec<_> = (0..UPLOADS)
        .map(|i| {
            let path = dir.path().join(format!("tone{i}.wav"));
            std::fs::write(&path, tone(220.0 + 7.0 * i as f64, 4.0)).expect("write tone");
            path
        })
        .collect();
    let size = std::fs::metadata(&files[0]).expect("tone").len();
    let quota = 5 * size + size / 2;
    let key = app
        .key(
            "uploader",
            KeyLimits {
                storage_quota_bytes: Some(quota),
                ..KeyLimits::default()
            },
        )
        .await;
    let answers = futures::future::join_all(files.iter().map(|f| app.upload(&key, f))).await;
    let created = answers
        .iter()
        .filter(|r| r.status() == StatusCode::CREATED)
        .count();
    let refused: Vec<_> = answers
        .into_iter()
        .filter(|r| r.status() == StatusCode::PAYLOAD_TOO_LARGE)
        .collect();
    let stored = usage(&app, &key).await.stored_bytes;
    eprintln!(
        "{db:?}: {UPLOADS} distinct {size}-byte uploads at once against a {quota}-byte quota: \
         {created} stored, {} refused with 413; {stored} bytes stored ({:.2}x the quota)",
        refused.len(),
        stored as f64 / quota as f64
    );
    assert!(
        stored <= quota,
        "{stored} bytes stored past a {quota}-byte quota"
    );
    assert_eq!(created, 5, "five fit");
    assert_eq!(refused.len(), UPLOADS - created);
    let first = refused.into_iter().next().expect("refusals");
    expect_problem(
        first,
        StatusCode::PAYLOAD_TOO_LARGE,
        "storage-quota-exceeded",
    )
    .await;
    app.stop().await;
}

async fn a_tenant_at_its_quota_gets_no_more_results(db: Db) {
    let app = spawn(db, |c| {
        c.models_dir = crate::common_models::models_dir();
        c.workers = 1;
    })
    .await;
    let song_bytes = std::fs::metadata(short_song()).expect("song").len();
    // Room for the song and a little: the first job's results will pass the quota.
    let quota = song_bytes + 4096;
    let key = app
        .key(
            "small",
            KeyLimits {
                storage_quota_bytes: Some(quota),
                ..KeyLimits::default()
            },
        )
        .await;
    let song = app.song(&key).await;
    let mut ids = Vec::new();
    for seed in 0..2 {
        let response = app
            .post_job(
                &key,
                &json!({"song_id": song, "model": "dance-revolution", "seed": seed}),
            )
            .await;
        assert_eq!(
            response.status(),
            StatusCode::ACCEPTED,
            "admitted under the quota"
        );
        let job: serde_json::Value = response.json().await.expect("job");
        ids.push(job["id"].as_str().expect("id").to_string());
    }
    let mut outcomes = Vec::new();
    for id in &ids {
        outcomes.push(app.wait_job(&key, id).await);
    }
    let succeeded = outcomes
        .iter()
        .filter(|j| j["status"] == "succeeded")
        .count();
    let refused: Vec<_> = outcomes
        .iter()
        .filter(|j| {
            j["status"] == "failed"
                && j["error"]
                    .as_str()
                    .is_some_and(|e| e.contains("storage-quota-exceeded"))
        })
        .collect();
    let stored = usage(&app, &key).await.stored_bytes;
    eprintln!(
        "{db:?}: two jobs admitted under a {quota}-byte quota: {succeeded} succeeded, {} refused its \
         results; {stored} bytes stored, one job's results past the quota",
        refused.len()
    );
    assert_eq!((succeeded, refused.len()), (1, 1), "{outcomes:?}");
    assert!(stored > quota, "the first job's results were kept");
    // At its quota, a new job is refused before it is queued.
    let body = expect_problem(
        app.post_job(&key, &json!({"song_id": song, "model": "dance-revolution"}))
            .await,
        StatusCode::PAYLOAD_TOO_LARGE,
        "storage-quota-exceeded",
    )
    .await;
    assert!(
        body["detail"].as_str().unwrap_or("").contains("quota"),
        "{body}"
    );
    // The refused job's files are gone from the data dir.
    let refused_id = refused[0]["id"].as_str().expect("id");
    let dir = app.app.data_dir.path().join("jobs").join(refused_id);
    let left: Vec<_> = std::fs::read_dir(&dir)
        .map(|d| d.flatten().map(|e| e.file_name()).collect())
        .unwrap_or_default();
    assert!(
        !left
            .iter()
            .any(|n| n.to_string_lossy().starts_with("motion")),
        "{left:?}"
    );
    app.stop().await;
}

/// A rate stored out of range (written by hand, or before limits were checked) is held to the
/// range: every request is answered, none panics.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stored_rate_of_1e_minus_19_cannot_break_a_request() {
    let app = spawn_with(Db::Sqlite, false, |_| {}).await;
    let (key, secret) = NewKey::mint(
        "slow",
        false,
        KeyLimits {
            rate_limit_rps: Some(1e-19),
            ..KeyLimits::default()
        },
    );
    app.store().add_key(key).await.expect("add key");
    assert_eq!(app.get("/v1/jobs", &secret).await.status(), StatusCode::OK);
    let refused = app.get("/v1/jobs", &secret).await;
    let wait: u64 = refused.headers()["retry-after"]
        .to_str()
        .expect("ascii")
        .parse()
        .expect("seconds");
    assert!(wait <= 100, "the slowest rate is 0.01 per second: {wait} s");
    expect_problem(refused, StatusCode::TOO_MANY_REQUESTS, "rate-limited").await;
    app.stop().await;
}

/// Out-of-range limits are refused where they are set, with a message and exit code 2.
#[test]
fn limits_out_of_range_are_refused_where_they_are_set() {
    let dir = tempfile::tempdir().expect("tempdir");
    let run = |args: &[&str], env: &[(&str, &str)]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_choreo"))
            .args(args)
            .arg("--data-dir")
            .arg(dir.path())
            .envs(env.iter().copied())
            .env_remove("CHOREO_DATABASE_URL")
            .output()
            .expect("run choreo")
    };
    for (flag, value) in [
        ("--rate-limit-rps", "1e-19"),
        ("--rate-limit-rps", "NaN"),
        ("--rate-limit-rps", "200000"),
        ("--max-queued-jobs", "0"),
        ("--storage-quota-bytes", "12"),
    ] {
        let out = run(&["keys", "create", "--name", "x", flag, value], &[]);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{flag} {value}: {stderr}");
        assert!(stderr.contains("must be from"), "{flag} {value}: {stderr}");
    }
    for (name, value) in [
        ("CHOREO_RATE_LIMIT_RPS", "0.001"),
        ("CHOREO_MAX_EVENT_STREAMS_PER_KEY", "0"),
        ("CHOREO_EVENT_STREAM_MAX_S", "1000000"),
    ] {
        let out = run(&["keys", "list"], &[(name, value)]);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{name}={value}: {stderr}");
        assert!(stderr.contains("must be from"), "{name}={value}: {stderr}");
    }
    let out = run(
        &["keys", "create", "--name", "ok", "--rate-limit-rps", "0.5"],
        &[],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}
