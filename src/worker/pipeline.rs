//! The work of each job kind: decode → analyse, or decode → model → export + report.
//!
//! A generate job hears its song through the song's cache ([`crate::song_cache`]): the song is
//! decoded, analysed and turned into the model's features only when its earlier jobs have not
//! stored them.
use super::serve::{after_model, render};
use super::{Execute, WorkerError};
use crate::artifacts::ArtifactStore;
use crate::audio::{self, AudioError, Budget, DecodeOptions, DecodedAudio, Keep, SongAudio};
use crate::config::Config;
use crate::models::{Cancelled, GenerateRequest, Progress, Registry};
use crate::motion::{Motion, MotionStages};
use crate::queue::{DataDir, GenerateOptions, Job, JobKind, Outcome, SeedMotion, Song};
use crate::report::preview::Caption;
use crate::song_cache::{self, CacheFiles, MemoryFiles, SongCache, StoredFiles};
use crate::stage::Stage;
use crate::telemetry::StageTimer;
use std::cell::RefCell;
use std::sync::Arc;
use std::time::Duration;

/// Share of a generate job's progress spent before the model starts (decoding).
const MODEL_START: f32 = 0.1;
/// Share of a generate job's progress done when the model finishes; the rest is export.
const MODEL_END: f32 = 0.85;
/// Where the report and the preview begin: the rigid fit and the BVH, JSON and glb before it
/// take about as long as they do on a 3-minute song.
const REPORT_START: f32 = 0.93;

/// The service's [`Execute`]: real decoding, analysis, models and exporters.
pub struct Pipeline {
    registry: Arc<Registry>,
    data: DataDir,
    /// Song length limit: songs stored before a lower limit are refused, not decoded whole.
    max_duration_s: f64,
    /// Wall-clock budget of one decode and of one analysis.
    audio_timeout: Duration,
    /// Where songs' caches are stored; without it each job computes everything itself.
    song_caches: Option<SongCaches>,
}

/// What a pipeline stores songs' caches with.
#[derive(Clone)]
pub struct SongCaches {
    pub artifacts: Arc<dyn ArtifactStore>,
    /// The bytes a job adds to a song's cache are counted here, in the song's tenant's storage.
    pub store: Arc<dyn crate::queue::Store>,
    /// The worker's runtime, which a job's thread waits on for the stores.
    pub runtime: tokio::runtime::Handle,
}

impl Pipeline {
    /// A pipeline over the loaded models, writing results under `data`.
    pub fn new(registry: Arc<Registry>, data: DataDir, config: &Config) -> Self {
        Self {
            registry,
            data,
            max_duration_s: config.max_duration_s,
            audio_timeout: Duration::from_secs_f64(config.audio_timeout_s),
            song_caches: None,
        }
    }

    /// The same pipeline, keeping each song's decoded features and beats in `caches`.
    pub fn with_song_caches(self, caches: SongCaches) -> Self {
        Self {
            song_caches: Some(caches),
            ..self
        }
    }

    /// Runs `work` under the audio budget, stopping it when the job is cancelled (or the
    /// server stops): the stop signal is the job's own progress checkpoint.
    fn budgeted<T>(
        &self,
        progress: &mut dyn Progress,
        stage: Stage,
        fraction: f32,
        work: impl FnOnce(&Budget) -> Result<T, AudioError>,
    ) -> Result<T, WorkerError> {
        let progress = RefCell::new(progress);
        let stop = || progress.borrow_mut().report(stage, fraction).is_err();
        let budget = Budget::new(Some(self.audio_timeout), Some(&stop));
        Ok(work(&budget)?)
    }

    #[tracing::instrument(skip_all, fields(song_id = %song.id))]
    fn decode(
        &self,
        kind: &'static str,
        song: &Song,
        keep: Keep,
        progress: &mut dyn Progress,
    ) -> Result<DecodedAudio, WorkerError> {
        let _timer = StageTimer::start(kind, Stage::DecodeAudio);
        self.budgeted(progress, Stage::DecodeAudio, 0.0, |budget| {
            self.decode_within(song, keep, budget)
        })
    }

    /// The stored song decoded at `keep`, within `budget` and the song length limit.
    fn decode_within(
        &self,
        song: &Song,
        keep: Keep,
        budget: &Budget,
    ) -> Result<DecodedAudio, AudioError> {
        audio::decode_file(
            &self.data.song_path(song.id, song.format),
            &DecodeOptions {
                keep,
                max_duration_s: self.max_duration_s,
                budget,
            },
        )
        .map(|decoded| decoded.audio)
    }

