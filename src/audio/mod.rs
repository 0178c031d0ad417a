//! Music analysis: decode, resample, and librosa-grade features.
//!
//! The flow is `decode` (symphonia, mono downmix, encoder-delay trim, rubato resampling while
//! streaming) → `dsp` (STFT, Slaney mel, MFCC, delta: librosa 0.11 defaults) → `onset`,
//! `rhythm` (onset strength, tempogram, tempo, the Ellis dynamic-programming beat tracker,
//! downbeats), `tempo_curve` (the local tempo of songs whose tempo changes) and `chroma` (chroma_stft, constant-Q chroma) → `features` (one named feature set
//! per model, frame i = music at time i/fps). `reference` compares against librosa fixtures.
//!
//! Every function here returns `AudioError` for bad input and never panics on user audio.
use serde::{Deserialize, Serialize};

use crate::stage::Stage;

pub mod bench;
pub mod budget;
pub mod chroma;
pub mod clock;
mod decimate;
pub mod decode;
pub mod dsp;
pub mod features;
pub mod mp4;
pub mod onset;
mod resample;
pub mod rhythm;
pub mod tempo_curve;

pub use budget::Budget;
pub use decode::{
    decode_bytes, decode_file, decode_path_at, resample, DecodeOptions, Decoded, Keep,
};

/// Sample rate of `analyze` (librosa's default `sr`).
pub const ANALYSIS_SR: u32 = 22_050;
/// STFT hop in samples, librosa's default.
pub const HOP_LENGTH: usize = 512;
/// STFT window length in samples, librosa's default.
pub const N_FFT: usize = 2048;
/// Number of mel bands, librosa's default.
pub const N_MELS: usize = 128;
/// Longest song decoded when the caller gives no limit of its own, in seconds.
pub const MAX_DURATION_S: f64 = 30.0 * 60.0;
/// Lowest native sample rate accepted.
pub const MIN_SAMPLE_RATE: u32 = 4_000;
/// Highest native sample rate accepted (checked from the header, before any decoding).
pub const MAX_SAMPLE_RATE: u32 = 384_000;

/// The container/codec a song was decoded as, found by decoding, never by extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum AudioFormat {
    Mp3,
    Wav,
    Flac,
    Ogg,
    M4a,
}

/// A decoded song, downmixed to mono at `sample_rate` (native unless resampled while decoding).
#[derive(Clone, Debug)]
pub struct DecodedAudio {
    pub format: AudioFormat,
    pub sample_rate: u32,
    pub channels: u16,
    pub duration_s: f64,
    pub samples: Vec<f32>,
}

/// A song as a model hears it: its length, a feature set, its beats. A decoded song computes
/// each when asked; a job's song (`crate::song_cache::SongCache`) computes each once per song,
/// stores it with the song, and decodes only when something it needs is not stored yet.
pub trait SongAudio: Sync {
    /// The song's length (s).
    fn duration_s(&self) -> f64;
    /// `set` at `fps`, row i at time `start_s + i / fps`, `n_frames` rows.
    fn features(
        &self,
        set: features::FeatureSet,
        fps: f64,
        start_s: f64,
        n_frames: usize,
    ) -> Result<ndarray::Array2<f32>, AudioError>;
    /// Tempo, beats and downbeats ([`analyze`]).
    fn analysis(&self) -> Result<Analysis, AudioError>;
}

impl SongAudio for DecodedAudio {
    fn duration_s(&self) -> f64 {
        self.duration_s
    }

    fn features(
        &self,
        set: features::FeatureSet,
        fps: f64,
        start_s: f64,
        n_frames: usize,
    ) -> Result<ndarray::Array2<f32>, AudioError> {
        set.compute(self, fps, start_s, n_frames)
    }

    fn analysis(&self) -> Result<Analysis, AudioError> {
        analyze(self)
    }
}

/// What `choreo analyze` prints and `GET /v1/songs/{id}` returns.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct Analysis {
    /// librosa's global tempo for a steady song; for a song whose tempo changes, the median of
    /// `tempo_curve`.
    pub tempo_bpm: f64,
    pub beat_times: Vec<f64>,
    pub downbeat_times: Vec<f64>,
    /// The music's tempo through the song: two points for a steady song, a point every 2 s or
    /// so where the tempo moves (`src/audio/tempo_curve.rs`). Empty in analyses stored before
    /// it existed and for songs without beats.
    #[serde(default)]
    pub tempo_curve: Vec<TempoPoint>,
}

