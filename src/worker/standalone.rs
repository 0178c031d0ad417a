//! The generate pipeline outside the queue: `choreo generate` and `choreo bench generate` run
//! exactly the stages a job runs (decode → model → analysis → beat-align + feet → export + report), reporting to a callback
//! (the CLI's progress bar) or a stage clock instead of a job row.
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use crate::audio::{self, DecodedAudio};
use crate::models::{Cancelled, DanceStyle, GenerateRequest, ModelId, Progress, Registry};
use crate::motion::{KeyPose, Motion, MotionStages};
use crate::report::preview::Caption;
use crate::stage::Stage;

use super::WorkerError;

/// A dance for one song file (`choreo generate`).
#[derive(Clone, Debug)]
pub struct GenerateSong {
    /// An mp3, wav, flac, ogg or m4a file.
    pub song: PathBuf,
    /// The model id (see `choreo doctor` or `GET /v1/models`).
    pub model: String,
    /// Output folder for motion.bvh, motion.json, motion.glb, report.json and preview.png.
    pub out: PathBuf,
    /// Seeds every random draw: the same seed gives the same dance.
    pub seed: u64,
    /// A JSON file with key poses `[{time_s, joints}]` as the API takes them: 26 joints (a frame of
    /// motion.json), 23 (dataset order), or `bvh: {text, frame}` (models that take them).
    pub key_poses: Option<PathBuf>,
    /// Where trained models live.
    pub models_dir: PathBuf,
    /// Keep the model's motion as it came: do not plant the feet (`motion::feet`).
    pub no_plant_feet: bool,
    /// Keep the network's timing: do not move its steps onto the song's beats
    /// (`motion::beat_align`), to see what the network does on its own.
    pub no_beat_align: bool,
    /// The style to dance (models that take one): waltz, rumba, cha-cha or tango. `None`: the
    /// model's classifier picks one from the song.
    pub style: Option<String>,
    /// Sampling temperature (sampling models): 1 is as trained.
    pub temperature: Option<f64>,
    /// Sample only among the k likeliest choices (models over discrete choices).
    pub top_k: Option<u32>,
}

impl Default for GenerateSong {
    /// The CLI's defaults; `song` and `out` are empty paths (always given).
    fn default() -> Self {
        Self {
            song: PathBuf::new(),
            // The server's default, first in `GET /v1/models` and on the page.
            model: crate::models::MODELS[0].id.into(),
            out: PathBuf::new(),
            seed: 0,
            key_poses: None,
            models_dir: PathBuf::from("models"),
            no_plant_feet: false,
            no_beat_align: false,
            style: None,
            temperature: None,
            top_k: None,
        }
    }
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

/// The message of [`WorkerError::ModelNotInFolder`]: the models found, the folder searched,
/// and the nearest id when the one asked for looks like a misspelling of it.
pub(crate) fn not_in_folder(model: &ModelId, dir: &std::path::Path, found: &[String]) -> String {
    let asked = &model.0;
    let mut message = if found.is_empty() {
        format!(
            "model {asked} is not available: {} holds no trained model (train one with \
             `choreo train`, or point --models-dir at a folder that holds one)",
            dir.display()
        )
    } else {
        format!(
            "model {asked} is not available in {}, which holds {}",
            dir.display(),
            found.join(", ")
        )
    };
    if let Some(near) = nearest(asked, found) {
        message.push_str(&format!("; did you mean {near}?"));
    } else if crate::models::MODELS.iter().any(|m| m.id == asked) {
        message.push_str(&format!(
            "; {asked} is a model choreo knows, but its folder there has no weights"
        ));
    }
    message
}

/// The id in `ids` nearest `asked` by edit distance, when within a third of its length (two
/// letters swapped or one dropped, not a different name).
pub fn nearest<'a>(asked: &str, ids: &'a [String]) -> Option<&'a str> {
    ids.iter()
        .map(|id| (strsim::levenshtein(asked, id), id))
        .filter(|(d, _)| *d > 0 && *d <= (asked.len() / 3).max(2))
        .min_by_key(|(d, _)| *d)
        .map(|(_, id)| id.as_str())
}

