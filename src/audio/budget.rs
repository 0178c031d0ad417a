//! A wall-clock budget and a stop signal for long audio work (decoding, analysis).
//!
//! Work on user audio calls [`Budget::check`] at its checkpoints (every decoded packet, between
//! analysis stages). Past the budget it returns [`AudioError::TimedOut`], and when the stop
//! signal is up (a server shutdown, a cancelled job) [`AudioError::Cancelled`], so the thread
//! doing the work returns instead of burning a core on a file nobody will get an answer for.
use super::AudioError;
use crate::stage::Stage;
use std::time::{Duration, Instant};

/// The limits one piece of audio work runs under.
pub struct Budget<'a> {
    start: Instant,
    limit: Option<Duration>,
    stop: Option<&'a dyn Fn() -> bool>,
}

impl<'a> Budget<'a> {
    /// No time limit and no stop signal (the CLI, tests, offline evaluation).
    pub fn unlimited() -> Self {
        Self {
            start: Instant::now(),
            limit: None,
            stop: None,
        }
    }

    /// A budget of `limit` from now; `stop` returning true ends the work at its next checkpoint.
    pub fn new(limit: Option<Duration>, stop: Option<&'a dyn Fn() -> bool>) -> Self {
        Self {
            start: Instant::now(),
            limit,
            stop,
        }
    }

    /// `Err` when the work must end now: stopped, or past its budget while in `stage`.
    pub fn check(&self, stage: Stage) -> Result<(), AudioError> {
        if self.stop.is_some_and(|stop| stop()) {
            return Err(AudioError::Cancelled);
        }
        match self.limit {
            Some(limit) if self.start.elapsed() > limit => Err(AudioError::TimedOut {
                stage,
                limit_s: limit.as_secs_f64(),
            }),
            _ => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::audio::{analyze_within, AudioFormat, DecodedAudio, ANALYSIS_SR};
    use std::cell::Cell;

    #[test]
    fn stops_when_asked_and_when_over_budget() {
        assert!(Budget::unlimited().check(Stage::DecodeAudio).is_ok());
        let flag = Cell::new(false);
        let stop = || flag.get();
        let budget = Budget::new(Some(Duration::from_secs(60)), Some(&stop));
        assert!(budget.check(Stage::DecodeAudio).is_ok());
        flag.set(true);
        assert!(matches!(
            budget.check(Stage::DecodeAudio),
            Err(AudioError::Cancelled)
        ));
        let over = Budget::new(Some(Duration::ZERO), None);
        std::thread::sleep(Duration::from_millis(2));
        assert!(matches!(
            over.check(Stage::Analyze),
            Err(AudioError::TimedOut {
                stage: Stage::Analyze,
                ..
            })
        ));
    }

    #[test]
    fn an_analysis_stops_between_its_stages() {
        let sr = ANALYSIS_SR;
        let samples: Vec<f32> = (0..sr * 10)
            .map(|i| if i % (sr / 2) < 200 { 0.8 } else { 0.0 })
            .collect();
        let audio = DecodedAudio {
            format: AudioFormat::Wav,
            sample_rate: sr,
            channels: 1,
            duration_s: 10.0,
            samples,
        };
        assert!(
            analyze_within(&audio, &Budget::unlimited()).is_ok_and(|a| !a.beat_times.is_empty())
        );
        // The fourth checkpoint comes after the mel spectrogram: the analysis stops there.
        let calls = Cell::new(0);
        let stop = || {
            calls.set(calls.get() + 1);
            calls.get() >= 4
        };
        let budget = Budget::new(None, Some(&stop));
        assert!(matches!(
            analyze_within(&audio, &budget),
            Err(AudioError::Cancelled)
        ));
        assert_eq!(calls.get(), 4);
    }
}