    #[tracing::instrument(skip_all, fields(job_id = %job.id))]
    fn analyze(
        &self,
        job: &Job,
        song: &Song,
        progress: &mut dyn Progress,
    ) -> Result<Outcome, WorkerError> {
        progress.report(Stage::DecodeAudio, 0.0)?;
        // Decoded straight to the analysis rate: the song never exists at its native rate.
        let decoded = self.decode("analyze", song, Keep::At(audio::ANALYSIS_SR), progress)?;
        progress.report(Stage::Analyze, 0.5)?;
        let _timer = StageTimer::start("analyze", Stage::Analyze);
        let analysis = self.budgeted(progress, Stage::Analyze, 0.5, |budget| {
            audio::analyze_within(&decoded, budget)
        })?;
        Ok(Outcome::Analysis(analysis))
    }

    #[tracing::instrument(skip_all, fields(job_id = %job.id, model = %options.model.0))]
    fn generate(
        &self,
        job: &Job,
        song: &Song,
        options: &GenerateOptions,
        progress: &mut dyn Progress,
    ) -> Result<Outcome, WorkerError> {
        let model = self
            .registry
            .get(&options.model)
            .ok_or_else(|| WorkerError::ModelUnavailable(options.model.clone()))?;
        progress.report(Stage::DecodeAudio, 0.0)?;
        let memory = MemoryFiles::default();
        let stored = self.song_caches.as_ref().map(|c| StoredFiles {
            artifacts: c.artifacts.clone(),
            data: self.data.clone(),
            song: song.id,
            runtime: c.runtime.clone(),
        });
        let files: &dyn CacheFiles = match &stored {
            Some(stored) => stored,
            None => &memory,
        };
        let decode = |budget: &Budget| {
            self.decode_within(song, Keep::AtMost(song_cache::GENERATE_MAX_SR), budget)
        };
        let song_audio = SongCache::new(files, &decode, "generate", Some(self.audio_timeout));
        let outcome = self.dance(job, song, options, model.as_ref(), &song_audio, progress);
        // What the job stored is the song's whatever became of the job. A job with results has
        // the worker count it after them, so the job that filled the cache is held to the
        // storage quota as it stood before.
        let stored = song_audio.stored_bytes();
        match outcome {
            Ok(Outcome::Files(mut files)) => {
                files.song_cache_bytes = stored;
                Ok(Outcome::Files(files))
            }
            other => {
                if let Some(c) = &self.song_caches {
                    c.runtime.block_on(song_cache::count_stored(
                        c.store.as_ref(),
                        c.artifacts.as_ref(),
                        song.id,
                        stored,
                    ));
                }
                other
            }
        }
    }

    /// A generate job's work on its song: analyse → model → motion stages → export + report.
    fn dance(
        &self,
        job: &Job,
        song: &Song,
        options: &GenerateOptions,
        model: &dyn crate::models::DanceModel,
        song_audio: &SongCache<'_>,
        progress: &mut dyn Progress,
    ) -> Result<Outcome, WorkerError> {
        if !song_audio.is_analysed() {
            self.budgeted(progress, Stage::DecodeAudio, 0.0, |budget| {
                song_audio.decode_within(budget)
            })?;
        }
        let seed_motion = options.seed_motion.as_ref().map(seed_motion).transpose()?;
        // The song's beats, once, within the job's budget: a model that listens to them
        // (keypose-transformer's scaffold), the beat-align stage and the report all use these.
        progress.report(Stage::Analyze, MODEL_START)?;
        let analysis = self.budgeted(progress, Stage::Analyze, MODEL_START, |budget| {
            song_audio.analyze_within(budget)
        })?;
        // The model's first stage is its features; each stage it reports is timed as it goes.
        progress.report(Stage::Features, MODEL_START)?;
        let generated = {
            let request = GenerateRequest {
                audio: song_audio,
                seed: options.seed,
                key_poses: &options.key_poses,
                seed_motion: seed_motion.as_ref(),
                style: options.style,
                temperature: options.temperature,
                top_k: options.top_k,
                analysis: Some(&analysis),
            };
            model.generate(
                &request,
                &mut Scaled {
                    inner: progress,
                    from: MODEL_START,
                    to: MODEL_END,
                    timer: None,
                },
            )?
        };
        progress.report(Stage::BeatAlign, MODEL_END)?;
        let style = generated.style.clone();
        let finished = {
            let _timer = StageTimer::start("generate", Stage::BeatAlign);
            let stages = MotionStages {
                beat_align: true,
                plant_feet: options.plant_feet,
                tempo_follow: true,
            };
            after_model(
                generated,
                analysis,
                song_audio.duration_s(),
                &options.key_poses,
                seed_motion.as_ref(),
                stages,
            )?
        };
        progress.report(Stage::Export, MODEL_END)?;
        let _timer = StageTimer::start("generate", Stage::Export);
        let caption = Caption {
            model: options.model.0.clone(),
            seed: options.seed,
            song: Some(song.filename.clone()),
            style,
        };
        let files = render(
            &self.data.job_dir(job.id),
            &finished,
            &options.key_poses,
            &caption,
            &mut |stage| {
                let at = if stage == Stage::Report {
                    REPORT_START
                } else {
                    MODEL_END
                };
                progress.report(stage, at)
            },
        )?;
        Ok(Outcome::Files(files))
    }
}

