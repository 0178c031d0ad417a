//! Tracing set-up and metric names.
//!
//! Metrics go through the `metrics` facade into one process-wide Prometheus recorder, rendered
//! by `GET /metrics`. Names are constants here so the worker, the API and the tests agree.
use crate::config::LogFormat;
use crate::stage::Stage;
use metrics_exporter_prometheus::{Matcher, PrometheusBuilder, PrometheusHandle};
use std::sync::OnceLock;
use std::time::Instant;
use tracing_subscriber::EnvFilter;

/// Gauge: jobs by `status` label, refreshed from the database at each scrape.
pub const JOBS: &str = "choreo_jobs";
/// Gauge: jobs waiting to be claimed.
pub const QUEUE_DEPTH: &str = "choreo_queue_depth";
/// Gauge: workers running a job right now.
pub const BUSY_WORKERS: &str = "choreo_busy_workers";
/// Counter: jobs that reached a terminal state, by `kind` and `status`.
pub const JOBS_FINISHED: &str = "choreo_jobs_finished_total";
/// Histogram: wall time of one job attempt, seconds, by `kind`.
pub const JOB_DURATION: &str = "choreo_job_duration_seconds";
/// Histogram: wall time of one stage of a job, seconds, by `kind` and `stage`.
pub const STAGE_DURATION: &str = "choreo_stage_duration_seconds";
/// Counter: HTTP responses, by `status` class.
pub const HTTP_RESPONSES: &str = "choreo_http_responses_total";
/// Counter: connections refused because `max_connections` were open.
pub const CONNECTIONS_REFUSED: &str = "choreo_connections_refused_total";
/// Counter: failed accepts (out of file handles, most often).
pub const ACCEPT_ERRORS: &str = "choreo_accept_errors_total";
/// Counter: log lines that could not be written (a closed or full stderr) and were dropped.
pub const LOG_WRITE_ERRORS: &str = "choreo_log_write_errors_total";
/// Counter: workers restarted after dying.
pub const WORKER_RESTARTS: &str = "choreo_worker_restarts_total";
/// Counter: claims that failed because the store did not answer or could not write.
pub const CLAIM_ERRORS: &str = "choreo_claim_errors_total";

/// Buckets for job and stage durations: from 10 ms to 10 minutes.
const DURATION_BUCKETS: &[f64] = &[
    0.01, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0, 60.0, 120.0, 300.0, 600.0,
];

static PROMETHEUS: OnceLock<PrometheusHandle> = OnceLock::new();

/// Installs the process-wide Prometheus recorder once and returns its handle.
pub fn prometheus() -> PrometheusHandle {
    PROMETHEUS
        .get_or_init(|| {
            let builder = PrometheusBuilder::new()
                .set_buckets_for_metric(Matcher::Suffix("_seconds".into()), DURATION_BUCKETS)
                .expect("duration buckets are a non-empty constant");
            // Another recorder may already be installed (a library user's); then build ours
            // unregistered so `/metrics` still renders, just without facade-fed values.
            let recorder = builder.build_recorder();
            let handle = recorder.handle();
            if metrics::set_global_recorder(recorder).is_err() {
                tracing::warn!("a metrics recorder was already installed; /metrics will be sparse");
            }
            describe();
            handle
        })
        .clone()
}

