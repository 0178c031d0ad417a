//! `choreo train <model>`: the arguments of each trainer. Every default is the library's
//! `Default` (the schedule behind the committed weights), read here so the two cannot drift.
use std::path::PathBuf;

use anyhow::Context;
use choreo::models::dancenet::style::Readout;
use choreo::models::train::{self, Training};

/// `choreo train <model>`: one variant per trainable model.
#[derive(Clone, Debug, clap::Subcommand)]
pub enum TrainArgs {
    /// beat-graph: real dance units of the train split, a motion graph and a music match
    /// (ChoreoMaster's manner); minutes, no gradient descent.
    BeatGraph(BeatGraphArgs),
    /// DanceRevolution (Huang et al., ICLR 2021).
    DanceRevolution(DanceRevolutionArgs),
    /// DanceNet (Zhuang et al. 2020): dilated gated causal convolutions, mixture output, style control.
    Dancenet(DancenetArgs),
    /// Key-pose controllable cross-modal transformer.
    KeyposeTransformer(KeyposeTransformerArgs),
    /// TSMT, the two-stream motion transformer over discretised poses (Li et al. 2020).
    Tsmt(TsmtArgs),
    /// DanceNet's musical style classifier (Zhuang et al. 2020): song → style, into models/dancenet/style.*.
    DancenetStyle(DancenetStyleArgs),
    /// The motion style classifier the metrics use: motion → style, into models/motion-style/.
    MotionStyle(MotionStyleArgs),
}

impl From<TrainArgs> for Training {
    fn from(a: TrainArgs) -> Self {
        match a {
            TrainArgs::BeatGraph(o) => Training::BeatGraph(o.into()),
            TrainArgs::DanceRevolution(o) => Training::DanceRevolution(o.into()),
            TrainArgs::Dancenet(o) => Training::Dancenet(o.into()),
            TrainArgs::KeyposeTransformer(o) => Training::KeyposeTransformer(o.into()),
            TrainArgs::Tsmt(o) => Training::Tsmt(o.into()),
            TrainArgs::DancenetStyle(o) => Training::DancenetStyle(o.into()),
            TrainArgs::MotionStyle(o) => Training::MotionStyle(o.into()),
        }
    }
}

/// Trains (or evaluates) and prints what it wrote.
pub fn run(args: &TrainArgs) -> anyhow::Result<()> {
    choreo::telemetry::init_tracing(choreo::telemetry::env_log_format(), "info");
    println!(
        "{}",
        Training::from(args.clone()).run().context("choreo train")?
    );
    Ok(())
}

/// `--readout`, as the library's [`Readout`] (the flag's values and their help).
#[derive(Clone, Copy, clap::ValueEnum)]
enum ReadoutArg {
    /// The forward direction's last state and the backward direction's first.
    Last,
    /// The mean over time of the outputs of both directions.
    Mean,
}

fn readout_parser() -> impl clap::builder::TypedValueParser<Value = Readout> {
    use clap::builder::TypedValueParser as _;
    clap::builder::EnumValueParser::<ReadoutArg>::new().map(|r| match r {
        ReadoutArg::Last => Readout::Last,
        ReadoutArg::Mean => Readout::Mean,
    })
}

args_into! {
    /// Options every trainer takes, flattened into each model's own `Options`.
    pub struct CommonArgs => train::CommonOptions {
        /// The dance-with-melody folder.
        #[arg(long, default_value_os_t = train::CommonOptions::default().data)]
        data: PathBuf,
        /// The model folder to write [default: models/<id>].
        #[arg(long)]
        out: Option<PathBuf>,
        /// libtorch intra-op threads.
        #[arg(long, default_value_t = train::CommonOptions::default().threads)]
        threads: i32,
        /// Stop after this many minutes even if epochs remain (the weights are saved either way).
        #[arg(long)]
        max_minutes: Option<f64>,
        /// Start from these weights (same configuration), e.g. to continue a committed run; the log
        /// is then appended to, not replaced.
        #[arg(long)]
        init: Option<PathBuf>,
        /// Use the tiny test configuration (for smoke runs, never for committed weights).
        #[arg(long)]
        tiny: bool,
    }
}

