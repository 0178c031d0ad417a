//! Workers: claim jobs, run them on blocking threads, heartbeat, report progress.
//!
//! Each of the N workers is a tokio task that loops: claim a job (one atomic statement), run
//! its [`Execute`] on a blocking thread with one libtorch intra-op thread, and write the outcome
//! back. While the job runs, a heartbeat task extends the lease, copies stage and progress to
//! the job row, and reads back `cancel_requested`; the job sees that flag at its next
//! [`Progress::report`] checkpoint. A panic inside a job fails that job and the worker goes on;
//! a worker that dies anyway (a panic outside a job) is restarted after a pause, and
//! [`Context::alive`] counts the workers running, for `/readyz`. While the store fails (full
//! disk, database down) a worker waits longer between claims, up to [`MAX_CLAIM_BACKOFF`], and
//! goes back to its normal pace at the first claim that works.
use crate::artifacts::{Artifact, ArtifactStore};
use crate::models::{Cancelled, Progress, Registry};
use crate::queue::{
    Beat, DataDir, Job, JobStore, LeasePolicy, Outcome, QueueError, Scope, Song, Store,
};
use crate::stage::Stage;
use crate::telemetry;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::sync::Notify;
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;
use tracing::Instrument;

mod error;
pub mod pipeline;
pub mod process;
pub mod serve;
pub mod standalone;

pub use error::WorkerError;
pub use pipeline::Pipeline;

/// Runs one job's work on a blocking thread. The service uses [`Pipeline`].
pub trait Execute: Send + Sync + 'static {
    /// Does the work of `job` on `song`, reporting through `progress`.
    fn execute(
        &self,
        job: &Job,
        song: &Song,
        progress: &mut dyn Progress,
    ) -> Result<Outcome, WorkerError>;
}

/// What every worker shares.
#[derive(Clone)]
pub struct Context {
    pub store: Arc<dyn Store>,
    /// Songs are fetched from it before a job runs; results are published to it after.
    pub artifacts: Arc<dyn ArtifactStore>,
    pub executor: Arc<dyn Execute>,
    pub policy: LeasePolicy,
    /// How often a running job heartbeats and flushes progress.
    pub heartbeat: Duration,
    /// How often an idle worker looks for work when not woken.
    pub poll: Duration,
    /// Woken when a job is registered, so idle workers claim it at once.
    pub wake: Arc<Notify>,
    /// Workers running right now (a dead one is restarted after a pause).
    pub alive: Arc<AtomicUsize>,
    /// The data dir's root, taken out of error messages stored on jobs.
    pub data_root: std::path::PathBuf,
}

/// The longest a worker waits between claims while the store keeps failing.
pub const MAX_CLAIM_BACKOFF: Duration = Duration::from_secs(5);
/// The first pause before a dead worker is restarted; it doubles with each death in a row.
const RESTART_PAUSE: Duration = Duration::from_millis(100);
/// The longest pause before a restart.
const MAX_RESTART_PAUSE: Duration = Duration::from_secs(5);
/// A worker that ran this long before dying starts its pauses over.
const HEALTHY_RUN: Duration = Duration::from_secs(60);

/// Counts one running worker while it lives; dropped on return or while a panic unwinds.
struct Alive(Arc<AtomicUsize>);

impl Alive {
    fn new(count: &Arc<AtomicUsize>) -> Self {
        count.fetch_add(1, Ordering::SeqCst);
        Self(count.clone())
    }
}

impl Drop for Alive {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::SeqCst);
    }
}

/// The live state of one running job, shared by its blocking thread and its heartbeat task.
#[derive(Debug, Default)]
struct JobState {
    /// The stage last reported (none yet: the job is as the queue claimed it) and the progress.
    stage_progress: Mutex<(Option<Stage>, f64)>,
    /// Stages entered since the last heartbeat, with the progress then: each is written on its
    /// own, so the job's event stream shows every stage however short (`api::events`).
    entered: Mutex<Vec<(Stage, f64)>>,
    /// Wakes the heartbeat task when a stage is entered, so it is written at once.
    stage_changed: tokio::sync::Notify,
    cancel: AtomicBool,
    lease_lost: AtomicBool,
}

impl JobState {
    fn snapshot(&self) -> (Option<Stage>, f64) {
        match self.stage_progress.lock() {
            Ok(guard) => *guard,
            Err(poisoned) => *poisoned.into_inner(),
        }
    }
}

