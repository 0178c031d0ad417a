//! `choreo train dance-revolution`: L1 loss, Adam, and the dynamic auto-condition curriculum
//! (paper §3.3) on the train split of dance-with-melody.
use std::path::PathBuf;
use std::time::Instant;

use tch::nn::{self, OptimizerConfig};
use tch::{Device, Kind, Tensor};

use super::{append_log, batch_tensor, fit_normalizers, load_sequences, window_starts, write_atomic, EpochLog, Sequence, TrainError};
use crate::models::dance_revolution::{curriculum_q, Config, DanceRevolution, ModelFile, TrainingRecord, WEIGHTS_FILE, MODEL_FILE};
use crate::motion::dataset::Dataset;

/// Options of one training run; the defaults reproduce the committed weights.
#[derive(Clone, Debug, clap::Args)]
pub struct Options {
    /// The dance-with-melody folder.
    #[arg(long, default_value = "../shared/data/dance-with-melody")]
    pub data: PathBuf,
    /// Where model.json, weights.safetensors and train_log.jsonl go.
    #[arg(long, default_value = "models/dance-revolution")]
    pub out: PathBuf,
    #[arg(long, default_value_t = 60)]
    pub epochs: usize,
    #[arg(long, default_value_t = 32)]
    pub batch: usize,
    /// Training window in frames (10 s at 25 fps; see the model card for why).
    #[arg(long, default_value_t = 250)]
    pub window: usize,
    /// Stride between window starts, in frames.
    #[arg(long, default_value_t = 125)]
    pub stride: usize,
    #[arg(long, default_value_t = 1e-3)]
    pub lr: f64,
    /// `p`: ground-truth frames per curriculum segment (paper: 10).
    #[arg(long, default_value_t = 10)]
    pub p: i64,
    /// `λ`: the curriculum grows q = ⌊λ·epoch⌋.
    #[arg(long, default_value_t = 0.75)]
    pub lambda: f64,
    /// Upper bound on q, so late epochs stay within the window.
    #[arg(long, default_value_t = 40)]
    pub q_max: i64,
    #[arg(long, default_value_t = 2021)]
    pub seed: u64,
    /// libtorch intra-op threads.
    #[arg(long, default_value_t = 2)]
    pub threads: i32,
    /// Start from these weights (same configuration), e.g. to continue a committed run; the log
    /// is then appended to, not replaced.
    #[arg(long)]
    pub init: Option<PathBuf>,
    /// The curriculum epoch the first epoch of this run counts as (continuing a run).
    #[arg(long, default_value_t = 0)]
    pub first_epoch: usize,
    /// Train the encoder at position offsets drawn over a whole 15-minute song (default), or at 0 only.
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub random_positions: bool,
    /// Stop after this many minutes even if epochs remain (the weights are saved either way).
    #[arg(long)]
    pub max_minutes: Option<f64>,
    /// Use the tiny test configuration (for smoke runs, never for committed weights).
    #[arg(long)]
    pub tiny: bool,
}

