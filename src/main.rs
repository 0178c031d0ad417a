//! The `choreo` command line: a thin dispatcher over the library (`anyhow` lives only here).
use anyhow::Context;
use choreo::config::{Config, Overrides};
use clap::{Args, Parser, Subcommand};
use std::path::PathBuf;

#[derive(Parser)]
#[command(name = "choreo", version, about = "A service that turns a song into a dance")]
struct Cli {
    /// Config file; defaults to ./config.toml when present.
    #[arg(long, global = true, env = "CHOREO_CONFIG")]
    config: Option<PathBuf>,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the HTTP service and its workers (`--no-workers`: the API only).
    Serve(ServeArgs),
    /// Run workers only, no HTTP: they take jobs from the configured database.
    Worker(WorkerArgs),
    /// Print a song's tempo, beats and downbeats as JSON.
    Analyze {
        /// An mp3, wav, flac, ogg or m4a file.
        path: PathBuf,
    },
    /// Print the libtorch version, thread settings, data dir and the models found.
    Doctor(ServiceArgs),
    /// Score Real, Mismatched-real and models on the test split (Markdown table + JSON).
    Eval(choreo::eval::EvalArgs),
    /// Generate a dance for a song: motion.bvh, motion.json, motion.glb, report.json and preview.png.
    Generate(choreo::worker::standalone::GenerateArgs),
    /// Train a model on the train split of dance-with-melody and write its folder under models/.
    Train {
        #[command(subcommand)]
        model: choreo::models::train::TrainCommand,
    },
    /// Write a dataset dance as BVH, JSON or glb through the exporter generated dances use.
    Export(choreo::motion::export::ExportArgs),
    /// Benchmarks.
    Bench {
        #[command(subcommand)]
        what: BenchCommand,
    },
}

#[derive(Subcommand)]
enum BenchCommand {
    /// Seconds per minute of music for each model, split by stage (decode → report).
    Generate(choreo::worker::standalone::BenchArgs),
    /// Throughput and p99 of GET /v1/jobs/{id} on loopback while the workers are busy.
    Http(HttpBenchArgs),
    /// Decode + DanceRevolution features per song vs librosa (one thread each), peak memory.
    Audio(choreo::audio::bench::BenchArgs),
}

/// Flags that override the config file and `CHOREO_*` environment.
#[derive(Args)]
struct ServiceArgs {
    /// Listen address, e.g. 127.0.0.1:8080 (port 0 picks one) [env: CHOREO_BIND].
    #[arg(long)]
    bind: Option<String>,
    /// Where the database, songs and results live [env: CHOREO_DATA_DIR].
    #[arg(long)]
    data_dir: Option<PathBuf>,
    /// Where trained models live [env: CHOREO_MODELS_DIR].
    #[arg(long)]
    models_dir: Option<PathBuf>,
    /// Worker count; 0 = one per core [env: CHOREO_WORKERS].
    #[arg(long)]
    workers: Option<usize>,
}

impl ServiceArgs {
    fn overrides(&self) -> Overrides {
        Overrides {
            bind: self.bind.clone(),
            data_dir: self.data_dir.clone(),
            models_dir: self.models_dir.clone(),
            workers: self.workers,
        }
    }
}

#[derive(Args)]
struct ServeArgs {
    #[command(flatten)]
    service: ServiceArgs,
    /// Serve the API only; `choreo worker` processes sharing the database run the jobs.
    #[arg(long)]
    no_workers: bool,
}

#[derive(Args)]
struct WorkerArgs {
    /// Where songs and results live [env: CHOREO_DATA_DIR].
    #[arg(long)]
    data_dir: Option<PathBuf>,
    /// Where trained models live [env: CHOREO_MODELS_DIR].
    #[arg(long)]
    models_dir: Option<PathBuf>,
    /// Worker count; 0 = one per core [env: CHOREO_WORKERS].
    #[arg(long)]
    workers: Option<usize>,
}

impl WorkerArgs {
    fn overrides(&self) -> Overrides {
        Overrides { data_dir: self.data_dir.clone(), models_dir: self.models_dir.clone(), workers: self.workers, ..Overrides::default() }
    }
}