/// The worker's [`Progress`]: records stage and overall progress, answers cancellation.
pub struct JobProgress {
    state: Arc<JobState>,
}

impl Progress for JobProgress {
    fn report(&mut self, stage: Stage, fraction: f32) -> Result<(), Cancelled> {
        {
            let mut guard = match self.state.stage_progress.lock() {
                Ok(guard) => guard,
                Err(poisoned) => poisoned.into_inner(),
            };
            let entered = guard.0 != Some(stage);
            guard.0 = Some(stage);
            // Stages report their own 0..1; the job's progress never goes backwards.
            let fraction = f64::from(fraction);
            if fraction.is_finite() {
                guard.1 = guard.1.max(fraction.clamp(0.0, 1.0));
            }
            if entered {
                let progress = guard.1;
                drop(guard);
                match self.state.entered.lock() {
                    Ok(mut e) => e.push((stage, progress)),
                    Err(poisoned) => poisoned.into_inner().push((stage, progress)),
                }
                self.state.stage_changed.notify_one();
            }
        }
        if self.state.cancel.load(Ordering::Relaxed) {
            Err(Cancelled)
        } else {
            Ok(())
        }
    }
}

/// A unique name for this process's workers, stored as the lease owner.
fn owner_prefix() -> String {
    format!(
        "{}-{}",
        std::process::id(),
        &uuid::Uuid::now_v7().simple().to_string()[24..]
    )
}

/// Starts `count` workers, the lease reaper and the store's wake-ups (jobs queued by other
/// processes); they stop when `shutdown` is cancelled.
pub fn start(ctx: Context, count: usize, shutdown: CancellationToken) -> Vec<JoinHandle<()>> {
    let prefix = owner_prefix();
    let mut handles: Vec<JoinHandle<()>> = (0..count)
        .map(|n| {
            let owner = format!("{prefix}-w{n}");
            tokio::spawn(supervise(ctx.clone(), owner, shutdown.clone()))
        })
        .collect();
    handles.push(tokio::spawn(watch(ctx.clone(), shutdown.clone())));
    handles.push(tokio::spawn(reaper(ctx, shutdown)));
    handles
}

/// Wakes idle workers when another process queues a job (PostgreSQL's `LISTEN`).
async fn watch(ctx: Context, shutdown: CancellationToken) {
    if let Err(e) = ctx.store.watch(ctx.wake.clone(), shutdown).await {
        tracing::error!(error = %e, "job notifications stopped; idle workers find new jobs by polling");
    }
}

/// Requeues jobs whose lease expired (their worker died), every half lease.
async fn reaper(ctx: Context, shutdown: CancellationToken) {
    let every = (ctx.policy.lease / 2).max(Duration::from_millis(100));
    loop {
        tokio::select! {
            _ = shutdown.cancelled() => return,
            _ = tokio::time::sleep(every) => {}
        }
        match ctx.store.requeue_expired(ctx.policy).await {
            Ok(done) => {
                if !done.requeued.is_empty() {
                    tracing::warn!(jobs = ?done.requeued, "requeued jobs whose lease expired");
                    ctx.wake.notify_waiters();
                }
                if !done.failed.is_empty() {
                    tracing::warn!(jobs = ?done.failed, "failed jobs whose lease expired on their last attempt");
                }
            }
            Err(e) => {
                tracing::error!(error = %e, "requeueing expired leases failed; retrying next round")
            }
        }
    }
}

/// Runs one worker, and runs it again, after a growing pause, whenever it dies.
async fn supervise(ctx: Context, owner: String, shutdown: CancellationToken) {
    let mut pause = RESTART_PAUSE;
    loop {
        let span = tracing::info_span!("worker", worker = %owner);
        let started = Instant::now();
        let run = tokio::spawn(
            worker_loop(ctx.clone(), owner.clone(), shutdown.clone()).instrument(span),
        )
        .await;
        let Err(death) = run else { return };
        metrics::counter!(telemetry::WORKER_RESTARTS).increment(1);
        if shutdown.is_cancelled() {
            return;
        }
        if started.elapsed() > HEALTHY_RUN {
            pause = RESTART_PAUSE;
        }
        tracing::error!(worker = %owner, error = %death, pause_s = pause.as_secs_f64(), "worker died; restarting it");
        tokio::select! {
            _ = shutdown.cancelled() => return,
            _ = tokio::time::sleep(pause) => {}
        }
        pause = (pause * 2).min(MAX_RESTART_PAUSE);
    }
}

