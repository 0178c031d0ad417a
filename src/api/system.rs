//! Health, readiness, Prometheus metrics and the model list.
use super::problem::{ApiError, Problem};
use super::AppState;
use crate::models::ModelInfo;
use crate::queue::Status;
use crate::telemetry;
use axum::extract::State;
use axum::http::header;
use axum::response::IntoResponse;
use axum::Json;
use serde::Serialize;
use std::sync::atomic::Ordering;

/// A health or readiness answer.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct Health {
    /// `ok` or `ready`.
    pub status: String,
}

/// The process is up.
#[utoipa::path(get, path = "/healthz", operation_id = "healthz", tag = "system", responses((status = 200, body = Health)))]
pub async fn healthz() -> Json<Health> {
    Json(Health {
        status: "ok".into(),
    })
}

/// The database answers (within `db_timeout_s`) and at least one worker runs.
#[utoipa::path(
    get,
    path = "/readyz",
    operation_id = "readyz",
    tag = "system",
    responses(
        (status = 200, body = Health),
        (status = 503, description = "Not ready", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn readyz(State(state): State<AppState>) -> Result<Json<Health>, ApiError> {
    // An API-only process (`serve --no-workers`) is ready when its database answers.
    if state.runs_workers && state.workers_alive.load(Ordering::SeqCst) == 0 {
        return Err(ApiError::NotReady("no worker is running".into()));
    }
    let limit = std::time::Duration::from_secs_f64(state.config.db_timeout_s);
    match tokio::time::timeout(limit, state.store.ping()).await {
        Ok(Ok(())) => Ok(Json(Health {
            status: "ready".into(),
        })),
        Ok(Err(e)) => Err(ApiError::NotReady(format!("database: {e}"))),
        Err(_) => Err(ApiError::NotReady(format!(
            "the database did not answer within {} s",
            state.config.db_timeout_s
        ))),
    }
}

/// Prometheus text: jobs by status, queue depth, busy workers, job and stage durations.
#[utoipa::path(get, path = "/metrics", operation_id = "metrics", tag = "system", responses((status = 200, description = "Prometheus text format", content_type = "text/plain")))]
pub async fn metrics(State(state): State<AppState>) -> Result<impl IntoResponse, ApiError> {
    // Counts come from the database at scrape time, so they are right across restarts.
    let counts = state.store.counts().await?;
    for (status, n) in &counts {
        metrics::gauge!(telemetry::JOBS, "status" => status.as_str()).set(*n as f64);
        if *status == Status::Queued {
            metrics::gauge!(telemetry::QUEUE_DEPTH).set(*n as f64);
        }
    }
    Ok((
        [(
            header::CONTENT_TYPE,
            "text/plain; version=0.0.4; charset=utf-8",
        )],
        state.metrics.render(),
    ))
}

/// The models this server can dance with.
#[utoipa::path(get, path = "/v1/models", operation_id = "listModels", tag = "models", responses((status = 200, body = [ModelInfo])), security(("bearer" = [])))]
pub async fn models(State(state): State<AppState>) -> Json<Vec<ModelInfo>> {
    Json(state.registry.list())
}
