//! A song's work done once: its beats and the feature sets the models hear, computed by the first
//! job on the song and stored with it, so later jobs (other seeds, other workers, other hosts)
//! read them instead of decoding and analysing the song again.
//!
//! What is stored is what a generate job would compute: the song decoded at up to
//! [`GENERATE_MAX_SR`] (the decoded samples themselves are not stored: at 48 kHz a 3-minute song
//! is 35 MB of `f32`, its features a few hundred kB), its analysis and length
//! ([`analysis_file`]), and each feature set a model asked for, by layout, frame rate, start and
//! rows ([`features_file`]). The files are in the artifact store beside the song
//! (`song-cache/<song id>/`, [`crate::artifacts::Artifact::SongCache`]), written whole and never
//! changed: every name carries [`VERSION`], so a build whose decoding, analysis or feature code
//! computes something else reads none of an older build's files. The numbers are stored as their
//! bits ([`codec`]), so a job served from the cache makes byte for byte the dance it would have
//! made without it.
//!
//! A [`SongCache`] is one job's view: it decodes the song only when something it needs is not
//! stored, and records each stage it does run (`decode-audio`, `analyze`, `features`) on the
//! `choreo_stage_duration_seconds` metric, so a stage that was read from the cache is not
//! counted. Its files are removed with the song (`artifacts::retention::remove_files`) and
//! counted in its tenant's storage (`songs.cache_bytes`).
use crate::audio::features::FeatureSet;
use crate::audio::{Analysis, AudioError, Budget, DecodedAudio, SongAudio};
use crate::stage::Stage;
use crate::telemetry::StageTimer;
use ndarray::Array2;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::OnceLock;
use std::time::Duration;

pub mod codec;
pub mod stored;

pub use stored::{count_stored, StoredFiles};

/// The cache's version, in every file name. Bump it when the decode a job does
/// ([`GENERATE_MAX_SR`], `audio::decode`), the analysis (`audio::analyze`) or any feature set
/// (`audio::features`) computes anything else, or when [`codec`] changes.
pub const VERSION: u32 = 2;

/// Highest rate a generate job keeps the song at: the models' feature grids resample to at most
/// 22 050 Hz, so more only costs memory (a 15-minute song at 384 kHz would be 1.4 GB).
pub const GENERATE_MAX_SR: u32 = 48_000;

/// The file holding the song's length and analysis.
pub fn analysis_file() -> String {
    format!("analysis-v{VERSION}.bin")
}

/// The file holding one feature set: its layout (name and width), frame rate, start and rows.
pub fn features_file(set: FeatureSet, fps: f64, start_s: f64, n_frames: usize) -> String {
    format!(
        "features-v{VERSION}-{}-{fps}fps-{start_s}s-{n_frames}.bin",
        set.name()
    )
}

/// Errors of the cache's files. None fails a job: a file that cannot be read is computed again,
/// one that cannot be stored is computed again by the next job.
#[derive(Debug, thiserror::Error)]
pub enum SongCacheError {
    #[error("song cache {file}: {source}")]
    Store {
        file: String,
        source: crate::artifacts::ArtifactError,
    },
    #[error("song cache {file}: {source}")]
    Io {
        file: String,
        source: std::io::Error,
    },
    #[error("song cache {file} is not a cache file of version {VERSION}: {reason}")]
    Corrupt { file: String, reason: String },
}

impl SongCacheError {
    /// Stable kebab-case name of the failure (for the logs).
    pub fn code(&self) -> &'static str {
        match self {
            SongCacheError::Store { .. } => "song-cache-store",
            SongCacheError::Io { .. } => "song-cache-io",
            SongCacheError::Corrupt { .. } => "song-cache-corrupt",
        }
    }
}

/// Where a song's cache files are kept (the artifact store: [`StoredFiles`]).
pub trait CacheFiles: Sync {
    /// The bytes of a stored file; `None` when it is not stored.
    fn get(&self, file: &str) -> Result<Option<Vec<u8>>, SongCacheError>;
    /// Stores a file, whole or not at all.
    fn put(&self, file: &str, bytes: &[u8]) -> Result<(), SongCacheError>;
}

/// Decodes the song (the job's way: at up to [`GENERATE_MAX_SR`]) within a budget.
pub type Decode<'a> = dyn Fn(&Budget) -> Result<DecodedAudio, AudioError> + Sync + 'a;

/// One job's view of its song's cache: a [`SongAudio`] that reads what is stored, and computes,
/// stores and times what is not.
pub struct SongCache<'a> {
    files: &'a dyn CacheFiles,
    decode: &'a Decode<'a>,
    /// The job kind the stage metrics are labelled with.
    kind: &'static str,
    /// The budget of a decode started by a model's request for features (the model's progress
    /// checkpoints stop the job before and after it, not during).
    audio_timeout: Option<Duration>,
    decoded: OnceLock<DecodedAudio>,
    /// The song's length (s) and analysis, read or computed.
    heard: OnceLock<(f64, Analysis)>,
    /// Bytes this job stored, for its tenant's storage.
    stored_bytes: AtomicU64,
}

