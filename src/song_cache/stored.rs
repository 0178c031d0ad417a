//! A song's cache files in the artifact store, for a job's blocking thread: each read and write
//! waits on the store's future on the runtime the worker runs on.
use super::{CacheFiles, SongCacheError};
use crate::artifacts::{Artifact, ArtifactError, ArtifactStore};
use crate::queue::{DataDir, SongId, Store};
use std::sync::Arc;

/// One song's cache files in `artifacts`, through the local data dir (the store, or a bucket's
/// local cache).
pub struct StoredFiles {
    pub artifacts: Arc<dyn ArtifactStore>,
    pub data: DataDir,
    pub song: SongId,
    /// The worker's runtime. Only called from threads outside it (a job's own thread): blocking
    /// on it from one of its own threads would panic.
    pub runtime: tokio::runtime::Handle,
}

impl CacheFiles for StoredFiles {
    fn get(&self, file: &str) -> Result<Option<Vec<u8>>, SongCacheError> {
        let artifact = Artifact::SongCache(self.song, file);
        match self.runtime.block_on(self.artifacts.fetch(artifact)) {
            Ok(path) => std::fs::read(path)
                .map(Some)
                .map_err(|source| SongCacheError::Io {
                    file: file.to_string(),
                    source,
                }),
            Err(ArtifactError::NotFound(_)) => Ok(None),
            Err(source) => Err(SongCacheError::Store {
                file: file.to_string(),
                source,
            }),
        }
    }

    fn put(&self, file: &str, bytes: &[u8]) -> Result<(), SongCacheError> {
        let artifact = Artifact::SongCache(self.song, file);
        // Two jobs that miss the same file at once write the same bytes; the rename makes
        // either one the file, whole.
        crate::queue::files::write_atomic(&artifact.local_path(&self.data), bytes).map_err(
            |source| SongCacheError::Io {
                file: file.to_string(),
                source,
            },
        )?;
        self.runtime
            .block_on(self.artifacts.publish(artifact))
            .map_err(|source| SongCacheError::Store {
                file: file.to_string(),
                source,
            })
    }
}

/// Adds the `bytes` a job stored in its song's cache to the song's size in its tenant's storage,
/// or removes the cache when the song was deleted while the job ran. A failure only under-counts
/// (or leaves the cache to the sweep), so it is logged, not raised.
pub async fn count_stored(
    store: &dyn Store,
    artifacts: &dyn ArtifactStore,
    song: SongId,
    bytes: u64,
) {
    if bytes == 0 {
        return;
    }
    match store.add_song_cache_bytes(song, bytes).await {
        Ok(true) => {}
        Ok(false) => {
            if let Err(e) = artifacts.remove_song_cache(song).await {
                tracing::warn!(error = %e, "the song was deleted while the job ran; its cache is left to the sweep");
            }
        }
        Err(e) => {
            tracing::warn!(error = %e, bytes, "could not count the song cache's new bytes in the tenant's storage")
        }
    }
}
