//! `choreo generate` (with its progress bar) and `choreo bench generate`.
use std::path::PathBuf;

use anyhow::Context;
use choreo::worker::standalone::{self, BenchOptions, GenerateSong};

fn generate_defaults() -> GenerateSong {
    GenerateSong::default()
}

fn bench_defaults() -> BenchOptions {
    BenchOptions::default()
}

args_into! {
    /// `choreo generate` arguments.
    pub struct GenerateArgs => GenerateSong {
        /// An mp3, wav, flac, ogg or m4a file.
        song: PathBuf,
        /// The model id (see `choreo doctor` or `GET /v1/models`).
        #[arg(long, default_value_t = generate_defaults().model)]
        model: String,
        /// Output folder for motion.bvh, motion.json, motion.glb, report.json and preview.png.
        #[arg(long)]
        out: PathBuf,
        /// Seeds every random draw: the same seed gives the same dance.
        #[arg(long, default_value_t = generate_defaults().seed)]
        seed: u64,
        /// A JSON file with key poses `[{time_s, joints}]` as the API takes them: 26 joints (a frame of
        /// motion.json), 23 (dataset order), or `bvh: {text, frame}` (models that take them).
        #[arg(long)]
        key_poses: Option<PathBuf>,
        /// Where trained models live.
        #[arg(long, default_value_os_t = generate_defaults().models_dir)]
        models_dir: PathBuf,
        /// Keep the model's motion as it came: do not plant the feet (`motion::feet`).
        #[arg(long)]
        no_plant_feet: bool,
        /// Keep the network's timing: do not move its steps onto the song's beats
        /// (`motion::beat_align`), to see what the network does on its own.
        #[arg(long)]
        no_beat_align: bool,
        /// The style to dance (models that take one): waltz, rumba, cha-cha or tango. Default: the
        /// model's classifier picks one from the song.
        #[arg(long)]
        style: Option<String>,
        /// Sampling temperature (sampling models): 1 is as trained.
        #[arg(long)]
        temperature: Option<f64>,
        /// Sample only among the k likeliest choices (models over discrete choices).
        #[arg(long)]
        top_k: Option<u32>,
    }
}

args_into! {
    /// `choreo bench generate` arguments.
    pub struct BenchArgs => BenchOptions {
        /// Models to time (default: every model found).
        #[arg(long)]
        model: Vec<String>,
        /// Songs to time; a 3-minute song made by joining them is always added.
        #[arg(long, default_values_os_t = bench_defaults().songs)]
        songs: Vec<PathBuf>,
        #[arg(long, default_value_os_t = bench_defaults().models_dir)]
        models_dir: PathBuf,
        /// libtorch intra-op threads (the service uses 1 per worker).
        #[arg(long, default_value_t = bench_defaults().threads)]
        threads: i32,
        /// Also time a 90-s and a 420-s song (the given songs joined and looped: none of the shared
        /// songs is 7 minutes long) and print each model's cost ratio beside the length ratio.
        #[arg(long)]
        scaling: bool,
    }
}

/// `choreo generate`: the generation arguments and the rig to add.
#[derive(Clone, Debug, clap::Args)]
pub struct GenerateCmd {
    #[command(flatten)]
    pub song: GenerateArgs,
    /// Also write the dance on this skeleton beside the others: mixamo (motion.mixamo.bvh and
    /// .glb), vrm (motion.vrm.bvh, .glb and motion.vrma) or smpl (motion.smpl.bvh, .glb and
    /// motion.smpl.npz); choreo (the default) adds nothing.
    #[arg(long, default_value = "choreo")]
    pub rig: String,
}

/// `choreo generate`: a dance for one song, with a progress bar on stderr; prints each stage's
/// time (stderr) and the files written (stdout).
pub fn generate(cmd: &GenerateCmd) -> anyhow::Result<()> {
    // An unknown rig fails before the generation, not after it.
    if cmd.rig != "choreo" {
        super::retarget::target(&cmd.rig)?;
    }
    let args = &cmd.song;
    // Warnings (and RUST_LOG's choice) from the models reach the terminal.
    choreo::telemetry::init_tracing(choreo::telemetry::env_log_format(), "warn");
    let mut bar: Option<indicatif::ProgressBar> = None;
    let mut on_progress = |stage: choreo::stage::Stage, done: f64| {
        let bar = bar.get_or_insert_with(progress_bar);
        bar.set_message(stage.as_str());
        bar.set_position((done * 1000.0) as u64);
    };
    // The library's audio errors do not name the file (the service's never show its paths):
    // here the path is the user's own, so a file that cannot be read is named.
    std::fs::File::open(&args.song)
        .with_context(|| format!("cannot read the song {}", args.song.display()))?;
    let g = standalone::generate(&args.clone().into(), &mut on_progress)
        .with_context(|| format!("choreo generate {}", args.song.display()))?;
    if let Some(bar) = &bar {
        bar.finish_with_message("done");
    }
    for (stage, d) in &g.stages {
        eprintln!("{:<14} {:>8.3} s", stage.as_str(), d.as_secs_f64());
    }
    for file in &g.files {
        println!("{}", file.display());
    }
    for file in super::retarget::beside(&args.out, &cmd.rig)? {
        println!("{}", file.display());
    }
    Ok(())
}

/// The bar `choreo generate` draws: the stage, then the share of the whole run.
fn progress_bar() -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(1000);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{spinner} {msg:>9} [{bar:40}] {percent:>3}% {elapsed}",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
        .progress_chars("=> "),
    );
    bar
}

/// `choreo bench generate`: prints the library's table.
pub fn bench(args: &BenchArgs) -> anyhow::Result<()> {
    println!(
        "{}",
        standalone::bench(&args.clone().into()).context("choreo bench generate")?
    );
    Ok(())
}
