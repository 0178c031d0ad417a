//! `choreo eval`: its arguments, the reference statistics it writes, and what it prints.
use std::path::PathBuf;

use anyhow::Context;
use choreo::eval::{self, EvalOptions};

fn defaults() -> EvalOptions {
    EvalOptions::default()
}

/// Arguments of `choreo eval`.
#[derive(Clone, Debug, clap::Args)]
pub struct EvalArgs {
    /// Model ids to evaluate (e.g. dance-revolution); none means every model served from
    /// --models-dir.
    pub models: Vec<String>,
    /// Real and Mismatched real only: no model is run.
    #[arg(long)]
    pub real_only: bool,
    /// Dataset split whose songs are evaluated.
    #[arg(long, default_value_t = defaults().split)]
    pub split: String,
    /// More songs, danced whole by each model beside ../shared/audio: audio files, or folders
    /// (every audio file in each). Files of one name in several folders are named by their folder.
    #[arg(long)]
    pub songs: Vec<PathBuf>,
    /// Leave out ../shared/audio (the test split and --songs only).
    #[arg(long)]
    pub no_shared_songs: bool,
    /// Write the full results as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// The dance-with-melody folder.
    #[arg(long, default_value_os_t = defaults().data)]
    pub data: PathBuf,
    /// Where trained models live.
    #[arg(long, default_value_os_t = defaults().models_dir)]
    pub models_dir: PathBuf,
    /// First seed (mismatch pairing and generation).
    #[arg(long, default_value_t = defaults().seed)]
    pub seed: u64,
    /// Dances generated per song and model (seeds seed..seed+N); ≥ 2 gives multimodality and
    /// the seed sensitivity.
    #[arg(long, default_value_t = defaults().seeds)]
    pub seeds: u64,
    /// Key poses given to models that take them, on each test song: this many poses of the real
    /// test dance (root-relative) at frames drawn by the seed after its first second. Extra songs
    /// get none. The key-pose error column then shows how closely the dances pass through them.
    #[arg(long, default_value_t = defaults().key_poses)]
    pub key_poses: usize,
    /// Write each generated dance's contact sheet (as served) here as
    /// `<model>_<song>_seed<seed>.png` (the picture jobs serve as preview.png); the tempo
    /// section's copies as `<model>_<song>_<factor>x_seed<seed>.png`.
    #[arg(long, value_name = "DIR")]
    pub previews: Option<PathBuf>,
    /// Train dances paired with each test song in the Mismatched-real row.
    #[arg(long, default_value_t = defaults().mismatch_per_song)]
    pub mismatch_per_song: usize,
    /// Tempo factors every extra song is also danced at (sox, pitch kept), for the tempo
    /// section, e.g. --tempi 0.8,1.25.
    #[arg(long, value_delimiter = ',', default_values_t = defaults().tempi)]
    pub tempi: Vec<f64>,
    /// No tempo section.
    #[arg(long)]
    pub no_tempo: bool,
    /// With --split train: only the train dances of fold K/N (each style's dances, in split
    /// order, go to fold i mod N; the lone tango never), the ones a model built with
    /// `choreo train … --hold-out K/N` left out. Settings are chosen there, not on the test split.
    #[arg(long, value_parser = |s: &str| choreo::motion::dataset::Fold::parse(s).map_err(|e| e.to_string()))]
    pub hold_out: Option<choreo::motion::dataset::Fold>,
    /// Recompute the reference statistics from the train split, write them to
    /// src/metrics/reference_train.json (or --reference-out) and exit.
    #[arg(long)]
    pub write_reference: bool,
    /// Print the table a model card shows from this evaluation JSON (a committed
    /// `models/<id>/eval.json`) and exit.
    #[arg(long, value_name = "EVAL_JSON")]
    pub card_table: Option<PathBuf>,
    /// Output path for --write-reference.
    #[arg(long, default_value = eval::REFERENCE_PATH)]
    pub reference_out: PathBuf,
}

impl EvalArgs {
    /// What the library evaluates (the flags the CLI handles itself left out).
    pub fn options(&self) -> EvalOptions {
        EvalOptions {
            models: self.models.clone(),
            real_only: self.real_only,
            split: self.split.clone(),
            songs: self.songs.clone(),
            no_shared_songs: self.no_shared_songs,
            data: self.data.clone(),
            models_dir: self.models_dir.clone(),
            seed: self.seed,
            seeds: self.seeds,
            key_poses: self.key_poses,
            previews: self.previews.clone(),
            mismatch_per_song: self.mismatch_per_song,
            tempi: if self.no_tempo {
                Vec::new()
            } else {
                self.tempi.clone()
            },
            hold_out: self.hold_out,
        }
    }
}

/// `choreo eval`: writes the reference, or evaluates, prints the tables and writes the JSON.
pub fn run(args: &EvalArgs) -> anyhow::Result<()> {
    if let Some(path) = &args.card_table {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("choreo eval: reading {}", path.display()))?;
        let result: eval::EvalResult = serde_json::from_str(&text)
            .with_context(|| format!("choreo eval: {} is not an evaluation", path.display()))?;
        print!("{}", eval::tables::card_table(&result));
        return Ok(());
    }
    if args.write_reference {
        let s = eval::write_reference(&args.data, &args.reference_out).context("choreo eval")?;
        println!(
            "wrote {} ({} train dances, {} kinetic / {} geometric windows, body scale {:?})",
            args.reference_out.display(),
            s.dances.len(),
            s.kinetic.gaussian.count,
            s.geometric.gaussian.count,
            s.body_scale
        );
        let p = &s.physical;
        println!(
            "train physical: lowest foot p5 {:.3} / median {:.3} / p95 {:.3} m; acceleration median {:.2}, p99 {:.2}, p99.9 {:.2}, max {:.2} m/s²; mean joint speed {:.3} m/s (per dance {:.2}–{:.2})",
            p.pooled.lowest_foot_m.p5,
            p.pooled.lowest_foot_m.median,
            p.pooled.lowest_foot_m.p95,
            p.pooled.acceleration_m_s2.median,
            p.pooled.acceleration_m_s2.p99,
            p.pooled.acceleration_m_s2.p99_9,
            p.pooled.acceleration_m_s2.max,
            p.pooled.mean_speed_m_s,
            p.mean_speed_range_m_s[0],
            p.mean_speed_range_m_s[1]
        );
        return Ok(());
    }
    let options = args.options();
    if options.shared_songs_missing() {
        eprintln!(
            "note: {} not found; the extra-song section covers --songs only",
            eval::SHARED_SONGS
        );
    }
    let result = eval::evaluate(&options).context("choreo eval")?;
    print!("{}", eval::markdown(&result));
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&result).context("choreo eval")?;
        std::fs::write(path, text)
            .with_context(|| format!("choreo eval: writing {}", path.display()))?;
    }
    Ok(())
}
