//! Webhooks: when a job that carries a `webhook_url` ends (succeeded, failed or cancelled), the
//! job, as `GET /v1/jobs/{id}` returns it, is POSTed there, signed per Standard Webhooks.
//!
//! The life of a delivery:
//! 1. `POST /v1/jobs` checks the URL ([`accept_url`]: http(s), every address of its host global
//!    unless `webhook_allowed_hosts` lists its `host:port`, see [`guard`]) and stores it in the
//!    job's options. Without a `webhook_secret` the server cannot sign, so it refuses the URL.
//! 2. When the job turns terminal, a trigger on the job row puts a `webhooks` row in the same
//!    transaction (migration `20261127000200_events.sql`): a delivery is never lost to a crash.
//! 3. On the worker side (every process that runs workers: `choreo serve`, `choreo worker`),
//!    [`spawn`]'s loop takes due rows ([`crate::queue::EventStore::take_webhook`]), checks the URL
//!    again (DNS may have changed), connects to exactly the addresses it checked, never follows
//!    a redirect, and logs the attempt in `webhook_deliveries`. A 2xx answer delivers it;
//!    anything else is retried after `webhook_backoff_s`, doubling, until `webhook_retry_s`
//!    after the job ended. A process that stops or dies mid-attempt leaves the row to the next.
//!
//! Headers: `webhook-id` (the job id; the same on every retry, so a receiver can drop
//! duplicates), `webhook-timestamp` (Unix seconds of this attempt), `webhook-signature`
//! (`v1,<base64 HMAC-SHA256 of "{id}.{timestamp}.{body}">`, see [`sign`]).
//!
//! The body is the API's own view of the job ([`crate::queue::view::JobView`], which the API
//! returns too).
use crate::config::Config;
use crate::queue::events::{WebhookAttempt, WebhookDue, WebhookNext};
use crate::queue::view::JobView;
use crate::queue::{QueueError, Scope, Store};
use chrono::Utc;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::Semaphore;
use tokio::task::{JoinHandle, JoinSet};
use tokio_util::sync::CancellationToken;

pub mod guard;
pub mod sign;

pub use sign::SigningKey;

/// Longest one delivery attempt may take, connection included.
pub const REQUEST_TIMEOUT: Duration = Duration::from_secs(10);
/// How long a taken delivery is held from other workers: past one attempt, its DNS lookup and
/// the write of its log line.
const HOLD: Duration = Duration::from_secs(30);
/// The longest pause between retries.
const MAX_BACKOFF: Duration = Duration::from_secs(3600);
/// Deliveries attempted at once by one process.
const CONCURRENT: usize = 8;
/// The longest error text kept in an attempt's log line.
const MAX_LOGGED_ERROR: usize = 500;

/// Why a submitted `webhook_url` is not taken.
#[derive(Debug, thiserror::Error)]
pub enum Submission {
    #[error("the server has no webhook_secret")]
    NotConfigured,
    #[error(transparent)]
    Refused(#[from] guard::Refused),
}

impl Submission {
    /// Stable kebab-case name of the failure.
    pub fn code(&self) -> &'static str {
        match self {
            Submission::NotConfigured => "webhooks-not-configured",
            Submission::Refused(_) => "webhook-url-refused",
        }
    }
}

/// Checks a submitted `webhook_url`; returns it as it is stored.
pub async fn accept_url(config: &Config, url: &str) -> Result<String, Submission> {
    if config.webhook_secret.is_none() {
        return Err(Submission::NotConfigured);
    }
    let target = guard::check(url, &config.webhook_allowed_hosts).await?;
    Ok(target.url.to_string())
}

/// What the delivery loop needs from the configuration.
#[derive(Clone, Debug)]
pub struct Deliverer {
    key: SigningKey,
    allowed: Vec<String>,
    retry: Duration,
    backoff: Duration,
    poll: Duration,
}

impl Deliverer {
    /// `None` when the configuration has no (valid) `webhook_secret`: nothing can be signed.
    pub fn from_config(config: &Config) -> Option<Self> {
        let key = config.webhook_key().ok().flatten()?;
        Some(Self {
            key: SigningKey::new(key),
            allowed: config.webhook_allowed_hosts.clone(),
            retry: Duration::from_secs_f64(config.webhook_retry_s),
            backoff: Duration::from_secs_f64(config.webhook_backoff_s),
            poll: Duration::from_secs_f64(config.poll_s),
        })
    }

    /// The pause after failed attempt `attempt` (from 1).
    fn backoff(&self, attempt: u32) -> Duration {
        let doublings = attempt.saturating_sub(1).min(16);
        self.backoff.saturating_mul(1 << doublings).min(MAX_BACKOFF)
    }
}

/// Starts the delivery loop when webhooks are configured; it stops with `shutdown`.
pub fn spawn(
    store: Arc<dyn Store>,
    config: &Config,
    shutdown: CancellationToken,
) -> Option<JoinHandle<()>> {
    let deliverer = Deliverer::from_config(config)?;
    Some(tokio::spawn(run(store, deliverer, shutdown)))
}