args_into! {
    /// The schedule flags both trainers take.
    pub struct ClassifyArgs => train::classify::ClassifyOptions {
        #[arg(long, default_value_t = train::classify::ClassifyOptions::default().epochs)]
        epochs: usize,
        #[arg(long, default_value_t = train::classify::ClassifyOptions::default().batch)]
        batch: usize,
        /// Training windows drawn per epoch (see the class balance in `models::train::classify`).
        #[arg(long, default_value_t = train::classify::ClassifyOptions::default().windows_per_epoch)]
        windows_per_epoch: usize,
        #[arg(long, default_value_t = train::classify::ClassifyOptions::default().lr)]
        lr: f64,
        #[arg(long, default_value_t = train::classify::ClassifyOptions::default().seed)]
        seed: u64,
        /// Leave fold `K/N` of the train split's dances out of training and score them beside the
        /// test split (a leave-dances-out check; write it with `--out` elsewhere, never over the
        /// committed folder). Each style's dances, in split order, go to fold i mod N; a style with
        /// one train dance (the tango) is never left out.
        #[arg(long)]
        hold_out: Option<String>,
        /// Class balance β: a style's share of the windows is proportional to its number of dances
        /// to the power 1 − β (1: every style a quarter; 0: as many as its dances).
        #[arg(long, default_value_t = train::classify::ClassifyOptions::default().balance)]
        balance: f64,
        /// Max-pool stride after each convolution [default: the configuration's].
        #[arg(long)]
        pool: Option<i64>,
        /// Dropout before the FC layer [default: the configuration's].
        #[arg(long)]
        dropout: Option<f64>,
        /// What the FC layer reads of the Bi-LSTM [default: the configuration's].
        #[arg(long, value_parser = readout_parser())]
        readout: Option<Readout>,
    }
}