fn describe() {
    metrics::describe_gauge!(JOBS, "Jobs by status");
    metrics::describe_gauge!(QUEUE_DEPTH, "Jobs waiting to be claimed");
    metrics::describe_gauge!(BUSY_WORKERS, "Workers running a job");
    metrics::describe_counter!(JOBS_FINISHED, "Jobs that reached a terminal state");
    metrics::describe_histogram!(
        JOB_DURATION,
        metrics::Unit::Seconds,
        "Wall time of one job attempt"
    );
    metrics::describe_histogram!(
        STAGE_DURATION,
        metrics::Unit::Seconds,
        "Wall time of one job stage"
    );
    metrics::describe_counter!(HTTP_RESPONSES, "HTTP responses by status class");
    metrics::describe_counter!(
        CONNECTIONS_REFUSED,
        "Connections refused at the max_connections cap"
    );
    metrics::describe_counter!(ACCEPT_ERRORS, "Failed accepts of HTTP connections");
    metrics::describe_counter!(
        LOG_WRITE_ERRORS,
        "Log lines dropped because the log sink failed"
    );
    metrics::describe_counter!(WORKER_RESTARTS, "Workers restarted after dying");
    metrics::describe_counter!(
        CLAIM_ERRORS,
        "Failed claims (store unreachable or unwritable)"
    );
}

/// Log output that cannot fail: a line that stderr does not take (a closed pipe, a full disk
/// behind a redirect) is dropped and counted in [`LOG_WRITE_ERRORS`], never a panic or an error
/// for the code that logged it. A log sink that fails must not stop the work it describes.
#[derive(Clone, Copy, Debug, Default)]
pub struct Stderr;

impl std::io::Write for Stderr {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if std::io::stderr().write_all(buf).is_err() {
            metrics::counter!(LOG_WRITE_ERRORS).increment(1);
        }
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        let _ = std::io::stderr().flush();
        Ok(())
    }
}

impl tracing_subscriber::fmt::MakeWriter<'_> for Stderr {
    type Writer = Stderr;

    fn make_writer(&self) -> Self::Writer {
        Stderr
    }
}

/// Third-party log targets the default filter silences. symphonia logs at ERROR what it then
/// returns as an error (`probe reach EOF` for a file that is not audio); choreo reports that
/// error itself (a 415, a failed job, the command line's message), so its line is a duplicate,
/// at the wrong level, in a colour and format of its own. `RUST_LOG` still turns it back on
/// (`RUST_LOG=info,symphonia=debug`).
pub const QUIET_LIBRARIES: &str = "symphonia=off";

/// The filter used when `RUST_LOG` is unset: `level`, with [`QUIET_LIBRARIES`] unless `level`
/// names one of them itself.
pub fn default_filter(level: &str) -> String {
    let mut filter = level.trim().to_string();
    for directive in QUIET_LIBRARIES.split(',') {
        let target = directive.split('=').next().unwrap_or(directive);
        if !filter.contains(target) {
            if !filter.is_empty() {
                filter.push(',');
            }
            filter.push_str(directive);
        }
    }
    filter
}

/// Whether log lines are coloured: only on a terminal (a file, a pipe or a log collector gets
/// plain text, not escape codes), and never with `NO_COLOR` set to anything but the empty
/// string (no-color.org).
pub fn colour(is_terminal: bool, no_color: Option<&std::ffi::OsStr>) -> bool {
    is_terminal && no_color.is_none_or(|v| v.is_empty())
}

/// The log format of the commands that load no configuration (`generate`, `train`):
/// `CHOREO_LOG_FORMAT`, read as the service reads it; anything but `json` is pretty.
pub fn env_log_format() -> LogFormat {
    match std::env::var("CHOREO_LOG_FORMAT") {
        Ok(v) if v.trim().eq_ignore_ascii_case("json") => LogFormat::Json,
        _ => LogFormat::Pretty,
    }
}

/// Starts the global tracing subscriber; a second call (tests) is a no-op. `default_level` is
/// the filter when `RUST_LOG` is unset (see [`default_filter`]).
pub fn init_tracing(format: LogFormat, default_level: &str) {
    use std::io::IsTerminal as _;
    let filter = EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| EnvFilter::new(default_filter(default_level)));
    let ansi = format == LogFormat::Pretty
        && colour(
            std::io::stderr().is_terminal(),
            std::env::var_os("NO_COLOR").as_deref(),
        );
    // log_internal_errors(false): tracing-subscriber would otherwise report a failed write with
    // eprintln!, which panics when stderr is closed.
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(Stderr)
        .with_ansi(ansi)
        .log_internal_errors(false);
    let _ = match format {
        LogFormat::Pretty => builder.try_init(),
        LogFormat::Json => builder.json().flatten_event(true).try_init(),
    };
}