async fn worker_loop(ctx: Context, owner: String, shutdown: CancellationToken) {
    let _alive = Alive::new(&ctx.alive);
    tracing::debug!("worker started");
    let mut backoff = ctx.poll;
    while !shutdown.is_cancelled() {
        // Register interest before claiming, so a job registered in between still wakes us.
        let woken = ctx.wake.notified();
        let claimed = ctx.store.claim(&owner, ctx.policy).await;
        if claimed.is_ok() {
            backoff = ctx.poll;
        }
        match claimed {
            Ok(Some(job)) => {
                let span = tracing::info_span!("job", job_id = %job.id, kind = job.kind.name(), attempt = job.attempts);
                run_job(&ctx, &owner, job, &shutdown).instrument(span).await;
            }
            Ok(None) => {
                tokio::select! {
                    _ = shutdown.cancelled() => {}
                    _ = woken => {}
                    _ = tokio::time::sleep(ctx.poll) => {}
                }
            }
            Err(e) => {
                // The store cannot take the claim (full disk, database down): wait longer each
                // time rather than hammer it; the first claim that works resets the pace.
                metrics::counter!(telemetry::CLAIM_ERRORS).increment(1);
                tracing::error!(error = %e, retry_in_s = backoff.as_secs_f64(), "claiming a job failed; backing off");
                tokio::select! {
                    _ = shutdown.cancelled() => {}
                    _ = tokio::time::sleep(backoff) => {}
                }
                backoff = (backoff * 2).min(MAX_CLAIM_BACKOFF.max(ctx.poll));
            }
        }
    }
    tracing::debug!("worker stopped");
}

/// Niceness of job threads: model work yields the cores to the HTTP server, so API latency
/// stays low while every worker is busy.
const JOB_NICE: i32 = 10;

/// Lowers the calling thread's scheduling priority (Linux sets niceness per thread).
fn lower_priority() {
    #[cfg(target_os = "linux")]
    {
        // SAFETY: gettid has no preconditions; setpriority only reads its arguments.
        let rc = unsafe {
            libc::setpriority(libc::PRIO_PROCESS, libc::gettid() as libc::id_t, JOB_NICE)
        };
        if rc != 0 {
            tracing::debug!(error = %std::io::Error::last_os_error(), "could not lower the job thread's priority");
        }
    }
}

fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "a panic without a message".to_string()
    }
}

