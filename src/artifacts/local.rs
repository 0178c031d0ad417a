//! The data dir as the artifact store: every artifact is already in place when published.
use super::{
    Artifact, ArtifactError, ArtifactFuture, ArtifactStore, ArtifactStream, STREAM_CHUNK_BYTES,
};
use crate::queue::{DataDir, JobId, SongId};
use futures::StreamExt;
use std::path::PathBuf;

/// Artifacts in the local data dir, shared by the processes of one host.
#[derive(Clone, Debug)]
pub struct LocalArtifacts {
    data: DataDir,
}

impl LocalArtifacts {
    /// The store of `data`.
    pub fn new(data: DataDir) -> Self {
        Self { data }
    }
}

fn io(artifact: &Artifact<'_>, source: std::io::Error) -> ArtifactError {
    if source.kind() == std::io::ErrorKind::NotFound {
        ArtifactError::NotFound(artifact.key())
    } else {
        ArtifactError::Io {
            key: artifact.key(),
            source,
        }
    }
}

impl ArtifactStore for LocalArtifacts {
    fn publish<'a>(&'a self, artifact: Artifact<'a>) -> ArtifactFuture<'a, ()> {
        Box::pin(async move {
            // The atomic write that put it there is the publication.
            tokio::fs::metadata(artifact.local_path(&self.data))
                .await
                .map_err(|e| io(&artifact, e))?;
            Ok(())
        })
    }

    fn fetch<'a>(&'a self, artifact: Artifact<'a>) -> ArtifactFuture<'a, PathBuf> {
        Box::pin(async move {
            let path = artifact.local_path(&self.data);
            tokio::fs::metadata(&path)
                .await
                .map_err(|e| io(&artifact, e))?;
            Ok(path)
        })
    }

    fn stream<'a>(&'a self, artifact: Artifact<'a>) -> ArtifactFuture<'a, ArtifactStream> {
        Box::pin(async move {
            let file = tokio::fs::File::open(artifact.local_path(&self.data))
                .await
                .map_err(|e| io(&artifact, e))?;
            let len = file.metadata().await.map_err(|e| io(&artifact, e))?.len();
            let body =
                tokio_util::io::ReaderStream::with_capacity(file, STREAM_CHUNK_BYTES).boxed();
            Ok(ArtifactStream { len, body })
        })
    }

    fn remove<'a>(&'a self, artifact: Artifact<'a>) -> ArtifactFuture<'a, ()> {
        Box::pin(async move {
            match tokio::fs::remove_file(artifact.local_path(&self.data)).await {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(io(&artifact, e)),
                _ => Ok(()),
            }
        })
    }

    fn remove_results(&self, job: JobId) -> ArtifactFuture<'_, ()> {
        Box::pin(super::remove_job_dir(&self.data, job))
    }

    fn remove_song_cache(&self, song: SongId) -> ArtifactFuture<'_, ()> {
        Box::pin(super::remove_song_cache_dir(&self.data, song))
    }
}
