//! The start-up sweep of crash leftovers in the local data dir.
//!
//! A process killed mid-write leaves files no row names: a result's `.partial-*` temp file in a
//! job dir, a song renamed into `songs/` whose row was never committed, a job dir of a job that
//! does not exist. Nothing reads them, but they fill the disk. The sweep removes those older
//! than the grace period (`sweep_grace_s`), so it never races a write in progress in another
//! process sharing the data dir. It runs once, in the background, after the store opens.
use crate::queue::{DataDir, JobId, QueueError, Scope, SongId, Store};
use std::path::Path;
use std::str::FromStr;
use std::sync::Arc;
use std::time::{Duration, SystemTime};

/// What one sweep removed.
#[derive(Debug, Default, PartialEq, Eq)]
pub struct Swept {
    pub temp_files: usize,
    pub songs: usize,
    pub job_dirs: usize,
}

/// Runs [`sweep`] in the background and logs what it removed.
pub fn spawn(store: Arc<dyn Store>, data: DataDir, grace: Duration) {
    tokio::spawn(async move {
        match sweep(store.as_ref(), &data, grace).await {
            Ok(swept) if swept != Swept::default() => {
                tracing::info!(?swept, "removed crash leftovers from the data dir")
            }
            Ok(_) => {}
            Err(e) => tracing::warn!(error = %e, "the start-up sweep of crash leftovers stopped"),
        }
    });
}

fn older_than(path: &Path, grace: Duration) -> bool {
    let modified = std::fs::symlink_metadata(path)
        .and_then(|m| m.modified())
        .unwrap_or_else(|_| SystemTime::now());
    SystemTime::now()
        .duration_since(modified)
        .is_ok_and(|age| age >= grace)
}

/// Removes leftovers older than `grace`; a database error stops it (nothing is removed on doubt).
pub async fn sweep(
    store: &dyn Store,
    data: &DataDir,
    grace: Duration,
) -> Result<Swept, QueueError> {
    let mut swept = Swept::default();
    for entry in std::fs::read_dir(data.root().join("songs"))
        .into_iter()
        .flatten()
        .flatten()
    {
        let path = entry.path();
        let Some(id) = path
            .file_stem()
            .and_then(|s| s.to_str())
            .and_then(|s| SongId::from_str(s).ok())
        else {
            continue;
        };
        if !older_than(&path, grace) {
            continue;
        }
        match store.song(Scope::All, id).await {
            Err(QueueError::SongNotFound(_)) => {
                if std::fs::remove_file(&path).is_ok() {
                    swept.songs += 1;
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
