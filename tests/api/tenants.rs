//! API keys as tenants, on SQLite and on PostgreSQL: two keys share nothing they can see (every
//! `/v1` route answers another tenant's id with 404), revoked and unknown keys get 401, a key's
//! rate limit answers 429 under a burst while another key's requests pass, queue and storage
//! quotas refuse what would pass them, one tenant's 200 queued jobs do not hold back another's
//! first job by more than one job's time, and `choreo keys` works on the running server's
//! database from another process.
use crate::helpers::{expect_problem, short_song, test_config, TestApp};
use crate::postgres::Postgres;
use choreo::api::Server;
use choreo::config::{Config, Secret};
use choreo::queue::{KeyLimits, NewKey};
use reqwest::multipart::{Form, Part};
use reqwest::{Method, Response, StatusCode};
use serde_json::{json, Value};
use std::path::Path;
use std::time::{Duration, Instant};

/// Which store a test runs on.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Db {
    Sqlite,
    Postgres,
}

/// The service, its database server when PostgreSQL, and its config (for the CLI's environment).
pub(crate) struct App {
    pub(crate) app: TestApp,
    config: Config,
    _pg: Option<Postgres>,
}

pub(crate) async fn spawn(db: Db, edit: impl FnOnce(&mut Config)) -> App {
    spawn_with(db, true, edit).await
}

/// The service on `db`, with its workers or (`workers: false`) the API only, so jobs stay queued.
pub(crate) async fn spawn_with(db: Db, workers: bool, edit: impl FnOnce(&mut Config)) -> App {
    choreo::telemetry::init_tracing(choreo::config::LogFormat::Pretty, "warn");
    let pg = match db {
        Db::Sqlite => None,
        Db::Postgres => Some(
            tokio::task::spawn_blocking(Postgres::start)
                .await
                .expect("start postgres"),
        ),
    };
    let data_dir = tempfile::tempdir().expect("tempdir");
    let mut config = test_config(data_dir.path());
    if let Some(pg) = &pg {
        config.database_url = Some(Secret::new(pg.url()));
    }
    edit(&mut config);
    config.validate().expect("valid test config");
    let server = if workers {
        Server::start(config.clone()).await
    } else {
        Server::start_api_only(config.clone()).await
    }
    .expect("service starts");
    App {
        app: TestApp {
            addr: server.addr(),
            client: reqwest::Client::builder()
                .timeout(Duration::from_secs(60))
                .build()
                .expect("client"),
            data_dir,
            server: Some(server),
            token: None,
        },
        config,
        _pg: pg,
    }
}

impl App {
    /// A new key (its own tenant) with `limits`; returns its secret.
    pub(crate) async fn key(&self, name: &str, limits: KeyLimits) -> String {
        let (key, secret) = NewKey::mint(name, false, limits);
        self.store().add_key(key).await.expect("add key");
        secret
    }

    pub(crate) fn store(&self) -> &std::sync::Arc<dyn choreo::queue::Store> {
        &self.app.server.as_ref().expect("server runs").state().store
    }

    /// `method path` with `secret` as the bearer (none: no Authorization header).
    pub(crate) async fn call(&self, method: Method, path: &str, secret: Option<&str>) -> Response {
        let mut request = self.app.client.request(method, self.app.url(path));
        if let Some(secret) = secret {
            request = request.bearer_auth(secret);
        }
        request.send().await.expect("request")
    }

    pub(crate) async fn get(&self, path: &str, secret: &str) -> Response {
        self.call(Method::GET, path, Some(secret)).await
    }

    pub(crate) async fn upload(&self, secret: &str, path: &Path) -> Response {
        let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("song");
        let form = Form::new().part(
            "file",
            Part::bytes(std::fs::read(path).expect("read song")).file_name(name.to_string()),
        );
        self.app
            .client
            .post(self.app.url("/v1/songs"))
            .bearer_auth(secret)
            .multipart(form)
            .send()
            .await
            .expect("upload")
    }

    pub(crate) async fn upload_rig(&self, secret: &str) -> Response {
        let bytes = std::fs::read(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/rig_unreal_cm.bvh"),
        )
        .expect("rig fixture");
        let form = Form::new().part("file", Part::bytes(bytes).file_name("rig.bvh"));
        self.app
            .client
            .post(self.app.url("/v1/rigs"))
            .bearer_auth(secret)
            .multipart(form)
            .send()
            .await
            .expect("upload rig")
    }

