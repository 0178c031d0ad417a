//! The artifact store: uploaded songs and job results, addressed by id.
//!
//! Every artifact is first written, atomically, to its place in the local data dir
//! ([`crate::queue::DataDir`]): uploads are renamed into place, results are written to a temp
//! file and renamed. [`ArtifactStore::publish`] then makes that file the stored artifact, and
//! [`ArtifactStore::fetch`] gives a process a local path holding one. Two stores:
//!
//! - [`LocalArtifacts`] (the default): the data dir is the store; publish and fetch only check
//!   the file is there. API and worker processes on one host share it.
//! - [`BucketArtifacts`]: an S3-compatible bucket (`object_store`), for processes on many hosts;
//!   the data dir is each host's cache. A PUT is atomic (an object appears whole or not at all),
//!   and a fetched artifact is written to the cache through a temp file and a rename.
//!
//! Artifacts never change once written (names come from ids, and a song cache's file names carry
//! the cache's version and what it holds), so a cached copy is never stale.
use crate::audio::AudioFormat;
use crate::motion::retarget::uploaded::RigFormat;
use crate::queue::{DataDir, JobId, RigId, SongId};
use bytes::Bytes;
use futures::future::BoxFuture;
use futures::stream::BoxStream;
use std::path::PathBuf;
use std::sync::Arc;

pub mod bucket;
pub mod local;
pub mod retention;
pub mod sweep;

pub use bucket::BucketArtifacts;
pub use local::LocalArtifacts;

/// Errors from the artifact store.
#[derive(Debug, thiserror::Error)]
pub enum ArtifactError {
    #[error("artifact {0} not found")]
    NotFound(String),
    #[error("artifact {key}: {source}")]
    Io { key: String, source: std::io::Error },
    #[error("artifact {key}: object store: {source}")]
    Bucket {
        key: String,
        source: object_store::Error,
    },
    #[error("artifact store configuration: {0}")]
    Config(String),
}

impl ArtifactError {
    /// Stable kebab-case name of the failure.
    pub fn code(&self) -> &'static str {
        match self {
            ArtifactError::NotFound(_) => "artifact-not-found",
            ArtifactError::Io { .. } => "artifact-io",
            ArtifactError::Bucket { .. } => "artifact-store",
            ArtifactError::Config(_) => "artifact-config",
        }
    }

    /// Whether trying again later may succeed.
    pub fn is_retryable(&self) -> bool {
        match self {
            // A song or result that is missing now may be a replica that has not caught up.
            ArtifactError::NotFound(_) => true,
            ArtifactError::Io { .. } => true,
            ArtifactError::Bucket { .. } => true,
            ArtifactError::Config(_) => false,
        }
    }
}

/// One artifact, named by ids only (never by user input).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Artifact<'a> {
    /// An uploaded song, in the format decoding found.
    Song(SongId, AudioFormat),
    /// An uploaded rig, in the format its bytes are.
    Rig(RigId, RigFormat),
    /// One result file of a generate job (a name from `queue::files::RESULT_FILES`).
    Result(JobId, &'a str),
    /// One file of a song's cache of its decoded features and beats (a name from
    /// `crate::song_cache`, never user input).
    SongCache(SongId, &'a str),
}

impl Artifact<'_> {
    /// Its key in a bucket, the same as its path under the data dir: `songs/<id>.<ext>`,
    /// `jobs/<id>/<file>`.
    pub fn key(&self) -> String {
        match self {
            Artifact::Song(id, format) => {
                format!("songs/{id}.{}", crate::queue::files::extension(*format))
            }
            Artifact::Rig(id, format) => format!("rigs/{id}.{}", format.extension()),
            Artifact::Result(id, file) => format!("jobs/{id}/{file}"),
            Artifact::SongCache(id, file) => format!("{SONG_CACHE_DIR}/{id}/{file}"),
        }
    }

    /// Where it lives (or is cached) in the local data dir.
    pub fn local_path(&self, data: &DataDir) -> PathBuf {
        match self {
            Artifact::Song(id, format) => data.song_path(*id, *format),
            Artifact::Rig(id, format) => data.rig_path(*id, *format),
            Artifact::Result(id, file) => data.job_dir(*id).join(file),
            Artifact::SongCache(id, file) => song_cache_dir(data, *id).join(file),
        }
    }
}

/// The folder of the song caches, in the data dir and in a bucket: beside `songs/`, not in it, so
/// the sweep of `songs/` never meets a cache (a cache is removed with its song's row).
pub const SONG_CACHE_DIR: &str = "song-cache";

/// The local folder of one song's cache.
pub fn song_cache_dir(data: &DataDir, song: SongId) -> PathBuf {
    data.root().join(SONG_CACHE_DIR).join(song.to_string())
}

/// A future returned by an artifact store.
pub type ArtifactFuture<'a, T> = BoxFuture<'a, Result<T, ArtifactError>>;

/// Bytes read from a file or a bucket at a time when streaming an artifact.
pub const STREAM_CHUNK_BYTES: usize = 64 * 1024;

