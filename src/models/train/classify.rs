//! The training both style classifiers share (DanceNet's musical one, `choreo train
//! dancenet-style`, and the motion one the metrics use, `choreo train motion-style`):
//! class-balanced windows at random offsets, cross-entropy, Adam, and after every epoch the test
//! split scored per window and per dance as served (`models::dancenet::style::evaluate`).
//!
//! # Class balance
//! The train split holds 26 waltzes, 6 rumbas, 4 cha-chas and 1 tango. Each training window is
//! drawn by picking a style uniformly among the four, then one of its dances with probability
//! proportional to the window starts it has (its length), then a start uniformly: every style
//! makes a quarter of the windows whatever its number of dances, every frame of a style is
//! equally likely, and the offsets differ every epoch. The lone tango is thus seen as often as
//! the 26 waltzes together (the model cards say what that costs).
use std::cell::RefCell;
use std::ops::Range;

use ndarray::{s, Array2};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use serde::Serialize;
use tch::{Kind, Tensor};

use super::{CommonOptions, EpochLog, EpochResult, FolderFiles, TrainError, Trainer};
use crate::models::dancenet::style::{
    evaluate, Evaluation, HeldOut, Labelled, Readout, Schedule, StyleClassifier, StyleConfig,
    STYLES,
};
use crate::models::folder::TrainingRecord;
use crate::motion::dataset::NormStats;

/// How [`balanced_windows`] draws, as the training record states it.
pub const SAMPLING: &str = "style uniform, then dance in proportion to its window starts, then a uniform start, afresh each epoch";

/// The schedule flags both trainers take.
#[derive(Clone, Debug)]
pub struct ClassifyOptions {
    pub epochs: usize,
    pub batch: usize,
    /// Training windows drawn per epoch (see the class balance in `models::train::classify`).
    pub windows_per_epoch: usize,
    pub lr: f64,
    pub seed: u64,
    /// Leave fold `K/N` of the train split's dances out of training and score them beside the
    /// test split (a leave-dances-out check; write it with `--out` elsewhere, never over the
    /// committed folder). Each style's dances, in split order, go to fold i mod N; a style with
    /// one train dance (the tango) is never left out.
    pub hold_out: Option<String>,
    /// Class balance β: a style's share of the windows is proportional to its number of dances
    /// to the power 1 − β (1: every style a quarter; 0: as many as its dances).
    pub balance: f64,
    /// Max-pool stride after each convolution [default: the configuration's].
    pub pool: Option<i64>,
    /// Dropout before the FC layer [default: the configuration's].
    pub dropout: Option<f64>,
    /// What the FC layer reads of the Bi-LSTM [default: the configuration's].
    pub readout: Option<Readout>,
}

impl Default for ClassifyOptions {
    fn default() -> Self {
        Self {
            epochs: 40,
            batch: 32,
            windows_per_epoch: 512,
            lr: 2e-3,
            seed: 12,
            hold_out: None,
            balance: 1.0,
            pool: None,
            dropout: None,
            readout: None,
        }
    }
}

impl ClassifyOptions {
    /// `config` with this run's overrides.
    pub fn apply(&self, config: StyleConfig) -> StyleConfig {
        StyleConfig {
            pool: self.pool.unwrap_or(config.pool),
            dropout: self.dropout.unwrap_or(config.dropout),
            readout: self.readout.unwrap_or(config.readout),
            ..config
        }
    }
}

/// Changes one training window `[len, F]` in place (data augmentation), drawing from the rng.
pub type Augment = fn(&mut Array2<f32>, &mut StdRng);