/// Runs model → analysis → beat-align + feet → export → report on a decoded song (named `song` in
/// the preview's title) into `out`, timing every stage.
pub fn generate_decoded(
    registry: &Registry,
    model: &ModelId,
    song: Option<String>,
    request: &GenerateRequest<'_>,
    stages: MotionStages,
    out: &Path,
    on_progress: &mut dyn FnMut(Stage, f32),
) -> Result<Generated, WorkerError> {
    let id = model.0.clone();
    let model = registry
        .get(model)
        .ok_or_else(|| WorkerError::ModelUnavailable(model.clone()))?;
    let mut clock = StageClock {
        current: None,
        done: Vec::new(),
        on_progress,
    };
    // The song's beats, once, before the model (as a job does): the model may listen to them, the
    // beat-align stage and the report use them.
    clock.report(Stage::Analyze, 0.0)?;
    let analysis = request.analysis_or_analyze()?;
    let generated = model.generate(
        &GenerateRequest {
            analysis: Some(&analysis),
            ..*request
        },
        &mut clock,
    )?;
    let caption = Caption {
        model: id,
        seed: request.seed,
        song,
        style: generated.style.clone(),
    };
    let analysis = analysis.into_owned();
    clock.report(Stage::BeatAlign, 0.0)?;
    let finished = super::serve::after_model(
        generated,
        analysis,
        request.audio.duration_s(),
        request.key_poses,
        request.seed_motion,
        stages,
    )?;
    let files = super::serve::render(out, &finished, request.key_poses, &caption, &mut |stage| {
        clock.enter(stage);
        Ok(())
    })?;
    Ok(Generated {
        motion: finished.motion,
        files: files.files.iter().map(|f| out.join(f)).collect(),
        stages: clock.finish(),
    })
}

/// `choreo generate`: a dance for one song. `on_progress` hears the stage and the share of the
/// whole run done (0..1), for a progress bar.
pub fn generate(
    args: &GenerateSong,
    on_progress: &mut dyn FnMut(Stage, f64),
) -> Result<Generated, WorkerError> {
    tch::set_num_threads(
        std::thread::available_parallelism()
            .map(|n| n.get() as i32)
            .unwrap_or(1),
    );
    let registry = Registry::load(&args.models_dir)?;
    // Checked before the song is decoded, so a misspelt --model fails at once.
    let model = ModelId(args.model.clone());
    if registry.get(&model).is_none() {
        return Err(WorkerError::ModelNotInFolder {
            model,
            dir: args.models_dir.clone(),
            found: registry.list().into_iter().map(|m| m.id.0).collect(),
        });
    }
    let key_inputs: Vec<crate::motion::input::KeyPoseInput> = match &args.key_poses {
        Some(p) => serde_json::from_str(&std::fs::read_to_string(p)?)
            .map_err(|e| WorkerError::InvalidOptions(format!("{}: {e}", p.display())))?,
        None => Vec::new(),
    };
    on_progress(Stage::DecodeAudio, 0.0);
    let t0 = Instant::now();
    let audio = audio::decode_path(&args.song)?;
    let decode = t0.elapsed();
    let frames = crate::motion::validate::song_frames(audio.duration_s, crate::motion::MOTION_FPS);
    let key_poses: Vec<KeyPose> =
        crate::motion::input::key_poses(&key_inputs, frames, crate::motion::MOTION_FPS)
            .map_err(|e| WorkerError::InvalidOptions(format!("key poses: {e}")))?;
    // Progress over the whole run: decode 0–5%, features 5–25%, encode 25–35%, frame loop 35–90%.
    let span = |stage: Stage| match stage {
        Stage::Claimed | Stage::DecodeAudio => (0.0, 0.05),
        // The song's beats, before the model (for it, the beat-align stage and the report).
        Stage::Analyze => (0.05, 0.08),
        Stage::Features => (0.08, 0.25),
        Stage::Encode => (0.25, 0.35),
        Stage::Generate => (0.35, 0.88),
        Stage::BeatAlign => (0.88, 0.90),
        Stage::Export | Stage::Report | Stage::Done => (0.90, 0.95),
    };
    let mut on_stage_progress = |stage: Stage, f: f32| {
        let (a, b) = span(stage);
        on_progress(stage, a + (b - a) * f64::from(f));
    };
    let style = match &args.style {
        Some(s) => Some(DanceStyle::parse(s).ok_or_else(|| {
            WorkerError::InvalidOptions(format!(
                "unknown style `{s}`: one of {}",
                DanceStyle::names()
            ))
        })?),
        None => None,
    };
    let request = GenerateRequest {
        key_poses: &key_poses,
        style,
        temperature: args.temperature,
        top_k: args.top_k,
        ..GenerateRequest::plain(&audio, args.seed)
    };
    let song = args
        .song
        .file_name()
        .map(|n| n.to_string_lossy().into_owned());
    let stages = MotionStages {
        beat_align: !args.no_beat_align,
        plant_feet: !args.no_plant_feet,
        tempo_follow: true,
    };
    let mut g = generate_decoded(
        &registry,
        &model,
        song,
        &request,
        stages,
        &args.out,
        &mut on_stage_progress,
    )?;
    g.stages.insert(0, (Stage::DecodeAudio, decode));
    Ok(g)
}