async fn run(store: Arc<dyn Store>, deliverer: Deliverer, shutdown: CancellationToken) {
    let deliverer = Arc::new(deliverer);
    // Several at once, so one slow receiver does not hold up everyone else's deliveries.
    let permits = Arc::new(Semaphore::new(CONCURRENT));
    let mut running = JoinSet::new();
    loop {
        while running.try_join_next().is_some() {}
        let permit = tokio::select! {
            _ = shutdown.cancelled() => break,
            permit = permits.clone().acquire_owned() => match permit {
                Ok(permit) => permit,
                Err(_) => break,
            },
        };
        let pause = match store.take_webhook(HOLD).await {
            Ok(Some(due)) => {
                let (store, deliverer, shutdown) =
                    (store.clone(), deliverer.clone(), shutdown.clone());
                running.spawn(async move {
                    let _permit = permit;
                    if let Err(e) = attempt(store.as_ref(), &deliverer, due, &shutdown).await {
                        tracing::error!(error = %e, "logging a webhook attempt failed; it is retried once its hold lapses");
                    }
                });
                continue;
            }
            Ok(None) => deliverer.poll,
            Err(e) => {
                tracing::warn!(error = %e, "looking for due webhooks failed; trying again");
                deliverer.poll.max(Duration::from_secs(1))
            }
        };
        drop(permit);
        tokio::select! {
            _ = shutdown.cancelled() => break,
            _ = tokio::time::sleep(pause) => {}
        }
    }
    // Attempts in flight see the shutdown too, and log themselves as cut off.
    while running.join_next().await.is_some() {}
}

/// One attempt at `due`, logged with what becomes of it.
#[tracing::instrument(skip_all, fields(job_id = %due.job_id, attempt = due.attempt))]
async fn attempt(
    store: &dyn Store,
    deliverer: &Deliverer,
    due: WebhookDue,
    shutdown: &CancellationToken,
) -> Result<(), QueueError> {
    let sent = tokio::select! {
        sent = send(store, deliverer, &due) => sent,
        // The attempt is logged as cut off and handed to the next process at once.
        _ = shutdown.cancelled() => Sent::Stopped,
    };
    let (status_code, error) = match &sent {
        Sent::Answered(code) if (200..300).contains(code) => (Some(*code), None),
        Sent::Answered(code) => (Some(*code), Some(format!("the receiver answered {code}"))),
        Sent::Failed(e) => (None, Some(e.clone())),
        Sent::JobGone => (None, Some("the job no longer exists".to_string())),
        Sent::Stopped => (
            None,
            Some("the server stopped during the attempt".to_string()),
        ),
    };
    let now = Utc::now();
    let next = match sent {
        Sent::Answered(code) if (200..300).contains(&code) => WebhookNext::Delivered,
        Sent::JobGone => WebhookNext::GiveUp,
        Sent::Stopped => WebhookNext::RetryAt(now),
        Sent::Answered(_) | Sent::Failed(_) => {
            let at = now + deliverer.backoff(due.attempt);
            let deadline = due.created_at + deliverer.retry;
            if at > deadline {
                WebhookNext::GiveUp
            } else {
                WebhookNext::RetryAt(at)
            }
        }
    };
    match (&next, &error) {
        (WebhookNext::Delivered, _) => tracing::info!(status = ?status_code, "webhook delivered"),
        (WebhookNext::GiveUp, error) => {
            tracing::warn!(?error, "webhook given up after its last attempt")
        }
        (WebhookNext::RetryAt(at), error) => {
            tracing::info!(?error, retry_at = %at, "webhook attempt failed; retrying")
        }
    }
    store
        .webhook_attempted(
            WebhookAttempt {
                job_id: due.job_id,
                attempt: due.attempt,
                status_code,
                error: error.map(|mut e| {
                    e.truncate(e.floor_char_boundary(MAX_LOGGED_ERROR));
                    e
                }),
                at: now,
            },
            next,
        )
        .await
}

/// How an attempt went.
enum Sent {
    Answered(u16),
    Failed(String),
    JobGone,
    Stopped,
}

async fn send(store: &dyn Store, deliverer: &Deliverer, due: &WebhookDue) -> Sent {
    let job = match store.job(Scope::Tenant(due.tenant), due.job_id).await {
        Ok(job) => job,
        Err(QueueError::JobNotFound(_)) => return Sent::JobGone,
        Err(e) => return Sent::Failed(format!("reading the job: {e}")),
    };
    let body = match serde_json::to_vec(&JobView::from(job)) {
        Ok(body) => body,
        Err(e) => return Sent::Failed(format!("serialising the job: {e}")),
    };
    // Checked again: the name may point elsewhere than at submission.
    let target = match guard::check(&due.url, &deliverer.allowed).await {
        Ok(target) => target,
        Err(e) => return Sent::Failed(format!("the URL is refused now: {e}")),
    };
    let client = match reqwest::Client::builder()
        .redirect(reqwest::redirect::Policy::none())
        .timeout(REQUEST_TIMEOUT)
        .no_proxy()
        // Connect to the addresses just checked, not to a second lookup's answer.
        .resolve_to_addrs(&target.host, &target.addrs)
        .user_agent(concat!("choreo/", env!("CARGO_PKG_VERSION"), " webhooks"))
        .build()
    {
        Ok(client) => client,
        Err(e) => return Sent::Failed(format!("building the HTTP client: {e}")),
    };
    let id = due.job_id.to_string();
    let timestamp = Utc::now().timestamp();
    let signature = deliverer.key.sign(&id, timestamp, &body);
    let response = client
        .post(target.url)
        .header(reqwest::header::CONTENT_TYPE, "application/json")
        .header("webhook-id", &id)
        .header("webhook-timestamp", timestamp.to_string())
        .header("webhook-signature", signature)
        .body(body)
        .send()
        .await;
    match response {
        // The answer's body is not read: only its status counts.
        Ok(response) => Sent::Answered(response.status().as_u16()),
        Err(e) => Sent::Failed(error_chain(&e)),
    }
}

/// An error and its sources on one line (reqwest's own Display says only "error sending request").
fn error_chain(e: &dyn std::error::Error) -> String {
    let mut text = e.to_string();
    let mut source = e.source();
    while let Some(s) = source {
        text.push_str(": ");
        text.push_str(&s.to_string());
        source = s.source();
    }
    text
}
