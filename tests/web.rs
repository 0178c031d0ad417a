//! The page at `/` in a real browser: Playwright (`tests/web/flow.mjs`, npm `playwright-core`)
//! drives Debian's chromium through the whole flow against two real servers, the page from one
//! and the API from another origin with a bearer token and CORS: upload (file input and drop),
//! key poses, submit, progress, playback in sync with the song, scrub, the mannequin (its skin
//! on its joints at two times) and the stick toggle, rig upload and pick, loop, compare, report
//! plots, downloads and deep links. Also: the embedded assets, and that `web/dist` is what
//! `web/src` builds to; the TypeScript client (`clients/typescript`): its drift from the spec
//! and its sources, and with Node against a real server; and the `<choreo-player>` element on a
//! sample page of another origin.
//!
//! Needs node, chromium, `npm ci` in `tests/web`, `web` and `clients/typescript` (all from
//! `scripts/setup.sh --test`) and `../shared/audio`; without them the tests fail under
//! `CI=true` and print a notice otherwise.
#[path = "common/models.rs"]
mod common_models;
#[allow(dead_code)]
#[path = "api/helpers.rs"]
mod helpers;
use common_models::models_dir;

use helpers::{spawn_app, spawn_app_with, TestApp};
use reqwest::StatusCode;
use std::path::{Path, PathBuf};
use std::time::Duration;

const TOKEN: &str = "web-test-token";
/// The whole browser flow (two generations of a 5-s song, playback) is killed past this.
const FLOW_LIMIT: Duration = Duration::from_secs(480);

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn chromium() -> PathBuf {
    std::env::var_os("CHROMIUM").map_or_else(|| PathBuf::from("/usr/bin/chromium"), PathBuf::from)
}

/// What a test needs besides node.
struct Needs {
    node_modules: &'static [&'static str],
    browser_and_songs: bool,
}

/// What is missing to run a test, if anything.
fn missing_prerequisites(needs: &Needs) -> Vec<String> {
    let mut missing = Vec::new();
    match std::process::Command::new("node").arg("--version").output() {
        Ok(out) if out.status.success() => {}
        _ => missing.push("node (Node.js 20 or later)".to_string()),
    }
    for dir in needs.node_modules {
        if !root().join(dir).is_dir() {
            missing.push(format!("{dir} (npm ci)"));
        }
    }
    if needs.browser_and_songs {
        if !chromium().is_file() {
            missing.push(format!(
                "{} (Debian's chromium package)",
                chromium().display()
            ));
        }
        if !root()
            .join("../shared/audio/trumpet_loop_90bpm.ogg")
            .is_file()
        {
            missing.push("../shared/audio".to_string());
        }
    }
    missing
}