/// An artifact's bytes, read as they are consumed: the reader holds one chunk at a time, so a
/// client that reads slowly costs a buffer, not the file.
pub struct ArtifactStream {
    /// Its size in bytes.
    pub len: u64,
    pub body: BoxStream<'static, Result<Bytes, std::io::Error>>,
}

/// Where songs and results are kept.
pub trait ArtifactStore: Send + Sync {
    /// Stores the file at `artifact`'s local path (written there atomically) as the artifact.
    fn publish<'a>(&'a self, artifact: Artifact<'a>) -> ArtifactFuture<'a, ()>;
    /// A local path holding the artifact, fetched into the data dir if it is not there.
    fn fetch<'a>(&'a self, artifact: Artifact<'a>) -> ArtifactFuture<'a, PathBuf>;
    /// The artifact's bytes, streamed (see [`ArtifactStream`]).
    fn stream<'a>(&'a self, artifact: Artifact<'a>) -> ArtifactFuture<'a, ArtifactStream>;
    /// Removes the artifact and its local copy (an upload that lost a race to its twin).
    fn remove<'a>(&'a self, artifact: Artifact<'a>) -> ArtifactFuture<'a, ()>;
    /// Removes every result of a job, whatever their names (a deleted or expired job), and its
    /// local dir. Nothing there is not an error.
    fn remove_results(&self, job: JobId) -> ArtifactFuture<'_, ()>;
    /// Removes every file of a song's cache, whatever its version, and its local dir (a deleted
    /// or expired song). Nothing there is not an error.
    fn remove_song_cache(&self, song: SongId) -> ArtifactFuture<'_, ()>;
}

/// Removes the local dir of a job's results; a missing one is fine.
async fn remove_job_dir(data: &DataDir, job: JobId) -> Result<(), ArtifactError> {
    match tokio::fs::remove_dir_all(data.job_dir(job)).await {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(ArtifactError::Io {
            key: format!("jobs/{job}/"),
            source: e,
        }),
        _ => Ok(()),
    }
}

/// Removes the local dir of a song's cache; a missing one is fine.
async fn remove_song_cache_dir(data: &DataDir, song: SongId) -> Result<(), ArtifactError> {
    match tokio::fs::remove_dir_all(song_cache_dir(data, song)).await {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(ArtifactError::Io {
            key: format!("{SONG_CACHE_DIR}/{song}/"),
            source: e,
        }),
        _ => Ok(()),
    }
}

/// Where [`open`] keeps artifacts.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Location {
    /// The data dir.
    Local,
    /// An S3-compatible bucket, with an optional key prefix.
    Bucket { bucket: String, prefix: String },
}

impl Location {
    /// Parses `artifacts_url`: unset or `local`, or `s3://bucket[/prefix]`.
    pub fn parse(url: Option<&str>) -> Result<Self, ArtifactError> {
        match url {
            None | Some("local") => Ok(Location::Local),
            Some(url) => {
                let Some(rest) = url.strip_prefix("s3://") else {
                    return Err(ArtifactError::Config(format!(
                        "artifacts_url {url:?}: use \"local\" or s3://bucket[/prefix]"
                    )));
                };
                let (bucket, prefix) = rest.split_once('/').unwrap_or((rest, ""));
                if bucket.is_empty() {
                    return Err(ArtifactError::Config(format!(
                        "artifacts_url {url:?} names no bucket"
                    )));
                }
                Ok(Location::Bucket {
                    bucket: bucket.to_string(),
                    prefix: prefix.trim_matches('/').to_string(),
                })
            }
        }
    }
}

/// Opens the artifact store the configuration names; `data` is the store or its cache.
pub fn open(
    config: &crate::config::Config,
    data: DataDir,
) -> Result<Arc<dyn ArtifactStore>, ArtifactError> {
    Ok(match Location::parse(config.artifacts_url.as_deref())? {
        Location::Local => Arc::new(LocalArtifacts::new(data)),
        Location::Bucket { bucket, prefix } => Arc::new(BucketArtifacts::connect(
            &bucket,
            &prefix,
            config.s3_endpoint.as_deref(),
            &config.s3_region,
            data,
        )?),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_come_from_ids_and_urls_parse() {
        let song = SongId::new();
        assert_eq!(
            Artifact::Song(song, AudioFormat::Flac).key(),
            format!("songs/{song}.flac")
        );
        let job = JobId::new();
        assert_eq!(
            Artifact::Result(job, "motion.bvh").key(),
            format!("jobs/{job}/motion.bvh")
        );
        assert_eq!(
            Artifact::SongCache(song, "analysis-v1.bin").key(),
            format!("song-cache/{song}/analysis-v1.bin")
        );
        assert_eq!(Location::parse(None).expect("default"), Location::Local);
        assert_eq!(
            Location::parse(Some("s3://b/choreo/prod/")).expect("bucket"),
            Location::Bucket {
                bucket: "b".into(),
                prefix: "choreo/prod".into()
            }
        );
        assert!(Location::parse(Some("s3:///x")).is_err());
        assert!(Location::parse(Some("gs://b")).is_err());
    }
}