async fn run_job(ctx: &Context, owner: &str, job: Job, shutdown: &CancellationToken) {
    let started = Instant::now();
    let kind = job.kind.name();
    metrics::gauge!(telemetry::BUSY_WORKERS).increment(1.0);
    tracing::info!("job started");

    let state = Arc::new(JobState::default());
    let done = CancellationToken::new();
    let heartbeat = tokio::spawn(heartbeat_loop(
        ctx.clone(),
        owner.to_string(),
        job.id,
        state.clone(),
        done.clone(),
        shutdown.clone(),
    ));

    let song = match ctx.store.song(Scope::All, job.kind.song_id()).await {
        Err(e) => Err(WorkerError::Queue(e)),
        // The song in the local data dir, where the pipeline reads it (a bucket's is fetched).
        Ok(song) => ctx
            .artifacts
            .fetch(Artifact::Song(song.id, song.format))
            .await
            .map(|_| song)
            .map_err(WorkerError::from),
    };
    let result = match song {
        Err(e) => Err(e),
        Ok(song) => {
            let executor = ctx.executor.clone();
            let mut progress = JobProgress {
                state: state.clone(),
            };
            let job = job.clone();
            let (done_tx, done_rx) = tokio::sync::oneshot::channel();
            // A thread of its own per job, so its settings (threads, priority) touch no other work.
            let spawned = std::thread::Builder::new()
                .name(format!("job-{}", job.id))
                .spawn(move || {
                    // One intra-op thread per worker, so N workers never oversubscribe N cores.
                    tch::set_num_threads(1);
                    lower_priority();
                    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                        executor.execute(&job, &song, &mut progress)
                    }));
                    let _ = done_tx.send(result);
                });
            match spawned {
                Err(e) => Err(WorkerError::Io(e)),
                Ok(_) => match done_rx.await {
                    Ok(Ok(result)) => result,
                    Ok(Err(panic)) => Err(WorkerError::Panicked(panic_message(panic.as_ref()))),
                    Err(_) => Err(WorkerError::Panicked(
                        "the job's thread ended without a result".into(),
                    )),
                },
            }
        }
    };
    // Results are published before the job is marked succeeded, so a succeeded job's files
    // are there for every API process to serve.
    let result = match result {
        Ok(Outcome::Files(files)) => {
            let published = publish(ctx, job.id, &files).await;
            // The song's cache is the song's whatever became of the results; counted after
            // them (`Pipeline::generate`).
            crate::song_cache::count_stored(
                ctx.store.as_ref(),
                ctx.artifacts.as_ref(),
                job.kind.song_id(),
                files.song_cache_bytes,
            )
            .await;
            published.map(|()| Outcome::Files(files))
        }
        other => other,
    };
    done.cancel();
    if let Err(e) = heartbeat.await {
        tracing::error!(error = %e, "heartbeat task ended abnormally");
    }

    let lost = state.lease_lost.load(Ordering::Relaxed);
    let cancel_requested = state.cancel.load(Ordering::Relaxed) && !shutdown.is_cancelled();
    let write = match &result {
        Ok(outcome) => ctx
            .store
            .complete(job.id, owner, outcome.clone())
            .await
            .map(|held| (held, "succeeded")),
        Err(WorkerError::Cancelled) if cancel_requested || lost => ctx
            .store
            .finish_cancelled(job.id, owner)
            .await
            .map(|held| (held, "cancelled")),
        Err(WorkerError::Cancelled) => ctx
            .store
            .fail(
                job.id,
                owner,
                "interrupted by a server shutdown",
                true,
                ctx.policy,
            )
            .await
            .map(|held| (held, "interrupted")),
        Err(e) => {
            let message = without_paths(&format!("{} ({})", e, e.code()), &ctx.data_root);
            ctx.store
                .fail(job.id, owner, &message, e.is_retryable(), ctx.policy)
                .await
                .map(|held| (held, "failed"))
        }
    };
    metrics::gauge!(telemetry::BUSY_WORKERS).decrement(1.0);
    metrics::histogram!(telemetry::JOB_DURATION, "kind" => kind)
        .record(started.elapsed().as_secs_f64());
    match write {
        Ok((true, outcome)) => {
            metrics::counter!(telemetry::JOBS_FINISHED, "kind" => kind, "status" => outcome)
                .increment(1);
            match &result {
                Ok(_) => tracing::info!(seconds = started.elapsed().as_secs_f64(), "job succeeded"),
                Err(WorkerError::Model(m)) => {
                    tracing::warn!(error = %m, model_error = m.code(), outcome, "job did not succeed")
                }
                Err(e) => tracing::warn!(error = %e, outcome, "job did not succeed"),
            }
        }
        Ok((false, _)) => {
            tracing::warn!("lease lost before the outcome was written; the queue owns the job now");
            // Or the job was deleted while it ran: then what it wrote meanwhile goes too.
            crate::artifacts::retention::forget_if_deleted(
                ctx.store.as_ref(),
                ctx.artifacts.as_ref(),
                job.id,
            )
            .await;
        }
        Err(e) => {
            tracing::error!(error = %e, "writing the job outcome failed; its lease will expire and it will be retried")
        }
    }
}

/// `message` with the data dir's absolute path taken out: job errors are shown to API clients,
/// and the server's layout is none of their business (`songs/<id>.ogg` says enough).
fn without_paths(message: &str, root: &std::path::Path) -> String {
    let root = root.to_string_lossy();
    if root.is_empty() {
        return message.to_string();
    }
    message
        .replace(&format!("{}/", root.trim_end_matches('/')), "")
        .replace(root.as_ref(), "data dir")
}

async fn publish(
    ctx: &Context,
    id: crate::queue::JobId,
    files: &crate::queue::JobFiles,
) -> Result<(), WorkerError> {
    // The layout exists (the server made it); this only names the result files' paths.
    let data = crate::queue::DataDir::create(&ctx.data_root).ok();
    let mut bytes = 0;
    // Measured before publishing: a bucket store may move the local file away.
    if let Some(data) = &data {
        for file in &files.files {
            let path = Artifact::Result(id, file).local_path(data);
            bytes += tokio::fs::metadata(path).await.map_or(0, |m| m.len());
        }
    }
    // Counted against the tenant's storage quota before anything is published: a tenant already
    // at its quota gets no more results (the job fails with storage-quota-exceeded, its files
    // removed). A failed write for any other reason only under-counts.
    match ctx.store.record_result_bytes(id, bytes).await {
        Ok(()) => {}
        Err(e @ (QueueError::QuotaFull { .. } | QueueError::QuotaExceeded { .. })) => {
            if let Some(data) = &data {
                for file in &files.files {
                    let _ =
                        tokio::fs::remove_file(Artifact::Result(id, file).local_path(data)).await;
                }
            }
            return Err(WorkerError::Queue(e));
        }
        Err(e) => tracing::warn!(error = %e, "could not record the size of the job's results"),
    }
    for file in &files.files {
        ctx.artifacts.publish(Artifact::Result(id, file)).await?;
    }
    Ok(())
}