/// What `choreo bench generate` times. `Default` is the committed benchmark.
#[derive(Clone, Debug)]
pub struct BenchOptions {
    /// Models to time (empty: every model found).
    pub model: Vec<String>,
    /// Songs to time; a 3-minute song made by joining them is always added.
    pub songs: Vec<PathBuf>,
    /// Where trained models live.
    pub models_dir: PathBuf,
    /// libtorch intra-op threads (the service uses 1 per worker).
    pub threads: i32,
    /// Also time a 90-s and a 420-s song (the given songs joined and looped: none of the shared
    /// songs is 7 minutes long) and print each model's cost ratio beside the length ratio.
    pub scaling: bool,
}

impl Default for BenchOptions {
    fn default() -> Self {
        Self {
            model: Vec::new(),
            songs: [
                "../shared/audio/vibe_ace.ogg",
                "../shared/audio/sugar_plum_fairy.ogg",
                "../shared/audio/lets_go_fishin.ogg",
            ]
            .map(PathBuf::from)
            .to_vec(),
            models_dir: PathBuf::from("models"),
            threads: 1,
            scaling: false,
        }
    }
}

/// The lengths `--scaling` compares, seconds: a 1.5-minute and a 7-minute song.
pub const SCALING_LENGTHS_S: [u32; 2] = [90, 420];

/// The seconds `choreo bench generate` aims for on a 3-minute song (decode → BVH + report, one
/// thread): 100× real time.
pub const TARGET_3MIN_S: f64 = 1.8;

