//! The generate pipeline outside the queue: `choreo generate` and `choreo bench generate` run
//! exactly the stages a job runs (decode → model → export + report), with a terminal progress
//! bar or a stage clock instead of a job row.
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use crate::audio::{self, DecodedAudio};
use crate::models::{Cancelled, DanceStyle, GenerateRequest, ModelId, Progress, Registry};
use crate::motion::{KeyPose, Motion};
use crate::report::preview::Caption;
use crate::stage::Stage;

use super::WorkerError;

/// `choreo generate` arguments.
#[derive(Clone, Debug, clap::Args)]
pub struct GenerateArgs {
    /// An mp3, wav, flac, ogg or m4a file.
    pub song: PathBuf,
    /// The model id (see `choreo doctor` or `GET /v1/models`).
    #[arg(long, default_value = "dance-revolution")]
    pub model: String,
    /// Output folder for motion.bvh, motion.json, motion.glb, report.json and preview.png.
    #[arg(long)]
    pub out: PathBuf,
    /// Seeds every random draw: the same seed gives the same dance.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// A JSON file with key poses `[{time_s, joints}]` as the API takes them: 26 joints (a frame of
    /// motion.json), 23 (dataset order), or `bvh: {text, frame}` (models that take them).
    #[arg(long)]
    pub key_poses: Option<PathBuf>,
    /// Where trained models live.
    #[arg(long, default_value = "models")]
    pub models_dir: PathBuf,
    /// Keep the model's motion as it came: do not plant the feet (`motion::feet`).
    #[arg(long)]
    pub no_plant_feet: bool,
    /// The style to dance (models that take one): waltz, rumba, cha-cha or tango. Default: the
    /// model's classifier picks one from the song.
    #[arg(long)]
    pub style: Option<String>,
    /// Sampling temperature (sampling models): 1 is as trained.
    #[arg(long)]
    pub temperature: Option<f64>,
    /// Sample only among the k likeliest choices (models over discrete choices).
    #[arg(long)]
    pub top_k: Option<u32>,
}

/// What one generation produced and how long each stage took.
#[derive(Debug)]
pub struct Generated {
    pub motion: Motion,
    /// motion.bvh, motion.json, motion.glb, report.json and preview.png.
    pub files: Vec<PathBuf>,
    /// `(stage, duration)` in pipeline order.
    pub stages: Vec<(Stage, Duration)>,
}

/// Times each stage a model reports, and forwards fractions to an optional callback.
struct StageClock<'a> {
    current: Option<(Stage, Instant)>,
    done: Vec<(Stage, Duration)>,
    on_progress: &'a mut dyn FnMut(Stage, f32),
}

impl StageClock<'_> {
    fn enter(&mut self, stage: Stage) {
        if self.current.as_ref().is_some_and(|(s, _)| *s == stage) {
            return;
        }
        if let Some((s, t)) = self.current.take() {
            self.done.push((s, t.elapsed()));
        }
        self.current = Some((stage, Instant::now()));
    }

    fn finish(mut self) -> Vec<(Stage, Duration)> {
        if let Some((s, t)) = self.current.take() {
            self.done.push((s, t.elapsed()));
        }
        self.done
    }
}

impl Progress for StageClock<'_> {
    fn report(&mut self, stage: Stage, fraction: f32) -> Result<(), Cancelled> {
        self.enter(stage);
        (self.on_progress)(stage, fraction);
        Ok(())
    }
}

/// Runs model → export → report on a decoded song (named `song` in the preview's title) into
/// `out`, timing every stage.
pub fn generate_decoded(
    registry: &Registry,
    model: &ModelId,
    song: Option<String>,
    request: &GenerateRequest<'_>,
    plant_feet: bool,
    out: &Path,
    on_progress: &mut dyn FnMut(Stage, f32),
) -> Result<Generated, WorkerError> {
    let id = model.0.clone();
    let model = registry.get(model).ok_or_else(|| WorkerError::ModelUnavailable(model.clone()))?;
    let mut clock = StageClock { current: None, done: Vec::new(), on_progress };
    let generated = model.generate(request, &mut clock)?;
    let caption = Caption { model: id, seed: request.seed, song, style: generated.style };
    let motion = crate::motion::finish(generated.motion, plant_feet);
    let files = super::pipeline::render(out, &motion, request.audio, request.key_poses, &caption, &mut |stage| clock.enter(stage))?;
    Ok(Generated { motion, files: files.files.iter().map(|f| out.join(f)).collect(), stages: clock.finish() })
}