args_into! {
    /// Options of one training run; the defaults reproduce the committed weights' schedule (the
    /// card gives the runs).
    pub struct DanceRevolutionArgs => train::dance_revolution::Options {
        #[command(flatten)]
        common: CommonArgs,
        #[arg(long, default_value_t = train::dance_revolution::Options::default().epochs)]
        epochs: usize,
        #[arg(long, default_value_t = train::dance_revolution::Options::default().batch)]
        batch: usize,
        /// Training window in frames (10 s at 25 fps; see the model card for why).
        #[arg(long, default_value_t = train::dance_revolution::Options::default().window)]
        window: usize,
        /// Stride between window starts, in frames.
        #[arg(long, default_value_t = train::dance_revolution::Options::default().stride)]
        stride: usize,
        #[arg(long, default_value_t = train::dance_revolution::Options::default().lr)]
        lr: f64,
        /// `p`: ground-truth frames per curriculum segment (paper: 10).
        #[arg(long, default_value_t = train::dance_revolution::Options::default().p)]
        p: i64,
        /// `λ`: the curriculum grows q = ⌊λ·epoch⌋.
        #[arg(long, default_value_t = train::dance_revolution::Options::default().lambda)]
        lambda: f64,
        /// Upper bound on q, so late epochs stay within the window.
        #[arg(long, default_value_t = train::dance_revolution::Options::default().q_max)]
        q_max: i64,
        #[arg(long, default_value_t = train::dance_revolution::Options::default().seed)]
        seed: u64,
        /// The curriculum epoch the first epoch of this run counts as (continuing a run).
        #[arg(long, default_value_t = train::dance_revolution::Options::default().first_epoch)]
        first_epoch: usize,
        /// Train the encoder at position offsets drawn over a whole 15-minute song (default), or at 0 only.
        #[arg(long, default_value_t = train::dance_revolution::Options::default().random_positions, action = clap::ArgAction::Set)]
        random_positions: bool,
        /// Append the beat clock (beat and bar phase as sin/cos, tempo) to the music features.
        #[arg(long, default_value_t = train::dance_revolution::Options::default().beat_clock, action = clap::ArgAction::Set)]
        beat_clock: bool,
        /// Slowest tempo factor a training window is drawn at (music and dance resampled together).
        #[arg(long, default_value_t = train::dance_revolution::Options::default().min_tempo)]
        min_tempo: f64,
        /// Fastest tempo factor a training window is drawn at.
        #[arg(long, default_value_t = train::dance_revolution::Options::default().max_tempo)]
        max_tempo: f64,
        /// Mirror half the training windows left ↔ right.
        #[arg(long, default_value_t = train::dance_revolution::Options::default().mirror, action = clap::ArgAction::Set)]
        mirror: bool,
        /// Weight of the L1 loss on frame-to-frame pose change.
        #[arg(long, default_value_t = train::dance_revolution::Options::default().velocity_weight)]
        velocity_weight: f64,
        /// Train in beat time (`models::beat_time`): every train dance re-timed to the split's
        /// median tempo before the drawn tempo factor; the model then serves in beat time.
        #[arg(long, default_value_t = train::dance_revolution::Options::default().beat_time, action = clap::ArgAction::Set)]
        beat_time: bool,
        /// Weight of the L1 between predicted and real joint-velocity magnitude spectra.
        #[arg(long, default_value_t = train::dance_revolution::Options::default().spectral_weight)]
        spectral_weight: f64,
        /// Weight of the same L1 over the elbows and wrists relative to the spine alone.
        #[arg(long, default_value_t = train::dance_revolution::Options::default().arm_weight)]
        arm_weight: f64,
        /// Train only the read-out's rows of the elbows and wrists, every other weight frozen.
        #[arg(long, default_value_t = train::dance_revolution::Options::default().arm_readout_only, action = clap::ArgAction::Set)]
        arm_readout_only: bool,
        /// Hidden width of an arm head: the elbows and wrists read out beside the paper's read-out
        /// and never fed back to the LSTM (0: none). Its last layer starts at zero.
        #[arg(long, default_value_t = train::dance_revolution::Options::default().arm_head)]
        arm_head: i64,
        /// Train only the arm head, every other weight frozen (with `--init`: the network's own
        /// motion stays exactly the earlier weights').
        #[arg(long, default_value_t = train::dance_revolution::Options::default().arm_head_only, action = clap::ArgAction::Set)]
        arm_head_only: bool,
        /// With `--arm-head-only`: how many seeds (101, 102, …) each train song is danced from.
        #[arg(long, default_value_t = train::dance_revolution::Options::default().rollout_seeds)]
        rollout_seeds: u64,
        /// With `--arm-head-only`: the head also reads the figure the arms are to hold, trained
        /// on the network's own dances told real figures from the train split, which
        /// `model.json` then keeps for serving (the model card).
        #[arg(long, default_value_t = train::dance_revolution::Options::default().arm_figures, action = clap::ArgAction::Set)]
        arm_figures: bool,
    }
}