impl<'a> SongCache<'a> {
    /// The song's cache in `files`, its length and analysis read if they are stored; `decode`
    /// decodes the song when something is not.
    pub fn new(
        files: &'a dyn CacheFiles,
        decode: &'a Decode<'a>,
        kind: &'static str,
        audio_timeout: Option<Duration>,
    ) -> Self {
        let cache = Self {
            files,
            decode,
            kind,
            audio_timeout,
            decoded: OnceLock::new(),
            heard: OnceLock::new(),
            stored_bytes: AtomicU64::new(0),
        };
        let file = analysis_file();
        if let Some(heard) = cache.read(&file).and_then(|bytes| {
            codec::decode_heard(&file, &bytes)
                .map_err(cache.warn())
                .ok()
        }) {
            let _ = cache.heard.set(heard);
        }
        cache
    }

    /// Whether the song's length and analysis were read from the cache (or computed already).
    pub fn is_analysed(&self) -> bool {
        self.heard.get().is_some()
    }

    /// Decodes the song within `budget`, unless it is decoded already.
    pub fn decode_within(&self, budget: &Budget) -> Result<(), AudioError> {
        self.decoded(budget).map(|_| ())
    }

    /// The song's analysis: read, or computed within `budget` (decoding the song first when it
    /// is not decoded) and stored.
    pub fn analyze_within(&self, budget: &Budget) -> Result<Analysis, AudioError> {
        if let Some((_, analysis)) = self.heard.get() {
            return Ok(analysis.clone());
        }
        let decoded = self.decoded(budget)?;
        let analysis = {
            let _timer = StageTimer::start(self.kind, Stage::Analyze);
            crate::audio::analyze_within(decoded, budget)?
        };
        self.write(
            &analysis_file(),
            &codec::encode_heard(decoded.duration_s, &analysis),
        );
        let (_, analysis) = self.heard.get_or_init(|| (decoded.duration_s, analysis));
        Ok(analysis.clone())
    }

    /// Bytes this job added to the song's cache.
    pub fn stored_bytes(&self) -> u64 {
        self.stored_bytes.load(Ordering::Relaxed)
    }

    /// The decoded song, decoded now (and timed) on first use.
    fn decoded(&self, budget: &Budget) -> Result<&DecodedAudio, AudioError> {
        if let Some(decoded) = self.decoded.get() {
            return Ok(decoded);
        }
        let decoded = {
            let _timer = StageTimer::start(self.kind, Stage::DecodeAudio);
            (self.decode)(budget)?
        };
        Ok(self.decoded.get_or_init(|| decoded))
    }

    fn warn(&self) -> impl Fn(SongCacheError) + '_ {
        |e| tracing::warn!(error = %e, code = e.code(), "song cache file not used; computing it again")
    }

    fn read(&self, file: &str) -> Option<Vec<u8>> {
        self.files.get(file).map_err(self.warn()).ok().flatten()
    }

    fn write(&self, file: &str, bytes: &[u8]) {
        match self.files.put(file, bytes) {
            Ok(()) => {
                self.stored_bytes
                    .fetch_add(bytes.len() as u64, Ordering::Relaxed);
            }
            Err(e) => {
                tracing::warn!(error = %e, code = e.code(), "song cache file not stored; the next job computes it again")
            }
        }
    }
}

impl SongAudio for SongCache<'_> {
    fn duration_s(&self) -> f64 {
        // The caller analyses first (a job does, before its model); a song only decoded is
        // measured by its decode.
        match (self.heard.get(), self.decoded.get()) {
            (Some((duration_s, _)), _) => *duration_s,
            (None, Some(decoded)) => decoded.duration_s,
            (None, None) => 0.0,
        }
    }

    fn features(
        &self,
        set: FeatureSet,
        fps: f64,
        start_s: f64,
        n_frames: usize,
    ) -> Result<Array2<f32>, AudioError> {
        let file = features_file(set, fps, start_s, n_frames);
        if let Some(bytes) = self.read(&file) {
            match codec::decode_features(&file, &bytes) {
                Ok(features) => return Ok(features),
                Err(e) => self.warn()(e),
            }
        }
        let decoded = self.decoded(&Budget::new(self.audio_timeout, None))?;
        let features = {
            let _timer = StageTimer::start(self.kind, Stage::Features);
            set.compute(decoded, fps, start_s, n_frames)?
        };
        self.write(&file, &codec::encode_features(&features));
        Ok(features)
    }

    fn analysis(&self) -> Result<Analysis, AudioError> {
        self.analyze_within(&Budget::new(self.audio_timeout, None))
    }
}

/// Files kept in memory only: for a caller without an artifact store, and for tests.
#[derive(Default)]
pub struct MemoryFiles {
    files: std::sync::Mutex<std::collections::HashMap<String, Vec<u8>>>,
}

impl MemoryFiles {
    /// The names stored, sorted.
    pub fn names(&self) -> Vec<String> {
        let files = self.files.lock().unwrap_or_else(|p| p.into_inner());
        let mut names: Vec<String> = files.keys().cloned().collect();
        names.sort();
        names
    }
}

impl CacheFiles for MemoryFiles {
    fn get(&self, file: &str) -> Result<Option<Vec<u8>>, SongCacheError> {
        let files = self.files.lock().unwrap_or_else(|p| p.into_inner());
        Ok(files.get(file).cloned())
    }

    fn put(&self, file: &str, bytes: &[u8]) -> Result<(), SongCacheError> {
        let mut files = self.files.lock().unwrap_or_else(|p| p.into_inner());
        files.insert(file.to_string(), bytes.to_vec());
        Ok(())
    }
}

#[cfg(test)]
mod tests;