/// Records how long a stage took when dropped, so early returns are timed too.
pub struct StageTimer {
    kind: &'static str,
    stage: Stage,
    start: Instant,
}

impl StageTimer {
    /// Starts timing `stage` of a job of `kind`.
    pub fn start(kind: &'static str, stage: Stage) -> Self {
        Self {
            kind,
            stage,
            start: Instant::now(),
        }
    }
}

impl Drop for StageTimer {
    fn drop(&mut self) {
        metrics::histogram!(STAGE_DURATION, "kind" => self.kind, "stage" => self.stage.as_str())
            .record(self.start.elapsed().as_secs_f64());
    }
}

/// The libtorch this binary was built against (`LIBTORCH` at build time).
const LIBTORCH_AT_BUILD: Option<&str> = option_env!("LIBTORCH");

/// The torch version of the wheel libtorch came from, read from its `version.py`.
fn torch_version() -> String {
    let Some(dir) = LIBTORCH_AT_BUILD else {
        return "unknown (LIBTORCH was not set at build time)".into();
    };
    let file = std::path::Path::new(dir).join("version.py");
    match std::fs::read_to_string(&file) {
        Ok(text) => text
            .lines()
            .find_map(|l| {
                l.strip_prefix("__version__ = ")
                    .map(|v| v.trim_matches(['\'', '"']).to_string())
            })
            .unwrap_or_else(|| format!("unknown (no __version__ in {})", file.display())),
        Err(e) => format!("unknown ({}: {e})", file.display()),
    }
}

/// The libtorch shared library this process actually loaded.
fn loaded_libtorch() -> String {
    std::fs::read_to_string("/proc/self/maps")
        .ok()
        .and_then(|maps| {
            maps.lines()
                .find(|l| l.contains("libtorch_cpu.so"))
                .and_then(|l| l.split_whitespace().last())
                .map(str::to_string)
        })
        .unwrap_or_else(|| "not mapped (or /proc unavailable)".into())
}

/// The API keys `choreo doctor` found in the configured database.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum KeysSeen {
    /// The SQLite file does not exist yet (so no key does either).
    NoDatabase,
    Counted {
        active: usize,
        revoked: usize,
    },
    /// The database could not be opened or read; why.
    Unreadable(String),
}

/// Whether `/v1` needs credentials, and which, by the rules of `api::auth`: any key ever made
/// (revoked ones count) closes the service; an `auth_token` does too, and keeps working beside
/// keys as the open tenant.
pub fn auth_line(token: bool, keys: &KeysSeen) -> String {
    let (active, revoked) = match keys {
        KeysSeen::Counted { active, revoked } => (*active, *revoked),
        KeysSeen::NoDatabase => (0, 0),
        KeysSeen::Unreadable(why) => {
            let token = if token {
                "on: the auth_token is required on /v1"
            } else {
                "no auth_token"
            };
            return format!("{token}; API keys unknown (the database: {why})");
        }
    };
    let counted = format!("API keys: {active} active, {revoked} revoked");
    match (active + revoked > 0, token) {
        (true, true) => {
            format!("on: an API key or the auth_token required on /v1 ({counted})")
        }
        (true, false) => format!("on: an API key required on /v1 ({counted})"),
        (false, true) => "on: the auth_token required on /v1 (no API keys)".into(),
        (false, false) => "off: the service is open (no API keys, no auth_token)".into(),
    }
}

