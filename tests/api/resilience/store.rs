//! A failing store against a real `choreo serve` process: a disk that fills up acknowledges
//! nothing it cannot keep, and a stopped PostgreSQL makes the server answer 503 quickly; both
//! recover once the store does.
use super::*;

/// A 24 MB tmpfs, unmounted when dropped.
struct SmallDisk {
    dir: tempfile::TempDir,
}

impl SmallDisk {
    /// Mounts it, or says why not: mounting needs root (CI runs as root).
    fn mount() -> Result<Self, String> {
        let dir = tempfile::tempdir().map_err(|e| e.to_string())?;
        let out = Command::new("mount")
            .args(["-t", "tmpfs", "-o", "size=24m", "tmpfs"])
            .arg(dir.path())
            .output()
            .map_err(|e| e.to_string())?;
        if out.status.success() {
            Ok(Self { dir })
        } else {
            Err(String::from_utf8_lossy(&out.stderr).into_owned())
        }
    }

    fn path(&self) -> &Path {
        self.dir.path()
    }

    /// Writes a file until the filesystem is full (at most 64 MB, so the loop is bounded).
    fn fill(&self) -> u64 {
        use std::io::Write;
        let mut file = std::fs::File::create(self.path().join("fill")).expect("fill file");
        let chunk = vec![7u8; 256 * 1024];
        let mut written = 0u64;
        for _ in 0..256 {
            match file.write(&chunk) {
                Ok(0) | Err(_) => break,
                Ok(n) => written += n as u64,
            }
        }
        let _ = file.sync_all();
        written
    }

    fn free(&self) {
        std::fs::remove_file(self.path().join("fill")).expect("remove the fill file");
    }
}

