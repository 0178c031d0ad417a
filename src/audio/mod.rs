//! Music analysis: decode, resample, and librosa-grade features.
//!
//! CONTRACT STUB (lead): the names below are what the rest of the crate calls; the audio
//! owner replaces the bodies and may add fields, not rename.
use serde::{Deserialize, Serialize};

/// The container/codec a song was decoded as, found by decoding, never by extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum AudioFormat { Mp3, Wav, Flac, Ogg, M4a }

/// A decoded song, downmixed to mono at its native sample rate.
#[derive(Clone, Debug)]
pub struct DecodedAudio {
    pub format: AudioFormat,
    pub sample_rate: u32,
    pub channels: u16,
    pub duration_s: f64,
    pub samples: Vec<f32>,
}

/// What `choreo analyze` prints and `GET /v1/songs/{id}` returns.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct Analysis {
    pub tempo_bpm: f64,
    pub beat_times: Vec<f64>,
    pub downbeat_times: Vec<f64>,
}

/// Errors from decoding or analysing audio.
#[derive(Debug, thiserror::Error)]
pub enum AudioError {
    #[error("not audio, or a format choreo cannot decode: {0}")]
    Undecodable(String),
    #[error("i/o error: {0}")]
    Io(#[from] std::io::Error),
}

/// Decodes a file (any supported format) to mono.
pub fn decode_path(_path: &std::path::Path) -> Result<DecodedAudio, AudioError> { todo!("audio owner") }

/// Tempo, beats and downbeats of a song.
pub fn analyze(_audio: &DecodedAudio) -> Result<Analysis, AudioError> { todo!("audio owner") }