/// `choreo generate`: a dance for one song, with a progress bar on stderr.
pub fn generate(args: &GenerateArgs) -> Result<Generated, WorkerError> {
    tch::set_num_threads(std::thread::available_parallelism().map(|n| n.get() as i32).unwrap_or(1));
    let registry = Registry::load(&args.models_dir)?;
    let key_inputs: Vec<crate::motion::input::KeyPoseInput> = match &args.key_poses {
        Some(p) => serde_json::from_str(&std::fs::read_to_string(p)?)
            .map_err(|e| WorkerError::InvalidOptions(format!("{}: {e}", p.display())))?,
        None => Vec::new(),
    };
    let bar = indicatif::ProgressBar::new(1000);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{spinner} {msg:>9} [{bar:40}] {percent:>3}% {elapsed}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    bar.set_message(Stage::DecodeAudio.as_str());
    let t0 = Instant::now();
    let audio = audio::decode_path(&args.song)?;
    let decode = t0.elapsed();
    let frames = crate::motion::validate::song_frames(audio.duration_s, crate::motion::MOTION_FPS);
    let key_poses: Vec<KeyPose> = crate::motion::input::key_poses(&key_inputs, frames, crate::motion::MOTION_FPS)
        .map_err(|e| WorkerError::InvalidOptions(format!("key poses: {e}")))?;
    // Progress over the whole run: decode 0–5%, features 5–25%, encode 25–35%, frame loop 35–90%.
    let span = |stage: Stage| match stage {
        Stage::Claimed | Stage::DecodeAudio | Stage::Analyze => (0.0, 0.05),
        Stage::Features => (0.05, 0.25),
        Stage::Encode => (0.25, 0.35),
        Stage::Generate => (0.35, 0.90),
        Stage::Export | Stage::Report | Stage::Done => (0.90, 0.95),
    };
    let mut on_progress = |stage: Stage, f: f32| {
        let (a, b) = span(stage);
        bar.set_message(stage.as_str());
        bar.set_position(((a + (b - a) * f64::from(f)) * 1000.0) as u64);
    };
    let style = match &args.style {
        Some(s) => Some(DanceStyle::parse(s).ok_or_else(|| WorkerError::InvalidOptions(format!("unknown style `{s}`: one of {}", DanceStyle::names())))?),
        None => None,
    };
    let request = GenerateRequest { key_poses: &key_poses, style, temperature: args.temperature, top_k: args.top_k, ..GenerateRequest::plain(&audio, args.seed) };
    let song = args.song.file_name().map(|n| n.to_string_lossy().into_owned());
    let mut g = generate_decoded(&registry, &ModelId(args.model.clone()), song, &request, !args.no_plant_feet, &args.out, &mut on_progress)?;
    g.stages.insert(0, (Stage::DecodeAudio, decode));
    bar.finish_with_message("done");
    Ok(g)
}

/// `choreo bench generate` arguments.
#[derive(Clone, Debug, clap::Args)]
pub struct BenchArgs {
    /// Models to time (default: every model found).
    #[arg(long)]
    pub model: Vec<String>,
    /// Songs to time; a 3-minute song made by joining them is always added.
    #[arg(long, default_values = ["../shared/audio/vibe_ace.ogg", "../shared/audio/sugar_plum_fairy.ogg", "../shared/audio/lets_go_fishin.ogg"])]
    pub songs: Vec<PathBuf>,
    #[arg(long, default_value = "models")]
    pub models_dir: PathBuf,
    /// libtorch intra-op threads (the service uses 1 per worker).
    #[arg(long, default_value_t = 1)]
    pub threads: i32,
    /// Also time a 90-s and a 420-s song (the given songs joined and looped: none of the shared
    /// songs is 7 minutes long) and print each model's cost ratio beside the length ratio.
    #[arg(long)]
    pub scaling: bool,
}

/// The lengths `--scaling` compares, seconds: a 1.5-minute and a 7-minute song.
pub const SCALING_LENGTHS_S: [u32; 2] = [90, 420];

/// The seconds `choreo bench generate` aims for on a 3-minute song (decode → BVH + report).
pub const TARGET_3MIN_S: f64 = 5.0;

