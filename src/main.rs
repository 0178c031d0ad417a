//! The `choreo` binary: parses the command line ([`cli`]: every flag, the tables printed, the
//! progress bar) and dispatches to the library (`anyhow` lives only in the binary).
use anyhow::Context;
use choreo::config::Config;
use clap::Parser;

mod cli;

use cli::{BenchCommand, Cli, Command, ServiceArgs};

/// Exit code for a configuration that is refused, as clap uses for a refused flag.
const EXIT_USAGE: u8 = 2;

fn main() -> std::process::ExitCode {
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("Error: {e:?}");
            let refused = e.chain().any(|cause| {
                cause
                    .downcast_ref::<choreo::config::ConfigError>()
                    .is_some()
            });
            if refused {
                std::process::ExitCode::from(EXIT_USAGE)
            } else {
                std::process::ExitCode::FAILURE
            }
        }
    }
}

fn run() -> anyhow::Result<()> {
    let cli = Cli::parse();
    let load = |args: &ServiceArgs| {
        Config::load(cli.config.as_deref(), &args.overrides()).context("loading configuration")
    };
    match &cli.command {
        Command::Serve(args) => serve(load(&args.service)?, !args.no_workers),
        Command::Worker(args) => worker(
            Config::load(cli.config.as_deref(), &args.overrides())
                .context("loading configuration")?,
        ),
        Command::Analyze { path } => analyze(path),
        Command::Doctor(args) => {
            let config = load(args)?;
            let keys = cli::keys::seen(&config);
            for (name, value) in choreo::telemetry::doctor(&config, &keys) {
                println!("{name:<34} {value}");
            }
            Ok(())
        }
        Command::Generate(args) => cli::generate::generate(args),
        Command::Bench {
            what: BenchCommand::Generate(args),
        } => cli::generate::bench(args),
        Command::Train { model } => cli::train::run(model),
        Command::Bench {
            what: BenchCommand::Http(args),
        } => cli::bench::http(args, load(&args.service)?),
        Command::Bench {
            what: BenchCommand::Audio(args),
        } => cli::bench::audio(args),
        Command::Bench {
            what: BenchCommand::Jobs(args),
        } => cli::bench::jobs(args, load(&args.service)?),
        Command::Eval(args) => cli::eval::run(args),
        Command::Export(args) => cli::export::run(args),
        Command::Retarget(args) => cli::retarget::run(args),
        Command::Keys(args) => cli::keys::run(args, load(&args.service())?),
    }
}

fn serve(config: Config, with_workers: bool) -> anyhow::Result<()> {
    choreo::telemetry::init_tracing(config.log_format, &config.log_level);
    cli::runtime()?.block_on(async {
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
    cli::runtime()?.block_on(async {
        let workers = choreo::worker::process::WorkerProcess::start(&config)
            .await
            .context("starting the workers")?;
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
    let decoded =
        choreo::audio::decode_path(path).with_context(|| format!("decoding {}", path.display()))?;
    let analysis = choreo::audio::analyze(&decoded)
        .with_context(|| format!("analysing {}", path.display()))?;
    println!("{}", serde_json::to_string_pretty(&analysis)?);
    Ok(())
}