args_into! {
    /// Options of one training run (the card gives the run behind the committed weights).
    pub struct DancenetArgs => train::dancenet::Options {
        #[command(flatten)]
        common: CommonArgs,
        #[arg(long, default_value_t = train::dancenet::Options::default().epochs)]
        epochs: usize,
        #[arg(long, default_value_t = train::dancenet::Options::default().batch)]
        batch: usize,
        /// Training window, frames (the context encoder's 8 s).
        #[arg(long, default_value_t = train::dancenet::Options::default().window)]
        window: usize,
        /// Stride between window starts, frames.
        #[arg(long, default_value_t = train::dancenet::Options::default().stride)]
        stride: usize,
        #[arg(long, default_value_t = train::dancenet::Options::default().lr)]
        lr: f64,
        /// λ, the weight of the foot-contact loss.
        #[arg(long, default_value_t = train::dancenet::Options::default().lambda_foot)]
        lambda_foot: f64,
        /// σ_in: standard deviation of the Gaussian noise on the decoder's input frames (normalised
        /// units; the targets stay clean), so it learns to come back from its own samples.
        #[arg(long, default_value_t = train::dancenet::Options::default().input_noise)]
        input_noise: f64,
        /// Correlation from frame to frame of that noise (AR(1)); 0 is independent per frame. Noise
        /// independent per frame taught the decoder to undo a frame-to-frame zig-zag, and on its own
        /// (smooth) samples it then made one: its means alternated direction on 57 % of frames.
        #[arg(long, default_value_t = train::dancenet::Options::default().input_coherence)]
        input_coherence: f64,
        /// Standard deviation of a constant offset added to each window's input frames (normalised
        /// units; per window and dimension): a history that has drifted off the real dances, which
        /// the decoder must learn to come back from since the targets stay clean. Sampling drifts:
        /// every draw adds its own error to what the decoder reads next.
        #[arg(long, default_value_t = train::dancenet::Options::default().input_offset)]
        input_offset: f64,
        /// Standard deviation per frame of a random walk added to the input frames (normalised
        /// units): drift that grows within the window.
        #[arg(long, default_value_t = train::dancenet::Options::default().input_walk)]
        input_walk: f64,
        /// Frames of each window that are context only (default: the receptive field, so every
        /// scored frame sees real history, never zero padding).
        #[arg(long)]
        warmup: Option<usize>,
        /// Windows of the rarer styles repeat `(waltz frames / style frames)^p` times (at most 4), so
        /// the style input is learned from more than waltz; 0 trains on the data as it is.
        #[arg(long, default_value_t = train::dancenet::Options::default().style_balance)]
        style_balance: f64,
        /// Mixture components (the paper: 1).
        #[arg(long)]
        mixtures: Option<i64>,
        /// Leading frame columns whose mixture means are absolute rather than relative to the current
        /// frame (default: all; 4 makes only the root's absolute, see `dancenet::Config::absolute_dims`).
        #[arg(long)]
        absolute_dims: Option<i64>,
        /// Default sampling temperature written into `model.json` (served: 0.8; see the model card).
        #[arg(long, default_value_t = train::dancenet::Options::default().temperature)]
        temperature: f64,
        /// Default coherence ρ of the sampling draws written into `model.json` (`dancenet::Sampling`).
        #[arg(long, default_value_t = train::dancenet::Options::default().coherence)]
        coherence: f64,
        /// σ (frames) of the served smoothing written into `model.json` (`dancenet::Serving`).
        #[arg(long, default_value_t = train::dancenet::Options::default().smooth_frames)]
        smooth_frames: f64,
        #[arg(long, default_value_t = train::dancenet::Options::default().seed)]
        seed: u64,
        /// Weight of the rhythm term: a few windows per batch danced on freely by the decoder, the
        /// magnitude spectra of their velocities held to the real continuation's (model card).
        #[arg(long, default_value_t = train::dancenet::Options::default().spectral_weight)]
        spectral_weight: f64,
        /// Weight of the lock term: the same free-running windows, scored by how much of the
        /// toes' speed swings at the style's fraction of the song's beats (model card).
        #[arg(long, default_value_t = train::dancenet::Options::default().lock_weight)]
        lock_weight: f64,
        /// Windows per batch danced on freely for the rhythm and lock terms.
        #[arg(long, default_value_t = train::dancenet::Options::default().rollout_windows)]
        rollout_windows: usize,
        /// Slowest tempo factor a training window is drawn at (music and dance resampled together).
        #[arg(long, default_value_t = train::dancenet::Options::default().min_tempo)]
        min_tempo: f64,
        /// Fastest tempo factor a training window is drawn at.
        #[arg(long, default_value_t = train::dancenet::Options::default().max_tempo)]
        max_tempo: f64,
        /// Share of training windows whose style input is zeroed, so the decoder learns what the
        /// style implies from the music code too.
        #[arg(long, default_value_t = train::dancenet::Options::default().style_dropout)]
        style_dropout: f64,
        /// The control signals (onset, beat, downbeat, chroma) join the music code in every gated
        /// layer's conditioning; with `--init` their new weights start at zero.
        #[arg(long)]
        music_direct: bool,
        /// A phase turning once per step of the song's beats joins every gated layer's
        /// conditioning (in training at the real dancer's own step rate and zero); with `--init`
        /// its new weights start at zero.
        #[arg(long)]
        step_clock: bool,
    }
}

