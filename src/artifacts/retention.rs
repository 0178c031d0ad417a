//! Deletion's files, and retention: songs, results and rigs expire `retention_days` after last
//! use.
//!
//! A deletion (`DELETE /v1/songs/{id}`, `DELETE /v1/jobs/{id}`, `DELETE /v1/rigs/{id}`) and an
//! expiry remove rows first, in one transaction of the store (`queue/sql/delete.rs`,
//! `queue/sql/rigs.rs`), then the files those rows named, with [`remove_files`]. A file left
//! behind by a failed removal has no row any more, so the data dir's sweep ([`super::sweep`])
//! removes it after its grace period.
//!
//! The expiry runs on the worker side ([`spawn`], from every process that runs workers: `choreo
//! serve` and `choreo worker`, not `choreo serve --no-workers`), a pass every tenth of the
//! retention (at least every [`MIN_PASS`], at most every [`MAX_PASS`]); with several worker
//! processes each runs it, and the store's transaction makes a row go once. What counts as a use
//! is in `migrations/20261127000300_retention.sql` (songs and jobs) and
//! `migrations/20261207000000_rig_use.sql` (rigs).
//!
//! A worker whose job was deleted while it ran writes nothing to the store (every write matches
//! no row) and calls [`forget_if_deleted`] when it is done, removing what it published meanwhile.
use super::{Artifact, ArtifactError, ArtifactStore};
use crate::queue::{JobId, QueueError, Removed, Scope, Store};
use std::sync::Arc;
use std::time::Duration;
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;

/// The shortest pause between two expiry passes.
pub const MIN_PASS: Duration = Duration::from_millis(200);
/// The longest pause between two expiry passes.
pub const MAX_PASS: Duration = Duration::from_secs(600);
/// Rows one pass removes at most of each kind (songs, jobs, rigs), so a transaction stays
/// short; a full batch starts the next pass at once.
pub const BATCH: u32 = 200;

/// The audit reason of an expiry.
pub const EXPIRED: &str = "expired: unused for longer than retention_days";

/// Removes the files of removed rows: each song's file and cache, each rig's file and each job's
/// results.
/// Every file is tried; the first failure is returned (what it left has no row, so the sweep
/// takes it later).
pub async fn remove_files(
    artifacts: &dyn ArtifactStore,
    removed: &Removed,
) -> Result<(), ArtifactError> {
    let mut first = None;
    for song in &removed.songs {
        if let Err(e) = artifacts.remove(Artifact::Song(song.id, song.format)).await {
            first.get_or_insert(e);
        }
        // What the song's jobs computed of it (its features and beats) goes with it.
        if let Err(e) = artifacts.remove_song_cache(song.id).await {
            first.get_or_insert(e);
        }
    }
    for job in &removed.jobs {
        if let Err(e) = artifacts.remove_results(job.id).await {
            first.get_or_insert(e);
        }
    }
    for rig in &removed.rigs {
        if let Err(e) = artifacts.remove(Artifact::Rig(rig.id, rig.format)).await {
            first.get_or_insert(e);
        }
    }
    first.map_or(Ok(()), Err)
}

/// After a worker lost its job: when the job is gone (deleted while it ran), removes whatever the
/// worker wrote or published for it. A job that still exists (its lease expired and it was
/// requeued) keeps its files for the next attempt.
pub async fn forget_if_deleted(store: &dyn Store, artifacts: &dyn ArtifactStore, id: JobId) {
    match store.job(Scope::All, id).await {
        Err(QueueError::JobNotFound(_)) => match artifacts.remove_results(id).await {
            Ok(()) => tracing::info!("the job was deleted while it ran; its files are removed"),
            Err(e) => {
                tracing::warn!(error = %e, "the job was deleted while it ran; its files are left to the sweep")
            }
        },
        Err(e) => {
            tracing::warn!(error = %e, "could not tell whether the lost job was deleted; its files are left to the sweep")
        }
        Ok(_) => {}
    }
}

/// How long between two passes for a retention of `keep`.
pub fn pass_every(keep: Duration) -> Duration {
    (keep / 10).clamp(MIN_PASS, MAX_PASS)
}

/// One expiry pass: removes what was last used more than `keep` ago, rows then files, in
/// batches until none is left.
pub async fn expire(
    store: &dyn Store,
    artifacts: &dyn ArtifactStore,
    keep: Duration,
) -> Result<Removed, QueueError> {
    let mut all = Removed::default();
    loop {
        let cutoff =
            chrono::Utc::now() - chrono::Duration::from_std(keep).unwrap_or(chrono::Duration::MAX);
        let removed = store.expire(cutoff, BATCH, EXPIRED).await?;
        if let Err(e) = remove_files(artifacts, &removed).await {
            tracing::warn!(error = %e, "removing expired files failed; the sweep removes what is left");
        }
        let full = [removed.songs.len(), removed.jobs.len(), removed.rigs.len()]
            .into_iter()
            .any(|n| n >= BATCH as usize);
        all.songs.extend(removed.songs);
        all.jobs.extend(removed.jobs);
        all.rigs.extend(removed.rigs);
        if !full {
            return Ok(all);
        }
    }
}

/// Runs [`expire`] every [`pass_every`] until `shutdown`; nothing when `retention_days` is unset.
pub fn spawn(
    store: Arc<dyn Store>,
    artifacts: Arc<dyn ArtifactStore>,
    config: &crate::config::Config,
    shutdown: CancellationToken,
) -> Option<JoinHandle<()>> {
    let keep = config.retention()?;
    let every = pass_every(keep);
    Some(tokio::spawn(async move {
        loop {
            tokio::select! {
                _ = shutdown.cancelled() => return,
                _ = tokio::time::sleep(every) => {}
            }
            match expire(store.as_ref(), artifacts.as_ref(), keep).await {
                Ok(removed) if !removed.is_empty() => tracing::info!(
                    songs = removed.songs.len(),
                    jobs = removed.jobs.len(),
                    rigs = removed.rigs.len(),
                    "removed songs, results and rigs past retention_days"
                ),
                Ok(_) => {}
                Err(e) => {
                    tracing::warn!(error = %e, "the retention pass failed; retrying next pass")
                }
            }
        }
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn passes_come_a_tenth_of_the_retention_apart_within_bounds() {
        assert_eq!(
            pass_every(Duration::from_secs(5)),
            Duration::from_millis(500)
        );
        assert_eq!(pass_every(Duration::from_millis(10)), MIN_PASS);
        assert_eq!(pass_every(Duration::from_secs(30 * 86_400)), MAX_PASS);
    }
}
