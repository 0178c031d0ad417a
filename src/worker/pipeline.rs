//! The work of each job kind: decode → analyse, or decode → model → export + report.
use super::{Execute, WorkerError};
use crate::audio::{self, AudioError, Budget, DecodeOptions, DecodedAudio, Keep};
use crate::config::Config;
use crate::models::{Cancelled, GenerateRequest, Progress, Registry};
use crate::motion::{KeyPose, Motion};
use crate::queue::{DataDir, GenerateOptions, Job, JobFiles, JobKind, Outcome, SeedMotion, Song};
use crate::telemetry::StageTimer;
use std::cell::RefCell;
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

/// Share of a generate job's progress spent before the model starts (decoding).
const MODEL_START: f32 = 0.1;
/// Share of a generate job's progress done when the model finishes; the rest is export.
const MODEL_END: f32 = 0.85;

/// Highest rate a generate job keeps the song at: the models' feature grids resample to at
/// most 22 050 Hz, so more only costs memory (a 15-minute song at 384 kHz would be 1.4 GB).
const GENERATE_MAX_SR: u32 = 48_000;

/// The service's [`Execute`]: real decoding, analysis, models and exporters.
pub struct Pipeline {
    registry: Arc<Registry>,
    data: DataDir,
    /// Song length limit: songs stored before a lower limit are refused, not decoded whole.
    max_duration_s: f64,
    /// Wall-clock budget of one decode and of one analysis.
    audio_timeout: Duration,
}

impl Pipeline {
    /// A pipeline over the loaded models, writing results under `data`.
    pub fn new(registry: Arc<Registry>, data: DataDir, config: &Config) -> Self {
        Self {
            registry,
            data,
            max_duration_s: config.max_duration_s,
            audio_timeout: Duration::from_secs_f64(config.audio_timeout_s),
        }
    }

    /// Runs `work` under the audio budget, stopping it when the job is cancelled (or the
    /// server stops): the stop signal is the job's own progress checkpoint.
    fn budgeted<T>(
        &self,
        progress: &mut dyn Progress,
        stage: &'static str,
        fraction: f32,
        work: impl FnOnce(&Budget) -> Result<T, AudioError>,
    ) -> Result<T, WorkerError> {
        let progress = RefCell::new(progress);
        let stop = || progress.borrow_mut().report(stage, fraction).is_err();
        let budget = Budget::new(Some(self.audio_timeout), Some(&stop));
        Ok(work(&budget)?)
    }

    #[tracing::instrument(skip_all, fields(song_id = %song.id))]
    fn decode(&self, kind: &'static str, song: &Song, keep: Keep, progress: &mut dyn Progress) -> Result<DecodedAudio, WorkerError> {
        let _timer = StageTimer::start(kind, "decode");
        let path = self.data.song_path(song.id, song.format);
        let max_duration_s = self.max_duration_s;
        let decoded = self.budgeted(progress, "decode", 0.0, |budget| {
            audio::decode_file(&path, &DecodeOptions { keep, max_duration_s, budget })
        })?;
        Ok(decoded.audio)
    }

    #[tracing::instrument(skip_all, fields(job_id = %job.id))]
    fn analyze(&self, job: &Job, song: &Song, progress: &mut dyn Progress) -> Result<Outcome, WorkerError> {
        progress.report("decode", 0.0)?;
        // Decoded straight to the analysis rate: the song never exists at its native rate.
        let decoded = self.decode("analyze", song, Keep::At(audio::ANALYSIS_SR), progress)?;
        progress.report("analyze", 0.5)?;
        let _timer = StageTimer::start("analyze", "analyze");
        let analysis = self.budgeted(progress, "analyze", 0.5, |budget| audio::analyze_within(&decoded, budget))?;
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
        let model = self.registry.get(&options.model).ok_or_else(|| WorkerError::ModelUnavailable(options.model.clone()))?;
        progress.report("decode", 0.0)?;
        let decoded = self.decode("generate", song, Keep::AtMost(GENERATE_MAX_SR), progress)?;
        let seed_motion = options.seed_motion.as_ref().map(seed_motion).transpose()?;
        progress.report("model", MODEL_START)?;
        let motion = {
            let _timer = StageTimer::start("generate", "model");
            let request = GenerateRequest {
                audio: &decoded,
                seed: options.seed,
                key_poses: &options.key_poses,
                seed_motion: seed_motion.as_ref(),
            };
            model.generate(&request, &mut Scaled { inner: progress, from: MODEL_START, to: MODEL_END })?
        };
        let motion = crate::motion::finish(motion, options.plant_feet);
        progress.report("export", MODEL_END)?;
        let _timer = StageTimer::start("generate", "export");
        let files = render(&self.data.job_dir(job.id), &motion, &decoded, &options.key_poses, &mut |_| {})?;
        Ok(Outcome::Files(files))
    }
}