/// `choreo bench generate`: seconds per minute of music, split by stage, for each model.
pub fn bench(args: &BenchArgs) -> Result<String, WorkerError> {
    tch::set_num_threads(args.threads);
    let registry = Registry::load(&args.models_dir)?;
    let models: Vec<ModelId> = if args.model.is_empty() {
        registry.list().into_iter().map(|m| m.id).collect()
    } else {
        args.model.iter().cloned().map(ModelId).collect()
    };
    let mut songs = Vec::new();
    for p in &args.songs {
        let t = Instant::now();
        let a = audio::decode_path(p)?;
        songs.push((p.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default(), a, t.elapsed()));
    }
    // A 3-minute song: the given songs joined (at the first one's rate) and cut to 180 s.
    let mut scaling = Vec::new();
    if let Some((_, first, _)) = songs.first() {
        let sr = first.sample_rate;
        let mut samples = Vec::new();
        for (_, a, _) in &songs {
            if a.sample_rate == sr {
                samples.extend_from_slice(&a.samples);
            }
        }
        samples.truncate(180 * sr as usize);
        let secs = samples.len() as f64 / f64::from(sr);
        let decode_share: Duration = songs.iter().map(|(_, _, d)| *d).sum::<Duration>().mul_f64(secs / songs.iter().map(|(_, a, _)| a.duration_s).sum::<f64>());
        if args.scaling && !samples.is_empty() {
            // The joined songs looped to each length; decode time is charged pro rata.
            let per_s = decode_share.div_f64(secs.max(1e-9));
            for len in SCALING_LENGTHS_S {
                let want = len as usize * sr as usize;
                let looped: Vec<f32> = samples.iter().copied().cycle().take(want).collect();
                let a = DecodedAudio { format: first.format, sample_rate: sr, channels: first.channels, duration_s: f64::from(len), samples: looped };
                scaling.push((format!("looped {len} s"), a, per_s.mul_f64(f64::from(len))));
            }
        }
        let joined = DecodedAudio { format: first.format, sample_rate: sr, channels: first.channels, duration_s: secs, samples };
        songs.push((format!("joined {:.0} s", secs), joined, decode_share));
    }
    let n_timed = songs.len();
    songs.extend(scaling);
    let stage_names = [Stage::DecodeAudio, Stage::Features, Stage::Encode, Stage::Generate, Stage::Export, Stage::Report];
    let mut table = format!(
        "| model | song | music s | {} | total s | s per music min | generate ms per frame | 3-min target |\n|---|---|---|{}---|---|---|---|\n",
        stage_names.map(Stage::as_str).join(" | "),
        "---|".repeat(stage_names.len())
    );
    let out = tempfile::tempdir()?;
    let mut ratios = String::new();
    for model in &models {
        // (music s, total s, decode s) of the scaling songs.
        let mut scaled: Vec<(f64, f64, f64)> = Vec::new();
        for (k, (name, audio, decode)) in songs.iter().enumerate() {
            let request = GenerateRequest::plain(audio, 0);
            let g = generate_decoded(&registry, model, Some(name.clone()), &request, true, out.path(), &mut |_, _| {})?;
            let mut stages = vec![(Stage::DecodeAudio, *decode)];
            stages.extend(g.stages);
            // "–" for a stage this model does not have (the key-pose transformer has no separate encode).
            let get = |s: Stage| {
                let times: Vec<f64> = stages.iter().filter(|(n, _)| *n == s).map(|(_, d)| d.as_secs_f64()).collect();
                if times.is_empty() {
                    "–".to_string()
                } else {
                    format!("{:.2}", times.iter().sum::<f64>())
                }
            };
            let total: f64 = stages.iter().map(|(_, d)| d.as_secs_f64()).sum();
            let per_min = total / (audio.duration_s / 60.0);
            let target = if (audio.duration_s - 180.0).abs() < 1.0 {
                format!("{:.2}× of {TARGET_3MIN_S} s", total / TARGET_3MIN_S)
            } else {
                "-".into()
            };
            let cells: Vec<String> = stage_names.iter().map(|&s| get(s)).collect();
            // The autoregressive loop's cost per motion frame (a TSMT "step").
            let decode_s: f64 = stages.iter().filter(|(n, _)| *n == Stage::Generate).map(|(_, d)| d.as_secs_f64()).sum();
            let frames = (audio.duration_s * crate::motion::MOTION_FPS).floor().max(1.0);
            let per_frame = if decode_s > 0.0 { format!("{:.2}", 1000.0 * decode_s / frames) } else { "–".into() };
            table += &format!("| {} | {name} | {:.0} | {} | {total:.2} | {per_min:.2} | {per_frame} | {target} |\n", model.0, audio.duration_s, cells.join(" | "));
            if k >= n_timed {
                scaled.push((audio.duration_s, total, decode_s));
            }
        }
        if let [(la, ta, da), (lb, tb, db)] = scaled[..] {
            ratios += &format!(
                "{}: {lb:.0} s song / {la:.0} s song: length × {:.2}, total cost × {:.2}, generate × {}\n",
                model.0,
                lb / la,
                tb / ta,
                if da > 0.0 { format!("{:.2}", db / da) } else { "–".into() }
            );
        }
    }
    if !ratios.is_empty() {
        table += "\n";
        table += &ratios;
    }
    Ok(table)
}