impl Drop for SmallDisk {
    fn drop(&mut self) {
        let _ = Command::new("umount")
            .arg("-l")
            .arg(self.dir.path())
            .status();
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_full_disk_acknowledges_nothing_it_cannot_keep_and_recovers() {
    let disk = match SmallDisk::mount() {
        Ok(disk) => disk,
        Err(why) if std::env::var("CI").is_ok_and(|v| v == "true") => {
            panic!("CI=true: a 24 MB tmpfs must mount for this test: {why}")
        }
        Err(why) => {
            eprintln!("NOT RUN (not root, or mounts not allowed here; CI runs it as root): mount -t tmpfs: {why}");
            return;
        }
    };
    let data = disk.path().join("data");
    let mut serve = Serve::start(Options {
        models: true,
        data_dir: Some(data.clone()),
        env: &[("CHOREO_RETRY_BACKOFF_S", "0.2"), ("CHOREO_POLL_S", "0.1")],
        ..Options::default()
    });
    let client = client();
    let song = upload(&client, &serve, &short_song()).await;
    settle(&client, &serve, Duration::from_secs(60)).await;

    let filled = disk.fill();
    eprintln!("filled the 24 MB tmpfs with {:.1} MB", filled as f64 / 1e6);
    let mut accepted = Vec::new();
    let mut refused = 0;
    for seed in 0..8 {
        let response = client
            .post(serve.url("/v1/jobs"))
            .json(&json!({"song_id": song["id"], "model": "dance-revolution", "seed": seed}))
            .send()
            .await
            .expect("POST /v1/jobs");
        match response.status() {
            StatusCode::ACCEPTED => {
                let job: Value = response.json().await.expect("job");
                let id = job["id"].as_str().expect("id").to_string();
                // Acknowledged means durable: the job is there when asked for.
                let got = client
                    .get(serve.url(&format!("/v1/jobs/{id}")))
                    .send()
                    .await
                    .expect("GET job");
                let log = serve.log();
                let tail: String = log.lines().rev().take(15).collect::<Vec<_>>().join("\n");
                assert_eq!(got.status(), StatusCode::OK, "job {id} was acknowledged with 202 but is not there; server log, last lines first:\n{tail}");
                accepted.push(id);
            }
            StatusCode::INSUFFICIENT_STORAGE => {
                crate::helpers::expect_problem(
                    response,
                    StatusCode::INSUFFICIENT_STORAGE,
                    "insufficient-storage",
                )
                .await;
                refused += 1;
            }
            other => panic!(
                "a full disk answered {other}: {}",
                response.text().await.unwrap_or_default()
            ),
        }
    }
    eprintln!(
        "on the full disk: {} jobs acknowledged (and there), {refused} refused with 507",
        accepted.len()
    );
    let response = {
        let form = reqwest::multipart::Form::new().part(
            "file",
            reqwest::multipart::Part::bytes(
                std::fs::read(crate::helpers::fixture("wav")).expect("wav"),
            )
            .file_name("a.wav"),
        );
        client
            .post(serve.url("/v1/songs"))
            .multipart(form)
            .send()
            .await
            .expect("upload")
    };
    crate::helpers::expect_problem(
        response,
        StatusCode::INSUFFICIENT_STORAGE,
        "insufficient-storage",
    )
    .await;
    tokio::time::sleep(Duration::from_secs(3)).await;
    serve.assert_alive();

    // Space returns: the service resumes by itself.
    disk.free();
    let response = client
        .post(serve.url("/v1/jobs"))
        .json(&json!({"song_id": song["id"], "model": "dance-revolution", "seed": 99}))
        .send()
        .await
        .expect("POST /v1/jobs");
    let status = response.status();
    assert_eq!(
        status,
        StatusCode::ACCEPTED,
        "accepted again once space returned: {}",
        response.text().await.unwrap_or_default()
    );
    let jobs = settle(&client, &serve, Duration::from_secs(180)).await;
    for id in &accepted {
        let job = jobs
            .iter()
            .find(|j| j["id"] == id.as_str())
            .unwrap_or_else(|| panic!("acknowledged job {id} was lost: {jobs:?}"));
        assert_eq!(job["status"], "succeeded", "{job}");
    }
    for job in &jobs {
        assert_eq!(job["status"], "succeeded", "{job}");
    }
    // SIGTERM, then the event log: no job ran twice.
    // SAFETY: kill only signals our own child.
    assert_eq!(
        unsafe { libc::kill(serve.child.id() as libc::pid_t, libc::SIGTERM) },
        0
    );
    let deadline = Instant::now() + Duration::from_secs(30);
    while serve.child.try_wait().expect("try_wait").is_none() {
        assert!(Instant::now() < deadline, "no exit 30 s after SIGTERM");
        std::thread::sleep(Duration::from_millis(50));
    }
    let options = sqlx::sqlite::SqliteConnectOptions::new()
        .filename(data.join("choreo.sqlite"))
        .read_only(true);
    let pool = sqlx::SqlitePool::connect_with(options)
        .await
        .expect("open db");
    let rows: Vec<(String, i64, i64)> = sqlx::query_as(
        "SELECT job_id, SUM(to_status = 'running'), SUM(to_status = 'succeeded') FROM job_events GROUP BY job_id",
    )
    .fetch_all(&pool)
    .await
    .expect("events");
    assert_eq!(rows.len(), jobs.len());
    for (id, runs, successes) in rows {
        assert_eq!(
            (runs, successes),
            (1, 1),
            "job {id} ran once and succeeded once"
        );
    }
}

/// GET `path` until it answers `want` (bounded); how long it took.
async fn answers(
    client: &reqwest::Client,
    serve: &Serve,
    path: &str,
    want: StatusCode,
    limit: Duration,
) -> Duration {
    let start = Instant::now();
    loop {
        let last = match client.get(serve.url(path)).send().await {
            Ok(response) if response.status() == want => return start.elapsed(),
            Ok(response) => format!(
                "{}: {}",
                response.status(),
                response.text().await.unwrap_or_default()
            ),
            Err(e) => e.to_string(),
        };
        assert!(
            start.elapsed() < limit,
            "GET {path} did not answer {want} within {limit:?}; last: {last}"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn postgres_stopped_answers_503_within_5_s_and_recovers() {
    let mut db = tokio::task::spawn_blocking(crate::postgres::Postgres::start)
        .await
        .expect("start postgres");
    let url = db.url();
    let mut serve = Serve::start(Options {
        env: &[("CHOREO_DATABASE_URL", &url)],
        ..Options::default()
    });
    let client = client();
    answers(
        &client,
        &serve,
        "/readyz",
        StatusCode::OK,
        Duration::from_secs(10),
    )
    .await;
    assert_eq!(
        client
            .get(serve.url("/v1/jobs"))
            .send()
            .await
            .expect("GET jobs")
            .status(),
        StatusCode::OK
    );

    let db = tokio::task::spawn_blocking(move || {
        db.stop();
        db
    })
    .await
    .expect("stop postgres");
    // Every call that needs the database fails fast with a problem, not a hang or a 500.
    for (method, path) in [
        ("GET", "/v1/jobs"),
        ("GET", "/v1/jobs/0191f0a0-0000-7000-8000-000000000000"),
        ("POST", "/v1/jobs"),
    ] {
        let start = Instant::now();
        let request = match method {
            "POST" => client.post(serve.url(path)).json(&json!({"song_id": "0191f0a0-0000-7000-8000-000000000000", "model": "dance-revolution"})),
            _ => client.get(serve.url(path)),
        };
        let response = request.send().await.expect("request");
        let took = start.elapsed();
        assert!(
            took < Duration::from_secs(5),
            "{method} {path} took {took:?} with PostgreSQL stopped"
        );
        crate::helpers::expect_problem(
            response,
            StatusCode::SERVICE_UNAVAILABLE,
            "service-unavailable",
        )
        .await;
        eprintln!("{method} {path}: 503 in {took:?}");
    }
    let start = Instant::now();
    let ready = client
        .get(serve.url("/readyz"))
        .send()
        .await
        .expect("readyz");
    assert_eq!(ready.status(), StatusCode::SERVICE_UNAVAILABLE);
    assert!(
        start.elapsed() < Duration::from_secs(5),
        "/readyz took {:?}",
        start.elapsed()
    );

    let mut db = db;
    let db = tokio::task::spawn_blocking(move || {
        db.restart();
        db
    })
    .await
    .expect("restart postgres");
    let took = answers(
        &client,
        &serve,
        "/readyz",
        StatusCode::OK,
        Duration::from_secs(15),
    )
    .await;
    eprintln!("ready again {took:?} after PostgreSQL restarted");
    answers(
        &client,
        &serve,
        "/v1/jobs",
        StatusCode::OK,
        Duration::from_secs(5),
    )
    .await;
    serve.assert_alive();
    drop(db);
}