/// Trains and writes the model folder; returns the per-epoch log.
pub fn train(opts: &Options) -> Result<Vec<EpochLog>, TrainError> {
    tch::set_num_threads(opts.threads);
    tch::manual_seed(opts.seed as i64);
    let started = Instant::now();
    let ds = Dataset::open(&opts.data)?;
    let features: super::FeatureFn = crate::audio::features::dance_revolution_at;
    let train = load_sequences(&ds, ds.train_ids(), features)?;
    let test = load_sequences(&ds, ds.test_ids(), features)?;
    let (music_norm, pose_norm) = fit_normalizers(&train)?;
    let norm = |seqs: Vec<Sequence>| -> Result<Vec<Sequence>, TrainError> {
        seqs.into_iter()
            .map(|s| Ok(Sequence { music: music_norm.normalize(&s.music)?, poses: pose_norm.normalize(&s.poses)?, id: s.id }))
            .collect()
    };
    let (train, test) = (norm(train)?, norm(test)?);
    tracing::info!(seconds = started.elapsed().as_secs_f64(), "data ready");

    let base = if opts.tiny { Config::tiny(0, 0) } else { Config::cpu() };
    let config = Config { music_dim: music_norm.dim() as i64, pose_dim: pose_norm.dim() as i64, ..base };
    let mut vs = nn::VarStore::new(Device::Cpu);
    let model = DanceRevolution::new(&vs.root(), config.clone());
    if let Some(init) = &opts.init {
        vs.load(init)?;
        tracing::info!(from = %init.display(), "initialised from earlier weights");
    }
    let mut opt = nn::Adam::default().build(&vs, opts.lr)?;
    std::fs::create_dir_all(&opts.out).map_err(|source| TrainError::Io { path: opts.out.clone(), source })?;
    let log_path = opts.out.join("train_log.jsonl");
    if opts.init.is_none() {
        let _ = std::fs::remove_file(&log_path);
    }

    // Windows hold window + 1 frames: frame 0 is only the decoder's first input.
    let len = opts.window + 1;
    let mut logs = Vec::new();
    for epoch in opts.first_epoch..opts.first_epoch + opts.epochs {
        let t0 = Instant::now();
        let q = curriculum_q(opts.lambda, epoch).min(opts.q_max);
        let starts = window_starts(&train, len, opts.stride, opts.seed + epoch as u64);
        if starts.is_empty() {
            return Err(TrainError::NoWindows(len));
        }
        let mut total = 0.0;
        let mut batches = 0;
        for (bi, chunk) in starts.chunks(opts.batch).enumerate() {
            let loss = window_loss(&model, &train, chunk, len, opts.p, q, opts.seed ^ ((epoch * 100_003 + bi) as u64), true, opts.random_positions);
            opt.backward_step_clip(&loss, 1.0);
            total += loss.double_value(&[]);
            batches += 1;
        }
        let test_loss = tch::no_grad(|| {
            let starts = window_starts(&test, len, opts.window, 0);
            let losses: Vec<f64> = starts
                .chunks(opts.batch)
                .map(|c| window_loss(&model, &test, c, len, opts.p, q, 7, false, opts.random_positions).double_value(&[]))
                .collect();
            (!losses.is_empty()).then(|| losses.iter().sum::<f64>() / losses.len() as f64)
        });
        let line = EpochLog { epoch, train_loss: total / batches as f64, test_loss, note: format!("p={} q={q} random_positions={}", opts.p, opts.random_positions), seconds: t0.elapsed().as_secs_f64() };
        tracing::info!(epoch, train_loss = line.train_loss, test_loss = ?line.test_loss, q, seconds = line.seconds, "epoch");
        append_log(&log_path, &line)?;
        logs.push(line);
        let out_of_time = opts.max_minutes.is_some_and(|m| started.elapsed().as_secs_f64() > m * 60.0);
        if epoch % 5 == 4 || epoch + 1 == opts.first_epoch + opts.epochs || out_of_time {
            save(&vs, &opts.out, ModelFile {
                config: config.clone(),
                music_norm: music_norm.clone(),
                pose_norm: pose_norm.clone(),
                fps: crate::motion::MOTION_FPS,
                training: TrainingRecord { epochs: epoch + 1, window: opts.window, p: opts.p, lambda: opts.lambda, q_max: opts.q_max, lr: opts.lr, batch: opts.batch, seed: opts.seed, final_train_loss: logs.last().map(|l| l.train_loss).unwrap_or(f64::NAN), minutes: started.elapsed().as_secs_f64() / 60.0 },
            })?;
        }
        if out_of_time {
            tracing::warn!(epoch, "stopping: --max-minutes reached");
            break;
        }
    }
    Ok(logs)
}

/// Mean L1 between the curriculum forward pass and the ground truth over a batch of windows.
#[allow(clippy::too_many_arguments)]
fn window_loss(model: &DanceRevolution, seqs: &[Sequence], starts: &[(usize, usize)], len: usize, p: i64, q: i64, seed: u64, train: bool, random_positions: bool) -> Tensor {
    let music = batch_tensor(seqs, starts, len, |s| &s.music, Device::Cpu).narrow(1, 1, len as i64 - 1);
    let poses = batch_tensor(seqs, starts, len, |s| &s.poses, Device::Cpu);
    // A position offset drawn per batch over the whole range a served song uses (issue 10 §5).
    let start = if random_positions { (seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 11) as i64 % (crate::models::dance_revolution::MAX_POSITION - len as i64).max(1) } else { 0 };
    let pred = model.forward_curriculum(&music, &poses, start, p, q, seed, train);
    (pred - poses.narrow(1, 1, len as i64 - 1)).abs().mean(Kind::Float)
}

fn save(vs: &nn::VarStore, dir: &std::path::Path, file: ModelFile) -> Result<(), TrainError> {
    let tmp = dir.join(format!("{WEIGHTS_FILE}.tmp.safetensors"));
    vs.save(&tmp)?;
    std::fs::rename(&tmp, dir.join(WEIGHTS_FILE)).map_err(|source| TrainError::Io { path: dir.to_owned(), source })?;
    write_atomic(&dir.join(MODEL_FILE), serde_json::to_string_pretty(&file)?.as_bytes())
}