/// `choreo bench generate`: seconds per minute of music, split by stage, for each model.
pub fn bench(args: &BenchOptions) -> Result<String, WorkerError> {
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
        songs.push((
            p.file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default(),
            a,
            t.elapsed(),
        ));
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
        let decode_share: Duration = songs
            .iter()
            .map(|(_, _, d)| *d)
            .sum::<Duration>()
            .mul_f64(secs / songs.iter().map(|(_, a, _)| a.duration_s).sum::<f64>());
        if args.scaling && !samples.is_empty() {
            // The joined songs looped to each length; decode time is charged pro rata.
            let per_s = decode_share.div_f64(secs.max(1e-9));
            for len in SCALING_LENGTHS_S {
                let want = len as usize * sr as usize;
                let looped: Vec<f32> = samples.iter().copied().cycle().take(want).collect();
                let a = DecodedAudio {
                    format: first.format,
                    sample_rate: sr,
                    channels: first.channels,
                    duration_s: f64::from(len),
                    samples: looped,
                };
                scaling.push((format!("looped {len} s"), a, per_s.mul_f64(f64::from(len))));
            }
        }
        let joined = DecodedAudio {
            format: first.format,
            sample_rate: sr,
            channels: first.channels,
            duration_s: secs,
            samples,
        };
        songs.push((format!("joined {:.0} s", secs), joined, decode_share));
    }
    let n_timed = songs.len();
    songs.extend(scaling);
    let stage_names = [
        Stage::DecodeAudio,
        Stage::Features,
        Stage::Encode,
        Stage::Generate,
        Stage::Analyze,
        Stage::BeatAlign,
        Stage::Export,
        Stage::Report,
    ];
    let mut table = format!(
        "| model | song | music s | {} | total s | s per music min | generate ms per frame | 3-min target |\n|---|---|---|{}---|---|---|---|\n",
        stage_names.map(Stage::as_str).join(" | "),
        "---|".repeat(stage_names.len())
    );
    let out = tempfile::tempdir()?;
    let mut ratios = String::new();
    // Per model: the frame loop's ms per frame on the 3-minute song.
    let mut loop_ms: Vec<(ModelId, f64)> = Vec::new();
    for model in &models {
        // (music s, total s, decode s) of the scaling songs.
        let mut scaled: Vec<(f64, f64, f64)> = Vec::new();
        for (k, (name, audio, decode)) in songs.iter().enumerate() {
            let request = GenerateRequest::plain(audio, 0);
            let g = generate_decoded(
                &registry,
                model,
                Some(name.clone()),
                &request,
                MotionStages::default(),
                out.path(),
                &mut |_, _| {},
            )?;
            let mut stages = vec![(Stage::DecodeAudio, *decode)];
            stages.extend(g.stages);
            // "–" for a stage this model does not have (the key-pose transformer has no separate encode).
            let get = |s: Stage| {
                let times: Vec<f64> = stages
                    .iter()
                    .filter(|(n, _)| *n == s)
                    .map(|(_, d)| d.as_secs_f64())
                    .collect();
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
            let decode_s: f64 = stages
                .iter()
                .filter(|(n, _)| *n == Stage::Generate)
                .map(|(_, d)| d.as_secs_f64())
                .sum();
            let frames =
                crate::motion::validate::song_frames(audio.duration_s, crate::motion::MOTION_FPS)
                    as f64;
            let ms_per_frame = (decode_s > 0.0).then(|| 1000.0 * decode_s / frames);
            if let Some(ms) = ms_per_frame.filter(|_| (audio.duration_s - 180.0).abs() < 1.0) {
                loop_ms.push((model.clone(), ms));
            }
            let per_frame = ms_per_frame.map_or("–".into(), |ms| format!("{ms:.2}"));
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
    if !loop_ms.is_empty() {
        table += "\n";
        table += &flop_bound(&registry, &loop_ms);
    }
    if let Some((name, audio, decode)) = songs.get(n_timed.saturating_sub(1)) {
        table += "\n";
        table += &bench_song_cache(&registry, &models, name, audio, *decode, out.path())?;
    }
    Ok(table)
}

/// Each model's frame loop against the arithmetic it does: its FLOPs per frame
/// ([`crate::models::DanceModel::frame_flops`]), the rate its measured ms per frame makes of them
/// (the generate stage's time over the song's frames: frames drawn by the serving checks and
/// thrown away are in the time, so the rate is what a served frame costs), and that rate's share
/// of what one core reaches in libtorch's matrix product on the same threads (measured here, so
/// the ratio is of this machine at this moment). A loop far below the
/// peak is spent on per-operation overhead, not arithmetic: the headroom a fused or batched loop
/// could take.
fn flop_bound(registry: &Registry, loop_ms: &[(ModelId, f64)]) -> String {
    let peak = gemm_gflops();
    let mut table = format!(
        "| model | loop MFLOP per frame | loop ms per frame (3-min song) | loop GFLOP/s | share of one core's peak ({peak:.1} GFLOP/s, 512² matmul) | FLOP-bound ms per frame |\n|---|---|---|---|---|---|\n"
    );
    for (id, ms) in loop_ms {
        let Some(flops) = registry.get(id).and_then(|m| m.frame_flops()) else {
            table += &format!("| {} | – | {ms:.3} | – | – | – |\n", id.0);
            continue;
        };
        let rate = flops / (ms / 1000.0) / 1e9;
        table += &format!(
            "| {} | {:.2} | {ms:.3} | {rate:.2} | {:.1} % | {:.3} |\n",
            id.0,
            flops / 1e6,
            100.0 * rate / peak,
            1000.0 * flops / (peak * 1e9),
        );
    }
    table
}

/// GFLOP/s of a 512 × 512 single-precision matrix product in libtorch on its current threads:
/// the best of five timed rounds of eight products, after one untimed.
fn gemm_gflops() -> f64 {
    const N: i64 = 512;
    const PRODUCTS: u32 = 8;
    let opts = (tch::Kind::Float, tch::Device::Cpu);
    let (a, b) = (
        tch::Tensor::randn([N, N], opts),
        tch::Tensor::randn([N, N], opts),
    );
    let _ = a.matmul(&b);
    let best = (0..5)
        .map(|_| {
            let t = Instant::now();
            for _ in 0..PRODUCTS {
                let _ = a.matmul(&b);
            }
            t.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min);
    2.0 * (N as f64).powi(3) * f64::from(PRODUCTS) / best / 1e9
}

/// A job's seconds on `audio` (decoding it took `decode`) through an empty song cache, then
/// through the cache that job filled (as a second job with another seed on the same song).
fn bench_song_cache(
    registry: &Registry,
    models: &[ModelId],
    name: &str,
    audio: &DecodedAudio,
    decode: Duration,
    out: &Path,
) -> Result<String, WorkerError> {
    use crate::song_cache::{MemoryFiles, SongCache};
    use std::sync::atomic::{AtomicBool, Ordering};
    let mut table = String::from(
        "| model | song | job s, song computed | job s, song from its cache | saved s |\n|---|---|---|---|---|\n",
    );
    for model in models {
        let files = MemoryFiles::default();
        let decoded = AtomicBool::new(false);
        let decode_song = |_: &audio::Budget| {
            decoded.store(true, Ordering::Relaxed);
            Ok(audio.clone())
        };
        let mut job_s = Vec::new();
        for seed in [0, 1] {
            decoded.store(false, Ordering::Relaxed);
            let t = Instant::now();
            let cache = SongCache::new(&files, &decode_song, "bench", None);
            generate_decoded(
                registry,
                model,
                Some(name.to_string()),
                &GenerateRequest::plain(&cache, seed),
                MotionStages::default(),
                out,
                &mut |_, _| {},
            )?;
            // The decode is handed over ready-made: its measured time is charged when it ran.
            let charged = if decoded.load(Ordering::Relaxed) {
                decode
            } else {
                Duration::ZERO
            };
            job_s.push((t.elapsed() + charged).as_secs_f64());
        }
        table += &format!(
            "| {} | {name} | {:.2} | {:.2} | {:.2} |\n",
            model.0,
            job_s[0],
            job_s[1],
            job_s[0] - job_s[1]
        );
    }
    Ok(table)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_misspelt_model_names_the_folder_what_it_holds_and_the_nearest_id() {
        let found = vec!["beat-graph".to_string(), "dance-revolution".to_string()];
        let message = WorkerError::ModelNotInFolder {
            model: ModelId("dance-revolutoin".into()),
            dir: "models".into(),
            found: found.clone(),
        }
        .to_string();
        assert_eq!(
            message,
            "model dance-revolutoin is not available in models, which holds beat-graph, \
             dance-revolution; did you mean dance-revolution?"
        );
        assert_eq!(nearest("tsmt", &found), None);
        assert_eq!(nearest("beatgraph", &found), Some("beat-graph"));
        let empty = WorkerError::ModelNotInFolder {
            model: ModelId("tsmt".into()),
            dir: "/nowhere".into(),
            found: Vec::new(),
        }
        .to_string();
        assert!(empty.contains("/nowhere holds no trained model"), "{empty}");
        assert!(
            empty.ends_with("but its folder there has no weights"),
            "{empty}"
        );
    }
}