/// True when the test can run; panics under CI=true when it cannot, so CI never skips it.
fn ready(test: &str, needs: &Needs) -> bool {
    let missing = missing_prerequisites(needs);
    if missing.is_empty() {
        return true;
    }
    let message = format!(
        "{test} needs {}: run `scripts/setup.sh --test` (or `make test`)",
        missing.join(", ")
    );
    assert!(
        std::env::var("CI").as_deref() != Ok("true"),
        "{message} (CI=true)"
    );
    eprintln!("NOTICE: skipping: {message}");
    false
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_whole_flow_works_in_chromium_with_the_api_on_another_origin() {
    if !ready(
        "the browser flow test",
        &Needs {
            node_modules: &["tests/web/node_modules/playwright-core"],
            browser_and_songs: true,
        },
    ) {
        return;
    }
    // The page from one server; the API, with models, a token and CORS for the page, from another.
    let page: TestApp = spawn_app().await;
    let page_origin = format!("http://{}", page.addr);
    let api = spawn_app_with(|c| {
        c.models_dir = models_dir();
        c.auth_token = Some(choreo::config::Secret::new(TOKEN));
        c.cors_origins = vec![page_origin.clone()];
    })
    .await;
    let out = Path::new(env!("CARGO_TARGET_TMPDIR")).join("web-flow");
    let _ = std::fs::remove_dir_all(&out);
    std::fs::create_dir_all(&out).expect("screenshot dir");

    let run = tokio::process::Command::new("node")
        .arg(root().join("tests/web/flow.mjs"))
        .env("PAGE_URL", &page_origin)
        .env("API_URL", format!("http://{}", api.addr))
        .env("TOKEN", TOKEN)
        .env("EXPECT_EVENTS", if spec_has_events() { "1" } else { "0" })
        .env("SONG", helpers::short_song())
        .env("OUT_DIR", &out)
        .env("CHROMIUM", chromium())
        .current_dir(root().join("tests/web"))
        .kill_on_drop(true)
        .output();
    let output = tokio::time::timeout(FLOW_LIMIT, run)
        .await
        .unwrap_or_else(|_| {
            panic!(
                "the browser flow ran past {FLOW_LIMIT:?}; screenshots in {}",
                out.display()
            )
        })
        .expect("run node tests/web/flow.mjs");
    let stdout = String::from_utf8_lossy(&output.stdout);
    eprintln!("{stdout}{}", String::from_utf8_lossy(&output.stderr));
    assert!(
        output.status.success(),
        "the browser flow failed (above); screenshots in {}",
        out.display()
    );

    // The script's own summary, checked again here: the numbers it must meet.
    let summary: serde_json::Value = stdout
        .lines()
        .find_map(|l| l.strip_prefix("summary: "))
        .and_then(|s| serde_json::from_str(s).ok())
        .expect("the flow prints its summary");
    for (phase, sync) in summary["sync"].as_object().expect("sync phases") {
        let worst = sync["worst_diff_s"].as_f64().expect("worst_diff_s");
        // Over the frames drawn in time; clock.mjs checks every pose against the clock read in its
        // frame and bounds the CPU-starved frames.
        assert!(
            worst <= 1.0 / 25.0,
            "{phase}: |audioTime − animationTime| reached {worst} s"
        );
        assert!(
            sync["audio_advanced_s"].as_f64().expect("advanced") > 1.0,
            "{phase}: the song did not play: {sync}"
        );
    }
    assert!(
        summary["sync"].as_object().is_some_and(|s| s.len() >= 3),
        "playing, looping and deep link were measured: {summary}"
    );
    // The mannequin drawn and moving with the song, its skin on its joints; a rig upload mapped.
    let mannequin = &summary["mannequin"];
    assert!(
        mannequin["triangles"].as_u64().is_some_and(|n| n > 1000),
        "{summary}"
    );
    assert!(
        mannequin["travel_m"].as_f64().is_some_and(|m| m > 0.05),
        "{summary}"
    );
    assert!(
        summary["rig"]["mapped"].as_u64().is_some_and(|n| n >= 13),
        "{summary}"
    );
    let shots = summary["screenshots"].as_array().expect("screenshots");
    assert!(shots.len() >= 6, "{summary}");
    for shot in shots {
        let bytes = std::fs::read(shot.as_str().expect("path")).expect("screenshot file");
        assert!(
            bytes.starts_with(b"\x89PNG") && bytes.len() > 10_000,
            "{shot} is a real PNG"
        );
    }
    eprintln!("screenshots: {}", out.display());
    api.stop().await;
    page.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_page_and_its_assets_are_served_from_the_binary() {
    let app = spawn_app().await;
    let page = app.get("/").await;
    assert_eq!(page.status(), StatusCode::OK);
    let csp = page
        .headers()
        .get("content-security-policy")
        .and_then(|v| v.to_str().ok())
        .unwrap_or("")
        .to_string();
    assert!(
        csp.contains("script-src 'self'") && csp.contains("default-src 'none'"),
        "{csp}"
    );
    assert!(page.headers()["content-type"]
        .to_str()
        .is_ok_and(|t| t.starts_with("text/html")));
    let html = page.text().await.expect("html");
    assert!(
        html.contains(r#"src="/assets/app.js""#) && html.contains(r#"href="/assets/app.css""#),
        "{html}"
    );
    // Nothing is fetched from elsewhere: no absolute URL in the page's src or href attributes.
    assert!(
        !html.contains("src=\"http") && !html.contains("href=\"http"),
        "{html}"
    );

    for (path, kind) in [
        ("/assets/app.js", "text/javascript"),
        ("/assets/app.css", "text/css"),
        ("/assets/choreo-player.js", "text/javascript"),
    ] {
        let first = app.get(path).await;
        assert_eq!(first.status(), StatusCode::OK, "{path}");
        assert!(
            first.headers()["content-type"]
                .to_str()
                .is_ok_and(|t| t.starts_with(kind)),
            "{path}"
        );
        let etag = first.headers()["etag"].clone();
        let body = first.bytes().await.expect("body");
        let on_disk = std::fs::read(
            root()
                .join("web/dist")
                .join(path.trim_start_matches("/assets/")),
        )
        .expect("web/dist file");
        assert_eq!(
            body.as_ref(),
            on_disk.as_slice(),
            "{path} is web/dist's file"
        );
        let again = app
            .client
            .get(app.url(path))
            .header("if-none-match", etag)
            .send()
            .await
            .expect("GET");
        assert_eq!(
            again.status(),
            StatusCode::NOT_MODIFIED,
            "{path} with its ETag"
        );
    }
    app.stop().await;
}

#[test]
fn web_dist_is_what_web_src_builds_to() {
    // The page bundles the TypeScript client, so its dependencies are needed too.
    let needs = Needs {
        node_modules: &[
            "web/node_modules/esbuild",
            "web/node_modules/three",
            "clients/typescript/node_modules/openapi-fetch",
        ],
        browser_and_songs: false,
    };
    if !ready("the web build check", &needs) {
        return;
    }
    let out = tempfile::tempdir().expect("tempdir");
    let status = std::process::Command::new("node")
        .arg("build.mjs")
        .arg(out.path())
        .current_dir(root().join("web"))
        .status()
        .expect("run node web/build.mjs");
    assert!(status.success(), "npm run build failed");
    for file in ["index.html", "app.js", "app.css", "choreo-player.js"] {
        let built = std::fs::read(out.path().join(file)).expect("built file");
        let committed = std::fs::read(root().join("web/dist").join(file)).expect("committed file");
        assert!(
            built == committed,
            "web/dist/{file} differs from what web/src builds to: run `npm run build` in web/ and commit web/dist"
        );
    }
}

/// The TypeScript client's own checks (node's test runner): its generated types are what
/// openapi-typescript makes of `openapi/openapi.json` today, `dist/` is what its sources build to,
/// its server-sent-events reader keeps order and resumes with Last-Event-ID (a fake server),
/// the webhook receiver of docs/integrating.md verifies a Standard Webhooks signature, a stopped
/// server is an `ApiError` with the code `network-error` that names the URL, and the
/// `npm pack`ed package type-checks in a project with moduleResolution nodenext and bundler
/// (where a misspelt request field is a compile error).
#[test]
fn the_typescript_client_is_what_the_spec_and_its_sources_make() {
    let needs = Needs {
        node_modules: &[
            "clients/typescript/node_modules/openapi-typescript",
            "clients/typescript/node_modules/typescript",
            "clients/typescript/node_modules/esbuild",
            "clients/typescript/node_modules/standardwebhooks",
        ],
        browser_and_songs: false,
    };
    if !ready("the TypeScript client's checks", &needs) {
        return;
    }
    let output = std::process::Command::new("node")
        .args([
            "--test",
            "test/drift.test.mjs",
            "test/events.test.mjs",
            "test/webhook.test.mjs",
            "test/errors.test.mjs",
            "test/consumer.test.mjs",
        ])
        .current_dir(root().join("clients/typescript"))
        .output()
        .expect("run node --test in clients/typescript");
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "the TypeScript client's tests failed:\n{stdout}{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(
        stdout.contains("# fail 0") && !stdout.contains("# pass 0"),
        "{stdout}"
    );
}

/// A new API key (a tenant of its own) in `app`'s store, as `choreo keys create` makes one;
/// returns its secret.
async fn api_key(app: &TestApp, name: &str) -> String {
    let (key, secret) =
        choreo::queue::NewKey::mint(name, false, choreo::queue::KeyLimits::default());
    let server = app.server.as_ref().expect("the server runs");
    server
        .state()
        .store
        .add_key(key)
        .await
        .expect("add the key");
    secret
}

/// Whether the checked-in spec has the job events route (then the client must follow a job by
/// its events, not by polling).
fn spec_has_events() -> bool {
    let spec: serde_json::Value = serde_json::from_slice(
        &std::fs::read(root().join("openapi/openapi.json")).expect("openapi.json"),
    )
    .expect("spec json");
    spec["paths"].get("/v1/jobs/{id}/events").is_some()
}

/// Runs `node script` in `dir` with `env`, within `limit`; returns its stdout's summary line as
/// JSON.
async fn run_node(
    script: &Path,
    dir: &Path,
    env: &[(&str, String)],
    limit: Duration,
) -> serde_json::Value {
    let mut command = tokio::process::Command::new("node");
    command.arg(script).current_dir(dir).kill_on_drop(true);
    for (name, value) in env {
        command.env(name, value);
    }
    let output = tokio::time::timeout(limit, command.output())
        .await
        .unwrap_or_else(|_| panic!("{} ran past {limit:?}", script.display()))
        .unwrap_or_else(|e| panic!("run node {}: {e}", script.display()));
    let stdout = String::from_utf8_lossy(&output.stdout);
    eprintln!("{stdout}{}", String::from_utf8_lossy(&output.stderr));
    assert!(
        output.status.success(),
        "{} failed (above)",
        script.display()
    );
    stdout
        .lines()
        .find_map(|l| l.strip_prefix("summary: "))
        .and_then(|s| serde_json::from_str(s).ok())
        .unwrap_or_else(|| panic!("{} prints its summary", script.display()))
}

/// `clients/typescript` run with Node against a real server with an API key: it uploads a
/// song, waits for a dance (by its events when the server has them) and downloads motion.glb and
/// motion.json (`clients/typescript/test/e2e.mjs`; it needs only the committed dist/).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_typescript_client_uploads_waits_and_downloads_from_a_real_server() {
    if !ready(
        "the TypeScript client's end-to-end test",
        &Needs {
            node_modules: &[],
            browser_and_songs: true,
        },
    ) {
        return;
    }
    let mut app = spawn_app_with(|c| c.models_dir = models_dir()).await;
    let key = api_key(&app, "typescript-client").await;
    app.token = Some(key.clone()); // for the helpers' own check of the job below
    let events = spec_has_events();
    let env = [
        ("API_URL", format!("http://{}", app.addr)),
        ("API_KEY", key.clone()),
        ("SONG", helpers::short_song().display().to_string()),
        ("MODEL", "dance-revolution".to_string()),
        ("EXPECT_EVENTS", if events { "1" } else { "0" }.to_string()),
    ];
    let dir = root().join("clients/typescript");
    let summary = run_node(
        &dir.join("test/e2e.mjs"),
        &dir,
        &env,
        Duration::from_secs(240),
    )
    .await;
    let job = app.job(summary["job_id"].as_str().expect("job_id")).await;
    assert_eq!(job["status"], "succeeded", "{job}");
    assert!(
        summary["frames"].as_u64().is_some_and(|n| n > 25),
        "{summary}"
    );
    assert_eq!(
        summary["transport"],
        if events { "events" } else { "poll" },
        "{summary}"
    );
    app.stop().await;
}

/// `<choreo-player>` on a page of someone else's: Playwright loads `web/sample/player.html`
/// (its server address and ids replaced, an api-key attribute with a real API key added) in
/// Chromium from another origin, the element from `/assets/choreo-player.js` of a real server;
/// the dance plays within one motion frame of the song; after a seek the camera is on the dancer
/// of a dance that travels 3.6 m; a dance that cannot be loaded is reported inside the element.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_player_element_plays_a_dance_in_sync_on_another_page_in_chromium() {
    if !ready(
        "the player element test",
        &Needs {
            node_modules: &["tests/web/node_modules/playwright-core"],
            browser_and_songs: true,
        },
    ) {
        return;
    }
    // The sample page's own origin: a free port for player.mjs's page server, listed for CORS.
    // (A made-up host would not do: Chromium keeps pages on public origins from loopback servers.)
    let page_port = free_port();
    let mut app = spawn_app_with(|c| {
        c.models_dir = models_dir();
        c.cors_origins = vec![format!("http://127.0.0.1:{page_port}")];
    })
    .await;
    // The helpers send `token` as the bearer: the key's secret, so the dance is the key's tenant's.
    let key = api_key(&app, "player-page").await;
    app.token = Some(key.clone());
    let song = app.upload_ok(&helpers::short_song()).await;
    let song_id = song["id"].as_str().expect("song id").to_string();
    let first = app
        .dance(&serde_json::json!({"song_id": song_id, "model": "dance-revolution", "seed": 2}))
        .await;
    // A dance that travels: its first 4.8 s are the first dance's, carried 0.75 m/s along x
    // (3.6 m in all) as a seed motion that beat-graph keeps as given, so the camera must follow.
    let motion: serde_json::Value = app
        .get(&format!("/v1/jobs/{first}/motion.json"))
        .await
        .json()
        .await
        .expect("motion.json");
    let travelling: Vec<serde_json::Value> = motion["positions"]
        .as_array()
        .expect("positions")
        .iter()
        .take(TRAVEL_FRAMES)
        .enumerate()
        .map(|(f, frame)| {
            let dx = TRAVEL_M_S * f as f64 / 25.0;
            let joints: Vec<serde_json::Value> = frame
                .as_array()
                .expect("a frame")
                .iter()
                .map(|j| {
                    let p: Vec<f64> = j
                        .as_array()
                        .expect("a joint")
                        .iter()
                        .map(|v| v.as_f64().expect("a number"))
                        .collect();
                    serde_json::json!([p[0] + dx, p[1], p[2]])
                })
                .collect();
            serde_json::Value::Array(joints)
        })
        .collect();
    let job_id = app
        .dance(&serde_json::json!({
            "song_id": song_id, "model": "beat-graph", "seed": 2,
            "seed_motion": {"fps": 25.0, "positions": travelling},
        }))
        .await;
    let summary = run_player(&app, &job_id, &song_id, Some(&key), page_port, "web-player").await;
    let worst = summary["sync"]["worst_diff_s"]
        .as_f64()
        .expect("worst_diff_s");
    assert!(
        worst <= 1.0 / 25.0,
        "|audioTime − animationTime| reached {worst} s: {summary}"
    );
    assert!(
        summary["sync"]["audio_advanced_s"]
            .as_f64()
            .is_some_and(|s| s > 1.0),
        "{summary}"
    );
    let shot = std::fs::read(summary["screenshot"].as_str().expect("screenshot"))
        .expect("screenshot file");
    assert!(
        shot.starts_with(b"\x89PNG") && shot.len() > 10_000,
        "a real screenshot"
    );
    let travelled = summary["follow"]["travelled_m"]
        .as_f64()
        .expect("travelled_m");
    let off_centre = summary["follow"]["worst_off_centre"]
        .as_f64()
        .expect("worst_off_centre");
    assert!(
        travelled > 3.0,
        "the dance travelled {travelled} m: {summary}"
    );
    assert!(
        off_centre < 0.5,
        "after each seek the body centre is drawn within half the view of its middle: {summary}"
    );
    app.stop().await;
}

