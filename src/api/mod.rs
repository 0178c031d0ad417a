//! HTTP API: routes, handlers, problem+json errors and the OpenAPI document.
//!
//! [`Server::start`] is the whole service: it opens the data dir and database, requeues the
//! jobs of a previous process whose leases expired, loads the models, starts the workers and
//! serves HTTP. Tests start it on port 0; `choreo serve` starts it on the configured address.
use crate::artifacts::ArtifactStore;
use crate::config::Config;
use crate::models::Registry;
use crate::queue::{DataDir, Store};
use crate::telemetry;
use axum::extract::Request;
use axum::http::{header, HeaderName, Method};
use axum::middleware::{self, Next};
use axum::response::Response;
use axum::routing::get;
use axum::Router;
use metrics_exporter_prometheus::PrometheusHandle;
use std::net::SocketAddr;
use std::sync::atomic::AtomicUsize;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::{Notify, Semaphore};
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;
use tower_http::cors::{AllowOrigin, CorsLayer};
use tower_http::request_id::{MakeRequestUuid, PropagateRequestIdLayer, SetRequestIdLayer};
use tower_http::timeout::RequestBodyTimeoutLayer;
use tower_http::trace::TraceLayer;
use utoipa_swagger_ui::SwaggerUi;

pub mod auth;
pub mod bench;
pub mod downloads;
pub mod events;
pub mod extract;
pub mod jobs;
pub mod listen;
pub mod multipart;
pub mod openapi;
pub mod paging;
pub mod problem;
pub mod ranges;
pub mod rigs;
pub mod song_audio;
pub mod songs;
pub mod system;
pub mod tenancy;
pub mod web;

pub use problem::ApiError;

/// The request-id header, set when the client sends none and echoed on the response.
pub const REQUEST_ID: HeaderName = HeaderName::from_static("x-request-id");
/// Room for multipart boundaries and headers above the file size limit.
const MULTIPART_OVERHEAD: u64 = 64 * 1024;
/// Longest `x-request-id` taken from a client; a longer one (or one with other than visible
/// ASCII) is replaced by a fresh id, since it is echoed and copied into every log line.
pub const MAX_REQUEST_ID_CHARS: usize = 128;

/// What every handler shares.
#[derive(Clone)]
pub struct AppState {
    pub store: Arc<dyn Store>,
    pub registry: Arc<Registry>,
    pub data: DataDir,
    /// Where songs and results are kept (the data dir, or a bucket).
    pub artifacts: Arc<dyn ArtifactStore>,
    pub config: Arc<Config>,
    /// Wakes idle workers when a job is registered.
    pub wake: Arc<Notify>,
    pub metrics: PrometheusHandle,
    /// Bounds concurrent upload decodes, so memory stays bounded under many uploads.
    pub decode_permits: Arc<Semaphore>,
    /// Workers of this process running right now (0 in an API-only process, or once they stop).
    pub workers_alive: Arc<AtomicUsize>,
    /// Whether this process runs workers (`false` under `choreo serve --no-workers`).
    pub runs_workers: bool,
    /// Cancelled when the server stops; in-flight upload decodes watch it and return.
    pub shutdown: CancellationToken,
    /// API keys as recently read, and each tenant's rate limit.
    pub tenancy: Arc<tenancy::Tenancy>,
}