impl Execute for Pipeline {
    fn execute(&self, job: &Job, song: &Song, progress: &mut dyn Progress) -> Result<Outcome, WorkerError> {
        match &job.kind {
            JobKind::Analyze { .. } => self.analyze(job, song, progress),
            JobKind::Generate(options) => self.generate(job, song, options, progress),
        }
    }
}

/// Maps a model's own 0..1 into a slice of the job's progress.
struct Scaled<'a> {
    inner: &'a mut dyn Progress,
    from: f32,
    to: f32,
}

impl Progress for Scaled<'_> {
    fn report(&mut self, stage: &str, fraction: f32) -> Result<(), Cancelled> {
        let fraction = if fraction.is_finite() { fraction.clamp(0.0, 1.0) } else { 0.0 };
        self.inner.report(stage, self.from + (self.to - self.from) * fraction)
    }
}

/// Turns the API's seed motion into the model's `Motion`, checking its shape.
fn seed_motion(seed: &SeedMotion) -> Result<Motion, WorkerError> {
    let frames = seed.positions.len();
    let joints = seed.positions.first().map_or(0, Vec::len);
    if frames == 0 || joints != crate::motion::NUM_JOINTS || seed.positions.iter().any(|f| f.len() != joints) {
        return Err(WorkerError::InvalidOptions(format!(
            "seed_motion.positions must be T × {} × 3 with T ≥ 1",
            crate::motion::NUM_JOINTS
        )));
    }
    let flat: Vec<f32> = seed.positions.iter().flatten().flat_map(|p| p.iter().map(|&v| v as f32)).collect();
    let positions = ndarray::Array3::from_shape_vec((frames, joints, 3), flat)
        .map_err(|e| WorkerError::InvalidOptions(format!("seed_motion: {e}")))?;
    Ok(Motion { fps: seed.fps, positions })
}

/// File name of a generate job's report.
pub const REPORT_FILE: &str = "report.json";

/// The last two stages of a dance, shared by jobs and the CLI: export (BVH, JSON, glb) and the
/// report, each file written atomically into `dir`. `on_stage` hears each stage as it starts.
pub fn render(
    dir: &Path,
    motion: &Motion,
    audio: &DecodedAudio,
    key_poses: &[KeyPose],
    on_stage: &mut dyn FnMut(&str),
) -> Result<JobFiles, WorkerError> {
    use crate::motion::export::{write_all, write_atomic, BVH_FILE, GLB_FILE, JSON_FILE};
    std::fs::create_dir_all(dir)?;
    on_stage("export");
    write_all(motion, dir)?;
    on_stage("report");
    let analysis = audio::analyze(audio)?;
    let reference = crate::metrics::reference::ReferenceStats::builtin()?;
    let report = crate::report::build(motion, &analysis, key_poses, &reference)?;
    let text = serde_json::to_vec_pretty(&report).map_err(|e| WorkerError::Export(format!("report.json: {e}")))?;
    write_atomic(&dir.join(REPORT_FILE), &text)?;
    Ok(JobFiles { files: [BVH_FILE, JSON_FILE, GLB_FILE, REPORT_FILE].map(String::from).to_vec() })
}