impl Execute for Pipeline {
    fn execute(
        &self,
        job: &Job,
        song: &Song,
        progress: &mut dyn Progress,
    ) -> Result<Outcome, WorkerError> {
        match &job.kind {
            JobKind::Analyze { .. } => self.analyze(job, song, progress),
            JobKind::Generate(options) => self.generate(job, song, options, progress),
        }
    }
}

/// The slice of the model's share of a job's progress each stage a model reports fills: a
/// model reports each stage's own 0..1, so mapping every stage onto the whole share left a job
/// at its end (85 %) from the last feature row through the whole frame loop. The frame loop,
/// most of a model's time, gets most of the share.
fn model_slice(stage: Stage) -> (f32, f32) {
    match stage {
        Stage::Features => (0.0, 0.1),
        Stage::Encode => (0.1, 0.25),
        Stage::Generate => (0.25, 1.0),
        _ => (0.0, 1.0),
    }
}

/// Maps a model's own 0..1 into a slice of the job's progress, and times each stage the model
/// reports (the timer of one stage is dropped, and recorded, when the next begins), but
/// `features`: the song's cache times that itself, when it computes them rather than reads them.
struct Scaled<'a> {
    inner: &'a mut dyn Progress,
    from: f32,
    to: f32,
    timer: Option<(Stage, StageTimer)>,
}

impl Progress for Scaled<'_> {
    fn report(&mut self, stage: Stage, fraction: f32) -> Result<(), Cancelled> {
        if self.timer.as_ref().is_none_or(|(s, _)| *s != stage) {
            self.timer = None;
            if stage != Stage::Features {
                self.timer = Some((stage, StageTimer::start("generate", stage)));
            }
        }
        let fraction = if fraction.is_finite() {
            fraction.clamp(0.0, 1.0)
        } else {
            0.0
        };
        let (lo, hi) = model_slice(stage);
        self.inner.report(
            stage,
            self.from + (self.to - self.from) * (lo + (hi - lo) * fraction),
        )
    }
}