#[derive(Args)]
struct HttpBenchArgs {
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
    service: ServiceArgs,
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    let load = |args: &ServiceArgs| Config::load(cli.config.as_deref(), &args.overrides()).context("loading configuration");
    match &cli.command {
        Command::Serve(args) => serve(load(&args.service)?, !args.no_workers),
        Command::Worker(args) => {
            worker(Config::load(cli.config.as_deref(), &args.overrides()).context("loading configuration")?)
        }
        Command::Analyze { path } => analyze(path),
        Command::Doctor(args) => {
            for (name, value) in choreo::telemetry::doctor(&load(args)?) {
                println!("{name:<34} {value}");
            }
            Ok(())
        }
        Command::Generate(args) => {
            // Warnings (and RUST_LOG's choice) from the models reach the terminal.
            choreo::telemetry::init_tracing(choreo::config::LogFormat::default(), "warn");
            let g = choreo::worker::standalone::generate(args).context("choreo generate")?;
            for (stage, d) in &g.stages {
                eprintln!("{stage:<14} {:>8.3} s", d.as_secs_f64());
            }
            for file in &g.files {
                println!("{}", file.display());
            }
            Ok(())
        }
        Command::Bench { what: BenchCommand::Generate(args) } => {
            println!("{}", choreo::worker::standalone::bench(args).context("choreo bench generate")?);
            Ok(())
        }
        Command::Train { model } => {
            choreo::telemetry::init_tracing(choreo::config::LogFormat::default(), "info");
            println!("{}", model.run().context("choreo train")?);
            Ok(())
        }
        Command::Bench { what: BenchCommand::Http(args) } => bench_http(args, load(&args.service)?),
        Command::Bench { what: BenchCommand::Audio(args) } => args.run().map(|_| ()).context("choreo bench audio"),
        Command::Eval(args) => choreo::eval::run(args).context("choreo eval"),
        Command::Export(args) => args.run().context("choreo export"),
    }
}

fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread().enable_all().build().context("starting the async runtime")
}

fn serve(config: Config, with_workers: bool) -> anyhow::Result<()> {
    choreo::telemetry::init_tracing(config.log_format, &config.log_level);
    runtime()?.block_on(async {
        let server = if with_workers {
            choreo::api::Server::start(config).await
        } else {
            choreo::api::Server::start_api_only(config).await
        }
        .context("starting the service")?;
        // Tools and tests read the bound address (port 0 resolves here) from this line.
        println!("choreo listening on http://{}", server.addr());
        shutdown_signal().await;
        tracing::info!("shutting down");
        server.stop().await;
        Ok(())
    })
}

fn worker(config: Config) -> anyhow::Result<()> {
    choreo::telemetry::init_tracing(config.log_format, &config.log_level);
    runtime()?.block_on(async {
        let workers = choreo::worker::process::WorkerProcess::start(&config).await.context("starting the workers")?;
        // Tools and tests wait for this line.
        println!("choreo worker running {} workers", workers.count());
        shutdown_signal().await;
        tracing::info!("shutting down");
        workers.stop().await;
        Ok(())
    })
}

async fn shutdown_signal() {
    let ctrl_c = tokio::signal::ctrl_c();
    #[cfg(unix)]
    {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut term) => {
                tokio::select! {
                    _ = ctrl_c => {}
                    _ = term.recv() => {}
                }
            }
            Err(_) => {
                let _ = ctrl_c.await;
            }
        }
    }
    #[cfg(not(unix))]
    {
        let _ = ctrl_c.await;
    }
}

fn analyze(path: &std::path::Path) -> anyhow::Result<()> {
    let decoded = choreo::audio::decode_path(path).with_context(|| format!("decoding {}", path.display()))?;
    let analysis = choreo::audio::analyze(&decoded).with_context(|| format!("analysing {}", path.display()))?;
    println!("{}", serde_json::to_string_pretty(&analysis)?);
    Ok(())
}

fn bench_http(args: &HttpBenchArgs, config: Config) -> anyhow::Result<()> {
    choreo::telemetry::init_tracing(config.log_format, "warn");
    anyhow::ensure!(args.seconds > 0.0 && args.seconds <= 600.0, "--seconds must be within (0, 600]");
    let bench = choreo::api::bench::HttpBench {
        song: args.song.clone(),
        duration: std::time::Duration::from_secs_f64(args.seconds),
        connections: args.connections,
        busy_jobs: args.busy_jobs,
        config,
    };
    let report = runtime()?.block_on(choreo::api::bench::run(bench)).context("running the HTTP bench")?;
    println!("{}", serde_json::to_string_pretty(&report)?);
    Ok(())
}