/// What a trainer adds to the shared loop.
#[derive(Clone, Debug, Default)]
pub struct Additions {
    /// Changes each training window, and how the training record describes it.
    pub augment: Option<(Augment, &'static str)>,
    /// Windows that are no style (raw features `[window, F]`, before normalising), and how the
    /// training record describes them: `no_style_per_batch` of them, drawn at random, join each
    /// batch with a uniform target, so that such inputs read as no style rather than as
    /// whichever style the network happens to map them to.
    pub no_style: Option<(Vec<Array2<f32>>, &'static str)>,
    pub no_style_per_batch: usize,
}

pub use crate::motion::dataset::Fold;

/// The dances a run learns from, leaves out and is tested on, normalised with statistics of
/// the dances it learns from.
pub struct Splits {
    pub train: Vec<Labelled>,
    pub held_out: Vec<Labelled>,
    pub test: Vec<Labelled>,
    pub norm: NormStats,
    pub fold: Option<Fold>,
}

impl Splits {
    /// Leaves `fold` out of `train_raw`, fits the normalisation on the rest (one mean and
    /// standard deviation shared by the columns of each range of `tied`, so that permuting them
    /// commutes with normalising), normalises all.
    pub fn new(
        train_raw: Vec<Labelled>,
        test_raw: Vec<Labelled>,
        fold: Option<Fold>,
        tied: &[Range<usize>],
    ) -> Result<Self, TrainError> {
        let holds = fold
            .map(|f| {
                f.holds(
                    &train_raw
                        .iter()
                        .map(|d| d.style.index())
                        .collect::<Vec<_>>(),
                )
            })
            .unwrap_or_else(|| vec![false; train_raw.len()]);
        let (mut train, mut held_out) = (Vec::new(), Vec::new());
        for (d, h) in train_raw.into_iter().zip(holds) {
            if h {
                held_out.push(d)
            } else {
                train.push(d)
            }
        }
        let mut norm = NormStats::fit(train.iter().map(|d| &d.features))?;
        for cols in tied {
            tie(&mut norm, cols.clone());
        }
        let apply = |v: &mut Vec<Labelled>| -> Result<(), TrainError> {
            for d in v.iter_mut() {
                d.features = norm.normalize(&d.features)?;
            }
            Ok(())
        };
        let mut test = test_raw;
        apply(&mut train)?;
        apply(&mut held_out)?;
        apply(&mut test)?;
        Ok(Self {
            train,
            held_out,
            test,
            norm,
            fold,
        })
    }
}

/// Replaces the statistics of `cols` by those of all their values pooled (every column has
/// the same number of rows, so the pooled mean is the mean of the means and the pooled second
/// moment the mean of the second moments).
pub fn tie(norm: &mut NormStats, cols: Range<usize>) {
    let n = cols.len() as f64;
    if n == 0.0 || cols.end > norm.dim() {
        return;
    }
    let mean = cols.clone().map(|c| f64::from(norm.mean[c])).sum::<f64>() / n;
    let second = cols
        .clone()
        .map(|c| f64::from(norm.std[c]).powi(2) + f64::from(norm.mean[c]).powi(2))
        .sum::<f64>()
        / n;
    let std = ((second - mean * mean).max(0.0).sqrt() as f32).max(NormStats::MIN_STD);
    for c in cols {
        norm.mean[c] = mean as f32;
        norm.std[c] = std;
    }
}

/// Draws `n` windows `(dance, start)` of `len` frames, class-balanced (module doc). Dances
/// shorter than `len` are never drawn.
pub fn balanced_windows(
    dances: &[Labelled],
    len: usize,
    n: usize,
    balance: f64,
    rng: &mut StdRng,
) -> Result<Vec<(usize, usize)>, TrainError> {
    // Per style: its dances and their number of window starts.
    let mut by_style: Vec<Vec<(usize, usize)>> = vec![Vec::new(); STYLES];
    for (i, d) in dances.iter().enumerate() {
        let t = d.features.nrows();
        if t >= len {
            by_style[d.style.index()].push((i, t - len + 1));
        }
    }
    let present: Vec<&Vec<(usize, usize)>> = by_style.iter().filter(|v| !v.is_empty()).collect();
    if present.is_empty() {
        return Err(TrainError::NoWindows(len));
    }
    let weights: Vec<f64> = present
        .iter()
        .map(|v| (v.len() as f64).powf(1.0 - balance))
        .collect();
    let styles = rand::distributions::WeightedIndex::new(&weights)
        .map_err(|e| TrainError::InvalidOption(format!("--balance {balance}: {e}")))?;
    Ok((0..n)
        .map(|_| {
            let style = present[rng.sample(&styles)];
            let total: usize = style.iter().map(|&(_, starts)| starts).sum();
            let mut k = rng.gen_range(0..total);
            let &(dance, starts) = style
                .iter()
                .find(|&&(_, starts)| {
                    if k < starts {
                        true
                    } else {
                        k -= starts;
                        false
                    }
                })
                .unwrap_or(&style[0]);
            (dance, k.min(starts - 1))
        })
        .collect())
}

/// Windows `[b, len, F]` (each through `augment`, when given) and their styles `[b]`.
fn batch(
    dances: &[Labelled],
    picks: &[(usize, usize)],
    len: usize,
    augment: Option<Augment>,
    rng: &mut StdRng,
) -> (Tensor, Tensor) {
    let xs: Vec<Tensor> = picks
        .iter()
        .map(|&(d, f)| {
            let mut w = dances[d].features.slice(s![f..f + len, ..]).to_owned();
            if let Some(a) = augment {
                a(&mut w, rng);
            }
            crate::models::to_tensor(&w)
        })
        .collect();
    let ys: Vec<i64> = picks
        .iter()
        .map(|&(d, _)| dances[d].style.index() as i64)
        .collect();
    (Tensor::stack(&xs, 0), Tensor::from_slice(&ys))
}

/// What a run ends with.
pub struct Fitted {
    pub logs: Vec<EpochLog>,
    pub test: Evaluation,
    pub held_out: Option<HeldOut>,
}

impl Fitted {
    /// One line for the CLI: accuracies on the test split (and the held-out dances).
    pub fn summary(&self, out: &std::path::Path) -> String {
        let e = &self.test;
        let mut line = format!(
            "trained {} epochs into {}: test split {}/{} windows ({:.3}, balanced {:.3}), {}/{} dances",
            self.logs.len(),
            out.display(),
            (e.window_accuracy * e.windows as f64).round(),
            e.windows,
            e.window_accuracy,
            e.window_balanced_accuracy,
            (e.dance_accuracy * e.dances as f64).round(),
            e.dances
        );
        if let Some(h) = &self.held_out {
            let e = &h.evaluation;
            line += &format!(
                "; held-out fold {}: {:.3} of {} windows (balanced {:.3}), {:.3} of {} dances",
                h.fold,
                e.window_accuracy,
                e.windows,
                e.window_balanced_accuracy,
                e.dance_accuracy,
                e.dances
            );
        }
        line
    }
}

/// Trains a [`StyleClassifier`] of `config` on `splits.train` in `window`-frame windows, scores
/// the test split (and the held-out dances) every epoch in windows every `hop` frames, and saves
/// `files` in the folder of `id` with the description `file(record, test, held_out)` builds.
#[allow(clippy::too_many_arguments)]
pub fn fit<F: Serialize>(
    common: &CommonOptions,
    id: &str,
    files: FolderFiles,
    opts: &ClassifyOptions,
    config: &StyleConfig,
    splits: &Splits,
    window: usize,
    hop: usize,
    additions: Additions,
    file: impl Fn(TrainingRecord<Schedule>, Evaluation, Option<HeldOut>) -> F,
) -> Result<(Fitted, std::path::PathBuf), TrainError> {
    let (mut trainer, model) = Trainer::with_files(common, id, files, opts.lr, opts.seed, |p| {
        StyleClassifier::new(p, config)
    })?;
    let no_style: Vec<Tensor> = match &additions.no_style {
        Some((windows, _)) if additions.no_style_per_batch > 0 => windows
            .iter()
            .map(|w| Ok(crate::models::to_tensor(&splits.norm.normalize(w)?)))
            .collect::<Result<_, TrainError>>()?,
        _ => Vec::new(),
    };
    let latest: RefCell<(Evaluation, Option<HeldOut>, usize)> =
        RefCell::new((Evaluation::default(), None, 0));
    let held = |model: &StyleClassifier| -> Result<Option<HeldOut>, TrainError> {
        match splits.fold {
            Some(f) if !splits.held_out.is_empty() => Ok(Some(HeldOut {
                fold: f.to_string(),
                evaluation: evaluate(model, &splits.held_out, window, hop)?,
            })),
            _ => Ok(None),
        }
    };
    trainer.run(
        0..opts.epochs,
        5,
        |epoch, opt, deadline| {
            let mut rng = StdRng::seed_from_u64(
                opts.seed ^ (epoch as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15),
            );
            let picks = balanced_windows(
                &splits.train,
                window,
                opts.windows_per_epoch,
                opts.balance,
                &mut rng,
            )?;
            let (mut total, mut batches) = (0.0, 0usize);
            for chunk in picks.chunks(opts.batch.max(1)) {
                let (x, y) = batch(
                    &splits.train,
                    chunk,
                    window,
                    additions.augment.map(|a| a.0),
                    &mut rng,
                );
                let loss = if !no_style.is_empty() {
                    let (b, n) = (chunk.len() as i64, additions.no_style_per_batch as i64);
                    let drawn: Vec<Tensor> = (0..n)
                        .map(|_| no_style[rng.gen_range(0..no_style.len())].shallow_clone())
                        .collect();
                    let logits =
                        model.forward(&Tensor::cat(&[x, Tensor::stack(&drawn, 0)], 0), true); // [b + n, classes]
                    let real = logits.narrow(0, 0, b).cross_entropy_for_logits(&y);
                    // Cross-entropy against the uniform distribution: −mean over styles of log p.
                    let uniform = -logits
                        .narrow(0, b, n)
                        .log_softmax(-1, Kind::Float)
                        .mean(Kind::Float);
                    (real * b as f64 + uniform * n as f64) / (b + n) as f64
                } else {
                    model.loss(&x, &y, true)
                };
                opt.backward_step_clip(&loss, 1.0);
                total += loss.double_value(&[]);
                batches += 1;
                if deadline.expired() {
                    break;
                }
            }
            let test = evaluate(&model, &splits.test, window, hop)?;
            let held_out = held(&model)?;
            let mut note = format!(
                "test: windows {:.3} (balanced {:.3}), dances {:.3}",
                test.window_accuracy, test.window_balanced_accuracy, test.dance_accuracy
            );
            if let Some(h) = &held_out {
                note += &format!(
                    "; held out: windows {:.3} (balanced {:.3}), dances {:.3}",
                    h.evaluation.window_accuracy,
                    h.evaluation.window_balanced_accuracy,
                    h.evaluation.dance_accuracy
                );
            }
            let test_loss = Some(test.window_loss);
            let mut l = latest.borrow_mut();
            let steps = l.2 + batches;
            *l = (test, held_out, steps);
            Ok(EpochResult {
                train_loss: total / batches.max(1) as f64,
                test_loss,
                note,
            })
        },
        |t| {
            let l = latest.borrow();
            let schedule = Schedule {
                windows_per_epoch: opts.windows_per_epoch,
                sampling: SAMPLING.into(),
                augmentation: additions
                    .augment
                    .map(|a| a.1.to_string())
                    .unwrap_or_default(),
                no_style: additions
                    .no_style
                    .as_ref()
                    .map(|n| n.1.to_string())
                    .unwrap_or_default(),
                no_style_per_batch: if no_style.is_empty() {
                    0
                } else {
                    additions.no_style_per_batch
                },
                steps: l.2,
            };
            file(
                t.record(opts.lr, opts.batch, opts.seed, schedule),
                l.0.clone(),
                l.1.clone(),
            )
        },
    )?;
    let (test, held_out, _) = latest.into_inner();
    Ok((
        Fitted {
            logs: trainer.logs,
            test,
            held_out,
        },
        trainer.out,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::models::DanceStyle;

    fn dance(id: &str, style: DanceStyle, t: usize) -> Labelled {
        Labelled {
            id: id.into(),
            style,
            features: Array2::zeros((t, 2)),
        }
    }

    #[test]
    fn every_style_gets_a_quarter_of_the_windows() {
        // 6 waltzes, 1 cha-cha, 2 rumbas, 1 tango, and one waltz too short for a window.
        let mut d: Vec<Labelled> = (0..6)
            .map(|i| dance(&format!("W{i}"), DanceStyle::Waltz, 100))
            .collect();
        d.push(dance("C", DanceStyle::ChaCha, 50));
        d.push(dance("R1", DanceStyle::Rumba, 40));
        d.push(dance("R2", DanceStyle::Rumba, 200));
        d.push(dance("T", DanceStyle::Tango, 30));
        d.push(dance("short", DanceStyle::Waltz, 10));
        let picks = balanced_windows(&d, 20, 8000, 1.0, &mut StdRng::seed_from_u64(0)).unwrap();
        let mut per_style = [0usize; STYLES];
        for &(i, f) in &picks {
            per_style[d[i].style.index()] += 1;
            assert!(f + 20 <= d[i].features.nrows());
            assert_ne!(d[i].id, "short");
        }
        for n in per_style {
            assert!((1800..2200).contains(&n), "{per_style:?}");
        }
        // Within the rumbas, in proportion to the starts (21 vs 181).
        let r1 = picks.iter().filter(|p| d[p.0].id == "R1").count() as f64;
        let r2 = picks.iter().filter(|p| d[p.0].id == "R2").count() as f64;
        assert!((r1 / (r1 + r2) - 21.0 / 202.0).abs() < 0.03, "{r1} vs {r2}");
    }

    #[test]
    fn folds_leave_out_each_style_in_turn_but_never_a_lone_one() {
        let d: Vec<Labelled> = ["W1", "W2", "W3", "C1", "C2", "T1", "W4"]
            .iter()
            .map(|id| {
                dance(
                    id,
                    DanceStyle::from_letter(id.chars().next().unwrap()).unwrap(),
                    10,
                )
            })
            .collect();
        let styles: Vec<usize> = d.iter().map(|d| d.style.index()).collect();
        let f1 = Fold::parse("1/2").unwrap().holds(&styles);
        let f2 = Fold::parse("2/2").unwrap().holds(&styles);
        assert_eq!(f1, vec![true, false, true, true, false, false, false]);
        assert_eq!(f2, vec![false, true, false, false, true, false, true]);
        for bad in ["0/2", "3/2", "1/1", "x", "1/"] {
            assert!(Fold::parse(bad).is_err(), "{bad}");
        }
    }
}

#[cfg(test)]
mod tie_tests {
    use super::*;

    #[test]
    fn tied_columns_share_the_pooled_statistics() {
        let a = ndarray::array![[0.0f32, 2.0, 10.0], [2.0, 6.0, 10.0]];
        let mut n = NormStats::fit([&a]).unwrap();
        tie(&mut n, 0..2);
        // Pooled values of columns 0 and 1: 0, 2, 2, 6 → mean 2.5, variance 4.75.
        assert!((n.mean[0] - 2.5).abs() < 1e-6 && (n.mean[1] - 2.5).abs() < 1e-6);
        assert!((n.std[0] - 4.75f32.sqrt()).abs() < 1e-5 && n.std[0] == n.std[1]);
        assert_eq!(n.mean[2], 10.0);
    }
}
