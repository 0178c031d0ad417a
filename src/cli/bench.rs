//! `choreo bench audio`, `http` and `jobs`: their arguments and what they print.
use std::path::PathBuf;

use anyhow::Context;
use choreo::audio::bench::{BenchOptions, BenchRow, PYTHON};
use choreo::config::Config;

use super::ServiceArgs;

fn audio_defaults() -> BenchOptions {
    BenchOptions::default()
}

/// `choreo bench audio` flags.
#[derive(Clone, Debug, clap::Args)]
pub struct AudioBenchArgs {
    /// Folder of songs to time (every mp3/wav/flac/ogg/m4a in it).
    #[arg(long, default_value_os_t = audio_defaults().songs_dir)]
    pub songs: PathBuf,
    /// Motion frame rate of the DanceRevolution feature set.
    #[arg(long, default_value_t = audio_defaults().fps)]
    pub fps: f64,
    /// Length of the long song (built by concatenating the songs) for the memory check; 0 skips it.
    #[arg(long, default_value_t = audio_defaults().long_minutes)]
    pub long_minutes: f64,
    /// Python used to run tools/librosa_reference.py (it creates .venv-librosa on first use).
    #[arg(long, default_value = PYTHON)]
    pub python: PathBuf,
    /// Time choreo only.
    #[arg(long)]
    pub no_librosa: bool,
}

impl AudioBenchArgs {
    /// The benchmark, run from `repo_root`.
    pub fn options(&self, repo_root: PathBuf) -> BenchOptions {
        BenchOptions {
            songs_dir: self.songs.clone(),
            fps: self.fps,
            long_minutes: self.long_minutes,
            python: (!self.no_librosa).then(|| self.python.clone()),
            repo_root,
        }
    }
}

/// `choreo bench audio`: runs from the repository root (the working directory) and prints the table.
pub fn audio(args: &AudioBenchArgs) -> anyhow::Result<()> {
    let root = std::env::current_dir().context("choreo bench audio")?;
    let rows = choreo::audio::bench::run(&args.options(root)).context("choreo bench audio")?;
    print_table(&rows, args.fps);
    Ok(())
}

/// `choreo bench http` flags.
#[derive(clap::Args)]
pub struct HttpBenchArgs {
    /// The song whose analysis keeps the workers busy.
    #[arg(long, default_value = "../shared/audio/vibe_ace.ogg")]
    song: PathBuf,
    /// Seconds to measure.
    #[arg(long, default_value_t = 10.0)]
    seconds: f64,
    /// Concurrent keep-alive connections.
    #[arg(long, default_value_t = 16)]
    connections: usize,
    /// Analyze jobs queued to keep the workers busy.
    #[arg(long, default_value_t = 500)]
    busy_jobs: usize,
    #[command(flatten)]
    pub service: ServiceArgs,
}

/// `choreo bench http`: prints the report as JSON.
pub fn http(args: &HttpBenchArgs, config: Config) -> anyhow::Result<()> {
    choreo::telemetry::init_tracing(config.log_format, "warn");
    anyhow::ensure!(
        args.seconds > 0.0 && args.seconds <= 600.0,
        "--seconds must be within (0, 600]"
    );
    let bench = choreo::api::bench::HttpBench {
        song: args.song.clone(),
        duration: std::time::Duration::from_secs_f64(args.seconds),
        connections: args.connections,
        busy_jobs: args.busy_jobs,
        config,
    };
    let report = super::runtime()?
        .block_on(choreo::api::bench::run(bench))
        .context("running the HTTP bench")?;
    println!("{}", serde_json::to_string_pretty(&report)?);
    Ok(())
}

