//! The sweep of files no row names in the local data dir.
//!
//! A process killed mid-write leaves files no row names: a result's `.partial-*` temp file in a
//! job dir, a song or rig renamed into `songs/` or `rigs/` whose row was never committed, a job
//! dir of a job that does not exist, a song's cache (`song-cache/<id>/`) stored by a job while
//! its song was deleted. A deletion whose file removal failed leaves the same, and so
//! does another host's deletion of a song, rig or result this host has a cached copy of (with a bucket, the data
//! dir is each host's cache: `artifacts::retention`). Nothing reads them, but they fill the disk.
//! The sweep removes those older than the grace period (`sweep_grace_s`), so it never races a
//! write in progress in another process sharing the data dir. It runs in the background, once
//! after the store opens and then every half grace period (at least every second, at most hourly).
use crate::queue::{DataDir, JobId, QueueError, Scope, SongId, Store};
use std::future::Future;
use std::path::Path;
use std::str::FromStr;
use std::sync::Arc;
use std::time::{Duration, SystemTime};
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;

/// What one sweep removed.
#[derive(Debug, Default, PartialEq, Eq)]
pub struct Swept {
    pub temp_files: usize,
    pub songs: usize,
    pub rigs: usize,
    pub job_dirs: usize,
    /// Song caches of songs that are gone (a job stored one while its song was deleted).
    pub song_caches: usize,
}

/// How long between two sweeps for a grace period of `grace`.
pub fn sweep_every(grace: Duration) -> Duration {
    (grace / 2).clamp(Duration::from_secs(1), Duration::from_secs(3600))
}

/// Runs [`sweep`] in the background now and every [`sweep_every`], logging what it removed,
/// until `shutdown`.
pub fn spawn(
    store: Arc<dyn Store>,
    data: DataDir,
    grace: Duration,
    shutdown: CancellationToken,
) -> JoinHandle<()> {
    tokio::spawn(async move {
        loop {
            match sweep(store.as_ref(), &data, grace).await {
                Ok(swept) if swept != Swept::default() => {
                    tracing::info!(?swept, "removed files no row names from the data dir")
                }
                Ok(_) => {}
                Err(e) => {
                    tracing::warn!(error = %e, "the sweep of the data dir stopped; retrying next round")
                }
            }
            tokio::select! {
                _ = shutdown.cancelled() => return,
                _ = tokio::time::sleep(sweep_every(grace)) => {}
            }
        }
    })
}

fn older_than(path: &Path, grace: Duration) -> bool {
    let modified = std::fs::symlink_metadata(path)
        .and_then(|m| m.modified())
        .unwrap_or_else(|_| SystemTime::now());
    SystemTime::now()
        .duration_since(modified)
        .is_ok_and(|age| age >= grace)
}

/// Removes the uploads in `dir` (files named `<id>.<ext>`) older than `grace` whose row is gone
/// (`exists` answers false); returns how many went.
async fn sweep_uploads<Id, F, Fut>(
    dir: &Path,
    grace: Duration,
    exists: F,
) -> Result<usize, QueueError>
where
    Id: FromStr,
    F: Fn(Id) -> Fut,
    Fut: Future<Output = Result<bool, QueueError>>,
{
    let mut removed = 0;
    for entry in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        let path = entry.path();
        let Some(id) = path
            .file_stem()
            .and_then(|s| s.to_str())
            .and_then(|s| Id::from_str(s).ok())
        else {
            continue;
        };
        if older_than(&path, grace) && !exists(id).await? && std::fs::remove_file(&path).is_ok() {
            removed += 1;
        }
    }
    Ok(removed)
}

/// Removes leftovers older than `grace`; a database error stops it (nothing is removed on doubt).
pub async fn sweep(
    store: &dyn Store,
    data: &DataDir,
    grace: Duration,
) -> Result<Swept, QueueError> {
    let songs = sweep_uploads(&data.root().join("songs"), grace, |id| async move {
        match store.song(Scope::All, id).await {
            Err(QueueError::SongNotFound(_)) => Ok(false),
            Err(e) => Err(e),
            Ok(_) => Ok(true),
        }
    })
    .await?;
    let rigs = sweep_uploads(&data.root().join("rigs"), grace, |id| async move {
        match store.rig(Scope::All, id).await {
            Err(QueueError::RigNotFound(_)) => Ok(false),
            Err(e) => Err(e),
            Ok(_) => Ok(true),
        }
    })
    .await?;
    let mut swept = Swept {
        songs,
        rigs,
        ..Swept::default()
    };
    for entry in std::fs::read_dir(data.root().join(super::SONG_CACHE_DIR))
        .into_iter()
        .flatten()
        .flatten()
    {
        let dir = entry.path();
        let Some(id) = dir
            .file_name()
            .and_then(|s| s.to_str())
            .and_then(|s| SongId::from_str(s).ok())
        else {
            continue;
        };
        // A file stored in it refreshes the dir's time: a cache being written is never swept.
        if !older_than(&dir, grace) {
            continue;
        }
        match store.song(Scope::All, id).await {
            Err(QueueError::SongNotFound(_)) => {
                if std::fs::remove_dir_all(&dir).is_ok() {
                    swept.song_caches += 1;
                }
            }
            Err(e) => return Err(e),
            Ok(_) => {}
        }
    }
    for entry in std::fs::read_dir(data.root().join("jobs"))
        .into_iter()
        .flatten()
        .flatten()
    {
        let dir = entry.path();
        let Some(id) = dir
            .file_name()
            .and_then(|s| s.to_str())
            .and_then(|s| JobId::from_str(s).ok())
        else {
            continue;
        };
        for file in std::fs::read_dir(&dir).into_iter().flatten().flatten() {
            let is_temp = file
                .file_name()
                .to_str()
                .is_some_and(|n| n.starts_with(".partial-") || n.starts_with(".tmp"));
            if is_temp
                && older_than(&file.path(), grace)
                && std::fs::remove_file(file.path()).is_ok()
            {
                swept.temp_files += 1;
            }
        }
        if !older_than(&dir, grace) {
            continue;
        }
        match store.job(Scope::All, id).await {
            Err(QueueError::JobNotFound(_)) => {
                if std::fs::remove_dir_all(&dir).is_ok() {
                    swept.job_dirs += 1;
                }
            }
            Err(e) => return Err(e),
            Ok(_) => {}
        }
    }
    Ok(swept)
}