/// Turns the API's seed motion into the model's `Motion`, checking its shape.
fn seed_motion(seed: &SeedMotion) -> Result<Motion, WorkerError> {
    let frames = seed.positions.len();
    let joints = seed.positions.first().map_or(0, Vec::len);
    if frames == 0
        || joints != crate::motion::NUM_JOINTS
        || seed.positions.iter().any(|f| f.len() != joints)
    {
        return Err(WorkerError::InvalidOptions(format!(
            "seed_motion.positions must be T × {} × 3 with T ≥ 1",
            crate::motion::NUM_JOINTS
        )));
    }
    let flat: Vec<f32> = seed
        .positions
        .iter()
        .flatten()
        .flat_map(|p| p.iter().map(|&v| v as f32))
        .collect();
    let positions = ndarray::Array3::from_shape_vec((frames, joints, 3), flat)
        .map_err(|e| WorkerError::InvalidOptions(format!("seed_motion: {e}")))?;
    Ok(Motion {
        fps: seed.fps,
        positions,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::audio::AudioFormat;
    use crate::queue::{JobFiles, JobId, SongId, Status};

    /// A mono 16-bit WAV of a 440 Hz tone.
    fn wav(sr: u32, seconds: u32) -> Vec<u8> {
        let n = sr * seconds;
        let mut b = Vec::with_capacity(44 + 2 * n as usize);
        b.extend_from_slice(b"RIFF");
        b.extend_from_slice(&(36 + 2 * n).to_le_bytes());
        b.extend_from_slice(b"WAVEfmt ");
        b.extend_from_slice(&16u32.to_le_bytes());
        b.extend_from_slice(&1u16.to_le_bytes()); // PCM
        b.extend_from_slice(&1u16.to_le_bytes()); // mono
        b.extend_from_slice(&sr.to_le_bytes());
        b.extend_from_slice(&(2 * sr).to_le_bytes());
        b.extend_from_slice(&2u16.to_le_bytes());
        b.extend_from_slice(&16u16.to_le_bytes());
        b.extend_from_slice(b"data");
        b.extend_from_slice(&(2 * n).to_le_bytes());
        for i in 0..n {
            let v = (f64::from(i) * 440.0 * std::f64::consts::TAU / f64::from(sr)).sin() * 8000.0;
            b.extend_from_slice(&(v as i16).to_le_bytes());
        }
        b
    }

    /// What a job's progress reads as a model reports its stages.
    #[derive(Default)]
    struct Record(Vec<(Stage, f32)>);

    impl Progress for Record {
        fn report(&mut self, stage: Stage, fraction: f32) -> Result<(), Cancelled> {
            self.0.push((stage, fraction));
            Ok(())
        }
    }

    /// Features, then the encoder, then the frame loop: the job's progress rises through each,
    /// the frame loop taking most of the model's share, and never goes back.
    #[test]
    fn progress_rises_through_each_stage_a_model_reports() {
        let mut record = Record::default();
        let mut scaled = Scaled {
            inner: &mut record,
            from: MODEL_START,
            to: MODEL_END,
            timer: None,
        };
        for (stage, fraction) in [
            (Stage::Features, 0.0),
            (Stage::Features, 1.0),
            (Stage::Encode, 1.0),
            (Stage::Generate, 0.0),
            (Stage::Generate, 0.5),
            (Stage::Generate, 1.0),
        ] {
            scaled.report(stage, fraction).expect("not cancelled");
        }
        let p: Vec<f32> = record.0.iter().map(|(_, p)| *p).collect();
        assert!(p.windows(2).all(|w| w[0] <= w[1]), "{p:?}");
        assert!((p[0] - MODEL_START).abs() < 1e-6 && (p[5] - MODEL_END).abs() < 1e-6);
        // Half the frame loop is past half the model's share, and the loop spans most of it.
        assert!(
            p[4] > MODEL_START + 0.5 * (MODEL_END - MODEL_START),
            "{p:?}"
        );
        assert!(p[5] - p[3] > 0.7 * (MODEL_END - MODEL_START), "{p:?}");
    }

    /// Stops at its `stop_after`-th checkpoint.
    struct StopAfter(usize);

    impl Progress for StopAfter {
        fn report(&mut self, _stage: Stage, _fraction: f32) -> Result<(), Cancelled> {
            if self.0 == 0 {
                return Err(Cancelled);
            }
            self.0 -= 1;
            Ok(())
        }
    }

    fn setup(timeout_s: f64) -> (tempfile::TempDir, Pipeline, Job, Song) {
        let dir = tempfile::tempdir().expect("tempdir");
        let data = DataDir::create(&dir.path().join("data")).expect("data dir");
        let registry = Arc::new(Registry::load(&dir.path().join("no-models")).expect("registry"));
        let config = Config {
            audio_timeout_s: timeout_s,
            ..Config::default()
        };
        let song = Song {
            id: SongId::new(),
            tenant: crate::queue::TenantId::OPEN,
            filename: "tone.wav".into(),
            format: AudioFormat::Wav,
            duration_s: 30.0,
            sample_rate: 44_100,
            channels: 1,
            sha256: "tone".into(),
            size_bytes: 0,
            analysis: None,
            created_at: chrono::Utc::now(),
        };
        std::fs::write(data.song_path(song.id, song.format), wav(44_100, 30)).expect("write song");
        let job = Job {
            id: JobId::new(),
            tenant: crate::queue::TenantId::OPEN,
            kind: JobKind::Analyze { song_id: song.id },
            status: Status::Running,
            stage: None,
            progress: 0.0,
            priority: 0,
            attempts: 1,
            max_attempts: 3,
            cancel_requested: false,
            error: None,
            files: JobFiles::default(),
            created_at: chrono::Utc::now(),
            started_at: None,
            finished_at: None,
        };
        (dir, Pipeline::new(registry, data, &config), job, song)
    }

    #[test]
    fn an_analysis_past_its_budget_fails_and_is_not_retried() {
        let (_dir, pipeline, job, song) = setup(1e-6);
        let err = pipeline
            .execute(&job, &song, &mut StopAfter(usize::MAX))
            .expect_err("over budget");
        assert!(
            matches!(err, WorkerError::Audio(AudioError::TimedOut { .. })),
            "{err}"
        );
        assert!(!err.is_retryable());
        assert_eq!(err.code(), "audio-timeout");
    }

    #[test]
    fn a_cancel_stops_the_decode_at_its_next_packet() {
        // The job's first two checkpoints pass (decode and its first packet); the third stops it
        // inside the decode, long before the 30 s song is through.
        let (_dir, pipeline, job, song) = setup(60.0);
        let err = pipeline
            .execute(&job, &song, &mut StopAfter(2))
            .expect_err("cancelled");
        assert!(matches!(err, WorkerError::Cancelled), "{err}");
        let analysis = pipeline
            .execute(&job, &song, &mut StopAfter(usize::MAX))
            .expect("analyses");
        assert!(matches!(analysis, Outcome::Analysis(a) if (a.tempo_bpm).is_finite()));
    }
}