/// The table `choreo bench audio` prints.
fn print_table(rows: &[BenchRow], fps: f64) {
    let f = |v: Option<f64>, p: usize| v.map_or("-".to_string(), |x| format!("{x:.p$}"));
    println!("decode + DanceRevolution features (438-d, {fps} fps), one thread each");
    println!("peak MB: growth of this process's resident memory while the song is processed (0 when it fits in memory an earlier song freed)");
    println!(
        "| {:<28} | {:>7} | {:>9} | {:>10} | {:>9} | {:>10} | {:>7} | {:>10} |",
        "song", "len s", "decode s", "features s", "choreo s", "librosa s", "speedup", "peak MB"
    );
    println!(
        "|{:-<30}|{:-<9}|{:-<11}|{:-<12}|{:-<11}|{:-<12}|{:-<9}|{:-<12}|",
        "", "", "", "", "", "", "", ""
    );
    for r in rows {
        println!(
            "| {:<28} | {:>7.1} | {:>9.3} | {:>10.3} | {:>9.3} | {:>10} | {:>7} | {:>10} |",
            r.song,
            r.duration_s,
            r.rust_decode_s,
            r.rust_features_s,
            r.rust_total_s,
            f(r.librosa_total_s, 3),
            f(r.speedup, 1),
            f(r.rust_peak_mb, 1)
        );
    }
    let (rs, ls): (f64, f64) = rows
        .iter()
        .filter(|r| r.librosa_total_s.is_some())
        .map(|r| (r.rust_total_s, r.librosa_total_s.unwrap_or(0.0)))
        .fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
    if ls > 0.0 {
        println!(
            "total: choreo {rs:.2} s, librosa {ls:.2} s, speedup {:.1}x",
            ls / rs
        );
    }
    println!();
    println!("decode + beats (choreo: audio::analyze, with downbeats and the tempo curve; librosa: load at 22050 Hz + beat.beat_track), one thread each");
    println!(
        "| {:<28} | {:>9} | {:>10} | {:>7} |",
        "song", "choreo s", "librosa s", "speedup"
    );
    println!("|{:-<30}|{:-<11}|{:-<12}|{:-<9}|", "", "", "", "");
    for r in rows {
        println!(
            "| {:<28} | {:>9.3} | {:>10} | {:>7} |",
            r.song,
            r.rust_beats_s,
            f(r.librosa_beats_s, 3),
            f(r.beats_speedup, 1)
        );
    }
    let (rb, lb): (f64, f64) = rows
        .iter()
        .filter_map(|r| r.librosa_beats_s.map(|l| (r.rust_beats_s, l)))
        .fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
    if lb > 0.0 {
        println!(
            "total: choreo {rb:.2} s, librosa {lb:.2} s, speedup {:.1}x",
            lb / rb
        );
    }
}

/// `choreo bench jobs` flags.
#[derive(clap::Args)]
pub struct JobsBenchArgs {
    /// The song every job dances; by default a 3-minute song made by joining --join.
    #[arg(long)]
    song: Option<PathBuf>,
    /// Songs joined (looped and cut to 3 minutes) when no --song is given.
    #[arg(long, num_args = 1.., default_values = [
        "../shared/audio/vibe_ace.ogg",
        "../shared/audio/sugar_plum_fairy.ogg",
        "../shared/audio/lets_go_fishin.ogg",
    ])]
    join: Vec<PathBuf>,
    /// The model every job asks for.
    #[arg(long, default_value = "beat-graph")]
    model: String,
    /// Jobs queued at once on the one song (seeds 1..=N).
    #[arg(long, default_value_t = 10)]
    jobs: usize,
    /// Worker counts to measure, each on a fresh service.
    #[arg(long, num_args = 1.., default_values_t = [1, 2])]
    workers: Vec<usize>,
    #[command(flatten)]
    pub service: ServiceArgs,
}

/// `choreo bench jobs`: prints a Markdown table, then the rows as JSON.
pub fn jobs(args: &JobsBenchArgs, config: Config) -> anyhow::Result<()> {
    choreo::telemetry::init_tracing(config.log_format, "warn");
    anyhow::ensure!(
        (1..=1000).contains(&args.jobs),
        "--jobs must be within 1..=1000"
    );
    anyhow::ensure!(
        !args.workers.is_empty() && args.workers.iter().all(|w| (1..=256).contains(w)),
        "--workers must list counts within 1..=256"
    );
    let dir = tempfile::tempdir()?;
    let song = match &args.song {
        Some(p) => p.clone(),
        None => {
            let joined = dir.path().join("joined.wav");
            choreo::audio::bench::make_long_song(&args.join, 180.0, &joined)
                .context("joining --join")?;
            joined
        }
    };
    let seconds = choreo::audio::decode_path(&song)
        .with_context(|| format!("decoding {}", song.display()))?
        .duration_s;
    let bench = choreo::api::bench::jobs::JobsBench {
        song,
        model: args.model.clone(),
        jobs: args.jobs,
        workers: args.workers.clone(),
        config,
    };
    let rows = super::runtime()?
        .block_on(choreo::api::bench::jobs::run(bench))
        .context("running the jobs bench")?;
    println!(
        "{} dances of one {seconds:.0}-s song by {}, queued at once (seeds 1–{}), through the HTTP API",
        args.jobs, args.model, args.jobs
    );
    println!(
        "| workers | jobs | seconds | jobs/min | jobs/min per worker | × the first row | ideal × |"
    );
    println!("|---|---|---|---|---|---|---|");
    for r in &rows {
        println!(
            "| {} | {} | {:.1} | {:.1} | {:.1} | {:.2} | {:.2} |",
            r.workers,
            r.succeeded,
            r.seconds,
            r.jobs_per_min,
            r.jobs_per_min_per_worker,
            r.speedup,
            r.ideal_speedup
        );
    }
    println!("{}", serde_json::to_string(&rows)?);
    Ok(())
}