/// What `choreo doctor` prints: libtorch, threads, data dir, models, auth. Runs a tensor op to
/// prove libtorch loads.
pub fn doctor(config: &crate::config::Config, keys: &KeysSeen) -> Vec<(&'static str, String)> {
    let sum = tch::Tensor::from_slice(&[1.0f32, 2.0, 3.0])
        .sum(tch::Kind::Float)
        .double_value(&[]);
    let models = match crate::models::Registry::load(&config.models_dir) {
        Ok(registry) => {
            let ids: Vec<String> = registry.list().into_iter().map(|m| m.id.0).collect();
            if ids.is_empty() {
                "none (train one first)".to_string()
            } else {
                ids.join(", ")
            }
        }
        Err(e) => format!("error: {e}"),
    };
    let env = |name: &str| std::env::var(name).unwrap_or_else(|_| "unset".into());
    let data_dir = match std::fs::metadata(&config.data_dir) {
        Ok(m) if m.is_dir() => format!("{} (exists)", config.data_dir.display()),
        Ok(_) => format!("{} (NOT A DIRECTORY)", config.data_dir.display()),
        Err(_) => format!("{} (will be created)", config.data_dir.display()),
    };
    vec![
        ("choreo", env!("CARGO_PKG_VERSION").to_string()),
        ("torch", torch_version()),
        (
            "libtorch built against",
            LIBTORCH_AT_BUILD.unwrap_or("unknown").to_string(),
        ),
        ("libtorch loaded", loaded_libtorch()),
        ("libtorch works", format!("sum([1, 2, 3]) = {sum}")),
        (
            "openmp / mkl / mkldnn",
            format!(
                "{} / {} / {}",
                tch::utils::has_openmp(),
                tch::utils::has_mkl(),
                tch::utils::has_mkldnn()
            ),
        ),
        (
            "intra-op threads (main thread)",
            tch::get_num_threads().to_string(),
        ),
        (
            "intra-op threads per worker",
            "1 (set on each worker thread)".to_string(),
        ),
        (
            "OMP_NUM_THREADS / OMP_WAIT_POLICY",
            format!("{} / {}", env("OMP_NUM_THREADS"), env("OMP_WAIT_POLICY")),
        ),
        (
            "cores",
            std::thread::available_parallelism()
                .map_or(0, |n| n.get())
                .to_string(),
        ),
        ("workers", config.worker_count().to_string()),
        ("bind", config.bind.clone()),
        ("data dir", data_dir),
        ("models dir", config.models_dir.display().to_string()),
        ("models found", models),
        ("auth", auth_line(config.auth_token.is_some(), keys)),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::ffi::OsStr;

    #[test]
    fn colour_only_on_a_terminal_without_no_color() {
        assert!(colour(true, None));
        assert!(colour(true, Some(OsStr::new(""))));
        assert!(!colour(true, Some(OsStr::new("1"))));
        assert!(!colour(false, None));
    }

    #[test]
    fn auth_is_on_once_a_key_or_a_token_exists() {
        let none = KeysSeen::Counted {
            active: 0,
            revoked: 0,
        };
        assert!(auth_line(false, &none).starts_with("off:"));
        assert!(auth_line(false, &KeysSeen::NoDatabase).starts_with("off:"));
        assert!(auth_line(true, &none).starts_with("on: the auth_token"));
        // A revoked key still closes the service (revoking the last key does not open it).
        let revoked = KeysSeen::Counted {
            active: 0,
            revoked: 1,
        };
        assert_eq!(
            auth_line(false, &revoked),
            "on: an API key required on /v1 (API keys: 0 active, 1 revoked)"
        );
        assert!(auth_line(true, &KeysSeen::Unreadable("x".into())).contains("unknown"));
    }

    #[test]
    fn the_default_filter_silences_symphonia_unless_asked_for() {
        assert_eq!(default_filter("info"), "info,symphonia=off");
        assert_eq!(default_filter(""), "symphonia=off");
        assert_eq!(
            default_filter("warn,symphonia=debug"),
            "warn,symphonia=debug"
        );
    }
}
