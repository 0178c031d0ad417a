//! `choreo train motion-style`: the motion style classifier of `models::motion_style` on the train
//! split's real motion, in 10-s windows drawn class-balanced at random offsets
//! (`models::train::classify`), with windows of no style beside them ([`no_style_windows`]).
//! Writes `weights.safetensors`, `model.json` (with the test split's accuracy) and
//! `train_log.jsonl` into `models/motion-style/`; the card (`README.md`) is written by hand.
use ndarray::{Array2, Array3, Axis};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};

use super::classify::{fit, Additions, ClassifyOptions, Fold, Splits};
use super::{CommonOptions, FolderFiles, TrainError};
use crate::models::dancenet::style::{Labelled, StyleConfig};
use crate::models::motion_style::{config, features, MotionStyleFile, FPS, HOP_S, ID, WINDOW_S};
use crate::models::DanceStyle;
use crate::motion::dataset::Dataset;
use crate::motion::Motion;

/// Options of one training run (the card gives the run behind the committed weights).
#[derive(Clone, Debug)]
pub struct Options {
    pub common: CommonOptions,
    pub schedule: ClassifyOptions,
    /// Windows of no style ([`no_style_windows`]) added to each batch with a uniform target
    /// (0: none).
    pub no_style_per_batch: usize,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            common: CommonOptions::default(),
            schedule: ClassifyOptions::default(),
            no_style_per_batch: 4,
        }
    }
}

/// How many windows of no style are made (each batch draws from them).
const NO_STYLE_WINDOWS: usize = 256;
/// Range of the markers' tremor in windows of no style, metres (σ, drawn log-uniformly).
const TREMOR_M: (f64, f64) = (0.001, 0.03);
/// What the training record says the windows of no style are.
const NO_STYLE: &str = "a train pose held still, its markers trembling (Gaussian per joint and frame, sigma log-uniform 1 mm - 3 cm; one window in 8 without tremor)";

/// Windows `[frames, 52]` of no style: a pose of one of `motions` held for the whole window,
/// every marker trembling independently (σ log-uniform over 1 mm – 3 cm), one window in 8
/// held perfectly still. A dance that stands or fidgets in place must read as no style, and a
/// classifier trained on dances alone calls such input a style at up to 0.95.
pub fn no_style_windows(
    motions: &[&Motion],
    frames: usize,
    count: usize,
    seed: u64,
) -> Result<Vec<Array2<f32>>, TrainError> {
    let mut rng = StdRng::seed_from_u64(seed);
    let mut out = Vec::with_capacity(count);
    for i in 0..count {
        if motions.is_empty() {
            break;
        }
        let m = motions[rng.gen_range(0..motions.len())];
        let pose = m
            .positions
            .index_axis(Axis(0), rng.gen_range(0..m.num_frames()))
            .to_owned();
        let sigma = if i % 8 == 0 {
            0.0
        } else {
            (rng.gen_range(TREMOR_M.0.ln()..TREMOR_M.1.ln())).exp()
        };
        let noise = Normal::new(0.0, sigma)
            .map_err(|e| TrainError::InvalidOption(format!("tremor σ {sigma}: {e}")))?;
        let positions = Array3::from_shape_fn((frames, pose.nrows(), 3), |(_, j, k)| {
            pose[[j, k]] + noise.sample(&mut rng) as f32
        });
        out.push(features(&Motion {
            fps: m.fps,
            positions,
        })?);
    }
    Ok(out)
}

/// Every dance of `ids` with its motion style features.
fn dances(ds: &Dataset, ids: &[String]) -> Result<(Vec<Labelled>, Vec<Motion>), TrainError> {
    let mut labelled = Vec::new();
    let mut motions = Vec::new();
    for id in ids {
        let dance = ds.load(id)?;
        let style = DanceStyle::of_dance_id(id)
            .ok_or_else(|| crate::motion::MotionError::UnknownDance { id: id.clone() })?;
        labelled.push(Labelled {
            id: id.clone(),
            style,
            features: features(&dance.motion)?,
        });
        motions.push(dance.motion);
    }
    Ok((labelled, motions))
}

/// Trains and writes the classifier; returns a one-line summary.
pub fn train(opts: &Options) -> Result<String, TrainError> {
    let fold = opts
        .schedule
        .hold_out
        .as_deref()
        .map(Fold::parse)
        .transpose()?;
    let ds = Dataset::open(&opts.common.data)?;
    let (train, train_motions) = dances(&ds, ds.train_ids())?;
    let (test, _) = dances(&ds, ds.test_ids())?;
    let splits = Splits::new(train, test, fold, &[])?;
    let config = opts.schedule.apply(if opts.common.tiny {
        StyleConfig {
            input_dim: config().input_dim,
            ..StyleConfig::tiny()
        }
    } else {
        config()
    });
    let (window, hop) = (
        (WINDOW_S * FPS).round() as usize,
        (HOP_S * FPS).round() as usize,
    );
    // Poses for the windows of no style come from the dances trained on (not the held-out ones).
    let learnt: Vec<&Motion> = ds
        .train_ids()
        .iter()
        .zip(&train_motions)
        .filter(|(id, _)| splits.train.iter().any(|d| &&d.id == id))
        .map(|(_, m)| m)
        .collect();
    let no_style = no_style_windows(&learnt, window, NO_STYLE_WINDOWS, opts.schedule.seed)?;
    let additions = Additions {
        augment: None,
        no_style: Some((no_style, NO_STYLE)),
        no_style_per_batch: opts.no_style_per_batch,
    };
    let (fitted, out) = fit(
        &opts.common,
        ID,
        FolderFiles::MODEL,
        &opts.schedule,
        &config,
        &splits,
        window,
        hop,
        additions,
        |training, test, held_out| MotionStyleFile {
            config: config.clone(),
            pose_norm: splits.norm.clone(),
            fps: FPS,
            window,
            hop,
            training,
            test,
            held_out,
        },
    )?;
    Ok(fitted.summary(&out))
}