/// `<choreo-player>` without an api-key on an open service: the <audio> reads the song's URL
/// itself, so seeking in the song works only where the server answers Range requests; the
/// element seeks to 3 s and plays on from there (player.mjs checks it), in time with the dance.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_player_element_seeks_the_song_without_a_key_in_chromium() {
    if !ready(
        "the keyless player element test",
        &Needs {
            node_modules: &["tests/web/node_modules/playwright-core"],
            browser_and_songs: true,
        },
    ) {
        return;
    }
    let page_port = free_port();
    let app = spawn_app_with(|c| {
        c.models_dir = models_dir();
        c.cors_origins = vec![format!("http://127.0.0.1:{page_port}")];
    })
    .await;
    let song = app.upload_ok(&helpers::short_song()).await;
    let song_id = song["id"].as_str().expect("song id").to_string();
    let job_id = app
        .dance(&serde_json::json!({"song_id": song_id, "model": "dance-revolution", "seed": 2}))
        .await;
    let summary = run_player(
        &app,
        &job_id,
        &song_id,
        None,
        page_port,
        "web-player-keyless",
    )
    .await;
    assert_eq!(summary["audio_seek"]["keyed"], false, "{summary}");
    let heard = summary["audio_seek"]["heard"].as_f64().expect("heard");
    assert!(
        (2.95..4.0).contains(&heard),
        "the song played on from 3 s: {summary}"
    );
    let worst = summary["sync"]["worst_diff_s"]
        .as_f64()
        .expect("worst_diff_s");
    assert!(worst <= 1.0 / 25.0, "in time with the dance: {summary}");
    app.stop().await;
}

