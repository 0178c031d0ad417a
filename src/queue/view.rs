//! A job as its clients see it: the body of `GET /v1/jobs/{id}` and of every webhook delivery.
//!
//! One wire type for both, so a webhook's body is the API's own view of the job by
//! construction. It sits with the job it shows, below the API and the webhooks that send it.
use chrono::{DateTime, Utc};
use serde::Serialize;

use super::{Job, JobId, JobKind, SongId, Status};

/// Where to find a job and its results.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct Links {
    #[serde(rename = "self")]
    pub self_: String,
    pub song: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub motion_bvh: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub motion_json: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub motion_glb: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub report: Option<String>,
    /// The contact sheet: stick figures over the floor, speed and foot height over time (PNG).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub preview: Option<String>,
}

/// A job as the API shows it.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct JobView {
    pub id: JobId,
    /// `analyze` or `generate`.
    pub kind: String,
    pub song_id: SongId,
    pub model: Option<String>,
    pub seed: Option<u64>,
    /// The style danced, once a generate job of a model that dances one has succeeded: the one
    /// asked for, or the one its classifier predicted from the song (`predicted: true`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub style: Option<crate::models::StyleChoice>,
    pub status: Status,
    /// What the job is doing now: one kind of work (`decode-audio`, `analyze`, `features`, `encode`,
    /// `generate`, `beat-align`, `export`), or `claimed` / `done` as the queue marks it.
    pub stage: Option<crate::stage::Stage>,
    /// 0..=1.
    pub progress: f64,
    pub priority: i64,
    pub attempts: u32,
    pub max_attempts: u32,
    /// A cancel was asked for; a running job stops at its next checkpoint.
    pub cancel_requested: bool,
    /// The last error.
    pub error: Option<String>,
    pub created_at: DateTime<Utc>,
    pub started_at: Option<DateTime<Utc>>,
    pub finished_at: Option<DateTime<Utc>>,
    /// Where the job is POSTed when it ends (generate jobs submitted with one).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub webhook_url: Option<String>,
    pub links: Links,
}

impl From<Job> for JobView {
    fn from(job: Job) -> Self {
        let base = format!("/v1/jobs/{}", job.id);
        let file =
            |name: &str| matches!(job.kind, JobKind::Generate(_)).then(|| format!("{base}/{name}"));
        let links = Links {
            song: format!("/v1/songs/{}", job.kind.song_id()),
            motion_bvh: file("motion.bvh"),
            motion_json: file("motion.json"),
            motion_glb: file("motion.glb"),
            report: file("report.json"),
            preview: file("preview.png"),
            self_: base.clone(),
        };
        let (model, seed, webhook_url) = match &job.kind {
            JobKind::Analyze { .. } => (None, None, None),
            JobKind::Generate(options) => (
                Some(options.model.0.clone()),
                Some(options.seed),
                options.webhook_url.clone(),
            ),
        };
        JobView {
            id: job.id,
            kind: job.kind.name().to_string(),
            song_id: job.kind.song_id(),
            model,
            seed,
            style: job.files.style.clone(),
            status: job.status,
            stage: job.stage,
            progress: job.progress,
            priority: job.priority,
            attempts: job.attempts,
            max_attempts: job.max_attempts,
            cancel_requested: job.cancel_requested,
            error: job.error,
            created_at: job.created_at,
            started_at: job.started_at,
            finished_at: job.finished_at,
            webhook_url,
            links,
        }
    }
}