async fn heartbeat_loop(
    ctx: Context,
    owner: String,
    id: crate::queue::JobId,
    state: Arc<JobState>,
    done: CancellationToken,
    shutdown: CancellationToken,
) {
    loop {
        tokio::select! {
            _ = done.cancelled() => return,
            _ = shutdown.cancelled() => {
                // Stop the job at its next checkpoint; it is requeued for the next start.
                state.cancel.store(true, Ordering::Relaxed);
                done.cancelled().await;
                return;
            }
            _ = tokio::time::sleep(ctx.heartbeat) => {}
            _ = state.stage_changed.notified() => {}
        }
        let entered = match state.entered.lock() {
            Ok(mut e) => std::mem::take(&mut *e),
            Err(poisoned) => std::mem::take(&mut *poisoned.into_inner()),
        };
        let now = state.snapshot();
        // Each stage entered since the last beat, in order, then where the job is now.
        let beats = entered
            .into_iter()
            .map(|(stage, progress)| (Some(stage), progress))
            .chain(std::iter::once(now));
        let mut last = None;
        for (stage, progress) in beats {
            if last == Some((stage, progress)) {
                continue;
            }
            last = Some((stage, progress));
            if !beat(
                &ctx,
                &owner,
                id,
                &state,
                stage.unwrap_or(Stage::Claimed),
                progress,
            )
            .await
            {
                return;
            }
        }
    }
}

/// One heartbeat; `false` when the lease is lost and the job must stop.
async fn beat(
    ctx: &Context,
    owner: &str,
    id: crate::queue::JobId,
    state: &JobState,
    stage: Stage,
    progress: f64,
) -> bool {
    match ctx
        .store
        .heartbeat(id, owner, stage.as_str(), progress, ctx.policy)
        .await
    {
        Ok(Beat::Held { cancel_requested }) => {
            if cancel_requested {
                state.cancel.store(true, Ordering::Relaxed);
            }
            true
        }
        Ok(Beat::Lost) => {
            tracing::warn!("lease lost; stopping the job");
            state.lease_lost.store(true, Ordering::Relaxed);
            state.cancel.store(true, Ordering::Relaxed);
            false
        }
        Err(e) => {
            tracing::warn!(error = %e, "heartbeat failed; the lease expires unless a later one succeeds");
            true
        }
    }
}

/// Builds the service's worker context.
pub fn context(
    store: Arc<dyn Store>,
    artifacts: Arc<dyn ArtifactStore>,
    registry: Arc<Registry>,
    data: DataDir,
    config: &crate::config::Config,
) -> Context {
    let mut pipeline = Pipeline::new(registry, data, config);
    // Called on the runtime the workers run on (the server's start); the songs' caches are
    // stored through it.
    if let Ok(runtime) = tokio::runtime::Handle::try_current() {
        pipeline = pipeline.with_song_caches(pipeline::SongCaches {
            artifacts: artifacts.clone(),
            store: store.clone(),
            runtime,
        });
    }
    Context {
        store,
        artifacts,
        executor: Arc::new(pipeline),
        policy: LeasePolicy {
            lease: Duration::from_secs_f64(config.lease_s),
            backoff: Duration::from_secs_f64(config.retry_backoff_s),
        },
        heartbeat: Duration::from_secs_f64(config.heartbeat_s),
        poll: Duration::from_secs_f64(config.poll_s),
        wake: Arc::new(Notify::new()),
        alive: Arc::new(AtomicUsize::new(0)),
        data_root: std::path::absolute(&config.data_dir)
            .unwrap_or_else(|_| config.data_dir.clone()),
    }
}

/// Requeues expired leases once; call at start-up before the workers begin.
pub async fn recover(
    store: &dyn JobStore,
    policy: LeasePolicy,
) -> Result<crate::queue::Requeued, QueueError> {
    store.requeue_expired(policy).await
}

#[cfg(test)]
mod tests;
