//! The stages of a job: one name per kind of work, from the audio decode to the report.
//!
//! A job's `stage` (the job row, `GET /v1/jobs/{id}`), the models' [`crate::models::Progress`]
//! reports, the audio [`crate::audio::Budget`] (and the stage an [`crate::audio::AudioError::TimedOut`]
//! names), the CLI's stage clock and the `choreo_stage_duration_seconds` metric's `stage` label all
//! speak these names. It lives at the crate root because the lowest layer that uses it is audio's
//! budget, and every layer above speaks it too.
//!
//! The queue writes two states of its own into the same column: [`Stage::Claimed`] (a worker holds
//! the job and has not reported yet) and [`Stage::Done`] (it succeeded).
use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

/// One kind of work a job does, in the order a generate job meets them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "kebab-case")]
pub enum Stage {
    /// A worker claimed the job; no stage has reported yet (written by the queue).
    Claimed,
    /// Decoding the uploaded song to mono samples (symphonia, resampling while streaming).
    DecodeAudio,
    /// Tempo, beats and downbeats of the song (an analyze job's work).
    Analyze,
    /// A model's audio features of the song.
    Features,
    /// A model's encoder over the whole song, before the frame loop.
    Encode,
    /// A model's autoregressive loop, one frame (or key pose) after another.
    Generate,
    /// The network's steps moved onto the song's beats ([`crate::motion::beat_align`]), then the
    /// feet planted ([`crate::motion::finish`]).
    BeatAlign,
    /// The rigid skeleton and the files a client downloads (BVH, JSON, glb).
    Export,
    /// report.json and the preview contact sheet.
    Report,
    /// The job succeeded (written by the queue).
    Done,
}

impl Stage {
    /// Every stage, in the order a generate job meets them.
    pub const ALL: [Stage; 10] = [
        Stage::Claimed,
        Stage::DecodeAudio,
        Stage::Analyze,
        Stage::Features,
        Stage::Encode,
        Stage::Generate,
        Stage::BeatAlign,
        Stage::Export,
        Stage::Report,
        Stage::Done,
    ];

    /// The stable kebab-case name: the job row's value, the metric label, the API's enum.
    pub const fn as_str(self) -> &'static str {
        match self {
            Stage::Claimed => "claimed",
            Stage::DecodeAudio => "decode-audio",
            Stage::Analyze => "analyze",
            Stage::Features => "features",
            Stage::Encode => "encode",
            Stage::Generate => "generate",
            Stage::BeatAlign => "beat-align",
            Stage::Export => "export",
            Stage::Report => "report",
            Stage::Done => "done",
        }
    }

    /// A stored stage, read back: `None` for no stage, and for a name this build does not know
    /// (a row written by another version, or by hand), which is logged and read as no stage
    /// rather than failing the read of the whole job.
    pub fn from_stored(stored: Option<&str>) -> Option<Stage> {
        let s = stored?;
        match s.parse() {
            Ok(stage) => Some(stage),
            Err(e) => {
                tracing::warn!(error = %e, "a stored job stage is not one this build knows; read as none");
                None
            }
        }
    }
}

impl fmt::Display for Stage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        // `pad`, so width and alignment (`{stage:<14}`) apply.
        f.pad(self.as_str())
    }
}

/// A name that is no [`Stage`].
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown stage `{0}`")]
pub struct UnknownStage(pub String);

impl FromStr for Stage {
    type Err = UnknownStage;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Stage::ALL
            .into_iter()
            .find(|stage| stage.as_str() == s)
            .ok_or_else(|| UnknownStage(s.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_name_round_trips_through_str_serde_and_display() {
        for stage in Stage::ALL {
            assert_eq!(stage.as_str().parse::<Stage>(), Ok(stage));
            assert_eq!(
                serde_json::to_value(stage).expect("serialises"),
                serde_json::json!(stage.as_str())
            );
            assert_eq!(
                serde_json::from_value::<Stage>(serde_json::json!(stage.as_str()))
                    .expect("deserialises"),
                stage
            );
            assert_eq!(format!("{stage:<14}|"), format!("{:<14}|", stage.as_str()));
        }
    }

    #[test]
    fn an_unknown_stored_name_reads_as_no_stage() {
        assert_eq!(Stage::from_stored(Some("decode")), None);
        assert_eq!(Stage::from_stored(Some("")), None);
        assert_eq!(Stage::from_stored(None), None);
        // The two states the queue writes itself.
        assert_eq!(Stage::from_stored(Some("claimed")), Some(Stage::Claimed));
        assert_eq!(Stage::from_stored(Some("done")), Some(Stage::Done));
    }
}