    pub(crate) async fn post_job(&self, secret: &str, body: &Value) -> Response {
        self.app
            .client
            .post(self.app.url("/v1/jobs"))
            .bearer_auth(secret)
            .json(body)
            .send()
            .await
            .expect("POST /v1/jobs")
    }

    pub(crate) async fn json(&self, path: &str, secret: &str) -> Value {
        let response = self.get(path, secret).await;
        let status = response.status();
        let body: Value = response.json().await.expect("json");
        assert_eq!(status, StatusCode::OK, "{path}: {body}");
        body
    }

    /// Polls a job until it is terminal.
    pub(crate) async fn wait_job(&self, secret: &str, id: &str) -> Value {
        let deadline = Instant::now() + Duration::from_secs(180);
        loop {
            let job = self.json(&format!("/v1/jobs/{id}"), secret).await;
            if ["succeeded", "failed", "cancelled"].contains(&job["status"].as_str().unwrap_or(""))
            {
                return job;
            }
            assert!(Instant::now() < deadline, "job {id} not finished: {job}");
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }

    /// Uploads the short song as `secret` and returns its id (201 expected).
    pub(crate) async fn song(&self, secret: &str) -> String {
        let response = self.upload(secret, &short_song()).await;
        let status = response.status();
        let body: Value = response.json().await.expect("song");
        assert_eq!(status, StatusCode::CREATED, "{body}");
        body["id"].as_str().expect("song id").to_string()
    }

    pub(crate) async fn stop(self) {
        self.app.stop().await;
    }
}

/// One test per store from one async fn.
macro_rules! both_stores {
    ($($name:ident),* $(,)?) => {
        mod sqlite {
            $(
                #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
                async fn $name() {
                    super::$name(super::Db::Sqlite).await
                }
            )*
        }
        mod postgres {
            $(
                #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
                async fn $name() {
                    super::$name(super::Db::Postgres).await
                }
            )*
        }
    };
}

both_stores!(
    tenants_cannot_reach_each_others_songs_jobs_results_or_rigs,
    unknown_and_revoked_keys_get_401_and_the_token_is_its_own_tenant,
    a_burst_past_the_rate_limit_gets_429_while_another_key_passes,
    queue_and_storage_quotas_refuse_what_would_pass_them,
    two_hundred_queued_jobs_do_not_hold_back_another_tenants_first_job,
    the_keys_cli_works_on_the_running_servers_database,
);

async fn tenants_cannot_reach_each_others_songs_jobs_results_or_rigs(db: Db) {
    let app = spawn(db, |c| c.models_dir = crate::common_models::models_dir()).await;
    let a = app.key("a", KeyLimits::default()).await;
    let b = app.key("b", KeyLimits::default()).await;

    let song_a = app.song(&a).await;
    let response = app
        .post_job(
            &a,
            &json!({"song_id": song_a, "model": "dance-revolution", "seed": 1}),
        )
        .await;
    assert_eq!(response.status(), StatusCode::ACCEPTED);
    let job_a = response.json::<Value>().await.expect("job")["id"]
        .as_str()
        .expect("job id")
        .to_string();
    let done = app.wait_job(&a, &job_a).await;
    assert_eq!(done["status"], "succeeded", "{done}");
    let rig = app.upload_rig(&a).await;
    assert_eq!(rig.status(), StatusCode::CREATED);
    let rig_a = rig.json::<Value>().await.expect("rig")["id"]
        .as_str()
        .expect("rig id")
        .to_string();

    // Every route that takes an id: a's key reads it, b's gets 404 as for an id never made.
    let reads = [
        format!("/v1/songs/{song_a}"),
        format!("/v1/songs/{song_a}/audio"),
        format!("/v1/rigs/{rig_a}"),
        format!("/v1/jobs/{job_a}"),
        format!("/v1/jobs/{job_a}/preview.png"),
        format!("/v1/jobs/{job_a}/motion.json"),
        format!("/v1/jobs/{job_a}/report.json"),
        format!("/v1/jobs/{job_a}/motion.bvh"),
        format!("/v1/jobs/{job_a}/motion.glb"),
        format!("/v1/jobs/{job_a}/motion.vrma"),
        format!("/v1/jobs/{job_a}/motion.smpl.npz"),
        format!("/v1/jobs/{job_a}/motion.bvh?rig={rig_a}"),
    ];
    for path in &reads {
        let mine = app.get(path, &a).await;
        assert_eq!(mine.status(), StatusCode::OK, "{path} as its owner");
        let theirs = app.get(path, &b).await;
        assert_eq!(
            theirs.status(),
            StatusCode::NOT_FOUND,
            "{path} as another tenant"
        );
    }
    // An operator's key reads every tenant's rows.
    let (admin, admin_secret) = NewKey::mint("ops", true, KeyLimits::default());
    app.store().add_key(admin).await.expect("add admin key");
    for path in &reads[..4] {
        assert_eq!(
            app.get(path, &admin_secret).await.status(),
            StatusCode::OK,
            "{path} as admin"
        );
    }
    // A rig is found in the caller's tenant only, also as a download's `rig=`.
    let song_b = app.song(&b).await;
    let response = app
        .post_job(
            &b,
            &json!({"song_id": song_b, "model": "dance-revolution", "seed": 1}),
        )
        .await;
    let job_b = response.json::<Value>().await.expect("job")["id"]
        .as_str()
        .expect("job id")
        .to_string();
    assert_eq!(app.wait_job(&b, &job_b).await["status"], "succeeded");
    expect_problem(
        app.get(&format!("/v1/jobs/{job_b}/motion.bvh?rig={rig_a}"), &b)
            .await,
        StatusCode::NOT_FOUND,
        "rig-not-found",
    )
    .await;
    // The same bytes are b's own song: a new id, never a's.
    assert_ne!(song_b, song_a);
    // b cannot dance a's song, nor cancel a's job.
    expect_problem(
        app.post_job(&b, &json!({"song_id": song_a, "model": "dance-revolution"}))
            .await,
        StatusCode::NOT_FOUND,
        "song-not-found",
    )
    .await;
    let cancel = app
        .call(Method::DELETE, &format!("/v1/jobs/{job_a}"), Some(&b))
        .await;
    assert_eq!(cancel.status(), StatusCode::NOT_FOUND);
    // Listings hold the caller's own jobs only.
    for (secret, own, other) in [(&a, &job_a, &job_b), (&b, &job_b, &job_a)] {
        let page = app.json("/v1/jobs?limit=100", secret).await;
        let ids: Vec<&str> = page["items"]
            .as_array()
            .expect("items")
            .iter()
            .filter_map(|j| j["id"].as_str())
            .collect();
        assert!(
            ids.contains(&own.as_str()) && !ids.contains(&other.as_str()),
            "{page}"
        );
        let songs: Vec<&str> = page["items"]
            .as_array()
            .expect("items")
            .iter()
            .filter_map(|j| j["song_id"].as_str())
            .collect();
        assert!(songs
            .iter()
            .all(|s| *s == if secret == &a { &song_a } else { &song_b }));
    }
    app.stop().await;
}

async fn unknown_and_revoked_keys_get_401_and_the_token_is_its_own_tenant(db: Db) {
    let app = spawn(db, |c| c.auth_token = Some(Secret::new("the-token"))).await;
    // The token alone, before any key: the single open tenant, as before keys existed.
    let open_song = app.song("the-token").await;
    let (key, secret) = NewKey::mint("soon-revoked", false, KeyLimits::default());
    let id = key.id;
    app.store().add_key(key).await.expect("add key");
    assert_eq!(app.get("/v1/jobs", &secret).await.status(), StatusCode::OK);
    // The token still opens its own tenant, which is not the key's.
    assert_eq!(
        app.get(&format!("/v1/songs/{open_song}"), "the-token")
            .await
            .status(),
        StatusCode::OK
    );
    assert_eq!(
        app.get(&format!("/v1/songs/{open_song}"), &secret)
            .await
            .status(),
        StatusCode::NOT_FOUND
    );
    // No header, a wrong token, an unknown key, a known key's id with a wrong secret: 401.
    let unknown = NewKey::mint("never-stored", false, KeyLimits::default()).1;
    let mut forged = secret.clone();
    let last = if forged.ends_with('a') { "b" } else { "a" };
    forged.replace_range(forged.len() - 1.., last);
    for given in [
        None,
        Some("nope"),
        Some(unknown.as_str()),
        Some(forged.as_str()),
    ] {
        expect_problem(
            app.call(Method::GET, "/v1/jobs", given).await,
            StatusCode::UNAUTHORIZED,
            "unauthorized",
        )
        .await;
    }
    app.store().revoke_key(id).await.expect("revoke");
    // Keys are cached for a second at most.
    tokio::time::sleep(choreo::api::tenancy::KEY_CACHE + Duration::from_millis(200)).await;
    expect_problem(
        app.get("/v1/jobs", &secret).await,
        StatusCode::UNAUTHORIZED,
        "unauthorized",
    )
    .await;
    let stored = app.store().key(id).await.expect("key");
    assert!(
        stored.revoked_at.is_some() && stored.last_used_at.is_some(),
        "{stored:?}"
    );
    app.stop().await;

    // Without a token: once a key exists, even a revoked one, a request without a key is 401.
    let app = spawn(db, |_| {}).await;
    assert_eq!(
        app.call(Method::GET, "/v1/jobs", None).await.status(),
        StatusCode::OK,
        "no key and no token: open"
    );
    let (key, secret) = NewKey::mint("only", false, KeyLimits::default());
    let id = key.id;
    app.store().add_key(key).await.expect("add key");
    app.store().revoke_key(id).await.expect("revoke");
    tokio::time::sleep(choreo::api::tenancy::KEY_CACHE + Duration::from_millis(200)).await;
    for given in [None, Some(secret.as_str())] {
        expect_problem(
            app.call(Method::GET, "/v1/jobs", given).await,
            StatusCode::UNAUTHORIZED,
            "unauthorized",
        )
        .await;
    }
    app.stop().await;
}

async fn a_burst_past_the_rate_limit_gets_429_while_another_key_passes(db: Db) {
    let app = spawn(db, |c| c.rate_limit_rps = Some(1000.0)).await;
    let slow = app
        .key(
            "slow",
            KeyLimits {
                rate_limit_rps: Some(2.0),
                ..KeyLimits::default()
            },
        )
        .await;
    let other = app.key("other", KeyLimits::default()).await;
    let burst = |secret: String| {
        let app = &app;
        async move {
            let calls = (0..20).map(|_| app.get("/v1/jobs", &secret));
            futures::future::join_all(calls).await
        }
    };
    let (limited, passed) = tokio::join!(burst(slow.clone()), burst(other.clone()));
    let ok = limited
        .iter()
        .filter(|r| r.status() == StatusCode::OK)
        .count();
    assert!((1..=3).contains(&ok), "{ok} of 20 passed a 2/s limit");
    let refused = limited
        .into_iter()
        .find(|r| r.status() == StatusCode::TOO_MANY_REQUESTS)
        .expect("a 429");
    let retry_after: u64 = refused.headers()["retry-after"]
        .to_str()
        .expect("ascii")
        .parse()
        .expect("seconds");
    assert!((1..=2).contains(&retry_after), "Retry-After {retry_after}");
    expect_problem(refused, StatusCode::TOO_MANY_REQUESTS, "rate-limited").await;
    assert!(
        passed.iter().all(|r| r.status() == StatusCode::OK),
        "another key's requests all pass"
    );
    // After the wait it says, the key is served again.
    tokio::time::sleep(Duration::from_secs(retry_after)).await;
    assert_eq!(app.get("/v1/jobs", &slow).await.status(), StatusCode::OK);
    app.stop().await;
}

async fn queue_and_storage_quotas_refuse_what_would_pass_them(db: Db) {
    let song_bytes = std::fs::metadata(short_song()).expect("song").len();
    // No workers in this process: the jobs stay queued.
    let app = spawn_with(db, false, |c| {
        c.models_dir = crate::common_models::models_dir();
        c.max_queued_jobs = Some(3);
        c.storage_quota_bytes = Some(song_bytes + 1000);
    })
    .await;
    let capped = app.key("capped", KeyLimits::default()).await;
    let roomy = app
        .key(
            "roomy",
            KeyLimits {
                max_queued_jobs: Some(1000),
                storage_quota_bytes: Some(1 << 30),
                ..KeyLimits::default()
            },
        )
        .await;
    // Storage: the first song fits, a second does not, the same bytes again are no new bytes.
    let song_id = app.song(&capped).await;
    // The same song as WAV: other bytes, and larger.
    let second = crate::helpers::fixture("wav");
    let body = expect_problem(
        app.upload(&capped, &second).await,
        StatusCode::PAYLOAD_TOO_LARGE,
        "storage-quota-exceeded",
    )
    .await;
    assert!(
        body["detail"].as_str().unwrap_or("").contains("quota"),
        "{body}"
    );
    assert_eq!(
        app.upload(&capped, &short_song()).await.status(),
        StatusCode::OK
    );
    let roomy_song = app.song(&roomy).await;
    assert_eq!(
        app.upload(&roomy, &second).await.status(),
        StatusCode::CREATED,
        "the key's own quota overrides the config's"
    );
    // Queue: at most 3 queued or running (the song's analyze job counts).
    let job = json!({"song_id": song_id, "model": "dance-revolution", "priority": -100});
    let mut accepted = 0;
    let mut refused = None;
    for _ in 0..6 {
        let response = app.post_job(&capped, &job).await;
        match response.status() {
            StatusCode::ACCEPTED => accepted += 1,
            StatusCode::TOO_MANY_REQUESTS => {
                refused = Some(response);
                break;
            }
            other => panic!("{other}: {}", response.text().await.unwrap_or_default()),
        }
    }
    assert_eq!(accepted, 2, "the analyze job and 2 more make the 3 allowed");
    let refused = refused.expect("a 429 once 3 are queued or running");
    assert!(refused.headers().contains_key("retry-after"));
    expect_problem(
        refused,
        StatusCode::TOO_MANY_REQUESTS,
        "too-many-queued-jobs",
    )
    .await;
    // Another key with its own limit is not held back by this one's queue.
    let roomy_job = json!({"song_id": roomy_song, "model": "dance-revolution", "priority": -100});
    for _ in 0..4 {
        assert_eq!(
            app.post_job(&roomy, &roomy_job).await.status(),
            StatusCode::ACCEPTED
        );
    }
    app.stop().await;
}

async fn two_hundred_queued_jobs_do_not_hold_back_another_tenants_first_job(db: Db) {
    const QUEUED: usize = 200;
    let app = spawn(db, |c| {
        c.workers = 1;
        c.models_dir = crate::common_models::models_dir();
    })
    .await;
    let busy = app.key("busy", KeyLimits::default()).await;
    let newcomer = app.key("newcomer", KeyLimits::default()).await;
    let busy_song = app.song(&busy).await;
    let mut ids = Vec::new();
    for seed in 0..QUEUED {
        let response = app
            .post_job(
                &busy,
                &json!({"song_id": busy_song, "model": "dance-revolution", "seed": seed, "priority": 100}),
            )
            .await;
        assert_eq!(response.status(), StatusCode::ACCEPTED);
        ids.push(
            response.json::<Value>().await.expect("job")["id"]
                .as_str()
                .expect("id")
                .to_string(),
        );
    }
    // Let the busy tenant's queue get going, then the newcomer uploads: its analyze job is its
    // first job, and then it asks for a dance.
    let first = app.wait_job(&busy, &ids[0]).await;
    assert_eq!(first["status"], "succeeded", "{first}");
    let song_id = app.song(&newcomer).await;
    let submitted = Instant::now();
    let response = app
        .post_job(
            &newcomer,
            &json!({"song_id": song_id, "model": "dance-revolution", "seed": 1}),
        )
        .await;
    assert_eq!(response.status(), StatusCode::ACCEPTED);
    let job_id = response.json::<Value>().await.expect("job")["id"]
        .as_str()
        .expect("id")
        .to_string();
    let done = app.wait_job(&newcomer, &job_id).await;
    let waited = submitted.elapsed();
    let analyze = app.json("/v1/jobs?limit=10", &newcomer).await["items"]
        .as_array()
        .expect("items")
        .iter()
        .find(|j| j["kind"] == "analyze")
        .cloned()
        .expect("the newcomer's analyze job");
    let time = |v: &Value| {
        chrono::DateTime::parse_from_rfc3339(v.as_str().expect("a time")).expect("time")
    };
    let first_wait = (time(&analyze["started_at"]) - time(&analyze["created_at"]))
        .to_std()
        .unwrap_or_default();
    assert_eq!(done["status"], "succeeded", "{done}");
    // One job's time: the busiest of the busy tenant's finished jobs so far.
    let mut longest = Duration::ZERO;
    let mut finished = 0;
    for id in &ids {
        let job = app.json(&format!("/v1/jobs/{id}"), &busy).await;
        if let (Some(start), Some(end)) = (job["started_at"].as_str(), job["finished_at"].as_str())
        {
            let start = chrono::DateTime::parse_from_rfc3339(start).expect("time");
            let end = chrono::DateTime::parse_from_rfc3339(end).expect("time");
            longest = longest.max((end - start).to_std().unwrap_or_default());
            finished += 1;
        }
    }
    assert!(
        finished < QUEUED / 2,
        "the busy tenant's queue was still long ({finished} of {QUEUED} done)"
    );
    eprintln!(
        "{db:?}: newcomer's first job waited {first_wait:?}, its dance {waited:?}; longest busy job {longest:?}, {finished} of {QUEUED} busy jobs done"
    );
    assert!(
        first_wait <= longest + Duration::from_secs(1),
        "the newcomer's first job waited {first_wait:?} to start; one busy job takes up to {longest:?}"
    );
    // The newcomer waits for its analyze job and its dance (each behind at most the one busy
    // job running when it arrived): four jobs' time, with room for polling.
    assert!(
        waited <= longest * 4 + Duration::from_secs(2),
        "the newcomer's first dance took {waited:?}; one busy job takes up to {longest:?}"
    );
    let queued_ahead = app.json("/v1/jobs?status=queued&limit=100", &busy).await["items"]
        .as_array()
        .map_or(0, Vec::len);
    assert!(queued_ahead > 0, "the busy tenant still had jobs queued");
    app.stop().await;
}

async fn the_keys_cli_works_on_the_running_servers_database(db: Db) {
    let app = spawn(db, |_| {}).await;
    let keys = |args: &[&str]| {
        let mut command = std::process::Command::new(env!("CARGO_BIN_EXE_choreo"));
        command
            .arg("keys")
            .args(args)
            .env("CHOREO_DATA_DIR", &app.config.data_dir)
            .env_remove("CHOREO_DATABASE_URL");
        if let Some(url) = &app.config.database_url {
            command.env("CHOREO_DATABASE_URL", url.expose());
        }
        let out = command.output().expect("run choreo keys");
        assert!(
            out.status.success(),
            "choreo keys {args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        serde_json::from_slice::<Value>(&out.stdout).expect("JSON on stdout")
    };
    assert_eq!(
        app.call(Method::GET, "/v1/jobs", None).await.status(),
        StatusCode::OK
    );
    let made = keys(&["create", "--name", "cli", "--max-queued-jobs", "5"]);
    let fields: Vec<&String> = made.as_object().expect("object").keys().collect();
    assert_eq!(fields, ["id", "name", "secret"]);
    assert_eq!(made["name"], "cli");
    let secret = made["secret"].as_str().expect("secret").to_string();
    let id = made["id"].as_str().expect("id").to_string();
    // The server sees the key within its cache time; from then on a key is needed.
    tokio::time::sleep(choreo::api::tenancy::KEY_CACHE + Duration::from_millis(200)).await;
    assert_eq!(app.get("/v1/jobs", &secret).await.status(), StatusCode::OK);
    expect_problem(
        app.call(Method::GET, "/v1/jobs", None).await,
        StatusCode::UNAUTHORIZED,
        "unauthorized",
    )
    .await;
    // The list shows the key, its override and its use, never its secret.
    let mut listed = Value::Null;
    for _ in 0..50 {
        listed = keys(&["list"]);
        if listed[0]["last_used_at"].is_string() {
            break;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    assert_eq!(listed.as_array().map(Vec::len), Some(1), "{listed}");
    assert_eq!(listed[0]["id"], id.as_str());
    assert_eq!(listed[0]["max_queued_jobs"], 5);
    assert!(listed[0]["last_used_at"].is_string(), "{listed}");
    let random = secret.rsplit('_').next().expect("random part");
    assert!(!listed.to_string().contains(random), "{listed}");
    let revoked = keys(&["revoke", &id]);
    assert!(revoked["revoked_at"].is_string(), "{revoked}");
    tokio::time::sleep(choreo::api::tenancy::KEY_CACHE + Duration::from_millis(200)).await;
    expect_problem(
        app.get("/v1/jobs", &secret).await,
        StatusCode::UNAUTHORIZED,
        "unauthorized",
    )
    .await;
    app.stop().await;
}