/// Errors from starting the service.
#[derive(Debug, thiserror::Error)]
pub enum StartError {
    #[error("data dir {path}: {source}")]
    DataDir {
        path: String,
        source: std::io::Error,
    },
    #[error("binding {bind}: {source}")]
    Bind {
        bind: String,
        source: std::io::Error,
    },
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
    #[error(transparent)]
    Queue(#[from] crate::queue::QueueError),
    #[error("loading models: {0}")]
    Models(#[from] crate::models::ModelError),
    #[error(transparent)]
    Artifacts(#[from] crate::artifacts::ArtifactError),
}

impl StartError {
    /// Stable kebab-case name of the failure; a wrapped module error keeps its own code.
    pub fn code(&self) -> &'static str {
        match self {
            StartError::DataDir { .. } => "data-dir",
            StartError::Bind { .. } => "bind",
            StartError::Config(e) => e.code(),
            StartError::Queue(e) => e.code(),
            StartError::Models(_) => "models-load",
            StartError::Artifacts(e) => e.code(),
        }
    }
}

/// All routes, with auth on `/v1`, CORS, request ids and tracing.
pub fn router(state: AppState) -> Router {
    let v1 = Router::new()
        .route("/songs", get(songs::list).post(songs::upload))
        .route("/songs/{id}", get(songs::get).delete(songs::delete))
        .route("/songs/{id}/audio", get(song_audio::audio))
        .route("/rigs", get(rigs::list).post(rigs::upload))
        .route("/rigs/{id}", get(rigs::get).delete(rigs::delete))
        .route(
            "/jobs",
            get(jobs::list)
                .post(jobs::create)
                .layer(axum::extract::DefaultBodyLimit::max(
                    usize::try_from(state.config.max_job_body_bytes).unwrap_or(usize::MAX),
                )),
        )
        .route("/jobs/{id}", get(jobs::get).delete(jobs::cancel_or_delete))
        .route("/jobs/{id}/events", get(events::events))
        .route("/jobs/{id}/preview.png", get(jobs::preview))
        .route("/jobs/{id}/motion.bvh", get(downloads::motion_bvh))
        .route("/jobs/{id}/motion.glb", get(downloads::motion_glb))
        .route("/jobs/{id}/motion.vrma", get(downloads::motion_vrma))
        .route("/jobs/{id}/motion.smpl.npz", get(downloads::motion_smpl))
        .route("/jobs/{id}/{file}", get(jobs::result))
        .route("/models", get(system::models))
        .layer(axum::extract::DefaultBodyLimit::max(
            // Room to read and drop the rest of a refused upload (songs::read_form).
            usize::try_from(
                state.config.max_upload_bytes + MULTIPART_OVERHEAD + songs::DRAIN_LIMIT_BYTES,
            )
            .unwrap_or(usize::MAX),
        ))
        .route_layer(middleware::from_fn_with_state(
            state.clone(),
            auth::authenticate,
        ));

    let request_span = |req: &Request| {
        let id = req
            .headers()
            .get(REQUEST_ID)
            .and_then(|v| v.to_str().ok())
            .unwrap_or("-");
        tracing::info_span!("request", method = %req.method(), path = %req.uri().path(), request_id = %id)
    };
    Router::new()
        .nest("/v1", v1)
        .merge(web::routes())
        .route("/healthz", get(system::healthz))
        .route("/readyz", get(system::readyz))
        .route("/metrics", get(system::metrics))
        .merge(
            SwaggerUi::new("/docs")
                .external_url_unchecked("/openapi.json", openapi::spec().unwrap_or_default()),
        )
        .fallback(|| async { ApiError::NoRoute })
        .method_not_allowed_fallback(|| async { ApiError::MethodNotAllowed })
        .layer(middleware::from_fn(count_responses))
        .layer(cors(&state.config))
        .layer(PropagateRequestIdLayer::new(REQUEST_ID))
        .layer(TraceLayer::new_for_http().make_span_with(request_span))
        .layer(SetRequestIdLayer::new(REQUEST_ID, MakeRequestUuid))
        .layer(middleware::from_fn(cap_request_id))
        // The longest pause between two pieces of any request body.
        .layer(RequestBodyTimeoutLayer::new(Duration::from_secs_f64(
            state.config.body_timeout_s,
        )))
        .with_state(state)
}

fn cors(config: &Config) -> CorsLayer {
    let origins = if config.cors_origins.iter().any(|o| o == "*") {
        AllowOrigin::any()
    } else {
        AllowOrigin::list(config.cors_origins.iter().filter_map(|o| o.parse().ok()))
    };
    CorsLayer::new()
        .allow_origin(origins)
        .allow_methods([Method::GET, Method::POST, Method::DELETE])
        .allow_headers([
            header::AUTHORIZATION,
            header::CONTENT_TYPE,
            jobs::IDEMPOTENCY_KEY,
        ])
        .expose_headers([REQUEST_ID, header::LOCATION, jobs::IDEMPOTENT_REPLAYED])
        .max_age(Duration::from_secs(3600))
}

/// Drops a client's `x-request-id` that is too long or not visible ASCII, so a fresh one is made.
async fn cap_request_id(mut req: Request, next: Next) -> Response {
    let acceptable = |v: &axum::http::HeaderValue| {
        let bytes = v.as_bytes();
        !bytes.is_empty()
            && bytes.len() <= MAX_REQUEST_ID_CHARS
            && bytes.iter().all(|b| b.is_ascii_graphic())
    };
    if req
        .headers()
        .get_all(REQUEST_ID)
        .iter()
        .any(|v| !acceptable(v))
        || req.headers().get_all(REQUEST_ID).iter().count() > 1
    {
        req.headers_mut().remove(REQUEST_ID);
    }
    next.run(req).await
}

async fn count_responses(req: Request, next: Next) -> Response {
    let response = next.run(req).await;
    let class = match response.status().as_u16() {
        100..=199 => "1xx",
        200..=299 => "2xx",
        300..=399 => "3xx",
        400..=499 => "4xx",
        _ => "5xx",
    };
    metrics::counter!(telemetry::HTTP_RESPONSES, "class" => class).increment(1);
    response
}

/// The running service: HTTP server, workers and lease reaper.
pub struct Server {
    addr: SocketAddr,
    state: AppState,
    shutdown: CancellationToken,
    http: JoinHandle<std::io::Result<()>>,
    workers: Vec<JoinHandle<()>>,
    upkeep: JoinHandle<()>,
}

impl Server {
    /// Starts everything; `config.bind` may use port 0.
    pub async fn start(config: Config) -> Result<Self, StartError> {
        Self::launch(config, true).await
    }

    /// Starts the HTTP API without workers: `choreo worker` processes run the jobs.
    pub async fn start_api_only(config: Config) -> Result<Self, StartError> {
        Self::launch(config, false).await
    }

    async fn launch(config: Config, run_workers: bool) -> Result<Self, StartError> {
        let data_err = |source| StartError::DataDir {
            path: config.data_dir.display().to_string(),
            source,
        };
        let data = DataDir::create(&config.data_dir).map_err(data_err)?;
        let stale = data.clean_tmp().map_err(data_err)?;
        if stale > 0 {
            tracing::info!(
                files = stale,
                "removed uploads cut off by a previous process"
            );
        }
        let store: Arc<dyn Store> = crate::queue::open(
            &config.database()?,
            Duration::from_secs_f64(config.db_timeout_s),
        )
        .await?;
        let artifacts = crate::artifacts::open(&config, data.clone())?;
        let shutdown = CancellationToken::new();
        let registry = Arc::new(Registry::load(&config.models_dir)?);
        let workers = config.worker_count();
        tracing::info!(
            data_dir = %config.data_dir.display(),
            models = ?registry.list().iter().map(|m| m.id.0.clone()).collect::<Vec<_>>(),
            workers = if run_workers { workers } else { 0 },
            "starting"
        );

        let ctx = crate::worker::context(
            store.clone(),
            artifacts.clone(),
            registry.clone(),
            data.clone(),
            &config,
        );
        if run_workers {
            let recovered = crate::worker::recover(store.as_ref(), ctx.policy).await?;
            if recovered != crate::queue::Requeued::default() {
                tracing::warn!(
                    ?recovered,
                    "recovered jobs of a previous process whose leases had expired"
                );
            }
        }
        let metrics = telemetry::prometheus();
        let state = AppState {
            store,
            registry,
            data,
            artifacts,
            config: Arc::new(config.clone()),
            wake: ctx.wake.clone(),
            metrics: metrics.clone(),
            decode_permits: Arc::new(Semaphore::new(
                std::thread::available_parallelism().map_or(1, |n| n.get()),
            )),
            workers_alive: ctx.alive.clone(),
            runs_workers: run_workers,
            shutdown: shutdown.clone(),
            tenancy: Arc::default(),
        };

        let listener = tokio::net::TcpListener::bind(&config.bind)
            .await
            .map_err(|source| StartError::Bind {
                bind: config.bind.clone(),
                source,
            })?;
        let addr = listener.local_addr().map_err(|source| StartError::Bind {
            bind: config.bind.clone(),
            source,
        })?;

        // Stops with the server (`shutdown`); not awaited: a sweep holds nothing to finish.
        crate::artifacts::sweep::spawn(
            state.store.clone(),
            state.data.clone(),
            Duration::from_secs_f64(config.sweep_grace_s),
            shutdown.clone(),
        );
        let worker_handles = if run_workers {
            let retention = crate::artifacts::retention::spawn(
                state.store.clone(),
                state.artifacts.clone(),
                &config,
                shutdown.clone(),
            );
            let mut handles = crate::worker::start(ctx, workers, shutdown.clone());
            handles.extend(retention);
            // Webhooks are delivered on the worker side, with the workers.
            handles.extend(crate::webhooks::spawn(
                state.store.clone(),
                &config,
                shutdown.clone(),
            ));
            handles
        } else {
            Vec::new()
        };
        let upkeep = tokio::spawn({
            let shutdown = shutdown.clone();
            async move {
                // Histograms are drained into their buckets only at upkeep.
                loop {
                    tokio::select! {
                        _ = shutdown.cancelled() => return,
                        _ = tokio::time::sleep(Duration::from_secs(5)) => metrics.run_upkeep(),
                    }
                }
            }
        });
        let app = router(state.clone());
        let limits = listen::Limits::new(&config);
        let http = tokio::spawn(listen::serve(listener, app, limits, shutdown.clone()));
        tracing::info!(%addr, max_connections = limits.max_connections, "listening");
        Ok(Self {
            addr,
            state,
            shutdown,
            http,
            workers: worker_handles,
            upkeep,
        })
    }

    /// The address actually bound (resolves port 0).
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// The shared state (store, data dir), for tools and tests that inspect the service.
    pub fn state(&self) -> &AppState {
        &self.state
    }

    /// Stops taking requests and jobs; running jobs stop at their next checkpoint and are requeued.
    pub async fn stop(self) {
        self.shutdown.cancel();
        match self.http.await {
            Ok(Ok(())) => {}
            Ok(Err(e)) => tracing::error!(error = %e, "http server ended with an error"),
            Err(e) => tracing::error!(error = %e, "http server task failed"),
        }
        for worker in self.workers {
            if let Err(e) = worker.await {
                tracing::error!(error = %e, "worker task failed");
            }
        }
        if let Err(e) = self.upkeep.await {
            tracing::error!(error = %e, "metrics upkeep task failed");
        }
    }
}