args_into! {
    /// Options of one training run; the model card gives the runs (and flags) behind the committed weights.
    pub struct KeyposeTransformerArgs => train::keypose_transformer::Options {
        #[command(flatten)]
        common: CommonArgs,
        #[arg(long, default_value_t = train::keypose_transformer::Options::default().epochs)]
        epochs: usize,
        #[arg(long, default_value_t = train::keypose_transformer::Options::default().batch)]
        batch: usize,
        /// Stride between training window starts, in frames.
        #[arg(long, default_value_t = train::keypose_transformer::Options::default().stride)]
        stride: usize,
        #[arg(long, default_value_t = train::keypose_transformer::Options::default().lr)]
        lr: f64,
        /// `λ`: weight of the key-pose terms in ω(t).
        #[arg(long, default_value_t = train::keypose_transformer::Options::default().lambda)]
        lambda: f64,
        /// `σ`: width of each key-pose term in ω(t), frames.
        #[arg(long, default_value_t = train::keypose_transformer::Options::default().sigma)]
        sigma: f64,
        /// Weight of the L1 on frame differences (velocities) beside the pose term: the pose term alone
        /// lets a regression average fast motion away.
        #[arg(long, default_value_t = train::keypose_transformer::Options::default().velocity_weight)]
        velocity_weight: f64,
        /// Frames between the scaffold poses the served model draws (0: none); see the scaffold module.
        #[arg(long, default_value_t = train::keypose_transformer::Options::default().scaffold_spacing)]
        scaffold_spacing: usize,
        /// Clips of the served pose bank, and their length in frames.
        #[arg(long, default_value_t = train::keypose_transformer::Options::default().bank_clips)]
        bank_clips: usize,
        #[arg(long, default_value_t = train::keypose_transformer::Options::default().bank_frames)]
        bank_frames: usize,
        /// Key poses per training window are drawn uniformly from 0..=max_keys.
        #[arg(long, default_value_t = train::keypose_transformer::Options::default().max_keys)]
        max_keys: usize,
        /// Key poses per test dance in the consistency evaluation.
        #[arg(long, default_value_t = train::keypose_transformer::Options::default().eval_keys)]
        eval_keys: usize,
        #[arg(long, default_value_t = train::keypose_transformer::Options::default().seed)]
        seed: u64,
        /// Do not train: re-run the test-split evaluation of the model already in `--out` and rewrite
        /// its `eval.json`.
        #[arg(long)]
        eval_only: bool,
        /// Do not train: redraw the pose bank with each clip's source and beats into `--out`
        /// (`pose_bank.safetensors`, `pose_bank.json`).
        #[arg(long)]
        bank_only: bool,
    }
}