/// A free port on the loopback (for player.mjs's page server, listed for CORS).
fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port()
}

/// tests/web/player.mjs on `job_id`'s dance of `song_id`, its page served on `page_port`, with
/// `token` as the element's api-key (none: the element reads the server's URLs itself); its
/// screenshot goes under `out` in the test target's folder. Returns its summary.
async fn run_player(
    app: &TestApp,
    job_id: &str,
    song_id: &str,
    token: Option<&str>,
    page_port: u16,
    out: &str,
) -> serde_json::Value {
    let out = Path::new(env!("CARGO_TARGET_TMPDIR")).join(out);
    let mut env = vec![
        ("API_URL", format!("http://{}", app.addr)),
        ("JOB_ID", job_id.to_string()),
        ("SONG_ID", song_id.to_string()),
        ("PAGE_PORT", page_port.to_string()),
        ("OUT_DIR", out.display().to_string()),
        ("CHROMIUM", chromium().display().to_string()),
    ];
    if let Some(token) = token {
        env.push(("TOKEN", token.to_string()));
    }
    run_node(
        &root().join("tests/web/player.mjs"),
        &root().join("tests/web"),
        &env,
        Duration::from_secs(180),
    )
    .await
}

/// How long, and how fast along x, the player test's seed motion travels.
const TRAVEL_FRAMES: usize = 120;
const TRAVEL_M_S: f64 = 0.75;