/// One point of an analysis' `tempo_curve`: the tempo (BPM) at `time_s` (s), running linearly to
/// the next point.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct TempoPoint {
    pub time_s: f64,
    pub bpm: f64,
}

/// Errors from decoding or analysing audio.
#[derive(Debug, thiserror::Error)]
pub enum AudioError {
    #[error("not audio, or a format choreo cannot decode: {0}")]
    Undecodable(String),
    #[error("i/o error: {0}")]
    Io(#[from] std::io::Error),
    #[error("the file decodes to no audio samples")]
    Empty,
    #[error("the song is longer than the {limit:.0} s limit ({seconds:.1} s declared or decoded)")]
    TooLong { seconds: f64, limit: f64 },
    #[error(
        "sample rate {0} Hz is outside the supported {MIN_SAMPLE_RATE}..={MAX_SAMPLE_RATE} Hz"
    )]
    UnsupportedSampleRate(u32),
    #[error("audio contains non-finite samples")]
    NonFinite,
    #[error("invalid feature parameters: {0}")]
    InvalidParameter(String),
    #[error("resampling failed: {0}")]
    Resample(String),
    #[error("librosa reference run failed: {0}")]
    Reference(String),
    #[error("{stage} took longer than its {limit_s} s budget and was abandoned")]
    TimedOut { stage: Stage, limit_s: f64 },
    #[error("stopped: the server is shutting down or the job was cancelled")]
    Cancelled,
}

impl AudioError {
    /// Stable kebab-case code for API problem responses.
    pub fn code(&self) -> &'static str {
        match self {
            AudioError::Undecodable(_) => "audio-undecodable",
            AudioError::Io(_) => "audio-io",
            AudioError::Empty => "audio-empty",
            AudioError::TooLong { .. } => "audio-too-long",
            AudioError::UnsupportedSampleRate(_) => "audio-unsupported-sample-rate",
            AudioError::NonFinite => "audio-non-finite",
            AudioError::InvalidParameter(_) => "audio-invalid-parameter",
            AudioError::Resample(_) => "audio-resample",
            AudioError::Reference(_) => "audio-reference",
            AudioError::TimedOut { .. } => "audio-timeout",
            AudioError::Cancelled => "audio-cancelled",
        }
    }

    /// True when the error is the client's audio (4xx), false when it is ours (5xx).
    pub fn is_client_error(&self) -> bool {
        match self {
            AudioError::Undecodable(_)
            | AudioError::Empty
            | AudioError::TooLong { .. }
            | AudioError::UnsupportedSampleRate(_)
            | AudioError::NonFinite
            // Within the size and duration limits a file decodes in a few seconds; one that
            // does not is built to stall the decoder, and another try would stall it again.
            | AudioError::TimedOut { .. } => true,
            AudioError::Io(_)
            | AudioError::Cancelled
            | AudioError::InvalidParameter(_)
            | AudioError::Resample(_)
            | AudioError::Reference(_) => false,
        }
    }
}

/// Decodes a file (any supported format) to mono at its native sample rate.
pub fn decode_path(path: &std::path::Path) -> Result<DecodedAudio, AudioError> {
    decode::decode_path_at(path, None)
}

/// Tempo, beats and downbeats of a song (librosa `beat_track` at 22 050 Hz, hop 512).
pub fn analyze(audio: &DecodedAudio) -> Result<Analysis, AudioError> {
    analyze_within(audio, &Budget::unlimited())
}

/// [`analyze`], checking `budget` between its stages (resampling, mel spectrogram, onsets,
/// tempo, beats, downbeats).
pub fn analyze_within(audio: &DecodedAudio, budget: &Budget) -> Result<Analysis, AudioError> {
    budget.check(Stage::Analyze)?;
    // Decoded at the analysis rate already (the worker does that), the samples are used as they are.
    let y: std::borrow::Cow<[f32]> = if audio.sample_rate == ANALYSIS_SR {
        std::borrow::Cow::Borrowed(&audio.samples)
    } else {
        std::borrow::Cow::Owned(resample(&audio.samples, audio.sample_rate, ANALYSIS_SR)?)
    };
    rhythm::analyze_mono_within(&y, ANALYSIS_SR, HOP_LENGTH, budget)
}