args_into! {
    /// Options of one training run (the card gives the run behind the committed weights).
    pub struct TsmtArgs => train::tsmt::Options {
        #[command(flatten)]
        common: CommonArgs,
        #[arg(long, default_value_t = train::tsmt::Options::default().epochs)]
        epochs: usize,
        #[arg(long, default_value_t = train::tsmt::Options::default().batch)]
        batch: usize,
        /// Stride between window starts, in frames (the window is the configuration's context).
        #[arg(long, default_value_t = train::tsmt::Options::default().stride)]
        stride: usize,
        #[arg(long, default_value_t = train::tsmt::Options::default().lr)]
        lr: f64,
        /// Standard deviation, in bins, of Gaussian noise added to the pose stream's input tokens
        /// (the targets stay clean), so that the model learns to come back from its own draws.
        #[arg(long, default_value_t = train::tsmt::Options::default().input_noise_bins)]
        input_noise_bins: f64,
        /// Default sampling temperature written into `model.json`.
        #[arg(long, default_value_t = train::tsmt::Options::default().temperature)]
        temperature: f64,
        /// Default top-k written into `model.json` (0: every bin).
        #[arg(long, default_value_t = train::tsmt::Options::default().top_k)]
        top_k: usize,
        /// Share of each window's predicted frames scored per step (drawn afresh every batch):
        /// the 300-bin read-out is most of a step's cost, so scoring a quarter of the frames gives
        /// about three times the steps for the same minutes.
        #[arg(long, default_value_t = train::tsmt::Options::default().loss_frames)]
        loss_frames: f64,
        /// Windows whose last second's mean root-relative joint speed is below this (m/s) are not
        /// trained on (the dancer comes to a stand, mostly a dance's closing hold). 0 keeps all (the
        /// served weights; 0.15 was tried, see the model card).
        #[arg(long, default_value_t = train::tsmt::Options::default().min_window_speed)]
        min_window_speed: f64,
        /// De-quantisation σ (frames) written into `model.json` (see `tsmt::Serving`).
        #[arg(long, default_value_t = train::tsmt::Options::default().smooth_frames)]
        smooth_frames: f64,
        /// De-quantisation σ (frames) of the height column (see `tsmt::Serving`).
        #[arg(long, default_value_t = train::tsmt::Options::default().smooth_height_frames)]
        smooth_height_frames: f64,
        /// The stall guard's reach (m) written into `model.json` (0: no guard; `tsmt::StallGuard`,
        /// over 2 s, temperature × 1.5).
        #[arg(long, default_value_t = train::tsmt::Options::default().stall_reach)]
        stall_reach: f64,
        /// The stall guard's reopen reach (m) written into `model.json`: an opening whose 2-s
        /// windows all reach less for 10 s in a row within the song's first 20 s is a freeze, and
        /// the dance opens from the next candidate clip (0: never; `tsmt::StallGuard`).
        #[arg(long, default_value_t = train::tsmt::Options::default().reopen_reach)]
        reopen_reach: f64,
        #[arg(long, default_value_t = train::tsmt::Options::default().seed)]
        seed: u64,
        /// Train in beat time (`models::beat_time`): every dance re-timed to the split's median
        /// tempo; the model then serves in beat time.
        #[arg(long, default_value_t = train::tsmt::Options::default().beat_time, action = clap::ArgAction::Set)]
        beat_time: bool,
        /// Slowest tempo factor a training window is drawn at (music and dance resampled together).
        #[arg(long, default_value_t = train::tsmt::Options::default().min_tempo)]
        min_tempo: f64,
        /// Fastest tempo factor a training window is drawn at.
        #[arg(long, default_value_t = train::tsmt::Options::default().max_tempo)]
        max_tempo: f64,
        /// Mirror half the training windows left ↔ right.
        #[arg(long, default_value_t = train::tsmt::Options::default().mirror, action = clap::ArgAction::Set)]
        mirror: bool,
        /// Share of each window's input frames replaced by the model's own draws (0: off; the
        /// auto-conditioned training against freezing, see `train::tsmt::Options`).
        #[arg(long, default_value_t = train::tsmt::Options::default().self_condition)]
        self_condition: f64,
        /// Length, in frames, of each run of the model's own draws.
        #[arg(long, default_value_t = train::tsmt::Options::default().self_run)]
        self_run: usize,
        /// Teacher-forced passes that draw the own frames (each from the last pass's input).
        #[arg(long, default_value_t = train::tsmt::Options::default().self_passes)]
        self_passes: usize,
        /// A phase turning once per step of the song's beats joins the pose stream's input and the
        /// fusion (in training at the real dancer's own step rate and zero over the 10 s up to
        /// each window's end; served, the song's beats at its metre's fraction); with `--init`
        /// its new weights start at zero.
        #[arg(long)]
        step_clock: bool,
        /// Weight of the lock term (with `--step-clock`): the toes' speed the network means to
        /// draw next, after its own draws and the dance, held to peak where the clock says the
        /// real dancer's does (model card).
        #[arg(long, default_value_t = train::tsmt::Options::default().lock_weight)]
        lock_weight: f64,
        /// Warped histories (with `--step-clock`): each window's first 40 frames are the same
        /// dance replayed at a pace drawn in [1/R, R], ending on the pose the window continues
        /// from, and only the frames after them are scored, so the continuation's pace is heard
        /// from the clock and the beats, not the history (0: off).
        #[arg(long, default_value_t = train::tsmt::Options::default().history_warp)]
        history_warp: f64,
        /// The lock term raises the toes' score on the clock itself, not only up to the real
        /// continuation's.
        #[arg(long)]
        lock_uncapped: bool,
        /// Free runs (with `--step-clock`): the first N windows of each batch are also danced
        /// freely by the network, as served, from 40 real frames on, through straight-through
        /// draws, and the toes' speed of the run is held to step with the clock (0: off).
        #[arg(long, default_value_t = train::tsmt::Options::default().free_runs)]
        free_runs: usize,
        /// Frames each free run draws (at most 210: the clock's 250 frames less the context).
        #[arg(long, default_value_t = train::tsmt::Options::default().free_frames)]
        free_frames: usize,
        /// Weight of the free runs' lock term.
        #[arg(long, default_value_t = train::tsmt::Options::default().free_weight)]
        free_weight: f64,
        /// Weight of the free runs' body term: every second of a run moves at least 0.7 of the
        /// real continuation's joint speed, the whole run at most `--free-pace-max` of it, and
        /// its lowest foot stays within 2 cm of the highest the real one reached (0: off).
        #[arg(long, default_value_t = train::tsmt::Options::default().free_body)]
        free_body: f64,
        /// The body term's pace ceiling, a multiple of the real continuation's mean joint speed
        /// (0: none).
        #[arg(long, default_value_t = train::tsmt::Options::default().free_pace_max)]
        free_pace_max: f64,
        /// The step clock's gain as served, written into `model.json` (`tsmt::Serving::clock_gain`;
        /// training itself hears the clock at 1).
        #[arg(long, default_value_t = train::tsmt::Options::default().clock_gain)]
        clock_gain: f64,
        /// The served clock turns at the fraction of the song's beat whose step rate is nearest
        /// this (Hz), written into `model.json` (`tsmt::Serving::clock_step_hz`; none: the
        /// metre's fraction).
        #[arg(long)]
        clock_step_hz: Option<f64>,
        /// The served clock turns once a bar, halved or doubled into this band of step rates
        /// (Hz, `LOW,HIGH`), written into `model.json` (`tsmt::Serving::clock_bar_hz`; read
        /// before `--clock-step-hz`).
        #[arg(long, value_delimiter = ',')]
        clock_bar_hz: Option<Vec<f64>>,
        /// Do not train: redraw the seed clips (the same clips for the same `--seed`) with each
        /// one's source and its song's beats into `--out` (`seed_clips.safetensors`,
        /// `seed_clips.json`; with it the song chooses the opening clip).
        #[arg(long)]
        clips_only: bool,
    }
}

