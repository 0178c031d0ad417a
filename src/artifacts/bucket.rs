//! An S3-compatible bucket as the artifact store, with the data dir as this host's cache.
//!
//! Credentials come from the standard AWS environment (`AWS_ACCESS_KEY_ID`,
//! `AWS_SECRET_ACCESS_KEY`, `AWS_SESSION_TOKEN`), never from `config.toml`, so they stay out of
//! files and logs. `s3_endpoint` points at any S3-compatible server (MinIO, moto, Ceph, R2).
use super::{Artifact, ArtifactError, ArtifactFuture, ArtifactStore, ArtifactStream};
use crate::queue::files::write_atomic;
use crate::queue::{DataDir, JobId, SongId};
use bytes::Bytes;
use futures::{StreamExt, TryStreamExt};
use object_store::aws::AmazonS3Builder;
use object_store::path::Path as ObjectPath;
use object_store::{ObjectStore, ObjectStoreExt, PutPayload};
use std::path::PathBuf;
use std::sync::Arc;

/// Artifacts in a bucket, cached in the local data dir.
#[derive(Clone, Debug)]
pub struct BucketArtifacts {
    bucket: Arc<dyn ObjectStore>,
    prefix: String,
    cache: DataDir,
}

impl BucketArtifacts {
    /// A store over `bucket` (keys under `prefix`), at `endpoint` when not AWS itself.
    pub fn connect(
        bucket: &str,
        prefix: &str,
        endpoint: Option<&str>,
        region: &str,
        cache: DataDir,
    ) -> Result<Self, ArtifactError> {
        let mut builder = AmazonS3Builder::from_env()
            .with_bucket_name(bucket)
            .with_region(region);
        if let Some(endpoint) = endpoint {
            // Self-hosted servers are addressed by path (`endpoint/bucket/key`), and may be plain
            // HTTP inside a private network.
            builder = builder
                .with_endpoint(endpoint)
                .with_virtual_hosted_style_request(false)
                .with_allow_http(endpoint.starts_with("http://"));
        }
        let bucket = builder
            .build()
            .map_err(|e| ArtifactError::Config(e.to_string()))?;
        Ok(Self {
            bucket: Arc::new(bucket),
            prefix: prefix.to_string(),
            cache,
        })
    }

    fn location(&self, artifact: &Artifact<'_>) -> ObjectPath {
        if self.prefix.is_empty() {
            ObjectPath::from(artifact.key())
        } else {
            ObjectPath::from(format!("{}/{}", self.prefix, artifact.key()))
        }
    }

    fn bucket_error(artifact: &Artifact<'_>, source: object_store::Error) -> ArtifactError {
        match source {
            object_store::Error::NotFound { .. } => ArtifactError::NotFound(artifact.key()),
            source => ArtifactError::Bucket {
                key: artifact.key(),
                source,
            },
        }
    }

    async fn get(&self, artifact: &Artifact<'_>) -> Result<Bytes, ArtifactError> {
        let got = self
            .bucket
            .get(&self.location(artifact))
            .await
            .map_err(|e| Self::bucket_error(artifact, e))?;
        got.bytes()
            .await
            .map_err(|e| Self::bucket_error(artifact, e))
    }
}

fn io(artifact: &Artifact<'_>, source: std::io::Error) -> ArtifactError {
    ArtifactError::Io {
        key: artifact.key(),
        source,
    }
}

impl ArtifactStore for BucketArtifacts {
    fn publish<'a>(&'a self, artifact: Artifact<'a>) -> ArtifactFuture<'a, ()> {
        Box::pin(async move {
            // Songs are at most `max_upload_bytes` and results a few MB: one PUT each, which S3
            // makes visible whole or not at all.
            let bytes = tokio::fs::read(artifact.local_path(&self.cache))
                .await
                .map_err(|e| io(&artifact, e))?;
            self.bucket
                .put(&self.location(&artifact), PutPayload::from(bytes))
                .await
                .map_err(|e| Self::bucket_error(&artifact, e))?;
            Ok(())
        })
    }

    fn fetch<'a>(&'a self, artifact: Artifact<'a>) -> ArtifactFuture<'a, PathBuf> {
        Box::pin(async move {
            let path = artifact.local_path(&self.cache);
            if tokio::fs::metadata(&path).await.is_ok() {
                return Ok(path);
            }
            let bytes = self.get(&artifact).await?;
            let target = path.clone();
            tokio::task::spawn_blocking(move || write_atomic(&target, &bytes))
                .await
                .map_err(|e| io(&artifact, std::io::Error::other(e)))?
                .map_err(|e| io(&artifact, e))?;
            Ok(path)
        })
    }

    fn stream<'a>(&'a self, artifact: Artifact<'a>) -> ArtifactFuture<'a, ArtifactStream> {
        Box::pin(async move {
            // The object's body streams from the bucket as the client reads it.
            let got = self
                .bucket
                .get(&self.location(&artifact))
                .await
                .map_err(|e| Self::bucket_error(&artifact, e))?;
            let len = got.meta.size;
            let body = got.into_stream().map_err(std::io::Error::other).boxed();
            Ok(ArtifactStream { len, body })
        })
    }

    fn remove<'a>(&'a self, artifact: Artifact<'a>) -> ArtifactFuture<'a, ()> {
        Box::pin(async move {
            match self.bucket.delete(&self.location(&artifact)).await {
                Ok(()) | Err(object_store::Error::NotFound { .. }) => {}
                Err(e) => return Err(Self::bucket_error(&artifact, e)),
            }
            match tokio::fs::remove_file(artifact.local_path(&self.cache)).await {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(io(&artifact, e)),
                _ => Ok(()),
            }
        })
    }

    fn remove_results(&self, job: JobId) -> ArtifactFuture<'_, ()> {
        Box::pin(async move {
            // Listed rather than named: whatever a worker published under the job goes.
            self.remove_listed(&Artifact::Result(job, "")).await?;
            super::remove_job_dir(&self.cache, job).await
        })
    }

    fn remove_song_cache(&self, song: SongId) -> ArtifactFuture<'_, ()> {
        Box::pin(async move {
            // Listed: every version's files go, those of versions this build does not know too.
            self.remove_listed(&Artifact::SongCache(song, "")).await?;
            super::remove_song_cache_dir(&self.cache, song).await
        })
    }
}

impl BucketArtifacts {
    /// Deletes every object under `dir`'s key (an artifact with an empty file name).
    async fn remove_listed(&self, dir: &Artifact<'_>) -> Result<(), ArtifactError> {
        let prefix = self.location(dir);
        let objects: Vec<_> = self
            .bucket
            .list(Some(&prefix))
            .map_ok(|meta| meta.location)
            .try_collect()
            .await
            .map_err(|e| Self::bucket_error(dir, e))?;
        for location in objects {
            match self.bucket.delete(&location).await {
                Ok(()) | Err(object_store::Error::NotFound { .. }) => {}
                Err(source) => {
                    return Err(ArtifactError::Bucket {
                        key: dir.key(),
                        source,
                    })
                }
            }
        }
        Ok(())
    }
}