args_into! {
    /// Options of one training run (the card gives the run behind the committed weights).
    pub struct DancenetStyleArgs => train::dancenet_style::Options {
        #[command(flatten)]
        common: CommonArgs,
        #[command(flatten)]
        schedule: ClassifyArgs,
        /// Roll each training window's chroma by a random 0–11 semitones (a song's key says nothing
        /// of its style, and 37 songs are few enough to be told apart by their keys).
        #[arg(long, default_value_t = train::dancenet_style::Options::default().transpose, action = clap::ArgAction::Set)]
        transpose: bool,
    }
}

args_into! {
    /// Options of one training run (the card gives the run behind the committed weights).
    pub struct MotionStyleArgs => train::motion_style::Options {
        #[command(flatten)]
        common: CommonArgs,
        #[command(flatten)]
        schedule: ClassifyArgs,
        /// Windows of no style ([`no_style_windows`]) added to each batch with a uniform target
        /// (0: none).
        #[arg(long, default_value_t = train::motion_style::Options::default().no_style_per_batch)]
        no_style_per_batch: usize,
    }
}

args_into! {
    /// Options of the library build (the card gives the one behind the committed folder).
    pub struct BeatGraphArgs => train::beat_graph::Options {
        #[command(flatten)]
        common: CommonArgs,
        /// Ridge penalty of the music match, per pair.
        #[arg(long, default_value_t = train::beat_graph::Options::default().ridge)]
        ridge: f64,
        /// Edges kept per unit in the motion graph.
        #[arg(long, default_value_t = train::beat_graph::Options::default().graph_degree)]
        graph_degree: usize,
        /// Leave fold `K/N` of the train dances out of the library (each style's dances, in
        /// split order, go to fold i mod N; the lone tango never), to choose settings with
        /// `choreo eval --split train --hold-out K/N` instead of on the test split. Write it with
        /// `--out` elsewhere, never over the committed folder.
        #[arg(long)]
        hold_out: Option<String>,
    }
}
